/* SPDX-License-Identifier: MIT */
/*
 * The stepping kernel: state, per-step coefficients and the shared tail of every step.
 *
 * Everything is in reduced units (η = R = E* = k_B = 1). The body sits at u (indentation, positive
 * into the sample) with velocity w; the spring support (the piezo) at u_spr moves at v_spr. The force
 * on the body is f = k(u_spr − u) − F_c(u) plus friction −mη(w − v_spr) (the cantilever in its medium)
 * and, in contact only, −mη_c·w (the optional contact channel), each channel with its own noise.
 *
 * An integrator's run() loop moves u (and w) and then calls s_khot_post_move(), which advances time
 * and the support, applies the contact hysteresis (touch at u_touch, detach below u_detach), evaluates
 * the contact force, accumulates the output sample and tracks the most tensile spring force. A change
 * of contact state ends run() after that step, so that the scene records the event and the integrator
 * switches coefficients (the contact friction channel). Nothing here allocates, locks or does I/O.
 *
 * Time and support position are computed from the step count since the phase began (t0 + n·dt), not
 * summed, so long runs do not drift and a curve is the same bit for bit however it is split in blocks.
 */
#ifndef VAFM_CORE_KERNEL_H
#define VAFM_CORE_KERNEL_H

#include <math.h>
#include <stdint.h>

#include "vafm/contact.h"
#include "vafm/integrator.h"
#include "vafm/params.h"
#include "core/gjf_step.h"
#include "core/jkr_inline.h"
#include "core/jkr_table.h"
#include "core/rng_philox.h"

typedef struct vafm_kcoef {
    double eta_tot;  /* total friction rate in this contact state */
    double zeta;     /* m·eta_tot */
    double gjf_a, gjf_b, gjf_sig;        /* GJF: a, b, sqrt(2 α kT dt) */
    double ou_c1, ou_c3;                 /* BAOAB O-step: exp(−η dt), sqrt(kT/m (1 − c1²)) */
    double vv_sig;                       /* paper VV: random force amplitude (unit-variance noise) */
    double bd_sig;                       /* Brownian: sqrt(2 kT dt / ζ) */
} vafm_kcoef;

typedef struct vafm_kernel {
    /* model */
    double m, k, kT, eta_c;
    vafm_contact contact;
    double (*cforce)(const vafm_contact *c, double u, double *s_io, double *dFdu);
    int is_jkr;        /* contact is JKR: the kernel calls the inline solver, not cforce */
    const vafm_jkr_table *jtab; /* tabulated JKR branch (NULL: solve exactly every step) */
    int thermal;       /* kT > 0: draw random numbers */
    int uniform_noise; /* VAFM_NOISE_UNIFORM */
    vafm_rng rng;      /* the stream; read only through rq (draws computed ahead, rng_philox.h) */
    vafm_rngq rq;
    double dt;
    vafm_kcoef co[2];  /* [0] out of contact, [1] in contact */
    /* state */
    double t0, uspr0;  /* phase origin: time and support position */
    int64_t n;         /* steps since the phase origin */
    double t, u, w, u_spr, v_spr;
    int in_contact;
    double s;          /* warm start: √a of the last contact evaluation */
    double Fc;         /* contact force at u */
    double f;          /* integrator's cached force */
    /* per-sample accumulators */
    double acc_u, acc_uspr;
    long acc_n;
    double fs_min;     /* most tensile (smallest) spring force k(u_spr − u) since last reset */
    int event;         /* +1 touched, −1 detached in the last step, else 0 */
    uint64_t steps, steps_contact, steps_free;
} vafm_kernel;

/** A standard normal draw of the kernel's stream. */
static inline double s_kernel_normal(vafm_kernel *K)
{
    return vafm_rngq_normal(&K->rq, &K->rng);
}

/** A unit-variance random number of the scene's distribution (gaussian or uniform on ±√3). */
static inline double s_kernel_noise(vafm_kernel *K)
{
    if (K->uniform_noise)
        return 1.7320508075688772 * (2.0 * vafm_rngq_uniform(&K->rq, &K->rng) - 1.0);
    return s_kernel_normal(K);
}

