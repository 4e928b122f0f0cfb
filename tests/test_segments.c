/* SPDX-License-Identifier: MIT */
/*
 * Segment lists (vafm/segments.h):
 *  1. today's curve as a list (vafm_segments_from_params) gives vafm_sim_curve's curve bit for bit, every
 *     channel and the result, over presets and protocol variants (dwell at height and force, relative
 *     setpoint, height trigger, fixed ramps, piezo hysteresis, drift, a trigger that never fires);
 *  2. validation: each refusal names the segment and the field;
 *  3. a height trigger fires at its height within one sample's travel;
 *  4. a constant-force pause holds its force, with the thermal spread equipartition predicts;
 *  5. a modulation's amplitude and frequency recovered by a least-squares fit of the height channel;
 *  6. a segment at a lower rate is the block mean of the same run at the scene's rate (decimation);
 *  7. a 4-segment list labels every sample with its segment, in order.
 */
#include "harness.h"

#include <stdint.h>

#include "vafm/params.h"
#include "vafm/segments.h"
#include "vafm/sim.h"
#include "trace.h"

#define S_KB 1.380649e-23

/* ---- 1. today's curve as a list, bit for bit ----------------------------------------------------------- */

static void t_bitwise_one(const char *name, const vafm_params *p, int trigger_off)
{
    vafm_sim *s = NULL;
    vafm_error err = { 0 };
    int rc = vafm_sim_new(&s, p, &err);
    ENSURE_MSG(rc == 0, "%s: %s", name, err.message);
    if (rc)
        return;
    vafm_sim_set_trigger(s, !trigger_off);
    vafm_segment_spec segs[VAFM_SEGMENTS_MAX];
    int n = vafm_segments_from_params(p, segs, VAFM_SEGMENTS_MAX);
    ENSURE(n == (p->dwell_s > 0 ? 3 : 2));
    for (uint64_t idx = 0; idx < 3; idx++) {
        t_trace a = { 0 }, b = { 0 };
        vafm_curve_result ra, rb;
        int r1 = vafm_sim_curve(s, idx, t_collect, &a, &ra);
        int r2 = vafm_sim_segments(s, idx, segs, (size_t)n, t_collect, &b, &rb);
        ENSURE_MSG(r1 == 0 && r2 == 0, "%s: curve %d, list %d (%s)", name, r1, r2,
                   vafm_sim_error(s) ? vafm_sim_error(s)->message : "");
        ENSURE_MSG(a.n > 10 && t_trace_same(&a, &b), "%s index %llu: %zu vs %zu samples differ", name, (unsigned long long)idx,
                   a.n, b.n);
        ENSURE_MSG(!memcmp(&ra, &rb, sizeof ra), "%s index %llu: results differ (pull-off %.17g vs %.17g, flags %d vs %d)",
                   name, (unsigned long long)idx, ra.pulloff_sampled_N, rb.pulloff_sampled_N, ra.flags, rb.flags);
        t_trace_free(&a);
        t_trace_free(&b);
    }
    vafm_sim_destroy(&s);
}

static void t_preset(vafm_params *p, const char *name)
{
    vafm_params_default(p);
    ENSURE(vafm_preset_apply(p, name, NULL) == 0);
}

