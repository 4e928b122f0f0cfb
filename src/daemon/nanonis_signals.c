/* SPDX-License-Identifier: MIT */
/*
 * Nanonis Signals and Bias (nanonis_cmds.h; docs/nanonis.md).
 *
 * The signal table: Nanonis numbers its signals 0-127 and names them "Name (unit)". vafm's come from the
 * stream (the last sample of the last run, or the scene's start before any run) or from a module's value
 * (Bias). Signals.ValGet/ValsGet read them; CalibrGet and RangeGet derive from the scene (the detector's
 * sensitivity, the spring constant, the ADC range, the curve's travel). Bias is a value kept for scripts
 * that set it: vafm has no tunnelling current, so it changes no physics.
 */
#include <math.h>
#include <pthread.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "daemon/nanonis_cmds.h"

/* ---- the signal table ------------------------------------------------------------------------------ */
const nnc_signal nnc_signals[NNC_NSIG] = {
    /* the stream: the last run's last sample (the curve's piezo height command, the detector signal...) */
    { "Z (m)", SRC_STREAM, NN_CH_HEIGHT, KIND_Z, NULL, 0, RNG_NONE },
    { "Deflection (V)", SRC_STREAM, NN_CH_DEFL_V, KIND_DEFL_V, NULL, 0, RNG_NONE },
    { "Deflection (m)", SRC_STREAM, NN_CH_DEFL_M, KIND_DEFL_M, NULL, 0, RNG_NONE },
    { "Force (N)", SRC_STREAM, NN_CH_FORCE, KIND_FORCE, NULL, 0, RNG_NONE },
    { "Z sensor (m)", SRC_STREAM, NN_CH_HMEAS, KIND_Z, NULL, 0, RNG_NONE },   /* = Z without a sensor model */
    { "Tip height (m)", SRC_STREAM, NN_CH_TIP, KIND_Z, NULL, 0, RNG_NONE },   /* ground truth */
    { "Bias (V)", SRC_BIAS, 0, KIND_OTHER, NULL, 0, RNG_NONE },
    /* the always-on controller's live state (status.ctrl), whatever runs did */
    { "Z piezo (m)", SRC_CTRL, 0, KIND_OTHER, "piezo_z_m", -1, RNG_PIEZO }, /* ZCtrl's Z: 0 retracted */
    { "Motor Z (m)", SRC_CTRL, 0, KIND_OTHER, "motor_z_m", 1, RNG_MOTOR },  /* the coarse motor's height */
    { "X (m)", SRC_CTRL, 0, KIND_OTHER, "x_m", 1, RNG_XY },
    { "Y (m)", SRC_CTRL, 0, KIND_OTHER, "y_m", 1, RNG_XY },
    { "Z ctrl setpoint (N)", SRC_CTRL, 0, KIND_OTHER, "setpoint_N", 1, RNG_FORCE },
    { "Z ctrl error (N)", SRC_CTRL, 0, KIND_OTHER, "error_N", 1, RNG_FORCE }, /* setpoint - force */
    { "Live force (N)", SRC_CTRL, 0, KIND_OTHER, "force_N", 1, RNG_FORCE },
    { "Live deflection (V)", SRC_CTRL, 0, KIND_OTHER, "signal_V", 1, RNG_VOLT },
    { "Sum (V)", SRC_CTRL, 0, KIND_OTHER, "sum_V", 1, RNG_VOLT },
    { "Gap (m)", SRC_CTRL, 0, KIND_OTHER, "gap_m", 1, RNG_GAP },         /* ground truth */
    { "Surface (m)", SRC_CTRL, 0, KIND_OTHER, "surface_m", 1, RNG_GAP }, /* ground truth */
};
const char *nnc_signal_names[NNC_NSIG];

/* ---- Signals ------------------------------------------------------------------------------------------ */

static const char *const s_scene_names[] = { "start_height_m", "k_N_per_m", "sensitivity_m_per_V", "adc_range_V",
                                             "ramp_size_m", "z_range_m", "baseline_offset_V",
                                             "ctrl_piezo_range_m", "ctrl_motor_min_m", "ctrl_motor_max_m",
                                             "ctrl_xy_range_m", "ctrl_force_limit_N" };
