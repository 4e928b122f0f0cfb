/* SPDX-License-Identifier: MIT */
/*
 * bench_work_precision: cost against error of a campaign statistic, per integrator and time step
 * (physics notes, "Speed against error"). It reports; it never fails.
 *
 * Scene: paper-fig4 (γ̃ = 0.229, k̃ = 0.1, k_BT̃ = 0.01, ṽ = 1e-3, m̃ = 0.01) started in contact near the
 * pull (start_in_contact): the support at u_spr = −6.5, y = 4.6 before the quasi-static instability
 * u_spr* = −11.09, where the spring already pulls (≈ 0.6 F_JKR) but the barrier is still ~5× the one
 * at which the body escapes. The body is drawn at thermal equilibrium there; the approach ends 0.01 R
 * later on the height trigger and the retract pulls it off at u_spr ≈ −9.5 ± 0.2 (force minimum and
 * instability still ahead), ~3000 time units = ~3000 relaxation times 1/η after the start. A start
 * at y = 10.1 (group "options") gave the same pull-off statistics within 0.5 standard errors at 2.7×
 * the cost. (The core's speed options are off in these groups.)
 *
 * Each row is one campaign of N curves (indices 0..N−1, the same seeds in every row; common random
 * numbers across time steps are impossible, so rows are independent samples). Statistics in F_JKR:
 * observable 2 (pulloff_spring_N, the paper's pull-off force) and 3 (detach_force_N). Bias against the
 * group's reference (dt₀/4 with the same integrator family) with the combined standard error
 * √(se² + se_ref²); distribution error: the two-sample KS distance with its 5% critical value
 * 1.36·√((n + m)/(n·m)) (= 1.36√(2/N) for equal sizes).
 *
 * Groups: underdamped (gjf, baoab, paper-vv with uniform noise = the paper's method; reference gjf at
 * dt₀/4) and overdamped (brownian at ζ = mη = 0.01, a different model with its own reference). The
 * overdamped step is ~15× smaller at the same ω·dt (K_max·dt/ζ instead of ω_max·dt), so that group
 * costs ~15× more per curve; N_bd sets its size.
 *
 * Group "options": the core's speed options (well_exact: one exact step of the linearised contact well
 * per sample interval; omega_dt_far: a larger step), which act only in contact farther than y_near
 * from the instability, against plain gjf and its own dt₀/4 reference, from a start at u_spr = −1
 * (y = 10.1) that leaves them room.
 *
 * Group "presets" (issue #13, the default step chosen by evidence): each case of s_cases is a scene as a
 * user runs it (a preset, maybe with one change: a stiffer lever, a start near the instability, the
 * coldest or hottest temperature of the studies), the core's default shortcuts on, only omega_dt changed;
 * rows at the case's reference step (dt0/4; dt0/2 or dt0 where a curve is costly) and the candidate steps
 * above. Besides bias/se_c each row reports its bias in units of a 2000-curve campaign's standard error
 * (sd/sqrt 2000), the figure the default is held to. Group "athermal": the same cases at T = 0, one curve
 * per row (exact bias, no noise). "caseI," in groups keeps only the cases named (e.g.
 * "presets,case0,case5,"). Written to default_step.{csv,md} and default_step_athermal.{csv,md};
 * bench/run_default_step.sh runs every case in its own process and bench/default_step_fit.py analyses them.
 *
 * Usage: bench_work_precision [outdir [N [N_bd [groups [threads]]]]]   (defaults ".", 2000, N,
 * "underdamped,overdamped,options", 0 = all cores; N_bd = 0 skips the overdamped group; N caps a preset
 * case's curves per row). Writes work_precision.csv and work_precision.md, prints the markdown to stdout
 * and progress to stderr.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench_util.h"
#include "vafm/campaign.h"
#include "vafm/integrator.h"
#include "vafm/params.h"
#include "vafm/sim.h"
#include "vafm/units.h"
#include "core/internal.h"

#define S_N_DEFAULT 2000
#define S_NOBS 2
#define S_PAPER_OMEGA_DT (2.0 * M_PI / 40.0)
#define S_REF_OMEGA_DT (S_PAPER_OMEGA_DT / 4.0)
#define S_Z_OK 2.0 /* "within 2 standard errors" */

static const double s_omega_dts[] = { S_PAPER_OMEGA_DT, 0.3, 0.6, 1.0, 1.5 };
#define S_NDT ((int)(sizeof s_omega_dts / sizeof s_omega_dts[0]))
#define S_N_CAMPAIGN 2000 /* the campaign whose standard error the default step's bias is held against */

static int s_threads; /* worker threads of every campaign (0: all cores) */

/* ---- clocks ------------------------------------------------------------------------------------ */

/* ---- rows -------------------------------------------------------------------------------------- */

/* group "presets": a scene as a user runs it (the table is below, s_cases) */
typedef struct s_case s_case;
struct s_case {
    const char *name;
    const char *preset;
    void (*tweak)(vafm_params *p); /* NULL: the preset as it is */
    double ref_omega_dt;           /* the reference row's step (dt0/4 unless the case is too costly) */
    uint64_t N;                    /* curves per row (capped by the run's N) */
    const char *what;
};


typedef struct s_row {
    /* configuration */
    const char *group;
    const s_case *cs;    /* group "presets": the case (a scene as a user runs it), else NULL */
    const vafm_integrator_type *it;
    int noise;
    double omega_dt;
    double omega_dt_far; /* the core's adaptive step far from the instability (0: off) */
    int well_exact;      /* the core's exact contact-well step far from the instability */
    double uspr_start;   /* reduced support position at the start */
    int is_ref;
    uint64_t N;
    /* derived numerics */
    double dt, stab; /* reduced step and ω_max·dt (K_max·dt/ζ overdamped) actually used */
    double y_near;   /* u_spr − u_spr* below which the options stop acting */
    /* results */
    uint64_t n_ok, n_failed, n_flagged, steps;
    double cpu_s, wall_s;
    double *obs[S_NOBS]; /* per curve, F_JKR units, NaN where excluded */
    double sd[S_NOBS], mean[S_NOBS], se[S_NOBS], bias[S_NOBS], se_c[S_NOBS], z[S_NOBS], ks[S_NOBS], ks_crit[S_NOBS];
} s_row;

