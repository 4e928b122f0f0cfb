/* SPDX-License-Identifier: MIT */
/*
 * The simulation thread: advances the running scene block by block, releases each block at an absolute
 * CLOCK_MONOTONIC deadline (t_start + (end sample of the block)/fs/speed: no drift, whatever the
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
 * log (a glibc allocator lock may be held by another thread): see "The log block pool" below. What
 * still allocates per block is libzmq (zmq_send copies frames of more than 33 bytes into heap messages;
 * no way around it with ZeroMQ) and jansson for the JSON events (a few per curve, not per block).
 */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#ifdef __linux__
#include <sys/prctl.h>
#endif
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

#define S_NS 1000000000LL
#define S_MAX_EVENTS 16
#define S_PIECE_NS 500000LL /* compute at most this long (plus one piece) before releasing or polling */
/* a piece of computation bounds how long a due block can wait for its release: ~20 µs of work, sized
 * from the measured cost per sample and capped in integrator steps (with pieces of 1/16 block the
 * release lateness was p99 ~0.2–0.4 ms for paper-fig4 curves, 0.9 ms for the default scene at 2 kS/s) */
#define S_PIECE_TARGET_NS 20000.0
#define S_PIECE_STEPS 512 /* integrator steps a piece at most (~18 µs at ~35 ns a step in contact) */

typedef struct s_event {
    uint64_t sample;
    int from, to;
} s_event;

/* A computed block waiting for its deadline in the run's FIFO. */
typedef struct s_block {
    size_t n;                          /* samples */
    double *ch[VAFM_CH_COUNT];  /* into the run's preallocated store; NULL: channel not streamed */
    uint32_t flags;                    /* LAST, SEG_CHANGE, CLIPPED (LATE and FREE_RUN at release) */
    uint8_t first_seg;
    s_event ev[S_MAX_EVENTS];
    int n_ev;
    vafmd_replay_event rev[VAFMD_REPLAY_MAX_EVENTS]; /* replay: curves that began in this block */
    int n_rev;
    int64_t deadline;                  /* CLOCK_MONOTONIC ns */
    int64_t ready;                     /* when its computation ended */
    double *log_t;                     /* a logged run: its samples' times and segments (the logged */
    uint8_t *log_seg;                  /* height, force and tip are the channels' own arrays), else NULL */
    int n_frec;                        /* controller faults applied to this block: published after it */
    vafmd_fault_rec frec[3];
} s_block;

/* Release lateness of the paced blocks of a run (send time − deadline), for run.end's percentiles: a
 * fixed histogram, so recording costs a clock read and an increment (no allocation, no sort). 1 µs bins
 * below 1 ms (the target scale), 100 µs bins to ~105 ms, then one overflow bin; quantiles report a bin's
 * upper edge (capped by the exact maximum). */
#define S_REL_FINE 1000
#define S_REL_BINS 2048

typedef struct s_run {
    int active;
    vafmd_sim_cmd cmd;     /* START command: sim, start_json, settings */
    size_t block_n;
    double *ch[VAFM_CH_COUNT]; /* + time_s (replays), height_measured_m; a channel not streamed is NULL */
    double sens;           /* m/V: vDeflection = deflection / sens (a replay: its curve's sensitivity) */
    size_t fill;
    uint8_t first_seg;
    int seg_change;
    int prev_seg;          /* segment of the previous sample, -1 before the first */
    s_event ev[S_MAX_EVENTS];
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
    s_block *q;
    double *qstore;        /* the channel (and log time) arrays of all slots (one allocation at run start) */
    uint8_t *qseg;         /* the log segment arrays of all slots (a logged run), or NULL */
    size_t qcap, qhead, qn;
    int filling;
    int src_rc;            /* the source's last return: 1 more to come, 0 ended, < 0 error */
    uint64_t computed;     /* samples in complete blocks (queued or published) */
    double sample_ns;      /* estimated compute time of one sample (fast attack, slow decay) */
    double piece_ns;       /* estimated compute time of one piece (a call of the source) */
    uint32_t rel_hist[S_REL_BINS]; /* release lateness histogram (paced runs) */
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
} s_run;

static void s_rel_add(s_run *r, int64_t late_ns)
{
    if (late_ns < 0)
        late_ns = 0;
    uint64_t i = (uint64_t)late_ns < S_REL_FINE * 1000u ? (uint64_t)late_ns / 1000u
                                                         : S_REL_FINE + ((uint64_t)late_ns - S_REL_FINE * 1000u) / 100000u;
    r->rel_hist[i < S_REL_BINS ? i : S_REL_BINS - 1]++;
    r->rel_n++;
    if (late_ns > r->rel_max_ns)
        r->rel_max_ns = late_ns;
}

/* The q-quantile of the release lateness, ns: the upper edge of the bin holding it (≤ the maximum). */
static int64_t s_rel_quantile(const s_run *r, double q)
{
    uint64_t want = (uint64_t)ceil(q * (double)r->rel_n), cum = 0;
    if (want < 1)
        want = 1;
    for (int i = 0; i < S_REL_BINS; i++) {
        cum += r->rel_hist[i];
        if (cum >= want) {
            int64_t edge = i < S_REL_FINE ? (int64_t)(i + 1) * 1000 : S_REL_FINE * 1000 + (int64_t)(i - S_REL_FINE + 1) * 100000;
            return edge < r->rel_max_ns ? edge : r->rel_max_ns;
        }
    }
    return r->rel_max_ns;
}

typedef struct s_ctx {
    vafmd *d;
    s_run run;
    vafmd_campaign *camp;  /* the campaign in progress (owned), or NULL */
    int nodrop;            /* current ZMQ_XPUB_NODROP setting */
    int sndhwm;            /* current ZMQ_SNDHWM of the stream (s_stream_bound), 0: the start's */
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
} s_ctx;

static int64_t s_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * S_NS + ts.tv_nsec;
}

static void s_sleep_until(int64_t t)
{
    struct timespec ts = { (time_t)(t / S_NS), (long)(t % S_NS) };
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR)
        ;
}

static void s_set_nodrop(s_ctx *x, int on)
{
    if (x->nodrop != on) {
        zmq_setsockopt(x->d->pub, ZMQ_XPUB_NODROP, &on, sizeof on);
        x->nodrop = on;
    }
}

/* The channels a run streams (bits of its channel mask). */
static size_t s_channels(unsigned chmask)
{
    return (size_t)__builtin_popcount(chmask & ((1u << VAFM_CH_COUNT) - 1u));
}

/* Bound each subscriber's queue in bytes as well as in messages: the setting hwm counts messages, and
 * a data message of a run carries up to VAFMD_MAX_BLOCK_SAMPLES samples of each channel (≈ 10 MB), so
 * a subscriber that stops reading could make the daemon queue hwm × 10 MB (GB at the default 1000).
 * Before a run, the send high-water mark becomes min(hwm, VAFMD_STREAM_MAX_BYTES / the run's largest
 * message), at least 2; libzmq applies a changed ZMQ_SNDHWM to the pipes already connected too. */
static void s_stream_bound(s_ctx *x, unsigned chmask, size_t block_n, int hwm_set)
{
    const size_t nch = s_channels(chmask);
    const double msg = 256.0 + (double)(nch * block_n * sizeof(double)); /* header and topic: < 256 B */
    double h = floor((double)VAFMD_STREAM_MAX_BYTES / msg);
    if (h > hwm_set)
        h = hwm_set;
    if (h < 2)
        h = 2;
    const int hwm = (int)h;
    if (hwm != x->sndhwm && zmq_setsockopt(x->d->pub, ZMQ_SNDHWM, &hwm, sizeof hwm) == 0)
        x->sndhwm = hwm;
}

/* Send one multipart message without blocking. With XPUB_NODROP on, a frame that some matching
 * subscriber has no room for fails with EAGAIN: that counts one drop, and the message then goes out
 * lossy (to everyone with room). @return 0, or -1 if the socket failed otherwise. */
static int s_send(s_ctx *x, const void *const *part, const size_t *len, int n)
{
    int dropped = 0;
    if (x->dead) /* a kill fault: the daemon is gone as far as the stream is concerned */
        return 0;
    s_set_nodrop(x, 1);
    for (int i = 0; i < n; i++) {
        int flags = ZMQ_DONTWAIT | (i + 1 < n ? ZMQ_SNDMORE : 0);
        int rc;
        while ((rc = zmq_send(x->d->pub, part[i], len[i], flags)) < 0 && errno == EINTR)
            ;
        if (rc < 0 && errno == EAGAIN && !dropped) {
            dropped = 1;
            s_set_nodrop(x, 0);
            while ((rc = zmq_send(x->d->pub, part[i], len[i], flags)) < 0 && errno == EINTR)
                ;
        }
        if (rc < 0)
            return -1;
    }
    if (dropped)
        atomic_fetch_add_explicit(&x->d->sh.dropped, 1, memory_order_relaxed);
    return 0;
}

static void s_send_json(s_ctx *x, const char *topic, json_t *j)
{
    char *text = json_dumps(j, JSON_COMPACT);
    json_decref(j);
    if (!text)
        return;
    const void *part[2] = { topic, text };
    size_t len[2] = { strlen(topic), strlen(text) };
    s_send(x, part, len, 2);
    free(text);
}

static void s_send_text(s_ctx *x, const char *topic, const char *text)
{
    const void *part[2] = { topic, text };
    size_t len[2] = { strlen(topic), strlen(text) };
    s_send(x, part, len, 2);
}

/* ---- Fault injection (faults.h, protocol/faults.md) -------------------------------------------------
 * Without a plan (x->fp NULL) every hook below is skipped by one predictable branch. With one, transport
 * faults are decided once per block at its release (s_fault_release), controller faults once per block
 * when its computation completes (s_fault_compute); decisions are stateless hashes of (seed, kind, run,
 * block), so a plan with a seed reproduces its faults. Each injected fault is recorded after it took
 * effect: published on the `faults` topic, handed to the control thread (status) and, with logging on,
 * to the log writer. None of it allocates (jansson's JSON for the topic aside, as for events). */

static double s_run_fs(const s_run *r);

