/* SPDX-License-Identifier: MIT */
/* The arguments of the controller commands (engage, withdraw, move, z, feedback; protocol/wire.md §2.3):
 * types and the ranges that need no state; the controller's own ranges (piezo, scanner) are checked by the
 * control thread against its settings (live_cmd.c), the state by the controller itself. */
#include <math.h>
#include <string.h>
#include "daemon/cmd_json.h"
#include "daemon/live.h"

/* A number argument: 0 absent, 1 present (*out set), -1 error. */
static int s_num(json_t *root, const char *key, double lo, double hi, const char *unit, double *out, vafmd_err *e)
{
    json_t *v = json_object_get(root, key);
    if (!v)
        return 0;
    if (!json_is_number(v)) {
        vafmd_err_set(e, VAFMD_E_WRONG_TYPE, key, "\"%s\" must be a number (%s)", key, unit);
        return -1;
    }
    double x = json_number_value(v);
    if (!(x >= lo && x <= hi)) {
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, key, "%s = %.17g is outside [%g, %g] %s", key, x, lo, hi, unit);
        return -1;
    }
    *out = x;
    return 1;
}

static int s_bool(json_t *root, const char *key, int *out, vafmd_err *e)
{
    json_t *v = json_object_get(root, key);
    if (!v)
        return 0;
    if (!json_is_boolean(v)) {
        vafmd_err_set(e, VAFMD_E_WRONG_TYPE, key, "\"%s\" must be true or false", key);
        return -1;
    }
    *out = json_is_true(v);
    return 1;
}

int vafmd_live_decode(json_t *root, vafmd_cmd *c, vafmd_err *e)
{
    vafmd_live_op *op = &c->ctrl;
    memset(op, 0, sizeof *op);
    snprintf(op->cmd, sizeof op->cmd, "%s", vafmd_cmd_name(c->kind));
    int r;
    if ((r = s_num(root, "at_s", 0, 1e9, "s", &op->at_s, e)) < 0)
        return -1;
    op->has_at = r;
    switch (c->kind) {
    case VAFMD_CMD_ENGAGE:
        op->op = VAFMD_LIVE_OP_ENGAGE;
        return 0;
    case VAFMD_CMD_WITHDRAW: {
        op->op = VAFMD_LIVE_OP_WITHDRAW;
        json_t *v = json_object_get(root, "motor_steps");
        if (v) {
            if (!json_is_integer(v)) {
                vafmd_err_set(e, VAFMD_E_WRONG_TYPE, "motor_steps", "\"motor_steps\" must be an integer");
                return -1;
            }
            json_int_t n = json_integer_value(v);
            if (n < 0 || n > 100000) {
                vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "motor_steps", "motor_steps = %lld is outside [0, 100000]",
                              (long long)n);
                return -1;
            }
            op->motor_steps = (unsigned)n;
        }
        return 0;
    }
    case VAFMD_CMD_MOVE:
        op->op = VAFMD_LIVE_OP_MOVE;
        op->speed_m_per_s = 0; /* 0: the controller's xy_speed_m_per_s */
        if ((r = s_num(root, "x_m", -1e-2, 1e-2, "m", &op->x_m, e)) < 0)
            return -1;
        if (!r) {
            vafmd_err_set(e, VAFMD_E_MISSING_FIELD, "x_m", "'move' needs \"x_m\" and \"y_m\" (m)");
            return -1;
        }
        if ((r = s_num(root, "y_m", -1e-2, 1e-2, "m", &op->y_m, e)) < 0)
            return -1;
        if (!r) {
            vafmd_err_set(e, VAFMD_E_MISSING_FIELD, "y_m", "'move' needs \"x_m\" and \"y_m\" (m)");
            return -1;
        }
        if (s_num(root, "speed_m_per_s", 1e-12, 1e-2, "m/s", &op->speed_m_per_s, e) < 0)
            return -1;
        return 0;
    case VAFMD_CMD_Z:
        op->op = VAFMD_LIVE_OP_Z;
        if ((r = s_num(root, "z_m", 0, 1e-3, "m", &op->z_m, e)) < 0)
            return -1;
        if (!r) {
            vafmd_err_set(e, VAFMD_E_MISSING_FIELD, "z_m", "'z' needs \"z_m\" (the piezo extension, m)");
            return -1;
        }
        return 0;
    case VAFMD_CMD_FEEDBACK: {
        op->op = VAFMD_LIVE_OP_FEEDBACK;
        op->on = -1;
        op->setpoint = op->p_m_per_N = op->i_m_per_N_s = op->tau_s = NAN;
        op->unit = -1;
        op->relative = -1;
        if (s_bool(root, "on", &op->on, e) < 0)
            return -1;
        int n = 0;
        if ((r = s_num(root, "setpoint", -100, 100, "N or V", &op->setpoint, e)) < 0)
            return -1;
        n += r;
        json_t *v = json_object_get(root, "unit");
        if (v) {
            const char *u = json_is_string(v) ? json_string_value(v) : NULL;
            if (!u || (strcmp(u, "N") && strcmp(u, "V"))) {
                vafmd_err_set(e, u ? VAFMD_E_OUT_OF_RANGE : VAFMD_E_WRONG_TYPE, "unit", "\"unit\" must be \"N\" or \"V\"");
                return -1;
            }
            op->unit = !strcmp(u, "V");
            n++;
        }
        if ((r = s_bool(root, "relative", &op->relative, e)) < 0)
            return -1;
        n += r;
        if ((r = s_num(root, "p_m_per_N", 0, 1e3, "m/N", &op->p_m_per_N, e)) < 0)
            return -1;
        n += r;
        if ((r = s_num(root, "i_m_per_N_s", 0, 1e12, "m/(N s)", &op->i_m_per_N_s, e)) < 0)
            return -1;
        n += r;
        if ((r = s_num(root, "tau_s", 0, 1e3, "s", &op->tau_s, e)) < 0)
            return -1;
        n += r;
        op->has_set = n > 0;
        if (op->on < 0 && !op->has_set) {
            vafmd_err_set(e, VAFMD_E_MISSING_FIELD, "on", "'feedback' needs \"on\" and/or a setpoint or gain "
                          "(setpoint, unit, relative, p_m_per_N, i_m_per_N_s, tau_s)");
            return -1;
        }
        return 0;
    }
    default:
        return 0;
    }
}
