/* SPDX-License-Identifier: MIT */
/*
 * The always-on controller in vafmd (issue #26, daemon half; docs/instrument.md "The daemon").
 *
 * One vafm_ctrl (include/vafm/ctrl.h) lives from start-up to shutdown. It is OWNED BY THE SIMULATION THREAD,
 * which advances it in real time (× `speed`) while no run is in progress and publishes its decimated samples on
 * the stream's `live` topic and its events on `event` (run_id 0). The control thread never touches it:
 *
 *   control thread                               simulation thread
 *   --------------                               -----------------
 *   engage/withdraw/move/z/feedback ──ring──▶   VAFMD_SIM_CTRL op: applied between two advances (or held until
 *     waits for the ack (≤ 1 s; the               its `at_s`, the controller's time), result written, then
 *     simulation thread never waits)              ack = req (release)
 *   set (scene or ctrl_* changed) ──ring──▶     OP_NEW: a controller built there replaces the old one and goes on
 *                                               from its state (vafm_ctrl_carry; a new seed or start
 *                                               height: afresh)
 *   status ◀── snapshot under a mutex that the simulation thread only ever TRY-locks (never waits)
 *
 * The live channel list is declared once, in live_int.h (s_live_channels).
 */
#ifndef VAFMD_LIVE_H
#define VAFMD_LIVE_H
#include <jansson.h>
#include <stdint.h>
#include "vafm/ctrl.h"

struct vafmd;
typedef struct vafmd_live vafmd_live;
struct vafmd_cmd;
struct vafmd_err;

enum vafmd_live_op_kind {
    VAFMD_LIVE_OP_ENGAGE = 1,
    VAFMD_LIVE_OP_WITHDRAW = 2,
    VAFMD_LIVE_OP_MOVE = 3,
    VAFMD_LIVE_OP_Z = 4,
    VAFMD_LIVE_OP_FEEDBACK = 5,
    VAFMD_LIVE_OP_NEW = 6,      /* a new controller (ctrl; ownership passes; NULL: none, `why` says why) */
    VAFMD_LIVE_OP_SETTINGS = 7, /* the pacing speed and the monitor rate */
};

/* The feedback settings of vafmd_live_op.fb_given. */
enum { VAFMD_LIVE_FB_SETPOINT = 1, VAFMD_LIVE_FB_UNIT = 2, VAFMD_LIVE_FB_RELATIVE = 4, VAFMD_LIVE_FB_P = 8,
       VAFMD_LIVE_FB_I = 16, VAFMD_LIVE_FB_TAU = 32 };

/* One controller command, copied through the command ring inside a vafmd_sim_cmd. */
typedef struct vafmd_live_op {
    int op;              /* enum vafmd_live_op_kind */
    uint64_t req;        /* the control thread's request number, acknowledged when applied (0: none) */
    int has_at;          /* 1: apply when the controller's time reaches at_s (no ack: a `ctrl_refused` event
                            reports a refusal) */
    double at_s;
    char cmd[16];        /* the command's name (events) */
    unsigned motor_steps;               /* withdraw */
    double x_m, y_m, speed_m_per_s;     /* move */
    double z_m;                         /* z */
    int on;                             /* feedback: 1 on, 0 off, -1 unchanged */
    int has_set;                        /* feedback: 1 = setpoint/unit/relative/gains given (NaN keeps) */
    double setpoint, p_m_per_N, i_m_per_N_s, tau_s;
    int unit, relative;
    vafm_ctrl *ctrl;                    /* NEW */
    vafm_map_spec *map;                 /* NEW: the sample ctrl borrows (malloc'ed; ownership passes; NULL: flat) */
    char why[256];                      /* NEW with ctrl NULL: why there is no controller */
    int fresh;                          /* NEW: 1 = start afresh (a new seed or ctrl_motor_z0_m), 0 = carry */
    unsigned fb_given;                  /* NEW: the feedback settings the `set` changed (VAFMD_LIVE_FB_*); the
                                           others carry from the running controller (a `feedback` command's) */
    double speed, monitor_rate_Hz;      /* SETTINGS */
    int free_run;
} vafmd_live_op;

