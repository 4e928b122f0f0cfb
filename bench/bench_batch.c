/* SPDX-License-Identifier: MIT */
/*
 * bench_batch: the batch kernel (src/core/batch.h) against the scalar kernel, measured in the same run.
 * It reports; it never fails on speed.
 *
 * 1. Lane steps: ns per curve-step of the in-contact plain gjf step (the near zone of the retract, where
 *    a curve's time goes) and of the out-of-contact one, for the scalar loop and the batch at 4 and 8 lanes
 *    (those the CPU has), on kernels taken from a paper-fig4 curve (ṽ = 1e-3) where it waits for the batch;
 *    16 lanes (two vectors of 8, or four of 4) run 200 steps per call. Median of S_REPS repetitions of
 *    ≥ 0.3 s each; CPU time of this process.
 * 2. Campaigns: curves per CPU-second of one thread, scalar against batch (the default: the widest), on the
 *    tools' presets, paper-fig1 and paper-fig4 at ṽ = 1e-3 and 1e-5, each with its own default numerics.
 *    Median of S_CREPS runs; the two kernels' results are compared (they must be the same bit for bit).
 * 3. The machine: this core's rate of independent vector multiplies and adds (8 chains, the widest vectors
 *    the CPU has), for a roofline: ops per curve-step against what the core did in the same run.
 * 4. Floors: what the in-contact step's own arithmetic costs on this core when nothing else runs, from the
 *    same kernel state: minimal loops of the batch kernel's common path (the same operations, the same
 *    table and its load, the contact tests; noise read from a buffer, no random numbers drawn, no masks,
 *    no chunks) for one curve (its latency) and for 1–4 vectors of 8 curves side by side (its throughput);
 *    and both kernels without random numbers (the same kernels at kT = 0). A kernel cannot beat its floor
 *    without different arithmetic, i.e. different curves.
 *
 * Usage: bench_batch [OUTDIR [quick]]: writes OUTDIR/bench_batch.csv and .md and prints the markdown.
 * "quick" runs fewer and shorter campaigns (a pipeline check).
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench_util.h"
#include "vafm/campaign.h"
#include "vafm/integrator.h"
#include "vafm/params.h"
#include "vafm/sim.h"
#include "vafm/units.h"
#include "core/batch.h"
#include "core/kernel.h"
#include "core/table8.h"

#define S_REPS 5
#define S_CREPS 3
#define S_MIN_REP_S 0.3
#define S_LANES 16
#define S_STEPS 200

static void s_scene(vafm_params *p, const char *preset, double v_red)
{
    vafm_preset_apply(p, preset, NULL);
    if (v_red > 0) {
        vafm_reduced r;
        vafm_units_reduce(p, &r);
        r.v_approach = r.v_retract = v_red;
        vafm_units_from_reduced(p, &r);
    }
}

/* ---- 1. lane steps ------------------------------------------------------------------------------- */

/* A kernel of curve 3 where it first waits for the batch in (in_contact) or out of contact. */
static int s_take_kernel(vafm_sim *s, int in_contact, vafm_kernel *out)
{
    if (vafm_sim_curve_begin(s, 3))
        return -1;
    for (;;) {
        if (vafm_sim_advance_batch(s, 1u << 20, NULL, NULL) != VAFM_SIM_BATCH_WAIT)
            return -1;
        long want, done;
        vafm_kernel *K = vafm_sim_batch_kernel(s, &want);
        if (K->in_contact == in_contact && (!in_contact || K->steps_contact > 1000)) {
            *out = *K;
            return 0;
        }
        vafm_batch_steps(&K, &want, &done, 1, 1);
        vafm_sim_batch_done(s, done);
    }
}

