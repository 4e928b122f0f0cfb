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
#include <stdint.h>

#include "vafm/params.h"

/** Apply the scene file `path` on top of p.
 *  @param preset   receives the file's preset name ("" if it has none); may be NULL
 *  @return 0, or VAFM_EIO (unreadable), VAFM_EFORMAT (not JSON / not an object, with line and column),
 *          VAFM_EINVAL (wrong type or value) or VAFM_ENOTFOUND (unknown key or preset); err names the key,
 *          the value, the allowed range and the file. p is left partly updated on failure. */
int vafm_cli_scene_load(vafm_params *p, const char *path, char *preset, size_t preset_len, vafm_error *err);

/** Apply a scene given as JSON text (the "vafm scene" root attribute of an HDF5 file); `origin` names
 *  where it came from in error messages. Same rules and return values as vafm_cli_scene_load. */
int vafm_cli_scene_parse(vafm_params *p, const char *text, const char *origin, vafm_error *err);

/** A campaign grid as vafm stores it in an HDF5 file ("vafm grid", protocol/hdf5.md). Lists absent or
 *  empty: NULL and 0 (the scene's value). curves_per_point 0: not recorded. */
typedef struct vafm_cli_grid {
    double *T_K, *v_m_per_s, *k_N_per_m;
    size_t n_T, n_v, n_k;
    uint64_t curves_per_point;
} vafm_cli_grid;

/** Parse a grid JSON object into g (free with vafm_cli_grid_free). @return 0 or VAFM_EFORMAT (err
 *  names the key and `origin`). */
int vafm_cli_grid_parse(const char *text, const char *origin, vafm_cli_grid *g, vafm_error *err);
void vafm_cli_grid_free(vafm_cli_grid *g);

/** Describe what a parameter accepts ("a number in [1e-06, 10000] N/m", "one of gjf|baoab|...") into
 *  buf, for error messages and help. */
void vafm_cli_param_allowed(const vafm_param_info *info, char *buf, size_t len);

#endif
