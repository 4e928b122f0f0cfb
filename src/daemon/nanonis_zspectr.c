/* SPDX-License-Identifier: MIT */
/*
 * Nanonis ZSpectr: Z spectroscopy, a force curve on vafm's physics (nanonis_cmds.h; docs/nanonis.md).
 *
 * The properties (channels, points, sweeps, range, timing, auto-retract) are module state shared by all
 * connections. ZSpectr.Start turns them into one `curve` of the scene per sweep (the scene's values set for
 * the sweep and restored after it), collects the run's samples from the stream (nanonis.c's collector) and
 * averages each point over its integration time after its settling time; forward and backward sweeps are
 * the curve's approach and retract. The other timings make the curve a segment list (see "the timings"
 * below). ZSpectr.Stop aborts the run in progress.
 */
#include <math.h>
#include <pthread.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "daemon/nanonis_cmds.h"
#include "vafm/segments.h"

/* ---- ZSpectr: properties -------------------------------------------------------------------------- */
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

/* The parameters ZSpectr.Start returns, in this order: the fixed ones, then the others. */
static const char *const s_fixed_params[] = { "Z offset (m)", "Z sweep distance (m)" };
static const char *const s_params[] = { "Settling time (s)", "Integration time (s)", "Number of sweeps",
                                        "Run ID", "Curve index", "Auto-retract triggered" };
#define S_NFIXED 2
#define S_NPARAMS 6

