/* SPDX-License-Identifier: MIT */
/*
 * `vafm study <name>`: the paper's results (issue #7) as campaigns, fits, theory, a report and figures.
 *
 * Each study is a list of campaigns (one HDF5 file each, written through the h5 library as `vafm
 * campaign` does, resumable); the per-curve ground truth is kept in memory (read back from the file on
 * resume) and reduced to tables. Fits live in study_fit.c, figures in study_plot.py (matplotlib, run
 * with /usr/bin/python3; skipped with a note when it is missing), references in theory.h.
 *
 * Numerics, the same for every study and stated in the report: gjf at ω·dt = 0.6 for Langevin (the
 * work–precision table's cheapest setting within 2 standard errors of the reference), the paper's
 * Eq. 12 Euler step for Brownian dynamics at the preset's step. The velocity studies pull from an
 * equilibrium start in contact (retract only, 1 R pressed in) instead of a full approach: the pull-off
 * happens ≥ 1.7 R of travel later, ≥ 4 relaxation times even at ṽ = 0.5, so the start is forgotten.
 * Their output sample interval is 0.05 R of travel (the spring-force observable is taken at every
 * step, so the sampling only changes the cost, through `well_exact`).
 */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <fcntl.h>
#include <limits.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

extern char **environ;

#include "cli/cli.h"
#include "cli/study.h"
#include "cli/study_fit.h"
#include "vafm/campaign.h"
#include "vafm/h5.h"
#include "vafm/record.h"
#include "vafm/stats.h"
#include "vafm/integrator.h"
#include "vafm/theory.h"
#include "vafm/units.h"

#ifndef VAFM_DATADIR_REL
#define VAFM_DATADIR_REL "../share/vafm"
#endif
#ifndef VAFM_STUDY_PLOT
#define VAFM_STUDY_PLOT "src/cli/study_plot.py"
#endif

#define S_PI 3.14159265358979323846
#define S_MAXP 16

/* A campaign's per-curve ground truth stays in memory until its tables are written, so -n (curves per
 * point) is bounded by that memory: at most S_TRUTH_BYTES_MAX for the largest grid a study gives -n
 * to (distribution: five temperatures). 100000 curves per point is 50 times the distribution's N and
 * about 40 CPU-hours of its curves, beyond any study run in one go. */
#define S_N_MAX 100000
#define S_N_POINTS_MAX 5u
#define S_TRUTH_BYTES_MAX ((size_t)256 << 20)
_Static_assert((size_t)S_N_MAX * S_N_POINTS_MAX * sizeof(vafm_h5_truth) <= S_TRUTH_BYTES_MAX,
               "-n's maximum must keep a campaign's ground truth within S_TRUTH_BYTES_MAX");

/* Every file of a study is DIR/NAME with NAME at most S_NAME_MAX bytes (the longest:
 * athermal-brownian-labframe-v0.05.h5, 35), so an --out of at most S_OUT_MAX bytes keeps every path
 * within PATH_MAX; a longer one is refused before anything is written, never cut short. */
#define S_PATH_LEN PATH_MAX
#define S_NAME_MAX 64
#define S_OUT_MAX 4000
_Static_assert(S_OUT_MAX + 1 + S_NAME_MAX < S_PATH_LEN, "--out's maximum must leave room for the file names");

/* ---- context and one campaign ---------------------------------------------------------------------- */

typedef struct s_ctx {
    const char *name, *out;
    int quick, threads, resume, quiet;
    vafm_campaign_spec kernel; /* --kernel: kernel and batch_width only */
    uint64_t n_override; /* -n: curves per point of the thermal campaigns (0: the study's own) */
    double min_se;       /* smallest standard error of a mean force in the study, F_JKR (NAN: none) */
    double cpu0, wall0;
    uint64_t curves_run, curves_kept, steps;
    FILE *rep; /* report.md */
} s_ctx;

typedef struct s_run {
    char file[S_PATH_LEN];
    vafm_params base;
    double T[S_MAXP], k[S_MAXP], v;
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
} s_run;

static double s_now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

static double s_cpu(void)
{
    struct timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

static void s_spec(const s_run *r, vafm_campaign_spec *sp)
{
    memset(sp, 0, sizeof *sp);
    sp->T_K = r->nT ? r->T : NULL;
    sp->n_T = r->nT;
    sp->v_m_per_s = &r->v;
    sp->n_v = 1;
    sp->k_N_per_m = r->nk ? r->k : NULL;
    sp->n_k = r->nk;
    sp->curves_per_point = r->N;
}

static int s_cb(void *user, const vafm_campaign_curve *c)
{
    s_run *r = user;
    if (c->status || !c->samples.n) {
        r->werr = c->status ? c->status : VAFM_EINVAL;
        snprintf(r->e.message, sizeof r->e.message, "curve %" PRIu64 " failed: %s", c->index, vafm_strerror(r->werr));
        return 1;
    }
    vafm_record_curve rc = { .samples = &c->samples, .params = c->params, .result = &c->result,
                             .point = c->point, .sensitivity_m_per_V = NAN };
    int e = vafm_recorder_append(r->rec, &rc, &r->e);
    if (e || (e = vafm_recorder_truth(r->rec, c->index, &r->truth[c->index])) != 0) {
        r->werr = e;
        return 1;
    }
    if (r->samples_csv) {
        const vafm_samples *s = &c->samples;
        for (size_t i = 0; i < s->n; ++i)
            fprintf(r->samples_csv, "%.9g,%.9g,%.9g,%.9g,%d\n", s->time_s[i], s->height_m[i], s->force_N[i],
                    s->tip_m[i], s->segment[i]);
    }
    return 0;
}

static void s_run_free(s_run *r)
{
    free(r->truth);
    r->truth = NULL;
}

/* buf = DIR/NAME, NAME from fmt. The --out length is checked up front, so this does not truncate; the
 * check stays so that a longer name added later is refused instead of cut short. @return 0, or 1 with
 * the error printed. */
static int s_path(char buf[S_PATH_LEN], const char *out, const char *fmt, ...) VAFM_CLI_PRINTF(3, 4);
static int s_path(char buf[S_PATH_LEN], const char *out, const char *fmt, ...)
{
    int n = snprintf(buf, S_PATH_LEN, "%s/", out), m = -1;
    if (n > 0 && n < S_PATH_LEN) {
        va_list ap;
        va_start(ap, fmt);
        m = vsnprintf(buf + n, (size_t)(S_PATH_LEN - n), fmt, ap);
        va_end(ap);
    }
    if (m < 0 || m >= S_PATH_LEN - n) {
        vafm_cli_error("study: --out: a file name in the %zu-byte directory name would make a path longer than %d "
                       "bytes", strlen(out), S_PATH_LEN - 1);
        return 1;
    }
    return 0;
}

/* fopen(path, "w"), printing why it failed. */
static FILE *s_open(const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f)
        vafm_cli_error("study: cannot write %s: %s", path, strerror(errno));
    return f;
}

/* Run one campaign into r->file (or continue it: --resume) and keep every curve's ground truth in
 * r->truth. @return 0, or 1 with the error printed and r->truth freed, so that a caller's error path
 * frees only its other runs. */
static int s_campaign(s_ctx *ctx, s_run *r)
{
    vafm_campaign_spec sp;
    s_spec(r, &sp);
    size_t points = vafm_campaign_points(&sp);
    /* -n is checked against this bound up front; this guards the studies' own grids as well */
    if (!points || r->N > S_TRUTH_BYTES_MAX / sizeof *r->truth / points) {
        vafm_cli_error("study: %s: %" PRIu64 " curves x %zu points would hold more than %zu MiB of results in "
                       "memory", r->file, r->N, points, S_TRUTH_BYTES_MAX >> 20);
        return 1;
    }
    r->total = r->N * points;
    r->truth = calloc(r->total, sizeof *r->truth);
    if (!r->truth) {
        vafm_cli_error("study: %s: out of memory for %" PRIu64 " curves", r->file, r->total);
        return 1;
    }
    vafm_error e;
    memset(&e, 0, sizeof e);
    if (vafm_campaign_validate(&r->base, &sp, NULL, &e)) {
        fprintf(stderr, "vafm study: %s, %s\n", r->file, e.message);
        goto fail;
    }
    vafm_recorder_opts o;
    vafm_recorder_opts_default(&o);
    o.gzip_level = 1;         /* the paper-fig1 curves hold ~0.5 MB of samples each; deflate costs ~1% of a curve */
    o.flush_interval_s = 1.0; /* durable about once a second, as `vafm campaign` */
    struct stat st;
    /* a study's directory holds its own outputs: a rerun replaces them, --resume continues them */
    o.mode = ctx->resume && stat(r->file, &st) == 0 && !r->samples_csv ? VAFM_RECORD_RESUME : VAFM_RECORD_OVERWRITE;
    if (vafm_recorder_open(&r->rec, r->file, &o, &r->base, &sp, &e)) {
        fprintf(stderr, "vafm study: %s: %s\n", r->file, e.message);
        goto fail;
    }
    uint64_t have = vafm_recorder_count(r->rec);
    if (have > r->total)
        have = r->total;
    for (uint64_t i = 0; i < have; ++i)
        if (vafm_recorder_truth(r->rec, i, &r->truth[i])) {
            fprintf(stderr, "vafm study: %s: no ground truth for curve %" PRIu64 "\n", r->file, i);
            vafm_recorder_close(&r->rec, NULL, NULL);
            goto fail;
        }
    ctx->curves_kept += have;
    int rc = 0;
    if (have < r->total) {
        sp.first_curve = have;
        sp.threads = ctx->threads;
        sp.kernel = ctx->kernel.kernel;
        sp.batch_width = ctx->kernel.batch_width;
        sp.keep_samples = 1;
        rc = vafm_campaign_run(&r->base, &sp, s_cb, r, &e);
    }
    int cr = vafm_recorder_close(&r->rec, NULL, r->werr ? NULL : &r->e);
    if (r->werr || (rc && rc != VAFM_EABORT) || cr) {
        fprintf(stderr, "vafm study: %s: %s\n", r->file,
                r->e.message[0] ? r->e.message : e.message[0] ? e.message : vafm_strerror(rc ? rc : cr));
        goto fail;
    }
    for (uint64_t i = have; i < r->total; ++i)
        ctx->steps += r->truth[i].result.steps;
    ctx->curves_run += r->total - have;
    if (!ctx->quiet)
        fprintf(stderr, "vafm study: %s: %" PRIu64 " curves (%" PRIu64 " run)\n", r->file, r->total, r->total - have);
    return 0;
fail:
    s_run_free(r);
    return 1;
}

