/* SPDX-License-Identifier: MIT */
/*
 * The stepping kernel's shortcuts against the plain computation they replace:
 * - the tabulated JKR branch (jkr_table.h) against the exact Newton solver, over the whole table,
 *   near the branch end u_min, and beyond the table (fallback);
 * - a force curve with the table against one without: athermal results agree to ~1e-9 relative
 *   (the trajectories differ only by the interpolation error, ~1e-13, amplified by the snap);
 * - the exact contact-well step (well_exact.h): its (X, V) block against the closed-form 2×2
 *   propagator of free_ou.c, its integral I against the long-time limit Var(I) → q·h/ω⁴; and a
 *   thermal dwell in contact, whose output samples (mean, variance) must agree with plain GJF steps;
 * - the closed-form well transition (ω·h ≥ 1) against Van Loan's series; the well step at a few steps
 *   per sample: athermal curves agree with plain steps to 1e-6, thermal pull-off distributions and a
 *   dwell's sample mean and variance within their statistical errors;
 * - the adaptive step (omega_dt_far) against the plain one: athermal pull-off observables agree to
 *   1e-4 relative (the far zone is the deep, nearly harmonic well, where GJF's configurational error is
 *   nil for a harmonic well) while the step count falls. Its thermal accuracy is judged by the
 *   work-precision benchmark, not here.
 */
#include "harness.h"

#include <string.h>

#include "vafm/sim.h"
#include "vafm/theory.h"
#include "vafm/units.h"
#include "core/internal.h"
#include "core/jkr_table.h"
#include "core/kernel.h"
#include "core/well_exact.h"

static void test_table_accuracy(void)
{
    const double gammas[] = { 1.2e-4, 0.01, 0.229, 3.0 };
    for (size_t g = 0; g < sizeof gammas / sizeof gammas[0]; g++) {
        vafm_contact c;
        ENSURE(vafm_contact_init(&c, vafm_contact_jkr, gammas[g]) == 0);
        double u_max = 10.0 * c.a0 * c.a0;
        vafm_jkr_table T;
        ENSURE(vafm_jkr_table_init(&T, &c, u_max) == 0);
        ENSURE_MSG(T.max_err < 1e-13, "gamma %g: build error %g with %d nodes", gammas[g], T.max_err, T.n);
        /* a dense sweep, not only the midpoints the builder checked: uniform in ξ and log-spaced near u_min */
        double worst = 0.0;
        for (int i = 0; i <= 200000; i++) {
            double xi = T.xi_max * i / 200000.0;
            double u = c.u_detach + xi * xi;
            double s_tab = 0.0, s_ex = 0.0;
            double F_tab = vafm_jkr_table_force(&T, &c, u, &s_tab);
            double F_ex = c.type->force(&c, u, &s_ex, NULL);
            double scale = c.F_jkr; /* F crosses zero: judge against the force scale */
            double e = fabs(F_tab - F_ex) / scale;
            if (e > worst)
                worst = e;
        }
        ENSURE_MSG(worst < 1e-12, "gamma %g: worst force error %g F_JKR", gammas[g], worst);
        /* the table's last intervals and its edge: nodes run to ξ = (n−1)·h = ξ_max + h, the lookup
         * interpolates below it and hands x ≥ n−1 to the exact solver. A sweep over (ξ_max, ξ_max + 2h],
         * edges included, catches a lookup that accepts x in [n−1, n) (it reads node n, one past the end) */
        worst = 0.0;
        for (int i = 1; i <= 4000; i++) {
            double xi = T.xi_max + 2.0 * T.h * i / 4000.0;
            double u = c.u_detach + xi * xi;
            double s_tab = 0.0, s_ex = 0.0;
            double e = fabs(vafm_jkr_table_force(&T, &c, u, &s_tab) - c.type->force(&c, u, &s_ex, NULL)) / c.F_jkr;
            if (!(e <= worst))
                worst = e;
        }
        ENSURE_MSG(worst < 1e-12, "gamma %g: worst force error %g F_JKR over (xi_max, xi_max + 2h]", gammas[g],
                   worst);
        for (int k = 1; k <= 16; k++) {
            double u = c.u_detach + pow(10.0, -k) * c.a0 * c.a0;
            double s_tab = 0.0, s_ex = 0.0;
            double F_tab = vafm_jkr_table_force(&T, &c, u, &s_tab);
            double F_ex = c.type->force(&c, u, &s_ex, NULL);
            ENSURE_ABS(F_tab / c.F_jkr, F_ex / c.F_jkr, 1e-12);
        }
        /* exactly at u_min: F = −(5/9) F_JKR */
        double s0 = 0.0;
        ENSURE_REL(vafm_jkr_table_force(&T, &c, c.u_detach, &s0), -5.0 / 9.0 * c.F_jkr, 1e-12);
        /* beyond the table: the exact solver takes over */
        double u_far = 4.0 * u_max, s_tab = 0.0, s_ex = 0.0;
        ENSURE_REL(vafm_jkr_table_force(&T, &c, u_far, &s_tab), c.type->force(&c, u_far, &s_ex, NULL), 1e-14);
        vafm_jkr_table_free(&T);
        ENSURE(T.node == NULL);
    }
    vafm_contact h;
    vafm_jkr_table T;
    ENSURE(vafm_contact_init(&h, vafm_contact_hertz, 0.0) == 0);
    ENSURE(vafm_jkr_table_init(&T, &h, 1.0) == VAFM_EINVAL);
}

