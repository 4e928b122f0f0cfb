/* SPDX-License-Identifier: MIT */
/*
 * JSON scene files for the vafm command-line tool.
 *
 * A scene file is one JSON object whose keys are the names of the parameter table (params.h) plus an
 * optional "preset" key. The preset is applied first whatever its position in the file, so a file can
 * say "paper-fig4, but with k = 0.2 N/m". Every other key goes through vafm_params_set, so the file
 * obeys exactly the ranges and choices of the command line. The output of vafm_params_to_json is a
 * valid scene file (round trip).
 */
#ifndef VAFM_CLI_SCENE_JSON_H
#define VAFM_CLI_SCENE_JSON_H

#include <stddef.h>

#include "vafm/params.h"

/** Apply the scene file `path` on top of p.
 *  @param preset   receives the file's preset name ("" if it has none); may be NULL
 *  @return 0, or VAFM_EIO (unreadable), VAFM_EFORMAT (not JSON / not an object, with line and column),
 *          VAFM_EINVAL (wrong type or value) or VAFM_ENOTFOUND (unknown key or preset); err names the key,
 *          the value, the allowed range and the file. p is left partly updated on failure. */
int vafm_cli_scene_load(vafm_params *p, const char *path, char *preset, size_t preset_len, vafm_error *err);

/** Describe what a parameter accepts ("a number in [1e-06, 10000] N/m", "one of gjf|baoab|...") into
 *  buf, for error messages and help. */
void vafm_cli_param_allowed(const vafm_param_info *info, char *buf, size_t len);

#endif
