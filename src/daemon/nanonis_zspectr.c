/* SPDX-License-Identifier: MIT */
/*
 * Nanonis ZSpectr: Z spectroscopy, a force curve on vafm's physics (nanonis_cmds.h; docs/nanonis.md).
 *
 * The properties (channels, points, sweeps, range, timing, auto-retract) are module state shared by all
 * connections. ZSpectr.Start turns them into one `curve` of the scene per sweep (the scene's values set for
 * the sweep and restored after it), collects the run's samples from the stream (nanonis.c's collector) and
 * averages each point over its integration time after its settling time; forward and backward sweeps are
 * the curve's approach and retract. ZSpectr.Stop aborts the run in progress.
 */
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "daemon/nanonis_cmds.h"

/* ---- ZSpectr: properties -------------------------------------------------------------------------- */

static int h_zs_status(nnc_ctx *x)
{
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    nn_put_u32(x->o, (uint32_t)nnc_m.running);
    pthread_mutex_unlock(&nnc_mu);
    return NNC_OK;
}

static int h_zs_chs_set(nnc_ctx *x)
{
    int32_t n = nn_get_i32(&x->r, "Number of channels");
    if (!x->r.bad && (n < 0 || n > NNC_MAX_CHS)) {
        snprintf(x->err, sizeof x->err, "Number of channels %d: must be in [0, %d]", (int)n, NNC_MAX_CHS);
        return NNC_FAIL;
    }
    int32_t idx[NNC_MAX_CHS];
    for (int32_t k = 0; k < n && !x->r.bad; k++)
        idx[k] = nn_get_i32(&x->r, "Channel indexes");
    if (nnc_args_done(x))
        return NNC_FAIL;
    for (int32_t k = 0; k < n; k++)
        if (nnc_signal_index(x, idx[k], "Channel indexes: index"))
            return NNC_FAIL;
        else if (nnc_signals[idx[k]].src == SRC_CTRL) {
            snprintf(x->err, sizeof x->err, "Channel indexes: index %d (%s): a controller signal, not recorded "
                     "by a sweep (the controller is held during runs)", (int)idx[k], nnc_signals[idx[k]].name);
            return NNC_FAIL;
        }
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    for (int32_t k = 0; k < n; k++)
        nnc_m.chs[k] = idx[k];
    nnc_m.n_chs = n;
    pthread_mutex_unlock(&nnc_mu);
    return NNC_OK;
}

static int h_zs_chs_get(nnc_ctx *x)
{
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    const char *names[NNC_MAX_CHS];
    pthread_mutex_lock(&nnc_mu);
    int n = nnc_m.n_chs;
    nn_put_i32(x->o, n);
    for (int k = 0; k < n; k++) {
        nn_put_i32(x->o, nnc_m.chs[k]);
        names[k] = nnc_signals[nnc_m.chs[k]].name;
    }
    pthread_mutex_unlock(&nnc_mu);
    nn_put_i32(x->o, (int32_t)nn_strings_bytes(names, (size_t)n));
    nn_put_strings(x->o, names, (size_t)n);
    return NNC_OK;
}

static int h_zs_props_set(nnc_ctx *x)
{
    unsigned bwd = nn_get_u16(&x->r, "Backward sweep");
    int32_t pts = nn_get_i32(&x->r, "Number of points");
    unsigned sw = nn_get_u16(&x->r, "Number of sweeps");
    unsigned as = nn_get_u16(&x->r, "Autosave");
    unsigned sd = nn_get_u16(&x->r, "Show save dialog");
    unsigned sa = nn_get_u16(&x->r, "Save all");
    if (nnc_args_done(x))
        return NNC_FAIL;
    if (pts < 0 || pts > NNC_MAX_POINTS) {
        snprintf(x->err, sizeof x->err, "Number of points %d: must be in [1, %d] (0: no change)", (int)pts,
                 NNC_MAX_POINTS);
        return NNC_FAIL;
    }
    if (sw > NNC_MAX_SWEEPS) {
        snprintf(x->err, sizeof x->err, "Number of sweeps %u: must be in [1, %d] (0: no change)", sw, NNC_MAX_SWEEPS);
        return NNC_FAIL;
    }
    int b = -1, a = -1, d = -1, s = -1;
    if (nnc_flag(x, bwd, "Backward sweep", &b) || nnc_flag(x, as, "Autosave", &a) ||
        nnc_flag(x, sd, "Show save dialog", &d) || nnc_flag(x, sa, "Save all", &s))
        return NNC_FAIL;
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    if (b >= 0)
        nnc_m.backward = b;
    if (pts)
        nnc_m.points = pts;
    if (sw)
        nnc_m.sweeps = (int)sw;
    if (a >= 0)
        nnc_m.autosave = a;
    if (d >= 0)
        nnc_m.show_dialog = d;
    if (s >= 0)
        nnc_m.save_all = s;
    pthread_mutex_unlock(&nnc_mu);
    return NNC_OK;
}

