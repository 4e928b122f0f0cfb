/* SPDX-License-Identifier: MIT */
/*
 * The model registry (src/core/models.h) and the contact models' capability flags (contact.h).
 *
 * - the registry: lookup, listing and the parameters' choices all come from the one list;
 * - a dummy contact model defined here only (Hertz's hooks, its flags cleared) is bound and simulated
 *   like any model: without VAFM_CONTACT_WELL it is stepped by the integrator, never by the exact well
 *   step, sample for sample as Hertz without the well step; with the flag it is well-stepped like Hertz;
 * - the stiffness guard's threshold asks VAFM_CONTACT_MONOTONE, not which model it holds;
 * - the batch kernel is offered an integrator's steps by its batch_lanes, not by its being gjf.
 */
#include "harness.h"

#include "vafm/contact.h"
#include "vafm/integrator.h"
#include "vafm/params.h"
#include "vafm/sim.h"
#include "core/batch.h"
#include "core/guard.h"
#include "core/internal.h"
#include "core/kernel.h"

#include <stdint.h>

/* ---- the registry --------------------------------------------------------------------------- */

/* "a|b|c" from the names of a listing */
static void t_join(char *out, size_t cap, int n, const char *(*name_at)(int))
{
    out[0] = 0;
    for (int i = 0; i < n; i++) {
        if (i)
            strncat(out, "|", cap - strlen(out) - 1);
        strncat(out, name_at(i), cap - strlen(out) - 1);
    }
}

static const char *t_contact_name(int i)
{
    return vafm_contact_type_at(i)->name;
}

static const char *t_integrator_name(int i)
{
    return vafm_integrator_at(i)->name;
}

static void test_registry(void)
{
    const int nc = vafm_contact_type_count();
    ENSURE(nc >= 3);
    ENSURE(vafm_contact_type_at(-1) == NULL && vafm_contact_type_at(nc) == NULL);
    for (int i = 0; i < nc; i++) {
        const vafm_contact_type *t = vafm_contact_type_at(i);
        ENSURE(t && t->name && t->description && t->force && t->energy && t->init);
        /* the row's name is the object's name: lookup finds the object back */
        ENSURE_MSG(vafm_contact_type_find(t->name) == t, "%s", t->name);
        ENSURE_MSG(!(t->flags & VAFM_CONTACT_SURFACE) || t->at_force, "%s: a surface needs at_force", t->name);
        /* the capabilities that lean on JKR's branch are claimed only by models that have it or its c = 0 case */
        vafm_contact c;
        ENSURE(vafm_contact_init(&c, t, 0.0) == VAFM_OK);
    }
    /* the flags of the shipped models, as contact.h documents them */
    const unsigned all = VAFM_CONTACT_SURFACE | VAFM_CONTACT_ADHESIVE | VAFM_CONTACT_JKR_BRANCH | VAFM_CONTACT_WELL |
                         VAFM_CONTACT_MONOTONE;
    ENSURE(vafm_contact_jkr->flags == all);
    ENSURE(vafm_contact_hertz->flags == (VAFM_CONTACT_SURFACE | VAFM_CONTACT_WELL | VAFM_CONTACT_MONOTONE));
    ENSURE(vafm_contact_none->flags == 0 && vafm_contact_none->at_force == NULL);

    const int ni = vafm_integrator_count();
    ENSURE(ni >= 4);
    ENSURE(vafm_integrator_at(-1) == NULL && vafm_integrator_at(ni) == NULL);
    for (int i = 0; i < ni; i++) {
        const vafm_integrator_type *t = vafm_integrator_at(i);
        ENSURE(t && t->name && t->run && t->prepare && t->set_dt);
        ENSURE_MSG(vafm_integrator_find(t->name) == t, "%s", t->name);
        ENSURE(t->batch_lanes >= 0);
    }
    ENSURE(vafm_integrator_gjf->batch_lanes > 1);
    ENSURE(vafm_integrator_baoab->batch_lanes == 0 && vafm_integrator_brownian->batch_lanes == 0);

    /* the parameters' choices are the registry's names, in its order; the doc names each model */
    char buf[512];
    const vafm_param_info *f = vafm_params_field_find("contact");
    ENSURE(f && f->choices && f->doc);
    t_join(buf, sizeof buf, nc, t_contact_name);
    ENSURE_MSG(!strcmp(f->choices, buf), "choices '%s', registry '%s'", f->choices, buf);
    for (int i = 0; i < nc; i++)
        ENSURE(strstr(f->doc, vafm_contact_type_at(i)->name));
    f = vafm_params_field_find("integrator");
    ENSURE(f && f->choices && f->doc);
    t_join(buf, sizeof buf, ni, t_integrator_name);
    ENSURE_MSG(!strcmp(f->choices, buf), "choices '%s', registry '%s'", f->choices, buf);
    for (int i = 0; i < ni; i++)
        ENSURE(strstr(f->doc, vafm_integrator_at(i)->name));
    /* every name is accepted by the parameter it lists */
    vafm_params p;
    vafm_params_default(&p);
    for (int i = 0; i < nc; i++) {
        ENSURE(vafm_params_set(&p, "contact", vafm_contact_type_at(i)->name, NULL) == 0);
        ENSURE(p.contact == vafm_contact_type_at(i));
    }
    ENSURE(vafm_params_set(&p, "contact", "no-such-model", NULL) != 0);
}

