/* SPDX-License-Identifier: MIT */
/*
 * The HDF5 writer thread (protocol/wire.md, "log"): it assembles each logged force curve from the blocks
 * the simulation thread pushes through the log ring, appends it to the file in the layout of
 * protocol/hdf5.md and flushes after every curve, so a killed daemon loses at most the curve in
 * progress. The arrays in the file are copies of the very doubles that were streamed (bit for bit).
 *
 * A paced run never waits for this thread: the ring is bounded and a full ring costs the curve (counted),
 * not time; a free run waits for room instead and loses nothing (sim_logpool.c, "Free run"). Each curve
 * whose run.end said "pending" gets exactly one notice, from here (its end item) or, when its end item
 * was lost, from the simulation thread; the counters count each curve once, where its notice comes from. The log blocks come from the simulation thread's preallocated pool and go
 * back to it through the free ring (sim_logpool.c, "The log block pool"). This thread polls the ring
 * (1 ms naps when it is empty); the writer object is handed over by the control thread through the
 * atomic log state (OFF → ON) and handed back, closed, by this thread (STOPPING → OFF).
 */
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>
#include "daemon/daemon.h"
#include "record/record.h"

typedef struct s_curve {
    vafmd_log_begin *begin; /* NULL: no curve in progress */
    int broken;
    size_t n, cap;
    double *ch[VAFM_CH_COUNT]; /* the rows of core/channels.h that go into files */
    unsigned mask;             /* the rows the curve's blocks carry */
    uint8_t *segment;
} s_curve;

static void s_curve_free(s_curve *c);

static void s_curve_reset(s_curve *c)
{
    free(c->begin);
    c->begin = NULL;
    c->broken = 0;
    c->mask = 0;
    c->n = 0;
    if (c->cap > ((size_t)1 << 20)) /* a long curve's buffers go back to the system (an idle daemon holds
                                      at most ~35 MB of them) */
        s_curve_free(c);
}

static void s_curve_free(s_curve *c)
{
    free(c->begin);
    for (int k = 0; k < VAFM_CH_COUNT; k++)
        free(c->ch[k]);
    free(c->segment);
    memset(c, 0, sizeof *c);
}

static int s_curve_grow(s_curve *c, size_t need)
{
    if (need <= c->cap)
        return 0;
    if (need > VAFMD_LOG_MAX_CURVE_SAMPLES)
        return -1; /* the curve is not written (log_failed), memory stays bounded */
    size_t cap = c->cap ? c->cap : 65536;
    while (cap < need)
        cap *= 2;
    if (cap > VAFMD_LOG_MAX_CURVE_SAMPLES)
        cap = VAFMD_LOG_MAX_CURVE_SAMPLES;
    for (int k = 0; k < VAFM_CH_COUNT; k++) {
        if (!vafm_channels[k].file)
            continue;
        double *p = realloc(c->ch[k], cap * sizeof(double));
        if (!p)
            return -1;
        c->ch[k] = p;
    }
    uint8_t *s = realloc(c->segment, cap);
    if (!s)
        return -1;
    c->segment = s;
    c->cap = cap;
    return 0;
}

static void s_set_err(vafmd_log *L, const char *fmt, const char *a, const char *b)
{
    pthread_mutex_lock(&L->err_mu);
    snprintf(L->err, sizeof L->err, fmt, a, b);
    pthread_mutex_unlock(&L->err_mu);
}

/* Tell the simulation thread (which publishes it) that run_id is durable as `group`, or will not be
 * written (ok 0). This thread may wait for room; it gives up once the daemon is quitting (the simulation
 * thread, which empties the ring, has gone then). */
static void s_notice(vafmd_log *L, uint64_t run_id, uint64_t group, int ok)
{
    vafmd_log_notice n = { run_id, group, ok };
    while (!vafmd_ring_push(&L->notice_ring, &n)) {
        if (atomic_load_explicit(&L->quit, memory_order_acquire))
            return;
        nanosleep(&(struct timespec){ 0, 1000000 }, NULL);
    }
}

/* "vafm ctrl" (protocol/hdf5.md): {"commands": [...], "runs": [...]} of the open file, as a root attribute
 * rewritten when it grows and made durable by the next flush (a curve's append, or at once for commands).
 * Bounded: past VAFMD_LOG_JOURNAL_MAX entries it records no more and says so ("truncated": true). */
