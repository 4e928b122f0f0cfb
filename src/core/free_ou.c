/* SPDX-License-Identifier: MIT */
/*
 * Exact propagation of the free cantilever. Out of contact the equation of motion is linear:
 * with y = u − u_spr and z = w − v_spr (support at constant speed, friction relative to it),
 * m z' = −k y − mη z + noise, an Ornstein–Uhlenbeck process in (y, z) whose transition over any step h
 * is Gaussian with mean E·(y, z) and covariance Σ∞ − E Σ∞ Eᵀ, Σ∞ = diag(kT/k, kT/m). So the free flight
 * needs no small steps: only its sampling (output rate, distance to the surface) limits h.
 * The overdamped variant (Brownian dynamics) is the scalar OU y' = −(k/ζ) y + noise.
 *
 * The same propagator serves a deep contact well (vafm_well_ou_*): there the force is linearised about
 * the moving equilibrium, u = u_eq(t) + x_s + X with X an OU process of stiffness k + dF/du; sim.c
 * decides where that holds (far from the instability, small excursions) and supplies the centre line.
 */
#include <math.h>
#include <string.h>

#include "core/kernel.h"
#include "core/well_exact.h"

void vafm_free_ou_setup(vafm_free_ou *o, const vafm_kernel *K, double h, int overdamped)
{
    /* out of contact: the spring alone, the cantilever's own friction channel */
    vafm_well_ou_setup(o, K->m, K->k, K->co[0].eta_tot, K->kT, h, overdamped);
}

void vafm_well_ou_setup(vafm_free_ou *o, double m, double stiff, double eta, double kT, double h, int overdamped)
{
    o->h = h;
    o->overdamped = overdamped;
    o->integrate = 0;
    if (overdamped) {
        double rate = stiff / (m * eta);
        o->a = exp(-rate * h);
        o->sd = sqrt(kT / stiff * -expm1(-2.0 * rate * h));
        o->e11 = o->a;
        o->e12 = o->e21 = o->e22 = 0.0;
        o->l11 = o->sd;
        o->l21 = o->l22 = 0.0;
        return;
    }
    const double w2 = stiff / m; /* ω0² */
    double E[2][2];
    vafm_osc2_propagator(w2, eta, h, E);
    o->e11 = E[0][0];
    o->e12 = E[0][1];
    o->e21 = E[1][0];
    o->e22 = E[1][1];
    const double s1 = kT / stiff, s2 = kT / m;
    double q11 = s1 - (o->e11 * o->e11 * s1 + o->e12 * o->e12 * s2);
    double q12 = -(o->e11 * o->e21 * s1 + o->e12 * o->e22 * s2);
    double q22 = s2 - (o->e21 * o->e21 * s1 + o->e22 * o->e22 * s2);
    o->l11 = q11 > 0 ? sqrt(q11) : 0.0;
    o->l21 = o->l11 > 0 ? q12 / o->l11 : 0.0;
    double r = q22 - o->l21 * o->l21;
    o->l22 = r > 0 ? sqrt(r) : 0.0;
}

/* g(x) = 2x − 2b − b², b = 1 − e^{−x}: x²·Var(I)/σ²·r²-style combination of the overdamped OU, which
 * is (2/3)x³ + O(x⁴) and cancels in the direct form for small x: there it comes from d = x − b − x²/2
 * = Σ_{n≥3} (−x)ⁿ/n! as g = 2d + x³ + 2xd − x⁴/4 − x²d − d² (no cancellation worse than 1/3). */
static double s_g_overdamped(double x)
{
    if (x >= 0.1) {
        const double b = -expm1(-x);
        return 2.0 * x - 2.0 * b - b * b;
    }
    double d = 0.0, term = x * x / 2.0;
    for (int n = 3; n <= 30; n++) {
        term *= -x / n;
        d += term;
    }
    return 2.0 * d + x * x * x + 2.0 * x * d - 0.25 * x * x * x * x - x * x * d - d * d;
}

void vafm_free_ou_integrate(vafm_free_ou *o, const vafm_kernel *K)
{
    const double m = K->m, stiff = K->k, eta = K->co[0].eta_tot, kT = K->kT, h = o->h;
    memset(o->p3, 0, sizeof o->p3);
    memset(o->c3, 0, sizeof o->c3);
    o->integrate = 1;
    if (o->overdamped) {
        /* y' = −r y + noise, stationary variance σ² = kT/k. Given y0: E[y1] = a y0, E[I] = (b/r) y0 and
         * Var y1 = σ²(1 − a²), Cov(y1, I) = σ² b²/r, Var I = σ² g(rh)/r² (a = e^{−rh}, b = 1 − a) */
        const double r = stiff / (m * eta), x = r * h, s2 = kT / stiff;
        const double a = exp(-x), b = -expm1(-x);
        const double v11 = s2 * -expm1(-2.0 * x), v12 = s2 * b * b / r, v22 = s2 * s_g_overdamped(x) / (r * r);
        o->p3[0][0] = a;
        o->p3[2][0] = b / r;
        o->c3[0][0] = v11 > 0 ? sqrt(v11) : 0.0;
        o->c3[2][0] = o->c3[0][0] > 0 ? v12 / o->c3[0][0] : 0.0;
        const double rest = v22 - o->c3[2][0] * o->c3[2][0];
        o->c3[2][2] = rest > 0 ? sqrt(rest) : 0.0;
        return;
    }
    /* the augmented oscillator (y, z, I) through Van Loan's block exponential (well_exact.c) */
    vafm_well3 W;
    vafm_well3_setup(&W, stiff / m, eta, 2.0 * eta * kT / m, h);
    for (int i = 0; i < 3; i++) {
        o->p3[i][0] = W.phi[i][0];
        o->p3[i][1] = W.phi[i][1];
        for (int j = 0; j <= i; j++)
            o->c3[i][j] = W.chol[i][j];
    }
}