/* ns of CPU per lane-step at width W (1: the scalar gjf loop), median of S_REPS. */
static double s_lane_ns(const vafm_kernel *K0, int W)
{
    static vafm_kernel L[S_LANES];
    vafm_kernel *lp[S_LANES];
    long want[S_LANES], done[S_LANES];
    double ns[S_REPS];
    for (int r = -1; r < S_REPS; r++) { /* r = -1: warm-up */
        double t0 = bench_clock_s(CLOCK_PROCESS_CPUTIME_ID), t1;
        uint64_t steps = 0;
        do {
            for (int l = 0; l < S_LANES; l++) {
                L[l] = *K0;
                lp[l] = &L[l];
                want[l] = S_STEPS;
            }
            for (int k = 0; k < 20; k++) {
                vafm_batch_steps(lp, want, done, S_LANES, W);
                for (int l = 0; l < S_LANES; l++)
                    steps += (uint64_t)done[l];
            }
            t1 = bench_clock_s(CLOCK_PROCESS_CPUTIME_ID);
        } while (t1 - t0 < S_MIN_REP_S);
        if (r >= 0)
            ns[r] = 1e9 * (t1 - t0) / (double)steps;
    }
    return bench_median(ns, S_REPS);
}

/* ---- 2. campaigns -------------------------------------------------------------------------------- */

typedef struct s_acc {
    uint64_t n, steps, steps_contact;
    uint64_t hash; /* FNV-1a of every result's observables, to compare the kernels */
} s_acc;

static int s_cb(void *user, const vafm_campaign_curve *c)
{
    s_acc *a = user;
    const double obs[4] = { c->result.pulloff_spring_N, c->result.detach_force_N, c->result.duration_s,
                            (double)c->result.steps };
    const unsigned char *b = (const unsigned char *)obs;
    for (size_t i = 0; i < sizeof obs; i++) {
        a->hash ^= b[i];
        a->hash *= UINT64_C(0x100000001b3);
    }
    a->n++;
    a->steps += c->result.steps;
    a->steps_contact += c->result.steps_contact;
    return c->status != 0;
}

typedef struct s_crow {
    const char *label;
    unsigned n;
    double cps_scalar, cps_batch, ns_step_scalar, ns_step_batch, steps_per_curve, contact_frac;
    int same, ok;
} s_crow;

/* Curves per CPU-second of one thread with a kernel; returns 0 and fills *cps, *ns, *acc. */
static int s_campaign(const vafm_params *p, unsigned n, int kernel, double *cps, double *ns, s_acc *acc)
{
    vafm_campaign_spec sp;
    memset(&sp, 0, sizeof sp);
    sp.curves_per_point = n;
    sp.threads = 1;
    sp.kernel = kernel;
    double v[S_CREPS], w[S_CREPS];
    for (int r = 0; r < S_CREPS; r++) {
        memset(acc, 0, sizeof *acc);
        acc->hash = UINT64_C(0xcbf29ce484222325);
        double t0 = bench_clock_s(CLOCK_PROCESS_CPUTIME_ID);
        if (vafm_campaign_run(p, &sp, s_cb, acc, NULL) || acc->n != n)
            return -1;
        double t = bench_clock_s(CLOCK_PROCESS_CPUTIME_ID) - t0;
        v[r] = n / t;
        w[r] = 1e9 * t / (double)acc->steps;
    }
    *cps = bench_median(v, S_CREPS);
    *ns = bench_median(w, S_CREPS);
    return 0;
}

/* ---- 3. the core's vector rate ------------------------------------------------------------------- */

/* ns per vector operation (multiply or add) of 8 independent chains, and the lanes per vector. */
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
static volatile double s_opaque[2] = { 0.999999999, 1e-9 }; /* keeps the compiler from folding the loop */

__attribute__((target("avx512f"), noinline)) static double s_ops512(long n)
{
    __m512d a[8];
    for (int i = 0; i < 8; i++)
        a[i] = _mm512_set1_pd(1.0 + i * 1e-9);
    const __m512d m = _mm512_set1_pd(s_opaque[0]), c = _mm512_set1_pd(s_opaque[1]);
    for (long k = 0; k < n; k++)
        for (int i = 0; i < 8; i++)
            a[i] = _mm512_add_pd(_mm512_mul_pd(a[i], m), c);
    double s = 0;
    for (int i = 0; i < 8; i++)
        s += _mm512_reduce_add_pd(a[i]);
    return s;
}
#endif

static double s_vector_ns(int *lanes)
{
    *lanes = 1;
#if defined(__x86_64__) && defined(__GNUC__)
    if (vafm_batch_width_max() == 8) {
        double ns[S_REPS];
        volatile double sink = 0;
        for (int r = 0; r < S_REPS; r++) {
            const long n = 4000000;
            double t0 = bench_clock_s(CLOCK_PROCESS_CPUTIME_ID);
            sink += s_ops512(n);
            ns[r] = 1e9 * (bench_clock_s(CLOCK_PROCESS_CPUTIME_ID) - t0) / (16.0 * (double)n);
        }
        (void)sink;
        *lanes = 8;
        return bench_median(ns, S_REPS);
    }
#endif
    return NAN;
}

