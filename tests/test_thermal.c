/* SPDX-License-Identifier: MIT */
/*
 * Thermal oracles of the free cantilever and of the integrators (physics notes, "Thermal oracles" and
 * "Integrators"): equipartition, the exact discrete stationary variances of each scheme's linear map
 * (discrete Lyapunov equation), the paper VV's kinetic-temperature error, Brownian Euler's ⟨x²⟩ error,
 * the thermal-tune PSD and its Lorentzian fit, the exact free propagation against plain small steps,
 * and the absence of random draws at T = 0.
 *
 * Statistics. Every stochastic check uses a fixed seed and block averaging: the run is cut into
 * S_NB = 100 blocks, each much longer than the correlation time of the observable (stated per test),
 * the block means are treated as independent and the standard error is sd(block means)/√S_NB. Checks are
 * at 5σ of that error (the error estimate itself is good to ±7% with 100 blocks). The long build runs the
 * full N; the sanitizer build a quarter (LONG_OR), the tolerances follow from the measured σ.
 *
 * Reference maps. The linear maps below are written from the schemes' published formulas as quoted in
 * src/core/integrator_*.c, independently of the kernel's code; the Lyapunov solution of each map is the
 * exact stationary covariance of that scheme for a harmonic well, to which the simulation must agree.
 */
#include "harness.h"

#include <stdint.h>

#include "vafm/contact.h"
#include "vafm/integrator.h"
#include "vafm/params.h"
#include "vafm/rng.h"
#include "vafm/sim.h"
#include "vafm/units.h"
#include "core/kernel.h"
#include "core/rng_philox.h"

#define S_PI 3.14159265358979323846
#define S_NB 100 /* blocks of the block-averaged standard errors */

/* ---- block averaging ---------------------------------------------------------------------------- */

typedef struct s_acc {
    long per, cnt;
    int nb;
    double sum, bm[S_NB];
} s_acc;

static void s_acc_init(s_acc *a, long n_total)
{
    memset(a, 0, sizeof *a);
    a->per = n_total / S_NB;
    if (a->per < 1)
        a->per = 1;
}

static void s_acc_push(s_acc *a, double v)
{
    if (a->nb >= S_NB)
        return;
    a->sum += v;
    if (++a->cnt == a->per) {
        a->bm[a->nb++] = a->sum / (double)a->per;
        a->sum = 0.0;
        a->cnt = 0;
    }
}

/* Mean of the block means and its standard error sd/√nb. */
static void s_acc_result(const s_acc *a, double *mean, double *se)
{
    double s = 0.0, s2 = 0.0;
    for (int i = 0; i < a->nb; i++)
        s += a->bm[i];
    double m = s / a->nb;
    for (int i = 0; i < a->nb; i++)
        s2 += (a->bm[i] - m) * (a->bm[i] - m);
    *mean = m;
    *se = sqrt(s2 / (a->nb - 1) / a->nb);
}

/* Block estimate of ⟨x_i x_{i+lag}⟩ / ⟨x_i²⟩ (per block, then averaged) for a recorded series. */
static void s_lag_corr(const double *x, size_t n, int lag, double *r, double *se)
{
    s_acc a;
    size_t per = (n - (size_t)lag) / S_NB;
    s_acc_init(&a, S_NB);
    for (int b = 0; b < S_NB; b++) {
        double sxy = 0.0, sxx = 0.0;
        for (size_t i = (size_t)b * per; i < (size_t)(b + 1) * per; i++) {
            sxy += x[i] * x[i + (size_t)lag];
            sxx += x[i] * x[i];
        }
        s_acc_push(&a, sxy / sxx);
    }
    s_acc_result(&a, r, se);
}

/* Block estimate of ⟨x²⟩ for a recorded series. */
static void s_meansq(const double *x, size_t n, double *m, double *se)
{
    s_acc a;
    s_acc_init(&a, (long)n);
    for (size_t i = 0; i < n; i++)
        s_acc_push(&a, x[i] * x[i]);
    s_acc_result(&a, m, se);
}

/* ---- discrete Lyapunov equation ----------------------------------------------------------------- */

#define S_DMAX 3

/* A linear scheme with one unit-variance noise per step: state' = A·state + B·ξ. step() applies the
 * scheme's formulas; the map is read off by applying it to unit vectors (it is linear). */
typedef void (*s_step_fn)(const double *par, const double *s, double xi, double *out);

static void s_map(s_step_fn step, const double *par, int d, double A[S_DMAX][S_DMAX], double B[S_DMAX])
{
    double e[S_DMAX], o[S_DMAX];
    for (int j = 0; j < d; j++) {
        memset(e, 0, sizeof e);
        e[j] = 1.0;
        step(par, e, 0.0, o);
        for (int i = 0; i < d; i++)
            A[i][j] = o[i];
    }
    memset(e, 0, sizeof e);
    step(par, e, 1.0, o);
    for (int i = 0; i < d; i++)
        B[i] = o[i];
}

/* Stationary covariance Σ = AΣAᵀ + BBᵀ: the d² linear equations (I − A⊗A)vec Σ = vec BBᵀ solved by
 * Gaussian elimination with partial pivoting. @return 0, or −1 if singular (an unstable map). */
static int s_lyapunov(int d, double A[S_DMAX][S_DMAX], const double B[S_DMAX], double S[S_DMAX][S_DMAX])
{
    enum { N = S_DMAX * S_DMAX };
    double M[N][N + 1];
    int n = d * d;
    for (int i = 0; i < S_DMAX; i++)
        for (int j = 0; j < S_DMAX; j++)
            S[i][j] = NAN; /* until solved */
    for (int i = 0; i < d; i++)
        for (int j = 0; j < d; j++) {
            int r = i * d + j;
            for (int k = 0; k < d; k++)
                for (int l = 0; l < d; l++)
                    M[r][k * d + l] = (r == k * d + l ? 1.0 : 0.0) - A[i][k] * A[j][l];
            M[r][n] = B[i] * B[j];
        }
    for (int c = 0; c < n; c++) {
        int p = c;
        for (int r = c + 1; r < n; r++)
            if (fabs(M[r][c]) > fabs(M[p][c]))
                p = r;
        if (!(fabs(M[p][c]) > 0.0))
            return -1;
        for (int k = 0; k <= n; k++) {
            double t = M[c][k];
            M[c][k] = M[p][k];
            M[p][k] = t;
        }
        for (int r = 0; r < n; r++) {
            if (r == c)
                continue;
            double f = M[r][c] / M[c][c];
            for (int k = c; k <= n; k++)
                M[r][k] -= f * M[c][k];
        }
    }
    for (int i = 0; i < d; i++)
        for (int j = 0; j < d; j++)
            S[i][j] = M[i * d + j][n] / M[i * d + j][i * d + j];
    return 0;
}

/* Scheme parameters: par = {m, k, kT, dt}, η = 1 (reduced), no support motion, free cantilever. */

/* GJF: α = mη, b = 1/(1 + α dt/2m), a = (1 − α dt/2m)b, β = √(2αkT dt)·ξ;
 * u' = u + b dt w + (b dt²/2m) f + (b dt/2m) β,  w' = a w + (dt/2m)(a f + f') + (b/m) β. State (u, w). */