static void test_default_list_is_the_curve(void)
{
    vafm_params p;
    const char *presets[] = { "paper-fig1", "contact-silica", "cell-liquid", "colloid-pdms", "stiff-polymer" };
    for (size_t i = 0; i < sizeof presets / sizeof *presets; i++) {
        t_preset(&p, presets[i]);
        t_bitwise_one(presets[i], &p, 0);
    }
    t_preset(&p, "contact-silica");
    p.dwell_s = 2e-3;
    t_bitwise_one("dwell height", &p, 0);
    p.dwell_mode = VAFM_DWELL_FORCE;
    t_bitwise_one("dwell force", &p, 0);
    p.dwell_feedback_s = 1e-3;
    t_bitwise_one("dwell force tau", &p, 0);
    t_preset(&p, "contact-silica");
    p.setpoint_mode = VAFM_SETPOINT_RELATIVE;
    t_bitwise_one("relative setpoint", &p, 0);
    t_preset(&p, "contact-silica");
    p.trigger = VAFM_TRIGGER_HEIGHT;
    p.trigger_height_m = -3e-9;
    t_bitwise_one("height trigger", &p, 0);
    t_preset(&p, "contact-silica");
    p.ramp_size_m = 100e-9;
    t_bitwise_one("fixed ramp", &p, 0);
    p.ramp_start = VAFM_RAMP_START_TRIGGER;
    t_bitwise_one("fixed ramp from trigger", &p, 0);
    t_preset(&p, "contact-silica");
    p.piezo_hysteresis = 0.1;
    p.piezo_hysteresis_length_m = 20e-9;
    p.piezo_creep = 0.01;
    p.piezo_creep_t0_s = 1e-3;
    t_bitwise_one("piezo", &p, 0);
    t_preset(&p, "contact-silica");
    p.sample_drift_m_per_s = 1e-8;
    p.contact_point_sd_m = 2e-9;
    t_bitwise_one("drift", &p, 0);
    t_preset(&p, "contact-silica");
    p.z_range_m = 150e-9;
    t_bitwise_one("no trigger", &p, 1);
    t_preset(&p, "contact-silica");
    p.antialias = VAFM_ANTIALIAS_POINT;
    t_bitwise_one("point", &p, 0);
}

/* ---- 2. validation ------------------------------------------------------------------------------------- */

static void t_refuse(const vafm_segment_spec *g, size_t n, const vafm_params *p, const char *field)
{
    vafm_error err = { 0 };
    int rc = vafm_segments_validate(g, n, p, &err);
    ENSURE_MSG(rc == VAFM_EINVAL && !strcmp(err.field, field), "want %s refused, got rc %d field '%s' (%s)", field, rc,
               err.field, err.message);
}

static void test_validation(void)
{
    vafm_params p;
    t_preset(&p, "contact-silica");
    vafm_segment_spec g[3];
    for (int i = 0; i < 3; i++)
        vafm_segment_spec_default(&g[i]);
    g[0].distance_m = 100e-9;
    g[1].kind = VAFM_SEGMENT_PAUSE;
    g[1].duration_s = 1e-3;
    g[2].kind = VAFM_SEGMENT_RETRACT;
    g[2].distance_m = 100e-9;
    vafm_error err = { 0 };
    ENSURE_MSG(vafm_segments_validate(g, 3, &p, &err) == 0, "%s", err.message);
    t_refuse(g, 0, &p, "segments");
    g[2].speed_m_per_s = -1;
    t_refuse(g, 3, &p, "segments[2].speed_m_per_s");
    g[2].speed_m_per_s = 1e-6;
    g[2].distance_m = 0;
    t_refuse(g, 3, &p, "segments[2].distance_m");
    g[2].end = VAFM_SEGMENT_END_DETACH;
    ENSURE(vafm_segments_validate(g, 3, &p, NULL) == 0);
    g[0].end = VAFM_SEGMENT_END_DETACH;
    t_refuse(g, 3, &p, "segments[0].end");
    g[0].end = VAFM_SEGMENT_END_TRAVEL;
    g[1].duration_s = -1;
    t_refuse(g, 3, &p, "segments[1].duration_s");
    g[1].duration_s = 1e-3;
    g[1].pause_mode = VAFM_PAUSE_FORCE;
    g[1].feedback_s = 1e-5; /* below 2 samples at 10 kHz */
    t_refuse(g, 3, &p, "segments[1].feedback_s");
    g[1].feedback_s = 0;
    g[1].trigger = VAFM_SEGMENT_TRIGGER_TIME;
    g[1].trigger_op = VAFM_SEGMENT_BELOW;
    g[1].trigger_value = 1e-3;
    t_refuse(g, 3, &p, "segments[1].trigger_op");
    g[1].trigger = VAFM_SEGMENT_TRIGGER_HEIGHT;
    g[1].trigger_relative = 1;
    t_refuse(g, 3, &p, "segments[1].trigger_relative");
    g[1].trigger = VAFM_SEGMENT_TRIGGER_NONE;
    g[1].trigger_relative = 0;
    g[0].sample_rate_Hz = 3000; /* 10 kHz / 3.33 */
    t_refuse(g, 3, &p, "segments[0].sample_rate_Hz");
    g[0].sample_rate_Hz = 2500;
    ENSURE(vafm_segments_validate(g, 3, &p, NULL) == 0);
    g[1].kind = VAFM_SEGMENT_MODULATE;
    g[1].frequency_Hz = 4000; /* above rate/4 */
    t_refuse(g, 3, &p, "segments[1].frequency_Hz");
    g[1].kind = 7;
    t_refuse(g, 3, &p, "segments[1].kind");
    g[1].kind = VAFM_SEGMENT_PAUSE;
    g[1].label = 255;
    t_refuse(g, 3, &p, "segments[1].label");
    /* the simulation refuses the list too, naming the segment */
    g[1].label = -1;
    g[2].speed_m_per_s = 0;
    vafm_sim *s = NULL;
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    ENSURE(vafm_sim_segments_begin(s, 0, g, 3) == VAFM_EINVAL);
    ENSURE(vafm_sim_error(s) && !strcmp(vafm_sim_error(s)->field, "segments[2].speed_m_per_s"));
    vafm_sim_destroy(&s);
}

