/* SPDX-License-Identifier: MIT */
/* The batch-kernel feeder of a free-run daemon campaign (camp_feed.h). */
#include "camp_feed.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "core/channels.h"
#include "vafm/common.h"

struct vafmd_feed {
    atomic_int refs;              /* the simulation thread's and the feeder's */
    atomic_int stop;              /* released: stop after the curves in flight */
    atomic_int ended;             /* the feeder's campaign returned (rc is set) */
    int rc;
    vafm_params base;
    vafm_campaign_spec spec;
    double *lists;                /* T, v, k (one allocation; spec points into it) */
    /* the ring: the feeder writes slot[head % N] then head, the simulation thread reads slot[tail % N] then tail */
    vafmd_feed_curve *slot[VAFMD_FEED_RING];
    atomic_uint_fast64_t head, tail;
    atomic_size_t bytes;          /* samples in the ring */
};

static void s_free(vafmd_feed *f)
{
    uint64_t t = atomic_load(&f->tail), h = atomic_load(&f->head);
    for (; t < h; t++)
        vafmd_feed_curve_free(&f->slot[t % VAFMD_FEED_RING]);
    free(f->lists);
    free(f);
}

static void s_unref(vafmd_feed *f)
{
    if (atomic_fetch_sub(&f->refs, 1) == 1)
        s_free(f);
}

static void s_nap(void)
{
    struct timespec ts = { 0, 1000000 };
    nanosleep(&ts, NULL);
}

/* Called by the campaign in index order, one at a time: copy the curve, wait for room, push it. */
static int s_on_curve(void *user, const vafm_campaign_curve *c)
{
    vafmd_feed *f = user;
    const size_t n = c->samples.n;
    size_t arrays = 0; /* the channel arrays the curve has (core/channels.h) */
    for (int k = 0; k < VAFM_CH_COUNT; k++)
        arrays += vafm_channel_samples(&c->samples, k) != NULL;
    const size_t bytes = n * (arrays * sizeof(double) + 1);
    vafmd_feed_curve *fc = malloc(sizeof *fc + bytes);
    if (!fc)
        return 1;
    memset(fc, 0, sizeof *fc);
    fc->index = c->index;
    fc->status = c->status;
    fc->error = c->error;
    fc->result = c->result;
    fc->n = n;
    fc->bytes = bytes;
    double *p = (double *)(fc + 1);
    fc->samples = (vafm_samples){ .n = n };
    for (int k = 0; k < VAFM_CH_COUNT; k++) {
        const double *src = vafm_channel_samples(&c->samples, k);
        if (!src)
            continue;
        if (n)
            memcpy(p, src, n * sizeof(double));
        vafm_channel_set_samples(&fc->samples, k, p);
        p += n;
    }
    uint8_t *seg = (uint8_t *)p;
    if (n)
        memcpy(seg, c->samples.segment, n);
    fc->samples.segment = seg;
    for (;;) { /* room: a free slot, and the byte budget (an empty ring takes any curve) */
        if (atomic_load(&f->stop)) {
            vafmd_feed_curve_free(&fc);
            return 1;
        }
        const uint64_t h = atomic_load(&f->head), t = atomic_load(&f->tail);
        if (h - t < VAFMD_FEED_RING && (h == t || (double)(atomic_load(&f->bytes) + bytes) <= VAFMD_FEED_MAX_BYTES))
            break;
        s_nap();
    }
    const uint64_t h = atomic_load(&f->head);
    f->slot[h % VAFMD_FEED_RING] = fc;
    atomic_fetch_add(&f->bytes, bytes);
    atomic_store(&f->head, h + 1); /* publishes the slot (sequentially consistent store) */
    return c->status != 0;          /* a failed curve ends the campaign, as in the simulation thread */
}

static void *s_thread(void *arg)
{
    vafmd_feed *f = arg;
    f->rc = vafm_campaign_run(&f->base, &f->spec, s_on_curve, f, NULL);
    atomic_store(&f->ended, 1);
    s_unref(f);
    return NULL;
}

int vafmd_feed_start(vafmd_feed **out, const vafm_params *base, const vafm_campaign_spec *spec)
{
    *out = NULL;
    if (spec->point_fn)
        return VAFM_EINVAL; /* a map's pixels come from its spec, which belongs to the campaign */
    vafmd_feed *f = calloc(1, sizeof *f);
    size_t nl = 0;
    for (int a = 0; a < VAFM_CAMPAIGN_NAXES; a++)
        nl += vafm_campaign_axis_values(spec, a, NULL);
    if (!f || !(f->lists = malloc((nl ? nl : 1) * sizeof(double)))) {
        free(f);
        return VAFM_ENOMEM;
    }
    f->base = *base;
    f->spec = *spec;
    double *l = f->lists;
    for (int a = 0; a < VAFM_CAMPAIGN_NAXES; a++) { /* the feed owns copies of the grid's lists */
        const double *v;
        size_t n = vafm_campaign_axis_values(spec, a, &v);
        if (n)
            vafm_campaign_axis_set(&f->spec, a, memcpy(l, v, n * sizeof(double)), n);
        l += n;
    }
    f->spec.threads = 1; /* the simulation thread streams on the other core */
    f->spec.keep_samples = 1;
    f->spec.kernel = VAFM_CAMPAIGN_KERNEL_BATCH;
    f->spec.batch_width = 0;
    f->spec.map_json = NULL;
    atomic_init(&f->refs, 2);
    atomic_init(&f->stop, 0);
    atomic_init(&f->ended, 0);
    atomic_init(&f->head, 0);
    atomic_init(&f->tail, 0);
    atomic_init(&f->bytes, 0);
    pthread_t th;
    pthread_attr_t at;
    int ok = !pthread_attr_init(&at) && !pthread_attr_setdetachstate(&at, PTHREAD_CREATE_DETACHED) &&
             !pthread_create(&th, &at, s_thread, f);
    pthread_attr_destroy(&at);
    if (!ok) {
        free(f->lists);
        free(f);
        return VAFM_ENOMEM;
    }
    *out = f;
    return 0;
}

vafmd_feed_curve *vafmd_feed_take(vafmd_feed *f, int *ended, int *rc)
{
    *ended = 0;
    *rc = 0;
    const int was_ended = atomic_load(&f->ended); /* read before the ring: a curve pushed before the end is seen */
    const uint64_t t = atomic_load(&f->tail);
    if (t == atomic_load(&f->head)) {
        if (was_ended) {
            *ended = 1;
            *rc = f->rc;
        }
        return NULL;
    }
    vafmd_feed_curve *c = f->slot[t % VAFMD_FEED_RING];
    f->slot[t % VAFMD_FEED_RING] = NULL;
    atomic_fetch_sub(&f->bytes, c->bytes);
    atomic_store(&f->tail, t + 1);
    return c;
}

void vafmd_feed_curve_free(vafmd_feed_curve **c)
{
    free(*c);
    *c = NULL;
}

void vafmd_feed_release(vafmd_feed **f)
{
    if (!*f)
        return;
    atomic_store(&(*f)->stop, 1);
    s_unref(*f);
    *f = NULL;
}
