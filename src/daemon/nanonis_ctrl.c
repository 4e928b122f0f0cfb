/* SPDX-License-Identifier: MIT */
/*
 * Nanonis ZCtrl, Motor, AutoApproach and FolMe: the always-on controller's commands in Nanonis words
 * (nanonis_cmds.h; docs/nanonis.md "The controller's modules"; protocol/wire.md §2.3-2.4).
 *
 * Each command becomes the daemon's own JSON commands over the bridge, as any client's: `status` (its
 * `ctrl` object) to read, `engage`, `withdraw`, `move`, `z`, `feedback` to act. Nothing here touches the
 * controller directly. "Wait until finished" (ZCtrl.Withdraw, Motor.StartMove, FolMe.XYPosSet) polls
 * `status` every S_POLL_S until the state says done, the timeout, or the daemon stopping.
 *
 * Sign convention (the spec is silent; docs/nanonis.md): Nanonis' Z is the piezo's position, positive away
 * from the sample, 0 fully retracted: Z = -ctrl.piezo_z_m, within [-ctrl_piezo_range_m, 0]. The coarse
 * motor's Z (Motor.PosGet) is ctrl.motor_z_m, the support's height above the substrate (up positive).
 * X and Y are the scanner's, in m, 0 at the centre.
 *
 * What vafm does not model is kept as a value and documented so: the switch-off delay, the motor's
 * frequency and amplitude, Z limits narrower than the piezo range (they bound ZCtrl.ZPosSet and Home only).
 */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include "daemon/nanonis_cmds.h"

#define S_POLL_S 0.02      /* a waiting command's `status` poll */
#define S_WAIT_MAX_S 600.0 /* the longest wait ("wait indefinitely" included) */

static pthread_mutex_t s_mu = PTHREAD_MUTEX_INITIALIZER;
typedef struct s_values {
    float tip_lift_m;     /* ZCtrl.TipLift: Z goes up by it when the controller is switched off */
    int home_relative;    /* ZCtrl.HomeProps: 0 absolute, 1 relative */
    float home_m;
    float switch_off_delay_s;
    int limits_set;       /* ZCtrl.LimitsSet given: else the piezo range */
    float z_hi_m, z_lo_m;
    float folme_speed;    /* FolMe.Speed (m/s); custom 0: the controller's ctrl_xy_speed_m_per_s */
    int folme_custom;
    float motor_freq_Hz, motor_amp_V;
    long long step_offset; /* Motor.StepCounterGet's reset: the controller's count at the last reset */
} s_values;
static s_values m = { .motor_freq_Hz = 1000.f, .motor_amp_V = 100.f };

