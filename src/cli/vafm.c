/* SPDX-License-Identifier: MIT */
/*
 * vafm: the command-line tool. A thin layer over the library: it resolves a scene (preset, JSON scene
 * file, --NAME=VALUE overrides, in that order), runs curves through vafm_sim / vafm_campaign_run, and
 * prints what came out. No physics here: every number shown is either a library result or a unit
 * conversion of one (F_JKR = 3πγR/2 is the force unit the physics notes use). campaign, info and
 * export write and read HDF5 force-curve files through vafm/h5.h (protocol/hdf5.md).
 *
 * Exit status: 0 success, 1 runtime error (a curve failed, I/O, a damaged file), 2 usage or parameter
 * error. Every parameter error repeats the library's vafm_error message, which names the field, value
 * and range.
 */
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
#include "vafm/common.h"
#include "vafm/contact.h"
#include "vafm/h5.h"
#include "vafm/record.h"
#include "vafm/stats.h"
#include "vafm/integrator.h"
#include "vafm/params.h"
#include "vafm/sim.h"
#include "vafm/theory.h"
#include "cli/campaign_mpi.h"
#include "cli/cli_ext.h"
#include "vafm/units.h"
#include "vafm/version.h"
#include "vafm/scene.h"

enum { S_EXIT_OK = 0, S_EXIT_RUNTIME = 1, S_EXIT_USAGE = 2 };

#define S_DEFAULT_PRESET "paper-fig1"
#define S_PROGRESS_PERIOD_S 0.5
#define S_CHUNK_SAMPLES 64 /* samples per vafm_sim_advance call: progress granularity of one curve */
#define S_MAX_TOTAL_CURVES 1000000000000000ULL
#define S_MAX_CURVE_ERRORS 20 /* vafm info names at most this many unreadable curves */

/* ---- messages --------------------------------------------------------------------------------- */

#if defined(__GNUC__)
__attribute__((format(printf, 1, 2)))
#endif
static void s_error(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fputs("vafm: ", stderr);
    vfprintf(stderr, fmt, ap);
    fputc('\n', stderr);
    va_end(ap);
}

/* Exit status of a library failure: parameter problems are the user's (2), the rest are runtime (1). */
static int s_exit_of(int code)
{
    return code == VAFM_EINVAL || code == VAFM_EUNSTABLE || code == VAFM_ENOTFOUND || code == VAFM_EFORMAT
               ? S_EXIT_USAGE
               : S_EXIT_RUNTIME;
}

static double s_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* ---- options ---------------------------------------------------------------------------------- */

enum s_opt {
    O_HELP, O_VERSION, O_QUIET, O_PROGRESS, O_PRESET, O_SCENE, O_INDEX, O_N, O_THREADS, O_FIRST, O_CSV,
    O_T, O_V, O_K, O_JSON, O_TUNE, O_OUT, O_RESUME, O_OVERWRITE, O_FLUSH, O_GZIP, O_CURVE, O_MPI, S_NOPT
};

typedef struct s_option {
    const char *name;  /* long form */
    const char *alias; /* short form, or NULL */
    int has_value;
} s_option;

static const s_option s_options[S_NOPT] = {
    [O_HELP] = { "--help", "-h", 0 },       [O_VERSION] = { "--version", NULL, 0 },
    [O_QUIET] = { "--quiet", "-q", 0 },     [O_PROGRESS] = { "--progress", NULL, 0 },
    [O_PRESET] = { "--preset", NULL, 1 },   [O_SCENE] = { "--scene", NULL, 1 },
    [O_INDEX] = { "--index", NULL, 1 },     [O_N] = { "-n", NULL, 1 },
    [O_THREADS] = { "--threads", NULL, 1 }, [O_FIRST] = { "--first", NULL, 1 },
    [O_CSV] = { "--csv", NULL, 1 },         [O_T] = { "--T", NULL, 1 },
    [O_V] = { "--v", NULL, 1 },             [O_K] = { "--k", NULL, 1 },
    [O_JSON] = { "--json", NULL, 0 },       [O_TUNE] = { "--tune", NULL, 0 },
    [O_OUT] = { "--out", "-o", 1 },         [O_RESUME] = { "--resume", NULL, 0 },
    [O_OVERWRITE] = { "--overwrite", NULL, 0 }, [O_FLUSH] = { "--flush-interval", NULL, 1 },
    [O_GZIP] = { "--gzip", NULL, 1 },       [O_CURVE] = { "--curve", NULL, 1 },
    [O_MPI] = { "--mpi", NULL, 0 },
};

#define M(o) (1u << (o))
#define S_GENERAL (M(O_HELP) | M(O_VERSION))
#define S_SCENE_OPTS (M(O_PRESET) | M(O_SCENE))

typedef struct s_override {
    char name[64];
    const char *value;
} s_override;

typedef struct s_command s_command;

typedef struct s_args {
    const s_command *cmd;    /* the command (NULL until named) */
    int explicit_cmd;        /* the command was named (bare `vafm` runs, `vafm --help` is the full usage) */
    int on[S_NOPT];          /* option given */
    const char *val[S_NOPT]; /* its value */
    s_override *ov;          /* parameter overrides, in order */
    int n_ov;
    const char *topic;       /* `vafm help TOPIC` */
    const char *file;        /* the FILE of `vafm info` and `vafm export` */
} s_args;

/* ---- commands (table at the end of the file) --------------------------------------------------- */

struct s_command {
    const char *name;
    int (*fn)(const s_args *a);
    unsigned opts;       /* options it accepts (M(O_*) bits) */
    int scene;           /* 1: takes scene options and parameter overrides */
    const char *summary; /* one line for the command list */
    const char *usage;   /* synopsis and option lines */
    int file;            /* 1: takes one FILE argument */
};

static const s_command *s_command_at(int i);
static const s_command *s_command_find(const char *name);

/* ---- number parsing --------------------------------------------------------------------------- */

static int s_parse_u64(const char *opt, const char *text, uint64_t lo, uint64_t hi, uint64_t *out)
{
    char *end = NULL;
    errno = 0;
    unsigned long long v = 0;
    int ok = text[0] >= '0' && text[0] <= '9';
    if (ok) {
        v = strtoull(text, &end, 10);
        ok = *end == '\0' && errno != ERANGE && v >= lo && v <= hi;
    }
    if (!ok) {
        s_error("%s: '%s' is not an integer in [%" PRIu64 ", %" PRIu64 "]", opt, text, lo, hi);
        return S_EXIT_USAGE;
    }
    *out = (uint64_t)v;
    return 0;
}

/* A comma-separated list of reals. Ranges are the library's business (campaign validation). */
static int s_parse_list(const char *opt, const char *text, double **out, size_t *n)
{
    size_t cap = 1;
    for (const char *c = text; *c; c++)
        cap += *c == ',';
    double *v = calloc(cap, sizeof *v);
    if (!v) {
        s_error("out of memory");
        return S_EXIT_RUNTIME;
    }
    const char *c = text;
    for (size_t i = 0; i < cap; i++) {
        char *end = NULL;
        v[i] = strtod(c, &end);
        if (end == c || (*end != ',' && *end != '\0')) {
            s_error("%s: '%s' is not a comma-separated list of numbers (element %zu)", opt, text, i + 1);
            free(v);
            return S_EXIT_USAGE;
        }
        c = end + (*end == ',');
    }
    *out = v;
    *n = cap;
    return 0;
}

/* ---- argument parsing ------------------------------------------------------------------------- */

static int s_find_option(const char *name, size_t len)
{
    for (int i = 0; i < S_NOPT; i++) {
        const s_option *o = &s_options[i];
        if ((strlen(o->name) == len && !strncmp(o->name, name, len)) ||
            (o->alias && strlen(o->alias) == len && !strncmp(o->alias, name, len)))
            return i;
    }
    return -1;
}

/* `--NAME=VALUE` or `--NAME VALUE` for a parameter of the table. */
static int s_parse_override(s_args *a, const char *arg, size_t len, const char *value)
{
    const char *name = arg + 2;
    size_t nlen = len - 2;
    s_override *o = &a->ov[a->n_ov];
    if (nlen >= sizeof o->name) {
        s_error("unknown option '%.*s' (see vafm --help)", (int)len, arg);
        return S_EXIT_USAGE;
    }
    memcpy(o->name, name, nlen);
    o->name[nlen] = '\0';
    if (!vafm_param_find(o->name)) {
        s_error("unknown option or parameter '%.*s' (see vafm --help for the PARAMETERS list)", (int)len, arg);
        return S_EXIT_USAGE;
    }
    if (!value) {
        s_error("parameter --%s needs a value (--%s=VALUE or --%s VALUE)", o->name, o->name, o->name);
        return S_EXIT_USAGE;
    }
    o->value = value;
    a->n_ov++;
    return 0;
}

static int s_parse_option(s_args *a, int argc, char **argv, int *i)
{
    const char *arg = argv[*i];
    const char *eq = strchr(arg, '=');
    size_t len = eq ? (size_t)(eq - arg) : strlen(arg);
    const char *inline_value = eq ? eq + 1 : NULL;
    int id = s_find_option(arg, len);
    if (id < 0) {
        if (strncmp(arg, "--", 2) != 0 || len <= 2) {
            s_error("unknown option '%s' (see vafm --help)", arg);
            return S_EXIT_USAGE;
        }
        const char *value = inline_value ? inline_value : *i + 1 < argc ? argv[++*i] : NULL;
        return s_parse_override(a, arg, len, value);
    }
    const s_option *o = &s_options[id];
    if (a->on[id] && o->has_value) {
        s_error("option %s is given twice", o->name);
        return S_EXIT_USAGE;
    }
    a->on[id] = 1;
    if (!o->has_value) {
        if (inline_value) {
            s_error("option %s takes no value", o->name);
            return S_EXIT_USAGE;
        }
        return 0;
    }
    if (!inline_value && *i + 1 >= argc) {
        s_error("option %s needs a value", o->name);
        return S_EXIT_USAGE;
    }
    a->val[id] = inline_value ? inline_value : argv[++*i];
    return 0;
}