static void s_step_gjf(const double *par, const double *s, double xi, double *o)
{
    const double m = par[0], k = par[1], kT = par[2], dt = par[3];
    const double b = 1.0 / (1.0 + 0.5 * dt), a = (1.0 - 0.5 * dt) * b, beta = sqrt(2.0 * m * kT * dt) * xi;
    const double f = -k * s[0];
    o[0] = s[0] + b * dt * s[1] + b * dt * dt / (2.0 * m) * f + b * dt / (2.0 * m) * beta;
    const double f1 = -k * o[0];
    o[1] = a * s[1] + dt / (2.0 * m) * (a * f + f1) + b / m * beta;
}

/* BAOAB: kick dt/2, drift dt/2, exact OU velocity step over dt (c1 = e^{−η dt}, c3 = √(kT/m (1 − c1²))),
 * drift dt/2, kick dt/2. State (u, w). */
static void s_step_baoab(const double *par, const double *s, double xi, double *o)
{
    const double m = par[0], k = par[1], kT = par[2], dt = par[3];
    const double c1 = exp(-dt), c3 = sqrt(kT / m * (1.0 - c1 * c1));
    double w = s[1] + 0.5 * dt / m * (-k * s[0]);
    double u = s[0] + 0.5 * dt * w;
    w = c1 * w + c3 * xi;
    u += 0.5 * dt * w;
    o[0] = u;
    o[1] = w + 0.5 * dt / m * (-k * u);
}

/* The paper's VV (Eq. 7 with the friction at the half-step velocity, one random force per force
 * evaluation, Γ = √(2mηkT/dt)·ξ). State (u, w, F) with F the total force of the last evaluation:
 * w½ = w + (dt/2m)F, u' = u + dt w½, F' = −k u' − mη w½ + Γ, w' = w½ + (dt/2m)F'. */
static void s_step_vv(const double *par, const double *s, double xi, double *o)
{
    const double m = par[0], k = par[1], kT = par[2], dt = par[3];
    const double wh = s[1] + 0.5 * dt / m * s[2];
    o[0] = s[0] + dt * wh;
    o[2] = -k * o[0] - m * wh + sqrt(2.0 * m * kT / dt) * xi;
    o[1] = wh + 0.5 * dt / m * o[2];
}

/* Brownian Euler (Eq. 12): u' = u + (dt/ζ)f + √(2kT dt/ζ)ξ, ζ = mη. State (u). */
static void s_step_bd(const double *par, const double *s, double xi, double *o)
{
    const double m = par[0], k = par[1], kT = par[2], dt = par[3];
    o[0] = s[0] + dt / m * (-k * s[0]) + sqrt(2.0 * kT * dt / m) * xi;
}

static int s_lyap_of(s_step_fn step, int d, double m, double k, double kT, double dt, double S[S_DMAX][S_DMAX])
{
    const double par[4] = { m, k, kT, dt };
    double A[S_DMAX][S_DMAX], B[S_DMAX];
    s_map(step, par, d, A, B);
    return s_lyapunov(d, A, B, S);
}

/* ---- the kernel driven by hand ------------------------------------------------------------------ */

/* A free cantilever (contact none, support at rest at 0) in reduced units, started from the continuous
 * equilibrium (x ~ N(0, kT/k), w ~ N(0, kT/m)) with draws from a separate stream. */
static void s_kernel_free(vafm_kernel *K, const vafm_integrator_type *it, double m, double k, double kT, double dt,
                          uint64_t seed)
{
    memset(K, 0, sizeof *K);
    K->m = m;
    K->k = k;
    K->kT = kT;
    K->eta_c = 0.0;
    vafm_contact_init(&K->contact, vafm_contact_none, 0.0);
    K->cforce = K->contact.type->force;
    K->thermal = kT > 0;
    K->uniform_noise = 0;
    vafm_rng_init(&K->rng, seed, 0);
    vafm_kernel_set_dt(K, dt);
    K->fs_min = INFINITY;
    if (kT > 0) {
        vafm_rng r0;
        vafm_rng_init(&r0, seed, 1u << 20);
        K->u = sqrt(kT / k) * vafm_rng_normal(&r0);
        K->w = it && it->overdamped ? 0.0 : sqrt(kT / m) * vafm_rng_normal(&r0);
    } else {
        K->u = 0.7;
        K->w = -0.3;
    }
    if (it)
        it->prepare(K);
}

/* Run a hand-built kernel n steps (after n/20 steps of burn-in) and block-average u², w² and the
 * half-step velocity² p² = (w − (dt/2m)·f)² (meaningful for paper-vv, whose K->f holds the total force). */
static void s_kernel_stats(vafm_kernel *K, const vafm_integrator_type *it, long n, double out[3][2])
{
    s_acc au, aw, ap;
    s_acc_init(&au, n);
    s_acc_init(&aw, n);
    s_acc_init(&ap, n);
    for (long i = 0; i < n / 20; i++)
        it->run(K, 1);
    const double c = 0.5 * K->dt / K->m;
    for (long i = 0; i < n; i++) {
        it->run(K, 1);
        double p = K->w - c * K->f;
        s_acc_push(&au, K->u * K->u);
        s_acc_push(&aw, K->w * K->w);
        s_acc_push(&ap, p * p);
    }
    s_acc_result(&au, &out[0][0], &out[0][1]);
    s_acc_result(&aw, &out[1][0], &out[1][1]);
    s_acc_result(&ap, &out[2][0], &out[2][1]);
}

/* ---- the SI thermal-tune lever ------------------------------------------------------------------ */

/* A contact-mode-like cantilever: k = 0.1 N/m, f0 = 10 kHz, Q = 10 (Q = ω0/η), T = 300 K, sampled
 * (point samples) at 8 f0. Reduced: ω0 = 10, sample interval ηTs = 0.0785. */
#define S_K 0.1
#define S_F0 1e4
#define S_Q 10.0
#define S_T 300.0
#define S_FS (8.0 * S_F0)

static void s_lever(vafm_params *p)
{
    vafm_params_default(p);
    p->contact = vafm_contact_none;
    p->gamma_J_per_m2 = 0.0;
    const double w0 = 2.0 * S_PI * S_F0;
    p->k_N_per_m = S_K;
    p->m_kg = S_K / (w0 * w0);
    p->eta_per_s = w0 / S_Q;
    p->eta_cont_per_s = 0.0;
    p->T_K = S_T;
    p->sample_rate_Hz = S_FS;
    p->antialias = VAFM_ANTIALIAS_POINT;
}

typedef struct s_trace {
    size_t n, cap;
    double *x;
} s_trace;

static int s_collect(void *user, const vafm_samples *b)
{
    s_trace *t = user;
    for (size_t i = 0; i < b->n && t->n < t->cap; i++)
        t->x[t->n++] = b->deflection_m[i];
    return 0;
}