/* What a report says of all its rows together. */
typedef struct s_totals {
    uint64_t excluded; /* curves left out of the statistics (N − n_ok) */
    uint64_t failed, flagged;
    double cpu_s;
} s_totals;

static s_totals s_sum_rows(const s_row *rows, int n)
{
    s_totals t = { 0, 0, 0, 0.0 };
    for (int i = 0; i < n; i++) {
        t.excluded += rows[i].N - rows[i].n_ok;
        t.failed += rows[i].n_failed;
        t.flagged += rows[i].n_flagged;
        t.cpu_s += rows[i].cpu_s;
    }
    return t;
}

static void s_row_free(s_row *r)
{
    for (int j = 0; j < S_NOBS; j++) {
        free(r->obs[j]);
        r->obs[j] = NULL;
    }
}

static const char *s_noise_name(int noise)
{
    return noise == VAFM_NOISE_UNIFORM ? "uniform" : "gaussian";
}

static int s_has_options(const s_row *r)
{
    return r->omega_dt_far > 0 || r->well_exact;
}

static void s_label(const s_row *r, char *buf, size_t len)
{
    if (r->well_exact)
        snprintf(buf, len, "%.4g + well_exact", r->omega_dt);
    else if (r->omega_dt_far > 0)
        snprintf(buf, len, "%.4g (far %.3g)", r->omega_dt, r->omega_dt_far);
    else
        snprintf(buf, len, "%.4g%s", r->omega_dt, r->is_ref ? " (ref)" : "");
}

/* ---- the scene --------------------------------------------------------------------------------- */

#define S_USPR_START (-6.5)     /* reduced: see the file comment */
#define S_USPR_START_FAR (-1.0) /* the options group: room for the far region */

static void s_scene(vafm_params *p, const s_row *r)
{
    if (r->cs) {
        vafm_preset_apply(p, r->cs->preset, NULL);
        if (r->cs->tweak)
            r->cs->tweak(p);
        p->omega_dt = r->omega_dt;
        if (!strcmp(r->group, "athermal"))
            p->T_K = 0.0; /* deterministic: one curve gives the step's bias exactly */
        vafm_params_resolve(p, NULL);
        return;
    }
    vafm_preset_apply(p, "paper-fig4", NULL);
    const double R = p->R_m;
    p->start_in_contact = 1;
    p->start_height_m = -r->uspr_start * R;
    p->trigger = VAFM_TRIGGER_HEIGHT;
    p->trigger_height_m = p->start_height_m - 0.01 * R;
    p->integrator = r->it;
    p->noise = r->noise;
    p->omega_dt = r->omega_dt;
    p->omega_dt_far = r->omega_dt_far;
    p->well_exact = r->well_exact;
}

/* ---- group "presets": the default step chosen by evidence (issue #13) ---------------------------
 * Each case is a scene as a user runs it: a preset with the core's default shortcuts (exact free steps,
 * the JKR table, the exact well step), only omega_dt changed, one thread. */

static void s_tweak_k10(vafm_params *p)
{
    p->k_N_per_m *= 10.0; /* f0 and Q kept: the mass and friction follow the stiffer lever */
}

static void s_tweak_near(vafm_params *p)
{
    /* the underdamped group's scene: paper-fig4 started in contact 4.6 R before the instability */
    const double R = p->R_m;
    p->start_in_contact = 1;
    p->start_height_m = -S_USPR_START * R;
    p->trigger = VAFM_TRIGGER_HEIGHT;
    p->trigger_height_m = p->start_height_m - 0.01 * R;
}

static void s_tweak_near_bd(vafm_params *p)
{
    /* the overdamped group's scene: the same start, brownian at zeta = m eta = 0.01 (not capped by the
     * brownian step's dt <= 1/(20 eta), which makes every omega_dt >= 0.13 of paper-fig4-bd one step) */
    s_tweak_near(p);
    p->integrator = vafm_integrator_brownian;
}

static void s_tweak_kT(vafm_params *p, double kT)
{
    vafm_reduced r;
    vafm_units_reduce(p, &r);
    r.kT = kT;
    vafm_units_from_reduced(p, &r);
}

static void s_tweak_kT_cold(vafm_params *p)
{
    s_tweak_kT(p, 0.003); /* the velocity-thermal study's coldest */
}

static void s_tweak_kT_hot(vafm_params *p)
{
    s_tweak_kT(p, 0.03); /* its hottest */
}

static void s_tweak_T70(vafm_params *p)
{
    p->T_K = 70.0; /* the distribution study's coldest */
}

static void s_tweak_T1121(vafm_params *p)
{
    p->T_K = 1121.0; /* its hottest (4 x 280.4 K) */
}

