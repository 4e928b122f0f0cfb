/* SPDX-License-Identifier: MIT */
/*
 * Campaigns on all cores. Workers take tickets 0, 1, 2, ... from a shared counter; ticket t is the
 * global curve index first_curve + t, or the t-th index an external source handed out (MPI ranks get
 * their indices from rank 0: vafm_campaign_run_source). Each worker keeps one vafm_sim per grid point
 * it is working on. Finished curves land in a window of slots (ticket modulo the window) and are handed
 * to the caller strictly in ticket order by whichever worker completes the next one, with the lock
 * released during the callback. A worker never runs more than `window` tickets ahead of delivery, so
 * memory stays bounded. The source is called by one worker at a time with the lock released (it may
 * block on the network); the ticket is taken before another worker may call it, so tickets follow the
 * source's order. The per-curve random stream is the global index: results are identical for any
 * thread count and any source.
 */
#include <math.h>
#include <pthread.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "vafm/campaign.h"
#include "core/backend.h"
#include "core/batch.h"
#include "core/internal.h"

/* ---- the grid's axes: one row each, slowest first ------------------------------------------------ */

typedef struct s_axis {
    vafm_campaign_axis info;
    size_t values, count; /* offsets of the list and its length in vafm_campaign_spec */
    size_t param;         /* offset of the scene's double it sets (v: also v_approach_m_per_s) */
} s_axis;

#define S_AXIS(name, sym, unit, param, list, n, field) \
    { { name, sym, unit, param }, offsetof(vafm_campaign_spec, list), offsetof(vafm_campaign_spec, n), \
      offsetof(vafm_params, field) }
static const s_axis s_axes[VAFM_CAMPAIGN_NAXES] = {
    S_AXIS("T_K", "T", "K", "T_K", T_K, n_T, T_K),
    S_AXIS("v_m_per_s", "v", "m/s", "v_approach_m_per_s", v_m_per_s, n_v, v_retract_m_per_s),
    S_AXIS("k_N_per_m", "k", "N/m", "k_N_per_m", k_N_per_m, n_k, k_N_per_m),
};
#undef S_AXIS

const vafm_campaign_axis *vafm_campaign_axis_at(int axis)
{
    return axis >= 0 && axis < VAFM_CAMPAIGN_NAXES ? &s_axes[axis].info : NULL;
}

size_t vafm_campaign_axis_values(const vafm_campaign_spec *spec, int axis, const double **values)
{
    if (axis < 0 || axis >= VAFM_CAMPAIGN_NAXES) {
        if (values)
            *values = NULL;
        return 0;
    }
    const char *sp = (const char *)spec;
    if (values)
        memcpy(values, sp + s_axes[axis].values, sizeof *values);
    size_t n;
    memcpy(&n, sp + s_axes[axis].count, sizeof n);
    return n;
}

void vafm_campaign_axis_set(vafm_campaign_spec *spec, int axis, const double *values, size_t n)
{
    if (axis < 0 || axis >= VAFM_CAMPAIGN_NAXES)
        return;
    char *sp = (char *)spec;
    memcpy(sp + s_axes[axis].values, &values, sizeof values);
    memcpy(sp + s_axes[axis].count, &n, sizeof n);
}

void vafm_campaign_axis_apply(vafm_params *p, int axis, double value)
{
    if (axis < 0 || axis >= VAFM_CAMPAIGN_NAXES)
        return;
    memcpy((char *)p + s_axes[axis].param, &value, sizeof value);
    if (axis == VAFM_CAMPAIGN_AXIS_V)
        p->v_approach_m_per_s = value; /* a grid speed is the approach's and the retract's */
}

double vafm_campaign_axis_value(const vafm_params *p, int axis)
{
    if (axis < 0 || axis >= VAFM_CAMPAIGN_NAXES)
        return NAN;
    double v;
    memcpy(&v, (const char *)p + s_axes[axis].param, sizeof v);
    return v;
}

size_t vafm_campaign_points(const vafm_campaign_spec *spec)
{
    if (spec->point_fn)
        return spec->n_points;
    size_t np = 1;
    for (int a = 0; a < VAFM_CAMPAIGN_NAXES; a++) {
        size_t n = vafm_campaign_axis_values(spec, a, NULL);
        np *= n ? n : 1;
    }
    return np;
}

