/* SPDX-License-Identifier: MIT */
/* What several `vafm` commands share: messages, number parsing, scene resolution, progress, formatting, output files, statistics tables (design: cli.h). */
#include "cli/cli.h"
#include "record/scene_value.h"
#include <float.h>
#include <math.h>

/* ---- messages --------------------------------------------------------------------------------- */

void vafm_cli_error(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fputs("vafm: ", stderr);
    vfprintf(stderr, fmt, ap);
    fputc('\n', stderr);
    va_end(ap);
}

/* Exit status of a library failure: parameter problems are the user's (2), the rest are runtime (1). */
int vafm_cli_exit_of(int code)
{
    return code == VAFM_EINVAL || code == VAFM_EUNSTABLE || code == VAFM_ENOTFOUND || code == VAFM_EFORMAT
               ? VAFM_CLI_EXIT_USAGE
               : VAFM_CLI_EXIT_RUNTIME;
}

double vafm_cli_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* ---- number parsing --------------------------------------------------------------------------- */

int vafm_cli_parse_u64(const char *opt, const char *text, uint64_t lo, uint64_t hi, uint64_t *out)
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
        vafm_cli_error("%s: '%s' is not an integer in [%" PRIu64 ", %" PRIu64 "]", opt, text, lo, hi);
        return VAFM_CLI_EXIT_USAGE;
    }
    *out = (uint64_t)v;
    return 0;
}

int vafm_cli_parse_kernel(const char *text, vafm_campaign_spec *spec)
{
    if (!text)
        return 0;
    if (vafm_campaign_kernel_parse(text, spec)) {
        char names[128];
        vafm_campaign_kernel_names(names, sizeof names, ", ");
        vafm_cli_error("--kernel: '%s' is not a kernel (%s)", text, names);
        return VAFM_CLI_EXIT_USAGE;
    }
    return 0;
}

double vafm_cli_grid_points(const vafm_campaign_spec *spec)
{
    return (double)(spec->n_T ? spec->n_T : 1) * (double)(spec->n_v ? spec->n_v : 1) *
           (double)(spec->n_k ? spec->n_k : 1);
}

/* A comma-separated list of values of one field, each with its unit if typed ("25C,35C", "1um/s,2um/s"). Ranges
 * are the library's business (campaign validation). */
int vafm_cli_parse_list(const char *opt, const char *field, const char *text, double **out, size_t *n)
{
    size_t cap = 1;
    for (const char *c = text; *c; c++)
        cap += *c == ',';
    double *v = calloc(cap, sizeof *v);
    char *tok = strdup(text);
    if (!v || !tok) {
        free(v);
        free(tok);
        vafm_cli_error("out of memory");
        return VAFM_CLI_EXIT_RUNTIME;
    }
    const vafm_param_info *f = vafm_params_field_find(field);
    char *c = tok;
    for (size_t i = 0; i < cap; i++) {
        char *comma = strchr(c, ',');
        if (comma)
            *comma = '\0';
        vafm_error err;
        memset(&err, 0, sizeof err);
        if (vafm_units_parse(field, c, f ? f->unit : "", &v[i], &err)) {
            vafm_cli_error("%s: element %zu of '%s': %s", opt, i + 1, text, err.message);
            free(v);
            free(tok);
            return VAFM_CLI_EXIT_USAGE;
        }
        c = comma ? comma + 1 : c + strlen(c);
    }
    free(tok);
    *out = v;
    *n = cap;
    return 0;
}

/* ---- scene resolution ------------------------------------------------------------------------- */

int vafm_cli_report(const vafm_error *err, int code)
{
    vafm_cli_error("%s", err->message[0] ? err->message : vafm_strerror(code));
    return vafm_cli_exit_of(code);
}

/* Is `field` set on the command line? (ctx: the args) */
static int s_given_on_cli(const char *field, void *ctx)
{
    const vafm_cli_args *a = ctx;
    for (int i = 0; i < a->n_ov; i++)
        if (!strcmp(a->ov[i].name, field))
            return 1;
    return 0;
}

static const char *s_unit(const char *field)
{
    const vafm_param_info *f = vafm_params_field_find(field);
    return f ? f->unit : "";
}

static const char *s_opt_of(const vafm_cli_args *a, const char *field)
{
    for (int i = a->n_ov - 1; i >= 0; i--) /* the last one: it is the value that stands */
        if (!strcmp(a->ov[i].name, field))
            return a->ov[i].opt;
    return NULL;
}

/* A field given on the command line that an instrument setting (> 0) would derive in vafm_params_resolve,
 * where 0.6.2 let the setting win without a word (--speed with --ramp-rate; --setpoint with --setpoint_V;
 * --rate with --segment_samples; a scene file's ramp_rate_Hz over --speed). Both on the command line: a
 * usage error naming both. The setting from the preset or the scene file: the command line wins, the
 * setting is set to 0 (the fields it derives and the command line does not give keep what it made them)
 * and a note on stderr says so. */
