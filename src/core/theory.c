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
#include "core/jkr_inline.h"

#include <math.h>
#include <stdlib.h>

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
    return vafm_jkr_P(j->s_m, t);
}

static double s_F(const s_jkr *j, double t)
{
    return vafm_jkr_F_t(j->s_m, j->c, t);
}

static double s_D(const s_jkr *j, double t)
{
    return vafm_jkr_D(j->s_m, t);
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


    vafm_quasistatic q;
    q.u_min = j.u_min;
    q.F_jkr = 1.5 * S_PI * gamma;
    q.u_star = j.u_min + P;
    q.F_star = -F;
    q.u_spr_star = q.u_star + F / k;
    q.F_det = q.F_star - k * P; /* = −k(u_spr* − u_min), without the cancellation */
    vafm_jkr_derivs(j.s_m, j.c, t, NULL, &q.F2, NULL); /* d²F/du² at the instability */
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

/* ---- exact 1D mean first passage (overdamped), physics notes "Thermal oracles" ------------------- *
 *
 * V(t) relative to a reference point, in t (u − u_min = P(t)): the spring part as a product so that
 * no large squares cancel, k/2[(d − P)² − (d − P_r)²] = k/2 (P_r − P)(2d − P − P_r), d = u_spr − u_min. */
typedef struct s_pot {
    s_jkr j;
    double k, beta, du_spr, t_ref, P_ref, U_ref;
} s_pot;

static double s_U(const s_jkr *j, double t)
{
    double s = j->s_m + t, s2 = s * s, s3 = s2 * s, s4 = s2 * s2;
    return s4 * (s3 * ((8.0 / 15.0) * s3 - (4.0 / 3.0) * j->c) + 0.5 * j->c * j->c);
}

static double s_V(const s_pot *p, double t)
{
    double P = s_P(&p->j, t);
    return 0.5 * p->k * (p->P_ref - P) * (2.0 * p->du_spr - P - p->P_ref) + (s_U(&p->j, t) - p->U_ref);
}

/* (1 − e^{−x})/x, continuous at 0 */
static double s_phi(double x)
{
    return fabs(x) < 1e-8 ? 1.0 - 0.5 * x : -expm1(-x) / x;
}

/* T(x₀) on n intervals per side. J(u) = ∫_u^∞ e^{−β(V(z) − V(u))} dz obeys, with V linear in u on each
 * interval (exact integration of the exponential there), J_i = e^{−x}J_{i+1} + Δu·φ(x), x = βΔV; the tail
 * beyond t_hi is J ≈ 1/(βV′) there. T = (ζ/kT)∫_{u_min}^{x₀} J du, J log-linear on each interval.
 * Returns INFINITY when J overflows (barrier beyond ~650 kT). */
static double s_mfpt_n(const s_pot *p, double t0, double t_hi, int n, double zeta)
{
    const double kT = 1.0 / p->beta;
    double g_hi = s_g(&p->j, p->k, p->du_spr, t_hi);
    double J = g_hi < 0.0 ? kT / -g_hi : 0.0;
    double V_next = s_V(p, t_hi), P_next = s_P(&p->j, t_hi);
    double T = 0.0;
    for (int side = 1; side >= 0; --side) {
        double a = side ? t0 : 0.0, b = side ? t_hi : t0, h = (b - a) / n;
        for (int i = n - 1; i >= 0; --i) {
            double t = a + h * i;
            double V = s_V(p, t), P = s_P(&p->j, t), du = P_next - P;
            double x = p->beta * (V_next - V);
            double J_new = exp(-x) * J + du * s_phi(x);
            if (!(J_new < 1e290))
                return INFINITY;
            if (!side && du > 0.0) { /* ∫ J du over [t, t + h], J log-linear */
                double r = J_new > 0.0 && J > 0.0 ? log(J / J_new) : 0.0;
                T += du * (fabs(r) < 1e-8 ? 0.5 * (J + J_new) : (J - J_new) / r);
            }
            J = J_new;
            V_next = V;
            P_next = P;
        }
    }
    return T * zeta / kT;
}

VAFM_API int vafm_theory_mfpt_rate(double gamma, double k, double kT, double zeta, double mass, double y,
                                   double *rate)
{
    if (!rate || !(gamma > 0.0) || !isfinite(gamma) || !(k > 0.0) || !isfinite(k) || !(kT > 0.0) ||
        !isfinite(kT) || !(zeta > 0.0) || !isfinite(zeta) || !isfinite(y) || !(mass >= 0.0) || !isfinite(mass))
        return VAFM_EINVAL;
    vafm_quasistatic q;
    vafm_theory_quasistatic(gamma, k, &q);
    s_pot p;
    s_jkr_set(&p.j, gamma);
    p.k = k;
    p.beta = 1.0 / kT;
    p.du_spr = y - q.F_det / k; /* u_spr − u_min = (u_spr* − u_min) + y, u_spr* − u_min = −F_det/k */
    const double ts = s_t_star(&p.j, k);
    /* start: the well (root of g beyond t*, where g(t*) = k·y > 0) or t* itself */
    double t0 = ts;
    if (y > 0.0) {
        double lo = ts, hi = ts + (1.0 + ts);
        while (s_g(&p.j, k, p.du_spr, hi) > 0.0) {
            lo = hi;
            hi = ts + 2.0 * (hi - ts);
            if (!isfinite(hi))
                return VAFM_EINVAL;
        }
        for (int i = 0; i < 200; ++i) {
            double mid = 0.5 * (lo + hi);
            if (!(mid > lo && mid < hi))
                break;
            if (s_g(&p.j, k, p.du_spr, mid) > 0.0)
                lo = mid;
            else
                hi = mid;
        }
        t0 = 0.5 * (lo + hi);
    }
    p.t_ref = t0;
    p.P_ref = s_P(&p.j, t0);
    p.U_ref = s_U(&p.j, t0);
    /* right end: where V has risen 40 kT above the start (V rises monotonically beyond t0) */
    double d = 1e-6 * (p.j.s_m + t0) + 1e-300;
    while (p.beta * s_V(&p, t0 + d) < 40.0) {
        d *= 2.0;
        if (!isfinite(d))
            return VAFM_EINVAL;
    }
    const double t_hi = t0 + d;
    double T_prev = s_mfpt_n(&p, t0, t_hi, 256, zeta), T = T_prev;
    for (int n = 512; n <= (1 << 20); n *= 2) {
        T = s_mfpt_n(&p, t0, t_hi, n, zeta);
        if (!isfinite(T) || fabs(T - T_prev) <= 1e-5 * T)
            break;
        T_prev = T;
    }
    double kappa = 1.0;
    if (mass > 0.0 && y > 0.0 && s_g(&p.j, k, p.du_spr, 0.0) < 0.0) {
        /* inertia: Kramers' spatial-diffusion factor at the barrier top (root of g in (0, t*)),
         * κ = η/(η/2 + √(η²/4 + ω_b²)), ω_b² = |V″_b|/m, V″ = k + dF/du, dF/du = N/D */
        double lo = 0.0, hi = ts;
        for (int i = 0; i < 200; ++i) {
            double mid = 0.5 * (lo + hi);
            if (!(mid > lo && mid < hi))
                break;
            if (s_g(&p.j, k, p.du_spr, mid) < 0.0)
                lo = mid;
            else
                hi = mid;
        }
        double tb = 0.5 * (lo + hi), s = p.j.s_m + tb, s2 = s * s;
        double dFdu = 2.0 * s2 * (4.0 * s2 * s - 3.0 * p.j.c) / s_D(&p.j, tb);
        double wb2 = fabs(k + dFdu) / mass, eta = zeta / mass;
        kappa = eta / (0.5 * eta + sqrt(0.25 * eta * eta + wb2));
    }
    *rate = isfinite(T) && T > 0.0 ? kappa / T : 0.0;
    return VAFM_OK;
}

/* One node of the rate table along the pull. */
typedef struct s_node {
    double y, r;
} s_node;

VAFM_API int vafm_theory_mfpt_pull(double gamma, double k, double kT, double zeta, double mass, double y_start,
                                   const double *v, size_t n_v, vafm_theory_pull *out)
{
    if (!v || !out || !n_v || !(gamma > 0.0) || !(k > 0.0) || !(kT > 0.0) || !(zeta > 0.0) ||
        !isfinite(gamma) || !isfinite(k) || !isfinite(kT) || !isfinite(zeta) || isnan(y_start) ||
        !(mass >= 0.0) || !isfinite(mass))
        return VAFM_EINVAL;
    double v_max = 0.0;
    for (size_t i = 0; i < n_v; ++i) {
        if (!(v[i] > 0.0) || !isfinite(v[i]))
            return VAFM_EINVAL;
        v_max = fmax(v_max, v[i]);
    }
    vafm_quasistatic q;
    vafm_theory_quasistatic(gamma, k, &q);
    if (!(y_start > 0.0)) { /* fold barrier (4√2/3)(ky)^{3/2}/√F″ = 80 kT */
        double ky = pow(80.0 * kT * sqrt(q.F2) * 3.0 / (4.0 * sqrt(2.0)), 2.0 / 3.0);
        y_start = ky / k;
    }
    if (!isfinite(y_start))
        return VAFM_EINVAL;

    /* Rate table from y_start downward: steps adapt so that ln r changes by ≤ 0.5 between nodes (ln r is smooth: log-linear interpolation). */
    size_t cap = 1024, n = 0;
    s_node *tab = malloc(cap * sizeof *tab);
    if (!tab)
        return VAFM_ENOMEM;
    double y = y_start, r, dy = y_start / 64.0;
    if (vafm_theory_mfpt_rate(gamma, k, kT, zeta, mass, y, &r)) {
        free(tab);
        return VAFM_EINVAL;
    }
    tab[n++] = (s_node){ y, r };
    double H_fast = 0.0; /* hazard accumulated by the fastest pull */
    const double dy_min = 1e-12 * (y_start + fabs(q.u_spr_star));
    while (y > -y_start && H_fast < 21.0 && n < 200000) {
        double y1 = y - dy, r1;
        if (vafm_theory_mfpt_rate(gamma, k, kT, zeta, mass, y1, &r1)) {
            free(tab);
            return VAFM_EINVAL;
        }
        double jump = (r > 0.0 && r1 > 0.0) ? fabs(log(r1 / r)) : (r == r1 ? 0.0 : INFINITY);
        if (jump > 0.5 && dy > dy_min && !(r == 0.0 && r1 < 1e-300)) {
            dy *= 0.5;
            continue;
        }
        if (n == cap) {
            s_node *nt = realloc(tab, 2 * cap * sizeof *tab);
            if (!nt) {
                free(tab);
                return VAFM_ENOMEM;
            }
            tab = nt;
            cap *= 2;
        }
        tab[n++] = (s_node){ y1, r1 };
        H_fast += dy * 0.5 * (r + r1) / v_max;
        y = y1;
        r = r1;
        if (jump < 0.15)
            dy *= 1.5;
        dy = fmin(dy, y_start / 16.0);
    }

    /* Per speed: survival through the table; inside a node interval ln r is linear, and an interval
     * whose hazard exceeds 0.01 is cut into pieces so the escape position is resolved. */
    for (size_t iv = 0; iv < n_v; ++iv) {
        double S = 1.0, m1 = 0.0, m2 = 0.0;
        for (size_t i = 0; i + 1 < n && S > 1e-12; ++i) {
            double ya = tab[i].y, yb = tab[i + 1].y, ra = tab[i].r, rb = tab[i + 1].r;
            double H = (ya - yb) * 0.5 * (ra + rb) / v[iv];
            int m = H > 0.01 ? (int)fmin(ceil(H / 0.01), 4096.0) : 1;
            double la = ra > 0.0 ? log(ra) : -745.0, lb = rb > 0.0 ? log(rb) : -745.0;
            for (int jj = 0; jj < m; ++jj) {
                double f0 = (double)jj / m, f1 = (double)(jj + 1) / m;
                double y0 = ya + (yb - ya) * f0, y1 = ya + (yb - ya) * f1;
                double r0 = exp(la + (lb - la) * f0), r1 = exp(la + (lb - la) * f1);
                double lr = log(r1 > 0 && r0 > 0 ? r1 / r0 : 1.0);
                double integ = (y0 - y1) * (fabs(lr) < 1e-8 ? 0.5 * (r0 + r1) : (r1 - r0) / lr);
                double S1 = S * exp(-integ / v[iv]);
                double p = S - S1, ym = 0.5 * (y0 + y1);
                m1 += p * ym;
                m2 += p * ym * ym;
                S = S1;
            }
        }
        double mass = 1.0 - S;
        vafm_theory_pull *o = &out[iv];
        o->v = v[iv];
        o->p_unescaped = S;
        if (mass > 0.0) {
            o->mean_y = m1 / mass;
            double var = m2 / mass - o->mean_y * o->mean_y;
            o->sd_y = var > 0.0 ? sqrt(var) : 0.0;
        } else {
            o->mean_y = o->sd_y = NAN;
        }
        /* friction relative to the support: at speed v it pulls the body with ζv more, so the escape that
         * the frozen-spring rate places at y happens with the spring ζv/k further in (y larger) */
        o->mean_y += zeta * v[iv] / k;
        o->mean_F = q.F_det - k * o->mean_y;
        o->sd_F = k * o->sd_y;
    }
    free(tab);
    return VAFM_OK;
}
