/* SPDX-License-Identifier: MIT */
/*
 * The control loop: one REP socket, one request at a time, every request answered exactly once.
 *
 * The control thread owns the scene and the settings. Starting a run builds (and so validates) the
 * simulation here, where an error can still be answered, then hands it to the simulation thread through
 * the SPSC ring. Whether a run is in progress is known without asking the simulation thread: runs
 * started here minus runs the simulation thread reports as done.
 */
#include <errno.h>
#include <math.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <zmq.h>
#include "h5/h5.h"
#include "record/record.h"
#include "daemon/camp_feed.h"
#include "daemon/cmd_json.h"
#include "daemon/daemon.h"
#include "daemon/replay.h"
#include "core/channels.h"
#include "daemon/run_json.h"
#include "vafm/wire.h"

/* Client run ids seen lately: a retried start with the same id gets the same run back. */
#define S_HISTORY 32
typedef struct s_hist {
    char client_run_id[VAFMD_CLIENT_RUN_ID_MAX + 1];
    uint64_t run_id;
    int kind;              /* enum vafmd_run_kind, or S_KIND_CAMPAIGN */
    uint64_t campaign_id, curves; /* campaigns */
    size_t block_samples;  /* runs: the accepted reply's block_samples (a duplicate reply repeats it) */
} s_hist;
#define S_KIND_CAMPAIGN 1000

static s_hist s_history[S_HISTORY];
static unsigned s_history_n;

static const s_hist *s_history_find(const char *id)
{
    for (unsigned i = 0; i < S_HISTORY && i < s_history_n; i++)
        if (!strcmp(s_history[i].client_run_id, id))
            return &s_history[i];
    return NULL;
}

static json_t *s_ok(const vafmd_cmd *c)
{
    json_t *r = json_object();
    json_object_set_new(r, "status", json_string("ok"));
    json_object_set_new(r, "cmd", json_string(vafmd_cmd_name(c->kind)));
    if (c->id)
        json_object_set(r, "id", c->id);
    return r;
}

/* A job (curve, tune, campaign) is in progress: the simulation thread has not reported it done. */
static int s_busy(const vafmd *d)
{
    return d->jobs_started != atomic_load_explicit(&d->sh.jobs_done, memory_order_acquire);
}

static json_t *s_hello(const vafmd *d, const vafmd_cmd *c)
{
    json_t *r = s_ok(c);
    json_object_set_new(r, "protocol_version", json_integer(VAFM_WIRE_PROTOCOL_VERSION));
    json_object_set_new(r, "daemon", json_string("vafmd"));
    json_object_set_new(r, "daemon_version", json_string(VAFMD_VERSION));
    json_object_set_new(r, "library_version", json_string(vafm_version()));
    /* every command of commands.def, in 0.5's order (log before shutdown; tests/test_commands.py checks the
     * list against the table): a new command goes at the end of both */
    json_object_set_new(r, "capabilities",
                        json_pack("[sssssssssssssssssss]", "hello", "get", "set", "presets", "curve", "tune", "abort",
                                  "status", "log", "shutdown", "campaign", "replay", "faults", "map", "engage",
                                  "withdraw", "move", "z", "feedback"));
    json_object_set_new(r, "not_implemented", json_array());
    json_object_set_new(r, "security", json_string(d->auth.on ? "curve" : "none"));
    json_t *stream = json_string(d->pub_endpoint); /* NULL for an endpoint that is not UTF-8 */
    json_object_set_new(r, "stream", stream ? stream : json_null());
    json_object_set_new(r, "channels", vafmd_channels_json(vafm_channels_mask(VAFM_CHF_LIVE)));
    json_object_set_new(r, "max_request_bytes", json_integer(VAFMD_MAX_CMD_BYTES));
    json_object_set_new(r, "session", json_integer(atomic_load(&d->sh.session)));
    json_object_set_new(r, "live", vafmd_live_hello_json()); /* the controller's topic (live.c) */
    return r;
}

static json_t *s_presets(const vafmd_cmd *c)
{
    json_t *r = s_ok(c), *a = json_array();
    for (int i = 0; i < vafm_preset_count(); i++)
        json_array_append_new(a, json_pack("{s:s,s:s}", "name", vafm_preset_name(i), "description",
                                           vafm_preset_description(i)));
    json_object_set_new(r, "presets", a);
    return r;
}

static const char *s_log_state_name(int st)
{
    return st == VAFMD_LOG_ON ? "on" : st == VAFMD_LOG_STOPPING ? "stopping" : "off";
}

/* Logging counters, in status and in the reply to `log`. */
static json_t *s_log_report(vafmd *d)
{
    vafmd_log *L = &d->log;
    int st = atomic_load_explicit(&L->state, memory_order_acquire);
    json_t *o = json_object();
    json_object_set_new(o, "state", json_string(s_log_state_name(st)));
    json_object_set_new(o, "path", L->path[0] ? json_string(L->path) : json_null());
    json_object_set_new(o, "curves", json_integer((json_int_t)atomic_load(&L->curves)));
    json_object_set_new(o, "overflows", json_integer((json_int_t)atomic_load(&L->overflows)));
    json_object_set_new(o, "curves_dropped", json_integer((json_int_t)atomic_load(&L->curves_dropped)));
    json_object_set_new(o, "curves_skipped", json_integer((json_int_t)atomic_load(&L->curves_skipped)));
    /* items (curve begin/block/end) waiting for the writer: a reading of the SPSC ring's two indices */
    size_t tail = atomic_load_explicit(&L->ring.tail, memory_order_acquire);
    size_t head = atomic_load_explicit(&L->ring.head, memory_order_acquire);
    json_object_set_new(o, "queued", json_integer((json_int_t)(head >= tail ? head - tail : 0)));
    pthread_mutex_lock(&L->err_mu);
    json_object_set_new(o, "error", L->err[0] ? json_string(L->err) : json_null());
    pthread_mutex_unlock(&L->err_mu);
    return o;
}