static int s_derived_conflicts(const vafm_cli_args *a, vafm_cli_scene *sc)
{
    vafm_scene_conflict cf;
    for (int next = 0; (next = vafm_scene_derived_next(&sc->p, next, s_given_on_cli, (void *)a, &cf)) != 0;) {
        const char *opt = s_opt_of(a, cf.derived), *sopt = s_opt_of(a, cf.setting);
        if (sopt) {
            vafm_cli_error("%s and %s conflict: %s = %g %s sets %s (to %.6g %s), %s gives %.6g %s; give one of them "
                           "(%s 0 gives %s directly)", opt, sopt, cf.setting, cf.setting_value, s_unit(cf.setting),
                           cf.derived, cf.derives, s_unit(cf.derived), opt, cf.value, s_unit(cf.derived), sopt,
                           cf.derived);
            return VAFM_CLI_EXIT_USAGE;
        }
        vafm_params r = sc->p;
        int resolved = vafm_params_resolve(&r, NULL) == 0;
        for (int i = 0; resolved && i < vafm_params_field_count(); i++) { /* keep what the setting made the others */
            const char *f = vafm_params_field_at(i)->name;
            static const char *const derived[] = { "v_approach_m_per_s", "v_retract_m_per_s", "sample_rate_Hz",
                                                   "setpoint_N" };
            char buf[64];
            for (size_t k = 0; k < sizeof derived / sizeof *derived; k++)
                if (!strcmp(f, derived[k]) && !s_given_on_cli(f, (void *)a) &&
                    !vafm_params_get(&r, f, buf, sizeof buf))
                    vafm_params_set(&sc->p, f, buf, NULL);
        }
        vafm_error err;
        if (vafm_params_set(&sc->p, cf.setting, "0", &err)) /* every setting takes 0 (off): not reached */
            return vafm_cli_report(&err, VAFM_EINVAL);
        fprintf(stderr, "vafm: note: %s (%s = %.6g %s) wins over %s = %g %s of the %s%s: %s set to 0\n", opt,
                cf.derived, cf.value, s_unit(cf.derived), cf.setting, cf.setting_value, s_unit(cf.setting),
                sc->file ? "scene file " : "preset ", sc->file ? sc->file : sc->preset, cf.setting);
        next = 0; /* the setting is 0 now: look again from the start */
    }
    return 0;
}

/* Preset, then scene file (its own "preset" key first), then overrides in order; then validate. */
int vafm_cli_resolve_scene(const vafm_cli_args *a, vafm_cli_scene *sc, int validate)
{
    vafm_error err;
    memset(&err, 0, sizeof err);
    memset(sc, 0, sizeof *sc);
    const char *preset = a->val[O_PRESET] ? a->val[O_PRESET] : VAFM_CLI_DEFAULT_PRESET;
    int r = vafm_preset_apply(&sc->p, preset, &err);
    if (r)
        return vafm_cli_report(&err, r);
    snprintf(sc->preset, sizeof sc->preset, "%s", preset);
    if (a->val[O_SCENE]) {
        char file_preset[64];
        sc->file = a->val[O_SCENE];
        r = vafm_scene_load_file(&sc->p, sc->file, file_preset, sizeof file_preset, &err);
        if (r) {
            vafm_cli_error("%s", err.message);
            return VAFM_CLI_EXIT_USAGE;
        }
        if (file_preset[0])
            snprintf(sc->preset, sizeof sc->preset, "%s", file_preset);
    }
    sc->ov = a->ov;
    sc->n_ov = a->n_ov;
    for (int i = 0; i < a->n_ov; i++) {
        r = vafm_params_set(&sc->p, a->ov[i].name, a->ov[i].value, &err);
        if (r)
            return vafm_cli_report(&err, r);
    }
    if ((r = s_derived_conflicts(a, sc)) != 0)
        return r;
    if ((r = vafm_params_resolve(&sc->p, &err)) != 0) /* the instrument's settings → speeds, rate, setpoint */
        return vafm_cli_report(&err, r);
    if (validate && (r = vafm_params_validate(&sc->p, &err)) != 0)
        return vafm_cli_report(&err, r);
    return 0;
}

void vafm_cli_print_provenance(FILE *o, const vafm_cli_scene *sc)
{
    fprintf(o, "scene        preset %s", sc->preset);
    if (sc->file)
        fprintf(o, ", scene file %s", sc->file);
    for (int i = 0; i < sc->n_ov; i++)
        fprintf(o, "%s--%s=%s", i ? " " : ", overrides ", sc->ov[i].name, sc->ov[i].value);
    fputc('\n', o);
}

/* ---- progress --------------------------------------------------------------------------------- */

void vafm_cli_progress_init(vafm_cli_progress *pg, const vafm_cli_args *a)
{
    memset(pg, 0, sizeof *pg);
    pg->tty = isatty(STDERR_FILENO);
    pg->on = !a->on[O_QUIET] && (pg->tty || a->on[O_PROGRESS]);
    pg->t0 = pg->last = vafm_cli_now();
}