/* The Get/Set pairs: each a table of its arguments (nanonis_cmds.h, nnc_props_get/set). */
#define S_T nnc_state
#define S_PROPS(name, ...)                                                                                   \
    static const nnc_field name##_f[] = { __VA_ARGS__ };                                                     \
    _Static_assert(sizeof name##_f / sizeof name##_f[0] <= NNC_MAX_FIELDS, #name ": too many fields");      \
    static const nnc_props name = { &nnc_mu, &nnc_m, name##_f, (int)(sizeof name##_f / sizeof name##_f[0]) }
#define S_CMP(mem) /* a comparison: 0 >, 1 <, 2 no change */                                                  \
    NNF_ROW(NNF_U16, S_T, "Comparison", mem, NNF_RANGE, NNF_SAME, 0, 1, 2, "must be 0 (>), 1 (<) or 2 (no change)")
#define S_SIGNAL(mem) NNF_ROW(NNF_I32, S_T, "Signal index", mem, NNF_SIGNAL, NNF_SAME, 0, 0, -1, "")
#define S_THRESHOLD(mem) NNF_F32(S_T, "Threshold", mem, NNF_ANY, 0, 0, "must be a finite number")

S_PROPS(s_status, NNF_ROW(NNF_U32, S_T, "Status", running, NNF_ANY, NNF_NONE, 0, 0, NNF_NO_NC, ""));
/* PropsGet's layout; PropsSet reads the same less the strings */
S_PROPS(s_props, NNF_FLAG(S_T, "Backward sweep", backward),
        NNF_ROW(NNF_I32, S_T, "Number of points", points, NNF_RANGE, NNF_SAME, 1, NNC_MAX_POINTS, 0,
                "must be in [1, 100000] (0: no change)"),
        NNF_STRS(s_params, S_NPARAMS), NNF_STRS(s_fixed_params, S_NFIXED),
        NNF_ROW(NNF_U16, S_T, "Number of sweeps", sweeps, NNF_RANGE, NNF_SAME, 1, NNC_MAX_SWEEPS, 0,
                "must be in [1, 1000] (0: no change)"),
        NNF_FLAG(S_T, "Autosave", autosave), NNF_FLAG(S_T, "Show save dialog", show_dialog),
        NNF_FLAG(S_T, "Save all", save_all));
_Static_assert(NNC_MAX_POINTS == 100000 && NNC_MAX_SWEEPS == 1000, "the ranges' messages above");
S_PROPS(s_adv, NNF_TIME(S_T, "Time between forward and backward sweep (s)", t_fwd_bwd_s),
        NNF_FLAG(S_T, "Record final Z", record_final_z), NNF_FLAG(S_T, "Lockin Run", lockin_run),
        NNF_FLAG(S_T, "Reset Z", reset_z));
S_PROPS(s_range, NNF_F32(S_T, "Z offset (m)", z_offset_m, NNF_RANGE, -1e-4, 1e-4, "must be in [-1e-4, 1e-4] m"),
        NNF_F32(S_T, "Z sweep distance (m)", z_distance_m, NNF_MAGNITUDE, 1e-12, 1e-4,
                "its magnitude must be in [1e-12, 1e-4] m"));
S_PROPS(s_timing, NNF_TIME(S_T, "Z averaging time (s)", t_zavg_s),
        NNF_TIME(S_T, "Initial settling time (s)", t_init_settle_s),
        { .type = NNF_F32, .name = "Maximum slew rate (V/s)", .off = offsetof(S_T, slew_V_per_s),
          .check = NNF_RANGE, .lo_open = 1, .lo = 0, .hi = INFINITY, .must = "must be a positive number" },
        NNF_TIME(S_T, "Settling time (s)", t_settle_s),
        { .type = NNF_F32, .name = "Integration time (s)", .off = offsetof(S_T, t_integr_s), .check = NNF_RANGE,
          .lo_open = 1, .lo = 0, .hi = 1000,
          .must = "must be in (0, 1000] s (each point's samples are averaged over it)" },
        NNF_TIME(S_T, "End settling time (s)", t_end_settle_s), NNF_TIME(S_T, "Z control time (s)", t_zctrl_s));
S_PROPS(s_rdelay, NNF_TIME(S_T, "Retract delay (s)", retract_delay_s));
S_PROPS(s_retract, NNF_FLAG(S_T, "Enable", ar_enable), S_THRESHOLD(ar_threshold), S_SIGNAL(ar_signal),
        S_CMP(ar_cmp));
/* Set counts the condition from "no change", Get from -No- */
S_PROPS(s_retract2, NNF_ROW(NNF_I32, S_T, "2nd condition", ar2_cond, NNF_RANGE, NNF_MINUS1, 1, 4, 0,
                            "must be 0 (no change), 1 (-No-), 2 (OR), 3 (AND) or 4 (THEN)"),
        S_THRESHOLD(ar2_threshold), S_SIGNAL(ar2_signal), S_CMP(ar2_cmp));

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

/* ---- the timings (ZSpectr.TimingSet) ------------------------------------------------------------------
 * Settling and integration time shape each point of the plain curve. The others give the sweep phases a
 * plain curve does not have, so a sweep that needs one runs a segment list (docs/instrument.md "Segments")
 * instead: the move from the current Z to the sweep's start at the maximum slew rate, a pause of the
 * initial settling time there, the forward sweep (an extend by the sweep distance, the auto-retract as its
 * trigger), the dwell, the backward sweep (a retract back to the start: a height trigger), a pause of the
 * end settling time and, where the controller was engaged, its feedback switched back on for the Z control
 * time (a constant-force pause at its setpoint). The Z averaging time is spent before: the engaged
 * controller's gap averaged over it (the feedback on) gives the current Z. A list's curve is logged like
 * any curve, with its own list (wire.md `curve`).
 * All of them 0 (and the move shorter than one sample): the plain curve, as before. */

#define S_M_PER_V_DIV 20.0    /* the slew rate's volts: the piezo range spans the Z output's 20 V (±10 V) */

typedef struct s_plan {
    json_t *list;       /* the segment list, or NULL: the plain curve */
    int fwd, bwd;       /* the positions of the forward sweep's extend and the backward sweep's retract */
    double run_start_m; /* the run's start height (the current Z, where the move begins) */
    double extra_s;     /* the time the list adds to the plain curve's */
    double samples;     /* the output samples it adds */
    double rate_Hz;     /* the output rate of the pauses after the sweeps (end settling, Z control): one
                           sample a point time, the run's rate / its samples a point */
} s_plan;

/* The engaged controller's gap averaged over t s (the feedback on), polled every 2 ms: *gap. */
static int s_zavg(nnc_ctx *x, double t, double *gap)
{
    double sum = 0, end = nn_now_s() + t;
    long n = 0;
    int rc = NNC_OK;
    do {
        json_t *st = NULL;
        if ((rc = nnc_call(x, json_pack("{s:s}", "cmd", "status"), &st)))
            return rc;
        double g = nnc_num(json_object_get(st, "ctrl"), "gap_m");
        json_decref(st);
        if (isfinite(g))
            sum += g, n++;
        pthread_mutex_lock(&nnc_mu);
        int stop = nnc_m.stop;
        pthread_mutex_unlock(&nnc_mu);
        if (stop || nn_quitting())
            break;
        struct timespec ts = { 0, 2000000 };
        nanosleep(&ts, NULL);
    } while (nn_now_s() < end);
    if (n)
        *gap = sum / (double)n;
    return rc;
}

/* A pause of dur_s at rate_Hz (0: the run's, fs) (extra: more of its keys, consumed); added: it adds to the
 * plain curve's time. */
static void s_pause(json_t *list, s_plan *pl, double fs, double rate_Hz, double dur_s, json_t *extra, int added)
{
    json_t *g = json_pack("{s:s,s:f}", "kind", "pause", "duration_s", dur_s);
    if (rate_Hz > 0)
        json_object_set_new(g, "sample_rate_Hz", json_real(rate_Hz));
    if (extra)
        json_object_update(g, extra);
    json_decref(extra);
    json_array_append_new(list, g);
    pl->extra_s += added ? dur_s : 0;
    pl->samples += added ? dur_s * (rate_Hz > 0 ? rate_Hz : fs) + 2 : 2; /* the dwell's are counted already */
}

/* The sweep's plan: a segment list when a timing asks for one (pl->list), else the plain curve. vals: the
 * sweep's scene values (its trigger, rate); kpt: its samples a point; hc: the current Z; start: the sweep's.
 * The pauses after the sweeps (end settling, Z control) are recorded at one sample a point time (decimated by
 * kpt: a paced run still takes their simulated time, the physics runs at the run's rate, the points are cut
 * from the sweeps' samples only), so long ones do not fill the 2^20 samples. The move and the initial
 * settling keep the run's rate: a logged curve's time must start within one mean sample interval of 0
 * (hdf5.md), which a decimated first segment breaks. */
static void s_plan_make(const nnc_state *p, json_t *vals, double kpt, double hc, double start, double dist,
                        double range_m, int engaged, double setpoint_N, s_plan *pl)
{
    memset(pl, 0, sizeof *pl);
    pl->run_start_m = start;
    double tp = (double)p->t_settle_s + (double)p->t_integr_s, v = dist / (tp * p->points);
    double fs = nnc_num(vals, "sample_rate_Hz"), dwell = nnc_num(vals, "dwell_s");
    pl->rate_Hz = fs / fmin(fmax(kpt, 1), VAFM_SEGMENT_DECIMATION_MAX);
    double v_slew = fmin((double)p->slew_V_per_s * range_m / S_M_PER_V_DIV, 1e3);
    double move = start - hc, t_move = isfinite(v_slew) && v_slew > 0 ? fabs(move) / v_slew : 0;
    int zctrl = engaged && p->t_zctrl_s > 0 && isfinite(setpoint_N);
    if (!(t_move * fs >= 1))
        t_move = 0; /* shorter than one sample: not modelled (the plain curve starts at the start) */
    if (t_move == 0 && p->t_init_settle_s == 0 && p->t_end_settle_s == 0 && !zctrl)
        return;
    json_t *list = json_array();
    if (t_move > 0) { /* from the current Z to the start */
        json_array_append_new(list, json_pack("{s:s,s:f,s:f}", "kind", move > 0 ? "retract" : "extend",
                                              "speed_m_per_s", v_slew, "distance_m", fabs(move)));
        pl->run_start_m = hc;
        pl->extra_s += t_move;
        pl->samples += t_move * fs + 2;
    }
    if (p->t_init_settle_s > 0)
        s_pause(list, pl, fs, 0, p->t_init_settle_s, NULL, 1);
    pl->fwd = (int)json_array_size(list);
    const char *trig = json_string_value(json_object_get(vals, "trigger"));
    int force = trig && !strcmp(trig, "force");
    json_array_append_new(list, json_pack("{s:s,s:f,s:f,s:{s:s,s:s,s:f}}", "kind", "extend", "speed_m_per_s", v,
                                          "distance_m", dist, "trigger", "channel", force ? "force" : "height",
                                          "op", force ? ">" : "<", "value",
                                          nnc_num(vals, force ? "setpoint_N" : "trigger_height_m")));
    if (dwell > 0)
        s_pause(list, pl, fs, 0, dwell, NULL, 0);
    pl->bwd = (int)json_array_size(list);
    json_array_append_new(list, json_pack("{s:s,s:f,s:f,s:{s:s,s:s,s:f}}", "kind", "retract", "speed_m_per_s", v,
                                          "distance_m", dist + 1e-9, "trigger", "channel", "height", "op", ">",
                                          "value", start));
    if (p->t_end_settle_s > 0)
        s_pause(list, pl, fs, pl->rate_Hz, p->t_end_settle_s, NULL, 1);
    if (zctrl) /* the feedback back on: the force held at the controller's setpoint */
        s_pause(list, pl, fs, pl->rate_Hz, p->t_zctrl_s,
                json_pack("{s:s,s:f}", "mode", "force", "hold_force_N", setpoint_N), 1);
    pl->list = list;
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
    json_t *saved = NULL, *vals = NULL, *seg_list = NULL; /* seg_list: the sweep's segment list, or NULL */
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
    int engaged = 0;
    double setpoint_N = NAN, range_m = NAN;
    {   /* the current Z: where the controller is engaged, its gap (the tip above the surface under it) */
        json_t *st = NULL;
        if ((rc = nnc_call(x, json_pack("{s:s}", "cmd", "status"), &st)))
            goto out;
        json_t *c = json_object_get(st, "ctrl");
        json_t *state = json_object_get(c, "state");
        double gap = nnc_num(c, "gap_m");
        engaged = json_is_string(state) && !strcmp(json_string_value(state), "engaged") && isfinite(gap);
        if (engaged)
            start = gap + (double)p.z_offset_m;
        setpoint_N = nnc_num(c, "setpoint_N");
        json_decref(st);
    }
    if (engaged && p.t_zavg_s > 0) { /* the current Z: the gap averaged with the feedback on */
        double gap = start - (double)p.z_offset_m;
        if ((rc = s_zavg(x, p.t_zavg_s, &gap)))
            goto out;
        start = gap + (double)p.z_offset_m;
    }
    {
        static const char *const rn[] = { "ctrl_piezo_range_m" };
        json_t *r = nnc_get(x, rn, 1, &rc);
        if (!r)
            goto out;
        range_m = nnc_num(r, "ctrl_piezo_range_m");
        json_decref(r);
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
    s_plan pl;
    s_plan_make(&p, vals, kpt, start - (double)p.z_offset_m, start, dist, range_m, engaged, setpoint_N, &pl);
    seg_list = pl.list;
    json_object_set_new(vals, "start_height_m", json_real(pl.run_start_m));
    total += pl.samples;
    if (!(total <= (double)VAFMD_NANONIS_MAX_RUN_SAMPLES)) {
        snprintf(x->err, sizeof x->err, "this sweep with its timings would have ~%.3g samples: at most %zu; use "
                 "shorter initial and end settling or Z control times, a faster maximum slew rate, or a lower "
                 "sample_rate_Hz", total, VAFMD_NANONIS_MAX_RUN_SAMPLES);
        rc = NNC_FAIL;
        goto out;
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
            rc = nnc_call(x, json_pack("{s:s,s:I,s:O*}", "cmd", "curve", "index", (json_int_t)index, "segments",
                                       pl.list), &reply);
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
        double expect = 2 * tp * p.points + dwell + pl.extra_s;
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
        int64_t r0 = run.retract_at >= 0 ? run.retract_at : (int64_t)run.n, f0 = 0;
        if (pl.list) { /* a list: its forward extend, what follows it, its backward retract */
            f0 = pl.fwd == 0 ? 0 : run.seg_at[pl.fwd] >= 0 ? run.seg_at[pl.fwd] : (int64_t)run.n;
            turn = run.seg_at[pl.fwd + 1] >= 0 ? run.seg_at[pl.fwd + 1] : (int64_t)run.n;
            r0 = run.seg_at[pl.bwd] >= 0 ? run.seg_at[pl.bwd] : (int64_t)run.n;
        }
        int64_t done_pts = (turn - f0) / K; /* forward points completed */
        if (done_pts < p.points)
            triggered = 1;
        for (int d = 0; d < n_dirs; d++)
            for (int row = 0; row < n_rows; row++) {
                int sig = row == 0 ? 0 : p.chs[row - 1];
                for (size_t i = 0; i < n_cols; i++) {
                    double val;
                    int64_t a, b;
                    if (d == 0) {
                        a = f0 + (int64_t)i * K + Ks;
                        b = f0 + (int64_t)(i + 1) * K;
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
    json_decref(seg_list);
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
    { "ZSpectr.Open", nnc_ping_only, "", NULL },
    { "ZSpectr.Start", h_zs_start, "iiiii", NULL },
    { "ZSpectr.Stop", h_zs_stop, "", NULL },
    { "ZSpectr.StatusGet", nnc_props_get, "I", &s_status },
    { "ZSpectr.ChsSet", h_zs_chs_set, "", NULL },
    { "ZSpectr.ChsGet", h_zs_chs_get, "ii", NULL },
    { "ZSpectr.PropsSet", nnc_props_set, "", &s_props },
    { "ZSpectr.PropsGet", nnc_props_get, "HiiiiiHHHH", &s_props },
    { "ZSpectr.AdvPropsSet", nnc_props_set, "", &s_adv },
    { "ZSpectr.AdvPropsGet", nnc_props_get, "fHHH", &s_adv },
    { "ZSpectr.RangeSet", nnc_props_set, "", &s_range },
    { "ZSpectr.RangeGet", nnc_props_get, "ff", &s_range },
    { "ZSpectr.TimingSet", nnc_props_set, "", &s_timing },
    { "ZSpectr.TimingGet", nnc_props_get, "fffffff", &s_timing },
    { "ZSpectr.RetractDelaySet", nnc_props_set, "", &s_rdelay },
    { "ZSpectr.RetractDelayGet", nnc_props_get, "f", &s_rdelay },
    { "ZSpectr.RetractSet", nnc_props_set, "", &s_retract },
    { "ZSpectr.RetractGet", nnc_props_get, "HfiH", &s_retract },
    { "ZSpectr.Retract2ndSet", nnc_props_set, "", &s_retract2 },
    { "ZSpectr.Retract2ndGet", nnc_props_get, "ifiH", &s_retract2 },
    { "ZSpectr.RetractSecondSet", nnc_props_set, "", &s_retract2 }, /* the spelling nanonis_spm sends */
    { "ZSpectr.RetractSecondGet", nnc_props_get, "ifiH", &s_retract2 },
};
const size_t nnc_zspectr_ncmds = sizeof nnc_zspectr_cmds / sizeof nnc_zspectr_cmds[0];