/** The conservative force on the body at its state: spring minus contact, k(u_spr − u) − F_c. */
static inline double s_kernel_force(const vafm_kernel *K)
{
    return K->k * (K->u_spr - K->u) - K->Fc;
}

/** An integrator's prepare() whose step reads the conservative force from K->f (all but paper-vv's). */
static inline void s_kernel_prepare(vafm_kernel *K)
{
    K->f = s_kernel_force(K);
}

/** Start the kernel's stream: stream `stream` of `seed`, nothing drawn ahead. */
static inline void s_kernel_rng_init(vafm_kernel *K, uint64_t seed, uint64_t stream)
{
    vafm_rng_init(&K->rng, seed, stream);
    vafm_rngq_reset(&K->rq);
}

/* The hot part of the state, copied into a local by an integrator's loop so that the compiler keeps
 * it in registers (a K-> field may be clobbered by the random generator's rare slow-path call, so the
 * compiler would otherwise store and reload every field each step). */
typedef struct vafm_khot {
    int64_t n;
    double u, w, u_spr, s, Fc, f;
    double acc_u, acc_uspr, fs_min;
    long acc_n;
    int in_contact, event;
    uint64_t steps_contact;
} vafm_khot;

static inline void s_khot_load(const vafm_kernel *K, vafm_khot *h)
{
    h->n = K->n;
    h->u = K->u;
    h->w = K->w;
    h->u_spr = K->u_spr;
    h->s = K->s;
    h->Fc = K->Fc;
    h->f = K->f;
    h->acc_u = K->acc_u;
    h->acc_uspr = K->acc_uspr;
    h->fs_min = K->fs_min;
    h->acc_n = K->acc_n;
    h->in_contact = K->in_contact;
    h->event = K->event;
    h->steps_contact = K->steps_contact;
}

static inline void s_khot_store(vafm_kernel *K, const vafm_khot *h, long steps)
{
    K->n = h->n;
    K->t = K->t0 + (double)h->n * K->dt;
    K->u = h->u;
    K->w = h->w;
    K->u_spr = h->u_spr;
    K->s = h->s;
    K->Fc = h->Fc;
    K->f = h->f;
    K->acc_u = h->acc_u;
    K->acc_uspr = h->acc_uspr;
    K->fs_min = h->fs_min;
    K->acc_n = h->acc_n;
    K->in_contact = h->in_contact;
    K->event = h->event;
    K->steps_contact = h->steps_contact;
    K->steps += (uint64_t)steps;
}

/** The end of every step, given the spring force fs = k(u_spr − u) at the new position: the force on the
 *  body, the output sample's accumulators, the most tensile spring force and the count of contact steps. */
static inline void s_khot_account(vafm_khot *h, double fs)
{
    h->f = fs - h->Fc;
    h->acc_u += h->u;
    h->acc_uspr += h->u_spr;
    h->acc_n++;
    if (fs < h->fs_min)
        h->fs_min = fs;
    h->steps_contact += (uint64_t)h->in_contact;
}

/** The tail of every step, on the loop's local hot state. */
static inline void s_khot_post_move(const vafm_kernel *K, const vafm_jkr_table *jtab, vafm_khot *h)
{
    h->n++;
    const double tau = (double)h->n * K->dt;
    h->u_spr = K->uspr0 + K->v_spr * tau;
    if (h->in_contact) {
        if (h->u < K->contact.u_detach) {
            h->in_contact = 0;
            h->event = -1;
            h->Fc = 0.0;
        }
    } else if (h->u >= K->contact.u_touch) {
        h->in_contact = 1;
        h->event = 1;
        h->s = 0.0;
    } else {
        h->Fc = 0.0;
    }
    if (h->in_contact) {
        if (jtab)
            h->Fc = vafm_jkr_table_force(jtab, &K->contact, h->u, &h->s);
        else if (K->is_jkr)
            h->Fc = vafm_jkr_force_inline(&K->contact, h->u, &h->s, NULL);
        else
            h->Fc = K->cforce(&K->contact, h->u, &h->s, NULL);
    }
    s_khot_account(h, VAFM_SPRING_FORCE(K->k, h->u_spr, h->u));
}

