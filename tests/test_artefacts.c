/* SPDX-License-Identifier: MIT */
/*
 * The instrument's artefacts (issue #14, vafm/detector.h and the sample's in sim.c), each against its own
 * model: exact where the model is deterministic (drift, virtual deflection, interference, mains, the
 * contact point's shift of every reported height), statistical with the N and the sigma stated where it is
 * random (the random walk, the contact point's spread, the 1/f spectrum against S_w·(1 + f_c/f) through
 * the Hann window). And the contract: each artefact has its own random stream, so turning one on changes
 * no other sample or draw.
 */
#include "harness.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "vafm/detector.h"
#include "vafm/params.h"
#include "vafm/sim.h"
#include "core/piezo.h"

/* ---- the signal ---------------------------------------------------------------------------------- */

static vafm_params t_base(void)
{
    vafm_params p;
    vafm_preset_apply(&p, "contact-silica", NULL);
    p.sample_rate_Hz = 1000.0;
    return p;
}

/* The signal of deflection 0 at times i/fs and heights h0 - i*dh, n samples. */
static void t_signal(const vafm_params *p, uint64_t index, size_t n, double h0, double dh, double *v)
{
    vafm_detector d;
    vafm_detector_begin(&d, p, index);
    for (size_t i = 0; i < n; i++)
        vafm_detector_apply(&d, (double)i / p->sample_rate_Hz, h0 - (double)i * dh, 0.0, &v[i], NULL, NULL);
}

/* Deterministic terms are what their formulas say, and none of them moves the white noise's draws. */
static void test_deterministic_terms(void)
{
    enum { N = 2000 };
    static double a[N], b[N];
    vafm_params p = t_base();
    p.noise_V_rms = 1e-3;
    p.baseline_offset_V = 0.2;
    t_signal(&p, 7, N, 1e-6, 1e-10, a);
    vafm_params q = p;
    q.drift_V_per_s = 0.05;
    q.virtual_deflection_V_per_m = 2e4;
    t_signal(&q, 7, N, 1e-6, 1e-10, b);
    double worst = 0.0;
    for (size_t i = 0; i < N; i++) {
        double t = (double)i / p.sample_rate_Hz, h = 1e-6 - (double)i * 1e-10;
        worst = fmax(worst, fabs(b[i] - a[i] - (0.05 * t + 2e4 * h)));
    }
    ENSURE_MSG(worst < 1e-13, "drift + virtual deflection: worst deviation %g V", worst);

    /* interference: A sin(2π h / P + φ) over ten periods of height, one sample per nm */
    q = t_base();
    q.interference_V = 0.01;
    q.interference_period_m = 320e-9;
    static double c[4000];
    t_signal(&q, 3, 4000, 0.0, -1e-9, c); /* h = i nm */
    double mx = -1, mn = 1, per = 0.0;
    for (size_t i = 0; i < 4000; i++) {
        mx = fmax(mx, c[i]);
        mn = fmin(mn, c[i]);
        if (i >= 320)
            per = fmax(per, fabs(c[i] - c[i - 320]));
    }
    ENSURE_MSG(fabs(mx - 0.01) < 2e-6 && fabs(mn + 0.01) < 2e-6, "interference: range [%g, %g] V", mn, mx);
    ENSURE_MSG(per < 1e-12, "interference: not periodic in 320 nm (%g V)", per);
    double c0 = c[0];
    t_signal(&q, 4, 1, 0.0, 0.0, c);
    ENSURE_MSG(c[0] != c0, "interference: the phase is the same for curves 3 and 4");

    /* mains: amplitudes A, A/2, A/3 at 50, 100, 150 Hz, projected over 20 whole periods */
    q = t_base();
    q.mains_V = 0.02;
    q.mains_Hz = 50.0;
    enum { M = 400 }; /* 0.4 s at 1 kHz */
    static double m[M];
    t_signal(&q, 0, M, 0.0, 0.0, m);
    for (int n = 1; n <= 4; n++) {
        double sc = 0, cc = 0, w = 2.0 * M_PI * 50.0 * n;
        for (size_t i = 0; i < M; i++) {
            sc += m[i] * sin(w * (double)i / 1000.0);
            cc += m[i] * cos(w * (double)i / 1000.0);
        }
        double amp = 2.0 * hypot(sc, cc) / M, want = n <= 3 ? 0.02 / n : 0.0;
        ENSURE_MSG(fabs(amp - want) < 1e-12, "mains harmonic %d: %g V, want %g V", n, amp, want);
    }
}