static void s_fig4(vafm_params *p, double k_red, int table)
{
    vafm_preset_apply(p, "paper-fig4", NULL);
    vafm_reduced r;
    vafm_units_reduce(p, &r);
    r.kT = 0.0;
    r.k = k_red;
    vafm_units_from_reduced(p, &r);
    p->contact_table = table;
}

/* Curve 0 of scene p, without samples: its result in *r; the sim is gone (NULL) after. */
static void s_result(const vafm_params *p, vafm_curve_result *r)
{
    vafm_sim *s = NULL;
    ENSURE(vafm_sim_new(&s, p, NULL) == 0);
    ENSURE(vafm_sim_curve(s, 0, NULL, NULL, r) == 0);
    vafm_sim_destroy(&s);
    ENSURE(s == NULL);
}

static void test_table_vs_solver_curve(void)
{
    const double ks[] = { 0.1, 0.8 };
    for (size_t i = 0; i < 2; i++) {
        vafm_params p0, p1;
        s_fig4(&p0, ks[i], 0);
        s_fig4(&p1, ks[i], 1);
        vafm_curve_result r0, r1;
        s_result(&p0, &r0);
        s_result(&p1, &r1);
        ENSURE(r0.flags == 0 && r1.flags == 0);
        ENSURE(r0.steps == r1.steps);
        ENSURE_REL(r1.detach_force_N, r0.detach_force_N, 1e-9);
        ENSURE_REL(r1.detach_height_m, r0.detach_height_m, 1e-9);
        ENSURE_REL(r1.pulloff_spring_N, r0.pulloff_spring_N, 1e-9);
        ENSURE_REL(r1.pulloff_sampled_N, r0.pulloff_sampled_N, 1e-9);
    }
}

static void test_adaptive_vs_plain(void)
{
    const double ks[] = { 0.1, 0.8 };
    for (size_t i = 0; i < 2; i++) {
        vafm_params p0, p1;
        s_fig4(&p0, ks[i], 1);
        s_fig4(&p1, ks[i], 1);
        p1.omega_dt_far = 1.5;
        /* the larger step acts where the exact well step would otherwise take over: off in both runs */
        p0.well_exact = p1.well_exact = 0;
        vafm_curve_result r0, r1;
        s_result(&p0, &r0);
        s_result(&p1, &r1);
        ENSURE(r0.flags == 0 && r1.flags == 0);
        ENSURE_MSG(r1.steps < 0.7 * r0.steps, "k %g: adaptive %llu steps vs plain %llu", ks[i],
                   (unsigned long long)r1.steps, (unsigned long long)r0.steps);
        ENSURE_REL(r1.detach_force_N, r0.detach_force_N, 1e-4);
        ENSURE_REL(r1.detach_height_m, r0.detach_height_m, 1e-4);
        ENSURE_REL(r1.pulloff_spring_N, r0.pulloff_spring_N, 1e-4);
    }
}

/* start_in_contact: a retract-only curve from a spring position between u_spr* and 0 */
static void test_start_in_contact(void)
{
    vafm_params p;
    s_fig4(&p, 0.1, 1);
    vafm_reduced r;
    vafm_units_reduce(&p, &r);
    vafm_quasistatic q;
    ENSURE(vafm_theory_quasistatic(r.gamma, r.k, &q) == 0);
    vafm_scale sc = vafm_units_scale(&p);
    p.start_in_contact = 1;
    p.trigger = VAFM_TRIGGER_HEIGHT;
    p.start_height_m = -(q.u_spr_star + 2.0) * sc.length_m; /* 2 R before the instability */
    p.trigger_height_m = p.start_height_m - 1e-3 * sc.length_m;
    vafm_sim *s = NULL;
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    vafm_curve_result res;
    ENSURE(vafm_sim_curve(s, 0, NULL, NULL, &res) == 0);
    ENSURE(res.flags == 0);
    ENSURE(res.touch_time_s == 0.0);
    double uspr_det = -res.detach_height_m / sc.length_m;
    ENSURE_REL(uspr_det, q.u_spr_star, 2e-3); /* ṽ = 1e-3: lag well below 0.2% (test_curve covers slow runs) */
    vafm_sim_destroy(&s);
    /* below the instability there is no equilibrium: refused, naming the field */
    p.start_height_m = -(q.u_spr_star - 0.5) * sc.length_m;
    p.trigger_height_m = p.start_height_m - 1e-3 * sc.length_m;
    vafm_error err;
    memset(&err, 0, sizeof err);
    ENSURE(vafm_sim_new(&s, &p, &err) == VAFM_EINVAL);
    ENSURE(!strcmp(err.field, "start_height_m"));
    ENSURE(strstr(err.message, "instability") != NULL);
    ENSURE(s == NULL);
}