/* ---- 4. floors ---------------------------------------------------------------------------------- */

/* The common path's constants and start state of a kernel (batch_lanes.h's BLOAD for one lane). */
typedef struct s_fl {
    double dt, hdm, hdmdt, drift, sig, a, b, binvm, uspr0, vspr, kk, udet, invh, xend, sm, c2;
    const double *node;
    double u, w, s, Fc, hf, us, nd;
    double nz[S_STEPS]; /* the lane's noise, drawn once from its stream */
} s_fl;

static void s_fl_load(s_fl *c, const vafm_kernel *K0)
{
    vafm_kernel K = *K0;
    const vafm_kcoef co = K.co[1];
    vafm_kinv v;
    s_kinv_load(&K, &v);
    c->dt = K.dt;
    c->hdm = 0.5 * K.dt / K.m;
    c->hdmdt = c->hdm * K.dt;
    c->drift = K.m * K.v_spr;
    c->sig = K.thermal ? co.gjf_sig : 0.0;
    c->a = co.gjf_a;
    c->b = co.gjf_b;
    c->binvm = co.gjf_b * (1.0 / K.m);
    c->uspr0 = v.uspr0;
    c->vspr = v.v_spr;
    c->kk = v.k;
    c->udet = v.u_detach;
    c->invh = v.inv_h;
    c->xend = v.x_end;
    c->sm = v.s_m;
    c->c2 = v.c2;
    c->node = v.node;
    c->u = K.u;
    c->w = K.w;
    c->s = K.s;
    c->Fc = K.Fc;
    c->hf = K.f;
    c->us = K.u_spr;
    c->nd = (double)K.n;
    for (int j = 0; j < S_STEPS; j++)
        c->nz[j] = K.thermal ? s_kernel_noise(&K) : 0.0;
}

/* One curve: the chain of S_STEPS steps from the start state; returns the steps that left the table (0).
 * On x86 compiled for SSE4.1 (one roundsd for the interval's fraction, as the kernel's table loop where the
 * CPU has it; s_floor_ns checks the CPU). */
#if defined(__x86_64__) && defined(__GNUC__)
#define S_FLOOR1_ATTR __attribute__((target("sse4.1"), noinline))
#else
#define S_FLOOR1_ATTR __attribute__((noinline))
#endif
S_FLOOR1_ATTR static long s_floor1(const s_fl *c, double *sink)
{
    double u = c->u, w = c->w, hf = c->hf, nd = c->nd, au = 0, aus = 0, fmin = INFINITY, sn = c->s, Fn = c->Fc;
    long left = 0;
    for (int j = 0; j < S_STEPS; j++) {
        const double f = hf + c->drift;
        const double beta = c->sig * c->nz[j];
        const double un = VAFM_GJF_MOVE(u, w, f, beta, c->b, c->dt, c->hdmdt, c->hdm); /* core/gjf_step.h */
        const double ndn = nd + 1.0;
        const double usn = c->uspr0 + c->vspr * (ndn * c->dt);
        const double x = VAFM_JKR_TABLE_X(un, c->udet, c->invh, sqrt);
        if (__builtin_expect(!(un >= c->udet) || !(x < c->xend), 0)) {
            left++;
            break;
        }
        const double fr = x - __builtin_trunc(x);
        const double gg = 1.0 - fr;
        const double *p = c->node + 2 * (long)x;
        const double t = VAFM_JKR_HERMITE(fr, gg, p[0], p[1], p[2], p[3]);
        sn = c->sm + t;
        const double s3 = VAFM_JKR_CUBE(sn);
        Fn = VAFM_JKR_FORCE(s3, c->c2);
        const double fs = VAFM_SPRING_FORCE(c->kk, usn, un);
        const double hfn = fs - Fn;
        w = VAFM_GJF_KICK(w, f, hfn, beta, c->a, c->hdm, c->drift, c->binvm);
        u = un;
        hf = hfn;
        nd = ndn;
        au += un;
        aus += usn;
        fmin = fs < fmin ? fs : fmin;
    }
    *sink += u + w + au + aus + fmin + sn + Fn;
    return left;
}