static int s_parse_positional(s_args *a, const char *arg)
{
    if (!a->cmd) {
        a->cmd = s_command_find(arg);
        a->explicit_cmd = 1;
        if (!a->cmd) {
            s_error("unknown command '%s' (see vafm --help)", arg);
            return S_EXIT_USAGE;
        }
        return 0;
    }
    if (!strcmp(a->cmd->name, "help") && !a->topic) {
        a->topic = arg;
        return 0;
    }
    if (a->cmd->file && !a->file) {
        a->file = arg;
        return 0;
    }
    s_error("unexpected argument '%s' (see vafm --help)", arg);
    return S_EXIT_USAGE;
}

/* Every option given must belong to the command; parameter overrides only to scene commands. */
static int s_check_options(const s_args *a)
{
    const s_command *c = a->cmd;
    for (int id = 0; id < S_NOPT; id++)
        if (a->on[id] && !(c->opts & M(id)) && !(c->scene && (S_SCENE_OPTS & M(id)))) {
            s_error("option %s does not apply to `vafm %s` (see vafm %s --help)", s_options[id].name, c->name,
                    c->name);
            return S_EXIT_USAGE;
        }
    if (a->n_ov && !c->scene) {
        s_error("parameter --%s does not apply to `vafm %s`", a->ov[0].name, c->name);
        return S_EXIT_USAGE;
    }
    return 0;
}

static int s_parse_args(s_args *a, int argc, char **argv)
{
    memset(a, 0, sizeof *a);
    a->ov = calloc((size_t)argc + 1, sizeof *a->ov);
    if (!a->ov) {
        s_error("out of memory");
        return S_EXIT_RUNTIME;
    }
    for (int i = 1; i < argc; i++) {
        int r = argv[i][0] == '-' && argv[i][1] != '\0' ? s_parse_option(a, argc, argv, &i)
                                                        : s_parse_positional(a, argv[i]);
        if (r)
            return r;
    }
    if (!a->cmd)
        a->cmd = s_command_find("run");
    if (!a->cmd)
        return S_EXIT_USAGE; /* unreachable: "run" is in the table */
    return a->on[O_HELP] || a->on[O_VERSION] ? 0 : s_check_options(a);
}

/* ---- scene resolution ------------------------------------------------------------------------- */

typedef struct s_scene {
    vafm_params p;
    char preset[64]; /* the preset the scene started from */
    const char *file;
    const s_override *ov;
    int n_ov;
} s_scene;

static int s_report(const vafm_error *err, int code)
{
    s_error("%s", err->message[0] ? err->message : vafm_strerror(code));
    return s_exit_of(code);
}

/* Preset, then scene file (its own "preset" key first), then overrides in order; then validate. */
static int s_resolve_scene(const s_args *a, s_scene *sc, int validate)
{
    vafm_error err;
    memset(&err, 0, sizeof err);
    memset(sc, 0, sizeof *sc);
    const char *preset = a->val[O_PRESET] ? a->val[O_PRESET] : S_DEFAULT_PRESET;
    int r = vafm_params_preset(&sc->p, preset, &err);
    if (r)
        return s_report(&err, r);
    snprintf(sc->preset, sizeof sc->preset, "%s", preset);
    if (a->val[O_SCENE]) {
        char file_preset[64];
        sc->file = a->val[O_SCENE];
        r = vafm_scene_load_file(&sc->p, sc->file, file_preset, sizeof file_preset, &err);
        if (r) {
            s_error("%s", err.message);
            return S_EXIT_USAGE;
        }
        if (file_preset[0])
            snprintf(sc->preset, sizeof sc->preset, "%s", file_preset);
    }
    sc->ov = a->ov;
    sc->n_ov = a->n_ov;
    for (int i = 0; i < a->n_ov; i++) {
        r = vafm_params_set(&sc->p, a->ov[i].name, a->ov[i].value, &err);
        if (r)
            return s_report(&err, r);
    }
    if (validate && (r = vafm_params_validate(&sc->p, &err)) != 0)
        return s_report(&err, r);
    return 0;
}

static void s_print_provenance(FILE *o, const s_scene *sc)
{
    fprintf(o, "scene        preset %s", sc->preset);
    if (sc->file)
        fprintf(o, ", scene file %s", sc->file);
    for (int i = 0; i < sc->n_ov; i++)
        fprintf(o, "%s--%s=%s", i ? " " : ", overrides ", sc->ov[i].name, sc->ov[i].value);
    fputc('\n', o);
}

/* ---- progress --------------------------------------------------------------------------------- */

typedef struct s_progress {
    int on, tty, printed;
    double t0, last;
} s_progress;

static void s_progress_init(s_progress *pg, const s_args *a)
{
    memset(pg, 0, sizeof *pg);
    pg->tty = isatty(STDERR_FILENO);
    pg->on = !a->on[O_QUIET] && (pg->tty || a->on[O_PROGRESS]);
    pg->t0 = pg->last = s_now();
}

/* 1 when a progress line is due (at most every S_PROGRESS_PERIOD_S). */
static int s_progress_due(s_progress *pg)
{
    if (!pg->on)
        return 0;
    double t = s_now();
    if (t - pg->last < S_PROGRESS_PERIOD_S)
        return 0;
    pg->last = t;
    pg->printed = 1;
    return 1;
}

static void s_progress_line(const s_progress *pg, const char *text)
{
    /* A terminal gets one line rewritten in place; a log gets one line per report. */
    fprintf(stderr, pg->tty ? "\rvafm: %s\033[K" : "vafm: %s\n", text);
    fflush(stderr);
}

static void s_progress_end(const s_progress *pg)
{
    if (pg->printed && pg->tty)
        fputc('\n', stderr);
}

/* ---- running one scene ------------------------------------------------------------------------ */

/* Advance the running scene to its end, reporting the simulated time as progress. */
static int s_advance_all(vafm_sim *sim, vafm_sample_fn fn, void *user, s_progress *pg)
{
    int r;
    do {
        r = vafm_sim_advance(sim, S_CHUNK_SAMPLES, fn, user);
        if (r == 1 && s_progress_due(pg)) {
            vafm_curve_result now;
            vafm_sim_result(sim, &now);
            char line[128];
            double wall = s_now() - pg->t0;
            snprintf(line, sizeof line, "simulated %.4g s in %.1f s wall (%.3g x real time)", now.duration_s,
                     wall, now.duration_s / wall);
            s_progress_line(pg, line);
        }
    } while (r == 1);
    s_progress_end(pg);
    return r;
}

static int s_new_sim(const vafm_params *p, vafm_sim **sim)
{
    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = vafm_sim_new(sim, p, &err);
    return r ? s_report(&err, r) : 0;
}

/* ---- formatting ------------------------------------------------------------------------------- */

/* "   1.04921 nN        0.972268 F_JKR": SI value and the same in a reference unit (n/a where undefined). */
static void s_fmt_pair(char *buf, size_t len, double v, double si_scale, const char *si_unit, double ref,
                       const char *ref_unit)
{
    if (!isfinite(v))
        snprintf(buf, len, "%12s %-2s    %12s %-5s", "n/a", "", "n/a", "");
    else if (ref > 0)
        snprintf(buf, len, "%12.6g %-2s    %12.6g %-5s", v * si_scale, si_unit, v / ref, ref_unit);
    else
        snprintf(buf, len, "%12.6g %-2s    %12s %-5s", v * si_scale, si_unit, "n/a", "");
}

static void s_print_flags(FILE *o, int flags)
{
    if (!flags) {
        fputs("none\n", o);
        return;
    }
    const char *sep = "";
    for (int i = 0; i < VAFM_STATS_NFLAGS; i++)
        if (flags & (1 << i)) {
            const char *doc;
            const char *word = vafm_stats_flag_word(i, &doc);
            fprintf(o, "%s%s (%s)", sep, word, doc);
            sep = "; ";
        }
    fputc('\n', o);
}

static const char *s_get(const vafm_params *p, const char *name, char *buf, size_t len)
{
    if (vafm_params_get(p, name, buf, len) != 0)
        snprintf(buf, len, "?");
    return buf;
}

static void s_print_scene_si(FILE *o, const vafm_params *p)
{
    char b1[64], b2[64], b3[64];
    fprintf(o, "sample       E* = %.6g Pa, R = %.6g nm, gamma = %.6g J/m^2, contact %s\n", p->E_star_Pa,
            p->R_m * 1e9, p->gamma_J_per_m2, s_get(p, "contact", b1, sizeof b1));
    fprintf(o, "cantilever   k = %.6g N/m, m = %.6g kg, eta = %.6g 1/s, eta_cont = %.6g 1/s, T = %.6g K\n",
            p->k_N_per_m, p->m_kg, p->eta_per_s, p->eta_cont_per_s, p->T_K);
    fprintf(o, "ramp         v_approach = %.6g m/s, v_retract = %.6g m/s, start %.6g nm, ", p->v_approach_m_per_s,
            p->v_retract_m_per_s, p->start_height_m * 1e9);
    if (p->trigger == VAFM_TRIGGER_HEIGHT)
        fprintf(o, "trigger at height %.6g nm", p->trigger_height_m * 1e9);
    else
        fprintf(o, "trigger at force %.6g nN", p->setpoint_N * 1e9);
    fprintf(o, ", dwell %.6g s\n", p->dwell_s);
    fprintf(o, "output       %.6g Hz, antialias %s\n", p->sample_rate_Hz, s_get(p, "antialias", b1, sizeof b1));
    fprintf(o, "numerics     integrator %s, noise %s, free_exact %s, seed %" PRIu64 "\n",
            s_get(p, "integrator", b1, sizeof b1), s_get(p, "noise", b2, sizeof b2),
            s_get(p, "free_exact", b3, sizeof b3), p->seed);
}

static void s_print_scene_reduced(FILE *o, const vafm_params *p, double dt_s)
{
    vafm_reduced r;
    vafm_units_reduce(p, &r);
    vafm_scale u = vafm_units_scale(p);
    fprintf(o, "reduced      m~ = %.6g, k~ = %.6g, kT~ = %.6g, gamma~ = %.6g, v~ = %.6g (approach) %.6g "
               "(retract), eta_cont~ = %.6g\n",
            r.m, r.k, r.kT, r.gamma, r.v_approach, r.v_retract, r.eta_cont);
    fprintf(o, "units        length R = %.6g nm, time 1/eta = %.6g s, force E*R^2 = %.6g nN\n", u.length_m * 1e9,
            u.time_s, u.force_N * 1e9);
    fprintf(o, "time step    dt = %.6g s (%.6g /eta)\n", dt_s, dt_s / u.time_s);
}

