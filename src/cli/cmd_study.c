/* SPDX-License-Identifier: MIT */
/*
 * `vafm study <name>`: the paper's results (issue #7) as campaigns, fits, theory, a report and figures.
 *
 * Each study is a list of campaigns (one HDF5 file each, written through the h5 library as `vafm
 * campaign` does, resumable); the per-curve ground truth is kept in memory (read back from the file on
 * resume) and reduced to tables. Fits live in study_fit.c, figures in study_plot.py (matplotlib, run
 * with /usr/bin/python3; skipped with a note when it is missing), references in theory.h.
 *
 * This file is the driver (options, the report's head and cost budget, the figures); each study is in
 * study_<name>.c, what they share in study_common.c.
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
#include "cli/study_common.h"
#include "vafm/campaign.h"

#ifndef VAFM_DATADIR_REL
#define VAFM_DATADIR_REL "../share/vafm"
#endif
#ifndef VAFM_STUDY_PLOT
#define VAFM_STUDY_PLOT "src/cli/study_plot.py"
#endif

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

static void s_plot(vafm_study_ctx *ctx)
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

/* ---- driver --------------------------------------------------------------------------------------------- */

static void s_help(FILE *o)
{
    fputs("vafm study <distribution|velocity-athermal|velocity-thermal|hysteresis> [--quick] [--out DIR]\n"
          "           [-n N] [--threads T] [--kernel NAME] [--resume] [-q]\n"
          "  Reproduce one of the paper's results: campaigns (HDF5, one file per campaign), fits with\n"
          "  errors, theory beside every point, DIR/report.md, CSV tables and PNG figures (matplotlib).\n"
          "  --quick       small grids and N (about 10-20 s each): checks the pipeline, not the physics\n"
          "  --out DIR     output directory (default study-NAME; created), at most " VAFM_CLI_XSTR(VAFM_STUDY_OUT_MAX) " bytes\n"
          "  -n N          curves per point of the thermal campaigns, 2 to " VAFM_CLI_XSTR(VAFM_STUDY_N_MAX) " (distribution: 2000,\n"
          "                quick 12; velocity-thermal: 200, quick 8); the T = 0 campaigns always run one\n"
          "  --threads T   worker threads (default 0: all cores); results do not depend on it\n",
          o);
    char names[128];
    vafm_campaign_kernel_names(names, sizeof names, ", ");
    fprintf(o, "  --kernel NAME %s (auto: the default): as for vafm campaign (same results)\n", names);
    fputs("  --resume      keep the complete curves of existing files and run the rest (same results)\n"
          "                without it, the study's files in DIR are replaced\n"
          "  -q, --quiet   no progress lines\n"
          "  Exit status: 0 ok, 1 runtime error, 2 usage error, 4 a fit did not converge (report written).\n",
          o);
}

int vafm_cmd_study(int argc, char **argv)
{
    vafm_study_ctx ctx;
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
            if (end == argv[i] || *end || errno == ERANGE || n < 2 || n > (long long)VAFM_STUDY_N_MAX) {
                vafm_cli_error("study: -n: '%s' is not a curve count in [2, %d] (every curve's results are kept in "
                               "memory: at most %d curves per point)", argv[i], VAFM_STUDY_N_MAX, VAFM_STUDY_N_MAX);
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
                char names[128];
                vafm_campaign_kernel_names(names, sizeof names, ", ");
                fprintf(stderr, "vafm study: --kernel: '%s' is not a kernel (%s)\n", argv[i], names);
                return 2;
            }
        } else if (a[0] != '-' && !ctx.name) {
            ctx.name = a;
        } else {
            fprintf(stderr, "vafm study: unknown or incomplete option '%s' (see vafm study --help)\n", a);
            return 2;
        }
    }
    int (*fn)(vafm_study_ctx *) = NULL;
    if (!ctx.name) {
        fprintf(stderr, "vafm study: a study name is required: distribution, velocity-athermal, velocity-thermal, "
                        "hysteresis (see vafm study --help)\n");
        return 2;
    }
    if (!strcmp(ctx.name, "distribution"))
        fn = vafm_study_distribution;
    else if (!strcmp(ctx.name, "velocity-athermal"))
        fn = vafm_study_velocity_athermal;
    else if (!strcmp(ctx.name, "velocity-thermal"))
        fn = vafm_study_velocity_thermal;
    else if (!strcmp(ctx.name, "hysteresis"))
        fn = vafm_study_hysteresis;
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
    if (strlen(ctx.out) > VAFM_STUDY_OUT_MAX) { /* its files' paths would not fit (VAFM_STUDY_OUT_MAX) */
        vafm_cli_error("study: --out: the directory name is %zu bytes; at most %d (the paths of the files in it "
                       "must fit in %d bytes)", strlen(ctx.out), VAFM_STUDY_OUT_MAX, VAFM_STUDY_PATH_LEN - 1);
        return 2;
    }
    if (mkdir(ctx.out, 0777) && errno != EEXIST) {
        fprintf(stderr, "vafm study: cannot create %s: %s\n", ctx.out, strerror(errno));
        return 1;
    }
    char path[VAFM_STUDY_PATH_LEN];
    if (vafm_study_path(path, ctx.out, "report.md"))
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
