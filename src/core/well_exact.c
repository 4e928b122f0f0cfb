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

void vafm_well3_setup(vafm_well3 *W, double omega2, double eta, double q, double h)
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
    /* symmetrise, then Cholesky (clamping the round-off of a singular direction to zero) */
    memcpy(W->phi, phi, sizeof phi);
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