/* The parameters ZSpectr.Start returns, in this order: the fixed ones, then the others. */
static const char *const s_fixed_params[] = { "Z offset (m)", "Z sweep distance (m)" };
static const char *const s_params[] = { "Settling time (s)", "Integration time (s)", "Number of sweeps",
                                        "Run ID", "Curve index", "Auto-retract triggered" };
#define S_NFIXED 2
#define S_NPARAMS 6

static int h_zs_props_get(nnc_ctx *x)
{
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    nn_put_u16(x->o, (uint16_t)nnc_m.backward);
    nn_put_i32(x->o, nnc_m.points);
    nn_put_i32(x->o, (int32_t)nn_strings_bytes(s_params, S_NPARAMS));
    nn_put_i32(x->o, S_NPARAMS);
    nn_put_strings(x->o, s_params, S_NPARAMS);
    nn_put_i32(x->o, (int32_t)nn_strings_bytes(s_fixed_params, S_NFIXED));
    nn_put_i32(x->o, S_NFIXED);
    nn_put_strings(x->o, s_fixed_params, S_NFIXED);
    nn_put_u16(x->o, (uint16_t)nnc_m.sweeps);
    nn_put_u16(x->o, (uint16_t)nnc_m.autosave);
    nn_put_u16(x->o, (uint16_t)nnc_m.show_dialog);
    nn_put_u16(x->o, (uint16_t)nnc_m.save_all);
    pthread_mutex_unlock(&nnc_mu);
    return NNC_OK;
}

static int h_zs_adv_set(nnc_ctx *x)
{
    float t = nn_get_f32(&x->r, "Time between forward and backward sweep (s)");
    unsigned rf = nn_get_u16(&x->r, "Record final Z");
    unsigned lr = nn_get_u16(&x->r, "Lockin Run");
    unsigned rz = nn_get_u16(&x->r, "Reset Z");
    if (nnc_args_done(x) || nnc_time(x, t, "Time between forward and backward sweep (s)"))
        return NNC_FAIL;
    int a = -1, b = -1, c = -1;
    if (nnc_flag(x, rf, "Record final Z", &a) || nnc_flag(x, lr, "Lockin Run", &b) || nnc_flag(x, rz, "Reset Z", &c))
        return NNC_FAIL;
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    nnc_m.t_fwd_bwd_s = t;
    if (a >= 0)
        nnc_m.record_final_z = a;
    if (b >= 0)
        nnc_m.lockin_run = b;
    if (c >= 0)
        nnc_m.reset_z = c;
    pthread_mutex_unlock(&nnc_mu);
    return NNC_OK;
}

static int h_zs_adv_get(nnc_ctx *x)
{
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    nn_put_f32(x->o, nnc_m.t_fwd_bwd_s);
    nn_put_u16(x->o, (uint16_t)nnc_m.record_final_z);
    nn_put_u16(x->o, (uint16_t)nnc_m.lockin_run);
    nn_put_u16(x->o, (uint16_t)nnc_m.reset_z);
    pthread_mutex_unlock(&nnc_mu);
    return NNC_OK;
}

static int h_zs_range_set(nnc_ctx *x)
{
    float off = nn_get_f32(&x->r, "Z offset (m)");
    float dist = nn_get_f32(&x->r, "Z sweep distance (m)");
    if (nnc_args_done(x))
        return NNC_FAIL;
    if (!isfinite(off) || fabsf(off) > 1e-4f) {
        snprintf(x->err, sizeof x->err, "Z offset (m) %g: must be in [-1e-4, 1e-4] m", (double)off);
        return NNC_FAIL;
    }
    if (!isfinite(dist) || fabsf(dist) < 1e-12f || fabsf(dist) > 1e-4f) {
        snprintf(x->err, sizeof x->err, "Z sweep distance (m) %g: its magnitude must be in [1e-12, 1e-4] m",
                 (double)dist);
        return NNC_FAIL;
    }
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    nnc_m.z_offset_m = off;
    nnc_m.z_distance_m = dist;
    pthread_mutex_unlock(&nnc_mu);
    return NNC_OK;
}

