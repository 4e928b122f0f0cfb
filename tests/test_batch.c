/* SPDX-License-Identifier: MIT */
/*
 * The batch kernel (src/core/batch.h) against the scalar kernel, bit for bit.
 *
 * 1. Lanes: kernels taken from running curves where they wait for the batch (in contact on the table, and
 *    out of contact), plus made-up hard lanes (a point beyond the contact table, a touch, a detachment,
 *    no temperature, uniform noise, a stiffer spring), run for step counts that cross the kernel's
 *    64-step chunks, side by side in batches of 1, 4 and 8 lanes: every lane must end in exactly the
 *    state (and with exactly the random stream) that the scalar gjf loop leaves for the same steps.
 * 2. Campaigns: a T × v grid of paper-fig4 curves (ṽ = 1e-2, short curves) with every sample kept, run by
 *    the scalar kernel and by the batch kernel at 1, 4 and 8 lanes (those the CPU has) and 1 and 2
 *    threads: every sample and every ground-truth row must be the same bytes.
 * 3. Kernel names and widths.
 * 4. The scalar table loop compiled for SSE4.1 (core/kernel.h, VAFM_KLOOP_TABLE41) against the baseline
 *    loop: whole curves of every integrator on paper-fig4 (ṽ = 1e-2) and of the underdamped ones on
 *    contact-silica, the same bytes.
 * 5. The backend table (core/backend.h): each row the CPU runs gives whole curves the same bytes as the
 *    scalar row, run alone (the wider rows masked off as on an older CPU); a row masked off is refused by
 *    name, never chosen by a width, and vafm_batch_steps() runs the scalar row for its width; the kernel
 *    names are the table's.
 */
#include "harness.h"

#include "campaign_spec.h"
#include "trace.h"
#include "vafm/campaign.h"
#include "vafm/integrator.h"
#include "vafm/params.h"
#include "vafm/sim.h"
#include "vafm/units.h"
#include "core/backend.h"
#include "core/batch.h"
#include "core/kernel.h"

static void t_scene(vafm_params *p, double v_red)
{
    vafm_preset_apply(p, "paper-fig4", NULL);
    vafm_reduced r;
    vafm_units_reduce(p, &r);
    r.v_approach = r.v_retract = v_red;
    vafm_units_from_reduced(p, &r);
}

/* ---- 1. lanes ---------------------------------------------------------------------------------- */

#define T_MAXL 40

/* Kernels of one curve at n of its waits for the batch, spread evenly over the curve (it runs on in between):
 * *n_in of them in contact. */
static int t_harvest(vafm_sim *s, uint64_t index, vafm_kernel *out, int n, int *n_in)
{
    long waits = 0, got = 0;
    for (int pass = 0; pass < 2; pass++) {
        const long stride = pass ? waits / n + 1 : 0;
        long seen = 0;
        ENSURE(vafm_sim_curve_begin(s, index) == 0);
        for (;;) {
            int r = vafm_sim_advance_batch(s, 1u << 20, NULL, NULL);
            if (r != VAFM_SIM_BATCH_WAIT)
                break;
            long want, done;
            vafm_kernel *K = vafm_sim_batch_kernel(s, &want);
            if (pass && seen % stride == stride / 2 && got < n) {
                out[got++] = *K;
                *n_in += K->in_contact;
            }
            seen++;
            vafm_batch_steps(&K, &want, &done, 1, 1);
            vafm_sim_batch_done(s, done);
        }
        waits = seen;
    }
    return (int)got;
}

/* The lanes' end states equal, and their streams too (the next 24 normals of each, from copies). */
static int t_same_kernel(const vafm_kernel *a, const vafm_kernel *b)
{
#define T_EQ(f) (memcmp(&a->f, &b->f, sizeof a->f) == 0)
    int same = T_EQ(u) && T_EQ(w) && T_EQ(s) && T_EQ(Fc) && T_EQ(f) && T_EQ(u_spr) && T_EQ(t) && T_EQ(n) && T_EQ(acc_u) &&
               T_EQ(acc_uspr) && T_EQ(acc_n) && T_EQ(fs_min) && T_EQ(in_contact) && T_EQ(event) && T_EQ(steps) &&
               T_EQ(steps_contact);
#undef T_EQ
    vafm_kernel ca = *a, cb = *b;
    for (int i = 0; same && i < 24; i++) {
        double x = s_kernel_normal(&ca), y = s_kernel_normal(&cb);
        same = memcmp(&x, &y, sizeof x) == 0;
    }
    return same;
}

