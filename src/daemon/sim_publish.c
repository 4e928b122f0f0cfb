/* SPDX-License-Identifier: MIT */
/*
 * The simulation thread's side of the stream (design: sim_thread.h): sending on the XPUB socket without
 * waiting, the bound of a subscriber's queue in bytes, the release of a computed block at its deadline
 * (header, channel arrays, events, log block, counters), the release-lateness histogram of run.end,
 * heartbeats, and what a new subscriber gets.
 */
#include "daemon/sim_thread.h"

static void s_rel_add(vafmd_st_run *r, int64_t late_ns)
{
    if (late_ns < 0)
        late_ns = 0;
    const uint64_t fine = VAFMD_ST_REL_FINE * 1000u; /* ns of the 1 µs bins */
    uint64_t i = (uint64_t)late_ns < fine ? (uint64_t)late_ns / 1000u
                                          : VAFMD_ST_REL_FINE + ((uint64_t)late_ns - fine) / 100000u;
    r->rel_hist[i < VAFMD_ST_REL_BINS ? i : VAFMD_ST_REL_BINS - 1]++;
    r->rel_n++;
    if (late_ns > r->rel_max_ns)
        r->rel_max_ns = late_ns;
}

/* The q-quantile of the release lateness, ns: the upper edge of the bin holding it (≤ the maximum). */
int64_t vafmd_st_rel_quantile(const vafmd_st_run *r, double q)
{
    uint64_t want = (uint64_t)ceil(q * (double)r->rel_n), cum = 0;
    if (want < 1)
        want = 1;
    for (int i = 0; i < VAFMD_ST_REL_BINS; i++) {
        cum += r->rel_hist[i];
        if (cum >= want) {
            int64_t edge = i < VAFMD_ST_REL_FINE ? (int64_t)(i + 1) * 1000
                                                 : VAFMD_ST_REL_FINE * 1000 + (int64_t)(i - VAFMD_ST_REL_FINE + 1) * 100000;
            return edge < r->rel_max_ns ? edge : r->rel_max_ns;
        }
    }
    return r->rel_max_ns;
}


int64_t vafmd_st_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * VAFMD_ST_NS + ts.tv_nsec;
}

void vafmd_st_sleep_until(int64_t t)
{
    struct timespec ts = { (time_t)(t / VAFMD_ST_NS), (long)(t % VAFMD_ST_NS) };
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR)
        ;
}

/* The channels a run streams (bits of its channel mask). */
size_t vafmd_st_channels(unsigned chmask)
{
    return (size_t)__builtin_popcount(chmask & ((1u << VAFM_CH_COUNT) - 1u));
}

/* Bound each subscriber's queue in bytes as well as in messages: the setting hwm counts messages, and
 * a data message of a run carries up to VAFMD_MAX_BLOCK_SAMPLES samples of each channel (≈ 10 MB), so
 * a subscriber that stops reading could make the daemon queue hwm × 10 MB (GB at the default 1000).
 * Before a run, the send high-water mark becomes min(hwm, VAFMD_STREAM_MAX_BYTES / the run's largest
 * message), at least 2; libzmq applies a changed ZMQ_SNDHWM to the pipes already connected too. */
