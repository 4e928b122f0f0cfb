/* SPDX-License-Identifier: MIT */
/*
 * Fits of `vafm study` (GSL): the skew-normal distribution by maximum (penalised) likelihood, and the paper's
 * Eq. 14 (athermal pull-off force against speed) and Eq. 15 (thermal reduction against speed) by
 * weighted nonlinear least squares. Every fit reports its parameters with standard errors (inverse
 * Hessian of the log-likelihood, or the Jacobian covariance) and whether it converged.
 */
#ifndef VAFM_CLI_STUDY_FIT_H
#define VAFM_CLI_STUDY_FIT_H

#include <stddef.h>

/* Skew-normal density 2/ω φ((x − ξ)/ω) Φ(α(x − ξ)/ω). */
typedef struct vafm_fit_skewnorm {
    double xi, omega, alpha;          /* location, scale, shape */
    double se_xi, se_omega, se_alpha; /* standard errors (NaN where the Hessian is singular) */
    double loglik;
    int converged;                    /* 1: the optimiser met its tolerance and the Hessian is positive definite */
} vafm_fit_skewnorm;

int vafm_fit_skewnorm_ml(const double *x, size_t n, vafm_fit_skewnorm *out);
double vafm_skewnorm_pdf(double x, double xi, double omega, double alpha);

/* Eq. 14: F0/F_JKR = {1 + (v/v0)^α0}^β0. Eq. 15: F_t = ξ{1 + α_t exp[−(v/v_t)^β_t]}.
 * p[] holds (v0, α0, β0) or (ξ, α_t, v_t, β_t); se[] their standard errors. sigma: the data's
 * standard errors (NULL: unweighted, errors scaled by the residual χ²/dof). Eq. 14 falls back to its
 * onset form exp(c·v^α), c = β0·v0^(−α0), when v0 comes out beyond the data; Eq. 15 to a + b·ln v when
 * its parameters are not determined (then onset = 1). */
typedef struct vafm_fit_nls {
    int np;
    double p[4], se[4];
    double chi2_dof;
    int dof, converged;
    int onset; /* 1: the data determine only a reduced form: Eq. 14 p = (c, α) of exp(c·v^α);
                  Eq. 15 p = (a, b) of a + b·ln v */
} vafm_fit_nls;

int vafm_fit_eq14(const double *v, const double *f_over_fjkr, const double *sigma, size_t n, vafm_fit_nls *out);
int vafm_fit_eq15(const double *v, const double *ft, const double *sigma, size_t n, vafm_fit_nls *out);
double vafm_eq14(double v, const double *p);
double vafm_eq15(double v, const double *p);
#endif
