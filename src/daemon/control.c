/* SPDX-License-Identifier: MIT */
/*
 * The control loop: one REP socket, one request at a time, every request answered exactly once.
 *
 * The control thread owns the scene and the settings. Starting a run builds (and so validates) the
 * simulation here, where an error can still be answered, then hands it to the simulation thread through
 * the SPSC ring. Whether a run is in progress is known without asking the simulation thread: runs
 * started here minus runs the simulation thread reports as done. Starting runs and campaigns is in
 * control_runs.c (control_int.h).
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
#include "daemon/control_int.h"


/* The handlers of commands.def share one signature; *quit is set by `shutdown` (below). */

static json_t *s_cmd_hello(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit, (void)e;
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
    json_object_set_new(r, "live", vafmd_live_hello_json()); /* the controller's topic (live_cmd.c) */
    return r;
}

static json_t *s_cmd_presets(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)d, (void)quit, (void)e;
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

static json_t *s_cmd_log(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit;
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

static json_t *s_cmd_status(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit, (void)e;
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
    json_object_set_new(r, "ctrl", vafmd_live_status_json(d)); /* the always-on controller (live_cmd.c) */
    return r;
}


/* ---- the other handlers of commands.def ----------------------------------------------------------- */

static json_t *s_cmd_get(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit;
    json_t *v = vafmd_live_get(d, c, e); /* vafmd_get_values and the controller's settings (live_cmd.c) */
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
    if (vafmd_live_set(d, c, e)) /* vafmd_apply_set and the controller's settings (live_cmd.c) */
        return NULL;
    s_journal(d, c, NULL);
    json_t *r = s_ok(c);
    json_object_set_new(r, "applies_to", json_string(s_busy(d) ? "next_run" : "now"));
    return r;
}

/* curve, tune and replay: one start each */
static json_t *s_cmd_start(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit;
    return vafmd_control_start(d, c, e);
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
    return vafmd_control_campaign(d, c, e);
}

static json_t *s_cmd_faults(vafmd *d, const vafmd_cmd *c, int *quit, vafmd_err *e)
{
    (void)quit;
    return s_faults_cmd(d, c, e);
}

/* engage, withdraw, move, z, feedback: the always-on controller (live_cmd.c) */
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