/* ---- statistics ---------------------------------------------------------------------------------- */

typedef struct s_stat {
    size_t n;
    double mean, sd, se;
} s_stat;

static s_stat s_stats(const double *x, size_t n)
{
    s_stat s = { n, NAN, NAN, NAN };
    if (!n)
        return s;
    double m = 0, v = 0;
    for (size_t i = 0; i < n; ++i)
        m += x[i];
    m /= n;
    for (size_t i = 0; i < n; ++i)
        v += (x[i] - m) * (x[i] - m);
    s.mean = m;
    s.sd = n > 1 ? sqrt(v / (n - 1)) : 0.0;
    s.se = n > 1 ? s.sd / sqrt((double)n) : 0.0;
    return s;
}

/* Values of one observable for grid point `pt` (curves with a clean pull-off: flags 0), scaled. */
static size_t s_collect(const s_run *r, size_t pt, int which, double scale, double *out)
{
    size_t n = 0;
    for (uint64_t i = pt * r->N; i < (pt + 1) * r->N; ++i) {
        const vafm_h5_truth *t = &r->truth[i];
        double x = vafm_stats_value(&t->result, which);
        if (vafm_stats_is_pulloff(t->status, &t->result) && isfinite(x))
            out[n++] = x * scale;
    }
    return n;
}

static size_t s_flagged(const s_run *r, size_t pt)
{
    size_t n = 0;
    for (uint64_t i = pt * r->N; i < (pt + 1) * r->N; ++i)
        n += r->truth[i].status || (r->truth[i].result.flags & VAFM_STATS_EXCLUDING_FLAGS) ? 1 : 0;
    return n;
}

/* ---- scenes -------------------------------------------------------------------------------------- */

/* The velocity studies' scene: paper-fig4 (Langevin, m̃ = 0.01) or paper-fig4-bd (Brownian, ζ = 1),
 * retract only from an equilibrium 1 R pressed in, sampled every 0.05 R of travel. */
static void s_fig4_scene(vafm_params *p, int brownian, double v_red)
{
    vafm_preset_apply(p, brownian ? "paper-fig4-bd" : "paper-fig4", NULL);
    vafm_scale sc = vafm_units_scale(p);
    if (!brownian)
        p->omega_dt = 0.6;
    p->start_in_contact = 1;
    p->start_height_m = -1.0 * sc.length_m;
    p->trigger = VAFM_TRIGGER_HEIGHT;
    p->trigger_height_m = -1.0001 * sc.length_m;
    p->v_approach_m_per_s = p->v_retract_m_per_s = v_red * sc.speed_m_per_s;
    p->sample_rate_Hz = v_red / (0.05 * sc.time_s);
    p->retract_margin_m = 0.5 * sc.length_m;
}

static double s_kT_to_K(const vafm_params *p, double kT_red)
{
    return kT_red * vafm_units_scale(p).energy_J / VAFM_KB_J_PER_K;
}

/* ---- figures --------------------------------------------------------------------------------------- */

/* Run the plotter with an argument vector (never through a shell: the output directory is the user's
 * string, and `x'$(touch y)'` or O'Brien must reach python as they are). Its stdout and stderr go into
 * msg. @return its wait status, or -1 when it could not be started. */
static int s_run_plotter(const char *script, const char *name, const char *out, char *msg, size_t len)
{
    int fds[2];
    if (pipe2(fds, O_CLOEXEC))
        return -1;
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_adddup2(&fa, fds[1], STDOUT_FILENO);
    posix_spawn_file_actions_adddup2(&fa, fds[1], STDERR_FILENO);
    /* the environment plus MPLBACKEND=Agg (no display) */
    size_t ne = 0;
    while (environ[ne])
        ne++;
    char **env = calloc(ne + 2, sizeof *env);
    int st = -1;
    if (env) {
        size_t k = 0;
        for (size_t i = 0; i < ne; i++)
            if (strncmp(environ[i], "MPLBACKEND=", 11))
                env[k++] = environ[i];
        env[k++] = (char *)"MPLBACKEND=Agg";
        env[k] = NULL;
        char *argv[] = { (char *)"/usr/bin/python3", (char *)script, (char *)name, (char *)out, NULL };
        pid_t pid;
        if (posix_spawn(&pid, argv[0], &fa, NULL, argv, env) == 0) {
            close(fds[1]);
            fds[1] = -1;
            size_t used = 0;
            char buf[1024];
            ssize_t got;
            while ((got = read(fds[0], buf, sizeof buf)) > 0 || (got < 0 && errno == EINTR))
                if (got > 0 && used + (size_t)got < len) {
                    memcpy(msg + used, buf, (size_t)got);
                    used += (size_t)got;
                }
            msg[used < len ? used : len - 1] = '\0';
            while (waitpid(pid, &st, 0) < 0 && errno == EINTR)
                ;
        }
        free(env);
    }
    posix_spawn_file_actions_destroy(&fa);
    close(fds[0]);
    if (fds[1] >= 0)
        close(fds[1]);
    return st;
}

/* The plotter: $VAFM_STUDY_PLOT; else installed beside the binary (BINDIR/VAFM_DATADIR_REL/study_plot.py,
 * e.g. /usr/bin/../share/vafm), so an installed vafm finds its own wherever the source tree went; else the
 * source tree's (a build tree's vafm). */
static const char *s_plot_script(char *buf, size_t len)
{
    const char *env = getenv("VAFM_STUDY_PLOT");
    if (env && *env)
        return env;
    char exe[4096];
    ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (n > 0) {
        exe[n] = '\0';
        char *slash = strrchr(exe, '/');
        if (slash) {
            *slash = '\0';
            struct stat st;
            int w = VAFM_DATADIR_REL[0] == '/' ? snprintf(buf, len, "%s/study_plot.py", VAFM_DATADIR_REL)
                                               : snprintf(buf, len, "%s/%s/study_plot.py", exe, VAFM_DATADIR_REL);
            if (w > 0 && w < (int)len && stat(buf, &st) == 0)
                return buf;
        }
    }
    return VAFM_STUDY_PLOT;
}

static void s_plot(s_ctx *ctx)
{
    char found[4096];
    const char *script = s_plot_script(found, sizeof found);
    struct stat st;
    if (stat(script, &st) || stat("/usr/bin/python3", &st)) {
        fprintf(ctx->rep, "\n**Figures: skipped** (plot script %s or /usr/bin/python3 not found).\n", script);
        fprintf(stderr, "vafm study: figures skipped: %s or /usr/bin/python3 not found\n", script);
        return;
    }
    char msg[4096] = "";
    int st2 = s_run_plotter(script, ctx->name, ctx->out, msg, sizeof msg);
    int code = st2 >= 0 && WIFEXITED(st2) ? WEXITSTATUS(st2) : -1;
    if (code == 0) {
        fprintf(ctx->rep, "\nFigures (matplotlib, `%s`):\n\n%s", script, msg);
    } else if (code == 3) {
        fprintf(ctx->rep, "\n**Figures: skipped** (matplotlib is not installed for /usr/bin/python3); the data "
                          "behind every figure are in the CSV files.\n");
        fprintf(stderr, "vafm study: figures skipped: matplotlib missing\n");
    } else {
        fprintf(ctx->rep, "\n**Figures: failed** (exit %d):\n\n```\n%s```\n", code, msg);
        fprintf(stderr, "vafm study: the plot script failed (exit %d):\n%s", code, msg);
    }
}

/* ---- distribution --------------------------------------------------------------------------------- */