static json_t *s_log(vafmd *d, const vafmd_cmd *c, vafmd_err *e)
{
    vafmd_log *L = &d->log;
    int st = atomic_load_explicit(&L->state, memory_order_acquire);
    if (s_busy(d)) {
        vafmd_err_set(e, VAFMD_E_STATE, "cmd", "logging starts and stops between runs: a run is in progress "
                      "(run %" PRIu64 ")", d->next_run_id - 1);
        return NULL;
    }
    if (c->log_stop) {
        if (st == VAFMD_LOG_OFF) {
            vafmd_err_set(e, VAFMD_E_STATE, "stop", "logging is off");
            return NULL;
        }
        /* the run's items were pushed before runs_done counted it (s_busy above): the writer sees them
         * before this request */
        if (st == VAFMD_LOG_ON)
            atomic_store_explicit(&L->state, VAFMD_LOG_STOPPING, memory_order_release);
        /* the control thread may wait for the writer (only the simulation thread never waits) */
        for (int i = 0; i < 600000 && atomic_load_explicit(&L->state, memory_order_acquire) != VAFMD_LOG_OFF; i++)
            nanosleep(&(struct timespec){ 0, 100000 }, NULL);
        json_t *r = s_ok(c);
        json_object_set_new(r, "log", s_log_report(d));
        return r;
    }
    if (st != VAFMD_LOG_OFF) {
        vafmd_err_set(e, VAFMD_E_STATE, "path", "already logging to '%.300s'; stop it first", L->path);
        return NULL;
    }
    vafm_recorder_opts o;
    vafm_recorder_opts_default(&o); /* durable after every curve */
    o.keep_intact = 1;               /* live curves cannot be recomputed: a resume never drops an intact one */
    o.mode = c->log_resume ? VAFM_RECORD_RESUME : c->log_overwrite ? VAFM_RECORD_OVERWRITE : VAFM_RECORD_CREATE;
    vafm_error verr;
    memset(&verr, 0, sizeof verr);
    vafm_recorder *w = NULL;
    /* the file's provenance is the scene at log start (wire.md "log") */
    int rc = vafm_recorder_open(&w, c->log_path, &o, &d->scene, NULL, &verr);
    if (rc) {
        /* a resume whose scene is not the file's names the scene field; the file itself, "path" */
        int scene_mismatch = c->log_resume && rc == VAFM_EINVAL && verr.field[0] && strcmp(verr.field, "path");
        vafmd_err_set(e, scene_mismatch ? VAFMD_E_INVALID_SCENE : rc == VAFM_EINVAL ? VAFMD_E_OUT_OF_RANGE : VAFMD_E_IO,
                      scene_mismatch ? "resume" : "path", "cannot %s '%.300s': %s%s%s",
                      c->log_resume ? "resume" : "create", c->log_path, verr.message[0] ? verr.message : vafm_strerror(rc),
                      scene_mismatch ? "; scene field " : "", scene_mismatch ? verr.field : "");
        return NULL;
    }
    uint64_t kept = vafm_recorder_count(w);
    L->w = w;
    snprintf(L->path, sizeof L->path, "%s", c->log_path);
    atomic_store(&L->curves, 0);
    atomic_store(&L->overflows, 0);
    atomic_store(&L->curves_dropped, 0);
    atomic_store(&L->curves_skipped, 0);
    pthread_mutex_lock(&L->err_mu);
    L->err[0] = 0;
    pthread_mutex_unlock(&L->err_mu);
    atomic_store_explicit(&L->state, VAFMD_LOG_ON, memory_order_release); /* hands w to the writer thread */
    json_t *r = s_ok(c);
    json_object_set_new(r, "path", json_string(L->path));
    json_object_set_new(r, "curves_in_file", json_integer((json_int_t)kept));
    return r;
}

/* ---- fault injection (faults.h, protocol/faults.md) ------------------------------------------------ */

/* Faults the simulation thread recorded (its own and the command faults noted to it), and plans it
 * replaced: taken here, between requests. */
static void s_faults_poll(vafmd *d)
{
    vafmd_fault_rec fr;
    while (vafmd_ring_pop(&d->fault_ring, &fr))
        d->fault_last[d->faults_total++ % VAFMD_FAULT_LAST] = fr;
    vafmd_fault_plan *old;
    while (vafmd_ring_pop(&d->retire_ring, &old))
        free(old);
}

/* {"plan": as given or null, "count": N, "last": [records, oldest first]} */
static json_t *s_faults_report(vafmd *d)
{
    s_faults_poll(d);
    json_t *o = json_object(), *a = json_array();
    json_object_set_new(o, "plan", d->fplan_json ? json_incref(d->fplan_json) : json_null());
    json_object_set_new(o, "count", json_integer((json_int_t)d->faults_total));
    uint64_t n = d->faults_total < VAFMD_FAULT_LAST ? d->faults_total : VAFMD_FAULT_LAST;
    for (uint64_t i = d->faults_total - n; i < d->faults_total; i++)
        json_array_append_new(a, vafmd_fault_rec_json(&d->fault_last[i % VAFMD_FAULT_LAST]));
    json_object_set_new(o, "last", a);
    return o;
}

/* Install a plan (NULL: clear): the control thread's copy here, a heap copy for the simulation thread.
 * @return 0, or -1 (busy: the ring is full; nothing changed). */
static int s_faults_install(vafmd *d, const vafmd_fault_plan *p, json_t *given, vafmd_err *e)
{
    vafmd_fault_plan *mine = NULL, *sim = NULL;
    if (p && (!(mine = malloc(sizeof *mine)) || !(sim = malloc(sizeof *sim)))) {
        free(mine);
        vafmd_err_set(e, VAFMD_E_INTERNAL, "", "out of memory");
        return -1;
    }
    if (p) {
        *mine = *p;
        *sim = *p;
    }
    vafmd_sim_cmd sc;
    memset(&sc, 0, sizeof sc);
    sc.type = VAFMD_SIM_FAULTS;
    sc.plan = sim && sim->any_stream ? sim : NULL; /* a plan of command faults only: the stream stays off */
    if (!vafmd_ring_push(&d->ring, &sc)) {
        free(mine);
        free(sim);
        vafmd_err_set(e, VAFMD_E_BUSY, "", "the simulation thread does not take commands now; retry");
        return -1;
    }
    if (sim && !sc.plan)
        free(sim);
    free(d->fplan);
    d->fplan = mine;
    json_decref(d->fplan_json);
    d->fplan_json = given ? json_deep_copy(given) : NULL;
    d->fault_requests = 0;
    memset(d->fault_match, 0, sizeof d->fault_match);
    return 0;
}