static void test_lanes(void)
{
    vafm_params p;
    vafm_kernel base[T_MAXL];
    int n = 0, n_in = 0;
    vafm_sim *sims[4] = { NULL, NULL, NULL, NULL };
    /* paper-fig4 at two speeds, a stiffer spring (other table and constants), and uniform noise */
    for (int k = 0; k < 4; k++) {
        t_scene(&p, k == 1 ? 1e-3 : 1e-2);
        if (k == 2)
            p.k_N_per_m *= 2.0;
        if (k == 3)
            p.noise = VAFM_NOISE_UNIFORM;
        ENSURE(vafm_sim_new(&sims[k], &p, NULL) == 0);
        n += t_harvest(sims[k], 3 + (uint64_t)k, base + n, 8, &n_in);
    }
    ENSURE(n == 32);
    ENSURE(n_in >= 8 && n - n_in >= 4); /* lanes in and out of contact */
    /* hard lanes, made from harvested ones */
    int far = -1, touch = -1, detach = -1, cold = -1;
    for (int i = 0; i < n; i++) {
        if (base[i].in_contact && far < 0)
            far = i;
        else if (base[i].in_contact && detach < 0)
            detach = i;
        else if (!base[i].in_contact && touch < 0)
            touch = i;
        else if (base[i].in_contact && cold < 0)
            cold = i;
    }
    ENSURE(far >= 0 && touch >= 0 && detach >= 0 && cold >= 0);
    if (far < 0 || touch < 0 || detach < 0 || cold < 0)
        goto out;
    {
        vafm_kernel *K = &base[far]; /* beyond the table's end: the exact solver for that lane */
        const double h = 1.0 / K->jtab->inv_h, x = (double)(K->jtab->n - 1) * h;
        K->u = K->contact.u_detach + 1.05 * x * x;
        K = &base[touch]; /* just outside, moving in fast */
        K->u = K->contact.u_touch - 1e-3;
        K->w = 50.0;
        K = &base[detach]; /* just inside, moving out fast */
        K->u = K->contact.u_detach + 1e-4;
        K->w = -50.0;
        base[cold].thermal = 0; /* no random numbers */
    }
    const long wants[] = { 1, 5, 63, 64, 65, 130, 200, 17 };
    long want[T_MAXL], d_ref[T_MAXL], d[T_MAXL];
    vafm_kernel ref[T_MAXL], lane[T_MAXL];
    vafm_kernel *lp[T_MAXL];
    for (int i = 0; i < n; i++) {
        want[i] = wants[i % 8];
        ref[i] = base[i];
        long left = want[i], done = 0;
        while (left > 0) { /* the scalar loop as a scene runs it: a run ends at a contact change */
            long r = vafm_integrator_gjf->run(&ref[i], left);
            done += r;
            left -= r;
            if (ref[i].event)
                break;
        }
        d_ref[i] = done;
    }
    int events = 0, touched = 0, far_ok = 0;
    for (int i = 0; i < n; i++) {
        events += ref[i].event != 0;
        touched += ref[i].event > 0;
    }
    { /* the far lane's first step ends beyond the table (so its force came from the exact solver) */
        vafm_kernel one = base[far];
        vafm_integrator_gjf->run(&one, 1);
        far_ok = sqrt(one.u - one.contact.u_detach) * one.jtab->inv_h >= (double)(one.jtab->n - 1);
    }
    ENSURE_MSG(events >= 2 && touched >= 1 && far_ok, "events %d touched %d far %d", events, touched,
               far_ok); /* the hard paths ran (detach, touch, beyond the table) */
    const int widths[] = { 1, 4, 8 };
    for (int wi = 0; wi < 3; wi++) {
        const int W = vafm_batch_width(widths[wi]);
        if (W != widths[wi])
            continue; /* not on this CPU */
        for (int i = 0; i < n; i++) {
            lane[i] = base[i];
            lp[i] = &lane[i];
        }
        vafm_batch_steps(lp, want, d, n, W);
        for (int i = 0; i < n; i++) {
            ENSURE_MSG(d[i] == d_ref[i], "W %d lane %d: %ld steps, scalar %ld", W, i, d[i], d_ref[i]);
            ENSURE_MSG(t_same_kernel(&lane[i], &ref[i]), "W %d lane %d (in contact %d, want %ld): state differs", W, i,
                       base[i].in_contact, want[i]);
        }
    }
out:
    for (int k = 0; k < 4; k++)
        vafm_sim_destroy(&sims[k]);
}