static const s_case s_cases[] = {
    { "contact-silica", "contact-silica", NULL, S_REF_OMEGA_DT, 2000, "the tools' default scene" },
    { "cell-liquid", "cell-liquid", NULL, S_REF_OMEGA_DT, 2000, "Hertz, no adhesion: forces in sqrt(k kT)" },
    { "colloid-pdms", "colloid-pdms", NULL, S_REF_OMEGA_DT, 2000, "" },
    { "stiff-polymer", "stiff-polymer", NULL, S_REF_OMEGA_DT, 2000, "40 N/m, Q 400" },
    { "contact-silica k x10", "contact-silica", s_tweak_k10, S_REF_OMEGA_DT, 2000, "stiff spring: 1 N/m" },
    { "paper-fig4 (Langevin)", "paper-fig4", NULL, S_REF_OMEGA_DT, 2000, "kT~ 0.01" },
    { "paper-fig4 kT~ 0.003", "paper-fig4", s_tweak_kT_cold, S_REF_OMEGA_DT, 2000, "coldest of velocity-thermal" },
    { "paper-fig4 kT~ 0.03", "paper-fig4", s_tweak_kT_hot, S_REF_OMEGA_DT, 2000, "hottest of velocity-thermal" },
    { "near instability", "paper-fig4", s_tweak_near, S_REF_OMEGA_DT, 2000,
      "the underdamped group's start, u_spr = -6.5" },
    { "paper-fig4-bd (Brownian)", "paper-fig4-bd", NULL, S_REF_OMEGA_DT, 1000,
      "brownian, zeta = 1: dt <= 1/(20 eta) caps every omega_dt >= 0.13 to one step" },
    { "near instability, brownian", "paper-fig4", s_tweak_near_bd, S_PAPER_OMEGA_DT / 2.0, 400,
      "the overdamped group's scene: brownian at zeta = 0.01" },
    { "paper-fig1 70 K", "paper-fig1", s_tweak_T70, S_REF_OMEGA_DT, 400, "coldest of distribution" },
    { "paper-fig1 1121 K", "paper-fig1", s_tweak_T1121, S_REF_OMEGA_DT, 100, "hottest of distribution" },
};
#define S_NCASES ((int)(sizeof s_cases / sizeof s_cases[0]))

/* The force unit of a case: F_JKR = 3 pi gamma R / 2, or sqrt(k kT) (the thermal force) without adhesion. */
static double s_F_jkr_N(const vafm_params *p)
{
    if (p->gamma_J_per_m2 > 0 || p->T_K == 0)
        return 1.5 * M_PI * p->gamma_J_per_m2 * p->R_m;
    return sqrt(p->k_N_per_m * VAFM_KB_J_PER_K * p->T_K);
}

/* ---- running a row ----------------------------------------------------------------------------- */

typedef struct s_collect {
    s_row *row;
    double F_jkr_N;
    int adhesive;
    uint64_t done, next_report;
    double t0;
} s_collect;

static int s_on_curve(void *user, const vafm_campaign_curve *c)
{
    s_collect *col = user;
    s_row *r = col->row;
    const vafm_curve_result *res = &c->result;
    /* without adhesion (cell-liquid) thermal touch-and-go before the retract is the scene's nature: kept */
    const int bad_flags = VAFM_CURVE_NO_CONTACT | VAFM_CURVE_NO_TRIGGER |
                          (col->adhesive ? VAFM_CURVE_EARLY_DETACH | VAFM_CURVE_NO_DETACH : 0);
    double o[S_NOBS] = { res->pulloff_spring_N / col->F_jkr_N, res->detach_force_N / col->F_jkr_N };
    int ok = c->status == 0 && !(res->flags & bad_flags) && isfinite(o[0]) && isfinite(o[1]);
    if (c->status)
        r->n_failed++;
    if (res->flags)
        r->n_flagged++;
    for (int j = 0; j < S_NOBS; j++)
        r->obs[j][c->index] = ok ? o[j] : NAN;
    r->n_ok += (uint64_t)ok;
    r->steps += res->steps;
    if (++col->done >= col->next_report) {
        fprintf(stderr, "    %llu / %llu curves, %.0f s\n", (unsigned long long)col->done,
                (unsigned long long)r->N, bench_clock_s(CLOCK_MONOTONIC) - col->t0);
        col->next_report += r->N / 10 ? r->N / 10 : 1;
    }
    return 0;
}

static void s_stats(s_row *r)
{
    for (int j = 0; j < S_NOBS; j++) {
        double s = 0.0, ss = 0.0;
        uint64_t n = 0;
        for (uint64_t i = 0; i < r->N; i++)
            if (isfinite(r->obs[j][i])) {
                s += r->obs[j][i];
                n++;
            }
        double mean = n ? s / (double)n : NAN;
        for (uint64_t i = 0; i < r->N; i++)
            if (isfinite(r->obs[j][i]))
                ss += (r->obs[j][i] - mean) * (r->obs[j][i] - mean);
        r->mean[j] = mean;
        r->sd[j] = n > 1 ? sqrt(ss / (double)(n - 1)) : NAN;
        r->se[j] = n > 1 ? r->sd[j] / sqrt((double)n) : NAN;
    }
}

static int s_run_row(s_row *r)
{
    vafm_params p;
    vafm_numerics nm;
    vafm_error err;
    s_scene(&p, r);
    if (vafm_numerics_check(&p, &nm, &err)) {
        fprintf(stderr, "bench_work_precision: %s omega_dt %g: %s\n", r->it->name, r->omega_dt, err.message);
        return -1;
    }
    r->dt = nm.dt;
    r->stab = nm.stab;
    r->y_near = nm.y_near;
    for (int j = 0; j < S_NOBS; j++) {
        if (!(r->obs[j] = malloc(r->N * sizeof(double))))
            return -1;
        for (uint64_t i = 0; i < r->N; i++)
            r->obs[j][i] = NAN; /* a curve never delivered stays out of the statistics */
    }
    char lab[48];
    s_label(r, lab, sizeof lab);
    if (r->cs)
        fprintf(stderr, "  [%s]", r->cs->name);
    fprintf(stderr, "  %s %s (%s noise) omega_dt %s, dt %.4g, %llu curves\n", r->group, r->it->name,
            s_noise_name(r->noise), lab, r->dt, (unsigned long long)r->N);
    vafm_campaign_spec spec;
    memset(&spec, 0, sizeof spec);
    spec.curves_per_point = r->N;
    spec.threads = s_threads;
    s_collect col = { r, s_F_jkr_N(&p), p.gamma_J_per_m2 > 0 || !r->cs, 0, r->N / 10 ? r->N / 10 : 1, bench_clock_s(CLOCK_MONOTONIC) };
    double c0 = bench_clock_s(CLOCK_PROCESS_CPUTIME_ID), w0 = col.t0;
    int rc = vafm_campaign_run(&p, &spec, s_on_curve, &col, &err);
    r->cpu_s = bench_clock_s(CLOCK_PROCESS_CPUTIME_ID) - c0;
    r->wall_s = bench_clock_s(CLOCK_MONOTONIC) - w0;
    if (rc) {
        fprintf(stderr, "bench_work_precision: campaign: %s\n", err.message);
        return -1;
    }
    s_stats(r);
    fprintf(stderr, "    done: %.1f s CPU, %.1f s wall; obs2 %.5f +- %.5f, obs3 %.5f +- %.5f F_JKR; %llu excluded\n",
            r->cpu_s, r->wall_s, r->mean[0], r->se[0], r->mean[1], r->se[1], (unsigned long long)(r->N - r->n_ok));
    return 0;
}

