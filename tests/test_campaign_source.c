/* SPDX-License-Identifier: MIT */
/*
 * vafm_campaign_run_source (the hook MPI campaigns use): a campaign over the indices a source hands
 * out, in any order, must deliver exactly those curves, in the source's order, one at a time, each
 * bit-identical (result and every sample) to the same index computed alone with vafm_sim_curve on the
 * point's scene, for any thread count; the source is never called concurrently and may block; its
 * error, an index out of range and a stopping callback end the campaign with the documented codes.
 * Deterministic: no statistics.
 */
#include <stdint.h>
#include <string.h>
#include <time.h>

#include "harness.h"
#include "vafm/campaign.h"
#include "vafm/params.h"
#include "vafm/sim.h"
#include "trace.h"
#include "campaign_spec.h"

#define T_N 6       /* curves per point */
#define T_TOTAL 12  /* two points */

/* The reference: one curve alone, with the library's single-curve API (samples collected whole). */
static vafm_params t_base;
static double t_v[2];
static vafm_campaign_spec t_spec;
static vafm_curve_result t_ref[T_TOTAL];
static uint64_t t_ref_hash[T_TOTAL];

static void t_setup(void)
{
    vafm_error err = { 0 };
    ENSURE(vafm_preset_apply(&t_base, "paper-fig4", &err) == 0);
    /* fast ramps: ~1 ms per curve; two speeds so workers switch scenes */
    t_v[0] = 6.4e-4;
    t_v[1] = 1.28e-3;
    t_spec = t_campaign_spec(NULL, 0, t_v, 2, T_N);
    t_spec.keep_samples = 1;
    for (uint64_t i = 0; i < T_TOTAL; i++) {
        vafm_params pp;
        ENSURE(vafm_campaign_point_params(&t_base, &t_spec, (size_t)(i / T_N), &pp) == 0);
        vafm_sim *s = NULL;
        ENSURE(vafm_sim_new(&s, &pp, &err) == 0);
        t_trace b = { 0 };
        ENSURE(s && vafm_sim_curve(s, i, t_collect, &b, &t_ref[i]) == 0);
        t_ref_hash[i] = t_trace_hash(&b);
        t_trace_free(&b);
        vafm_sim_destroy(&s);
    }
    /* the curves differ from one another, so comparing them means something */
    ENSURE(t_ref_hash[0] != t_ref_hash[1] && t_ref_hash[0] != t_ref_hash[T_N] && t_ref[0].samples > 100);
    ENSURE(!t_result_same(&t_ref[0], &t_ref[1]));
}

/* A source over a fixed list; sleeps a little to look like a network round trip. */
typedef struct t_src {
    const uint64_t *list;
    size_t n, pos;
    int inside, overlap;
    int fail_after;      /* >0: return VAFM_EIO after this many indices */
    uint64_t bad_index;  /* != 0: hand out this index first */
} t_src;

static int t_source(void *user, uint64_t *index)
{
    t_src *s = user;
    if (__atomic_fetch_add(&s->inside, 1, __ATOMIC_SEQ_CST) != 0)
        s->overlap = 1;
    struct timespec ts = { 0, 200000 };
    nanosleep(&ts, NULL);
    int r;
    if (s->bad_index) {
        *index = s->bad_index;
        s->bad_index = 0;
        r = 1;
    } else if (s->fail_after > 0 && s->pos == (size_t)s->fail_after) {
        r = VAFM_EIO;
    } else if (s->pos < s->n) {
        *index = s->list[s->pos++];
        r = 1;
    } else {
        r = 0;
    }
    __atomic_fetch_sub(&s->inside, 1, __ATOMIC_SEQ_CST);
    return r;
}

typedef struct t_got {
    uint64_t idx[T_TOTAL * 2];
    size_t n;
    int bad_point, bad_curve, stop_at;
} t_got;

static int t_deliver(void *user, const vafm_campaign_curve *c)
{
    t_got *g = user;
    if (g->n < T_TOTAL * 2)
        g->idx[g->n] = c->index;
    g->n++;
    if (c->point != c->index / T_N || c->params->v_retract_m_per_s != t_v[c->point])
        g->bad_point = 1;
    if (c->index >= T_TOTAL || c->status || !t_result_same(&c->result, &t_ref[c->index]) ||
        t_samples_hash(&c->samples) != t_ref_hash[c->index])
        g->bad_curve = 1;
    return g->stop_at && g->n >= (size_t)g->stop_at;
}

