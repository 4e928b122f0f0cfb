/* SPDX-License-Identifier: MIT */
/*
 * The controller's settings (vafm/ctrl.h): defaults, one table of ranges that validation walks, the checks of
 * their combination, the absolute setpoint, and the names of states, events and failures.
 */
#include <math.h>
#include <stddef.h>
#include <string.h>

#include "core/ctrl_impl.h"
#include "core/internal.h"

void vafm_ctrl_params_default(vafm_ctrl_params *p)
{
    if (!p)
        return;
    memset(p, 0, sizeof *p);
    p->motor_z0_m = 200e-6;
    p->motor_min_m = 0.0;
    p->motor_max_m = 10e-3;
    p->motor_step_m = 5e-6;
    p->motor_speed_m_per_s = 100e-6;
    p->piezo_range_m = 10e-6;
    p->xy_range_m = 100e-6;
    p->xy_speed_m_per_s = 10e-6;
    p->z_speed_m_per_s = 100e-6;
    p->engage_speed_m_per_s = 20e-6;
    p->engage_timeout_s = 300.0;
    p->force_limit_N = 50e-9;
    p->setpoint = 2e-9;
    p->setpoint_unit = VAFM_CTRL_UNIT_N;
    p->setpoint_relative = 1;
    p->fb_p_m_per_N = 0.0;
    p->fb_i_m_per_N_s = 0.0;
    p->fb_tau_s = 0.0;
    p->sum_V = 5.0;
    p->stream = 0;
}

typedef struct s_range {
    const char *name, *unit;
    size_t off;
    double min, max;
    int open_low; /* (min, max] */
} s_range;

#define R(f, u, lo, hi, open) { #f, u, offsetof(vafm_ctrl_params, f), lo, hi, open }
static const s_range s_ranges[] = {
    R(motor_z0_m, "m", -1e-2, 1e-1, 0),
    R(motor_min_m, "m", -1e-2, 1e-1, 0),
    R(motor_max_m, "m", -1e-2, 1e-1, 0),
    R(motor_step_m, "m", 0, 1e-3, 1),
    R(motor_speed_m_per_s, "m/s", 0, 1e-2, 1),
    R(piezo_range_m, "m", 0, 1e-3, 1),
    R(xy_range_m, "m", 0, 1e-2, 1),
    R(xy_speed_m_per_s, "m/s", 0, 1e-2, 1),
    R(z_speed_m_per_s, "m/s", 0, 1e-2, 1),
    R(engage_speed_m_per_s, "m/s", 0, 1e-2, 1),
    R(engage_timeout_s, "s", 0, 1e5, 1),
    R(force_limit_N, "N", 0, 1e-3, 1),
    R(setpoint, "N or V", -100, 100, 0),
    R(fb_p_m_per_N, "m/N", 0, 1e3, 0),
    R(fb_i_m_per_N_s, "m/(N s)", 0, 1e12, 0),
    R(fb_tau_s, "s", 0, 1e3, 0),
    R(sum_V, "V", 0, 100, 0),
};
#undef R

double vafm_ctrl_setpoint_abs(const vafm_ctrl_params *cp, double base, double k, double invols, double offset_V)
{
    double sp = cp->setpoint;
    if (cp->setpoint_unit == VAFM_CTRL_UNIT_V)
        sp = k * invols * (cp->setpoint_relative ? sp : sp - offset_V);
    return cp->setpoint_relative ? base + sp : sp;
}

int vafm_ctrl_check(const vafm_ctrl_params *p, double k, double invols, vafm_error *err)
{
    if (!p) {
        vafm_err_set(err, VAFM_EINVAL, "", "no controller settings given");
        return VAFM_EINVAL;
    }
    for (size_t i = 0; i < sizeof s_ranges / sizeof s_ranges[0]; i++) {
        const s_range *r = &s_ranges[i];
        const double v = *(const double *)(const void *)((const char *)p + r->off);
        if (!isfinite(v) || v > r->max || (r->open_low ? !(v > r->min) : !(v >= r->min))) {
            vafm_err_set(err, VAFM_EINVAL, r->name, "%s = %g %s is outside the allowed range %s%g, %g] %s", r->name,
                         v, r->unit, r->open_low ? "(" : "[", r->min, r->max, r->unit);
            return VAFM_EINVAL;
        }
    }
    if (p->setpoint_unit != VAFM_CTRL_UNIT_N && p->setpoint_unit != VAFM_CTRL_UNIT_V) {
        vafm_err_set(err, VAFM_EINVAL, "setpoint_unit", "setpoint_unit = %d: allowed 0 (N) or 1 (V)", p->setpoint_unit);
        return VAFM_EINVAL;
    }
    if (p->setpoint_relative != 0 && p->setpoint_relative != 1) {
        vafm_err_set(err, VAFM_EINVAL, "setpoint_relative", "setpoint_relative = %d: allowed 0 or 1",
                     p->setpoint_relative);
        return VAFM_EINVAL;
    }
    if (!(p->motor_max_m > p->motor_min_m)) {
        vafm_err_set(err, VAFM_EINVAL, "motor_max_m", "motor_max_m = %g m must exceed motor_min_m = %g m",
                     p->motor_max_m, p->motor_min_m);
        return VAFM_EINVAL;
    }
    if (p->motor_z0_m < p->motor_min_m || p->motor_z0_m > p->motor_max_m) {
        vafm_err_set(err, VAFM_EINVAL, "motor_z0_m", "motor_z0_m = %g m is outside the motor's range [%g, %g] m",
                     p->motor_z0_m, p->motor_min_m, p->motor_max_m);
        return VAFM_EINVAL;
    }
    /* the setpoint as a force step above the baseline (relative) or as a force (absolute, offset ignored) */
    double sp = p->setpoint_unit == VAFM_CTRL_UNIT_V ? k * invols * p->setpoint : p->setpoint;
    if (!(sp < p->force_limit_N)) {
        vafm_err_set(err, VAFM_EINVAL, "force_limit_N", "force_limit_N = %g N must exceed the setpoint (%g N)",
                     p->force_limit_N, sp);
        return VAFM_EINVAL;
    }
    return 0;
}

int vafm_ctrl_params_validate(const vafm_ctrl_params *p, const vafm_params *scene, vafm_error *err)
{
    if (!scene) {
        vafm_err_set(err, VAFM_EINVAL, "", "no scene given");
        return VAFM_EINVAL;
    }
    return vafm_ctrl_check(p, scene->k_N_per_m, scene->sensitivity_m_per_V, err);
}

const char *vafm_ctrl_state_name(int state)
{
    static const char *const n[] = { "idle", "approaching", "engaged", "withdrawing", "withdrawn", "crashed" };
    return state >= 0 && state < (int)(sizeof n / sizeof n[0]) ? n[state] : "?";
}

const char *vafm_ctrl_event_name(int type)
{
    static const char *const n[] = { "?", "engaged", "failed", "crash", "z-saturated", "z-recovered", "xy-range",
                                     "withdrawn", "moved", "z-reached", "lost-contact", "sim-error", "overflow" };
    return type >= 0 && type < (int)(sizeof n / sizeof n[0]) ? n[type] : "?";
}

const char *vafm_ctrl_fail_name(int reason)
{
    static const char *const n[] = { "none", "motor-range", "timeout", "crash", "aborted" };
    return reason >= 0 && reason < (int)(sizeof n / sizeof n[0]) ? n[reason] : "?";
}