/* 1 when a progress line is due (at most every VAFM_CLI_PROGRESS_PERIOD_S). */
int vafm_cli_progress_due(vafm_cli_progress *pg)
{
    if (!pg->on)
        return 0;
    double t = vafm_cli_now();
    if (t - pg->last < VAFM_CLI_PROGRESS_PERIOD_S)
        return 0;
    pg->last = t;
    pg->printed = 1;
    return 1;
}

void vafm_cli_progress_line(const vafm_cli_progress *pg, const char *text)
{
    /* A terminal gets one line rewritten in place; a log gets one line per report. */
    fprintf(stderr, pg->tty ? "\rvafm: %s\033[K" : "vafm: %s\n", text);
    fflush(stderr);
}

void vafm_cli_progress_end(const vafm_cli_progress *pg)
{
    if (pg->printed && pg->tty)
        fputc('\n', stderr);
}

/* ---- running one scene ------------------------------------------------------------------------ */

/* Advance the running scene to its end, reporting the simulated time as progress. */
int vafm_cli_advance_all(vafm_sim *sim, vafm_sample_fn fn, void *user, vafm_cli_progress *pg)
{
    int r;
    do {
        r = vafm_sim_advance(sim, VAFM_CLI_CHUNK_SAMPLES, fn, user);
        if (r == 1 && vafm_cli_progress_due(pg)) {
            vafm_curve_result now;
            vafm_sim_result(sim, &now);
            char line[128];
            double wall = vafm_cli_now() - pg->t0;
            snprintf(line, sizeof line, "simulated %.4g s in %.1f s wall (%.3g x real time)", now.duration_s,
                     wall, now.duration_s / wall);
            vafm_cli_progress_line(pg, line);
        }
    } while (r == 1);
    vafm_cli_progress_end(pg);
    return r;
}

int vafm_cli_new_sim(const vafm_params *p, vafm_sim **sim)
{
    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = vafm_sim_new(sim, p, &err);
    return r ? vafm_cli_report(&err, r) : 0;
}

/* ---- formatting ------------------------------------------------------------------------------- */

/* "   1.04921 nN        0.972268 F_JKR": SI value and the same in a reference unit (n/a where undefined). */
void vafm_cli_fmt_pair(char *buf, size_t len, double v, double si_scale, const char *si_unit, double ref,
                       const char *ref_unit)
{
    if (!isfinite(v))
        snprintf(buf, len, "%12s %-2s    %12s %-5s", "n/a", "", "n/a", "");
    else if (ref > 0)
        snprintf(buf, len, "%12.6g %-2s    %12.6g %-5s", v * si_scale, si_unit, v / ref, ref_unit);
    else
        snprintf(buf, len, "%12.6g %-2s    %12s %-5s", v * si_scale, si_unit, "n/a", "");
}

void vafm_cli_print_flags(FILE *o, int flags)
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

const char *vafm_cli_get(const vafm_params *p, const char *name, char *buf, size_t len)
{
    if (vafm_params_get(p, name, buf, len) != 0)
        snprintf(buf, len, "?");
    return buf;
}

void vafm_cli_print_scene_si(FILE *o, const vafm_params *p)
{
    char b1[64], b2[64], b3[64];
    fprintf(o, "sample       E* = %.6g Pa, R = %.6g nm, gamma = %.6g J/m^2, contact %s\n", p->E_star_Pa,
            p->R_m * 1e9, p->gamma_J_per_m2, vafm_cli_get(p, "contact", b1, sizeof b1));
    /* the effective mass and friction (from f0 and Q when they are given), and f0 and Q they make */
    double m = vafm_params_mass_kg(p), eta = vafm_params_eta_per_s(p), w0 = sqrt(p->k_N_per_m / m);
    fprintf(o, "cantilever   k = %.6g N/m, f0 = %.6g kHz, Q = %.4g (m = %.6g kg, eta = %.6g 1/s%s), eta_cont = %.6g "
               "1/s, T = %.6g K (%.2f C)\n",
            p->k_N_per_m, w0 / (2.0 * M_PI) * 1e-3, w0 / eta, m, eta,
            p->f0_Hz > 0 || p->Q > 0 ? ", from f0 and Q" : "", p->eta_cont_per_s, p->T_K, p->T_K - 273.15);
    fprintf(o, "detector     InvOLS %.6g nm/V", p->sensitivity_m_per_V * 1e9);
    if (p->noise_V_rms > 0 || p->adc_bits > 0 || p->baseline_offset_V != 0)
        fprintf(o, ", noise %.6g mV rms, ADC %d bits over %.6g V, offset %.6g V\n", p->noise_V_rms * 1e3, p->adc_bits,
                p->adc_range_V, p->baseline_offset_V);
    else
        fprintf(o, ", ideal (no noise, no ADC, no offset)\n");
    fprintf(o, "ramp         v_approach = %.6g m/s, v_retract = %.6g m/s, start %.6g nm, ", p->v_approach_m_per_s,
            p->v_retract_m_per_s, p->start_height_m * 1e9);
    if (p->trigger == VAFM_TRIGGER_HEIGHT)
        fprintf(o, "trigger at height %.6g nm", p->trigger_height_m * 1e9);
    else
        fprintf(o, "trigger at force %.6g nN", p->setpoint_N * 1e9);
    fprintf(o, ", dwell %.6g s\n", p->dwell_s);
    fprintf(o, "output       %.6g Hz, antialias %s\n", p->sample_rate_Hz, vafm_cli_get(p, "antialias", b1, sizeof b1));
    fprintf(o, "numerics     integrator %s, noise %s, free_exact %s, seed %" PRIu64 "\n",
            vafm_cli_get(p, "integrator", b1, sizeof b1), vafm_cli_get(p, "noise", b2, sizeof b2),
            vafm_cli_get(p, "free_exact", b3, sizeof b3), p->seed);
}