int vafm_campaign_point_params(const vafm_params *base, const vafm_campaign_spec *spec, size_t point,
                               vafm_params *out)
{
    if (point >= vafm_campaign_points(spec))
        return VAFM_EINVAL;
    if (spec->point_fn)
        return spec->point_fn(spec->point_user, base, point, out);
    *out = *base;
    /* the last axis fastest: peel the point's index from the fastest axis up */
    for (int a = VAFM_CAMPAIGN_NAXES - 1; a >= 0; a--) {
        const double *v;
        size_t n = vafm_campaign_axis_values(spec, a, &v);
        if (n) {
            vafm_campaign_axis_apply(out, a, v[point % n]);
            point /= n;
        }
    }
    return 0;
}

typedef struct s_buf {
    size_t n, cap;
    double *t, *h, *d, *f, *tip;
    double *hm;    /* the actual piezo height (a scene with a piezo actuator model; NULL: none) */
    size_t hm_cap; /* its room (it grows only for curves that carry it) */
    int has_hm;    /* the curve's samples carry it */
    uint8_t *seg;
} s_buf;

typedef struct s_slot {
    int done, status;
    uint64_t index;
    size_t point;
    vafm_params params; /* the scene of its point */
    vafm_curve_result res;
    vafm_error err;     /* the curve's error detail (status ≠ 0) */
    s_buf buf;
} s_slot;

typedef struct s_shared {
    const vafm_params *base;
    const vafm_campaign_spec *spec;
    vafm_campaign_fn fn;
    void *user;
    vafm_campaign_source_fn source;
    void *source_user;
    uint64_t N, total, first, next, deliver_next; /* next, deliver_next: tickets */
    size_t window;
    s_slot *slots;
    int delivering, stop, error, in_source, exhausted;
    int width;      /* batch kernel lanes (0: the scalar worker) */
    int flight;     /* curves a batch worker keeps in flight */
    pthread_mutex_t mu;
    pthread_cond_t space;
} s_shared;

static void s_buf_free(s_buf *b)
{
    free(b->t);
    free(b->h);
    free(b->d);
    free(b->f);
    free(b->tip);
    free(b->hm);
    free(b->seg);
    memset(b, 0, sizeof *b);
}

static int s_collect(void *user, const vafm_samples *blk)
{
    s_buf *b = user;
    double **chan[5] = { &b->t, &b->h, &b->d, &b->f, &b->tip };
    const double *src[5] = { blk->time_s, blk->height_m, blk->deflection_m, blk->force_N, blk->tip_m };
    if (b->n == 0)
        b->has_hm = blk->height_measured_m != NULL; /* a scene's samples all carry it, or none */
    if (b->has_hm != (blk->height_measured_m != NULL))
        return 1; /* cannot happen: a piezo model is a property of the scene */
    if (b->has_hm && b->n + blk->n > b->hm_cap) {
        size_t cap = b->hm_cap ? b->hm_cap : 4096;
        while (cap < b->n + blk->n)
            cap *= 2;
        double *p = realloc(b->hm, cap * sizeof(double));
        if (!p)
            return 1;
        b->hm = p;
        b->hm_cap = cap;
    }
    if (b->has_hm)
        memcpy(b->hm + b->n, blk->height_measured_m, blk->n * sizeof(double));
    if (b->n + blk->n > b->cap) {
        size_t cap = b->cap ? b->cap : 4096;
        while (cap < b->n + blk->n)
            cap *= 2;
        for (int c = 0; c < 5; c++) {
            double *p = realloc(*chan[c], cap * sizeof(double));
            if (!p)
                return 1; /* out of memory: stop this curve (the arrays grown so far stay valid) */
            *chan[c] = p;
        }
        uint8_t *seg = realloc(b->seg, cap);
        if (!seg)
            return 1;
        b->seg = seg;
        b->cap = cap;
    }
    for (int c = 0; c < 5; c++)
        memcpy(*chan[c] + b->n, src[c], blk->n * sizeof(double));
    memcpy(b->seg + b->n, blk->segment, blk->n);
    b->n += blk->n;
    return 0;
}

