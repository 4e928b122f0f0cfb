/* SPDX-License-Identifier: MIT */
/*
 * HDF5 force-curve files: what the writer, the reader and the conformance checker share.
 *
 * Layout (protocol/hdf5.md): afmformats' HDF5 export. Root attributes "software" and "software
 * version"; one group per curve named "0", "1", …; in each group 1-D datasets (force, height
 * (measured), height (piezo), segment, time, tip position) with a string attribute "unit", and the
 * curve metadata as scalar attributes whose names come from afmformats' fixed list (s_keys below).
 * afmformats' reader builds its metadata dictionary from the group attributes and raises on any name
 * it does not know; it reads strings through h5py, which returns variable-length strings as text and
 * fixed-length ones as bytes (then "imaging mode" never equals "force-distance" and the file is not
 * detected). So every string vafm writes is a scalar variable-length UTF-8 string, like h5py's.
 *
 * Durability. HDF5 has no journal and SWMR forbids creating groups, so vafm adds one underneath:
 *  - the file format is pinned to the 1.8 format (libver bounds V18..V18): checksummed superblock v2,
 *    object headers and dense link/attribute storage, so damage is detected, and no superblock-v3
 *    "file is open for write" flag that would lock a killed file until h5clear;
 *  - a journaling file driver (h5_journal.c) makes each H5Fflush atomic for a killed process: writes
 *    into the last flushed state are buffered, journaled at the end of the file, applied, and the
 *    journal cut off; a complete journal left by a kill is replayed when vafm opens the file;
 *  - the ground truth of the curves appended since the last flush goes into one new root attribute
 *    ("vafm ground truth from <first>") in the same flush, so a curve counts as complete only with its
 *    row. Resume keeps the longest prefix 0..c−1 of groups that pass the layout check and have a row
 *    (the last two are read back through their Fletcher-32 checksums), deletes the rest and merges the
 *    rows into "vafm ground truth"; a clean close merges them too.
 * Damage HDF5 1.10 does not catch by itself (global heap, v1 chunk index) is caught before HDF5 trips
 * over it (vafm_h5i_gheap_check, vafm_h5i_storage_complete).
 */
#ifndef VAFM_H5_INTERNAL_H
#define VAFM_H5_INTERNAL_H

#include <hdf5.h>
#include <stdarg.h>
#include <stdint.h>

#include "h5/h5.h"

#if defined(__GNUC__)
#define VAFM_H5_PRINTF(a, b) __attribute__((format(printf, a, b)))
#else
#define VAFM_H5_PRINTF(a, b)
#endif

/* Root attribute names of vafm's provenance. */
#define VAFM_H5I_A_FORMAT "vafm format version"
#define VAFM_H5I_A_SCENE "vafm scene"
#define VAFM_H5I_A_GRID "vafm grid"
#define VAFM_H5I_A_SEED "vafm seed"
#define VAFM_H5I_A_CREATED "vafm created"
#define VAFM_H5I_A_SEGMENTS "vafm segments" /* format 1.2: the segment list of every curve */
#define VAFM_H5I_A_CURVE_SEGMENTS "vafm segments " /* + group: format 1.3, that curve's own list */
#define VAFM_H5I_A_TRUTH "vafm ground truth"           /* merged table */
#define VAFM_H5I_A_TRUTH_PART "vafm ground truth from " /* + first curve: rows of one flush */

/* ---- curve-group attributes: afmformats' list ---------------------------------------------------- */

enum { VAFM_H5I_STR = 0, VAFM_H5I_REAL = 1, VAFM_H5I_INT = 2 };

typedef struct vafm_h5i_key {
    const char *name; /* attribute name */
    int kind;         /* VAFM_H5I_STR / REAL / INT */
    size_t offset;    /* of the field in vafm_h5_meta */
    const char *unit; /* SI unit, for messages */
} vafm_h5i_key;

extern const vafm_h5i_key vafm_h5i_keys[];
extern const int vafm_h5i_nkeys;

/** @return the key named `name`, or NULL. */
const vafm_h5i_key *vafm_h5i_key_find(const char *name);