/* n exact steps about the centre line c0 + c1·τ, the state in locals (the random draws may write K). */
static VAFM_KALWAYS void s_ou_steps(vafm_kernel *K, const vafm_free_ou *o, double c0, double c1, int in_contact, long n)
{
    const double dt = K->dt, k = K->k, uspr0 = K->uspr0, v_spr = K->v_spr;
    const int thermal = K->thermal;
    int64_t kn = K->n;
    double u = K->u, w = K->w, u_spr = K->u_spr, fs = 0.0;
    double acc_u = K->acc_u, acc_uspr = K->acc_uspr, fs_min = K->fs_min;
    for (long step = 0; step < n; step++) {
        const double tau0 = (double)kn * dt;
        double y = u - (c0 + c1 * tau0), z = w - c1;
        double ny, nz, nI = 0.0;
        if (o->integrate) {
            /* (y, z, I) jointly: the sample mean gets the exact integral of the path over the step */
            ny = o->p3[0][0] * y + o->p3[0][1] * z;
            nz = o->p3[1][0] * y + o->p3[1][1] * z;
            nI = o->p3[2][0] * y + o->p3[2][1] * z;
            if (thermal) {
                double x1 = s_kernel_normal(K), x2 = s_kernel_normal(K);
                if (o->overdamped) {
                    ny += o->c3[0][0] * x1;
                    nI += o->c3[2][0] * x1 + o->c3[2][2] * x2;
                } else {
                    double x3 = s_kernel_normal(K);
                    ny += o->c3[0][0] * x1;
                    nz += o->c3[1][0] * x1 + o->c3[1][1] * x2;
                    nI += o->c3[2][0] * x1 + o->c3[2][1] * x2 + o->c3[2][2] * x3;
                }
            }
        } else if (o->overdamped) {
            ny = o->a * y;
            if (thermal)
                ny += o->sd * s_kernel_normal(K);
            nz = 0.0;
        } else {
            ny = o->e11 * y + o->e12 * z;
            nz = o->e21 * y + o->e22 * z;
            if (thermal) {
                double x1 = s_kernel_normal(K), x2 = s_kernel_normal(K);
                ny += o->l11 * x1;
                nz += o->l21 * x1 + o->l22 * x2;
            }
        }
        kn++;
        const double tau = (double)kn * dt;
        u_spr = uspr0 + v_spr * tau;
        u = c0 + c1 * tau + ny;
        w = c1 + nz;
        fs = k * (u_spr - u);
        if (o->integrate) { /* the step's time averages: centre line at mid-step plus I/h */
            const double mid = tau0 + 0.5 * o->h;
            acc_u += c0 + c1 * mid + nI / o->h;
            acc_uspr += uspr0 + v_spr * mid;
        } else {
            acc_u += u;
            acc_uspr += u_spr;
        }
        if (fs < fs_min)
            fs_min = fs;
    }
    if (n <= 0)
        return;
    K->n = kn;
    K->t = K->t0 + (double)kn * dt;
    K->u_spr = u_spr;
    K->u = u;
    K->w = w;
    if (!in_contact) {
        K->Fc = 0.0;
        K->f = fs;
    }
    K->acc_u = acc_u;
    K->acc_uspr = acc_uspr;
    K->acc_n += n;
    K->fs_min = fs_min;
    K->steps += (uint64_t)n;
    K->steps_free += (uint64_t)n;
    K->steps_contact += in_contact ? (uint64_t)n : 0u;
}

void vafm_free_ou_step(vafm_kernel *K, const vafm_free_ou *o)
{
    s_ou_steps(K, o, K->uspr0, K->v_spr, 0, 1);
}

void vafm_free_ou_steps(vafm_kernel *K, const vafm_free_ou *o, long n)
{
    s_ou_steps(K, o, K->uspr0, K->v_spr, 0, n);
}

void vafm_well_ou_step(vafm_kernel *K, const vafm_free_ou *o, double c0, double c1, int in_contact)
{
    s_ou_steps(K, o, c0, c1, in_contact, 1);
}