static json_t *s_journal(vafmd_log *L)
{
    if (L->jnote_of != L->w || !L->jnote) {
        json_decref(L->jnote);
        L->jnote = json_pack("{s:[],s:[],s:b}", "commands", "runs", "truncated", 0);
        L->jnote_of = L->w;
        L->jlast[0] = 0;
    }
    return L->jnote;
}

static int s_journal_add(vafmd_log *L, const char *list, json_t *rec)
{
    json_t *j = s_journal(L);
    if (!j || json_array_size(json_object_get(j, "commands")) + json_array_size(json_object_get(j, "runs")) >=
                  VAFMD_LOG_JOURNAL_MAX) {
        if (j)
            json_object_set_new(j, "truncated", json_true());
        json_decref(rec);
        return -1;
    }
    json_array_append_new(json_object_get(j, list), rec);
    L->jdirty = 1;
    return 0;
}

static void s_journal_note(vafmd_log *L)
{
    if (!L->jdirty || !L->w)
        return;
    L->jdirty = 0;
    char *text = json_dumps(L->jnote, JSON_COMPACT);
    vafm_error e;
    memset(&e, 0, sizeof e);
    if (!text || vafm_recorder_set_note(L->w, "vafm ctrl", text, &e))
        s_set_err(L, "the controller journal: %s%s", text ? e.message : "out of memory", "");
    free(text);
}

void vafmd_log_journal(vafmd *d, json_t *rec)
{
    vafmd_log *L = &d->log;
    if (!rec)
        return;
    if (atomic_load_explicit(&L->state, memory_order_acquire) != VAFMD_LOG_ON) {
        json_decref(rec); /* no file: nothing to record it in */
        return;
    }
    pthread_mutex_lock(&L->jmu);
    if (!L->jpend)
        L->jpend = json_array();
    if (json_array_size(L->jpend) < 4096)
        json_array_append(L->jpend, rec);
    const uint64_t seq = ++L->jseq;
    pthread_mutex_unlock(&L->jmu);
    json_decref(rec);
    /* durable before the reply (a kill -9 right after it must not lose it): the writer takes it within a
     * millisecond, or between two items of a run it is writing */
    struct timespec t0, t;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    while (atomic_load_explicit(&L->jdone, memory_order_acquire) < seq &&
           atomic_load_explicit(&L->state, memory_order_acquire) == VAFMD_LOG_ON &&
           !atomic_load_explicit(&L->quit, memory_order_acquire)) {
        clock_gettime(CLOCK_MONOTONIC, &t);
        if ((long long)(t.tv_sec - t0.tv_sec) * 1000000000LL + (t.tv_nsec - t0.tv_nsec) > VAFMD_LOG_JOURNAL_WAIT_NS)
            break;
        nanosleep(&(struct timespec){ 0, 50000 }, NULL);
    }
}

/* Writer thread: the commands handed over since the last call into the journal, flushed (durable), and the
 * control thread told (jdone). */
static void s_journal_take(vafmd_log *L, int st)
{
    json_t *cmds = NULL;
    pthread_mutex_lock(&L->jmu);
    if (L->jpend && json_array_size(L->jpend)) {
        cmds = L->jpend;
        L->jpend = NULL;
    }
    const uint64_t upto = L->jseq;
    pthread_mutex_unlock(&L->jmu);
    if (cmds && st == VAFMD_LOG_ON && L->w) {
        size_t i;
        json_t *v;
        json_array_foreach(cmds, i, v) s_journal_add(L, "commands", json_incref(v));
        s_journal_note(L);
        vafm_error e; /* durable now: commands are rare, and a kill must not lose one */
        memset(&e, 0, sizeof e);
        if (vafm_recorder_flush(L->w, &e))
            s_set_err(L, "the controller journal: %s%s", e.message, "");
    }
    json_decref(cmds);
    atomic_store_explicit(&L->jdone, upto, memory_order_release);
}