static void s_fault_record(s_ctx *x, vafmd_fault_rec *fr)
{
    fr->n = ++x->fault_n;
    fr->session = (uint32_t)atomic_load_explicit(&x->d->sh.session, memory_order_relaxed);
    s_send_json(x, "faults", vafmd_fault_rec_json(fr));
    vafmd_ring_push(&x->d->fault_ring, fr); /* full (control thread far behind): status misses it, counted */
    if (atomic_load_explicit(&x->d->log.state, memory_order_acquire) == VAFMD_LOG_ON)
        vafmd_ring_push(&x->d->log.fault_ring, fr);
}

/* A record of kind k at block bi of the current run. */
static void s_fault_rec_init(s_ctx *x, vafmd_fault_rec *fr, int k, uint64_t bi, double p0, double p1, int scripted)
{
    s_run *r = &x->run;
    memset(fr, 0, sizeof *fr);
    fr->kind = k;
    fr->time_s = (double)(s_now() - x->t_boot) / 1e9;
    fr->run_id = r->cmd.run_id;
    fr->block = (int64_t)bi;
    fr->run_time_s = (double)(bi * r->block_n) / s_run_fs(r);
    fr->seq = -1;
    fr->p0 = p0;
    fr->p1 = p1;
    fr->scripted = (uint32_t)scripted;
}

/* Does fault kind k strike block bi of the current run? Its parameters then go to *p0, *p1. */
static int s_fault_due(s_ctx *x, int k, uint64_t bi, double *p0, double *p1, int *scripted)
{
    const vafmd_fault_plan *p = x->fp;
    const s_run *r = &x->run;
    for (size_t i = 0; i < p->n_script; i++) {
        const vafmd_fault_entry *en = &p->script[i];
        if (en->kind != k || (en->run && en->run != r->cmd.run_id))
            continue;
        uint64_t b = en->block >= 0 ? (uint64_t)en->block
                                    : (uint64_t)floor(en->time_s * s_run_fs(r) / (double)r->block_n);
        if (b == bi) {
            *p0 = en->p0;
            *p1 = en->p1;
            *scripted = 1;
            return 1;
        }
    }
    const vafmd_fault_random *rr = &p->rnd[k];
    if (!(rr->rate > 0))
        return 0;
    *p0 = rr->p0;
    *p1 = rr->p1;
    *scripted = 0;
    if (rr->per == VAFMD_FPER_BLOCK)
        return vafmd_fault_u01(p->seed, k, r->cmd.run_id, bi + 2) < rr->rate;
    return rr->per == VAFMD_FPER_RUN && r->frun_block[k] == (int64_t)bi;
}

/* A no_trigger fault for the curve starting now: a scripted entry for this run (or any run; its block and time
 * do not matter), or the per-run random rate. Its record is published with the block where the approach
 * turns (at its travel limit): after the fault took effect. */
static int s_no_trigger_due(s_ctx *x)
{
    const vafmd_fault_plan *p = x->fp;
    s_run *r = &x->run;
    r->no_trig = 0;
    if (__builtin_expect(p == NULL, 1))
        return 0;
    int hit = 0, sc = 0;
    double p0 = 0, p1 = 0;
    for (size_t i = 0; i < p->n_script && !hit; i++) {
        const vafmd_fault_entry *en = &p->script[i];
        if (en->kind == VAFMD_F_NO_TRIGGER && (!en->run || en->run == r->cmd.run_id))
            hit = sc = 1;
    }
    const vafmd_fault_random *rr = &p->rnd[VAFMD_F_NO_TRIGGER];
    if (!hit && rr->rate > 0 && rr->per != VAFMD_FPER_COMMAND)
        hit = vafmd_fault_u01(p->seed, VAFMD_F_NO_TRIGGER, r->cmd.run_id, 0) < rr->rate;
    if (hit) {
        r->no_trig = 1;
        s_fault_rec_init(x, &r->no_trig_rec, VAFMD_F_NO_TRIGGER, 0, p0, p1, sc);
    }
    return hit;
}

/* At run start: where this run's per-run random faults strike (a block drawn over the last run's length). */
static void s_fault_run_begin(s_ctx *x)
{
    s_run *r = &x->run;
    const vafmd_fault_plan *p = x->fp;
    uint64_t nb = x->last_run_blocks ? x->last_run_blocks : 16;
    for (int k = 0; k < VAFMD_F_N; k++) {
        r->frun_block[k] = -1;
        const vafmd_fault_random *rr = &p->rnd[k];
        if (rr->per == VAFMD_FPER_RUN && vafmd_fault_u01(p->seed, k, r->cmd.run_id, 0) < rr->rate)
            r->frun_block[k] = (int64_t)(vafmd_fault_u01(p->seed, k, r->cmd.run_id, 1) * (double)nb);
    }
}

/* Controller faults on a block just computed (index bi): ADC saturation and detector dropout act on the
 * measured chain (vDeflection_V, then deflection_m and force_N derived from it; height and the ground
 * truth tip_m stay), for `samples` samples from the block's first on, into the following blocks. */
static void s_fault_compute(s_ctx *x, s_block *b, uint64_t bi)
{
    s_run *r = &x->run;
    double *volts = b->ch[VAFM_CH_VDEFLECTION], *defl = b->ch[VAFM_CH_DEFLECTION], *force = b->ch[VAFM_CH_FORCE];
    if (r->cmd.replay || !defl || !force || !volts)
        return; /* a replay streams what was recorded */
    double p0, p1;
    int sc;
    b->n_frec = 0;
    if (s_fault_due(x, VAFMD_F_SATURATE, bi, &p0, &p1, &sc)) {
        r->sat_left = (uint64_t)p0;
        r->sat_level = p1;
        s_fault_rec_init(x, &b->frec[b->n_frec++], VAFMD_F_SATURATE, bi, p0, p1, sc);
    }
    if (s_fault_due(x, VAFMD_F_DROPOUT, bi, &p0, &p1, &sc)) {
        r->dout_left = (uint64_t)p0;
        r->dout_stuck = p1 != 0;
        s_fault_rec_init(x, &b->frec[b->n_frec++], VAFMD_F_DROPOUT, bi, p0, p1, sc);
    }
    if (r->no_trig && (b->flags & (VAFM_WIRE_FLAG_SEG_CHANGE | VAFM_WIRE_FLAG_LAST))) {
        r->no_trig_rec.block = (int64_t)bi; /* the approach ended at its limit in this block */
        r->no_trig_rec.run_time_s = (double)(bi * r->block_n) / s_run_fs(r);
        b->frec[b->n_frec++] = r->no_trig_rec;
        r->no_trig = 0;
    }
    double k = vafm_sim_params(r->cmd.sim)->k_N_per_m;
    size_t i = 0;
    if (r->sat_left) {
        for (; i < b->n && r->sat_left; i++, r->sat_left--) {
            volts[i] = r->sat_level;
            defl[i] = r->sat_level * r->sens;
            force[i] = k * defl[i];
        }
        b->flags |= VAFM_WIRE_FLAG_CLIPPED;
        r->force_altered = 1;
    }
    if (r->dout_left) {
        if (bi == 0 && !r->dout_stuck) /* nothing before: NaN; stuck at the first sample's values */
            r->last_v[0] = r->last_v[1] = r->last_v[2] = NAN;
        else if (bi == 0)
            r->last_v[0] = volts[0], r->last_v[1] = defl[0], r->last_v[2] = force[0];
        r->force_altered = 1;
        for (i = 0; i < b->n && r->dout_left; i++, r->dout_left--) {
            volts[i] = r->dout_stuck ? r->last_v[0] : NAN;
            defl[i] = r->dout_stuck ? r->last_v[1] : NAN;
            force[i] = r->dout_stuck ? r->last_v[2] : NAN;
        }
    }
    if (b->n) {
        r->last_v[0] = volts[b->n - 1];
        r->last_v[1] = defl[b->n - 1];
        r->last_v[2] = force[b->n - 1];
    }
}

static void s_run_end(s_ctx *x, const char *status, int err_code);

/* Transport faults at the release of the head block (index r->block_index), decided once per block.
 * @return 1: the block is not released now (held by late/jitter/stall, or the run is over: truncate,
 * kill), 0: release it (s_release then drops it or restarts the session as decided). */
static int s_fault_release(s_ctx *x, int64_t now)
{
    s_run *r = &x->run;
    uint64_t bi = r->block_index;
    if (r->fdecided > bi)
        return 0;
    r->fdecided = bi + 1;
    double p0, p1;
    int sc;
    vafmd_fault_rec fr;
    if (s_fault_due(x, VAFMD_F_KILL, bi, &p0, &p1, &sc) || s_fault_due(x, VAFMD_F_TRUNCATE, bi, &p0, &p1, &sc)) {
        int kill = s_fault_due(x, VAFMD_F_KILL, bi, &p0, &p1, &sc);
        s_fault_rec_init(x, &fr, kill ? VAFMD_F_KILL : VAFMD_F_TRUNCATE, bi, p0, p1, sc);
        fr.seq = (int64_t)atomic_load_explicit(&x->d->sh.seq, memory_order_relaxed);
        r->fault_silent = 1;
        s_run_end(x, "ok", 0); /* silent: no run.end, not logged; a campaign goes on (not after a kill) */
        s_fault_record(x, &fr);
        if (kill) {
            x->dead = 1;
            atomic_store_explicit(&x->d->sh.fault_exit, (int)p0, memory_order_release);
        }
        return 1;
    }
    int held = 0;
    if (s_fault_due(x, VAFMD_F_STALL, bi, &p0, &p1, &sc)) {
        s_fault_rec_init(x, &x->stall_rec, VAFMD_F_STALL, bi, p0, p1, sc);
        x->stall_until = now + (int64_t)llround(p0 * 1e9);
        held = 1;
    }
    r->n_held = 0;
    if (s_fault_due(x, VAFMD_F_LATE, bi, &p0, &p1, &sc)) {
        s_fault_rec_init(x, &r->held[r->n_held++], VAFMD_F_LATE, bi, p0, p1, sc);
        r->hold_until = now + (int64_t)llround(p0 * 1e9);
        held = 1;
    }
    if (s_fault_due(x, VAFMD_F_JITTER, bi, &p0, &p1, &sc)) {
        double dly = p0 * vafmd_fault_u01(x->fp->seed, VAFMD_F_JITTER, r->cmd.run_id, bi + (1ULL << 40));
        s_fault_rec_init(x, &r->held[r->n_held++], VAFMD_F_JITTER, bi, p0, dly, sc);
        int64_t t = now + (int64_t)llround(dly * 1e9);
        if (t > r->hold_until)
            r->hold_until = t;
        held = 1;
    }
    if ((r->restart_due = s_fault_due(x, VAFMD_F_RESTART, bi, &p0, &p1, &sc)) != 0)
        s_fault_rec_init(x, &r->restart_rec, VAFMD_F_RESTART, bi, p0, p1, sc);
    if (!r->drop_left && s_fault_due(x, VAFMD_F_DROP, bi, &p0, &p1, &sc)) {
        r->drop_left = (uint64_t)p0;
        s_fault_rec_init(x, &r->drop_rec, VAFMD_F_DROP, bi, p0, p1, sc);
    }
    return held;
}