/* Each artefact draws from its own stream: the white noise of a scene is the same with the random walk and
 * the 1/f noise on (their difference is their own terms, not a changed draw). */
static void test_own_streams(void)
{
    enum { N = 512 };
    static double a[N], b[N], c[N];
    vafm_params p = t_base();
    p.noise_V_rms = 1e-3;
    t_signal(&p, 11, N, 0.0, 0.0, a);
    vafm_params q = p;
    q.drift_walk_V_per_sqrt_s = 0.01;
    t_signal(&q, 11, N, 0.0, 0.0, b);
    vafm_params r = p;
    r.flicker_corner_Hz = 10.0;
    t_signal(&r, 11, N, 0.0, 0.0, c);
    /* the walk's increments are its own: b - a is a random walk starting at 0 whose steps are independent of a */
    ENSURE(fabs(b[0] - a[0]) < 1e-15);
    double sxy = 0, sxx = 0, syy = 0;
    for (size_t i = 1; i < N; i++) {
        double dw = (b[i] - a[i]) - (b[i - 1] - a[i - 1]);
        sxy += dw * a[i];
        sxx += dw * dw;
        syy += a[i] * a[i];
    }
    /* N = 511 pairs: the correlation of independent series has sd 1/√511 = 0.044; 4 sigma */
    double corr = sxy / sqrt(sxx * syy);
    ENSURE_MSG(fabs(corr) < 0.18, "walk steps correlate with the white noise: %g", corr);
    ENSURE_MSG(c[5] != a[5], "1/f noise adds nothing");
}

/* The random walk: w(t2) - w(t1) ~ N(0, σ²(t2 - t1)) over curves. N = 4000 curves: the sample variance has a
 * relative sd of √(2/N) = 2.2%; 4 sigma. */
static void test_random_walk(void)
{
    enum { NC = 4000, L = 200 };
    vafm_params p = t_base();
    p.drift_walk_V_per_sqrt_s = 0.01;
    static double v[L];
    double s2 = 0.0, s1 = 0.0;
    for (uint64_t i = 0; i < NC; i++) {
        t_signal(&p, i, L, 0.0, 0.0, v);
        double d = v[L - 1] - v[0];
        s1 += d;
        s2 += d * d;
    }
    double var = s2 / NC - (s1 / NC) * (s1 / NC), want = 0.01 * 0.01 * (L - 1) / p.sample_rate_Hz;
    ENSURE_MSG(fabs(var / want - 1.0) < 4.0 * sqrt(2.0 / NC), "walk variance %g V^2, model %g V^2", var, want);
}

/* The Hann window's squared DTFT magnitude at frequency offset df (Hz) for L samples at fs, in closed form:
 * h_n = 1/2 − cos(2πn/L)/2 transforms to D(ω)/2 − D(ω − 2π/L)/4 − D(ω + 2π/L)/4 with the Dirichlet kernel
 * D(ω) = e^{−iω(L−1)/2} sin(Lω/2)/sin(ω/2). */
static double t_hann2(double df, int L, double fs)
{
    const double w0 = 2.0 * M_PI * df / fs, c[3] = { 0.5, -0.25, -0.25 }, sh[3] = { 0.0, -1.0, 1.0 };
    double re = 0.0, im = 0.0;
    for (int k = 0; k < 3; k++) {
        double w = w0 + sh[k] * 2.0 * M_PI / L, sw = sin(0.5 * w);
        double r = fabs(sw) < 1e-12 ? (double)L : sin(0.5 * L * w) / sw, ph = -0.5 * w * (L - 1);
        re += c[k] * r * cos(ph);
        im += c[k] * r * sin(ph);
    }
    return re * re + im * im;
}

