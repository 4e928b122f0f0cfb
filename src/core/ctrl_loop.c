/* SPDX-License-Identifier: MIT */
/*
 * One sample boundary of the always-on controller: the live scene (vafm_sim_live_begin) has made a sample; here
 * the controller measures it through the detector, checks the force limit, runs its state machines (engage,
 * withdraw, crash) and the Z feedback, moves the motor, the piezo and the tip one sample interval on, and
 * returns the support's height above the surface at the end of that interval. The support moves there at a
 * constant speed, so a change of the surface under the tip (a move over topography) is a change of that height.
 *
 * Timing: everything acts at sample boundaries, as a digital controller on its filtered input does. The
 * Z feedback is a velocity-form PI on the measured force: z += P·(e − e_prev) + I·Ts·e, e = setpoint − F,
 * clamped to [0, piezo_range_m] (an end reached is a saturation). A motor step moves blind (the setpoint is
 * watched only during the piezo sweep, as in a step-and-sweep auto-approach), so a step longer than the piezo
 * range, or too fast a sweep, can press the tip past force_limit_N: a crash. No allocation, no I/O.
 */
#include <math.h>

#include "core/ctrl_impl.h"

double vafm_ctrl_surface(const vafm_ctrl *c, double x, double y)
{
    double h = 0.0;
    if (c->map)
        vafm_map_surface_at(c->map, x, y, NULL, &h);
    return h;
}

/* value moved toward target by at most step; *arrived set when it is there */
static double s_toward(double value, double target, double step, int *arrived)
{
    const double d = target - value;
    if (fabs(d) <= step) {
        *arrived = 1;
        return target;
    }
    *arrived = 0;
    return value + (d > 0 ? step : -step);
}

void vafm_ctrl_crash(vafm_ctrl *c)
{
    if (c->state == VAFM_CTRL_APPROACHING) {
        c->last_fail = VAFM_CTRL_FAIL_CRASH;
        vafm_ctrl_push(c, VAFM_CTRL_EV_FAILED, VAFM_CTRL_FAIL_CRASH, c->motor_z);
    }
    vafm_ctrl_push(c, VAFM_CTRL_EV_CRASH, 0, c->force);
    c->crash_force = c->force;
    c->state = VAFM_CTRL_CRASHED;
    c->phase = VAFM_CTRL_ENGAGE_NONE;
    c->feedback = 0;
    c->saturated = 0;
    c->moving = 0;
    /* the motor stops and backs off one step (the piezo alone cannot free a tip the motor pressed in) */
    c->motor_target = fmin(c->motor_z + c->cp.motor_step_m, c->cp.motor_max_m);
    vafm_ctrl_piezo_to(c, 0.0); /* the piezo retracts */
}

static void s_fail(vafm_ctrl *c, int reason)
{
    c->last_fail = reason;
    vafm_ctrl_push(c, VAFM_CTRL_EV_FAILED, reason, c->motor_z);
    c->state = VAFM_CTRL_IDLE;
    c->phase = VAFM_CTRL_ENGAGE_NONE;
    c->motor_target = c->motor_z;
    vafm_ctrl_piezo_to(c, 0.0);
}

/* the engage's state machine, at one sample boundary (before the motion) */
static void s_engage(vafm_ctrl *c, double t)
{
    const vafm_ctrl_params *cp = &c->cp;
    if (t - c->t_engage0 > cp->engage_timeout_s) {
        s_fail(c, VAFM_CTRL_FAIL_TIMEOUT);
        return;
    }
    switch (c->phase) {
    case VAFM_CTRL_ENGAGE_BASELINE:
        if (c->piezo_z > 0.0)
            break; /* still retracting */
        c->base_sum += c->force;
        if (++c->base_n >= VAFM_BASELINE_SAMPLES) {
            c->baseline = c->base_sum / c->base_n;
            c->F_target = vafm_ctrl_setpoint_abs(cp, c->baseline, c->k, c->invols, c->scene.baseline_offset_V);
            c->phase = VAFM_CTRL_ENGAGE_EXTEND;
            c->z_target = cp->piezo_range_m;
            c->z_speed = cp->engage_speed_m_per_s;
        }
        break;
    case VAFM_CTRL_ENGAGE_EXTEND:
        if (c->force >= c->F_target) {
            c->state = VAFM_CTRL_ENGAGED;
            c->phase = VAFM_CTRL_ENGAGE_NONE;
            c->feedback = 1;
            c->err_prev = c->F_target - c->force;
            c->lost_contact = 0;
            c->z_moving = 0;
            vafm_ctrl_push(c, VAFM_CTRL_EV_ENGAGED, 0, c->force);
        } else if (c->piezo_z >= cp->piezo_range_m) {
            c->phase = VAFM_CTRL_ENGAGE_RETRACT;
            c->z_target = 0.0;
            c->z_speed = cp->z_speed_m_per_s;
        }
        break;
    case VAFM_CTRL_ENGAGE_RETRACT:
        if (c->piezo_z <= 0.0) {
            if (c->motor_z - cp->motor_step_m < cp->motor_min_m) {
                s_fail(c, VAFM_CTRL_FAIL_MOTOR_RANGE);
                break;
            }
            c->phase = VAFM_CTRL_ENGAGE_MOTOR;
            c->motor_target = c->motor_z - cp->motor_step_m;
            c->motor_steps++;
        }
        break;
    case VAFM_CTRL_ENGAGE_MOTOR:
        if (c->motor_z == c->motor_target) {
            c->phase = VAFM_CTRL_ENGAGE_EXTEND;
            c->z_target = cp->piezo_range_m;
            c->z_speed = cp->engage_speed_m_per_s;
        }
        break;
    default: break;
    }
}

