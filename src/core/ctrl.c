/* SPDX-License-Identifier: MIT */
/*
 * The always-on controller (vafm/ctrl.h): lifecycle, commands, status, events and the advance that drives the
 * simulation's live scene. Commands set targets and states only; ctrl_loop.c acts on them at the next sample
 * boundary. Everything is allocated in vafm_ctrl_new.
 */
#include <inttypes.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "core/ctrl_impl.h"
#include "core/internal.h"

static int s_live_start(vafm_ctrl *c)
{
    const double gap = c->motor_z - c->piezo_z - c->surface;
    return vafm_sim_live_begin(c->sim, c->cp.stream + c->restarts, gap, vafm_ctrl_loop, c);
}

int vafm_ctrl_new(vafm_ctrl **out, const vafm_params *scene, const vafm_ctrl_params *cp, const vafm_map_spec *map,
                  vafm_error *err)
{
    if (!out || !scene) {
        vafm_err_set(err, VAFM_EINVAL, "", "vafm_ctrl_new: no output or scene given");
        return VAFM_EINVAL;
    }
    *out = NULL;
    vafm_ctrl_params def;
    if (!cp) {
        vafm_ctrl_params_default(&def);
        cp = &def;
    }
    int r = vafm_ctrl_check(cp, scene->k_N_per_m, scene->sensitivity_m_per_V, err);
    if (r)
        return r;
    vafm_ctrl *c = calloc(1, sizeof *c);
    if (!c)
        return VAFM_ENOMEM;
    c->cp = *cp;
    c->map = map;
    c->scene = *scene;
    /* the scene's numerics (time step, contact table) must cover the forces the controller can reach: up to the
     * force limit, and what one sample interval can add past it before the crash is seen */
    c->scene.setpoint_N = fmax(scene->setpoint_N, 2.0 * cp->force_limit_N);
    c->scene.setpoint_V = 0.0;
    c->scene.trigger = VAFM_TRIGGER_FORCE;
    r = vafm_sim_new(&c->sim, &c->scene, err);
    if (r) {
        free(c);
        return r;
    }
    c->Ts = 1.0 / c->scene.sample_rate_Hz;
    c->k = c->scene.k_N_per_m;
    c->invols = c->scene.sensitivity_m_per_V;
    vafm_detector_begin(&c->det, &c->scene, cp->stream ^ VAFM_SIM_LIVE_KEY);
    c->state = VAFM_CTRL_IDLE;
    c->motor_z = c->motor_target = cp->motor_z0_m;
    c->piezo_z = c->z_target = 0.0;
    c->z_speed = cp->z_speed_m_per_s;
    c->xy_speed = cp->xy_speed_m_per_s;
    c->surface = vafm_ctrl_surface(c, 0.0, 0.0);
    c->F_target = NAN;
    c->baseline = 0.0;
    c->base_boot = 1;
    c->crash_force = NAN;
    if (!cp->setpoint_relative)
        c->F_target = vafm_ctrl_setpoint_abs(cp, 0.0, c->k, c->invols, c->scene.baseline_offset_V);
    r = s_live_start(c);
    if (r) {
        if (err)
            *err = *vafm_sim_error(c->sim);
        vafm_sim_destroy(&c->sim);
        free(c);
        return r;
    }
    *out = c;
    return 0;
}

void vafm_ctrl_destroy(vafm_ctrl **c)
{
    if (!c || !*c)
        return;
    vafm_sim_destroy(&(*c)->sim);
    free(*c);
    *c = NULL;
}

static void s_flush(vafm_ctrl *c, vafm_ctrl_sample_fn fn, void *user)
{
    if (c->nblk == 0)
        return;
    if (fn) {
        vafm_ctrl_samples b = { c->nblk, c->sample - c->nblk, c->b_t, c->b_motor, c->b_z, c->b_x, c->b_y, c->b_gap,
                                c->b_defl, c->b_f, c->b_v, c->b_err, c->b_surf, c->b_state };
        fn(user, &b);
    }
    c->nblk = 0;
}

