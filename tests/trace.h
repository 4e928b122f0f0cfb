/* SPDX-License-Identifier: MIT */
/*
 * Test helpers: every sample of a run collected per channel (a vafm_sample_fn), compared and hashed
 * bytewise, and curve results compared member by member. Shared by the bit-for-bit tests and by every test
 * that reads a run's samples back.
 */
#ifndef VAFM_TESTS_TRACE_H
#define VAFM_TESTS_TRACE_H

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "vafm/sim.h"

/* The channels a vafm_samples block delivers (hashed), then the measured height (the commanded one where
 * the scene has no piezo model to measure it by). */
#define T_HASHED 5
#define T_CHANNELS 6

/* Every sample of a run, concatenated per channel, plus the FNV-1a hash of the bytes in delivery order.
 * Each channel has a name and an index: c.f[i] is c.ch[3][i]. */
typedef struct t_trace {
    size_t n, cap;
    union {
        double *ch[T_CHANNELS];
        struct {
            double *t, *h, *d, *f, *tip, *hm; /* time, height, deflection, force, tip, measured height */
        };
    };
    uint8_t *seg;
    uint64_t first_expected; /* the next block must start here */
    int order_ok;
} t_trace;

static inline void t_trace_free(t_trace *t)
{
    for (int i = 0; i < T_CHANNELS; i++)
        free(t->ch[i]);
    free(t->seg);
    memset(t, 0, sizeof *t);
}

static inline int t_collect(void *user, const vafm_samples *b)
{
    t_trace *t = user;
    if (b->first != t->first_expected)
        t->order_ok = 0;
    t->first_expected = b->first + b->n;
    if (t->n + b->n > t->cap) {
        size_t cap = t->cap ? 2 * t->cap : 4096;
        while (cap < t->n + b->n)
            cap *= 2;
        for (int i = 0; i < T_CHANNELS; i++) {
            double *p = realloc(t->ch[i], cap * sizeof(double));
            if (!p)
                return 1;
            t->ch[i] = p;
        }
        uint8_t *s = realloc(t->seg, cap);
        if (!s)
            return 1;
        t->seg = s;
        t->cap = cap;
    }
    const double *src[T_CHANNELS] = {b->time_s, b->height_m, b->deflection_m, b->force_N, b->tip_m,
                                     b->height_measured_m ? b->height_measured_m : b->height_m};
    for (int i = 0; i < T_CHANNELS; i++)
        memcpy(t->ch[i] + t->n, src[i], b->n * sizeof(double));
    memcpy(t->seg + t->n, b->segment, b->n);
    t->n += b->n;
    return 0;
}

static inline uint64_t t_fnv1a(uint64_t h, const void *data, size_t len)
{
    const unsigned char *p = data;
    for (size_t i = 0; i < len; i++) {
        h ^= p[i];
        h *= UINT64_C(0x100000001b3);
    }
    return h;
}

#define T_FNV_BASIS UINT64_C(0xcbf29ce484222325)

/* Hash of a block's sample bytes: each delivered channel's array in turn, then the segments. */
static inline uint64_t t_samples_hash(const vafm_samples *b)
{
    const double *ch[T_HASHED] = {b->time_s, b->height_m, b->deflection_m, b->force_N, b->tip_m};
    uint64_t h = T_FNV_BASIS;
    for (int i = 0; i < T_HASHED; i++)
        h = t_fnv1a(h, ch[i], b->n * sizeof(double));
    return t_fnv1a(h, b->segment, b->n);
}

/* The same hash over all the samples a trace collected. */
static inline uint64_t t_trace_hash(const t_trace *t)
{
    const vafm_samples all = {t->n, 0, t->t, t->h, t->d, t->f, t->tip, t->seg, NULL};
    return t_samples_hash(&all);
}

static inline int t_trace_same(const t_trace *a, const t_trace *b)
{
    if (a->n != b->n)
        return 0;
    for (int i = 0; i < T_CHANNELS; i++)
        if (memcmp(a->ch[i], b->ch[i], a->n * sizeof(double)))
            return 0;
    return memcmp(a->seg, b->seg, a->n) == 0;
}

/* Results compared member by member, bytewise (NaN == NaN; no struct padding involved). */
static inline int t_result_same(const vafm_curve_result *a, const vafm_curve_result *b)
{
#define T_SAME(f) (memcmp(&a->f, &b->f, sizeof a->f) == 0)
    return T_SAME(index) && T_SAME(flags) && T_SAME(pulloff_sampled_N) && T_SAME(pulloff_spring_N) &&
           T_SAME(detach_force_N) && T_SAME(detach_height_m) && T_SAME(detach_eq_force_N) &&
           T_SAME(detach_time_s) && T_SAME(touch_time_s) && T_SAME(touch_height_m) && T_SAME(retract_start_s) &&
           T_SAME(duration_s) && T_SAME(samples) && T_SAME(steps) && T_SAME(steps_contact) && T_SAME(steps_free);
#undef T_SAME
}

#endif
