/* SPDX-License-Identifier: MIT */
/*
 * The simulation thread (vafmd_sim_main): advances the running scene block by block, releases each block
 * at an absolute CLOCK_MONOTONIC deadline (t_start + (end sample of the block)/fs/speed: no drift, whatever the
 * computation time), and publishes it on the XPUB socket it owns.
 *
 * Compute ahead: the cost of a sample is not uniform (the contact phase near detachment steps more
 * slowly than real time while the whole curve is faster), so blocks are computed into a bounded FIFO
 * (the `lookahead_s` setting: seconds of samples, preallocated at run start, ≤ VAFMD_LOOKAHEAD_MAX_BYTES)
 * and released from it at their deadlines. The loop: release every queued block whose deadline has
 * passed; else compute a piece of the next block if there is room; else sleep until the head's deadline
 * (at most 1 ms, to keep looking at the command ring). A block is computed in pieces (~20 µs of work each:
 * sized from the measured cost per sample, and at most S_PIECE_STEPS integrator steps, inside a sample if
 * need be, through vafm_sim_advance_steps; at most S_PIECE_NS of work before the loop looks again) so
 * that a due block waits at most one piece. Release
 * does exactly what publication did before compute-ahead (header, events, log block, counters), so the
 * stream and the log file do not depend on the lookahead; unreleased blocks were never published and are
 * dropped by abort/shutdown.
 *
 * It never waits on anyone: commands arrive through the SPSC ring (polled between pieces), reports go
 * out through atomics, and the socket is used with ZMQ_DONTWAIT. A subscriber at its high-water mark
 * loses the message (counted), the others still get it. Nor does it call malloc/free per block for the
 * log (a glibc allocator lock may be held by another thread): see "The log block pool" in sim_logpool.c. What
 * still allocates per block is libzmq (zmq_send copies frames of more than 33 bytes into heap messages;
 * no way around it with ZeroMQ) and jansson for the JSON events (a few per curve, not per block).
 */
/*
 * Its files, one responsibility each, share the run's state below (only this thread touches it):
 *   sim_thread.c    the loop: commands, run start and end, computing blocks into the FIFO, campaigns
 *   sim_publish.c   the socket: sending, the stream bound, releasing a block (header, arrays, events,
 *                   counters), heartbeats and new subscribers, the release-lateness histogram
 *   sim_logpool.c   the log: the block pool, handing items to the writer, a free run waiting for it
 *   sim_faults.c    fault injection: decides and applies the plan's faults; at a block's release it returns
 *                   an action (release, hold, end the run) that the loop carries out, never calling back
 */
#ifndef VAFMD_SIM_THREAD_H
#define VAFMD_SIM_THREAD_H

#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <jansson.h>
#include <zmq.h>
#include "core/channels.h"
#include "daemon/camp_feed.h"
#include "daemon/daemon.h"
#include "daemon/replay.h"
#include "daemon/run_json.h"
#include "vafm/detector.h"
#include "vafm/rng.h"
#include "vafm/wire.h"

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "vafmd sends channel arrays in host order: big-endian hosts need a byte swap (not yet implemented)"
#endif

#define VAFMD_ST_NS 1000000000LL
#define VAFMD_ST_MAX_EVENTS 16

typedef struct vafmd_st_event {
    uint64_t sample;
    int from, to;
} vafmd_st_event;

/* A computed block waiting for its deadline in the run's FIFO. */
typedef struct vafmd_st_block {
    size_t n;                          /* samples */
    double *ch[VAFM_CH_COUNT];  /* into the run's preallocated store; NULL: channel not streamed */
    uint32_t flags;                    /* LAST, SEG_CHANGE, CLIPPED (LATE and FREE_RUN at release) */
    uint8_t first_seg;
    vafmd_st_event ev[VAFMD_ST_MAX_EVENTS];
    int n_ev;
    vafmd_replay_event rev[VAFMD_REPLAY_MAX_EVENTS]; /* replay: curves that began in this block */
    int n_rev;
    int64_t deadline;                  /* CLOCK_MONOTONIC ns */
    int64_t ready;                     /* when its computation ended */
    double *log_t;                     /* a logged run: its samples' times and segments (the logged */
    uint8_t *log_seg;                  /* height, force and tip are the channels' own arrays), else NULL */
    int n_frec;                        /* controller faults applied to this block: published after it */
    vafmd_fault_rec frec[3];
} vafmd_st_block;