static int s_distribution(s_ctx *ctx)
{
    const double mult_full[] = { 0.25, 0.5, 1.0, 2.0, 4.0 }, mult_quick[] = { 1.0, 4.0 };
    const double *mult = ctx->quick ? mult_quick : mult_full;
    size_t nT = ctx->quick ? 2 : 5;
    s_run r;
    memset(&r, 0, sizeof r);
    vafm_preset_apply(&r.base, "paper-fig1", NULL);
    r.base.omega_dt = 0.6;
    vafm_reduced red;
    vafm_units_reduce(&r.base, &red);
    vafm_scale sc = vafm_units_scale(&r.base);
    for (size_t i = 0; i < nT; ++i)
        r.T[i] = r.base.T_K * mult[i];
    r.nT = nT;
    r.v = r.base.v_retract_m_per_s;
    r.N = ctx->n_override ? ctx->n_override : ctx->quick ? 12 : 2000;
    if (s_path(r.file, ctx->out, "distribution.h5") || s_campaign(ctx, &r))
        return 1;

    vafm_quasistatic q;
    vafm_theory_quasistatic(red.gamma, red.k, &q);
    const double FJ = q.F_jkr * sc.force_N;
    char path[S_PATH_LEN];
    FILE *c = NULL, *f = NULL;
    if (!s_path(path, ctx->out, "distribution_curves.csv"))
        c = s_open(path);
    if (c && !s_path(path, ctx->out, "distribution_fits.csv"))
        f = s_open(path);
    double *x = malloc(r.N * sizeof *x), *y = malloc(r.N * sizeof *y), *z = malloc(r.N * sizeof *z);
    if (c && f && !(x && y && z))
        vafm_cli_error("study: out of memory");
    if (!c || !f || !x || !y || !z) {
        if (c)
            fclose(c);
        if (f)
            fclose(f);
        free(x);
        free(y);
        free(z);
        s_run_free(&r);
        return 1;
    }
    fprintf(c, "T_K,kT_reduced,pulloff_sampled_nN,pulloff_spring_nN,detach_nN,F_JKR_nN\n");
    fprintf(f, "T_K,kT_reduced,observable,n,mean_nN,sd_nN,se_nN,xi_nN,se_xi_nN,omega_nN,se_omega_nN,alpha,se_alpha,"
               "converged\n");
    FILE *o = ctx->rep;
    fprintf(o, "## Pull-off force distribution (paper Figs. 2 and 3)\n\n");
    fprintf(o, "Scene: paper-fig1 (m̃ = 5e-5, ṽ = 1e-4, k̃ = 2e-5, γ̃ = 1.2e-4; E* = 20 GPa, R = 15.7 nm, "
               "k = %.3g N/m, v = %.4g nm/s), full loading–unloading curves, gjf at ω·dt = 0.6. N = %" PRIu64
               " curves per temperature, T = %s × %.1f K. F_JKR = %.4f nN.\n\n",
            r.base.k_N_per_m, r.v * 1e9, r.N, ctx->quick ? "{1, 4}" : "{0.25, 0.5, 1, 2, 4}", r.base.T_K, FJ * 1e9);
    fprintf(o, "**Observable.** Figure `distribution.png` and the skew-normal fits use `pulloff_spring_N`, the most "
               "tensile spring force of any step of the retract (the paper's definition, Eq. 10). The table also "
               "gives `pulloff_sampled_N` (what an AFM user reads from the 2 kHz box-car-filtered output) and "
               "`detach_force_N` (spring force when contact is lost). At this compliant spring the three agree "
               "to within their errors (physics notes: the noise bias of the spring-force maximum is negligible "
               "for k̃ = 2e-5).\n\n");
    fprintf(o, "Skew-normal fits: maximum penalised likelihood (GSL Nelder–Mead; the Azzalini–Arellano-Valle "
               "penalty 0.876·ln(1 + 0.856α²), which keeps the shape α finite in small samples, where the plain "
               "MLE diverges with positive probability, and regularises the singular information at α = 0; its "
               "weight relative to ln L falls as 1/n), errors from the inverse Hessian of the penalised −ln L. "
               "Forces in nN.\n\n");
    fprintf(o, "| T (K) | k_BT̃ | observable | n | flagged | mean ± se | sd | ξ ± se | ω ± se | α ± se | fit |\n"
               "|---|---|---|---|---|---|---|---|---|---|---|\n");
    int all_conv = 1;
    const char *oname[] = { "pulloff_sampled_N", "pulloff_spring_N", "detach_force_N" };
    double mean_ref = NAN, sd_ref = NAN, mT[8], sT[8], aT[8];
    for (size_t pt = 0; pt < nT; ++pt) {
        double kT = red.kT * mult[pt];
        size_t n = s_collect(&r, pt, VAFM_OBS_PULLOFF_SPRING, 1e9, x);
        size_t ny = s_collect(&r, pt, VAFM_OBS_PULLOFF_SAMPLED, 1e9, y), nz = s_collect(&r, pt, VAFM_OBS_DETACH_FORCE, 1e9, z);
        if (ny < n)
            n = ny;
        if (nz < n)
            n = nz;
        for (size_t i = 0; i < n; ++i)
            fprintf(c, "%.6g,%.6g,%.9g,%.9g,%.9g,%.9g\n", r.T[pt], kT, y[i], x[i], z[i], FJ * 1e9);
        double *arr[3] = { y, x, z };
        for (int ob = 0; ob < 3; ++ob) {
            s_stat s = s_stats(arr[ob], n);
            vafm_fit_skewnorm fit;
            int ok = vafm_fit_skewnorm_ml(arr[ob], n, &fit) == 0;
            if (ob == 1) {
                all_conv &= ok;
                if (!(s.se / (FJ * 1e9) >= ctx->min_se))
                    ctx->min_se = s.se / (FJ * 1e9);
                mT[pt] = s.mean;
                sT[pt] = s.sd;
                aT[pt] = ok ? fit.alpha : NAN;
                if (mult[pt] == 1.0) {
                    mean_ref = s.mean;
                    sd_ref = s.sd;
                }
            }
            fprintf(f, "%.6g,%.6g,%s,%zu,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%d\n", r.T[pt], kT, oname[ob], n,
                    s.mean, s.sd, s.se, fit.xi, fit.se_xi, fit.omega, fit.se_omega, fit.alpha, fit.se_alpha, ok);
            fprintf(o, "| %.1f | %.3g | %s | %zu | %zu | %.4f ± %.4f | %.4f | %.4f ± %.4f | %.4f ± %.4f | %.2f ± %.2f | %s |\n",
                    r.T[pt], kT, oname[ob], n, s_flagged(&r, pt), s.mean, s.se, s.sd, fit.xi, fit.se_xi, fit.omega,
                    fit.se_omega, fit.alpha, fit.se_alpha, ok ? "converged" : "**not converged**");
        }
    }
    fclose(c);
    fclose(f);
    free(x);
    free(y);

    /* Time-step bias of this scene, measured (full runs only): the first Nb curves of the lowest
     * temperature again at a quarter of the step, with the same (seed, index) streams. The same stream
     * at another step is another noise history, so pairing gains nothing: the report says so with the
     * spread of the differences. */
    if (!ctx->quick) {
        s_run rb;
        memset(&rb, 0, sizeof rb);
        rb.base = r.base;
        rb.base.omega_dt = 0.15;
        rb.T[0] = r.T[0];
        rb.nT = 1;
        rb.v = r.v;
        rb.N = r.N < 100 ? r.N : 100;
        if (s_path(rb.file, ctx->out, "distribution-dt4.h5") || s_campaign(ctx, &rb)) {
            free(z);
            s_run_free(&r);
            return 1;
        }
        double *d = malloc(rb.N * sizeof *d);
        if (!d) {
            vafm_cli_error("study: out of memory");
            s_run_free(&rb);
            free(z);
            s_run_free(&r);
            return 1;
        }
        size_t nd = 0;
        for (uint64_t i = 0; i < rb.N; ++i) {
            const vafm_curve_result *a = &r.truth[i].result, *b = &rb.truth[i].result;
            if (!a->flags && !b->flags && !r.truth[i].status && !rb.truth[i].status)
                d[nd++] = (a->pulloff_spring_N - b->pulloff_spring_N) / FJ;
        }
        s_stat sd_ = s_stats(d, nd);
        free(d);
        fprintf(o, "\n**Time-step bias (measured).** The first %zu curves of T = %.1f K rerun at ω·dt = 0.15 (a "
                   "quarter step), same random streams: mean difference of `pulloff_spring_N` (ω·dt 0.6 − 0.15) "
                   "= %+.2g ± %.2g F_JKR (standard error of the per-curve differences; their sd %.2g F_JKR "
                   "against the distribution's sd %.2g F_JKR: the same stream at another step is another noise "
                   "history, so pairing does not reduce the error).\n",
                nd, rb.T[0], sd_.mean, sd_.se, sd_.sd, sT[0] / (FJ * 1e9));
        s_run_free(&rb);
    }

    /* references */
    double v_red = red.v_retract, zeta = red.m;
    fprintf(o, "\n**Theory.** Quasi-static: F* = %.6f F_JKR (jump), F_det = %.6f F_JKR (spring force when the body "
               "reaches u_min), maximum tensile force along the path = F_JKR = %.4f nN.\n",
            q.F_star / q.F_jkr, q.F_det / q.F_jkr, FJ * 1e9);
    fprintf(o, "Overdamped references at each temperature (ζ = m̃ = %.3g; y = spring position past the instability, "
               "F = F_det − k·y):\n\n| T (K) | DHS ⟨F⟩ (nN) | MFPT ⟨F⟩ ± sd (nN) | simulated ⟨detach_force⟩ (nN) |\n"
               "|---|---|---|---|\n", zeta);
    for (size_t pt = 0; pt < nT; ++pt) {
        double kT = red.kT * mult[pt];
        vafm_theory_pull tp;
        double yd = vafm_theory_dhs_mean_y(&q, red.k, kT, v_red, zeta);
        int ok = vafm_theory_mfpt_pull(red.gamma, red.k, kT, zeta, red.m, 0.0, &v_red, 1, &tp) == 0;
        size_t n = s_collect(&r, pt, VAFM_OBS_DETACH_FORCE, 1e9, z);
        s_stat s = s_stats(z, n);
        fprintf(o, "| %.1f | %.4f | %.4f ± %.4f | %.4f ± %.4f |\n", r.T[pt],
                (q.F_det - red.k * yd) * sc.force_N * 1e9, ok ? tp.mean_F * sc.force_N * 1e9 : NAN,
                ok ? tp.sd_F * sc.force_N * 1e9 : NAN, s.mean, s.se);
    }
    /* the regime (as `vafm theory`): energy lost per oscillation at the barrier, δ = η·(36/5)ΔV/(ω·kT) */
    vafm_theory_pull tp;
    vafm_theory_mfpt_pull(red.gamma, red.k, red.kT, zeta, red.m, 0.0, &v_red, 1, &tp);
    double y0 = tp.mean_y > 0 ? tp.mean_y : 0.0, w = sqrt(sqrt(2.0 * q.F2 * red.k * y0) / red.m);
    double delta = 7.2 * vafm_theory_barrier(&q, red.k, y0) / w / red.kT;
    fprintf(o, "\nDHS assumes overdamped motion; the MFPT column multiplies the exact overdamped rate by Kramers' "
               "spatial-diffusion factor for the mass. Here, at the reference temperature, the well frequency at "
               "the rupture point is ω/η = %.3g (so DHS does not apply) and the energy lost per oscillation at the "
               "barrier is δ = %.2g k_BT: %s\n\n",
            w, delta, delta > 5.0 ? "spatial diffusion, where the MFPT rate with Kramers' factor applies."
                      : "Kramers' turnover / energy-diffusion regime, where even the corrected rate overestimates "
                        "escape; the theory columns are for scale, and the simulation should detach later (at "
                        "higher force) than they say.");
    fprintf(o, "**Paper comparison.** The paper shows (Fig. 2) an asymmetric bell-shaped distribution for this "
               "scene from > 2000 curves and (Fig. 3) lower and broader distributions at higher temperature, fitted "
               "by skew-Gaussian densities; it gives no numbers for the fits. Here, at the reference temperature, "
               "mean %.4f nN and sd %.4f nN (%.3f and %.4f F_JKR).\n\n",
            mean_ref, sd_ref, mean_ref / (FJ * 1e9), sd_ref / (FJ * 1e9));
    int falls = 1, grows = 1, neg = 1;
    for (size_t pt = 0; pt < nT; ++pt) {
        if (pt && !(mT[pt] < mT[pt - 1]))
            falls = 0;
        if (pt && !(sT[pt] > sT[pt - 1]))
            grows = 0;
        if (!(aT[pt] < 0.0))
            neg = 0;
    }
    fprintf(o, "Measured against the paper's claims (`pulloff_spring_N`): the mean %s with temperature (%.4f → %.4f nN "
               "from %.0f to %.0f K), the width %s (sd %.4f → %.4f nN), and the fitted shape α is %s (%s).\n\n",
            falls ? "falls monotonically" : "does **not** fall monotonically", mT[0], mT[nT - 1], r.T[0], r.T[nT - 1],
            grows ? "grows monotonically" : "does **not** grow monotonically", sT[0], sT[nT - 1],
            neg ? "negative at every temperature" : "not negative at every temperature",
            neg ? "a tail toward low forces: the asymmetric bell of Fig. 2" : "see the table; small samples resolve α poorly");
    fprintf(o, "Fits converged: %s.\n\n", all_conv ? "all" : "**not all**");
    free(z);
    s_run_free(&r);
    return all_conv ? 0 : 4;
}