/* Append the finished curve; the recorder makes it durable before it returns (flush interval 0). */
static void s_write(vafmd_log *L, s_curve *c, const vafmd_log_end *end)
{
    vafm_samples s = { .n = c->n, .first = 0, .segment = c->segment };
    for (int k = 0; k < VAFM_CH_COUNT; k++)
        if (c->mask & (1u << k))
            vafm_channel_set_samples(&s, k, c->ch[k]);
    /* the group number is the file's curve count; the random stream index and the run are kept in the
     * curve id (the curve-group attribute list is closed). With the detector on the force is a measured
     * (noisy, quantised) one, so "tip position" = height + force/k (hdf5.md L14) is left out; so it is
     * when a saturate or stuck-dropout fault altered the force (0.6.1 refused such a curve: log_failed). */
    vafm_curve_result res = end->result;
    res.index = c->begin->index;
    vafm_record_curve rc = { .samples = &s, .params = &c->begin->p, .result = &res, .point = c->begin->point,
                             .run_id = c->begin->run_id, .client_run_id = c->begin->client_run_id,
                             .sensitivity_m_per_V = c->begin->p.sensitivity_m_per_V,
                             .measured_force = c->begin->detector || end->force_altered };
    if (c->begin->is_map) {
        rc.map = &c->begin->map;
        rc.pixel = &c->begin->pixel;
    }
    /* the controller's state at the run's start, when it differs from the last one recorded (a campaign's
     * curves share the held state): noted before the append, whose flush makes it durable with the curve */
    if (c->begin->ctrl[0] && strcmp(c->begin->ctrl, L->jlast)) {
        json_t *st = json_loads(c->begin->ctrl, 0, NULL);
        if (st) {
            json_object_set_new(st, "from_group", json_integer((json_int_t)vafm_recorder_count(L->w)));
            json_object_set_new(st, "run_id", json_integer((json_int_t)c->begin->run_id));
            if (!s_journal_add(L, "runs", st))
                snprintf(L->jlast, sizeof L->jlast, "%s", c->begin->ctrl);
            s_journal_note(L);
        }
    }
    vafm_error e;
    memset(&e, 0, sizeof e);
    char *lt = c->begin->nseg ? vafm_segments_to_json(c->begin->segs, c->begin->nseg) : NULL;
    rc.segments_json = lt; /* a list's curve carries its own list (hdf5.md V7, format 1.3) */
    int r = c->begin->nseg && !lt ? VAFM_ENOMEM : vafm_recorder_append(L->w, &rc, &e);
    free(lt);
    if (r) {
        atomic_fetch_add_explicit(&L->curves_dropped, 1, memory_order_relaxed);
        s_set_err(L, "%s (%s)", e.message[0] ? e.message : vafm_strerror(r), e.field);
        s_notice(L, c->begin->run_id, 0, 0);
    } else {
        atomic_fetch_add_explicit(&L->curves, 1, memory_order_relaxed);
        s_notice(L, c->begin->run_id, vafm_recorder_count(L->w) - 1, 1); /* durable: flushed in append */
    }
}

/* An item is done with: a log block goes back to the simulation thread's pool through the free ring (it
 * lives inside a pool allocation: never free()d one by one), begin and end items are freed here. The
 * free ring holds every block that can be out at once (sim_logpool.c sizes it), so the push does not
 * fail; if it ever did, the block would only be lost to its pool until the pool is freed whole. */
static void s_item_done(vafmd_log *L, vafmd_log_item *it)
{
    if (it->type == VAFMD_LOG_BLOCK) {
        if (it->ptr)
            vafmd_ring_push(&L->free_ring, &it->ptr);
    } else
        free(it->ptr);
    it->ptr = NULL;
}

static void s_handle(vafmd_log *L, s_curve *c, vafmd_log_item *it, int on)
{
    switch (it->type) {
    case VAFMD_LOG_BEGIN:
        s_curve_reset(c); /* a curve still open lost its end item: the simulation thread counted it */
        c->begin = it->ptr;
        it->ptr = NULL;
        break;
    case VAFMD_LOG_BLOCK: {
        const vafmd_log_block *b = it->ptr;
        if (!c->begin || c->begin->run_id != it->run_id || c->broken)
            break;
        if (s_curve_grow(c, c->n + b->n)) {
            c->broken = 1;
            break;
        }
        for (int k = 0; k < VAFM_CH_COUNT; k++)
            if (b->mask & (1u << k))
                memcpy(c->ch[k] + c->n, b->ch[k], b->n * sizeof(double));
        c->mask = b->mask;
        memcpy(c->segment + c->n, b->segment, b->n);
        c->n += b->n;
        break;
    }
    case VAFMD_LOG_END: {
        const vafmd_log_end *e = it->ptr;
        if (!c->begin || c->begin->run_id != it->run_id) { /* its begin was lost */
            if (e->ok) {
                atomic_fetch_add_explicit(&L->curves_dropped, 1, memory_order_relaxed);
                s_notice(L, it->run_id, 0, 0);
            } else
                atomic_fetch_add_explicit(&L->curves_skipped, 1, memory_order_relaxed);
            s_curve_reset(c);
            break;
        }
        if (!e->ok)
            atomic_fetch_add_explicit(&L->curves_skipped, 1, memory_order_relaxed);
        else if (c->broken || e->broken || c->n == 0 || !on) {
            atomic_fetch_add_explicit(&L->curves_dropped, 1, memory_order_relaxed);
            s_notice(L, it->run_id, 0, 0);
        } else
            s_write(L, c, e);
        s_curve_reset(c);
        break;
    }
    default: break;
    }
    s_item_done(L, it);
}

