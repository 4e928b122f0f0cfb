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

#ifdef __cplusplus
}
#endif
#endif