static int h_zs_range_get(nnc_ctx *x)
{
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    nn_put_f32(x->o, nnc_m.z_offset_m);
    nn_put_f32(x->o, nnc_m.z_distance_m);
    pthread_mutex_unlock(&nnc_mu);
    return NNC_OK;
}

static const char *const s_timing_names[7] = { "Z averaging time (s)", "Initial settling time (s)",
                                                "Maximum slew rate (V/s)", "Settling time (s)",
                                                "Integration time (s)", "End settling time (s)",
                                                "Z control time (s)" };

static int h_zs_timing_set(nnc_ctx *x)
{
    float t[7];
    for (int i = 0; i < 7; i++)
        t[i] = nn_get_f32(&x->r, s_timing_names[i]);
    if (nnc_args_done(x))
        return NNC_FAIL;
    for (int i = 0; i < 7; i++) {
        if (i == 2) {
            if (!isfinite(t[i]) || t[i] <= 0)
                return nnc_fail(x, "%s: must be a positive number", s_timing_names[i]);
        } else if (nnc_time(x, t[i], s_timing_names[i]))
            return NNC_FAIL;
    }
    if (!(t[4] > 0))
        return nnc_fail(x, "%s: must be > 0 (each point's samples are averaged over it)", s_timing_names[4]);
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    nnc_m.t_zavg_s = t[0];
    nnc_m.t_init_settle_s = t[1];
    nnc_m.slew_V_per_s = t[2];
    nnc_m.t_settle_s = t[3];
    nnc_m.t_integr_s = t[4];
    nnc_m.t_end_settle_s = t[5];
    nnc_m.t_zctrl_s = t[6];
    pthread_mutex_unlock(&nnc_mu);
    return NNC_OK;
}

static int h_zs_timing_get(nnc_ctx *x)
{
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    float t[7] = { nnc_m.t_zavg_s,   nnc_m.t_init_settle_s, nnc_m.slew_V_per_s,  nnc_m.t_settle_s,
                   nnc_m.t_integr_s, nnc_m.t_end_settle_s,  nnc_m.t_zctrl_s };
    pthread_mutex_unlock(&nnc_mu);
    for (int i = 0; i < 7; i++)
        nn_put_f32(x->o, t[i]);
    return NNC_OK;
}

static int h_zs_rdelay_set(nnc_ctx *x)
{
    float t = nn_get_f32(&x->r, "Retract delay (s)");
    if (nnc_args_done(x) || nnc_time(x, t, "Retract delay (s)"))
        return NNC_FAIL;
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    nnc_m.retract_delay_s = t;
    pthread_mutex_unlock(&nnc_mu);
    return NNC_OK;
}

static int h_zs_rdelay_get(nnc_ctx *x)
{
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    nn_put_f32(x->o, nnc_m.retract_delay_s);
    pthread_mutex_unlock(&nnc_mu);
    return NNC_OK;
}

static int h_zs_retract_set(nnc_ctx *x)
{
    unsigned en = nn_get_u16(&x->r, "Enable");
    float thr = nn_get_f32(&x->r, "Threshold");
    int32_t sig = nn_get_i32(&x->r, "Signal index");
    unsigned cmp = nn_get_u16(&x->r, "Comparison");
    if (nnc_args_done(x))
        return NNC_FAIL;
    int e = -1;
    if (nnc_flag(x, en, "Enable", &e) || (sig != -1 && nnc_signal_index(x, sig, "Signal index")))
        return NNC_FAIL;
    if (cmp > 2) {
        snprintf(x->err, sizeof x->err, "Comparison %u: must be 0 (>), 1 (<) or 2 (no change)", cmp);
        return NNC_FAIL;
    }
    if (!isfinite(thr))
        return nnc_fail(x, "%s: must be a finite number", "Threshold");
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    if (e >= 0)
        nnc_m.ar_enable = e;
    nnc_m.ar_threshold = thr;
    if (sig != -1)
        nnc_m.ar_signal = sig;
    if (cmp != 2)
        nnc_m.ar_cmp = (int)cmp;
    pthread_mutex_unlock(&nnc_mu);
    return NNC_OK;
}

