/* SPDX-License-Identifier: MIT */
/**
 * @file campaign.h
 * Many curves on all cores. A campaign is a grid of points (T × v × k over a base scene) with N curves
 * each. Curve i of point j has the global index j·N + i, which is its random stream: the results do not
 * depend on the thread count. Results reach the caller in index order, from one thread at a time.
 * vafm_campaign_run_source runs the indices a source hands out instead (MPI ranks: `vafm campaign`).
 */
#ifndef VAFM_CAMPAIGN_H
#define VAFM_CAMPAIGN_H

#include "vafm/common.h"
#include "vafm/params.h"
#include "vafm/sim.h"

#ifdef __cplusplus
extern "C" {
#endif

/** The scene of grid point `point` over `base` into *out, for a grid given point by point (a force map,
 *  vafm/map.h). Called from the worker threads concurrently: it must be thread-safe and give the same
 *  scene for the same point every time. @return 0 or a negative VAFM_E* code. */
typedef int (*vafm_campaign_point_fn)(void *user, const vafm_params *base, size_t point, vafm_params *out);

/** The grid. A list left NULL (count 0) means "the base scene's value". */
typedef struct vafm_campaign_spec {
    const double *T_K;          /**< temperatures, K */
    size_t n_T;
    const double *v_m_per_s;    /**< piezo speeds (approach and retract), m/s */
    size_t n_v;
    const double *k_N_per_m;    /**< spring constants, N/m */
    size_t n_k;
    uint64_t curves_per_point;  /**< N ≥ 1 */
    uint64_t first_curve;       /**< skip global indices below this (resume); usually 0 */
    int threads;                /**< worker threads, 0: all online cores */
    int keep_samples;           /**< 1: hand each curve's samples to the callback */
    /* a grid given point by point (a force map): with point_fn set the T, v, k lists must be empty */
    size_t n_points;            /**< points of the grid when point_fn is set, ≥ 1 */
    vafm_campaign_point_fn point_fn; /**< the scene of each point (NULL: the T × v × k grid) */
    void *point_user;           /**< for point_fn */
    const char *map_json;       /**< a force map's spec as a JSON object (vafm_map_to_json), which HDF5 files keep
                                     in their grid ("map") and resume compares; NULL: not a map */
    int kernel;                 /**< VAFM_CAMPAIGN_KERNEL_*: how curves are stepped (0: auto). The curves are the same bit
                                     for bit whichever runs them. */
    int batch_width;            /**< the batch kernel's lanes: 0 the widest this CPU runs (8 with AVX-512, 4 with AVX2,
                                     else 1), or 1, 4, 8 (capped at the CPU's) */
} vafm_campaign_spec;

/** Kernels of a campaign. */
enum {
    VAFM_CAMPAIGN_KERNEL_AUTO = 0,   /**< the batch kernel where the CPU has AVX2 or AVX-512, else the scalar one */
    VAFM_CAMPAIGN_KERNEL_SCALAR = 1, /**< one curve at a time per thread (the baseline) */
    VAFM_CAMPAIGN_KERNEL_BATCH = 2,  /**< several curves per thread in SIMD lanes (batch_width) */
};

/** One finished curve. */
typedef struct vafm_campaign_curve {
    uint64_t index;            /**< global curve index */
    size_t point;              /**< grid point (T index slowest, then v, then k; or point_fn's point) */
    const vafm_params *params; /**< the scene of that point (valid during the callback) */
    int status;                /**< 0, or the VAFM_E* code the curve ended with (e.g. VAFM_EUNSTABLE) */
    vafm_curve_result result;  /**< observables */
    vafm_samples samples;      /**< all samples of the curve when keep_samples, else n = 0 */
    vafm_error error;          /**< status ≠ 0: its detail (field, message) as vafm_sim_error gives it; else empty */
} vafm_campaign_curve;

/** Called for each curve in global index order, never concurrently. @return 0 to go on, non-zero to
 *  stop the campaign (VAFM_EABORT) after the curves in flight. */
typedef int (*vafm_campaign_fn)(void *user, const vafm_campaign_curve *c);

/** @return the number of grid points of a spec. */
VAFM_API size_t vafm_campaign_points(const vafm_campaign_spec *spec);

/** The axes of the T × v × k grid, slowest first: one table (campaign.c) that the grid's points, the
 *  CLI's --T/--v/--k, the daemon's `campaign` lists and the error messages read. */
enum { VAFM_CAMPAIGN_AXIS_T = 0, VAFM_CAMPAIGN_AXIS_V = 1, VAFM_CAMPAIGN_AXIS_K = 2, VAFM_CAMPAIGN_NAXES = 3 };

/** What an axis is called. */
typedef struct vafm_campaign_axis {
    const char *name;   /**< in files' grids and on the wire: "T_K", "v_m_per_s", "k_N_per_m" */
    const char *symbol; /**< in messages and CLI options (--T): "T", "v", "k" */
    const char *unit;   /**< "K", "m/s", "N/m" */
    const char *param;  /**< the scene parameter a bad value is reported as: "T_K", "v_approach_m_per_s", "k_N_per_m" */
} vafm_campaign_axis;

/** @return axis `axis` (VAFM_CAMPAIGN_AXIS_*), or NULL outside [0, VAFM_CAMPAIGN_NAXES). */
VAFM_API const vafm_campaign_axis *vafm_campaign_axis_at(int axis);

/** @return the number of values of an axis' list in spec (0: the base scene's value), with *values the list
 *  (may be NULL); 0 for an axis outside the table. */
VAFM_API size_t vafm_campaign_axis_values(const vafm_campaign_spec *spec, int axis, const double **values);

/** Set an axis' list in spec (values borrowed: they must outlive the spec's use). An axis outside the table is
 *  ignored. */
VAFM_API void vafm_campaign_axis_set(vafm_campaign_spec *spec, int axis, const double *values, size_t n);

/** Set a scene's value of an axis (v: both the approach and the retract speed). */
VAFM_API void vafm_campaign_axis_apply(vafm_params *p, int axis, double value);

/** @return a scene's value of an axis (v: the retract speed), NaN for an axis outside the table. */
VAFM_API double vafm_campaign_axis_value(const vafm_params *p, int axis);

/** The SIMD lanes a campaign with this spec steps curves in: 1 for the scalar kernel (or a CPU without
 *  AVX2), else 4 or 8. */
VAFM_API int vafm_campaign_kernel_width(const vafm_campaign_spec *spec);

/** Set spec's kernel from its name: "auto", "scalar", "batch" (the widest the CPU runs), "batch4", "batch8"
 *  (up to that many lanes, capped at the CPU's; one "batch<lanes>" per backend of the batch kernel).
 *  @return 0, or VAFM_EINVAL for another name (spec unchanged). */
VAFM_API int vafm_campaign_kernel_parse(const char *name, vafm_campaign_spec *spec);

/** The kernel names vafm_campaign_kernel_parse() accepts, joined by sep, into buf (e.g. "auto, scalar, batch,
 *  batch4, batch8"). @return 0, or VAFM_EINVAL (no buffer, or too small: buf then holds a truncated list). */
VAFM_API int vafm_campaign_kernel_names(char *buf, size_t size, const char *sep);

/** The kernel a campaign with this spec runs on this CPU, in words (e.g. "batch, 8 lanes (AVX-512)"). */
VAFM_API const char *vafm_campaign_kernel_describe(const vafm_campaign_spec *spec);

/** Fill `out` with the scene of grid point `point` (point_fn's, when the spec has one).
 *  @return 0, VAFM_EINVAL (no such point) or point_fn's error. */
VAFM_API int vafm_campaign_point_params(const vafm_params *base, const vafm_campaign_spec *spec,
                                        size_t point, vafm_params *out);

/** Validate the scene of every grid point (vafm_params_validate), in point order, before anything is
 *  run or written. @param bad_point receives the first invalid point (may be NULL)
 *  @return 0, or the first point's error with err->message "grid point P (T = …, v = …, k = …): why"
 *  and err->field the parameter. A spec with point_fn and T, v or k lists, or n_points 0, is VAFM_EINVAL. */
VAFM_API int vafm_campaign_validate(const vafm_params *base, const vafm_campaign_spec *spec, size_t *bad_point,
                                    vafm_error *err);

/** Run a campaign. Every point's scene is validated before any curve runs (err names the point).
 *  @return 0, VAFM_EABORT, or another negative VAFM_E* code. */
VAFM_API int vafm_campaign_run(const vafm_params *base, const vafm_campaign_spec *spec,
                               vafm_campaign_fn fn, void *user, vafm_error *err);

/** Supplies the global curve indices a campaign runs, in place of first_curve, first_curve + 1, ...
 *  (an MPI rank asks rank 0 for its next curve). Called by one worker thread at a time, without the
 *  campaign's lock held: it may block. @return 1 with *index set (< the campaign's curve count), 0 when
 *  there are no more, or a negative VAFM_E* code to stop the campaign with that error (an index out of
 *  range stops it with VAFM_EINVAL). */
typedef int (*vafm_campaign_source_fn)(void *user, uint64_t *index);

/** The most indices a campaign with this spec takes ahead of the one it delivers next (its worker threads
 *  times the curves each keeps in flight, plus slack). A source that waits for delivery before handing
 *  out more (an MPI dispenser bounding its reorder buffer) must allow at least this many, or the campaign
 *  may wait on it forever. */
VAFM_API size_t vafm_campaign_window(const vafm_params *base, const vafm_campaign_spec *spec);

/** vafm_campaign_run over the indices `source` hands out (first_curve is then ignored). The curves
 *  reach fn in the order the source handed out their indices, never concurrently; each is computed
 *  exactly as vafm_campaign_run computes it. source NULL: vafm_campaign_run.
 *  @return 0, VAFM_EABORT, the source's error, or another negative VAFM_E* code. */
VAFM_API int vafm_campaign_run_source(const vafm_params *base, const vafm_campaign_spec *spec,
                                      vafm_campaign_source_fn source, void *source_user,
                                      vafm_campaign_fn fn, void *user, vafm_error *err);

#ifdef __cplusplus
}
#endif
#endif