static void test_well3_closed_form(void)
{
    /* ω² = 25, η = 1, kT/m = 0.3: underdamped; and ω² = 0.04, η = 3: overdamped */
    const double cases[][3] = { { 25.0, 1.0, 0.3 }, { 0.04, 3.0, 0.3 }, { 3600.0, 1.0, 1e-3 } };
    for (size_t c = 0; c < 3; c++) {
        const double w2 = cases[c][0], eta = cases[c][1], kT_m = cases[c][2];
        const double hs[] = { 0.01, 0.3, 2.0, 50.0, 200.0, 5000.0 };
        /* the slowest relaxation rate of the oscillator */
        const double lam = eta * eta > 4.0 * w2 ? eta / 2.0 - sqrt(eta * eta / 4.0 - w2) : eta / 2.0;
        for (size_t j = 0; j < 6; j++) {
            double h = hs[j];
            vafm_well3 W;
            vafm_well3_setup(&W, w2, eta, 2.0 * eta * kT_m, h);
            vafm_free_ou o;
            vafm_well_ou_setup(&o, 1.0, w2, eta, kT_m, h, 0); /* m = 1, stiffness ω², kT = kT_m */
            ENSURE_ABS(W.phi[0][0], o.e11, 1e-12);
            ENSURE_ABS(W.phi[0][1], o.e12, 1e-12);
            ENSURE_ABS(W.phi[1][0], o.e21, 1e-12 * fmax(1.0, w2));
            ENSURE_ABS(W.phi[1][1], o.e22, 1e-12);
            /* covariance of (X, V): L Lᵀ against the closed form's Cholesky factor */
            double sxx = W.chol[0][0] * W.chol[0][0];
            double sxv = W.chol[1][0] * W.chol[0][0];
            double svv = W.chol[1][0] * W.chol[1][0] + W.chol[1][1] * W.chol[1][1];
            double s1 = kT_m / w2, s2 = kT_m;
            ENSURE_ABS(sxx, o.l11 * o.l11, 1e-10 * s1);
            ENSURE_ABS(sxv, o.l21 * o.l11, 1e-10 * sqrt(s1 * s2));
            ENSURE_ABS(svv, o.l21 * o.l21 + o.l22 * o.l22, 1e-10 * s2);
            /* I's own row: mean response to X0 is ∫Φ_XX, which for h ≫ 1/η tends to η/ω² */
            if (h * lam > 40.0) {
                ENSURE_REL(W.phi[2][0], eta / w2, 1e-9);
                double sii = 0.0;
                for (int k = 0; k < 3; k++)
                    sii += W.chol[2][k] * W.chol[2][k];
                /* Var(I) = q h/ω⁴ − 3qη/ω⁶... : the slope in h is q/ω⁴ */
                vafm_well3 W2;
                vafm_well3_setup(&W2, w2, eta, 2.0 * eta * kT_m, 2.0 * h);
                double sii2 = 0.0;
                for (int k = 0; k < 3; k++)
                    sii2 += W2.chol[2][k] * W2.chol[2][k];
                ENSURE_REL((sii2 - sii) / h, 2.0 * eta * kT_m / (w2 * w2), 1e-8);
            }
        }
    }
}

/* The closed-form transition (used where ω·h ≥ 1) against Van Loan's series, which agree with 80-digit
 * arithmetic to ≤ 2e-12 over this grid (measured with mpmath): every propagator entry to 1e-11 of its
 * natural scale (1, h, ω²h; the I row h, h²) and every covariance entry to 1e-11·√(Σᵢᵢ Σⱼⱼ). Outside the
 * closed forms' domain vafm_well3_setup is Van Loan's result bit for bit. */