/* Release lateness of the paced blocks of a run (send time − deadline), for run.end's percentiles: a
 * fixed histogram, so recording costs a clock read and an increment (no allocation, no sort). 1 µs bins
 * below 1 ms (the target scale), 100 µs bins to ~105 ms, then one overflow bin; quantiles report a bin's
 * upper edge (capped by the exact maximum). */
#define VAFMD_ST_REL_FINE 1000
#define VAFMD_ST_REL_BINS 2048

typedef struct vafmd_st_run {
    int active;
    vafmd_sim_cmd cmd;     /* START command: sim, start_json, settings */
    size_t block_n;
    double *ch[VAFM_CH_COUNT]; /* + time_s (replays), height_measured_m; a channel not streamed is NULL */
    double sens;           /* m/V: vDeflection = deflection / sens (a replay: its curve's sensitivity) */
    size_t fill;
    uint8_t first_seg;
    int seg_change;
    int prev_seg;          /* segment of the previous sample, -1 before the first */
    vafmd_st_event ev[VAFMD_ST_MAX_EVENTS];
    int n_ev;
    uint64_t block_index, samples, first_seq, late_blocks, worst_late_ns, dropped_at_start;
    int64_t t_start;       /* CLOCK_MONOTONIC ns */
    int overrun_reported;
    vafmd_log *log;        /* non-NULL: the run is logged (a curve with logging on) */
    double *lt;            /* log_t and log_seg of the block being filled (NULL: not logged) */
    uint8_t *lseg;
    int log_broken;        /* a log item was lost (full ring, empty pool): the writer drops the curve */
    /* detector chain (vafmd_settings): on, its noise stream, ADC step and code range, spring constant */
    vafm_detector det;     /* the measured chain (vafm/detector.h); det.clipped: a sample of the current
                              block hit the ADC range */
    /* compute-ahead FIFO: qn complete blocks from q[qhead]; the block being filled (if filling) is
     * q[(qhead + qn) % qcap]; ch[], lt, lseg, fill, ev above describe that block while it fills */
    vafmd_st_block *q;
    double *qstore;        /* the channel (and log time) arrays of all slots (one allocation at run start) */
    uint8_t *qseg;         /* the log segment arrays of all slots (a logged run), or NULL */
    size_t qcap, qhead, qn;
    int filling;
    int src_rc;            /* the source's last return: 1 more to come, 0 ended, < 0 error */
    uint64_t computed;     /* samples in complete blocks (queued or published) */
    double sample_ns;      /* estimated compute time of one sample (fast attack, slow decay) */
    double piece_ns;       /* estimated compute time of one piece (a call of the source) */
    uint32_t rel_hist[VAFMD_ST_REL_BINS]; /* release lateness histogram (paced runs) */
    uint64_t rel_n;
    int64_t rel_max_ns;
    /* fault injection (faults.h; untouched without a plan) */
    int64_t frun_block[VAFMD_F_N]; /* per-run random faults: the block they strike, -1: none */
    uint64_t fdecided;             /* transport faults decided for blocks below this index */
    int64_t hold_until;            /* late/jitter: the head block is held until then */
    int n_held;
    vafmd_fault_rec held[2];       /* late, jitter: published after the held block */
    int restart_due;
    vafmd_fault_rec restart_rec;
    uint64_t drop_left;            /* blocks still to drop */
    vafmd_fault_rec drop_rec;
    uint64_t sat_left, dout_left;  /* controller faults: samples still to alter */
    int force_altered;             /* a controller fault altered the measured chain: the log's force is a
                                      measured one (no tip position column, as with the detector on) */
    double sat_level;
    int dout_stuck;
    int no_trig;                   /* a no_trigger fault struck this curve: its record waits for the turn */
    size_t feed_pos;               /* a fed curve (cmd.feed): its samples handed over so far */
    vafmd_fault_rec no_trig_rec;
    double last_v[3];              /* vDeflection, deflection, force of the last sample computed */
    int fault_silent;              /* truncate/kill: the run ends without run.end and is not logged */
} vafmd_st_run;

