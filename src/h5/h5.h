/* SPDX-License-Identifier: MIT */
/**
 * @file h5.h
 * HDF5 force-curve files in the layout of afmformats (read by afmformats, nanite and PyJibe):
 * one group per curve named "0", "1", …, with the channels as 1-D datasets and the curve metadata as
 * attributes from afmformats' fixed list. vafm's provenance (scene, grid, seed, ground truth per
 * curve) lives in root attributes, the only place the layout leaves free. The layout, units, sign
 * conventions and version policy are written down in protocol/hdf5.md.
 *
 * The writer appends curves and makes them durable with vafm_h5_writer_flush(): a process killed at
 * any moment (kill -9) leaves a file that opens and holds every curve flushed before; reopening it
 * with resume drops what came after the last flush and continues. The reader opens any file of this
 * layout, vafm's or another program's (afmformats' own exports, instrument conversions), and refuses
 * damaged or non-conforming files with an error that names the file, the object and the rule broken.
 *
 * Errors: every function returns 0 or a negative VAFM_E* code and fills an optional vafm_error
 * (err->field holds the HDF5 object path, err->message the file, the object and the rule). The library
 * never prints; HDF5's own error printing is silenced during each call and restored afterwards.
 * Objects are not thread-safe: use one writer or reader from one thread at a time.
 */
#ifndef VAFM_H5_H
#define VAFM_H5_H

#include "vafm/campaign.h"
#include "vafm/map.h"
#include "vafm/common.h"
#include "vafm/params.h"
#include "vafm/sim.h"