/* ---- per-state step loops ----------------------------------------------------------------------
 *
 * A contact change ends run() after that step, so within one call the contact state is fixed: each
 * integrator has one loop per state (out of contact; in contact with the tabulated JKR branch; in
 * contact with any other solver), and the loop's constants (coefficients of the state, support
 * motion, the table) are copied into locals once. The arithmetic is the same, in the same order, as
 * s_khot_post_move()'s, so a curve is the same bit for bit whichever loop ran it. */

#if defined(__GNUC__)
#define VAFM_KALWAYS inline __attribute__((always_inline))
#define VAFM_KCOLD __attribute__((noinline, cold))
#else
#define VAFM_KALWAYS inline
#define VAFM_KCOLD
#endif

/* VAFM_KLOOP_TABLE41: the table loop compiled for SSE4.1, where the CPU has it (every x86-64 since 2008; the
 * library itself is built for the x86-64 baseline). The in-contact step is a chain of dependent operations
 * (position, square root, table interval, cubic, force, position), so its latency is its cost: with roundsd
 * the table interval's fraction x − trunc(x) takes one rounding where the baseline converts to an integer and
 * back (≈ 3 ns of 34 a step, bench_step). For 0 ≤ x < 2³¹ both give the same double, bit for bit. */
enum { VAFM_KLOOP_FREE, VAFM_KLOOP_TABLE, VAFM_KLOOP_ANY, VAFM_KLOOP_TABLE41 };

#if defined(__x86_64__) && defined(__GNUC__)
#define VAFM_KSSE41 __attribute__((target("sse4.1")))
#define VAFM_KSSE41_OK 1
#else
#define VAFM_KSSE41
#define VAFM_KSSE41_OK 0
#endif

/** Nonzero: run the baseline table loop even where the CPU has SSE4.1 (tests compare the two; integrators.c). */
extern int vafm_kernel_baseline;

/** Whether a table run takes the SSE4.1 loop. */
static inline int s_kernel_sse41(void)
{
#if VAFM_KSSE41_OK
    return !vafm_kernel_baseline && __builtin_cpu_supports("sse4.1");
#else
    return 0;
#endif
}

/** Which loop a run() starting now takes. */
static inline int s_kernel_loop_kind(const vafm_kernel *K)
{
    if (!K->in_contact)
        return VAFM_KLOOP_FREE;
    return K->jtab ? VAFM_KLOOP_TABLE : VAFM_KLOOP_ANY;
}

/* Each integrator's run(): its step loop s_loop(K, n, kind), inlined once per contact state so that each copy
 * keeps that state's constants in registers, and the dispatch on the state a run starts in. */
#define VAFM_KERNEL_RUN_PER_LOOP(loop)                                                                             \
    static long s_run_free(vafm_kernel *K, long n) { return loop(K, n, VAFM_KLOOP_FREE); }                       \
    static long s_run_table(vafm_kernel *K, long n) { return loop(K, n, VAFM_KLOOP_TABLE); }                     \
    static VAFM_KSSE41 long s_run_table41(vafm_kernel *K, long n) { return loop(K, n, VAFM_KLOOP_TABLE41); }     \
    static long s_run_any(vafm_kernel *K, long n) { return loop(K, n, VAFM_KLOOP_ANY); }                         \
    static long s_run(vafm_kernel *K, long n)                                                                    \
    {                                                                                                            \
        switch (s_kernel_loop_kind(K)) {                                                                         \
        case VAFM_KLOOP_FREE: return s_run_free(K, n);                                                           \
        case VAFM_KLOOP_TABLE: return s_kernel_sse41() ? s_run_table41(K, n) : s_run_table(K, n);                \
        default: return s_run_any(K, n);                                                                         \
        }                                                                                                        \
    }

/* The constants of one run() call. */
typedef struct vafm_kinv {
    double dt, uspr0, v_spr, k, u_detach, u_touch;
    double inv_h, x_end, s_m, c2; /* the table: 1/h, its last interval's end (n − 1), s_m, 2c */
    const double *node;
} vafm_kinv;

