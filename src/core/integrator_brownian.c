/* SPDX-License-Identifier: MIT */
/*
 * Brownian dynamics (the paper's Eq. 12): overdamped Euler–Maruyama,
 *   u' = u + (dt/ζ)(f + mη·v_spr) + √(2kT dt/ζ)·ξ,  ζ = m(η + η_c in contact).
 * Only ζ matters; the velocity reported is (u' − u)/dt. Stable for K dt/ζ < 2; its harmonic ⟨x²⟩ is
 * too large by the factor 1/(1 − h/2), h = K dt/ζ.
 */
#include "core/kernel.h"

static void s_set_dt(vafm_kernel *K)
{
    for (int i = 0; i < 2; i++) {
        vafm_kcoef *c = &K->co[i];
        c->bd_sig = sqrt(2.0 * K->kT * K->dt / c->zeta);
    }
}

/* The constants of a run in one contact state; c holds that state's coefficients. */
typedef struct s_consts {
    double dt, inv_dt, drift;
    int thermal;
    vafm_kcoef c;
} s_consts;

static VAFM_KALWAYS s_consts s_consts_load(const vafm_kernel *K)
{
    return (s_consts){ .dt = K->dt, .inv_dt = 1.0 / K->dt, .drift = K->m * K->v_spr, .thermal = K->thermal,
    .c = K->co[K->in_contact] };
}

static VAFM_KALWAYS void s_step(vafm_kernel *K, const s_consts *q, const vafm_kinv *v, vafm_khot *h, const int kind)
{
    double du = q->dt / q->c.zeta * (h->f + q->drift);
    if (q->thermal)
        du += q->c.bd_sig * s_kernel_noise(K);
    h->u += du;
    h->w = du * q->inv_dt;
    s_khot_post_move_k(K, v, h, kind);
}

VAFM_KERNEL_INTEGRATOR(vafm_integrator_brownian, s_kernel_prepare,
    .name = "brownian",
    .description = "overdamped Euler-Maruyama (the paper's Eq. 12): friction zeta = m*eta only",
    .overdamped = 1,
    .stability_limit = 2.0,
    .batch_lanes = 0)