/* 1/f noise: Welch periodogram (Hann, L = 1024 at 1 kHz, K = 2048 segments) at a few bins against the
 * target spectrum S_w·(1 + f_c/f) (f ≥ 1 mHz) seen through the same window, averaged over 3 adjacent bins.
 * Statistical error: 1/√(3K) = 1.3% per point; the bank's ripple about 1/f is below 1%. Tolerance 8%. The
 * white floor alone would be off by a factor 1 + f_c/f (3.6 at 3.9 Hz). */
static void test_flicker_spectrum(void)
{
    enum { L = 1024, K = 2048 };
    const double fs = 1000.0, fc = 10.0, sw = 1e-3;
    vafm_params p = t_base();
    p.noise_V_rms = sw;
    p.flicker_corner_Hz = fc;
    vafm_detector d;
    vafm_detector_begin(&d, &p, 0);
    ENSURE(d.n_poles > 10 && d.n_poles <= VAFM_FLICKER_POLES_MAX);
    static const int bins[] = { 4, 8, 16, 64, 200 };
    enum { NB = sizeof bins / sizeof bins[0] };
    double acc[NB][3];
    memset(acc, 0, sizeof acc);
    double *x = malloc(L * sizeof *x), hsum2 = 0.0;
    for (int n = 0; n < L; n++) {
        double h = 0.5 - 0.5 * cos(2.0 * M_PI * n / L);
        hsum2 += h * h;
    }
    uint64_t ns = 0;
    for (int k = 0; k < K && x; k++) {
        for (int n = 0; n < L; n++, ns++)
            vafm_detector_apply(&d, (double)ns / fs, 0.0, 0.0, &x[n], NULL, NULL);
        for (int b = 0; b < NB; b++)
            for (int j = -1; j <= 1; j++) {
                double w = 2.0 * M_PI * (bins[b] + j) / L, re = 0.0, im = 0.0;
                for (int n = 0; n < L; n++) {
                    double h = (0.5 - 0.5 * cos(2.0 * M_PI * n / L)) * x[n];
                    re += h * cos(w * n);
                    im -= h * sin(w * n);
                }
                acc[b][j + 1] += 2.0 * (re * re + im * im) / (fs * hsum2) / K;
            }
    }
    free(x);
    const double Sw = 2.0 * sw * sw / fs;
    for (int b = 0; b < NB; b++) {
        double got = (acc[b][0] + acc[b][1] + acc[b][2]) / 3.0, want = 0.0;
        for (int j = -1; j <= 1; j++) {
            double f = (bins[b] + j) * fs / L, num = 0.0;
            /* ∫ S(f') (|H(f - f')|² + |H(f + f')|²) df' / (f_s Σh²) of the 1/f part, on a fine log grid */
            for (double lf = log(1e-3); lf < log(fs / 2); lf += 0.002) {
                double fp = exp(lf), dfp = fp * 0.002;
                num += Sw * (fc / fp) * (t_hann2(f - fp, L, fs) + t_hann2(f + fp, L, fs)) * dfp;
            }
            want += (Sw + num / (fs * hsum2)) / 3.0;
        }
        printf("  1/f: %6.3g Hz: %.4g V^2/Hz, model %.4g (ratio %.4f; white alone %.3g)\n", bins[b] * fs / L, got,
               want, got / want, Sw);
        ENSURE_MSG(fabs(got / want - 1.0) < 0.08, "1/f spectrum at bin %d (%.3g Hz): %g V^2/Hz, model %g (white %g)",
                   bins[b], bins[b] * fs / L, got, want, Sw);
    }
}

/* ---- the sample ---------------------------------------------------------------------------------- */

typedef struct t_run {
    size_t n;
    double h[20000], tip[20000], f[20000];
} t_run;

static int t_collect(void *user, const vafm_samples *b)
{
    t_run *r = user;
    for (size_t i = 0; i < b->n && r->n < 20000; i++, r->n++) {
        r->h[r->n] = b->height_m[i];
        r->tip[r->n] = b->tip_m[i];
        r->f[r->n] = b->force_N[i];
    }
    return 0;
}