/* After the head block went out (or was dropped): the records of the faults that took effect with it. */
static void s_fault_released(s_ctx *x, s_block *b)
{
    s_run *r = &x->run;
    for (int i = 0; i < r->n_held; i++)
        s_fault_record(x, &r->held[i]);
    r->n_held = 0;
    if (r->restart_due) {
        r->restart_due = 0;
        s_fault_record(x, &r->restart_rec);
    }
    for (int i = 0; i < b->n_frec; i++)
        s_fault_record(x, &b->frec[i]);
    b->n_frec = 0;
}

static const char *s_seg_name(int s)
{
    static const char *const n[] = { "approach", "retract", "dwell", "tune" };
    return s >= 0 && s < 4 ? n[s] : "unknown";
}

static int s_sink(void *user, const vafm_samples *b)
{
    s_run *r = user;
    if (!r->det.on) /* volts = deflection / the run's sensitivity (a replay: its curve's, set per batch) */
        r->det.sens = r->sens;
    for (size_t i = 0; i < b->n; i++) {
        size_t k = r->fill + i;
        if (k >= r->block_n)
            return 1; /* cannot happen: advance is asked for at most the room left */
        /* the measured rows come out of the detector chain (deflection and force derived from its volts;
         * the measured height from the z sensor, where the piezo is), the others from the block's arrays;
         * a channel the run does not stream is NULL (a replay streams what its file has) */
        double m[VAFM_CH_COUNT];
        vafm_detector_sample(&r->det, b, i, &m[VAFM_CH_VDEFLECTION], &m[VAFM_CH_DEFLECTION], &m[VAFM_CH_FORCE],
                             r->ch[VAFM_CH_HEIGHT_MEASURED] ? &m[VAFM_CH_HEIGHT_MEASURED] : NULL);
        for (int c = 0; c < VAFM_CH_COUNT; c++)
            if (r->ch[c])
                r->ch[c][k] = vafm_channels[c].kind == VAFM_CHK_MEASURED ? m[c] : vafm_channel_samples(b, c)[i];
        if (r->lt) { /* the log takes these and the table's file rows at release: the stream's doubles */
            r->lt[k] = b->time_s[i];
            r->lseg[k] = b->segment[i];
        }
        int seg = b->segment[i];
        if (k == 0)
            r->first_seg = (uint8_t)seg;
        if (r->prev_seg >= 0 && seg != r->prev_seg) {
            if (k > 0)
                r->seg_change = 1;
            if (r->n_ev < S_MAX_EVENTS)
                r->ev[r->n_ev++] = (s_event){ b->first + i, r->prev_seg, seg };
        }
        r->prev_seg = seg;
    }
    r->fill += b->n;
    return 0;
}

/* A fed curve's next samples, up to max: as vafm_sim_advance hands a computed curve's over, ending with its
 * status together with its last sample. */
static int s_feed_advance(s_run *r, size_t max)
{
    const vafmd_feed_curve *c = r->cmd.feed;
    size_t m = c->n - r->feed_pos < max ? c->n - r->feed_pos : max;
    if (m > 0) {
        const size_t i = r->feed_pos;
        vafm_samples b = { m, i, c->time_s + i, c->height_m + i, c->deflection_m + i, c->force_N + i, c->tip_m + i,
                           c->segment + i, c->height_measured_m ? c->height_measured_m + i : NULL };
        if (s_sink(r, &b))
            return VAFM_EABORT;
        r->feed_pos += m;
    }
    if (r->feed_pos < c->n)
        return 1;
    return c->status;
}

/* The curve result of a run: its simulation's, or the fed curve's. */
static int s_run_result(const s_run *r, vafm_curve_result *res)
{
    if (r->cmd.feed) {
        *res = r->cmd.feed->result;
        return 0;
    }
    return vafm_sim_result(r->cmd.sim, res);
}

/* The sample source of a run: advance it by at most max samples, handing them to s_sink (which fills
 * the block buffers from r->fill on). Contract for every source: @return 1 while the run goes on, 0 when
 * it ended -- together with its last sample, never on a later call, so that the block holding that
 * sample carries the LAST flag -- or a negative VAFM_E* code. */
static int s_advance(s_run *r, size_t max)
{
    /* replay: a VAFMD_RUN_REPLAY run takes its samples from the replay source here (src/daemon/replay.c) */
    if (r->cmd.replay)
        return vafmd_replay_advance(r->cmd.replay, max, s_sink, r, &r->sens);
    if (r->cmd.feed) /* a curve the batch kernel computed ahead (camp_feed.h): its samples as they are */
        return s_feed_advance(r, max);
    /* at most S_PIECE_STEPS integrator steps a call, inside a sample if need be: a near-zone sample of the
     * default scene at 2 kS/s spans 25 000 steps (~0.9 ms), which would otherwise be the smallest piece */
    return vafm_sim_advance_steps(r->cmd.sim, max, S_PIECE_STEPS, s_sink, r);
}

/* ---- The log block pool ----------------------------------------------------------------------------
 * The simulation thread calls no malloc/free per block (glibc's allocator may take a lock another thread
 * holds): a logged run's block is copied, at its release, into a log block taken from a pool, and the
 * writer thread gives each block back through the free ring (SPSC, writer → simulation thread) once it
 * has copied it into its curve. An empty pool is handled exactly like a full log ring: the block is
 * dropped, an overflow counted and the curve marked broken (not written); the other curves are intact.
 *
 * When: the pool is allocated at the start of a logged run, not when logging is switched on, because
 * the block size (sample_rate_Hz · block_s) is known only then and may change between runs while
 * logging stays on; run start already allocates (the compute-ahead FIFO, run.start), so nothing moves
 * into the paced block loop. The pool is kept from run to run while the block size stays (a campaign, a
 * series of curves), replaced when it changes, and released at the first run start after logging was
 * switched off (or at exit).
 * Size: the log ring's capacity + 1 blocks (what the ring and the writer's hand can hold, so that the
 * pool runs empty only when the ring is full anyway), at most VAFMD_LOG_POOL_MAX_BYTES of samples (with
 * large blocks the pool, not the ring, bounds the blocks in flight), at least 1; $VAFMD_TEST_LOG_POOL
 * (tests only) makes it smaller. The lookahead FIFO stages its blocks' own copies (time and segment
 * next to the channels), so the pool does not grow with the lookahead.
 * Lifetime: a replaced pool with blocks still at the writer is retired; its blocks come home through
 * the free ring (each block knows its pool) and it is freed at a run start once all are home. The free
 * ring has room for 2 · (ring capacity + 1) blocks: when a pool is replaced at most a ring's worth + 1
 * of blocks are out (this thread holds none between runs), plus the new pool's, so the writer's push
 * never fails. At exit this thread frees the pools that are home and leaves the others to the writer
 * thread (vafmd_log.orphans), which exits after it and frees them with the free ring's slots. */

static size_t s_pool_stride(size_t cap) /* bytes of one block's samples, 64-byte aligned */
{
    return ((5 * sizeof(double) + 1) * cap + 63) & ~(size_t)63;
}

static size_t s_pool_head(size_t n) /* the pool header, block headers and free stack, 64-byte aligned */
{
    return (sizeof(vafmd_log_pool) + n * (sizeof(vafmd_log_block) + sizeof(vafmd_log_block *)) + 63) & ~(size_t)63;
}

/* Blocks of a pool for blocks of block_n samples (see above). */
static size_t s_pool_size(const s_ctx *x, size_t block_n)
{
    size_t n = x->d->log.ring.cap + 1, most = VAFMD_LOG_POOL_MAX_BYTES / s_pool_stride(block_n);
    if (n > most)
        n = most;
    if (x->pool_test_n && n > x->pool_test_n)
        n = x->pool_test_n;
    return n ? n : 1;
}

/* One allocation (free(p) releases it whole); the sample memory is not touched here (only the blocks
 * in use get their pages). Block 0 is on top of the free stack, and the stack is LIFO, so a writer that
 * keeps up makes the same few blocks go round. */
static vafmd_log_pool *s_pool_new(size_t n, size_t cap)
{
    size_t head = s_pool_head(n), stride = s_pool_stride(cap);
    if (stride && n > (SIZE_MAX - head) / stride)
        return NULL;
    unsigned char *m = malloc(head + n * stride);
    if (!m)
        return NULL;
    vafmd_log_pool *p = (vafmd_log_pool *)m;
    p->next = NULL;
    p->n_blocks = n;
    p->block_cap = cap;
    p->blocks = (vafmd_log_block *)(m + sizeof *p);
    p->free = (vafmd_log_block **)(p->blocks + n);
    for (size_t k = 0; k < n; k++) {
        vafmd_log_block *b = &p->blocks[k];
        double *d = (double *)(m + head + k * stride);
        b->n = 0;
        b->time_s = d;
        b->height_m = d + cap;
        b->force_N = d + 2 * cap;
        b->tip_m = d + 3 * cap;
        b->height_measured_m = d + 4 * cap;
        b->segment = (uint8_t *)(d + 5 * cap);
        b->pool = p;
        p->free[n - 1 - k] = b;
    }
    p->n_free = n;
    return p;
}

