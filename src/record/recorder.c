/* SPDX-License-Identifier: MIT */
/*
 * The recorder (record/record.h): one HDF5 writer behind a mutex, and, with a flush interval, a flusher
 * thread.
 *
 * Why a flusher thread: a flush rewrites the file's metadata; flushing after every curve cost 7.7% of a
 * paper-fig4 campaign's wall time, so a campaign flushes by time instead, `interval` seconds after the
 * previous flush whenever curves wait. A curve never waits longer than that, even when the next one is
 * slow to come, and the close flushes the rest. One mutex serialises every call into the writer: the
 * HDF5 library is not thread-safe. Interval 0 (the daemon's log, `vafm listen`) flushes inside append.
 */
#include <inttypes.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "record/record.h"

struct vafm_recorder {
    vafm_h5_writer *w;
    pthread_mutex_t mu;   /* the writer and every field below */
    pthread_cond_t wake;  /* the flusher: curves pending, or stop */
    pthread_t flusher;
    int has_flusher;
    double interval;      /* seconds between flushes; 0: flush in append */
    double last_flush;    /* s_now() at the end of the last flush */
    uint64_t pending;     /* curves appended since */
    int stop;             /* the flusher ends */
    int has_prov;         /* provenance recorded (or compared) */
    int list;             /* the curves run a segment list (opts.segments_json) */
    int werr_code;        /* the first writer error (sticky) */
    vafm_error werr;
    void (*on_durable)(void *, uint64_t);
    void *user;
    vafm_recorder_report rep;
};

static double s_now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static void s_err_copy(vafm_error *dst, const vafm_error *src)
{
    if (dst && src)
        *dst = *src;
}

void vafm_recorder_opts_default(vafm_recorder_opts *o)
{
    memset(o, 0, sizeof *o);
    o->mode = VAFM_RECORD_CREATE;
}

void vafm_record_ids(uint64_t seed, uint64_t index, uint64_t run_id, const char *client, char *session,
                     size_t session_len, char *curve, size_t curve_len)
{
    if (session && session_len)
        snprintf(session, session_len, "seed %" PRIu64, seed);
    if (!curve || !curve_len)
        return;
    char run[32] = "";
    if (run_id)
        snprintf(run, sizeof run, "run %" PRIu64 " ", run_id);
    int has_client = client && client[0];
    snprintf(curve, curve_len, "%sindex %" PRIu64 "%s%s", run, index, has_client ? " client " : "",
             has_client ? client : "");
}

/* With the lock held. */
static void s_set_werr(vafm_recorder *r, int code, const vafm_error *e)
{
    if (!r->werr_code) {
        r->werr_code = code;
        r->werr = *e;
    }
}

/* With the lock held. */
static int s_flush_locked(vafm_recorder *r)
{
    vafm_error e;
    memset(&e, 0, sizeof e);
    double t0 = s_now();
    int rc = vafm_h5_writer_flush(r->w, &e);
    double t1 = s_now();
    r->rep.writer_s += t1 - t0;
    r->last_flush = t1;
    r->rep.flushes++;
    if (rc) {
        s_set_werr(r, rc, &e);
        return rc;
    }
    r->pending = 0;
    if (r->on_durable)
        r->on_durable(r->user, vafm_h5_writer_count(r->w));
    return 0;
}

static void *s_flusher(void *arg)
{
    vafm_recorder *r = arg;
    pthread_mutex_lock(&r->mu);
    while (!r->stop) {
        if (!r->pending || r->werr_code) {
            pthread_cond_wait(&r->wake, &r->mu);
            continue;
        }
        double due = r->last_flush + r->interval;
        if (s_now() >= due) {
            s_flush_locked(r);
            continue;
        }
        struct timespec ts;
        ts.tv_sec = (time_t)due;
        ts.tv_nsec = (long)((due - (double)ts.tv_sec) * 1e9);
        pthread_cond_timedwait(&r->wake, &r->mu, &ts);
    }
    pthread_mutex_unlock(&r->mu);
    return NULL;
}