/* Record n deflection samples (m) of a thermal tune. @return 0 or the failing status. */
static int s_tune(const vafm_params *p, size_t n, s_trace *tr)
{
    vafm_params q = *p;
    q.tune_duration_s = (double)n / q.sample_rate_Hz;
    vafm_sim *sim = NULL;
    vafm_error err;
    int r = vafm_sim_new(&sim, &q, &err);
    if (r) {
        fprintf(stderr, "vafm_sim_new: %s\n", err.message);
        return r;
    }
    tr->n = 0;
    tr->cap = n;
    tr->x = malloc(n * sizeof *tr->x);
    if (!tr->x) {
        vafm_sim_destroy(&sim);
        return VAFM_ENOMEM;
    }
    r = vafm_sim_tune(sim, 0, s_collect, tr);
    vafm_sim_destroy(&sim);
    return r;
}

/* Normalised autocorrelation of the free cantilever's position at lag τ (continuous OU, reduced time,
 * η = 1): e^{−τ/2}[cos ω1τ + sin(ω1τ)/(2ω1)], ω1 = √(ω0² − 1/4) (underdamped). */
static double s_rho(double w0, double tau)
{
    double w1 = sqrt(w0 * w0 - 0.25);
    return exp(-0.5 * tau) * (cos(w1 * tau) + sin(w1 * tau) / (2.0 * w1));
}

/* One-sided PSD of the lever's deflection (SI): S(f) = 4kTη / (m[(ω0² − ω²)² + η²ω²]). */
static double s_psd(const vafm_params *p, double f)
{
    const double w = 2.0 * S_PI * f, w0sq = p->k_N_per_m / p->m_kg, eta = p->eta_per_s;
    const double kT = VAFM_KB_J_PER_K * p->T_K;
    return 4.0 * kT * eta / (p->m_kg * ((w0sq - w * w) * (w0sq - w * w) + eta * eta * w * w));
}

/* ---- 1. equipartition ------------------------------------------------------------------------- */

/* Tune samples (point) of the SI lever: ⟨defl²⟩ = kT/k for the exact free propagation and for gjf and
 * baoab stepping (free_exact = 0, automatic ω0 dt = 0.157: both sample x exactly at any dt).
 * N = 2^20 samples (2^18 short); the x² correlation time is ~1/η = 12.7 samples, blocks are 10^4
 * samples; σ ≈ 0.4% (0.8% short) of kT/k. */
static void test_equipartition_tune(void)
{
    vafm_params p;
    s_lever(&p);
    const size_t n = LONG_OR((size_t)1 << 20, (size_t)1 << 18);
    const double var = VAFM_KB_J_PER_K * S_T / S_K;
    const struct {
        const char *name;
        const vafm_integrator_type *it;
        int exact;
    } runs[] = {
        { "exact OU", vafm_integrator_gjf, 1 },
        { "gjf", vafm_integrator_gjf, 0 },
        { "baoab", vafm_integrator_baoab, 0 },
    };
    for (size_t i = 0; i < sizeof runs / sizeof runs[0]; i++) {
        p.integrator = runs[i].it;
        p.free_exact = runs[i].exact;
        p.seed = 101 + i;
        s_trace tr = { 0 };
        int r = s_tune(&p, n, &tr);
        ENSURE(r == 0);
        ENSURE(tr.n == n);
        if (r == 0 && tr.n == n) {
            double m, se;
            s_meansq(tr.x, n, &m, &se);
            fprintf(stderr, "  tune %-8s <x^2>/(kT/k) = %.5f +- %.5f\n", runs[i].name, m / var, se / var);
            ENSURE(se < 0.02 * var); /* the statistics are as strong as planned */
            ENSURE_ABS(m, var, 5.0 * se);
        }
        free(tr.x);
    }
}

/* ⟨w²⟩ = kT/m through the kernel (the samples carry no velocity). Reduced m = 0.01, k = 1 (ω0 = 10,
 * Q = 10), kT = 0.01, ω0 dt = 0.157 (the paper's rule). GJF's and BAOAB's full-step velocities are not
 * exact: their stationary ⟨w²⟩ is the map's Lyapunov value (−0.6% for GJF here, O(ω0²dt²)); the
 * simulation must hit that within 5σ, and kT/m within 5σ plus that known bias, which must itself be
 * below ω0²dt²/2. The exact free propagation has no bias at any step (h = 0.3 here).
 * N = 4·10^6 steps (10^6 short); w² correlates over ~1/η = 64 steps, blocks are 4·10^4 steps;
 * σ ≈ 0.6% (1.2% short). ⟨u²⟩ = kT/k is checked alongside (x is exact for all three). */
static void test_equipartition_velocity(void)
{
    const double m = 0.01, k = 1.0, kT = 0.01, dt = 0.157 / sqrt(k / m);
    const long n = LONG_OR(4000000L, 1000000L);
    const struct {
        const vafm_integrator_type *it;
        s_step_fn step;
    } runs[] = { { vafm_integrator_gjf, s_step_gjf }, { vafm_integrator_baoab, s_step_baoab } };
    for (size_t i = 0; i < 2; i++) {
        double S[S_DMAX][S_DMAX], st[3][2];
        ENSURE(s_lyap_of(runs[i].step, 2, m, k, kT, dt, S) == 0);
        vafm_kernel K;
        s_kernel_free(&K, runs[i].it, m, k, kT, dt, 201 + i);
        s_kernel_stats(&K, runs[i].it, n, st);
        double bias = S[1][1] / (kT / m) - 1.0;
        fprintf(stderr, "  kernel %-6s <w^2>/(kT/m) = %.5f +- %.5f (map %.5f), <u^2>/(kT/k) = %.5f +- %.5f\n",
                runs[i].it->name, st[1][0] / (kT / m), st[1][1] / (kT / m), S[1][1] / (kT / m), st[0][0] / (kT / k),
                st[0][1] / (kT / k));
        ENSURE(fabs(bias) < 0.5 * (k / m) * dt * dt);
        ENSURE_ABS(st[1][0], S[1][1], 5.0 * st[1][1]);
        ENSURE_ABS(st[1][0], kT / m, 5.0 * st[1][1] + fabs(bias) * kT / m);
        ENSURE_ABS(st[0][0], kT / k, 5.0 * st[0][1]);
        ENSURE(st[1][1] < 0.03 * kT / m);
    }
    /* exact free propagation */
    vafm_kernel K;
    s_kernel_free(&K, NULL, m, k, kT, dt, 203);
    vafm_free_ou ou;
    const double h = 0.3;
    vafm_free_ou_setup(&ou, &K, h, 0);
    K.dt = h;
    s_acc au, aw;
    const long nf = n / 4; /* h is 15× the integrators' step: ~3·10^5 η⁻¹ of simulated time (σ ≈ 0.4%, 0.8% short) */
    s_acc_init(&au, nf);
    s_acc_init(&aw, nf);
    for (long i = 0; i < nf; i++) {
        vafm_free_ou_step(&K, &ou);
        s_acc_push(&au, K.u * K.u);
        s_acc_push(&aw, K.w * K.w);
    }
    double mu, su, mw, sw;
    s_acc_result(&au, &mu, &su);
    s_acc_result(&aw, &mw, &sw);
    fprintf(stderr, "  kernel exact  <w^2>/(kT/m) = %.5f +- %.5f, <u^2>/(kT/k) = %.5f +- %.5f\n", mw / (kT / m),
            sw / (kT / m), mu / (kT / k), su / (kT / k));
    ENSURE_ABS(mw, kT / m, 5.0 * sw);
    ENSURE_ABS(mu, kT / k, 5.0 * su);
    ENSURE(sw < 0.03 * kT / m);
}

