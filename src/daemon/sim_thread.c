/* SPDX-License-Identifier: MIT */
/*
 * The simulation thread: advances the running scene block by block, releases each block at an absolute
 * CLOCK_MONOTONIC deadline (t_start + (end sample of the block)/fs/speed: no drift, whatever the
 * computation time), and publishes it on the XPUB socket it owns.
 *
 * It never waits on anyone: commands arrive through the SPSC ring (polled between blocks), reports go
 * out through atomics, and the socket is used with ZMQ_DONTWAIT. A subscriber at its high-water mark
 * loses the message (counted), the others still get it.
 */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <jansson.h>
#include <zmq.h>
#include "daemon/daemon.h"
#include "vafm/wire.h"

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "vafmd sends channel arrays in host order: big-endian hosts need a byte swap (not yet implemented)"
#endif

#define S_NS 1000000000LL
#define S_MAX_EVENTS 16

typedef struct s_event {
    uint64_t sample;
    int from, to;
} s_event;

typedef struct s_run {
    int active;
    vafmd_sim_cmd cmd;     /* START command: sim, start_json, settings */
    size_t block_n;
    double *ch[VAFMD_N_CHANNELS];
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
    vafmd_log_block *lb;   /* the block being filled for the writer thread, or NULL */
    int log_broken;        /* a log item was lost to a full ring: the writer drops the curve */
} s_run;