/* Deliver every finished curve at the head of the window. Called and returns with the lock held. */
static void s_deliver(s_shared *sh)
{
    if (sh->delivering)
        return;
    sh->delivering = 1;
    for (;;) {
        s_slot *sl = &sh->slots[sh->deliver_next % sh->window];
        if (!sl->done)
            break;
        vafm_campaign_curve c;
        memset(&c, 0, sizeof c);
        c.index = sl->index;
        c.point = sl->point;
        c.params = &sl->params;
        c.status = sl->status;
        c.result = sl->res;
        c.error = sl->err;
        if (sh->spec->keep_samples) {
            c.samples.n = sl->buf.n;
            c.samples.first = 0;
            c.samples.time_s = sl->buf.t;
            c.samples.height_m = sl->buf.h;
            c.samples.deflection_m = sl->buf.d;
            c.samples.force_N = sl->buf.f;
            c.samples.tip_m = sl->buf.tip;
            c.samples.segment = sl->buf.seg;
            c.samples.height_measured_m = sl->buf.has_hm ? sl->buf.hm : NULL;
        }
        int stop = 0;
        if (!sh->stop) {
            pthread_mutex_unlock(&sh->mu);
            stop = sh->fn ? sh->fn(sh->user, &c) : 0;
            pthread_mutex_lock(&sh->mu);
        }
        if (stop)
            sh->stop = 1;
        sl->done = 0;
        sh->deliver_next++;
        pthread_cond_broadcast(&sh->space);
    }
    sh->delivering = 0;
}

/* Take the next ticket (the next global index, or the source's). Called and returns with the lock held.
 * may_wait: wait for room in the window (a worker with curves in flight must not: it may hold the one
 * delivery waits for). @return 1 with *ticket and *idx, 0 no room now, -1 no more tickets. */
static int s_take(s_shared *sh, int may_wait, uint64_t *ticket, uint64_t *idx)
{
    for (;;) {
        if (sh->stop || sh->exhausted)
            return -1;
        uint64_t t = sh->next, i = sh->first + t;
        if (t >= sh->deliver_next + sh->window || sh->in_source) {
            if (!may_wait)
                return 0;
            pthread_cond_wait(&sh->space, &sh->mu);
            continue;
        }
        if (sh->source) {
            sh->in_source = 1;
            pthread_mutex_unlock(&sh->mu);
            int got = sh->source(sh->source_user, &i);
            pthread_mutex_lock(&sh->mu);
            sh->in_source = 0;
            pthread_cond_broadcast(&sh->space);
            if (got < 0 && !sh->error)
                sh->error = got;
            if (got == 1 && i >= sh->total && !sh->error)
                sh->error = VAFM_EINVAL;
            if (got != 1 || sh->error) {
                sh->exhausted = 1;
                return -1;
            }
        } else if (i >= sh->total) {
            sh->exhausted = 1;
            return -1;
        }
        sh->next++;
        *ticket = t;
        *idx = i;
        return 1;
    }
}

/* A worker's simulation for the scene of grid point `point`: the one it has when the scene is equal (a grid
 * given point by point repeats scenes), else a new one. Called without the lock. @return 0 or VAFM_E*. */
static int s_sim_for(const s_shared *sh, size_t point, vafm_sim **sim, size_t *sim_point, vafm_params *sim_params,
                     vafm_params *p)
{
    if (point == *sim_point)
        return 0;
    int status = vafm_campaign_point_params(sh->base, sh->spec, point, p); /* validated before the run */
    if (!status && !(*sim && !memcmp(p, sim_params, sizeof *p))) {
        vafm_sim_destroy(sim);
        status = vafm_sim_new(sim, p, NULL);
        *sim_params = *p;
    }
    *sim_point = status ? (size_t)-1 : point;
    if (status)
        vafm_sim_destroy(sim);
    return status;
}

/* Hand a finished curve to its slot (its samples by swapping *buf with the slot's) and deliver what is
 * ready. Called and returns with the lock held. */
static void s_publish(s_shared *sh, uint64_t ticket, uint64_t idx, size_t point, const vafm_params *p, int status,
                      const vafm_curve_result *res, const vafm_sim *sim, s_buf *buf)
{
    s_slot *sl = &sh->slots[ticket % sh->window];
    const vafm_error *e = status && sim ? vafm_sim_error(sim) : NULL;
    if (e)
        sl->err = *e;
    else
        memset(&sl->err, 0, sizeof sl->err);
    s_buf tmp = sl->buf;
    sl->buf = *buf;
    *buf = tmp;
    sl->res = *res;
    sl->status = status;
    sl->point = point;
    sl->params = *p;
    sl->index = idx;
    sl->done = 1;
    if (status == VAFM_ENOMEM)
        sh->error = status;
    s_deliver(sh);
}

