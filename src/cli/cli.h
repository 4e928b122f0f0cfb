/* SPDX-License-Identifier: MIT */
/*
 * The `vafm` command-line tool's own internals, shared by its command files. vafm.c holds the one command
 * table (every subcommand, those with the common option parser and those that parse their own
 * arguments), the option parser, help and main; each subcommand lives in a cmd_*.c of its own
 * (cmd_run.c: run, samples; cmd_campaign.c: curves, campaign; cmd_file.c: info, export; cmd_params.c:
 * params, presets, integrators; cmd_client.c, cmd_replay.c, cmd_study.c, cmd_theory.c); cli_common.c
 * has what several of them print or parse. The library does the work (include/vafm); this layer keeps only
 * words and I/O.
 *
 * Exit status: 0 success, 1 runtime error (a curve failed, I/O, a damaged file), 2 usage or parameter
 * error. Every parameter error repeats the library's vafm_error message, which names the field, value
 * and range.
 */
#ifndef VAFM_CLI_CLI_H
#define VAFM_CLI_CLI_H

#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <time.h>
#include <unistd.h>
#include "vafm/campaign.h"
#include "vafm/detector.h"
#include "vafm/common.h"
#include "vafm/contact.h"
#include "h5/h5.h"
#include "record/record.h"
#include "vafm/stats.h"
#include "vafm/integrator.h"
#include "vafm/map.h"
#include "vafm/params.h"
#include "vafm/sim.h"
#include "vafm/theory.h"
#include "cli/campaign_mpi.h"
#include "vafm/units.h"
#include "vafm/version.h"
#include "record/scene.h"

enum { VAFM_CLI_EXIT_OK = 0, VAFM_CLI_EXIT_RUNTIME = 1, VAFM_CLI_EXIT_USAGE = 2 };

#define VAFM_CLI_DEFAULT_PRESET VAFM_TOOLS_DEFAULT_PRESET
#define VAFM_CLI_PROGRESS_PERIOD_S 0.5
#define VAFM_CLI_CHUNK_SAMPLES 64 /* samples per vafm_sim_advance call: progress granularity of one curve */
#define VAFM_CLI_MAX_TOTAL_CURVES 1000000000000000ULL
#define VAFM_CLI_STR_(x) #x
#define VAFM_CLI_XSTR(x) VAFM_CLI_STR_(x) /* a numeric macro's value as a string literal (help texts) */
#define VAFM_CLI_MAX_POINTS 65536 /* grid points of curves and campaign (--T x --v x --k) */
#define VAFM_CLI_MAX_CURVE_ERRORS 20 /* vafm info names at most this many unreadable curves */

enum vafm_cli_opt {
    O_HELP, O_VERSION, O_QUIET, O_PROGRESS, O_PRESET, O_SCENE, O_INDEX, O_N, O_THREADS, O_FIRST, O_CSV,
    O_T, O_V, O_K, O_JSON, O_TUNE, O_OUT, O_RESUME, O_OVERWRITE, O_FLUSH, O_GZIP, O_CURVE, O_MPI,
    O_NX, O_NY, O_SIZE, O_PATTERN, O_PPARAM, O_SAMPLE, O_KERNEL, O_SEGMENTS, VAFM_CLI_NOPT
};

typedef struct vafm_cli_override {
    char name[64];
    char opt[72]; /* the option as typed, for messages: --speed, --v, --v_approach_m_per_s */
    const char *value;
    int axis; /* 1 + O_T, O_V or O_K when that option set it (dropped where the option is a grid axis), else 0 */
} vafm_cli_override;

typedef struct vafm_cli_command vafm_cli_command;

typedef struct vafm_cli_args {
    const vafm_cli_command *cmd;    /* the command (NULL until named) */
    int explicit_cmd;        /* the command was named (bare `vafm` runs, `vafm --help` is the full usage) */
    int on[VAFM_CLI_NOPT];          /* option given */
    const char *val[VAFM_CLI_NOPT]; /* its value */
    vafm_cli_override *ov;          /* parameter overrides, in order */
    int n_ov;
    const char *topic;       /* `vafm help TOPIC` */
    const char *file;        /* the FILE of `vafm info` and `vafm export` */
} vafm_cli_args;