/* ---- a dummy model: Hertz's hooks under a name of its own, with chosen flags ------------------- */

static int t_dummy_init(vafm_contact *c, double gamma)
{
    if (gamma != 0.0)
        return VAFM_EINVAL;
    c->u_touch = c->u_detach = 0.0;
    return VAFM_OK;
}

static vafm_contact_type t_dummy(unsigned flags)
{
    vafm_contact_type t = *vafm_contact_hertz;
    t.name = "dummy";
    t.description = "test only: Hertz's force under other flags";
    t.init = t_dummy_init;
    t.flags = flags;
    return t;
}

typedef struct {
    uint64_t hash; /* FNV-1a over the bits of every force and tip sample */
    size_t n;
} t_acc;

static int t_collect(void *user, const vafm_samples *b)
{
    t_acc *a = user;
    for (size_t i = 0; i < b->n; i++) {
        const double v[2] = {b->force_N[i], b->tip_m[i]};
        const unsigned char *x = (const unsigned char *)v;
        for (size_t j = 0; j < sizeof v; j++)
            a->hash = (a->hash ^ x[j]) * 1099511628211ull;
    }
    a->n += b->n;
    return 0;
}

/* paper-fig4's lever pressed 20 R into the sample at one sample per 20 /η (~2000 integrator steps per
 * sample: test_kernel's scene where the exact well step is used), a dwell of 200 samples */
static void t_run(const vafm_contact_type *ct, int well, uint64_t *steps, t_acc *a)
{
    vafm_params p;
    ENSURE(vafm_preset_apply(&p, "paper-fig4", NULL) == 0);
    p.contact = ct;
    p.gamma_J_per_m2 = 0.0;
    p.well_exact = well;
    p.trigger = VAFM_TRIGGER_HEIGHT;
    vafm_scale sc = vafm_units_scale(&p);
    p.start_height_m = -20.0 * sc.length_m; /* Hertz: deep enough for the well step's harmonic bounds */
    p.trigger_height_m = p.start_height_m - 1e-6 * sc.length_m;
    p.sample_rate_Hz = 1.0 / (20.0 * sc.time_s);
    p.dwell_s = 200.0 / p.sample_rate_Hz;
    vafm_error err;
    memset(&err, 0, sizeof err);
    vafm_sim *s = NULL;
    vafm_curve_result res;
    a->hash = 1469598103934665603ull;
    a->n = 0;
    ENSURE_MSG(vafm_sim_new(&s, &p, &err) == 0, "%s: %s", ct->name, err.message);
    if (!s)
        return;
    ENSURE(vafm_sim_curve(s, 3, t_collect, a, &res) == 0);
    vafm_sim_destroy(&s);
    *steps = res.steps;
}