void *vafmd_log_main(void *arg)
{
    vafmd *d = arg;
    vafmd_log *L = &d->log;
    s_curve c;
    memset(&c, 0, sizeof c);
    json_t *faults = NULL;          /* the faults of the open file (root attribute "vafm faults") */
    vafm_recorder *faults_of = NULL; /* the recorder they belong to (a new log starts a new list) */
    for (;;) {
        vafmd_log_item it;
        int got = 0;
        vafmd_fault_rec fr;
        if (L->test_stall && !atomic_load_explicit(&L->quit, memory_order_acquire) && access(L->test_stall, F_OK) == 0) {
            nanosleep(&(struct timespec){ 0, 1000000 }, NULL); /* test hook: a writer that does not keep up */
            continue;
        }
        int st = atomic_load_explicit(&L->state, memory_order_acquire);
        int fdirty = 0;
        while (vafmd_ring_pop(&L->fault_ring, &fr)) { /* faults first: a curve's come before its end */
            if (st == VAFMD_LOG_OFF || !L->w)
                continue;
            if (faults_of != L->w) {
                json_decref(faults);
                faults = json_array();
                faults_of = L->w;
            }
            json_array_append_new(faults, vafmd_fault_rec_json(&fr));
            fdirty = 1;
        }
        if (fdirty) { /* durable with the next flush: the next curve's append, or the close */
            char *text = json_dumps(faults, JSON_COMPACT);
            vafm_error e;
            memset(&e, 0, sizeof e);
            if (!text || vafm_recorder_set_note(L->w, "vafm faults", text, &e))
                s_set_err(L, "the fault record: %s%s", text ? e.message : "out of memory", "");
            free(text);
        }
        s_journal_take(L, st); /* state-changing commands from the control thread */
        while (vafmd_ring_pop(&L->ring, &it)) {
            got = 1;
            s_handle(L, &c, &it, st != VAFMD_LOG_OFF);
            s_journal_take(L, st); /* a run's items may keep coming: the command waits for its reply */
        }
        if (st == VAFMD_LOG_STOPPING) {
            /* everything pushed before the stop request was popped above (the request is made only when
             * no run is in progress, after its end was pushed) */
            vafm_error e;
            memset(&e, 0, sizeof e);
            s_curve_reset(&c); /* a curve still open lost its end item: the simulation thread counted it */
            faults_of = NULL; /* the next log starts a list of its own */
            if (vafm_recorder_close(&L->w, NULL, &e))
                s_set_err(L, "closing the file: %s%s", e.message, "");
            atomic_store_explicit(&L->state, VAFMD_LOG_OFF, memory_order_release);
            continue;
        }
        if (st == VAFMD_LOG_OFF && atomic_load_explicit(&L->quit, memory_order_acquire)) {
            while (vafmd_ring_pop(&L->ring, &it))
                s_item_done(L, &it);
            break;
        }
        if (!got)
            nanosleep(&(struct timespec){ 0, 1000000 }, NULL);
    }
    s_curve_free(&c);
    json_decref(faults);
    /* last one out: the simulation thread has exited (main.c joins it before it sets quit), so the pools
     * it left with blocks still in flight and the free ring's slots are this thread's to free */
    while (L->orphans) {
        vafmd_log_pool *p = L->orphans;
        L->orphans = p->next;
        free(p);
    }
    free(L->free_store);
    L->free_store = NULL;
    return NULL;
}
