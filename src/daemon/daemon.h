/* SPDX-License-Identifier: MIT */
/*
 * vafmd internals shared by main.c, control.c and the simulation thread (sim_thread.h).
 *
 * Threads: the main thread runs the control loop (REP socket, JSON, scene) and the simulation thread
 * owns the PUB socket. The control thread hands work over through a lock-free SPSC ring of commands;
 * the simulation thread reports back only through atomic counters (never a lock, never a wait).
 */
#ifndef VAFMD_DAEMON_H
#define VAFMD_DAEMON_H
#include <jansson.h>
#include <pthread.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdint.h>
#include "core/channels.h"
#include "vafm/campaign.h"
#include "vafm/map.h"
#include "vafm/params.h"
#include "vafm/segments.h"
#include "vafm/sim.h"
#include "daemon/spsc_ring.h"
#include "daemon/faults.h"
#include "daemon/live.h"

#ifndef VAFM_PROJECT_VERSION
#define VAFM_PROJECT_VERSION "unknown"
#endif
#define VAFMD_VERSION VAFM_PROJECT_VERSION /* one version, from meson.build */
#define VAFMD_DEFAULT_REP "tcp://127.0.0.1:5555"
#define VAFMD_DEFAULT_PUB "tcp://127.0.0.1:5556"
#define VAFMD_MAX_CMD_BYTES 65536 /* larger requests get a "too_large" error reply */

/* Daemon settings that are not part of the physics scene (get/set like scene parameters). */
typedef struct vafmd_settings {
    double speed;               /* pacing speed factor, [0.01, 1000] (1: real time) */
    int free_run;               /* 1: no pacing, as fast as possible */
    double block_s;             /* samples per data block, as a duration, [1e-3, 1e-2] s */
    int hwm;                    /* PUB send high-water mark, messages per subscriber (set at start only) */
    int kernel;                 /* VAFMD_KERNEL_*: a campaign's curves by the simulation thread, or ahead by the
                                   batch kernel (free run, not a map: camp_feed.h) */
    double lookahead_s;         /* compute ahead: samples computed before their release, as a duration of
                                   samples, [0, 10] s (0: each block is computed just before its deadline);
                                   memory at most VAFMD_LOOKAHEAD_MAX_BYTES per run (fewer blocks then) */
    int segment_channel;        /* 1: runs stream the per-sample channel "segment" (core/channels.h), 0: not */
    /* The detector chain (sensitivity, noise, ADC, offset) is part of the scene (vafm_params, applied by
     * vafm/detector.h), so the CLI and the files have it too. */
} vafmd_settings;

enum { VAFMD_KERNEL_SCALAR = 0, VAFMD_KERNEL_BATCH = 1 };

void vafmd_settings_default(vafmd_settings *s);

enum vafmd_run_kind { VAFMD_RUN_CURVE = 0, VAFMD_RUN_TUNE = 1, VAFMD_RUN_REPLAY = 2 };
enum vafmd_sim_cmd_type {
    VAFMD_SIM_START = 1, VAFMD_SIM_ABORT = 2, VAFMD_SIM_QUIT = 3,
    VAFMD_SIM_FAULTS = 4,     /* a new fault plan (plan; NULL: none); the old one goes back on the retire ring */
    VAFMD_SIM_FAULT_NOTE = 5, /* a command fault the control thread injected: record and publish it */
    VAFMD_SIM_CTRL = 6,       /* a controller command or a new controller (live: live.h) */
};

/* A campaign (protocol/wire.md, `campaign`): the grid of `vafm campaign`, run curve after curve by the
 * simulation thread on its own. Global curve g (g = point·N + i, its random stream) is run
 * first_run_id + (g - first_index). Built and checked by the control thread, then owned by the
 * simulation thread (which frees it when the campaign ends). */