/* ---- velocity, athermal ------------------------------------------------------------------------------ */

static const double s_v_full[] = { 1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.2, 0.5 };
static const double s_v_quick[] = { 1e-4, 1e-3, 1e-2, 0.05, 0.2, 0.5 };
static const double s_vt_quick[] = { 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 0.1 };

static int s_velocity_athermal(s_ctx *ctx)
{
    const double k_full[] = { 0.1, 0.2, 0.4, 0.8 }, k_quick[] = { 0.1, 0.8 };
    const double *kl = ctx->quick ? k_quick : k_full, *vl = ctx->quick ? s_v_quick : s_v_full;
    size_t nk = ctx->quick ? 2 : 4, nv = ctx->quick ? 6 : 11;
    const double gamma = 0.229;
    double F0[2][4][16], Fd[2][4][16];
    char path[S_PATH_LEN];
    FILE *c = NULL;
    if (s_path(path, ctx->out, "athermal.csv") || !(c = s_open(path)))
        return 1;
    fprintf(c, "dynamics,k,v,F0_spring_over_FJKR,F_detach_over_FJKR,Fstar_over_FJKR,Fdet_qs_over_FJKR\n");
    for (int dyn = 0; dyn < 2; ++dyn)
        for (size_t iv = 0; iv < nv; ++iv) {
            s_run r;
            memset(&r, 0, sizeof r);
            s_fig4_scene(&r.base, dyn, vl[iv]);
            r.base.T_K = 0.0;
            vafm_scale sc = vafm_units_scale(&r.base);
            for (size_t i = 0; i < nk; ++i)
                r.k[i] = kl[i] * sc.stiffness_N_per_m;
            r.nk = nk;
            r.v = r.base.v_retract_m_per_s;
            r.N = 1; /* T = 0: deterministic, one curve per point */
            if (s_path(r.file, ctx->out, "athermal-%s-v%g.h5", dyn ? "brownian" : "langevin", vl[iv]) ||
                s_campaign(ctx, &r)) {
                fclose(c);
                return 1;
            }
            for (size_t ik = 0; ik < nk; ++ik) {
                vafm_quasistatic q;
                vafm_theory_quasistatic(gamma, kl[ik], &q);
                double FJ = q.F_jkr * sc.force_N;
                const vafm_curve_result *res = &r.truth[ik].result;
                F0[dyn][ik][iv] = res->pulloff_spring_N / FJ;
                Fd[dyn][ik][iv] = res->detach_force_N / FJ;
                fprintf(c, "%s,%g,%g,%.10g,%.10g,%.10g,%.10g\n", dyn ? "brownian" : "langevin", kl[ik], vl[iv],
                        F0[dyn][ik][iv], Fd[dyn][ik][iv], q.F_star / q.F_jkr, q.F_det / q.F_jkr);
            }
            s_run_free(&r);
        }
    fclose(c);

    /* time-step bias, measured: the slowest and fastest speeds again at a quarter of the step */
    double bias[2][2][2]; /* dyn, (slow, fast), (F0, Fdet) — relative to F_JKR */
    double vb[2] = { vl[0], vl[nv - 1] };
    for (int dyn = 0; dyn < 2; ++dyn)
        for (int j = 0; j < 2; ++j) {
            s_run r;
            memset(&r, 0, sizeof r);
            s_fig4_scene(&r.base, dyn, vb[j]);
            r.base.T_K = 0.0;
            r.base.omega_dt *= 0.25;
            vafm_scale sc = vafm_units_scale(&r.base);
            r.k[0] = kl[0] * sc.stiffness_N_per_m;
            r.nk = 1;
            r.v = r.base.v_retract_m_per_s;
            r.N = 1;
            if (s_path(r.file, ctx->out, "athermal-%s-v%g-dt4.h5", dyn ? "brownian" : "langevin", vb[j]) ||
                s_campaign(ctx, &r))
                return 1;
            vafm_quasistatic q;
            vafm_theory_quasistatic(gamma, kl[0], &q);
            double FJ = q.F_jkr * sc.force_N;
            size_t iv = j ? nv - 1 : 0;
            bias[dyn][j][0] = F0[dyn][0][iv] - r.truth[0].result.pulloff_spring_N / FJ;
            bias[dyn][j][1] = Fd[dyn][0][iv] - r.truth[0].result.detach_force_N / FJ;
            s_run_free(&r);
        }

    /* damping-frame check: Brownian with the contact friction relative to the sample (lab) instead of
     * the support: ζ_ela = 0.01 (support frame, m̃ = 0.01) + ζ_cont = 0.99 (eta_cont, lab frame), so ζ = 1
     * in contact as in the Brownian runs above. Fast speeds only (out of contact ζ = 0.01 makes the step
     * small, and the frame matters only where ζ·ṽ is not negligible). */
    const double vf[3] = { 0.05, 0.2, 0.5 };
    double Flab[2][3];
    for (int j = 0; j < 3; ++j) {
        s_run r;
        memset(&r, 0, sizeof r);
        s_fig4_scene(&r.base, 1, vf[j]);
        r.base.T_K = 0.0;
        vafm_reduced rd;
        vafm_units_reduce(&r.base, &rd);
        rd.m = 0.01;
        rd.eta_cont = 99.0;
        vafm_units_from_reduced(&r.base, &rd);
        vafm_scale sc = vafm_units_scale(&r.base);
        r.k[0] = kl[0] * sc.stiffness_N_per_m;
        r.k[1] = kl[nk - 1] * sc.stiffness_N_per_m;
        r.nk = 2;
        r.v = r.base.v_retract_m_per_s;
        r.N = 1;
        if (s_path(r.file, ctx->out, "athermal-brownian-labframe-v%g.h5", vf[j]) || s_campaign(ctx, &r))
            return 1;
        for (int ik = 0; ik < 2; ++ik) {
            vafm_quasistatic q;
            vafm_theory_quasistatic(gamma, ik ? kl[nk - 1] : kl[0], &q);
            Flab[ik][j] = r.truth[ik].result.pulloff_spring_N / (q.F_jkr * sc.force_N);
        }
        s_run_free(&r);
    }

    FILE *f = NULL;
    if (s_path(path, ctx->out, "athermal_fits.csv") || !(f = s_open(path)))
        return 1;
    fprintf(f, "dynamics,k,v0,se_v0,alpha0,se_alpha0,beta0,se_beta0,c,se_c,onset_only,rms_residual,converged\n");
    FILE *o = ctx->rep;
    fprintf(o, "## Athermal pull-off force against speed (paper Fig. 4, Eq. 14)\n\n");
    fprintf(o, "Scene: γ̃ = 0.229, T = 0, k̃ ∈ {%s}, ṽ ∈ {", ctx->quick ? "0.1, 0.8" : "0.1, 0.2, 0.4, 0.8");
    for (size_t i = 0; i < nv; ++i)
        fprintf(o, "%s%g", i ? ", " : "", vl[i]);
    fprintf(o, "}; Langevin m̃ = 0.01 (gjf, ω·dt = 0.6) and Brownian ζ = mη = 1 (Euler, the paper's Eq. 12, "
               "K·dt/ζ = 2π/40). One curve per point (deterministic at T = 0). Retract only, from an equilibrium "
               "start 1 R pressed in (see the numerics note).\n\n");
    fprintf(o, "**Observable.** F̃₀ = `pulloff_spring_N`, the most tensile spring force of any step (the paper's "
               "definition; it tends to F_JKR for every k as ṽ → 0, as the paper's Eq. 14 requires). "
               "`detach_force_N` (spring force when contact is lost) is tabulated beside it; it tends to the "
               "quasi-static F_det < F_JKR instead.\n\n");
    fprintf(o, "| dynamics | k̃ | ṽ | F̃₀/F_JKR | F_detach/F_JKR | theory: F_JKR (max tensile) | F*/F_JKR | F_det/F_JKR |\n"
               "|---|---|---|---|---|---|---|---|\n");
    for (int dyn = 0; dyn < 2; ++dyn)
        for (size_t ik = 0; ik < nk; ++ik) {
            vafm_quasistatic q;
            vafm_theory_quasistatic(gamma, kl[ik], &q);
            for (size_t iv = 0; iv < nv; ++iv)
                fprintf(o, "| %s | %g | %g | %.6f | %.6f | 1 | %.6f | %.6f |\n", dyn ? "Brownian" : "Langevin", kl[ik],
                        vl[iv], F0[dyn][ik][iv], Fd[dyn][ik][iv], q.F_star / q.F_jkr, q.F_det / q.F_jkr);
        }
    fprintf(o, "\n**Eq. 14 fits** F̃₀ = F_JKR{1 + (ṽ/v₀)^α₀}^β₀, unweighted nonlinear least squares (GSL "
               "Levenberg–Marquardt from a grid start; the data are deterministic, so the errors are the "
               "covariance scaled by the residual variance: they measure how well Eq. 14 describes the points, "
               "not noise). Where the fit puts v₀ beyond 10× the fastest speed, the data show only the onset "
               "of Eq. 14, {1 + (ṽ/v₀)^α₀}^β₀ → exp(c·ṽ^α₀) with c = β₀v₀^−α₀: v₀ and β₀ are then not "
               "separately determined (a flat valley of χ²), and the onset form is fitted instead (marked "
               "\"onset only\").\n\n| dynamics | k̃ | v₀ | α₀ | β₀ | c = β₀v₀^−α₀ | rms residual (F_JKR) | fit |\n"
               "|---|---|---|---|---|---|---|---|\n");
    int all_conv = 1;
    double beta[2][4], cc[2][4];
    int onset[2][4];
    for (int dyn = 0; dyn < 2; ++dyn)
        for (size_t ik = 0; ik < nk; ++ik) {
            vafm_fit_nls fit;
            int ok = vafm_fit_eq14(vl, F0[dyn][ik], NULL, nv, &fit) == 0;
            all_conv &= ok;
            double rms = sqrt(fit.chi2_dof * fit.dof / nv);
            onset[dyn][ik] = fit.onset;
            if (fit.onset) {
                beta[dyn][ik] = NAN;
                cc[dyn][ik] = fit.p[0];
                fprintf(f, "%s,%g,nan,nan,%.8g,%.3g,nan,nan,%.8g,%.3g,1,%.3g,%d\n", dyn ? "brownian" : "langevin", kl[ik],
                        fit.p[1], fit.se[1], fit.p[0], fit.se[0], rms, ok);
                fprintf(o, "| %s | %g | not determined | %.4g ± %.2g | not determined | %.4g ± %.2g | %.2g | %s (onset only) |\n",
                        dyn ? "Brownian" : "Langevin", kl[ik], fit.p[1], fit.se[1], fit.p[0], fit.se[0], rms,
                        ok ? "converged" : "**not converged**");
            } else {
                beta[dyn][ik] = fit.p[2];
                cc[dyn][ik] = fit.p[2] * pow(fit.p[0], -fit.p[1]);
                fprintf(f, "%s,%g,%.8g,%.3g,%.8g,%.3g,%.8g,%.3g,%.8g,nan,0,%.3g,%d\n", dyn ? "brownian" : "langevin", kl[ik],
                        fit.p[0], fit.se[0], fit.p[1], fit.se[1], fit.p[2], fit.se[2], cc[dyn][ik], rms, ok);
                fprintf(o, "| %s | %g | %.4g ± %.2g | %.4g ± %.2g | %.4g ± %.2g | %.4g | %.2g | %s |\n",
                        dyn ? "Brownian" : "Langevin", kl[ik], fit.p[0], fit.se[0], fit.p[1], fit.se[1], fit.p[2],
                        fit.se[2], cc[dyn][ik], rms, ok ? "converged" : "**not converged**");
            }
        }
    fclose(f);
    fprintf(o, "\n**Paper comparison.** The paper: β₀ falls from 0.134 at k̃ = 0.8 to 0.005 at k̃ = 0.1 (Langevin), "
               "similarly for Brownian dynamics, and F̃₀ rises with speed in both. Here: ");
    for (int dyn = 0; dyn < 2; ++dyn)
        for (size_t ik = 0; ik < nk; ik += nk - 1) {
            if (onset[dyn][ik])
                fprintf(o, "%s k̃ = %g: β₀ not determined (onset only, c = %.3g); ", dyn ? "Brownian" : "Langevin", kl[ik],
                        cc[dyn][ik]);
            else
                fprintf(o, "%s k̃ = %g: β₀ = %.3g; ", dyn ? "Brownian" : "Langevin", kl[ik], beta[dyn][ik]);
        }
    double rise[2][2];
    for (int dyn = 0; dyn < 2; ++dyn)
        for (int j = 0; j < 2; ++j)
            rise[dyn][j] = F0[dyn][j ? nk - 1 : 0][nv - 1] - 1.0;
    if (!onset[0][0])
        fprintf(o, "At k̃ = %g (Langevin) β₀ = %.3g is of the order of the paper's 0.005; ", kl[0], beta[0][0]);
    fprintf(o, "F̃₀/F_JKR − 1 at ṽ = %g: Langevin %+.4f (k̃ = %g), %+.4f (k̃ = %g); Brownian %+.4f, %+.4f.\n\n",
            vl[nv - 1], rise[0][0], kl[0], rise[0][1], kl[nk - 1], rise[1][0], rise[1][1]);
    fprintf(o, "Differences and their causes, with the evidence in the table: (1) **Langevin**: F̃₀ rises by less "
               "than 1%% up to ṽ = 0.5 at every stiffness, so the paper's large β₀ at k̃ = 0.8 is not reproduced. "
               "The friction on the body is ζ·(relative speed) with ζ = mη = 0.01, i.e. ≤ 0.005 F̃ units at ṽ = 0.5, "
               "against F_JKR = 1.08: a drag that small cannot produce the rise a β₀ of 0.134 implies (with v₀ "
               "inside the speed range, of order 10%% by ṽ = 0.5); only inertia contributes (the rise grows like ṽ^α₀ with α₀ ≈ 1.3–1.9). "
               "(2) **Brownian** (ζ = 1): F̃₀ *falls* with speed. The damping frame is the cause: the physics notes "
               "settle the paper's Eq. 1 as friction relative to the spring support, ζ(v_body − v_spr), so at "
               "speed ṽ the friction pulls the nearly stuck body along with up to ζ·ṽ = %.2g F_JKR (at ṽ = %g) "
               "and the spring needs less extension to break the contact. Check (measured, the same ζ = 1 in "
               "contact but 99%% of it relative to the sample, via `eta_cont`): F̃₀/F_JKR = %.4f, %.4f, %.4f at "
               "ṽ = 0.05, 0.2, 0.5 (k̃ = %g) and %.4f, %.4f, %.4f (k̃ = %g): the fall turns into a rise that is "
               "larger for the stiffer spring, the paper's trend. So the paper's Brownian results are consistent "
               "with friction relative to the sample, not to the support as its Eq. 1 is written (vafm follows "
               "the equation). For Langevin (ζ = 0.01) the frame cannot matter at these speeds, and the paper's "
               "large β₀ there stays unexplained by anything tested here. (3) The detachment force (`detach_force_N`) rises with "
               "speed in both dynamics (the body is still being pulled while it slides to u_min), but it tends "
               "to F_det < F_JKR, not to F_JKR as Eq. 14 requires. (4) Protocol: retract only from an "
               "equilibrium start; the start is ≥ 4 relaxation times before the pull-off at every speed. (5) Time "
               "step: measured below, far smaller than the differences.\n\n",
            vl[nv - 1] / 1.0791, vl[nv - 1], Flab[0][0], Flab[0][1], Flab[0][2], kl[0], Flab[1][0], Flab[1][1],
            Flab[1][2], kl[nk - 1]);
    fprintf(o, "**Time-step bias (measured).** The same k̃ = %g point rerun at a quarter of the step: "
               "F̃₀ changes by %.2g (ṽ = %g) and %.2g (ṽ = %g) F_JKR for Langevin, %.2g and %.2g for Brownian; "
               "the detachment force by %.2g, %.2g (Langevin) and %.2g, %.2g (Brownian) F_JKR.\n\n",
            kl[0], bias[0][0][0], vb[0], bias[0][1][0], vb[1], bias[1][0][0], bias[1][1][0], bias[0][0][1],
            bias[0][1][1], bias[1][0][1], bias[1][1][1]);
    fprintf(o, "Fits converged: %s.\n\n", all_conv ? "all" : "**not all**");
    return all_conv ? 0 : 4;
}

