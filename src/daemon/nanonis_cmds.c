/* SPDX-License-Identifier: MIT */
/*
 * The Nanonis command table (nanonis.h, docs/nanonis.md): each command's argument and return layout as
 * TCPProtocol_SPM gives them, and what it does in vafm.
 *
 * Every request that names a known command reaches the control loop at least once as a JSON request (its
 * id "nanonis:CONN:SEQ:COMMAND"): the commands that need the daemon send theirs (get, set, curve, abort);
 * the others send `status`. So a fault plan acts on Nanonis requests as on any client's (no_reply: no
 * response; reply_delay; busy: an error status) and each shows in the daemon's records.
 *
 * On an error the response still carries the return arguments, zero (arrays empty), then the error status
 * 1 and its description: clients parse the return arguments before they look at the error.
 */
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "daemon/nanonis.h"

#define S_ERR 512
#define S_MAX_POINTS 100000
#define S_MAX_SWEEPS 1000
#define S_MAX_CHS 32

/* ---- the signal table ------------------------------------------------------------------------------
 * Nanonis numbers its signals 0-127. vafm's come from the stream (the last sample of the last run, or the
 * scene's start before any run) or from a module's value. The always-on controller (issue #26) will add its
 * own rows (the Z controller's setpoint and output, the XY position) as further sources. */
enum s_src { SRC_STREAM = 0, SRC_BIAS = 1 };
enum s_kind { KIND_Z = 0, KIND_DEFL_V, KIND_DEFL_M, KIND_FORCE, KIND_OTHER };
typedef struct s_signal {
    const char *name; /* Nanonis style: "Name (unit)" */
    int src;
    int ch;           /* SRC_STREAM: the stream channel (nanonis.h NN_CH_*) */
    int kind;
} s_signal;
static const s_signal s_signals[] = {
    { "Z (m)", SRC_STREAM, NN_CH_HEIGHT, KIND_Z },             /* the piezo height (command) */
    { "Deflection (V)", SRC_STREAM, NN_CH_DEFL_V, KIND_DEFL_V }, /* the detector signal */
    { "Deflection (m)", SRC_STREAM, NN_CH_DEFL_M, KIND_DEFL_M },
    { "Force (N)", SRC_STREAM, NN_CH_FORCE, KIND_FORCE },
    { "Z sensor (m)", SRC_STREAM, NN_CH_HMEAS, KIND_Z },        /* the height sensor (= Z without a model) */
    { "Tip height (m)", SRC_STREAM, NN_CH_TIP, KIND_Z },        /* ground truth: the true tip height */
    { "Bias (V)", SRC_BIAS, 0, KIND_OTHER },
};
#define S_NSIG ((int)(sizeof s_signals / sizeof s_signals[0]))
static const char *s_signal_names[S_NSIG];

/* ---- module state (all connections share it: the instrument's) ---------------------------------- */
static pthread_mutex_t s_mu = PTHREAD_MUTEX_INITIALIZER;
static struct {
    float bias_V;
    /* Z spectroscopy */
    int chs[S_MAX_CHS], n_chs;
    int backward, points, sweeps, autosave, show_dialog, save_all;
    float t_fwd_bwd_s;
    int record_final_z, lockin_run, reset_z;
    float z_offset_m, z_distance_m;
    float t_zavg_s, t_init_settle_s, slew_V_per_s, t_settle_s, t_integr_s, t_end_settle_s, t_zctrl_s;
    float retract_delay_s;
    int ar_enable, ar_signal, ar_cmp;
    float ar_threshold;
    int ar2_cond, ar2_signal, ar2_cmp; /* ar2_cond as Get reports it: 0 -No-, 1 OR, 2 AND, 3 THEN */
    float ar2_threshold;
    int running, stop;
    unsigned long long curves; /* curves run: the next one's index (its random stream) */
} m;

void nn_cmds_init(void)
{
    for (int i = 0; i < S_NSIG; i++)
        s_signal_names[i] = s_signals[i].name;
    pthread_mutex_lock(&s_mu);
    memset(&m, 0, sizeof m);
    m.chs[0] = 1; /* Deflection (V) */
    m.chs[1] = 3; /* Force (N) */
    m.n_chs = 2;
    m.backward = 1;
    m.points = 128;
    m.sweeps = 1;
    m.reset_z = 1;
    m.z_distance_m = 200e-9f;
    m.t_zavg_s = 0.1f;
    m.slew_V_per_s = 1000.f;
    m.t_integr_s = 1e-3f;
    m.ar_enable = 1;
    m.ar_threshold = 5e-9f;
    m.ar_signal = 3; /* Force (N) > 5 nN: vafm's default setpoint */
    m.ar_cmp = 0;
    pthread_mutex_unlock(&s_mu);
}

/* ---- helpers ---------------------------------------------------------------------------------------- */

typedef struct s_ctx {
    nn_conn *c;
    nn_rd r;
    nn_buf *o;
    char err[S_ERR];
} s_ctx;

enum { S_OK = 0, S_FAIL = -1, S_SILENT = -2 };