/* ---- 3. a height trigger fires at its height within one sample's travel ------------------------------- */

/* A list is costed as a scene's curve is (VAFM_SIM_MAX_SAMPLES at the scene's rate): a crawl, a long pause or
 * 64 long ones are refused before they run for hours, naming the segment that takes longest. */
static void test_cost_bound(void)
{
    vafm_params p;
    t_preset(&p, "contact-silica");
    const double t_max = (double)VAFM_SIM_MAX_SAMPLES / p.sample_rate_Hz; /* simulated seconds a list may take */
    vafm_segment_spec g[VAFM_SEGMENTS_MAX];
    for (int i = 0; i < VAFM_SEGMENTS_MAX; i++)
        vafm_segment_spec_default(&g[i]);
    /* an extend of 1 mm at 1e-12 m/s: 1e9 s */
    g[0].distance_m = 1e-3;
    g[0].speed_m_per_s = 1e-12;
    t_refuse(g, 1, &p, "segments[0].speed_m_per_s");
    g[0].speed_m_per_s = 1e-3 / (0.9 * t_max); /* just inside */
    vafm_error err = { 0 };
    ENSURE_MSG(vafm_segments_validate(g, 1, &p, &err) == 0, "%s", err.message);
    g[0].speed_m_per_s = 1e-3 / (1.1 * t_max); /* just outside */
    t_refuse(g, 1, &p, "segments[0].speed_m_per_s");
    g[0].trigger = VAFM_SEGMENT_TRIGGER_TIME; /* a time trigger cuts it short */
    g[0].trigger_value = 1.0;
    ENSURE_MSG(vafm_segments_validate(g, 1, &p, &err) == 0, "%s", err.message);
    /* 64 pauses, each allowed alone (1e4 s each is the field's range), but together far too long */
    vafm_segment_spec_default(&g[0]);
    g[0].distance_m = 100e-9;
    for (int i = 1; i < VAFM_SEGMENTS_MAX; i++) {
        g[i].kind = VAFM_SEGMENT_PAUSE;
        g[i].duration_s = 0.5 * t_max / (VAFM_SEGMENTS_MAX - 1);
    }
    ENSURE_MSG(vafm_segments_validate(g, VAFM_SEGMENTS_MAX, &p, &err) == 0, "%s", err.message);
    g[7].duration_s = 1e4;
    t_refuse(g, VAFM_SEGMENTS_MAX, &p, "segments[7].duration_s");
    g[7].kind = VAFM_SEGMENT_MODULATE;
    t_refuse(g, VAFM_SEGMENTS_MAX, &p, "segments[7].duration_s");
}

