/* SPDX-License-Identifier: MIT */
/*
 * The exact contact-well step of a scene's sample interval (well_exact.h): in contact, far from the
 * pull-off instability, with the thermal spread and the current excursion small against the distance to
 * the branch's soft point, the force is linear over the body's whole range and one closed-form transition
 * replaces the interval's integrator steps. sim.c decides when to try it; this file decides whether it
 * applies and takes it.
 */
#include <math.h>
#include <string.h>

#include "vafm/theory.h"
#include "core/jkr_inline.h"
#include "core/kernel.h"
#include "core/sim_impl.h"
#include "core/well_exact.h"

/* The equilibrium on the contact branch for the support at uspr: k(uspr − u) = F(u). Newton in t
 * (u = u_min + P(t), s = s_m + t) from the last equilibrium, which the pull has moved by a tiny fraction
 * of a well width, so two or three iterations reach round-off; a cold start, or a Newton run that does not
 * settle, takes the bracketing solver of theory.c instead. The derivatives come in closed form
 * (vafm_jkr_derivs, jkr_inline.h).
 * @return 1, or 0 if there is no equilibrium on the branch there (past the instability). */
static int s_weq_solve(const vafm_sim *s, double uspr, double t_warm, s_weq *e)
{
    const vafm_kernel *K = &s->K;
    const double s_m = K->contact.s_m, c = K->contact.c, k = K->k;
    const double u_min = vafm_jkr_u_min(s_m), du_spr = uspr - u_min;
    double t = t_warm;
    int done = 0;
    if (t > 0.0) {
        for (int it = 0; it < 6 && !done; it++) {
            const double sv = s_m + t, s2 = sv * sv, t2 = t * t;
            /* g = k(Δu_spr − P) − F, F = s³((4/3)s³ − 2c) with s³ rounded as s²·s here (the warm-started
             * Newton's own rounding, which the pinned curves depend on) */
            const double g = k * (du_spr - vafm_jkr_P(s_m, t)) - s2 * sv * ((4.0 / 3.0) * s2 * sv - 2.0 * c);
            const double dP = t * (4.0 * t2 + 12.0 * s_m * t + 12.0 * s_m * s_m);
            const double dg = -k * dP - 2.0 * s2 * (4.0 * s2 * sv - 3.0 * c); /* −k·dP/dt − dF/ds */
            const double d = g / dg;
            if (!(dg < 0.0) || !(fabs(d) <= 0.25 * t))
                break; /* not on the stable branch's monotone side, or far off: bracket instead */
            t -= d;
            /* quadratic convergence: after a step |d| ≤ 1e-12·t what is left is ~d²/t, far below an ulp */
            done = fabs(d) <= 1e-12 * t;
        }
    }
    if (!done) {
        double ueq, Feq;
        if (vafm_theory_equilibrium(K->contact.gamma, k, uspr, &ueq, &Feq) != 0)
            return 0;
        t = vafm_jkr_solve_t(s_m, ueq - u_min, 0.0);
    }
    if (!(t > 0.0))
        return 0;
    e->uspr = uspr;
    e->t = t;
    e->ueq = u_min + vafm_jkr_P(s_m, t);
    vafm_jkr_derivs(s_m, c, t, &e->dF, &e->F2, &e->F3);
    e->ok = 1;
    return 1;
}

/* The equilibrium at uspr through the one-entry memo (consecutive well intervals share their boundary
 * support position bit for bit). */
static int s_weq_at(vafm_sim *s, double uspr, s_weq *e)
{
    if (s->weq.ok && s->weq.uspr == uspr) {
        *e = s->weq;
        return 1;
    }
    if (!s_weq_solve(s, uspr, s->weq.ok ? s->weq.t : 0.0, e))
        return 0;
    s->weq = *e;
    return 1;
}

/* The exact contact-well step over one sample interval, when it applies (see the file comment).
 * Linearised about the equilibrium u_eq0 at the interval start with stiffness K = k + dF/du there; the
 * equilibrium moves at r = (u_eq1 − u_eq0)/Ts and friction (relative to the support for the cantilever
 * channel, to the sample for the contact channel) shifts the centre by x_s = −m(η_tot·r − v)/K.
 * @return 1 if the interval was done this way, 0 if it does not apply. */