static void *s_worker(void *arg)
{
    s_shared *sh = arg;
    vafm_sim *sim = NULL;
    size_t sim_point = (size_t)-1;
    vafm_params sim_params, p;
    memset(&sim_params, 0, sizeof sim_params);
    memset(&p, 0, sizeof p);
    s_buf local;
    memset(&local, 0, sizeof local);
    uint64_t ticket, idx;
    pthread_mutex_lock(&sh->mu);
    while (s_take(sh, 1, &ticket, &idx) == 1) {
        pthread_mutex_unlock(&sh->mu);
        size_t point = (size_t)(idx / sh->N);
        vafm_curve_result res;
        memset(&res, 0, sizeof res);
        int status = s_sim_for(sh, point, &sim, &sim_point, &sim_params, &p);
        local.n = 0;
        if (!status)
            status = vafm_sim_curve(sim, idx, sh->spec->keep_samples ? s_collect : NULL, &local, &res);
        pthread_mutex_lock(&sh->mu);
        s_publish(sh, ticket, idx, point, &p, status, &res, sim, &local);
    }
    pthread_cond_broadcast(&sh->space);
    pthread_mutex_unlock(&sh->mu);
    vafm_sim_destroy(&sim);
    s_buf_free(&local);
    return NULL;
}

/* ---- the batch kernel's worker ---------------------------------------------------------------------
 *
 * A worker keeps S_FLIGHT_PER_LANE curves per lane in flight (one: two per lane gave no more throughput
 * on contact-silica and paper-fig4 and doubled the memory and the wait for the first curve). Each round it advances every curve in the
 * scalar path until the curve either ends or waits for the batch kernel (vafm_sim_advance_batch), then
 * runs all waiting curves' in-contact runs in batches of W lanes. Curves in other phases (approach, free
 * flight, the exact well step, dwell) go on in the scalar path while others wait; having more curves than
 * lanes keeps the lanes full. Each curve is computed exactly as the scalar worker computes it. */

#define S_FLIGHT_PER_LANE 1
/* the samples a batch worker may hold for its curves in flight (keep_samples: whole curves) */
#define S_FLIGHT_BYTES (128.0 * 1024 * 1024)

typedef struct s_flight {
    int busy, waiting;
    uint64_t ticket, idx;
    size_t point, sim_point;
    vafm_params p, sim_params;
    vafm_sim *sim;
    s_buf buf;
} s_flight;

static void s_flight_end(s_shared *sh, s_flight *f, int status)
{
    vafm_curve_result res;
    memset(&res, 0, sizeof res);
    const vafm_sim *sim = f->sim && f->sim_point == f->point ? f->sim : NULL;
    if (sim)
        vafm_sim_result(sim, &res);
    pthread_mutex_lock(&sh->mu);
    s_publish(sh, f->ticket, f->idx, f->point, &f->p, status, &res, sim, &f->buf);
    pthread_mutex_unlock(&sh->mu);
    f->busy = f->waiting = 0;
}