static void test_well3_closed_vs_series(void)
{
    const double whs[] = { 1.0, 1.5, 3.0, 10.0, 40.0, 100.0 };
    const double ehs[] = { 0.01, 0.125, 1.0, 8.0, 30.0, 100.0 };
    const double h = 0.7, kT_m = 0.37;
    int n_closed = 0;
    for (size_t a = 0; a < sizeof whs / sizeof whs[0]; a++)
        for (size_t b = 0; b < sizeof ehs / sizeof ehs[0]; b++) {
            const double w = whs[a] / h, eta = ehs[b] / h, w2 = w * w, q = 2.0 * eta * kT_m;
            if (w2 * h < 0.5 * eta) /* strongly overdamped: outside the closed forms' domain */
                continue;
            n_closed++;
            vafm_well3 C, V;
            vafm_well3_setup(&C, w2, eta, q, h);
            vafm_well3_setup_vanloan(&V, w2, eta, q, h);
            const double scale[3][2] = { { 1.0, h }, { w2 * h, 1.0 }, { h, h * h } };
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 2; j++)
                    ENSURE_MSG(fabs(C.phi[i][j] - V.phi[i][j]) <= 1e-11 * scale[i][j],
                               "wh %g eh %g: phi[%d][%d] %.17g vs %.17g", whs[a], ehs[b], i, j, C.phi[i][j],
                               V.phi[i][j]);
            double SC[3][3], SV[3][3];
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++) {
                    SC[i][j] = SV[i][j] = 0.0;
                    for (int k = 0; k < 3; k++) {
                        SC[i][j] += C.chol[i][k] * C.chol[j][k];
                        SV[i][j] += V.chol[i][k] * V.chol[j][k];
                    }
                }
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    ENSURE_MSG(fabs(SC[i][j] - SV[i][j]) <= 1e-11 * sqrt(SV[i][i] * SV[j][j]),
                               "wh %g eh %g: sigma[%d][%d] %.17g vs %.17g", whs[a], ehs[b], i, j, SC[i][j],
                               SV[i][j]);
        }
    ENSURE(n_closed >= 25); /* 28 of the 36 points */
    /* outside: ω·h < 1, η·h < 0.01, strongly overdamped */
    const double out[][2] = { { 0.5, 0.125 }, { 3.0, 1e-3 }, { 1.0, 30.0 } };
    for (size_t c = 0; c < 3; c++) {
        const double w = out[c][0] / h, eta = out[c][1] / h;
        vafm_well3 C, V;
        vafm_well3_setup(&C, w * w, eta, 2.0 * eta * kT_m, h);
        vafm_well3_setup_vanloan(&V, w * w, eta, 2.0 * eta * kT_m, h);
        ENSURE(memcmp(&C, &V, sizeof C) == 0);
    }
}

/* A thermal dwell in contact: the force samples with the exact well step against plain GJF steps.
 * paper-fig4 (k̃ 0.1, k_BT̃ 0.01), pressed in 1 R, dwell of N_s samples of 20 time units each (10× the
 * well's relaxation time 2/η, so samples are independent). Means agree within 5 standard errors of the
 * difference; variances within 5σ of their ratio (σ ≈ √(2/N_s) each). */
/* Sums of one channel over the dwell samples. */
typedef struct s_acc {
    int tip; /* 0: force_N, 1: tip_m */
    double sum, sum2;
    long n;
} s_acc;

static int s_collect_dwell(void *user, const vafm_samples *blk)
{
    s_acc *a = user;
    const double *x = a->tip ? blk->tip_m : blk->force_N;
    for (size_t i = 0; i < blk->n; i++)
        if (blk->segment[i] == VAFM_SEG_DWELL) {
            a->sum += x[i];
            a->sum2 += x[i] * x[i];
            a->n++;
        }
    return 0;
}

static void s_dwell_stats(int well, int n_samples, double *mean, double *var, long *n, uint64_t *steps)
{
    vafm_params p;
    vafm_preset_apply(&p, "paper-fig4", NULL);
    p.well_exact = well;
    p.trigger = VAFM_TRIGGER_HEIGHT;
    vafm_scale sc = vafm_units_scale(&p);
    p.start_height_m = -1.0 * sc.length_m; /* pressed in 1 R: a repulsive load, deep in the well */
    p.trigger_height_m = p.start_height_m - 1e-6 * sc.length_m;
    /* one sample per 20 /η: ~2000 integrator steps per sample, where the exact well step is used
     * (and samples 10 relaxation times apart are independent) */
    p.sample_rate_Hz = 1.0 / (20.0 * sc.time_s);
    p.dwell_s = n_samples / p.sample_rate_Hz;
    vafm_sim *s = NULL;
    vafm_curve_result res;
    s_acc a = { 0, 0.0, 0.0, 0 };
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    ENSURE(vafm_sim_curve(s, 3, s_collect_dwell, &a, &res) == 0);
    vafm_sim_destroy(&s);
    *n = a.n;
    *mean = a.sum / a.n;
    *var = a.sum2 / a.n - *mean * *mean;
    *steps = res.steps;
}

static void test_well_vs_plain_dwell(void)
{
    const int N = LONG_OR(8000, 2000); /* samples of the dwell; σ(var)/var ≈ √(2/N) */
    double m0, v0, m1, v1;
    long n0, n1;
    uint64_t st0, st1;
    s_dwell_stats(0, N, &m0, &v0, &n0, &st0);
    s_dwell_stats(1, N, &m1, &v1, &n1, &st1);
    ENSURE(n0 >= N - 1 && n1 >= N - 1);
    ENSURE_MSG(st1 < st0 / 5, "well steps %llu vs plain %llu", (unsigned long long)st1, (unsigned long long)st0);
    /* samples 20 time units apart with relaxation time 2/η = 2: neighbour correlation ≤ e^{-10};
     * the inflation √((1+ρ)/(1−ρ)) of the standard errors is kept for form (≈ 1 + 5e-5) */
    const double infl = sqrt((1.0 + exp(-10.0)) / (1.0 - exp(-10.0)));
    double se = infl * sqrt(v0 / n0 + v1 / n1);
    ENSURE_MSG(fabs(m1 - m0) <= 5.0 * se, "dwell mean force %.9g (well) vs %.9g (plain), 5 se = %.3g", m1, m0,
               5.0 * se);
    double sr = infl * sqrt(2.0 / n0 + 2.0 / n1);
    ENSURE_MSG(fabs(v1 / v0 - 1.0) <= 5.0 * sr, "dwell force variance ratio %.5f, 5 sigma = %.3g", v1 / v0, 5.0 * sr);
}