typedef struct s_ctx {
    vafmd *d;
    s_run run;
    int nodrop;            /* current ZMQ_XPUB_NODROP setting */
    int64_t t_boot;        /* CLOCK_MONOTONIC ns at thread start */
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

/* Send one multipart message without blocking. With XPUB_NODROP on, a frame that some matching
 * subscriber has no room for fails with EAGAIN: that counts one drop, and the message then goes out
 * lossy (to everyone with room). @return 0, or -1 if the socket failed otherwise. */
static int s_send(s_ctx *x, const void *const *part, const size_t *len, int n)
{
    int dropped = 0;
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

static const char *s_seg_name(int s)
{
    static const char *const n[] = { "approach", "retract", "dwell", "tune" };
    return s >= 0 && s < 4 ? n[s] : "unknown";
}

static int s_sink(void *user, const vafm_samples *b)
{
    s_run *r = user;
    for (size_t i = 0; i < b->n; i++) {
        size_t k = r->fill + i;
        if (k >= r->block_n)
            return 1; /* cannot happen: advance is asked for at most the room left */
        r->ch[0][k] = b->height_m[i];
        r->ch[1][k] = b->deflection_m[i];
        r->ch[2][k] = b->force_N[i];
        /* a division, not a multiplication by the inverse: bit-exact with deflection / sensitivity */
        r->ch[3][k] = b->deflection_m[i] / r->cmd.set.sensitivity_m_per_V;
        r->ch[4][k] = b->tip_m[i];
        if (r->lb) { /* the same doubles as the stream's: the file equals the stream bit for bit */
            r->lb->time_s[k] = b->time_s[i];
            r->lb->height_m[k] = b->height_m[i];
            r->lb->force_N[k] = b->force_N[i];
            r->lb->tip_m[k] = b->tip_m[i];
            r->lb->segment[k] = b->segment[i];
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

/* Hand one item to the writer thread without waiting: a full ring loses it (counted) and the curve. */
static void s_log_push(s_run *r, int type, void *ptr)
{
    vafmd_log_item it = { type, r->cmd.run_id, ptr };
    if (!ptr || !vafmd_ring_push(&r->log->ring, &it)) {
        free(ptr);
        r->log_broken = 1;
        atomic_fetch_add_explicit(&r->log->overflows, 1, memory_order_relaxed);
    }
}

static vafmd_log_block *s_log_block_new(size_t n)
{
    vafmd_log_block *b = malloc(sizeof *b + 4 * n * sizeof(double) + n);
    if (!b)
        return NULL;
    b->n = 0;
    b->time_s = b->data;
    b->height_m = b->data + n;
    b->force_N = b->data + 2 * n;
    b->tip_m = b->data + 3 * n;
    b->segment = (uint8_t *)(b->data + 4 * n);
    return b;
}

static void s_run_free(s_run *r)
{
    free(r->lb);
    r->lb = NULL;
    vafm_sim_destroy(&r->cmd.sim);
    free(r->cmd.start_json);
    r->cmd.start_json = NULL;
    for (int i = 0; i < VAFMD_N_CHANNELS; i++) {
        free(r->ch[i]);
        r->ch[i] = NULL;
    }
    r->active = 0;
}

static json_t *s_num_or_null(double v)
{
    return isfinite(v) ? json_real(v) : json_null();
}

/* Publish run.end and report the run as done (the control thread may start the next one). */
static void s_run_end(s_ctx *x, const char *status, int err_code)
{
    s_run *r = &x->run;
    vafmd_shared *sh = &x->d->sh;
    json_t *j = json_object();
    json_object_set_new(j, "run_id", json_integer((json_int_t)r->cmd.run_id));
    json_object_set_new(j, "client_run_id", r->cmd.client_run_id[0] ? json_string(r->cmd.client_run_id) : json_null());
    json_object_set_new(j, "kind", json_string(r->cmd.kind == VAFMD_RUN_TUNE ? "tune" : "curve"));
    json_object_set_new(j, "status", json_string(status));
    if (err_code) {
        const vafm_error *e = vafm_sim_error(r->cmd.sim);
        json_object_set_new(j, "error", json_pack("{s:s,s:s}", "message", e && e->message[0] ? e->message
                                                  : vafm_strerror(err_code), "field", e ? e->field : ""));
    } else
        json_object_set_new(j, "error", json_null());
    json_object_set_new(j, "samples", json_integer((json_int_t)r->samples));
    json_object_set_new(j, "blocks", json_integer((json_int_t)r->block_index));
    uint64_t seq = atomic_load_explicit(&sh->seq, memory_order_relaxed);
    json_object_set_new(j, "first_seq", r->block_index ? json_integer((json_int_t)r->first_seq) : json_null());
    json_object_set_new(j, "last_seq", r->block_index ? json_integer((json_int_t)(seq - 1)) : json_null());
    json_object_set_new(j, "late_blocks", json_integer((json_int_t)r->late_blocks));
    json_object_set_new(j, "worst_late_ns", json_integer((json_int_t)r->worst_late_ns));
    json_object_set_new(j, "dropped", json_integer((json_int_t)(atomic_load(&sh->dropped) - r->dropped_at_start)));
    json_object_set_new(j, "wall_s", json_real((double)(s_now() - r->t_start) / 1e9));
    if (r->cmd.kind == VAFMD_RUN_CURVE) {
        vafm_curve_result res;
        if (vafm_sim_result(r->cmd.sim, &res) == 0) {
            json_t *o = json_object();
            json_object_set_new(o, "index", json_integer((json_int_t)res.index));
            json_object_set_new(o, "flags", json_integer(res.flags));
            json_object_set_new(o, "pulloff_sampled_N", s_num_or_null(res.pulloff_sampled_N));
            json_object_set_new(o, "pulloff_spring_N", s_num_or_null(res.pulloff_spring_N));
            json_object_set_new(o, "detach_force_N", s_num_or_null(res.detach_force_N));
            json_object_set_new(o, "detach_height_m", s_num_or_null(res.detach_height_m));
            json_object_set_new(o, "detach_time_s", s_num_or_null(res.detach_time_s));
            json_object_set_new(o, "touch_time_s", s_num_or_null(res.touch_time_s));
            json_object_set_new(o, "retract_start_s", s_num_or_null(res.retract_start_s));
            json_object_set_new(o, "duration_s", s_num_or_null(res.duration_s));
            json_object_set_new(o, "samples", json_integer((json_int_t)res.samples));
            json_object_set_new(j, "result", o);
            if (!strcmp(status, "ok") && !(res.flags & VAFM_CURVE_NO_CONTACT) && isfinite(res.detach_time_s))
                s_send_json(x, "event", json_pack("{s:I,s:s,s:o,s:o,s:o}", "run_id", (json_int_t)r->cmd.run_id,
                                                   "kind", "detach", "time_s", s_num_or_null(res.detach_time_s),
                                                   "height_m", s_num_or_null(res.detach_height_m), "force_N",
                                                   s_num_or_null(res.detach_force_N)));
        }
    }
    if (r->log) {
        vafmd_log_end *le = calloc(1, sizeof *le);
        if (le) {
            le->ok = !strcmp(status, "ok") && !err_code;
            le->broken = r->log_broken;
            if (vafm_sim_result(r->cmd.sim, &le->result))
                le->ok = 0;
        }
        s_log_push(r, VAFMD_LOG_END, le);
    }
    s_send_json(x, "run.end", j);
    s_run_free(r);
    atomic_store_explicit(&sh->state, VAFMD_IDLE, memory_order_relaxed);
    atomic_fetch_add_explicit(&sh->runs_done, 1, memory_order_release);
}

static void s_run_start(s_ctx *x, const vafmd_sim_cmd *c)
{
    s_run *r = &x->run;
    vafmd_shared *sh = &x->d->sh;
    memset(r, 0, sizeof *r);
    r->cmd = *c;
    r->prev_seg = -1;
    r->t_start = s_now();
    const vafm_params *p = vafm_sim_params(c->sim);
    r->block_n = vafmd_block_samples(p->sample_rate_Hz, c->set.block_s);
    r->first_seq = atomic_load_explicit(&sh->seq, memory_order_relaxed);
    r->dropped_at_start = atomic_load(&sh->dropped);
    r->active = 1;
    if (c->log && c->kind == VAFMD_RUN_CURVE) {
        r->log = &x->d->log;
        vafmd_log_begin *lb = calloc(1, sizeof *lb);
        if (lb) {
            lb->p = *p;
            lb->run_id = c->run_id;
            lb->index = c->index;
            memcpy(lb->client_run_id, c->client_run_id, sizeof lb->client_run_id);
        }
        s_log_push(r, VAFMD_LOG_BEGIN, lb);
    }
    atomic_store_explicit(&sh->run_id, c->run_id, memory_order_relaxed);
    atomic_store_explicit(&sh->run_samples, 0, memory_order_relaxed);
    atomic_store_explicit(&sh->state, VAFMD_RUNNING, memory_order_relaxed);
    s_send_text(x, "run.start", c->start_json);
    int rc = 0;
    for (int i = 0; i < VAFMD_N_CHANNELS; i++)
        if (!(r->ch[i] = malloc(r->block_n * sizeof(double))))
            rc = VAFM_ENOMEM;
    if (!rc)
        rc = c->kind == VAFMD_RUN_TUNE ? vafm_sim_tune_begin(c->sim, c->index) : vafm_sim_curve_begin(c->sim, c->index);
    /* the clock of the run starts when its first sample can be computed: setting up the scene (tables,
     * first contact solve) is not acquisition time */
    r->t_start = s_now();
    if (rc)
        s_run_end(x, "error", rc);
}

/* Compute, pace and publish one block. */
static void s_run_block(s_ctx *x)
{
    s_run *r = &x->run;
    vafmd_shared *sh = &x->d->sh;
    r->fill = 0;
    r->seg_change = 0;
    r->n_ev = 0;
    if (r->log && !r->log_broken && !r->lb && !(r->lb = s_log_block_new(r->block_n))) {
        r->log_broken = 1;
        atomic_fetch_add_explicit(&r->log->overflows, 1, memory_order_relaxed);
    }
    int rc = 1;
    while (r->fill < r->block_n && rc == 1)
        rc = vafm_sim_advance(r->cmd.sim, r->block_n - r->fill, s_sink, r);
    if (r->fill > 0) {
        uint32_t flags = 0;
        if (rc != 1)
            flags |= VAFM_WIRE_FLAG_LAST;
        if (r->seg_change)
            flags |= VAFM_WIRE_FLAG_SEG_CHANGE;
        const vafm_params *p = vafm_sim_params(r->cmd.sim);
        double fs = p->sample_rate_Hz;
        uint64_t end = r->samples + r->fill;
        if (r->cmd.set.free_run)
            flags |= VAFM_WIRE_FLAG_FREE_RUN;
        else {
            int64_t deadline = r->t_start + (int64_t)llround((double)end / fs / r->cmd.set.speed * 1e9);
            int64_t now = s_now();
            if (now > deadline) {
                uint64_t late = (uint64_t)(now - deadline);
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
            } else
                s_sleep_until(deadline);
        }
        vafm_wire_header h = {
            .magic = VAFM_WIRE_MAGIC,
            .version = VAFM_WIRE_PROTOCOL_VERSION,
            .header_size = VAFM_WIRE_HEADER_SIZE,
            .seq = atomic_load_explicit(&sh->seq, memory_order_relaxed),
            .run_id = r->cmd.run_id,
            .block_index = r->block_index,
            .first_sample = r->samples,
            .n_samples = (uint32_t)r->fill,
            .n_channels = VAFMD_N_CHANNELS,
            .segment = r->first_seg,
            .sample_rate_Hz = fs,
            .t0_ns = (int64_t)llround((double)r->samples / fs * 1e9),
            .flags = flags,
        };
        unsigned char hb[VAFM_WIRE_HEADER_SIZE];
        vafm_wire_header_encode(&h, hb);
        const void *part[2 + VAFMD_N_CHANNELS] = { "data", hb };
        size_t len[2 + VAFMD_N_CHANNELS] = { 4, sizeof hb };
        for (int i = 0; i < VAFMD_N_CHANNELS; i++) {
            part[2 + i] = r->ch[i];
            len[2 + i] = r->fill * sizeof(double);
        }
        s_send(x, part, len, 2 + VAFMD_N_CHANNELS);
        if (r->lb) {
            r->lb->n = r->fill;
            vafmd_log_block *lb = r->lb;
            r->lb = NULL;
            s_log_push(r, VAFMD_LOG_BLOCK, lb);
        }
        for (int i = 0; i < r->n_ev; i++)
            s_send_json(x, "event", json_pack("{s:I,s:s,s:I,s:s,s:s}", "run_id", (json_int_t)r->cmd.run_id, "kind",
                                              "segment", "sample", (json_int_t)r->ev[i].sample, "from",
                                              s_seg_name(r->ev[i].from), "to", s_seg_name(r->ev[i].to)));
        atomic_store_explicit(&sh->seq, h.seq + 1, memory_order_relaxed);
        r->samples = end;
        r->block_index++;
        atomic_fetch_add_explicit(&sh->samples, r->fill, memory_order_relaxed);
        atomic_fetch_add_explicit(&sh->blocks, 1, memory_order_relaxed);
        atomic_store_explicit(&sh->run_samples, r->samples, memory_order_relaxed);
    }
    if (rc == 0)
        s_run_end(x, "ok", 0);
    else if (rc < 0)
        s_run_end(x, rc == VAFM_EABORT ? "aborted" : "error", rc);
}

static void s_heartbeat(s_ctx *x, int64_t now)
{
    vafmd_shared *sh = &x->d->sh;
    uint64_t seq = atomic_load(&sh->seq);
    json_t *j = json_object();
    json_object_set_new(j, "state", json_string(x->run.active ? "running" : "idle"));
    json_object_set_new(j, "run_id", x->run.active ? json_integer((json_int_t)x->run.cmd.run_id) : json_null());
    json_object_set_new(j, "last_seq", seq ? json_integer((json_int_t)(seq - 1)) : json_null());
    json_object_set_new(j, "samples", json_integer((json_int_t)atomic_load(&sh->samples)));
    json_object_set_new(j, "blocks", json_integer((json_int_t)atomic_load(&sh->blocks)));
    json_object_set_new(j, "late_blocks", json_integer((json_int_t)atomic_load(&sh->late_blocks)));
    json_object_set_new(j, "worst_late_ns", json_integer((json_int_t)atomic_load(&sh->worst_late_ns)));
    json_object_set_new(j, "dropped", json_integer((json_int_t)atomic_load(&sh->dropped)));
    json_object_set_new(j, "uptime_s", json_real((double)(now - x->t_boot) / 1e9));
    s_send_json(x, "heartbeat", j);
}

/* XPUB delivers (un)subscriptions as messages: a new subscriber gets a heartbeat at once (so a client
 * knows its subscription is in place) and, mid-run, the run's start message again. */
static void s_subscriptions(s_ctx *x)
{
    char buf[256];
    int rc;
    int again = 0;
    while ((rc = zmq_recv(x->d->pub, buf, sizeof buf, ZMQ_DONTWAIT)) >= 0)
        if (rc >= 1 && buf[0] == 1)
            again = 1;
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
    int64_t next_hb = x->t_boot;
    for (;;) {
        vafmd_sim_cmd c;
        int quit = 0;
        while (vafmd_ring_pop(&x->d->ring, &c)) {
            if (c.type == VAFMD_SIM_START) {
                if (x->run.active) /* the control thread prevents this; never leak the run either way */
                    s_run_end(x, "aborted", VAFM_EABORT);
                s_run_start(x, &c);
            } else if (c.type == VAFMD_SIM_ABORT) {
                if (x->run.active)
                    s_run_end(x, "aborted", 0);
            } else if (c.type == VAFMD_SIM_QUIT) {
                if (x->run.active)
                    s_run_end(x, "aborted", 0);
                quit = 1;
            }
        }
        if (quit)
            break;
        s_subscriptions(x);
        int64_t now = s_now();
        if (now >= next_hb) {
            s_heartbeat(x, now);
            next_hb += S_NS;
            if (next_hb < now) /* after a long stall: keep the 1 Hz grid, skip the missed beats */
                next_hb = now + S_NS - (now - next_hb) % S_NS;
        }
        if (x->run.active)
            s_run_block(x);
        else
            s_sleep_until(now + 1000000); /* idle: look at the ring every millisecond */
    }
    free(x);
    return NULL;
}