void vafm_cli_print_scene_reduced(FILE *o, const vafm_params *p, double dt_s)
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

void vafm_cli_print_observables(FILE *o, const vafm_params *p, const vafm_curve_result *res)
{
    double F_jkr = vafm_stats_f_jkr_N(p);
    char buf[96];
    fprintf(o, "pull-off     (F_JKR = 3*pi*gamma*R/2 = %.6g nN)\n", F_jkr * 1e9);
    for (int i = 0; i < VAFM_OBS_COUNT; i++) {
        const vafm_observable_info *ob = vafm_stats_observable(i);
        double v = vafm_stats_value(res, i);
        if (ob->is_force)
            vafm_cli_fmt_pair(buf, sizeof buf, v, 1e9, "nN", F_jkr, "F_JKR");
        else
            vafm_cli_fmt_pair(buf, sizeof buf, v, 1e9, "nm", p->R_m, "R");
        fprintf(o, "  %-19s %s   %s\n", ob->name, buf, ob->doc);
    }
}

void vafm_cli_print_quasistatic(FILE *o, const vafm_params *p, const vafm_curve_result *res)
{
    vafm_reduced r;
    vafm_units_reduce(p, &r);
    vafm_quasistatic q;
    if (!(p->contact->flags & VAFM_CONTACT_JKR_BRANCH) || p->gamma_J_per_m2 <= 0 || vafm_theory_quasistatic(r.gamma, r.k, &q) != 0) {
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

void vafm_cli_print_run_result(FILE *o, const vafm_params *p, const vafm_curve_result *res, double wall)
{
    fprintf(o, "steps        %" PRIu64 " (contact %" PRIu64 ", exact free %" PRIu64 "), %" PRIu64 " samples\n",
            res->steps, res->steps_contact, res->steps_free, res->samples);
    fprintf(o, "curve        index %" PRIu64 ", flags: ", res->index);
    vafm_cli_print_flags(o, res->flags);
    vafm_cli_print_observables(o, p, res);
    vafm_cli_print_quasistatic(o, p, res);
    fprintf(o, "time         simulated %.6g s, wall %.3f s, real-time factor %.4g\n", res->duration_s, wall,
            wall > 0 ? res->duration_s / wall : INFINITY);
}

/* ---- output files ----------------------------------------------------------------------------- */

FILE *vafm_cli_open_out(const char *path)
{
    if (!path || !strcmp(path, "-"))
        return stdout;
    FILE *f = fopen(path, "w");
    if (!f)
        vafm_cli_error("cannot open '%s' for writing: %s", path, strerror(errno));
    return f;
}

/* Close (or flush stdout) and report a write error. @return an exit status. */
int vafm_cli_close_out(FILE *f, const char *path, int failed)
{
    int bad = failed || ferror(f);
    if (f == stdout)
        bad |= fflush(f) != 0;
    else
        bad |= fclose(f) != 0;
    if (bad) {
        vafm_cli_error("writing '%s' failed", path && strcmp(path, "-") ? path : "(stdout)");
        return VAFM_CLI_EXIT_RUNTIME;
    }
    return VAFM_CLI_EXIT_OK;
}

/* ---- vafm curves: statistics ------------------------------------------------------------------ */

void vafm_cli_print_moments_row(FILE *o, const char *name, const vafm_moments *m, double scale, const char *unit,
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

void vafm_cli_print_point(FILE *o, size_t point, const vafm_params *p, const vafm_point_stats *st)
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
            vafm_cli_print_moments_row(o, ob->name, &st->obs[i], 1e9, "nN", F_jkr, "F_JKR");
        else
            vafm_cli_print_moments_row(o, ob->name, &st->obs[i], 1e9, "nm", p->R_m, "R");
    }
}

/* ---- HDF5 files: shared helpers ------------------------------------------------------------------ */

/* A real option in [lo, hi]. */
int vafm_cli_parse_real(const char *opt, const char *text, double lo, double hi, const char *unit, double *out)
{
    char *end = NULL;
    double v = strtod(text, &end);
    if (end == text || *end != '\0' || !(v >= lo && v <= hi)) {
        vafm_cli_error("%s: '%s' is not a number in [%g, %g]%s%s", opt, text, lo, hi, unit[0] ? " " : "", unit);
        return VAFM_CLI_EXIT_USAGE;
    }
    int nonzero = 0; /* "1e-400" reads as 0: an underflow, not a zero */
    for (const char *c = text; *c && *c != 'e' && *c != 'E'; c++)
        nonzero |= *c >= '1' && *c <= '9';
    if (nonzero && fabs(v) < DBL_MIN) {
        vafm_cli_error("%s: '%s' underflows (a nonzero value must be at least %.17g in magnitude; range [%g, %g]%s%s)",
                       opt, text, DBL_MIN, lo, hi, unit[0] ? " " : "", unit);
        return VAFM_CLI_EXIT_USAGE;
    }
    *out = v;
    return 0;
}

double vafm_cli_file_mb(const char *path)
{
    struct stat st;
    return stat(path, &st) ? 0.0 : (double)st.st_size / 1e6;
}

/* Per-point statistics of every curve of a vafm file, from its ground truth, in curve order (so a
 * resumed campaign prints the same numbers as an uninterrupted one). @return curves without a row. */
uint64_t vafm_cli_truth_stats(const vafm_h5_reader *r, size_t np, vafm_point_stats *stats)
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

/* The per-point statistics of a campaign (vafm curves, vafm campaign, vafm info). */
void vafm_cli_print_statistics(FILE *o, const vafm_params *base, const vafm_campaign_spec *spec,
                               const vafm_point_stats *stats)
{
    fprintf(o, "statistics   over curves with a pull-off (no-contact and no-detach curves left out); "
               "sd sample, sem = sd/sqrt(n), skew g1\n");
    size_t np = vafm_campaign_points(spec);
    for (size_t i = 0; i < np; i++) {
        vafm_params p;
        vafm_campaign_point_params(base, spec, i, &p);
        vafm_cli_print_point(o, i, &p, &stats[i]);
    }
}

/* ---- recording a campaign into one HDF5 file (vafm campaign, vafm map) ----------------------------- */

/* "done/total curves, rate, ETA" on the progress line, when one is due (vafm curves and campaign). */
void vafm_cli_progress_curves(vafm_cli_progress *pg, uint64_t done, uint64_t total)
{
    if (!vafm_cli_progress_due(pg))
        return;
    double wall = vafm_cli_now() - pg->t0, rate = (double)done / wall;
    char line[160];
    snprintf(line, sizeof line, "%" PRIu64 "/%" PRIu64 " curves, %.3g curves/s, ETA %.0f s", done, total, rate,
             rate > 0 ? (double)(total - done) / rate : 0.0);
    vafm_cli_progress_line(pg, line);
}


/*
 * The curves reach vafm_cli_rec_curve in index order, one at a time, from whichever worker finished the
 * next one, and go into the file at once through the recorder (record/record.h), which flushes on a timer
 * (--flush-interval) from its own thread: a kill -9 at any moment loses at most the curves of the last
 * interval; --resume recomputes exactly those.
 */

/* The curve's samples through the scene's measured chain (vafm/detector.h) into cp's buffers. */
static int s_measure(vafm_cli_rec *cp, const vafm_campaign_curve *c, vafm_samples *out)
{
    const vafm_samples *s = &c->samples;
    if (s->n > cp->mcap) {
        double *d = realloc(cp->mdefl, s->n * sizeof *d), *f = d ? realloc(cp->mforce, s->n * sizeof *f) : NULL;
        if (d)
            cp->mdefl = d;
        if (f)
            cp->mforce = f;
        double *h = f ? realloc(cp->mheight, s->n * sizeof *h) : NULL;
        if (!h)
            return -1;
        cp->mheight = h;
        cp->mcap = s->n;
    }
    vafm_detector det;
    vafm_detector_begin(&det, c->params, c->index);
    for (size_t i = 0; i < s->n; i++) /* the z sensor reads where the piezo is (a sensor of its own) */
        vafm_detector_sample(&det, s, i, NULL, &cp->mdefl[i], &cp->mforce[i], det.zs_on ? &cp->mheight[i] : NULL);
    *out = *s;
    out->deflection_m = cp->mdefl;
    out->force_N = cp->mforce;
    if (det.zs_on)
        out->height_measured_m = cp->mheight;
    return 0;
}

/* Called in index order, one at a time. A failed curve stops the campaign, as in vafm curves. */
int vafm_cli_rec_curve(void *user, const vafm_campaign_curve *c)
{
    vafm_cli_rec *cp = user;
    if (c->status) {
        cp->fail_status = c->status;
        cp->fail_index = c->index;
        return 1;
    }
    vafm_record_curve rc = { .samples = &c->samples, .params = c->params, .result = &c->result,
                             .point = c->point, .sensitivity_m_per_V = c->params->sensitivity_m_per_V };
    vafm_map_truth px;
    if (cp->map) { /* a force map: the pixel's indices and position (curve index = iy*nx + ix) */
        int ix = (int)(c->index % (uint64_t)cp->map->nx), iy = (int)(c->index / (uint64_t)cp->map->nx);
        vafm_map_pixel(cp->map, cp->base, ix, iy, NULL, &px, NULL);
        rc.map = cp->map;
        rc.pixel = &px;
    }
    vafm_samples measured;
    if (vafm_detector_on(c->params)) {
        /* the measured chain, as vafmd streams it: force and deflection are the instrument's, the file then
         * has no tip position = height + force/k column (hdf5.md L14); the ground truth stays physical */
        if (s_measure(cp, c, &measured)) {
            cp->werr_code = VAFM_ENOMEM;
            snprintf(cp->werr.message, sizeof cp->werr.message, "out of memory for curve %" PRIu64 "'s samples",
                     c->index);
            return 1;
        }
        rc.samples = &measured;
        rc.measured_force = 1;
    }
    int r = vafm_recorder_append(cp->rec, &rc, &cp->werr);
    if (r) {
        cp->werr_code = r;
        return 1;
    }
    cp->done++;
    vafm_cli_progress_curves(&cp->pg, cp->done, cp->total);
    return 0;
}

int vafm_cli_rec_parse(const vafm_cli_args *a, vafm_cli_rec_opts *o)
{
    memset(o, 0, sizeof *o);
    o->out = a->val[O_OUT];
    o->resume = a->on[O_RESUME];
    o->overwrite = a->on[O_OVERWRITE];
    o->interval = 1.0;
    uint64_t gz = 0;
    int rc = 0;
    if ((a->val[O_FLUSH] && (rc = vafm_cli_parse_real("--flush-interval", a->val[O_FLUSH], 0.0,
                                               VAFM_RECORD_MAX_FLUSH_INTERVAL_S, "s", &o->interval))) ||
        (a->val[O_GZIP] && (rc = vafm_cli_parse_u64("--gzip", a->val[O_GZIP], 0, 9, &gz))))
        return rc;
    o->gzip = (int)gz;
    if (!o->out) {
        vafm_cli_error("vafm %s: --out FILE.h5 (the HDF5 file to write) is required", a->cmd->name);
        return VAFM_CLI_EXIT_USAGE;
    }
    if (o->resume && o->overwrite) {
        vafm_cli_error("vafm %s: --resume continues %s and --overwrite replaces it; give one of them", a->cmd->name, o->out);
        return VAFM_CLI_EXIT_USAGE;
    }
    struct stat st;
    int exists = stat(o->out, &st) == 0;
    if (exists && !o->resume && !o->overwrite) {
        vafm_cli_error("vafm %s: %s exists already; --resume continues it, --overwrite replaces it", a->cmd->name, o->out);
        return VAFM_CLI_EXIT_USAGE;
    }
    if (!exists && o->resume) {
        vafm_cli_error("vafm %s: --resume: %s cannot be resumed: %s", a->cmd->name, o->out, strerror(errno));
        return VAFM_CLI_EXIT_USAGE;
    }
    o->mb_before = o->resume ? (double)st.st_size / 1e6 : 0.0;
    return 0;
}

/* Open (create or resume) the file and record or compare the provenance. */
int vafm_cli_rec_open(vafm_cli_rec *cp, const vafm_cli_rec_opts *o, const vafm_cli_scene *sc, const vafm_campaign_spec *spec)
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
    return r ? vafm_cli_report(&err, r) : 0;
}