void vafmd_st_stream_bound(vafmd_st *x, unsigned chmask, size_t block_n, int hwm_set)
{
    const size_t nch = vafmd_st_channels(chmask);
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

/* ---- the daemon's PUB socket: the stream's messages and the live mode's ----------------------------- */

static void s_set_nodrop(void *pub, int *nodrop, int on)
{
    if (*nodrop != on) {
        zmq_setsockopt(pub, ZMQ_XPUB_NODROP, &on, sizeof on);
        *nodrop = on;
    }
}

static int s_send_part(void *pub, const void *data, size_t len, int flags)
{
    int rc;
    while ((rc = zmq_send(pub, data, len, flags)) < 0 && errno == EINTR)
        ;
    return rc;
}

int vafmd_pub_send(void *pub, int *nodrop, const void *const *part, const size_t *len, int n)
{
    int lossy = 0;
    if (nodrop)
        s_set_nodrop(pub, nodrop, 1);
    for (int i = 0; i < n; i++) {
        const int flags = ZMQ_DONTWAIT | (i + 1 < n ? ZMQ_SNDMORE : 0);
        int rc = s_send_part(pub, part[i], len[i], flags);
        if (rc < 0 && errno == EAGAIN && nodrop && !lossy) {
            lossy = 1;
            s_set_nodrop(pub, nodrop, 0);
            rc = s_send_part(pub, part[i], len[i], flags);
        }
        if (rc < 0)
            return VAFM_EIO;
    }
    return lossy;
}

int vafmd_pub_send_text(void *pub, int *nodrop, const char *topic, const char *text)
{
    const void *part[2] = { topic, text };
    size_t len[2] = { strlen(topic), strlen(text) };
    return vafmd_pub_send(pub, nodrop, part, len, 2);
}

int vafmd_pub_send_json(void *pub, int *nodrop, const char *topic, json_t *j)
{
    char *text = json_dumps(j, JSON_COMPACT);
    json_decref(j);
    if (!text)
        return VAFM_ENOMEM;
    int rc = vafmd_pub_send_text(pub, nodrop, topic, text);
    free(text);
    return rc;
}

/* ---- the stream's sends: lossless to every subscriber with room, else lossy and one drop counted ---- */

/* A send's outcome on the counters: a message that went out lossy (some subscriber had no room) counts one
 * drop; one that did not go out (the socket failed) counts none. */
static void s_sent(vafmd_st *x, int rc)
{
    if (rc == 1)
        atomic_fetch_add_explicit(&x->d->sh.dropped, 1, memory_order_relaxed);
}

/* A kill fault: the daemon is gone as far as the stream is concerned, nothing is sent. */
static void s_send(vafmd_st *x, const void *const *part, const size_t *len, int n)
{
    if (!x->dead)
        s_sent(x, vafmd_pub_send(x->d->pub, &x->nodrop, part, len, n));
}

void vafmd_st_send_json(vafmd_st *x, const char *topic, json_t *j)
{
    if (x->dead)
        json_decref(j);
    else
        s_sent(x, vafmd_pub_send_json(x->d->pub, &x->nodrop, topic, j));
}

void vafmd_st_send_text(vafmd_st *x, const char *topic, const char *text)
{
    if (!x->dead)
        s_sent(x, vafmd_pub_send_text(x->d->pub, &x->nodrop, topic, text));
}

static const char *s_seg_name(int s)
{
    static const char *const n[] = { "approach", "retract", "dwell", "tune" };
    return s >= 0 && s < 4 ? n[s] : "unknown";
}

/* Publish the FIFO's head block (its deadline has passed, or free run): header and samples, its log
 * block, its events, the counters. It is late if it was not computed by its deadline. */
void vafmd_st_release(vafmd_st *x, int64_t now)
{
    vafmd_st_run *r = &x->run;
    vafmd_shared *sh = &x->d->sh;
    vafmd_st_block *b = &r->q[r->qhead];
    uint32_t flags = b->flags;
    double fs = vafmd_st_run_fs(r);
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
            vafmd_st_send_json(x, "event", json_pack("{s:I,s:s,s:I,s:I}", "run_id", (json_int_t)r->cmd.run_id,
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
        s_rel_add(r, vafmd_st_now() - b->deadline);
    if (__builtin_expect(!drop, 1))
        s_send(x, part, len, 2 + h.n_channels);
    else if (r->drop_rec.seq < 0) /* a drop fault: this seq is not sent (subscribers see a gap) */
        r->drop_rec.seq = (int64_t)h.seq;
    /* logged at release: an unreleased (aborted) block never reaches the writer; after a lost block no
     * further block of the curve is queued (the writer drops it whole) */
    if (r->log && !r->log_broken)
        vafmd_st_log_block(x, b);
    for (int i = 0; i < b->n_ev; i++) {
        json_t *ev = json_pack("{s:I,s:s,s:I,s:s,s:s}", "run_id", (json_int_t)r->cmd.run_id, "kind", "segment",
                               "sample", (json_int_t)b->ev[i].sample, "from", s_seg_name(b->ev[i].from), "to",
                               s_seg_name(b->ev[i].to));
        if (r->cmd.segs && ev) { /* a list's segments are its labels (positions), not the curve's phases */
            json_object_set_new(ev, "from_segment", json_integer(b->ev[i].from));
            json_object_set_new(ev, "to_segment", json_integer(b->ev[i].to));
        }
        vafmd_st_send_json(x, "event", ev);
    }
    for (int i = 0; i < b->n_rev; i++)
        vafmd_st_send_json(x, "event", json_pack("{s:I,s:s,s:I,s:I,s:I,s:I,s:I}", "run_id", (json_int_t)r->cmd.run_id,
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
            vafmd_st_fault_record(x, &r->drop_rec);
        vafmd_st_fault_released(x, b);
    }
    r->qhead = (r->qhead + 1) % r->qcap;
    r->qn--;
    atomic_store_explicit(&sh->queued, r->qn, memory_order_relaxed);
}

void vafmd_st_heartbeat(vafmd_st *x, int64_t now)
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
    vafmd_st_send_json(x, "heartbeat", j);
}

/* XPUB delivers (un)subscriptions as messages: a new subscriber gets a heartbeat at once (so a client
 * knows its subscription is in place) and, mid-run, the run's start message again. */
void vafmd_st_subscriptions(vafmd_st *x)
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
        vafmd_st_heartbeat(x, vafmd_st_now());
        if (x->run.active)
            vafmd_st_send_text(x, "run.start", x->run.cmd.start_json);
    }
}
