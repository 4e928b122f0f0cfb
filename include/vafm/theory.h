/* SPDX-License-Identifier: MIT */
/**
 * @file theory.h
 * Closed forms and semi-analytic references, in reduced units (physics notes): the quasi-static
 * spring instability of the JKR branch, the equilibrium on the stable branch, the barrier near the
 * instability and the overdamped Dudko–Hummer–Szabo prediction. No simulation; pure functions.
 */
#ifndef VAFM_THEORY_H
#define VAFM_THEORY_H

#include "vafm/common.h"

#ifdef __cplusplus
extern "C" {
#endif

/** The quasi-static (athermal, v → 0) pull-off of a JKR contact held by a spring k. */
typedef struct vafm_quasistatic {
    double u_min;      /**< indentation where contact is lost (the branches meet) */
    double F_jkr;      /**< 3πγ/2: the load-controlled pull-off force (magnitude) */
    double u_star;     /**< indentation where dF/du = −k on the unstable part (the instability) */
    double u_spr_star; /**< spring position there (u_spr = u when the spring is relaxed) */
    double F_star;     /**< contact force magnitude there (tensile) */
    double F_det;      /**< spring force magnitude when the body reaches u_min with the spring at u_spr* */
    double F2;         /**< d²F/du² at u_star (enters the barrier) */
} vafm_quasistatic;

/** Compute the quasi-static instability for reduced γ > 0 and k > 0. @return 0 or VAFM_EINVAL. */
VAFM_API int vafm_theory_quasistatic(double gamma, double k, vafm_quasistatic *out);

/** Equilibrium on the stable contact branch for a spring at u_spr: k(u_spr − u) = F(u).
 *  @return 0, or VAFM_EINVAL when no stable equilibrium exists (u_spr beyond u_spr*). */
VAFM_API int vafm_theory_equilibrium(double gamma, double k, double u_spr, double *u_eq, double *F_eq);

/** Barrier ΔV(y) = (4√2/3)(k·y)^{3/2}/√F″ for a spring y = u_spr − u_spr* short of the instability. */
VAFM_API double vafm_theory_barrier(const vafm_quasistatic *q, double k, double y);

/** Overdamped DHS (ν = 2/3) mean distance y* = u_spr − u_spr* at rupture, for friction ζ = mη,
 *  temperature kT and pulling speed v (all reduced). NaN where Λ = F″kT/(4πζkv) ≤ 1. */
VAFM_API double vafm_theory_dhs_mean_y(const vafm_quasistatic *q, double k, double kT, double v,
                                       double zeta);

/** Overdamped mean-first-passage rate out of the contact well (physics notes, "Thermal oracles": the
 *  exact 1D reference beyond DHS). The spring is frozen at u_spr = u_spr* + y; the body diffuses on the
 *  contact branch in V(u) = k/2 (u_spr − u)² + U(u) with friction ζ = mη (diffusion kT/ζ), reflecting
 *  at u → ∞ and absorbed at u_min (contact lost). The start is the well's minimum for y > 0 and the
 *  inflection u* for y ≤ 0 (no well left: the rate is then the inverse slide time). Computed by
 *  quadrature of T(x₀) = (ζ/kT)∫_{u_min}^{x₀} du e^{βV(u)} ∫_u^∞ e^{−βV}, refined to ~1e-5 relative.
 *  With a mass m > 0 (Langevin, η = ζ/m) the rate is multiplied by Kramers' spatial-diffusion factor
 *  κ = η/(η/2 + √(η²/4 + ω_b²)), ω_b² = |V″|/m at the barrier top (1 for ω_b ≪ η, η/ω_b for ω_b ≫ η;
 *  1 where there is no interior top: then the top is the branch end u_min, and for small m the rate is
 *  overestimated). The energy-diffusion regime (very weak friction) is not covered either.
 *  m = 0: overdamped (Brownian dynamics).
 *  @param rate receives the rate (1/reduced time; 0 when the barrier exceeds ~650 kT).
 *  @return 0 or VAFM_EINVAL (γ, k, kT, ζ ≤ 0 or not finite, m < 0, y NaN). */
VAFM_API int vafm_theory_mfpt_rate(double gamma, double k, double kT, double zeta, double mass, double y,
                                   double *rate);

/** Escape statistics of a pull at constant speed, from the MFPT rate integrated along the pull (the
 *  adiabatic approximation: the rate at each spring position as if frozen; the slide from the barrier
 *  to u_min is taken as instantaneous). The friction acts relative to the spring support (physics
 *  notes), so a pull at speed v adds a constant force ζv on the body: the escape happens with the spring
 *  ζv/k closer to the sample than at a frozen spring, and mean_y includes that shift. */
typedef struct vafm_theory_pull {
    double v;           /**< pulling speed (reduced, as given) */
    double mean_y;      /**< mean spring position at escape, y = u_spr − u_spr* (reduced length; > 0: early) */
    double sd_y;        /**< its standard deviation */
    double mean_F;      /**< mean spring force at detachment, F_det − k·y (tensile magnitude, reduced) */
    double sd_F;        /**< its standard deviation (= k·sd_y) */
    double p_unescaped; /**< survival left where the integration stopped (≈ 0; large: v too fast) */
} vafm_theory_pull;

/** Integrate the MFPT rate (mass as for vafm_theory_mfpt_rate) along pulls at speeds v[0..n_v) from y_start (> 0; ≤ 0: automatic, where the
 *  fold barrier is 80 kT) down through the instability until every pull has escaped (survival < 1e-9)
 *  or y reaches −y_start. One rate table serves every speed. Memory: allocates a table (freed).
 *  @return 0, VAFM_EINVAL (bad argument or v ≤ 0) or VAFM_ENOMEM. */
VAFM_API int vafm_theory_mfpt_pull(double gamma, double k, double kT, double zeta, double mass, double y_start,
                                   const double *v, size_t n_v, vafm_theory_pull *out);

#ifdef __cplusplus
}
#endif
#endif