long vafm_ctrl_advance(vafm_ctrl *c, size_t max_samples, vafm_ctrl_sample_fn fn, void *user)
{
    if (!c)
        return VAFM_EINVAL;
    const uint64_t first = c->sample;
    size_t left = max_samples;
    while (left > 0) {
        size_t chunk = VAFM_CTRL_BLOCK - c->nblk;
        if (chunk > left)
            chunk = left;
        const uint64_t before = c->sample;
        int r = vafm_sim_advance(c->sim, chunk, NULL, NULL);
        left -= (size_t)(c->sample - before);
        if (c->nblk == VAFM_CTRL_BLOCK)
            s_flush(c, fn, user);
        if (r < 0) {
            /* the lever restarts at rest where it was, on the next stream (a session stays reproducible) */
            vafm_ctrl_push(c, VAFM_CTRL_EV_SIM_ERROR, r, 0.0);
            c->restarts++;
            s_flush(c, fn, user);
            int r2 = s_live_start(c);
            return r2 ? r2 : r;
        }
        if (r == 0 || c->sample == before)
            break; /* cannot happen: the live scene ends only when told */
    }
    s_flush(c, fn, user);
    return (long)(c->sample - first);
}

double vafm_ctrl_sample_interval_s(const vafm_ctrl *c)
{
    return c ? c->Ts : NAN;
}

const vafm_ctrl_params *vafm_ctrl_params_get(const vafm_ctrl *c)
{
    return c ? &c->cp : NULL;
}

int vafm_ctrl_status_get(const vafm_ctrl *c, vafm_ctrl_status *st)
{
    if (!c || !st)
        return VAFM_EINVAL;
    memset(st, 0, sizeof *st);
    st->state = c->state;
    st->engage_phase = c->phase;
    st->last_fail = c->last_fail;
    st->sample = c->sample;
    st->time_s = c->t0 + (double)(c->sample - c->s0) * c->Ts;
    st->clock_base_s = c->t0;
    st->clock_base_sample = c->s0;
    st->motor_z_m = c->motor_z;
    st->piezo_z_m = c->piezo_z;
    st->x_m = c->x;
    st->y_m = c->y;
    st->target_x_m = c->moving ? c->tx : c->x;
    st->target_y_m = c->moving ? c->ty : c->y;
    st->moving = c->moving;
    st->surface_m = c->surface;
    st->gap_m = c->motor_z - c->piezo_z - c->surface;
    st->in_contact = c->in_contact;
    st->feedback = c->feedback;
    st->saturated = c->saturated;
    st->setpoint_N = c->F_target;
    st->baseline_N = c->baseline;
    st->error_N = c->error;
    st->force_N = c->force;
    st->deflection_m = c->defl;
    st->signal_V = c->volts;
    st->sum_V = c->cp.sum_V;
    st->invols_m_per_V = c->invols;
    st->crash_force_N = c->crash_force;
    st->motor_steps = c->motor_steps;
    return 0;
}

int vafm_ctrl_event_pop(vafm_ctrl *c, vafm_ctrl_event *ev)
{
    if (!c || !ev)
        return 0;
    if (c->ev_dropped && c->ev_n < VAFM_CTRL_EVENTS) {
        const uint64_t n = c->ev_dropped;
        c->ev_dropped = 0;
        vafm_ctrl_push(c, VAFM_CTRL_EV_OVERFLOW, 0, (double)n);
    }
    if (c->ev_n == 0)
        return 0;
    *ev = c->ev[c->ev_head];
    c->ev_head = (c->ev_head + 1) % VAFM_CTRL_EVENTS;
    c->ev_n--;
    return 1;
}

/* ---- commands ---------------------------------------------------------------------------------- */