struct vafm_cli_command {
    const char *name;
    int (*fn)(const vafm_cli_args *a);
    unsigned opts;       /* options it accepts (M(O_*) bits) */
    int scene;           /* 1: takes scene options and parameter overrides */
    const char *summary; /* one line for the command list */
    const char *usage;   /* synopsis and option lines */
    int file;            /* 1: takes one FILE argument */
    /* a command that parses its own arguments (network clients, studies, replay): main-like, argv[0] its
     * name, returns the exit status and prints its own --help; fn and opts are unused then */
    int (*main)(int argc, char **argv);
};

typedef struct vafm_cli_scene {
    vafm_params p;
    char preset[64]; /* the preset the scene started from */
    const char *file;
    const vafm_cli_override *ov;
    int n_ov;
} vafm_cli_scene;


typedef struct vafm_cli_progress {
    int on, tty, printed;
    double t0, last;
} vafm_cli_progress;


#if defined(__GNUC__)
#define VAFM_CLI_PRINTF(a, b) __attribute__((format(printf, a, b)))
#else
#define VAFM_CLI_PRINTF(a, b)
#endif

/* recording a campaign into one HDF5 file (cli_common.c; vafm campaign, vafm map) */
typedef struct vafm_cli_rec {
    vafm_recorder *rec;
    double *mdefl, *mforce, *mheight; /* measured deflection, force and height of the curve being recorded */
    size_t mcap;
    int werr_code; /* the first recorder error */
    vafm_error werr;
    vafm_cli_progress pg; /* the fields below belong to the delivering worker */
    uint64_t done, total;
    int fail_status;
    uint64_t fail_index;
    const vafm_map_spec *map; /* a force map: its curves get the pixel's map attributes (NULL: none) */
    const vafm_params *base;  /* the map's base scene */
} vafm_cli_rec;

typedef struct vafm_cli_rec_opts {
    const char *out;
    int resume, overwrite, gzip;
    double interval;
    double mb_before; /* size of the file continued by --resume */
} vafm_cli_rec_opts;

/* "done/total curves, rate, ETA" on the progress line, when one is due */
void vafm_cli_progress_curves(vafm_cli_progress *pg, uint64_t done, uint64_t total);
/* --out, --resume, --overwrite, --flush-interval, --gzip */
int vafm_cli_rec_parse(const vafm_cli_args *a, vafm_cli_rec_opts *o);
/* the file's size estimated before anything is written; refused when it cannot fit */
int vafm_cli_rec_size_check(const vafm_cli_args *a, const vafm_cli_rec_opts *co, const vafm_params *base,
                            const vafm_campaign_spec *spec);
/* open (create, resume, overwrite) and record or compare the provenance */
int vafm_cli_rec_open(vafm_cli_rec *cp, const vafm_cli_rec_opts *o, const vafm_cli_scene *sc,
                      const vafm_campaign_spec *spec);
/* the campaign callback (vafm_campaign_fn): one curve into the file, through the scene's detector */
int vafm_cli_rec_curve(void *user, const vafm_campaign_curve *c);
/* close the recorder after a run (r: the campaign's return), report what failed; @return the exit status */
int vafm_cli_rec_close(vafm_cli_rec *cp, const vafm_cli_rec_opts *co, uint64_t first, int r, const vafm_error *err,
                       vafm_recorder_report *rep);

/* cli_common.c */
void vafm_cli_error(const char *fmt, ...) VAFM_CLI_PRINTF(1, 2);
int vafm_cli_exit_of(int code);
double vafm_cli_now(void);
int vafm_cli_parse_u64(const char *opt, const char *text, uint64_t lo, uint64_t hi, uint64_t *out);
/** --kernel NAME into spec (vafm_campaign_kernel_parse); NULL text: leave spec as it is. @return 0 or a usage exit code. */
int vafm_cli_parse_kernel(const char *text, vafm_campaign_spec *spec);
int vafm_cli_parse_list(const char *opt, const char *field, const char *text, double **out, size_t *n);
/* The points of a T x v x k grid, in double: the product of three list lengths read from input (options, a
 * file's grid) may not fit a size_t; compare it with VAFM_CLI_MAX_POINTS before sizing anything by it. */