/** Keys afmformats knows but the list leaves out ("enum", "path", "format"): afmformats' own
 *  exporter writes "enum" and "path". The reader ignores them; the checker and the writer refuse them.
 *  @return 1 if tolerated. */
int vafm_h5i_key_tolerated(const char *name);

/* ---- channels ------------------------------------------------------------------------------------- */

typedef struct vafm_h5i_chan {
    const char *name; /* dataset name */
    const char *unit; /* value of its "unit" attribute */
    int is_segment;   /* 1: uint8 segment labels, 0: float64 */
    size_t offset;    /* of the pointer in vafm_h5_curve */
} vafm_h5i_chan;

#define VAFM_H5I_NCHAN 6
extern const vafm_h5i_chan vafm_h5i_chans[VAFM_H5I_NCHAN];
enum { VAFM_H5I_FORCE = 0, VAFM_H5I_HMEAS, VAFM_H5I_HPIEZO, VAFM_H5I_SEGMENT, VAFM_H5I_TIME, VAFM_H5I_TIP };

/** @return the channel index of dataset `name`, or −1. */
int vafm_h5i_chan_find(const char *name);

/* ---- ground-truth rows ---------------------------------------------------------------------------- */

typedef struct vafm_h5i_row {
    uint64_t curve, point;
    int32_t status, flags;
    double T_K, v_m_per_s, k_N_per_m;
    double pulloff_sampled_N, pulloff_spring_N, detach_force_N, detach_height_m, detach_eq_force_N;
    double detach_time_s, touch_time_s, touch_height_m, retract_start_s, duration_s;
    uint64_t samples, steps, steps_contact, steps_free;
    double E_star_Pa, gamma_J_per_m2, surface_height_m; /* format 1.1 */
} vafm_h5i_row;

/** Compound type of a row: file = 1 (little-endian, packed) or 0 (native, for memory). Caller closes. */
hid_t vafm_h5i_row_type(int file);
void vafm_h5i_row_from_truth(vafm_h5i_row *row, uint64_t curve, const vafm_h5_truth *t);
void vafm_h5i_truth_from_row(vafm_h5_truth *t, const vafm_h5i_row *row);

/** Number of fields of the row type, and field i's name (for the checker). */
int vafm_h5i_row_nfields(void);
/** Number of fields a row of format 1.minor has (1.0: the first 21). */
int vafm_h5i_row_nfields_of(int minor);
/** Set the fields a row of format 1.minor lacks to NaN. */
void vafm_h5i_row_absent(vafm_h5i_row *row, int minor);
const char *vafm_h5i_row_field(int i);

/* ---- HDF5 error handling -------------------------------------------------------------------------- */

/** Silence HDF5's automatic error printing for one public call (the library never prints). */
typedef struct vafm_h5i_quiet {
    H5E_auto2_t fn;
    void *data;
} vafm_h5i_quiet;
void vafm_h5i_quiet_begin(vafm_h5i_quiet *q);
void vafm_h5i_quiet_end(const vafm_h5i_quiet *q);

/** Close each id of ids[0..n) that is open (>= 0) with the close call of its kind (attribute, dataspace,
 *  datatype, dataset, group, property list, file), in order; the ids of a function's way out. */
void vafm_h5i_close_ids(const hid_t *ids, size_t n);
#define VAFM_H5I_CLOSE(...)                                                                               \
    vafm_h5i_close_ids((const hid_t[]){__VA_ARGS__}, sizeof((const hid_t[]){__VA_ARGS__}) / sizeof(hid_t))

/** Fill err: code, object path (err->field) and message. */
void vafm_h5i_err(vafm_error *err, int code, const char *object, const char *fmt, ...) VAFM_H5_PRINTF(4, 5);
/** The innermost message on HDF5's error stack into buf (unchanged when the stack is empty). Take it right
 *  after the failing call: every later HDF5 call (a close on the way out) clears the stack. */
void vafm_h5i_reason(char *buf, size_t len);
/** Same as vafm_h5i_err, appending " (HDF5: <innermost message of HDF5's error stack>)". */
void vafm_h5i_err_hdf5(vafm_error *err, int code, const char *object, const char *fmt, ...)
    VAFM_H5_PRINTF(4, 5);