static int s_fail(s_ctx *x, const char *fmt, const char *a)
{
    snprintf(x->err, sizeof x->err, fmt, a);
    return S_FAIL;
}

/* One JSON request to the daemon: S_OK, S_FAIL (x->err) or S_SILENT (no reply). */
static int s_call(s_ctx *x, json_t *req, json_t **reply)
{
    int rc = nn_call(x->c, req, reply, x->err, sizeof x->err);
    return rc == NN_OK ? S_OK : rc == NN_ENOREPLY ? S_SILENT : S_FAIL;
}

static int s_ping(s_ctx *x) { return s_call(x, json_pack("{s:s}", "cmd", "status"), NULL); }

/* `get` of some scene values: an object {name: value} (the caller frees it), or NULL with rc set. */
static json_t *s_get(s_ctx *x, const char *const *names, size_t n, int *rc)
{
    json_t *a = json_array();
    for (size_t i = 0; i < n; i++)
        json_array_append_new(a, json_string(names[i]));
    json_t *reply = NULL;
    *rc = s_call(x, json_pack("{s:s,s:o}", "cmd", "get", "names", a), &reply);
    if (*rc)
        return NULL;
    json_t *v = json_incref(json_object_get(reply, "values"));
    json_decref(reply);
    if (!v) {
        *rc = S_FAIL;
        snprintf(x->err, sizeof x->err, "the daemon's get reply has no values");
    }
    return v;
}

static double s_num(json_t *o, const char *k)
{
    json_t *v = json_object_get(o, k);
    return json_is_number(v) ? json_number_value(v) : NAN;
}

static int s_args_done(s_ctx *x)
{
    if (x->r.bad) {
        snprintf(x->err, sizeof x->err, "%s", x->r.why);
        return S_FAIL;
    }
    return S_OK;
}

static int s_signal_index(s_ctx *x, int32_t i, const char *arg)
{
    if (i < 0 || i >= S_NSIG) {
        snprintf(x->err, sizeof x->err, "%s %d: no such signal; vafm has signals 0 to %d (Signals.NamesGet)", arg,
                 (int)i, S_NSIG - 1);
        return S_FAIL;
    }
    return S_OK;
}

/* ---- Signals ------------------------------------------------------------------------------------------ */

static const char *const s_scene_names[] = { "start_height_m", "k_N_per_m", "sensitivity_m_per_V", "adc_range_V",
                                             "ramp_size_m", "z_range_m", "baseline_offset_V" };
enum { SC_START, SC_K, SC_SENS, SC_ADC, SC_RAMP, SC_ZRANGE, SC_OFFSET, SC_N };

static int s_scene(s_ctx *x, double sc[SC_N])
{
    int rc;
    json_t *v = s_get(x, s_scene_names, SC_N, &rc);
    if (!v)
        return rc;
    for (int i = 0; i < SC_N; i++)
        sc[i] = s_num(v, s_scene_names[i]);
    json_decref(v);
    return S_OK;
}

/* The current value of signal i: the stream's last sample; before any, the scene's start (at rest). */
static double s_value(int i, const double sc[SC_N])
{
    const s_signal *g = &s_signals[i];
    if (g->src == SRC_BIAS) {
        pthread_mutex_lock(&s_mu);
        double b = m.bias_V;
        pthread_mutex_unlock(&s_mu);
        return b;
    }
    double v[NN_CH_N];
    int hm = 0;
    if (nn_live(v, &hm))
        return g->ch == NN_CH_HMEAS && !hm ? v[NN_CH_HEIGHT] : v[g->ch];
    switch (g->ch) {
    case NN_CH_HEIGHT:
    case NN_CH_HMEAS:
    case NN_CH_TIP: return sc[SC_START];
    case NN_CH_DEFL_V: return sc[SC_OFFSET];
    default: return 0;
    }
}

static int h_names(s_ctx *x)
{
    int rc = s_ping(x);
    if (rc)
        return rc;
    nn_put_i32(x->o, (int32_t)nn_strings_bytes(s_signal_names, S_NSIG));
    nn_put_i32(x->o, S_NSIG);
    nn_put_strings(x->o, s_signal_names, S_NSIG);
    return S_OK;
}

static int h_valget(s_ctx *x)
{
    int32_t i = nn_get_i32(&x->r, "Signal index");
    (void)nn_get_u32(&x->r, "Wait for newest data");
    double sc[SC_N];
    int rc = s_args_done(x) || s_signal_index(x, i, "Signal index") ? S_FAIL : s_scene(x, sc);
    if (rc)
        return rc;
    nn_put_f32(x->o, (float)s_value(i, sc));
    return S_OK;
}

