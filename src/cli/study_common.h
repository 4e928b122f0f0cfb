/* SPDX-License-Identifier: MIT */
/*
 * `vafm study` (issue #7), internal: what the studies share. The driver (cmd_study.c) parses the options
 * into a vafm_study_ctx, opens DIR/report.md and calls one study (study_<name>.c); each study runs its
 * campaigns through vafm_study_campaign(), which keeps every curve's ground truth in memory, reduces them
 * with the statistics below and writes its tables and its section of the report. Studies return 0, 1 on
 * a runtime error (printed), 4 when a fit did not converge (report written).
 */
#ifndef VAFM_CLI_STUDY_COMMON_H
#define VAFM_CLI_STUDY_COMMON_H

#include <limits.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "cli/cli.h"
#include "vafm/campaign.h"
#include "h5/h5.h"
#include "vafm/params.h"
#include "record/record.h"

#define VAFM_STUDY_MAXP 16

/* A campaign's per-curve ground truth stays in memory until its tables are written, so -n (curves per
 * point) is bounded by that memory: at most VAFM_STUDY_TRUTH_BYTES_MAX for the largest grid a study gives -n
 * to (distribution: five temperatures). 100000 curves per point is 50 times the distribution's N and
 * about 40 CPU-hours of its curves, beyond any study run in one go. */
#define VAFM_STUDY_N_MAX 100000
#define VAFM_STUDY_N_POINTS_MAX 5u
#define VAFM_STUDY_TRUTH_BYTES_MAX ((size_t)256 << 20)
_Static_assert((size_t)VAFM_STUDY_N_MAX * VAFM_STUDY_N_POINTS_MAX * sizeof(vafm_h5_truth) <= VAFM_STUDY_TRUTH_BYTES_MAX,
               "-n's maximum must keep a campaign's ground truth within VAFM_STUDY_TRUTH_BYTES_MAX");

/* Every file of a study is DIR/NAME with NAME at most VAFM_STUDY_NAME_MAX bytes (the longest:
 * athermal-brownian-labframe-v0.05.h5, 35), so an --out of at most VAFM_STUDY_OUT_MAX bytes keeps every path
 * within PATH_MAX; a longer one is refused before anything is written, never cut short. */
#define VAFM_STUDY_PATH_LEN PATH_MAX
#define VAFM_STUDY_NAME_MAX 64
#define VAFM_STUDY_OUT_MAX 4000
_Static_assert(VAFM_STUDY_OUT_MAX + 1 + VAFM_STUDY_NAME_MAX < VAFM_STUDY_PATH_LEN, "--out's maximum must leave room for the file names");

/* ---- context and one campaign ---------------------------------------------------------------------- */

typedef struct vafm_study_ctx {
    const char *name, *out;
    int quick, threads, resume, quiet;
    vafm_campaign_spec kernel; /* --kernel: kernel and batch_width only */
    uint64_t n_override; /* -n: curves per point of the thermal campaigns (0: the study's own) */
    double min_se;       /* smallest standard error of a mean force in the study, F_JKR (NAN: none) */
    double cpu0, wall0;
    uint64_t curves_run, curves_kept, steps;
    FILE *rep; /* report.md */
} vafm_study_ctx;

typedef struct vafm_study_run {
    char file[VAFM_STUDY_PATH_LEN];
    vafm_params base;
    double T[VAFM_STUDY_MAXP], k[VAFM_STUDY_MAXP], v;
    size_t nT, nk;
    uint64_t N;
    int keep_samples;
    FILE *samples_csv;
    /* results, by global index */
    vafm_h5_truth *truth;
    uint64_t total;
    /* recorder state */
    vafm_recorder *rec;
    int werr;
    vafm_error e;
} vafm_study_run;

/* ---- the studies (study_<name>.c) ------------------------------------------------------------------ */

int vafm_study_distribution(vafm_study_ctx *ctx);
int vafm_study_velocity_athermal(vafm_study_ctx *ctx);
int vafm_study_velocity_thermal(vafm_study_ctx *ctx);
int vafm_study_hysteresis(vafm_study_ctx *ctx);

/* ---- shared pieces (study_common.c) ---------------------------------------------------------------- */

/* The reduced pulling speeds of both velocity studies' full grids. */
#define VAFM_STUDY_N_V_FULL 11
extern const double vafm_study_v_full[VAFM_STUDY_N_V_FULL];

/* Run one campaign into r->file (or continue it: --resume) and keep every curve's ground truth in
 * r->truth. @return 0, or 1 with the error printed and r->truth freed. */
int vafm_study_campaign(vafm_study_ctx *ctx, vafm_study_run *r);
void vafm_study_run_free(vafm_study_run *r);
/* buf = DIR/NAME, NAME from fmt. @return 0, or 1 with the error printed (the path would not fit). */
int vafm_study_path(char buf[VAFM_STUDY_PATH_LEN], const char *out, const char *fmt, ...) VAFM_CLI_PRINTF(3, 4);
/* fopen(path, "w"), printing why it failed. */
FILE *vafm_study_open(const char *path);

typedef struct vafm_study_stat {
    size_t n;
    double mean, sd, se;
} vafm_study_stat;

/* Mean, sample standard deviation and standard error of x[0..n). */
vafm_study_stat vafm_study_stats(const double *x, size_t n);
/* Values of one observable for grid point `pt` (curves with a clean pull-off: flags 0), scaled. */
size_t vafm_study_collect(const vafm_study_run *r, size_t pt, int which, double scale, double *out);
/* Curves of grid point `pt` that failed or carry an excluding flag. */
size_t vafm_study_flagged(const vafm_study_run *r, size_t pt);

/* The velocity studies' scene: paper-fig4 (Langevin) or paper-fig4-bd (Brownian), retract only from an
 * equilibrium 1 R pressed in, sampled every 0.05 R of travel. */
void vafm_study_fig4_scene(vafm_params *p, int brownian, double v_red);
/* A reduced temperature k_BT̃ in K for the scene p. */
double vafm_study_kT_to_K(const vafm_params *p, double kT_red);
#endif