/* ---- 2. campaigns ------------------------------------------------------------------------------ */

typedef struct t_camp {
    size_t n;
    t_trace tr[16];
    vafm_curve_result res[16];
    int status[16];
} t_camp;

static int t_camp_fn(void *user, const vafm_campaign_curve *c)
{
    t_camp *cp = user;
    if (cp->n >= 16)
        return 1;
    t_trace *t = &cp->tr[cp->n];
    memset(t, 0, sizeof *t);
    t->order_ok = 1;
    t_collect(t, &c->samples);
    cp->res[cp->n] = c->result;
    cp->status[cp->n] = c->status;
    cp->n++;
    return 0;
}

static void t_camp_free(t_camp *c)
{
    for (size_t i = 0; i < c->n; i++)
        t_trace_free(&c->tr[i]);
    c->n = 0;
}

static void test_campaigns(void)
{
    vafm_params p;
    t_scene(&p, 1e-2);
    const double T[2] = { p.T_K, 2.0 * p.T_K };
    const double v[2] = { p.v_retract_m_per_s, 0.5 * p.v_retract_m_per_s };
    vafm_campaign_spec sp = t_campaign_spec(T, 2, v, 2, 4);
    sp.keep_samples = 1;
    sp.threads = 1;
    sp.kernel = VAFM_CAMPAIGN_KERNEL_SCALAR;
    static t_camp ref, got;
    ENSURE(vafm_campaign_run(&p, &sp, t_camp_fn, &ref, NULL) == 0);
    ENSURE(ref.n == 16);
    const int widths[] = { 1, 4, 8 };
    for (int wi = 0; wi < 3; wi++) {
        if (vafm_batch_width(widths[wi]) != widths[wi])
            continue;
        for (int threads = 1; threads <= 2; threads++) {
            sp.kernel = VAFM_CAMPAIGN_KERNEL_BATCH;
            sp.batch_width = widths[wi];
            sp.threads = threads;
            ENSURE(vafm_campaign_kernel_width(&sp) == widths[wi]);
            ENSURE(vafm_campaign_run(&p, &sp, t_camp_fn, &got, NULL) == 0);
            ENSURE(got.n == ref.n);
            for (size_t i = 0; i < got.n && i < ref.n; i++) {
                ENSURE_MSG(t_trace_same(&got.tr[i], &ref.tr[i]) && got.tr[i].n > 100,
                           "W %d, %d thread(s): curve %zu's samples differ", widths[wi], threads, i);
                ENSURE_MSG(t_result_same(&got.res[i], &ref.res[i]) && got.status[i] == ref.status[i],
                           "W %d, %d thread(s): curve %zu's result differs", widths[wi], threads, i);
            }
            t_camp_free(&got);
        }
    }
    /* the check has content: contact, detachment, a pull-off */
    ENSURE(ref.res[0].steps_contact > 1000 && isfinite(ref.res[0].detach_force_N) && ref.res[0].pulloff_spring_N > 0);
    t_camp_free(&ref);
}

/* A scene with a piezo actuator model: the campaign hands each curve's actual piezo height over (the
 * files' "height (measured)"), the same as a single curve's, with either kernel. Before 0.6 it handed
 * none, and `vafm campaign` refused such a scene's first curve (its tip position did not match). */
typedef struct t_hm {
    int n, ok;
    double *ref;
    size_t nref;
} t_hm;

