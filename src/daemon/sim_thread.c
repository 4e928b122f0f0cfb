/* SPDX-License-Identifier: MIT */
/*
 * The simulation thread's loop (design: sim_thread.h): commands from the ring, a run's start and end, the
 * computation of blocks into the compute-ahead FIFO in pieces, and a campaign's curves one after the other.
 */
#include "daemon/sim_thread.h"
#include "vafm/segments.h"
#ifdef __linux__
#include <sys/prctl.h>
#endif

#define S_PIECE_NS 500000LL /* compute at most this long (plus one piece) before releasing or polling */
/* a piece of computation bounds how long a due block can wait for its release: ~20 µs of work, sized
 * from the measured cost per sample and capped in integrator steps (with pieces of 1/16 block the
 * release lateness was p99 ~0.2–0.4 ms for paper-fig4 curves, 0.9 ms for the default scene at 2 kS/s) */
#define S_PIECE_TARGET_NS 20000.0
#define S_PIECE_STEPS 512 /* integrator steps a piece at most (~18 µs at ~35 ns a step in contact) */


static int s_sink(void *user, const vafm_samples *b)
{
    vafmd_st_run *r = user;
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
                r->ch[c][k] = vafm_channels[c].kind == VAFM_CHK_MEASURED  ? m[c]
                              : vafm_channels[c].kind == VAFM_CHK_SEGMENT ? (double)b->segment[i]
                                                                          : vafm_channel_samples(b, c)[i];
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
            if (r->n_ev < VAFMD_ST_MAX_EVENTS)
                r->ev[r->n_ev++] = (vafmd_st_event){ b->first + i, r->prev_seg, seg };
        }
        r->prev_seg = seg;
    }
    r->fill += b->n;
    return 0;
}

/* A fed curve's next samples, up to max: as vafm_sim_advance hands a computed curve's over, ending with its
 * status together with its last sample. */
static int s_feed_advance(vafmd_st_run *r, size_t max)
{
    const vafmd_feed_curve *c = r->cmd.feed;
    size_t m = c->n - r->feed_pos < max ? c->n - r->feed_pos : max;
    if (m > 0) {
        const size_t i = r->feed_pos;
        vafm_samples b = vafm_channels_slice(&c->samples, i, m);
        if (s_sink(r, &b))
            return VAFM_EABORT;
        r->feed_pos += m;
    }
    if (r->feed_pos < c->n)
        return 1;
    return c->status;
}

/* The curve result of a run: its simulation's, or the fed curve's. */
static int s_run_result(const vafmd_st_run *r, vafm_curve_result *res)
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
static int s_advance(vafmd_st_run *r, size_t max)
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

static void s_run_free(vafmd_st_run *r, vafmd_shared *sh)
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
    free(r->cmd.segs);
    r->cmd.segs = NULL;
    vafmd_replay_free(&r->cmd.replay);
    vafmd_feed_curve_free(&r->cmd.feed); /* between curves, as the campaign's simulations are built */
    for (int i = 0; i < VAFM_CH_COUNT; i++)
        r->ch[i] = NULL; /* pointed into qstore */
    r->active = 0;
}

static void s_camp_end(vafmd_st *x, const char *status, const char *message, int mark_done);
static int s_queue_alloc(vafmd_st *x, unsigned chmask, double fs);

static json_t *s_num_or_null(double v)
{
    return isfinite(v) ? json_real(v) : json_null();
}


/* Report the run as done and publish its run.end. The daemon turns idle (a new run is accepted) BEFORE
 * run.end goes out, so a client may start the next run as soon as it sees run.end. A campaign's curve
 * ends the job only if it is the campaign's last (or failed): then campaign.end follows run.end. */
static void s_run_end(vafmd_st *x, const char *status, int err_code)
{
    vafmd_st_run *r = &x->run;
    vafmd_shared *sh = &x->d->sh;
    int silent = r->fault_silent; /* truncate/kill: no run.end, not logged (faults.md) */
    const uint64_t run_id = r->cmd.run_id; /* for after s_run_free */
    if (r->drop_left) { /* a drop fault that outlasted the run: record the blocks it did drop */
        r->drop_rec.p0 -= (double)r->drop_left;
        r->drop_left = 0;
        if (r->drop_rec.p0 > 0)
            vafmd_st_fault_record(x, &r->drop_rec);
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
                                             (json_int_t)vafmd_st_rel_quantile(r, 0.5), "p99",
                                             (json_int_t)vafmd_st_rel_quantile(r, 0.99), "max", (json_int_t)r->rel_max_ns)
                                 : json_null());
    json_object_set_new(j, "dropped", json_integer((json_int_t)(atomic_load(&sh->dropped) - r->dropped_at_start)));
    json_object_set_new(j, "wall_s", json_real((double)(vafmd_st_now() - r->t_start) / 1e9));
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
                vafmd_st_send_json(x, "event", json_pack("{s:I,s:s,s:o,s:o,s:o,s:o}", "run_id", (json_int_t)r->cmd.run_id,
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
        if (!vafmd_st_log_push(r, VAFMD_LOG_END, le)) {
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
            vafmd_st_send_text(x, "run.end", text);
        free(text);
    }
    if (log_lost)
        vafmd_st_send_json(x, "event", json_pack("{s:I,s:s}", "run_id", (json_int_t)run_id, "kind", "log_failed"));
    if (cp && job_over)
        s_camp_end(x, ok ? "ok" : failed ? "error" : "aborted", failed ? msg : NULL, 0);
}

/* Publish campaign.end and free the campaign. mark_done: the job is not yet reported done (no curve
 * of it was running). */
static void s_camp_end(vafmd_st *x, const char *status, const char *message, int mark_done)
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
    vafmd_st_send_json(x, "campaign.end", j);
    vafmd_feed_release(&cp->feed);
    vafm_sim_destroy(&cp->sim);
    json_decref(cp->sample);
    free(cp->lists);
    free(cp);
}