/* ---- comparison against the reference ---------------------------------------------------------- */

/* The finite values of x, sorted, into out; @return their number. */
static size_t s_sorted_finite(const double *x, uint64_t n, double *out)
{
    size_t m = 0;
    for (uint64_t i = 0; i < n; i++)
        if (isfinite(x[i]))
            out[m++] = x[i];
    return m;
}

/* Two-sample Kolmogorov–Smirnov distance sup|F_a − F_b| of sorted samples (ties stepped together). */
static double s_ks_sorted(const double *a, size_t na, const double *b, size_t nb)
{
    size_t i = 0, j = 0;
    double d = 0.0;
    while (i < na && j < nb) {
        double v = a[i] < b[j] ? a[i] : b[j];
        while (i < na && a[i] == v)
            i++;
        while (j < nb && b[j] == v)
            j++;
        double diff = fabs((double)i / (double)na - (double)j / (double)nb);
        if (diff > d)
            d = diff;
    }
    return d;
}

static int s_compare(s_row *r, const s_row *ref)
{
    double *a = malloc(r->N * sizeof *a), *b = malloc(ref->N * sizeof *b);
    if (!a || !b) {
        free(a);
        free(b);
        return -1;
    }
    for (int j = 0; j < S_NOBS; j++) {
        size_t na = s_sorted_finite(r->obs[j], r->N, a), nb = s_sorted_finite(ref->obs[j], ref->N, b);
        qsort(a, na, sizeof *a, bench_cmp_double);
        qsort(b, nb, sizeof *b, bench_cmp_double);
        r->bias[j] = r->mean[j] - ref->mean[j];
        r->se_c[j] = r->is_ref ? r->se[j] : sqrt(r->se[j] * r->se[j] + ref->se[j] * ref->se[j]);
        r->z[j] = r->is_ref ? 0.0 : r->bias[j] / r->se_c[j];
        r->ks[j] = na && nb ? s_ks_sorted(a, na, b, nb) : NAN;
        r->ks_crit[j] = na && nb ? 1.36 * sqrt((double)(na + nb) / ((double)na * (double)nb)) : NAN;
    }
    free(a);
    free(b);
    return 0;
}

/* ---- output ------------------------------------------------------------------------------------ */

static double s_steps_per_curve(const s_row *r)
{
    return (double)r->steps / (double)r->N;
}

static void s_write_csv(FILE *f, const s_row *rows, int n)
{
    fprintf(f, "group,integrator,noise,omega_dt,omega_dt_far,well_exact,uspr_start,is_ref,dt_reduced,omega_max_dt,"
               "steps_per_curve,n,n_ok,n_failed,n_flagged,cpu_s,wall_s,curves_per_s");
    for (int j = 0; j < S_NOBS; j++) {
        const char *o = j ? "obs3" : "obs2";
        fprintf(f, ",%s_mean,%s_se,%s_bias,%s_se_combined,%s_bias_over_se,%s_ks,%s_ks_crit", o, o, o, o, o, o, o);
    }
    fputc('\n', f);
    for (int i = 0; i < n; i++) {
        const s_row *r = &rows[i];
        fprintf(f, "%s,%s,%s,%.6g,%.6g,%d,%.6g,%d,%.6g,%.6g,%.6g,%llu,%llu,%llu,%llu,%.4f,%.4f,%.6g", r->group,
                r->it->name, s_noise_name(r->noise), r->omega_dt, r->omega_dt_far, r->well_exact, r->uspr_start,
                r->is_ref, r->dt, r->stab, s_steps_per_curve(r),
                (unsigned long long)r->N, (unsigned long long)r->n_ok, (unsigned long long)r->n_failed,
                (unsigned long long)r->n_flagged, r->cpu_s, r->wall_s, (double)r->N / r->wall_s);
        for (int j = 0; j < S_NOBS; j++)
            fprintf(f, ",%.8f,%.8f,%.8f,%.8f,%.4f,%.6f,%.6f", r->mean[j], r->se[j], r->bias[j], r->se_c[j], r->z[j],
                    r->ks[j], r->ks_crit[j]);
        fputc('\n', f);
    }
}

static void s_md_obs_cells(FILE *f, const s_row *r, int j)
{
    fprintf(f, " %.5f ± %.5f |", r->mean[j], r->se[j]);
    if (r->is_ref)
        fprintf(f, " reference | - | - |");
    else
        fprintf(f, " %+.5f ± %.5f | %+.1f%s | %.3f%s |", r->bias[j], r->se_c[j], r->z[j],
                fabs(r->z[j]) > S_Z_OK ? " **" : "", r->ks[j], r->ks[j] > r->ks_crit[j] ? " **" : "");
}