double vafm_cli_grid_points(const vafm_campaign_spec *spec);
int vafm_cli_report(const vafm_error *err, int code);
int vafm_cli_resolve_scene(const vafm_cli_args *a, vafm_cli_scene *sc, int validate);

/** A command that may run on MPI (vafm campaign, vafm map): start MPI under an MPI launcher or with --mpi
 *  (plain runs never touch it), run body(a, mpi) (mpi NULL in a single process), finish MPI. @return the
 *  exit status: body's, or vafm_cli_mpi_begin's when MPI could not start. */
int vafm_cli_with_mpi(const vafm_cli_args *a, int (*body)(const vafm_cli_args *a, vafm_cli_mpi *mpi));
void vafm_cli_print_provenance(FILE *o, const vafm_cli_scene *sc);
void vafm_cli_progress_init(vafm_cli_progress *pg, const vafm_cli_args *a);
int vafm_cli_progress_due(vafm_cli_progress *pg);
void vafm_cli_progress_line(const vafm_cli_progress *pg, const char *text);
void vafm_cli_progress_end(const vafm_cli_progress *pg);
int vafm_cli_advance_all(vafm_sim *sim, vafm_sample_fn fn, void *user, vafm_cli_progress *pg);
int vafm_cli_new_sim(const vafm_params *p, vafm_sim **sim);
void vafm_cli_fmt_pair(char *buf, size_t len, double v, double si_scale, const char *si_unit, double ref, const char *ref_unit);
void vafm_cli_print_flags(FILE *o, int flags);
const char *vafm_cli_get(const vafm_params *p, const char *name, char *buf, size_t len);
void vafm_cli_print_scene_si(FILE *o, const vafm_params *p);
void vafm_cli_print_scene_reduced(FILE *o, const vafm_params *p, double dt_s);
void vafm_cli_print_observables(FILE *o, const vafm_params *p, const vafm_curve_result *res);
void vafm_cli_print_quasistatic(FILE *o, const vafm_params *p, const vafm_curve_result *res);
void vafm_cli_print_run_result(FILE *o, const vafm_params *p, const vafm_curve_result *res, double wall);
FILE *vafm_cli_open_out(const char *path);
int vafm_cli_close_out(FILE *f, const char *path, int failed);
void vafm_cli_print_moments_row(FILE *o, const char *name, const vafm_moments *m, double scale, const char *unit, double ref, const char *ref_unit);
void vafm_cli_print_point(FILE *o, size_t point, const vafm_params *p, const vafm_point_stats *st);
int vafm_cli_parse_real(const char *opt, const char *text, double lo, double hi, const char *unit, double *out);
double vafm_cli_file_mb(const char *path);
uint64_t vafm_cli_truth_stats(const vafm_h5_reader *r, size_t np, vafm_point_stats *stats);
void vafm_cli_print_statistics(FILE *o, const vafm_params *base, const vafm_campaign_spec *spec, const vafm_point_stats *stats);
/* A force map's grid, per-region statistics and text renderings (by material, adhesion, height), from the
 * file's map attributes and ground truth. @return 1 printed, 0 not a map, -1 out of memory. */
int vafm_cli_print_map(FILE *o, vafm_h5_reader *r);

/* the subcommands (one table in vafm.c) */
int vafm_cli_cmd_run(const vafm_cli_args *a);
int vafm_cli_cmd_samples(const vafm_cli_args *a);
int vafm_cli_cmd_curves(const vafm_cli_args *a);
int vafm_cli_cmd_campaign(const vafm_cli_args *a);
int vafm_cli_cmd_map(const vafm_cli_args *a);
int vafm_cli_cmd_info(const vafm_cli_args *a);
int vafm_cli_cmd_export(const vafm_cli_args *a);
int vafm_cli_cmd_params(const vafm_cli_args *a);
int vafm_cli_cmd_presets(const vafm_cli_args *a);
int vafm_cli_cmd_integrators(const vafm_cli_args *a);
int vafm_cli_replay(int argc, char **argv); /* cmd_replay.c */

#endif
