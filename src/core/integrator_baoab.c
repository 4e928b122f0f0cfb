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

static void s_prepare(vafm_kernel *K)
{
    K->f = K->k * (K->u_spr - K->u) - K->Fc;
}

/* The step loop of one contact state (kind: VAFM_KLOOP_*, a constant); c holds that state's coefficients. */
static VAFM_KALWAYS long s_loop(vafm_kernel *K, long n, const int kind)
{
    const double dt = K->dt, half_dt = 0.5 * dt, half_dt_m = 0.5 * dt / K->m;
    const int thermal = K->thermal;
    const vafm_kcoef c = K->co[K->in_contact];
    const double vref = K->v_spr / c.eta_tot;
    vafm_kinv v;
    s_kinv_load(K, &v);
    vafm_khot h;
    s_khot_load(K, &h);
    long i = 0;
    while (i < n) {
        h.w += half_dt_m * h.f;
        h.u += half_dt * h.w;
        h.w = vref + c.ou_c1 * (h.w - vref);
        if (thermal)
            h.w += c.ou_c3 * s_kernel_noise(K);
        h.u += half_dt * h.w;
        s_khot_post_move_k(K, &v, &h, kind);
        h.w += half_dt_m * h.f;
        i++;
        if (h.event)
            break;
    }
    s_khot_store(K, &h, i);
    return i;
}

VAFM_KERNEL_RUN_PER_LOOP(s_loop)

static const vafm_integrator_type s_type = {
    .name = "baoab",
    .description = "BAOAB splitting (Leimkuhler & Matthews 2013): exact harmonic <x^2> for omega*dt < 2",
    .overdamped = 0,
    .stability_limit = 2.0,
    .prepare = s_prepare,
    .run = s_run,
    .set_dt = s_set_dt,
    .batch_lanes = 0,
};

const vafm_integrator_type *const vafm_integrator_baoab = &s_type;