/* The contact friction channel (eta_cont, the paper's Γ_cont) obeys the fluctuation–dissipation
 * theorem on its own: in a held contact, the tip's variance is k_BT/K_tot (K_tot = k + dF/du at the
 * equilibrium) with or without it. k_BT̃ = 1e-4 keeps the anharmonic correction (~F″σ/K ≈ 1e-3) below
 * the statistical error. Point samples every 2 /η; N = LONG_OR(20000, 4000) each, σ(var)/var = √(2/N)
 * (samples decorrelate within 2/η_tot), 5σ bounds. A missing contact-channel noise would give the
 * factor η/(η + η_cont) = 1/5. */
static void test_contact_channel_fdt(void)
{
    const int N = LONG_OR(20000, 4000);
    const double eta_c[2] = { 0.0, 4.0 };
    /* well_exact on: the held contact is stepped by the exact well propagator; off: by plain GJF steps
     * with the in-contact coefficients (η_tot = η + η_cont), which the first pass never takes */
    for (int j = 0; j < 4; j++) {
        vafm_params p;
        vafm_preset_apply(&p, "paper-fig4", NULL);
        vafm_reduced r;
        vafm_units_reduce(&p, &r);
        r.kT = 1e-4;
        r.eta_cont = eta_c[j % 2];
        vafm_units_from_reduced(&p, &r);
        vafm_scale sc = vafm_units_scale(&p);
        p.well_exact = j < 2;
        p.trigger = VAFM_TRIGGER_HEIGHT;
        p.start_height_m = -1.0 * sc.length_m;
        p.trigger_height_m = p.start_height_m - 1e-6 * sc.length_m;
        p.antialias = VAFM_ANTIALIAS_POINT;
        p.dwell_s = N / p.sample_rate_Hz;
        vafm_sim *s = NULL;
        vafm_curve_result res;
        s_acc a = { 1, 0.0, 0.0, 0 };
        ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
        ENSURE(vafm_sim_curve(s, 7, s_collect_dwell, &a, &res) == 0);
        vafm_sim_destroy(&s);
        double mean = a.sum / a.n, var = a.sum2 / a.n - mean * mean;
        /* equilibrium at u_spr = 1 (pressed 1 R): K_tot = k + dF/du there */
        double ueq, Feq;
        ENSURE(vafm_theory_equilibrium(r.gamma, r.k, 1.0, &ueq, &Feq) == 0);
        vafm_contact c;
        vafm_contact_init(&c, vafm_contact_jkr, r.gamma);
        vafm_contact_eval ev;
        ENSURE(vafm_contact_eval_at(&c, ueq, &ev) == 0);
        double expect = r.kT / (r.k + ev.dFdu) * sc.length_m * sc.length_m;
        ENSURE_MSG(fabs(var / expect - 1.0) <= 5.0 * sqrt(2.0 / a.n),
                   "eta_cont %g, well_exact %d: var/expected %.4f (5 sigma %.3f)", eta_c[j % 2], p.well_exact,
                   var / expect, 5.0 * sqrt(2.0 / a.n));
        ENSURE_REL(-mean / sc.length_m, ueq, 1e-2);
    }
}

/* GJF's in-contact coefficients, by the kernel itself: a held JKR contact (paper-fig4's γ, k̃, m̃;
 * k_BT̃ = 1e-4, the support fixed at u_spr = 1) stepped by vafm_integrator_gjf with the contact channel
 * η_cont = 4 (η_tot = 5), dt = 0.02/max(ω, η_tot). The position variance is k_BT/K_tot and the velocity
 * variance k_BT/m (GJF's on-site velocity: k_BT/m·(1 − ω²dt²/4), a 1e-4 correction here, far below
 * σ). N = LONG_OR(20000, 4000) states 2/η apart (decorrelated within 2/η_tot), σ(var)/var = √(2/N), 5σ
 * bounds. Coefficients that leave η_cont out of the friction (b, a) but not out of the noise would give
 * both variances ×η_tot/η = 5; a noise without it ×1/5. */