int vafm_sim_well_interval(vafm_sim *s)
{
    vafm_kernel *K = &s->K;
    const double Ts = s->nm.Ts, v = K->v_spr;
    s_weq e0, e1;
    if (!s_weq_at(s, K->u_spr, &e0) || !s_weq_at(s, K->u_spr + v * Ts, &e1))
        return 0;
    const double ueq0 = e0.ueq, ueq1 = e1.ueq;
    const double Kt = K->k + e0.dF;
    const double room = ueq0 - s->nm.u_soft; /* distance to where the branch's stiffness vanishes */
    if (!(Kt > 0.0) || !(room > 0.0))
        return 0;
    const double eta = K->co[1].eta_tot, m = K->m;
    const double sigma = sqrt(K->kT / Kt);
    /* curvature of the force: the leading anharmonic effect is the mean shift −F″kT/(2K²); it is
     * added to the centre line. The second order (the variance, below) goes into the stiffness, and the
     * scheme is used only while the third order is small: |F″|σ ≤ 0.1 K and |F‴|σ² ≤ 0.1 K, which keeps
     * the neglected terms of the variance at the 1e-3 level (they go like (F″σ/K)³ and F″F‴σ³/K²). */
    const double F2 = e0.F2;
    const double r = (ueq1 - ueq0) / Ts;
    const double xs = -m * (eta * r - v) / Kt - F2 * K->kT / (2.0 * Kt * Kt);
    const double X = K->u - (ueq0 + xs), V = K->w - r;
    const double amp = sqrt(X * X + m * V * V / Kt);
    if (!(6.0 * sigma <= room) || !(fabs(F2) * sigma <= 0.1 * Kt) || !(fabs(e0.F3) * sigma * sigma <= 0.1 * Kt) ||
        !(amp <= 6.0 * sigma + 1e-3 * room))
        return 0;
    vafm_well3 W;
    /* quasi-harmonic stiffness: the anharmonic well's variance to second order, kT/K·(1 + (F″σ/K)² −
     * F‴σ²/(2K)) (perturbation theory of V = Kx²/2 + F″x³/6 + F‴x⁴/24 about its minimum; the mean
     * shift above is the first order). Without it the box-car samples' variance and lag-1 autocovariance
     * of a paper-fig4 dwell (F″σ/K = 0.04) came out 1.0% and 1.3% low (−3σ, −4σ at N = 4e6) against plain
     * steps at a quarter step; with it, −0.2% and −0.3% (−0.7σ, −0.9σ). */
    const double Keff = Kt / (1.0 + (F2 * sigma / Kt) * (F2 * sigma / Kt) - e0.F3 * sigma * sigma / (2.0 * Kt));
    vafm_well3_setup(&W, Keff / m, eta, 2.0 * eta * K->kT / m, Ts);
    const vafm_kernel K0 = *K; /* to undo a draw that leaves the linear range (see below) */
    double x[3] = { X, V, 0.0 }, nx[3];
    for (int i = 0; i < 3; i++)
        nx[i] = W.phi[i][0] * x[0] + W.phi[i][1] * x[1];
    if (K->thermal) {
        double xi[3];
        for (int i = 0; i < 3; i++)
            xi[i] = s_kernel_normal(K);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j <= i; j++)
                nx[i] += W.chol[i][j] * xi[j];
    }
    s_kernel_phase(K, v);
    K->dt = Ts;
    K->n = 1;
    K->t = K->t0 + Ts;
    K->u_spr = K->uspr0 + v * Ts;
    const double c0 = ueq0 + xs;
    K->u = c0 + r * Ts + nx[0];
    K->w = r + nx[1];
    if (!(K->u > s->nm.u_soft)) {
        /* a tail draw (≥ 6σ, probability < 1e-9) beyond the branch's soft point, where the linear well
         * is qualitatively wrong: undo it, random stream included, and let the integrator do this
         * interval from the same state */
        *K = K0;
        return 0;
    }
    /* the sample is the interval mean: centre line mean plus I/Ts */
    K->acc_u = c0 + 0.5 * r * Ts + nx[2] / Ts;
    K->acc_uspr = K->uspr0 + 0.5 * v * Ts;
    K->acc_n = 1;
    K->s = K->contact.s_m + e1.t; /* warm start: the body is within a few σ of the new equilibrium */
    K->Fc = K->jtab ? vafm_jkr_table_force(K->jtab, &K->contact, K->u, &K->s) /* as the integrator's steps */
                    : K->cforce(&K->contact, K->u, &K->s, NULL);
    double fs = K->k * (K->u_spr - K->u);
    K->f = fs - K->Fc;
    if (fs < K->fs_min)
        K->fs_min = fs;
    K->steps++;
    K->steps_contact++;
    K->steps_free++;
    return 1;
}