static void s_pool_put(vafmd_log_block *b)
{
    b->pool->free[b->pool->n_free++] = b;
}

/* Every block the writer gave back onto its pool's free stack: lock-free, bounded by the blocks of the
 * live pools. */
static void s_pool_reclaim(vafmd_log *L)
{
    vafmd_log_block *b;
    while (L->free_store && vafmd_ring_pop(&L->free_ring, &b))
        s_pool_put(b);
}

/* A free block of the current pool, or NULL (empty: the caller counts an overflow). No waiting. */
static vafmd_log_block *s_pool_get(s_ctx *x)
{
    vafmd_log_pool *p = x->pool;
    if (!p)
        return NULL;
    if (!p->n_free)
        s_pool_reclaim(&x->d->log);
    return p->n_free ? p->free[--p->n_free] : NULL;
}

static void s_pool_retire(s_ctx *x)
{
    if (x->pool) {
        x->pool->next = x->retired;
        x->retired = x->pool;
        x->pool = NULL;
    }
}

/* At run start (off the block loop): the pool this run needs; retired pools whose blocks are all home
 * are freed. A pool that cannot be allocated costs the run's log (every block overflows), not the run. */
static void s_pool_prepare(s_ctx *x, int logged, size_t block_n)
{
    vafmd_log *L = &x->d->log;
    s_pool_reclaim(L);
    if (logged) {
        size_t n = s_pool_size(x, block_n);
        if (x->pool && (x->pool->block_cap != block_n || x->pool->n_blocks != n))
            s_pool_retire(x);
        if (!x->pool && L->free_store)
            x->pool = s_pool_new(n, block_n);
    } else if (atomic_load_explicit(&L->state, memory_order_acquire) == VAFMD_LOG_OFF)
        s_pool_retire(x);
    for (vafmd_log_pool **pp = &x->retired; *pp;) {
        vafmd_log_pool *p = *pp;
        if (p->n_free == p->n_blocks) {
            *pp = p->next;
            free(p);
        } else
            pp = &p->next;
    }
}

/* Hand one item to the writer thread without waiting: a full ring loses it (counted) and the curve. A
 * lost block goes back to its pool, a lost begin/end item is freed (they are allocated once per run, at
 * its start and end, not per block). @return 1 if the writer has it. */
static int s_log_push(s_run *r, int type, void *ptr)
{
    vafmd_log_item it = { type, r->cmd.run_id, ptr };
    if (!ptr || !vafmd_ring_push(&r->log->ring, &it)) {
        if (type == VAFMD_LOG_BLOCK && ptr)
            s_pool_put(ptr);
        else
            free(ptr);
        r->log_broken = 1;
        atomic_fetch_add_explicit(&r->log->overflows, 1, memory_order_relaxed);
        return 0;
    }
    return 1;
}

/* ---- Free run: the simulation waits for the writer ---------------------------------------------------
 * A paced run never waits for the writer (a block that finds no room costs its curve, counted). A free
 * run has no deadline to keep, so it loses nothing: it releases a logged block only when the ring has
 * room for it AND for the curve's end item, and its pool a free block (so the end item always fits,
 * after a block as after the begin item); otherwise the block stays in the FIFO and the loop comes back
 * (commands, notices and heartbeats go on meanwhile). 0.6.2 dropped instead: a 16 x 16 free-run map lost
 * up to 164 of its 256 curves to a busy writer, and their end items with them (issue #29). */
static int s_log_room(s_ctx *x, size_t need)
{
    return vafmd_ring_room(&x->d->log.ring) >= need;
}

/* A logged free-run block may be released now (see above). Without a pool (it could not be allocated)
 * every block overflows anyway: nothing to wait for. */
static int s_log_ready(s_ctx *x)
{
    vafmd_log_pool *p = x->pool;
    if (!p)
        return 1;
    if (!p->n_free)
        s_pool_reclaim(&x->d->log);
    return p->n_free && s_log_room(x, 2);
}

static void s_log_notices(s_ctx *x);

/* A free run's begin item: wait until the ring has room for it and the end item (the writer frees a slot
 * within one curve append, milliseconds), publishing the writer's notices meanwhile (the writer may be
 * waiting for room for them). Given up at shutdown (then the item may be lost, counted). */
static void s_log_wait_room(s_ctx *x)
{
    while (!s_log_room(x, 2) && !atomic_load_explicit(&x->d->quitting, memory_order_acquire) && !*x->d->stop) {
        s_log_notices(x);
        s_sleep_until(s_now() + 100000);
    }
}

/* At release: the block's logged samples (the very doubles just streamed) into a pool block, to the
 * writer. An empty pool counts as a full ring. */
static void s_log_block(s_ctx *x, const s_block *b)
{
    s_run *r = &x->run;
    vafmd_log_block *lb = s_pool_get(x);
    if (lb && (lb->pool->block_cap < b->n || !b->log_t || !b->ch[VAFM_CH_HEIGHT] || !b->ch[VAFM_CH_FORCE] ||
               !b->ch[VAFM_CH_TIP])) {
        s_pool_put(lb); /* cannot happen: the pool is made for the run's blocks, curves stream 0, 2 and 4 */
        lb = NULL;
    }
    if (lb) {
        memcpy(lb->time_s, b->log_t, b->n * sizeof(double));
        memcpy(lb->height_m, b->ch[VAFM_CH_HEIGHT], b->n * sizeof(double));
        memcpy(lb->force_N, b->ch[VAFM_CH_FORCE], b->n * sizeof(double));
        memcpy(lb->tip_m, b->ch[VAFM_CH_TIP], b->n * sizeof(double));
        lb->has_measured = b->ch[VAFM_CH_HEIGHT_MEASURED] != NULL;
        if (lb->has_measured)
            memcpy(lb->height_measured_m, b->ch[VAFM_CH_HEIGHT_MEASURED], b->n * sizeof(double));
        memcpy(lb->segment, b->log_seg, b->n);
        lb->n = b->n;
    }
    s_log_push(r, VAFMD_LOG_BLOCK, lb);
}

static void s_run_free(s_run *r, vafmd_shared *sh)
{
    /* unreleased blocks were never published: dropped (they hold no log block: those are taken at release) */
    free(r->q);
    r->q = NULL;
    free(r->qstore);
    r->qstore = NULL;
    free(r->qseg);
    r->qseg = NULL;
    r->lt = NULL;
    r->lseg = NULL;
    r->qn = 0;
    atomic_store_explicit(&sh->queued, 0, memory_order_relaxed);
    if (r->cmd.camp) /* a campaign's simulation belongs to the campaign (reused for a point's curves) */
        r->cmd.sim = NULL;
    else
        vafm_sim_destroy(&r->cmd.sim);
    free(r->cmd.start_json);
    r->cmd.start_json = NULL;
    vafmd_replay_free(&r->cmd.replay);
    vafmd_feed_curve_free(&r->cmd.feed); /* between curves, as the campaign's simulations are built */
    for (int i = 0; i < VAFM_CH_COUNT; i++)
        r->ch[i] = NULL; /* pointed into qstore */
    r->active = 0;
}

static json_t *s_num_or_null(double v)
{
    return isfinite(v) ? json_real(v) : json_null();
}

static void s_camp_end(s_ctx *x, const char *status, const char *message, int mark_done);
static int s_queue_alloc(s_ctx *x, unsigned chmask, double fs);

/* Report the run as done and publish its run.end. The daemon turns idle (a new run is accepted) BEFORE
 * run.end goes out, so a client may start the next run as soon as it sees run.end. A campaign's curve
 * ends the job only if it is the campaign's last (or failed): then campaign.end follows run.end. */