static void s_print_observables(FILE *o, const vafm_params *p, const vafm_curve_result *res)
{
    double F_jkr = vafm_stats_f_jkr_N(p);
    char buf[96];
    fprintf(o, "pull-off     (F_JKR = 3*pi*gamma*R/2 = %.6g nN)\n", F_jkr * 1e9);
    for (int i = 0; i < VAFM_OBS_COUNT; i++) {
        const vafm_observable_info *ob = vafm_stats_observable(i);
        double v = vafm_stats_value(res, i);
        if (ob->is_force)
            s_fmt_pair(buf, sizeof buf, v, 1e9, "nN", F_jkr, "F_JKR");
        else
            s_fmt_pair(buf, sizeof buf, v, 1e9, "nm", p->R_m, "R");
        fprintf(o, "  %-19s %s   %s\n", ob->name, buf, ob->doc);
    }
}

static void s_print_quasistatic(FILE *o, const vafm_params *p, const vafm_curve_result *res)
{
    vafm_reduced r;
    vafm_units_reduce(p, &r);
    vafm_quasistatic q;
    if (p->contact != vafm_contact_jkr || p->gamma_J_per_m2 <= 0 || vafm_theory_quasistatic(r.gamma, r.k, &q) != 0) {
        fprintf(o, "quasi-static n/a (no adhesion)\n");
        return;
    }
    double F_jkr = vafm_stats_f_jkr_N(p);
    fprintf(o, "quasi-static athermal v -> 0 reference (vafm_theory_quasistatic)\n");
    fprintf(o, "  %-19s %12.6g nN    %12.8f F_JKR   contact force at the spring instability\n", "F*",
            q.F_star / q.F_jkr * F_jkr * 1e9, q.F_star / q.F_jkr);
    fprintf(o, "  %-19s %12.6g nN    %12.8f F_JKR   spring force when the body reaches u_min\n", "F_det",
            q.F_det / q.F_jkr * F_jkr * 1e9, q.F_det / q.F_jkr);
    fprintf(o, "  %-19s %12.6g nm    %12.6g R       piezo height of the instability\n", "height*",
            -q.u_spr_star * p->R_m * 1e9, -q.u_spr_star);
    if (isfinite(res->detach_force_N))
        fprintf(o, "  detach_force_N / F_det = %.6f\n", res->detach_force_N / (q.F_det / q.F_jkr * F_jkr));
}

static void s_print_run_result(FILE *o, const vafm_params *p, const vafm_curve_result *res, double wall)
{
    fprintf(o, "steps        %" PRIu64 " (contact %" PRIu64 ", exact free %" PRIu64 "), %" PRIu64 " samples\n",
            res->steps, res->steps_contact, res->steps_free, res->samples);
    fprintf(o, "curve        index %" PRIu64 ", flags: ", res->index);
    s_print_flags(o, res->flags);
    s_print_observables(o, p, res);
    s_print_quasistatic(o, p, res);
    fprintf(o, "time         simulated %.6g s, wall %.3f s, real-time factor %.4g\n", res->duration_s, wall,
            wall > 0 ? res->duration_s / wall : INFINITY);
}

/* ---- vafm run ------------------------------------------------------------------------------------ */

static int s_index_arg(const s_args *a, uint64_t *index)
{
    *index = 0;
    return a->val[O_INDEX] ? s_parse_u64("--index", a->val[O_INDEX], 0, UINT64_MAX, index) : 0;
}

/* The scene, the --index and a simulation for it: the common start of vafm run and vafm samples. */
static int s_open_sim(const s_args *a, s_scene *sc, uint64_t *index, vafm_sim **sim)
{
    int rc = s_resolve_scene(a, sc, 1);
    if (rc || (rc = s_index_arg(a, index)) != 0)
        return rc;
    return s_new_sim(&sc->p, sim);
}

static int s_cmd_run(const s_args *a)
{
    s_scene sc;
    uint64_t index;
    vafm_sim *sim = NULL;
    int rc = s_open_sim(a, &sc, &index, &sim);
    if (rc)
        return rc;
    s_print_provenance(stdout, &sc);
    s_print_scene_si(stdout, &sc.p);
    s_print_scene_reduced(stdout, &sc.p, vafm_sim_dt(sim));
    fflush(stdout);
    s_progress pg;
    s_progress_init(&pg, a);
    int r = vafm_sim_curve_begin(sim, index);
    if (!r)
        r = s_advance_all(sim, NULL, NULL, &pg);
    double wall = s_now() - pg.t0;
    vafm_curve_result res;
    vafm_sim_result(sim, &res);
    if (r) {
        const vafm_error *e = vafm_sim_error(sim);
        s_error("curve %" PRIu64 " failed after %.6g s simulated: %s", index, res.duration_s,
                e ? e->message : vafm_strerror(r));
        vafm_sim_destroy(&sim);
        return S_EXIT_RUNTIME;
    }
    vafm_sim_destroy(&sim);
    s_print_run_result(stdout, &sc.p, &res, wall);
    return S_EXIT_OK;
}

/* ---- output files ----------------------------------------------------------------------------- */

static FILE *s_open_out(const char *path)
{
    if (!path || !strcmp(path, "-"))
        return stdout;
    FILE *f = fopen(path, "w");
    if (!f)
        s_error("cannot open '%s' for writing: %s", path, strerror(errno));
    return f;
}

/* Close (or flush stdout) and report a write error. @return an exit status. */
static int s_close_out(FILE *f, const char *path, int failed)
{
    int bad = failed || ferror(f);
    if (f == stdout)
        bad |= fflush(f) != 0;
    else
        bad |= fclose(f) != 0;
    if (bad) {
        s_error("writing '%s' failed", path && strcmp(path, "-") ? path : "(stdout)");
        return S_EXIT_RUNTIME;
    }
    return S_EXIT_OK;
}

/* ---- vafm samples ------------------------------------------------------------------------------ */

static int s_write_samples(void *user, const vafm_samples *b)
{
    FILE *f = user;
    for (size_t i = 0; i < b->n; i++)
        if (fprintf(f, "%.17g,%.17g,%.17g,%.17g,%.17g,%u\n", b->time_s[i], b->height_m[i], b->deflection_m[i],
                    b->force_N[i], b->tip_m[i], (unsigned)b->segment[i]) < 0)
            return 1; /* stop: the output is broken */
    return 0;
}

static int s_cmd_samples(const s_args *a)
{
    s_scene sc;
    uint64_t index;
    vafm_sim *sim = NULL;
    int rc = s_open_sim(a, &sc, &index, &sim);
    if (rc)
        return rc;
    FILE *f = s_open_out(a->val[O_CSV]);
    if (!f) {
        vafm_sim_destroy(&sim);
        return S_EXIT_RUNTIME;
    }
    s_progress pg;
    s_progress_init(&pg, a);
    int r = a->on[O_TUNE] ? vafm_sim_tune_begin(sim, index) : vafm_sim_curve_begin(sim, index);
    int began = r == 0; /* a scene refused at the start (a tune too long) is a parameter error */
    fputs("time_s,height_m,deflection_m,force_N,tip_m,segment\n", f);
    if (!r)
        r = s_advance_all(sim, s_write_samples, f, &pg);
    rc = s_close_out(f, a->val[O_CSV], r == VAFM_EABORT);
    if (r && r != VAFM_EABORT) {
        const vafm_error *e = vafm_sim_error(sim);
        s_error("%s %" PRIu64 " failed: %s", a->on[O_TUNE] ? "tune" : "curve", index,
                e && e->message[0] ? e->message : vafm_strerror(r));
        vafm_sim_destroy(&sim);
        return began ? S_EXIT_RUNTIME : s_exit_of(r);
    }
    vafm_sim_destroy(&sim);
    return rc;
}

/* ---- vafm curves: statistics ------------------------------------------------------------------ */

static void s_print_moments_row(FILE *o, const char *name, const vafm_moments *m, double scale, const char *unit,
                                double ref, const char *ref_unit)
{
    if (m->n == 0) {
        fprintf(o, "  %-19s %6d %13s\n", name, 0, "n/a");
        return;
    }
    double sd = vafm_moments_sd(m), sem = vafm_moments_sem(m), skew = vafm_moments_skewness(m);
    fprintf(o, "  %-19s %6" PRIu64 " %13.6g %12.5g %12.5g %8.3f %-4s", name, m->n, m->mean * scale, sd * scale,
            sem * scale, skew, unit);
    if (ref > 0)
        fprintf(o, " | %11.6g %11.5g %11.5g %s", m->mean / ref, sd / ref, sem / ref, ref_unit);
    fputc('\n', o);
}

static void s_print_point(FILE *o, size_t point, const vafm_params *p, const vafm_point_stats *st)
{
    double F_jkr = vafm_stats_f_jkr_N(p);
    fprintf(o, "\npoint %zu: T = %.6g K, v = %.6g m/s, k = %.6g N/m, F_JKR = %.6g nN\n", point, p->T_K,
            p->v_retract_m_per_s, p->k_N_per_m, F_jkr * 1e9);
    fprintf(o, "  curves %" PRIu64 ", with a pull-off %" PRIu64 "; flagged:", st->curves, st->used);
    int any = 0;
    for (int i = 0; i < VAFM_STATS_NFLAGS; i++)
        if (st->flag_count[i]) {
            fprintf(o, " %s %" PRIu64, vafm_stats_flag_word(i, NULL), st->flag_count[i]);
            any = 1;
        }
    fputs(any ? "\n" : " none\n", o);
    fprintf(o, "  %-19s %6s %13s %12s %12s %8s %-4s | %11s %11s %11s\n", "observable", "n", "mean", "sd", "sem",
            "skew", "unit", "mean", "sd", "sem");
    for (int i = 0; i < VAFM_OBS_COUNT; i++) {
        const vafm_observable_info *ob = vafm_stats_observable(i);
        if (ob->is_force)
            s_print_moments_row(o, ob->name, &st->obs[i], 1e9, "nN", F_jkr, "F_JKR");
        else
            s_print_moments_row(o, ob->name, &st->obs[i], 1e9, "nm", p->R_m, "R");
    }
}

