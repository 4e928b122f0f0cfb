/* SPDX-License-Identifier: MIT */
#include <math.h>
#include <string.h>

#include "core/well_exact.h"

typedef double s_m3[3][3];
typedef double s_m6[6][6];

static void s_mul3(s_m3 a, s_m3 b, s_m3 out)
{
    s_m3 r;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double acc = 0.0;
            for (int k = 0; k < 3; k++)
                acc += a[i][k] * b[k][j];
            r[i][j] = acc;
        }
    memcpy(out, r, sizeof r);
}

/* exp(M) by Taylor series for ‖M‖∞ ≤ 1/2 (18 terms: the remainder is below 0.5^19/19! ≈ 2e-23). */
static void s_expm6(s_m6 M, s_m6 E)
{
    s_m6 term, next;
    memset(E, 0, sizeof(s_m6));
    memset(term, 0, sizeof term);
    for (int i = 0; i < 6; i++)
        E[i][i] = term[i][i] = 1.0;
    for (int n = 1; n <= 18; n++) {
        for (int i = 0; i < 6; i++)
            for (int j = 0; j < 6; j++) {
                double acc = 0.0;
                for (int k = 0; k < 6; k++)
                    acc += term[i][k] * M[k][j];
                next[i][j] = acc / n;
            }
        memcpy(term, next, sizeof term);
        for (int i = 0; i < 6; i++)
            for (int j = 0; j < 6; j++)
                E[i][j] += term[i][j];
    }
}

/* Symmetrise sig and store its lower Cholesky factor (clamping the round-off of a singular direction to
 * zero). */
static void s_chol3(vafm_well3 *W, s_m3 sig)
{
    memset(W->chol, 0, sizeof W->chol);
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < i; j++)
            sig[i][j] = sig[j][i] = 0.5 * (sig[i][j] + sig[j][i]);
    for (int j = 0; j < 3; j++) {
        double d = sig[j][j];
        for (int k = 0; k < j; k++)
            d -= W->chol[j][k] * W->chol[j][k];
        double ljj = d > 0.0 ? sqrt(d) : 0.0;
        W->chol[j][j] = ljj;
        for (int i = j + 1; i < 3; i++) {
            double v = sig[i][j];
            for (int k = 0; k < j; k++)
                v -= W->chol[i][k] * W->chol[j][k];
            W->chol[i][j] = ljj > 0.0 ? v / ljj : 0.0;
        }
    }
}

void vafm_well3_setup_vanloan(vafm_well3 *W, double omega2, double eta, double q, double h)
{
    const double A[3][3] = { { 0.0, 1.0, 0.0 }, { -omega2, -eta, 0.0 }, { 1.0, 0.0, 0.0 } };
    /* the sub-step: ‖A·hs‖∞ ≤ 1/2 (and the noise block no larger), then 2^n doublings back to h */
    double norm = fmax(1.0, fmax(omega2 + eta, fabs(q)));
    int n = 0;
    double hs = h;
    while (hs * norm > 0.5 && n < 60) {
        hs *= 0.5;
        n++;
    }
    /* Van Loan: exp([[−A, Q], [0, Aᵀ]]·hs) = [[·, F12], [0, F22]]; Φ = F22ᵀ, Σ = Φ·F12 */
    s_m6 M, E;
    memset(M, 0, sizeof M);
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            M[i][j] = -A[i][j] * hs;
            M[3 + i][3 + j] = A[j][i] * hs;
        }
    M[1][4] = q * hs;
    s_expm6(M, E);
    s_m3 phi, sig, tmp, phit;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            phi[i][j] = E[3 + j][3 + i];
    s_m3 f12;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            f12[i][j] = E[i][3 + j];
    s_mul3(phi, f12, sig);
    for (int k = 0; k < n; k++) {
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                phit[i][j] = phi[j][i];
        s_mul3(phi, sig, tmp);
        s_mul3(tmp, phit, tmp);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                sig[i][j] += tmp[i][j];
        s_mul3(phi, phi, phi);
    }
    memcpy(W->phi, phi, sizeof phi);
    s_chol3(W, sig);
}

void vafm_osc2_propagator(double w2, double eta, double h, double E[2][2])
{
    const double lam = -0.5 * eta, mu2 = 0.25 * eta * eta - w2;
    double eC, eS; /* e^{λ̄h}·cosh(μh), e^{λ̄h}·sinh(μh)/μ (cos/sin for μ² < 0; series at μ² ≈ 0) */
    if (fabs(mu2) * h * h < 1e-8) {
        double x = mu2 * h * h;
        eC = exp(lam * h) * (1.0 + x / 2.0 + x * x / 24.0);
        eS = exp(lam * h) * h * (1.0 + x / 6.0 + x * x / 120.0);
    } else if (mu2 > 0) {
        double mu = sqrt(mu2);
        double ep = exp((lam + mu) * h), em = exp((lam - mu) * h);
        eC = 0.5 * (ep + em);
        eS = 0.5 * (ep - em) / mu;
    } else {
        double om = sqrt(-mu2), e = exp(lam * h);
        eC = e * cos(om * h);
        eS = e * sin(om * h) / om;
    }
    E[0][0] = eC + eS * 0.5 * eta;
    E[0][1] = eS;
    E[1][0] = -eS * w2;
    E[1][1] = eC - eS * 0.5 * eta;
}