int vafmd_faults_configure(vafmd *d, json_t *plan, vafmd_err *e)
{
    vafmd_fault_plan *p = malloc(sizeof *p);
    if (!p) {
        vafmd_err_set(e, VAFMD_E_INTERNAL, "", "out of memory");
        return -1;
    }
    int rc = vafmd_faults_decode(plan, p, e) || s_faults_install(d, p, plan, e) ? -1 : 0;
    free(p);
    return rc;
}

static json_t *s_faults_cmd(vafmd *d, const vafmd_cmd *c, vafmd_err *e)
{
    if (c->fault_clear && s_faults_install(d, NULL, NULL, e))
        return NULL;
    if (c->fault_plan && vafmd_faults_configure(d, c->fault_plan, e))
        return NULL;
    json_t *r = s_ok(c);
    json_t *rep = s_faults_report(d); /* the plan now in force, the count and the last faults */
    json_object_update(r, rep);       /* (copies the members: the report itself is ours to free) */
    json_decref(rep);
    return r;
}

/* The command fault this request gets, if any (-1: none). The `faults` command itself is never faulted,
 * so that a plan can always be cleared. */
static int s_command_fault(vafmd *d, const vafmd_cmd *c, vafmd_fault_rec *fr)
{
    const vafmd_fault_plan *p = d->fplan;
    if (__builtin_expect(!p || !p->any_command, 1) || !(vafmd_cmd_flags(c->kind) & VAFMD_CF_FAULTABLE))
        return -1;
    const char *name = vafmd_cmd_name(c->kind);
    uint64_t nreq = ++d->fault_requests;
    int kind = -1;
    memset(fr, 0, sizeof *fr);
    for (size_t i = 0; i < p->n_script && kind < 0; i++) {
        const vafmd_fault_entry *en = &p->script[i];
        if (vafmd_fault_where(en->kind) != VAFMD_FW_COMMAND || (en->cmd[0] && strcmp(en->cmd, name)))
            continue;
        if (++d->fault_match[i] == en->nth) {
            kind = en->kind;
            fr->p0 = en->p0;
            fr->p1 = en->p1;
            fr->scripted = 1;
        }
    }
    for (int k = 0; k < VAFMD_F_N && kind < 0; k++) {
        const vafmd_fault_random *rr = &p->rnd[k];
        if (rr->per != VAFMD_FPER_COMMAND || !(rr->rate > 0) || (rr->cmd[0] && strcmp(rr->cmd, name)))
            continue;
        if (vafmd_fault_u01(p->seed, k, nreq, 0) < rr->rate) {
            kind = k;
            fr->p0 = rr->p0;
            fr->p1 = rr->p1;
        }
    }
    if (kind >= 0) {
        fr->kind = kind;
        fr->run_id = 0;
        fr->block = fr->seq = -1;
        fr->run_time_s = NAN;
        snprintf(fr->cmd, sizeof fr->cmd, "%s", name);
    }
    return kind;
}

/* Hand an injected command fault to the simulation thread, which numbers, publishes and logs it. */
static void s_fault_note(vafmd *d, vafmd_fault_rec *fr)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    fr->time_s = (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec; /* made uptime by the simulation thread */
    vafmd_sim_cmd sc;
    memset(&sc, 0, sizeof sc);
    sc.type = VAFMD_SIM_FAULT_NOTE;
    sc.fault = *fr;
    for (int i = 0; i < 1000 && !vafmd_ring_push(&d->ring, &sc); i++) /* the control thread may wait */
        nanosleep(&(struct timespec){ 0, 1000000 }, NULL);
}

static json_t *s_status(vafmd *d, const vafmd_cmd *c)
{
    const vafmd_shared *sh = &d->sh;
    json_t *r = s_ok(c);
    int busy = s_busy(d);
    int st = atomic_load(&sh->state);
    json_object_set_new(r, "state", json_string(!busy ? "idle" : st == VAFMD_RUNNING ? "running" : "starting"));
    /* One run at a time: while busy, the run in progress is the last one started here (the simulation
     * thread may not have picked it up yet). */
    json_object_set_new(r, "run_id", !busy ? json_null() : st == VAFMD_RUNNING
                                                     ? json_integer((json_int_t)atomic_load(&sh->run_id))
                                                     : json_integer((json_int_t)d->pending_run_id));
    json_object_set_new(r, "last_run_id", d->next_run_id > 1 ? json_integer((json_int_t)(d->next_run_id - 1))
                                                             : json_null());
    json_object_set_new(r, "runs_started",
                        json_integer((json_int_t)(d->runs_started + atomic_load(&sh->extra_runs))));
    json_object_set_new(r, "runs_done", json_integer((json_int_t)atomic_load(&sh->runs_done)));
    json_object_set_new(r, "run_samples", json_integer((json_int_t)atomic_load(&sh->run_samples)));
    json_object_set_new(r, "samples", json_integer((json_int_t)atomic_load(&sh->samples)));
    json_object_set_new(r, "blocks", json_integer((json_int_t)atomic_load(&sh->blocks)));
    json_object_set_new(r, "late_blocks", json_integer((json_int_t)atomic_load(&sh->late_blocks)));
    json_object_set_new(r, "worst_late_ns", json_integer((json_int_t)atomic_load(&sh->worst_late_ns)));
    json_object_set_new(r, "dropped", json_integer((json_int_t)atomic_load(&sh->dropped)));
    uint64_t seq = atomic_load(&sh->seq);
    json_object_set_new(r, "last_seq", seq ? json_integer((json_int_t)(seq - 1)) : json_null());
    json_object_set_new(r, "speed", json_real(d->set.speed));
    json_object_set_new(r, "free_run", json_boolean(d->set.free_run));
    json_object_set_new(r, "lookahead_s", json_real(d->set.lookahead_s));
    json_object_set_new(r, "lookahead_blocks", json_integer((json_int_t)atomic_load(&sh->lookahead_blocks)));
    json_object_set_new(r, "queued", json_integer((json_int_t)atomic_load(&sh->queued)));
    json_object_set_new(r, "log", s_log_report(d));
    uint64_t cid = d->next_campaign_id;
    if (cid) { /* the last campaign accepted; until the simulation thread takes it up, nothing is done */
        int seen = atomic_load(&sh->camp_id) == cid;
        int crun = busy && d->pending_run_id == d->camp_run_id;
        json_object_set_new(r, "campaign", json_pack("{s:I,s:b,s:I,s:I,s:I,s:o}", "campaign_id", (json_int_t)cid,
                                                     "running", crun, "curves", (json_int_t)d->camp_total,
                                                     "first_index", (json_int_t)d->camp_first, "curves_done",
                                                     (json_int_t)(seen ? atomic_load(&sh->camp_done) : 0), "curve",
                                                     !crun ? json_null()
                                                     : json_integer((json_int_t)(seen ? atomic_load(&sh->camp_next)
                                                                                      : d->camp_first))));
    } else
        json_object_set_new(r, "campaign", json_null());
    json_object_set_new(r, "session", json_integer(atomic_load(&d->sh.session)));
    json_object_set_new(r, "faults", s_faults_report(d));
    json_object_set_new(r, "auth", json_pack("{s:s,s:I,s:I,s:I}", "mechanism", d->auth.on ? "curve" : "null", "clients",
                                             (json_int_t)d->auth.n_clients, "accepted",
                                             (json_int_t)atomic_load(&d->auth.accepted), "refused",
                                             (json_int_t)atomic_load(&d->auth.refused)));
    json_object_set_new(r, "ctrl", vafmd_live_status_json(d)); /* the always-on controller (live.c) */
    return r;
}

