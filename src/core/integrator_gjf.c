/* SPDX-License-Identifier: MIT */
/*
 * GJF: Grønbech-Jensen & Farago, Mol. Phys. 111, 983 (2013). With α = mη, b = 1/(1 + α dt/2m),
 * a = (1 − α dt/2m)·b and β ~ N(0, 2αkT dt):
 *   u' = u + b dt w + (b dt²/2m) f + (b dt/2m) β
 *   w' = a w + (dt/2m)(a f + f') + (b/m) β
 * Configurational sampling of a harmonic well is exact at any dt with ω dt < 2; the overdamped limit
 * is Brownian dynamics. Friction relative to the moving support enters as the constant force mη·v_spr.
 */
#include "core/kernel.h"

static void s_set_dt(vafm_kernel *K)
{
    const double dt = K->dt;
    for (int i = 0; i < 2; i++) {
        vafm_kcoef *c = &K->co[i];
        double h = 0.5 * c->eta_tot * dt;
        c->gjf_b = 1.0 / (1.0 + h);
        c->gjf_a = (1.0 - h) * c->gjf_b;
        c->gjf_sig = sqrt(2.0 * c->zeta * K->kT * dt);
    }
}

/* The constants of a run in one contact state; c holds that state's coefficients. */
typedef struct s_consts {
    double dt, half_dt_m, inv_m, drift;
    int thermal;
    vafm_kcoef c;
} s_consts;

static VAFM_KALWAYS s_consts s_consts_load(const vafm_kernel *K)
{
    return (s_consts){ .dt = K->dt, .half_dt_m = 0.5 * K->dt / K->m, .inv_m = 1.0 / K->m, .drift = K->m * K->v_spr,
    .thermal = K->thermal, .c = K->co[K->in_contact] };
}

static VAFM_KALWAYS void s_step(vafm_kernel *K, const s_consts *q, const vafm_kinv *v, vafm_khot *h, const int kind)
{
    const vafm_kcoef *c = &q->c;
    const double f = h->f + q->drift;
    const double beta = q->thermal ? c->gjf_sig * s_kernel_noise(K) : 0.0;
    h->u = VAFM_GJF_MOVE(h->u, h->w, f, beta, c->gjf_b, q->dt, q->half_dt_m * q->dt, q->half_dt_m); /* core/gjf_step.h */
    s_khot_post_move_k(K, v, h, kind);
    h->w = VAFM_GJF_KICK(h->w, f, h->f, beta, c->gjf_a, q->half_dt_m, q->drift, c->gjf_b * q->inv_m);
}

VAFM_KERNEL_INTEGRATOR(vafm_integrator_gjf, s_kernel_prepare,
    .name = "gjf",
    .description = "Gronbech-Jensen & Farago 2013 Langevin (default): exact harmonic <x^2> for omega*dt < 2",
    .overdamped = 0,
    .stability_limit = 2.0,
    .batch_lanes = 8) /* batch.c: AVX-512 8, AVX2 4 lanes */