static void test_height_trigger(void)
{
    vafm_params p;
    t_preset(&p, "contact-silica");
    p.antialias = VAFM_ANTIALIAS_POINT; /* a sample's height is the command at its end */
    vafm_segment_spec g[2];
    vafm_segment_spec_default(&g[0]);
    vafm_segment_spec_default(&g[1]);
    const double h_t = 37.3e-9, v = 1e-6;
    g[0].speed_m_per_s = v;
    g[0].trigger = VAFM_SEGMENT_TRIGGER_HEIGHT;
    g[0].trigger_op = VAFM_SEGMENT_BELOW;
    g[0].trigger_value = h_t;
    g[0].distance_m = 500e-9;
    g[1].kind = VAFM_SEGMENT_RETRACT;
    g[1].speed_m_per_s = v;
    g[1].trigger = VAFM_SEGMENT_TRIGGER_HEIGHT;
    g[1].trigger_op = VAFM_SEGMENT_ABOVE;
    g[1].trigger_value = 81.1e-9;
    g[1].distance_m = 500e-9;
    vafm_sim *s = NULL;
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    t_trace c = { 0 };
    vafm_curve_result r;
    ENSURE(vafm_sim_segments(s, 0, g, 2, t_collect, &c, &r) == 0);
    const double step = v / p.sample_rate_Hz;
    size_t last0 = 0;
    for (size_t i = 0; i < c.n; i++)
        if (c.seg[i] == 0)
            last0 = i;
    ENSURE_MSG(c.h[last0] <= h_t && c.h[last0] > h_t - step * (1 + 1e-9), "extend ended at %.6g m (trigger %.6g m, step %.3g m)",
               c.h[last0], h_t, step);
    ENSURE_MSG(last0 > 0 && c.h[last0 - 1] > h_t, "the trigger fired late: the sample before is at %.6g m", c.h[last0 - 1]);
    const double h_end = c.h[c.n - 1];
    ENSURE_MSG(h_end >= 81.1e-9 && h_end < 81.1e-9 + step * (1 + 1e-9), "retract ended at %.6g m", h_end);
    ENSURE(!(r.flags & VAFM_CURVE_NO_TRIGGER));
    t_trace_free(&c);
    vafm_sim_destroy(&s);
}

/* ---- 4. a constant-force pause holds its force with the thermal spread ---------------------------------- */

