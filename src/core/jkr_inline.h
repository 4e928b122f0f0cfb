/* SPDX-License-Identifier: MIT */
/*
 * The JKR solver and force as static inline functions, so that the stepping kernel can call them
 * without an indirect call (the contact solve is the largest part of an in-contact step); the
 * `jkr` type object in contact_jkr.c wraps the same code. See contact_jkr.c for the derivation.
 */
#ifndef VAFM_CORE_JKR_INLINE_H
#define VAFM_CORE_JKR_INLINE_H

#include <math.h>

#include "vafm/contact.h"
#include "core/gjf_step.h"

#define VAFM_JKR_PI 3.14159265358979323846

/* Newton stops after a step |δ| ≤ VAFM_JKR_TOL·t. Near the root the error after a step is
 * e' = P''(ξ)/(2P'(t))·e² ≤ (3/2)e²/t, because t·P''/(2P') = (12t² + 24s_m t + 12s_m²)/
 * (8t² + 24s_m t + 24s_m²) ≤ 3/2. With |δ| ≤ 5e-9·t the error left is ≤ 3.8e-17·t, i.e. below an
 * ulp: the step that would merely confirm convergence (|δ| ~ 1e-16·t) is skipped. A warm start that
 * is off by ≲ 5e-5 relative therefore returns after 2 iterations, one off by ≲ 5e-9 after 1. */
#define VAFM_JKR_TOL 5e-9
#define VAFM_JKR_MAX_ITER 60

/* u_min = −3s_m⁴: the same expression is used for the solver and for vafm_contact.u_detach. */
static inline double vafm_jkr_u_min(double s_m)
{
    double s2 = s_m * s_m;
    return -3.0 * (s2 * s2);
}

/* The t-form of the branch (s = s_m + t, c = 4s_m³): u − u_min = P(t), the force F(t), D = du/ds. */
static inline double vafm_jkr_P(double s_m, double t)
{
    double t2 = t * t;
    return t2 * (t2 + 4.0 * s_m * t + 6.0 * s_m * s_m);
}

static inline double vafm_jkr_F_t(double s_m, double c, double t)
{
    double s = s_m + t, s3 = VAFM_JKR_CUBE(s);
    return VAFM_JKR_FORCE(s3, 2.0 * c);
}

static inline double vafm_jkr_D(double s_m, double t)
{
    double s = s_m + t;
    return 4.0 * t * (s * s + s * s_m + s_m * s_m); /* = 4s³ − c without the cancellation at t → 0 */
}

/* dF/du, d²F/du² and d³F/du³ at t > 0 (any output may be NULL), in closed form: with N = dF/ds =
 * 2s²(4s³ − 3c), dF/du = N/D, d²F/du² = (N′D − N·D′)/D³ (N′ = 40s⁴ − 12cs, D′ = 12s²) and
 * d³F/du³ = [(N″D − N·D″)/D³ − 3(N′D − N·D′)D′/D⁴]/D (N″ = 160s³ − 12c, D″ = 24s). */
static inline void vafm_jkr_derivs(double s_m, double c, double t, double *dF, double *F2, double *F3)
{
    const double s = s_m + t, s2 = s * s, D = vafm_jkr_D(s_m, t);
    const double N = 2.0 * s2 * (4.0 * s2 * s - 3.0 * c);
    const double dN = 40.0 * s2 * s2 - 12.0 * c * s, dD = 12.0 * s2;
    if (dF)
        *dF = N / D;
    if (F2)
        *F2 = (dN * D - N * dD) / (D * D * D);
    if (F3) {
        const double d2N = 160.0 * (s2 * s) - 12.0 * c, d2D = 24.0 * s;
        *F3 = ((d2N * D - N * d2D) / (D * D * D) - 3.0 * (dN * D - N * dD) * dD / (D * D * D * D)) / D;
    }
}

/* The cold start t₀ = min[Δu^{1/4}, √(Δu/6)/s_m] ≥ root (s_m > 0, du > 0). */
static inline double vafm_jkr_t_cold(double s_m, double du)
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
static inline double vafm_jkr_solve_t(double s_m, double du, double t_guess)
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
        t0 = vafm_jkr_t_cold(s_m, du);
        t = t0;
    }
    for (int it = 0; it < VAFM_JKR_MAX_ITER; ++it) {
        double t2 = t * t;
        double p = t2 * (t2 + b * t + q) - du;
        double dp = t * (4.0 * t2 + 3.0 * b * t + 2.0 * q);
        double d = p / dp;
        double tn = t - d;
        if (!(fabs(d) <= 0.25 * t)) {
            if (t0 < 0.0)
                t0 = vafm_jkr_t_cold(s_m, du);
            if (!(tn <= t0) || !(tn >= 0.0)) /* too far right, non-finite, or negative */
                tn = t0;
        }
        t = tn;
        if (fabs(d) <= VAFM_JKR_TOL * t)
            break;
    }
    return t;
}


static inline double vafm_jkr_force_inline(const vafm_contact *ct, double u, double *s_io, double *dFdu)
{
    const double c = ct->c, s_m = ct->s_m;
    double t_guess = 0.0;
    if (s_io && *s_io > s_m)
        t_guess = *s_io - s_m;
    const double t = vafm_jkr_solve_t(s_m, u - vafm_jkr_u_min(s_m), t_guess);
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
    return VAFM_JKR_FORCE(s3, 2.0 * c); /* core/gjf_step.h, as the table */
}

/* Where the stable branch carries force F ≥ 0 (JKR, and Hertz as c = 0): F = (4/3)x² − 2c·x with
 * x = s³ gives x = (3/4)(c + √(c² + 4F/3)), then u = s⁴ − c·s and dF/du = 2s²(4x − 3c)/(4x − c). The
 * contact models' at_force hook (numerics.c chooses the time step from it). */
static inline void vafm_jkr_at_force(double c, double F, double *u, double *dFdu)
{
    const double x = 0.75 * (c + sqrt(c * c + 4.0 * F / 3.0)), s = cbrt(x);
    if (u)
        *u = s * s * s * s - c * s;
    if (dFdu)
        *dFdu = 2.0 * s * s * (4.0 * x - 3.0 * c) / (4.0 * x - c);
}

#endif