/* ---- 2. GJF and BAOAB: exact ⟨x²⟩ at large η dt ---------------------------------------------- */

/* Closed form: the Lyapunov solution of each map gives ⟨x²⟩ = kT/k to 1e-12 at any η dt for ω0 dt < 2
 * (a grid of cases, including the overdamped extreme η dt = 50). Then simulation at η dt = 5,
 * ω0 dt = 1.5 (m = 1, k = 0.09, kT = 1, dt = 5): x relaxes in ~k/ζ ≈ 0.09 per unit time, i.e. ~2
 * steps; N = 10^6 steps (2.5·10^5 short), blocks 10^4 steps, σ ≈ 0.3% (0.6%); check at 5σ. */
static void test_exact_config_large_dt(void)
{
    const double cases[][2] = { { 0.01, 0.1 }, { 0.157, 0.157 }, { 1.0, 1.9 }, { 5.0, 1.5 }, { 50.0, 0.5 },
                                { 2.0, 1.99 } };
    const s_step_fn steps[2] = { s_step_gjf, s_step_baoab };
    for (int s = 0; s < 2; s++)
        for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
            const double m = 1.0, kT = 1.0, dt = cases[c][0], w0 = cases[c][1] / dt, k = m * w0 * w0;
            double S[S_DMAX][S_DMAX];
            ENSURE(s_lyap_of(steps[s], 2, m, k, kT, dt, S) == 0);
            ENSURE_REL(S[0][0], kT / k, 1e-12);
        }
    const double m = 1.0, kT = 1.0, dt = 5.0, k = m * (1.5 / dt) * (1.5 / dt);
    const long n = LONG_OR(1000000L, 250000L);
    const vafm_integrator_type *its[2] = { vafm_integrator_gjf, vafm_integrator_baoab };
    for (int s = 0; s < 2; s++) {
        double S[S_DMAX][S_DMAX], st[3][2];
        ENSURE(s_lyap_of(steps[s], 2, m, k, kT, dt, S) == 0);
        vafm_kernel K;
        s_kernel_free(&K, its[s], m, k, kT, dt, 301 + (uint64_t)s);
        s_kernel_stats(&K, its[s], n, st);
        fprintf(stderr, "  %-6s eta*dt = 5, w0*dt = 1.5: <x^2>/(kT/k) = %.5f +- %.5f (map %.15f)\n", its[s]->name,
                st[0][0] / (kT / k), st[0][1] / (kT / k), S[0][0] / (kT / k));
        ENSURE_ABS(st[0][0], S[0][0], 5.0 * st[0][1]);
        ENSURE(st[0][1] < 0.02 * kT / k);
        /* the velocity is the map's too (GJF: kT/m (1 − ω0²dt²/4) = 0.4375 kT/m here) */
        ENSURE_ABS(st[1][0], S[1][1], 5.0 * st[1][1]);
    }
}

/* ---- 3. the paper's VV and Brownian Euler ------------------------------------------------------ */

/* The paper's VV. Its map, solved by hand for the leapfrog pair (u, w½) with ε = η dt, Ω = ω0²dt²
 * (stationarity of ⟨u²⟩, ⟨u w½⟩, ⟨w½²⟩; then w = (1 − ε/2)w½ − (Ω/2dt)u + (dt/2m)Γ):
 *   ⟨x²⟩ = kT/k / D,  ⟨w½²⟩ = kT/m / ((1 − ε/2) D),  ⟨w²⟩ = kT/m exactly,  D = 1 − Ω/(4 − 2ε).
 * So the kinetic-temperature error O(η dt) of this scheme lives in the half-step (leapfrog) velocity
 * w½ = w − (dt/2m)F, the one the friction sees: +ε/2/(1 − ε/2) = +33% at η dt = 0.5; the full-step
 * velocity w that the code stores is unbiased (the friction at the half step makes it so), and the
 * configurational error is O(ω0²dt²) only (+0.33% at ω0 dt = 0.1). These closed forms are checked on
 * the Lyapunov solution of the map (state u, w, F) to 1e-12 over a grid of (η dt, ω0 dt), then the
 * simulation (η dt = 0.5, ω0 dt = 0.1: m = 1, k = 0.04, kT = 1, dt = 0.5) against the map at 5σ, and
 * the w½ excess is resolved with the predicted sign (> 10σ). x correlates over ~ζ/k = 25 time units
 * = 50 steps, the velocities over ~2 steps; N = 4·10^6 steps (10^6 short), blocks of 4·10^4 steps:
 * σ(x²) ≈ 0.5% (1%), σ(w²) ≈ 0.1% (0.2%). */
static void s_vv_closed(double m, double k, double kT, double dt, double S[S_DMAX][S_DMAX], double *p2,
                        double *x2_cf, double *p2_cf)
{
    ENSURE(s_lyap_of(s_step_vv, 3, m, k, kT, dt, S) == 0);
    const double c[3] = { 0.0, 1.0, -0.5 * dt / m }; /* w½ = c·(u, w, F) */
    *p2 = 0.0;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            *p2 += c[i] * S[i][j] * c[j];
    const double eps = dt, Om = k / m * dt * dt, D = 1.0 - Om / (4.0 - 2.0 * eps);
    *x2_cf = kT / k / D;
    *p2_cf = kT / m / ((1.0 - 0.5 * eps) * D);
}