/* ---- the path of a file (h5_path.c) --------------------------------------------------------------- */

/** Before HDF5 opens an existing file: refuse what is not a regular file (a FIFO would block forever)
 *  with VAFM_EIO, and a file another process (or this one) has open — for writing, or at all when
 *  for_write — with VAFM_ESTATE naming the holder from /proc/locks. An absent path passes. */
int vafm_h5i_check_path(const char *path, int for_write, vafm_error *err);
/* 1 when errno en means "may not write" (EACCES, EPERM: mode or immutable; EROFS: read-only mount). */
int vafm_h5i_errno_denied(int en);
/* The words for such an errno: "the file system is mounted read-only" or "permission denied ...". */
const char *vafm_h5i_denied_why(int en);
/* A new file at path: VAFM_EACCES (naming the directory and "read-only"/"permission denied") when its directory
 * cannot be written, else 0 (other failures are left to the create). */
int vafm_h5i_check_dir_writable(const char *path, vafm_error *err);

/* ---- attributes ----------------------------------------------------------------------------------- */

/** What an attribute holds, as found in the file. */
typedef struct vafm_h5i_val {
    H5T_class_t cls;   /* H5T_STRING, H5T_INTEGER, H5T_FLOAT, or another class (refused by callers) */
    int vlen;          /* string: variable length */
    H5T_cset_t cset;   /* string: character set */
    size_t size;       /* datatype size, bytes */
    H5T_sign_t sign;   /* integer: signedness */
    H5T_order_t order; /* byte order */
    int scalar;        /* dataspace is scalar */
    hssize_t npoints;  /* elements */
    char *s;           /* string value (malloc'd, NUL-terminated) when cls == H5T_STRING and npoints == 1 */
    double d;          /* numeric value when npoints == 1 */
    int64_t i;         /* integer value (integers, and floats when integral) */
    uint64_t u;        /* unsigned integer value */
    int integral;      /* the numeric value is an integer */
} vafm_h5i_val;

/** Open attribute `name` of loc with its datatype and dataspace (the caller closes the three).
 *  @return the attribute, *t and *sp (each −1 where HDF5 failed), or −1: nothing opened, *t = *sp = −1. */
hid_t vafm_h5i_attr_open(hid_t loc, const char *name, hid_t *t, hid_t *sp);
/** Read attribute `name` of loc into v (v->s to be freed with vafm_h5i_val_free). @return 0, or −1 if
 *  HDF5 failed (absent attribute, damage); the error stays on HDF5's stack for vafm_h5i_err_hdf5. */
int vafm_h5i_attr_get(hid_t loc, const char *name, vafm_h5i_val *v);
void vafm_h5i_val_free(vafm_h5i_val *v);

/** Scalar variable-length UTF-8 string type (caller closes). */
hid_t vafm_h5i_str_type(void);
/** Write (create or replace) a scalar attribute. @return 0 or −1. */
int vafm_h5i_put_str(hid_t loc, const char *name, const char *value);
int vafm_h5i_put_f64(hid_t loc, const char *name, double value);
int vafm_h5i_put_i64(hid_t loc, const char *name, int64_t value);
int vafm_h5i_put_u64(hid_t loc, const char *name, uint64_t value);

/* ---- value rules ---------------------------------------------------------------------------------- */

/** "YYYY-MM-DD" with a plausible month and day. */
int vafm_h5i_date_ok(const char *s);
/** "HH:MM:SS" or "HH:MM:SS.f…" (afmformats' format, not ISO 8601). */
int vafm_h5i_time_ok(const char *s);
/** A syntactically valid JSON document whose top level is an object. */
int vafm_h5i_json_object_ok(const char *s);
/** Canonical curve-group name: "0" or [1-9][0-9]* below 2^63. @return 1 and *out, or 0. */
int vafm_h5i_group_name(const char *name, uint64_t *out);
/** qsort order of uint64_t (curve-group numbers). */
int vafm_h5i_u64_cmp(const void *a, const void *b);
/** The first index of ascending v[0..n) whose value is not below key (n when none). */
size_t vafm_h5i_u64_lower_bound(const uint64_t *v, size_t n, uint64_t key);