enum { SC_START, SC_K, SC_SENS, SC_ADC, SC_RAMP, SC_ZRANGE, SC_OFFSET, SC_PIEZO, SC_MOTOR_MIN, SC_MOTOR_MAX,
       SC_XY, SC_FLIMIT, SC_N };

/* status.ctrl when one of the n signals idx[] is the controller's (else *c = NULL): NNC_OK or an error. */
static int s_ctrl(nnc_ctx *x, const int32_t *idx, int32_t n, json_t **c)
{
    *c = NULL;
    int need = 0;
    for (int32_t k = 0; k < n; k++)
        need |= nnc_signals[idx[k]].src == SRC_CTRL;
    if (!need)
        return NNC_OK;
    json_t *reply = NULL;
    int rc = nnc_call(x, json_pack("{s:s}", "cmd", "status"), &reply);
    if (rc)
        return rc;
    *c = json_incref(json_object_get(reply, "ctrl"));
    json_decref(reply);
    if (!json_is_true(json_object_get(*c, "available"))) {
        json_t *why = json_object_get(*c, "error");
        snprintf(x->err, sizeof x->err, "a controller signal: the controller is not available: %s",
                 json_is_string(why) ? json_string_value(why) : "no status");
        json_decref(*c);
        *c = NULL;
        return NNC_FAIL;
    }
    return NNC_OK;
}

static int s_scene(nnc_ctx *x, double sc[SC_N])
{
    int rc;
    json_t *v = nnc_get(x, s_scene_names, SC_N, &rc);
    if (!v)
        return rc;
    for (int i = 0; i < SC_N; i++)
        sc[i] = nnc_num(v, s_scene_names[i]);
    json_decref(v);
    return NNC_OK;
}

/* The current value of signal i: the stream's last sample; before any, the scene's start (at rest); the
 * controller's rows from its status (ctrl). */