static void test_paper_vv(void)
{
    const double grid[][2] = { { 0.01, 0.1 }, { 0.5, 0.1 }, { 0.5, 1.0 }, { 1.0, 0.3 }, { 1.5, 1.2 } };
    for (size_t g = 0; g < sizeof grid / sizeof grid[0]; g++) {
        const double m = 1.0, kT = 1.0, dt = grid[g][0], k = m * (grid[g][1] / dt) * (grid[g][1] / dt);
        double S[S_DMAX][S_DMAX], p2, x2_cf, p2_cf;
        s_vv_closed(m, k, kT, dt, S, &p2, &x2_cf, &p2_cf);
        ENSURE_REL(S[0][0], x2_cf, 1e-12);
        ENSURE_REL(S[1][1], kT / m, 1e-12);
        ENSURE_REL(p2, p2_cf, 1e-12);
    }
    const double m = 1.0, kT = 1.0, dt = 0.5, k = m * (0.1 / dt) * (0.1 / dt);
    double S[S_DMAX][S_DMAX], p2, x2_cf, p2_cf;
    s_vv_closed(m, k, kT, dt, S, &p2, &x2_cf, &p2_cf);
    fprintf(stderr, "  paper-vv map: <w^2> %+.2g, <w_half^2> %+.4f, <x^2> %+.5f (relative to kT/m, kT/k)\n",
            S[1][1] / (kT / m) - 1.0, p2 / (kT / m) - 1.0, S[0][0] / (kT / k) - 1.0);
    /* sign and size of the kinetic-temperature error: O(η dt), within 2% of ε/2/(1 − ε/2) here */
    ENSURE_REL(p2 / (kT / m) - 1.0, 0.5 * dt / (1.0 - 0.5 * dt), 0.02);

    const long n = LONG_OR(4000000L, 1000000L);
    double st[3][2];
    vafm_kernel K;
    s_kernel_free(&K, vafm_integrator_paper_vv, m, k, kT, dt, 401);
    s_kernel_stats(&K, vafm_integrator_paper_vv, n, st);
    fprintf(stderr, "  paper-vv sim: <w^2> %.5f +- %.5f, <w_half^2> %.5f +- %.5f, <x^2> %.5f +- %.5f (kT units)\n",
            st[1][0] / (kT / m), st[1][1] / (kT / m), st[2][0] / (kT / m), st[2][1] / (kT / m), st[0][0] / (kT / k),
            st[0][1] / (kT / k));
    ENSURE_ABS(st[1][0], S[1][1], 5.0 * st[1][1]);
    ENSURE_ABS(st[2][0], p2, 5.0 * st[2][1]);
    ENSURE_ABS(st[0][0], S[0][0], 5.0 * st[0][1]);
    /* the kinetic-temperature error is resolved: far more than 5σ from kT/m, with the predicted sign */
    ENSURE(st[2][0] - kT / m > 10.0 * st[2][1]);
    ENSURE(st[1][1] < 0.01 * kT / m && st[0][1] < 0.03 * kT / k);
}

/* Brownian Euler: ⟨x²⟩ = kT/k / (1 − h/2), h = K dt/ζ (physics notes), here h = 0.5 (+33%): the map's
 * Lyapunov value equals the closed form to 1e-12, and the simulation (ζ = m = 1, k = 1, kT = 1,
 * dt = 0.5; x keeps a fraction 1 − h = 0.5 of itself per step: ~3 steps of correlation) agrees at 5σ.
 * N = 10^6 steps (2.5·10^5 short): σ ≈ 0.2% (0.4%). */
static void test_brownian_euler(void)
{
    const double m = 1.0, k = 1.0, kT = 1.0, dt = 0.5, h = k * dt / m;
    const double x2 = kT / k / (1.0 - 0.5 * h);
    double S[S_DMAX][S_DMAX], st[3][2];
    ENSURE(s_lyap_of(s_step_bd, 1, m, k, kT, dt, S) == 0);
    ENSURE_REL(S[0][0], x2, 1e-12);
    const long n = LONG_OR(1000000L, 250000L);
    vafm_kernel K;
    s_kernel_free(&K, vafm_integrator_brownian, m, k, kT, dt, 501);
    s_kernel_stats(&K, vafm_integrator_brownian, n, st);
    fprintf(stderr, "  brownian h = 0.5: <x^2>/(kT/k) = %.5f +- %.5f (theory %.5f)\n", st[0][0] / (kT / k),
            st[0][1] / (kT / k), x2 / (kT / k));
    ENSURE_ABS(st[0][0], x2, 5.0 * st[0][1]);
    ENSURE(st[0][1] < 0.01 * x2);
}

/* ---- 4. PSD and the thermal-tune fit --------------------------------------------------------- */

/* In-place radix-2 complex FFT (n a power of two), forward sign. */
static void s_fft(double *re, double *im, size_t n)
{
    for (size_t i = 1, j = 0; i < n; i++) {
        size_t bit = n >> 1;
        for (; j & bit; bit >>= 1)
            j ^= bit;
        j ^= bit;
        if (i < j) {
            double t = re[i];
            re[i] = re[j];
            re[j] = t;
            t = im[i];
            im[i] = im[j];
            im[j] = t;
        }
    }
    for (size_t len = 2; len <= n; len <<= 1) {
        const double ang = -2.0 * S_PI / (double)len;
        for (size_t i = 0; i < n; i += len)
            for (size_t j = 0; j < len / 2; j++) {
                const double c = cos(ang * (double)j), s = sin(ang * (double)j);
                const size_t a = i + j, b = i + j + len / 2;
                const double xr = re[b] * c - im[b] * s, xi = re[b] * s + im[b] * c;
                re[b] = re[a] - xr;
                im[b] = im[a] - xi;
                re[a] += xr;
                im[a] += xi;
            }
    }
}

/* Solve the 3×3 system M x = b (Cramer). @return 0 or −1. */
static int s_solve3(double M[3][3], const double b[3], double x[3])
{
    double det = M[0][0] * (M[1][1] * M[2][2] - M[1][2] * M[2][1]) - M[0][1] * (M[1][0] * M[2][2] - M[1][2] * M[2][0]) +
                 M[0][2] * (M[1][0] * M[2][1] - M[1][1] * M[2][0]);
    if (!(fabs(det) > 0.0))
        return -1;
    for (int c = 0; c < 3; c++) {
        double T[3][3];
        memcpy(T, M, sizeof T);
        for (int r = 0; r < 3; r++)
            T[r][c] = b[r];
        x[c] = (T[0][0] * (T[1][1] * T[2][2] - T[1][2] * T[2][1]) - T[0][1] * (T[1][0] * T[2][2] - T[1][2] * T[2][0]) +
                T[0][2] * (T[1][0] * T[2][1] - T[1][1] * T[2][0])) /
               det;
    }
    return 0;
}

/* Levenberg–Marquardt fit of ln S = ln A + 4 ln f0 − ln[(f0² − f²)² + (f f0/Q)²] to (f_i, y_i = ln P_i).
 * p = {ln A, f0, Q} holds the start and receives the fit. @return the final sum of squares. */
static double s_fit_sho(const double *f, const double *y, size_t n, double p[3])
{
    double lambda = 1e-3, ss = INFINITY;
    for (int it = 0; it < 200; it++) {
        double JTJ[3][3] = { { 0 } }, JTr[3] = { 0 }, s0 = 0.0;
        for (size_t i = 0; i < n; i++) {
            const double f0 = p[1], Q = p[2], d = f0 * f0 - f[i] * f[i];
            const double D = d * d + f[i] * f[i] * f0 * f0 / (Q * Q);
            const double r = y[i] - (p[0] + 4.0 * log(f0) - log(D));
            const double J[3] = { 1.0, 4.0 / f0 - (4.0 * f0 * d + 2.0 * f[i] * f[i] * f0 / (Q * Q)) / D,
                                  2.0 * f[i] * f[i] * f0 * f0 / (Q * Q * Q * D) };
            for (int a = 0; a < 3; a++) {
                JTr[a] += J[a] * r;
                for (int b = 0; b < 3; b++)
                    JTJ[a][b] += J[a] * J[b];
            }
            s0 += r * r;
        }
        ss = s0;
        /* try steps with growing damping until the sum of squares falls */
        int improved = 0;
        for (int tries = 0; tries < 30 && !improved; tries++) {
            double M[3][3], dp[3], q[3];
            memcpy(M, JTJ, sizeof M);
            for (int a = 0; a < 3; a++)
                M[a][a] *= 1.0 + lambda;
            if (s_solve3(M, JTr, dp))
                break;
            for (int a = 0; a < 3; a++)
                q[a] = p[a] + dp[a];
            if (!(q[1] > 0 && q[2] > 0)) {
                lambda *= 10.0;
                continue;
            }
            double s1 = 0.0;
            for (size_t i = 0; i < n; i++) {
                const double d = q[1] * q[1] - f[i] * f[i];
                const double D = d * d + f[i] * f[i] * q[1] * q[1] / (q[2] * q[2]);
                const double r = y[i] - (q[0] + 4.0 * log(q[1]) - log(D));
                s1 += r * r;
            }
            if (s1 <= s0) {
                memcpy(p, q, sizeof q);
                lambda = fmax(lambda / 10.0, 1e-12);
                improved = 1;
                if (s0 - s1 < 1e-14 * s0)
                    return s1;
            } else {
                lambda *= 10.0;
            }
        }
        if (!improved)
            break;
    }
    return ss;
}