/* Remember a start that carries a client run id, so that a retry of it is answered, not run again.
 * @return the entry (for kind-specific fields), or NULL without a client run id. */
static s_hist *s_history_add(const vafmd_cmd *c, uint64_t run_id, int kind)
{
    if (!c->client_run_id[0])
        return NULL;
    s_hist *h = &s_history[s_history_n++ % S_HISTORY];
    memset(h, 0, sizeof *h);
    snprintf(h->client_run_id, sizeof h->client_run_id, "%s", c->client_run_id);
    h->run_id = run_id;
    h->kind = kind;
    return h;
}

/* A duplicate start's reply says whether that run (a campaign: its first run) is still going: a client
 * that waits for its run.end after an "ended" answer would wait forever, so it is told (wire.md "curve"). */
static void s_duplicate_state(vafmd *d, json_t *r, uint64_t run_id)
{
    int running = s_busy(d) && (d->pending_run_id == run_id || d->camp_run_id == run_id);
    json_object_set_new(r, "state", json_string(running ? "running" : "ended"));
    if (!running)
        json_object_set_new(r, "note", json_string("this run has ended: its run.end was published on the stream "
                                                   "already (and its curve logged, with logging on); start a new "
                                                   "run with a new client_run_id to run again"));
}

/* A run handed to the simulation thread: count it, remember its client run id (idempotent retries)
 * and build the ok reply. */
static json_t *s_run_accepted(vafmd *d, const vafmd_cmd *c, uint64_t run_id, int kind, size_t block_n)
{
    d->pending_run_id = run_id;
    d->next_run_id++;
    d->runs_started++;
    d->jobs_started++;
    s_hist *h = s_history_add(c, run_id, kind);
    if (h)
        h->block_samples = block_n;
    json_t *r = s_ok(c);
    json_object_set_new(r, "run_id", json_integer((json_int_t)run_id));
    json_object_set_new(r, "client_run_id", c->client_run_id[0] ? json_string(c->client_run_id) : json_null());
    json_object_set_new(r, "duplicate", json_false());
    json_object_set_new(r, "block_samples", json_integer((json_int_t)block_n));
    return r;
}

/* replay: the file is read and checked here (replay.c); the simulation thread streams it from memory. */
static json_t *s_start_replay(vafmd *d, const vafmd_cmd *c, vafmd_err *e)
{
    vafmd_sim_cmd sc;
    memset(&sc, 0, sizeof sc);
    size_t block_n = 0;
    uint64_t run_id = d->next_run_id;
    if (vafmd_replay_prepare(c, &d->set, run_id, &sc.replay, &sc.start_json, &block_n, e))
        return NULL;
    sc.type = VAFMD_SIM_START;
    sc.kind = VAFMD_RUN_REPLAY;
    sc.run_id = run_id;
    sc.set = d->set;
    if (c->has_speed)
        sc.set.speed = c->speed;
    snprintf(sc.client_run_id, sizeof sc.client_run_id, "%s", c->client_run_id);
    if (!vafmd_ring_push(&d->ring, &sc)) {
        free(sc.start_json);
        vafmd_replay_free(&sc.replay);
        vafmd_err_set(e, VAFMD_E_BUSY, "", "the simulation thread does not take commands now; retry");
        return NULL;
    }
    return s_run_accepted(d, c, run_id, VAFMD_RUN_REPLAY, block_n);
}

/* With logging on, a run whose typical curve has more samples than the writer assembles in memory is
 * refused at once (wire.md "log"). @return 0, or -1 with e filled. */
static int s_log_fits(vafmd *d, const vafm_params *p, const char *where, vafmd_err *e)
{
    if (atomic_load_explicit(&d->log.state, memory_order_acquire) != VAFMD_LOG_ON)
        return 0;
    vafm_sim_estimate est;
    if (vafm_sim_estimate_cost(p, &est, NULL) || est.samples <= (double)VAFMD_LOG_MAX_CURVE_SAMPLES)
        return 0;
    vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "sample_rate_Hz",
                  "%s: with logging on a curve may have at most %zu samples (256 MiB in the writer); this one would "
                  "have ~%.3g (%.3g s at %.6g Hz): lower sample_rate_Hz, or stop logging",
                  where, VAFMD_LOG_MAX_CURVE_SAMPLES, est.samples, est.duration_s, p->sample_rate_Hz);
    return -1;
}

