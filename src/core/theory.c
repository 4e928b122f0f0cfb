/* SPDX-License-Identifier: MIT */
/*
 * Quasi-static and thermal references for the JKR contact held by a spring (physics notes,
 * "Quasi-static pull-off with a spring" and "Thermal oracles"), reduced units E* = R = 1.
 *
 * Everything is written in t = s − s_m (s = √a), as in the contact solver, so that points close to the
 * branch end u_min (the stiff-spring instability lies only ~4e-7 above it at k = 1e3) keep full
 * relative precision:
 *   u − u_min = P(t) = t⁴ + 4s_m t³ + 6s_m² t²,   F = s³((4/3)s³ − 2c),
 *   dF/du = N/D,  N = 2s²(4s³ − 3c),  D = du/ds = 4s³ − c = 4t(s² + s·s_m + s_m²).
 */
#include "vafm/theory.h"

#include <math.h>

#define S_PI 3.14159265358979323846
#define S_EULER_GAMMA 0.5772156649015329

typedef struct s_jkr {
    double c, s_m, u_min;
} s_jkr;

/* Same expressions as vafm_contact_init(), so both modules agree bit for bit on c, s_m and u_min. */
static void s_jkr_set(s_jkr *j, double gamma)
{
    j->c = sqrt(2.0 * S_PI * gamma);
    j->s_m = cbrt(j->c / 4.0);
    double s2 = j->s_m * j->s_m;
    j->u_min = -3.0 * (s2 * s2);
}

static double s_P(const s_jkr *j, double t)
{
    double t2 = t * t;
    return t2 * (t2 + 4.0 * j->s_m * t + 6.0 * j->s_m * j->s_m);
}

static double s_F(const s_jkr *j, double t)
{
    double s = j->s_m + t, s3 = s * s * s;
    return s3 * ((4.0 / 3.0) * s3 - 2.0 * j->c);
}

static double s_D(const s_jkr *j, double t)
{
    double s = j->s_m + t;
    return 4.0 * t * (s * s + s * j->s_m + j->s_m * j->s_m);
}

/* Instability: dF/du = −k on the unstable part s ∈ (s_m, (3c/4)^{1/3}). Multiplied by D > 0 this is
 * h(t) = 2s²(3c − 4s³) − k·D(t) = 0, with h(0) = 4s_m²c > 0 and h < 0 for s ≥ (3c/4)^{1/3}; the root is
 * unique because dF/du rises monotonically from −∞ to 0 on that part. Bisection to adjacent doubles,
 * then a secant polish inside the final bracket. γ = 0 (s_m = 0) has no unstable part: t* = 0. */
static double s_h(const s_jkr *j, double k, double t)
{
    double s = j->s_m + t, s2 = s * s;
    return 2.0 * s2 * (3.0 * j->c - 4.0 * s2 * s) - k * s_D(j, t);
}

static double s_t_star(const s_jkr *j, double k)
{
    if (j->s_m == 0.0)
        return 0.0;
    double lo = 0.0, hi = 1.25 * (cbrt(0.75 * j->c) - j->s_m); /* h(hi) < 0: both terms negative */
    double h_lo = s_h(j, k, lo), h_hi = s_h(j, k, hi);
    for (int i = 0; i < 2000; ++i) {
        double mid = 0.5 * (lo + hi);
        if (!(mid > lo && mid < hi))
            break;
        double h = s_h(j, k, mid);
        if (h > 0.0) {
            lo = mid;
            h_lo = h;
        } else {
            hi = mid;
            h_hi = h;
        }
    }
    if (h_lo > 0.0 && h_hi < 0.0) {
        double t = lo + (hi - lo) * (h_lo / (h_lo - h_hi));
        if (t >= lo && t <= hi)
            return t;
    }
    return h_lo > -h_hi ? hi : lo;
}

VAFM_API int vafm_theory_quasistatic(double gamma, double k, vafm_quasistatic *out)
{
    if (!out || !(gamma > 0.0) || !isfinite(gamma) || !(k > 0.0) || !isfinite(k))
        return VAFM_EINVAL;
    s_jkr j;
    s_jkr_set(&j, gamma);
    const double t = s_t_star(&j, k);
    const double P = s_P(&j, t);
    const double F = s_F(&j, t); /* < 0: tensile */

    /* d²F/du² = (d/ds dF/du)/(du/ds) = (N'D − N·D')/D³, N' = 40s⁴ − 12cs, D' = 12s² */
    const double s = j.s_m + t, s2 = s * s;
    const double N = 2.0 * s2 * (4.0 * s2 * s - 3.0 * j.c);
    const double dN = 40.0 * s2 * s2 - 12.0 * j.c * s;
    const double D = s_D(&j, t), dD = 12.0 * s2;

    vafm_quasistatic q;
    q.u_min = j.u_min;
    q.F_jkr = 1.5 * S_PI * gamma;
    q.u_star = j.u_min + P;
    q.F_star = -F;
    q.u_spr_star = q.u_star + F / k;
    q.F_det = q.F_star - k * P; /* = −k(u_spr* − u_min), without the cancellation */
    q.F2 = (dN * D - N * dD) / (D * D * D);
    *out = q;
    return VAFM_OK;
}