static void *s_worker_batch(void *arg)
{
    s_shared *sh = arg;
    const int W = sh->width, P = sh->flight;
    s_flight *fl = calloc((size_t)P, sizeof *fl);
    struct vafm_kernel **K = calloc((size_t)P, sizeof *K);
    long *want = calloc((size_t)P, sizeof *want), *done = calloc((size_t)P, sizeof *done);
    int *who = calloc((size_t)P, sizeof *who);
    if (!fl || !K || !want || !done || !who) { /* no room for the batch: the scalar worker */
        free(fl);
        free(K);
        free(want);
        free(done);
        free(who);
        return s_worker(arg);
    }
    for (int i = 0; i < P; i++)
        fl[i].sim_point = (size_t)-1;
    int more = 1;
    for (;;) {
        /* start curves in the free places */
        int busy = 0;
        for (int i = 0; i < P; i++)
            busy += fl[i].busy;
        pthread_mutex_lock(&sh->mu);
        for (int i = 0; i < P && more && !sh->stop; i++) {
            s_flight *f = &fl[i];
            if (f->busy)
                continue;
            int r = s_take(sh, busy == 0, &f->ticket, &f->idx);
            if (r < 0)
                more = 0;
            if (r != 1)
                break;
            pthread_mutex_unlock(&sh->mu);
            f->point = (size_t)(f->idx / sh->N);
            f->buf.n = 0;
            f->busy = 1;
            busy++;
            int status = s_sim_for(sh, f->point, &f->sim, &f->sim_point, &f->sim_params, &f->p);
            if (!status)
                status = vafm_sim_curve_begin(f->sim, f->idx);
            if (status) {
                s_flight_end(sh, f, status);
                busy--;
            }
            pthread_mutex_lock(&sh->mu);
        }
        const int stop = sh->stop;
        pthread_mutex_unlock(&sh->mu);
        if (stop || (busy == 0 && !more))
            break;
        /* the scalar path: each curve until it ends or waits for the batch */
        int n = 0;
        for (int i = 0; i < P; i++) {
            s_flight *f = &fl[i];
            if (!f->busy)
                continue;
            int r;
            do
                r = vafm_sim_advance_batch(f->sim, 1u << 20, sh->spec->keep_samples ? s_collect : NULL, &f->buf);
            while (r == 1);
            if (r == VAFM_SIM_BATCH_WAIT) {
                K[n] = vafm_sim_batch_kernel(f->sim, &want[n]);
                who[n++] = i;
            } else {
                s_flight_end(sh, f, r);
            }
        }
        /* the batch: the waiting curves' in-contact runs, W lanes at a time */
        vafm_batch_steps(K, want, done, n, W);
        for (int j = 0; j < n; j++)
            vafm_sim_batch_done(fl[who[j]].sim, done[j]);
    }
    pthread_mutex_lock(&sh->mu);
    pthread_cond_broadcast(&sh->space);
    pthread_mutex_unlock(&sh->mu);
    for (int i = 0; i < P; i++) {
        vafm_sim_destroy(&fl[i].sim);
        s_buf_free(&fl[i].buf);
    }
    free(fl);
    free(K);
    free(want);
    free(done);
    free(who);
    return NULL;
}

/* The row of backend.h's table with `lanes` lanes (> 1), or -1. */
static int s_backend_of_lanes(int lanes)
{
    for (int i = 1; i < vafm_backend_count(); i++)
        if (vafm_backend_at(i)->lanes == lanes)
            return i;
    return -1;
}

/* Kernel names: "auto", "scalar", "batch" (the widest the CPU runs) and "batch<lanes>" for each backend
 * row with more than one lane (up to that many lanes, capped at the CPU's: vafm_batch_width). */
int vafm_campaign_kernel_parse(const char *name, vafm_campaign_spec *spec)
{
    if (!name || !spec)
        return VAFM_EINVAL;
    int kernel = -1, width = 0;
    if (!strcmp(name, "auto"))
        kernel = VAFM_CAMPAIGN_KERNEL_AUTO;
    else if (!strcmp(name, "scalar"))
        kernel = VAFM_CAMPAIGN_KERNEL_SCALAR;
    else if (!strcmp(name, "batch"))
        kernel = VAFM_CAMPAIGN_KERNEL_BATCH;
    else if (!strncmp(name, "batch", 5) && name[5] >= '1' && name[5] <= '9' && strlen(name) <= 7) {
        char *end = NULL;
        const long lanes = strtol(name + 5, &end, 10);
        if (*end == '\0' && s_backend_of_lanes((int)lanes) > 0) {
            kernel = VAFM_CAMPAIGN_KERNEL_BATCH;
            width = (int)lanes;
        }
    }
    if (kernel < 0)
        return VAFM_EINVAL;
    spec->kernel = kernel;
    spec->batch_width = width;
    return 0;
}

int vafm_campaign_kernel_names(char *buf, size_t size, const char *sep)
{
    if (!buf || !size || !sep)
        return VAFM_EINVAL;
    size_t n = (size_t)snprintf(buf, size, "auto%sscalar%sbatch", sep, sep);
    for (int i = 1; i < vafm_backend_count() && n < size; i++)
        n += (size_t)snprintf(buf + n, size - n, "%sbatch%d", sep, vafm_backend_at(i)->lanes);
    return n < size ? 0 : VAFM_EINVAL;
}

const char *vafm_campaign_kernel_describe(const vafm_campaign_spec *spec)
{
    const int w = vafm_campaign_kernel_width(spec);
    if (w == 1 && !(spec && spec->kernel == VAFM_CAMPAIGN_KERNEL_BATCH))
        return "scalar";
    const int i = w == 1 ? 0 : s_backend_of_lanes(w);
    return vafm_backend_at(i < 0 ? 0 : i)->describe;
}