/* Thermal tune of the SI lever (exact free propagation, point samples at fs = 8 f0). Welch estimate:
 * M segments of L = 4096 samples (df = 19.5 Hz, the resonance's half width f0/2Q = 500 Hz spans 26
 * bins), periodic Hann window, no overlap, one-sided P = 2|X|²/(fs Σw²). Reference: S(f) with its
 * aliases, Σ_j S(|f + j fs|) (exact for point samples). The Hann window's smoothing bias is checked to
 * be < 0.5% on the exact expected periodogram (built from the OU autocovariance σ²ρ(lΔt)), so the
 * comparison is limited by statistics: each bin is a χ²₂ variable (relative sd 1) averaged over M
 * segments; Hann makes neighbouring bins correlate (periodogram correlation 4/9 at ±1, 1/36 at ±2), so
 * a band of K bins has relative sd √(1.944/(M K)). Bands of K = 32 bins from bin 32 to fs/4 (31 bands):
 * M = 256 (64 short): sd 1.5% (3.1%); each band at 5σ, and the χ² over bands below nb + 5√(2nb).
 * Fit: S = A f0⁴/((f0² − f²)² + (f f0/Q)²) by least squares on ln P over 0.1–1.9 f0 (ln of an average
 * of M χ²₂/2 has mean ln E − 1/(2M), added back), k = 2kT/(πA f0 Q) within 3% (notes: ~2%), f0 within
 * 0.5% and Q within 5%. */
static void test_psd(void)
{
    enum { L = 4096 };
    const size_t M = LONG_OR(256, 64);
    vafm_params p;
    s_lever(&p);
    p.free_exact = 1;
    p.seed = 601;
    s_trace tr = { 0 };
    int r = s_tune(&p, M * L, &tr);
    ENSURE(r == 0 && tr.n == M * L);
    if (r || tr.n != M * L) {
        free(tr.x);
        return;
    }
    double *re = malloc(L * sizeof *re), *im = malloc(L * sizeof *im), *win = malloc(L * sizeof *win);
    double *P = calloc(L / 2 + 1, sizeof *P), *ref = calloc(L / 2 + 1, sizeof *ref);
    double *cw = malloc(L * sizeof *cw);
    ENSURE(re && im && win && P && ref && cw);
    if (!(re && im && win && P && ref && cw))
        goto done;
    double sw2 = 0.0;
    for (size_t i = 0; i < L; i++) {
        win[i] = 0.5 * (1.0 - cos(2.0 * S_PI * (double)i / L));
        sw2 += win[i] * win[i];
    }
    for (size_t s = 0; s < M; s++) {
        for (size_t i = 0; i < L; i++) {
            re[i] = tr.x[s * L + i] * win[i];
            im[i] = 0.0;
        }
        s_fft(re, im, L);
        for (size_t kb = 1; kb < L / 2; kb++)
            P[kb] += 2.0 * (re[kb] * re[kb] + im[kb] * im[kb]) / (S_FS * sw2) / (double)M;
    }
    const double df = S_FS / L;
    for (size_t kb = 1; kb < L / 2; kb++) {
        double f = df * (double)kb, s = 0.0;
        for (int j = -400; j <= 400; j++)
            s += s_psd(&p, fabs(f + j * S_FS));
        ref[kb] = s;
    }
    /* ∫S df = kT/k (closed form) on the formula itself, by the trapezoid rule out to 400 f0 */
    {
        double integ = 0.0, h = S_F0 / 2000.0;
        for (long i = 1; i < 800000; i++)
            integ += s_psd(&p, h * (double)i) * h;
        integ += 0.5 * h * s_psd(&p, 0.0);
        integ += S_F0 * 400.0 * s_psd(&p, 400.0 * S_F0) / 3.0; /* tail ~ f⁻⁴ */
        ENSURE_REL(integ, VAFM_KB_J_PER_K * S_T / S_K, 1e-4);
    }
    /* exact expectation of the Hann periodogram from the autocovariance: smoothing bias < 0.5% */
    {
        const double var = VAFM_KB_J_PER_K * S_T / S_K, w0 = S_Q, Ts = p.eta_per_s / S_FS; /* reduced */
        for (size_t l = 0; l < L; l++) {
            double s = 0.0;
            for (size_t i = 0; i + l < L; i++)
                s += win[i] * win[i + l];
            cw[l] = s * var * s_rho(w0, (double)l * Ts);
        }
        double worst = 0.0;
        for (size_t kb = 32; kb <= L / 4; kb += 4) {
            double e = cw[0];
            for (size_t l = 1; l < L; l++)
                e += 2.0 * cw[l] * cos(2.0 * S_PI * (double)(kb * l % L) / L);
            e *= 2.0 / (S_FS * sw2);
            worst = fmax(worst, fabs(e / ref[kb] - 1.0));
        }
        fprintf(stderr, "  psd: Hann bias of the expected periodogram vs aliased S(f): max %.2e\n", worst);
        ENSURE(worst < 5e-3);
    }
    /* bands */
    {
        const int K = 32;
        const double sd = sqrt(1.944 / ((double)M * K));
        int nb = 0;
        double chi2 = 0.0, zmax = 0.0;
        for (size_t b0 = 32; b0 + K <= L / 4 + 1; b0 += K) {
            double sp = 0.0, sr = 0.0;
            for (size_t kb = b0; kb < b0 + K; kb++) {
                sp += P[kb];
                sr += ref[kb];
            }
            double z = (sp / sr - 1.0) / sd;
            ENSURE_MSG(fabs(z) < 5.0, "band at %.0f Hz: ratio %.4f, z = %.2f", df * (double)b0, sp / sr, z);
            chi2 += z * z;
            zmax = fmax(zmax, fabs(z));
            nb++;
        }
        fprintf(stderr, "  psd: %d bands, band sd %.4f, chi2 = %.1f, max |z| = %.2f\n", nb, sd, chi2, zmax);
        ENSURE(nb == 31);
        ENSURE(chi2 < nb + 5.0 * sqrt(2.0 * nb));
    }
    /* thermal-tune fit */
    {
        size_t lo = (size_t)ceil(0.1 * S_F0 / df), hi = (size_t)floor(1.9 * S_F0 / df), n = 0;
        double *fx = malloc((hi - lo + 1) * sizeof *fx), *fy = malloc((hi - lo + 1) * sizeof *fy);
        ENSURE(fx && fy);
        if (fx && fy) {
            size_t kmax = lo;
            for (size_t kb = lo; kb <= hi; kb++) {
                fx[n] = df * (double)kb;
                fy[n] = log(P[kb]) + 0.5 / (double)M;
                n++;
                if (P[kb] > P[kmax])
                    kmax = kb;
            }
            double low = 0.0;
            for (size_t kb = lo; kb < lo + 8; kb++)
                low += P[kb] / 8.0;
            double par[3] = { log(low), df * (double)kmax, sqrt(P[kmax] / low) };
            s_fit_sho(fx, fy, n, par);
            const double A = exp(par[0]), f0 = par[1], Q = par[2];
            const double kfit = 2.0 * VAFM_KB_J_PER_K * S_T / (S_PI * A * f0 * Q);
            fprintf(stderr, "  tune fit: k = %.5f N/m (%.2f%%), f0 = %.1f Hz (%.3f%%), Q = %.3f (%.2f%%)\n", kfit,
                    100.0 * (kfit / S_K - 1.0), f0, 100.0 * (f0 / S_F0 - 1.0), Q, 100.0 * (Q / S_Q - 1.0));
            ENSURE_REL(kfit, S_K, 0.03);
            ENSURE_REL(f0, S_F0, 0.005);
            ENSURE_REL(Q, S_Q, 0.05);
        }
        free(fx);
        free(fy);
    }
done:
    free(re);
    free(im);
    free(win);
    free(P);
    free(ref);
    free(cw);
    free(tr.x);
}