static void test_source_order_and_identity(void)
{
    /* out of order, with gaps (7 of 12 indices), across both points */
    static const uint64_t list[] = { 11, 2, 9, 0, 5, 6, 3 };
    const size_t n = sizeof list / sizeof list[0];
    const int threads[3] = { 1, 2, 3 };
    for (int k = 0; k < 3; k++) {
        vafm_campaign_spec sp = t_spec;
        sp.threads = threads[k];
        sp.first_curve = 4; /* ignored with a source */
        t_src src = { list, n, 0, 0, 0, 0, 0 };
        t_got got;
        memset(&got, 0, sizeof got);
        vafm_error err = { 0 };
        ENSURE_MSG(vafm_campaign_run_source(&t_base, &sp, t_source, &src, t_deliver, &got, &err) == 0, "%s",
                   err.message);
        ENSURE_MSG(got.n == n, "threads %d: %zu curves delivered, want %zu", threads[k], got.n, n);
        for (size_t i = 0; i < n && i < got.n; i++)
            ENSURE_MSG(got.idx[i] == list[i], "threads %d: curve %zu is index %llu, want %llu", threads[k], i,
                       (unsigned long long)got.idx[i], (unsigned long long)list[i]);
        ENSURE(!got.bad_point);
        ENSURE_MSG(!got.bad_curve, "threads %d: a curve differs from the same index run alone", threads[k]);
        ENSURE(!src.overlap);
    }
}

static void test_source_errors(void)
{
    static const uint64_t list[] = { 0, 1, 2, 3, 4, 5, 6, 7 };
    /* the source's error stops the campaign with that error; the curves handed out before are delivered */
    t_src src = { list, 8, 0, 0, 0, 3, 0 };
    t_got got;
    memset(&got, 0, sizeof got);
    vafm_campaign_spec sp = t_spec;
    sp.threads = 2;
    ENSURE(vafm_campaign_run_source(&t_base, &sp, t_source, &src, t_deliver, &got, NULL) == VAFM_EIO);
    ENSURE(got.n == 3 && !got.bad_curve);

    /* an index beyond the campaign is refused */
    t_src bad = { list, 8, 0, 0, 0, 0, T_TOTAL };
    memset(&got, 0, sizeof got);
    ENSURE(vafm_campaign_run_source(&t_base, &sp, t_source, &bad, t_deliver, &got, NULL) == VAFM_EINVAL);
    ENSURE(got.n == 0);

    /* a callback that stops: VAFM_EABORT, nothing delivered after it */
    t_src all = { list, 8, 0, 0, 0, 0, 0 };
    memset(&got, 0, sizeof got);
    got.stop_at = 2;
    ENSURE(vafm_campaign_run_source(&t_base, &sp, t_source, &all, t_deliver, &got, NULL) == VAFM_EABORT);
    ENSURE(got.n == 2);

    /* source NULL is vafm_campaign_run: every index from first_curve, in order */
    memset(&got, 0, sizeof got);
    sp.first_curve = 7;
    ENSURE(vafm_campaign_run_source(&t_base, &sp, NULL, NULL, t_deliver, &got, NULL) == 0);
    ENSURE(got.n == T_TOTAL - 7 && got.idx[0] == 7 && got.idx[got.n - 1] == T_TOTAL - 1 && !got.bad_curve);
}

/* The grid's order (include/vafm/campaign.h, protocol/hdf5.md "vafm grid"): point = (iT·n_v + iv)·n_k + ik,
 * k fastest, then v, then T. A 2 T × 2 v × 3 k grid makes every axis distinguishable; a point past the end
 * is VAFM_EINVAL; an empty list leaves the scene's value. */
static void test_grid_order(void)
{
    vafm_params base, q;
    vafm_preset_apply(&base, "paper-fig4", NULL);
    const double T[2] = { 1.0, 2.0 }, v[2] = { 1e-5, 2e-5 }, k[3] = { 0.5, 1.0, 1.5 };
    vafm_campaign_spec spec = t_campaign_spec(T, 2, v, 2, 1);
    spec.k_N_per_m = k;
    spec.n_k = 3;
    ENSURE(vafm_campaign_points(&spec) == 12);
    int bad = 0;
    for (size_t pt = 0; pt < 12; pt++) {
        ENSURE(vafm_campaign_point_params(&base, &spec, pt, &q) == 0);
        size_t iT = pt / 6, iv = (pt / 3) % 2, ik = pt % 3;
        if (q.T_K != T[iT] || q.v_approach_m_per_s != v[iv] || q.v_retract_m_per_s != v[iv] || q.k_N_per_m != k[ik]) {
            fprintf(stderr, "  point %zu: T %g v %g k %g, expected T %g v %g k %g\n", pt, q.T_K, q.v_approach_m_per_s,
                    q.k_N_per_m, T[iT], v[iv], k[ik]);
            bad++;
        }
        q.T_K = base.T_K;
        q.v_approach_m_per_s = base.v_approach_m_per_s;
        q.v_retract_m_per_s = base.v_retract_m_per_s;
        q.k_N_per_m = base.k_N_per_m;
        bad += memcmp(&q, &base, sizeof q) != 0; /* nothing else changes */
    }
    ENSURE_MSG(bad == 0, "%d grid points out of order (k fastest, then v, then T)", bad);
    ENSURE(vafm_campaign_point_params(&base, &spec, 12, &q) == VAFM_EINVAL);
    spec.n_v = 0; /* no v list: the scene's speed; k still fastest */
    ENSURE(vafm_campaign_points(&spec) == 6);
    ENSURE(vafm_campaign_point_params(&base, &spec, 4, &q) == 0);
    ENSURE(q.T_K == T[1] && q.k_N_per_m == k[1] && q.v_approach_m_per_s == base.v_approach_m_per_s);
}