int vafm_campaign_kernel_width(const vafm_campaign_spec *spec)
{
    if (!spec || spec->kernel == VAFM_CAMPAIGN_KERNEL_SCALAR)
        return 1;
    return vafm_batch_width(spec->batch_width);
}

/* How a campaign runs: worker threads, batch width (0: the scalar worker), curves a batch worker keeps in
 * flight, and the window of tickets ahead of delivery. */
static size_t s_plan(const vafm_params *base, const vafm_campaign_spec *spec, int *threads_out, int *width_out,
                     int *flight_out)
{
    const size_t np = vafm_campaign_points(spec);
    int threads = spec->threads > 0 ? spec->threads : (int)sysconf(_SC_NPROCESSORS_ONLN);
    if (threads < 1)
        threads = 1;
    if (threads > 256)
        threads = 256;
    int width = vafm_campaign_kernel_width(spec);
    if (width == 1 && spec->kernel != VAFM_CAMPAIGN_KERNEL_BATCH)
        width = 0; /* the scalar kernel: one curve at a time per worker */
    int flight = 0;
    if (width) {
        /* enough curves in flight to keep the lanes busy while some are in scalar phases; with whole curves
         * kept, as many as the sample budget holds (a long curve at a high rate is tens of MB) */
        const int lanes = vafm_batch_lanes_per_call(width);
        double f = (double)(S_FLIGHT_PER_LANE * lanes);
        if (spec->keep_samples) {
            double samples = 0;
            for (size_t i = 0; i < np && i < 64; i++) { /* a long grid given point by point: its first points */
                vafm_params pp;
                vafm_sim_estimate est;
                if (!vafm_campaign_point_params(base, spec, i, &pp) && !vafm_sim_estimate_cost(&pp, &est, NULL) &&
                    est.samples > samples)
                    samples = est.samples;
            }
            const double bytes = samples * (5.0 * sizeof(double) + 1.0);
            if (bytes * f > S_FLIGHT_BYTES)
                f = fmax(1.0, floor(S_FLIGHT_BYTES / bytes));
        }
        flight = (int)f;
    }
    *threads_out = threads;
    *width_out = width;
    *flight_out = flight;
    return (size_t)threads * (width ? (size_t)flight + 4 : 4);
}

size_t vafm_campaign_window(const vafm_params *base, const vafm_campaign_spec *spec)
{
    if (!base || !spec)
        return 0;
    int t, w, f;
    return s_plan(base, spec, &t, &w, &f);
}

int vafm_campaign_validate(const vafm_params *base, const vafm_campaign_spec *spec, size_t *bad_point,
                           vafm_error *err)
{
    if (!base || !spec) {
        vafm_err_set(err, VAFM_EINVAL, "", "vafm_campaign_validate: no scene or no spec");
        return VAFM_EINVAL;
    }
    int lists = 0;
    for (int a = 0; a < VAFM_CAMPAIGN_NAXES; a++)
        lists |= vafm_campaign_axis_values(spec, a, NULL) != 0;
    if (spec->point_fn && (lists || spec->n_points == 0)) {
        vafm_err_set(err, VAFM_EINVAL, "n_points",
                     "a grid given point by point takes no T, v or k lists and at least one point");
        return VAFM_EINVAL;
    }
    if (spec->kernel < VAFM_CAMPAIGN_KERNEL_AUTO || spec->kernel > VAFM_CAMPAIGN_KERNEL_BATCH) {
        vafm_err_set(err, VAFM_EINVAL, "kernel", "kernel = %d is not a kernel (0 auto, 1 scalar, 2 batch)", spec->kernel);
        return VAFM_EINVAL;
    }
    if (spec->batch_width != 0 && spec->batch_width != 1 && s_backend_of_lanes(spec->batch_width) < 0) {
        char widths[64] = "1";
        for (int i = 1; i < vafm_backend_count(); i++) /* the backend rows' lanes */
            snprintf(widths + strlen(widths), sizeof widths - strlen(widths), "%s%d",
                     i + 1 < vafm_backend_count() ? ", " : " or ", vafm_backend_at(i)->lanes);
        vafm_err_set(err, VAFM_EINVAL, "batch_width", "batch_width = %d is not a width (0: the widest, %s)",
                     spec->batch_width, widths);
        return VAFM_EINVAL;
    }
    size_t np = vafm_campaign_points(spec);
    for (size_t i = 0; i < np; i++) {
        vafm_params p;
        int r = vafm_campaign_point_params(base, spec, i, &p);
        if (r) {
            if (bad_point)
                *bad_point = i;
            vafm_err_set(err, r, "", "grid point %zu: its scene cannot be made (%s)", i, vafm_strerror(r));
            return r;
        }
        r = vafm_params_validate(&p, err);
        if (r) {
            if (bad_point)
                *bad_point = i;
            if (err) {
                char msg[sizeof err->message + 128], at[128] = "";
                for (int a = 0; a < VAFM_CAMPAIGN_NAXES; a++) /* "T = 300 K, v = 1e-06 m/s, k = 0.1 N/m" */
                    snprintf(at + strlen(at), sizeof at - strlen(at), "%s%s = %g %s", a ? ", " : "",
                             s_axes[a].info.symbol, vafm_campaign_axis_value(&p, a), s_axes[a].info.unit);
                snprintf(msg, sizeof msg, "grid point %zu (%s): %s", i, at,
                         err->message[0] ? err->message : vafm_strerror(r));
                snprintf(err->message, sizeof err->message, "%.*s", (int)(sizeof err->message - 1), msg);
            }
            return r;
        }
    }
    return 0;
}

