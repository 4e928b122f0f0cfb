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
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "vafm/campaign.h"
#include "core/internal.h"

size_t vafm_campaign_points(const vafm_campaign_spec *spec)
{
    if (spec->point_fn)
        return spec->n_points;
    size_t nT = spec->n_T ? spec->n_T : 1, nv = spec->n_v ? spec->n_v : 1, nk = spec->n_k ? spec->n_k : 1;
    return nT * nv * nk;
}

int vafm_campaign_point_params(const vafm_params *base, const vafm_campaign_spec *spec, size_t point,
                               vafm_params *out)
{
    size_t nv = spec->n_v ? spec->n_v : 1, nk = spec->n_k ? spec->n_k : 1;
    if (point >= vafm_campaign_points(spec))
        return VAFM_EINVAL;
    if (spec->point_fn)
        return spec->point_fn(spec->point_user, base, point, out);
    *out = *base;
    size_t ik = point % nk, iv = (point / nk) % nv, iT = point / (nk * nv);
    if (spec->n_T)
        out->T_K = spec->T_K[iT];
    if (spec->n_v)
        out->v_approach_m_per_s = out->v_retract_m_per_s = spec->v_m_per_s[iv];
    if (spec->n_k)
        out->k_N_per_m = spec->k_N_per_m[ik];
    return 0;
}

typedef struct s_buf {
    size_t n, cap;
    double *t, *h, *d, *f, *tip;
    uint8_t *seg;
} s_buf;

typedef struct s_slot {
    int done, status;
    uint64_t index;
    size_t point;
    vafm_params params; /* the scene of its point */
    vafm_curve_result res;
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
    free(b->seg);
    memset(b, 0, sizeof *b);
}

static int s_collect(void *user, const vafm_samples *blk)
{
    s_buf *b = user;
    double **chan[5] = { &b->t, &b->h, &b->d, &b->f, &b->tip };
    const double *src[5] = { blk->time_s, blk->height_m, blk->deflection_m, blk->force_N, blk->tip_m };
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
        if (sh->spec->keep_samples) {
            c.samples.n = sl->buf.n;
            c.samples.first = 0;
            c.samples.time_s = sl->buf.t;
            c.samples.height_m = sl->buf.h;
            c.samples.deflection_m = sl->buf.d;
            c.samples.force_N = sl->buf.f;
            c.samples.tip_m = sl->buf.tip;
            c.samples.segment = sl->buf.seg;
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
    pthread_mutex_lock(&sh->mu);
    while (!sh->stop && !sh->exhausted) {
        uint64_t ticket = sh->next, idx = sh->first + ticket;
        if (ticket >= sh->deliver_next + sh->window || sh->in_source) {
            pthread_cond_wait(&sh->space, &sh->mu);
            continue;
        }
        if (sh->source) {
            sh->in_source = 1;
            pthread_mutex_unlock(&sh->mu);
            int got = sh->source(sh->source_user, &idx);
            pthread_mutex_lock(&sh->mu);
            sh->in_source = 0;
            pthread_cond_broadcast(&sh->space);
            if (got < 0 && !sh->error)
                sh->error = got;
            if (got == 1 && idx >= sh->total && !sh->error)
                sh->error = VAFM_EINVAL;
            if (got != 1 || sh->error) {
                sh->exhausted = 1;
                break;
            }
        } else if (idx >= sh->total) {
            sh->exhausted = 1;
            break;
        }
        sh->next++;
        pthread_mutex_unlock(&sh->mu);

        size_t point = (size_t)(idx / sh->N);
        int status = 0;
        vafm_curve_result res;
        memset(&res, 0, sizeof res);
        if (point != sim_point) {
            /* a point's scene (validated before the run); a grid given point by point (a map) repeats
             * scenes: the simulation of an equal one is kept */
            status = vafm_campaign_point_params(sh->base, sh->spec, point, &p);
            if (!status && !(sim && !memcmp(&p, &sim_params, sizeof p))) {
                vafm_sim_destroy(&sim);
                status = vafm_sim_new(&sim, &p, NULL);
                sim_params = p;
            }
            sim_point = status ? (size_t)-1 : point;
            if (status)
                vafm_sim_destroy(&sim);
        }
        local.n = 0;
        if (!status)
            status = vafm_sim_curve(sim, idx, sh->spec->keep_samples ? s_collect : NULL, &local, &res);

        pthread_mutex_lock(&sh->mu);
        s_slot *sl = &sh->slots[ticket % sh->window];
        s_buf tmp = sl->buf;
        sl->buf = local;
        local = tmp;
        sl->res = res;
        sl->status = status;
        sl->point = point;
        sl->params = p;
        sl->index = idx;
        sl->done = 1;
        if (status == VAFM_ENOMEM)
            sh->error = status;
        s_deliver(sh);
    }
    pthread_cond_broadcast(&sh->space);
    pthread_mutex_unlock(&sh->mu);
    vafm_sim_destroy(&sim);
    s_buf_free(&local);
    return NULL;
}

int vafm_campaign_validate(const vafm_params *base, const vafm_campaign_spec *spec, size_t *bad_point,
                           vafm_error *err)
{
    if (!base || !spec) {
        vafm_err_set(err, VAFM_EINVAL, "", "vafm_campaign_validate: no scene or no spec");
        return VAFM_EINVAL;
    }
    if (spec->point_fn && (spec->n_T || spec->n_v || spec->n_k || spec->n_points == 0)) {
        vafm_err_set(err, VAFM_EINVAL, "n_points",
                     "a grid given point by point takes no T, v or k lists and at least one point");
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
                char msg[sizeof err->message + 128];
                snprintf(msg, sizeof msg, "grid point %zu (T = %g K, v = %g m/s, k = %g N/m): %s", i, p.T_K,
                         p.v_retract_m_per_s, p.k_N_per_m, err->message[0] ? err->message : vafm_strerror(r));
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
    int threads = spec->threads > 0 ? spec->threads : (int)sysconf(_SC_NPROCESSORS_ONLN);
    if (threads < 1)
        threads = 1;
    if (threads > 256)
        threads = 256;
    sh.window = (size_t)threads * 4;
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
        if (pthread_create(&tid[i], NULL, s_worker, &sh) != 0)
            break;
        started++;
    }
    if (started == 0)
        s_worker(&sh);
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