/* The grid's axes are one table (campaign.h): their names in files and on the wire, their symbols and units
 * in messages and CLI options; the lists set and read through it are the spec's own fields. */
static void test_axes(void)
{
    static const char *const name[3] = { "T_K", "v_m_per_s", "k_N_per_m" }, *const sym[3] = { "T", "v", "k" },
                             *const unit[3] = { "K", "m/s", "N/m" },
                             *const param[3] = { "T_K", "v_approach_m_per_s", "k_N_per_m" };
    ENSURE(VAFM_CAMPAIGN_NAXES == 3 && !vafm_campaign_axis_at(-1) && !vafm_campaign_axis_at(VAFM_CAMPAIGN_NAXES));
    for (int a = 0; a < VAFM_CAMPAIGN_NAXES; a++) {
        const vafm_campaign_axis *x = vafm_campaign_axis_at(a);
        ENSURE_MSG(x && !strcmp(x->name, name[a]) && !strcmp(x->symbol, sym[a]) && !strcmp(x->unit, unit[a]) &&
                       !strcmp(x->param, param[a]),
                   "axis %d", a);
    }
    const double T[2] = { 300.0, -5.0 }, v[1] = { 2e-6 }, k[3] = { 0.5, 1.0, 1.5 };
    vafm_campaign_spec spec;
    memset(&spec, 0, sizeof spec);
    vafm_campaign_axis_set(&spec, VAFM_CAMPAIGN_AXIS_T, T, 2);
    vafm_campaign_axis_set(&spec, VAFM_CAMPAIGN_AXIS_V, v, 1);
    vafm_campaign_axis_set(&spec, VAFM_CAMPAIGN_AXIS_K, k, 3);
    vafm_campaign_axis_set(&spec, VAFM_CAMPAIGN_NAXES, T, 7); /* ignored */
    ENSURE(spec.T_K == T && spec.n_T == 2 && spec.v_m_per_s == v && spec.n_v == 1 && spec.k_N_per_m == k &&
           spec.n_k == 3 && vafm_campaign_points(&spec) == 6);
    const double *got = T;
    ENSURE(vafm_campaign_axis_values(&spec, VAFM_CAMPAIGN_AXIS_K, &got) == 3 && got == k);
    ENSURE(vafm_campaign_axis_values(&spec, -1, &got) == 0 && got == NULL);

    vafm_params p;
    vafm_preset_apply(&p, "paper-fig4", NULL);
    vafm_campaign_axis_apply(&p, VAFM_CAMPAIGN_AXIS_V, 3e-6);
    ENSURE(p.v_approach_m_per_s == 3e-6 && p.v_retract_m_per_s == 3e-6);
    vafm_campaign_axis_apply(&p, VAFM_CAMPAIGN_AXIS_T, 310.0);
    vafm_campaign_axis_apply(&p, VAFM_CAMPAIGN_AXIS_K, 0.25);
    ENSURE(vafm_campaign_axis_value(&p, VAFM_CAMPAIGN_AXIS_T) == 310.0 &&
           vafm_campaign_axis_value(&p, VAFM_CAMPAIGN_AXIS_V) == 3e-6 &&
           vafm_campaign_axis_value(&p, VAFM_CAMPAIGN_AXIS_K) == 0.25 && isnan(vafm_campaign_axis_value(&p, 3)));

    /* a bad point's error names its values axis by axis, in the table's order (the text 0.6 wrote) */
    vafm_preset_apply(&p, "contact-silica", NULL);
    vafm_error e = { 0 };
    size_t bad = 99;
    ENSURE(vafm_campaign_validate(&p, &spec, &bad, &e) == VAFM_EINVAL);
    char want[200];
    snprintf(want, sizeof want, "grid point 3 (T = -5 K, v = %g m/s, k = %g N/m): ", v[0], k[0]);
    ENSURE_MSG(bad == 3 && !strncmp(e.message, want, strlen(want)), "bad %zu: %s", bad, e.message);
}

int main(void)
{
    t_setup();
    RUN_TEST(test_grid_order);
    RUN_TEST(test_axes);
    RUN_TEST(test_source_order_and_identity);
    RUN_TEST(test_source_errors);
    return harness_done();
}