static void test_dummy_never_well_steps(void)
{
    const vafm_contact_type plain = t_dummy(VAFM_CONTACT_SURFACE);
    const vafm_contact_type welled = t_dummy(VAFM_CONTACT_SURFACE | VAFM_CONTACT_WELL);
    uint64_t st_hw = 0, st_h = 0, st_plain = 0, st_welled = 0;
    t_acc a_hw, a_h, a_plain, a_welled;
    t_run(vafm_contact_hertz, 1, &st_hw, &a_hw);
    t_run(vafm_contact_hertz, 0, &st_h, &a_h);
    t_run(&plain, 1, &st_plain, &a_plain);
    t_run(&welled, 1, &st_welled, &a_welled);
    ENSURE(a_hw.n > 200 && a_h.n > 200 && a_plain.n == a_h.n && a_welled.n == a_hw.n);
    /* the scene is one where the well step is taken (Hertz with it: far fewer steps; the retract, integrated
     * either way, keeps the ratio above test_kernel's 1/5) ... */
    ENSURE_MSG(st_hw < st_h / 2, "hertz: well %llu steps, plain %llu", (unsigned long long)st_hw,
               (unsigned long long)st_h);
    /* ... but the model without the capability asked for it (well_exact = 1) and was integrated: the same
     * steps and the same samples, bit for bit, as Hertz without the well step */
    ENSURE_MSG(st_plain == st_h, "dummy without WELL: %llu steps, hertz integrated %llu", (unsigned long long)st_plain,
               (unsigned long long)st_h);
    ENSURE(a_plain.hash == a_h.hash);
    /* the flag, not the object, decides: with it the dummy is well-stepped exactly as Hertz */
    ENSURE_MSG(st_welled == st_hw, "dummy with WELL: %llu steps, hertz %llu", (unsigned long long)st_welled,
               (unsigned long long)st_hw);
    ENSURE(a_welled.hash == a_hw.hash);
}

/* The stiffness guard's shortcut (a threshold below which no contact solve is needed) is taken for a
 * model that declares its stiffness monotone, and for no other. */
static void test_guard_asks_flags(void)
{
    const vafm_contact_type mono = t_dummy(VAFM_CONTACT_SURFACE | VAFM_CONTACT_MONOTONE);
    const vafm_contact_type plain = t_dummy(VAFM_CONTACT_SURFACE);
    const vafm_contact_type *ts[3] = {vafm_contact_hertz, &mono, &plain};
    double thr[3];
    for (int i = 0; i < 3; i++) {
        vafm_contact c;
        ENSURE(vafm_contact_init(&c, ts[i], 0.0) == VAFM_OK);
        vafm_kernel K;
        memset(&K, 0, sizeof K);
        K.m = 0.01;
        K.k = 0.1;
        K.contact = c;
        K.cforce = c.type->force;
        vafm_kernel_set_dt(&K, 1e-3);
        thr[i] = vafm_guard_threshold(&K, vafm_integrator_gjf, 1e-3);
    }
    ENSURE(isfinite(thr[0]) && thr[0] > 0);
    ENSURE_MSG(thr[1] == thr[0], "monotone dummy %.17g, hertz %.17g", thr[1], thr[0]);
    ENSURE_MSG(thr[2] == -INFINITY, "dummy without MONOTONE: %.17g", thr[2]);
}

/* A model without its hooks cannot be bound (its touch and detach points are unknown). */
static void test_bind_needs_hooks(void)
{
    vafm_contact c;
    vafm_contact_type t = t_dummy(VAFM_CONTACT_SURFACE);
    t.init = NULL;
    ENSURE(vafm_contact_init(&c, &t, 0.0) == VAFM_EINVAL);
    t = t_dummy(VAFM_CONTACT_SURFACE);
    t.at_force = NULL;
    ENSURE(vafm_contact_init(&c, &t, 0.0) == VAFM_EINVAL);
    t.flags = 0; /* no surface: no branch to ask */
    ENSURE(vafm_contact_init(&c, &t, 0.0) == VAFM_OK);
    t = t_dummy(VAFM_CONTACT_SURFACE);
    ENSURE(vafm_contact_init(&c, &t, 0.1) == VAFM_EINVAL); /* its init hook refuses adhesion */
}

/* paper-fig4's default curve, stepped through vafm_sim_advance_batch (the campaign's path): how often
 * the simulation handed its steps to the batch kernel (run here at width 1), and the samples */