static void test_gjf_contact_coefficients(void)
{
    const int N = LONG_OR(20000, 4000);
    vafm_params p;
    vafm_preset_apply(&p, "paper-fig4", NULL);
    vafm_reduced r;
    vafm_units_reduce(&p, &r);
    vafm_kernel K;
    memset(&K, 0, sizeof K);
    K.m = r.m;
    K.k = r.k;
    K.kT = 1e-4;
    K.eta_c = 4.0;
    ENSURE(vafm_contact_init(&K.contact, vafm_contact_jkr, r.gamma) == 0);
    K.cforce = K.contact.type->force;
    K.is_jkr = 1;
    K.thermal = 1;
    s_kernel_rng_init(&K, 11, 0);
    double ueq, Feq;
    ENSURE(vafm_theory_equilibrium(r.gamma, r.k, 1.0, &ueq, &Feq) == 0);
    vafm_contact_eval ev;
    ENSURE(vafm_contact_eval_at(&K.contact, ueq, &ev) == 0);
    const double K_tot = r.k + ev.dFdu, omega = sqrt(K_tot / r.m), eta_tot = 1.0 + K.eta_c;
    const double dt = 0.02 / fmax(omega, eta_tot);
    vafm_kernel_set_dt(&K, dt);
    ENSURE_REL(K.co[1].eta_tot, eta_tot, 1e-15);
    K.uspr0 = K.u_spr = 1.0;
    K.u = ueq;
    K.in_contact = 1;
    vafm_kfs fs = vafm_kernel_contact_eval(&K, ueq, 0.0);
    K.Fc = fs.F;
    K.s = fs.s;
    vafm_integrator_gjf->prepare(&K);
    const long per = (long)ceil(2.0 / dt);
    ENSURE(vafm_integrator_gjf->run(&K, 10 * per) == 10 * per); /* equilibrate */
    double su = 0.0, su2 = 0.0, sw = 0.0, sw2 = 0.0;
    for (int i = 0; i < N; i++) {
        ENSURE(vafm_integrator_gjf->run(&K, per) == per && K.in_contact == 1);
        su += K.u;
        su2 += K.u * K.u;
        sw += K.w;
        sw2 += K.w * K.w;
    }
    const double mu = su / N, var_u = su2 / N - mu * mu, mw = sw / N, var_w = sw2 / N - mw * mw;
    const double tol = 5.0 * sqrt(2.0 / N);
    fprintf(stderr, "  omega %.4g, eta_tot %g, dt %.3g: var(u) K_tot/kT %.4f, var(w) m/kT %.4f (5 sigma %.3f)\n",
            omega, eta_tot, dt, var_u * K_tot / K.kT, var_w * r.m / K.kT, tol);
    ENSURE_MSG(fabs(var_u * K_tot / K.kT - 1.0) <= tol, "var(u)/(kT/K_tot) %.4f (5 sigma %.3f)",
               var_u * K_tot / K.kT, tol);
    ENSURE_MSG(fabs(var_w * r.m / K.kT - 1.0) <= tol, "var(w)/(kT/m) %.4f (5 sigma %.3f)", var_w * r.m / K.kT, tol);
    ENSURE_ABS(mu, ueq, 1e-2);
}

/* The exact well step at a few integrator steps per sample (paper-fig4's own 200 kHz: ~204 steps per
 * sample; and 2 MHz: ~20), athermal: a force curve with it against one without. The far zone is
 * linear to O(excursion²) and athermally the body follows the moving equilibrium with its friction lag,
 * so at the preset's ṽ = 1e-3 the pull-off observables (made in the near zone, where both integrate)
 * agree to 1e-9 relative (measured: 12 digits) while the step count falls at least 3×. At ṽ = 0.5
 * (inertia and drag dominate, contact lasts a few hundred steps) the well's centre line, linear in time
 * over each sample, leaves out the equilibrium's acceleration v²·d²u_eq/du_spr² (a lag m·a/K): measured
 * 3.5e-7 (200 kHz) and 4.6e-6 to 8.8e-6 (2 MHz) relative; asserted 3e-5, and fewer steps. */
static void test_well_pull_athermal(void)
{
    const double rates[] = { 200e3, 2e6 };
    const double vred[] = { 1e-3, 0.5 };
    for (size_t a = 0; a < 2; a++)
        for (size_t b = 0; b < 2; b++) {
            vafm_params p[2];
            vafm_curve_result r[2];
            for (int w = 0; w < 2; w++) {
                s_fig4(&p[w], 0.1, 1);
                vafm_reduced rd;
                vafm_units_reduce(&p[w], &rd);
                rd.v_approach = rd.v_retract = vred[b];
                vafm_units_from_reduced(&p[w], &rd);
                p[w].sample_rate_Hz = rates[a];
                p[w].well_exact = w;
                vafm_sim *s = NULL;
                ENSURE(vafm_sim_new(&s, &p[w], NULL) == 0);
                ENSURE(vafm_sim_curve(s, 0, NULL, NULL, &r[w]) == 0);
                vafm_sim_destroy(&s);
                ENSURE(r[w].flags == 0);
            }
            fprintf(stderr, "  %g S/s, v %g: steps %llu (well) vs %llu; detach %.12g vs %.12g N\n", rates[a], vred[b],
                    (unsigned long long)r[1].steps, (unsigned long long)r[0].steps, r[1].detach_force_N,
                    r[0].detach_force_N);
            const int slow = vred[b] < 0.1;
            ENSURE_MSG(r[1].steps * (slow ? 3 : 1) < r[0].steps, "%g S/s, v %g: steps %llu (well) vs %llu", rates[a],
                       vred[b], (unsigned long long)r[1].steps, (unsigned long long)r[0].steps);
            const double tol = slow ? 1e-9 : 3e-5;
            ENSURE_REL(r[1].detach_force_N, r[0].detach_force_N, tol);
            ENSURE_REL(r[1].detach_height_m, r[0].detach_height_m, tol);
            ENSURE_REL(r[1].pulloff_spring_N, r[0].pulloff_spring_N, tol);
            ENSURE_REL(r[1].pulloff_sampled_N, r[0].pulloff_sampled_N, tol);
        }
}