static json_t *s_start(vafmd *d, const vafmd_cmd *c, vafmd_err *e)
{
    int kind = c->kind == VAFMD_CMD_TUNE     ? VAFMD_RUN_TUNE
               : c->kind == VAFMD_CMD_REPLAY ? VAFMD_RUN_REPLAY
                                             : VAFMD_RUN_CURVE;
    if (c->client_run_id[0]) {
        const s_hist *h = s_history_find(c->client_run_id);
        if (h) {
            if (h->kind != kind) {
                vafmd_err_set(e, VAFMD_E_STATE, "client_run_id", "client_run_id '%s' was used for a %s", h->client_run_id,
                              h->kind == VAFMD_RUN_TUNE ? "tune" : h->kind == VAFMD_RUN_REPLAY ? "replay"
                              : h->kind == S_KIND_CAMPAIGN ? "campaign" : "curve");
                return NULL;
            }
            json_t *r = s_ok(c);
            json_object_set_new(r, "run_id", json_integer((json_int_t)h->run_id));
            json_object_set_new(r, "client_run_id", json_string(h->client_run_id));
            json_object_set_new(r, "duplicate", json_true());
            json_object_set_new(r, "block_samples", json_integer((json_int_t)h->block_samples));
            s_duplicate_state(d, r, h->run_id);
            return r;
        }
    }
    if (s_busy(d)) {
        vafmd_err_set(e, VAFMD_E_STATE, "cmd", "a run is in progress (run %" PRIu64 "); abort it or wait for its end",
                      d->next_run_id - 1);
        return NULL;
    }
    if (kind == VAFMD_RUN_REPLAY)
        return s_start_replay(d, c, e);
    if (c->segs && atomic_load_explicit(&d->log.state, memory_order_acquire) != VAFMD_LOG_OFF) {
        vafmd_err_set(e, VAFMD_E_STATE, "segments", "a segment list's curve cannot go into the log: a log file "
                      "holds plain curves (format 1.1, segment count 2), and a format-1.2 file's curves all run the "
                      "one list of its root attribute 'vafm segments' (protocol/hdf5.md V6); stop the log (or run "
                      "the list with vafm run --segments --out)");
        return NULL;
    }
    vafm_params p = d->scene;
    json_t *at_tip = NULL; /* a curve from the live state over a sample: the point under the tip (live.c) */
    if (kind == VAFMD_RUN_CURVE && vafmd_live_curve_scene(d, &p, &at_tip, e) < 0)
        return NULL;
    if (c->has_duration) {
        char buf[64];
        snprintf(buf, sizeof buf, "%.17g", c->duration_s);
        vafm_error verr = { 0 };
        if (vafm_params_set(&p, "tune_duration_s", buf, &verr)) {
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "duration_s", "%s", verr.message);
            json_decref(at_tip);
            return NULL;
        }
    }
    vafm_sim *sim = NULL;
    vafm_error verr = { 0 };
    /* a tune runs at its own rate (tune_rate_Hz) and is bounded by its own length, not by a force curve's at
     * that rate (vafm_sim_new_tune), as vafm samples --tune */
    int rc = kind == VAFMD_RUN_TUNE ? vafm_sim_new_tune(&sim, &p, &verr) : vafm_sim_new(&sim, &p, &verr);
    if (rc && kind == VAFMD_RUN_TUNE && !strcmp(verr.field, "tune_duration_s")) {
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "duration_s", "%s", verr.message); /* the tune's own length */
        json_decref(at_tip);
        return NULL;
    }
    if (rc) {
        vafmd_err_set(e, VAFMD_E_INVALID_SCENE, verr.field, "cannot build the simulation: %s",
                      verr.message[0] ? verr.message : vafm_strerror(rc));
        json_decref(at_tip);
        return NULL;
    }
    if (kind == VAFMD_RUN_TUNE)
        p = *vafm_sim_params(sim); /* the tune's scene, at the tune's sample rate */
    vafm_segment_spec *segs = NULL;
    if (kind == VAFMD_RUN_CURVE && c->segs) { /* checked against the scene now, where the error can be answered */
        memset(&verr, 0, sizeof verr);
        rc = vafm_segments_validate(c->segs, c->nseg, &p, &verr);
        segs = rc ? NULL : malloc(c->nseg * sizeof *segs);
        if (rc || !segs) {
            vafmd_err_set(e, rc ? VAFMD_E_OUT_OF_RANGE : VAFMD_E_BUSY, verr.field[0] ? verr.field : "segments",
                          "%s", rc ? verr.message : "out of memory; retry");
            vafm_sim_destroy(&sim);
            json_decref(at_tip);
            return NULL;
        }
        memcpy(segs, c->segs, c->nseg * sizeof *segs);
    }
    if (kind == VAFMD_RUN_CURVE && s_log_fits(d, &p, "curve", e)) {
        vafm_sim_destroy(&sim);
        free(segs);
        json_decref(at_tip);
        return NULL;
    }
    uint64_t run_id = d->next_run_id;
    size_t block_n = vafmd_block_samples(p.sample_rate_Hz, d->set.block_s);
    vafmd_sim_cmd sc;
    memset(&sc, 0, sizeof sc);
    sc.type = VAFMD_SIM_START;
    sc.kind = kind;
    sc.run_id = run_id;
    sc.index = c->has_index ? c->index : 0;
    sc.sim = sim;
    sc.segs = segs;
    sc.nseg = segs ? c->nseg : 0;
    sc.start_json = vafmd_run_start_json(&p, &d->set, kind, run_id, sc.index, c->client_run_id, vafm_sim_dt(sim), NULL);
    if (at_tip && sc.start_json) { /* run.start names the point: its scene (above) re-runs the curve exactly */
        json_t *j = json_loads(sc.start_json, 0, NULL);
        char *t = NULL;
        if (j && !json_object_set(j, "sample", at_tip))
            t = json_dumps(j, JSON_COMPACT);
        json_decref(j);
        free(sc.start_json);
        sc.start_json = t;
    }
    json_decref(at_tip);
    if (segs && sc.start_json) { /* run.start names the list: a block's segment is its position in it */
        json_t *j = json_loads(sc.start_json, 0, NULL);
        char *lt = vafm_segments_to_json(segs, sc.nseg);
        json_t *l = lt ? json_loads(lt, 0, NULL) : NULL;
        char *t = NULL;
        if (j && l && !json_object_set(j, "segment_list", json_object_get(l, "segments")))
            t = json_dumps(j, JSON_COMPACT);
        free(lt);
        json_decref(l);
        json_decref(j);
        free(sc.start_json);
        sc.start_json = t;
    }
    sc.set = d->set;
    sc.log = kind == VAFMD_RUN_CURVE && atomic_load_explicit(&d->log.state, memory_order_acquire) == VAFMD_LOG_ON;
    snprintf(sc.client_run_id, sizeof sc.client_run_id, "%s", c->client_run_id);
    if (!sc.start_json || !vafmd_ring_push(&d->ring, &sc)) {
        free(sc.start_json);
        free(segs);
        vafm_sim_destroy(&sim);
        vafmd_err_set(e, VAFMD_E_BUSY, "", "the simulation thread does not take commands now; retry");
        return NULL;
    }
    return s_run_accepted(d, c, run_id, kind, block_n);
}

/* `campaign`: check the whole grid here (every point's scene, the first point's simulation), where an
 * error can still be answered; the simulation thread then runs the curves one after the other. */
