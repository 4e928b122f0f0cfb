/* SPDX-License-Identifier: MIT */
/*
 * The stepping kernel: state, per-step coefficients and the shared tail of every step.
 *
 * Everything is in reduced units (η = R = E* = k_B = 1). The body sits at u (indentation, positive
 * into the sample) with velocity w; the spring support (the piezo) at u_spr moves at v_spr. The force
 * on the body is f = k(u_spr − u) − F_c(u) plus friction −mη(w − v_spr) (the cantilever in its medium)
 * and, in contact only, −mη_c·w (the optional contact channel), each channel with its own noise.
 *
 * An integrator's run() loop moves u (and w) and then calls s_kernel_post_move(), which advances time
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
    vafm_rng rng;
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

/** A unit-variance random number of the scene's distribution (gaussian or uniform on ±√3). */
static inline double s_kernel_noise(vafm_kernel *K)
{
    if (K->uniform_noise)
        return 1.7320508075688772 * (2.0 * vafm_rng_uniform_inline(&K->rng) - 1.0);
    return vafm_rng_normal_inline(&K->rng);
}

/** Contact force at the current u, with the hysteresis; sets K->event on a change. */
static inline void s_kernel_contact(vafm_kernel *K)
{
    if (K->in_contact) {
        if (K->u < K->contact.u_detach) {
            K->in_contact = 0;
            K->event = -1;
            K->Fc = 0.0;
            return;
        }
    } else {
        if (!(K->u >= K->contact.u_touch)) {
            K->Fc = 0.0;
            return;
        }
        K->in_contact = 1;
        K->event = 1;
        K->s = 0.0; /* cold start of the solver */
    }
    if (K->jtab)
        K->Fc = vafm_jkr_table_force(K->jtab, &K->contact, K->u, &K->s);
    else if (K->is_jkr)
        K->Fc = vafm_jkr_force_inline(&K->contact, K->u, &K->s, NULL);
    else
        K->Fc = K->cforce(&K->contact, K->u, &K->s, NULL);
}

/** The tail of every step: time, support, contact, force, accumulation. Returns the spring force. */
static inline double s_kernel_post_move(vafm_kernel *K)
{
    K->n++;
    double tau = (double)K->n * K->dt;
    K->t = K->t0 + tau;
    K->u_spr = K->uspr0 + K->v_spr * tau;
    s_kernel_contact(K);
    double fs = K->k * (K->u_spr - K->u);
    K->f = fs - K->Fc;
    K->acc_u += K->u;
    K->acc_uspr += K->u_spr;
    K->acc_n++;
    if (fs < K->fs_min)
        K->fs_min = fs;
    K->steps++;
    K->steps_contact += (uint64_t)K->in_contact;
    return fs;
}

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
} vafm_free_ou;

void vafm_free_ou_setup(vafm_free_ou *o, const vafm_kernel *K, double h, int overdamped);
/** One exact step of length o->h (out of contact, support at constant speed). */
void vafm_free_ou_step(vafm_kernel *K, const vafm_free_ou *o);

#endif