/* Thermal pulls (paper-fig4, k_BT̃ = 0.01, ṽ = 1e-2, 200 kHz: ~204 steps per sample): the distribution of
 * the pull-off force with the exact well step against plain steps, N = LONG_OR(400, 100) curves each.
 * The mean pull-off (spring and detachment force) agrees within 4 standard errors of the difference
 * (sd ≈ 0.019 and 0.025 F_JKR: σ_diff ≈ 0.0014 / 0.0017 F_JKR at N = 400; measured with N = 400:
 * 0.94338 vs 0.94319 and 0.86945 vs 0.86872 F_JKR, 0.1σ and 0.4σ), the sd within 4σ of the ratio
 * (σ ≈ √(1/N) each for near-normal samples, doubled for the skewed tail). */
static void test_well_pull_thermal(void)
{
    const int N = LONG_OR(400, 100);
    double mean[2][2], var[2][2];
    for (int w = 0; w < 2; w++) {
        vafm_params p;
        vafm_preset_apply(&p, "paper-fig4", NULL);
        vafm_reduced rd;
        vafm_units_reduce(&p, &rd);
        rd.v_approach = rd.v_retract = 1e-2;
        vafm_units_from_reduced(&p, &rd);
        p.well_exact = w;
        const double FJ = 1.5 * 3.14159265358979323846 * rd.gamma * vafm_units_scale(&p).force_N;
        vafm_sim *s = NULL;
        ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
        double s1[2] = { 0, 0 }, s2[2] = { 0, 0 };
        for (int i = 0; i < N; i++) {
            vafm_curve_result r;
            ENSURE(vafm_sim_curve(s, (uint64_t)i, NULL, NULL, &r) == 0);
            const double x[2] = { r.pulloff_spring_N / FJ, r.detach_force_N / FJ };
            for (int o = 0; o < 2; o++) {
                s1[o] += x[o];
                s2[o] += x[o] * x[o];
            }
        }
        vafm_sim_destroy(&s);
        for (int o = 0; o < 2; o++) {
            mean[w][o] = s1[o] / N;
            var[w][o] = (s2[o] / N - mean[w][o] * mean[w][o]) * N / (N - 1.0);
        }
    }
    for (int o = 0; o < 2; o++) {
        const double se = sqrt((var[0][o] + var[1][o]) / N);
        fprintf(stderr, "  %s: %.5f (well) vs %.5f F_JKR, diff %.2f se; sd ratio %.3f\n", o ? "detach" : "pull-off spring",
                mean[1][o], mean[0][o], (mean[1][o] - mean[0][o]) / se, sqrt(var[1][o] / var[0][o]));
        ENSURE(fabs(mean[1][o] - mean[0][o]) <= 4.0 * se);
        ENSURE(fabs(sqrt(var[1][o] / var[0][o]) - 1.0) <= 4.0 * 2.0 * sqrt(1.0 / N));
    }
}

/* A thermal dwell at ~10 steps per sample (Ts = 0.1 /η, ω·Ts ≈ 1.8 in the well: the closed-form
 * transition): force samples with the well step against plain GJF steps. Samples are correlated over
 * the relaxation time 2/η = 20 samples, so standard errors come from batch means over 200 samples
 * (20 time units, 10 relaxation times): B = N/200 batches. Mean, variance and the autocovariance at lags
 * 1 and 5 samples (the box-car samples' spectrum; delta method on the batch means of x, x² and x·x₊L)
 * within 5 standard errors of the difference (N = 4e5: se ≈ 0.7% of the variance, 0.7% of the lag-1
 * autocovariance). The well here has F″σ/K = 0.04: the quasi-harmonic stiffness (sim.c) matters at
 * the 1% level, visible at N = 4e6 (measured with it: z = −0.7, −0.7, −0.9, −0.6; without: −0.7,
 * −1.7, −4.1, −2.7). */
enum { S_Q = 4 }; /* x, x², x·x₋₁, x·x₋₅ */
typedef struct s_batch {
    long n, per;
    double cur[S_Q];               /* sums of the batch being filled */
    double S[S_Q], C[S_Q][S_Q];    /* sums over batches of the batch means and of their products */
    double prev[5];                /* the last five samples (prev[0] the newest) */
    long nb;
} s_batch;