/* The file a campaign (or a map) will write, estimated before anything is written (vafm_sim_estimate_cost of every
 * grid point; 41 bytes a sample: five float64 channels and the segment byte). Said on stderr; refused
 * when it cannot fit the free space of the file system (with --gzip only said: the ratio is not known). */
#define S_CURVE_META_BYTES 19000.0 /* a curve's share of a file beyond its samples (measured; see below) */

int vafm_cli_rec_size_check(const vafm_cli_args *a, const vafm_cli_rec_opts *co, const vafm_params *base,
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
        /* 41 B a sample (five float64 channels and the segment byte), plus each curve's group, dataset
         * headers, attributes and ground-truth row: 18.9 kB measured for 200 curves of 2 samples (0.6.1
         * counted the samples only, so a campaign of short curves could fill the disk unwarned) */
        bytes += todo * (est.samples * 41.0 + S_CURVE_META_BYTES);
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
    int vs_ok = statvfs(dir, &vs) == 0;
    if (vs_ok && (vs.f_flag & ST_RDONLY)) { /* its free space reads 0: say what it is (0.6.2: "0 GB free") */
        vafm_cli_error("--out: %s: the file system of %s is mounted read-only (%s); nothing was written", co->out, dir,
                       vafm_strerror(VAFM_EACCES));
        return VAFM_CLI_EXIT_RUNTIME;
    }
    double avail = vs_ok ? (double)vs.f_bavail * (double)vs.f_frsize : INFINITY;
    if (!a->on[O_QUIET])
        fprintf(stderr, "vafm: %s: %.0f curve(s) to run, ~%.3g GB uncompressed (%.3g GB free there)\n",
                co->out, curves, bytes / 1e9, avail / 1e9);
    if (bytes > avail && !co->gzip) {
        vafm_cli_error("-n: the campaign would write ~%.3g GB to %s, more than the %.3g GB free on its file system; "
                "run fewer curves (-n, the grid), lower sample_rate_Hz, or compress (--gzip)", bytes / 1e9, co->out,
                avail / 1e9);
        return VAFM_CLI_EXIT_USAGE;
    }
    return 0;
}