static int h_valsget(s_ctx *x)
{
    int32_t n = nn_get_i32(&x->r, "Signals indexes size");
    if (!x->r.bad && (n < 0 || n > 128)) {
        snprintf(x->err, sizeof x->err, "Signals indexes size %d: must be in [0, 128]", (int)n);
        return S_FAIL;
    }
    int32_t idx[128];
    for (int32_t k = 0; k < n && !x->r.bad; k++)
        idx[k] = nn_get_i32(&x->r, "Signals indexes");
    (void)nn_get_u32(&x->r, "Wait for newest data");
    if (s_args_done(x))
        return S_FAIL;
    for (int32_t k = 0; k < n; k++)
        if (s_signal_index(x, idx[k], "Signals indexes: index"))
            return S_FAIL;
    double sc[SC_N];
    int rc = s_scene(x, sc);
    if (rc)
        return rc;
    nn_put_i32(x->o, n);
    for (int32_t k = 0; k < n; k++)
        nn_put_f32(x->o, (float)s_value(idx[k], sc));
    return S_OK;
}

static int h_calibr(s_ctx *x)
{
    int32_t i = nn_get_i32(&x->r, "Signal index");
    double sc[SC_N];
    int rc = s_args_done(x) || s_signal_index(x, i, "Signal index") ? S_FAIL : s_scene(x, sc);
    if (rc)
        return rc;
    /* physical units per volt of the detector signal, and the offset in physical units */
    int kind = s_signals[i].kind;
    double cal = kind == KIND_DEFL_M ? sc[SC_SENS] : kind == KIND_FORCE ? sc[SC_SENS] * sc[SC_K] : 1.0;
    double off = kind == KIND_DEFL_M ? -sc[SC_OFFSET] * sc[SC_SENS]
                 : kind == KIND_FORCE ? -sc[SC_OFFSET] * sc[SC_SENS] * sc[SC_K]
                                      : 0.0;
    nn_put_f32(x->o, (float)cal);
    nn_put_f32(x->o, (float)off);
    return S_OK;
}

static int h_range(s_ctx *x)
{
    int32_t i = nn_get_i32(&x->r, "Signal index");
    double sc[SC_N];
    int rc = s_args_done(x) || s_signal_index(x, i, "Signal index") ? S_FAIL : s_scene(x, sc);
    if (rc)
        return rc;
    double hi, lo, half = sc[SC_ADC] / 2;
    switch (s_signals[i].kind) {
    case KIND_Z: { /* the travel of a curve: from the start height down by the ramp (or the travel limit) */
        double travel = sc[SC_RAMP] > 0 ? sc[SC_RAMP] : sc[SC_ZRANGE] > 0 ? sc[SC_ZRANGE] : sc[SC_START];
        hi = sc[SC_START];
        lo = sc[SC_START] - travel;
        break;
    }
    case KIND_DEFL_V: hi = half, lo = -half; break;
    case KIND_DEFL_M: hi = half * sc[SC_SENS], lo = -hi; break;
    case KIND_FORCE: hi = half * sc[SC_SENS] * sc[SC_K], lo = -hi; break;
    default: hi = 10, lo = -10; break; /* bias: the ±10 V of a controller's output */
    }
    nn_put_f32(x->o, (float)hi);
    nn_put_f32(x->o, (float)lo);
    return S_OK;
}

/* ---- Bias: a value (no physics) ------------------------------------------------------------------- */