static long t_batch_run(const vafm_integrator_type *it, t_acc *a)
{
    vafm_params p;
    ENSURE(vafm_preset_apply(&p, "paper-fig4", NULL) == 0);
    p.integrator = it;
    vafm_sim *s = NULL;
    a->hash = 1469598103934665603ull;
    a->n = 0;
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    if (!s)
        return -1;
    ENSURE(vafm_sim_curve_begin(s, 5) == 0);
    long waits = 0;
    for (;;) {
        int r = vafm_sim_advance_batch(s, 1u << 20, t_collect, a);
        if (r == VAFM_SIM_BATCH_WAIT) {
            long want, done;
            vafm_kernel *K = vafm_sim_batch_kernel(s, &want);
            vafm_batch_steps(&K, &want, &done, 1, 1);
            vafm_sim_batch_done(s, done);
            waits++;
        } else if (r != 1) {
            ENSURE(r == 0);
            break;
        }
    }
    vafm_sim_destroy(&s);
    return waits;
}

static void test_batch_by_lanes(void)
{
    vafm_integrator_type with = *vafm_integrator_gjf, without = *vafm_integrator_gjf;
    with.name = "gjf-copy";
    without.name = "gjf-scalar";
    without.batch_lanes = 0;
    t_acc a_ref, a_with, a_without;
    const long w_ref = t_batch_run(vafm_integrator_gjf, &a_ref);
    const long w_with = t_batch_run(&with, &a_with);
    const long w_without = t_batch_run(&without, &a_without);
    ENSURE_MSG(w_ref > 0 && w_with == w_ref, "gjf handed out %ld runs, its copy %ld", w_ref, w_with);
    ENSURE_MSG(w_without == 0, "batch_lanes = 0 handed out %ld runs", w_without);
    /* either way the same curve: the batch kernel at width 1 is the scalar loop */
    ENSURE(a_ref.n > 100 && a_with.n == a_ref.n && a_without.n == a_ref.n);
    ENSURE(a_with.hash == a_ref.hash && a_without.hash == a_ref.hash);
}

/* The friction limit of an integrator (the paper's VV: η·dt < 2) is its own field: a copy of gjf that
 * declares one (0.25 here) is refused beyond it, gjf itself is not. paper-fig4's lever, free, at
 * dt = 0.3/η (ω·dt = 0.95, inside gjf's stability limit). */
static void test_eta_dt_limit(void)
{
    vafm_params p;
    ENSURE(vafm_preset_apply(&p, "paper-fig4", NULL) == 0);
    p.contact = vafm_contact_none;
    p.gamma_J_per_m2 = 0.0;
    p.free_exact = 0;
    vafm_scale sc = vafm_units_scale(&p);
    p.sample_rate_Hz = 1.0 / (1000.0 * sc.time_s);
    p.dt_s = 0.3 * sc.time_s;
    vafm_error err;
    memset(&err, 0, sizeof err);
    ENSURE_MSG(vafm_params_validate(&p, &err) == 0, "gjf at eta*dt = 0.3: %s", err.message);
    vafm_integrator_type lim = *vafm_integrator_gjf;
    lim.name = "gjf-limited";
    lim.eta_dt_limit = 0.25;
    p.integrator = &lim;
    memset(&err, 0, sizeof err);
    ENSURE(vafm_params_validate(&p, &err) == VAFM_EUNSTABLE && !strcmp(err.field, "dt_s"));
    ENSURE(strstr(err.message, "gjf-limited") != NULL);
    p.dt_s = 0.2 * sc.time_s;
    ENSURE(vafm_params_validate(&p, NULL) == 0);
    ENSURE(vafm_integrator_paper_vv->eta_dt_limit == 2.0 && vafm_integrator_gjf->eta_dt_limit == 0.0);
}

int main(void)
{
    RUN_TEST(test_registry);
    RUN_TEST(test_dummy_never_well_steps);
    RUN_TEST(test_guard_asks_flags);
    RUN_TEST(test_bind_needs_hooks);
    RUN_TEST(test_batch_by_lanes);
    RUN_TEST(test_eta_dt_limit);
    return harness_done();
}