static int s_start_flusher(vafm_recorder *r)
{
    pthread_condattr_t ca;
    if (pthread_condattr_init(&ca))
        return -1;
    pthread_condattr_setclock(&ca, CLOCK_MONOTONIC); /* the deadlines are s_now() times */
    int rc = pthread_cond_init(&r->wake, &ca);
    pthread_condattr_destroy(&ca);
    if (rc)
        return -1;
    if (pthread_create(&r->flusher, NULL, s_flusher, r)) {
        pthread_cond_destroy(&r->wake);
        return -1;
    }
    r->has_flusher = 1;
    return 0;
}

int vafm_recorder_open(vafm_recorder **out, const char *path, const vafm_recorder_opts *opts,
                       const vafm_params *scene, const vafm_campaign_spec *grid, vafm_error *err)
{
    vafm_recorder_opts o;
    if (opts)
        o = *opts;
    else
        vafm_recorder_opts_default(&o);
    if (!out) {
        if (err) {
            memset(err, 0, sizeof *err);
            err->code = VAFM_EINVAL;
            snprintf(err->message, sizeof err->message, "vafm_recorder_open: out is NULL");
        }
        return VAFM_EINVAL;
    }
    *out = NULL;
    if (o.mode < VAFM_RECORD_CREATE || o.mode > VAFM_RECORD_OVERWRITE || o.gzip_level < 0 || o.gzip_level > 9 ||
        !(o.flush_interval_s >= 0.0 && o.flush_interval_s <= VAFM_RECORD_MAX_FLUSH_INTERVAL_S)) {
        if (err) {
            memset(err, 0, sizeof *err);
            err->code = VAFM_EINVAL;
            const char *f = o.mode < VAFM_RECORD_CREATE || o.mode > VAFM_RECORD_OVERWRITE ? "mode"
                            : o.gzip_level < 0 || o.gzip_level > 9                          ? "gzip_level"
                                                                                             : "flush_interval_s";
            snprintf(err->field, sizeof err->field, "%s", f);
            snprintf(err->message, sizeof err->message,
                     "recorder option %s out of range (mode 0-2, gzip_level 0-9, flush_interval_s [0, %g] s)", f,
                     VAFM_RECORD_MAX_FLUSH_INTERVAL_S);
        }
        return VAFM_EINVAL;
    }
    vafm_recorder *r = calloc(1, sizeof *r);
    if (!r)
        return VAFM_ENOMEM;
    r->interval = o.flush_interval_s;
    r->on_durable = o.on_durable;
    r->user = o.user;
    vafm_h5_writer_opts wo;
    vafm_h5_writer_opts_default(&wo);
    wo.resume = o.mode == VAFM_RECORD_RESUME;
    wo.overwrite = o.mode == VAFM_RECORD_OVERWRITE;
    wo.gzip_level = o.gzip_level;
    wo.keep_intact = o.keep_intact;
    double t0 = s_now();
    /* a resume that would be refused (another scene or grid) is refused before a byte of the file changes */
    int rc = scene ? vafm_h5_provenance_check(scene, grid, err) : 0; /* before any file is touched */
    if (!rc && wo.resume && scene)
        rc = vafm_h5_resume_check_segments(path, scene, grid, o.segments_json, err);
    if (!rc)
        rc = vafm_h5_writer_open(&r->w, path, &wo, err);
    if (!rc && o.segments_json)
        rc = vafm_h5_writer_set_segments(r->w, o.segments_json, err);
    r->list = o.segments_json != NULL;
    if (!rc && scene) {
        rc = vafm_h5_writer_set_provenance(r->w, scene, grid, err);
        r->has_prov = !rc;
    }
    r->rep.writer_s = s_now() - t0;
    if (rc) {
        vafm_h5_writer_destroy(&r->w);
        free(r);
        return rc;
    }
    r->rep.kept = vafm_h5_writer_count(r->w);
    r->last_flush = s_now();
    if (pthread_mutex_init(&r->mu, NULL) || (r->interval > 0 && s_start_flusher(r))) {
        vafm_h5_writer_destroy(&r->w);
        free(r);
        if (err) {
            memset(err, 0, sizeof *err);
            err->code = VAFM_ENOMEM;
            snprintf(err->message, sizeof err->message, "%s: cannot start the recorder's flusher thread", path);
        }
        return VAFM_ENOMEM;
    }
    *out = r;
    return 0;
}