static int h_zs_retract_get(nnc_ctx *x)
{
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    nn_put_u16(x->o, (uint16_t)nnc_m.ar_enable);
    nn_put_f32(x->o, nnc_m.ar_threshold);
    nn_put_i32(x->o, nnc_m.ar_signal);
    nn_put_u16(x->o, (uint16_t)nnc_m.ar_cmp);
    pthread_mutex_unlock(&nnc_mu);
    return NNC_OK;
}

static int h_zs_retract2_set(nnc_ctx *x)
{
    int32_t cond = nn_get_i32(&x->r, "2nd condition");
    float thr = nn_get_f32(&x->r, "Threshold");
    int32_t sig = nn_get_i32(&x->r, "Signal index");
    unsigned cmp = nn_get_u16(&x->r, "Comparison");
    if (nnc_args_done(x))
        return NNC_FAIL;
    if (cond < 0 || cond > 4) {
        snprintf(x->err, sizeof x->err, "2nd condition %d: must be 0 (no change), 1 (-No-), 2 (OR), 3 (AND) or 4 "
                 "(THEN)", (int)cond);
        return NNC_FAIL;
    }
    if ((sig != -1 && nnc_signal_index(x, sig, "Signal index")))
        return NNC_FAIL;
    if (cmp > 2) {
        snprintf(x->err, sizeof x->err, "Comparison %u: must be 0 (>), 1 (<) or 2 (no change)", cmp);
        return NNC_FAIL;
    }
    if (!isfinite(thr))
        return nnc_fail(x, "%s: must be a finite number", "Threshold");
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    if (cond)
        nnc_m.ar2_cond = cond - 1; /* Set counts from "no change", Get from -No- */
    nnc_m.ar2_threshold = thr;
    if (sig != -1)
        nnc_m.ar2_signal = sig;
    if (cmp != 2)
        nnc_m.ar2_cmp = (int)cmp;
    pthread_mutex_unlock(&nnc_mu);
    return NNC_OK;
}

static int h_zs_retract2_get(nnc_ctx *x)
{
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&nnc_mu);
    nn_put_i32(x->o, nnc_m.ar2_cond);
    nn_put_f32(x->o, nnc_m.ar2_threshold);
    nn_put_i32(x->o, nnc_m.ar2_signal);
    nn_put_u16(x->o, (uint16_t)nnc_m.ar2_cmp);
    pthread_mutex_unlock(&nnc_mu);
    return NNC_OK;
}

/* ---- ZSpectr.Start: a force curve on vafm's physics ------------------------------------------------
 * The sweep is one `curve` of the scene with a fixed symmetric ramp: it starts Z offset above the scene's
 * start height, the forward sweep approaches by |Z sweep distance| in points · (settling + integration)
 * time, the retract delay (plus the time between forward and backward sweep) is the dwell, the backward
 * sweep returns at the same speed. The auto-retract condition is the curve's trigger. Each point is the mean
 * of the samples of its integration time, after its settling time (docs/nanonis.md). */

static const char *const s_saved_names[] = { "start_height_m", "ramp_size_m", "ramp_start", "ramp_rate_Hz",
                                             "extend_time_s", "retract_time_s", "segment_samples", "dwell_s",
                                             "v_approach_m_per_s", "v_retract_m_per_s",
                                             "trigger", "setpoint_N", "setpoint_V", "setpoint_mode",
                                             "trigger_height_m", "sample_rate_Hz", "k_N_per_m",
                                             "sensitivity_m_per_V", "speed", "free_run" };
#define S_NSAVED (sizeof s_saved_names / sizeof s_saved_names[0])

/* Mean of v over [a, b) (clipped to n), NaN if empty. */
static double s_mean(const double *v, int64_t a, int64_t b, size_t n)
{
    if (a < 0)
        a = 0;
    if (b > (int64_t)n)
        b = (int64_t)n;
    double sum = 0;
    int64_t k = 0;
    for (int64_t i = a; i < b; i++, k++)
        sum += v[i];
    return k ? sum / (double)k : NAN;
}