static void t_curve(const vafm_params *p, uint64_t index, t_run *r, vafm_curve_result *res)
{
    vafm_sim *s = NULL;
    memset(r, 0, sizeof *r);
    ENSURE(vafm_sim_new(&s, p, NULL) == 0);
    ENSURE(s && vafm_sim_curve(s, index, t_collect, r, res) == 0);
    vafm_sim_destroy(&s);
}

/* A random contact point moves every reported height of the curve by the same amount, and nothing else: the
 * physics relative to the surface is the same curve bit for bit. Over N = 2000 curves the contact points
 * have mean surface_height_m (sd/√N) and sd contact_point_sd_m (relative sd √(1/(2N)) = 1.6%); 4 sigma. */
static void test_contact_point(void)
{
    vafm_params p;
    vafm_preset_apply(&p, "contact-silica", NULL);
    vafm_params q = p;
    q.contact_point_sd_m = 50e-9;
    static t_run a, b;
    vafm_curve_result ra, rb;
    t_curve(&p, 5, &a, &ra);
    t_curve(&q, 5, &b, &rb);
    double z = vafm_artefact_contact_point(&q, 5), worst = 0.0;
    ENSURE(a.n == b.n && ra.flags == rb.flags && ra.pulloff_spring_N == rb.pulloff_spring_N);
    for (size_t i = 0; i < a.n && i < b.n; i++) {
        worst = fmax(worst, fabs(b.h[i] - a.h[i] - z));
        worst = fmax(worst, fabs(b.tip[i] - a.tip[i] - z));
        ENSURE(a.f[i] == b.f[i]);
    }
    ENSURE_MSG(worst < 1e-20 + 1e-15 * fabs(z) * 4, "heights moved by %g m, not %g m", worst, z);
    ENSURE(rb.surface_height_m == z && fabs(rb.touch_height_m - ra.touch_height_m - z) < 1e-15);

    enum { NC = 2000 };
    double s1 = 0.0, s2 = 0.0;
    q.surface_height_m = 1e-6;
    for (uint64_t i = 0; i < NC; i++) {
        double d = vafm_artefact_contact_point(&q, i) - 1e-6;
        s1 += d;
        s2 += d * d;
    }
    double mean = s1 / NC, sd = sqrt(s2 / NC - mean * mean);
    ENSURE_MSG(fabs(mean) < 4.0 * 50e-9 / sqrt(NC), "contact point mean offset %g m", mean);
    ENSURE_MSG(fabs(sd / 50e-9 - 1.0) < 4.0 * sqrt(0.5 / NC), "contact point sd %g m", sd);
}

/* A rising sample: the tip touches when the support meets the moving surface, so the reported touch height
 * is the no-drift one (relative to the surface) plus the surface's rise by then, to within the change of the
 * approach speed's lag (athermal, 10% drift against 1 µm/s: well under a nm). The piezo still ramps its
 * own 200 nm: the first and the last reported heights are the start height. */
static void test_sample_drift(void)
{
    vafm_params p;
    vafm_preset_apply(&p, "contact-silica", NULL);
    p.T_K = 0;
    vafm_params q = p;
    q.sample_drift_m_per_s = 100e-9;
    static t_run a, b;
    vafm_curve_result ra, rb;
    t_curve(&p, 0, &a, &ra);
    t_curve(&q, 0, &b, &rb);
    double rise = q.sample_drift_m_per_s * rb.touch_time_s;
    ENSURE_MSG(fabs(rb.touch_height_m - rise - ra.touch_height_m) < 0.5e-9,
               "touch at %g m, drift-free %g m, surface rose %g m", rb.touch_height_m, ra.touch_height_m, rise);
    ENSURE_MSG(rb.touch_time_s < ra.touch_time_s, "the rising surface is met later (%g s vs %g s)", rb.touch_time_s,
               ra.touch_time_s);
    double step = p.v_approach_m_per_s / p.sample_rate_Hz;
    ENSURE_MSG(fabs(b.h[0] - p.start_height_m) <= step && fabs(b.h[b.n - 1] - p.start_height_m) <= step,
               "the piezo's ramp: %g m ... %g m", b.h[0], b.h[b.n - 1]);
}