static void s_write_tables(FILE *f, const s_row *rows, int n)
{
    char lab[48];
    fprintf(f, "| group | integrator | noise | omega_dt | dt | steps/curve | CPU s | wall s | curves/s | "
               "F2/F_JKR ± se | bias ± se_c | bias/se_c | KS |\n"
               "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (int i = 0; i < n; i++) {
        const s_row *r = &rows[i];
        s_label(r, lab, sizeof lab);
        fprintf(f, "| %s | %s | %s | %s | %.3g | %.3g | %.2f | %.2f | %.1f |", r->group, r->it->name,
                s_noise_name(r->noise), lab, r->dt, s_steps_per_curve(r), r->cpu_s, r->wall_s,
                (double)r->N / r->wall_s);
        s_md_obs_cells(f, r, 0);
        fputc('\n', f);
    }
    fprintf(f, "\nObservable 3 (detach_force_N: the spring force when the body passes u_min), same runs:\n\n"
               "| group | integrator | omega_dt | F3/F_JKR ± se | bias ± se_c | bias/se_c | KS |\n"
               "|---|---|---|---|---|---|---|\n");
    for (int i = 0; i < n; i++) {
        const s_row *r = &rows[i];
        s_label(r, lab, sizeof lab);
        fprintf(f, "| %s | %s | %s |", r->group, r->it->name, lab);
        s_md_obs_cells(f, r, 1);
        fputc('\n', f);
    }
}

static int s_within(const s_row *r)
{
    for (int j = 0; j < S_NOBS; j++)
        if (!(fabs(r->z[j]) <= S_Z_OK))
            return 0;
    return 1;
}

/* Per integrator of a group: the largest ω·dt whose row, and every smaller one, is within 2 se_c. */
static void s_write_largest_dt(FILE *f, const s_row *rows, int n, const char *group)
{
    const vafm_integrator_type *seen[8];
    int n_seen = 0;
    fprintf(f, "Largest omega_dt with it and every smaller step within %.0f se_c on both observables:", S_Z_OK);
    for (int i = 0; i < n; i++) {
        const s_row *r = &rows[i];
        int known = 0;
        for (int k = 0; k < n_seen; k++)
            known |= seen[k] == r->it;
        if (strcmp(r->group, group) || r->is_ref || s_has_options(r) || known || n_seen == 8)
            continue;
        seen[n_seen++] = r->it;
        double largest = NAN;
        for (int j = i; j < n; j++) { /* the rows of one integrator come in increasing ω·dt */
            const s_row *q = &rows[j];
            if (q->it != r->it || strcmp(q->group, group) || q->is_ref || s_has_options(q))
                continue;
            if (!s_within(q))
                break;
            largest = q->omega_dt;
        }
        if (isnan(largest))
            fprintf(f, "%s %s none", n_seen > 1 ? "," : "", r->it->name);
        else
            fprintf(f, "%s %s %.3g", n_seen > 1 ? "," : "", r->it->name, largest);
    }
    fprintf(f, ". ");
}

/* gjf and baoab fed the same normals: how far apart their means are (largest over the common steps). */
static double s_gjf_baoab_gap(const s_row *rows, int n)
{
    double gap = NAN;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++)
            if (rows[i].it == vafm_integrator_gjf && rows[j].it == vafm_integrator_baoab && !rows[i].is_ref &&
                !s_has_options(&rows[i]) && !strcmp(rows[i].group, rows[j].group) &&
                rows[i].omega_dt == rows[j].omega_dt)
                for (int o = 0; o < S_NOBS; o++) {
                    double d = fabs(rows[i].mean[o] - rows[j].mean[o]);
                    if (isnan(gap) || d > gap)
                        gap = d;
                }
    return gap;
}

/* The reading: per group, the cheapest row whose bias is within 2 combined standard errors on both
 * observables, against the group's baseline (the paper's method at the paper's step, or the
 * overdamped integrator at that ω·dt). */
static void s_write_reading(FILE *f, const s_row *rows, int n)
{
    const char *groups[] = { "underdamped", "overdamped", "options" };
    for (int g = 0; g < 3; g++) {
        const s_row *best = NULL, *base = NULL;
        int n_rows = 0, n_out = 0, n_ks = 0;
        for (int i = 0; i < n; i++) {
            const s_row *r = &rows[i];
            if (strcmp(r->group, groups[g]) || r->is_ref)
                continue;
            n_rows++;
            if (!s_within(r))
                n_out++;
            if (r->ks[0] > r->ks_crit[0] || r->ks[1] > r->ks_crit[1])
                n_ks++;
            /* the baseline: the paper's step without options, the paper's method where the group has it */
            if (r->omega_dt == S_PAPER_OMEGA_DT && !s_has_options(r) && (!base || r->it == vafm_integrator_paper_vv))
                base = r;
            if (s_within(r) && (!best || r->cpu_s < best->cpu_s))
                best = r;
        }
        if (!n_rows)
            continue;
        char lab[48];
        fprintf(f, "%s: %d of %d rows have a bias beyond %.0f combined standard errors on at least one observable, "
                   "%d exceed the 5%% KS critical value on at least one. ",
                groups[g], n_out, n_rows, S_Z_OK, n_ks);
        if (g < 2)
            s_write_largest_dt(f, rows, n, groups[g]);
        if (best) {
            s_label(best, lab, sizeof lab);
            fprintf(f, "The cheapest within %.0f standard errors on both observables is %s (%s noise) at omega_dt = "
                       "%s: "
                       "%.1f CPU s for %llu curves",
                    S_Z_OK, best->it->name, s_noise_name(best->noise), lab, best->cpu_s, (unsigned long long)best->N);
            if (base && base != best)
                fprintf(f, ", %.1fx cheaper than %s at the paper's omega_dt = %.3f (%.1f CPU s)",
                        base->cpu_s / best->cpu_s, base->it->name, base->omega_dt, base->cpu_s);
            fprintf(f, ".\n\n");
        } else {
            fprintf(f, "No row is within %.0f standard errors on both observables.\n\n", S_Z_OK);
        }
    }
    const s_totals tot = s_sum_rows(rows, n);
    fprintf(f, "Curves left out of the statistics (failed, no contact, early or no detachment): %llu, of which %llu "
               "failed; curves with any flag (including a recontact after the pull-off, which are kept): %llu.\n\n",
            (unsigned long long)tot.excluded, (unsigned long long)tot.failed, (unsigned long long)tot.flagged);
    double gap = s_gjf_baoab_gap(rows, n);
    if (!isnan(gap))
        fprintf(f, "gjf and baoab draw the same normals and differ only at O((eta dt)^3) in their damping and noise "
                   "coefficients (eta dt <= 0.1 here): their means agree to %.1e F_JKR at every step, so their rows "
                   "are one measurement, not two.\n",
                gap);
}

