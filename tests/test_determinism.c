/* SPDX-License-Identifier: MIT */
/*
 * Bit-for-bit reproducibility: a curve is a pure function of (scene, seed, curve index), whatever sim
 * object runs it, however its samples are pulled (block sizes, step budgets that pause inside samples), and whatever the thread count of a
 * campaign or where a campaign is resumed. Plus a regression pin of the current numerics.
 *
 * Scene: the paper-fig4 preset (γ̃ = 0.229, k̃ = 0.1, m̃ = 0.01, k_BT̃ = 0.01, thermal: every step
 * draws random numbers) with the piezo speed raised to ṽ = 1e-2 to keep each curve short
 * (~2e5 steps).
 */
#include "harness.h"

#include <inttypes.h>

#include "vafm/campaign.h"
#include "vafm/integrator.h"
#include "vafm/params.h"
#include "vafm/sim.h"
#include "vafm/units.h"

#include "trace.h"
#include "campaign_spec.h"

static void t_scene(vafm_params *p)
{
    vafm_preset_apply(p, "paper-fig4", NULL);
    vafm_reduced r;
    vafm_units_reduce(p, &r);
    r.v_approach = r.v_retract = 1e-2;
    vafm_units_from_reduced(p, &r);
}

static int t_run(const vafm_params *p, uint64_t index, t_trace *t, vafm_curve_result *res)
{
    vafm_sim *s = NULL;
    int r = vafm_sim_new(&s, p, NULL);
    if (r)
        return r;
    memset(t, 0, sizeof *t);
    t->order_ok = 1;
    r = vafm_sim_curve(s, index, t_collect, t, res);
    vafm_sim_destroy(&s);
    return r;
}

/* Two sim objects, same (seed, index): same bytes and results. A different index or seed: different. */
static void test_two_sims(void)
{
    vafm_params p;
    t_scene(&p);
    t_trace a, b, c;
    vafm_curve_result ra, rb, rc;
    ENSURE(t_run(&p, 3, &a, &ra) == 0);
    ENSURE(t_run(&p, 3, &b, &rb) == 0);
    ENSURE(a.n > 100 && a.order_ok && b.order_ok);
    ENSURE(a.n == ra.samples);
    ENSURE(t_trace_same(&a, &b));
    ENSURE(t_result_same(&ra, &rb));
    ENSURE(ra.flags == 0 && isfinite(ra.detach_force_N)); /* a normal curve, so the check has content */
    t_trace_free(&b);

    ENSURE(t_run(&p, 4, &c, &rc) == 0); /* another stream */
    ENSURE(!t_trace_same(&a, &c));
    t_trace_free(&c);
    p.seed = 2;
    ENSURE(t_run(&p, 3, &c, &rc) == 0); /* another seed */
    ENSURE(!t_trace_same(&a, &c));
    t_trace_free(&c);

    /* one sim object reused: running other curves in between does not leak state into curve 3 */
    t_scene(&p);
    vafm_sim *s = NULL;
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    vafm_curve_result tmp;
    ENSURE(vafm_sim_curve(s, 7, NULL, NULL, &tmp) == 0);
    ENSURE(vafm_sim_tune(s, 1, NULL, NULL) == 0); /* and a tune scene */
    memset(&b, 0, sizeof b);
    b.order_ok = 1;
    ENSURE(vafm_sim_curve(s, 3, t_collect, &b, &rb) == 0);
    ENSURE(t_trace_same(&a, &b));
    ENSURE(t_result_same(&ra, &rb));
    vafm_sim_destroy(&s);
    ENSURE(s == NULL);
    t_trace_free(&a);
    t_trace_free(&b);
}

/* A new sim object with curve `index` begun and an empty trace for it. */
static vafm_sim *t_begin(const vafm_params *p, uint64_t index, t_trace *t)
{
    vafm_sim *s = NULL;
    ENSURE(vafm_sim_new(&s, p, NULL) == 0);
    ENSURE(s && vafm_sim_curve_begin(s, index) == 0);
    memset(t, 0, sizeof *t);
    t->order_ok = 1;
    return s;
}

/* Pulling the curve in blocks of 7 samples (or 1, or 1000) gives the same bytes as one go. */
static void test_blocks(void)
{
    vafm_params p;
    t_scene(&p);
    t_trace whole;
    vafm_curve_result rw;
    ENSURE(t_run(&p, 11, &whole, &rw) == 0);
    const size_t sizes[] = {7, 1, 1000};
    for (size_t k = 0; k < sizeof sizes / sizeof sizes[0]; k++) {
        t_trace t;
        vafm_sim *s = t_begin(&p, 11, &t);
        int r, calls = 0;
        while ((r = vafm_sim_advance(s, sizes[k], t_collect, &t)) == 1)
            calls++;
        ENSURE(r == 0);
        ENSURE(calls >= (int)(whole.n / sizes[k]) - 1);
        ENSURE(t.order_ok);
        ENSURE_MSG(t_trace_same(&whole, &t), "blocks of %zu differ", sizes[k]);
        vafm_curve_result rb;
        ENSURE(vafm_sim_result(s, &rb) == 0);
        ENSURE(t_result_same(&rw, &rb));
        /* the scene is over: advancing further does nothing */
        ENSURE(vafm_sim_advance(s, 10, t_collect, &t) == 0);
        ENSURE(t.n == whole.n);
        vafm_sim_destroy(&s);
        t_trace_free(&t);
    }
    /* advancing before any scene began is a state error */
    vafm_sim *s = NULL;
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    ENSURE(vafm_sim_advance(s, 10, NULL, NULL) == VAFM_ESTATE);
    vafm_sim_destroy(&s);
    t_trace_free(&whole);
}