static double s_value(int i, const double sc[SC_N], json_t *ctrl)
{
    const nnc_signal *g = &nnc_signals[i];
    if (g->src == SRC_CTRL)
        return g->scale * nnc_num(ctrl, g->key);
    if (g->src == SRC_BIAS) {
        pthread_mutex_lock(&nnc_mu);
        double b = nnc_m.bias_V;
        pthread_mutex_unlock(&nnc_mu);
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

static int h_names(nnc_ctx *x)
{
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    nn_put_i32(x->o, (int32_t)nn_strings_bytes(nnc_signal_names, NNC_NSIG));
    nn_put_i32(x->o, NNC_NSIG);
    nn_put_strings(x->o, nnc_signal_names, NNC_NSIG);
    return NNC_OK;
}

static int h_valget(nnc_ctx *x)
{
    int32_t i = nn_get_i32(&x->r, "Signal index");
    (void)nn_get_u32(&x->r, "Wait for newest data");
    double sc[SC_N];
    json_t *c = NULL;
    int rc = nnc_args_done(x) || nnc_signal_index(x, i, "Signal index") ? NNC_FAIL : s_scene(x, sc);
    if (rc || (rc = s_ctrl(x, &i, 1, &c)))
        return rc;
    nn_put_f32(x->o, (float)s_value(i, sc, c));
    json_decref(c);
    return NNC_OK;
}

static int h_valsget(nnc_ctx *x)
{
    int32_t n = nn_get_i32(&x->r, "Signals indexes size");
    if (!x->r.bad && (n < 0 || n > 128)) {
        snprintf(x->err, sizeof x->err, "Signals indexes size %d: must be in [0, 128]", (int)n);
        return NNC_FAIL;
    }
    int32_t idx[128];
    for (int32_t k = 0; k < n && !x->r.bad; k++)
        idx[k] = nn_get_i32(&x->r, "Signals indexes");
    (void)nn_get_u32(&x->r, "Wait for newest data");
    if (nnc_args_done(x))
        return NNC_FAIL;
    for (int32_t k = 0; k < n; k++)
        if (nnc_signal_index(x, idx[k], "Signals indexes: index"))
            return NNC_FAIL;
    double sc[SC_N];
    json_t *c = NULL;
    int rc = s_scene(x, sc);
    if (rc || (rc = s_ctrl(x, idx, n, &c)))
        return rc;
    nn_put_i32(x->o, n);
    for (int32_t k = 0; k < n; k++)
        nn_put_f32(x->o, (float)s_value(idx[k], sc, c));
    json_decref(c);
    return NNC_OK;
}

/* CalibrGet and RangeGet: the signal index, then two floats that derive from the scene. */
static int s_signal_pair(nnc_ctx *x, void (*pair)(int i, const double sc[SC_N], double v[2]))
{
    int32_t i = nn_get_i32(&x->r, "Signal index");
    double sc[SC_N], v[2];
    int rc = nnc_args_done(x) || nnc_signal_index(x, i, "Signal index") ? NNC_FAIL : s_scene(x, sc);
    if (rc)
        return rc;
    pair(i, sc, v);
    nn_put_f32(x->o, (float)v[0]);
    nn_put_f32(x->o, (float)v[1]);
    return NNC_OK;
}

/* physical units per volt of the detector signal, and the offset in physical units */
static void s_calibr(int i, const double sc[SC_N], double v[2])
{
    int kind = nnc_signals[i].kind;
    v[0] = kind == KIND_DEFL_M ? sc[SC_SENS] : kind == KIND_FORCE ? sc[SC_SENS] * sc[SC_K] : 1.0;
    v[1] = kind == KIND_DEFL_M ? -sc[SC_OFFSET] * sc[SC_SENS]
           : kind == KIND_FORCE ? -sc[SC_OFFSET] * sc[SC_SENS] * sc[SC_K]
                                : 0.0;
}

/* the signal's range: v[0] the high end, v[1] the low */
static void s_range(int i, const double sc[SC_N], double v[2])
{
    double half = sc[SC_ADC] / 2;
    switch (nnc_signals[i].range) { /* the controller's rows */
    case RNG_PIEZO: v[0] = 0, v[1] = -sc[SC_PIEZO]; return;
    case RNG_MOTOR: v[0] = sc[SC_MOTOR_MAX], v[1] = sc[SC_MOTOR_MIN]; return;
    case RNG_XY: v[0] = sc[SC_XY] / 2, v[1] = -v[0]; return;
    case RNG_FORCE: v[0] = sc[SC_FLIMIT], v[1] = -v[0]; return;
    case RNG_VOLT: v[0] = half, v[1] = -half; return;
    case RNG_GAP: v[0] = sc[SC_MOTOR_MAX], v[1] = -sc[SC_PIEZO]; return;
    default: break;
    }
    switch (nnc_signals[i].kind) {
    case KIND_Z: { /* the travel of a curve: from the start height down by the ramp (or the travel limit) */
        double travel = sc[SC_RAMP] > 0 ? sc[SC_RAMP] : sc[SC_ZRANGE] > 0 ? sc[SC_ZRANGE] : sc[SC_START];
        v[0] = sc[SC_START];
        v[1] = sc[SC_START] - travel;
        break;
    }
    case KIND_DEFL_V: v[0] = half, v[1] = -half; break;
    case KIND_DEFL_M: v[0] = half * sc[SC_SENS], v[1] = -v[0]; break;
    case KIND_FORCE: v[0] = half * sc[SC_SENS] * sc[SC_K], v[1] = -v[0]; break;
    default: v[0] = 10, v[1] = -10; break; /* bias: the ±10 V of a controller's output */
    }
}

static int h_calibr(nnc_ctx *x) { return s_signal_pair(x, s_calibr); }
static int h_range(nnc_ctx *x) { return s_signal_pair(x, s_range); }

/* ---- Bias: a value (no physics) ------------------------------------------------------------------- */

static const nnc_field s_bias_f[] = { NNF_F32(nnc_state, "Bias value (V)", bias_V, NNF_RANGE, -10, 10,
                                              "must be in [-10, 10] V") };
static const nnc_props s_bias = { &nnc_mu, &nnc_m, s_bias_f, 1 };

const nnc_cmd nnc_signals_cmds[] = {
    { "Signals.NamesGet", h_names, "ii", NULL },
    { "Signals.ValGet", h_valget, "f", NULL },
    { "Signals.ValsGet", h_valsget, "i", NULL },
    { "Signals.CalibrGet", h_calibr, "ff", NULL },
    { "Signals.RangeGet", h_range, "ff", NULL },
    { "Signals.MeasNamesGet", h_names, "ii", NULL },
    { "Bias.Set", nnc_props_set, "", &s_bias },
    { "Bias.Get", nnc_props_get, "f", &s_bias },
};
const size_t nnc_signals_ncmds = sizeof nnc_signals_cmds / sizeof nnc_signals_cmds[0];