static void test_force_pause(void)
{
    /* Hertz on the contact-silica lever (no adhesion, closed-form contact stiffness), end-point samples. In
     * contact at force F the tip's thermal variance is kT/(k + K_c), K_c = 2E*√(Rδ), F = (4/3)E*√R δ^{3/2};
     * the lever's force is k·(support − tip): sd_F = k·√(kT/(k + K_c)). The integral loop (τ = 10 samples =
     * 1 ms) is slow against the lever's correlation time (~0.1 ms in contact) and does not change it.
     * N: 1 s of pause = 10 000 samples; the mean's standard error from 50 block means; checks at 5σ. */
    vafm_params p;
    t_preset(&p, "contact-silica");
    p.antialias = VAFM_ANTIALIAS_POINT;
    vafm_error err = { 0 };
    ENSURE(vafm_params_set(&p, "contact", "hertz", &err) == 0);
    p.gamma_J_per_m2 = 0;
    const double F_hold = 2e-9;
    vafm_segment_spec g[3];
    for (int i = 0; i < 3; i++)
        vafm_segment_spec_default(&g[i]);
    g[0].speed_m_per_s = p.v_approach_m_per_s;
    g[0].trigger = VAFM_SEGMENT_TRIGGER_FORCE;
    g[0].trigger_value = 1e-9;
    g[1].kind = VAFM_SEGMENT_PAUSE;
    g[1].pause_mode = VAFM_PAUSE_FORCE;
    g[1].hold_force_N = F_hold;
    g[1].duration_s = 1.05;
    g[2].kind = VAFM_SEGMENT_RETRACT;
    g[2].speed_m_per_s = p.v_retract_m_per_s;
    g[2].distance_m = 100e-9;
    vafm_sim *s = NULL;
    ENSURE_MSG(vafm_sim_new(&s, &p, &err) == 0, "%s", err.message);
    t_trace c = { 0 };
    ENSURE(vafm_sim_segments(s, 3, g, 3, t_collect, &c, NULL) == 0);
    /* the pause's samples after 50 ms of settling (50 τ) */
    size_t i0 = 0, np = 0;
    for (size_t i = 0; i < c.n; i++)
        if (c.seg[i] == 1) {
            if (!np)
                i0 = i;
            np++;
        }
    ENSURE(np == (size_t)lround(1.05 * p.sample_rate_Hz));
    const size_t skip = (size_t)(0.05 * p.sample_rate_Hz), n = np - skip, per = n / 50;
    double sum = 0, sum2 = 0, bm[50];
    for (int b = 0; b < 50; b++) {
        double bs = 0;
        for (size_t k = 0; k < per; k++) {
            double f = c.f[i0 + skip + b * per + k];
            bs += f;
            sum += f;
            sum2 += f * f;
        }
        bm[b] = bs / per;
    }
    const double N = 50.0 * per, mean = sum / N, sd = sqrt(sum2 / N - mean * mean);
    double sb = 0;
    for (int b = 0; b < 50; b++)
        sb += (bm[b] - mean) * (bm[b] - mean);
    const double se = sqrt(sb / 49.0) / sqrt(50.0);
    const double E = p.E_star_Pa, R = p.R_m, k = p.k_N_per_m, kT = S_KB * p.T_K;
    const double delta = pow(3.0 * F_hold / (4.0 * E * sqrt(R)), 2.0 / 3.0), Kc = 2.0 * E * sqrt(R * delta);
    const double sd_th = k * sqrt(kT / (k + Kc));
    fprintf(stderr, "     force pause: mean %.5g N (hold %.5g, se %.3g), sd %.4g N (theory %.4g), N = %.0f\n", mean, F_hold,
            se, sd, sd_th, N);
    ENSURE_ABS(mean, F_hold, 5.0 * se);
    /* the sd of a sample sd over N_eff ≈ N/7 (correlation ~7 samples): ~1%; 10% holds it with margin */
    ENSURE_REL(sd, sd_th, 0.10);
    t_trace_free(&c);
    vafm_sim_destroy(&s);
}

/* ---- 5. modulation: amplitude and frequency by a fit --------------------------------------------------- */