int vafm_campaign_run(const vafm_params *base, const vafm_campaign_spec *spec, vafm_campaign_fn fn, void *user,
                      vafm_error *err)
{
    return vafm_campaign_run_source(base, spec, NULL, NULL, fn, user, err);
}

int vafm_campaign_run_source(const vafm_params *base, const vafm_campaign_spec *spec,
                             vafm_campaign_source_fn source, void *source_user, vafm_campaign_fn fn, void *user,
                             vafm_error *err)
{
    if (!base || !spec) {
        vafm_err_set(err, VAFM_EINVAL, "", "vafm_campaign_run: no scene or no spec");
        return VAFM_EINVAL;
    }
    if (spec->curves_per_point < 1) {
        vafm_err_set(err, VAFM_EINVAL, "curves", "curves per point = %llu must be >= 1",
                     (unsigned long long)spec->curves_per_point);
        return VAFM_EINVAL;
    }
    size_t np = vafm_campaign_points(spec);
    s_shared sh;
    memset(&sh, 0, sizeof sh);
    sh.base = base;
    sh.spec = spec;
    sh.fn = fn;
    sh.user = user;
    sh.source = source;
    sh.source_user = source_user;
    sh.N = spec->curves_per_point;
    sh.total = sh.N * (uint64_t)np;
    if (!source && spec->first_curve > sh.total) {
        vafm_err_set(err, VAFM_EINVAL, "first_curve", "first curve %llu is beyond the campaign's %llu curves",
                     (unsigned long long)spec->first_curve, (unsigned long long)sh.total);
        return VAFM_EINVAL;
    }
    sh.first = source ? 0 : spec->first_curve;
    size_t bad;
    int vr = vafm_campaign_validate(base, spec, &bad, err);
    if (vr)
        return vr;
    int threads;
    sh.window = s_plan(base, spec, &threads, &sh.width, &sh.flight);
    sh.slots = calloc(sh.window, sizeof *sh.slots);
    pthread_t *tid = calloc((size_t)threads, sizeof *tid);
    if (!sh.slots || !tid) {
        free(sh.slots);
        free(tid);
        return VAFM_ENOMEM;
    }
    pthread_mutex_init(&sh.mu, NULL);
    pthread_cond_init(&sh.space, NULL);
    int started = 0;
    for (int i = 0; i < threads; i++) {
        if (pthread_create(&tid[i], NULL, sh.width ? s_worker_batch : s_worker, &sh) != 0)
            break;
        started++;
    }
    if (started == 0)
        (sh.width ? s_worker_batch : s_worker)(&sh);
    for (int i = 0; i < started; i++)
        pthread_join(tid[i], NULL);
    pthread_mutex_destroy(&sh.mu);
    pthread_cond_destroy(&sh.space);
    for (size_t i = 0; i < sh.window; i++)
        s_buf_free(&sh.slots[i].buf);
    free(sh.slots);
    free(tid);
    if (sh.error) {
        vafm_err_set(err, sh.error, "", "campaign: %s", vafm_strerror(sh.error));
        return sh.error;
    }
    if (sh.stop) {
        vafm_err_set(err, VAFM_EABORT, "", "campaign stopped by the caller");
        return VAFM_EABORT;
    }
    return 0;
}
