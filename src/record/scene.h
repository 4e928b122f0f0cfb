/* SPDX-License-Identifier: MIT */
/**
 * @file scene.h
 * Scenes as JSON, one set of rules for every program: `vafm --scene FILE`, vafmd's commands, the
 * "vafm scene" and "vafm grid" attributes of HDF5 files and the scenes in a stream's run.start.
 *
 * A scene is one JSON object whose keys are the names of the parameter table (vafm/params.h) plus an
 * optional "preset" key, applied first whatever its position ("paper-fig4, but with k = 0.2 N/m").
 * Every other key goes through vafm_params_set(), so a scene obeys exactly the ranges and choices of
 * the command line. The JSON type must fit the parameter's kind: numbers for reals; true or false for
 * booleans (not 0/1); a non-negative integer or a string of decimal digits for the seed; a string for a
 * choice. vafm_params_to_json() writes a valid scene (an exact round trip: reals as %.17g).
 */
#ifndef VAFM_SCENE_H
#define VAFM_SCENE_H

#include <stddef.h>
#include <stdint.h>

#include "vafm/common.h"
#include "h5/h5.h"
#include "vafm/params.h"

#ifdef __cplusplus
extern "C" {
#endif

/** The largest scene file read, bytes (a scene is a few kB; anything larger is not one). */
#define VAFM_SCENE_MAX_FILE_BYTES (1u << 20)

/** Apply the scene file `path` on top of p.
 *  @param preset receives the file's preset name ("" if it has none); may be NULL
 *  @return 0, or VAFM_EIO (unreadable, not a regular file, larger than VAFM_SCENE_MAX_FILE_BYTES),
 *          VAFM_EFORMAT (not JSON / not an object, with line and column), VAFM_EINVAL (wrong type or
 *          value) or VAFM_ENOTFOUND (unknown key or preset); err names the key, the value, the allowed
 *          range and the file. p is left partly updated on failure. */
VAFM_API int vafm_scene_load_file(vafm_params *p, const char *path, char *preset, size_t preset_len,
                                  vafm_error *err);

/** Apply a scene given as JSON text; `origin` names where it came from in error messages. Same rules
 *  and return values as vafm_scene_load_file. */
VAFM_API int vafm_scene_parse(vafm_params *p, const char *text, const char *origin, vafm_error *err);

/** A campaign grid as vafm stores it in an HDF5 file ("vafm grid", protocol/hdf5.md). Lists absent or
 *  empty: NULL and 0 (the scene's value). curves_per_point 0: not recorded. */
typedef struct vafm_scene_grid {
    double *T_K;         /**< temperatures, K */
    double *v_m_per_s;   /**< piezo speeds, m/s */
    double *k_N_per_m;   /**< spring constants, N/m */
    size_t n_T, n_v, n_k;
    uint64_t curves_per_point;
} vafm_scene_grid;

/** Parse a grid JSON object into g (free with vafm_scene_grid_free). @return 0 or VAFM_EFORMAT (err
 *  names the key and `origin`). */
VAFM_API int vafm_scene_grid_parse(const char *text, const char *origin, vafm_scene_grid *g, vafm_error *err);

/** Free a grid's lists; NULL-safe fields. */
VAFM_API void vafm_scene_grid_free(vafm_scene_grid *g);

/** The scene (and grid, if g is not NULL) a vafm file was written with, from its provenance: p is
 *  reset to the defaults first. @return 0, VAFM_ENOTFOUND (not a vafm file: no scene recorded), or the
 *  parse error naming the file. */
VAFM_API int vafm_scene_from_h5(const vafm_h5_reader *r, const char *path, vafm_params *p, vafm_scene_grid *g,
                                vafm_error *err);

/** What a parameter accepts on the command line ("a number in [1e-06, 10000] N/m", "one of gjf|baoab|…"). */
VAFM_API void vafm_scene_param_allowed(const vafm_param_info *info, char *buf, size_t len);

/** What a parameter accepts in a JSON scene ("true or false", …). */
VAFM_API void vafm_scene_json_allowed(const vafm_param_info *info, char *buf, size_t len);

#ifdef __cplusplus
}
#endif
#endif