int vafm_recorder_append(vafm_recorder *r, const vafm_record_curve *c, vafm_error *err)
{
    if (!r || !c || !c->samples || !c->params || !c->result)
        return VAFM_EINVAL;
    vafm_h5_curve hc;
    vafm_h5_curve_from_sim(&hc, c->samples, c->params, c->result);
    if (c->measured_force)
        hc.tip_position_m = NULL;
    if (r->list && c->segments_json) {
        if (err) {
            memset(err, 0, sizeof *err);
            err->code = VAFM_EINVAL;
            snprintf(err->field, sizeof err->field, "segments");
            snprintf(err->message, sizeof err->message, "the file's curves all run one list (format 1.2): a curve "
                     "cannot bring its own");
        }
        return VAFM_EINVAL;
    }
    if (r->list || c->segments_json) { /* a segment list's curve: its count is the list's, its segments' rates and
                                          speeds are the list's */
        hc.meta.segment_count = -1;
        hc.meta.setpoint_N = hc.meta.rate_approach_Hz = hc.meta.rate_retract_Hz = NAN;
        hc.meta.speed_approach_m_per_s = hc.meta.speed_retract_m_per_s = NAN;
        hc.meta.duration_approach_s = hc.meta.duration_retract_s = NAN;
    }
    if (!isnan(c->sensitivity_m_per_V))
        hc.meta.sensitivity_m_per_V = c->sensitivity_m_per_V;
    char sid[48], cid[200];
    vafm_record_ids(c->params->seed, c->result->index, c->run_id, c->client_run_id, sid, sizeof sid, cid,
                    sizeof cid);
    hc.meta.session_id = sid;
    hc.meta.curve_id = cid;
    if (c->map && c->pixel) { /* afmformats' map attributes */
        hc.meta.grid_shape_x = c->map->nx;
        hc.meta.grid_shape_y = c->map->ny;
        hc.meta.grid_index_x = c->pixel->ix;
        hc.meta.grid_index_y = c->pixel->iy;
        hc.meta.grid_center_x_m = c->map->center_x_m;
        hc.meta.grid_center_y_m = c->map->center_y_m;
        hc.meta.grid_size_x_m = c->map->size_x_m;
        hc.meta.grid_size_y_m = c->map->size_y_m;
        hc.meta.position_x_m = c->pixel->x_m;
        hc.meta.position_y_m = c->pixel->y_m;
    }
    vafm_h5_truth t;
    vafm_h5_truth_from_sim(&t, c->point, c->params, c->result);
    vafm_error e;
    memset(&e, 0, sizeof e);
    pthread_mutex_lock(&r->mu);
    int rc = r->werr_code;
    if (rc) {
        s_err_copy(err, &r->werr);
        pthread_mutex_unlock(&r->mu);
        return rc;
    }
    double t0 = s_now();
    if (!r->has_prov) { /* the file's provenance: the scene of its first curve */
        if ((rc = vafm_h5_writer_set_provenance(r->w, c->params, NULL, &e)) == 0)
            r->has_prov = 1;
    }
    t.result.index = vafm_h5_writer_count(r->w); /* the group number; the stream index is in the curve id */
    if (!rc && c->segments_json) /* the curve's own list (format 1.3), for this append only */
        rc = vafm_h5_writer_set_curve_segments(r->w, c->segments_json, &e);
    if (!rc)
        rc = vafm_h5_writer_append(r->w, &hc, &t, &e);
    r->rep.writer_s += s_now() - t0;
    if (rc == VAFM_EIO || rc == VAFM_ENOMEM)
        s_set_werr(r, rc, &e); /* the file's state is unknown: nothing more goes in */
    if (!rc) {
        r->rep.appended++;
        if (r->interval <= 0)
            rc = s_flush_locked(r) ? r->werr_code : 0;
        else if (r->pending++ == 0)
            pthread_cond_signal(&r->wake);
        if (rc)
            e = r->werr;
    }
    pthread_mutex_unlock(&r->mu);
    if (rc)
        s_err_copy(err, &e);
    return rc;
}

