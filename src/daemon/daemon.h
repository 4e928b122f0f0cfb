/* SPDX-License-Identifier: MIT */
/*
 * vafmd internals shared by main.c, control.c and sim_thread.c.
 *
 * Threads: the main thread runs the control loop (REP socket, JSON, scene) and the simulation thread
 * owns the PUB socket. The control thread hands work over through a lock-free SPSC ring of commands;
 * the simulation thread reports back only through atomic counters (never a lock, never a wait).
 */
#ifndef VAFMD_DAEMON_H
#define VAFMD_DAEMON_H
#include <signal.h>
#include <stdatomic.h>
#include <stdint.h>
#include "vafm/params.h"
#include "vafm/sim.h"
#include "daemon/spsc_ring.h"

#define VAFMD_VERSION "0.1.0"
#define VAFMD_DEFAULT_REP "tcp://127.0.0.1:5555"
#define VAFMD_DEFAULT_PUB "tcp://127.0.0.1:5556"
#define VAFMD_MAX_CMD_BYTES 65536 /* larger requests get a "too_large" error reply */
#define VAFMD_N_CHANNELS 5

/* Daemon settings that are not part of the physics scene (get/set like scene parameters). */
typedef struct vafmd_settings {
    double speed;               /* pacing speed factor, [0.01, 1000] (1: real time) */
    int free_run;               /* 1: no pacing, as fast as possible */
    double sensitivity_m_per_V; /* InvOLS: vDeflection = deflection / sensitivity, m/V */
    double block_s;             /* samples per data block, as a duration, [1e-3, 1e-2] s */
    int hwm;                    /* PUB send high-water mark, messages per subscriber (set at start only) */
} vafmd_settings;

void vafmd_settings_default(vafmd_settings *s);

enum vafmd_run_kind { VAFMD_RUN_CURVE = 0, VAFMD_RUN_TUNE = 1 };
enum vafmd_sim_cmd_type { VAFMD_SIM_START = 1, VAFMD_SIM_ABORT = 2, VAFMD_SIM_QUIT = 3 };

/* One command for the simulation thread (copied through the ring). */
typedef struct vafmd_sim_cmd {
    int type;
    int kind;            /* enum vafmd_run_kind */
    uint64_t run_id;
    uint64_t index;      /* curve index (RNG stream) */
    vafm_sim *sim;       /* START: ownership passes to the simulation thread */
    char *start_json;    /* START: the "run.start" message (malloc'ed; ownership passes) */
    vafmd_settings set;  /* settings in force for this run */
    char client_run_id[65];
} vafmd_sim_cmd;

#define VAFMD_MAX_BLOCK_SAMPLES 262144 /* bounds a block's memory at very high sample rates */
/* Samples per data block: round(fs · block duration), at least 1, at most VAFMD_MAX_BLOCK_SAMPLES. */
static inline size_t vafmd_block_samples(double fs, double block_s)
{
    double n = fs * block_s + 0.5;
    if (!(n >= 1))
        return 1;
    return n > VAFMD_MAX_BLOCK_SAMPLES ? VAFMD_MAX_BLOCK_SAMPLES : (size_t)n;
}

enum vafmd_state { VAFMD_IDLE = 0, VAFMD_RUNNING = 1 };

/* Written by the simulation thread only, read by the control thread (relaxed: they are reports). */
typedef struct vafmd_shared {
    atomic_int state;                 /* enum vafmd_state */
    atomic_uint_least64_t run_id;     /* current (or last) run */
    atomic_uint_least64_t runs_done;  /* runs finished (ended, aborted, failed) */
    atomic_uint_least64_t samples;    /* samples published, all runs */
    atomic_uint_least64_t blocks;     /* data blocks published */
    atomic_uint_least64_t late_blocks;
    atomic_uint_least64_t worst_late_ns;
    atomic_uint_least64_t dropped;    /* overflows: messages that found a subscriber's queue full (a lower
                                         bound of the losses: ZeroMQ then skips that subscriber silently
                                         until it drains) */
    atomic_uint_least64_t seq;        /* next data sequence number */
    atomic_uint_least64_t run_samples; /* samples of the current run so far */
} vafmd_shared;

typedef struct vafmd {
    void *zctx;
    void *rep, *pub;
    vafmd_ring ring;
    vafmd_sim_cmd ring_store[VAFMD_RING_CAP];
    vafmd_shared sh;
    vafm_params scene;
    vafmd_settings set;
    uint64_t runs_started; /* control thread only */
    uint64_t next_run_id;  /* control thread only */
    volatile sig_atomic_t *stop; /* set by SIGINT/SIGTERM */
} vafmd;

/* sim_thread.c */
void *vafmd_sim_main(void *arg);
/* control.c: serve until shutdown or a signal. @return 0 on a clean stop. */
int vafmd_control_loop(vafmd *d);
#endif
