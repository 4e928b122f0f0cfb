/* SPDX-License-Identifier: MIT */
/*
 * BAOAB: Leimkuhler & Matthews, AMRX 2013. Half kick, half drift, exact Ornstein–Uhlenbeck velocity
 * step (relative to the friction's reference velocity), half drift, half kick. Exact configurational
 * sampling of a harmonic well for ω dt < 2. The O-step mixes the cantilever channel (relative to the
 * support, rate 1) and the contact channel (relative to the sample, rate η_c): reference velocity
 * v_spr/η_tot, each channel with its own fluctuation–dissipation noise, summed exactly.
 */
#include "core/kernel.h"

static void s_set_dt(vafm_kernel *K)
{
    const double dt = K->dt;
    for (int i = 0; i < 2; i++) {
        vafm_kcoef *c = &K->co[i];
        c->ou_c1 = exp(-c->eta_tot * dt);
        c->ou_c3 = sqrt(K->kT / K->m * -expm1(-2.0 * c->eta_tot * dt));
    }
}

/* The constants of a run in one contact state; c holds that state's coefficients. */
typedef struct s_consts {
    double half_dt, half_dt_m, vref;
    int thermal;
    vafm_kcoef c;
} s_consts;

static VAFM_KALWAYS s_consts s_consts_load(const vafm_kernel *K)
{
    const vafm_kcoef c = K->co[K->in_contact];
    return (s_consts){ .half_dt = 0.5 * K->dt, .half_dt_m = 0.5 * K->dt / K->m, .vref = K->v_spr / c.eta_tot,
    .thermal = K->thermal, .c = c };
}

static VAFM_KALWAYS void s_step(vafm_kernel *K, const s_consts *q, const vafm_kinv *v, vafm_khot *h, const int kind)
{
    h->w += q->half_dt_m * h->f;
    h->u += q->half_dt * h->w;
    h->w = q->vref + q->c.ou_c1 * (h->w - q->vref);
    if (q->thermal)
        h->w += q->c.ou_c3 * s_kernel_noise(K);
    h->u += q->half_dt * h->w;
    s_khot_post_move_k(K, v, h, kind);
    h->w += q->half_dt_m * h->f;
}

VAFM_KERNEL_INTEGRATOR(vafm_integrator_baoab, s_kernel_prepare,
    .name = "baoab",
    .description = "BAOAB splitting (Leimkuhler & Matthews 2013): exact harmonic <x^2> for omega*dt < 2",
    .overdamped = 0,
    .stability_limit = 2.0,
    .batch_lanes = 0)
