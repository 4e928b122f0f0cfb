/* SPDX-License-Identifier: MIT */
/* The runtime stiffness guard's measure and its threshold (guard.h). */
#include <math.h>

#include "core/guard.h"

double vafm_guard_measure(const vafm_kernel *K, const vafm_integrator_type *it, double dt, double u, double *sq,
                          double *Kl)
{
    double dF = 0.0;
    K->cforce(&K->contact, u, sq, &dF);
    const double k_loc = K->k + dF;
    if (Kl)
        *Kl = k_loc;
    if (!(k_loc > 0))
        return 0.0;
    return it->overdamped ? k_loc * dt / K->co[1].zeta : sqrt(k_loc / K->m) * dt;
}

/* Only for a model that declares VAFM_CONTACT_MONOTONE. Why a threshold is exact for JKR and Hertz: Hertz has dF/du = 2a, growing with u. On the JKR branch (contact_jkr.c's
 * s-form, c = 4s_m³) d²F/du² = (N′D − N·D′)/D³ (jkr_inline.h) with N′D − N·D′ = 4s(16s⁶ − 4cs³ + 3c²),
 * a quadratic in s³ whose discriminant 16c² − 192c² is negative: positive for every s > 0, so dF/du is
 * strictly increasing along the branch. The margin of 1e-6 in the measure covers the solver's round-off
 * (≲ 1e-15 relative) many times over: the computed measure of any u ≤ u_ok stays below the limit. */
double vafm_guard_threshold(const vafm_kernel *K, const vafm_integrator_type *it, double dt)
{
    if (!(dt > 0) || !(K->contact.type->flags & VAFM_CONTACT_MONOTONE))
        return -INFINITY;
    const double thr = (1.0 - 1e-6) * it->stability_limit;
    double lo = K->contact.u_detach, sq = 0.0;
    if (!isfinite(lo) || !(vafm_guard_measure(K, it, dt, lo, &sq, NULL) < thr))
        return -INFINITY;
    double hi = fmax(1.0, 2.0 * fabs(lo));
    for (;;) { /* doubling from ≥ 1 passes 1e300 within ~1000 steps, far below DBL_MAX */
        sq = 0.0;
        if (!(vafm_guard_measure(K, it, dt, hi, &sq, NULL) < thr))
            break;
        if (!(hi < 1e300))
            return hi; /* the limit is never reached on any indentation a double holds */
        lo = hi;
        hi *= 2.0;
    }
    /* invariant: measure(lo) < thr ≤ measure(hi) */
    for (int i = 0; i < 200 && hi - lo > 1e-15 * fmax(1.0, fabs(hi)); i++) {
        const double mid = 0.5 * (lo + hi);
        sq = 0.0;
        if (vafm_guard_measure(K, it, dt, mid, &sq, NULL) < thr)
            lo = mid;
        else
            hi = mid;
    }
    return lo;
}
