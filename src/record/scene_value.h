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

/** A field vafm_params_resolve derives from an instrument setting, given directly as well. */
typedef struct vafm_scene_conflict {
    const char *derived; /**< v_approach_m_per_s, v_retract_m_per_s, sample_rate_Hz or setpoint_N */
    const char *setting; /**< the setting > 0 that derives it: ramp_rate_Hz, extend_time_s, retract_time_s,
                              segment_samples or setpoint_V */
    double value;        /**< the derived field's value in p (as given) */
    double setting_value;
    double derives;      /**< what the settings make it (NaN if the scene does not resolve) */
} vafm_scene_conflict;

/** The next pair, from pair index `from` (0 first), where given(derived, ctx) is true, the setting is > 0
 *  and the setting makes the field something else than p holds: resolve would overwrite the value given
 *  without a word. @return the index to continue from (> 0) with *out filled, or 0 when there is none. */
int vafm_scene_derived_next(const vafm_params *p, int from, int (*given)(const char *field, void *ctx), void *ctx,
                            vafm_scene_conflict *out);

#endif