static int t_hm_fn(void *user, const vafm_campaign_curve *c)
{
    t_hm *h = user;
    if (c->index == 1)
        h->ok = c->samples.height_measured_m && c->samples.n == h->nref &&
                !memcmp(c->samples.height_measured_m, h->ref, h->nref * sizeof(double));
    h->n++;
    return 0;
}

static int t_hm_collect(void *user, const vafm_samples *b)
{
    t_hm *h = user;
    if (!b->height_measured_m)
        return 1;
    double *p = realloc(h->ref, (h->nref + b->n) * sizeof(double));
    if (!p)
        return 1;
    h->ref = p;
    memcpy(h->ref + h->nref, b->height_measured_m, b->n * sizeof(double));
    h->nref += b->n;
    return 0;
}

static void test_campaign_measured_height(void)
{
    vafm_params p;
    vafm_preset_apply(&p, "contact-silica", NULL);
    p.piezo_hysteresis = 0.05;
    t_hm h;
    memset(&h, 0, sizeof h);
    vafm_sim *s = NULL;
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    ENSURE(vafm_sim_curve(s, 1, t_hm_collect, &h, NULL) == 0 && h.nref > 100);
    vafm_sim_destroy(&s);
    for (int k = VAFM_CAMPAIGN_KERNEL_SCALAR; k <= VAFM_CAMPAIGN_KERNEL_BATCH; k++) {
        vafm_campaign_spec sp = t_campaign_spec(NULL, 0, NULL, 0, 3);
        sp.keep_samples = 1;
        sp.threads = 1;
        sp.kernel = k;
        h.n = h.ok = 0;
        ENSURE(vafm_campaign_run(&p, &sp, t_hm_fn, &h, NULL) == 0);
        ENSURE_MSG(h.n == 3 && h.ok, "kernel %d: curve 1's measured height differs from the single curve's", k);
    }
    free(h.ref);
}

/* ---- 4. the SSE4.1 table loop ------------------------------------------------------------------ */

static void test_table_loop_isa(void)
{
    const int has = s_kernel_sse41();
    printf("  this CPU runs the %s table loop\n", has ? "SSE4.1" : "baseline");
    const char *scenes[2] = {"paper-fig4", "contact-silica"};
    int curves = 0;
    for (int si = 0; si < 2; si++)
        for (int ii = 0; ii < vafm_integrator_count(); ii++) {
            vafm_params p;
            if (si == 0)
                t_scene(&p, 1e-2);
            else
                vafm_preset_apply(&p, scenes[si], NULL);
            p.integrator = vafm_integrator_at(ii);
            if (si == 1 && p.integrator->overdamped)
                continue; /* brownian on contact-silica: ~1 min a curve at its own tiny step */
            for (uint64_t idx = 0; idx < 2; idx++) {
                t_trace tr[2];
                vafm_curve_result res[2];
                for (int b = 0; b < 2; b++) {
                    memset(&tr[b], 0, sizeof tr[b]);
                    vafm_kernel_baseline = b;
                    vafm_sim *s = NULL;
                    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
                    ENSURE(vafm_sim_curve(s, idx, t_collect, &tr[b], &res[b]) == 0);
                    vafm_sim_destroy(&s);
                }
                vafm_kernel_baseline = 0;
                ENSURE_MSG(tr[0].n > 100 && res[0].steps_contact > 1000, "%s %s: %zu samples", scenes[si],
                           p.integrator->name, tr[0].n);
                ENSURE_MSG(t_trace_same(&tr[0], &tr[1]) && t_result_same(&res[0], &res[1]),
                           "%s %s curve %llu: the SSE4.1 and baseline table loops differ", scenes[si],
                           p.integrator->name, (unsigned long long)idx);
                curves++;
                t_trace_free(&tr[0]);
                t_trace_free(&tr[1]);
            }
        }
    printf("  %d curves, the same bytes with both loops\n", curves);
}

/* ---- 3. names ---------------------------------------------------------------------------------- */