static void s_run_end(s_ctx *x, const char *status, int err_code)
{
    s_run *r = &x->run;
    vafmd_shared *sh = &x->d->sh;
    int silent = r->fault_silent; /* truncate/kill: no run.end, not logged (faults.md) */
    const uint64_t run_id = r->cmd.run_id; /* for after s_run_free */
    if (r->drop_left) { /* a drop fault that outlasted the run: record the blocks it did drop */
        r->drop_rec.p0 -= (double)r->drop_left;
        r->drop_left = 0;
        if (r->drop_rec.p0 > 0)
            s_fault_record(x, &r->drop_rec);
    }
    if (r->block_index)
        x->last_run_blocks = r->block_index;
    json_t *j = json_object();
    json_object_set_new(j, "run_id", json_integer((json_int_t)r->cmd.run_id));
    json_object_set_new(j, "client_run_id", r->cmd.client_run_id[0] ? json_string(r->cmd.client_run_id) : json_null());
    json_object_set_new(j, "kind", json_string(r->cmd.kind == VAFMD_RUN_TUNE     ? "tune"
                                               : r->cmd.kind == VAFMD_RUN_REPLAY ? "replay"
                                                                                 : "curve"));
    json_object_set_new(j, "status", json_string(status));
    const char *err_msg = NULL;
    if (err_code) {
        const vafm_error *e = r->cmd.feed ? (r->cmd.feed->error.code ? &r->cmd.feed->error : NULL)
                                          : vafm_sim_error(r->cmd.sim);
        err_msg = e && e->message[0] ? e->message : vafm_strerror(err_code);
        json_object_set_new(j, "error", json_pack("{s:s,s:s}", "message", err_msg, "field", e ? e->field : ""));
    } else
        json_object_set_new(j, "error", json_null());
    json_object_set_new(j, "samples", json_integer((json_int_t)r->samples));
    json_object_set_new(j, "blocks", json_integer((json_int_t)r->block_index));
    uint64_t seq = atomic_load_explicit(&sh->seq, memory_order_relaxed);
    json_object_set_new(j, "first_seq", r->block_index ? json_integer((json_int_t)r->first_seq) : json_null());
    json_object_set_new(j, "last_seq", r->block_index ? json_integer((json_int_t)(seq - 1)) : json_null());
    json_object_set_new(j, "late_blocks", json_integer((json_int_t)r->late_blocks));
    json_object_set_new(j, "worst_late_ns", json_integer((json_int_t)r->worst_late_ns));
    json_object_set_new(j, "release_lateness_ns",
                        r->rel_n ? json_pack("{s:I,s:I,s:I,s:I}", "blocks", (json_int_t)r->rel_n, "p50",
                                             (json_int_t)s_rel_quantile(r, 0.5), "p99", (json_int_t)s_rel_quantile(r, 0.99),
                                             "max", (json_int_t)r->rel_max_ns)
                                 : json_null());
    json_object_set_new(j, "dropped", json_integer((json_int_t)(atomic_load(&sh->dropped) - r->dropped_at_start)));
    json_object_set_new(j, "wall_s", json_real((double)(s_now() - r->t_start) / 1e9));
    vafmd_campaign *cp = r->cmd.camp;
    if (cp)
        json_object_set_new(j, "campaign", json_pack("{s:I,s:I,s:I}", "campaign_id", (json_int_t)cp->campaign_id,
                                                     "curve", (json_int_t)r->cmd.index, "curves",
                                                     (json_int_t)cp->total));
    if (r->cmd.kind == VAFMD_RUN_CURVE) {
        vafm_curve_result res;
        if (s_run_result(r, &res) == 0) {
            json_t *o = json_object();
            json_object_set_new(o, "index", json_integer((json_int_t)res.index));
            json_object_set_new(o, "flags", json_integer(res.flags));
            json_object_set_new(o, "pulloff_sampled_N", s_num_or_null(res.pulloff_sampled_N));
            json_object_set_new(o, "pulloff_spring_N", s_num_or_null(res.pulloff_spring_N));
            json_object_set_new(o, "detach_force_N", s_num_or_null(res.detach_force_N));
            json_object_set_new(o, "detach_height_m", s_num_or_null(res.detach_height_m));
            json_object_set_new(o, "detach_eq_force_N", s_num_or_null(res.detach_eq_force_N));
            json_object_set_new(o, "detach_time_s", s_num_or_null(res.detach_time_s));
            json_object_set_new(o, "touch_time_s", s_num_or_null(res.touch_time_s));
            json_object_set_new(o, "touch_height_m", s_num_or_null(res.touch_height_m));
            json_object_set_new(o, "retract_start_s", s_num_or_null(res.retract_start_s));
            json_object_set_new(o, "duration_s", s_num_or_null(res.duration_s));
            json_object_set_new(o, "samples", json_integer((json_int_t)res.samples));
            json_object_set_new(o, "steps", json_integer((json_int_t)res.steps));
            json_object_set_new(o, "steps_contact", json_integer((json_int_t)res.steps_contact));
            json_object_set_new(o, "steps_free", json_integer((json_int_t)res.steps_free));
            json_object_set_new(o, "surface_height_m", s_num_or_null(res.surface_height_m));
            json_object_set_new(j, "result", o);
            if (!silent && !strcmp(status, "ok") && !(res.flags & VAFM_CURVE_NO_CONTACT) && isfinite(res.detach_time_s))
                /* time_s from the run's start, as every other stream time; retract_time_s from the retract's
                 * start (the result's detach_time_s) */
                s_send_json(x, "event", json_pack("{s:I,s:s,s:o,s:o,s:o,s:o}", "run_id", (json_int_t)r->cmd.run_id,
                                                   "kind", "detach", "time_s",
                                                   s_num_or_null(res.retract_start_s + res.detach_time_s),
                                                   "retract_time_s", s_num_or_null(res.detach_time_s), "height_m",
                                                   s_num_or_null(res.detach_height_m), "force_N",
                                                   s_num_or_null(res.detach_force_N)));
        }
    }
    int log_pending = 0, log_lost = 0;
    if (r->log) {
        vafm_curve_result lres;
        log_pending = !strcmp(status, "ok") && !err_code && !silent && s_run_result(r, &lres) == 0;
        vafmd_log_end *le = calloc(1, sizeof *le);
        if (le) {
            le->ok = log_pending;
            le->broken = r->log_broken;
            le->force_altered = r->force_altered;
            if (log_pending)
                le->result = lres;
        }
        /* an end item the writer does not get (a full ring: paced runs only, or no memory): this thread
         * counts the curve and, if pending, says log_failed itself after run.end; the writer, which then
         * finds the curve's begin still open at the next begin or at the stop, counts nothing */
        if (!s_log_push(r, VAFMD_LOG_END, le)) {
            log_lost = log_pending;
            atomic_fetch_add_explicit(log_pending ? &r->log->curves_dropped : &r->log->curves_skipped, 1,
                                      memory_order_relaxed);
        }
    }
    /* "pending": the writer thread will append it; the event "logged" (or "log_failed") says when it is
     * durable in the file, exactly one of them for each pending run. null: this run is not logged. */
    json_object_set_new(j, "log", log_pending ? json_string("pending") : json_null());
    int ok = !strcmp(status, "ok") && !err_code;
    if (cp && ok && !silent)
        atomic_store_explicit(&sh->camp_done, ++cp->done, memory_order_relaxed);
    int job_over = !cp || !ok || cp->next >= cp->total;
    /* a failed curve ends its campaign: campaign.end says which curve and why (wire.md §3.6) */
    int failed = !ok && strcmp(status, "aborted");
    char msg[sizeof ((vafm_error *)0)->message + 96];
    if (cp && failed)
        snprintf(msg, sizeof msg, "curve %" PRIu64 " (run %" PRIu64 ") failed: %s", r->cmd.index, r->cmd.run_id,
                 err_msg ? err_msg : status);
    char *text = json_dumps(j, JSON_COMPACT);
    json_decref(j);
    s_run_free(r, sh);
    atomic_fetch_add_explicit(&sh->runs_done, 1, memory_order_relaxed);
    if (job_over) { /* the log items above were pushed before this release (log stop relies on it) */
        atomic_store_explicit(&sh->state, VAFMD_IDLE, memory_order_relaxed);
        atomic_fetch_add_explicit(&sh->jobs_done, 1, memory_order_release);
    }
    if (text) {
        if (!silent)
            s_send_text(x, "run.end", text);
        free(text);
    }
    if (log_lost)
        s_send_json(x, "event", json_pack("{s:I,s:s}", "run_id", (json_int_t)run_id, "kind", "log_failed"));
    if (cp && job_over)
        s_camp_end(x, ok ? "ok" : failed ? "error" : "aborted", failed ? msg : NULL, 0);
}

/* The writer thread's durability notices, published as events (the simulation thread owns the socket). */
static void s_log_notices(s_ctx *x)
{
    vafmd_log_notice n;
    while (vafmd_ring_pop(&x->d->log.notice_ring, &n)) {
        if (n.ok)
            s_send_json(x, "event", json_pack("{s:I,s:s,s:I}", "run_id", (json_int_t)n.run_id, "kind", "logged",
                                              "group", (json_int_t)n.group));
        else
            s_send_json(x, "event", json_pack("{s:I,s:s}", "run_id", (json_int_t)n.run_id, "kind", "log_failed"));
    }
}

/* Publish campaign.end and free the campaign. mark_done: the job is not yet reported done (no curve
 * of it was running). */
static void s_camp_end(s_ctx *x, const char *status, const char *message, int mark_done)
{
    vafmd_campaign *cp = x->camp;
    vafmd_shared *sh = &x->d->sh;
    if (!cp)
        return;
    x->camp = NULL;
    if (mark_done) {
        atomic_store_explicit(&sh->state, VAFMD_IDLE, memory_order_relaxed);
        atomic_fetch_add_explicit(&sh->jobs_done, 1, memory_order_release);
    }
    json_t *j = json_object();
    json_object_set_new(j, "campaign_id", json_integer((json_int_t)cp->campaign_id));
    json_object_set_new(j, "client_run_id", cp->client_run_id[0] ? json_string(cp->client_run_id) : json_null());
    json_object_set_new(j, "status", json_string(status));
    json_object_set_new(j, "error", message ? json_pack("{s:s}", "message", message) : json_null());
    json_object_set_new(j, "curves_done", json_integer((json_int_t)cp->done));
    json_object_set_new(j, "curves", json_integer((json_int_t)cp->total));
    json_object_set_new(j, "first_index", json_integer((json_int_t)cp->spec.first_curve));
    s_send_json(x, "campaign.end", j);
    vafmd_feed_release(&cp->feed);
    vafm_sim_destroy(&cp->sim);
    free(cp->lists);
    free(cp);
}

static void s_run_start(s_ctx *x, const vafmd_sim_cmd *c)
{
    s_run *r = &x->run;
    vafmd_shared *sh = &x->d->sh;
    memset(r, 0, sizeof *r);
    r->cmd = *c;
    r->prev_seg = -1;
    if (__builtin_expect(x->fp != NULL, 0))
        s_fault_run_begin(x);
    r->t_start = s_now();
    const vafm_params *p = c->replay ? NULL : vafm_sim_params(c->sim); /* a replay has no scene */
    r->block_n = vafmd_block_samples(p ? p->sample_rate_Hz : vafmd_replay_rate_Hz(c->replay), c->set.block_s);
    r->sens = p ? p->sensitivity_m_per_V : NAN; /* a replay sets its file's */
    r->first_seq = atomic_load_explicit(&sh->seq, memory_order_relaxed);
    r->dropped_at_start = atomic_load(&sh->dropped);
    r->active = 1;
    s_pool_prepare(x, c->log && c->kind == VAFMD_RUN_CURVE, r->block_n);
    if (p) /* replays stream the recorded signals: no detector */
        vafm_detector_begin(&r->det, p, c->index);
    else
        memset(&r->det, 0, sizeof r->det);
    if (c->log && c->kind == VAFMD_RUN_CURVE) {
        r->log = &x->d->log;
        vafmd_log_begin *lb = calloc(1, sizeof *lb);
        if (lb) {
            lb->p = *p;
            lb->run_id = c->run_id;
            lb->index = c->index;
            lb->point = c->camp ? c->camp->sim_point : 0;
            lb->detector = r->det.on;
            memcpy(lb->client_run_id, c->client_run_id, sizeof lb->client_run_id);
            if (c->camp && c->camp->is_map) { /* the file gets the pixel's map attributes */
                lb->is_map = 1;
                lb->map = c->camp->map;
                vafm_map_pixel(&c->camp->map, &c->camp->base, (int)(c->index % (uint64_t)c->camp->map.nx),
                               (int)(c->index / (uint64_t)c->camp->map.nx), NULL, &lb->pixel, NULL);
            }
        }
        if (c->set.free_run) /* loses nothing: waits for room (a campaign's curve has it already) */
            s_log_wait_room(x);
        s_log_push(r, VAFMD_LOG_BEGIN, lb);
    }
    atomic_store_explicit(&sh->run_id, c->run_id, memory_order_relaxed);
    atomic_store_explicit(&sh->run_samples, 0, memory_order_relaxed);
    atomic_store_explicit(&sh->state, VAFMD_RUNNING, memory_order_relaxed);
    vafmd_live_run_start(x->d, &r->cmd.start_json); /* + "ctrl": the controller's state, held during the run */
    s_send_text(x, "run.start", r->cmd.start_json);
    unsigned chmask = c->replay ? vafmd_replay_channels(c->replay) : vafmd_live_channels(p);
    r->src_rc = 1;
    s_stream_bound(x, chmask, r->block_n, c->set.hwm);
    int rc = s_queue_alloc(x, chmask, p ? p->sample_rate_Hz : vafmd_replay_rate_Hz(c->replay));
    if (!rc && !c->replay)
    {
        if (!rc && !c->replay && c->kind == VAFMD_RUN_CURVE) /* a trigger that never fires: decided per curve */
            vafm_sim_set_trigger(c->sim, !s_no_trigger_due(x));
        rc = c->kind == VAFMD_RUN_TUNE ? vafm_sim_tune_begin(c->sim, c->index) : vafm_sim_curve_begin(c->sim, c->index);
    }
    /* the clock of the run starts when its first sample can be computed: setting up the scene (tables,
     * first contact solve) is not acquisition time */
    r->t_start = s_now();
    if (rc)
        s_run_end(x, "error", rc);
}