/* ---- vafm curves: the campaign ----------------------------------------------------------------- */

typedef struct s_curves {
    FILE *csv;
    vafm_point_stats *stats;
    s_progress pg;
    uint64_t done, total;
    int fail_status, io_error;
    uint64_t fail_index;
} s_curves;

static int s_csv_row(FILE *f, const vafm_campaign_curve *c)
{
    const vafm_curve_result *r = &c->result;
    const vafm_params *p = c->params;
    return fprintf(f,
                   "%" PRIu64 ",%zu,%.17g,%.17g,%.17g,%d,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,"
                   "%" PRIu64 ",%" PRIu64 ",%" PRIu64 ",%" PRIu64 ",%.17g\n",
                   c->index, c->point, p->T_K, p->v_retract_m_per_s, p->k_N_per_m, r->flags, r->pulloff_sampled_N,
                   r->pulloff_spring_N, r->detach_force_N, r->detach_height_m, r->detach_eq_force_N,
                   r->detach_time_s, r->touch_time_s, r->touch_height_m, r->retract_start_s, r->samples, r->steps,
                   r->steps_contact, r->steps_free, r->duration_s);
}

static const char s_csv_header[] =
    "index,point,T_K,v_m_per_s,k_N_per_m,flags,pulloff_sampled_N,pulloff_spring_N,detach_force_N,"
    "detach_height_m,detach_eq_force_N,detach_time_s,touch_time_s,touch_height_m,retract_start_s,samples,"
    "steps,steps_contact,steps_free,duration_s\n";

/* "done/total curves, rate, ETA" on the progress line, when one is due (vafm curves and campaign). */
static void s_progress_curves(s_progress *pg, uint64_t done, uint64_t total)
{
    if (!s_progress_due(pg))
        return;
    double wall = s_now() - pg->t0, rate = (double)done / wall;
    char line[160];
    snprintf(line, sizeof line, "%" PRIu64 "/%" PRIu64 " curves, %.3g curves/s, ETA %.0f s", done, total, rate,
             rate > 0 ? (double)(total - done) / rate : 0.0);
    s_progress_line(pg, line);
}

static void s_curves_progress(s_curves *cv)
{
    s_progress_curves(&cv->pg, cv->done, cv->total);
}

/* Called in index order, one at a time. A failed curve stops the campaign: it is a runtime error. */
static int s_on_curve(void *user, const vafm_campaign_curve *c)
{
    s_curves *cv = user;
    if (c->status) {
        cv->fail_status = c->status;
        cv->fail_index = c->index;
        return 1;
    }
    if (cv->csv && s_csv_row(cv->csv, c) < 0) {
        cv->io_error = 1;
        return 1;
    }
    vafm_point_stats_add(&cv->stats[c->point], 0, &c->result);
    cv->done++;
    s_curves_progress(cv);
    return 0;
}

typedef struct s_grid {
    vafm_campaign_spec spec;
    double *T, *v, *k;
} s_grid;

static void s_grid_free(s_grid *g)
{
    free(g->T);
    free(g->v);
    free(g->k);
}

static int s_grid_parse(const s_args *a, s_grid *g)
{
    memset(g, 0, sizeof *g);
    uint64_t N = 1, threads = 0, first = 0;
    int rc = 0;
    if (!a->val[O_N]) {
        s_error("vafm %s: -n N (curves per grid point) is required", a->cmd->name);
        return S_EXIT_USAGE;
    }
    if ((rc = s_parse_u64("-n", a->val[O_N], 1, 1000000000ULL, &N)) ||
        (a->val[O_THREADS] && (rc = s_parse_u64("--threads", a->val[O_THREADS], 0, 256, &threads))) ||
        (a->val[O_FIRST] && (rc = s_parse_u64("--first", a->val[O_FIRST], 0, UINT64_MAX, &first))) ||
        (a->val[O_T] && (rc = s_parse_list("--T", a->val[O_T], &g->T, &g->spec.n_T))) ||
        (a->val[O_V] && (rc = s_parse_list("--v", a->val[O_V], &g->v, &g->spec.n_v))) ||
        (a->val[O_K] && (rc = s_parse_list("--k", a->val[O_K], &g->k, &g->spec.n_k))))
        return rc;
    g->spec.T_K = g->T;
    g->spec.v_m_per_s = g->v;
    g->spec.k_N_per_m = g->k;
    g->spec.curves_per_point = N;
    g->spec.threads = (int)threads;
    g->spec.first_curve = first;
    size_t np = vafm_campaign_points(&g->spec);
    if ((double)np * (double)N > (double)S_MAX_TOTAL_CURVES) {
        s_error("vafm %s: %zu grid points x %" PRIu64 " curves is too many", a->cmd->name, np, N);
        return S_EXIT_USAGE;
    }
    if (first > N * np) {
        s_error("--first: %" PRIu64 " is beyond the campaign's %" PRIu64 " curves", first, N * (uint64_t)np);
        return S_EXIT_USAGE;
    }
    return 0;
}

/* The per-point statistics of a campaign (vafm curves, vafm campaign, vafm info). */
static void s_print_statistics(FILE *o, const vafm_params *base, const vafm_campaign_spec *spec,
                               const vafm_point_stats *stats)
{
    fprintf(o, "statistics   over curves with a pull-off (no-contact and no-detach curves left out); "
               "sd sample, sem = sd/sqrt(n), skew g1\n");
    size_t np = vafm_campaign_points(spec);
    for (size_t i = 0; i < np; i++) {
        vafm_params p;
        vafm_campaign_point_params(base, spec, i, &p);
        s_print_point(o, i, &p, &stats[i]);
    }
}

static void s_print_campaign_line(FILE *o, const vafm_campaign_spec *spec, uint64_t done, double wall)
{
    fprintf(o, "campaign     %zu grid point(s) x %" PRIu64 " curves, %" PRIu64 " run in %.3f s (%.4g curves/s)\n",
            vafm_campaign_points(spec), spec->curves_per_point, done, wall, wall > 0 ? (double)done / wall : 0.0);
}

static void s_print_curves_summary(FILE *o, const s_scene *sc, const s_grid *g, const s_curves *cv, double wall)
{
    s_print_provenance(o, sc);
    s_print_campaign_line(o, &g->spec, cv->done, wall);
    s_print_statistics(o, &sc->p, &g->spec, cv->stats);
}

/* With no grid lists the base scene is the only point: check it here for a plain error message
 * (the campaign's own check prefixes the grid point). */
static int s_curves_check(const s_args *a, s_scene *sc, const s_grid *g)
{
    int grid = g->spec.n_T || g->spec.n_v || g->spec.n_k;
    return s_resolve_scene(a, sc, !grid);
}

static int s_curves_finish(const s_curves *cv, int r, const vafm_error *err)
{
    if (cv->fail_status) {
        s_error("curve %" PRIu64 " failed: %s", cv->fail_index, vafm_strerror(cv->fail_status));
        return S_EXIT_RUNTIME;
    }
    if (cv->io_error)
        return S_EXIT_RUNTIME; /* reported when the file is closed */
    if (r)
        return s_report(err, r);
    return S_EXIT_OK;
}

static int s_cmd_curves(const s_args *a)
{
    s_grid g;
    s_scene sc;
    int rc = s_grid_parse(a, &g);
    if (rc || (rc = s_curves_check(a, &sc, &g)) != 0) {
        s_grid_free(&g);
        return rc;
    }
    s_curves cv;
    memset(&cv, 0, sizeof cv);
    size_t np = vafm_campaign_points(&g.spec);
    cv.total = g.spec.curves_per_point * (uint64_t)np - g.spec.first_curve;
    cv.stats = calloc(np, sizeof *cv.stats);
    if (!cv.stats) {
        s_grid_free(&g);
        s_error("out of memory");
        return S_EXIT_RUNTIME;
    }
    const char *csv_path = a->val[O_CSV];
    if (csv_path && !(cv.csv = s_open_out(csv_path))) {
        free(cv.stats);
        s_grid_free(&g);
        return S_EXIT_RUNTIME;
    }
    if (cv.csv)
        fputs(s_csv_header, cv.csv);
    s_progress_init(&cv.pg, a);
    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = vafm_campaign_run(&sc.p, &g.spec, s_on_curve, &cv, &err);
    double wall = s_now() - cv.pg.t0;
    s_progress_end(&cv.pg);
    int crc = cv.csv ? s_close_out(cv.csv, csv_path, cv.io_error) : 0;
    rc = s_curves_finish(&cv, r == VAFM_EABORT ? 0 : r, &err);
    /* The summary goes where the CSV does not. */
    int csv_stdout = csv_path && !strcmp(csv_path, "-");
    if (!rc && !crc && !(csv_stdout && a->on[O_QUIET]))
        s_print_curves_summary(csv_stdout ? stderr : stdout, &sc, &g, &cv, wall);
    free(cv.stats);
    s_grid_free(&g);
    return rc ? rc : crc;
}

/* ---- HDF5 files: shared helpers ------------------------------------------------------------------ */

/* A real option in [lo, hi]. */
static int s_parse_real(const char *opt, const char *text, double lo, double hi, const char *unit, double *out)
{
    char *end = NULL;
    double v = strtod(text, &end);
    if (end == text || *end != '\0' || !(v >= lo && v <= hi)) {
        s_error("%s: '%s' is not a number in [%g, %g]%s%s", opt, text, lo, hi, unit[0] ? " " : "", unit);
        return S_EXIT_USAGE;
    }
    *out = v;
    return 0;
}

static double s_file_mb(const char *path)
{
    struct stat st;
    return stat(path, &st) ? 0.0 : (double)st.st_size / 1e6;
}

/* Per-point statistics of every curve of a vafm file, from its ground truth, in curve order (so a
 * resumed campaign prints the same numbers as an uninterrupted one). @return curves without a row. */
static uint64_t s_truth_stats(const vafm_h5_reader *r, size_t np, vafm_point_stats *stats)
{
    uint64_t missing = 0;
    size_t n = vafm_h5_reader_count(r);
    for (uint64_t i = 0; i < n; i++) {
        vafm_h5_truth t;
        if (vafm_h5_reader_truth(r, i, &t) || t.point >= np)
            missing++;
        else
            vafm_point_stats_add(&stats[t.point], t.status, &t.result);
    }
    return missing;
}