/* run.start's "ctrl" and "sample" (a curve taken over ctrl_sample) as one compact JSON object into buf ("" if
 * neither, or {"truncated": true} if it does not fit), for the log's "vafm ctrl" (log.c). */
static void s_log_ctrl(char *buf, size_t len, const char *start_json)
{
    buf[0] = 0;
    json_t *j = start_json ? json_loads(start_json, 0, NULL) : NULL, *o = json_object();
    json_t *ctrl = j ? json_object_get(j, "ctrl") : NULL, *smp = j ? json_object_get(j, "sample") : NULL;
    if (ctrl && !json_is_null(ctrl))
        json_object_set(o, "ctrl", ctrl);
    if (smp)
        json_object_set(o, "sample", smp);
    char *t = json_object_size(o) ? json_dumps(o, JSON_COMPACT) : NULL;
    if (t)
        snprintf(buf, len, "%s", strlen(t) < len ? t : "{\"truncated\":true}");
    free(t);
    json_decref(o);
    json_decref(j);
}

static void s_run_start(vafmd_st *x, const vafmd_sim_cmd *c)
{
    vafmd_st_run *r = &x->run;
    vafmd_shared *sh = &x->d->sh;
    memset(r, 0, sizeof *r);
    r->cmd = *c;
    r->prev_seg = -1;
    if (__builtin_expect(x->fp != NULL, 0))
        vafmd_st_fault_run_begin(x);
    r->t_start = vafmd_st_now();
    const vafm_params *p = c->replay ? NULL : vafm_sim_params(c->sim); /* a replay has no scene */
    r->block_n = vafmd_block_samples(p ? p->sample_rate_Hz : vafmd_replay_rate_Hz(c->replay), c->set.block_s);
    r->sens = p ? p->sensitivity_m_per_V : NAN; /* a replay sets its file's */
    r->first_seq = atomic_load_explicit(&sh->seq, memory_order_relaxed);
    r->dropped_at_start = atomic_load(&sh->dropped);
    r->active = 1;
    vafmd_st_pool_prepare(x, c->log && c->kind == VAFMD_RUN_CURVE, r->block_n);
    vafmd_live_run_start(x->d, &r->cmd.start_json); /* + "ctrl": the controller's state, held during the run */
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
            s_log_ctrl(lb->ctrl, sizeof lb->ctrl, r->cmd.start_json);
            if (c->segs && c->nseg <= VAFM_SEGMENTS_MAX) { /* the curve's list goes into the file with it */
                memcpy(lb->segs, c->segs, c->nseg * sizeof *lb->segs);
                lb->nseg = c->nseg;
            }
            if (c->camp && c->camp->is_map) { /* the file gets the pixel's map attributes */
                lb->is_map = 1;
                lb->map = c->camp->map;
                vafm_map_pixel(&c->camp->map, &c->camp->base, (int)(c->index % (uint64_t)c->camp->map.nx),
                               (int)(c->index / (uint64_t)c->camp->map.nx), NULL, &lb->pixel, NULL);
            }
        }
        if (c->set.free_run) /* loses nothing: waits for room (a campaign's curve has it already) */
            vafmd_st_log_wait_room(x);
        vafmd_st_log_push(r, VAFMD_LOG_BEGIN, lb);
    }
    atomic_store_explicit(&sh->run_id, c->run_id, memory_order_relaxed);
    atomic_store_explicit(&sh->run_samples, 0, memory_order_relaxed);
    atomic_store_explicit(&sh->state, VAFMD_RUNNING, memory_order_relaxed);
    vafmd_st_send_text(x, "run.start", r->cmd.start_json);
    unsigned chmask = c->replay ? vafmd_replay_channels(c->replay) : vafmd_live_channels(p, &c->set);
    r->src_rc = 1;
    vafmd_st_stream_bound(x, chmask, r->block_n, c->set.hwm);
    int rc = s_queue_alloc(x, chmask, p ? p->sample_rate_Hz : vafmd_replay_rate_Hz(c->replay));
    if (!rc && !c->replay)
    {
        if (!rc && !c->replay && c->kind == VAFMD_RUN_CURVE) /* a trigger that never fires: decided per curve */
            vafm_sim_set_trigger(c->sim, !vafmd_st_no_trigger_due(x));
        rc = c->kind == VAFMD_RUN_TUNE ? vafm_sim_tune_begin(c->sim, c->index)
             : c->segs                 ? vafm_sim_segments_begin(c->sim, c->index, c->segs, c->nseg)
                                       : vafm_sim_curve_begin(c->sim, c->index);
    }
    /* the clock of the run starts when its first sample can be computed: setting up the scene (tables,
     * first contact solve) is not acquisition time */
    r->t_start = vafmd_st_now();
    if (rc)
        s_run_end(x, "error", rc);
}

