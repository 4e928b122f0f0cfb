/* SPDX-License-Identifier: MIT */
/* What several `vafm` commands share: messages, number parsing, scene resolution, progress, formatting, output files, statistics tables (design: cli.h). */
#include "cli/cli.h"

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