static int h_bias_set(s_ctx *x)
{
    float v = nn_get_f32(&x->r, "Bias value (V)");
    if (s_args_done(x))
        return S_FAIL;
    if (!isfinite(v) || fabsf(v) > 10.f) {
        snprintf(x->err, sizeof x->err, "Bias value (V) %g: must be in [-10, 10] V", (double)v);
        return S_FAIL;
    }
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    m.bias_V = v;
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

static int h_bias_get(s_ctx *x)
{
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    nn_put_f32(x->o, m.bias_V);
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

/* ---- ZSpectr: properties -------------------------------------------------------------------------- */

static int h_ping_only(s_ctx *x) { return s_args_done(x) ? S_FAIL : s_ping(x); }

static int h_zs_status(s_ctx *x)
{
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    nn_put_u32(x->o, (uint32_t)m.running);
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

static int h_zs_chs_set(s_ctx *x)
{
    int32_t n = nn_get_i32(&x->r, "Number of channels");
    if (!x->r.bad && (n < 0 || n > S_MAX_CHS)) {
        snprintf(x->err, sizeof x->err, "Number of channels %d: must be in [0, %d]", (int)n, S_MAX_CHS);
        return S_FAIL;
    }
    int32_t idx[S_MAX_CHS];
    for (int32_t k = 0; k < n && !x->r.bad; k++)
        idx[k] = nn_get_i32(&x->r, "Channel indexes");
    if (s_args_done(x))
        return S_FAIL;
    for (int32_t k = 0; k < n; k++)
        if (s_signal_index(x, idx[k], "Channel indexes: index"))
            return S_FAIL;
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    for (int32_t k = 0; k < n; k++)
        m.chs[k] = idx[k];
    m.n_chs = n;
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

static int h_zs_chs_get(s_ctx *x)
{
    int rc = s_ping(x);
    if (rc)
        return rc;
    const char *names[S_MAX_CHS];
    pthread_mutex_lock(&s_mu);
    int n = m.n_chs;
    nn_put_i32(x->o, n);
    for (int k = 0; k < n; k++) {
        nn_put_i32(x->o, m.chs[k]);
        names[k] = s_signals[m.chs[k]].name;
    }
    pthread_mutex_unlock(&s_mu);
    nn_put_i32(x->o, (int32_t)nn_strings_bytes(names, (size_t)n));
    nn_put_strings(x->o, names, (size_t)n);
    return S_OK;
}

/* a flag of a Set: 0 no change, 1 on, 2 off */
static int s_flag(s_ctx *x, unsigned v, const char *arg, int *dst)
{
    if (v > 2) {
        snprintf(x->err, sizeof x->err, "%s %u: must be 0 (no change), 1 (on) or 2 (off)", arg, v);
        return S_FAIL;
    }
    if (v)
        *dst = v == 1;
    return S_OK;
}

static int h_zs_props_set(s_ctx *x)
{
    unsigned bwd = nn_get_u16(&x->r, "Backward sweep");
    int32_t pts = nn_get_i32(&x->r, "Number of points");
    unsigned sw = nn_get_u16(&x->r, "Number of sweeps");
    unsigned as = nn_get_u16(&x->r, "Autosave");
    unsigned sd = nn_get_u16(&x->r, "Show save dialog");
    unsigned sa = nn_get_u16(&x->r, "Save all");
    if (s_args_done(x))
        return S_FAIL;
    if (pts < 0 || pts > S_MAX_POINTS) {
        snprintf(x->err, sizeof x->err, "Number of points %d: must be in [1, %d] (0: no change)", (int)pts,
                 S_MAX_POINTS);
        return S_FAIL;
    }
    if (sw > S_MAX_SWEEPS) {
        snprintf(x->err, sizeof x->err, "Number of sweeps %u: must be in [1, %d] (0: no change)", sw, S_MAX_SWEEPS);
        return S_FAIL;
    }
    int b = -1, a = -1, d = -1, s = -1;
    if (s_flag(x, bwd, "Backward sweep", &b) || s_flag(x, as, "Autosave", &a) ||
        s_flag(x, sd, "Show save dialog", &d) || s_flag(x, sa, "Save all", &s))
        return S_FAIL;
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    if (b >= 0)
        m.backward = b;
    if (pts)
        m.points = pts;
    if (sw)
        m.sweeps = (int)sw;
    if (a >= 0)
        m.autosave = a;
    if (d >= 0)
        m.show_dialog = d;
    if (s >= 0)
        m.save_all = s;
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

/* The parameters ZSpectr.Start returns, in this order: the fixed ones, then the others. */
static const char *const s_fixed_params[] = { "Z offset (m)", "Z sweep distance (m)" };
static const char *const s_params[] = { "Settling time (s)", "Integration time (s)", "Number of sweeps",
                                        "Run ID", "Curve index", "Auto-retract triggered" };
#define S_NFIXED 2
#define S_NPARAMS 6

static int h_zs_props_get(s_ctx *x)
{
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    nn_put_u16(x->o, (uint16_t)m.backward);
    nn_put_i32(x->o, m.points);
    nn_put_i32(x->o, (int32_t)nn_strings_bytes(s_params, S_NPARAMS));
    nn_put_i32(x->o, S_NPARAMS);
    nn_put_strings(x->o, s_params, S_NPARAMS);
    nn_put_i32(x->o, (int32_t)nn_strings_bytes(s_fixed_params, S_NFIXED));
    nn_put_i32(x->o, S_NFIXED);
    nn_put_strings(x->o, s_fixed_params, S_NFIXED);
    nn_put_u16(x->o, (uint16_t)m.sweeps);
    nn_put_u16(x->o, (uint16_t)m.autosave);
    nn_put_u16(x->o, (uint16_t)m.show_dialog);
    nn_put_u16(x->o, (uint16_t)m.save_all);
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

static int s_time(s_ctx *x, float v, const char *arg)
{
    if (!isfinite(v) || v < 0 || v > 1000) {
        snprintf(x->err, sizeof x->err, "%s %g: must be in [0, 1000] s", arg, (double)v);
        return S_FAIL;
    }
    return S_OK;
}

static int h_zs_adv_set(s_ctx *x)
{
    float t = nn_get_f32(&x->r, "Time between forward and backward sweep (s)");
    unsigned rf = nn_get_u16(&x->r, "Record final Z");
    unsigned lr = nn_get_u16(&x->r, "Lockin Run");
    unsigned rz = nn_get_u16(&x->r, "Reset Z");
    if (s_args_done(x) || s_time(x, t, "Time between forward and backward sweep (s)"))
        return S_FAIL;
    int a = -1, b = -1, c = -1;
    if (s_flag(x, rf, "Record final Z", &a) || s_flag(x, lr, "Lockin Run", &b) || s_flag(x, rz, "Reset Z", &c))
        return S_FAIL;
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    m.t_fwd_bwd_s = t;
    if (a >= 0)
        m.record_final_z = a;
    if (b >= 0)
        m.lockin_run = b;
    if (c >= 0)
        m.reset_z = c;
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

static int h_zs_adv_get(s_ctx *x)
{
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    nn_put_f32(x->o, m.t_fwd_bwd_s);
    nn_put_u16(x->o, (uint16_t)m.record_final_z);
    nn_put_u16(x->o, (uint16_t)m.lockin_run);
    nn_put_u16(x->o, (uint16_t)m.reset_z);
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

static int h_zs_range_set(s_ctx *x)
{
    float off = nn_get_f32(&x->r, "Z offset (m)");
    float dist = nn_get_f32(&x->r, "Z sweep distance (m)");
    if (s_args_done(x))
        return S_FAIL;
    if (!isfinite(off) || fabsf(off) > 1e-4f) {
        snprintf(x->err, sizeof x->err, "Z offset (m) %g: must be in [-1e-4, 1e-4] m", (double)off);
        return S_FAIL;
    }
    if (!isfinite(dist) || fabsf(dist) < 1e-12f || fabsf(dist) > 1e-4f) {
        snprintf(x->err, sizeof x->err, "Z sweep distance (m) %g: its magnitude must be in [1e-12, 1e-4] m",
                 (double)dist);
        return S_FAIL;
    }
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    m.z_offset_m = off;
    m.z_distance_m = dist;
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

static int h_zs_range_get(s_ctx *x)
{
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    nn_put_f32(x->o, m.z_offset_m);
    nn_put_f32(x->o, m.z_distance_m);
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

static const char *const s_timing_names[7] = { "Z averaging time (s)", "Initial settling time (s)",
                                                "Maximum slew rate (V/s)", "Settling time (s)",
                                                "Integration time (s)", "End settling time (s)",
                                                "Z control time (s)" };

static int h_zs_timing_set(s_ctx *x)
{
    float t[7];
    for (int i = 0; i < 7; i++)
        t[i] = nn_get_f32(&x->r, s_timing_names[i]);
    if (s_args_done(x))
        return S_FAIL;
    for (int i = 0; i < 7; i++) {
        if (i == 2) {
            if (!isfinite(t[i]) || t[i] <= 0)
                return s_fail(x, "%s: must be a positive number", s_timing_names[i]);
        } else if (s_time(x, t[i], s_timing_names[i]))
            return S_FAIL;
    }
    if (!(t[4] > 0))
        return s_fail(x, "%s: must be > 0 (each point's samples are averaged over it)", s_timing_names[4]);
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    m.t_zavg_s = t[0];
    m.t_init_settle_s = t[1];
    m.slew_V_per_s = t[2];
    m.t_settle_s = t[3];
    m.t_integr_s = t[4];
    m.t_end_settle_s = t[5];
    m.t_zctrl_s = t[6];
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

static int h_zs_timing_get(s_ctx *x)
{
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    float t[7] = { m.t_zavg_s, m.t_init_settle_s, m.slew_V_per_s, m.t_settle_s, m.t_integr_s, m.t_end_settle_s,
                   m.t_zctrl_s };
    pthread_mutex_unlock(&s_mu);
    for (int i = 0; i < 7; i++)
        nn_put_f32(x->o, t[i]);
    return S_OK;
}

static int h_zs_rdelay_set(s_ctx *x)
{
    float t = nn_get_f32(&x->r, "Retract delay (s)");
    if (s_args_done(x) || s_time(x, t, "Retract delay (s)"))
        return S_FAIL;
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    m.retract_delay_s = t;
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

static int h_zs_rdelay_get(s_ctx *x)
{
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    nn_put_f32(x->o, m.retract_delay_s);
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

static int h_zs_retract_set(s_ctx *x)
{
    unsigned en = nn_get_u16(&x->r, "Enable");
    float thr = nn_get_f32(&x->r, "Threshold");
    int32_t sig = nn_get_i32(&x->r, "Signal index");
    unsigned cmp = nn_get_u16(&x->r, "Comparison");
    if (s_args_done(x))
        return S_FAIL;
    int e = -1;
    if (s_flag(x, en, "Enable", &e) || (sig != -1 && s_signal_index(x, sig, "Signal index")))
        return S_FAIL;
    if (cmp > 2) {
        snprintf(x->err, sizeof x->err, "Comparison %u: must be 0 (>), 1 (<) or 2 (no change)", cmp);
        return S_FAIL;
    }
    if (!isfinite(thr))
        return s_fail(x, "%s: must be a finite number", "Threshold");
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    if (e >= 0)
        m.ar_enable = e;
    m.ar_threshold = thr;
    if (sig != -1)
        m.ar_signal = sig;
    if (cmp != 2)
        m.ar_cmp = (int)cmp;
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

static int h_zs_retract_get(s_ctx *x)
{
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    nn_put_u16(x->o, (uint16_t)m.ar_enable);
    nn_put_f32(x->o, m.ar_threshold);
    nn_put_i32(x->o, m.ar_signal);
    nn_put_u16(x->o, (uint16_t)m.ar_cmp);
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

static int h_zs_retract2_set(s_ctx *x)
{
    int32_t cond = nn_get_i32(&x->r, "2nd condition");
    float thr = nn_get_f32(&x->r, "Threshold");
    int32_t sig = nn_get_i32(&x->r, "Signal index");
    unsigned cmp = nn_get_u16(&x->r, "Comparison");
    if (s_args_done(x))
        return S_FAIL;
    if (cond < 0 || cond > 4) {
        snprintf(x->err, sizeof x->err, "2nd condition %d: must be 0 (no change), 1 (-No-), 2 (OR), 3 (AND) or 4 "
                 "(THEN)", (int)cond);
        return S_FAIL;
    }
    if ((sig != -1 && s_signal_index(x, sig, "Signal index")))
        return S_FAIL;
    if (cmp > 2) {
        snprintf(x->err, sizeof x->err, "Comparison %u: must be 0 (>), 1 (<) or 2 (no change)", cmp);
        return S_FAIL;
    }
    if (!isfinite(thr))
        return s_fail(x, "%s: must be a finite number", "Threshold");
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    if (cond)
        m.ar2_cond = cond - 1; /* Set counts from "no change", Get from -No- */
    m.ar2_threshold = thr;
    if (sig != -1)
        m.ar2_signal = sig;
    if (cmp != 2)
        m.ar2_cmp = (int)cmp;
    pthread_mutex_unlock(&s_mu);
    return S_OK;
}

static int h_zs_retract2_get(s_ctx *x)
{
    int rc = s_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(&s_mu);
    nn_put_i32(x->o, m.ar2_cond);
    nn_put_f32(x->o, m.ar2_threshold);
    nn_put_i32(x->o, m.ar2_signal);
    nn_put_u16(x->o, (uint16_t)m.ar2_cmp);
    pthread_mutex_unlock(&s_mu);
    return S_OK;
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
 * S_FAIL with the restore's message unless *rc already holds an error (its message is kept). @return the
 * restore's own result. */
static int s_restore(s_ctx *x, const json_t *saved, int *rc)
{
    json_t *back = json_deep_copy(saved);
    json_object_del(back, "speed");
    json_object_del(back, "free_run");
    json_object_del(back, "k_N_per_m");
    json_object_del(back, "sensitivity_m_per_V");
    char tmp[S_ERR];
    memcpy(tmp, x->err, sizeof tmp);
    int r = s_call(x, json_pack("{s:s,s:o}", "cmd", "set", "values", back), NULL);
    if (r && *rc == S_OK)
        *rc = S_FAIL; /* the error message of the restore stays in x->err */
    else
        memcpy(x->err, tmp, sizeof tmp);
    return r;
}

static int h_zs_start(s_ctx *x)
{
    uint32_t get_data = nn_get_u32(&x->r, "Get data");
    int32_t sl = nn_get_i32(&x->r, "Save base name string size");
    if (!x->r.bad && (sl < 0 || (size_t)sl > x->r.n - x->r.off)) {
        snprintf(x->err, sizeof x->err, "Save base name string size %d: the body holds %zu more bytes", (int)sl,
                 x->r.n - x->r.off);
        return S_FAIL;
    }
    if (s_args_done(x))
        return S_FAIL;
    pthread_mutex_lock(&s_mu);
    if (m.running) {
        pthread_mutex_unlock(&s_mu);
        return s_fail(x, "%s", "a Z spectroscopy is running already (ZSpectr.Stop ends it)");
    }
    __typeof__(m) p = m; /* this sweep's settings */
    m.running = 1;
    m.stop = 0;
    pthread_mutex_unlock(&s_mu);
    int rc = S_OK, applied = 0; /* applied: the sweep's values are set and not yet put back */
    json_t *saved = NULL, *vals = NULL;
    double *acc = NULL;
    const char **names = NULL;
    int n_rows = 1 + p.n_chs, n_dirs = p.backward ? 2 : 1, triggered = 0;
    uint64_t last_run = 0, first_index = p.curves;
    double tp = (double)p.t_settle_s + (double)p.t_integr_s;
    double dist = fabs((double)p.z_distance_m);
    /* the auto-retract condition as the curve's trigger */
    if (p.ar2_cond != 0) {
        rc = s_fail(x, "%s", "the auto-retract's 2nd condition is not supported (vafm's curve has one trigger): "
                             "set it to -No- (ZSpectr.Retract2ndSet 1)");
        goto out;
    }
    if (p.ar_enable) {
        int k = s_signals[p.ar_signal].kind;
        if (!((p.ar_cmp == 0 && (k == KIND_FORCE || k == KIND_DEFL_V || k == KIND_DEFL_M)) ||
              (p.ar_cmp == 1 && k == KIND_Z && s_signals[p.ar_signal].ch == NN_CH_HEIGHT))) {
            rc = s_fail(x, "auto-retract on '%s' with this comparison is not supported: vafm triggers on Force (N), "
                           "Deflection (V) or Deflection (m) > threshold, or Z (m) < threshold",
                        s_signals[p.ar_signal].name);
            goto out;
        }
    }
    int grc;
    saved = s_get(x, s_saved_names, S_NSAVED, &grc);
    if (!saved) {
        rc = grc;
        goto out;
    }
    double fs = s_num(saved, "sample_rate_Hz"), start = s_num(saved, "start_height_m") + (double)p.z_offset_m;
    double k_N = s_num(saved, "k_N_per_m"), sens = s_num(saved, "sensitivity_m_per_V");
    double speed = s_num(saved, "speed");
    int free_run = json_is_true(json_object_get(saved, "free_run"));
    /* samples per point: the scene's rate, at least 4 in each integration time */
    double kpt = fmax(round(tp * fs), ceil(4.0 * tp / (double)p.t_integr_s));
    double dwell = (double)p.retract_delay_s + (double)p.t_fwd_bwd_s;
    double total = kpt * p.points * 2 + dwell * kpt / tp + 16;
    if (!(total <= (double)VAFMD_NANONIS_MAX_RUN_SAMPLES) || kpt * p.points > 1e9) {
        snprintf(x->err, sizeof x->err, "this sweep would have ~%.3g samples (%d points of %.0f): at most %zu; use "
                 "fewer points, shorter settling and integration times, or a lower sample_rate_Hz",
                 total, p.points, kpt, VAFMD_NANONIS_MAX_RUN_SAMPLES);
        rc = S_FAIL;
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
    if (p.ar_enable && s_signals[p.ar_signal].kind != KIND_Z) {
        int k = s_signals[p.ar_signal].kind;
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
        rc = s_fail(x, "%s", "out of memory");
        goto out;
    }
    /* each sweep: the sweep's values, its curve (which keeps the scene it started with), the scene put back
     * at once: JSON clients see the scene unchanged while the curve runs, and their own `set`s survive */
    for (int sw = 0; sw < p.sweeps && rc == S_OK; sw++) {
        pthread_mutex_lock(&s_mu);
        int stop = m.stop;
        unsigned long long index = m.curves++;
        pthread_mutex_unlock(&s_mu);
        if (stop)
            break;
        if (nn_collect_arm((size_t)total)) {
            rc = s_fail(x, "%s", "out of memory");
            break;
        }
        json_t *reply = NULL;
        if (sw > 0) { /* the scene to put back: as it is now (a JSON client may have set values meanwhile) */
            json_t *now = s_get(x, s_saved_names, S_NSAVED, &rc);
            if (!now) {
                nn_collect_disarm();
                break;
            }
            json_decref(saved);
            saved = now;
        }
        rc = s_call(x, json_pack("{s:s,s:O}", "cmd", "set", "values", vals), NULL);
        if (rc == S_OK) {
            applied = 1;
            rc = s_call(x, json_pack("{s:s,s:I}", "cmd", "curve", "index", (json_int_t)index), &reply);
            if (s_restore(x, saved, &rc) == S_OK)
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
            rc = wrc && nn_quitting() ? S_SILENT : S_FAIL;
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
                    if (s_signals[sig].src == SRC_BIAS)
                        val = b > a ? p.bias_V : NAN;
                    else {
                        int ch = s_signals[sig].ch;
                        val = s_mean(run.v[ch], a, b, run.n);
                    }
                    acc[((size_t)d * (size_t)n_rows + (size_t)row) * n_cols + i] += val / p.sweeps;
                }
            }
        int aborted = strcmp(run.status, "ok") != 0;
        if (aborted && strcmp(run.status, "aborted")) {
            snprintf(x->err, sizeof x->err, "run %llu ended with status '%s'", (unsigned long long)run_id, run.status);
            rc = S_FAIL;
        }
        nn_run_free(&run);
        if (aborted)
            break;
    }
    if (rc == S_OK && get_data) {
        names = calloc((size_t)(n_rows * n_dirs), sizeof *names);
        char *store = malloc((size_t)(n_rows * n_dirs) * 64);
        if (!names || !store) {
            free(store);
            rc = s_fail(x, "%s", "out of memory");
            goto out;
        }
        for (int d = 0; d < n_dirs; d++)
            for (int row = 0; row < n_rows; row++) {
                const char *nm = s_signals[row == 0 ? 0 : p.chs[row - 1]].name;
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
    } else if (rc == S_OK) { /* no data asked: empty arrays */
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
    pthread_mutex_lock(&s_mu);
    m.running = 0;
    pthread_mutex_unlock(&s_mu);
    return rc;
}

static int h_zs_stop(s_ctx *x)
{
    pthread_mutex_lock(&s_mu);
    int running = m.running;
    m.stop = 1;
    pthread_mutex_unlock(&s_mu);
    if (!running)
        return s_ping(x);
    int rc = s_call(x, json_pack("{s:s}", "cmd", "abort"), NULL);
    if (rc == S_FAIL) { /* no run in progress (between sweeps, or just ended): stopped all the same */
        x->err[0] = 0;
        rc = S_OK;
    }
    return rc;
}

/* ---- modules that need the always-on controller (issue #26) ---------------------------------------- */

static int h_not_yet(s_ctx *x)
{
    int rc = s_ping(x);
    if (rc)
        return rc;
    snprintf(x->err, sizeof x->err, "%s: not yet: needs the always-on controller (vafm issue #26)",
             nn_conn_cmd(x->c));
    return S_FAIL;
}

/* ---- the table ----------------------------------------------------------------------------------------
 * ret: the return arguments written zero on an error (i int32, I uint32, H uint16, f float32, d float64). */
typedef struct s_cmd {
    const char *name;
    int (*fn)(s_ctx *x);
    const char *ret;
} s_cmd;

static const s_cmd s_table[] = {
    { "Signals.NamesGet", h_names, "ii" },
    { "Signals.ValGet", h_valget, "f" },
    { "Signals.ValsGet", h_valsget, "i" },
    { "Signals.CalibrGet", h_calibr, "ff" },
    { "Signals.RangeGet", h_range, "ff" },
    { "Signals.MeasNamesGet", h_names, "ii" },
    { "Bias.Set", h_bias_set, "" },
    { "Bias.Get", h_bias_get, "f" },
    { "ZSpectr.Open", h_ping_only, "" },
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
    /* not yet: the always-on controller */
    { "ZCtrl.OnOffSet", h_not_yet, "" },
    { "ZCtrl.OnOffGet", h_not_yet, "I" },
    { "ZCtrl.ZPosSet", h_not_yet, "" },
    { "ZCtrl.ZPosGet", h_not_yet, "f" },
    { "ZCtrl.SetpntSet", h_not_yet, "" },
    { "ZCtrl.SetpntGet", h_not_yet, "f" },
    { "ZCtrl.GainSet", h_not_yet, "" },
    { "ZCtrl.GainGet", h_not_yet, "fff" },
    { "ZCtrl.Withdraw", h_not_yet, "" },
    { "ZCtrl.LimitsSet", h_not_yet, "" },
    { "ZCtrl.LimitsGet", h_not_yet, "ff" },
    { "ZCtrl.StatusGet", h_not_yet, "H" },
    { "ZCtrl.TipLiftSet", h_not_yet, "" },
    { "ZCtrl.TipLiftGet", h_not_yet, "f" },
    { "ZCtrl.Home", h_not_yet, "" },
    { "ZCtrl.HomePropsSet", h_not_yet, "" },
    { "ZCtrl.HomePropsGet", h_not_yet, "Hf" },
    { "ZCtrl.SwitchOffDelaySet", h_not_yet, "" },
    { "ZCtrl.SwitchOffDelayGet", h_not_yet, "f" },
    { "Motor.StartMove", h_not_yet, "" },
    { "Motor.StartClosedLoop", h_not_yet, "" },
    { "Motor.StopMove", h_not_yet, "" },
    { "Motor.PosGet", h_not_yet, "ddd" },
    { "Motor.StepCounterGet", h_not_yet, "iii" },
    { "Motor.FreqAmpGet", h_not_yet, "ff" },
    { "Motor.FreqAmpSet", h_not_yet, "" },
    { "AutoApproach.Open", h_not_yet, "" },
    { "AutoApproach.OnOffSet", h_not_yet, "" },
    { "AutoApproach.OnOffGet", h_not_yet, "H" },
    { "FolMe.XYPosSet", h_not_yet, "" },
    { "FolMe.XYPosGet", h_not_yet, "dd" },
    { "FolMe.SpeedSet", h_not_yet, "" },
    { "FolMe.SpeedGet", h_not_yet, "fI" },
    { "FolMe.Stop", h_not_yet, "" },
};
#define S_NCMD (sizeof s_table / sizeof s_table[0])

static void s_zero(nn_buf *o, const char *ret)
{
    for (const char *c = ret; *c; c++)
        switch (*c) {
        case 'H': nn_put_u16(o, 0); break;
        case 'd': nn_put_f64(o, 0); break;
        default: nn_put_u32(o, 0); break; /* i, I, f: four zero bytes */
        }
}

int nn_dispatch(nn_conn *c, const char *name, const unsigned char *body, size_t n, nn_buf *out)
{
    s_ctx x;
    memset(&x, 0, sizeof x);
    x.c = c;
    x.o = out;
    x.r.p = body;
    x.r.n = n;
    const s_cmd *cmd = NULL;
    for (size_t i = 0; i < S_NCMD && !cmd; i++)
        if (!strcmp(s_table[i].name, name))
            cmd = &s_table[i];
    int rc;
    if (!cmd) {
        char safe[4 * 32 + 1];
        size_t k = 0;
        for (const unsigned char *p = (const unsigned char *)name; *p && k + 4 < sizeof safe; p++)
            k += (size_t)snprintf(safe + k, sizeof safe - k, *p >= 32 && *p < 127 ? "%c" : "\\x%02x", *p);
        safe[k] = 0;
        snprintf(x.err, sizeof x.err, "unknown command '%s': vafmd serves %zu Nanonis commands (docs/nanonis.md)",
                 safe, S_NCMD);
        rc = S_FAIL;
    } else
        rc = cmd->fn(&x);
    if (rc == S_SILENT)
        return 1;
    if (rc == S_FAIL) {
        out->n = 0;
        out->oom = 0;
        if (cmd)
            s_zero(out, cmd->ret);
    }
    nn_put_u32(out, rc == S_FAIL);
    size_t l = rc == S_FAIL ? strlen(x.err) : 0;
    nn_put_i32(out, (int32_t)l);
    nn_put_bytes(out, x.err, l);
    return 0;
}