/* The compute-ahead FIFO of a run: 1 + ceil(lookahead_s · fs / block_n) slots (1, i.e. no lookahead:
 * compute a block, wait for its deadline, release it), fewer if the slots, their channel arrays and (a
 * logged run) their staged log times and segments would pass VAFMD_LOOKAHEAD_MAX_BYTES; at least 1. Free
 * run: 1 (blocks go out as soon as they are computed). */
static int s_queue_alloc(s_ctx *x, unsigned chmask, double fs)
{
    s_run *r = &x->run;
    const size_t nch = s_channels(chmask);
    size_t nlog = r->log ? 1 : 0; /* a logged run stages its samples' times (a double) and segments (a byte) */
    double per = (double)sizeof(s_block) + (double)(nch * r->block_n * sizeof(double)) +
                 (double)(nlog * r->block_n * (sizeof(double) + 1));
    double want = r->cmd.set.free_run ? 1 : 1 + ceil(r->cmd.set.lookahead_s * fs / (double)r->block_n);
    double most = floor((double)VAFMD_LOOKAHEAD_MAX_BYTES / per);
    if (!(want <= most))
        want = most;
    if (!(want >= 1))
        want = 1;
    r->qcap = (size_t)want;
    r->q = calloc(r->qcap, sizeof *r->q);
    r->qstore = malloc(r->qcap * ((nch + nlog) ? nch + nlog : 1) * r->block_n * sizeof(double));
    r->qseg = nlog ? malloc(r->qcap * r->block_n) : NULL;
    if (!r->q || !r->qstore || (nlog && !r->qseg))
        return VAFM_ENOMEM;
    for (size_t k = 0; k < r->qcap; k++) {
        double *p = r->qstore + k * (nch + nlog) * r->block_n;
        for (int i = 0; i < VAFM_CH_COUNT; i++)
            if (chmask >> i & 1) {
                r->q[k].ch[i] = p;
                p += r->block_n;
            }
        if (nlog) {
            r->q[k].log_t = p;
            r->q[k].log_seg = r->qseg + k * r->block_n;
        }
    }
    atomic_store_explicit(&x->d->sh.lookahead_blocks, r->qcap, memory_order_relaxed);
    return 0;
}

static double s_run_fs(const s_run *r)
{
    return r->cmd.replay ? vafmd_replay_rate_Hz(r->cmd.replay) : vafm_sim_params(r->cmd.sim)->sample_rate_Hz;
}

/* The FIFO is far enough ahead that idling until the head's release costs no lateness later: at least
 * half full. (Not "its last block is due ≥ 50 ms from now": that idled up to a piece per block all
 * through the default scene's near zone, where compute is scarcest, and made 2 kS/s late: 127 late
 * blocks, worst 0.4 s.) */
static int s_fifo_ahead(const s_run *r)
{
    return 2 * r->qn >= r->qcap;
}

/* Compute into the FIFO's free slot: from its start or where the last call stopped, until the block is
 * full or the run ends, or S_PIECE_NS of work has passed, or the head block falls due (then the loop
 * releases it and comes back). A complete block is queued with its deadline. */
static void s_compute(s_ctx *x)
{
    s_run *r = &x->run;
    s_block *b = &r->q[(r->qhead + r->qn) % r->qcap];
    if (!r->filling) {
        r->filling = 1;
        r->fill = 0;
        r->seg_change = 0;
        r->n_ev = 0;
        r->det.clipped = 0;
        for (int i = 0; i < VAFM_CH_COUNT; i++)
            r->ch[i] = b->ch[i];
        r->lt = b->log_t;
        r->lseg = b->log_seg;
    }
    int64_t t0 = s_now(), t = t0, due = r->qn ? r->q[r->qhead].deadline : INT64_MAX;
    int rc = 1;
    while (r->fill < r->block_n) {
        /* a piece: about S_PIECE_TARGET_NS of work at the current cost per sample */
        double sns = r->sample_ns > 0.0 ? r->sample_ns : 1000.0;
        double want = (double)S_PIECE_TARGET_NS / sns;
        size_t piece = want < 1.0 ? 1 : want > (double)r->block_n ? r->block_n : (size_t)want;
        size_t m = r->block_n - r->fill;
        if (m > piece)
            m = piece;
        size_t fill0 = r->fill;
        rc = s_advance(r, m);
        int64_t t1 = s_now();
        /* the cost of a piece (a call: bounded by its samples and by S_PIECE_STEPS) and of a sample, fast
         * attack, slow decay */
        const double c_call = (double)(t1 - t);
        r->piece_ns = c_call > r->piece_ns ? c_call : 0.9 * r->piece_ns + 0.1 * c_call;
        if (r->fill > fill0) {
            double c = c_call / (double)(r->fill - fill0);
            r->sample_ns = c > r->sample_ns ? c : 0.9 * r->sample_ns + 0.1 * c;
        }
        t = t1;
        if (rc != 1)
            break;
        /* stop when the head is due, or before a piece that would end after its deadline if the FIFO
         * is at least half full (then waiting for the release costs no lateness; below half, every
         * moment of computation counts more than a piece of release jitter) */
        if (r->fill < r->block_n &&
            (t >= due || (s_fifo_ahead(r) && t + (int64_t)r->piece_ns >= due) || t - t0 >= S_PIECE_NS))
            return; /* go on later */
    }
    r->filling = 0;
    r->src_rc = rc;
    if (r->fill == 0)
        return;
    b->n = r->fill;
    b->flags = (rc != 1 ? VAFM_WIRE_FLAG_LAST : 0) | (r->seg_change ? VAFM_WIRE_FLAG_SEG_CHANGE : 0) |
               (r->det.clipped ? VAFM_WIRE_FLAG_CLIPPED : 0);
    b->n_frec = 0;
    if (__builtin_expect(x->fp != NULL, 0))
        s_fault_compute(x, b, r->block_index + r->qn);
    b->first_seg = r->first_seg;
    b->n_ev = r->n_ev;
    memcpy(b->ev, r->ev, (size_t)r->n_ev * sizeof *r->ev);
    /* replay: the curves of the selection that began in this block */
    b->n_rev = r->cmd.replay ? vafmd_replay_take_events(r->cmd.replay, b->rev, VAFMD_REPLAY_MAX_EVENTS) : 0;
    uint64_t end = r->computed + r->fill;
    /* a replay is paced by its recorded times (replay.c), a simulation by its sample index */
    double t_end = r->cmd.replay ? vafmd_replay_clock_s(r->cmd.replay) : (double)end / s_run_fs(r);
    b->deadline = r->t_start + (int64_t)llround(t_end / r->cmd.set.speed * 1e9);
    b->ready = s_now();
    r->computed = end;
    r->qn++;
    atomic_store_explicit(&x->d->sh.queued, r->qn, memory_order_relaxed);
}

/* Publish the FIFO's head block (its deadline has passed, or free run): header and samples, its log
 * block, its events, the counters. It is late if it was not computed by its deadline. */