static void test_modulation_fit(void)
{
    vafm_params p;
    t_preset(&p, "contact-silica");
    p.antialias = VAFM_ANTIALIAS_POINT;
    const double A = 3e-9, fm = 170.0, dur = 0.05;
    vafm_segment_spec g[3];
    for (int i = 0; i < 3; i++)
        vafm_segment_spec_default(&g[i]);
    g[0].speed_m_per_s = p.v_approach_m_per_s;
    g[0].trigger = VAFM_SEGMENT_TRIGGER_FORCE;
    g[0].trigger_value = 2e-9;
    g[1].kind = VAFM_SEGMENT_MODULATE;
    g[1].amplitude_m = A;
    g[1].frequency_Hz = fm;
    g[1].duration_s = dur;
    g[2].kind = VAFM_SEGMENT_RETRACT;
    g[2].end = VAFM_SEGMENT_END_DETACH;
    g[2].speed_m_per_s = p.v_retract_m_per_s;
    vafm_sim *s = NULL;
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    t_trace c = { 0 };
    ENSURE(vafm_sim_segments(s, 1, g, 3, t_collect, &c, NULL) == 0);
    size_t i0 = 0, n = 0;
    for (size_t i = 0; i < c.n; i++)
        if (c.seg[i] == 1) {
            if (!n)
                i0 = i;
            n++;
        }
    ENSURE(n == (size_t)lround(dur * p.sample_rate_Hz));
    /* least squares of h = c0 + a sin(ωt) + b cos(ωt) at each trial frequency; the best fit's residual */
    const double t0 = c.t[i0] - 1.0 / p.sample_rate_Hz; /* the segment began one interval before its first sample */
    double best_f = 0, best_res = INFINITY, best_amp = 0;
    for (double f = 150.0; f <= 190.0; f += 0.01) {
        double S[3][3] = { { 0 } }, y[3] = { 0 };
        for (size_t i = 0; i < n; i++) {
            double x[3] = { 1.0, sin(2 * M_PI * f * (c.t[i0 + i] - t0)), cos(2 * M_PI * f * (c.t[i0 + i] - t0)) };
            for (int a = 0; a < 3; a++) {
                y[a] += x[a] * c.h[i0 + i];
                for (int b = 0; b < 3; b++)
                    S[a][b] += x[a] * x[b];
            }
        }
        /* Gauss elimination of the 3×3 normal equations */
        for (int a = 0; a < 3; a++)
            for (int r = a + 1; r < 3; r++) {
                double m = S[r][a] / S[a][a];
                for (int b = a; b < 3; b++)
                    S[r][b] -= m * S[a][b];
                y[r] -= m * y[a];
            }
        double q[3];
        for (int a = 2; a >= 0; a--) {
            double v = y[a];
            for (int b = a + 1; b < 3; b++)
                v -= S[a][b] * q[b];
            q[a] = v / S[a][a];
        }
        double res = 0;
        for (size_t i = 0; i < n; i++) {
            double tt = c.t[i0 + i] - t0;
            double e = c.h[i0 + i] - q[0] - q[1] * sin(2 * M_PI * f * tt) - q[2] * cos(2 * M_PI * f * tt);
            res += e * e;
        }
        if (res < best_res) {
            best_res = res;
            best_f = f;
            best_amp = hypot(q[1], q[2]);
        }
    }
    fprintf(stderr, "     modulation: fit %.3f Hz (set %.1f), amplitude %.5g m (set %.3g), rms residual %.3g m\n", best_f, fm,
            best_amp, A, sqrt(best_res / n));
    ENSURE_ABS(best_f, fm, 0.02);
    ENSURE_REL(best_amp, A, 1e-3);
    t_trace_free(&c);
    vafm_sim_destroy(&s);
}

/* ---- 6. decimation: a segment's lower rate is block means of the scene's rate --------------------------- */