static inline void s_kinv_load(const vafm_kernel *K, vafm_kinv *v)
{
    v->dt = K->dt;
    v->uspr0 = K->uspr0;
    v->v_spr = K->v_spr;
    v->k = K->k;
    v->u_detach = K->contact.u_detach;
    v->u_touch = K->contact.u_touch;
    v->s_m = K->contact.s_m;
    v->c2 = 2.0 * K->contact.c; /* exact: the same as the factor 2.0 * c inside the force */
    if (K->jtab) {
        v->inv_h = K->jtab->inv_h;
        v->x_end = (double)(K->jtab->n - 1);
        v->node = K->jtab->node;
    } else {
        v->inv_h = v->x_end = 0.0;
        v->node = NULL;
    }
}

typedef struct vafm_kfs {
    double F, s; /* contact force and √a */
} vafm_kfs;

/* The contact force at u by the kernel's solver (table, inline JKR or the type's) from the warm start s:
 * on the first step of a contact (s = 0) and beyond the table's end (integrators.c; out of line, rare). */
vafm_kfs vafm_kernel_contact_eval(const vafm_kernel *K, double u, double s);
/* The exact inline JKR solver, for a point beyond the table. */
vafm_kfs vafm_kernel_table_far(const vafm_kernel *K, double u, double s);

/* vafm_jkr_table_force() on the loop's constants (the same expressions). */
static VAFM_KALWAYS double s_kinv_table_force(const vafm_kernel *K, const vafm_kinv *v, double u, double *s_io,
                                              const int sse41)
{
    const double x = VAFM_JKR_TABLE_X(u, v->u_detach, v->inv_h, sqrt);
    if (!(x < v->x_end)) {
        const vafm_kfs r = vafm_kernel_table_far(K, u, *s_io);
        *s_io = r.s;
        return r.F;
    }
    const int i = (int)x;
    const double f = (sse41 ? x - __builtin_trunc(x) : x - (double)i), g = 1.0 - f;
    const double *p = v->node + 2 * i;
    const double t = VAFM_JKR_HERMITE(f, g, p[0], p[1], p[2], p[3]);
    const double s = v->s_m + t, s3 = VAFM_JKR_CUBE(s);
    *s_io = s;
    return VAFM_JKR_FORCE(s3, v->c2);
}

/** s_khot_post_move() for a loop of the given kind (a compile-time constant). */
static VAFM_KALWAYS void s_khot_post_move_k(const vafm_kernel *K, const vafm_kinv *v, vafm_khot *h, const int kind)
{
    if (kind == VAFM_KLOOP_ANY) {
        s_khot_post_move(K, K->jtab, h);
        return;
    }
    h->n++;
    const double tau = (double)h->n * v->dt;
    h->u_spr = v->uspr0 + v->v_spr * tau;
    if (kind == VAFM_KLOOP_TABLE || kind == VAFM_KLOOP_TABLE41) {
        if (h->u < v->u_detach) {
            h->in_contact = 0;
            h->event = -1;
            h->Fc = 0.0;
        } else {
            h->Fc = s_kinv_table_force(K, v, h->u, &h->s, kind == VAFM_KLOOP_TABLE41);
        }
    } else if (h->u >= v->u_touch) {
        h->in_contact = 1;
        h->event = 1;
        const vafm_kfs r = vafm_kernel_contact_eval(K, h->u, 0.0);
        h->Fc = r.F;
        h->s = r.s;
    } else {
        h->Fc = 0.0;
    }
    s_khot_account(h, VAFM_SPRING_FORCE(v->k, h->u_spr, h->u));
}

/* A kernel integrator's step loop, run() and type, from what its file defines:
 *   s_consts, s_consts_load(K)  the step's constants in the contact state a run starts in (copied into a
 *                               local once a run, so that they stay in registers);
 *   s_step(K, &q, &v, &h, kind) one step: moves h->u and h->w and calls s_khot_post_move_k() once;
 *   s_set_dt                    as in vafm_integrator_type.
 * The loop runs at most n steps and ends after a step with a contact event; the hot state lives in a local
 * and is stored back after. `var` is the type, with prepare_fn as its prepare() (s_kernel_prepare when the step
 * reads the conservative force) and the designated initializers given (name, description, ...). */