typedef struct vafmd_campaign {
    uint64_t campaign_id;
    vafm_params base;              /* the scene at the campaign command */
    double *lists;                 /* the T, v and k lists (one allocation); spec points into it */
    vafm_campaign_spec spec;       /* curves_per_point = N; first_curve = first_index */
    uint64_t total;                /* N · points: the grid's curves (global indices 0..total-1) */
    uint64_t next;                 /* global index of the next curve to start */
    uint64_t done;                 /* curves finished ok (simulation thread) */
    uint64_t first_run_id;         /* run id of global curve first_index */
    size_t sim_point;              /* grid point `sim` was built for, (size_t)-1: none */
    vafm_sim *sim;                 /* the simulation of sim_point (reused for its N curves) */
    vafmd_settings set;            /* settings in force for the whole campaign */
    int log;                       /* 1: log its curves */
    char client_run_id[65];
    /* a force map (the `map` command): a campaign over its pixels, one curve each (curve = iy·nx + ix) */
    int is_map;
    struct vafmd_feed *feed;       /* the batch kernel's feeder (camp_feed.h), NULL: the simulation thread computes */
    vafm_map_spec map;             /* spec.point_user points here */
    double lateral_speed_m_per_s;  /* the lateral move between pixels takes distance / this (paced runs) */
    int64_t move_until_ns;         /* the move to the next pixel ends then (0: none under way) */
    json_t *sample;                /* from the live state (ctrl_sample set): each run.start's "sample", or NULL */
} vafmd_campaign;

/* One command for the simulation thread (copied through the ring). */
typedef struct vafmd_sim_cmd {
    int type;
    int kind;            /* enum vafmd_run_kind */
    uint64_t run_id;
    uint64_t index;      /* curve index (RNG stream) */
    vafm_sim *sim;       /* START: ownership passes to the simulation thread */
    struct vafmd_replay *replay; /* START of a VAFMD_RUN_REPLAY (sim is NULL): ownership passes (replay.h) */
    char *start_json;    /* START: the "run.start" message (malloc'ed; ownership passes) */
    vafmd_settings set;  /* settings in force for this run */
    int log;             /* START: 1 = push the run's samples to the HDF5 writer thread */
    char client_run_id[65];
    vafmd_campaign *camp; /* START of a campaign (sim, start_json NULL): ownership passes */
    vafmd_fault_plan *plan; /* FAULTS: ownership passes (NULL: clear) */
    vafmd_fault_rec fault;  /* FAULT_NOTE */
    struct vafmd_feed_curve *feed; /* START of a fed campaign curve: its samples (ownership passes; sim: metadata) */
    vafmd_live_op live;     /* CTRL (live.h) */
    struct vafm_segment_spec *segs; /* START of a curve that runs a segment list (ownership passes), or NULL */
    size_t nseg;
} vafmd_sim_cmd;

/* ---- HDF5 logging (log.c) ------------------------------------------------------------------------
 * The simulation thread copies each released block of a logged curve into a log block taken from a
 * preallocated pool and pushes a pointer through the log ring (SPSC; a paced run never waits: a full
 * ring, or an empty pool, drops the block, counts an overflow and marks the curve broken; a broken curve
 * is not written; a free run waits for room instead, sim_logpool.c "Free run"). The writer thread assembles the curve, appends it, with a flush, when its LOG_END arrives,
 * and gives each block back through the free ring (a second SPSC ring, writer → simulation thread).
 * The pool's design and lifetime: sim_logpool.c, "The log block pool". */
enum vafmd_log_item_type { VAFMD_LOG_BEGIN = 1, VAFMD_LOG_BLOCK = 2, VAFMD_LOG_END = 3 };
#define VAFMD_LOG_RING_CAP 4096u /* blocks in flight: 20 s of samples at the default 5 ms blocks */
#define VAFMD_LOG_POOL_MAX_BYTES (256u << 20) /* sample memory of the log block pool (sim_logpool.c) */

struct vafmd_log_pool;
typedef struct vafmd_log_block {
    size_t n;                    /* samples in use */
    double *ch[VAFM_CH_COUNT];   /* the rows of core/channels.h that go into files (a dataset name), in
                                    its pool's sample memory; NULL for the others */
    unsigned mask;               /* the rows this block carries (the measured height: a piezo model or a
                                    z sensor) */
    uint8_t *segment;
    struct vafmd_log_pool *pool; /* the pool it belongs to (and goes back to) */
} vafmd_log_block;

/* A pool of log blocks of block_cap samples: ONE allocation (this header, the block headers, the free
 * stack, then the sample memory), so that free(pool) releases it whole. */
