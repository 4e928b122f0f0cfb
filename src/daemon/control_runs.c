/* SPDX-License-Identifier: MIT */
/*
 * Starting jobs from the control thread: curve, tune, replay and campaign (map). Each start is built (and so
 * validated) here, where an error can still be answered, then handed to the simulation thread through the
 * SPSC ring. A start that carries a client run id is remembered (s_history), so that a retry of it is
 * answered with the same run, not run again. Split out of control.c (issue #25); the loop is there.
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

json_t *vafmd_control_start(vafmd *d, const vafmd_cmd *c, vafmd_err *e)
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
    vafm_params p = d->scene;
    /* a curve or tune from the live state over a sample: the scene and the point under the tip (live_cmd.c) */
    json_t *at_tip = NULL;
    if (vafmd_live_curve_scene(d, &p, &at_tip, e) < 0)
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
    sc.start_json = vafmd_run_start_json(&p, &d->set, kind, run_id, sc.index, c->client_run_id, vafm_sim_dt(sim), NULL,
                                         at_tip);
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

/* A campaign not handed over: free it (its simulation and feeder are the caller's). */
static void s_camp_free(vafmd_campaign *cp)
{
    json_decref(cp->sample);
    free(cp->lists);
    free(cp);
}

/* A map from the live state: a `map` whose spec names no field of the sample maps the controller's
 * (ctrl_sample), its grid's fields given by the request over ctrl_sample's; run.start's "sample" says so.
 * @return 0 (cp->map set, cp->sample set or NULL) or -1 with e filled. */
static int s_camp_map_spec(vafmd *d, const vafmd_cmd *c, vafmd_campaign *cp, vafmd_err *e)
{
    const char *text = NULL;
    cp->map = c->map;
    int live = !c->map_own_sample && vafmd_live_sample(d, &cp->map, &text);
    if (live)
        vafmd_map_grid_merge(&cp->map, &c->map, c->map_grid_given);
    size_t pixels = vafm_map_pixels(&cp->map); /* the decoder checked first_index only against an own spec's */
    if (c->camp_first >= pixels) {
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "first_index", "\"first_index\" must be an integer in [0, %zu] (the "
                      "map's pixels, iy*nx + ix%s)", pixels ? pixels - 1 : 0, live ? ", over ctrl_sample" : "");
        return -1;
    }
    if (!live)
        return 0; /* the request's own spec, as before */
    char buf[4096];
    json_t *spec = vafm_map_to_json(&cp->map, buf, sizeof buf) > 0 ? json_loads(buf, 0, NULL) : NULL;
    if (!spec || !(cp->sample = json_pack("{s:s,s:o}", "ctrl_sample", text, "map", spec))) {
        vafmd_err_set(e, VAFMD_E_BUSY, "", "out of memory for the map's sample; retry");
        return -1;
    }
    return 0;
}

/* `campaign`: check the whole grid here (every point's scene, the first point's simulation), where an
 * error can still be answered; the simulation thread then runs the curves one after the other. */
json_t *vafmd_control_campaign(vafmd *d, const vafmd_cmd *c, vafmd_err *e)
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
    /* a campaign from the live state over a sample: all its curves over the material under the tip (as a
     * curve's), each run.start naming the point; a map: the controller's sample, if it gives none */
    if (c->kind != VAFMD_CMD_MAP ? vafmd_live_curve_scene(d, &cp->base, &cp->sample, e) < 0
                                 : s_camp_map_spec(d, c, cp, e) < 0) {
        s_camp_free(cp);
        return NULL;
    }
    if (c->kind == VAFMD_CMD_MAP) {
        /* a force map: a campaign whose grid is the pixels, each curve the pixel's scene (vafm_map_pixel) */
        cp->is_map = 1;
        cp->lateral_speed_m_per_s = c->map_lateral_speed;
        vafm_error merr = { 0 };
        int mrc = vafm_map_validate(&cp->map, &cp->base, &merr);
        if (!mrc)
            mrc = vafm_map_campaign(&cp->map, &cp->spec);
        if (mrc) {
            vafmd_err_set(e, VAFMD_E_INVALID_SCENE, merr.field, "%s",
                          merr.message[0] ? merr.message : vafm_strerror(mrc));
            s_camp_free(cp);
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
        s_camp_free(cp);
        return NULL;
    }
    for (size_t pt = 0; pt < points; pt++) {
        vafm_params pp;
        char where[64];
        vafm_campaign_point_params(&cp->base, &cp->spec, pt, &pp);
        snprintf(where, sizeof where, "grid point %zu", pt);
        if (s_log_fits(d, &pp, where, e)) {
            s_camp_free(cp);
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
        s_camp_free(cp);
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
        s_camp_free(cp);
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
        s_camp_free(cp);
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