/** Channel rules shared by the writer (before writing) and the checker (after reading). Each returns
 *  NULL when the rule holds, else a static description of the rule, with *at the first bad sample. */
/* L12 with the curve's 'segment count' (−1 absent): 0/1/2 when it is absent or 2, else below it; list 1 (a
 * file with "vafm segments", V6): below it always. */
const char *vafm_h5i_rule_segment(const uint8_t *seg, size_t n, int64_t count, int list, size_t *at);
/* The number of segments of a "vafm segments" text ({"segments": [objects]}, 1 to VAFM_H5_SEGMENTS_MAX),
 * or −1 when it is not such a text. */
int vafm_h5i_segments_count(const char *s);
const char *vafm_h5i_rule_time(const double *t, size_t n, size_t *at);
const char *vafm_h5i_rule_tip(const double *tip, const double *hm, const double *f, double k, size_t n,
                              size_t *at);
const char *vafm_h5i_rule_finite(const double *x, size_t n, size_t *at);

/* ---- the journaling file driver (h5_journal.c) ----------------------------------------------------- */

/** Use the journaling driver on a file access property list (writer, reader, checker): flushes become
 *  atomic for a killed process, and a journal left by one is replayed on open. @return 0 or −1. */
int vafm_h5i_fapl_journal(hid_t fapl);

/** Overlay the pages of a complete journal left at the end of `path` (if any) on buf = file[off, off+n).
 *  *state caches the journal between calls (start with NULL); call with n == 0 to free it. */
int vafm_h5i_journal_overlay(const char *path, unsigned char *buf, uint64_t off, size_t n, void **state);

/** Test hook (tests/test_h5.c only): die at step 1–4 of the next commit (h5_journal.c). */
extern int vafm_h5i_journal_crash_at;
/** errno of the journal driver's last failed write or truncate on this thread (0: none since reset): the
 *  operating system's reason ("No space left on device") that HDF5's error stack does not carry up. */
extern _Thread_local int vafm_h5i_io_errno;

/* ---- defences against damage HDF5 1.10 does not detect ------------------------------------------- */

/**
 * Validate every global-heap collection ("GCOL") of a file before HDF5 parses one. Variable-length
 * strings live there, without a checksum, and HDF5 1.10 trusts the object sizes and indices it finds
 * (it asserts instead of checking, then copies out of bounds). The scan mirrors HDF5's parse: objects
 * must lie inside their collection, indices increase, free space comes last. Only the file's allocated
 * space (HDF5's end of allocation of the open file) is scanned: past it lie bytes of a killed writer that
 * HDF5 never reads. Cost: one pass over the file. @return 0, or −1 with a reason in why (a damaged
 * collection), or −2 (the file cannot be read).
 */
int vafm_h5i_gheap_check(hid_t file, const char *path, char *why, size_t len);

/**
 * Every element of a 1-D dataset has storage: a damaged (unchecksummed) v1 B-tree chunk index can lose
 * a chunk or clear its filter mask, and HDF5 then returns fill values or unfiltered bytes without an
 * error. @return 0 or −1.
 */
int vafm_h5i_storage_complete(hid_t d, hsize_t n);

/* "MAJOR.MINOR" of "vafm format version": decimal digits only, each at most 6 (sscanf's %d took "1.-0", " 1.+0").
 * @return 0 with *major, *minor, or -1. */
int vafm_h5i_format_parse(const char *s, int *major, int *minor);

/**
 * Why dataset d's raw data are not read, when they do not lie in the file itself: raw data in an external
 * file (H5Pset_external) or a virtual dataset's source files can name any path, a FIFO or a device among
 * them, and HDF5 opens it on the first read (a FIFO with no writer blocks forever). Called before the
 * dataset's shape or data are touched. @return NULL (the data are in the file), or a phrase to follow
 * "'name' is": "stored in an external file (not read)", ...
 */
const char *vafm_h5i_storage_foreign(hid_t d);