typedef struct vafmd_log_pool {
    struct vafmd_log_pool *next; /* simulation thread: retired pools; at its exit: the orphans list */
    size_t n_blocks, block_cap;
    size_t n_free;               /* blocks on the free stack (simulation thread only) */
    vafmd_log_block **free;      /* the free stack (into this allocation) */
    vafmd_log_block *blocks;     /* the n_blocks block headers (into this allocation) */
} vafmd_log_pool;

#define VAFMD_LOG_CTRL_MAX 4096
#define VAFMD_LOG_JOURNAL_MAX 100000 /* entries of "vafm ctrl" (commands + run states) per file, then a mark */
typedef struct vafmd_log_begin {
    vafm_params p;
    uint64_t run_id, index;
    size_t point;        /* campaign grid point (0 outside campaigns) */
    int detector;        /* 1: detector signals on: force is measured, the file gets no "tip position" */
    char client_run_id[65];
    int is_map;          /* a force map's pixel: the file gets afmformats' map attributes */
    vafm_map_spec map;
    vafm_map_truth pixel;
    char ctrl[VAFMD_LOG_CTRL_MAX]; /* run.start's "ctrl" and "sample" as one JSON object ("" none): the
                                      controller's state at the run's start, for the file's "vafm ctrl" */
    size_t nseg;                   /* a segment list's curve: its list (the file's "vafm segments <group>",
                                      format 1.3); 0: a force-distance curve */
    struct vafm_segment_spec segs[VAFM_SEGMENTS_MAX];
} vafmd_log_begin;

typedef struct vafmd_log_end {
    int ok;                   /* 1: the curve ran to its end (aborted and failed curves are not logged) */
    int broken;               /* 1: a block of it was lost (full ring, empty pool) */
    int force_altered;        /* 1: a saturate or stuck-dropout fault altered its force (protocol/faults.md) */
    vafm_curve_result result;
} vafmd_log_end;

typedef struct vafmd_log_item {
    int type;        /* enum vafmd_log_item_type */
    uint64_t run_id;
    void *ptr;       /* vafmd_log_begin / vafmd_log_end: ownership passes (the writer frees it);
                        vafmd_log_block: lent (the writer gives it back through the free ring) */
} vafmd_log_item;

enum vafmd_log_state { VAFMD_LOG_OFF = 0, VAFMD_LOG_ON = 1, VAFMD_LOG_STOPPING = 2 };

/* Writer thread → simulation thread: a logged curve is durable in the file (ok, its group), or will not
 * be written (ok 0). The simulation thread publishes it as an event "logged" / "log_failed" (wire.md
 * "log"): run.end comes first and says "log": "pending"; only this event says the curve is safe. */
typedef struct vafmd_log_notice {
    uint64_t run_id;
    uint64_t group; /* its curve group (file count − 1 after the append) */
    int ok;
} vafmd_log_notice;

/* The writer assembles a logged curve in memory before it appends it: at most this many samples (33
 * bytes each: 256 MiB, wire.md "log"). A run whose typical curve is longer is refused while logging is on;
 * a curve that grows past it anyway (no trigger, a late detachment) is not written (log_failed). */
#define VAFMD_LOG_MAX_CURVE_SAMPLES ((size_t)(256u << 20) / 33u)

#define VAFMD_LOG_NOTICE_CAP 256 /* the writer waits (it may; the simulation thread never does) when full */

