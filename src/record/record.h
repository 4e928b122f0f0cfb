/* SPDX-License-Identifier: MIT */
/**
 * @file record.h
 * The recorder: finished force curves into an HDF5 file of protocol/hdf5.md, for every program that
 * records (`vafm campaign`, `vafm study`, `vafm listen`, vafmd's log). It opens the file (create,
 * resume or overwrite: the lock rules are the writer's, h5/h5.h), records the provenance once,
 * appends each curve with its ground-truth row, ids and calibration by one rule, and makes curves
 * durable either after every curve or on a timer from its own flusher thread (a kill -9 at any moment
 * loses at most the curves of the last interval; resume recomputes exactly those).
 *
 * Ids, one rule for every program: "session id" is "seed S" (S the scene's seed); "curve id" is
 * "index I" (I the curve's random stream index), preceded by "run R " for a daemon run and followed by
 * " client C" for a client's run id. (seed, index) reproduces the curve.
 *
 * Thread safety: one recorder may be used from several threads; its calls are serialised inside.
 * The library never prints; errors are VAFM_E* codes with a vafm_error naming the file and the cause.
 */
#ifndef VAFM_RECORD_H
#define VAFM_RECORD_H

#include "vafm/campaign.h"
#include "vafm/common.h"
#include "h5/h5.h"
#include "vafm/map.h"
#include "vafm/params.h"
#include "vafm/segments.h"
#include "vafm/sim.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct vafm_recorder vafm_recorder;

/** How the file is opened. */
typedef enum vafm_record_mode {
    VAFM_RECORD_CREATE = 0,    /**< a new file; an existing one is refused */
    VAFM_RECORD_RESUME = 1,    /**< continue an existing vafm file with the same scene and grid */
    VAFM_RECORD_OVERWRITE = 2, /**< replace an existing file (never one another process writes) */
} vafm_record_mode;

/** The longest flush interval accepted, s. */
#define VAFM_RECORD_MAX_FLUSH_INTERVAL_S 86400.0

/** Recorder options. */
typedef struct vafm_recorder_opts {
    int mode;                /**< vafm_record_mode (default VAFM_RECORD_CREATE) */
    int gzip_level;          /**< 0: no compression (default); 1–9 shuffle + deflate */
    double flush_interval_s; /**< 0 (default): durable after every curve; (0, 86400]: a flusher thread
                                  flushes this long after the previous flush whenever curves wait */
    /** Called from the thread that made them durable, after each successful flush, with the number of
     *  curves now durable in the file (NULL: none). Must not call back into the recorder. */
    void (*on_durable)(void *user, uint64_t curves);
    void *user;              /**< for on_durable */
    int keep_intact;         /**< resume: vafm_h5_writer_opts.keep_intact (default 0) */
    /** Every curve runs this segment list (vafm_segments_to_json's text; NULL, the default: force-distance
     *  curves): the file gets it as "vafm segments" and format 1.2 (vafm_h5_writer_set_segments), each curve
     *  "segment count" = its length and no approach/retract attributes (rates, speeds, durations, setpoint:
     *  the list has each segment's own). A resume needs the file's list. Borrowed for vafm_recorder_open. */
    const char *segments_json;
    uint8_t reserved[16];
} vafm_recorder_opts;

/** Fill o with the defaults. */
VAFM_API void vafm_recorder_opts_default(vafm_recorder_opts *o);

/**
 * Open a file and record (new file) or compare (resume) the provenance.
 * @param scene the base scene, or NULL to take the first appended curve's scene as the file's
 * @param grid  the campaign grid, or NULL for single curves
 * @return 0, VAFM_EINVAL (options, or on resume a scene or grid other than the file's), VAFM_EIO,
 *         VAFM_EACCES (may not be written), VAFM_EFORMAT, VAFM_ESTATE (the file is in use by another
 *         writer), VAFM_ENOMEM.
 */
VAFM_API int vafm_recorder_open(vafm_recorder **out, const char *path, const vafm_recorder_opts *opts,
                                const vafm_params *scene, const vafm_campaign_spec *grid, vafm_error *err);

/** One finished curve to record. */
typedef struct vafm_record_curve {
    const vafm_samples *samples;    /**< its samples (n ≥ 1) */
    const vafm_params *params;      /**< its scene */
    const vafm_curve_result *result;/**< its observables; result->index is its random stream index */
    uint64_t point;                 /**< its campaign grid point (0 for single curves) */
    uint64_t run_id;                /**< a daemon's run number, 0: none */
    const char *client_run_id;      /**< a client's name for the run, NULL: none */
    double sensitivity_m_per_V;     /**< deflection sensitivity (InvOLS), m/V; NaN: not recorded */
    int measured_force;             /**< 1: force is a measured (noisy, quantised) signal, so the file gets
                                         no "tip position" = height + force/k column (hdf5.md L14) */
    const vafm_map_spec *map;       /**< a force map (vafm/map.h), with pixel; NULL: not a map curve */
    const vafm_map_truth *pixel;    /**< the curve's pixel: its indices and position, with the map's shape, centre
                                         and size, become afmformats' map attributes ("grid index x", "position x",
                                         ...); its E*, γ and surface height are the scene's (params) */
    const char *segments_json;      /**< the segment list this curve ran (vafm_segments_to_json's text), in a file
                                         without one list for every curve (opts.segments_json NULL); NULL: a
                                         force-distance curve. The file gets it as "vafm segments <group>" and
                                         format 1.3 (vafm_h5_writer_set_curve_segments), the curve "segment count"
                                         = its length and no approach/retract attributes. Borrowed for the call */
} vafm_record_curve;