/* ---- the writer's state (h5_writer.c; its resume: h5_resume.c) ----------------------------------- */

struct vafm_h5_writer {
    uint32_t tag;
    char *path;
    hid_t file;
    vafm_h5_writer_opts o;
    uint64_t count;    /* curve groups in the file */
    int has_prov;      /* "vafm scene" is in the file */
    char *scene, *grid;
    vafm_h5i_row *rows; /* rows of curves 0..nrows−1 */
    size_t nrows, caprows;
    size_t rows_in_file; /* rows [0, rows_in_file) are in the file */
    int parts_in_file;   /* rows sit in flush parts: merge on close */
    char *segs;          /* "vafm segments": the file's list (set or found on resume), NULL: none */
    int nsegs;           /* its segments, 0: none */
    int segs_given;      /* the caller gave the list (vafm_h5_writer_set_segments) */
    int minor;           /* the file's format minor version as written now */
    char *cseg;          /* the next curve's own list (vafm_h5_writer_set_curve_segments), NULL: none */
    int ncseg;           /* its segments, 0: none */
};

/** The file access properties of every file the writer opens: the 1.8 format, strong close, the journal. */
hid_t vafm_h5i_writer_fapl(void);
/** Room for n ground-truth rows in w->rows. @return 0, or -1 out of memory. */
int vafm_h5i_writer_rows_reserve(vafm_h5_writer *w, size_t n);
/** Replace every ground-truth attribute by one merged table. @return 0, or -1. */
int vafm_h5i_writer_merge_rows(vafm_h5_writer *w);
/** Open w->path for resume (w->o.resume): keep the complete prefix, drop the rest, merge the rows. */
int vafm_h5i_writer_resume(vafm_h5_writer *w, vafm_error *err);

/* ---- reading one curve group (reader, writer's resume) -------------------------------------------- */

/** Storage behind a vafm_h5_curve that was read. */
typedef struct vafm_h5i_curvebuf {
    double *d[VAFM_H5I_NCHAN];
    uint8_t *seg;
    size_t cap[VAFM_H5I_NCHAN];
    char *str[16];
    int nstr;
} vafm_h5i_curvebuf;
void vafm_h5i_curvebuf_free(vafm_h5i_curvebuf *b);

/**
 * Read curve group `group` of an open file (the reader's lenient rules, protocol/hdf5.md). With
 * read_data 0, only the structure, attributes and dataset shapes are checked (no channel arrays).
 * file_size bounds the dataset lengths a damaged file could claim. @return 0 or VAFM_E* with err.
 */
int vafm_h5i_curve_read(hid_t file, const char *path, uint64_t group, int read_data, uint64_t file_size,
                        vafm_h5i_curvebuf *buf, vafm_h5_curve *out, vafm_error *err);

/** Read every ground-truth row of the root (merged table and parts) into a malloc'd array sorted by
 *  curve. Parts that cannot be read are skipped if skip_damaged, else refused. @return 0 or VAFM_E*. */
int vafm_h5i_rows_read(hid_t file, const char *path, int skip_damaged, vafm_h5i_row **rows, size_t *n,
                       vafm_error *err);

/** Names of the root's ground-truth attributes (merged and parts), malloc'd; caller frees each and
 *  the array. @return 0 or −1. */
int vafm_h5i_truth_attr_names(hid_t file, char ***names, size_t *n);

/** A growing list of names (links or attributes of an object), filled by H5Literate/H5Aiterate2
 *  through vafm_h5i_link_cb / vafm_h5i_attr_cb. A soft or external link is remembered in bad/bad_name. */
typedef struct vafm_h5i_names {
    char **v;
    size_t n, cap;
    int bad;           /* a soft or external link was seen */
    char bad_name[64]; /* the first such link */
} vafm_h5i_names;

void vafm_h5i_names_free(vafm_h5i_names *l);
int vafm_h5i_names_push(vafm_h5i_names *l, const char *name);
herr_t vafm_h5i_link_cb(hid_t g, const char *name, const H5L_info_t *info, void *data);
herr_t vafm_h5i_attr_cb(hid_t loc, const char *name, const H5A_info_t *info, void *data);

#endif