/* ---- 4b. box-car samples of the exact free propagation ---------------------------------------- */

/* Autocovariance of the free cantilever's position (units of kT/k) at lag τ, s: the damped oscillator
 * (underdamped: ω0 > η/2) or, overdamped (Brownian, ζ = mη), e^{−(k/ζ)|τ|}. */
static double s_cov_free(double w0, double eta, int overdamped, double tau)
{
    tau = fabs(tau);
    if (overdamped)
        return exp(-w0 * w0 / eta * tau);
    const double w1 = sqrt(w0 * w0 - 0.25 * eta * eta);
    return exp(-0.5 * eta * tau) * (cos(w1 * tau) + 0.5 * eta / w1 * sin(w1 * tau));
}

/* Covariance of two box-car means over [0, Ts] and [jTs, (j+1)Ts]: ∫ (1 − |s|/Ts)/Ts C(jTs + s) ds
 * over |s| < Ts (composite Simpson on each half, where C is smooth; 4000 panels: error < 1e-12). */
static double s_cov_boxcar(double w0, double eta, int overdamped, double Ts, int j)
{
    const int n = 4000;
    double sum = 0.0;
    for (int half = -1; half <= 1; half += 2) {
        const double h = Ts / n;
        double acc = 0.0;
        for (int i = 0; i <= n; i++) {
            const double sv = half * h * i;
            const double f = (1.0 - fabs(sv) / Ts) / Ts * s_cov_free(w0, eta, overdamped, j * Ts + sv);
            acc += f * (i == 0 || i == n ? 1.0 : (i % 2 ? 4.0 : 2.0));
        }
        sum += acc * h / 3.0;
    }
    return sum;
}

/* With antialias = mean a sample is the time average of the path over its interval; the exact free
 * propagation takes few long steps per sample where the sample rate is high (here 2, Brownian 1), so
 * each step must carry the exact integral of the path (free_ou.c), not its end value. Checked on
 * the variances of x and of its first and second differences, whose expectations follow from the
 * box-car-averaged autocovariance Γ_j (closed-form C(τ), quadrature above): Var x = Γ0,
 * Var Δx = 2(Γ0 − Γ1), Var Δ²x = 6Γ0 − 8Γ1 + 2Γ2. The second difference weighs the spectrum near fs/2,
 * where averaging the end values of two steps instead of the path leaves 5% more (Brownian, one step
 * per sample: 26% more). Lever f0 = 10 kHz, Q = 0.63 (the paper-fig1 lever's Q), fs = 25 f0.
 * N = 2^20 samples (2^18 short), 100 blocks: σ ≈ 0.2–0.5% (double short); each at 5σ. */
static void test_boxcar_exact(void)
{
    const size_t n = LONG_OR((size_t)1 << 20, (size_t)1 << 18);
    for (int od = 0; od < 2; od++) {
        vafm_params p;
        s_lever(&p);
        const double w0 = 2.0 * S_PI * S_F0, eta = w0 / 0.63;
        p.eta_per_s = eta;
        p.sample_rate_Hz = 25.0 * S_F0;
        p.antialias = VAFM_ANTIALIAS_MEAN;
        p.free_exact = 1;
        p.seed = 611 + (uint64_t)od;
        if (od)
            p.integrator = vafm_integrator_brownian;
        s_trace tr = { 0 };
        int r = s_tune(&p, n, &tr);
        ENSURE(r == 0 && tr.n == n);
        if (r || tr.n != n) {
            free(tr.x);
            continue;
        }
        const double var = VAFM_KB_J_PER_K * p.T_K / p.k_N_per_m, Ts = 1.0 / p.sample_rate_Hz;
        double mean = 0.0;
        for (size_t i = 0; i < n; i++)
            mean += tr.x[i] / (double)n;
        for (size_t i = 0; i < n; i++)
            tr.x[i] = (tr.x[i] - mean) / sqrt(var);
        double g[3];
        for (int j = 0; j < 3; j++)
            g[j] = s_cov_boxcar(w0, eta, od, Ts, j);
        const double want[3] = { g[0], 2.0 * (g[0] - g[1]), 6.0 * g[0] - 8.0 * g[1] + 2.0 * g[2] };
        double got[3], se[3];
        for (int d = 0; d < 3; d++) {
            s_acc a;
            s_acc_init(&a, (long)(n - 2));
            for (size_t i = 2; i < n; i++) {
                const double v = d == 0 ? tr.x[i] : d == 1 ? tr.x[i] - tr.x[i - 1]
                                                            : tr.x[i] - 2.0 * tr.x[i - 1] + tr.x[i - 2];
                s_acc_push(&a, v * v);
            }
            s_acc_result(&a, &got[d], &se[d]);
            fprintf(stderr, "  boxcar %s: Var %s = %.5f +- %.5f (theory %.5f)\n", od ? "brownian" : "langevin",
                    d == 0 ? "x  " : d == 1 ? "dx " : "d2x", got[d], se[d], want[d]);
            ENSURE_MSG(fabs(got[d] - want[d]) < 5.0 * se[d], "%s: Var of difference order %d: %.5f vs %.5f (se %.5f)",
                       od ? "brownian" : "langevin", d, got[d], want[d], se[d]);
        }
        free(tr.x);
    }
}

/* ---- 5. exact free propagation vs plain small steps ------------------------------------------- */