static int s_collect_batches(void *user, const vafm_samples *blk)
{
    s_batch *b = user;
    for (size_t i = 0; i < blk->n; i++) {
        if (blk->segment[i] != VAFM_SEG_DWELL)
            continue;
        const double x = blk->force_N[i] * 1e9;
        if (b->n < 5) { /* the lags need five samples of history; they start the first batch */
            memmove(b->prev + 1, b->prev, 4 * sizeof(double));
            b->prev[0] = x;
            b->n++;
            continue;
        }
        const double q[S_Q] = { x, x * x, x * b->prev[0], x * b->prev[4] };
        memmove(b->prev + 1, b->prev, 4 * sizeof(double));
        b->prev[0] = x;
        for (int k = 0; k < S_Q; k++)
            b->cur[k] += q[k];
        if (++b->n % b->per == 0) {
            double m[S_Q];
            for (int k = 0; k < S_Q; k++)
                m[k] = b->cur[k] / b->per;
            for (int k = 0; k < S_Q; k++) {
                b->S[k] += m[k];
                for (int l = 0; l < S_Q; l++)
                    b->C[k][l] += m[k] * m[l];
                b->cur[k] = 0.0;
            }
            b->nb++;
        }
    }
    return 0;
}

static void test_well_few_steps_dwell(void)
{
    const long N = LONG_OR(400000, 100000);
    /* per run: mean, variance, autocovariance at lags 1 and 5, and their standard errors */
    double est[2][S_Q], se[2][S_Q];
    uint64_t steps[2];
    for (int w = 0; w < 2; w++) {
        vafm_params p;
        vafm_preset_apply(&p, "paper-fig4", NULL);
        p.well_exact = w;
        if (!w) /* the reference at a quarter step: its box-car (a 40-point Riemann sum) is then exact to
                 * ~0.02%, at the paper's step it is ~0.3% high in the variance */
            p.omega_dt = 2.0 * 3.14159265358979323846 / 40.0 / 4.0;
        p.trigger = VAFM_TRIGGER_HEIGHT;
        const vafm_scale sc = vafm_units_scale(&p);
        p.start_height_m = -1.0 * sc.length_m;
        p.trigger_height_m = p.start_height_m - 1e-6 * sc.length_m;
        p.sample_rate_Hz = 1.0 / (0.1 * sc.time_s);
        p.dwell_s = (double)N / p.sample_rate_Hz;
        vafm_sim *s = NULL;
        vafm_curve_result r;
        s_batch b;
        memset(&b, 0, sizeof b);
        b.per = 200;
        ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
        ENSURE(vafm_sim_curve(s, 5, s_collect_batches, &b, &r) == 0);
        vafm_sim_destroy(&s);
        ENSURE(b.nb >= N / 200 - 1);
        const double B = (double)b.nb;
        double m[S_Q], c[S_Q][S_Q];
        for (int k = 0; k < S_Q; k++)
            m[k] = b.S[k] / B;
        for (int k = 0; k < S_Q; k++)
            for (int l = 0; l < S_Q; l++)
                c[k][l] = (b.C[k][l] / B - m[k] * m[l]) * B / (B - 1.0);
        est[w][0] = m[0];
        se[w][0] = sqrt(c[0][0] / B);
        /* second moments minus x̄²: gradient (−2x̄, 1) on (x̄, q̄) */
        for (int k = 1; k < S_Q; k++) {
            est[w][k] = m[k] - m[0] * m[0];
            se[w][k] = sqrt(fmax(0.0, (c[k][k] - 4.0 * m[0] * c[0][k] + 4.0 * m[0] * m[0] * c[0][0]) / B));
        }
        steps[w] = r.steps;
    }
    static const char *const name[S_Q] = { "mean", "variance", "autocovariance lag 1", "autocovariance lag 5" };
    fprintf(stderr, "  Ts = 0.1: steps %llu (well) vs %llu\n", (unsigned long long)steps[1], (unsigned long long)steps[0]);
    ENSURE(steps[1] * 3 < steps[0]);
    for (int k = 0; k < S_Q; k++) {
        const double z = (est[1][k] - est[0][k]) / hypot(se[0][k], se[1][k]);
        fprintf(stderr, "    %-21s %.8g (well) vs %.8g (se %.2g): z = %+.2f\n", name[k], est[1][k], est[0][k], se[0][k], z);
        ENSURE_MSG(fabs(z) <= 5.0, "%s: z = %.2f", name[k], z);
    }
}

int main(void)
{
    RUN_TEST(test_table_accuracy);
    RUN_TEST(test_table_vs_solver_curve);
    RUN_TEST(test_adaptive_vs_plain);
    RUN_TEST(test_start_in_contact);
    RUN_TEST(test_well3_closed_form);
    RUN_TEST(test_well3_closed_vs_series);
    RUN_TEST(test_well_pull_athermal);
    RUN_TEST(test_well_pull_thermal);
    RUN_TEST(test_well_few_steps_dwell);
    RUN_TEST(test_well_vs_plain_dwell);
    RUN_TEST(test_contact_channel_fdt);
    RUN_TEST(test_gjf_contact_coefficients);
    return harness_done();
}