typedef struct vafmd_log {
    vafmd_ring ring;               /* simulation thread → writer thread */
    vafmd_ring notice_ring;        /* writer thread → simulation thread: durability notices */
    vafmd_log_notice notice_store[VAFMD_LOG_NOTICE_CAP];
    vafmd_log_item *ring_store;
    vafmd_ring free_ring;          /* writer thread → simulation thread: log blocks to reuse (set up by the
                                      simulation thread before its first log item) */
    vafmd_log_block **free_store;  /* its slots; freed by the writer thread when it exits */
    vafmd_log_pool *orphans;       /* pools the simulation thread left at its exit with blocks still at the
                                      writer: freed by the writer thread when it exits (it exits after the
                                      simulation thread, main.c joins them in that order) */
    atomic_int state;              /* enum vafmd_log_state; OFF→ON by control, ON→STOPPING by control,
                                      STOPPING→OFF by the writer thread once the file is closed */
    struct vafm_recorder *w;       /* owned by the writer thread while state != OFF */
    char path[4096];
    atomic_uint_least64_t overflows;      /* blocks that found the ring full or the pool empty (simulation
                                             thread) */
    atomic_uint_least64_t curves;         /* curves written by this log */
    atomic_uint_least64_t curves_dropped; /* logged curves not written: broken or a write error */
    atomic_uint_least64_t curves_skipped; /* aborted/failed curves, not written */
    atomic_int quit;                      /* writer thread: exit once OFF */
    const char *test_stall;               /* tests only ($VAFMD_TEST_LOG_STALL): while this file exists the
                                             writer takes nothing from the ring (forces overflows) */
    pthread_mutex_t err_mu;               /* guards err (writer thread ↔ control thread) */
    char err[512];                        /* last write error, "" if none */
    vafmd_ring fault_ring;                /* simulation thread → writer: faults injected while logging is on,
                                             kept in the file's root attribute "vafm faults" (faults.md) */
    vafmd_fault_rec fault_store[256];
    pthread_mutex_t jmu;                  /* guards jpend, jseq (control thread ↔ writer thread; held briefly) */
    json_t *jpend;                        /* state-changing commands not yet taken by the writer (JSON array) */
    uint64_t jseq;                        /* commands handed over so far (jpend's last one's number) */
    atomic_uint_least64_t jdone;          /* the writer has made commands 1..jdone durable (or let them go: no
                                             file, or the journal full) */
    /* writer thread: the open file's root attribute "vafm ctrl" (protocol/hdf5.md) */
    json_t *jnote;
    const void *jnote_of;                 /* the recorder it belongs to (a new log starts a new journal) */
    char jlast[VAFMD_LOG_CTRL_MAX];       /* the last run state written into it */
    int jdirty;
} vafmd_log;

/* Control thread: a command that changed the controller's state (or may have: set) was applied; with
 * logging on, the writer adds it to the file's "vafm ctrl" journal (steals rec) and flushes the file. Returns
 * once it has (the command's reply says it is durable: protocol/hdf5.md), the log is no longer on, or after
 * VAFMD_LOG_JOURNAL_WAIT_NS (a writer held up: the record is still written, later). */
void vafmd_log_journal(struct vafmd *d, json_t *rec);
#define VAFMD_LOG_JOURNAL_WAIT_NS 2000000000LL

#define VAFMD_LOOKAHEAD_MAX_BYTES (256u << 20) /* memory of a run's compute-ahead FIFO (sim_thread.c) */
#define VAFMD_STREAM_MAX_BYTES (256u << 20)   /* samples queued for one subscriber (sim_publish.c) */
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
    atomic_uint_least64_t jobs_done;   /* jobs (a curve, a tune, a whole campaign) finished: the daemon is
                                          idle when it equals the control thread's jobs_started */
    atomic_uint_least64_t extra_runs;  /* campaign curves started after each campaign's first */
    atomic_uint_least64_t camp_id;     /* current (or last) campaign, 0: none */
    atomic_uint_least64_t camp_done;   /* its curves finished ok */
    atomic_uint_least64_t camp_next;   /* global index of its curve in progress (or next) */
    atomic_uint_least64_t queued;      /* blocks computed ahead, not yet released (current run) */
    atomic_uint_least64_t lookahead_blocks; /* capacity of the current (or last) run's FIFO, blocks */
    atomic_uint_least32_t session;     /* stream session (faults.md): changes with a `restart` fault */
    atomic_int fault_exit;             /* a `kill` fault: the exit status the daemon must stop with, 0: none */
} vafmd_shared;

/* CURVE security (auth.c). Configured = a server secret key is given; then both sockets are CURVE
 * servers and the ZAP thread admits only the listed client public keys. */
#define VAFMD_MAX_CLIENT_KEYS 1024
typedef struct vafmd_auth {
    int on;                       /* 1: CURVE on both sockets */
    char secret_z85[41];          /* server secret key, Z85 */
    char public_z85[41];          /* server public key, Z85 (derived from the secret key) */
    unsigned char (*clients)[32]; /* allow-list of client public keys (binary) */
    size_t n_clients;
    void *zap;                    /* REP on inproc://zeromq.zap.01, owned by the ZAP thread */
    atomic_int quit;
    atomic_uint_least64_t accepted, refused; /* handshakes admitted / refused */
} vafmd_auth;