static void s_release(s_ctx *x, int64_t now)
{
    s_run *r = &x->run;
    vafmd_shared *sh = &x->d->sh;
    s_block *b = &r->q[r->qhead];
    uint32_t flags = b->flags;
    double fs = s_run_fs(r);
    int drop = 0;
    if (__builtin_expect(x->fp != NULL, 0)) {
        if (r->restart_due) { /* a publisher restart: a new session, sequence numbers from 0 again */
            uint32_t old = (uint32_t)atomic_load_explicit(&sh->session, memory_order_relaxed);
            uint32_t ns = (uint32_t)(vafmd_fault_u01(x->fp->seed ^ old, VAFMD_F_RESTART, x->fault_n, r->block_index) *
                                     4294967296.0);
            atomic_store_explicit(&sh->session, ns && ns != old ? ns : old + 1, memory_order_relaxed);
            atomic_store_explicit(&sh->seq, 0, memory_order_relaxed);
        }
        drop = r->drop_left > 0;
    }
    if (r->cmd.set.free_run)
        flags |= VAFM_WIRE_FLAG_FREE_RUN;
    else if (b->ready > b->deadline) {
        uint64_t late = (uint64_t)(now - b->deadline);
        flags |= VAFM_WIRE_FLAG_LATE;
        r->late_blocks++;
        atomic_fetch_add_explicit(&sh->late_blocks, 1, memory_order_relaxed);
        if (late > r->worst_late_ns)
            r->worst_late_ns = late;
        if (late > atomic_load_explicit(&sh->worst_late_ns, memory_order_relaxed))
            atomic_store_explicit(&sh->worst_late_ns, late, memory_order_relaxed);
        if (!r->overrun_reported) {
            r->overrun_reported = 1;
            s_send_json(x, "event", json_pack("{s:I,s:s,s:I,s:I}", "run_id", (json_int_t)r->cmd.run_id,
                                              "kind", "overrun", "block", (json_int_t)r->block_index,
                                              "late_ns", (json_int_t)late));
        }
    }
    vafm_wire_header h = {
        .magic = VAFM_WIRE_MAGIC,
        .version = VAFM_WIRE_PROTOCOL_VERSION,
        .header_size = VAFM_WIRE_HEADER_SIZE,
        .seq = atomic_load_explicit(&sh->seq, memory_order_relaxed),
        .run_id = r->cmd.run_id,
        .block_index = r->block_index,
        .first_sample = r->samples,
        .n_samples = (uint32_t)b->n,
        .n_channels = 0, /* counted below */
        .segment = b->first_seg,
        .sample_rate_Hz = fs,
        .t0_ns = (int64_t)llround((double)r->samples / fs * 1e9),
        .flags = flags,
        .session = (uint32_t)atomic_load_explicit(&sh->session, memory_order_relaxed), /* the session */
    };
    unsigned char hb[VAFM_WIRE_HEADER_SIZE];
    const void *part[2 + VAFM_CH_COUNT] = { "data", hb };
    size_t len[2 + VAFM_CH_COUNT] = { 4, sizeof hb };
    for (int i = 0; i < VAFM_CH_COUNT; i++)
        if (b->ch[i]) {
            part[2 + h.n_channels] = b->ch[i];
            len[2 + h.n_channels++] = b->n * sizeof(double);
        }
    vafm_wire_header_encode(&h, hb);
    if (!r->cmd.set.free_run) /* the release lateness: the clock read just before the send */
        s_rel_add(r, s_now() - b->deadline);
    if (__builtin_expect(!drop, 1))
        s_send(x, part, len, 2 + h.n_channels);
    else if (r->drop_rec.seq < 0) /* a drop fault: this seq is not sent (subscribers see a gap) */
        r->drop_rec.seq = (int64_t)h.seq;
    /* logged at release: an unreleased (aborted) block never reaches the writer; after a lost block no
     * further block of the curve is queued (the writer drops it whole) */
    if (r->log && !r->log_broken)
        s_log_block(x, b);
    for (int i = 0; i < b->n_ev; i++)
        s_send_json(x, "event", json_pack("{s:I,s:s,s:I,s:s,s:s}", "run_id", (json_int_t)r->cmd.run_id, "kind",
                                          "segment", "sample", (json_int_t)b->ev[i].sample, "from",
                                          s_seg_name(b->ev[i].from), "to", s_seg_name(b->ev[i].to)));
    for (int i = 0; i < b->n_rev; i++)
        s_send_json(x, "event", json_pack("{s:I,s:s,s:I,s:I,s:I,s:I,s:I}", "run_id", (json_int_t)r->cmd.run_id,
                                          "kind", "curve", "sample", (json_int_t)b->rev[i].sample, "curve",
                                          (json_int_t)b->rev[i].curve, "selection_index",
                                          (json_int_t)b->rev[i].selection, "pass", (json_int_t)b->rev[i].pass,
                                          "samples", (json_int_t)b->rev[i].samples));
    atomic_store_explicit(&sh->seq, h.seq + 1, memory_order_relaxed);
    r->samples += b->n;
    r->block_index++;
    atomic_fetch_add_explicit(&sh->samples, b->n, memory_order_relaxed);
    atomic_fetch_add_explicit(&sh->blocks, 1, memory_order_relaxed);
    atomic_store_explicit(&sh->run_samples, r->samples, memory_order_relaxed);
    if (__builtin_expect(x->fp != NULL, 0)) {
        if (drop && --r->drop_left == 0)
            s_fault_record(x, &r->drop_rec);
        s_fault_released(x, b);
    }
    r->qhead = (r->qhead + 1) % r->qcap;
    r->qn--;
    atomic_store_explicit(&sh->queued, r->qn, memory_order_relaxed);
}

/* One step of a run: release the due blocks; end the run once its last block is out; else compute a
 * piece if the FIFO has room; else sleep until the head is due (at most 1 ms: the command ring, the
 * heartbeat and new subscribers are looked at between steps). */
static void s_run_step(s_ctx *x)
{
    s_run *r = &x->run;
    int64_t now = s_now();
    if (__builtin_expect(x->fp != NULL, 0) && r->hold_until) { /* late/jitter: the stream is held */
        if (now < r->hold_until) {
            s_sleep_until(r->hold_until < now + 1000000 ? r->hold_until : now + 1000000);
            return;
        }
        r->hold_until = 0;
    }
    while (r->qn > 0 && (r->cmd.set.free_run || now >= r->q[r->qhead].deadline)) {
        if (r->cmd.set.free_run && r->log && !r->log_broken && !s_log_ready(x)) {
            s_sleep_until(now + 100000); /* the writer is behind: wait for it (free run loses nothing) */
            return;
        }
        if (__builtin_expect(x->fp != NULL, 0) && s_fault_release(x, now))
            return; /* held (late, jitter, stall) or over (truncate, kill) */
        s_release(x, now);
        now = s_now();
    }
    if (r->qn == 0 && r->src_rc != 1 && !r->filling) {
        if (r->src_rc == 0)
            s_run_end(x, "ok", 0);
        else
            s_run_end(x, r->src_rc == VAFM_EABORT ? "aborted" : "error", r->src_rc);
        return;
    }
    int64_t t = r->qn ? r->q[r->qhead].deadline : INT64_MAX;
    /* room: compute, unless the FIFO holds enough and the head falls due before a piece would be done
     * (a piece would delay its release; s_compute) */
    if (r->src_rc == 1 && r->qn < r->qcap && (!s_fifo_ahead(r) || now + (int64_t)r->piece_ns < t)) {
        s_compute(x);
        return;
    }
    s_sleep_until(t < now + 1000000 ? t : now + 1000000);
}

/* Start the campaign's next curve (global index cp->next) on this thread, without the control thread.
 * Building the simulation of a new grid point happens here, between two curves (it allocates and
 * tabulates: not in the paced per-block path); the N curves of a point reuse it, each from its own
 * random stream, exactly as vafm_campaign_run does. */
static void s_camp_next(s_ctx *x)
{
    vafmd_campaign *cp = x->camp;
    vafmd_shared *sh = &x->d->sh;
    uint64_t g = cp->next, first = cp->spec.first_curve;
    size_t point = (size_t)(g / cp->spec.curves_per_point);
    if (cp->log && cp->set.free_run && !s_log_room(x, 2))
        return; /* free run: the next curve's begin waits for the writer (the loop looks again within 1 ms) */
    if (cp->is_map && g != first && !cp->set.free_run) {
        /* the lateral move from the last pixel to this one takes instrument time (paced: at the speed factor) */
        int64_t now = s_now();
        if (cp->move_until_ns == 0) {
            int nx = cp->map.nx;
            double dx = (double)((int)(g % (uint64_t)nx) - (int)((g - 1) % (uint64_t)nx)) * cp->map.size_x_m / nx;
            double dy = (double)((int)(g / (uint64_t)nx) - (int)((g - 1) / (uint64_t)nx)) * cp->map.size_y_m / cp->map.ny;
            double t = hypot(dx, dy) / cp->lateral_speed_m_per_s / cp->set.speed;
            cp->move_until_ns = now + (int64_t)(t * 1e9) + 1;
        }
        if (now < cp->move_until_ns)
            return; /* the loop looks again within a millisecond */
        cp->move_until_ns = 0;
    }
    vafmd_feed_curve *fed = NULL;
    if (cp->feed && x->fp) /* a fault plan acts on the simulation (no_trigger): the rest curve by curve here */
        vafmd_feed_release(&cp->feed);
    if (cp->feed) { /* the batch kernel's curve g, when it is ready (the loop looks again within a millisecond) */
        int ended, frc;
        fed = vafmd_feed_take(cp->feed, &ended, &frc);
        if (!fed && !ended)
            return;
        if (!fed || fed->index != g) {
            char msg[160];
            snprintf(msg, sizeof msg, "the batch kernel's feeder ended before curve %" PRIu64 ": %s", g,
                     vafm_strerror(frc ? frc : VAFM_EINVAL));
            vafmd_feed_curve_free(&fed);
            s_camp_end(x, "error", msg, 1);
            return;
        }
    }
    vafm_params pp;
    int rc = vafm_campaign_point_params(&cp->base, &cp->spec, point, &pp);
    if (!rc && point != cp->sim_point) {
        vafm_sim_destroy(&cp->sim);
        cp->sim_point = (size_t)-1;
        rc = vafm_sim_new(&cp->sim, &pp, NULL);
        if (!rc)
            cp->sim_point = point;
    }
    if (rc) {
        char msg[160];
        snprintf(msg, sizeof msg, "cannot build the simulation of grid point %zu: %s", point, vafm_strerror(rc));
        vafmd_feed_curve_free(&fed);
        s_camp_end(x, "error", msg, 1);
        return;
    }
    json_t *cj = json_object();
    json_object_set_new(cj, "campaign_id", json_integer((json_int_t)cp->campaign_id));
    json_object_set_new(cj, "curve", json_integer((json_int_t)g));
    json_object_set_new(cj, "curves", json_integer((json_int_t)cp->total));
    json_object_set_new(cj, "first_index", json_integer((json_int_t)first));
    json_object_set_new(cj, "point", json_integer((json_int_t)point));
    json_object_set_new(cj, "T_K", json_real(pp.T_K));
    json_object_set_new(cj, "v_m_per_s", json_real(pp.v_retract_m_per_s));
    json_object_set_new(cj, "k_N_per_m", json_real(pp.k_N_per_m));
    if (cp->is_map) { /* the pixel: its grid indices, position and ground truth */
        int ix = (int)(g % (uint64_t)cp->map.nx), iy = (int)(g / (uint64_t)cp->map.nx);
        vafm_map_truth t;
        memset(&t, 0, sizeof t);
        vafm_map_pixel(&cp->map, &cp->base, ix, iy, NULL, &t, NULL);
        json_object_set_new(cj, "map", json_pack("{s:i,s:i,s:i,s:i,s:f,s:f,s:i,s:f,s:f,s:f}", "ix", ix, "iy", iy,
                                                 "nx", cp->map.nx, "ny", cp->map.ny, "x_m", t.x_m, "y_m", t.y_m,
                                                 "material", t.material, "E_star_Pa", t.E_star_Pa, "gamma_J_per_m2",
                                                 t.gamma_J_per_m2, "surface_height_m", t.surface_height_m));
    }
    vafmd_sim_cmd c;
    memset(&c, 0, sizeof c);
    c.type = VAFMD_SIM_START;
    c.kind = VAFMD_RUN_CURVE;
    c.run_id = cp->first_run_id + (g - first);
    c.index = g;
    c.sim = cp->sim;
    c.feed = fed;
    c.set = cp->set;
    c.log = cp->log;
    c.camp = cp;
    memcpy(c.client_run_id, cp->client_run_id, sizeof c.client_run_id);
    c.start_json = vafmd_run_start_json(&pp, &cp->set, VAFMD_RUN_CURVE, c.run_id, g, cp->client_run_id,
                                        vafm_sim_dt(cp->sim), cj);
    if (!c.start_json) {
        vafmd_feed_curve_free(&c.feed);
        s_camp_end(x, "error", "out of memory", 1);
        return;
    }
    cp->next = g + 1;
    atomic_store_explicit(&sh->camp_next, g, memory_order_relaxed);
    if (g != first)
        atomic_fetch_add_explicit(&sh->extra_runs, 1, memory_order_relaxed);
    s_run_start(x, &c);
}