static void test_decimation(void)
{
    vafm_params p;
    t_preset(&p, "contact-silica");
    vafm_segment_spec g[4];
    for (int i = 0; i < 4; i++)
        vafm_segment_spec_default(&g[i]);
    g[0].speed_m_per_s = p.v_approach_m_per_s;
    g[0].trigger = VAFM_SEGMENT_TRIGGER_FORCE;
    g[0].trigger_value = 3e-9;
    g[1].kind = VAFM_SEGMENT_PAUSE;
    g[1].duration_s = 0.0123; /* 123 samples: not a multiple of 4, the last output sample gathers 3 */
    g[2].kind = VAFM_SEGMENT_RETRACT;
    g[2].end = VAFM_SEGMENT_END_DETACH;
    g[2].speed_m_per_s = p.v_retract_m_per_s;
    vafm_sim *s = NULL;
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    t_trace full = { 0 }, dec = { 0 };
    ENSURE(vafm_sim_segments(s, 5, g, 3, t_collect, &full, NULL) == 0);
    g[1].sample_rate_Hz = p.sample_rate_Hz / 4;
    ENSURE(vafm_sim_segments(s, 5, g, 3, t_collect, &dec, NULL) == 0);
    size_t a0 = 0, na = 0, b0 = 0, nb = 0;
    for (size_t i = 0; i < full.n; i++)
        if (full.seg[i] == 1 && !na++)
            a0 = i;
    for (size_t i = 0; i < dec.n; i++)
        if (dec.seg[i] == 1 && !nb++)
            b0 = i;
    ENSURE(na == 123 && nb == 31 && a0 == b0 && full.n - na == dec.n - nb);
    int ok = 1;
    for (size_t j = 0; j < nb && ok; j++) {
        size_t m = j < 30 ? 4 : 3;
        double f = 0, t = 0;
        for (size_t k = 0; k < m; k++) {
            f += full.f[a0 + 4 * j + k];
            t += full.t[a0 + 4 * j + k];
        }
        ok = fabs(dec.f[b0 + j] - f / m) <= 1e-12 * fabs(f / m) + 1e-24 && fabs(dec.t[b0 + j] - t / m) <= 1e-12 * t / m;
    }
    ENSURE_MSG(ok, "the decimated pause is not the block mean of the full-rate one");
    /* the physics is untouched: the retract after it is the same bit for bit */
    ENSURE(!memcmp(full.f + a0 + na, dec.f + b0 + nb, (full.n - a0 - na) * sizeof(double)));
    t_trace_free(&full);
    t_trace_free(&dec);
    vafm_sim_destroy(&s);
}

/* The run's clock (vafm_sim_clock_samples) as each output sample is handed over. */
typedef struct t_clock {
    const vafm_sim *s;
    uint64_t *at; /* at[i]: the clock when sample i arrived (the end of the block it came in) */
    size_t n, cap;
} t_clock;

static int t_clock_fn(void *user, const vafm_samples *b)
{
    t_clock *c = user;
    for (size_t i = 0; i < b->n && c->n < c->cap; i++)
        c->at[c->n++] = i + 1 == b->n ? vafm_sim_clock_samples(c->s) : 0;
    return 0;
}

/* 6b. the clock counts the scene's samples, whatever the segment's output rate: a list with a pause at
 * the scene's rate / 4 ends at the clock of the same list at full rate, and each output sample (advanced
 * one scene sample a call) ends at the scene samples it gathered: 1 a sample outside the pause, 4 in it
 * (its last: 3). Counting output samples instead (the old pacing) gives 92 fewer at the end. */
