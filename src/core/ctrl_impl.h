/* SPDX-License-Identifier: MIT */
/*
 * The always-on controller's private state (vafm/ctrl.h), shared by its files:
 *   ctrl_params.c  settings: defaults, ranges, validation, names;
 *   ctrl.c         lifecycle, commands (engage, withdraw, move, z, feedback), status, the event queue's reader,
 *                  vafm_ctrl_advance (drives the simulation's live scene and hands blocks out), vafm_ctrl_carry
 *                  (the state handed on to a controller built over new settings);
 *   ctrl_loop.c    what happens at each sample boundary: measure (detector), crash check, the engage and
 *                  withdraw state machines, the Z feedback, the motor, piezo and XY motion, and the support's
 *                  height for the next interval (the live scene's commander, vafm_sim_live_begin).
 * Commands only set targets and states here; ctrl_loop.c moves toward them one sample interval at a time, so a
 * command never blocks and the same commands at the same sample indices give the same session bit for bit.
 * Geometry: heights upward from the substrate; support H = motor_z − piezo_z; gap = H − surface(x, y).
 * Nothing here allocates after vafm_ctrl_new.
 */
#ifndef VAFM_CORE_CTRL_IMPL_H
#define VAFM_CORE_CTRL_IMPL_H

#include "vafm/ctrl.h"
#include "vafm/detector.h"
#include "vafm/sim.h"

#define VAFM_CTRL_BLOCK 512

struct vafm_ctrl {
    vafm_ctrl_params cp;
    vafm_params scene;          /* the live scene (setpoint raised to cover the force limit) */
    const vafm_map_spec *map;   /* borrowed; NULL: flat */
    vafm_sim *sim;
    vafm_detector det;
    double Ts;                  /* sample interval, s */
    double k;                   /* spring constant, N/m */
    double invols;              /* m/V */
    uint64_t restarts;          /* live scene restarts after a simulation error or a carry (its next stream) */
    int carried;                /* 1: a state was carried into it (vafm_ctrl_carry) */
    /* state */
    int state, phase, last_fail;
    uint64_t sample;            /* samples made */
    double t0;                  /* the clock's base: sample s0 ended at t0 (0, 0 unless carried: vafm_ctrl_carry) */
    uint64_t s0;
    double t_now;               /* time of the sample being handled (in the loop) or of the last one made, s */
    double motor_z, motor_target;
    double piezo_z, z_target, z_speed;
    double x, y, tx, ty, xy_speed, xy_dist;
    int moving, z_moving;
    double surface;             /* under (x, y) */
    int in_contact, feedback, saturated, lost_contact;
    double F_target;            /* absolute force the feedback holds, N (NaN: not yet known) */
    double base_sum;            /* baseline being measured */
    int base_n, base_boot;      /* samples in it; 1 while the start-up baseline is measured */
    double baseline;            /* the last baseline, N */
    double err_prev;            /* the last error (the P term's difference) */
    double t_engage0;           /* time the engage began, s */
    unsigned back_steps;        /* withdraw: motor steps to back off */
    double force, defl, volts, error, crash_force;
    uint64_t motor_steps;
    /* event queue (ring) */
    vafm_ctrl_event ev[VAFM_CTRL_EVENTS];
    unsigned ev_head, ev_n;
    uint64_t ev_dropped;
    /* output block */
    size_t nblk;
    double b_t[VAFM_CTRL_BLOCK], b_motor[VAFM_CTRL_BLOCK], b_z[VAFM_CTRL_BLOCK], b_x[VAFM_CTRL_BLOCK],
        b_y[VAFM_CTRL_BLOCK], b_gap[VAFM_CTRL_BLOCK], b_defl[VAFM_CTRL_BLOCK], b_f[VAFM_CTRL_BLOCK],
        b_v[VAFM_CTRL_BLOCK], b_err[VAFM_CTRL_BLOCK], b_surf[VAFM_CTRL_BLOCK];
    uint8_t b_state[VAFM_CTRL_BLOCK];
};

/** Queue an event (drops and counts it when the queue is full). */
static inline void vafm_ctrl_push(vafm_ctrl *c, int type, int reason, double value)
{
    if (c->ev_n == VAFM_CTRL_EVENTS) {
        c->ev_dropped++;
        return;
    }
    vafm_ctrl_event *e = &c->ev[(c->ev_head + c->ev_n++) % VAFM_CTRL_EVENTS];
    e->type = type;
    e->reason = reason;
    e->sample = c->sample;
    e->time_s = c->t_now;
    e->value = value;
}

/** The piezo moves to z (m) at the z speed of retracts, withdraws and z moves (cp.z_speed_m_per_s). */
static inline void vafm_ctrl_piezo_to(vafm_ctrl *c, double z)
{
    c->z_target = z;
    c->z_speed = c->cp.z_speed_m_per_s;
    c->z_moving = 1;
}

/** The crash: feedback off, the piezo retracts, the motor backs off one step; events (ctrl_loop.c). */
void vafm_ctrl_crash(vafm_ctrl *c);

/** The live scene's commander (ctrl_loop.c): one sample boundary. */
double vafm_ctrl_loop(void *user, const vafm_live_sample *smp);

/** The surface height under (x, y), m (ctrl_loop.c). */
double vafm_ctrl_surface(const vafm_ctrl *c, double x, double y);

/** The absolute setpoint (N) of settings cp over the baseline `base` (N), for spring k and InvOLS s. */
double vafm_ctrl_setpoint_abs(const vafm_ctrl_params *cp, double base, double k, double invols, double offset_V);

/** Check one setting set (ctrl_params.c). */
int vafm_ctrl_check(const vafm_ctrl_params *p, double k, double invols, vafm_error *err);

#endif