static json_t *s_campaign(vafmd *d, const vafmd_cmd *c, vafmd_err *e)
{
    if (c->client_run_id[0]) {
        const s_hist *h = s_history_find(c->client_run_id);
        if (h) {
            if (h->kind != S_KIND_CAMPAIGN) {
                vafmd_err_set(e, VAFMD_E_STATE, "client_run_id", "client_run_id '%s' was used for a %s",
                              h->client_run_id, h->kind == VAFMD_RUN_TUNE ? "tune" : h->kind == VAFMD_RUN_REPLAY
                              ? "replay" : "curve");
                return NULL;
            }
            json_t *r = s_ok(c);
            json_object_set_new(r, "campaign_id", json_integer((json_int_t)h->campaign_id));
            json_object_set_new(r, "curves", json_integer((json_int_t)h->curves));
            json_object_set_new(r, "run_id", json_integer((json_int_t)h->run_id));
            json_object_set_new(r, "client_run_id", json_string(h->client_run_id));
            json_object_set_new(r, "duplicate", json_true());
            s_duplicate_state(d, r, h->run_id);
            return r;
        }
    }
    if (s_busy(d)) {
        vafmd_err_set(e, VAFMD_E_STATE, "cmd", "a run is in progress; abort it or wait for its end");
        return NULL;
    }
    vafmd_campaign *cp = calloc(1, sizeof *cp);
    size_t n[VAFM_CAMPAIGN_NAXES] = { 0 }, total_vals = 0;
    for (int l = 0; l < VAFM_CAMPAIGN_NAXES; l++)
        total_vals += n[l] = c->camp_list[l] ? json_array_size(c->camp_list[l]) : 0;
    if (!cp || !(cp->lists = malloc((total_vals + 1) * sizeof(double)))) {
        free(cp);
        vafmd_err_set(e, VAFMD_E_INTERNAL, "", "out of memory");
        return NULL;
    }
    double *lp = cp->lists;
    const double *lists[VAFM_CAMPAIGN_NAXES];
    for (int l = 0; l < VAFM_CAMPAIGN_NAXES; l++) {
        lists[l] = n[l] ? lp : NULL;
        for (size_t i = 0; i < n[l]; i++)
            *lp++ = json_number_value(json_array_get(c->camp_list[l], i));
    }
    cp->base = d->scene;
    if (c->kind == VAFMD_CMD_MAP) {
        /* a force map: a campaign whose grid is the pixels, each curve the pixel's scene (vafm_map_pixel) */
        cp->is_map = 1;
        cp->map = c->map;
        cp->lateral_speed_m_per_s = c->map_lateral_speed;
        vafm_error merr = { 0 };
        int mrc = vafm_map_validate(&cp->map, &cp->base, &merr);
        if (!mrc)
            mrc = vafm_map_campaign(&cp->map, &cp->spec);
        if (mrc) {
            vafmd_err_set(e, VAFMD_E_INVALID_SCENE, merr.field, "%s",
                          merr.message[0] ? merr.message : vafm_strerror(mrc));
            free(cp->lists);
            free(cp);
            return NULL;
        }
    }
    for (int l = 0; l < VAFM_CAMPAIGN_NAXES; l++) /* camp_list[l] is axis l's */
        vafm_campaign_axis_set(&cp->spec, l, lists[l], n[l]);
    cp->spec.curves_per_point = c->camp_n; /* a map: 1 */
    cp->spec.first_curve = c->camp_first;
    size_t points = vafm_campaign_points(&cp->spec);
    cp->total = c->camp_n * (uint64_t)points; /* ≤ 1e9 · 1e5: no overflow */
    /* every point's scene, as vafm campaign checks them before its first curve (vafm_campaign_validate);
     * with logging on, each point's curves must fit the writer */
    size_t bad = 0;
    vafm_error cverr = { 0 };
    int crc = vafm_campaign_validate(&cp->base, &cp->spec, &bad, &cverr);
    if (crc) {
        const char *field = !strcmp(cverr.field, "T_K") && n[0] ? vafm_campaign_axis_at(VAFM_CAMPAIGN_AXIS_T)->name
                            : strstr(cverr.field, "_m_per_s") && n[1] ? vafm_campaign_axis_at(VAFM_CAMPAIGN_AXIS_V)->name
                            : !strcmp(cverr.field, "k_N_per_m") && n[2] ? vafm_campaign_axis_at(VAFM_CAMPAIGN_AXIS_K)->name
                                                                        : cverr.field;
        vafmd_err_set(e, n[0] + n[1] + n[2] ? VAFMD_E_OUT_OF_RANGE : VAFMD_E_INVALID_SCENE, field, "%s",
                      cverr.message[0] ? cverr.message : vafm_strerror(crc));
        free(cp->lists);
        free(cp);
        return NULL;
    }
    for (size_t pt = 0; pt < points; pt++) {
        vafm_params pp;
        char where[64];
        vafm_campaign_point_params(&cp->base, &cp->spec, pt, &pp);
        snprintf(where, sizeof where, "grid point %zu", pt);
        if (s_log_fits(d, &pp, where, e)) {
            free(cp->lists);
            free(cp);
            return NULL;
        }
    }
    /* the first curve's simulation, built here so that an unstable scene is answered at once */
    size_t pt0 = (size_t)(c->camp_first / c->camp_n);
    vafm_params p0;
    vafm_campaign_point_params(&cp->base, &cp->spec, pt0, &p0);
    vafm_error verr = { 0 };
    int rc = vafm_sim_new(&cp->sim, &p0, &verr);
    if (rc) {
        vafmd_err_set(e, VAFMD_E_INVALID_SCENE, verr.field, "grid point %zu: cannot build the simulation: %s", pt0,
                      verr.message[0] ? verr.message : vafm_strerror(rc));
        free(cp->lists);
        free(cp);
        return NULL;
    }
    cp->sim_point = pt0;
    cp->campaign_id = d->next_campaign_id + 1;
    cp->next = c->camp_first;
    cp->first_run_id = d->next_run_id;
    cp->set = d->set;
    cp->log = atomic_load_explicit(&d->log.state, memory_order_acquire) == VAFMD_LOG_ON;
    /* the batch kernel: a free-run campaign's curves computed ahead, several at once (camp_feed.h); paced runs and
     * maps are computed by the simulation thread, curve by curve */
    if (cp->set.kernel == VAFMD_KERNEL_BATCH && cp->set.free_run && !cp->is_map &&
        (rc = vafmd_feed_start(&cp->feed, &cp->base, &cp->spec)) != 0) {
        vafmd_err_set(e, VAFMD_E_INTERNAL, "kernel", "cannot start the batch kernel's feeder: %s", vafm_strerror(rc));
        vafm_sim_destroy(&cp->sim);
        free(cp->lists);
        free(cp);
        return NULL;
    }
    snprintf(cp->client_run_id, sizeof cp->client_run_id, "%s", c->client_run_id);
    vafmd_sim_cmd sc;
    memset(&sc, 0, sizeof sc);
    sc.type = VAFMD_SIM_START;
    sc.kind = VAFMD_RUN_CURVE;
    sc.camp = cp;
    /* read before the push: from it on cp belongs to the simulation thread, which frees it at
     * campaign.end, possibly before this thread runs again (0.6.2 read cp->total after the push:
     * ThreadSanitizer, issue #29) */
    const uint64_t curves = cp->total - c->camp_first;
    if (!vafmd_ring_push(&d->ring, &sc)) {
        vafmd_feed_release(&cp->feed);
        vafm_sim_destroy(&cp->sim);
        free(cp->lists);
        free(cp);
        vafmd_err_set(e, VAFMD_E_BUSY, "", "the simulation thread does not take commands now; retry");
        return NULL;
    }
    d->next_campaign_id++;
    d->camp_total = curves + c->camp_first;
    d->camp_first = c->camp_first;
    d->camp_n = c->camp_n;
    d->pending_run_id = d->camp_run_id = d->next_run_id;
    uint64_t run_id = d->next_run_id;
    d->next_run_id += curves;
    d->runs_started++;
    d->jobs_started++;
    s_hist *h = s_history_add(c, run_id, S_KIND_CAMPAIGN);
    if (h) {
        h->campaign_id = d->next_campaign_id;
        h->curves = curves + c->camp_first;
    }
    json_t *r = s_ok(c);
    json_object_set_new(r, "campaign_id", json_integer((json_int_t)d->next_campaign_id));
    json_object_set_new(r, "curves", json_integer((json_int_t)(curves + c->camp_first)));
    json_object_set_new(r, "first_index", json_integer((json_int_t)c->camp_first));
    json_object_set_new(r, "run_id", json_integer((json_int_t)run_id));
    json_object_set_new(r, "client_run_id", c->client_run_id[0] ? json_string(c->client_run_id) : json_null());
    json_object_set_new(r, "duplicate", json_false());
    return r;
}

