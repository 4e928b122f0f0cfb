/* SPDX-License-Identifier: MIT */
/*
 * Exact propagation of a deep contact well over a whole output sample.
 *
 * Far from the pull-off instability the body sits deep in the contact well, where the force is linear
 * in its (thermal, tiny) excursion: u = c(τ) + X with c the moving centre line (equilibrium plus the
 * friction lag) and X a damped oscillator driven by white noise. The output sample needs the endpoint
 * and the time average of u over the interval, so the state is augmented with I = ∫X dτ:
 *     d(X, V, I) = A (X, V, I) dτ + (0, √q, 0) dW,  A = [[0, 1, 0], [−ω², −η, 0], [1, 0, 0]].
 * The transition over h is Gaussian: mean Φ(h)·x, covariance Σ(h). Both come from Van Loan's block
 * exponential on a sub-step small enough that a Taylor series converges to round-off with no
 * cancellation, then doubling: Φ(2h) = Φ(h)², Σ(2h) = Φ(h)Σ(h)Φ(h)ᵀ + Σ(h). One step then replaces
 * the thousands of integrator steps a well with ω·Ts ≫ 1 would need; sim.c decides where it holds.
 * Where ω·h ≥ 1 the same transition has closed forms (well_exact.c), cheap enough to set up afresh for
 * every output sample even at a few integrator steps per sample.
 */
#ifndef VAFM_CORE_WELL_EXACT_H
#define VAFM_CORE_WELL_EXACT_H

typedef struct vafm_well3 {
    double phi[3][3]; /* mean propagator of (X, V, I) */
    double chol[3][3]; /* lower Cholesky factor of the covariance */
} vafm_well3;

/** Mean propagator over h of X″ + ηX′ + ω²X = 0 for (X, X′): E = exp(A·h), A = [[0, 1], [−ω², −η]]
 *  (under-, over- and critically damped alike). */
void vafm_osc2_propagator(double omega2, double eta, double h, double E[2][2]);
/** Transition of the augmented well over h: ω² = K/m, friction rate eta, noise intensity q = 2ηkT/m.
 *  Closed forms where they keep full precision (ω·h ≥ 1), else the series below. */
void vafm_well3_setup(vafm_well3 *W, double omega2, double eta, double q, double h);
/** The same through Van Loan's block exponential (any ω·h; ~30× the cost of the closed forms). */
void vafm_well3_setup_vanloan(vafm_well3 *W, double omega2, double eta, double q, double h);

#endif
