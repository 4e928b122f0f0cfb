/* SPDX-License-Identifier: MIT */
/*
 * The always-on controller's private interface, shared by live.c (the simulation thread's side: pacing,
 * decimation, publishing, applying commands) and live_cmd.c (the control thread's side: hello, status,
 * the commands, get/set of its settings, the configuration). Split out of live.c (issue #25: no source file
 * over 1000 lines); nothing else includes it. The design is in live.h and at the head of live.c.
 */
#ifndef VAFMD_LIVE_INT_H
#define VAFMD_LIVE_INT_H
#include <pthread.h>
#include <stddef.h>
#include <stdint.h>
#include "daemon/daemon.h"
#include "daemon/live.h"

#define S_NS 1000000000LL
#define S_GAP_NS 50000000LL   /* a longer gap between two idle calls re-anchors the pacing */
#define S_BUDGET_NS 2000000LL /* work per idle call at most (then the live scene falls behind, re-anchored) */
#define S_MAX_PTS 1024
#define S_PEND 32             /* commands held for their at_s */
#define S_ACK_WAIT_NS 1000000000LL
#define S_SAMPLE_MAX 1024   /* ctrl_sample: the longest spec text */

/* The live channels, declared once: name, unit, the vafm_ctrl_samples array (state: uint8_t, the last). */
typedef struct s_live_channel {
    const char *name, *unit;
    size_t off;
} s_live_channel;
#define S_CH(n, u, f) { n, u, offsetof(vafm_ctrl_samples, f) }
static const s_live_channel s_live_channels[] = {
    S_CH("time_s", "s", time_s),
    S_CH("motor_z_m", "m", motor_z_m),
    S_CH("piezo_z_m", "m", piezo_z_m),
    S_CH("x_m", "m", x_m),
    S_CH("y_m", "m", y_m),
    S_CH("deflection_m", "m", deflection_m),
    S_CH("force_N", "N", force_N),
    S_CH("signal_V", "V", signal_V),
    S_CH("error_N", "N", error_N),
    S_CH("state", "", state), /* enum vafm_ctrl_state after the point's last sample */
    S_CH("surface_m", "m", surface_m), /* ground truth */
    S_CH("gap_m", "m", gap_m),
};
#undef S_CH
#define S_NCH (sizeof s_live_channels / sizeof s_live_channels[0])
#define S_STATE_CH 9

typedef struct s_snap {
    int have;              /* a controller exists */
    char why[256];         /* else why not */
    vafm_ctrl_status st;
    vafm_ctrl_params cp;
    double fs, monitor_rate_Hz;
    uint64_t generation, seq, dropped, decimation;
    int held;              /* commands waiting for their at_s */
} s_snap;

struct vafmd_live {
    /* ---- simulation thread ---- */
    vafm_ctrl *ctrl;
    vafm_map_spec *map;    /* the sample the controller borrows (NULL: a flat uniform sample) */
    uint64_t generation;   /* controllers made so far (the first is 1) */
    char why[256];
    double fs, speed, rate;
    int64_t anchor_ns, last_ns;
    uint64_t anchor_sample, cur;
    double t0;             /* the controller's clock base (status.clock_base_s): at_s → sample from there */
    uint64_t s0;
    int anchored, dead;
    uint64_t decim;
    double acc[S_NCH];
    uint64_t acc_n;
    double out[S_NCH][S_MAX_PTS];
    size_t out_n, out_target;
    uint64_t out_first;    /* controller sample of the first point's first sample */
    uint64_t seq, dropped;
    unsigned subs;         /* bit n-1: a subscription to the first n bytes of "live" is in place */
    vafmd_live_op pend[S_PEND];
    size_t n_pend;
    vafmd *d;
    /* ---- simulation → control: the answer to the last request (written before ack is released) ---- */
    atomic_uint_least64_t ack;
    vafmd_err ack_err;
    int ack_rc;
    int ack_late;          /* the command's at_s had passed when it arrived: applied at once */
    /* ---- the status snapshot: the simulation thread only TRY-locks ---- */
    pthread_mutex_t mu;
    s_snap snap;
    /* ---- control thread ---- */
    uint64_t next_req;
    vafm_ctrl_params cp;   /* the settings the next controller is built with */
    double rate_ctl;
    uint64_t scene_hash;   /* FNV-1a of the scene's JSON the controller was built over */
    vafm_map_spec sample;  /* ctrl_sample: the sample under the controller (has_sample 0: a flat uniform one) */
    int has_sample;
    char sample_text[S_SAMPLE_MAX + 1];
};

/* FNV-1a of the scene's JSON (0 if it cannot be written). */
uint64_t vafmd_live_scene_hash(const vafm_params *p);
/* Build a controller over the scene (control thread, or main before the threads); NULL with why filled. */
vafm_ctrl *vafmd_live_build(const vafm_params *scene, const vafm_ctrl_params *cp, const vafm_map_spec *map,
                            char *why, size_t whylen);

#endif