int vafm_recorder_flush(vafm_recorder *r, vafm_error *err)
{
    if (!r)
        return VAFM_EINVAL;
    pthread_mutex_lock(&r->mu);
    int rc = r->werr_code ? r->werr_code : s_flush_locked(r);
    if (rc)
        s_err_copy(err, &r->werr);
    pthread_mutex_unlock(&r->mu);
    return rc;
}

int vafm_recorder_set_note(vafm_recorder *r, const char *name, const char *text, vafm_error *err)
{
    if (!r)
        return VAFM_EINVAL;
    pthread_mutex_lock(&r->mu);
    int rc = vafm_h5_writer_set_note(r->w, name, text, err);
    pthread_mutex_unlock(&r->mu);
    return rc;
}

uint64_t vafm_recorder_count(vafm_recorder *r)
{
    if (!r)
        return 0;
    pthread_mutex_lock(&r->mu);
    uint64_t n = vafm_h5_writer_count(r->w);
    pthread_mutex_unlock(&r->mu);
    return n;
}

int vafm_recorder_truth(vafm_recorder *r, uint64_t i, vafm_h5_truth *out)
{
    if (!r)
        return VAFM_EINVAL;
    pthread_mutex_lock(&r->mu);
    int rc = vafm_h5_writer_truth(r->w, i, out);
    pthread_mutex_unlock(&r->mu);
    return rc;
}

void vafm_recorder_report_get(vafm_recorder *r, vafm_recorder_report *out)
{
    if (!r || !out)
        return;
    pthread_mutex_lock(&r->mu);
    *out = r->rep;
    pthread_mutex_unlock(&r->mu);
}

int vafm_recorder_close(vafm_recorder **rp, vafm_recorder_report *rep, vafm_error *err)
{
    if (!rp || !*rp)
        return 0;
    vafm_recorder *r = *rp;
    *rp = NULL;
    if (r->has_flusher) {
        pthread_mutex_lock(&r->mu);
        r->stop = 1;
        pthread_cond_signal(&r->wake);
        pthread_mutex_unlock(&r->mu);
        pthread_join(r->flusher, NULL);
        pthread_cond_destroy(&r->wake);
    }
    pthread_mutex_destroy(&r->mu);
    /* a clean close merges the ground truth into one table and flushes the rest */
    vafm_error e;
    memset(&e, 0, sizeof e);
    double t0 = s_now();
    int rc = r->werr_code;
    if (rc) {
        s_err_copy(err, &r->werr);
        vafm_h5_writer_destroy(&r->w); /* what a crash leaves: every flushed curve stays readable */
    } else {
        uint64_t n = vafm_h5_writer_count(r->w);
        rc = vafm_h5_writer_close(&r->w, &e);
        if (rc)
            s_err_copy(err, &e);
        else if (r->on_durable)
            r->on_durable(r->user, n);
        r->rep.flushes++;
    }
    r->rep.writer_s += s_now() - t0;
    if (rep)
        *rep = r->rep;
    free(r);
    return rc;
}