typedef struct vafmd_st {
    vafmd *d;
    vafmd_st_run run;
    vafmd_campaign *camp;  /* the campaign in progress (owned), or NULL */
    int nodrop;            /* current ZMQ_XPUB_NODROP setting */
    int sndhwm;            /* current ZMQ_SNDHWM of the stream (vafmd_st_stream_bound), 0: the start's */
    int64_t t_boot;        /* CLOCK_MONOTONIC ns at thread start */
    vafmd_log_pool *pool;  /* the log block pool of the current block size, or NULL */
    vafmd_log_pool *retired; /* replaced pools with blocks still at the writer (freed once all are home) */
    size_t pool_test_n;    /* $VAFMD_TEST_LOG_POOL (tests only): at most this many blocks a pool, 0: no limit */
    vafmd_fault_plan *fp;  /* the fault plan (owned; given back through the retire ring), NULL: none */
    uint64_t fault_n;      /* faults recorded */
    int64_t stall_until;   /* a stall: nothing at all is sent until then (0: none) */
    vafmd_fault_rec stall_rec;
    int dead;              /* a kill fault: nothing is sent any more; the control thread exits */
    uint64_t last_run_blocks; /* blocks of the last run: where per-run random faults may strike */
} vafmd_st;

/* sim_publish.c: the socket and the release of a block */
int64_t vafmd_st_rel_quantile(const vafmd_st_run *r, double q); /* release lateness quantile, ns */
int64_t vafmd_st_now(void);                                     /* CLOCK_MONOTONIC, ns */
void vafmd_st_sleep_until(int64_t t);                           /* absolute CLOCK_MONOTONIC ns */
size_t vafmd_st_channels(unsigned chmask);                      /* channels of a channel mask */
void vafmd_st_stream_bound(vafmd_st *x, unsigned chmask, size_t block_n, int hwm_set);
void vafmd_st_send_json(vafmd_st *x, const char *topic, json_t *j); /* j stolen; never waits */
void vafmd_st_send_text(vafmd_st *x, const char *topic, const char *text);
void vafmd_st_release(vafmd_st *x, int64_t now);                /* publish the FIFO's head block */
void vafmd_st_heartbeat(vafmd_st *x, int64_t now);
void vafmd_st_subscriptions(vafmd_st *x);                       /* greet new subscribers */

/* sim_faults.c: fault injection (faults.h, protocol/faults.md) */
void vafmd_st_fault_record(vafmd_st *x, vafmd_fault_rec *fr);   /* publish and hand on a fault's record */
int vafmd_st_no_trigger_due(vafmd_st *x);                         /* a no_trigger fault for this curve? */
void vafmd_st_fault_run_begin(vafmd_st *x);                       /* where per-run random faults strike */
void vafmd_st_fault_compute(vafmd_st *x, vafmd_st_block *b, uint64_t bi); /* controller faults on a block */
/* what the loop does with the head block after the transport faults were decided (vafmd_st_fault_release) */
enum { VAFMD_ST_FA_RELEASE, VAFMD_ST_FA_HOLD, VAFMD_ST_FA_END };
int vafmd_st_fault_release(vafmd_st *x, int64_t now, vafmd_fault_rec *end);
void vafmd_st_fault_released(vafmd_st *x, vafmd_st_block *b);    /* records of the faults of a sent block */

/* sim_logpool.c: the log block pool and the writer hand-over */
void vafmd_st_pool_reclaim(vafmd_log *L);                    /* blocks the writer gave back */
void vafmd_st_pool_retire(vafmd_st *x);
void vafmd_st_pool_prepare(vafmd_st *x, int logged, size_t block_n); /* at run start */
int vafmd_st_log_push(vafmd_st_run *r, int type, void *ptr); /* to the writer; 1 if it has it */
int vafmd_st_log_room(vafmd_st *x, size_t need);             /* the log ring has room for need items */
int vafmd_st_log_ready(vafmd_st *x);                         /* a free run's logged block may go now */
void vafmd_st_log_wait_room(vafmd_st *x);                    /* a free run's begin item waits for room */
void vafmd_st_log_block(vafmd_st *x, const vafmd_st_block *b); /* a released block's samples to the log */
void vafmd_st_log_notices(vafmd_st *x);                      /* publish the writer's notices */

/* sim_thread.c: the run */
double vafmd_st_run_fs(const vafmd_st_run *r);               /* the run's sample rate, Hz */

#endif