static void s_write_md(FILE *f, const s_row *rows, int n, uint64_t N, uint64_t N_bd, double load0, double load1)
{
    fprintf(f, "## Work against precision (bench_work_precision)\n\n");
    fprintf(f, "Scene: paper-fig4 (gamma~ = 0.229, k~ = 0.1, kT~ = 0.01, v~ = 1e-3, m~ = 0.01) started in contact "
               "at u_spr = %.1f (y = %.1f before the quasi-static instability u_spr* = -11.09; start_in_contact, the "
               "body drawn at thermal equilibrium), height trigger 0.01 R later, retract through the pull-off "
               "(at u_spr = -9.5 +- 0.2). Curves 0..N-1 (same seeds) per row, N = %llu (overdamped group: %llu), "
               "via vafm_campaign_run on all cores (load average %.2f before, %.2f after). CPU s = "
               "CLOCK_PROCESS_CPUTIME_ID over the campaign (all threads); curves/s by wall time. Forces in F_JKR = "
               "3 pi gamma R / 2; F2 = pulloff_spring_N (the paper's pull-off force: most tensile spring force), "
               "F3 = detach_force_N. Reference per group: the same family at dt0/4 (omega_dt = %.5f), dt0 = the "
               "paper's omega_dt = 2pi/40. bias/se_c uses se_c = sqrt(se^2 + se_ref^2); KS: two-sample distance to "
               "the reference; ** where |bias| > 2 se_c or KS is above its 5%% critical value 1.36 sqrt(2/N) "
               "(= %.4f at N = %llu). omega_dt is omega_max dt at the stiffest contact the scene may reach "
               "(K_max dt/zeta for brownian); dt is reduced (unit 1/eta).\n\n",
            S_USPR_START, S_USPR_START + 11.094265, (unsigned long long)N, (unsigned long long)N_bd, load0, load1,
            S_REF_OMEGA_DT, 1.36 * sqrt(2.0 / (double)N), (unsigned long long)N);
    for (int i = 0; i < n; i++)
        if (!strcmp(rows[i].group, "options")) {
            fprintf(f, "Group options: the core's speed options against plain gjf, from a start farther from the "
                       "pull (u_spr = %.1f, y = %.1f) with its own gjf dt0/4 reference. Both act only in contact "
                       "with y > y_near = %.2f (near_barrier_kT = its default): well_exact takes one exact step of "
                       "the linearised contact well per sample interval, omega_dt_far a larger integrator step.\n\n",
                    rows[i].uspr_start, rows[i].uspr_start + 11.094265, rows[i].y_near);
            break;
        }
    s_write_tables(f, rows, n);
    fprintf(f, "\n");
    s_write_reading(f, rows, n);
}

static int s_emit(const char *dir, const s_row *rows, int n, uint64_t N, uint64_t N_bd, double load0, double load1)
{
    FILE *f = bench_open("bench_work_precision", dir, "work_precision.csv");
    if (!f)
        return -1;
    s_write_csv(f, rows, n);
    fclose(f);
    if (!(f = bench_open("bench_work_precision", dir, "work_precision.md")))
        return -1;
    s_write_md(f, rows, n, N, N_bd, load0, load1);
    fclose(f);
    s_write_md(stdout, rows, n, N, N_bd, load0, load1);
    return 0;
}

/* ---- output of group "presets" ----------------------------------------------------------------- */

/* The standard error of a campaign of S_N_CAMPAIGN curves of this row's scene (the row's sd / sqrt 2000). */
static double s_se_campaign(const s_row *r, int j)
{
    return r->sd[j] / sqrt((double)S_N_CAMPAIGN);
}

static double s_case_unit_N(const s_row *r)
{
    vafm_params p;
    s_scene(&p, r);
    return s_F_jkr_N(&p);
}

static void s_write_case_csv(FILE *f, const s_row *rows, int n)
{
    fprintf(f, "case,preset,integrator,omega_dt,is_ref,dt_reduced,omega_max_dt,steps_per_curve,n,n_ok,n_failed,"
               "n_flagged,threads,cpu_s,wall_s,F_unit_N");
    for (int j = 0; j < S_NOBS; j++) {
        const char *o = j ? "obs3" : "obs2";
        fprintf(f, ",%s_mean,%s_sd,%s_se,%s_bias,%s_se_combined,%s_bias_over_se,%s_bias_over_se%d,%s_ks,%s_ks_crit",
                o, o, o, o, o, o, o, S_N_CAMPAIGN, o, o);
    }
    fputc('\n', f);
    for (int i = 0; i < n; i++) {
        const s_row *r = &rows[i];
        fprintf(f, "\"%s\",%s,%s,%.6g,%d,%.6g,%.6g,%.6g,%llu,%llu,%llu,%llu,%d,%.4f,%.4f,%.6g", r->cs->name,
                r->cs->preset, r->it->name, r->omega_dt, r->is_ref, r->dt, r->stab, s_steps_per_curve(r),
                (unsigned long long)r->N, (unsigned long long)r->n_ok, (unsigned long long)r->n_failed,
                (unsigned long long)r->n_flagged, s_threads, r->cpu_s, r->wall_s, s_case_unit_N(r));
        for (int j = 0; j < S_NOBS; j++)
            fprintf(f, ",%.9g,%.9g,%.9g,%.9g,%.9g,%.4f,%.4f,%.6f,%.6f", r->mean[j], r->sd[j], r->se[j], r->bias[j],
                    r->se_c[j], r->z[j], r->bias[j] / s_se_campaign(r, j), r->ks[j], r->ks_crit[j]);
        fputc('\n', f);
    }
}