static void test_names(void)
{
    vafm_campaign_spec sp;
    memset(&sp, 0, sizeof sp);
    const int max = vafm_batch_width_max();
    ENSURE(max == 1 || max == 4 || max == 8);
    ENSURE(vafm_campaign_kernel_width(&sp) == max); /* auto: the widest */
    ENSURE(vafm_campaign_kernel_parse("scalar", &sp) == 0 && vafm_campaign_kernel_width(&sp) == 1);
    ENSURE(!strcmp(vafm_campaign_kernel_describe(&sp), "scalar"));
    ENSURE(vafm_campaign_kernel_parse("batch8", &sp) == 0 && sp.kernel == VAFM_CAMPAIGN_KERNEL_BATCH);
    ENSURE(vafm_campaign_kernel_width(&sp) == (max >= 8 ? 8 : max)); /* capped at the CPU's */
    ENSURE(vafm_campaign_kernel_parse("batch4", &sp) == 0 && vafm_campaign_kernel_width(&sp) == (max >= 4 ? 4 : 1));
    ENSURE(vafm_campaign_kernel_parse("fast", &sp) == VAFM_EINVAL && sp.batch_width == 4); /* unchanged */
    ENSURE(vafm_campaign_kernel_parse(NULL, &sp) == VAFM_EINVAL);
    ENSURE(vafm_batch_width(3) == 1 && vafm_batch_width(0) == max);
    /* a spec with another kernel or width is refused by name before anything runs */
    vafm_params p;
    t_scene(&p, 1e-2);
    vafm_error err;
    memset(&err, 0, sizeof err);
    sp.curves_per_point = 1;
    sp.kernel = 3;
    ENSURE(vafm_campaign_run(&p, &sp, NULL, NULL, &err) == VAFM_EINVAL && !strcmp(err.field, "kernel"));
    sp.kernel = VAFM_CAMPAIGN_KERNEL_BATCH;
    sp.batch_width = 2;
    ENSURE(vafm_campaign_run(&p, &sp, NULL, NULL, &err) == VAFM_EINVAL && !strcmp(err.field, "batch_width"));
    printf("batch kernel on this CPU: up to %d lanes\n", max);
}

/* ---- 5. the backend table ---------------------------------------------------------------------- */