/* The SI lever's tune with free_exact = 1 against gjf at a small step (ω0 dt = 0.05, 16 steps per
 * sample; GJF's frequency error ~ω0²dt²/24 moves ρ(Ts) by ~1e-4, well under the noise): the sample
 * variance and the lag-1 autocorrelation agree within 5σ of their difference, and each matches the
 * continuous OU value ρ(Ts) = e^{−ηTs/2}[cos ω1Ts + η sin(ω1Ts)/(2ω1)] (= 0.71455 here) at 5σ.
 * N = 2^20 samples (2^18 short), blocks of 10^4; σ(ρ) ≈ 1.3e-4 (2.6e-4): x_{i+1} is nearly ρ·x_i. */
static void test_exact_vs_steps(void)
{
    vafm_params p;
    s_lever(&p);
    const size_t n = LONG_OR((size_t)1 << 20, (size_t)1 << 18);
    double var[2], svar[2], rho[2], srho[2];
    for (int e = 0; e < 2; e++) {
        p.free_exact = e ? 0 : 1;
        p.integrator = vafm_integrator_gjf;
        p.omega_dt = e ? 0.05 : 2.0 * S_PI / 40.0;
        p.seed = 701 + (uint64_t)e;
        s_trace tr = { 0 };
        int r = s_tune(&p, n, &tr);
        ENSURE(r == 0 && tr.n == n);
        if (r || tr.n != n) {
            free(tr.x);
            return;
        }
        s_meansq(tr.x, n, &var[e], &svar[e]);
        s_lag_corr(tr.x, n, 1, &rho[e], &srho[e]);
        free(tr.x);
    }
    const double Ts = p.eta_per_s / S_FS, rho_th = s_rho(S_Q, Ts), v_th = VAFM_KB_J_PER_K * S_T / S_K;
    fprintf(stderr, "  exact: var %.5f +- %.5f rho1 %.5f +- %.5f; steps: var %.5f +- %.5f rho1 %.5f +- %.5f; "
                    "theory rho1 %.5f\n",
            var[0] / v_th, svar[0] / v_th, rho[0], srho[0], var[1] / v_th, svar[1] / v_th, rho[1], srho[1], rho_th);
    ENSURE_ABS(var[0], var[1], 5.0 * hypot(svar[0], svar[1]));
    ENSURE_ABS(rho[0], rho[1], 5.0 * hypot(srho[0], srho[1]));
    for (int e = 0; e < 2; e++) {
        ENSURE_ABS(rho[e], rho_th, 5.0 * srho[e]);
        ENSURE(srho[e] < 1e-3);
    }
}

/* ---- 6. T = 0 draws no random numbers --------------------------------------------------------- */

typedef struct s_curve_rec {
    size_t n, cap;
    double *v; /* 5 channels per sample */
    uint8_t *seg;
} s_curve_rec;

static int s_rec(void *user, const vafm_samples *b)
{
    s_curve_rec *c = user;
    if (c->n + b->n > c->cap) {
        size_t cap = c->cap ? 2 * c->cap : 1 << 14;
        while (cap < c->n + b->n)
            cap *= 2;
        double *v = realloc(c->v, cap * 5 * sizeof *v);
        if (!v)
            return 1;
        c->v = v;
        uint8_t *s = realloc(c->seg, cap);
        if (!s)
            return 1;
        c->seg = s;
        c->cap = cap;
    }
    for (size_t i = 0; i < b->n; i++) {
        double *o = c->v + 5 * (c->n + i);
        o[0] = b->time_s[i];
        o[1] = b->height_m[i];
        o[2] = b->deflection_m[i];
        o[3] = b->force_N[i];
        o[4] = b->tip_m[i];
        c->seg[c->n + i] = b->segment[i];
    }
    c->n += b->n;
    return 0;
}

/* An athermal force curve (paper-fig4 scene at T = 0, JKR, gjf) with two different seeds is the same
 * bit for bit (every sample, every observable); and every integrator and the exact free step leave the
 * kernel's random stream untouched at kT = 0. */
static void test_athermal_no_draws(void)
{
    vafm_params p;
    ENSURE(vafm_preset_apply(&p, "paper-fig4", NULL) == 0);
    p.T_K = 0.0;
    s_curve_rec rec[2] = { { 0 }, { 0 } };
    vafm_curve_result res[2];
    for (int i = 0; i < 2; i++) {
        p.seed = i ? 0xdeadbeefcafeULL : 7;
        vafm_sim *sim = NULL;
        ENSURE(vafm_sim_new(&sim, &p, NULL) == 0);
        if (!sim)
            return;
        ENSURE(vafm_sim_curve(sim, 3, s_rec, &rec[i], &res[i]) == 0);
        vafm_sim_destroy(&sim);
    }
    ENSURE(rec[0].n > 100 && rec[0].n == rec[1].n);
    if (rec[0].n == rec[1].n) {
        ENSURE(memcmp(rec[0].v, rec[1].v, rec[0].n * 5 * sizeof(double)) == 0);
        ENSURE(memcmp(rec[0].seg, rec[1].seg, rec[0].n) == 0);
    }
    ENSURE(memcmp(&res[0], &res[1], sizeof res[0]) == 0);
    ENSURE(isfinite(res[0].detach_force_N) && res[0].flags == 0);
    for (int i = 0; i < 2; i++) {
        free(rec[i].v);
        free(rec[i].seg);
    }

    for (int i = 0; i < vafm_integrator_count(); i++) {
        const vafm_integrator_type *it = vafm_integrator_at(i);
        vafm_kernel K;
        s_kernel_free(&K, it, 1.0, 0.5, 0.0, 0.1, 801);
        const vafm_rng before = K.rng;
        long done = it->run(&K, 5000);
        ENSURE(done == 5000);
        ENSURE_MSG(memcmp(&before, &K.rng, sizeof before) == 0, "%s drew random numbers at kT = 0", it->name);
        ENSURE(isfinite(K.u) && fabs(K.u) < 0.7); /* it moved: relaxed from the start at 0.7 */
    }
    for (int od = 0; od < 2; od++) {
        vafm_kernel K;
        s_kernel_free(&K, NULL, 1.0, 0.5, 0.0, 0.1, 802);
        vafm_free_ou ou;
        vafm_free_ou_setup(&ou, &K, 0.4, od);
        const vafm_rng before = K.rng;
        for (int j = 0; j < 1000; j++)
            vafm_free_ou_step(&K, &ou);
        ENSURE(memcmp(&before, &K.rng, sizeof before) == 0);
        ENSURE(fabs(K.u) < 0.1);
    }
}

int main(void)
{
    RUN_TEST(test_equipartition_tune);
    RUN_TEST(test_equipartition_velocity);
    RUN_TEST(test_exact_config_large_dt);
    RUN_TEST(test_paper_vv);
    RUN_TEST(test_brownian_euler);
    RUN_TEST(test_psd);
    RUN_TEST(test_boxcar_exact);
    RUN_TEST(test_exact_vs_steps);
    RUN_TEST(test_athermal_no_draws);
    return harness_done();
}