/* The controller's settings of a config file's "values" (ctrl_*, ctrl_sample, monitor_rate_Hz): main.c checks
 * them with the scene and daemon settings in force (vafmd_live_config_parse: 0, or -1 with e naming the field,
 * as `set` would), then vafmd_live_init builds the first controller with them. */
typedef struct vafmd_live_config {
    vafm_ctrl_params cp;
    double monitor_rate_Hz;
    vafm_map_spec sample;
    int has_sample;
    char sample_text[1025];
} vafmd_live_config;
void vafmd_live_config_default(vafmd_live_config *c);
/* Take the controller's keys out of values (they are deleted from it) into c. */
int vafmd_live_config_parse(const struct vafmd *d, json_t *values, vafmd_live_config *c, struct vafmd_err *e);
/* True for a key of `values` that vafmd_live_config_parse takes. */
int vafmd_live_config_key(const char *name);
/* {name: {"unit", "kind", "doc"}} of the controller's settings get/set take (ctrl_*, monitor_rate_Hz,
 * ctrl_sample), from the table that defines them (vafmd --help lists them). New reference, NULL: no memory. */
json_t *vafmd_live_settings_info(void);

/* main.c: create the live state and the first controller (before the threads start; c NULL: defaults), free
 * it after. */
int vafmd_live_init(struct vafmd *d, const vafmd_live_config *c);
void vafmd_live_free(struct vafmd *d);

/* simulation thread */
void vafmd_live_apply(struct vafmd *d, const vafmd_live_op *op);
/* While idle: advance the controller to now (paced) and publish. @return when to look again (ns). */
int64_t vafmd_live_idle(struct vafmd *d, int64_t now_ns, int dead);
/* A run starts: its run.start JSON (*start_json, malloc'ed) gains "ctrl", the controller's state. */
void vafmd_live_run_start(struct vafmd *d, char **start_json);
/* An XPUB (un)subscription (topic prefix, n bytes): the live topic is published only while a subscription to
 * a non-empty prefix of "live" exists, so that a client subscribed to everything ("") sees no new topic unless
 * another asked for it (the stream stays what it was for existing clients). */
void vafmd_live_subscription(struct vafmd *d, const char *topic, size_t n, int on);
/* at the thread's exit */
void vafmd_live_sim_exit(struct vafmd *d);

/* control thread */
json_t *vafmd_live_cmd(struct vafmd *d, const struct vafmd_cmd *c, json_t *ok, struct vafmd_err *e);
json_t *vafmd_live_status_json(struct vafmd *d);
json_t *vafmd_live_hello_json(void);
/* get/set with the controller's settings (ctrl_*) and monitor_rate_Hz: wrap vafmd_get_values/vafmd_apply_set */
json_t *vafmd_live_get(struct vafmd *d, const struct vafmd_cmd *c, struct vafmd_err *e);
int vafmd_live_set(struct vafmd *d, const struct vafmd_cmd *c, struct vafmd_err *e);
/* A curve started from the live state: with a sample under the controller (ctrl_sample), *p becomes the scene at
 * the tip's position (vafm_map_point over d->scene: the material, E*, gamma, contact model and surface height
 * there, as a map pixel's) and *info (new reference) the point's ground truth and the sample, for run.start.
 * @return 1 (p changed), 0 (no sample: p untouched, *info NULL) or -1 (e says why). */
int vafmd_live_curve_scene(struct vafmd *d, vafm_params *p, json_t **info, struct vafmd_err *e);
/* A map from the live state: with a sample under the controller (ctrl_sample), *spec becomes its spec and *text
 * its ctrl_sample text (borrowed: valid until the next `set` on the control thread).
 * @return 1 (a sample is set) or 0 (none: spec and text untouched). */
int vafmd_live_sample(struct vafmd *d, vafm_map_spec *spec, const char **text);
/* cmd_json.c: decode the controller commands' arguments (engage, withdraw, move, z, feedback) */
int vafmd_live_decode(json_t *root, struct vafmd_cmd *c, struct vafmd_err *e);
#endif