/* ---- vafm campaign: one HDF5 file ------------------------------------------------------------------ */

/*
 * The curves reach s_camp_curve in index order, one at a time, from whichever worker finished the next
 * one, and go into the file at once through the recorder (vafm/record.h), which flushes on a timer
 * (--flush-interval) from its own thread: a kill -9 at any moment loses at most the curves of the last
 * interval; --resume recomputes exactly those.
 */

typedef struct s_camp {
    vafm_recorder *rec;
    int werr_code; /* the first recorder error */
    vafm_error werr;
    s_progress pg; /* the fields below belong to the delivering worker */
    uint64_t done, total;
    int fail_status;
    uint64_t fail_index;
} s_camp;

/* Called in index order, one at a time. A failed curve stops the campaign, as in vafm curves. */
static int s_camp_curve(void *user, const vafm_campaign_curve *c)
{
    s_camp *cp = user;
    if (c->status) {
        cp->fail_status = c->status;
        cp->fail_index = c->index;
        return 1;
    }
    vafm_record_curve rc = { .samples = &c->samples, .params = c->params, .result = &c->result,
                             .point = c->point, .sensitivity_m_per_V = NAN };
    int r = vafm_recorder_append(cp->rec, &rc, &cp->werr);
    if (r) {
        cp->werr_code = r;
        return 1;
    }
    cp->done++;
    s_progress_curves(&cp->pg, cp->done, cp->total);
    return 0;
}

/* Every grid point's scene, checked before the file is created (so a bad grid leaves no file behind). */
static int s_check_points(const vafm_params *base, const vafm_campaign_spec *spec)
{
    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = vafm_campaign_validate(base, spec, NULL, &err);
    if (r) {
        s_error("%s", err.message[0] ? err.message : vafm_strerror(r));
        return s_exit_of(r);
    }
    return 0;
}

typedef struct s_camp_opts {
    const char *out;
    int resume, overwrite, gzip;
    double interval;
    double mb_before; /* size of the file continued by --resume */
} s_camp_opts;

static int s_camp_parse(const s_args *a, s_camp_opts *o)
{
    memset(o, 0, sizeof *o);
    o->out = a->val[O_OUT];
    o->resume = a->on[O_RESUME];
    o->overwrite = a->on[O_OVERWRITE];
    o->interval = 1.0;
    uint64_t gz = 0;
    int rc = 0;
    if ((a->val[O_FLUSH] && (rc = s_parse_real("--flush-interval", a->val[O_FLUSH], 0.0,
                                               VAFM_RECORD_MAX_FLUSH_INTERVAL_S, "s", &o->interval))) ||
        (a->val[O_GZIP] && (rc = s_parse_u64("--gzip", a->val[O_GZIP], 0, 9, &gz))))
        return rc;
    o->gzip = (int)gz;
    if (!o->out) {
        s_error("vafm campaign: --out FILE.h5 (the HDF5 file to write) is required");
        return S_EXIT_USAGE;
    }
    if (o->resume && o->overwrite) {
        s_error("vafm campaign: --resume continues %s and --overwrite replaces it; give one of them", o->out);
        return S_EXIT_USAGE;
    }
    struct stat st;
    int exists = stat(o->out, &st) == 0;
    if (exists && !o->resume && !o->overwrite) {
        s_error("vafm campaign: %s exists already; --resume continues it, --overwrite replaces it", o->out);
        return S_EXIT_USAGE;
    }
    if (!exists && o->resume) {
        s_error("vafm campaign: --resume: %s cannot be resumed: %s", o->out, strerror(errno));
        return S_EXIT_USAGE;
    }
    o->mb_before = o->resume ? (double)st.st_size / 1e6 : 0.0;
    return 0;
}

/* Open (create or resume) the file and record or compare the provenance. */
static int s_camp_open(s_camp *cp, const s_camp_opts *o, const s_scene *sc, const vafm_campaign_spec *spec)
{
    vafm_recorder_opts ro;
    vafm_recorder_opts_default(&ro);
    ro.mode = o->resume ? VAFM_RECORD_RESUME : o->overwrite ? VAFM_RECORD_OVERWRITE : VAFM_RECORD_CREATE;
    ro.gzip_level = o->gzip;
    /* a flush rewrites the file's metadata: a 0 s interval still flushes from the flusher thread, as
     * soon as a curve waits, so the workers never wait on it */
    ro.flush_interval_s = o->interval > 0 ? o->interval : 1e-9;
    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = vafm_recorder_open(&cp->rec, o->out, &ro, &sc->p, spec, &err);
    return r ? s_report(&err, r) : 0;
}

static void s_camp_summary(FILE *o, const s_scene *sc, const vafm_campaign_spec *spec, const s_camp_opts *co,
                           const s_camp *cp, const vafm_recorder_report *rep, uint64_t first, double wall)
{
    uint64_t in_file = first + cp->done;
    double mb = s_file_mb(co->out);
    s_print_provenance(o, sc);
    fprintf(o, "file         %s: %" PRIu64 " curves (%" PRIu64 " kept from before, %" PRIu64 " new), %.4g MB written, "
               "%.4g MB on disk\n",
            co->out, in_file, first, cp->done, mb - co->mb_before, mb);
    s_print_campaign_line(o, spec, cp->done, wall);
    fprintf(o, "writer       %.3f s in open, append, flush and close = %.2f%% of the wall time; %" PRIu64
               " flush(es) (every %g s and at the end), %.4g MB/s\n",
            rep->writer_s, wall > 0 ? 100.0 * rep->writer_s / wall : 0.0, rep->flushes, co->interval,
            wall > 0 ? (mb - co->mb_before) / wall : 0.0);
    /* The statistics cover every curve of the file, from its ground truth. */
    vafm_h5_reader *r = NULL;
    vafm_error err;
    memset(&err, 0, sizeof err);
    size_t np = vafm_campaign_points(spec);
    vafm_point_stats *stats = calloc(np, sizeof *stats);
    if (stats && !vafm_h5_reader_open(&r, co->out, &err)) {
        s_truth_stats(r, np, stats);
        s_print_statistics(o, &sc->p, spec, stats);
    } else {
        fprintf(o, "statistics   n/a: %s\n", stats ? err.message : "out of memory");
    }
    vafm_h5_reader_destroy(&r);
    free(stats);
}

/* The file a campaign will write, estimated before anything is written (vafm_sim_estimate_cost of every
 * grid point; 41 bytes a sample: five float64 channels and the segment byte). Said on stderr; refused
 * when it cannot fit the free space of the file system (with --gzip only said: the ratio is not known). */
static int s_camp_size_check(const s_args *a, const s_camp_opts *co, const vafm_params *base,
                             const vafm_campaign_spec *spec)
{
    uint64_t have = 0;
    if (co->resume) {
        vafm_h5_reader *r = NULL;
        vafm_error e;
        if (!vafm_h5_reader_open(&r, co->out, &e))
            have = vafm_h5_reader_count(r);
        vafm_h5_reader_destroy(&r);
    }
    size_t np = vafm_campaign_points(spec);
    double bytes = 0.0, curves = 0.0;
    for (size_t i = 0; i < np; i++) {
        vafm_params p;
        vafm_sim_estimate est;
        vafm_campaign_point_params(base, spec, i, &p);
        if (vafm_sim_estimate_cost(&p, &est, NULL))
            continue;
        /* the curves of this point still to run */
        double lo = (double)i * (double)spec->curves_per_point, hi = lo + (double)spec->curves_per_point;
        double todo = hi <= (double)have ? 0.0 : hi - fmax(lo, (double)have);
        bytes += todo * est.samples * 41.0;
        curves += todo;
    }
    char dir[4096];
    snprintf(dir, sizeof dir, "%s", co->out);
    char *slash = strrchr(dir, '/');
    if (slash)
        *(slash == dir ? slash + 1 : slash) = '\0';
    else
        snprintf(dir, sizeof dir, ".");
    struct statvfs vs;
    double avail = statvfs(dir, &vs) == 0 ? (double)vs.f_bavail * (double)vs.f_frsize : INFINITY;
    if (!a->on[O_QUIET])
        fprintf(stderr, "vafm: %s: %.0f curve(s) to run, ~%.3g GB of samples uncompressed (%.3g GB free there)\n",
                co->out, curves, bytes / 1e9, avail / 1e9);
    if (bytes > avail && !co->gzip) {
        s_error("-n: the campaign would write ~%.3g GB to %s, more than the %.3g GB free on its file system; "
                "run fewer curves (-n, the grid), lower sample_rate_Hz, or compress (--gzip)", bytes / 1e9, co->out,
                avail / 1e9);
        return S_EXIT_USAGE;
    }
    return 0;
}

/* One campaign, single-process (mpi NULL) or as one MPI rank (campaign_mpi.h): the same checks, the
 * same per-curve computation and the same writer callback; MPI only changes who computes which curve.
 * Rank 0 alone touches the file; the other ranks check their scene against rank 0's, then compute. */