#ifdef __cplusplus
extern "C" {
#endif

/** vafm's own format version, stored in the root attribute "vafm format version" as "MAJOR.MINOR".
 *  A reader refuses another major version; a newer minor version only adds root attributes. */
#define VAFM_H5_FORMAT_MAJOR 1
#define VAFM_H5_FORMAT_MINOR 1
/** The minor version of a file whose curves run a segment list (vafm_h5_writer_set_segments): "1.2". Only
 *  such files get it (others stay 1.1, byte for byte): a 1.1 reader would take a list's segment 1 for the
 *  retract. */
#define VAFM_H5_FORMAT_MINOR_SEGMENTS 2
/** The minor version of a file in which curves carry their own segment lists (vafm_h5_writer_set_curve_segments:
 *  a daemon's log whose curves run different lists, or none): "1.3". Only such files get it. */
#define VAFM_H5_FORMAT_MINOR_CURVE_SEGMENTS 3
/** The most segments a file's list may hold (segment values are uint8 positions below the count). */
#define VAFM_H5_SEGMENTS_MAX 255

/** The most samples a curve (each of its channels) may have, written or read: 2^25 = 33,554,432 (a
 *  3.4 s curve at 8 MS/s has 27 M; five float64 channels of this length take 1.3 GB). A reader checks
 *  the declared length against it before reading any data (a small file of deflated zeros can declare
 *  gigabytes). */
#define VAFM_H5_MAX_SAMPLES ((uint64_t)1 << 25)

typedef struct vafm_h5_writer vafm_h5_writer;
typedef struct vafm_h5_reader vafm_h5_reader;

/** Curve metadata: the curve group's attributes. Absent values: NULL strings, NaN reals, −1 integers.
 *  On write, strings are borrowed for the call; on read, they are owned by the reader and valid until
 *  the next vafm_h5_reader_curve() call or vafm_h5_reader_destroy(). */
typedef struct vafm_h5_meta {
    const char *imaging_mode;     /**< "imaging mode": "force-distance" (write: NULL means that) */
    const char *feedback_mode;    /**< "feedback mode": "contact" or "force-modulation" */
    const char *instrument;       /**< "instrument" */
    const char *software;         /**< "software" that recorded the curve */
    const char *software_version; /**< "software version" */
    const char *date;             /**< "date": "YYYY-MM-DD" (write: NULL and stamp_time → now, UTC) */
    const char *time;             /**< "time": "HH:MM:SS" with an optional fraction, not ISO 8601 */
    const char *session_id;       /**< "session id" */
    const char *curve_id;         /**< "curve id" */
    double spring_constant_N_per_m; /**< "spring constant", N/m */
    double sensitivity_m_per_V;     /**< "sensitivity", m/V */
    double setpoint_N;              /**< "setpoint", N */
    double rate_approach_Hz;        /**< "rate approach": sample rate of the approach, Hz */
    double rate_retract_Hz;         /**< "rate retract", Hz */
    double speed_approach_m_per_s;  /**< "speed approach": piezo speed, m/s */
    double speed_retract_m_per_s;   /**< "speed retract", m/s */
    double duration_s;              /**< "duration" of the whole curve, s */
    double duration_approach_s;     /**< "duration approach", s */
    double duration_retract_s;      /**< "duration retract", s */
    double z_range_m;               /**< "z range": piezo travel, m */
    double position_x_m;            /**< "position x", m */
    double position_y_m;            /**< "position y", m */
    double grid_center_x_m;         /**< "grid center x", m */
    double grid_center_y_m;         /**< "grid center y", m */
    double grid_size_x_m;           /**< "grid size x", m */
    double grid_size_y_m;           /**< "grid size y", m */
    int64_t point_count;            /**< "point count" (write: always the datasets' length) */
    int64_t segment_count;          /**< "segment count" (2 for force-distance; a segment list's length; write:
                                         −1 in a file with a list means the list's) */
    int64_t grid_shape_x;           /**< "grid shape x", pixels */
    int64_t grid_shape_y;           /**< "grid shape y", pixels */
    int64_t grid_index_x;           /**< "grid index x" */
    int64_t grid_index_y;           /**< "grid index y" */
    uint8_t reserved[32];
} vafm_h5_meta;

/** One curve: channels (1-D, n samples each, SI) and metadata. NULL channel = absent. */
typedef struct vafm_h5_curve {
    uint64_t group;                  /**< read: the group's number (its name); write: ignored */
    size_t n;                        /**< samples per channel, ≥ 1 */
    const double *force_N;           /**< "force", N, positive repulsive (required) */
    const double *height_measured_m; /**< "height (measured)", m, decreasing toward the sample */
    const double *height_piezo_m;    /**< "height (piezo)", m, decreasing toward the sample */
    const uint8_t *segment;          /**< "segment": 0 approach, 1 retract, 2 dwell (required); a segment list's
                                          curve ("segment count" ≠ 2): the segment's position in the list */
    const double *time_s;            /**< "time", s, from 0, increasing (optional in others' files) */
    const double *tip_position_m;    /**< "tip position" = height (measured) + force / spring constant */
    vafm_h5_meta meta;
} vafm_h5_curve;

/** Ground truth of one vafm curve (a row of the root table "vafm ground truth"). */
typedef struct vafm_h5_truth {
    uint64_t point;             /**< grid point of the campaign */
    int status;                 /**< 0, or the VAFM_E* code the curve ended with */
    double T_K;                 /**< temperature of the point, K */
    double v_m_per_s;           /**< piezo speed of the point, m/s */
    double k_N_per_m;           /**< spring constant of the point, N/m */
    vafm_curve_result result;   /**< observables; result.index is the curve's number (its group) */
    /* the sample under the tip (format 1.1; NaN when read from a 1.0 file) */
    double E_star_Pa;           /**< the curve's contact modulus E*, Pa (a map's pixel: its material's) */
    double gamma_J_per_m2;      /**< the curve's JKR surface energy γ, J/m² (0 for hertz, none) */
    double surface_height_m;    /**< height of the surface above the reference plane, m (a map's topography) */
} vafm_h5_truth;

/** Provenance read back from a file. Strings are owned by the reader (valid until destroy). */
typedef struct vafm_h5_provenance {
    const char *software;         /**< root "software" */
    const char *software_version; /**< root "software version" */
    int is_vafm;                  /**< 1 if the file carries vafm's root attributes */
    int format_major, format_minor; /**< "vafm format version" (is_vafm only) */
    const char *scene_json;       /**< "vafm scene": the base scene, vafm_params_to_json() */
    const char *grid_json;        /**< "vafm grid": temperatures, speeds, spring constants, N per point; a force
                                       map's grid has the map's spec under "map" (vafm/map.h) */
    const char *created;          /**< "vafm created": UTC time the file was created, ISO 8601 */
    uint64_t seed;                /**< "vafm seed" */
    size_t truth_rows;            /**< ground-truth rows present */
    const char *segments_json;    /**< "vafm segments" (format 1.2): {"segments": [...]}, the list every curve
                                       ran; NULL: none (force-distance curves) */
    int segment_count;            /**< segments of that list, 0: none */
} vafm_h5_provenance;

/** Writer options. */
typedef struct vafm_h5_writer_opts {
    int resume;      /**< 1: open an existing vafm file, keep its complete curves, drop the rest. Default 0 */
    int overwrite;   /**< create: 1 replaces an existing file, 0 refuses it. Default 0 */
    int gzip_level;  /**< 0: no compression (default); 1–9: shuffle + deflate at that level */
    int fletcher32;  /**< 1: checksum every channel so damaged data is refused on read (default 1) */
    int stamp_time;  /**< 1: curves without date/time get the current UTC date and time (default 1) */
    int keep_intact; /**< resume: 1 refuses (VAFM_EFORMAT, naming the damaged curve) a file in which intact curves
                          follow a damaged or missing one, rather than drop them with it: for curves that cannot
                          be recomputed (a daemon's log). 0 (default): they are dropped, to be recomputed */
    uint8_t reserved[28];
} vafm_h5_writer_opts;

/** Fill o with the defaults. */
VAFM_API void vafm_h5_writer_opts_default(vafm_h5_writer_opts *o);

/** Set every field of m to "absent". */
VAFM_API void vafm_h5_meta_default(vafm_h5_meta *m);

/**
 * Create a file (or reopen one for resume, see opts->resume). A new file gets the root attributes
 * "software" = "vafm" and "software version". The path must end in ".h5".
 * @param out   receives the writer; owned by the caller (vafm_h5_writer_close / _destroy)
 * @param path  file name
 * @param opts  options, NULL for the defaults
 * @param err   optional error detail
 * @return 0, VAFM_EINVAL (bad path or options), VAFM_EIO (cannot create/open), VAFM_EACCES (the file or its
 *         directory may not be written: permission denied, read-only file system), VAFM_EFORMAT (resume of
 *         a file that is not a vafm file of a known format version; with keep_intact, intact curves follow
 *         a damaged one), VAFM_ENOMEM.
 * @note On resume, vafm_h5_writer_count() tells how many complete curves were kept; a trailing curve
 *       that was not flushed, or whose data do not read back, is removed.
 */
VAFM_API int vafm_h5_writer_open(vafm_h5_writer **out, const char *path, const vafm_h5_writer_opts *opts,
                                 vafm_error *err);

/**
 * Record vafm's provenance in the root attributes: the scene as JSON, the campaign grid, the seed and
 * the format version. Call once before the first curve of a new file. On resume, the scene and grid
 * must equal the stored ones (else VAFM_EINVAL naming the first differing field).
 * @param scene the base scene (its seed is the file's seed)
 * @param grid  the campaign grid, or NULL for a single point (curves_per_point unknown)
 * @return 0, VAFM_EINVAL, VAFM_ESTATE (curves already written), VAFM_EIO.
 */
VAFM_API int vafm_h5_writer_set_provenance(vafm_h5_writer *w, const vafm_params *scene,
                                           const vafm_campaign_spec *grid, vafm_error *err);

/**
 * Check that a scene and a grid can be recorded: their JSON texts (the root attributes "vafm scene" and
 * "vafm grid") fit the format's 64 KiB each. Call before creating or overwriting a file, so that a grid
 * too long to record leaves any file as it was (vafm_h5_writer_set_provenance would refuse it after
 * vafm_h5_writer_open had created or truncated the file).
 * @return 0, VAFM_EINVAL (naming the grid's longest list, or "scene"), VAFM_ENOMEM.
 */
VAFM_API int vafm_h5_provenance_check(const vafm_params *scene, const vafm_campaign_spec *grid, vafm_error *err);

/**
 * Check, without changing a byte of it, that `path` can be resumed with this scene and grid: a vafm file
 * of this format major version whose stored scene and grid equal them (as vafm_h5_writer_set_provenance
 * compares them). Call before vafm_h5_writer_open with resume, which may drop an unflushed tail.
 * @return 0, VAFM_EINVAL (naming the first differing field), VAFM_EFORMAT, VAFM_EIO, VAFM_ESTATE (the
 *         file is in use by another process), VAFM_ENOMEM.
 */
VAFM_API int vafm_h5_resume_check(const char *path, const vafm_params *scene, const vafm_campaign_spec *grid,
                                  vafm_error *err);
/** vafm_h5_resume_check for a run of a segment list: segments_json as vafm_h5_writer_set_segments takes it
 *  (NULL: none; vafm_h5_resume_check passes NULL) must equal the file's "vafm segments". Same returns. */
VAFM_API int vafm_h5_resume_check_segments(const char *path, const vafm_params *scene,
                                           const vafm_campaign_spec *grid, const char *segments_json,
                                           vafm_error *err);

/**
 * Record that every curve of the file runs one segment list (vafm/segments.h): the root attribute
 * "vafm segments" = json, a JSON object {"segments": [...]} of 1 to VAFM_H5_SEGMENTS_MAX objects (the
 * recorder writes vafm_segments_to_json's text), and format version 1.2. Each curve then has "segment
 * count" = the list's length and segment values below it (afmformats' multi-segment convention, hdf5.md
 * "Segments"). Call before vafm_h5_writer_set_provenance and the first curve. On resume, json must equal the
 * file's list (a file with a list can only be resumed with it, one without only without).
 * @return 0, VAFM_EINVAL (not such a text; on resume another list, or a file without one), VAFM_ESTATE
 *         (provenance or curves already written), VAFM_EIO.
 */
VAFM_API int vafm_h5_writer_set_segments(vafm_h5_writer *w, const char *json, vafm_error *err);

/**
 * The segment list of the next appended curve alone (format 1.3, hdf5.md V7): json as
 * vafm_h5_writer_set_segments takes it, or NULL (the default) for a force-distance curve. The next
 * vafm_h5_writer_append, whatever it returns, uses it and clears it. That append writes the root attribute
 * "vafm segments <group>" = json with the group (the same flush makes both durable), gives the curve
 * "segment count" = the list's length, and, for the file's first such curve, sets the format version to 1.3;
 * a file whose curves carry no list stays 1.1, byte for byte. Not for a file with one list for every curve.
 * @return 0, VAFM_EINVAL (not such a text), VAFM_ESTATE (the file has one list for every curve), VAFM_ENOMEM.
 */
VAFM_API int vafm_h5_writer_set_curve_segments(vafm_h5_writer *w, const char *json, vafm_error *err);

/**
 * Append one curve as group "<count>". The curve is checked against the layout first (lengths,
 * segment values, time from 0 and increasing, tip position convention, date/time formats); "point
 * count" is set to n. In a file with provenance, truth is required and truth->result.index must equal
 * the group number. Data are written to the file at once; vafm_h5_writer_flush() makes them durable.
 * @return 0, VAFM_EINVAL (curve violates the layout; nothing is written), VAFM_EIO, VAFM_ENOMEM.
 */
VAFM_API int vafm_h5_writer_append(vafm_h5_writer *w, const vafm_h5_curve *c, const vafm_h5_truth *truth,
                                   vafm_error *err);

/**
 * Set a free root attribute (hdf5.md L3): a scalar string named "vafm ..." other than vafm's provenance
 * attributes (vafmd's log keeps its fault record in "vafm faults"). Replaces an earlier value; durable
 * at the next flush.
 * @return 0, VAFM_EINVAL (no writer, or a name that is not free), VAFM_EIO.
 */
VAFM_API int vafm_h5_writer_set_note(vafm_h5_writer *w, const char *name, const char *text, vafm_error *err);

/** Write pending ground-truth rows and flush the file to the operating system (H5Fflush). After it
 *  returns, a killed process leaves every curve appended so far readable. @return 0 or VAFM_EIO. */
VAFM_API int vafm_h5_writer_flush(vafm_h5_writer *w, vafm_error *err);

/** @return the number of curves in the file (kept on resume + appended). */
VAFM_API uint64_t vafm_h5_writer_count(const vafm_h5_writer *w);

/** Ground truth of curve group `curve` as the writer holds it (rows kept on resume and appended).
 *  @return 0, VAFM_EINVAL, or VAFM_ENOTFOUND (no row: a file without provenance, or beyond the count). */
VAFM_API int vafm_h5_writer_truth(const vafm_h5_writer *w, uint64_t curve, vafm_h5_truth *out);

/** Merge the ground-truth rows into the single root attribute "vafm ground truth", flush and close.
 *  *w is destroyed and set to NULL even on error. NULL-safe. @return 0 or VAFM_EIO. */
VAFM_API int vafm_h5_writer_close(vafm_h5_writer **w, vafm_error *err);

/** Close without merging the ground-truth parts (what a crash leaves; for tests and emergencies).
 *  NULL-safe; sets *w to NULL. */
VAFM_API void vafm_h5_writer_destroy(vafm_h5_writer **w);

/**
 * Open a file for reading. The file must follow the layout: root attributes "software" and "software
 * version", only curve groups at the root; curve groups are checked when read.
 * @param out receives the reader; owned by the caller (vafm_h5_reader_destroy)
 * @return 0, VAFM_EIO (cannot open), VAFM_EFORMAT (not HDF5, damaged, or not this layout), VAFM_ENOMEM.
 */
VAFM_API int vafm_h5_reader_open(vafm_h5_reader **out, const char *path, vafm_error *err);

/** Destroy a reader; NULL-safe; sets *r to NULL. */
VAFM_API void vafm_h5_reader_destroy(vafm_h5_reader **r);

/** @return the number of curve groups. */
VAFM_API size_t vafm_h5_reader_count(const vafm_h5_reader *r);

/**
 * Read curve i (0 ≤ i < count, in the order of the group numbers). Channel arrays and metadata
 * strings belong to the reader and stay valid until the next call or destroy.
 * @return 0, VAFM_EINVAL (i out of range), VAFM_EFORMAT (the group breaks the layout or its data are
 *         damaged: err names the object and the rule), VAFM_ENOTSUP (imaging mode other than
 *         force-distance), VAFM_ENOMEM.
 */
VAFM_API int vafm_h5_reader_curve(vafm_h5_reader *r, size_t i, vafm_h5_curve *out, vafm_error *err);

/** @return the group number (name) of curve i (0 ≤ i < count), or UINT64_MAX outside. Curves are
 *  addressed by group number everywhere users see them (vafm export --curve, replay selections); a file
 *  may number its groups with gaps or not from 0 (afmformats' exports do). */
VAFM_API uint64_t vafm_h5_reader_group(const vafm_h5_reader *r, size_t i);

/** The position i of group number `group`. @return 0, or VAFM_ENOTFOUND (no such group), VAFM_EINVAL. */
VAFM_API int vafm_h5_reader_find(const vafm_h5_reader *r, uint64_t group, size_t *i);

/** Curve i's metadata and length (out->n) without reading its data (channel pointers stay NULL): what a
 *  caller checks against its own limits before vafm_h5_reader_curve. Same returns as that. */
VAFM_API int vafm_h5_reader_curve_info(vafm_h5_reader *r, size_t i, vafm_h5_curve *out, vafm_error *err);

/** Provenance of the file (strings owned by the reader). @return 0. */
VAFM_API int vafm_h5_reader_provenance(const vafm_h5_reader *r, vafm_h5_provenance *out);

/**
 * The segment list curve i ran: {"segments": [...]} (format 1.2: the file's one list; format 1.3: the root
 * attribute "vafm segments <group>" of its group), or *json NULL for a force-distance curve. *json is owned
 * by the reader, valid until the next call of this function or destroy.
 * @return 0, VAFM_EINVAL (i out of range), VAFM_EFORMAT (the attribute is not a segment list: err names it;
 *         vafm_h5_check compares its length with the curve's "segment count"), VAFM_ENOMEM.
 */
VAFM_API int vafm_h5_reader_curve_segments(vafm_h5_reader *r, size_t i, const char **json, vafm_error *err);

/** Ground truth of curve number `curve`. @return 0, or VAFM_ENOTFOUND (no row for it). */
VAFM_API int vafm_h5_reader_truth(const vafm_h5_reader *r, uint64_t curve, vafm_h5_truth *out);

/**
 * Conformance check: every rule of protocol/hdf5.md, on the raw HDF5 objects (independent of the
 * reader's leniency). Rules L* apply to every file; rules V* to files that carry vafm's provenance.
 * @return 0 if the file conforms, else VAFM_EFORMAT (or VAFM_EIO) with err naming the first violation:
 *         "[rule] file: object: what is wrong".
 */
VAFM_API int vafm_h5_check(const char *path, vafm_error *err);

/**
 * A measured map to use as a virtual sample (vafm/map.h, pattern grid): the 2-D float datasets E_star_Pa,
 * gamma_J_per_m2 and height_m at the root (at least one; each [ny][nx], 2 to 65536 points a side, at most 2^24,
 * every value finite and in the scene's range) and the root attributes x0_m, y0_m (point (0, 0)) and dx_m,
 * dy_m (spacing, (0, 1e-2] m); protocol/hdf5.md, "Map grids". @return 0 with *out (free it with
 * vafm_h5_map_grid_free), or VAFM_EFORMAT / VAFM_EIO / VAFM_ENOMEM with err naming the dataset or attribute.
 */
VAFM_API int vafm_h5_map_grid_load(const char *path, vafm_map_grid **out, vafm_error *err);
VAFM_API void vafm_h5_map_grid_free(vafm_map_grid **g);

#ifdef __cplusplus
}
#endif
#endif
