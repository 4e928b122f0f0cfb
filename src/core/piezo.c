/* SPDX-License-Identifier: MIT */
/* The piezo actuator's hysteresis and creep (design: core/piezo.h). */
#include <math.h>
#include <string.h>

#include "core/piezo.h"

/* log10(1 + t/t0) ≈ Σ w_j (1 − e^{−t/τ_j}), τ_j = t0·10^{j/3 − 1}: non-negative least squares on a log grid of
 * 800 points over 0.01 t0 … 10^4.5 t0; the largest error on 0.01 t0 … 1e4 t0 is 2.5e-6 (the last lags carry
 * the tail beyond). */
static const double s_creep_w[VAFM_PIEZO_CREEP_LAGS] = {
    0.000013, 0.003239, 0.038602, 0.122690, 0.209498, 0.268774, 0.301575, 0.318248, 0.326197, 0.330052,
    0.331743, 0.332692, 0.332839, 0.333656, 0.331365, 0.340674, 0.326272, 0.197208, 0.901583,
};

int vafm_piezo_on(const vafm_params *p)
{
    return p->piezo_hysteresis > 0 || p->piezo_creep > 0;
}

void vafm_piezo_begin(vafm_piezo *pz, const vafm_params *p, double e)
{
    memset(pz, 0, sizeof *pz);
    pz->on = vafm_piezo_on(p);
    pz->H = p->piezo_hysteresis;
    pz->Ls = p->piezo_hysteresis_length_m;
    pz->C = p->piezo_creep;
    pz->t0 = p->piezo_creep_t0_s;
    pz->e = pz->ea = pz->e0 = e;
    for (int j = 0; j < VAFM_PIEZO_CREEP_LAGS; j++) {
        pz->y[j] = e;
        pz->tau[j] = pz->t0 * pow(10.0, j / 3.0 - 1.0);
    }
    pz->a_dt = NAN;
}

/* Bouc–Wen over a monotone move de (exact): with b = 1/(2 L_s), dh/de = H − 2b·h where the move drives h
 * toward its sign (de > 0 and h ≥ 0, or de < 0 and h ≤ 0), else H (linear through zero). */
static double s_hysteresis(double h, double de, double H, double Ls)
{
    if (de == 0.0 || H <= 0.0)
        return h;
    const double s = de > 0 ? 1.0 : -1.0, hinf = H * Ls;
    double left = fabs(de);
    if (s * h < 0) { /* the linear part: h moves by H·de until zero */
        double to_zero = fabs(h) / H;
        if (to_zero >= left)
            return h + H * de;
        h = 0.0;
        left -= to_zero;
    }
    /* relaxes toward s·hinf over the length L_s */
    return s * hinf + (h - s * hinf) * exp(-left / Ls);
}

double vafm_piezo_step(vafm_piezo *pz, double e_next, double dt)
{
    const double e = pz->e, de = e_next - e;
    pz->h = s_hysteresis(pz->h, de, pz->H, pz->Ls);
    double creep = 0.0;
    if (pz->C > 0) {
        if (dt > 0) {
            /* each lag y' = (e(t) − y)/τ along e(t) = e + v·t, exactly and without cancellation (vτ may be far
             * larger than y): y(dt) = y + (e − y)·g + v·(dt − τ·g) with g = 1 − e^{−dt/τ} */
            const double v = de / dt;
            if (dt != pz->a_dt) { /* one sample interval throughout a curve: computed once */
                for (int j = 0; j < VAFM_PIEZO_CREEP_LAGS; j++)
                    pz->a[j] = -expm1(-dt / pz->tau[j]);
                pz->a_dt = dt;
            }
            for (int j = 0; j < VAFM_PIEZO_CREEP_LAGS; j++)
                pz->y[j] += (e - pz->y[j]) * pz->a[j] + v * (dt - pz->tau[j] * pz->a[j]);
        }
        for (int j = 0; j < VAFM_PIEZO_CREEP_LAGS; j++)
            creep += s_creep_w[j] * (pz->y[j] - pz->e0);
        creep *= pz->C;
    }
    pz->e = e_next;
    pz->ea = e_next - pz->h + creep;
    return pz->ea;
}