int vafm_cli_rec_close(vafm_cli_rec *cp, const vafm_cli_rec_opts *co, uint64_t first, int r, const vafm_error *err,
                       vafm_recorder_report *rep)
{
    /* A clean close merges the ground truth into one table; the file holds every curve delivered. */
    vafm_error cerr;
    memset(&cerr, 0, sizeof cerr);
    int cr = vafm_recorder_close(&cp->rec, rep, &cerr);
    free(cp->mdefl);
    free(cp->mforce);
    free(cp->mheight);
    cp->mdefl = cp->mforce = cp->mheight = NULL;
    int rc = 0;
    if (cp->fail_status) {
        vafm_cli_error("curve %" PRIu64 " failed: %s; %s holds the %" PRIu64 " curve(s) before it", cp->fail_index,
                       vafm_strerror(cp->fail_status), co->out, first + cp->done);
        rc = VAFM_CLI_EXIT_RUNTIME;
    } else if (cp->werr_code) {
        vafm_cli_error("%s", cp->werr.message[0] ? cp->werr.message : vafm_strerror(cp->werr_code));
        rc = VAFM_CLI_EXIT_RUNTIME;
    } else if (r && r != VAFM_EABORT) {
        rc = vafm_cli_report(err, r);
    } else if (cr) {
        vafm_cli_error("%s", cerr.message[0] ? cerr.message : vafm_strerror(cr));
        rc = VAFM_CLI_EXIT_RUNTIME;
    }
    return rc;
}