/** Append one curve as the next group, with its ground truth; durable after the call when the flush
 *  interval is 0. A flusher's earlier error is returned here (and every call after it).
 *  @return 0, VAFM_EINVAL (the curve breaks the layout), VAFM_EIO, VAFM_ENOMEM. */
VAFM_API int vafm_recorder_append(vafm_recorder *r, const vafm_record_curve *c, vafm_error *err);

/** Make every appended curve durable now. @return 0 or VAFM_EIO. */
VAFM_API int vafm_recorder_flush(vafm_recorder *r, vafm_error *err);

/** Set a free root attribute of the file (a string named "vafm ...", vafm_h5_writer_set_note), durable
 *  with the next flush (the next append's, or the close's). @return 0, VAFM_EINVAL, VAFM_EIO. */
VAFM_API int vafm_recorder_set_note(vafm_recorder *r, const char *name, const char *text, vafm_error *err);

/** @return curves in the file: kept on resume + appended. */
VAFM_API uint64_t vafm_recorder_count(vafm_recorder *r);

/** Ground-truth row of curve group i (kept on resume or appended). @return 0 or VAFM_ENOTFOUND. */
VAFM_API int vafm_recorder_truth(vafm_recorder *r, uint64_t i, vafm_h5_truth *out);

/** What the recorder did (for summaries). */
typedef struct vafm_recorder_report {
    uint64_t kept;     /**< curves found in the file on resume */
    uint64_t appended; /**< curves appended */
    uint64_t flushes;  /**< flushes made, the one at close included */
    double writer_s;   /**< wall time spent inside the HDF5 writer (open, append, flush, close), s */
} vafm_recorder_report;

/** @return the report so far (safe at any time). */
VAFM_API void vafm_recorder_report_get(vafm_recorder *r, vafm_recorder_report *out);

/** Stop the flusher, merge the ground truth, flush and close. *r is destroyed and set to NULL even on
 *  error; NULL-safe. rep (may be NULL) receives the final report. @return 0, or the first error of the
 *  recorder's life that was not returned yet, or the close's. */
VAFM_API int vafm_recorder_close(vafm_recorder **r, vafm_recorder_report *rep, vafm_error *err);

/** The ids of protocol/hdf5.md's rule into buffers: session "seed S", curve "[run R ]index I[ client C]".
 *  run_id 0 and client NULL or "" leave those parts out. */
VAFM_API void vafm_record_ids(uint64_t seed, uint64_t index, uint64_t run_id, const char *client,
                              char *session, size_t session_len, char *curve, size_t curve_len);

/* ---- a simulated curve as a file's curve and row (from_sim.c) ---------------------------------- */

/**
 * Fill a curve from a simulated force curve: channels from the samples (height (measured) = height
 * (piezo) = the piezo height, tip position = vafm's true tip height = height + force/k), metadata from
 * the scene and the result (spring constant, setpoint, rates, speeds, durations, z range, segment
 * count, software). The arrays are borrowed from s; date, time, session id and curve id stay absent.
 */
VAFM_API void vafm_h5_curve_from_sim(vafm_h5_curve *c, const vafm_samples *s, const vafm_params *p,
                                     const vafm_curve_result *r);

/** Fill a ground-truth row for a simulated curve: grid point `point`, the scene's T, retract speed,
 *  spring constant, E*, γ and surface height, the curve result (status 0). result.index stays the curve's stream index: a writer
 *  that numbers rows by group sets it afterwards. */
VAFM_API void vafm_h5_truth_from_sim(vafm_h5_truth *t, uint64_t point, const vafm_params *p,
                                     const vafm_curve_result *r);

/** Parse a segment list from JSON text ({"segments": [...]} or a bare array; docs/instrument.md, "Segments")
 *  into out (at most cap segments); *n receives the count. Only the syntax is checked here (names, types,
 *  unknown keys, refused with err->field "segments[i].key"); vafm_segments_validate checks the values against
 *  a scene. @return 0 or VAFM_EINVAL. */
VAFM_API int vafm_segments_from_json(const char *text, vafm_segment_spec *out, size_t cap, size_t *n, vafm_error *err);
/** vafm_segments_from_json on a file's text (at most 1 MiB; err->message names the file). @return as it, or
 *  VAFM_ENOMEM. */
/** The list as the text vafm_segments_from_json reads back to the same specs: {"segments": [...]} with every
 *  field of every segment (defaults included; hold_force_N NaN as null), reals to 17 digits. The recorder
 *  stores it in a file ("vafm segments", protocol/hdf5.md). @return the text (free() it), or NULL (n out of
 *  [1, VAFM_SEGMENTS_MAX], a value not finite, out of memory). */
VAFM_API char *vafm_segments_to_json(const vafm_segment_spec *segs, size_t n);
VAFM_API int vafm_segments_load_file(const char *path, vafm_segment_spec *out, size_t cap, size_t *n, vafm_error *err);

#ifdef __cplusplus
}
#endif
#endif