static void test_backends(void)
{
    const int nb = vafm_backend_count();
    ENSURE(nb >= 3);
    ENSURE(!strcmp(vafm_backend_at(0)->name, "scalar") && vafm_backend_at(0)->lanes == 1 && vafm_backend_usable(0));
    ENSURE(vafm_backend_at(nb) == NULL && vafm_backend_at(-1) == NULL);
    char want_names[128] = "auto, scalar, batch";
    for (int i = 1; i < nb; i++) {
        const vafm_backend *b = vafm_backend_at(i);
        ENSURE_MSG(b->lanes > vafm_backend_at(i - 1)->lanes, "row %d (%s): rows go narrowest first", i, b->name);
        ENSURE(vafm_batch_lanes_per_call(b->lanes) >= b->lanes && b->available && b->describe);
        snprintf(want_names + strlen(want_names), sizeof want_names - strlen(want_names), ", batch%d", b->lanes);
    }
    /* the kernel names are the table's: each parses to its row's width */
    char names[128];
    ENSURE(vafm_campaign_kernel_names(names, sizeof names, ", ") == 0);
    ENSURE_MSG(!strcmp(names, want_names), "kernel names '%s', want '%s'", names, want_names);
    ENSURE(vafm_campaign_kernel_names(names, 8, ", ") == VAFM_EINVAL);
    vafm_campaign_spec sp;
    memset(&sp, 0, sizeof sp);
    for (int i = 1; i < nb; i++) {
        char nm[16];
        snprintf(nm, sizeof nm, "batch%d", vafm_backend_at(i)->lanes);
        ENSURE_MSG(vafm_campaign_kernel_parse(nm, &sp) == 0 && sp.batch_width == vafm_backend_at(i)->lanes, "%s", nm);
    }
    const char *bad[] = { "batch2", "batch16", "batch04", "batch4x", "batch", "avx512", "" };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
        ENSURE_MSG((vafm_campaign_kernel_parse(bad[i], &sp) == VAFM_EINVAL) == (i != 4), "'%s'", bad[i]);
    ENSURE(vafm_backend_find("nosuch", NULL) == VAFM_ENOTFOUND && vafm_backend_find(NULL, NULL) == VAFM_ENOTFOUND);

    /* whole curves: the reference, then each usable row alone (the rows above it masked off) */
    vafm_params p;
    t_scene(&p, 1e-2);
    const double T[2] = { p.T_K, 2.0 * p.T_K };
    sp = t_campaign_spec(T, 2, NULL, 0, 6);
    sp.keep_samples = 1;
    sp.threads = 1;
    sp.kernel = VAFM_CAMPAIGN_KERNEL_SCALAR;
    static t_camp ref, got;
    ENSURE(vafm_campaign_run(&p, &sp, t_camp_fn, &ref, NULL) == 0 && ref.n == 12);
    int ran = 0;
    for (int i = 0; i < nb; i++) {
        const vafm_backend *b = vafm_backend_at(i), *found = NULL;
        if (!vafm_backend_usable(i)) {
            printf("backend %s: not on this CPU\n", b->name);
            ENSURE(vafm_backend_find(b->name, &found) == VAFM_ENOTSUP && found == NULL);
            continue;
        }
        ENSURE(vafm_backend_find(b->name, &found) == 0 && found == b);
        vafm_backend_off = ~0u << (i + 1); /* as on a CPU whose widest row is i */
        ENSURE(vafm_batch_width_max() == b->lanes && vafm_batch_width(0) == b->lanes);
        for (int j = i + 1; j < nb; j++) { /* the rows above: refused by name, a width asking for them gets i */
            ENSURE_MSG(vafm_backend_find(vafm_backend_at(j)->name, &found) == VAFM_ENOTSUP && found == b,
                       "masked row %s was not refused", vafm_backend_at(j)->name);
            ENSURE(vafm_batch_width(vafm_backend_at(j)->lanes) == b->lanes);
        }
        sp.kernel = VAFM_CAMPAIGN_KERNEL_BATCH;
        sp.batch_width = 0; /* the widest: row i */
        ENSURE(vafm_campaign_kernel_width(&sp) == b->lanes);
        ENSURE(!strcmp(vafm_campaign_kernel_describe(&sp), b->describe));
        ENSURE(vafm_campaign_run(&p, &sp, t_camp_fn, &got, NULL) == 0);
        vafm_backend_off = 0;
        ENSURE(got.n == ref.n);
        for (size_t c = 0; c < got.n && c < ref.n; c++) {
            ENSURE_MSG(t_trace_same(&got.tr[c], &ref.tr[c]) && got.tr[c].n > 100, "row %s: curve %zu's samples differ",
                       b->name, c);
            ENSURE_MSG(t_result_same(&got.res[c], &ref.res[c]) && got.status[c] == ref.status[c],
                       "row %s: curve %zu's result differs", b->name, c);
        }
        t_camp_free(&got);
        ran++;
        printf("backend %s (%d lanes): %zu curves the same bytes as the scalar kernel's\n", b->name, b->lanes, ref.n);
    }
    ENSURE(ran >= 1);
    t_camp_free(&ref);

    /* vafm_batch_steps() at a width whose row is masked off runs the scalar row: the same end state as gjf's run */
    vafm_sim *s = NULL;
    vafm_kernel k0[2], k1[2];
    int n_in = 0;
    t_scene(&p, 1e-2);
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    ENSURE(t_harvest(s, 5, k0, 2, &n_in) == 2);
    memcpy(k1, k0, sizeof k0);
    vafm_kernel *kp[2] = { &k0[0], &k0[1] };
    const long want[2] = { 300, 77 };
    long done[2], done1[2];
    vafm_backend_off = ~1u; /* every vector row off */
    vafm_batch_steps(kp, want, done, 2, vafm_backend_at(nb - 1)->lanes);
    vafm_backend_off = 0;
    for (int l = 0; l < 2; l++) {
        done1[l] = vafm_integrator_gjf->run(&k1[l], want[l]);
        ENSURE(done[l] == done1[l] && t_same_kernel(&k0[l], &k1[l]));
    }
    vafm_sim_destroy(&s);
}

int main(void)
{
    RUN_TEST(test_names);
    RUN_TEST(test_lanes);
    RUN_TEST(test_campaigns);
    RUN_TEST(test_campaign_measured_height);
    RUN_TEST(test_table_loop_isa);
    RUN_TEST(test_backends);
    return harness_done();
}