/* Put the scene back as it was before the sweep (saved, less the values only read). A failure sets *rc to
 * NNC_FAIL with the restore's message unless *rc already holds an error (its message is kept). @return the
 * restore's own result. */
static int s_restore(nnc_ctx *x, const json_t *saved, int *rc)
{
    json_t *back = json_deep_copy(saved);
    json_object_del(back, "speed");
    json_object_del(back, "free_run");
    json_object_del(back, "k_N_per_m");
    json_object_del(back, "sensitivity_m_per_V");
    char tmp[NNC_ERR];
    memcpy(tmp, x->err, sizeof tmp);
    int r = nnc_call(x, json_pack("{s:s,s:o}", "cmd", "set", "values", back), NULL);
    if (r && *rc == NNC_OK)
        *rc = NNC_FAIL; /* the error message of the restore stays in x->err */
    else
        memcpy(x->err, tmp, sizeof tmp);
    return r;
}

static int h_zs_start(nnc_ctx *x)
{
    uint32_t get_data = nn_get_u32(&x->r, "Get data");
    int32_t sl = nn_get_i32(&x->r, "Save base name string size");
    if (!x->r.bad && (sl < 0 || (size_t)sl > x->r.n - x->r.off)) {
        snprintf(x->err, sizeof x->err, "Save base name string size %d: the body holds %zu more bytes", (int)sl,
                 x->r.n - x->r.off);
        return NNC_FAIL;
    }
    if (nnc_args_done(x))
        return NNC_FAIL;
    pthread_mutex_lock(&nnc_mu);
    if (nnc_m.running) {
        pthread_mutex_unlock(&nnc_mu);
        return nnc_fail(x, "%s", "a Z spectroscopy is running already (ZSpectr.Stop ends it)");
    }
    __typeof__(nnc_m) p = nnc_m; /* this sweep's settings */
    nnc_m.running = 1;
    nnc_m.stop = 0;
    pthread_mutex_unlock(&nnc_mu);
    int rc = NNC_OK, applied = 0; /* applied: the sweep's values are set and not yet put back */
    json_t *saved = NULL, *vals = NULL;
    double *acc = NULL;
    const char **names = NULL;
    int n_rows = 1 + p.n_chs, n_dirs = p.backward ? 2 : 1, triggered = 0;
    uint64_t last_run = 0, first_index = p.curves;
    double tp = (double)p.t_settle_s + (double)p.t_integr_s;
    double dist = fabs((double)p.z_distance_m);
    /* the auto-retract condition as the curve's trigger */
    if (p.ar2_cond != 0) {
        rc = nnc_fail(x, "%s", "the auto-retract's 2nd condition is not supported (vafm's curve has one trigger): "
                             "set it to -No- (ZSpectr.Retract2ndSet 1)");
        goto out;
    }
    if (p.ar_enable) {
        int k = nnc_signals[p.ar_signal].kind;
        if (!((p.ar_cmp == 0 && (k == KIND_FORCE || k == KIND_DEFL_V || k == KIND_DEFL_M)) ||
              (p.ar_cmp == 1 && k == KIND_Z && nnc_signals[p.ar_signal].ch == NN_CH_HEIGHT))) {
            rc = nnc_fail(x, "auto-retract on '%s' with this comparison is not supported: vafm triggers on Force (N), "
                           "Deflection (V) or Deflection (m) > threshold, or Z (m) < threshold",
                        nnc_signals[p.ar_signal].name);
            goto out;
        }
    }
    int grc;
    saved = nnc_get(x, s_saved_names, S_NSAVED, &grc);
    if (!saved) {
        rc = grc;
        goto out;
    }
    double fs = nnc_num(saved, "sample_rate_Hz"), start = nnc_num(saved, "start_height_m") + (double)p.z_offset_m;
    {   /* the current Z: where the controller is engaged, its gap (the tip above the surface under it) */
        json_t *st = NULL;
        if ((rc = nnc_call(x, json_pack("{s:s}", "cmd", "status"), &st)))
            goto out;
        json_t *c = json_object_get(st, "ctrl");
        json_t *state = json_object_get(c, "state");
        double gap = nnc_num(c, "gap_m");
        if (json_is_string(state) && !strcmp(json_string_value(state), "engaged") && isfinite(gap))
            start = gap + (double)p.z_offset_m;
        json_decref(st);
    }
    double k_N = nnc_num(saved, "k_N_per_m"), sens = nnc_num(saved, "sensitivity_m_per_V");
    double speed = nnc_num(saved, "speed");
    int free_run = json_is_true(json_object_get(saved, "free_run"));
    /* samples per point: the scene's rate, at least 4 in each integration time */
    double kpt = fmax(round(tp * fs), ceil(4.0 * tp / (double)p.t_integr_s));
    double dwell = (double)p.retract_delay_s + (double)p.t_fwd_bwd_s;
    double total = kpt * p.points * 2 + dwell * kpt / tp + 16;
    if (!(total <= (double)VAFMD_NANONIS_MAX_RUN_SAMPLES) || kpt * p.points > 1e9) {
        snprintf(x->err, sizeof x->err, "this sweep would have ~%.3g samples (%d points of %.0f): at most %zu; use "
                 "fewer points, shorter settling and integration times, or a lower sample_rate_Hz",
                 total, p.points, kpt, VAFMD_NANONIS_MAX_RUN_SAMPLES);
        rc = NNC_FAIL;
        goto out;
    }
    int64_t K = (int64_t)kpt, Ks = (int64_t)llround(kpt * (double)p.t_settle_s / tp);
    vals = json_object();
    json_object_set_new(vals, "ramp_rate_Hz", json_real(0));
    json_object_set_new(vals, "segment_samples", json_integer(0));
    json_object_set_new(vals, "sample_rate_Hz", json_real(kpt / tp));
    json_object_set_new(vals, "start_height_m", json_real(start));
    json_object_set_new(vals, "ramp_size_m", json_real(dist));
    json_object_set_new(vals, "ramp_start", json_string("surface"));
    json_object_set_new(vals, "extend_time_s", json_real(tp * p.points));
    json_object_set_new(vals, "retract_time_s", json_real(tp * p.points));
    json_object_set_new(vals, "dwell_s", json_real(dwell));
    if (p.ar_enable && nnc_signals[p.ar_signal].kind != KIND_Z) {
        int k = nnc_signals[p.ar_signal].kind;
        double thr_N = k == KIND_FORCE ? p.ar_threshold : k == KIND_DEFL_M ? p.ar_threshold * k_N
                                                                           : p.ar_threshold * sens * k_N;
        json_object_set_new(vals, "trigger", json_string("force"));
        json_object_set_new(vals, "setpoint_mode", json_string("absolute"));
        json_object_set_new(vals, "setpoint_V", json_real(0));
        json_object_set_new(vals, "setpoint_N", json_real(thr_N));
    } else {
        json_object_set_new(vals, "trigger", json_string("height"));
        json_object_set_new(vals, "trigger_height_m",
                            json_real(p.ar_enable ? fmax((double)p.ar_threshold, start - dist) : start - dist));
    }
    size_t n_cols = (size_t)p.points;
    acc = calloc((size_t)n_rows * (size_t)n_dirs * n_cols, sizeof *acc);
    if (!acc) {
        rc = nnc_fail(x, "%s", "out of memory");
        goto out;
    }
    /* each sweep: the sweep's values, its curve (which keeps the scene it started with), the scene put back
     * at once: JSON clients see the scene unchanged while the curve runs, and their own `set`s survive */
    for (int sw = 0; sw < p.sweeps && rc == NNC_OK; sw++) {
        pthread_mutex_lock(&nnc_mu);
        int stop = nnc_m.stop;
        unsigned long long index = nnc_m.curves++;
        pthread_mutex_unlock(&nnc_mu);
        if (stop)
            break;
        if (nn_collect_arm((size_t)total)) {
            rc = nnc_fail(x, "%s", "out of memory");
            break;
        }
        json_t *reply = NULL;
        if (sw > 0) { /* the scene to put back: as it is now (a JSON client may have set values meanwhile) */
            json_t *now = nnc_get(x, s_saved_names, S_NSAVED, &rc);
            if (!now) {
                nn_collect_disarm();
                break;
            }
            json_decref(saved);
            saved = now;
        }
        rc = nnc_call(x, json_pack("{s:s,s:O}", "cmd", "set", "values", vals), NULL);
        if (rc == NNC_OK) {
            applied = 1; /* the rebuilt controller keeps its state, X and Y included (wire.md §2.4) */
            rc = nnc_call(x, json_pack("{s:s,s:I}", "cmd", "curve", "index", (json_int_t)index), &reply);
            if (s_restore(x, saved, &rc) == NNC_OK)
                applied = 0;
        }
        if (rc) {
            json_decref(reply);
            nn_collect_disarm();
            break;
        }
        uint64_t run_id = (uint64_t)json_integer_value(json_object_get(reply, "run_id"));
        json_decref(reply);
        double expect = 2 * tp * p.points + dwell;
        double deadline = nn_now_s() + (free_run ? 60 : expect / (speed > 0 ? speed : 1) * 1.5 + 60);
        nn_run run;
        int wrc = nn_collect_wait(&run, deadline);
        if (wrc || run.run_id != run_id) {
            snprintf(x->err, sizeof x->err, "run %llu: %s", (unsigned long long)run_id,
                     wrc ? (nn_quitting() ? "the daemon is stopping" : "its end did not arrive in time")
                         : "another run's samples came (a JSON client started one?)");
            nn_run_free(&run);
            rc = wrc && nn_quitting() ? NNC_SILENT : NNC_FAIL;
            break;
        }
        last_run = run_id;
        /* forward: approach samples [0, turn); backward: from the retract's start */
        int64_t turn = run.dwell_at >= 0 ? run.dwell_at : run.retract_at >= 0 ? run.retract_at : (int64_t)run.n;
        int64_t r0 = run.retract_at >= 0 ? run.retract_at : (int64_t)run.n;
        int64_t done_pts = turn / K; /* forward points completed */
        if (done_pts < p.points)
            triggered = 1;
        for (int d = 0; d < n_dirs; d++)
            for (int row = 0; row < n_rows; row++) {
                int sig = row == 0 ? 0 : p.chs[row - 1];
                for (size_t i = 0; i < n_cols; i++) {
                    double val;
                    int64_t a, b;
                    if (d == 0) {
                        a = (int64_t)i * K + Ks;
                        b = (int64_t)(i + 1) * K;
                        if (b > turn)
                            b = a; /* not reached: NaN */
                    } else { /* backward point i is at forward point i's height: the j-th after the turn */
                        int64_t j = done_pts - 1 - (int64_t)i;
                        a = r0 + j * K + Ks;
                        b = r0 + (j + 1) * K;
                        if (j < 0)
                            b = a;
                    }
                    if (nnc_signals[sig].src == SRC_BIAS)
                        val = b > a ? p.bias_V : NAN;
                    else {
                        int ch = nnc_signals[sig].ch;
                        val = s_mean(run.v[ch], a, b, run.n);
                    }
                    acc[((size_t)d * (size_t)n_rows + (size_t)row) * n_cols + i] += val / p.sweeps;
                }
            }
        int aborted = strcmp(run.status, "ok") != 0;
        if (aborted && strcmp(run.status, "aborted")) {
            snprintf(x->err, sizeof x->err, "run %llu ended with status '%s'", (unsigned long long)run_id, run.status);
            rc = NNC_FAIL;
        }
        nn_run_free(&run);
        if (aborted)
            break;
    }
    if (rc == NNC_OK && get_data) {
        names = calloc((size_t)(n_rows * n_dirs), sizeof *names);
        char *store = malloc((size_t)(n_rows * n_dirs) * 64);
        if (!names || !store) {
            free(store);
            rc = nnc_fail(x, "%s", "out of memory");
            goto out;
        }
        for (int d = 0; d < n_dirs; d++)
            for (int row = 0; row < n_rows; row++) {
                const char *nm = nnc_signals[row == 0 ? 0 : p.chs[row - 1]].name;
                char *dst = store + (size_t)(d * n_rows + row) * 64;
                if (d == 0)
                    snprintf(dst, 64, "%s", nm);
                else { /* "Force (N)" -> "Force [bwd] (N)" */
                    const char *u = strrchr(nm, '(');
                    int stem = u ? (int)(u - nm) - 1 : (int)strlen(nm);
                    snprintf(dst, 64, "%.*s [bwd]%s%s", stem, nm, u ? " " : "", u ? u : "");
                }
                names[d * n_rows + row] = dst;
            }
        size_t nn = (size_t)(n_rows * n_dirs);
        nn_put_i32(x->o, (int32_t)nn_strings_bytes(names, nn));
        nn_put_i32(x->o, (int32_t)nn);
        nn_put_strings(x->o, names, nn);
        nn_put_i32(x->o, (int32_t)nn);
        nn_put_i32(x->o, (int32_t)n_cols);
        for (size_t r = 0; r < nn; r++)
            for (size_t i = 0; i < n_cols; i++)
                nn_put_f32(x->o, (float)acc[r * n_cols + i]);
        nn_put_i32(x->o, S_NFIXED + S_NPARAMS);
        float par[S_NFIXED + S_NPARAMS] = { p.z_offset_m, p.z_distance_m, p.t_settle_s, p.t_integr_s,
                                            (float)p.sweeps, (float)last_run, (float)first_index,
                                            (float)triggered };
        for (int i = 0; i < S_NFIXED + S_NPARAMS; i++)
            nn_put_f32(x->o, par[i]);
        free(store);
    } else if (rc == NNC_OK) { /* no data asked: empty arrays */
        for (int i = 0; i < 5; i++)
            nn_put_i32(x->o, 0);
    }
out:
    if (applied) /* a restore that failed after the curve started: once more */
        s_restore(x, saved, &rc);
    json_decref(saved);
    json_decref(vals);
    free(acc);
    free(names);
    pthread_mutex_lock(&nnc_mu);
    nnc_m.running = 0;
    pthread_mutex_unlock(&nnc_mu);
    return rc;
}