/* ---- velocity, thermal ------------------------------------------------------------------------------- */

static int s_velocity_thermal(s_ctx *ctx)
{
    const double kT_full[] = { 0.003, 0.01, 0.03 }, kT_quick[] = { 0.01 };
    const double *kTl = ctx->quick ? kT_quick : kT_full, *vl = ctx->quick ? s_vt_quick : s_v_full;
    size_t nT = ctx->quick ? 1 : 3, nv = ctx->quick ? 7 : 11;
    const double gamma = 0.229, k = 0.1;
    uint64_t N = ctx->n_override ? ctx->n_override : ctx->quick ? 8 : 200;
    vafm_quasistatic q;
    vafm_theory_quasistatic(gamma, k, &q);
    char path[S_PATH_LEN];
    FILE *c = NULL;
    if (s_path(path, ctx->out, "thermal.csv") || !(c = s_open(path)))
        return 1;
    fprintf(c, "dynamics,kT,v,n,F0_spring,Fp_spring,se_Fp_spring,Ft_spring,F0_detach,Fp_detach,se_Fp_detach,Ft_detach,"
               "y_mean,se_y,mfpt_y,mfpt_sd_y,mfpt_F_detach,dhs_y\n");
    FILE *o = ctx->rep;
    fprintf(o, "## Thermal reduction against speed (paper Figs. 5 and 6, Eq. 15)\n\n");
    fprintf(o, "Scene: γ̃ = 0.229, k̃ = 0.1, k_BT̃ ∈ {");
    for (size_t i = 0; i < nT; ++i)
        fprintf(o, "%s%g", i ? ", " : "", kTl[i]);
    fprintf(o, "}, N = %" PRIu64 " curves per point, ṽ as in the table; Langevin m̃ = 0.01 (gjf, ω·dt = 0.6) "
               "and Brownian ζ = 1. F̃_t = F̃₀ − F̃_p (Eq. 13) with F̃₀ from a T = 0 curve at the same speed.\n\n",
            N);
    fprintf(o, "**Observables.** The paper's F̃_p is the most tensile spring force (`pulloff_spring_N`): F̃_t(spring) "
               "below. With noise this maximum is biased upward at k̃ = 0.1 (physics notes: +2–3%% of F_JKR) — "
               "the maximum of a noisy signal, not a property of the escape — so the reduction is also given for "
               "the ground truth at detachment (`detach_force_N`): F̃_t(detach), which the rate theories predict. "
               "ȳ is the spring position at detachment past the quasi-static instability (u_spr − u_spr*, > 0: "
               "before it), from `detach_height_m`.\n\n");
    fprintf(o, "Theory beside every point: the exact 1D MFPT rate (overdamped, ζ = mη = 0.01 Langevin / 1 Brownian; "
               "for Langevin times Kramers' spatial-diffusion factor for the mass) integrated along the pull, and "
               "DHS; both give y at escape, hence the detachment force F_det − k·y. Both include the shift ζṽ/k "
               "of the support-frame friction (the pull adds a force ζṽ on the body; physics notes, Eq. 1), "
               "which dominates for Brownian dynamics at fast speeds. MFPT F̃_t(detach) = F̃₀(detach, simulated "
               "at T = 0) − MFPT ⟨F_detach⟩.\n\n");
    fprintf(o, "| dyn | k_BT̃ | ṽ | n | F̃_p(spring)/F_JKR | F̃_t(spring) | F̃_t(detach) | ȳ ± se | MFPT ȳ ± sd | "
               "DHS ȳ | MFPT F̃_t(detach) |\n|---|---|---|---|---|---|---|---|---|---|---|\n");
    int all_conv = 1;
    double Ft2[2][4][16], se2[2][4][16], Ft3[2][4][16], se3[2][4][16];
    double zsum[2][4] = { { 0 } }, zsq[2][4] = { { 0 } }, dbias[2] = { 0, 0 };
    int zn[2][4] = { { 0 } }, dn_[2] = { 0, 0 };
    for (int dyn = 0; dyn < 2; ++dyn) {
        for (size_t iv = 0; iv < nv; ++iv) {
            s_run r0, r;
            memset(&r0, 0, sizeof r0);
            memset(&r, 0, sizeof r);
            s_fig4_scene(&r0.base, dyn, vl[iv]);
            r0.base.T_K = 0.0;
            r0.v = r0.base.v_retract_m_per_s;
            r0.N = 1;
            s_fig4_scene(&r.base, dyn, vl[iv]);
            for (size_t i = 0; i < nT; ++i)
                r.T[i] = s_kT_to_K(&r.base, kTl[i]);
            r.nT = nT;
            r.v = r.base.v_retract_m_per_s;
            r.N = N;
            if (s_path(r0.file, ctx->out, "thermal-%s-v%g-T0.h5", dyn ? "brownian" : "langevin", vl[iv]) ||
                s_path(r.file, ctx->out, "thermal-%s-v%g.h5", dyn ? "brownian" : "langevin", vl[iv]) ||
                s_campaign(ctx, &r0)) {
                fclose(c);
                return 1;
            }
            if (s_campaign(ctx, &r)) {
                s_run_free(&r0);
                fclose(c);
                return 1;
            }
            vafm_scale sc = vafm_units_scale(&r.base);
            double FJ = q.F_jkr * sc.force_N;
            double F0s = r0.truth[0].result.pulloff_spring_N / FJ, F0d = r0.truth[0].result.detach_force_N / FJ;
            double *x = malloc(N * sizeof *x);
            if (!x) {
                vafm_cli_error("study: out of memory");
                s_run_free(&r0);
                s_run_free(&r);
                fclose(c);
                return 1;
            }
            for (size_t it = 0; it < nT; ++it) {
                size_t n = s_collect(&r, it, VAFM_OBS_PULLOFF_SPRING, 1.0 / FJ, x);
                s_stat s2 = s_stats(x, n);
                s_stat s3 = s_stats(x, s_collect(&r, it, VAFM_OBS_DETACH_FORCE, 1.0 / FJ, x));
                n = s_collect(&r, it, VAFM_OBS_DETACH_HEIGHT, 1.0 / sc.length_m, x);
                for (size_t i = 0; i < n; ++i)
                    x[i] = -x[i] - q.u_spr_star; /* y = u_spr − u_spr*, u_spr = −height */
                s_stat sy = s_stats(x, n);
                double zeta = dyn ? 1.0 : 0.01;
                vafm_theory_pull tp;
                int ok = vafm_theory_mfpt_pull(gamma, k, kTl[it], zeta, dyn ? 0.0 : 0.01, 0.0, &vl[iv], 1, &tp) == 0;
                double yd = vafm_theory_dhs_mean_y(&q, k, kTl[it], vl[iv], zeta) + zeta * vl[iv] / k;
                if (!(s2.se >= ctx->min_se))
                    ctx->min_se = s2.se;
                Ft2[dyn][it][iv] = F0s - s2.mean;
                se2[dyn][it][iv] = s2.se;
                Ft3[dyn][it][iv] = F0d - s3.mean;
                se3[dyn][it][iv] = s3.se;
                double mF = ok ? F0d - tp.mean_F / q.F_jkr : NAN;
                if (ok && vl[iv] <= 1e-2 && sy.se > 0.0) { /* slow pulls: where the adiabatic theory should hold */
                    double z = (sy.mean - tp.mean_y) / sy.se;
                    zsum[dyn][it] += z;
                    zsq[dyn][it] += z * z;
                    zn[dyn][it]++;
                }
                dbias[dyn] += (F0s - s2.mean) - (F0d - s3.mean);
                dn_[dyn]++;
                fprintf(c, "%s,%g,%g,%zu,%.8g,%.8g,%.3g,%.8g,%.8g,%.8g,%.3g,%.8g,%.6g,%.3g,%.6g,%.6g,%.8g,%.6g\n",
                        dyn ? "brownian" : "langevin", kTl[it], vl[iv], n, F0s, s2.mean, s2.se, F0s - s2.mean, F0d,
                        s3.mean, s3.se, F0d - s3.mean, sy.mean, sy.se, tp.mean_y, tp.sd_y, tp.mean_F / q.F_jkr, yd);
                fprintf(o, "| %s | %g | %g | %zu | %.4f ± %.4f | %.4f | %.4f ± %.4f | %.4f ± %.4f | %.4f ± %.4f | %.4f | %.4f |\n",
                        dyn ? "BD" : "LD", kTl[it], vl[iv], n, s2.mean, s2.se, F0s - s2.mean, F0d - s3.mean, s3.se,
                        sy.mean, sy.se, tp.mean_y, tp.sd_y, yd, mF);
            }
            free(x);
            s_run_free(&r0);
            s_run_free(&r);
        }
    }
    fclose(c);
    FILE *f = NULL;
    if (s_path(path, ctx->out, "thermal_fits.csv") || !(f = s_open(path)))
        return 1;
    fprintf(f, "dynamics,kT,observable,xi,se_xi,alpha_t,se_alpha_t,v_t,se_v_t,beta_t,se_beta_t,log_a,se_log_a,log_b,"
               "se_log_b,log_only,chi2_dof,converged\n");
    fprintf(o, "\n**Eq. 15 fits** F̃_t = ξ{1 + α_t exp[−(ṽ/v_t)^β_t]}, weighted by the standard errors of the "
               "means (GSL Levenberg–Marquardt from a grid start). Where the fit does not converge, puts v_t more "
               "than 3 decades outside the speeds, or leaves a parameter with a relative error above 10, the "
               "data show only the logarithmic middle of Eq. 15 (small β_t), where its four parameters are not "
               "separately determined; then F̃_t = a + b·ln ṽ is fitted instead (\"log only\"; DHS predicts "
               "F̃_t ∝ (ln Λ)^{2/3}, close to linear in ln ṽ over a few decades).\n\n"
               "| dyn | k_BT̃ | observable | ξ | α_t | v_t | β_t | a | b | χ²/dof | fit |\n"
               "|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (int dyn = 0; dyn < 2; ++dyn)
        for (size_t it = 0; it < nT; ++it)
            for (int ob = 0; ob < 2; ++ob) {
                vafm_fit_nls fit;
                double *y = ob ? Ft3[dyn][it] : Ft2[dyn][it], *sg = ob ? se3[dyn][it] : se2[dyn][it], sgc[16];
                for (size_t i = 0; i < nv; ++i)
                    sgc[i] = fmax(sg[i], 1e-6); /* a point with zero spread (n = 1) would get infinite weight */
                int ok = vafm_fit_eq15(vl, y, sgc, nv, &fit) == 0;
                all_conv &= ok;
                const char *on = ob ? "detach" : "spring";
                const char *dn = dyn ? "brownian" : "langevin";
                if (fit.onset) {
                    fprintf(f, "%s,%g,%s,nan,nan,nan,nan,nan,nan,nan,nan,%.8g,%.3g,%.8g,%.3g,1,%.3g,%d\n", dn, kTl[it], on,
                            fit.p[0], fit.se[0], fit.p[1], fit.se[1], fit.chi2_dof, ok);
                    fprintf(o, "| %s | %g | %s | – | – | – | – | %.4g ± %.2g | %.4g ± %.2g | %.3g | %s (log only) |\n",
                            dyn ? "BD" : "LD", kTl[it], on, fit.p[0], fit.se[0], fit.p[1], fit.se[1], fit.chi2_dof,
                            ok ? "converged" : "**not converged**");
                } else {
                    fprintf(f, "%s,%g,%s,%.8g,%.3g,%.8g,%.3g,%.8g,%.3g,%.8g,%.3g,nan,nan,nan,nan,0,%.3g,%d\n", dn, kTl[it],
                            on, fit.p[0], fit.se[0], fit.p[1], fit.se[1], fit.p[2], fit.se[2], fit.p[3], fit.se[3],
                            fit.chi2_dof, ok);
                    fprintf(o, "| %s | %g | %s | %.4g ± %.2g | %.4g ± %.2g | %.4g ± %.2g | %.4g ± %.2g | – | – | %.3g | %s |\n",
                            dyn ? "BD" : "LD", kTl[it], on, fit.p[0], fit.se[0], fit.p[1], fit.se[1], fit.p[2],
                            fit.se[2], fit.p[3], fit.se[3], fit.chi2_dof, ok ? "converged" : "**not converged**");
                }
            }
    fclose(f);
    fprintf(o, "\n**Theory against simulation.** Slow pulls (ṽ ≤ 0.01), spring position at detachment, "
               "z = (ȳ_sim − ȳ_MFPT)/se (agreement within the statistics: mean ≈ 0, rms ≈ 1):");
    for (int dyn = 0; dyn < 2; ++dyn)
        for (size_t it = 0; it < nT; ++it)
            if (zn[dyn][it])
                fprintf(o, " %s k_BT̃ = %g: mean %+.2f, rms %.2f (%d points);", dyn ? "Brownian" : "Langevin", kTl[it],
                        zsum[dyn][it] / zn[dyn][it], sqrt(zsq[dyn][it] / zn[dyn][it]), zn[dyn][it]);
    /* the barrier top reaches the branch end u_min (F there = −(5/9)F_JKR) for y above this */
    double y_clip = (q.F_det - (5.0 / 9.0) * q.F_jkr) / k;
    fprintf(o, " Where the Langevin rms is large the MFPT rate overestimates escape (ȳ_MFPT > ȳ_sim). The cause: "
               "for y > %.3g (k̃ = %g) the barrier top is no longer inside the branch but at its end u_min "
               "(where the contact force is −(5/9)F_JKR), so there is no barrier curvature, Kramers' "
               "spatial-diffusion factor is undefined and the rate stays the overdamped one (factor 1), which "
               "overestimates escape for the underdamped Langevin motion (ζ = 0.01). The affected rows are "
               "those with ȳ near or above %.3g; Brownian dynamics (no inertia) is not affected.\n",
            y_clip, k, y_clip);
    fprintf(o, "Observable effect: F̃_t(spring) − F̃_t(detach) averages %+.4f (Langevin) and %+.4f (Brownian) F_JKR: "
               "the spring-force maximum of a noisy curve lies above the force at detachment (physics notes: "
               "+2–3%% of F_JKR at k̃ = 0.1), so the paper's observable understates the thermal reduction.\n",
            dn_[0] ? dbias[0] / dn_[0] : NAN, dn_[1] ? dbias[1] / dn_[1] : NAN);
    int falls = 1, rises = 1;
    for (int dyn = 0; dyn < 2; ++dyn)
        for (size_t it = 0; it < nT; ++it) {
            if (!(Ft2[dyn][it][nv - 1] < Ft2[dyn][it][0]))
                falls = 0;
            if (it && !(Ft2[dyn][it][0] > Ft2[dyn][it - 1][0]))
                rises = 0;
        }
    fprintf(o, "\nMeasured against the paper's trends (F̃_t from `pulloff_spring_N`): F̃_t at ṽ = %g is %s than at "
               "ṽ = %g for every temperature and both dynamics; at ṽ = %g it %s with temperature.\n",
            vl[nv - 1], falls ? "smaller" : "**not always smaller**", vl[0], vl[0],
            nT > 1 ? (rises ? "rises monotonically" : "does **not** rise monotonically") : "(one temperature: not tested)");
    fprintf(o, "\n**Paper comparison.** The paper (Figs. 5, 6) finds F̃_t falling with speed and rising toward F̃₀ "
               "with temperature, fitted by Eq. 15; it quotes no fitted values. Both trends can be read from the "
               "table. The MFPT column is an adiabatic theory (the rate at a frozen spring, instantaneous slide "
               "to u_min): it should agree with the simulated detachment at slow speeds and high barriers, and "
               "it misses the dynamic lag at fast speeds, where F̃_t(detach) → 0 in the simulation.\n\n");
    fprintf(o, "Fits converged: %s.\n\n", all_conv ? "all" : "**not all**");
    return all_conv ? 0 : 4;
}

/* ---- hysteresis ----------------------------------------------------------------------------------------- */

static int s_hysteresis(s_ctx *ctx)
{
    s_run r;
    memset(&r, 0, sizeof r);
    vafm_preset_apply(&r.base, "paper-fig1", NULL);
    r.base.omega_dt = 0.6;
    r.v = r.base.v_retract_m_per_s;
    r.N = 1;
    char path[S_PATH_LEN];
    if (s_path(r.file, ctx->out, "hysteresis.h5") || s_path(path, ctx->out, "hysteresis.csv") ||
        !(r.samples_csv = s_open(path)))
        return 1;
    fprintf(r.samples_csv, "time_s,height_m,force_N,tip_m,segment\n");
    int rc = s_campaign(ctx, &r);
    fclose(r.samples_csv);
    if (rc)
        return 1;
    vafm_reduced red;
    vafm_units_reduce(&r.base, &red);
    vafm_scale sc = vafm_units_scale(&r.base);
    vafm_quasistatic q;
    vafm_theory_quasistatic(red.gamma, red.k, &q);
    /* the quasi-static branch, for the figure: spring force against spring position u_spr ≥ u_spr* */
    FILE *t = NULL;
    if (s_path(path, ctx->out, "hysteresis_theory.csv") || !(t = s_open(path))) {
        s_run_free(&r);
        return 1;
    }
    fprintf(t, "u_spr_over_u0,F_over_FJKR\n");
    double u0 = -q.u_spr_star; /* the paper's ũ₀: spring displacement at the athermal pull-off */
    double top = -r.base.trigger_height_m / sc.length_m;
    for (int i = 0; i <= 400; ++i) {
        double us = q.u_spr_star + (fmax(top, 0.2 * u0) - q.u_spr_star) * pow(i / 400.0, 2.0);
        double u, F;
        if (!vafm_theory_equilibrium(red.gamma, red.k, us, &u, &F))
            fprintf(t, "%.9g,%.9g\n", -us / u0, -F / q.F_jkr);
    }
    fclose(t);
    if (s_path(path, ctx->out, "hysteresis_meta.csv") || !(t = s_open(path))) {
        s_run_free(&r);
        return 1;
    }
    fprintf(t, "u0_m,F_JKR_N\n%.9g,%.9g\n", u0 * sc.length_m, q.F_jkr * sc.force_N);
    fclose(t);
    const vafm_curve_result *res = &r.truth[0].result;
    FILE *o = ctx->rep;
    double FJ = q.F_jkr * sc.force_N;
    fprintf(o, "## One loading–unloading curve (paper Fig. 1)\n\n");
    fprintf(o, "Scene: paper-fig1 at T = %.1f K (k_BT̃ = %.3g), gjf at ω·dt = 0.6, curve 0 of seed %" PRIu64
               ". Figure `hysteresis.png`: spring force F/F_JKR (the output samples, box-car filtered at 2 kHz, "
               "i.e. the user's observable) against the piezo height over ũ₀ = |u_spr*| = %.4g R (the spring "
               "position of the athermal pull-off), with the quasi-static equilibrium branch.\n\n",
            r.base.T_K, red.kT, r.base.seed, u0);
    fprintf(o, "| quantity | this curve | quasi-static theory |\n|---|---|---|\n");
    fprintf(o, "| most tensile output sample (`pulloff_sampled_N`) | %.4f nN = %.4f F_JKR | F_JKR = %.4f nN |\n",
            res->pulloff_sampled_N * 1e9, res->pulloff_sampled_N / FJ, FJ * 1e9);
    fprintf(o, "| most tensile spring force (`pulloff_spring_N`) | %.4f F_JKR | 1 |\n", res->pulloff_spring_N / FJ);
    fprintf(o, "| spring force at detachment (`detach_force_N`) | %.4f F_JKR | F_det = %.6f F_JKR |\n",
            res->detach_force_N / FJ, q.F_det / q.F_jkr);
    fprintf(o, "| piezo height at detachment / ũ₀ | %.4f | 1 |\n", res->detach_height_m / sc.length_m / u0);
    fprintf(o, "| flags | %d | 0 |\n\n", res->flags);
    fprintf(o, "**Paper comparison.** The paper's Fig. 1 shows the pull-off \"significantly reduced\" by thermal "
               "fluctuations in one such curve. Here the detachment comes at %.1f%% of F_JKR, %s.\n\n",
            100.0 * res->detach_force_N / FJ,
            res->detach_force_N / FJ < 0.95 ? "a clear thermal reduction, as in the paper"
                                            : "close to the athermal value (a single curve: see the distribution study)");
    s_run_free(&r);
    return 0;
}

/* ---- driver --------------------------------------------------------------------------------------------- */

static void s_help(FILE *o)
{
    fputs("vafm study <distribution|velocity-athermal|velocity-thermal|hysteresis> [--quick] [--out DIR]\n"
          "           [-n N] [--threads T] [--kernel NAME] [--resume] [-q]\n"
          "  Reproduce one of the paper's results: campaigns (HDF5, one file per campaign), fits with\n"
          "  errors, theory beside every point, DIR/report.md, CSV tables and PNG figures (matplotlib).\n"
          "  --quick       small grids and N (about 10-20 s each): checks the pipeline, not the physics\n"
          "  --out DIR     output directory (default study-NAME; created), at most " VAFM_CLI_XSTR(S_OUT_MAX) " bytes\n"
          "  -n N          curves per point of the thermal campaigns, 2 to " VAFM_CLI_XSTR(S_N_MAX) " (distribution: 2000,\n"
          "                quick 12; velocity-thermal: 200, quick 8); the T = 0 campaigns always run one\n"
          "  --threads T   worker threads (default 0: all cores); results do not depend on it\n"
          "  --kernel NAME auto (default), scalar, batch, batch4, batch8: as for vafm campaign (same results)\n"
          "  --resume      keep the complete curves of existing files and run the rest (same results)\n"
          "                without it, the study's files in DIR are replaced\n"
          "  -q, --quiet   no progress lines\n"
          "  Exit status: 0 ok, 1 runtime error, 2 usage error, 4 a fit did not converge (report written).\n",
          o);
}

int vafm_cmd_study(int argc, char **argv)
{
    s_ctx ctx;
    memset(&ctx, 0, sizeof ctx);
    for (int i = 1; i < argc; ++i) {
        const char *a = argv[i];
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            s_help(stdout);
            return 0;
        } else if (!strcmp(a, "--quick")) {
            ctx.quick = 1;
        } else if (!strcmp(a, "--resume")) {
            ctx.resume = 1;
        } else if (!strcmp(a, "-q") || !strcmp(a, "--quiet")) {
            ctx.quiet = 1;
        } else if ((!strcmp(a, "--out") || !strcmp(a, "-o")) && i + 1 < argc) {
            ctx.out = argv[++i];
        } else if (!strcmp(a, "-n") && i + 1 < argc) {
            char *end;
            errno = 0;
            long long n = strtoll(argv[++i], &end, 10);
            if (end == argv[i] || *end || errno == ERANGE || n < 2 || n > (long long)S_N_MAX) {
                vafm_cli_error("study: -n: '%s' is not a curve count in [2, %d] (every curve's results are kept in "
                               "memory: at most %d curves per point)", argv[i], S_N_MAX, S_N_MAX);
                return 2;
            }
            ctx.n_override = (uint64_t)n;
        } else if (!strcmp(a, "--threads") && i + 1 < argc) {
            char *end;
            long t = strtol(argv[++i], &end, 10);
            if (*end || t < 0 || t > 1024) {
                fprintf(stderr, "vafm study: --threads: '%s' is not a thread count in [0, 1024]\n", argv[i]);
                return 2;
            }
            ctx.threads = (int)t;
        } else if (!strcmp(a, "--kernel") && i + 1 < argc) {
            if (vafm_campaign_kernel_parse(argv[++i], &ctx.kernel)) {
                fprintf(stderr, "vafm study: --kernel: '%s' is not a kernel (auto, scalar, batch, batch4, batch8)\n",
                        argv[i]);
                return 2;
            }
        } else if (a[0] != '-' && !ctx.name) {
            ctx.name = a;
        } else {
            fprintf(stderr, "vafm study: unknown or incomplete option '%s' (see vafm study --help)\n", a);
            return 2;
        }
    }
    int (*fn)(s_ctx *) = NULL;
    if (!ctx.name) {
        fprintf(stderr, "vafm study: a study name is required: distribution, velocity-athermal, velocity-thermal, "
                        "hysteresis (see vafm study --help)\n");
        return 2;
    }
    if (!strcmp(ctx.name, "distribution"))
        fn = s_distribution;
    else if (!strcmp(ctx.name, "velocity-athermal"))
        fn = s_velocity_athermal;
    else if (!strcmp(ctx.name, "velocity-thermal"))
        fn = s_velocity_thermal;
    else if (!strcmp(ctx.name, "hysteresis"))
        fn = s_hysteresis;
    else {
        fprintf(stderr, "vafm study: unknown study '%s' (known: distribution, velocity-athermal, velocity-thermal, "
                        "hysteresis)\n", ctx.name);
        return 2;
    }
    char defout[256];
    if (!ctx.out) {
        snprintf(defout, sizeof defout, "study-%s", ctx.name);
        ctx.out = defout;
    }
    if (strlen(ctx.out) > S_OUT_MAX) { /* its files' paths would not fit (S_OUT_MAX) */
        vafm_cli_error("study: --out: the directory name is %zu bytes; at most %d (the paths of the files in it "
                       "must fit in %d bytes)", strlen(ctx.out), S_OUT_MAX, S_PATH_LEN - 1);
        return 2;
    }
    if (mkdir(ctx.out, 0777) && errno != EEXIST) {
        fprintf(stderr, "vafm study: cannot create %s: %s\n", ctx.out, strerror(errno));
        return 1;
    }
    char path[S_PATH_LEN];
    if (s_path(path, ctx.out, "report.md"))
        return 1;
    ctx.rep = fopen(path, "w");
    if (!ctx.rep) {
        fprintf(stderr, "vafm study: cannot write %s: %s\n", path, strerror(errno));
        return 1;
    }
    ctx.cpu0 = s_cpu();
    ctx.wall0 = s_now();
    ctx.min_se = NAN;
    fprintf(ctx.rep, "# vafm study %s%s\n\n", ctx.name, ctx.quick ? " (--quick: pipeline check, small N)" : "");
    fprintf(ctx.rep, "Reproduces the paper (Zhou et al., thermal JKR pull-off) with vafm. Reduced units: η = R = E* = "
                     "k_B = 1; forces are tensile magnitudes. Numerics: Langevin with gjf at ω·dt = 0.6 (README "
                     "\"Speed and accuracy\": 3.7× cheaper than the paper's step, within 2 standard errors of the "
                     "reference), Brownian with the paper's Euler step; Gaussian noise (the paper uses uniform "
                     "noise, Eq. 7; the work–precision table finds no difference at the paper's step).\n\n");
    int rc = fn(&ctx);
    double cpu = s_cpu() - ctx.cpu0, wall = s_now() - ctx.wall0;
    if (rc != 1) {
        fprintf(ctx.rep, "## Cost and error budget\n\n");
        fprintf(ctx.rep, "Cost: %" PRIu64 " curves run (%" PRIu64 " kept from earlier files), %.3g integrator steps, "
                         "%.1f s CPU (all threads), %.1f s wall, %.2f curves/s wall, %.2f curves per CPU second; kernel %s.\n\n",
                ctx.curves_run, ctx.curves_kept, (double)ctx.steps, cpu, wall, ctx.curves_run / fmax(wall, 1e-9),
                ctx.curves_run / fmax(cpu, 1e-9), vafm_campaign_kernel_describe(&ctx.kernel));
        fprintf(ctx.rep, "Error budget: statistical errors are the standard errors quoted with each mean (sd/√n). "
                         "Time-step bias of gjf at ω·dt = 0.6, from the work–precision table (N = 2000, γ̃ = 0.229, "
                         "k̃ = 0.1, k_BT̃ = 0.01, ṽ = 1e-3): −0.1 combined standard errors, i.e. |bias| ≲ 2 × 5.7e-4 "
                         "= 1.1e-3 F_JKR on the mean pull-off force (the table cannot resolve less), KS distance "
                         "0.020 (5%% critical value 0.043). That table's scene is paper-fig4's (the velocity studies). Where a study measures "
                         "its own bias (distribution: 100 curves at a quarter step; athermal: a quarter step) it is "
                         "quoted there; the hysteresis curve has no bias measurement.%s\n",
                ctx.quick ? " With --quick's N the statistical errors dominate everything." : "");
        if (isfinite(ctx.min_se))
            fprintf(ctx.rep, "\nHere the smallest standard error of a mean force is %.2g F_JKR, %s the time-step bias "
                             "bound of 1.1e-3 F_JKR: %s.\n",
                    ctx.min_se, ctx.min_se > 2.2e-3 ? "above" : ctx.min_se > 5e-4 ? "comparable to" : "below",
                    ctx.min_se > 2.2e-3 ? "the statistical error dominates the budget"
                                        : "the time-step bias is not negligible against it; rerun a point at a "
                                          "smaller omega_dt to measure it");
        s_plot(&ctx);
    }
    fclose(ctx.rep);
    if (!ctx.quiet)
        fprintf(stderr, "vafm study %s: %s/report.md written; %.1f s CPU, %.1f s wall%s\n", ctx.name, ctx.out, cpu,
                wall, rc == 4 ? "; a fit did not converge" : "");
    return rc;
}