/* ---- the handlers of commands.def: one signature; *quit is set by `shutdown` ---------------------- */

static json_t *s_cmd_hello(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit, (void)e;
    return s_hello(d, c);
}

static json_t *s_cmd_get(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit;
    json_t *v = vafmd_live_get(d, c, e); /* vafmd_get_values and the controller's settings (live.c) */
    if (!v)
        return NULL;
    json_t *r = s_ok(c);
    json_object_update(r, v);
    json_decref(v);
    return r;
}

/* A command that changed (set: may have changed) the controller's state: into the log's journal with the
 * controller's time and generation after it (reply: its "ctrl"; else the status now) and the wall time. */
static void s_journal(vafmd *d, const vafmd_cmd *c, json_t *reply)
{
    if (atomic_load_explicit(&d->log.state, memory_order_acquire) != VAFMD_LOG_ON)
        return;
    json_t *args = json_deep_copy(c->root);
    json_object_del(args, "id");
    const char *name = json_string_value(json_object_get(c->root, "cmd"));
    json_object_del(args, "cmd");
    json_t *st = reply ? json_incref(json_object_get(reply, "ctrl")) : vafmd_live_status_json(d);
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    json_t *rec = json_pack("{s:s,s:o,s:O*,s:O*,s:O*,s:f}", "cmd", name ? name : "?", "args", args, "ctrl_time_s",
                            json_object_get(st, "time_s"), "generation", json_object_get(st, "generation"), "state",
                            json_object_get(st, "state"), "unix_time_s", (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec);
    json_decref(st);
    vafmd_log_journal(d, rec);
}

static json_t *s_cmd_set(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit;
    if (vafmd_live_set(d, c, e)) /* vafmd_apply_set and the controller's settings (live.c) */
        return NULL;
    s_journal(d, c, NULL);
    json_t *r = s_ok(c);
    json_object_set_new(r, "applies_to", json_string(s_busy(d) ? "next_run" : "now"));
    return r;
}

static json_t *s_cmd_presets(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)d, (void)quit, (void)e;
    return s_presets(c);
}

/* curve, tune and replay: one start each */
static json_t *s_cmd_start(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit;
    return s_start(d, c, e);
}

static json_t *s_cmd_abort(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit;
    if (!s_busy(d)) {
        vafmd_err_set(e, VAFMD_E_STATE, "cmd", "no run is in progress");
        return NULL;
    }
    vafmd_sim_cmd sc;
    memset(&sc, 0, sizeof sc);
    sc.type = VAFMD_SIM_ABORT;
    if (!vafmd_ring_push(&d->ring, &sc)) {
        vafmd_err_set(e, VAFMD_E_BUSY, "", "the simulation thread does not take commands now; retry");
        return NULL;
    }
    json_t *r = s_ok(c);
    int st = atomic_load(&d->sh.state);
    json_object_set_new(r, "run_id", json_integer((json_int_t)(st == VAFMD_RUNNING ? atomic_load(&d->sh.run_id)
                                                                               : d->pending_run_id)));
    return r;
}

static json_t *s_cmd_status(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit, (void)e;
    return s_status(d, c);
}

static json_t *s_cmd_log(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit;
    return s_log(d, c, e);
}

static json_t *s_cmd_shutdown(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)d, (void)e;
    *quit = 1;
    return s_ok(c);
}

/* campaign, and map: a campaign over the map's pixels */
static json_t *s_cmd_campaign(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit;
    return s_campaign(d, c, e);
}

static json_t *s_cmd_faults(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit;
    return s_faults_cmd(d, c, e);
}

/* engage, withdraw, move, z, feedback: the always-on controller (live.c) */
static json_t *s_cmd_ctrl(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit;
    json_t *r = vafmd_live_cmd(d, c, s_ok(c), e);
    if (r)
        s_journal(d, c, r);
    return r;
}