#if defined(__x86_64__) && defined(__GNUC__)
typedef double s_fd8 __attribute__((vector_size(64)));
typedef long long s_fl8 __attribute__((vector_size(64)));
#define S_SQRT8(x) ((s_fd8)_mm512_sqrt_pd((__m512d)(x)))

/* G vectors of 8 curves side by side, S_STEPS steps each: batch_lanes.h's common path, term by term. */
static inline __attribute__((always_inline, target("avx512f,avx512dq"))) long s_floor8(const s_fl *c, int G,
                                                                                        double *sink)
{
    const s_fd8 z = { 0 };
    const s_fd8 dt = z + c->dt, hdm = z + c->hdm, hdmdt = z + c->hdmdt, drift = z + c->drift, sig = z + c->sig,
                a = z + c->a, b = z + c->b, binvm = z + c->binvm, uspr0 = z + c->uspr0, vspr = z + c->vspr,
                kk = z + c->kk, udet = z + c->udet, invh = z + c->invh, xend = z + c->xend, sm = z + c->sm,
                c2 = z + c->c2;
    const s_fl8 node = (s_fl8) { 0 } + (long long)(uintptr_t)c->node;
    s_fd8 u[4], w[4], hf[4], nd[4], au[4], aus[4], fmin[4], sv[4], Fv[4], us[4];
    for (int q = 0; q < G; q++) {
        u[q] = z + c->u;
        w[q] = z + c->w;
        hf[q] = z + c->hf;
        nd[q] = z + c->nd;
        au[q] = aus[q] = z;
        fmin[q] = z + INFINITY;
        sv[q] = z + c->s;
        Fv[q] = z + c->Fc;
        us[q] = z + c->us;
    }
    long left = 0;
    for (int j = 0; j < S_STEPS; j++) {
        const s_fd8 nz = z + c->nz[j];
        for (int q = 0; q < G; q++) {
            const s_fd8 f = hf[q] + drift;
            const s_fd8 beta = sig * nz;
            const s_fd8 un = VAFM_GJF_MOVE(u[q], w[q], f, beta, b, dt, hdmdt, hdm);
            const s_fd8 ndn = nd[q] + 1.0;
            const s_fd8 usn = uspr0 + vspr * (ndn * dt);
            const s_fd8 x = VAFM_JKR_TABLE_X(un, udet, invh, S_SQRT8);
            const s_fl8 out = (s_fl8)(un < udet) | ~(s_fl8)(x < xend);
            if (__builtin_expect(_mm512_movepi64_mask((__m512i)out) != 0, 0))
                left++;
            const __m256i x32 = _mm512_cvttpd_epi32((__m512d)x);
            const s_fd8 fr = x - (s_fd8)_mm512_cvtepi32_pd(x32);
            const s_fd8 gg = 1.0 - fr;
            const s_fl8 addr = node + (s_fl8)_mm512_cvtepi32_epi64(x32) * 16;
            __m512d q0, q1, q2, q3;
            vafm_table8_load((__m512i)addr, &q0, &q1, &q2, &q3);
            const s_fd8 p0 = (s_fd8)q0, p1 = (s_fd8)q1, p2 = (s_fd8)q2, p3 = (s_fd8)q3;
            const s_fd8 t = VAFM_JKR_HERMITE(fr, gg, p0, p1, p2, p3);
            const s_fd8 sn = sm + t;
            const s_fd8 s3 = VAFM_JKR_CUBE(sn);
            const s_fd8 Fn = VAFM_JKR_FORCE(s3, c2);
            const s_fd8 fs = VAFM_SPRING_FORCE(kk, usn, un);
            const s_fd8 hfn = fs - Fn;
            w[q] = VAFM_GJF_KICK(w[q], f, hfn, beta, a, hdm, drift, binvm);
            u[q] = un;
            sv[q] = sn;
            Fv[q] = Fn;
            hf[q] = hfn;
            us[q] = usn;
            nd[q] = ndn;
            au[q] = au[q] + un;
            aus[q] = aus[q] + usn;
            const s_fl8 lt = (s_fl8)(fs < fmin[q]);
            fmin[q] = (s_fd8)(((s_fl8)fs & lt) | ((s_fl8)fmin[q] & ~lt));
        }
    }
    for (int q = 0; q < G; q++)
        for (int l = 0; l < 8; l++)
            *sink += u[q][l] + w[q][l] + au[q][l] + aus[q][l] + fmin[q][l] + sv[q][l] + Fv[q][l] + us[q][l];
    return left;
}

