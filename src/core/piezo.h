/* SPDX-License-Identifier: MIT */
/*
 * The piezo actuator between the controller's command and where the support actually is (issue #14): a
 * rate-independent Bouc–Wen hysteresis and logarithmic creep. Pure computation on the extension e (m, toward
 * the sample: e = −height), advanced one sample at a time along a piecewise-linear command; sim.c moves the
 * support to the actual extension and reports the command as `height (piezo)`.
 *
 * Hysteresis (Bouc–Wen with n = 1 and β = γ = 1/(2 L_s)): e_a = e − h, dh = H de − (|de| h + de |h|)/(2 L_s).
 * On a monotone extension h relaxes to ±H·L_s over a travel of L_s (e^{−Δe/L_s}); after a reversal it first
 * changes linearly (slope H) through zero: a loop 2·H·L_s wide, the same at any speed. Integrated exactly
 * piece by piece (each piece is linear in e).
 *
 * Creep: after a move Δe the piezo goes on by C·Δe·log10(1 + t/t0). The kernel log10(1 + t/t0) is a sum of
 * first-order lags, w_j (1 − e^{−t/τ_j}) with τ_j = t0·10^{j/3 − 1} (j = 0..18) and weights fitted once by
 * non-negative least squares on 0.01 t0 ≤ t ≤ 1e4 t0 (error below 3e-6 decades there); each lag follows the
 * linear command exactly over a sample.
 */
#ifndef VAFM_CORE_PIEZO_H
#define VAFM_CORE_PIEZO_H

#include "vafm/params.h"

#define VAFM_PIEZO_CREEP_LAGS 19

typedef struct vafm_piezo {
    int on;
    double H, Ls;          /* hysteresis: strength, saturation length (m) */
    double h;              /* hysteresis state, m (e_a = e − h + creep) */
    double C, t0;          /* creep per decade (fraction of a move), reference time (s) */
    double e0;             /* the command at the start: creep counts moves from there */
    double y[VAFM_PIEZO_CREEP_LAGS]; /* the lags' states, m */
    double tau[VAFM_PIEZO_CREEP_LAGS], a[VAFM_PIEZO_CREEP_LAGS], a_dt; /* τ_j (s) and 1 − e^{−dt/τ_j} for dt = a_dt */
    double e, ea;          /* the last command and actual extension, m */
} vafm_piezo;

/** @return 1 when the scene has piezo hysteresis or creep. */
int vafm_piezo_on(const vafm_params *p);
/** Start at rest at extension e (m): no hysteresis, no creep pending. */
void vafm_piezo_begin(vafm_piezo *pz, const vafm_params *p, double e);
/** Advance over dt (s) along the command going linearly from pz->e to e_next (m); @return the actual
 *  extension at the end, m. */
double vafm_piezo_step(vafm_piezo *pz, double e_next, double dt);

#endif