/* ---- the piezo ------------------------------------------------------------------------------------ */

/* Bouc–Wen against its closed form along a triangle: from rest, a monotone extension by x gives
 * h = H·L_s·(1 − e^{−x/L_s}); after the reversal h falls linearly (slope H) through zero and then relaxes to
 * −H·L_s. Rate independent: the same path in 10 or in 1000 steps gives the same h at the turning points. */
static void test_piezo_hysteresis(void)
{
    vafm_params p;
    vafm_preset_apply(&p, "contact-silica", NULL);
    p.piezo_hysteresis = 0.1;
    p.piezo_hysteresis_length_m = 100e-9;
    const double H = 0.1, Ls = 100e-9, up = 300e-9;
    for (int n = 10; n <= 1000; n *= 10) {
        vafm_piezo pz;
        vafm_piezo_begin(&pz, &p, 0.0);
        double worst = 0.0;
        for (int i = 1; i <= n; i++) {
            double e = up * i / n, ea = vafm_piezo_step(&pz, e, 1e-3);
            double h = H * Ls * (1.0 - exp(-e / Ls));
            worst = fmax(worst, fabs((e - ea) - h));
        }
        double h_top = pz.h;
        /* back down: linear until h = 0 (after a travel h_top / H), then toward -H Ls */
        double back = 0.0;
        for (int i = 1; i <= n; i++) {
            double e = up - up * i / n, x = up - e, ea = vafm_piezo_step(&pz, e, 1e-3);
            double h = x <= h_top / H ? h_top - H * x : -H * Ls * (1.0 - exp(-(x - h_top / H) / Ls));
            back = fmax(back, fabs((e - ea) - h));
        }
        ENSURE_MSG(worst < 1e-20 && back < 1e-20, "n = %d: closed form missed by %g m up, %g m down", n, worst, back);
        ENSURE_MSG(fabs(h_top - H * Ls * (1.0 - exp(-3.0))) < 1e-21, "n = %d: h at the top %g m", n, h_top);
    }
}

/* Creep after a step: C·Δ·log10(1 + t/t0) from 0.01 t0 to 1e4 t0, to the lag bank's fit (3e-6 decades). */
static void test_piezo_creep(void)
{
    vafm_params p;
    vafm_preset_apply(&p, "contact-silica", NULL);
    p.piezo_creep = 0.02;
    p.piezo_creep_t0_s = 0.1;
    vafm_piezo pz;
    vafm_piezo_begin(&pz, &p, 0.0);
    const double D = 1e-6, tstep = 1e-9;
    vafm_piezo_step(&pz, D, tstep); /* the move: 1 µm in 1 ns */
    double t = tstep, worst = 0.0;
    for (double lt = log10(0.01 * 0.1); lt <= log10(1e4 * 0.1); lt += 0.05) {
        double tn = pow(10.0, lt), ea = vafm_piezo_step(&pz, D, tn - t);
        t = tn;
        double want = 0.02 * D * log10(1.0 + t / 0.1);
        worst = fmax(worst, fabs((ea - D) - want));
    }
    ENSURE_MSG(worst < 0.02 * D * 1e-5, "creep: worst deviation %g m (of %g m per decade)", worst, 0.02 * D);
}

struct t_col {
    double *hc, *hm;
    size_t n;
};

static int t_col_heights(void *u, const vafm_samples *b)
{
    struct t_col *c = u;
    for (size_t i = 0; i < b->n && c->n < 20000; i++, c->n++) {
        c->hc[c->n] = b->height_m[i];
        c->hm[c->n] = b->height_measured_m ? b->height_measured_m[i] : NAN;
    }
    return 0;
}

/* In a curve: the files' piezo height is the command (an exact ramp: steps of v/f_s, one turn), the measured
 * height is where the actuator took the support: its own model along that command, averaged over each
 * sample (the midpoint of its linear path, to within half an integrator step's share of it). Athermal. */