int vafm_ctrl_engage(vafm_ctrl *c)
{
    if (!c)
        return VAFM_EINVAL;
    if (c->state == VAFM_CTRL_ENGAGED || c->state == VAFM_CTRL_APPROACHING || c->state == VAFM_CTRL_CRASHED)
        return VAFM_ESTATE;
    c->state = VAFM_CTRL_APPROACHING;
    c->phase = VAFM_CTRL_ENGAGE_BASELINE;
    c->feedback = 0;
    c->saturated = 0;
    c->last_fail = VAFM_CTRL_FAIL_NONE;
    c->t_engage0 = c->t_now;
    c->base_sum = 0.0;
    c->base_n = 0;
    c->base_boot = 0;
    c->motor_target = c->motor_z;
    vafm_ctrl_piezo_to(c, 0.0); /* the baseline is measured with the piezo retracted */
    return 0;
}

int vafm_ctrl_withdraw(vafm_ctrl *c, unsigned motor_steps)
{
    if (!c)
        return VAFM_EINVAL;
    if (c->motor_z + motor_steps * c->cp.motor_step_m > c->cp.motor_max_m)
        return VAFM_EINVAL;
    if (c->state == VAFM_CTRL_APPROACHING) {
        c->last_fail = VAFM_CTRL_FAIL_ABORTED;
        vafm_ctrl_push(c, VAFM_CTRL_EV_FAILED, VAFM_CTRL_FAIL_ABORTED, c->motor_z);
    }
    c->state = VAFM_CTRL_WITHDRAWING;
    c->phase = VAFM_CTRL_ENGAGE_NONE;
    c->feedback = 0;
    c->saturated = 0;
    c->moving = 0;
    c->motor_target = c->motor_z;
    c->back_steps = motor_steps;
    vafm_ctrl_piezo_to(c, 0.0);
    return 0;
}

int vafm_ctrl_move(vafm_ctrl *c, double x_m, double y_m, double speed_m_per_s, vafm_error *err)
{
    if (!c)
        return VAFM_EINVAL;
    if (c->state == VAFM_CTRL_APPROACHING) {
        vafm_err_set(err, VAFM_ESTATE, "", "move: an engage is under way");
        return VAFM_ESTATE;
    }
    const double half = 0.5 * c->cp.xy_range_m;
    if (!isfinite(x_m) || !isfinite(y_m) || fabs(x_m) > half || fabs(y_m) > half) {
        const int bad_x = !(fabs(x_m) <= half);
        vafm_err_set(err, VAFM_EINVAL, bad_x ? "x_m" : "y_m", "move: %s = %g m is beyond the scanner's range [%g, %g] m",
                     bad_x ? "x_m" : "y_m", bad_x ? x_m : y_m, -half, half);
        vafm_ctrl_push(c, VAFM_CTRL_EV_XY_RANGE, 0, bad_x ? x_m : y_m);
        return VAFM_EINVAL;
    }
    if (!(speed_m_per_s <= 1e-2)) {
        vafm_err_set(err, VAFM_EINVAL, "speed_m_per_s", "move: speed %g m/s is outside (0, 0.01] m/s (<= 0: the default)",
                     speed_m_per_s);
        return VAFM_EINVAL;
    }
    c->tx = x_m;
    c->ty = y_m;
    c->xy_speed = speed_m_per_s > 0 ? speed_m_per_s : c->cp.xy_speed_m_per_s;
    c->xy_dist = 0.0;
    c->moving = 1;
    return 0;
}

int vafm_ctrl_z(vafm_ctrl *c, double z_m, vafm_error *err)
{
    if (!c)
        return VAFM_EINVAL;
    if (c->state == VAFM_CTRL_APPROACHING || c->state == VAFM_CTRL_WITHDRAWING) {
        vafm_err_set(err, VAFM_ESTATE, "", "z: the controller is %s", vafm_ctrl_state_name(c->state));
        return VAFM_ESTATE;
    }
    if (!(z_m >= 0.0 && z_m <= c->cp.piezo_range_m)) {
        vafm_err_set(err, VAFM_EINVAL, "z_m", "z: %g m is outside the piezo range [0, %g] m", z_m, c->cp.piezo_range_m);
        return VAFM_EINVAL;
    }
    if (c->state != VAFM_CTRL_CRASHED)
        c->state = VAFM_CTRL_IDLE;
    c->feedback = 0;
    c->saturated = 0;
    vafm_ctrl_piezo_to(c, z_m);
    return 0;
}