/* ---- force maps (vafm map, vafm info) ---------------------------------------------------------------- */

#define S_MAP_MAX_REGIONS 8
#define S_MAP_MAX_COLS 64
#define S_MAP_MAX_ROWS 32

typedef struct s_region {
    double E, gamma;
    uint64_t n;
    double hmin, hmax;
    vafm_point_stats st;
} s_region;

/* One text rendering of a per-pixel value: one character per shown pixel, y up (row ny-1 first). */
static void s_map_render(FILE *o, const char *title, const double *v, int nx, int ny, const char *levels, double lo,
                         double hi, const char *(*label)(double, char *))
{
    int sx = (nx + S_MAP_MAX_COLS - 1) / S_MAP_MAX_COLS, sy = (ny + S_MAP_MAX_ROWS - 1) / S_MAP_MAX_ROWS;
    fprintf(o, "%s", title);
    if (sx > 1 || sy > 1)
        fprintf(o, " (every %d. pixel along x, every %d. along y)", sx, sy);
    fputc('\n', o);
    int nl = (int)strlen(levels);
    for (int iy = ny - 1 - ((ny - 1) % sy); iy >= 0; iy -= sy) {
        fputs("  ", o);
        for (int ix = 0; ix < nx; ix += sx) {
            double x = v[(size_t)iy * (size_t)nx + (size_t)ix];
            char ch[8];
            if (label)
                fputs(label(x, ch), o);
            else if (isnan(x))
                fputc('?', o);
            else {
                int k = hi > lo ? (int)((x - lo) / (hi - lo) * (double)nl) : 0;
                fputc(levels[k < 0 ? 0 : k >= nl ? nl - 1 : k], o);
            }
        }
        fputc('\n', o);
    }
}

static const char *s_region_char(double x, char *buf)
{
    buf[0] = isnan(x) ? '?' : (char)('a' + (int)x);
    buf[1] = 0;
    return buf;
}