/* the Z feedback: velocity-form PI on the measured force */
static void s_feedback(vafm_ctrl *c)
{
    const vafm_ctrl_params *cp = &c->cp;
    const double e = c->F_target - c->force;
    const double I = cp->fb_i_m_per_N_s > 0 ? cp->fb_i_m_per_N_s
                                             : 1.0 / (c->k * (cp->fb_tau_s > 0 ? cp->fb_tau_s : 10.0 * c->Ts));
    double z = c->piezo_z + cp->fb_p_m_per_N * (e - c->err_prev) + I * c->Ts * e;
    c->err_prev = e;
    c->error = e;
    int sat = 0;
    if (!(z > 0.0)) { /* NaN-safe: a broken loop parks at full retraction */
        z = 0.0;
        sat = 1;
    } else if (z >= cp->piezo_range_m) {
        z = cp->piezo_range_m;
        sat = 1;
    }
    if (sat && !c->saturated)
        vafm_ctrl_push(c, VAFM_CTRL_EV_Z_SATURATED, 0, z);
    else if (!sat && c->saturated)
        vafm_ctrl_push(c, VAFM_CTRL_EV_Z_RECOVERED, 0, z);
    c->saturated = sat;
    c->piezo_z = z;
}

double vafm_ctrl_loop(void *user, const vafm_live_sample *smp)
{
    vafm_ctrl *c = user;
    const vafm_ctrl_params *cp = &c->cp;
    const double Ts = c->Ts, t = c->t0 + (double)(c->sample + 1 - c->s0) * Ts;
    c->t_now = t;
    /* measure: the detector's chain, as the instrument records it */
    c->defl = smp->deflection_m; /* the chain off leaves these as they are */
    c->force = smp->force_N;
    vafm_detector_apply(&c->det, t, smp->height_m, smp->deflection_m, &c->volts, &c->defl, &c->force);
    c->in_contact = smp->in_contact;
    c->error = 0.0;
    if (c->base_boot) { /* the start-up baseline (a relative setpoint before any engage) */
        c->base_sum += c->force;
        if (++c->base_n >= VAFM_BASELINE_SAMPLES) {
            c->baseline = c->base_sum / c->base_n;
            c->base_boot = 0;
            c->base_sum = 0.0;
            c->base_n = 0;
            if (c->state != VAFM_CTRL_APPROACHING && !isfinite(c->F_target))
                c->F_target = vafm_ctrl_setpoint_abs(cp, c->baseline, c->k, c->invols, c->scene.baseline_offset_V);
        }
    }
    if (c->state == VAFM_CTRL_CRASHED) {
        if (c->force > c->crash_force)
            c->crash_force = c->force; /* the force reached */
    } else if (c->force > cp->force_limit_N) {
        vafm_ctrl_crash(c);
    }
    if (c->state == VAFM_CTRL_APPROACHING)
        s_engage(c, t);
    if (c->state == VAFM_CTRL_ENGAGED) {
        if (!c->in_contact && !c->lost_contact) {
            c->lost_contact = 1;
            vafm_ctrl_push(c, VAFM_CTRL_EV_LOST_CONTACT, 0, c->force);
        } else if (c->in_contact) {
            c->lost_contact = 0;
        }
    }
    /* record the sample as measured, with the positions it was made at */
    size_t j = c->nblk++;
    c->b_t[j] = t;
    c->b_motor[j] = c->motor_z;
    c->b_z[j] = c->piezo_z;
    c->b_x[j] = c->x;
    c->b_y[j] = c->y;
    c->b_gap[j] = smp->height_m;
    c->b_defl[j] = c->defl;
    c->b_f[j] = c->force;
    c->b_v[j] = c->volts;
    c->b_surf[j] = c->surface;
    /* move one interval on: piezo (feedback or toward its target), motor, XY */
    int arrived;
    if (c->feedback) {
        s_feedback(c);
    } else if (c->z_moving) {
        c->piezo_z = s_toward(c->piezo_z, c->z_target, c->z_speed * Ts, &arrived);
        if (arrived) {
            c->z_moving = c->state == VAFM_CTRL_APPROACHING; /* an engage's sweeps keep going */
            if (c->state == VAFM_CTRL_IDLE)
                vafm_ctrl_push(c, VAFM_CTRL_EV_Z_REACHED, 0, c->piezo_z);
        }
    }
    c->b_err[j] = c->error;
    if (c->motor_z != c->motor_target)
        c->motor_z = s_toward(c->motor_z, c->motor_target, cp->motor_speed_m_per_s * Ts, &arrived);
    if (c->state == VAFM_CTRL_WITHDRAWING && c->piezo_z <= 0.0) {
        if (c->back_steps > 0) {
            c->motor_target = c->motor_z + c->back_steps * cp->motor_step_m;
            c->back_steps = 0;
        } else if (c->motor_z == c->motor_target) {
            c->state = VAFM_CTRL_WITHDRAWN;
            c->z_moving = 0;
            vafm_ctrl_push(c, VAFM_CTRL_EV_WITHDRAWN, 0, c->motor_z);
        }
    }
    if (c->moving) {
        const double dx = c->tx - c->x, dy = c->ty - c->y, d = hypot(dx, dy), step = c->xy_speed * Ts;
        if (d <= step) {
            c->x = c->tx;
            c->y = c->ty;
            c->moving = 0;
            c->xy_dist += d;
            vafm_ctrl_push(c, VAFM_CTRL_EV_MOVED, 0, c->xy_dist);
        } else {
            c->x += dx * (step / d);
            c->y += dy * (step / d);
            c->xy_dist += step;
        }
        c->surface = vafm_ctrl_surface(c, c->x, c->y);
    }
    c->b_state[j] = (uint8_t)c->state;
    c->sample++;
    return c->motor_z - c->piezo_z - c->surface;
}