/* g(t) = k(u_spr − u) − F: the net force on the body along the branch. dg/ds = −(k + dF/du)·D, so g
 * rises on (0, t*) and falls for t > t* (the stable branch), with g(t*) = k(u_spr − u_spr*). */
static double s_g(const s_jkr *j, double k, double du_spr, double t)
{
    return k * (du_spr - s_P(j, t)) - s_F(j, t);
}

VAFM_API int vafm_theory_equilibrium(double gamma, double k, double u_spr, double *u_eq, double *F_eq)
{
    if (!(gamma >= 0.0) || !isfinite(gamma) || !(k > 0.0) || !isfinite(k) || !isfinite(u_spr))
        return VAFM_EINVAL;
    s_jkr j;
    s_jkr_set(&j, gamma);
    const double t_star = s_t_star(&j, k);
    /* u_spr* exactly as vafm_theory_quasistatic() reports it (0 for γ = 0: contact lost at u = 0) */
    const double u_spr_star = (j.u_min + s_P(&j, t_star)) + s_F(&j, t_star) / k;
    if (u_spr < u_spr_star)
        return VAFM_EINVAL;

    /* Bracket [t*, hi] with g(hi) < 0 (g → −∞ as F ~ s⁶); g(t*) ≥ 0 up to rounding. */
    const double du_spr = u_spr - j.u_min;
    double lo = t_star, step = 1.0 + t_star, hi = lo + step;
    int n = 0;
    while (!(s_g(&j, k, du_spr, hi) < 0.0)) {
        lo = hi; /* g(hi) ≥ 0 and hi > t*: the root lies further out */
        step *= 2.0;
        hi = lo + step;
        if (++n > 2000 || !isfinite(hi))
            return VAFM_EINVAL;
    }
    double g_lo = s_g(&j, k, du_spr, lo), g_hi = s_g(&j, k, du_spr, hi);
    for (int i = 0; i < 2000; ++i) {
        double mid = 0.5 * (lo + hi);
        if (!(mid > lo && mid < hi))
            break;
        double g = s_g(&j, k, du_spr, mid);
        if (g >= 0.0) {
            lo = mid;
            g_lo = g;
        } else {
            hi = mid;
            g_hi = g;
        }
    }
    double t = lo;
    if (g_lo > 0.0 && g_hi < 0.0) { /* secant polish inside the final bracket */
        double ts = lo + (hi - lo) * (g_lo / (g_lo - g_hi));
        if (ts >= lo && ts <= hi)
            t = ts;
    }
    if (u_eq)
        *u_eq = j.u_min + s_P(&j, t);
    if (F_eq)
        *F_eq = s_F(&j, t);
    return VAFM_OK;
}

/* Near the instability V(u) has a cubic inflection: ΔV = (4√2/3)(k·y)^{3/2}/√F″. 0 for y ≤ 0 (no
 * barrier left at or past the instability); NaN for invalid arguments. */
VAFM_API double vafm_theory_barrier(const vafm_quasistatic *q, double k, double y)
{
    if (!q || !(k > 0.0) || isnan(y))
        return NAN;
    if (y <= 0.0)
        return 0.0;
    return (4.0 * sqrt(2.0) / 3.0) * pow(k * y, 1.5) / sqrt(fabs(q->F2));
}

/* Overdamped Dudko–Hummer–Szabo, ν = 2/3: the rupture barrier in units of kT is Gumbel distributed with
 * mean ln Λ + γ_E, Λ = F″kT/(4πζkv); inverting the barrier formula gives
 * k·y* = [3√F″·kT(ln Λ + γ_E)/(4√2)]^{2/3}. */
VAFM_API double vafm_theory_dhs_mean_y(const vafm_quasistatic *q, double k, double kT, double v,
                                       double zeta)
{
    if (!q || !(k > 0.0) || !(kT > 0.0) || !(v > 0.0) || !(zeta > 0.0))
        return NAN;
    const double F2 = fabs(q->F2);
    const double Lambda = F2 * kT / (4.0 * S_PI * zeta * k * v);
    if (!(Lambda > 1.0))
        return NAN;
    const double ky = pow(3.0 * sqrt(F2) * kT * (log(Lambda) + S_EULER_GAMMA) / (4.0 * sqrt(2.0)),
                          2.0 / 3.0);
    return ky / k;
}