int vafm_cli_print_map(FILE *o, vafm_h5_reader *r)
{
    size_t n = vafm_h5_reader_count(r);
    vafm_h5_curve c;
    if (!n || vafm_h5_reader_curve_info(r, 0, &c, NULL) || c.meta.grid_shape_x < 1 || c.meta.grid_shape_y < 1)
        return 0; /* not a map */
    if (c.meta.grid_shape_x > VAFM_MAP_MAX_SIDE || c.meta.grid_shape_y > VAFM_MAP_MAX_SIDE)
        return 0; /* compared as read (int64): 2^32 + 1 was 1 as an int */
    int nx = (int)c.meta.grid_shape_x, ny = (int)c.meta.grid_shape_y;
    size_t np = (size_t)nx * (size_t)ny;
    fprintf(o, "map          %d x %d pixels over %.6g x %.6g um centred at (%.6g, %.6g) um; curve = iy*%d + ix; "
               "%zu of %zu pixels recorded\n",
            nx, ny, c.meta.grid_size_x_m * 1e6, c.meta.grid_size_y_m * 1e6, c.meta.grid_center_x_m * 1e6,
            c.meta.grid_center_y_m * 1e6, nx, n < np ? n : np, np);
    double *reg = malloc(np * sizeof *reg), *pull = malloc(np * sizeof *pull), *hgt = malloc(np * sizeof *hgt);
    s_region rg[S_MAP_MAX_REGIONS];
    int nr = 0, more = 0;
    if (!reg || !pull || !hgt) {
        free(reg);
        free(pull);
        free(hgt);
        return -1;
    }
    for (size_t i = 0; i < np; i++)
        reg[i] = pull[i] = hgt[i] = NAN;
    double plo = INFINITY, phi = -INFINITY, hlo = INFINITY, hhi = -INFINITY;
    for (size_t i = 0; i < n; i++) {
        vafm_h5_truth t;
        if (vafm_h5_reader_curve_info(r, i, &c, NULL) || c.meta.grid_index_x < 0 || c.meta.grid_index_y < 0 ||
            c.meta.grid_index_x >= nx || c.meta.grid_index_y >= ny ||
            vafm_h5_reader_truth(r, vafm_h5_reader_group(r, i), &t))
            continue;
        size_t px = (size_t)c.meta.grid_index_y * (size_t)nx + (size_t)c.meta.grid_index_x;
        int k = 0;
        while (k < nr && !(rg[k].E == t.E_star_Pa && rg[k].gamma == t.gamma_J_per_m2))
            k++;
        if (k == nr && nr == S_MAP_MAX_REGIONS) {
            /* a material beyond the table: no region line and '?' in the material map, but its height and
             * pull-off are in their maps (0.6.2 skipped the pixel, and the adhesion map showed '?' there) */
            more++;
            k = -1;
        } else if (k == nr) {
            memset(&rg[nr], 0, sizeof rg[nr]);
            rg[nr].E = t.E_star_Pa;
            rg[nr].gamma = t.gamma_J_per_m2;
            rg[nr].hmin = INFINITY;
            rg[nr].hmax = -INFINITY;
            nr++;
        }
        if (k >= 0) {
            rg[k].n++;
            rg[k].hmin = fmin(rg[k].hmin, t.surface_height_m);
            rg[k].hmax = fmax(rg[k].hmax, t.surface_height_m);
            vafm_point_stats_add(&rg[k].st, t.status, &t.result);
            reg[px] = k;
        }
        hgt[px] = t.surface_height_m;
        if (isfinite(t.surface_height_m)) {
            hlo = fmin(hlo, t.surface_height_m);
            hhi = fmax(hhi, t.surface_height_m);
        }
        if (vafm_stats_is_pulloff(t.status, &t.result)) {
            pull[px] = t.result.pulloff_sampled_N;
            plo = fmin(plo, pull[px]);
            phi = fmax(phi, pull[px]);
        }
    }
    fprintf(o, "regions      the ground truth's materials (E*, gamma); pull-off = pulloff_sampled, mean +- sem\n");
    for (int k = 0; k < nr; k++) {
        const vafm_moments *m = &rg[k].st.obs[VAFM_OBS_PULLOFF_SAMPLED];
        fprintf(o, "  %c  E* = %-10.6g Pa  gamma = %-8.4g J/m^2  %6" PRIu64 " curves, surface height %.4g..%.4g um, "
                   "pull-off ",
                'a' + k, rg[k].E, rg[k].gamma, rg[k].n, rg[k].hmin * 1e6, rg[k].hmax * 1e6);
        if (m->n == 1) /* one curve has no sem (0.6.2 printed "+- nan") */
            fprintf(o, "%.6g nN (n 1)\n", m->mean * 1e9);
        else if (m->n)
            fprintf(o, "%.6g +- %.3g nN (n %" PRIu64 ")\n", m->mean * 1e9, vafm_moments_sem(m) * 1e9, m->n);
        else
            fprintf(o, "none (n 0)\n");
    }
    if (more)
        fprintf(o, "  (%d curve(s) of further materials left out)\n", more);
    if (nr > 0) {
        s_map_render(o, more ? "material map (one letter per pixel: its region, '?' a material left out; y up)"
                             : "material map (one letter per pixel: its region; y up)",
                     reg, nx, ny, "", 0, 0, s_region_char);
        if (phi > plo || isfinite(plo)) {
            char title[160];
            snprintf(title, sizeof title, "adhesion map (pull-off force, ' .:-=+*#%%@' from %.4g to %.4g nN; '?' none)",
                     plo * 1e9, phi * 1e9);
            s_map_render(o, title, pull, nx, ny, " .:-=+*#%@", plo, phi, NULL);
        }
        if (hhi > hlo) {
            char title[160];
            snprintf(title, sizeof title, "height map (surface height, ' .:-=+*#%%@' from %.4g to %.4g um)", hlo * 1e6,
                     hhi * 1e6);
            s_map_render(o, title, hgt, nx, ny, " .:-=+*#%@", hlo, hhi, NULL);
        }
    }
    free(reg);
    free(pull);
    free(hgt);
    return 1;
}

/* MPI starts only under an MPI launcher or with --mpi: a plain `vafm campaign` or `vafm map` never touches it. */
int vafm_cli_with_mpi(const vafm_cli_args *a, int (*body)(const vafm_cli_args *a, vafm_cli_mpi *mpi))
{
    vafm_cli_mpi *mpi = NULL;
    int rc = vafm_cli_mpi_begin(a->on[O_MPI], &mpi);
    if (!rc)
        rc = body(a, mpi);
    return vafm_cli_mpi_end(&mpi, rc);
}
