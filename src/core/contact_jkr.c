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
 *
 * The end of this file also holds the generic contact functions (init, eval_at, type_find).
 */
#include "vafm/contact.h"

#include <math.h>
#include <string.h>

#define S_PI 3.14159265358979323846

/* Newton stops after a step |δ| ≤ S_TOL·t. Near the root the error after a step is
 * e' = P''(ξ)/(2P'(t))·e² ≤ (3/2)e²/t, because t·P''/(2P') = (12t² + 24s_m t + 12s_m²)/
 * (8t² + 24s_m t + 24s_m²) ≤ 3/2. With |δ| ≤ 5e-9·t the error left is ≤ 3.8e-17·t, i.e. below an
 * ulp: the step that would merely confirm convergence (|δ| ~ 1e-16·t) is skipped. A warm start that
 * is off by ≲ 5e-5 relative therefore returns after 2 iterations, one off by ≲ 5e-9 after 1. */
#define S_TOL 5e-9
#define S_MAX_ITER 60

/* u_min = −3s_m⁴: the same expression is used for the solver and for vafm_contact.u_detach. */
static double s_u_min(double s_m)
{
    double s2 = s_m * s_m;
    return -3.0 * (s2 * s2);
}

/* The cold start t₀ = min[Δu^{1/4}, √(Δu/6)/s_m] ≥ root (s_m > 0, du > 0). */
static double s_t_cold(double s_m, double du)
{
    double t0 = sqrt(sqrt(du));
    double t1 = sqrt(du / 6.0) / s_m;
    return t1 < t0 ? t1 : t0;
}

/* Root t ≥ 0 of P(t) = du for s_m ≥ 0. t_guess > 0 is a warm start; ≤ 0 (or NaN) means cold.
 * du < 0 or NaN → NaN; du = 0 → 0 exactly. Never allocates.
 *
 * Warm start: Newton runs from t_guess directly. Right of the root it is monotone; left of it the first
 * step overshoots to the right, then it is monotone. Only a big step (|δ| > t/4: a guess far off, or
 * P'(t) = 0 at t = 0, or a non-finite step) brings in t₀, which caps the iterate; that keeps absurd
 * guesses (1e-300, 1e300) to a few iterations and spares the hot path its three square roots. */
static double s_solve_t(double s_m, double du, double t_guess)
{
    if (!(du > 0.0))
        return du == 0.0 ? 0.0 : NAN;
    if (s_m == 0.0 || isinf(du))
        return sqrt(sqrt(du)); /* γ = 0: exact Hertz, P(t) = t⁴ */

    const double b = 4.0 * s_m;        /* P(t) = t²(t² + b t + q) */
    const double q = 6.0 * s_m * s_m;  /* P'(t) = t(4t² + 3b t + 2q) */
    double t0 = -1.0;                  /* the cold start, computed when needed */
    double t;
    if (t_guess > 0.0 && t_guess < INFINITY) {
        t = t_guess;
    } else {
        t0 = s_t_cold(s_m, du);
        t = t0;
    }
    for (int it = 0; it < S_MAX_ITER; ++it) {
        double t2 = t * t;
        double p = t2 * (t2 + b * t + q) - du;
        double dp = t * (4.0 * t2 + 3.0 * b * t + 2.0 * q);
        double d = p / dp;
        double tn = t - d;
        if (!(fabs(d) <= 0.25 * t)) {
            if (t0 < 0.0)
                t0 = s_t_cold(s_m, du);
            if (!(tn <= t0) || !(tn >= 0.0)) /* too far right, non-finite, or negative */
                tn = t0;
        }
        t = tn;
        if (fabs(d) <= S_TOL * t)
            break;
    }
    return t;
}

VAFM_API double vafm_jkr_sqrt_a(double c, double s_m, double u, double s_guess)
{
    if (!(c >= 0.0) || !(s_m >= 0.0))
        return NAN;
    double t_guess = s_guess > s_m ? s_guess - s_m : 0.0;
    return s_m + s_solve_t(s_m, u - s_u_min(s_m), t_guess);
}

static double s_jkr_force(const vafm_contact *ct, double u, double *s_io, double *dFdu)
{
    const double c = ct->c, s_m = ct->s_m;
    double t_guess = 0.0;
    if (s_io && *s_io > s_m)
        t_guess = *s_io - s_m;
    const double t = s_solve_t(s_m, u - s_u_min(s_m), t_guess);
    const double s = s_m + t, s2 = s * s, s3 = s2 * s;
    if (dFdu) {
        if (c == 0.0)
            *dFdu = 2.0 * s2; /* Hertz: 2a */
        else if (t == 0.0)
            *dFdu = -INFINITY; /* the branch end u_min */
        else
            *dFdu = 2.0 * s2 * (4.0 * s3 - 3.0 * c) / (4.0 * t * (s2 + s * s_m + s_m * s_m));
    }
    if (s_io)
        *s_io = s;
    return s3 * ((4.0 / 3.0) * s3 - 2.0 * c);
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

static const vafm_contact_type s_jkr_type = {
    .name = "jkr",
    .description = "JKR adhesive contact (Johnson-Kendall-Roberts), hysteretic",
    .force = s_jkr_force,
    .energy = s_jkr_energy,
};

VAFM_API const vafm_contact_type *const vafm_contact_jkr = &s_jkr_type;

/* ---------------------------------------------------------------------------------------------- */
/* generic contact functions                                                                      */
/* ---------------------------------------------------------------------------------------------- */

VAFM_API int vafm_contact_init(vafm_contact *c, const vafm_contact_type *type, double gamma)
{
    if (!c || !type)
        return VAFM_EINVAL;
    if (!(gamma >= 0.0) || !isfinite(gamma))
        return VAFM_EINVAL;
    vafm_contact out = {.type = type};
    if (type == vafm_contact_jkr) {
        out.gamma = gamma;
        out.c = sqrt(2.0 * S_PI * gamma);
        out.s_m = cbrt(out.c / 4.0);
        out.u_touch = 0.0;
        out.u_detach = s_u_min(out.s_m);
        out.a0 = cbrt(2.0 * S_PI * gamma);
        out.F_jkr = 1.5 * S_PI * gamma;
    } else if (type == vafm_contact_hertz) {
        if (gamma != 0.0)
            return VAFM_EINVAL;
        out.u_touch = 0.0;
        out.u_detach = 0.0;
    } else if (type == vafm_contact_none) {
        /* gamma is ignored: no sample, no adhesion */
        out.u_touch = INFINITY;
        out.u_detach = INFINITY;
    } else {
        return VAFM_EINVAL; /* unknown model: its touch/detach points are not known here */
    }
    *c = out;
    return VAFM_OK;
}

VAFM_API int vafm_contact_eval_at(const vafm_contact *c, double u, vafm_contact_eval *out)
{
    if (!c || !c->type || !c->type->force || !out)
        return VAFM_EINVAL;
    if (!isfinite(u) || !(u >= c->u_detach))
        return VAFM_EINVAL;
    double s = 0.0, dFdu = 0.0;
    double F = c->type->force(c, u, &s, &dFdu);
    out->a = s * s;
    out->F = F;
    out->dFdu = dFdu;
    return VAFM_OK;
}

VAFM_API const vafm_contact_type *vafm_contact_type_find(const char *name)
{
    if (!name)
        return NULL;
    const vafm_contact_type *const all[] = {vafm_contact_jkr, vafm_contact_hertz, vafm_contact_none};
    for (size_t i = 0; i < sizeof all / sizeof all[0]; ++i)
        if (strcmp(all[i]->name, name) == 0)
            return all[i];
    return NULL;
}
