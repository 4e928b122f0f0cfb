/* SPDX-License-Identifier: MIT */
/*
 * The paper's method (its section 2.2): velocity Verlet on Eq. 1 with the friction evaluated at the
 * velocity available when the force is computed (the half-step velocity, as MD codes do) and a random
 * force drawn once per force evaluation, Γ = √(2αkT/dt)·ξ with ξ of unit variance; with noise = uniform
 * this is exactly Eq. 7, Γ = √(6αkT/dt)(2U − 1). Kept as the reference to compare against: its
 * kinetic temperature is off by O(η dt) and it is unstable for η dt ≳ 2 and for ω dt ≥ 2.
 * Between steps K->f holds the total force (conservative + friction + random); s_khot_post_move()
 * overwrites it with the conservative force, from which the total is rebuilt.
 */
#include "core/kernel.h"

/* conservative + friction (cantilever channel relative to the support, contact channel to 0) + random */
static inline double s_total(vafm_kernel *K, const vafm_kcoef *c, double f, double w)
{
    double ft = f - c->zeta * w + K->m * K->v_spr;
    if (K->thermal)
        ft += c->vv_sig * s_kernel_noise(K);
    return ft;
}

static void s_set_dt(vafm_kernel *K)
{
    for (int i = 0; i < 2; i++) {
        vafm_kcoef *c = &K->co[i];
        c->vv_sig = sqrt(2.0 * c->zeta * K->kT / K->dt);
    }
}

static void s_prepare(vafm_kernel *K)
{
    K->f = s_total(K, &K->co[K->in_contact], s_kernel_force(K), K->w);
}

/* The constants of a run in one contact state; c holds that state's coefficients. */
typedef struct s_consts {
    double dt, half_dt_m, drift;
    int thermal;
    vafm_kcoef c;
} s_consts;

static VAFM_KALWAYS s_consts s_consts_load(const vafm_kernel *K)
{
    return (s_consts){ .dt = K->dt, .half_dt_m = 0.5 * K->dt / K->m, .drift = K->m * K->v_spr,
    .thermal = K->thermal, .c = K->co[K->in_contact] };
}

/* One step. The total force after it is built with the coefficients of the state after it (c, or on a
 * contact change the new state's). */
static VAFM_KALWAYS void s_step(vafm_kernel *K, const s_consts *q, const vafm_kinv *v, vafm_khot *h, const int kind)
{
    h->w += q->half_dt_m * h->f; /* h->f holds the total force of the last evaluation */
    h->u += q->dt * h->w;
    s_khot_post_move_k(K, v, h, kind);
    if (h->event) {
        h->f = s_total(K, &K->co[h->in_contact], h->f, h->w);
    } else {
        /* s_total() on the loop's constants */
        double ft = h->f - q->c.zeta * h->w + q->drift;
        if (q->thermal)
            ft += q->c.vv_sig * s_kernel_noise(K);
        h->f = ft;
    }
    h->w += q->half_dt_m * h->f;
}

VAFM_KERNEL_INTEGRATOR(vafm_integrator_paper_vv, s_prepare,
    .name = "paper-vv",
    .description = "the paper's velocity Verlet with per-step random force (Eq. 7 with noise=uniform); reference",
    .overdamped = 0,
    .stability_limit = 2.0,
    .batch_lanes = 0,
    .eta_dt_limit = 2.0) /* its velocity half-kicks by (1 − η dt/2) change sign beyond */