static void test_decimation_clock(void)
{
    vafm_params p;
    t_preset(&p, "contact-silica");
    vafm_segment_spec g[3];
    for (int i = 0; i < 3; i++)
        vafm_segment_spec_default(&g[i]);
    g[0].speed_m_per_s = p.v_approach_m_per_s;
    g[0].trigger = VAFM_SEGMENT_TRIGGER_FORCE;
    g[0].trigger_value = 3e-9;
    g[1].kind = VAFM_SEGMENT_PAUSE;
    g[1].duration_s = 0.0123; /* 123 samples of the scene's rate: 31 at rate / 4 */
    g[2].kind = VAFM_SEGMENT_RETRACT;
    g[2].end = VAFM_SEGMENT_END_DETACH;
    g[2].speed_m_per_s = p.v_retract_m_per_s;
    vafm_sim *s = NULL;
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    ENSURE(vafm_sim_clock_samples(s) == 0 && vafm_sim_clock_samples(NULL) == 0);
    t_trace full = { 0 };
    ENSURE(vafm_sim_segments(s, 5, g, 3, t_collect, &full, NULL) == 0);
    ENSURE_MSG(vafm_sim_clock_samples(s) == full.n, "full rate: clock %llu, %zu samples",
               (unsigned long long)vafm_sim_clock_samples(s), full.n);
    g[1].sample_rate_Hz = p.sample_rate_Hz / 4;
    t_clock c = { s, calloc(full.n, sizeof(uint64_t)), 0, full.n };
    ENSURE(c.at != NULL && vafm_sim_segments_begin(s, 5, g, 3) == 0);
    int rc = 1;
    while (c.at && rc == 1)
        rc = vafm_sim_advance(s, 1, t_clock_fn, &c);
    ENSURE(rc == 0 && c.n == full.n - 92);
    ENSURE_MSG(vafm_sim_clock_samples(s) == full.n, "decimated: clock %llu, %zu samples at full rate",
               (unsigned long long)vafm_sim_clock_samples(s), full.n);
    size_t a0 = 0;
    while (a0 < full.n && full.seg[a0] != 1)
        a0++;
    int ok = c.at != NULL;
    for (size_t j = 0; j < c.n && ok; j++) {
        uint64_t want = j < a0 ? j + 1 : j < a0 + 31 ? a0 + (j - a0 + 1 < 31 ? 4 * (j - a0 + 1) : 123) : j + 93;
        ok = c.at[j] == want;
        if (!ok)
            ENSURE_MSG(0, "sample %zu: clock %llu, want %llu", j, (unsigned long long)c.at[j], (unsigned long long)want);
    }
    free(c.at);
    t_trace_free(&full);
    vafm_sim_destroy(&s);
}

/* ---- 7. a 4-segment list: every sample labelled with its segment, in order ------------------------------ */

static void test_four_segments(void)
{
    vafm_params p;
    t_preset(&p, "contact-silica");
    vafm_segment_spec g[4];
    for (int i = 0; i < 4; i++)
        vafm_segment_spec_default(&g[i]);
    g[0].kind = VAFM_SEGMENT_PAUSE; /* a baseline at constant height */
    g[0].duration_s = 5e-3;
    g[1].speed_m_per_s = p.v_approach_m_per_s;
    g[1].trigger = VAFM_SEGMENT_TRIGGER_FORCE;
    g[1].trigger_value = 2e-9;
    g[2].kind = VAFM_SEGMENT_PAUSE;
    g[2].duration_s = 10e-3;
    g[3].kind = VAFM_SEGMENT_RETRACT;
    g[3].end = VAFM_SEGMENT_END_DETACH;
    g[3].speed_m_per_s = p.v_retract_m_per_s;
    vafm_sim *s = NULL;
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    t_trace c = { 0 };
    vafm_curve_result r;
    ENSURE(vafm_sim_segments(s, 2, g, 4, t_collect, &c, &r) == 0);
    size_t cnt[4] = { 0 };
    int ordered = 1;
    for (size_t i = 0; i < c.n; i++) {
        ENSURE(c.seg[i] < 4);
        if (c.seg[i] < 4)
            cnt[c.seg[i]]++;
        if (i && c.seg[i] < c.seg[i - 1])
            ordered = 0;
    }
    ENSURE(ordered);
    ENSURE(cnt[0] == 50 && cnt[1] > 0 && cnt[2] == 100 && cnt[3] > 0);
    ENSURE(isfinite(r.pulloff_sampled_N) && r.pulloff_sampled_N > 0); /* JKR: a pull-off on the retract segment */
    ENSURE(vafm_sim_segment_current(s) == -1);
    t_trace_free(&c);
    vafm_sim_destroy(&s);
}

int main(void)
{
    RUN_TEST(test_default_list_is_the_curve);
    RUN_TEST(test_validation);
    RUN_TEST(test_cost_bound);
    RUN_TEST(test_height_trigger);
    RUN_TEST(test_force_pause);
    RUN_TEST(test_modulation_fit);
    RUN_TEST(test_decimation);
    RUN_TEST(test_decimation_clock);
    RUN_TEST(test_four_segments);
    return harness_done();
}