/* Pulling the curve by step budgets (vafm_sim_advance_steps: pauses inside output samples) gives the same
 * bytes and result as one go, for every integrator, with exact free and well steps and the adaptive step
 * in play; budgets of 1, 7 and 1000 steps, and a cycle of 0 (no progress), 3, 64 with 5 samples at most.
 * Calls that pause mid-sample must happen (the check has content): at least one call per 1000 steps. */
static void test_step_budget(void)
{
    const vafm_integrator_type *const its[] = { vafm_integrator_gjf, vafm_integrator_baoab,
                                                vafm_integrator_paper_vv, vafm_integrator_brownian };
    for (size_t k = 0; k < sizeof its / sizeof its[0]; k++) {
        vafm_params p;
        t_scene(&p);
        if (its[k] == vafm_integrator_brownian)
            vafm_preset_apply(&p, "paper-fig4-bd", NULL);
        else
            p.integrator = its[k];
        if (k == 1)
            p.omega_dt_far = 1.0; /* the adaptive step too */
        t_trace whole;
        vafm_curve_result rw;
        ENSURE(t_run(&p, 5, &whole, &rw) == 0);
        const uint64_t budgets[][3] = { { 1, 1, 1 }, { 7, 7, 7 }, { 1000, 1000, 1000 }, { 0, 3, 64 } };
        for (size_t b = 0; b < sizeof budgets / sizeof budgets[0]; b++) {
            if (LONG_OR(0, 1) && budgets[b][0] == 1)
                continue; /* sanitizer build: one step a call is slow, 7 covers the same paths */
            t_trace t;
            vafm_sim *s = t_begin(&p, 5, &t);
            int r;
            uint64_t calls = 0;
            while ((r = vafm_sim_advance_steps(s, b == 3 ? 5 : 1u << 20, budgets[b][calls % 3], t_collect, &t)) == 1)
                calls++;
            ENSURE(r == 0);
            ENSURE(t.order_ok);
            ENSURE_MSG(t_trace_same(&whole, &t), "%s, budgets %llu: samples differ", its[k]->name,
                       (unsigned long long)budgets[b][1]);
            vafm_curve_result rb;
            ENSURE(vafm_sim_result(s, &rb) == 0);
            ENSURE_MSG(t_result_same(&rw, &rb), "%s, budgets %llu: result differs", its[k]->name,
                       (unsigned long long)budgets[b][1]);
            ENSURE(calls + 1 >= rw.steps / 1000);
            vafm_sim_destroy(&s);
            t_trace_free(&t);
        }
        t_trace_free(&whole);
    }
}

/* ---- campaigns -------------------------------------------------------------------------------- */

#define T_NCURVES 12

typedef struct t_camp {
    uint64_t next;      /* expected next index */
    int order_ok;
    size_t n;
    vafm_curve_result res[2 * T_NCURVES];
    uint64_t hash[2 * T_NCURVES];
    int status[2 * T_NCURVES];
} t_camp;

static int t_camp_fn(void *user, const vafm_campaign_curve *c)
{
    t_camp *t = user;
    if (c->index != t->next)
        t->order_ok = 0;
    t->next = c->index + 1;
    if (c->index < 2 * T_NCURVES) {
        t->res[c->index] = c->result;
        t->status[c->index] = c->status;
        t->hash[c->index] = t_samples_hash(&c->samples);
    }
    t->n++;
    return 0;
}