static int s_campaign(const s_args *a, vafm_cli_mpi *mpi)
{
    s_grid g;
    s_scene sc;
    s_camp_opts co;
    int root = vafm_cli_mpi_rank(mpi) == 0;
    int rc = s_grid_parse(a, &g);
    if (!rc && !(rc = s_curves_check(a, &sc, &g)) && !(rc = root ? s_camp_parse(a, &co) : 0))
        rc = s_check_points(&sc.p, &g.spec);
    if (!rc && root)
        rc = s_camp_size_check(a, &co, &sc.p, &g.spec);
    if ((rc = vafm_cli_mpi_agree(mpi, rc, &sc.p, &g.spec)) != 0) {
        s_grid_free(&g);
        return rc;
    }
    if (!root) {
        vafm_error werr;
        memset(&werr, 0, sizeof werr);
        g.spec.keep_samples = 1;
        if (!(rc = vafm_cli_mpi_agree(mpi, 0, NULL, NULL))) /* rank 0 opened the file */
            rc = vafm_cli_mpi_run(mpi, &sc.p, &g.spec, NULL, NULL, &werr) ? S_EXIT_RUNTIME : S_EXIT_OK;
        s_grid_free(&g);
        return rc;
    }
    s_camp cp;
    memset(&cp, 0, sizeof cp);
    s_progress_init(&cp.pg, a);
    double t_start = cp.pg.t0;
    rc = s_camp_open(&cp, &co, &sc, &g.spec);
    if (mpi && (rc = vafm_cli_mpi_agree(mpi, rc, NULL, NULL)) != 0 && cp.rec)
        vafm_recorder_close(&cp.rec, NULL, NULL);
    if (rc) {
        s_grid_free(&g);
        return rc;
    }
    uint64_t first = vafm_recorder_count(cp.rec);
    uint64_t total = g.spec.curves_per_point * (uint64_t)vafm_campaign_points(&g.spec);
    g.spec.first_curve = first < total ? first : total;
    g.spec.keep_samples = 1;
    cp.total = total - g.spec.first_curve;
    if (co.resume && !a->on[O_QUIET])
        fprintf(stderr, "vafm: %s holds %" PRIu64 " of the campaign's %" PRIu64 " curves; running the rest\n", co.out,
                first, total);

    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = mpi ? vafm_cli_mpi_run(mpi, &sc.p, &g.spec, s_camp_curve, &cp, &err)
                : vafm_campaign_run(&sc.p, &g.spec, s_camp_curve, &cp, &err);
    s_progress_end(&cp.pg);

    /* A clean close merges the ground truth into one table; the file holds every curve delivered. */
    vafm_error cerr;
    memset(&cerr, 0, sizeof cerr);
    vafm_recorder_report rep;
    int cr = vafm_recorder_close(&cp.rec, &rep, &cerr);
    double wall = s_now() - t_start;

    if (cp.fail_status) {
        s_error("curve %" PRIu64 " failed: %s; %s holds the %" PRIu64 " curve(s) before it", cp.fail_index,
                vafm_strerror(cp.fail_status), co.out, first + cp.done);
        rc = S_EXIT_RUNTIME;
    } else if (cp.werr_code) {
        s_error("%s", cp.werr.message[0] ? cp.werr.message : vafm_strerror(cp.werr_code));
        rc = S_EXIT_RUNTIME;
    } else if (r && r != VAFM_EABORT) {
        rc = s_report(&err, r);
    } else if (cr) {
        s_error("%s", cerr.message[0] ? cerr.message : vafm_strerror(cr));
        rc = S_EXIT_RUNTIME;
    }
    if (!rc) {
        s_camp_summary(stdout, &sc, &g.spec, &co, &cp, &rep, first, wall);
        vafm_cli_mpi_describe(mpi, stdout);
    }
    s_grid_free(&g);
    return rc;
}

/* MPI starts only under an MPI launcher or with --mpi: plain `vafm campaign` never touches it. */
static int s_cmd_campaign(const s_args *a)
{
    vafm_cli_mpi *mpi = NULL;
    int rc = vafm_cli_mpi_begin(a->on[O_MPI], &mpi);
    if (!rc)
        rc = s_campaign(a, mpi);
    return vafm_cli_mpi_end(&mpi, rc);
}

/* ---- vafm info ------------------------------------------------------------------------------------ */

static int s_need_file(const s_args *a)
{
    if (a->file)
        return 0;
    s_error("vafm %s: FILE (an HDF5 force-curve file) is required (see vafm %s --help)", a->cmd->name,
            a->cmd->name);
    return S_EXIT_USAGE;
}

static int s_open_reader(const char *path, vafm_h5_reader **r)
{
    vafm_error err;
    memset(&err, 0, sizeof err);
    int rc = vafm_h5_reader_open(r, path, &err);
    if (rc) {
        s_error("%s", err.message[0] ? err.message : vafm_strerror(rc));
        return S_EXIT_RUNTIME; /* not this layout, damaged, truncated: the file is at fault, not the call */
    }
    return 0;
}

/* "%12.6g" of v·scale, or "-" when absent. */
static const char *s_num(char *buf, size_t len, double v, double scale)
{
    if (isnan(v))
        snprintf(buf, len, "-");
    else
        snprintf(buf, len, "%.6g", v * scale);
    return buf;
}

static void s_print_list(FILE *o, const char *name, const double *v, size_t n, const char *unit)
{
    fprintf(o, " %s ", name);
    if (!n)
        fputs("(the scene's)", o);
    for (size_t i = 0; i < n; i++)
        fprintf(o, "%s%.6g", i ? "," : "", v[i]);
    if (n)
        fprintf(o, " %s", unit);
    fputc(';', o);
}

typedef struct s_info_prov {
    int scene_ok, grid_ok;
    vafm_params p;
    vafm_scene_grid grid;
    vafm_campaign_spec spec;
} s_info_prov;

static void s_info_provenance(FILE *o, const char *path, const vafm_h5_provenance *pv, s_info_prov *ip)
{
    memset(ip, 0, sizeof *ip);
    fprintf(o, "software     %s %s\n", pv->software, pv->software_version);
    if (!pv->is_vafm) {
        fprintf(o, "provenance   none (no root attribute 'vafm format version': not written by vafm)\n");
        return;
    }
    fprintf(o, "vafm format  %d.%d, created %s, seed %" PRIu64 ", ground truth for %zu curve(s)\n", pv->format_major,
            pv->format_minor, pv->created ? pv->created : "(unknown)", pv->seed, pv->truth_rows);
    char origin[512];
    vafm_error err;
    memset(&err, 0, sizeof err);
    if (pv->grid_json) {
        snprintf(origin, sizeof origin, "%s: root attribute 'vafm grid'", path);
        ip->grid_ok = !vafm_scene_grid_parse(pv->grid_json, origin, &ip->grid, &err);
        if (ip->grid_ok) {
            vafm_campaign_spec *sp = &ip->spec;
            sp->T_K = ip->grid.T_K;
            sp->n_T = ip->grid.n_T;
            sp->v_m_per_s = ip->grid.v_m_per_s;
            sp->n_v = ip->grid.n_v;
            sp->k_N_per_m = ip->grid.k_N_per_m;
            sp->n_k = ip->grid.n_k;
            sp->curves_per_point = ip->grid.curves_per_point;
            fprintf(o, "grid         %zu point(s) x ", vafm_campaign_points(sp));
            if (sp->curves_per_point)
                fprintf(o, "%" PRIu64 " curves = %" PRIu64 " curves;", sp->curves_per_point,
                        sp->curves_per_point * (uint64_t)vafm_campaign_points(sp));
            else
                fputs("? curves;", o);
            s_print_list(o, "T", sp->T_K, sp->n_T, "K");
            s_print_list(o, "v", sp->v_m_per_s, sp->n_v, "m/s");
            s_print_list(o, "k", sp->k_N_per_m, sp->n_k, "N/m");
            fputc('\n', o);
        } else {
            fprintf(o, "grid         cannot be read: %s\n", err.message);
        }
    }
    if (!pv->scene_json) {
        fprintf(o, "scene        (none recorded)\n");
        return;
    }
    snprintf(origin, sizeof origin, "%s: root attribute 'vafm scene'", path);
    vafm_params_default(&ip->p);
    ip->scene_ok = !vafm_scene_parse(&ip->p, pv->scene_json, origin, &err);
    if (ip->scene_ok) {
        fprintf(o, "scene        as stored in the file (vafm info --json prints all of it as a --scene file)\n");
        s_print_scene_si(o, &ip->p);
    } else {
        fprintf(o, "scene        cannot be read: %s\n", err.message);
    }
}

static void s_info_curve_line(FILE *o, const vafm_h5_curve *c, const vafm_h5_reader *r, int is_vafm)
{
    size_t nseg[3] = { 0, 0, 0 };
    for (size_t j = 0; j < c->n; j++)
        if (c->segment[j] < 3)
            nseg[c->segment[j]]++;
    const vafm_h5_meta *m = &c->meta;
    char b[5][32];
    fprintf(o, "  %6" PRIu64 " %8zu %8zu %8zu %6zu %12s %12s %12s %12s", c->group, c->n, nseg[0], nseg[1], nseg[2],
            s_num(b[0], sizeof b[0], m->spring_constant_N_per_m, 1.0),
            s_num(b[1], sizeof b[1], m->speed_approach_m_per_s, 1.0),
            s_num(b[2], sizeof b[2], m->speed_retract_m_per_s, 1.0), s_num(b[3], sizeof b[3], m->duration_s, 1.0));
    vafm_h5_truth t;
    if (is_vafm && !vafm_h5_reader_truth(r, c->group, &t))
        fprintf(o, " | %5" PRIu64 " %6d %5d %12s %12s", t.point, t.status, t.result.flags,
                s_num(b[0], sizeof b[0], t.result.pulloff_sampled_N, 1e9),
                s_num(b[1], sizeof b[1], t.result.detach_force_N, 1e9));
    else if (is_vafm)
        fputs(" | (no ground truth)", o);
    fputc('\n', o);
}