static void test_piezo_in_curve(void)
{
    vafm_params p;
    vafm_preset_apply(&p, "contact-silica", NULL);
    p.T_K = 0;
    p.piezo_hysteresis = 0.1;
    p.piezo_hysteresis_length_m = 100e-9;
    p.piezo_creep = 0.02;
    vafm_sim *s = NULL;
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    if (!s)
        return;
    static double hc[20000], hm[20000];
    struct t_col col = { hc, hm, 0 };
    ENSURE(vafm_sim_curve_begin(s, 0) == 0);
    ENSURE(vafm_sim_advance(s, 20000, t_col_heights, &col) == 0);
    const double dt = 1.0 / p.sample_rate_Hz, n_sub = round(dt / vafm_sim_dt(s));
    vafm_sim_destroy(&s);
    vafm_piezo pz;
    vafm_piezo_begin(&pz, &p, -p.start_height_m);
    double prev = -p.start_height_m, worst_m = 0.0;
    int turns = 0, off_ramp = 0;
    for (size_t k = 0; k < col.n; k++) {
        double e_end = 2.0 * -hc[k] - prev; /* the command's mean is its midpoint */
        double ea0 = pz.ea, ea1 = vafm_piezo_step(&pz, e_end, dt), mid = -0.5 * (ea0 + ea1);
        worst_m = fmax(worst_m, fabs(hm[k] - mid) - 0.5 * fabs(ea1 - ea0) / n_sub);
        if (k > 0) {
            double step = fabs(hc[k] - hc[k - 1]);
            turns += step < 1e-18;
            off_ramp += step >= 1e-18 && fabs(step - p.v_approach_m_per_s * dt) > 1e-18;
        }
        prev = e_end;
    }
    ENSURE_MSG(turns == 1 && off_ramp == 0, "the command is not one ramp down and up: %d turns, %d odd steps", turns,
               off_ramp);
    ENSURE_MSG(worst_m < 1e-16, "measured height vs the actuator model: %g m beyond the bound", worst_m);
    ENSURE_MSG(fabs(hm[col.n - 1] - hc[col.n - 1]) > 1e-9, "the actuator made no difference (%g m)",
               hm[col.n - 1] - hc[col.n - 1]);
}

/* The z sensor: a first-order low-pass (a step settles as 1 − e^{−2π f t}) plus white noise of the given sd
 * (N = 20000 readings of a still piezo: relative sd of the sd √(1/(2N)) = 0.5%; 4 sigma). */
static void test_zsensor(void)
{
    vafm_params p = t_base();
    p.zsensor_bandwidth_Hz = 50.0;
    vafm_detector d;
    vafm_detector_begin(&d, &p, 0);
    ENSURE(vafm_detector_height(&d, 0.0, 0.0) == 0.0);
    double worst = 0.0;
    for (int i = 1; i <= 100; i++) {
        double t = i * 1e-3, y = vafm_detector_height(&d, t, 1e-6);
        worst = fmax(worst, fabs(y - 1e-6 * (1.0 - exp(-2.0 * M_PI * 50.0 * t))));
    }
    ENSURE_MSG(worst < 1e-18, "z sensor step response off by %g m", worst);
    p.zsensor_bandwidth_Hz = 0;
    p.zsensor_noise_m = 0.3e-9;
    vafm_detector_begin(&d, &p, 0);
    double s1 = 0, s2 = 0;
    enum { N = 20000 };
    for (int i = 0; i < N; i++) {
        double y = vafm_detector_height(&d, i * 1e-3, 5e-7) - 5e-7;
        s1 += y;
        s2 += y * y;
    }
    double sd = sqrt(s2 / N - (s1 / N) * (s1 / N));
    ENSURE_MSG(fabs(sd / 0.3e-9 - 1.0) < 4.0 * sqrt(0.5 / N), "z sensor noise sd %g m", sd);
}