typedef struct vafmd {
    void *zctx;
    void *rep, *pub;
    char pub_endpoint[512]; /* the stream endpoint as configured (hello tells clients) */
    vafmd_ring ring;
    vafmd_sim_cmd ring_store[VAFMD_RING_CAP];
    vafmd_shared sh;
    vafm_params scene;
    vafmd_settings set;
    uint64_t runs_started; /* control thread only (a campaign counts its first curve; sh.extra_runs the rest) */
    uint64_t jobs_started; /* control thread only: curves, tunes and campaigns handed to the simulation */
    uint64_t pending_run_id; /* control thread only: first run id of the last job started */
    uint64_t next_campaign_id; /* control thread only */
    uint64_t camp_total, camp_first, camp_n, camp_run_id; /* control thread only: the last campaign's
                                                              grid and first run id (status) */
    uint64_t next_run_id;  /* control thread only */
    volatile sig_atomic_t *stop; /* set by SIGINT/SIGTERM */
    atomic_int quitting;         /* set by main before it pushes QUIT: a stall fault ends at once */
    vafmd_log log;
    vafmd_auth auth;
    /* fault injection (faults.h): the control thread's copy of the plan, the plan as given (for the
     * query), the injected faults the simulation thread reports back, replaced plans to free */
    vafmd_fault_plan *fplan;
    json_t *fplan_json;
    uint64_t fault_requests;          /* requests seen since the plan was set (random command faults) */
    uint64_t fault_match[VAFMD_FAULT_SCRIPT_MAX]; /* per script entry: matching requests so far */
    vafmd_ring fault_ring;            /* simulation → control: injected faults (status) */
    vafmd_fault_rec fault_store[256];
    vafmd_ring retire_ring;           /* simulation → control: replaced plans, freed here */
    vafmd_fault_plan *retire_store[VAFMD_RING_CAP * 2];
    uint64_t faults_total;            /* control thread: faults recorded */
    vafmd_fault_rec fault_last[VAFMD_FAULT_LAST];
    int exit_status;                  /* control loop: the process exit status (a kill fault's) */
    struct vafmd_live *live;          /* the always-on controller (live.c; owned by main) */
} vafmd;

/* sim_thread.c */
void *vafmd_sim_main(void *arg);
/* sim_publish.c: send one n-part message on the PUB socket without blocking (EINTR retried). nodrop NULL: with
 * ZMQ_XPUB_NODROP as it is; else *nodrop caches that setting, turned on for the send: a message that some
 * matching subscriber has no room for (EAGAIN) then goes out lossy (to everyone with room), the setting off.
 * @return 0 the message went out whole, 1 it went out lossy, VAFM_EIO it did not go out (refused, nodrop NULL,
 * or the socket failed; errno says why). */
int vafmd_pub_send(void *pub, int *nodrop, const void *const *part, const size_t *len, int n);
/* The same for the two parts [topic, text]. */
int vafmd_pub_send_text(void *pub, int *nodrop, const char *topic, const char *text);
/* The same for [topic, j's compact JSON]; j is taken (decref'd). VAFM_ENOMEM: j could not be written, nothing
 * was sent. */
int vafmd_pub_send_json(void *pub, int *nodrop, const char *topic, json_t *j);
/* log.c: the HDF5 writer thread */
void *vafmd_log_main(void *arg);
/* auth.c: bind the ZAP socket (before any CURVE socket binds), make a socket a CURVE server, and the
 * ZAP handler thread. @return 0 or -1 (errno from ZeroMQ). */
int vafmd_auth_bind(vafmd *d);
int vafmd_auth_secure(vafmd *d, void *sock);
void *vafmd_auth_main(void *arg);
/* control.c: serve until shutdown or a signal. @return 0 on a clean stop. */
int vafmd_control_loop(vafmd *d);
/* control.c: check and install a fault plan (the config file's "faults", the `faults` command). @return 0
 * or -1 with e filled (nothing changed). */
struct vafmd_err;
int vafmd_faults_configure(vafmd *d, json_t *plan, struct vafmd_err *e);
#endif