static void test_campaign_threads(void)
{
    vafm_params p;
    t_scene(&p);
    /* two grid points (two speeds) so that workers switch scenes */
    vafm_reduced r;
    vafm_units_reduce(&p, &r);
    const double v[2] = {p.v_retract_m_per_s, 2.0 * p.v_retract_m_per_s};
    vafm_campaign_spec spec = t_campaign_spec(NULL, 0, v, 2, T_NCURVES);
    spec.keep_samples = 1;
    ENSURE(vafm_campaign_points(&spec) == 2);

    static t_camp runs[3];
    const int threads[3] = {1, 2, 3};
    for (int k = 0; k < 3; k++) {
        memset(&runs[k], 0, sizeof runs[k]);
        runs[k].order_ok = 1;
        spec.threads = threads[k];
        vafm_error err = {0};
        ENSURE_MSG(vafm_campaign_run(&p, &spec, t_camp_fn, &runs[k], &err) == 0, "%s", err.message);
        ENSURE(runs[k].order_ok);
        ENSURE(runs[k].n == 2 * T_NCURVES);
    }
    for (int i = 0; i < 2 * T_NCURVES; i++) {
        ENSURE(runs[0].status[i] == 0);
        ENSURE(runs[0].res[i].index == (uint64_t)i);
        for (int k = 1; k < 3; k++) {
            ENSURE_MSG(t_result_same(&runs[0].res[i], &runs[k].res[i]), "curve %d: threads %d vs 1", i, threads[k]);
            ENSURE_MSG(runs[0].hash[i] == runs[k].hash[i], "curve %d samples: threads %d vs 1", i, threads[k]);
        }
    }
    /* a campaign curve is the same as the curve run alone with the point's scene and the global index */
    vafm_params pp;
    ENSURE(vafm_campaign_point_params(&p, &spec, 1, &pp) == 0);
    ENSURE(pp.v_retract_m_per_s == v[1] && pp.v_approach_m_per_s == v[1]);
    t_trace t;
    vafm_curve_result rr;
    ENSURE(t_run(&pp, T_NCURVES + 2, &t, &rr) == 0);
    ENSURE(t_result_same(&rr, &runs[0].res[T_NCURVES + 2]));
    ENSURE(t_trace_hash(&t) == runs[0].hash[T_NCURVES + 2]);
    t_trace_free(&t);

    /* resumed at global index 5: curves 5.. equal the full run's, in order, none before 5 */
    static t_camp res5;
    memset(&res5, 0, sizeof res5);
    res5.order_ok = 1;
    res5.next = 5;
    spec.first_curve = 5;
    spec.threads = 2;
    ENSURE(vafm_campaign_run(&p, &spec, t_camp_fn, &res5, NULL) == 0);
    ENSURE(res5.order_ok);
    ENSURE(res5.n == 2 * T_NCURVES - 5);
    for (int i = 5; i < 2 * T_NCURVES; i++) {
        ENSURE_MSG(t_result_same(&runs[0].res[i], &res5.res[i]), "resumed curve %d differs", i);
        ENSURE(runs[0].hash[i] == res5.hash[i]);
    }
    /* resuming beyond the end is refused, naming first_curve */
    vafm_error err = {0};
    spec.first_curve = 2 * T_NCURVES + 1;
    ENSURE(vafm_campaign_run(&p, &spec, t_camp_fn, &res5, &err) == VAFM_EINVAL);
    ENSURE(!strcmp(err.field, "first_curve"));
}

/* A callback that stops the campaign gets VAFM_EABORT and no curve after the one that stopped it. */
static int t_stop_at_3(void *user, const vafm_campaign_curve *c)
{
    uint64_t *last = user;
    *last = c->index;
    return c->index == 3;
}

static void test_campaign_stop(void)
{
    vafm_params p;
    t_scene(&p);
    vafm_campaign_spec spec = t_campaign_spec(NULL, 0, NULL, 0, T_NCURVES);
    spec.threads = 2;
    uint64_t last = 0;
    vafm_error err = {0};
    ENSURE(vafm_campaign_run(&p, &spec, t_stop_at_3, &last, &err) == VAFM_EABORT);
    ENSURE(last == 3);
}

/* Regression pin of the current implementation: the FNV-1a hash of all sample bytes of paper-fig4
 * curve 0, seed 1, at ṽ = 1e-2. It is not a physics check; it changes only when the numerics change
 * on purpose (integrator, time-step rule, RNG, sampling), and then is re-pinned from the printed value.
 * The build uses -ffp-contract=off, so optimisation level and sanitizers do not change it; a different
 * libm (exp/log in the RNG's rare paths, cbrt, sqrt) might. Re-pinned 2026-11-22: box-car samples of
 * the exact free propagation now integrate the path (three normals per free step instead of two).
 * Re-pinned 2026-11-22 (second time): the exact well step now applies from 8 integrator steps per
 * sample (closed-form transition, Newton equilibrium, quasi-harmonic stiffness; before: from 256), and
 * this scene has ~204. */
#define T_GOLDEN_HASH UINT64_C(0x948a00d6629b9afc)

static void test_golden(void)
{
    vafm_params p;
    t_scene(&p);
    p.seed = 1;
    t_trace t;
    vafm_curve_result r;
    ENSURE(t_run(&p, 0, &t, &r) == 0);
    uint64_t h = t_trace_hash(&t);
    fprintf(stderr, "golden: paper-fig4 (v = 1e-2) curve 0 seed 1: %zu samples, FNV-1a 0x%016" PRIx64 "\n", t.n, h);
    ENSURE_MSG(h == T_GOLDEN_HASH, "hash 0x%016" PRIx64 " != pinned 0x%016" PRIx64 " (re-pin only if the numerics "
               "changed on purpose)", h, T_GOLDEN_HASH);
    t_trace_free(&t);
}

int main(void)
{
    RUN_TEST(test_two_sims);
    RUN_TEST(test_blocks);
    RUN_TEST(test_step_budget);
    RUN_TEST(test_campaign_threads);
    RUN_TEST(test_campaign_stop);
    RUN_TEST(test_golden);
    return harness_done();
}