/* The Get/Set pairs kept as values: each a table of its arguments (nanonis_cmds.h, nnc_props_get/set). */
#define S_PROPS(name, ...)                                                                                   \
    static const nnc_field name##_f[] = { __VA_ARGS__ };                                                     \
    _Static_assert(sizeof name##_f / sizeof name##_f[0] <= NNC_MAX_FIELDS, #name ": too many fields");      \
    static const nnc_props name = { &s_mu, &m, name##_f, (int)(sizeof name##_f / sizeof name##_f[0]) }


/* ---- helpers ---------------------------------------------------------------------------------------- */

/* The controller's status (status.ctrl, the caller frees it); NULL with rc set, NNC_FAIL if the scene
 * cannot host a controller. */
static json_t *s_status(nnc_ctx *x, int *rc)
{
    json_t *reply = NULL;
    *rc = nnc_call(x, json_pack("{s:s}", "cmd", "status"), &reply);
    if (*rc)
        return NULL;
    json_t *c = json_incref(json_object_get(reply, "ctrl"));
    json_decref(reply);
    if (!json_is_object(c) || !json_is_true(json_object_get(c, "available"))) {
        json_t *why = json_object_get(c, "error");
        snprintf(x->err, sizeof x->err, "%s: the controller is not available: %s", nn_conn_cmd(x->c),
                 json_is_string(why) ? json_string_value(why) : "no status");
        json_decref(c);
        *rc = NNC_FAIL;
        return NULL;
    }
    return c;
}

/* Numbers of status.ctrl: keys[i] a member ("a/b": b of the object a; true, false: 1, 0; else NaN). */
static int s_status_nums(nnc_ctx *x, const char *const *keys, int n, double *v)
{
    int rc;
    json_t *c = s_status(x, &rc);
    if (!c)
        return rc;
    for (int i = 0; i < n; i++) {
        const char *sl = strchr(keys[i], '/');
        json_t *o = c;
        if (sl) {
            char parent[32];
            snprintf(parent, sizeof parent, "%.*s", (int)(sl - keys[i]), keys[i]);
            o = json_object_get(c, parent);
        }
        json_t *j = json_object_get(o, sl ? sl + 1 : keys[i]);
        v[i] = json_is_boolean(j) ? (double)json_is_true(j) : nnc_num(o, sl ? sl + 1 : keys[i]);
    }
    json_decref(c);
    return NNC_OK;
}

static int s_status_num(nnc_ctx *x, const char *key, double *v) { return s_status_nums(x, &key, 1, v); }

static const char *s_state(json_t *c)
{
    json_t *s = json_object_get(c, "state");
    return json_is_string(s) ? json_string_value(s) : "";
}

/* One controller command (its reply dropped). */
static int s_cmd(nnc_ctx *x, json_t *req) { return nnc_call(x, req, NULL); }

/* Wait until done(status.ctrl) or timeout_s: NNC_OK, NNC_FAIL (timed out, message in x->err), NNC_SILENT. */
static int s_wait(nnc_ctx *x, int (*done)(json_t *c), double timeout_s, const char *what)
{
    if (!(timeout_s >= 0) || timeout_s > S_WAIT_MAX_S)
        timeout_s = S_WAIT_MAX_S;
    double end = nn_now_s() + timeout_s;
    for (;;) {
        int rc;
        json_t *c = s_status(x, &rc);
        if (!c)
            return rc;
        int ok = done(c);
        json_decref(c);
        if (ok)
            return NNC_OK;
        if (nn_quitting())
            return NNC_SILENT;
        if (nn_now_s() >= end) {
            snprintf(x->err, sizeof x->err, "%s: %s not finished within the timeout (%g s)", nn_conn_cmd(x->c),
                     what, timeout_s);
            return NNC_FAIL;
        }
        struct timespec ts = { 0, (long)(S_POLL_S * 1e9) };
        nanosleep(&ts, NULL);
    }
}

static int s_not_withdrawing(json_t *c) { return strcmp(s_state(c), "withdrawing") != 0; }
static int s_not_moving(json_t *c) { return !json_is_true(json_object_get(c, "moving")); }
/* The Z limits in Nanonis' convention (hi >= lo, both within [-range, 0]). */
static int s_limits(nnc_ctx *x, json_t *c, double *hi, double *lo, double *range)
{
    int rc;
    static const char *const names[] = { "ctrl_piezo_range_m" };
    json_t *v = nnc_get(x, names, 1, &rc);
    if (!v)
        return rc;
    *range = nnc_num(v, "ctrl_piezo_range_m");
    json_decref(v);
    (void)c;
    pthread_mutex_lock(&s_mu);
    *hi = m.limits_set ? m.z_hi_m : 0.0;
    *lo = m.limits_set ? m.z_lo_m : -*range;
    pthread_mutex_unlock(&s_mu);
    return NNC_OK;
}

/* Z (Nanonis) to the piezo: feedback off, the piezo to -z. */
static int s_zpos(nnc_ctx *x, double z, const char *arg)
{
    double hi = 0, lo = 0, range = 0;
    int rc = s_limits(x, NULL, &hi, &lo, &range);
    if (rc)
        return rc;
    if (!isfinite(z) || z > hi + 1e-15 || z < lo - 1e-15) {
        snprintf(x->err, sizeof x->err, "%s %g: must be in [%g, %g] m (the Z limits: 0 is fully retracted, "
                 "negative toward the sample)", arg, z, lo, hi);
        return NNC_FAIL;
    }
    return s_cmd(x, json_pack("{s:s,s:f}", "cmd", "z", "z_m", fmin(fmax(-z, 0.0), range)));
}

/* ---- ZCtrl -------------------------------------------------------------------------------------------- */

static int h_zc_onoff_set(nnc_ctx *x)
{
    uint32_t on = nn_get_u32(&x->r, "Z-Controller status");
    if (nnc_args_done(x))
        return NNC_FAIL;
    if (on > 1) {
        snprintf(x->err, sizeof x->err, "Z-Controller status %u: must be 0 (off) or 1 (on)", on);
        return NNC_FAIL;
    }
    int rc = s_cmd(x, json_pack("{s:s,s:b}", "cmd", "feedback", "on", (int)on));
    if (rc || on)
        return rc;
    pthread_mutex_lock(&s_mu);
    double lift = m.tip_lift_m;
    pthread_mutex_unlock(&s_mu);
    if (lift == 0)
        return NNC_OK;
    double z = 0; /* the tip lift: Z up by it (clamped at the piezo's ends) */
    if ((rc = s_status_num(x, "piezo_z_m", &z)))
        return rc;
    z = -z + lift;
    double hi = 0, lo = 0, range = 0;
    if ((rc = s_limits(x, NULL, &hi, &lo, &range)))
        return rc;
    return s_zpos(x, fmin(fmax(z, lo), hi), "Z position after the tip lift (m)");
}

static int h_zc_onoff_get(nnc_ctx *x)
{
    double on = 0;
    int rc = s_status_num(x, "feedback", &on);
    if (!rc)
        nn_put_u32(x->o, on == 1);
    return rc;
}

static int h_zc_zpos_set(nnc_ctx *x)
{
    float z = nn_get_f32(&x->r, "Z position (m)");
    return nnc_args_done(x) ? NNC_FAIL : s_zpos(x, z, "Z position (m)");
}

static int s_put_field(nnc_ctx *x, const char *key, double scale)
{
    double v = 0;
    int rc = s_status_num(x, key, &v);
    if (!rc)
        nn_put_f32(x->o, (float)(scale * v));
    return rc;
}

static int h_zc_zpos_get(nnc_ctx *x) { return s_put_field(x, "piezo_z_m", -1.0); }

static int h_zc_setpnt_set(nnc_ctx *x)
{
    float v = nn_get_f32(&x->r, "Z-Controller setpoint");
    if (nnc_args_done(x))
        return NNC_FAIL;
    if (!isfinite(v) || fabsf(v) > 100.f) {
        snprintf(x->err, sizeof x->err, "Z-Controller setpoint %g: must be in [-100, 100] (the unit of "
                 "ctrl_setpoint_unit: N or V)", (double)v);
        return NNC_FAIL;
    }
    return s_cmd(x, json_pack("{s:s,s:f}", "cmd", "feedback", "setpoint", (double)v));
}

static int h_zc_setpnt_get(nnc_ctx *x) { return s_put_field(x, "setpoint/value", 1.0); }

/* Gains: P in m/N, I in m/(N·s) (vafm's), the time constant T = P/I as the spec defines it (I = P/T). */
static int h_zc_gain_set(nnc_ctx *x)
{
    float p = nn_get_f32(&x->r, "P-gain");
    float t = nn_get_f32(&x->r, "Time constant (s)");
    float i = nn_get_f32(&x->r, "I-gain");
    if (nnc_args_done(x))
        return NNC_FAIL;
    if (!isfinite(p) || p < 0)
        return nnc_fail(x, "%s: must be a finite number >= 0 (m/N)", "P-gain");
    if (!isfinite(t) || t < 0)
        return nnc_fail(x, "%s: must be a finite number >= 0", "Time constant (s)");
    if (!isfinite(i) || i < 0)
        return nnc_fail(x, "%s: must be a finite number >= 0 (m/(N s))", "I-gain");
    double ig = i > 0 ? (double)i : t > 0 ? (double)p / (double)t : 0.0;
    if (!(ig > 0))
        return nnc_fail(x, "%s: the integral gain must be > 0 (give I-gain, or P-gain and a Time constant)",
                        "I-gain");
    return s_cmd(x, json_pack("{s:s,s:f,s:f}", "cmd", "feedback", "p_m_per_N", (double)p, "i_m_per_N_s", ig));
}

static int h_zc_gain_get(nnc_ctx *x)
{
    int rc;
    json_t *c = s_status(x, &rc);
    if (!c)
        return rc;
    json_t *g = json_object_get(c, "gains");
    double p = nnc_num(g, "p_m_per_N"), i = nnc_num(g, "i_m_per_N_s"), tau = nnc_num(g, "tau_s");
    double fs = nnc_num(c, "sample_rate_Hz");
    json_decref(c);
    if (!(i > 0)) { /* vafm's default: the integral gain from the time constant, 1/(k·τ), τ = 10 samples */
        static const char *const names[] = { "k_N_per_m" };
        json_t *v = nnc_get(x, names, 1, &rc);
        if (!v)
            return rc;
        double k = nnc_num(v, "k_N_per_m");
        json_decref(v);
        i = 1.0 / (k * (tau > 0 ? tau : 10.0 / fs));
    }
    nn_put_f32(x->o, (float)p);
    nn_put_f32(x->o, (float)(i > 0 ? p / i : 0.0));
    nn_put_f32(x->o, (float)i);
    return NNC_OK;
}

static int h_zc_withdraw(nnc_ctx *x)
{
    uint32_t wait = nn_get_u32(&x->r, "Wait until finished");
    int32_t tmo = nn_get_i32(&x->r, "Timeout (ms)");
    if (nnc_args_done(x))
        return NNC_FAIL;
    int rc = s_cmd(x, json_pack("{s:s,s:i}", "cmd", "withdraw", "motor_steps", 0));
    if (rc || !wait)
        return rc;
    return s_wait(x, s_not_withdrawing, tmo < 0 ? -1.0 : tmo / 1000.0, "the withdraw");
}

static int h_zc_limits_set(nnc_ctx *x)
{
    float hi = nn_get_f32(&x->r, "Z high limit (m)");
    float lo = nn_get_f32(&x->r, "Z low limit (m)");
    if (nnc_args_done(x))
        return NNC_FAIL;
    double h0 = 0, l0 = 0, range = 0;
    int rc = s_limits(x, NULL, &h0, &l0, &range);
    if (rc)
        return rc;
    if (!isfinite(hi) || !isfinite(lo) || hi > 0 || lo < -range * (1 + 1e-6) || lo > hi) {
        snprintf(x->err, sizeof x->err, "Z high limit (m) %g, Z low limit (m) %g: must satisfy -%g <= low <= "
                 "high <= 0 (the piezo range; 0 fully retracted)", (double)hi, (double)lo, range);
        return NNC_FAIL;
    }
    pthread_mutex_lock(&s_mu);
    m.limits_set = 1;
    m.z_hi_m = hi;
    m.z_lo_m = lo;
    pthread_mutex_unlock(&s_mu);
    return NNC_OK;
}

static int h_zc_limits_get(nnc_ctx *x)
{
    double hi = 0, lo = 0, range = 0;
    int rc = s_limits(x, NULL, &hi, &lo, &range);
    if (rc)
        return rc;
    nn_put_f32(x->o, (float)hi);
    nn_put_f32(x->o, (float)lo);
    return NNC_OK;
}

/* Off (1), On (2), Hold (3), switching off (4), Safe Tip event (5: vafm's crash), withdrawing (6). */
static int h_zc_status(nnc_ctx *x)
{
    int rc;
    json_t *c = s_status(x, &rc);
    if (!c)
        return rc;
    const char *s = s_state(c);
    uint16_t v = !strcmp(s, "withdrawing") ? 6 : !strcmp(s, "crashed") ? 5
                 : json_is_true(json_object_get(c, "feedback")) ? 2 : 1;
    json_decref(c);
    nn_put_u16(x->o, v);
    return NNC_OK;
}

S_PROPS(s_lift, NNF_F32(s_values, "TipLift (m)", tip_lift_m, NNF_RANGE, -1e-4, 1e-4, "must be in [-0.0001, 0.0001] m"));
S_PROPS(s_delay, NNF_TIME(s_values, "Z-Controller switch off delay (s)", switch_off_delay_s));

static int h_zc_home(nnc_ctx *x)
{
    double z = 0;
    int rc = s_status_num(x, "piezo_z_m", &z);
    if (rc)
        return rc;
    z = -z;
    pthread_mutex_lock(&s_mu);
    double target = m.home_relative ? z + m.home_m : m.home_m;
    pthread_mutex_unlock(&s_mu);
    return s_zpos(x, target, "the home position (m)");
}

S_PROPS(s_home, NNF_ROW(NNF_U16, s_values, "Relative or Absolute", home_relative, NNF_RANGE, NNF_IS2, 1, 2, 0,
                        "must be 0 (no change), 1 (absolute) or 2 (relative)"),
        NNF_F32(s_values, "Home position (m)", home_m, NNF_RANGE, -1e-4, 1e-4, "must be in [-1e-4, 1e-4] m"));

static double s_f64(nnc_ctx *x, const char *arg)
{
    uint32_t hi = nn_get_u32(&x->r, arg), lo = nn_get_u32(&x->r, arg);
    uint64_t b = (uint64_t)hi << 32 | lo;
    double v;
    memcpy(&v, &b, sizeof v);
    return v;
}

/* ---- Motor: the coarse Z motor (vafm has no coarse X/Y) ------------------------------------------------- */

static int s_group(nnc_ctx *x, uint32_t g)
{
    if (g > 5) {
        snprintf(x->err, sizeof x->err, "Group %u: must be in [0, 5]", g);
        return NNC_FAIL;
    }
    return NNC_OK;
}

/* Up by n steps (Z+): the controller's withdraw (feedback off, piezo retracted, then the motor). */
static int s_motor_up(nnc_ctx *x, long long n, uint32_t wait)
{
    int rc = s_cmd(x, json_pack("{s:s,s:I}", "cmd", "withdraw", "motor_steps", (json_int_t)n));
    if (rc || !wait)
        return rc;
    return s_wait(x, s_not_withdrawing, -1, "the motor's move");
}

static int h_mo_start(nnc_ctx *x)
{
    uint32_t dir = nn_get_u32(&x->r, "Direction");
    unsigned steps = nn_get_u16(&x->r, "Number of steps");
    uint32_t grp = nn_get_u32(&x->r, "Group");
    uint32_t wait = nn_get_u32(&x->r, "Wait until finished");
    if (nnc_args_done(x) || s_group(x, grp))
        return NNC_FAIL;
    if (dir > 5) {
        snprintf(x->err, sizeof x->err, "Direction %u: must be 0 (X+), 1 (X-), 2 (Y+), 3 (Y-), 4 (Z+) or 5 (Z-)",
                 dir);
        return NNC_FAIL;
    }
    if (dir < 4)
        return nnc_fail(x, "Direction %s: vafm's coarse motor moves in Z only (4 Z+, away from the sample)",
                        (const char *[]){ "0 (X+)", "1 (X-)", "2 (Y+)", "3 (Y-)" }[dir]);
    if (dir == 5)
        return nnc_fail(x, "%s", "Direction 5 (Z-): vafm's motor approaches the sample only under the "
                                 "auto-approach (AutoApproach.OnOffSet 1), which watches the setpoint");
    return s_motor_up(x, steps, wait);
}

static int h_mo_closed_loop(nnc_ctx *x)
{
    uint32_t absrel = nn_get_u32(&x->r, "Absolute/relative");
    static const char *const tn[3] = { "Target X(m)", "Target Y(m)", "Target Z(m)" };
    double t[3];
    for (int i = 0; i < 3; i++)
        t[i] = s_f64(x, tn[i]);
    uint32_t wait = nn_get_u32(&x->r, "Wait until finished");
    uint32_t grp = x->r.off < x->r.n ? nn_get_u32(&x->r, "Group") : 0; /* nanonis_spm sends no Group */
    if (nnc_args_done(x) || s_group(x, grp))
        return NNC_FAIL;
    if (absrel > 1) {
        snprintf(x->err, sizeof x->err, "Absolute/relative %u: must be 0 (relative) or 1 (absolute)", absrel);
        return NNC_FAIL;
    }
    if (!isfinite(t[0]) || !isfinite(t[1]) || !isfinite(t[2]))
        return nnc_fail(x, "%s: must be finite", "Target X(m), Target Y(m), Target Z(m)");
    if (t[0] != 0 || t[1] != 0)
        return nnc_fail(x, "%s: vafm's coarse motor moves in Z only (X and Y targets must be 0)",
                        t[0] != 0 ? tn[0] : tn[1]);
    double z = 0;
    int rc = s_status_num(x, "motor_z_m", &z);
    if (rc)
        return rc;
    static const char *const names[] = { "ctrl_motor_step_m" };
    json_t *v = nnc_get(x, names, 1, &rc);
    if (!v)
        return rc;
    double step = nnc_num(v, "ctrl_motor_step_m");
    json_decref(v);
    double dz = absrel ? t[2] - z : t[2];
    if (dz < 0)
        return nnc_fail(x, "%s: below the motor's position; vafm's motor approaches the sample only under the "
                           "auto-approach (AutoApproach.OnOffSet 1)", tn[2]);
    double n = step > 0 ? round(dz / step) : 0;
    if (n > 100000)
        return nnc_fail(x, "%s: more than 100000 motor steps away", tn[2]);
    return n >= 1 ? s_motor_up(x, (long long)n, wait) : nnc_ping(x);
}

/* Stops an auto-approach in progress (a withdraw of 0 steps aborts it); else nothing to stop. */
static int s_stop_approach(nnc_ctx *x)
{
    int rc;
    json_t *c = s_status(x, &rc);
    if (!c)
        return rc;
    int approaching = !strcmp(s_state(c), "approaching");
    json_decref(c);
    return approaching ? s_cmd(x, json_pack("{s:s,s:i}", "cmd", "withdraw", "motor_steps", 0)) : NNC_OK;
}

static int h_mo_stop(nnc_ctx *x) { return s_stop_approach(x); }

static int h_mo_pos(nnc_ctx *x)
{
    uint32_t grp = 0;
    if (x->r.n > 0) { /* the spec's Group and Timeout; the public clients send none */
        grp = nn_get_u32(&x->r, "Group");
        (void)nn_get_u32(&x->r, "Timeout");
    }
    if (nnc_args_done(x) || s_group(x, grp))
        return NNC_FAIL;
    double z = 0;
    int rc = s_status_num(x, "motor_z_m", &z);
    if (rc)
        return rc;
    nn_put_f64(x->o, 0);
    nn_put_f64(x->o, 0);
    nn_put_f64(x->o, z);
    return NNC_OK;
}

/* Step counter Z: the motor's net steps from its start position (ctrl_motor_z0_m), up positive; X, Y 0. */
static int h_mo_steps(nnc_ctx *x)
{
    uint32_t r[3];
    static const char *const rn[3] = { "Reset X", "Reset Y", "Reset Z" };
    for (int i = 0; i < 3; i++)
        r[i] = nn_get_u32(&x->r, rn[i]);
    if (nnc_args_done(x))
        return NNC_FAIL;
    double z = 0;
    int rc = s_status_num(x, "motor_z_m", &z);
    if (rc)
        return rc;
    static const char *const names[] = { "ctrl_motor_z0_m", "ctrl_motor_step_m" };
    json_t *v = nnc_get(x, names, 2, &rc);
    if (!v)
        return rc;
    double z0 = nnc_num(v, "ctrl_motor_z0_m"), step = nnc_num(v, "ctrl_motor_step_m");
    json_decref(v);
    /* the net steps from the motor's start, up (Z+) positive (status.ctrl.motor_steps counts only the
     * engage's steps down) */
    double q = step > 0 ? round((z - z0) / step) : 0;
    long long steps = isfinite(q) && fabs(q) < 2e9 ? (long long)q : 0;
    pthread_mutex_lock(&s_mu);
    long long n = steps - m.step_offset;
    if (r[2])
        m.step_offset = steps;
    pthread_mutex_unlock(&s_mu);
    nn_put_i32(x->o, 0);
    nn_put_i32(x->o, 0);
    nn_put_i32(x->o, (int32_t)n);
    return NNC_OK;
}

S_PROPS(s_freq, { .type = NNF_F32, .name = "Frequency (Hz)", .off = offsetof(s_values, motor_freq_Hz), .check = NNF_RANGE,
          .lo_open = 1, .lo = 0, .hi = 1e5, .must = "must be in (0, 1e5] Hz" },
        NNF_F32(s_values, "Amplitude (V)", motor_amp_V, NNF_RANGE, 0, 1000, "must be in [0, 1000] V"),
        NNF_ROW(NNF_U16, s_values, "Axis", motor_freq_Hz, NNF_RANGE, NNF_NONE, 0, 3, NNF_NO_NC,
                "must be 0 (all), 1 (X), 2 (Y) or 3 (Z)")); /* the axis: checked, not kept */
static const nnc_props s_freq_get = { &s_mu, &m, s_freq_f, 2 }; /* the Get: frequency and amplitude */

static int h_mo_freq_get(nnc_ctx *x)
{
    if (x->r.n > 0) /* the spec's Axis; the public clients send none */
        (void)nn_get_u16(&x->r, "Axis");
    int rc = nnc_args_done(x) ? NNC_FAIL : nnc_ping(x);
    return rc ? rc : nnc_props_put(x, &s_freq_get);
}

/* ---- AutoApproach: the controller's engage -------------------------------------------------------------- */

static int h_aa_onoff_set(nnc_ctx *x)
{
    unsigned on = nn_get_u16(&x->r, "On/Off");
    if (nnc_args_done(x))
        return NNC_FAIL;
    if (on > 1) {
        snprintf(x->err, sizeof x->err, "On/Off %u: must be 0 (stop) or 1 (start)", on);
        return NNC_FAIL;
    }
    return on ? s_cmd(x, json_pack("{s:s}", "cmd", "engage")) : s_stop_approach(x);
}

static int h_aa_onoff_get(nnc_ctx *x)
{
    int rc;
    json_t *c = s_status(x, &rc);
    if (!c)
        return rc;
    nn_put_u16(x->o, !strcmp(s_state(c), "approaching"));
    json_decref(c);
    return NNC_OK;
}

/* ---- FolMe: XY moves ---------------------------------------------------------------------------------- */

static int h_fm_xy_set(nnc_ctx *x)
{
    double xm = s_f64(x, "X (m)"), ym = s_f64(x, "Y (m)");
    uint32_t wait = nn_get_u32(&x->r, "Wait end of move");
    if (nnc_args_done(x))
        return NNC_FAIL;
    if (!isfinite(xm) || !isfinite(ym))
        return nnc_fail(x, "%s: must be finite", isfinite(xm) ? "Y (m)" : "X (m)");
    pthread_mutex_lock(&s_mu);
    double v = m.folme_custom ? m.folme_speed : 0;
    pthread_mutex_unlock(&s_mu);
    json_t *req = json_pack("{s:s,s:f,s:f}", "cmd", "move", "x_m", xm, "y_m", ym);
    if (v > 0)
        json_object_set_new(req, "speed_m_per_s", json_real(v));
    int rc = s_cmd(x, req);
    if (rc || !wait)
        return rc;
    return s_wait(x, s_not_moving, -1, "the move");
}

static int h_fm_xy_get(nnc_ctx *x)
{
    (void)nn_get_u32(&x->r, "Wait for newest data");
    static const char *const keys[] = { "x_m", "y_m" };
    double xy[2] = { 0, 0 };
    int rc = nnc_args_done(x) ? NNC_FAIL : s_status_nums(x, keys, 2, xy);
    if (rc)
        return rc;
    nn_put_f64(x->o, xy[0]);
    nn_put_f64(x->o, xy[1]);
    return NNC_OK;
}

S_PROPS(s_speed, { .type = NNF_F32, .name = "Speed (m/s)", .off = offsetof(s_values, folme_speed),
          .check = NNF_RANGE, .lo_open = 1, .lo = 0, .hi = 0.01, .must = "must be in (0, 0.01] m/s" },
        NNF_ROW(NNF_U32, s_values, "Custom speed", folme_custom, NNF_RANGE, NNF_SAME, 0, 1, NNF_NO_NC,
                "must be 0 (the scan speed) or 1 (custom)"));

static int h_fm_speed_get(nnc_ctx *x)
{
    static const char *const names[] = { "ctrl_xy_speed_m_per_s" };
    int rc;
    json_t *v = nnc_get(x, names, 1, &rc);
    if (!v)
        return rc;
    double scan = nnc_num(v, "ctrl_xy_speed_m_per_s");
    json_decref(v);
    pthread_mutex_lock(&s_mu);
    nn_put_f32(x->o, m.folme_custom ? m.folme_speed : (float)scan);
    nn_put_u32(x->o, (uint32_t)m.folme_custom);
    pthread_mutex_unlock(&s_mu);
    return NNC_OK;
}

/* Stop: a move to where the tip is now. */
static int h_fm_stop(nnc_ctx *x)
{
    static const char *const keys[] = { "moving", "x_m", "y_m" };
    double v[3] = { 0, 0, 0 };
    int rc = s_status_nums(x, keys, 3, v);
    if (rc || v[0] != 1)
        return rc;
    return s_cmd(x, json_pack("{s:s,s:f,s:f}", "cmd", "move", "x_m", v[1], "y_m", v[2]));
}

const nnc_cmd nnc_ctrl_cmds[] = {
    { "ZCtrl.OnOffSet", h_zc_onoff_set, "", NULL },
    { "ZCtrl.OnOffGet", h_zc_onoff_get, "I", NULL },
    { "ZCtrl.ZPosSet", h_zc_zpos_set, "", NULL },
    { "ZCtrl.ZPosGet", h_zc_zpos_get, "f", NULL },
    { "ZCtrl.SetpntSet", h_zc_setpnt_set, "", NULL },
    { "ZCtrl.SetpntGet", h_zc_setpnt_get, "f", NULL },
    { "ZCtrl.GainSet", h_zc_gain_set, "", NULL },
    { "ZCtrl.GainGet", h_zc_gain_get, "fff", NULL },
    { "ZCtrl.Withdraw", h_zc_withdraw, "", NULL },
    { "ZCtrl.LimitsSet", h_zc_limits_set, "", NULL },
    { "ZCtrl.LimitsGet", h_zc_limits_get, "ff", NULL },
    { "ZCtrl.StatusGet", h_zc_status, "H", NULL },
    { "ZCtrl.TipLiftSet", nnc_props_set, "", &s_lift },
    { "ZCtrl.TipLiftGet", nnc_props_get, "f", &s_lift },
    { "ZCtrl.Home", h_zc_home, "", NULL },
    { "ZCtrl.HomePropsSet", nnc_props_set, "", &s_home },
    { "ZCtrl.HomePropsGet", nnc_props_get, "Hf", &s_home },
    { "ZCtrl.SwitchOffDelaySet", nnc_props_set, "", &s_delay },
    { "ZCtrl.SwitchOffDelayGet", nnc_props_get, "f", &s_delay },
    { "Motor.StartMove", h_mo_start, "", NULL },
    { "Motor.StartClosedLoop", h_mo_closed_loop, "", NULL },
    { "Motor.StopMove", h_mo_stop, "", NULL },
    { "Motor.PosGet", h_mo_pos, "ddd", NULL },
    { "Motor.StepCounterGet", h_mo_steps, "iii", NULL },
    { "Motor.FreqAmpGet", h_mo_freq_get, "ff", NULL },
    { "Motor.FreqAmpSet", nnc_props_set, "", &s_freq },
    { "AutoApproach.Open", nnc_ping_only, "", NULL },
    { "AutoApproach.OnOffSet", h_aa_onoff_set, "", NULL },
    { "AutoApproach.OnOffGet", h_aa_onoff_get, "H", NULL },
    { "FolMe.XYPosSet", h_fm_xy_set, "", NULL },
    { "FolMe.XYPosGet", h_fm_xy_get, "dd", NULL },
    { "FolMe.SpeedSet", nnc_props_set, "", &s_speed },
    { "FolMe.SpeedGet", h_fm_speed_get, "fI", NULL },
    { "FolMe.Stop", h_fm_stop, "", NULL },
};
const size_t nnc_ctrl_ncmds = sizeof nnc_ctrl_cmds / sizeof nnc_ctrl_cmds[0];