int vafm_ctrl_feedback(vafm_ctrl *c, int on)
{
    if (!c)
        return VAFM_EINVAL;
    if (c->state == VAFM_CTRL_APPROACHING || c->state == VAFM_CTRL_WITHDRAWING || (on && c->state == VAFM_CTRL_CRASHED))
        return VAFM_ESTATE;
    if (on && !c->feedback) {
        if (!isfinite(c->F_target))
            c->F_target = vafm_ctrl_setpoint_abs(&c->cp, c->baseline, c->k, c->invols, c->scene.baseline_offset_V);
        c->err_prev = c->F_target - c->force;
        c->z_moving = 0;
        c->state = VAFM_CTRL_ENGAGED;
        c->lost_contact = !c->in_contact;
    } else if (!on && c->feedback) {
        c->state = VAFM_CTRL_IDLE;
        c->z_target = c->piezo_z;
        c->z_moving = 0;
    }
    c->feedback = on ? 1 : 0;
    c->saturated = c->feedback ? c->saturated : 0;
    return 0;
}

int vafm_ctrl_feedback_set(vafm_ctrl *c, double setpoint, int unit, int relative, double p_m_per_N,
                           double i_m_per_N_s, double tau_s, vafm_error *err)
{
    if (!c)
        return VAFM_EINVAL;
    vafm_ctrl_params q = c->cp;
    if (!isnan(setpoint))
        q.setpoint = setpoint;
    q.setpoint_unit = unit;
    q.setpoint_relative = relative;
    if (!isnan(p_m_per_N))
        q.fb_p_m_per_N = p_m_per_N;
    if (!isnan(i_m_per_N_s))
        q.fb_i_m_per_N_s = i_m_per_N_s;
    if (!isnan(tau_s))
        q.fb_tau_s = tau_s;
    int r = vafm_ctrl_check(&q, c->k, c->invols, err);
    if (r)
        return r;
    c->cp = q;
    /* the new setpoint counts from the last baseline (relative) */
    if (c->state != VAFM_CTRL_APPROACHING || c->phase != VAFM_CTRL_ENGAGE_BASELINE)
        c->F_target = vafm_ctrl_setpoint_abs(&c->cp, c->baseline, c->k, c->invols, c->scene.baseline_offset_V);
    return 0;
}

/* ---- carry: the state handed on to a controller built over new settings (issue #27) -------------- */

/* 1 when scenes a and b give the same detector chain (its settings, seed, spring, rate) for stream `index` */
static int s_same_detector(const vafm_params *a, const vafm_params *b, uint64_t index)
{
    vafm_detector da, db; /* vafm_detector_begin clears each whole, padding included */
    vafm_detector_begin(&da, a, index);
    vafm_detector_begin(&db, b, index);
    return memcmp(&da, &db, sizeof da) == 0;
}

/* 1 when the live scene (the lever) of controllers over scenes a and b is the same physics: the scenes differ at
 * most in what only curves, tunes and their artefacts use (the ramp, the trigger, the dwell, the piezo model, the
 * curve's sample: the live scene has none of them, vafm_sim_live_begin). A difference in padding bytes only makes
 * it 0 (the lever then restarts: safe). */
static void s_live_only(vafm_params *q)
{
    q->v_approach_m_per_s = q->v_retract_m_per_s = q->start_height_m = 0.0;
    q->start_in_contact = 0;
    q->trigger_height_m = q->z_range_m = q->dwell_s = q->retract_margin_m = q->retract_max_m = 0.0;
    q->tune_duration_s = q->tune_rate_Hz = 0.0;
    q->ramp_size_m = q->ramp_rate_Hz = q->extend_time_s = q->retract_time_s = 0.0;
    q->ramp_start = q->segment_samples = q->setpoint_mode = q->dwell_mode = 0;
    q->setpoint_V = q->dwell_feedback_s = q->surface_height_m = q->contact_point_sd_m = 0.0;
    q->sample_drift_m_per_s = q->piezo_hysteresis = q->piezo_hysteresis_length_m = 0.0;
    q->piezo_creep = q->piezo_creep_t0_s = 0.0;
}