/* vafm_detector_apply, the public function, bit for bit against its contract (detector.h). Off (every
 * setting at its default): volts = deflection / sensitivity, deflection and force left as they were.
 * On, offset only: volts = deflection / sensitivity + offset, deflection = volts·sensitivity, force =
 * k·deflection. On with white noise and a 12-bit ADC: the noise is the detector's own stream (Philox stream
 * `index` of seed ^ VAFM_DETECTOR_KEY), the code floor(v/q + 0.5) clipped to ±2^11, and a sample beyond the
 * range saturates and sets `clipped`. Deflections span ±50 nm over 101 samples
 * (contact-silica: 60 nm/V, so ±0.83 V; with the offset the top few clip). */
static void test_detector_apply_contract(void)
{
    vafm_params p = t_base();
    ENSURE(vafm_detector_on(&p) == 0);
    const double sens = p.sensitivity_m_per_V, k = p.k_N_per_m;
    vafm_detector d;
    vafm_detector_begin(&d, &p, 3);
    ENSURE(d.on == 0);
    int bad = 0;
    for (int i = 0; i <= 100; i++) {
        const double x = (i - 50) * 1e-9, t = i * 1e-3;
        double v = NAN, defl = -7.0, f = -9.0;
        vafm_detector_apply(&d, t, 1e-7, x, &v, &defl, &f);
        bad += !(v == x / sens) || defl != -7.0 || f != -9.0;
        vafm_detector_apply(&d, t, 1e-7, x, NULL, NULL, NULL); /* NULL outputs are allowed */
    }
    ENSURE_MSG(bad == 0, "off: %d samples differ from volts = deflection / sensitivity, outputs untouched", bad);

    p.baseline_offset_V = 0.25;
    ENSURE(vafm_detector_on(&p) == 1);
    vafm_detector_begin(&d, &p, 3);
    bad = 0;
    for (int i = 0; i <= 100; i++) {
        const double x = (i - 50) * 1e-9;
        double v = NAN, defl = NAN, f = NAN;
        vafm_detector_apply(&d, i * 1e-3, 1e-7, x, &v, &defl, &f);
        const double ve = x / sens + 0.25;
        bad += !(v == ve) || !(defl == ve * sens) || !(f == k * (ve * sens));
    }
    ENSURE_MSG(bad == 0, "offset: %d samples differ", bad);

    p.noise_V_rms = 0.01;
    p.adc_bits = 12;
    p.adc_range_V = 2.0;
    p.seed = 12345;
    vafm_detector_begin(&d, &p, 3);
    vafm_rng r;
    vafm_rng_init(&r, p.seed ^ VAFM_DETECTOR_KEY, 3);
    const double q = 2.0 / 4096.0;
    bad = 0;
    int clipped = 0;
    for (int i = 0; i <= 100; i++) {
        const double x = (i - 50) * 1e-9;
        double v = NAN, defl = NAN, f = NAN;
        vafm_detector_apply(&d, i * 1e-3, 1e-7, x, &v, &defl, &f);
        double code = floor((x / sens + 0.25 + 0.01 * vafm_rng_normal(&r)) / q + 0.5);
        if (code > 2047.0 || code < -2048.0) {
            code = code > 0 ? 2047.0 : -2048.0;
            clipped = 1;
        }
        const double ve = code * q;
        bad += !(v == ve) || !(defl == ve * sens) || !(f == k * (ve * sens));
    }
    ENSURE_MSG(bad == 0, "noise and ADC: %d samples differ", bad);
    ENSURE_MSG(clipped == 1 && d.clipped == 1, "clipped: expected %d, detector %d", clipped, d.clipped);
}

int main(void)
{
    RUN_TEST(test_detector_apply_contract);
    RUN_TEST(test_piezo_hysteresis);
    RUN_TEST(test_piezo_creep);
    RUN_TEST(test_piezo_in_curve);
    RUN_TEST(test_zsensor);
    RUN_TEST(test_deterministic_terms);
    RUN_TEST(test_own_streams);
    RUN_TEST(test_random_walk);
    RUN_TEST(test_flicker_spectrum);
    RUN_TEST(test_contact_point);
    RUN_TEST(test_sample_drift);
    return harness_done();
}