static int s_cmd_info(const s_args *a)
{
    vafm_h5_reader *r = NULL;
    int rc = s_need_file(a);
    if (rc || (rc = s_open_reader(a->file, &r)) != 0)
        return rc;
    vafm_h5_provenance pv;
    vafm_h5_reader_provenance(r, &pv);
    if (a->on[O_JSON]) {
        if (pv.scene_json)
            puts(pv.scene_json);
        else
            s_error("%s: no vafm scene in this file (root attribute 'vafm scene')", a->file);
        vafm_h5_reader_destroy(&r);
        return pv.scene_json ? S_EXIT_OK : S_EXIT_RUNTIME;
    }
    size_t n = vafm_h5_reader_count(r);
    printf("file         %s, %.4g MB, %zu curve(s)\n", a->file, s_file_mb(a->file), n);
    s_info_prov ip;
    s_info_provenance(stdout, a->file, &pv, &ip);
    printf("curves       points per segment (0 approach, 1 retract, 2 dwell); SI%s\n",
           pv.is_vafm ? "; ground truth: pull-off forces tensile, nN" : "");
    printf("  %6s %8s %8s %8s %6s %12s %12s %12s %12s", "curve", "points", "approach", "retract", "dwell",
           "k_N_per_m", "v_appr_m/s", "v_retr_m/s", "duration_s");
    if (pv.is_vafm)
        printf(" | %5s %6s %5s %12s %12s", "point", "status", "flags", "pulloff_samp", "detach_force");
    putchar('\n');
    uint64_t damaged = 0;
    for (size_t i = 0; i < n; i++) {
        vafm_h5_curve c;
        vafm_error err;
        memset(&err, 0, sizeof err);
        int cr = vafm_h5_reader_curve(r, i, &c, &err);
        if (cr) {
            /* the first S_MAX_CURVE_ERRORS are named; a file of a million damaged groups is summed up */
            if (damaged < S_MAX_CURVE_ERRORS) {
                fflush(stdout);
                s_error("%s", err.message[0] ? err.message : vafm_strerror(cr));
            }
            damaged++;
            continue;
        }
        s_info_curve_line(stdout, &c, r, pv.is_vafm);
    }
    if (damaged > S_MAX_CURVE_ERRORS)
        s_error("%s: ... and %" PRIu64 " more curve(s) that cannot be read (only the first %d are named)", a->file,
                damaged - S_MAX_CURVE_ERRORS, S_MAX_CURVE_ERRORS);
    if (pv.is_vafm && ip.scene_ok && ip.grid_ok && n) {
        size_t np = vafm_campaign_points(&ip.spec);
        vafm_point_stats *stats = calloc(np, sizeof *stats);
        if (stats) {
            uint64_t missing = s_truth_stats(r, np, stats);
            s_print_statistics(stdout, &ip.p, &ip.spec, stats);
            if (missing)
                printf("  (%" PRIu64 " curve(s) without a ground-truth row left out)\n", missing);
            free(stats);
        }
    }
    vafm_scene_grid_free(&ip.grid);
    vafm_h5_reader_destroy(&r);
    vafm_error cerr;
    memset(&cerr, 0, sizeof cerr);
    int ck = vafm_h5_check(a->file, &cerr);
    if (!ck)
        printf("conformance  ok: every rule of protocol/hdf5.md (L1-L16%s)\n", pv.is_vafm ? ", V1-V4" : "");
    else
        printf("conformance  FAILED: %s\n", cerr.message[0] ? cerr.message : vafm_strerror(ck));
    if (damaged) {
        s_error("%s: %" PRIu64 " of %zu curve(s) cannot be read", a->file, damaged, n);
        return S_EXIT_RUNTIME;
    }
    return S_EXIT_OK;
}

/* ---- vafm export ---------------------------------------------------------------------------------- */

/* One value of a CSV cell: %.17g (reads back bit for bit), or empty when absent. */
static int s_cell(FILE *f, const char *sep, double v, int present)
{
    return present ? fprintf(f, "%s%.17g", sep, v) : fprintf(f, "%s", sep);
}

static int s_export_rows(FILE *f, const vafm_h5_curve *c)
{
    double k = c->meta.spring_constant_N_per_m;
    int has_k = isfinite(k) && k > 0;
    const double *h = c->height_piezo_m ? c->height_piezo_m : c->height_measured_m;
    const double *hm = c->height_measured_m ? c->height_measured_m : c->height_piezo_m;
    for (size_t i = 0; i < c->n; i++) {
        double fi = c->force_N[i];
        /* tip position as stored; else nanite's convention, height (measured) + force / k (protocol/csv.md) */
        double tip = c->tip_position_m ? c->tip_position_m[i] : has_k && hm ? hm[i] + fi / k : NAN;
        if (s_cell(f, "", c->time_s ? c->time_s[i] : 0.0, c->time_s != NULL) < 0 ||
            s_cell(f, ",", h ? h[i] : 0.0, h != NULL) < 0 || s_cell(f, ",", has_k ? fi / k : 0.0, has_k) < 0 ||
            s_cell(f, ",", fi, 1) < 0 || s_cell(f, ",", tip, !isnan(tip)) < 0 ||
            fprintf(f, ",%u\n", (unsigned)c->segment[i]) < 0)
            return -1;
    }
    return 0;
}

static int s_cmd_export(const s_args *a)
{
    int rc = s_need_file(a);
    if (rc)
        return rc;
    if (!a->val[O_CURVE]) {
        s_error("vafm export: --curve I (the curve to export; vafm info lists them) is required");
        return S_EXIT_USAGE;
    }
    vafm_h5_reader *r = NULL;
    if ((rc = s_open_reader(a->file, &r)) != 0)
        return rc;
    size_t n = vafm_h5_reader_count(r), i = 0;
    uint64_t group = 0;
    if (!n) {
        s_error("--curve: %s holds no curves", a->file);
        rc = S_EXIT_USAGE;
    } else if (!(rc = s_parse_u64("--curve", a->val[O_CURVE], 0, UINT64_MAX - 1, &group)) &&
               vafm_h5_reader_find(r, group, &i)) {
        /* curves are named by their group, as vafm info lists them (a file may have gaps) */
        uint64_t lo = vafm_h5_reader_group(r, 0), hi = vafm_h5_reader_group(r, n - 1);
        s_error("--curve: %s has no curve group '%" PRIu64 "' (its %zu groups are numbered %" PRIu64 " to %" PRIu64
                "%s; vafm info lists them)", a->file, group, n, lo, hi, hi - lo + 1 > n ? ", with gaps" : "");
        rc = S_EXIT_USAGE;
    }
    vafm_h5_curve c;
    vafm_error err;
    memset(&err, 0, sizeof err);
    int cr = rc ? 0 : vafm_h5_reader_curve(r, i, &c, &err);
    if (!rc && cr) {
        s_error("%s", err.message[0] ? err.message : vafm_strerror(cr));
        rc = S_EXIT_RUNTIME;
    }
    FILE *f = NULL;
    if (!rc && !(f = s_open_out(a->val[O_CSV])))
        rc = S_EXIT_RUNTIME;
    if (!rc) {
        fputs("time_s,height_m,deflection_m,force_N,tip_m,segment\n", f);
        int bad = s_export_rows(f, &c) < 0;
        rc = s_close_out(f, a->val[O_CSV], bad);
    }
    vafm_h5_reader_destroy(&r);
    return rc;
}

/* ---- vafm params / presets / integrators ------------------------------------------------------ */

static int s_print_json(const vafm_params *p)
{
    for (size_t len = 4096; len <= (1u << 20); len *= 2) {
        char *buf = malloc(len);
        if (!buf)
            break;
        int n = vafm_params_to_json(p, buf, len);
        if (n >= 0)
            puts(buf);
        free(buf);
        if (n >= 0)
            return S_EXIT_OK;
    }
    s_error("cannot serialise the scene");
    return S_EXIT_RUNTIME;
}

static int s_cmd_params(const s_args *a)
{
    s_scene sc;
    int rc = s_resolve_scene(a, &sc, 1);
    if (rc)
        return rc;
    if (a->on[O_JSON])
        return s_print_json(&sc.p);
    s_print_provenance(stdout, &sc);
    char val[128];
    for (int i = 0; i < vafm_param_count(); i++) {
        const vafm_param_info *f = vafm_param_at(i);
        vafm_params_get(&sc.p, f->name, val, sizeof val);
        printf("  %-20s %-24s %-6s %s\n", f->name, val, f->unit[0] ? f->unit : "-", f->doc);
    }
    return S_EXIT_OK;
}

static int s_cmd_presets(const s_args *a)
{
    (void)a;
    for (int i = 0; i < vafm_preset_count(); i++)
        printf("%-16s %s%s\n", vafm_preset_name(i), vafm_preset_description(i),
               strcmp(vafm_preset_name(i), S_DEFAULT_PRESET) ? "" : " [default]");
    return S_EXIT_OK;
}

static int s_cmd_integrators(const s_args *a)
{
    (void)a;
    for (int i = 0; i < vafm_integrator_count(); i++) {
        const vafm_integrator_type *t = vafm_integrator_at(i);
        printf("%-10s %s (%s, stability limit %g)\n", t->name, t->description,
               t->overdamped ? "overdamped" : "underdamped", t->stability_limit);
    }
    return S_EXIT_OK;
}

/* ---- help ------------------------------------------------------------------------------------- */

static void s_print_param_help(FILE *o)
{
    vafm_params def;
    vafm_params_default(&def);
    fprintf(o, "\nPARAMETERS (--NAME=VALUE or --NAME VALUE; also the keys of a --scene file)\n"
               "  name                 unit   allowed                          default (%s)\n",
            S_DEFAULT_PRESET);
    char allowed[160], val[128], shown[64];
    for (int i = 0; i < vafm_param_count(); i++) {
        const vafm_param_info *f = vafm_param_at(i);
        vafm_params_get(&def, f->name, val, sizeof val);
        if (f->kind == VAFM_PARAM_REAL) {
            snprintf(allowed, sizeof allowed, "[%.6g, %.6g]", f->min, f->max);
            snprintf(shown, sizeof shown, "%.6g", strtod(val, NULL));
        } else {
            snprintf(allowed, sizeof allowed, "%s",
                     f->kind == VAFM_PARAM_CHOICE ? f->choices
                     : f->kind == VAFM_PARAM_BOOL ? "true|false"
                                                  : "integer [0, 2^64-1]");
            snprintf(shown, sizeof shown, "%.63s", val);
        }
        fprintf(o, "  %-20s %-6s %-32s %s\n  %-20s %s\n", f->name, f->unit[0] ? f->unit : "-", allowed, shown, "",
                f->doc);
    }
}

static const char s_scene_help[] =
    "\nSCENE (run, curves, samples, params, campaign), applied in this order:\n"
    "  --preset NAME        start from a preset (default " S_DEFAULT_PRESET "; see `vafm presets`)\n"
    "  --scene FILE.json    apply a JSON object {\"preset\": NAME, \"<parameter>\": value, ...};\n"
    "                       its preset comes first; `vafm params --json` writes one\n"
    "  --NAME=VALUE         set a parameter (see PARAMETERS); also --NAME VALUE; in command-line order\n";

static const char s_exit_help[] = "\nEXIT STATUS\n"
                                  "  0 success, 1 runtime error (a curve failed, output failed,\n"
                                  "  a file is damaged or unreadable),\n"
                                  "  2 usage or parameter error (the message names the field, value and range)\n";

