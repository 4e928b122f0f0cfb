/* SPDX-License-Identifier: MIT */
/*
 * Internal: number literals in JSON text that jansson would read silently wrong. jansson (strtod) rounds a
 * nonzero literal below DBL_MIN in magnitude ("1e-400") to 0 or a subnormal without a word; vafm refuses
 * such a number wherever a person writes one (units, the CLI, vafmd's requests, scene and segment files).
 */
#ifndef VAFM_RECORD_JSON_NUM_H
#define VAFM_RECORD_JSON_NUM_H

#include <stddef.h>

/** The key ("key": value) the value at b[pos] of JSON text b belongs to, into key (len bytes; "" when the key is
 *  longer, not plain (escapes) or absent). enclosing 0: an element of an array has none; 1: the key before it
 *  however far back (an element of an array gets the array's key: vafmd's requests). */
void vafm_rec_json_key_before(const char *b, size_t pos, int enclosing, char *key, size_t len);

/** The first nonzero number literal of JSON text b (n bytes, or up to a NUL) that reads as 0 or a subnormal.
 *  @return 1 found: key gets the key it is the value of (vafm_rec_json_key_before with enclosing), lit the
 *  literal (cut to litlen - 1 characters), *line its line (from 1), *as what it would read as; 0 none. */
int vafm_rec_json_underflow(const char *b, size_t n, int enclosing, char *key, size_t keylen, char *lit, size_t litlen,
                            size_t *line, double *as);

#endif