static int s_same_lever(const vafm_params *a, const vafm_params *b)
{
    vafm_params qa = *a, qb = *b;
    s_live_only(&qa);
    s_live_only(&qb);
    return memcmp(&qa, &qb, sizeof qa) == 0;
}

static double s_clamp(double v, double half)
{
    return v > half ? half : v < -half ? -half : v;
}

int vafm_ctrl_carry(vafm_ctrl *dst, vafm_ctrl *src, vafm_error *err)
{
    if (!dst || !src || dst == src) {
        vafm_err_set(err, VAFM_EINVAL, "", "vafm_ctrl_carry: two different controllers are needed");
        return VAFM_EINVAL;
    }
    if (dst->sample != 0 || dst->carried) {
        vafm_err_set(err, VAFM_ESTATE, "", "vafm_ctrl_carry: the new controller has run already (%" PRIu64
                     " samples%s): carry into one fresh from vafm_ctrl_new", dst->sample,
                     dst->carried ? ", carried into" : "");
        return VAFM_ESTATE;
    }
    vafm_ctrl *c = dst;
    const vafm_ctrl_params *cp = &c->cp;
    /* where the tip will be, checked before anything changes (the live scene takes heights within ±1 m) */
    const double half = 0.5 * cp->xy_range_m;
    const double x = s_clamp(src->x, half), y = s_clamp(src->y, half);
    const double pz = fmin(src->piezo_z, cp->piezo_range_m);
    const double surf = vafm_ctrl_surface(c, x, y), gap = src->motor_z - pz - surf;
    if (!(fabs(gap) <= 1.0)) {
        vafm_err_set(err, VAFM_EINVAL, "motor_z_m", "vafm_ctrl_carry: the support would be %g m above the new surface "
                     "(within [-1, 1] m only)", gap);
        return VAFM_EINVAL;
    }
    /* the same lever over the same surface, nothing clamped: dst takes src's running live scene over, so the
     * lever goes on exactly as it was (its position, velocity, contact and random stream): bit for bit as if
     * nothing had changed */
    const int takeover = cp->stream == src->cp.stream && s_same_lever(&src->scene, &c->scene) &&
                         surf == src->surface && x == src->x && y == src->y && pz == src->piezo_z;
    /* the clock goes on: at the same rate its base stays (the times are the same bits as without the carry);
     * at a new rate it moves to here */
    c->carried = 1;
    c->sample = src->sample;
    if (c->Ts == src->Ts) {
        c->s0 = src->s0;
        c->t0 = src->t0;
    } else {
        c->s0 = src->sample;
        c->t0 = src->t0 + (double)(src->sample - src->s0) * src->Ts;
    }
    c->t_now = src->t_now;
    c->restarts = takeover ? src->restarts : src->restarts + 1; /* a new lever: the next random stream */
    /* the state and what is under way */
    c->state = src->state;
    c->phase = src->phase;
    c->last_fail = src->last_fail;
    c->motor_z = src->motor_z;
    c->motor_target = src->motor_target;
    c->back_steps = src->back_steps;
    c->motor_steps = src->motor_steps;
    c->piezo_z = pz;
    c->z_target = fmin(src->z_target, cp->piezo_range_m);
    c->z_moving = src->z_moving;
    c->z_speed = c->state == VAFM_CTRL_APPROACHING && c->phase == VAFM_CTRL_ENGAGE_EXTEND ? cp->engage_speed_m_per_s
                                                                                          : cp->z_speed_m_per_s;
    if (c->state == VAFM_CTRL_APPROACHING && c->phase == VAFM_CTRL_ENGAGE_EXTEND)
        c->z_target = cp->piezo_range_m; /* the search sweeps the new range */
    c->t_engage0 = src->t_engage0;
    c->x = x;
    c->y = y;
    c->tx = src->tx;
    c->ty = src->ty;
    c->moving = src->moving;
    c->xy_dist = src->xy_dist;
    /* a move at the default speed takes the new default; one given its own speed keeps it */
    c->xy_speed = src->xy_speed == src->cp.xy_speed_m_per_s ? cp->xy_speed_m_per_s : src->xy_speed;
    c->surface = surf;
    c->in_contact = src->in_contact;
    c->feedback = src->feedback;
    c->saturated = src->saturated;
    c->lost_contact = src->lost_contact;
    c->err_prev = src->err_prev;
    c->baseline = src->baseline;
    c->base_sum = src->base_sum;
    c->base_n = src->base_n;
    c->base_boot = src->base_boot;
    c->force = src->force;
    c->defl = src->defl;
    c->volts = src->volts;
    c->error = src->error;
    c->crash_force = src->crash_force;
    /* the setpoint: an absolute one is the new setting's (vafm_ctrl_new computed it); a relative one counts from
     * the carried baseline once one is known */
    if (cp->setpoint_relative)
        c->F_target = isfinite(src->F_target)
                          ? vafm_ctrl_setpoint_abs(cp, c->baseline, c->k, c->invols, c->scene.baseline_offset_V)
                          : NAN;
    /* the events not yet read */
    memcpy(c->ev, src->ev, sizeof c->ev);
    c->ev_head = src->ev_head;
    c->ev_n = src->ev_n;
    c->ev_dropped = src->ev_dropped;
    /* the detector's chain: the same settings go on as they were, others start afresh on the next stream */
    if (s_same_detector(&src->scene, &c->scene, cp->stream ^ VAFM_SIM_LIVE_KEY))
        c->det = src->det;
    else
        vafm_detector_begin(&c->det, &c->scene, (cp->stream + c->restarts) ^ VAFM_SIM_LIVE_KEY);
    /* what the new settings make impossible: clamped above, reported here */
    if (src->piezo_z > cp->piezo_range_m) {
        vafm_ctrl_push(c, VAFM_CTRL_EV_Z_SATURATED, 0, c->piezo_z);
        c->saturated = c->feedback;
    }
    if (x != src->x || y != src->y)
        vafm_ctrl_push(c, VAFM_CTRL_EV_XY_RANGE, 0, x != src->x ? src->x : src->y);
    if (c->moving && (fabs(c->tx) > half || fabs(c->ty) > half)) {
        vafm_ctrl_push(c, VAFM_CTRL_EV_XY_RANGE, 0, fabs(c->tx) > half ? c->tx : c->ty);
        c->moving = 0;
    }
    double h0 = gap;
    const double depth = 2.0 * cp->force_limit_N / c->k; /* the deepest the scene's force range covers */
    if (gap < -depth) { /* a surface above the tip: crashed into */
        c->force = c->k * -gap;
        h0 = -depth;
        if (c->state == VAFM_CTRL_CRASHED) {
            c->crash_force = fmax(c->crash_force, c->force);
            vafm_ctrl_push(c, VAFM_CTRL_EV_CRASH, 0, c->force);
        } else {
            vafm_ctrl_crash(c);
        }
    }
    if (takeover && h0 == gap) {
        vafm_sim *mine = c->sim;
        c->sim = src->sim;
        src->sim = mine; /* src keeps dst's fresh lever: still a working controller, only to be destroyed */
        vafm_sim_live_commander(c->sim, vafm_ctrl_loop, c);
        vafm_sim_live_commander(src->sim, vafm_ctrl_loop, src);
        return 0;
    }
    int r = vafm_sim_live_begin_contact(c->sim, cp->stream + c->restarts, h0, c->in_contact, vafm_ctrl_loop, c);
    if (r && err)
        *err = *vafm_sim_error(c->sim);
    return r;
}