static void s_write_case_md(FILE *f, const s_row *rows, int n, double load0, double load1)
{
    fprintf(f, "## The default step: work against precision per scene (bench_work_precision, group presets)\n\n"
               "Each case is a scene as a user runs it (the preset with the core's default shortcuts: exact free "
               "steps, the JKR table, the exact well step), gjf (brownian for paper-fig4-bd), only omega_dt "
               "changed; %d thread(s), load average %.2f before and %.2f after. Curves 0..N-1 (same seeds) per row. "
               "Forces in F_JKR = 3 pi gamma R / 2 (cell-liquid: sqrt(k kT), it has no adhesion). F2 = "
               "pulloff_spring_N, F3 = detach_force_N. bias against the case's reference row (dt0/4 unless said); "
               "/se_c: combined standard error; /se%d: the standard error of a %d-curve campaign of that scene "
               "(sd/sqrt(%d)); KS: two-sample distance to the reference (** above its 5%% critical value).\n\n",
            s_threads, load0, load1, S_N_CAMPAIGN, S_N_CAMPAIGN, S_N_CAMPAIGN);
    if (n && !strcmp(rows[0].group, "athermal"))
        fprintf(f, "These rows are athermal (T = 0, one curve each, reference dt0/4): every curve is the same, so "
                   "the bias is exact and there is no standard error; set it against the thermal case's se%d "
                   "(bench/default_step_fit.py).\n\n", S_N_CAMPAIGN);
    const s_case *cur = NULL;
    for (int i = 0; i < n; i++) {
        const s_row *r = &rows[i];
        if (r->cs != cur) {
            cur = r->cs;
            fprintf(f, "%s**%s** (preset %s%s%s; N = %llu per row)\n\n"
                       "| omega_dt | steps/curve | CPU s | F2/F ± se | bias2/se_c | bias2/se%d | KS2 | "
                       "F3/F ± se | bias3/se_c | bias3/se%d | KS3 |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
                    i ? "\n" : "", cur->name, cur->preset, *cur->what ? "; " : "", cur->what, (unsigned long long)r->N,
                    S_N_CAMPAIGN, S_N_CAMPAIGN);
        }
        fprintf(f, "| %.4g%s | %.3g | %.2f |", r->omega_dt, r->is_ref ? " (ref)" : "", s_steps_per_curve(r), r->cpu_s);
        for (int j = 0; j < S_NOBS; j++) {
            fprintf(f, " %.5f ± %.5f |", r->mean[j], r->se[j]);
            if (r->is_ref)
                fprintf(f, " – | – | – |");
            else
                fprintf(f, " %+.1f | %+.2f | %.3f%s |", r->z[j], r->bias[j] / s_se_campaign(r, j), r->ks[j],
                        r->ks[j] > r->ks_crit[j] ? " **" : "");
        }
        fputc('\n', f);
    }
    const s_totals tot = s_sum_rows(rows, n);
    fprintf(f, "\nCurves left out (failed, no contact, early or no detachment): %llu; flagged (kept if only a "
               "recontact): %llu. CPU in all: %.0f s.\n",
            (unsigned long long)tot.excluded, (unsigned long long)tot.flagged, tot.cpu_s);
}

static int s_emit_cases(const char *dir, const char *stem, const s_row *rows, int n, double load0, double load1)
{
    char name[64];
    snprintf(name, sizeof name, "%s.csv", stem);
    FILE *f = bench_open("bench_work_precision", dir, name);
    if (!f)
        return -1;
    s_write_case_csv(f, rows, n);
    fclose(f);
    snprintf(name, sizeof name, "%s.md", stem);
    if (!(f = bench_open("bench_work_precision", dir, name)))
        return -1;
    s_write_case_md(f, rows, n, load0, load1);
    fclose(f);
    s_write_case_md(stdout, rows, n, load0, load1);
    return 0;
}

/* ---- the plan ---------------------------------------------------------------------------------- */

#define S_MAX_ROWS 128