/* Closed forms, where they keep (measured against 80-digit arithmetic) a relative error below ~1e-13:
 * ω·h ≥ 1, η·h ≥ 0.01 and, overdamped, a slow rate ω²/η with ω²h/η ≥ 0.5. Outside, the differences
 * below lose digits (1 − e^{−ηh} for the variances, (1 − Φ₁₁)/ω² for I) and the series above is used. (X, V) is the 2×2 oscillator of free_ou.c:
 * Φ = e^{λ̄h}[cosh μh + (η/2)·sinh μh/μ, …], Σ_XV = Σ∞ − ΦΣ∞Φᵀ with Σ∞ = diag(kT/K, kT/m). I needs no
 * integral of its own: integrating V' = −ω²X − ηV + √q ξ over the step gives
 *     I = (−(V₁ − V₀) − η(X₁ − X₀) + √q W)/ω²,   W = ∫dW the step's Wiener increment,
 * so (X₁, V₁, I) is a linear map of (X₁, V₁, W), whose covariance is closed-form too:
 * Cov((X₁, V₁), W) = √q ∫₀ʰ Φ(τ)·(0, 1)ᵀ dτ = √q ((1 − Φ₁₁)/ω², Φ₁₂) (from Φ′ = ΦA and Φ′ = AΦ), Var W = h.
 * Cost: one exp, one cos and one sin against ~4000 multiply-adds and a dozen doublings for the series. */
#define S_CLOSED_MIN_WH 1.0
#define S_CLOSED_MIN_EH 0.01
#define S_CLOSED_MIN_SLOW 0.5

static int s_setup_closed(vafm_well3 *W, double w2, double eta, double q, double h)
{
    if (!(w2 > 0.0) || !(eta > 0.0) || !(q >= 0.0) || !(w2 * h * h >= S_CLOSED_MIN_WH * S_CLOSED_MIN_WH) ||
        !(eta * h >= S_CLOSED_MIN_EH) || !(w2 * h >= S_CLOSED_MIN_SLOW * eta))
        return 0;
    double E[2][2];
    vafm_osc2_propagator(w2, eta, h, E);
    const double e11 = E[0][0], e12 = E[0][1], e21 = E[1][0], e22 = E[1][1];
    const double s2 = q / (2.0 * eta), s1 = s2 / w2, sq = sqrt(q);
    /* covariance of (X₁, V₁, W) */
    const double cxx = s1 - (e11 * e11 * s1 + e12 * e12 * s2);
    const double cxv = -(e11 * e21 * s1 + e12 * e22 * s2);
    const double cvv = s2 - (e21 * e21 * s1 + e22 * e22 * s2);
    const double cxw = sq * (1.0 - e11) / w2, cvw = sq * e12, cww = h;
    /* the row of I: (a_x, a_v, a_w)·(X₁, V₁, W) */
    const double ax = -eta / w2, av = -1.0 / w2, aw = sq / w2;
    memset(W->phi, 0, sizeof W->phi);
    W->phi[0][0] = e11;
    W->phi[0][1] = e12;
    W->phi[1][0] = e21;
    W->phi[1][1] = e22;
    W->phi[2][0] = (eta * (1.0 - e11) - e21) / w2;
    W->phi[2][1] = (1.0 - e22 - eta * e12) / w2;
    W->phi[2][2] = 1.0;
    s_m3 sig;
    sig[0][0] = cxx;
    sig[0][1] = sig[1][0] = cxv;
    sig[1][1] = cvv;
    sig[0][2] = sig[2][0] = ax * cxx + av * cxv + aw * cxw;
    sig[1][2] = sig[2][1] = ax * cxv + av * cvv + aw * cvw;
    sig[2][2] = ax * ax * cxx + av * av * cvv + aw * aw * cww +
                2.0 * (ax * av * cxv + ax * aw * cxw + av * aw * cvw);
    s_chol3(W, sig);
    return 1;
}

void vafm_well3_setup(vafm_well3 *W, double omega2, double eta, double q, double h)
{
    if (!s_setup_closed(W, omega2, eta, q, h))
        vafm_well3_setup_vanloan(W, omega2, eta, q, h);
}