#define VAFM_KERNEL_INTEGRATOR(var, prepare_fn, ...)                                                             \
    static VAFM_KALWAYS long s_loop(vafm_kernel *K, long n, const int kind)                                      \
    {                                                                                                            \
        const s_consts q = s_consts_load(K);                                                                     \
        vafm_kinv v;                                                                                             \
        s_kinv_load(K, &v);                                                                                      \
        vafm_khot h;                                                                                             \
        s_khot_load(K, &h);                                                                                      \
        long i = 0;                                                                                              \
        while (i < n) {                                                                                          \
            s_step(K, &q, &v, &h, kind);                                                                         \
            i++;                                                                                                 \
            if (h.event)                                                                                         \
                break;                                                                                           \
        }                                                                                                        \
        s_khot_store(K, &h, i);                                                                                  \
        return i;                                                                                                \
    }                                                                                                            \
    VAFM_KERNEL_RUN_PER_LOOP(s_loop)                                                                             \
    static const vafm_integrator_type s_type = { .prepare = prepare_fn, .run = s_run, .set_dt = s_set_dt,        \
                                                 __VA_ARGS__ };                                                  \
    const vafm_integrator_type *const var = &s_type;

/** Set the step-size dependent coefficients of both contact states. */
void vafm_kernel_set_dt(vafm_kernel *K, double dt);

/** Start a new phase at the current time and support position, with support speed v. */
static inline void s_kernel_phase(vafm_kernel *K, double v)
{
    K->t0 = K->t;
    K->uspr0 = K->u_spr;
    K->n = 0;
    K->v_spr = v;
}

/** Exact propagation of the free cantilever (out of contact) over a fixed step h. */
typedef struct vafm_free_ou {
    double h;
    int overdamped;
    double e11, e12, e21, e22; /* mean propagator of (y, z) = (u − u_spr, w − v_spr) */
    double l11, l21, l22;      /* Cholesky factor of the step covariance */
    double a, sd;              /* overdamped: y' = a·y + sd·ξ */
    /* Box-car output (antialias = mean): the sample is the time average of u, so each step also draws
     * I = ∫y dτ over the step, jointly Gaussian with the end state (the right-end value of a few long
     * steps would filter the samples by the wrong kernel: the PSD tail near fs/2 comes out ~20% high
     * at two steps per sample). integrate = 1 switches it on (vafm_free_ou_integrate). */
    int integrate;
    double p3[3][2];           /* mean propagator of (y, z, I) from (y, z) */
    double c3[3][3];           /* lower Cholesky factor of their step covariance */
} vafm_free_ou;

void vafm_free_ou_setup(vafm_free_ou *o, const vafm_kernel *K, double h, int overdamped);
/** Make the steps of o also integrate y for box-car output samples (3 normals per step instead of 2). */
void vafm_free_ou_integrate(vafm_free_ou *o, const vafm_kernel *K);
/** One exact step of length o->h (out of contact, support at constant speed). */
void vafm_free_ou_step(vafm_kernel *K, const vafm_free_ou *o);
/** n such steps (the same as n calls of vafm_free_ou_step). */
void vafm_free_ou_steps(vafm_kernel *K, const vafm_free_ou *o, long n);

/** The propagator of a harmonic well of stiffness `stiff`, friction rate eta, at temperature kT. */
void vafm_well_ou_setup(vafm_free_ou *o, double m, double stiff, double eta, double kT, double h, int overdamped);
/** One exact step about the centre line c0 + c1·τ (τ = time since the phase origin): the deviation
 *  (u − centre, w − c1) is propagated by o. in_contact: count the step as in contact and leave Fc
 *  (the caller evaluates the contact force where it needs it). */
void vafm_well_ou_step(vafm_kernel *K, const vafm_free_ou *o, double c0, double c1, int in_contact);

#endif
