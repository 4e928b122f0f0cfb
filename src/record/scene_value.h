/* SPDX-License-Identifier: MIT */
/*
 * Internal: one JSON value → the text vafm_params_set() takes, by the rules of record/scene.h. The CLI's
 * scene files (scene_json.c) and vafmd's command decoder (src/daemon/cmd_json.c) both call it, so a
 * scene means the same wherever it is written; it takes jansson's json_t, which is why it is not in the
 * public header.
 */
#ifndef VAFM_RECORD_SCENE_VALUE_H
#define VAFM_RECORD_SCENE_VALUE_H

#include <stddef.h>
#include <jansson.h>
#include "vafm/params.h"

/** The text form of JSON value v for parameter info (reals %.17g: lossless), or NULL when v has the
 *  wrong JSON type for the parameter's kind: a number for REAL; a non-negative integer or a string of
 *  1–20 decimal digits for SEED; a boolean for BOOL; a string without NUL shorter than len for CHOICE. */
const char *vafm_scene_value_text(const vafm_param_info *info, const json_t *v, char *buf, size_t len);

#endif