#define S_FLOOR8(G)                                                                                     \
    __attribute__((target("avx512f,avx512dq"), noinline)) static long s_floor8_##G(const s_fl *c, double *sink) \
    {                                                                                                   \
        return s_floor8(c, G, sink);                                                                    \
    }
S_FLOOR8(1)
S_FLOOR8(2)
S_FLOOR8(3)
S_FLOOR8(4)
#endif

/* ns per curve-step of a floor loop (G = 0: one curve; else G vectors of 8), median of S_REPS; NAN if the
 * CPU lacks the vectors or a lane left the table (the floor would not be the kernel's common path). */
static double s_floor_ns(const s_fl *c, int G)
{
    long (*fn)(const s_fl *, double *) = s_floor1;
#if defined(__x86_64__) && defined(__GNUC__)
    long (*const f8[4])(const s_fl *, double *) = { s_floor8_1, s_floor8_2, s_floor8_3, s_floor8_4 };
    __builtin_cpu_init();
    if (G == 0 && !__builtin_cpu_supports("sse4.1"))
        return NAN;
    if (G > 0) {
        if (vafm_batch_width_max() < 8 || G > 4)
            return NAN;
        fn = f8[G - 1];
    }
#else
    if (G > 0)
        return NAN;
#endif
    const double curves = G > 0 ? 8.0 * G : 1.0;
    double ns[S_REPS];
    volatile double vsink = 0;
    for (int r = -1; r < S_REPS; r++) {
        double t0 = bench_clock_s(CLOCK_PROCESS_CPUTIME_ID), t1, sink = 0;
        uint64_t steps = 0;
        do {
            for (int k = 0; k < 20; k++) {
                if (fn(c, &sink))
                    return NAN;
                steps += S_STEPS;
            }
            t1 = bench_clock_s(CLOCK_PROCESS_CPUTIME_ID);
        } while (t1 - t0 < S_MIN_REP_S);
        vsink += sink;
        if (r >= 0)
            ns[r] = 1e9 * (t1 - t0) / ((double)steps * curves);
    }
    (void)vsink;
    return bench_median(ns, S_REPS);
}