static int h_zs_stop(nnc_ctx *x)
{
    pthread_mutex_lock(&nnc_mu);
    int running = nnc_m.running;
    nnc_m.stop = 1;
    pthread_mutex_unlock(&nnc_mu);
    if (!running)
        return nnc_ping(x);
    int rc = nnc_call(x, json_pack("{s:s}", "cmd", "abort"), NULL);
    if (rc == NNC_FAIL) { /* no run in progress (between sweeps, or just ended): stopped all the same */
        x->err[0] = 0;
        rc = NNC_OK;
    }
    return rc;
}

const nnc_cmd nnc_zspectr_cmds[] = {
    { "ZSpectr.Open", nnc_ping_only, "" },
    { "ZSpectr.Start", h_zs_start, "iiiii" },
    { "ZSpectr.Stop", h_zs_stop, "" },
    { "ZSpectr.StatusGet", h_zs_status, "I" },
    { "ZSpectr.ChsSet", h_zs_chs_set, "" },
    { "ZSpectr.ChsGet", h_zs_chs_get, "ii" },
    { "ZSpectr.PropsSet", h_zs_props_set, "" },
    { "ZSpectr.PropsGet", h_zs_props_get, "HiiiiiHHHH" },
    { "ZSpectr.AdvPropsSet", h_zs_adv_set, "" },
    { "ZSpectr.AdvPropsGet", h_zs_adv_get, "fHHH" },
    { "ZSpectr.RangeSet", h_zs_range_set, "" },
    { "ZSpectr.RangeGet", h_zs_range_get, "ff" },
    { "ZSpectr.TimingSet", h_zs_timing_set, "" },
    { "ZSpectr.TimingGet", h_zs_timing_get, "fffffff" },
    { "ZSpectr.RetractDelaySet", h_zs_rdelay_set, "" },
    { "ZSpectr.RetractDelayGet", h_zs_rdelay_get, "f" },
    { "ZSpectr.RetractSet", h_zs_retract_set, "" },
    { "ZSpectr.RetractGet", h_zs_retract_get, "HfiH" },
    { "ZSpectr.Retract2ndSet", h_zs_retract2_set, "" },
    { "ZSpectr.Retract2ndGet", h_zs_retract2_get, "ifiH" },
    { "ZSpectr.RetractSecondSet", h_zs_retract2_set, "" }, /* the spelling nanonis_spm sends */
    { "ZSpectr.RetractSecondGet", h_zs_retract2_get, "ifiH" },
};
const size_t nnc_zspectr_ncmds = sizeof nnc_zspectr_cmds / sizeof nnc_zspectr_cmds[0];
