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

static void s_prepare(vafm_kernel *K)
{
    K->f = K->k * (K->u_spr - K->u) - K->Fc;
}

/* The step loop of one contact state (kind: VAFM_KLOOP_*, a constant); c holds that state's coefficients. */
static VAFM_KALWAYS long s_loop(vafm_kernel *K, long n, const int kind)
{
    const double dt = K->dt, inv_dt = 1.0 / dt, drift = K->m * K->v_spr;
    const int thermal = K->thermal;
    const vafm_kcoef c = K->co[K->in_contact];
    vafm_kinv v;
    s_kinv_load(K, &v);
    vafm_khot h;
    s_khot_load(K, &h);
    long i = 0;
    while (i < n) {
        double du = dt / c.zeta * (h.f + drift);
        if (thermal)
            du += c.bd_sig * s_kernel_noise(K);
        h.u += du;
        h.w = du * inv_dt;
        s_khot_post_move_k(K, &v, &h, kind);
        i++;
        if (h.event)
            break;
    }
    s_khot_store(K, &h, i);
    return i;
}

VAFM_KERNEL_RUN_PER_LOOP(s_loop)

static const vafm_integrator_type s_type = {
    .name = "brownian",
    .description = "overdamped Euler-Maruyama (the paper's Eq. 12): friction zeta = m*eta only",
    .overdamped = 1,
    .stability_limit = 2.0,
    .prepare = s_prepare,
    .run = s_run,
    .set_dt = s_set_dt,
    .batch_lanes = 0,
};

const vafm_integrator_type *const vafm_integrator_brownian = &s_type;
