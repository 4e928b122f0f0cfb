/* SPDX-License-Identifier: MIT */
/*
 * Internal: number literals in JSON text that jansson would read silently wrong. jansson (strtod) rounds a
 * nonzero literal below DBL_MIN in magnitude ("1e-400") to 0 or a subnormal without a word; vafm refuses
 * such a number wherever a person writes one (units, the CLI, vafmd's requests, scene and segment files).
 */
#ifndef VAFM_RECORD_JSON_NUM_H
#define VAFM_RECORD_JSON_NUM_H

#include <stddef.h>

/** The first nonzero number literal of JSON text b (n bytes, or up to a NUL) that reads as 0 or a subnormal.
 *  @return 1 found: key gets the key it is the value of ("" if none or not plain), lit the literal (cut to
 *  litlen - 1 characters), *line its line (from 1), *as what it would read as; 0 none. */
int vafm_rec_json_underflow(const char *b, size_t n, char *key, size_t keylen, char *lit, size_t litlen, size_t *line,
                            double *as);

#endif