/* The compute-ahead FIFO of a run: 1 + ceil(lookahead_s · fs / block_n) slots (1, i.e. no lookahead:
 * compute a block, wait for its deadline, release it), fewer if the slots, their channel arrays and (a
 * logged run) their staged log times and segments would pass VAFMD_LOOKAHEAD_MAX_BYTES; at least 1. Free
 * run: 1 (blocks go out as soon as they are computed). */
static int s_queue_alloc(vafmd_st *x, unsigned chmask, double fs)
{
    vafmd_st_run *r = &x->run;
    const size_t nch = vafmd_st_channels(chmask);
    size_t nlog = r->log ? 1 : 0; /* a logged run stages its samples' times (a double) and segments (a byte) */
    double per = (double)sizeof(vafmd_st_block) + (double)(nch * r->block_n * sizeof(double)) +
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

double vafmd_st_run_fs(const vafmd_st_run *r)
{
    return r->cmd.replay ? vafmd_replay_rate_Hz(r->cmd.replay) : vafm_sim_params(r->cmd.sim)->sample_rate_Hz;
}

/* The FIFO is far enough ahead that idling until the head's release costs no lateness later: at least
 * half full. (Not "its last block is due ≥ 50 ms from now": that idled up to a piece per block all
 * through the default scene's near zone, where compute is scarcest, and made 2 kS/s late: 127 late
 * blocks, worst 0.4 s.) */
static int s_fifo_ahead(const vafmd_st_run *r)
{
    return 2 * r->qn >= r->qcap;
}

/* Compute into the FIFO's free slot: from its start or where the last call stopped, until the block is
 * full or the run ends, or S_PIECE_NS of work has passed, or the head block falls due (then the loop
 * releases it and comes back). A complete block is queued with its deadline. */
static void s_compute(vafmd_st *x)
{
    vafmd_st_run *r = &x->run;
    vafmd_st_block *b = &r->q[(r->qhead + r->qn) % r->qcap];
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
    int64_t t0 = vafmd_st_now(), t = t0, due = r->qn ? r->q[r->qhead].deadline : INT64_MAX;
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
        int64_t t1 = vafmd_st_now();
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
        vafmd_st_fault_compute(x, b, r->block_index + r->qn);
    b->first_seg = r->first_seg;
    b->n_ev = r->n_ev;
    memcpy(b->ev, r->ev, (size_t)r->n_ev * sizeof *r->ev);
    /* replay: the curves of the selection that began in this block */
    b->n_rev = r->cmd.replay ? vafmd_replay_take_events(r->cmd.replay, b->rev, VAFMD_REPLAY_MAX_EVENTS) : 0;
    uint64_t end = r->computed + r->fill;
    /* a replay is paced by its recorded times (replay.c), a simulation by the simulated time at the end of
     * the block's last sample: its sample index at the scene's rate; a segment list's clock in samples of
     * the scene's rate (a segment decimated by d spans d of them a sample: counting its output samples
     * released it d times too fast) */
    double t_end = r->cmd.replay ? vafmd_replay_clock_s(r->cmd.replay)
                   : r->cmd.segs ? (double)vafm_sim_clock_samples(r->cmd.sim) / vafmd_st_run_fs(r)
                                 : (double)end / vafmd_st_run_fs(r);
    b->deadline = r->t_start + (int64_t)llround(t_end / r->cmd.set.speed * 1e9);
    b->ready = vafmd_st_now();
    r->computed = end;
    r->qn++;
    atomic_store_explicit(&x->d->sh.queued, r->qn, memory_order_relaxed);
}

/* One step of a run: release the due blocks; end the run once its last block is out; else compute a
 * piece if the FIFO has room; else sleep until the head is due (at most 1 ms: the command ring, the
 * heartbeat and new subscribers are looked at between steps). */
static void s_run_step(vafmd_st *x)
{
    vafmd_st_run *r = &x->run;
    int64_t now = vafmd_st_now();
    if (__builtin_expect(x->fp != NULL, 0) && r->hold_until) { /* late/jitter: the stream is held */
        if (now < r->hold_until) {
            vafmd_st_sleep_until(r->hold_until < now + 1000000 ? r->hold_until : now + 1000000);
            return;
        }
        r->hold_until = 0;
    }
    while (r->qn > 0 && (r->cmd.set.free_run || now >= r->q[r->qhead].deadline)) {
        if (r->cmd.set.free_run && r->log && !r->log_broken && !vafmd_st_log_ready(x)) {
            vafmd_st_sleep_until(now + 100000); /* the writer is behind: wait for it (free run loses nothing) */
            return;
        }
        if (__builtin_expect(x->fp != NULL, 0)) {
            vafmd_fault_rec end;
            int a = vafmd_st_fault_release(x, now, &end);
            if (a == VAFMD_ST_FA_END) { /* truncate, kill: the run ends silently, then the fault's record */
                s_run_end(x, "ok", 0);
                vafmd_st_fault_record(x, &end);
                if (end.kind == VAFMD_F_KILL) {
                    x->dead = 1;
                    atomic_store_explicit(&x->d->sh.fault_exit, (int)end.p0, memory_order_release);
                }
            }
            if (a != VAFMD_ST_FA_RELEASE)
                return; /* held (late, jitter, stall) or over (truncate, kill) */
        }
        vafmd_st_release(x, now);
        now = vafmd_st_now();
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
    vafmd_st_sleep_until(t < now + 1000000 ? t : now + 1000000);
}

/* Start the campaign's next curve (global index cp->next) on this thread, without the control thread.
 * Building the simulation of a new grid point happens here, between two curves (it allocates and
 * tabulates: not in the paced per-block path); the N curves of a point reuse it, each from its own
 * random stream, exactly as vafm_campaign_run does. */
static void s_camp_next(vafmd_st *x)
{
    vafmd_campaign *cp = x->camp;
    vafmd_shared *sh = &x->d->sh;
    uint64_t g = cp->next, first = cp->spec.first_curve;
    size_t point = (size_t)(g / cp->spec.curves_per_point);
    if (cp->log && cp->set.free_run && !vafmd_st_log_room(x, 2))
        return; /* free run: the next curve's begin waits for the writer (the loop looks again within 1 ms) */
    if (cp->is_map && g != first && !cp->set.free_run) {
        /* the lateral move from the last pixel to this one takes instrument time (paced: at the speed factor) */
        int64_t now = vafmd_st_now();
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
                                        vafm_sim_dt(cp->sim), cj, cp->sample); /* from the live state: the point
                                                                                 * under the tip, or the map's sample */
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

void *vafmd_sim_main(void *arg)
{
    vafmd_st *x = calloc(1, sizeof *x);
    if (!x)
        return NULL;
    x->d = arg;
    x->nodrop = -1;
    x->t_boot = vafmd_st_now();
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
            int64_t now = vafmd_st_now();
            /* a shutdown (command or signal) ends the stall: shutdown flushes within its 0.5 s, a stall
             * of up to 60 s made SIGTERM wait it out (0.6.1) */
            const int quitting = atomic_load_explicit(&x->d->quitting, memory_order_acquire) || *x->d->stop;
            if (now < x->stall_until && !quitting) {
                vafmd_st_sleep_until(x->stall_until < now + 1000000 ? x->stall_until : now + 1000000);
                continue;
            }
            x->stall_until = 0;
            vafmd_st_fault_record(x, &x->stall_rec);
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
                vafmd_st_fault_record(x, &c.fault);
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
        vafmd_st_log_notices(x);
        vafmd_st_subscriptions(x);
        int64_t now = vafmd_st_now();
        if (now >= next_hb) {
            vafmd_st_heartbeat(x, now);
            next_hb += VAFMD_ST_NS;
            if (next_hb < now) /* after a long stall: keep the 1 Hz grid, skip the missed beats */
                next_hb = now + VAFMD_ST_NS - (now - next_hb) % VAFMD_ST_NS;
        }
        if (!x->run.active && x->camp && !x->dead) /* a campaign goes on by itself */
            s_camp_next(x);
        if (x->run.active)
            s_run_step(x);
        else /* idle: the live controller (live.c), then look at the ring every millisecond */
            vafmd_st_sleep_until(vafmd_live_idle(x->d, now, x->dead));
    }
    vafmd_live_sim_exit(x->d);
    /* the pools: free those whose blocks are all home, leave the others to the writer thread */
    vafmd_st_pool_reclaim(L);
    vafmd_st_pool_retire(x);
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