static int s_plan(s_row *rows, uint64_t N, uint64_t N_bd, const char *groups)
{
    int n = 0;
    const struct {
        const vafm_integrator_type *const *it;
        int noise;
    } under[] = {
        { &vafm_integrator_gjf, VAFM_NOISE_GAUSSIAN },
        { &vafm_integrator_baoab, VAFM_NOISE_GAUSSIAN },
        { &vafm_integrator_paper_vv, VAFM_NOISE_UNIFORM },
    };
    const s_row ud = { .group = "underdamped", .it = vafm_integrator_gjf, .noise = VAFM_NOISE_GAUSSIAN,
                       .uspr_start = S_USPR_START, .N = N };
    if (strstr(groups, "underdamped")) {
        rows[n] = ud;
        rows[n].omega_dt = S_REF_OMEGA_DT;
        rows[n++].is_ref = 1;
        for (size_t k = 0; k < sizeof under / sizeof under[0]; k++)
            for (int d = 0; d < S_NDT; d++) {
                rows[n] = ud;
                rows[n].it = *under[k].it;
                rows[n].noise = under[k].noise;
                rows[n++].omega_dt = s_omega_dts[d];
            }
    }
    if (N_bd > 0 && strstr(groups, "overdamped")) {
        const s_row bd = { .group = "overdamped", .it = vafm_integrator_brownian, .noise = VAFM_NOISE_GAUSSIAN,
                           .uspr_start = S_USPR_START, .N = N_bd };
        rows[n] = bd;
        rows[n].omega_dt = S_REF_OMEGA_DT;
        rows[n++].is_ref = 1;
        for (int d = 0; d < S_NDT; d++) {
            rows[n] = bd;
            rows[n++].omega_dt = s_omega_dts[d];
        }
    }
    if (strstr(groups, "options")) {
        /* the core's speed options against plain gjf, from a start with room for them to act */
        const struct {
            double omega_dt, omega_dt_far;
            int well_exact, is_ref;
        } opt[] = {
            { S_REF_OMEGA_DT, 0.0, 0, 1 }, { S_PAPER_OMEGA_DT, 0.0, 0, 0 }, { S_PAPER_OMEGA_DT, 1.0, 0, 0 },
            { S_PAPER_OMEGA_DT, 0.0, 1, 0 }, { 0.6, 0.0, 0, 0 }, { 0.6, 0.0, 1, 0 },
        };
        for (size_t k = 0; k < sizeof opt / sizeof opt[0]; k++) {
            rows[n] = ud;
            rows[n].group = "options";
            rows[n].uspr_start = S_USPR_START_FAR;
            rows[n].omega_dt = opt[k].omega_dt;
            rows[n].omega_dt_far = opt[k].omega_dt_far;
            rows[n].well_exact = opt[k].well_exact;
            rows[n++].is_ref = opt[k].is_ref;
        }
    }
    for (int g = 0; g < 2; g++) {
        /* "presets": every case at its reference step and the candidate steps, the core's defaults on;
         * "athermal": the same at T = 0, one curve per row (dt0/4 reference; not cell-liquid: no adhesion) */
        const char *gname = g ? "athermal" : "presets";
        if (!strstr(groups, gname))
            continue;
        for (int c = 0; c < S_NCASES; c++) {
            const s_case *cs = &s_cases[c];
            char key[64];
            snprintf(key, sizeof key, "case%d,", c);
            if (strstr(groups, "case") && !strstr(groups, key))
                continue; /* "presets,case3,case5,": only those cases */
            vafm_params p;
            vafm_preset_apply(&p, cs->preset, NULL);
            if (cs->tweak)
                cs->tweak(&p);
            if (g && p.gamma_J_per_m2 == 0)
                continue;
            const s_row pr = { .group = gname, .cs = cs, .it = p.integrator, .noise = p.noise,
                               .omega_dt_far = p.omega_dt_far, .well_exact = p.well_exact,
                               .N = g ? 1 : cs->N < N ? cs->N : N };
            if (n + 1 + S_NDT > S_MAX_ROWS)
                break;
            const int i_ref = n;
            rows[n] = pr;
            rows[n].omega_dt = g ? S_REF_OMEGA_DT : cs->ref_omega_dt;
            rows[n++].is_ref = 1;
            for (int d = 0; d < S_NDT; d++) {
                if (s_omega_dts[d] == rows[i_ref].omega_dt)
                    continue; /* the reference is this step (a costly case): the same curves, not a new row */
                rows[n] = pr;
                rows[n++].omega_dt = s_omega_dts[d];
            }
        }
    }
    return n;
}

static uint64_t s_parse_count(const char *s, uint64_t dflt)
{
    char *end = NULL;
    unsigned long long v = strtoull(s, &end, 10);
    return end != s && *end == '\0' ? (uint64_t)v : dflt;
}

int main(int argc, char **argv)
{
    const char *dir = argc > 1 ? argv[1] : ".";
    uint64_t N = argc > 2 ? s_parse_count(argv[2], S_N_DEFAULT) : S_N_DEFAULT;
    if (N < 2)
        N = 2;
    uint64_t N_bd = argc > 3 ? s_parse_count(argv[3], N) : N;
    if (N_bd == 1)
        N_bd = 2;
    const char *groups = argc > 4 ? argv[4] : "underdamped,overdamped,options";
    s_threads = argc > 5 ? (int)s_parse_count(argv[5], 0) : 0;
    static s_row rows[S_MAX_ROWS];
    int n = s_plan(rows, N, N_bd, groups), rc = 0;
    fprintf(stderr, "work-precision: %d rows, N = %llu (overdamped N = %llu)\n", n, (unsigned long long)N,
            (unsigned long long)N_bd);
    double t0 = bench_clock_s(CLOCK_MONOTONIC), load0 = bench_loadavg();
    const s_row *ref = NULL;
    for (int i = 0; i < n && !rc; i++) {
        if (rows[i].is_ref)
            ref = &rows[i];
        rc = s_run_row(&rows[i]) || s_compare(&rows[i], ref);
    }
    fprintf(stderr, "work-precision: %.0f s wall in all\n", bench_clock_s(CLOCK_MONOTONIC) - t0);
    int n_classic = 0; /* the presets group's rows come last */
    while (n_classic < n && !rows[n_classic].cs)
        n_classic++;
    double load1 = bench_loadavg();
    if (!rc && n_classic)
        rc = s_emit(dir, rows, n_classic, N, N_bd, load0, load1);
    int n_presets = n_classic; /* then "presets", then "athermal" */
    while (n_presets < n && !strcmp(rows[n_presets].group, "presets"))
        n_presets++;
    if (!rc && n_presets > n_classic)
        rc = s_emit_cases(dir, "default_step", rows + n_classic, n_presets - n_classic, load0, load1);
    if (!rc && n > n_presets)
        rc = s_emit_cases(dir, "default_step_athermal", rows + n_presets, n - n_presets, load0, load1);
    for (int i = 0; i < n; i++)
        s_row_free(&rows[i]);
    return rc ? 1 : 0;
}