int main(int argc, char **argv)
{
    const char *dir = argc > 1 ? argv[1] : ".";
    const int quick = argc > 2 && !strcmp(argv[2], "quick");
    const double load0 = bench_loadavg();
    const int wmax = vafm_batch_width_max();

    /* 1. lane steps */
    vafm_params p;
    s_scene(&p, "paper-fig4", 1e-3);
    vafm_sim *sim = NULL;
    vafm_kernel kin, kfree;
    if (vafm_sim_new(&sim, &p, NULL) || s_take_kernel(sim, 1, &kin) || s_take_kernel(sim, 0, &kfree)) {
        fprintf(stderr, "bench_batch: no kernel to measure\n");
        return 1;
    }
    const int widths[3] = { 1, 4, 8 };
    double lane_in[3] = { NAN, NAN, NAN }, lane_free[3] = { NAN, NAN, NAN };
    for (int i = 0; i < 3; i++) {
        if (widths[i] > 1 && vafm_batch_width(widths[i]) != widths[i])
            continue;
        lane_in[i] = s_lane_ns(&kin, widths[i]);
        lane_free[i] = s_lane_ns(&kfree, widths[i]);
        fprintf(stderr, "lanes W=%d: in contact %.2f ns, free %.2f ns per curve-step\n", widths[i], lane_in[i],
                lane_free[i]);
    }
    /* 4. floors, from the same in-contact kernel */
    s_fl *fl = malloc(sizeof *fl);
    if (!fl)
        return 1;
    s_fl_load(fl, &kin);
    double floor1 = s_floor_ns(fl, 0), floor8[4];
    for (int g = 1; g <= 4; g++)
        floor8[g - 1] = s_floor_ns(fl, g);
    free(fl);
    vafm_kernel kcold = kin;
    kcold.thermal = 0; /* the same kernel, its noise terms zero: no random numbers drawn */
    const double cold1 = s_lane_ns(&kcold, 1), cold8 = vafm_batch_width(8) == 8 ? s_lane_ns(&kcold, 8) : NAN;
    fprintf(stderr, "floors: one curve %.2f ns; 8 lanes x G=1..4: %.2f %.2f %.2f %.2f ns; kernels at kT = 0: "
                    "scalar %.2f, 8 lanes %.2f ns per curve-step\n",
            floor1, floor8[0], floor8[1], floor8[2], floor8[3], cold1, cold8);
    vafm_sim_destroy(&sim);

    /* 2. campaigns */
    struct {
        const char *label, *preset;
        double v_red;
        unsigned n, n_quick;
    } cs[] = {
        { "contact-silica", "contact-silica", 0, 128, 32 },  { "cell-liquid", "cell-liquid", 0, 32, 16 },
        { "colloid-pdms", "colloid-pdms", 0, 32, 16 },       { "stiff-polymer", "stiff-polymer", 0, 64, 16 },
        { "paper-fig4, ṽ = 1e-3", "paper-fig4", 1e-3, 64, 16 }, { "paper-fig4, ṽ = 1e-5", "paper-fig4", 1e-5, 16, 0 },
        { "paper-fig1", "paper-fig1", 0, 16, 0 },
    };
    const int nc = (int)(sizeof cs / sizeof cs[0]);
    s_crow rows[16];
    memset(rows, 0, sizeof rows);
    for (int i = 0; i < nc; i++) {
        s_crow *r = &rows[i];
        r->label = cs[i].label;
        r->n = quick ? cs[i].n_quick : cs[i].n;
        if (r->n == 0)
            continue;
        s_scene(&p, cs[i].preset, cs[i].v_red);
        s_acc a, b;
        r->ok = !s_campaign(&p, r->n, VAFM_CAMPAIGN_KERNEL_SCALAR, &r->cps_scalar, &r->ns_step_scalar, &a) &&
                !s_campaign(&p, r->n, VAFM_CAMPAIGN_KERNEL_BATCH, &r->cps_batch, &r->ns_step_batch, &b);
        r->same = r->ok && a.hash == b.hash && a.steps == b.steps;
        r->steps_per_curve = (double)a.steps / r->n;
        r->contact_frac = (double)a.steps_contact / (double)a.steps;
        fprintf(stderr, "%s: %.3g / %.3g curves per CPU-s (scalar / batch), same %d\n", r->label, r->cps_scalar,
                r->cps_batch, r->same);
    }

    /* 3. the core */
    int vl;
    const double vns = s_vector_ns(&vl);
    const double load1 = bench_loadavg();

    char path[4096];
    snprintf(path, sizeof path, "%s/bench_batch.csv", dir);
    FILE *csv = fopen(path, "w");
    snprintf(path, sizeof path, "%s/bench_batch.md", dir);
    FILE *md = fopen(path, "w");
    if (!csv || !md) {
        fprintf(stderr, "bench_batch: cannot write into %s\n", dir);
        return 1;
    }
    fprintf(csv, "what,label,width,value,unit\n");
    for (int i = 0; i < 3; i++) {
        fprintf(csv, "lane_step,in_contact,%d,%.4g,ns\n", widths[i], lane_in[i]);
        fprintf(csv, "lane_step,free,%d,%.4g,ns\n", widths[i], lane_free[i]);
    }
    for (int i = 0; i < nc; i++)
        if (rows[i].n)
            fprintf(csv, "campaign,%s,scalar,%.4g,curves_per_cpu_s\ncampaign,%s,batch,%.4g,curves_per_cpu_s\n",
                    rows[i].label, rows[i].cps_scalar, rows[i].label, rows[i].cps_batch);
    fprintf(csv, "machine,vector_op,%d,%.4g,ns\n", vl, vns);
    fprintf(csv, "floor,minimal_loop_one_curve,1,%.4g,ns\n", floor1);
    for (int g = 1; g <= 4; g++)
        fprintf(csv, "floor,minimal_loop_%d_vectors,8,%.4g,ns\n", g, floor8[g - 1]);
    fprintf(csv, "floor,kernel_no_random_numbers,1,%.4g,ns\nfloor,kernel_no_random_numbers,8,%.4g,ns\n", cold1,
            cold8);
    fclose(csv);

    FILE *outs[2] = { md, stdout };
    for (int o = 0; o < 2; o++) {
        FILE *f = outs[o];
        fprintf(f, "## Batch kernel against the scalar kernel (bench_batch%s)\n\n", quick ? ", quick" : "");
        fprintf(f, "This CPU runs up to %d lanes; load average %.2f before, %.2f after. CPU time of one thread, "
                   "medians.\n\n", wmax, load0, load1);
        fprintf(f, "| curve-step (paper-fig4, ṽ = 1e-3) | scalar | batch, 4 lanes | batch, 8 lanes | best ratio |\n");
        fprintf(f, "|---|---|---|---|---|\n");
        const char *names[2] = { "in contact, on the table", "out of contact (plain step)" };
        const double *v[2] = { lane_in, lane_free };
        for (int k = 0; k < 2; k++) {
            double best = fmin(isnan(v[k][1]) ? INFINITY : v[k][1], isnan(v[k][2]) ? INFINITY : v[k][2]);
            fprintf(f, "| %s | %.2f ns | %.2f ns | %.2f ns | %.2f× |\n", names[k], v[k][0], v[k][1], v[k][2],
                    v[k][0] / best);
        }
        fprintf(f, "\n| campaign (one thread) | curves | steps/curve | in contact | scalar curves/CPU-s | batch "
                   "curves/CPU-s | ratio | ns/step scalar → batch | same results |\n");
        fprintf(f, "|---|---|---|---|---|---|---|---|---|\n");
        for (int i = 0; i < nc; i++) {
            const s_crow *r = &rows[i];
            if (!r->n)
                continue;
            fprintf(f, "| %s | %u | %.3g | %.0f%% | %.3g | %.3g | %.2f× | %.1f → %.1f | %s |\n", r->label, r->n,
                    r->steps_per_curve, 100.0 * r->contact_frac, r->cps_scalar, r->cps_batch,
                    r->cps_batch / r->cps_scalar, r->ns_step_scalar, r->ns_step_batch,
                    !r->ok ? "run failed" : r->same ? "yes" : "**NO**");
        }
        if (!isnan(vns))
            fprintf(f, "\nThis core, same run: %.3f ns per independent %d-lane vector multiply or add (%.2f ns per "
                       "lane-op); an in-contact curve-step is ≈ 55 lane-ops (≈ 50 arithmetic, one square root) "
                       "plus one normal (½ Philox4x32-10 block and a ziggurat draw): %.2f ns of arithmetic at "
                       "that rate, against %.2f ns measured at 8 lanes.\n",
                    vns, vl, vns / vl, 55.0 * vns / vl, lane_in[2]);
        double fbest = INFINITY;
        int gbest = 0;
        for (int g = 1; g <= 4; g++)
            if (floor8[g - 1] < fbest)
                fbest = floor8[g - 1], gbest = g;
        fprintf(f, "\n### Floors: the in-contact step's own arithmetic (same kernel state, no random numbers)\n\n");
        fprintf(f, "| in-contact curve-step | one curve | 8 lanes |\n|---|---|---|\n");
        fprintf(f, "| the kernel (thermal) | %.2f ns | %.2f ns |\n", lane_in[0], lane_in[2]);
        fprintf(f, "| the kernel at kT = 0 (no random numbers drawn) | %.2f ns | %.2f ns |\n", cold1, cold8);
        fprintf(f, "| minimal loop of the same operations (best of 1–4 vectors: %d) | %.2f ns | %.2f ns |\n\n",
                gbest, floor1, fbest);
        fprintf(f, "Minimal 8-lane loop by vectors side by side: 1: %.2f, 2: %.2f, 3: %.2f, 4: %.2f ns per "
                   "curve-step. The minimal loops have no random numbers, no lane masks and no chunks; they "
                   "keep the square root, the table load (core/table8.h) and the contact tests. One curve "
                   "is bound by the latency of its chain, 8 lanes by the core's throughput. A kernel with "
                   "these curves, bit for bit, costs at least this plus its normal.\n",
                floor8[0], floor8[1], floor8[2], floor8[3]);
    }
    fclose(md);
    return 0;
}