static void s_heartbeat(s_ctx *x, int64_t now)
{
    vafmd_shared *sh = &x->d->sh;
    uint64_t seq = atomic_load(&sh->seq);
    json_t *j = json_object();
    json_object_set_new(j, "state", json_string(x->run.active ? "running" : "idle"));
    json_object_set_new(j, "session", json_integer(atomic_load_explicit(&sh->session, memory_order_relaxed)));
    json_object_set_new(j, "run_id", x->run.active ? json_integer((json_int_t)x->run.cmd.run_id) : json_null());
    json_object_set_new(j, "last_seq", seq ? json_integer((json_int_t)(seq - 1)) : json_null());
    json_object_set_new(j, "samples", json_integer((json_int_t)atomic_load(&sh->samples)));
    json_object_set_new(j, "blocks", json_integer((json_int_t)atomic_load(&sh->blocks)));
    json_object_set_new(j, "late_blocks", json_integer((json_int_t)atomic_load(&sh->late_blocks)));
    json_object_set_new(j, "worst_late_ns", json_integer((json_int_t)atomic_load(&sh->worst_late_ns)));
    json_object_set_new(j, "dropped", json_integer((json_int_t)atomic_load(&sh->dropped)));
    json_object_set_new(j, "uptime_s", json_real((double)(now - x->t_boot) / 1e9));
    json_object_set_new(j, "campaign", x->camp ? json_pack("{s:I,s:I,s:I}", "campaign_id",
                                                           (json_int_t)x->camp->campaign_id, "curves_done",
                                                           (json_int_t)x->camp->done, "curves",
                                                           (json_int_t)x->camp->total)
                                               : json_null());
    s_send_json(x, "heartbeat", j);
}

/* XPUB delivers (un)subscriptions as messages: a new subscriber gets a heartbeat at once (so a client
 * knows its subscription is in place) and, mid-run, the run's start message again. */
static void s_subscriptions(s_ctx *x)
{
    char buf[256];
    int rc;
    int again = 0;
    while ((rc = zmq_recv(x->d->pub, buf, sizeof buf, ZMQ_DONTWAIT)) >= 0) {
        if (rc >= 1 && buf[0] == 1)
            again = 1;
        if (rc >= 1 && buf[0] <= 1) /* the live topic goes out only to explicit subscribers (live.c) */
            vafmd_live_subscription(x->d, buf + 1, (size_t)rc - 1 < sizeof buf - 1 ? (size_t)rc - 1 : sizeof buf - 1,
                                    buf[0]);
    }
    if (again) {
        s_heartbeat(x, s_now());
        if (x->run.active)
            s_send_text(x, "run.start", x->run.cmd.start_json);
    }
}

void *vafmd_sim_main(void *arg)
{
    s_ctx *x = calloc(1, sizeof *x);
    if (!x)
        return NULL;
    x->d = arg;
    x->nodrop = -1;
    x->t_boot = s_now();
#ifdef PR_SET_TIMERSLACK
    /* Linux lets a normal thread's timed sleeps end up to 50 µs late (timer slack, to batch wake-ups);
     * this thread's sleeps are release deadlines: 1 ns slack (measured on the project's VM, a bare
     * clock_nanosleep: p50 89 → 49 µs late; the OS wake-up itself is the rest) */
    prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
#endif
    /* the log pool's free ring (before any log item is pushed: the log ring's release/acquire publishes
     * it to the writer thread); without it no pool is made and every logged block overflows */
    vafmd_log *L = &x->d->log;
    size_t fcap = 1;
    while (fcap < 2 * (L->ring.cap + 1))
        fcap <<= 1;
    if ((L->free_store = calloc(fcap, sizeof *L->free_store)) != NULL)
        vafmd_ring_init(&L->free_ring, L->free_store, sizeof(vafmd_log_block *), fcap);
    const char *env = getenv("VAFMD_TEST_LOG_POOL"); /* test hook (tests/test_daemon.py): a small pool */
    if (env && env[0])
        x->pool_test_n = (size_t)strtoul(env, NULL, 10);
    int64_t next_hb = x->t_boot;
    for (;;) {
        vafmd_sim_cmd c;
        int quit = 0;
        if (__builtin_expect(x->stall_until != 0, 0)) { /* a stall: no message at all, heartbeats included */
            int64_t now = s_now();
            /* a shutdown (command or signal) ends the stall: shutdown flushes within its 0.5 s, a stall
             * of up to 60 s made SIGTERM wait it out (0.6.1) */
            const int quitting = atomic_load_explicit(&x->d->quitting, memory_order_acquire) || *x->d->stop;
            if (now < x->stall_until && !quitting) {
                s_sleep_until(x->stall_until < now + 1000000 ? x->stall_until : now + 1000000);
                continue;
            }
            x->stall_until = 0;
            s_fault_record(x, &x->stall_rec);
        }
        while (vafmd_ring_pop(&x->d->ring, &c)) {
            if (c.type == VAFMD_SIM_FAULTS) { /* a new plan; the old one goes back to be freed */
                if (x->fp)
                    (void)vafmd_ring_push(&x->d->retire_ring, &x->fp); /* full cannot happen (the control thread
                                                  empties it between requests); then leaked, never freed here */
                x->fp = c.plan;
                continue;
            }
            if (c.type == VAFMD_SIM_CTRL) { /* the always-on controller (live.c) */
                vafmd_live_apply(x->d, &c.live);
                continue;
            }
            if (c.type == VAFMD_SIM_FAULT_NOTE) { /* a command fault: time it from the daemon's start */
                c.fault.time_s -= (double)x->t_boot / 1e9;
                s_fault_record(x, &c.fault);
                continue;
            }
            if (x->dead && c.type == VAFMD_SIM_START) { /* killed: runs are no longer started */
                if (c.camp) {
                    vafmd_feed_release(&c.camp->feed);
                    vafm_sim_destroy(&c.camp->sim);
                    free(c.camp->lists);
                    free(c.camp);
                }
                vafm_sim_destroy(&c.sim);
                free(c.start_json);
                vafmd_replay_free(&c.replay);
                continue;
            }
            if (c.type == VAFMD_SIM_START) {
                if (x->run.active) /* the control thread prevents this; never leak the run either way */
                    s_run_end(x, "aborted", VAFM_EABORT);
                s_camp_end(x, "aborted", NULL, 0);
                if (c.camp) { /* a campaign: its first curve starts here, the others as each one ends */
                    x->camp = c.camp;
                    atomic_store_explicit(&x->d->sh.camp_id, c.camp->campaign_id, memory_order_relaxed);
                    atomic_store_explicit(&x->d->sh.camp_done, 0, memory_order_relaxed);
                    s_camp_next(x);
                } else
                    s_run_start(x, &c);
            } else if (c.type == VAFMD_SIM_ABORT || c.type == VAFMD_SIM_QUIT) {
                if (x->run.active)
                    s_run_end(x, "aborted", 0); /* ends its campaign too */
                s_camp_end(x, "aborted", NULL, 1);
                quit = c.type == VAFMD_SIM_QUIT;
            }
        }
        if (quit)
            break;
        s_log_notices(x);
        s_subscriptions(x);
        int64_t now = s_now();
        if (now >= next_hb) {
            s_heartbeat(x, now);
            next_hb += S_NS;
            if (next_hb < now) /* after a long stall: keep the 1 Hz grid, skip the missed beats */
                next_hb = now + S_NS - (now - next_hb) % S_NS;
        }
        if (!x->run.active && x->camp && !x->dead) /* a campaign goes on by itself */
            s_camp_next(x);
        if (x->run.active)
            s_run_step(x);
        else /* idle: the live controller (live.c), then look at the ring every millisecond */
            s_sleep_until(vafmd_live_idle(x->d, now, x->dead));
    }
    vafmd_live_sim_exit(x->d);
    /* the pools: free those whose blocks are all home, leave the others to the writer thread */
    s_pool_reclaim(L);
    s_pool_retire(x);
    while (x->retired) {
        vafmd_log_pool *p = x->retired;
        x->retired = p->next;
        if (p->n_free == p->n_blocks)
            free(p);
        else {
            p->next = L->orphans;
            L->orphans = p;
        }
    }
    free(x->fp); /* at exit, not on the real-time path */
    free(x);
    return NULL;
}
