/* SPDX-License-Identifier: MIT */
/*
 * JKR contact (physics notes, "JKR contact"), reduced units E* = R = 1.
 *
 * With s = √a and c = √(2πγ):
 *   u = s⁴ − c·s,   F = (4/3)s⁶ − 2c·s³,   dF/du = 2s²(4s³ − 3c)/(4s³ − c),
 *   U = (8/15)s¹⁰ − (4/3)c·s⁷ + (c²/2)s⁴   (dU/du = F).
 * The two branches of s(u) meet at s_m = (c/4)^{1/3}, u_min = −3s_m⁴; the physical branch is s ≥ s_m.
 *
 * Solver (t-form): with t = s − s_m ≥ 0 and c = 4s_m³,
 *   P(t) = t⁴ + 4s_m t³ + 6s_m² t² = u − u_min =: Δu.
 * P is increasing and convex on t ≥ 0, so Newton started to the right of the root decreases
 * monotonically to it. t₀ = min[Δu^{1/4}, √(Δu/6)/s_m] is such a start: each term of P alone is ≤ Δu at
 * the root, so each bound is ≥ the root. Working in t keeps the branch end (t = 0) exact and gives
 * dF/du through 4s³ − c = 4t(s² + s·s_m + s_m²) without cancellation, hence exactly −∞ at u_min.
 */
#include "vafm/contact.h"

#include <math.h>

#include "core/jkr_inline.h"
#include "core/internal.h"

double vafm_jkr_sqrt_a(double c, double s_m, double u, double s_guess)
{
    if (!(c >= 0.0) || !(s_m >= 0.0))
        return NAN;
    double t_guess = s_guess > s_m ? s_guess - s_m : 0.0;
    return s_m + vafm_jkr_solve_t(s_m, u - vafm_jkr_u_min(s_m), t_guess);
}

static double s_jkr_force(const vafm_contact *ct, double u, double *s_io, double *dFdu)
{
    return vafm_jkr_force_inline(ct, u, s_io, dFdu);
}

static double s_jkr_energy(const vafm_contact *ct, double u)
{
    if (isnan(u))
        return u;
    if (u < ct->u_detach)
        return 0.0;
    const double c = ct->c;
    const double s = vafm_jkr_sqrt_a(c, ct->s_m, u, 0.0);
    const double s2 = s * s, s3 = s2 * s, s4 = s2 * s2;
    return s4 * (s3 * ((8.0 / 15.0) * s3 - (4.0 / 3.0) * c) + 0.5 * c * c);
}

static int s_jkr_init(vafm_contact *out, double gamma)
{
    out->gamma = gamma;
    out->c = sqrt(2.0 * VAFM_JKR_PI * gamma);
    out->s_m = cbrt(out->c / 4.0);
    out->u_touch = 0.0;
    out->u_detach = vafm_jkr_u_min(out->s_m);
    out->a0 = cbrt(2.0 * VAFM_JKR_PI * gamma);
    out->F_jkr = 1.5 * VAFM_JKR_PI * gamma;
    return VAFM_OK;
}

static void s_jkr_at_force(const vafm_contact *ct, double F, double *u, double *dFdu)
{
    vafm_jkr_at_force(ct->c, F, u, dFdu);
}

static const vafm_contact_type s_jkr_type = {
    .name = "jkr",
    .description = "JKR adhesive contact (Johnson-Kendall-Roberts), hysteretic",
    .force = s_jkr_force,
    .energy = s_jkr_energy,
    .flags = VAFM_CONTACT_SURFACE | VAFM_CONTACT_ADHESIVE | VAFM_CONTACT_JKR_BRANCH | VAFM_CONTACT_WELL |
             VAFM_CONTACT_MONOTONE,
    .init = s_jkr_init,
    .at_force = s_jkr_at_force,
};

VAFM_API const vafm_contact_type *const vafm_contact_jkr = &s_jkr_type;