typedef json_t *s_handler(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e);

static s_handler *const s_handlers[VAFMD_CMD_N] = {
#define VAFMD_COMMAND(ID, NAME, KEYS, FLAGS, HANDLER, HELP) [VAFMD_CMD_##ID] = HANDLER,
#include "daemon/commands.def"
};

/* Execute one decoded command. *quit is set by `shutdown`. */
static json_t *s_execute(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    if (c->kind < 0 || c->kind >= VAFMD_CMD_N || !s_handlers[c->kind]) {
        vafmd_err_set(e, VAFMD_E_INTERNAL, "cmd", "command not handled");
        return NULL;
    }
    return s_handlers[c->kind](d, c, quit, e);
}

/* The command socket is a ROUTER that behaves as REP does for REQ (and DEALER) clients: a request is
 * [envelope..., empty delimiter, body...]; the reply goes back as [envelope..., empty, reply]. Being a
 * ROUTER, it can leave a request unanswered (the `no_reply` fault) and still serve every other request
 * and client: a REP socket must answer each request before it can receive the next. */
#define S_MAX_ENVELOPE 16

typedef struct s_request {
    zmq_msg_t env[S_MAX_ENVELOPE]; /* routing frames and the empty delimiter */
    int n_env;
    zmq_msg_t body;                /* the first body frame */
    int parts;                     /* body frames */
} s_request;

static void s_request_close(s_request *q)
{
    for (int i = 0; i < q->n_env; i++)
        zmq_msg_close(&q->env[i]);
    q->n_env = 0;
    zmq_msg_close(&q->body);
}

/* Receive one whole message. @return 1 a request, 0 nothing usable (dropped, as REP drops a message
 * without a delimiter), -1 the socket failed. */
static int s_request_recv(void *sock, s_request *q)
{
    q->n_env = 0;
    q->parts = 0;
    zmq_msg_init(&q->body);
    int delim = 0, more = 1, bad = 0;
    while (more) {
        zmq_msg_t m;
        zmq_msg_init(&m);
        if (zmq_msg_recv(&m, sock, 0) < 0) {
            zmq_msg_close(&m);
            if (errno == EINTR && (q->n_env || q->parts))
                continue;
            s_request_close(q);
            return errno == EINTR || errno == EAGAIN ? 0 : -1;
        }
        more = zmq_msg_more(&m);
        if (!delim) {
            if (q->n_env >= S_MAX_ENVELOPE) {
                bad = 1;
                zmq_msg_close(&m);
                continue;
            }
            delim = zmq_msg_size(&m) == 0 && q->n_env > 0;
            zmq_msg_init(&q->env[q->n_env]);
            zmq_msg_move(&q->env[q->n_env++], &m);
            zmq_msg_close(&m);
        } else if (q->parts++ == 0) {
            zmq_msg_move(&q->body, &m);
            zmq_msg_close(&m);
        } else
            zmq_msg_close(&m); /* further frames: counted, a "malformed" reply */
    }
    if (!delim || bad || !q->parts) {
        s_request_close(q);
        return 0;
    }
    return 1;
}

static void s_reply(void *sock, s_request *q, json_t *r)
{
    char *text = json_dumps(r, JSON_COMPACT);
    json_decref(r);
    if (!text)
        text = strdup("{\"status\":\"error\",\"code\":\"internal\",\"message\":\"reply encoding failed\","
                      "\"field\":null}");
    if (text) {
        for (int i = 0; i < q->n_env; i++) {
            zmq_msg_t m;
            zmq_msg_init(&m);
            zmq_msg_copy(&m, &q->env[i]);
            while (zmq_msg_send(&m, sock, ZMQ_SNDMORE) < 0 && errno == EINTR)
                ;
            zmq_msg_close(&m);
        }
        while (zmq_send(sock, text, strlen(text), 0) < 0 && errno == EINTR)
            ;
        free(text);
    }
}

int vafmd_control_loop(vafmd *d)
{
    int quit = 0;
    while (!quit && !*d->stop) {
        s_faults_poll(d);
        int fx = atomic_load_explicit(&d->sh.fault_exit, memory_order_acquire);
        if (fx) { /* a `kill` fault: stop as a shutdown does (the log is flushed and closed), with its status */
            d->exit_status = fx;
            fprintf(stderr, "vafmd: kill fault injected: exiting with status %d\n", fx);
            break;
        }
        zmq_pollitem_t it = { d->rep, 0, ZMQ_POLLIN, 0 };
        int n = zmq_poll(&it, 1, 50);
        if (n < 0) {
            if (errno == EINTR)
                continue;
            return 1;
        }
        if (n == 0 || !(it.revents & ZMQ_POLLIN))
            continue;
        s_request q;
        int got = s_request_recv(d->rep, &q);
        if (got < 0)
            return 1;
        if (!got)
            continue;
        vafmd_err e = { 0 };
        vafmd_cmd c;
        json_t *r = NULL;
        int fault = -1;
        vafmd_fault_rec fr;
        if (q.parts > 1)
            vafmd_err_set(&e, VAFMD_E_MALFORMED, "", "a request is one single-frame message (got %d frames)", q.parts);
        else {
            if (vafmd_cmd_decode(zmq_msg_data(&q.body), zmq_msg_size(&q.body), &c, &e) == 0) {
                fault = s_command_fault(d, &c, &fr);
                if (fault == VAFMD_F_BUSY) /* not executed: the client is told to retry */
                    vafmd_err_set(&e, VAFMD_E_BUSY, "", "the daemon is busy (injected fault); retry");
                else
                    r = s_execute(d, &c, &quit, &e);
            }
            if (!r)
                r = vafmd_error_reply(&e, c.id); /* the id of any request that was a JSON object */
            vafmd_cmd_free(&c);
        }
        if (!r)
            r = vafmd_error_reply(&e, NULL);
        if (fault == VAFMD_F_NO_REPLY) /* executed, its reply lost: the client must reopen its socket */
            json_decref(r);
        else {
            if (fault == VAFMD_F_REPLY_DELAY) /* the control thread may wait; the simulation thread never does */
                nanosleep(&(struct timespec){ (time_t)fr.p0, (long)((fr.p0 - floor(fr.p0)) * 1e9) }, NULL);
            s_reply(d->rep, &q, r);
        }
        s_request_close(&q);
        if (fault >= 0)
            s_fault_note(d, &fr);
    }
    return 0;
}