static void s_print_usage(FILE *o)
{
    fprintf(o, "vafm %s: a virtual AFM (thermal JKR pull-off force curves)\n\nUSAGE\n"
               "  vafm [COMMAND] [OPTIONS]     (no command: run)\n\nCOMMANDS\n",
            vafm_version());
    for (int i = 0; s_command_at(i); i++)
        fprintf(o, "  %-12s %s\n", s_command_at(i)->name, s_command_at(i)->summary);
    for (const vafm_cli_ext *e = vafm_cli_ext_commands; e->name; e++)
        fprintf(o, "  %-12s %s  (vafm %s --help)\n", e->name, e->summary, e->name);
    for (int i = 0; s_command_at(i); i++)
        if (s_command_at(i)->usage)
            fprintf(o, "\n%s", s_command_at(i)->usage);
    fprintf(o, "\nCOMMON OPTIONS\n  -h, --help           this text (vafm COMMAND --help: that command's)\n"
               "  --version            print the version\n");
    fputs(s_scene_help, o);
    fputs(s_exit_help, o);
    s_print_param_help(o);
}

static void s_print_command_help(FILE *o, const s_command *c)
{
    fprintf(o, "vafm %s: %s\n\n%s", c->name, c->summary, c->usage ? c->usage : "");
    if (c->scene) {
        fputs(s_scene_help, o);
        fputs(s_exit_help, o);
        s_print_param_help(o);
    }
}

static int s_cmd_help(const s_args *a)
{
    if (!a->topic) {
        s_print_usage(stdout);
        return S_EXIT_OK;
    }
    const s_command *c = s_command_find(a->topic);
    const vafm_cli_ext *e = c ? NULL : vafm_cli_ext_find(a->topic);
    if (e) {
        char *argv[] = { (char *)e->name, (char *)"--help", NULL };
        return e->fn(2, argv);
    }
    if (!c) {
        s_error("help: unknown command '%s'", a->topic);
        return S_EXIT_USAGE;
    }
    s_print_command_help(stdout, c);
    return S_EXIT_OK;
}

/* ---- the command table ------------------------------------------------------------------------ */

static const s_command s_commands[] = {
    { "run", s_cmd_run, S_GENERAL | M(O_INDEX) | M(O_PROGRESS) | M(O_QUIET), 1,
      "one force curve with a readable summary (the default command)",
      "vafm run [SCENE] [--index N] [--progress] [--quiet]\n"
      "  --index N            curve index = its random stream (default 0)\n"
      "  --progress           report progress on stderr even when it is not a terminal\n"
      "  -q, --quiet          no progress\n", 0 },
    { "curves", s_cmd_curves,
      S_GENERAL | M(O_N) | M(O_THREADS) | M(O_FIRST) | M(O_CSV) | M(O_T) | M(O_V) | M(O_K) | M(O_PROGRESS) |
          M(O_QUIET),
      1, "N curves per grid point on all cores: statistics, optional per-curve CSV",
      "vafm curves -n N [SCENE] [--threads T] [--first I] [--csv FILE|-] [--T LIST] [--v LIST] [--k LIST]\n"
      "  -n N                 curves per grid point (required)\n"
      "  --threads T          worker threads (default 0: all cores); results do not depend on it\n"
      "  --first I            skip global curve indices below I (resume)\n"
      "  --csv FILE|-         one row per curve (SI); '-' writes to stdout and the summary to stderr\n"
      "  --T LIST             temperatures, K, comma-separated (grid: T slowest, then v, then k)\n"
      "  --v LIST             piezo speeds (approach and retract), m/s\n"
      "  --k LIST             spring constants, N/m\n"
      "  --progress           report progress on stderr even when it is not a terminal\n"
      "  -q, --quiet          no progress (and no summary when the CSV goes to stdout)\n", 0 },
    { "samples", s_cmd_samples, S_GENERAL | M(O_INDEX) | M(O_CSV) | M(O_TUNE) | M(O_PROGRESS) | M(O_QUIET), 1,
      "one curve's (or a thermal tune's) output samples as CSV",
      "vafm samples [SCENE] [--index N] [--csv FILE|-] [--tune]\n"
      "  --index N            curve index (default 0)\n"
      "  --csv FILE|-         output file (default '-': stdout);\n"
      "                       columns time_s,height_m,deflection_m,force_N,tip_m,segment\n"
      "                       (segment 0 approach, 1 retract, 2 dwell, 3 tune)\n"
      "  --tune               a thermal tune (free cantilever) of tune_duration_s instead of a curve\n", 0 },
    { "params", s_cmd_params, S_GENERAL | M(O_JSON), 1, "print the resolved scene as a table or JSON",
      "vafm params [SCENE] [--json]\n"
      "  --json               JSON object (accepted back by --scene)\n", 0 },
    { "presets", s_cmd_presets, S_GENERAL, 0, "list the scene presets", "vafm presets\n", 0 },
    { "integrators", s_cmd_integrators, S_GENERAL, 0, "list the time integrators", "vafm integrators\n", 0 },
    { "help", s_cmd_help, S_GENERAL, 0, "this text, or one command's (vafm help COMMAND)", NULL, 0 },
    { "campaign", s_cmd_campaign,
      S_GENERAL | M(O_N) | M(O_OUT) | M(O_THREADS) | M(O_T) | M(O_V) | M(O_K) | M(O_RESUME) | M(O_OVERWRITE) |
          M(O_FLUSH) | M(O_GZIP) | M(O_PROGRESS) | M(O_QUIET) | M(O_MPI),
      1, "a grid of N curves per point on all cores into one HDF5 file (afmformats layout), resumable",
      "vafm campaign -n N --out FILE.h5 [SCENE] [--T LIST] [--v LIST] [--k LIST] [--threads T]\n"
      "              [--resume | --overwrite] [--flush-interval S] [--gzip L] [--progress | --quiet] [--mpi]\n"
      "  -n N                 curves per grid point (required)\n"
      "  -o, --out FILE.h5    the file: one group per curve with its channels, the scene, grid, seed and\n"
      "                       every curve's ground truth (protocol/hdf5.md; read by afmformats, nanite, PyJibe)\n"
      "  --T, --v, --k LIST   grid lists as for vafm curves (K, m/s, N/m; T slowest, then v, then k)\n"
      "  --threads T          worker threads (default 0: all cores); the file does not depend on it\n"
      "  --resume             continue FILE (same scene and grid, else refused naming the field): keep its\n"
      "                       complete curves and run the rest; the result equals an uninterrupted run\n"
      "  --overwrite          replace an existing FILE (without --resume or --overwrite it is refused)\n"
      "  --flush-interval S   make the curves durable every S seconds (default 1; 0: after each curve);\n"
      "                       a kill -9 loses at most the curves of the last S seconds\n"
      "  --gzip L             compress the channels: shuffle + deflate at level L (1-9; default 0: off)\n"
      "  --progress           report progress on stderr even when it is not a terminal\n"
      "  -q, --quiet          no progress\n"
      "  --mpi                run on MPI even without an MPI launcher in the environment (under mpirun or\n"
      "                       srun it is implied): `mpirun -np R vafm campaign ...` splits the curves over R\n"
      "                       ranks (x --threads each, default: the rank's share of its node's cores); rank 0\n"
      "                       writes FILE, identical to the single-process file (README: Campaigns on MPI)\n", 0 },
    { "info", s_cmd_info, S_GENERAL | M(O_JSON), 0,
      "summarise an HDF5 force-curve file (vafm's or another program's) and check its conformance",
      "vafm info FILE [--json]\n"
      "  FILE                 an HDF5 file of the afmformats layout: curves, provenance, per-point\n"
      "                       statistics (vafm files), conformance to protocol/hdf5.md (a broken rule is\n"
      "                       reported; exit 1 only when the file or a curve cannot be read)\n"
      "  --json               print only the scene the file was written with (a --scene file)\n",
      1 },
    { "export", s_cmd_export, S_GENERAL | M(O_CURVE) | M(O_CSV), 0, "one curve of an HDF5 file as CSV",
      "vafm export FILE --curve I [--csv OUT|-]\n"
      "  --curve I            the curve: its group number, as vafm info lists them\n"
      "  --csv OUT|-          output file (default '-': stdout); the columns of vafm samples;\n"
      "                       empty where the file lacks the channel (protocol/csv.md)\n",
      1 },
};
#define S_NCOMMANDS ((int)(sizeof s_commands / sizeof s_commands[0]))

static const s_command *s_command_at(int i)
{
    return i >= 0 && i < S_NCOMMANDS ? &s_commands[i] : NULL;
}

static const s_command *s_command_find(const char *name)
{
    for (int i = 0; i < S_NCOMMANDS; i++)
        if (!strcmp(name, s_commands[i].name))
            return &s_commands[i];
    return NULL;
}

/* ---- main ------------------------------------------------------------------------------------- */

static int s_dispatch(const s_args *a)
{
    const s_command *c = a->cmd;
    if (a->on[O_VERSION]) {
        printf("vafm %s (built against API %d.%d.%d)\n", vafm_version(), VAFM_API_VERSION_MAJOR,
               VAFM_API_VERSION_MINOR, VAFM_API_VERSION_PATCH);
        return S_EXIT_OK;
    }
    if (a->on[O_HELP]) {
        if (!a->explicit_cmd || c->fn == s_cmd_help)
            s_print_usage(stdout);
        else
            s_print_command_help(stdout, c);
        return S_EXIT_OK;
    }
    return c->fn(a);
}

int main(int argc, char **argv)
{
    const vafm_cli_ext *ext = argc > 1 ? vafm_cli_ext_find(argv[1]) : NULL;
    if (ext) {
        int erc = ext->fn(argc - 1, argv + 1);
        if (fflush(stdout) != 0 && !erc) {
            s_error("writing to stdout failed");
            erc = S_EXIT_RUNTIME;
        }
        return erc;
    }
    s_args a;
    int rc = s_parse_args(&a, argc, argv);
    if (!rc)
        rc = s_dispatch(&a);
    free(a.ov);
    if (fflush(stdout) != 0 && !rc) {
        s_error("writing to stdout failed");
        rc = S_EXIT_RUNTIME;
    }
    return rc;
}
