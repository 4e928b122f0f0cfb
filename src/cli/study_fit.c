/* SPDX-License-Identifier: MIT */
/*
 * GSL fits for `vafm study`. The skew normal is fitted by maximum penalised likelihood (the
 * Azzalini–Arellano-Valle penalty on α; Nelder–Mead simplex on (ξ, ln ω, α) from moment estimates, then
 * a central-difference Hessian of the penalised −ln L in (ξ, ω, α) whose inverse is the covariance). Eq. 14/15 are fitted with gsl_multifit_nlinear (Levenberg–Marquardt,
 * finite-difference Jacobian) from the best point of a coarse grid over the nonlinear parameters, where
 * the parameters that enter linearly are solved in closed form: the start does not depend on luck.
 * Speeds enter through log v so that v0 and v_t are fitted on their natural (logarithmic) scale.
 * VAFM_FIT_DEBUG=1 in the environment prints the optimisers' progress on stderr (diagnosis only).
 */
#include "cli/study_fit.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <gsl/gsl_blas.h>
#include <gsl/gsl_linalg.h>
#include <gsl/gsl_multifit_nlinear.h>
#include <gsl/gsl_multimin.h>
#include <gsl/gsl_errno.h>
#include <gsl/gsl_sf_erf.h>

/* ---- skew normal ---------------------------------------------------------------------------------- */

double vafm_skewnorm_pdf(double x, double xi, double omega, double alpha)
{
    double z = (x - xi) / omega;
    return 2.0 / omega * exp(-0.5 * z * z) / sqrt(2.0 * M_PI) * 0.5 * erfc(-alpha * z / M_SQRT2);
}

typedef struct s_sn {
    const double *x;
    size_t n;
} s_sn;

/* −ln L in (ξ, ω, α); ln Φ via gsl_sf_log_erfc for the far tail */
static double s_sn_nll3(const s_sn *d, double xi, double omega, double alpha)
{
    if (!(omega > 0.0))
        return GSL_POSINF;
    double s = 0.0;
    for (size_t i = 0; i < d->n; ++i) {
        double z = (d->x[i] - xi) / omega;
        s += -0.5 * z * z + gsl_sf_log_erfc(-alpha * z / M_SQRT2); /* ln(2Φ) = ln erfc(−αz/√2) */
    }
    /* Azzalini & Arellano-Valle (2013) penalty: the plain MLE of α is infinite with positive probability
     * in small samples and its information is singular at α = 0; the penalty (O(1/n) relative to ln L)
     * keeps both finite */
    return -(s - d->n * (log(omega) + 0.5 * log(2.0 * M_PI))) + 0.875913 * log1p(0.856250 * alpha * alpha);
}

static double s_sn_f(const gsl_vector *v, void *u)
{
    return s_sn_nll3(u, gsl_vector_get(v, 0), exp(gsl_vector_get(v, 1)), gsl_vector_get(v, 2));
}

int vafm_fit_skewnorm_ml(const double *x, size_t n, vafm_fit_skewnorm *out)
{
    memset(out, 0, sizeof *out);
    out->xi = out->omega = out->alpha = out->se_xi = out->se_omega = out->se_alpha = NAN;
    if (n < 5)
        return -1;
    double m = 0, m2 = 0, m3 = 0;
    for (size_t i = 0; i < n; ++i)
        m += x[i];
    m /= n;
    for (size_t i = 0; i < n; ++i) {
        double d = x[i] - m;
        m2 += d * d;
        m3 += d * d * d;
    }
    m2 /= n;
    m3 /= n;
    if (!(m2 > 0.0))
        return -1;
    /* fit the standardised sample z = (x − m)/sd (tolerances then mean the same for any unit), map back */
    const double sd = sqrt(m2);
    double *zs = malloc(n * sizeof *zs);
    if (!zs)
        return -1;
    for (size_t i = 0; i < n; ++i)
        zs[i] = (x[i] - m) / sd;
    m3 /= m2 * sd;
    m2 = 1.0;
    const double m_orig = m;
    m = 0.0;
    /* moment start: skewness g1 → δ, clipped inside the skew normal's range |g1| < 0.995 */
    double g1 = m3 / pow(m2, 1.5), ag = fmin(fabs(g1), 0.95);
    double t = pow(ag, 2.0 / 3.0), c = pow((4.0 - M_PI) / 2.0, 2.0 / 3.0);
    double delta = copysign(sqrt(M_PI / 2.0 * t / (t + c)), g1);
    double alpha0 = delta / sqrt(fmax(1.0 - delta * delta, 1e-6));
    double omega0 = sqrt(m2 / (1.0 - 2.0 * delta * delta / M_PI));
    double xi0 = m - omega0 * delta * sqrt(2.0 / M_PI);

    s_sn d = { zs, n };
    gsl_multimin_function f = { s_sn_f, 3, &d };
    gsl_vector *p = gsl_vector_alloc(3), *step = gsl_vector_alloc(3);
    gsl_vector_set(p, 0, xi0);
    gsl_vector_set(p, 1, log(omega0));
    gsl_vector_set(p, 2, alpha0);
    gsl_vector_set(step, 0, 0.3 * omega0);
    gsl_vector_set(step, 1, 0.3);
    gsl_vector_set(step, 2, 0.5);
    gsl_multimin_fminimizer *mn = gsl_multimin_fminimizer_alloc(gsl_multimin_fminimizer_nmsimplex2, 3);
    /* two passes: the second restarts from the first's optimum with a smaller simplex (a simplex can
     * stall); a pass converges when the simplex shrinks below 1e-5 (standardised units: far below the
     * statistical errors, ≥ 0.07 there even at n = 2000, and above the ~3e-7 resolution that rounding of
     * ln L leaves in the flat α direction), or stops making progress (GSL_ENOPROG) once below 1e-3 */
    int conv = 0;
    for (int pass = 0; pass < 2; ++pass) {
        gsl_multimin_fminimizer_set(mn, &f, p, step);
        conv = 0;
        for (int it = 0; it < 20000; ++it) {
            int st = gsl_multimin_fminimizer_iterate(mn);
            double size = gsl_multimin_fminimizer_size(mn);
            if (size < 1e-5 || (st && size < 1e-3)) {
                conv = 1;
                if (getenv("VAFM_FIT_DEBUG"))
                    fprintf(stderr, "skewnorm: pass %d converged after %d iterations (size %g)\n", pass, it, size);
                break;
            }
            if (st) {
                if (getenv("VAFM_FIT_DEBUG"))
                    fprintf(stderr, "skewnorm: pass %d stopped (%s) at size %g after %d iterations\n", pass,
                            gsl_strerror(st), size, it);
                break;
            }
        }
        gsl_vector_memcpy(p, mn->x);
        gsl_vector_scale(step, 0.1);
    }
    out->xi = gsl_vector_get(p, 0);
    out->omega = exp(gsl_vector_get(p, 1));
    out->alpha = gsl_vector_get(p, 2);
    out->loglik = -mn->fval;
    gsl_multimin_fminimizer_free(mn);
    gsl_vector_free(p);
    gsl_vector_free(step);

    /* Hessian of −ln L in (ξ, ω, α) by central differences */
    double th[3] = { out->xi, out->omega, out->alpha }, h[3] = { 1e-3 * out->omega, 1e-3 * out->omega,
                                                                   1e-3 * fmax(1.0, fabs(out->alpha)) };
    gsl_matrix *H = gsl_matrix_alloc(3, 3);
    for (int i = 0; i < 3; ++i)
        for (int j = i; j < 3; ++j) {
            double e[4];
            for (int s = 0; s < 4; ++s) {
                double a[3] = { th[0], th[1], th[2] };
                a[i] += (s & 1 ? -1 : 1) * h[i];
                a[j] += (s & 2 ? -1 : 1) * h[j];
                e[s] = s_sn_nll3(&d, a[0], a[1], a[2]);
            }
            double v = (e[0] - e[1] - e[2] + e[3]) / (4.0 * h[i] * h[j]);
            gsl_matrix_set(H, i, j, v);
            gsl_matrix_set(H, j, i, v);
        }
    gsl_error_handler_t *old = gsl_set_error_handler_off();
    int pd = gsl_linalg_cholesky_decomp1(H) == GSL_SUCCESS;
    if (pd && gsl_linalg_cholesky_invert(H) == GSL_SUCCESS) {
        out->se_xi = sqrt(gsl_matrix_get(H, 0, 0));
        out->se_omega = sqrt(gsl_matrix_get(H, 1, 1));
        out->se_alpha = sqrt(gsl_matrix_get(H, 2, 2));
    } else {
        pd = 0;
    }
    gsl_set_error_handler(old);
    gsl_matrix_free(H);
    free(zs);
    /* back to the data's units (ln L shifts by −n·ln sd) */
    out->xi = m_orig + sd * out->xi;
    out->omega *= sd;
    out->se_xi *= sd;
    out->se_omega *= sd;
    out->loglik -= n * log(sd);
    out->converged = conv && pd;
    if (getenv("VAFM_FIT_DEBUG"))
        fprintf(stderr, "skewnorm: n %zu simplex %d hessian-pd %d alpha %g\n", n, conv, pd, out->alpha);
    return out->converged ? 0 : -1;
}

/* ---- nonlinear least squares ------------------------------------------------------------------- */

/* Internal parameters: eq14 (ln v0, α0, β0); eq15 (ξ, α_t, ln v_t, β_t). */
double vafm_eq14(double v, const double *p)
{
    return pow(1.0 + pow(v / p[0], p[1]), p[2]);
}

double vafm_eq15(double v, const double *p)
{
    return p[0] * (1.0 + p[1] * exp(-pow(v / p[2], p[3])));
}

typedef struct s_nls {
    const double *v, *y, *sigma;
    size_t n;
    int which; /* 14 or 15 */
} s_nls;

static void s_ext(const s_nls *d, const double *q, double *p)
{
    if (d->which == 140) {
        p[0] = q[0];
        p[1] = q[1];
    } else if (d->which == 14) {
        p[0] = exp(q[0]);
        p[1] = q[1];
        p[2] = q[2];
    } else {
        p[0] = q[0];
        p[1] = q[1];
        p[2] = exp(q[2]);
        p[3] = q[3];
    }
}

static double s_model(const s_nls *d, double v, const double *p)
{
    if (d->which == 140)
        return exp(p[0] * pow(v, p[1]));
    return d->which == 14 ? vafm_eq14(v, p) : vafm_eq15(v, p);
}

static int s_nls_f(const gsl_vector *x, void *u, gsl_vector *f)
{
    const s_nls *d = u;
    double q[4] = { 0 }, p[4] = { 0 };
    for (size_t i = 0; i < x->size; ++i)
        q[i] = gsl_vector_get(x, i);
    s_ext(d, q, p);
    for (size_t i = 0; i < d->n; ++i) {
        double r = s_model(d, d->v[i], p) - d->y[i];
        gsl_vector_set(f, i, isfinite(r) ? r / (d->sigma ? d->sigma[i] : 1.0) : 1e30);
    }
    return GSL_SUCCESS;
}

static double s_cost(const s_nls *d, const double *q)
{
    double p[4] = { 0 }, c = 0.0;
    s_ext(d, q, p);
    for (size_t i = 0; i < d->n; ++i) {
        double r = (s_model(d, d->v[i], p) - d->y[i]) / (d->sigma ? d->sigma[i] : 1.0);
        c += r * r;
    }
    return isfinite(c) ? c : INFINITY;
}

/* Weighted linear least squares y ≈ a·f + b·g (g NULL: y ≈ a·f). */
static void s_lin2(const s_nls *d, const double *f, const double *g, double *a, double *b)
{
    double sff = 0, sfg = 0, sgg = 0, sfy = 0, sgy = 0;
    for (size_t i = 0; i < d->n; ++i) {
        double w = d->sigma ? 1.0 / (d->sigma[i] * d->sigma[i]) : 1.0;
        double yi = d->which == 15 ? d->y[i] : log(d->y[i]);
        sff += w * f[i] * f[i];
        sfy += w * f[i] * yi;
        if (g) {
            sfg += w * f[i] * g[i];
            sgg += w * g[i] * g[i];
            sgy += w * g[i] * yi;
        }
    }
    if (!g) {
        *a = sff > 0 ? sfy / sff : 0.0;
        return;
    }
    double det = sff * sgg - sfg * sfg;
    *a = det != 0 ? (sfy * sgg - sgy * sfg) / det : 0.0;
    *b = det != 0 ? (sgy * sff - sfy * sfg) / det : 0.0;
}

static int s_fit(s_nls *d, int np, vafm_fit_nls *out)
{
    memset(out, 0, sizeof *out);
    out->np = np;
    for (int i = 0; i < 4; ++i)
        out->p[i] = out->se[i] = NAN;
    out->dof = (int)d->n - np;
    if (out->dof < 1)
        return -1;
    /* grid start: ln v over the data's range ± 3 decades, exponent 0.1 … 4 */
    double lvmin = INFINITY, lvmax = -INFINITY;
    for (size_t i = 0; i < d->n; ++i) {
        lvmin = fmin(lvmin, log(d->v[i]));
        lvmax = fmax(lvmax, log(d->v[i]));
    }
    double best[4] = { 0 }, bc = INFINITY, f[256], g[256];
    if (d->n > 256)
        return -1;
    for (int a = 0; a <= (d->which == 140 ? 0 : 48); ++a) {
        double lv = d->which == 140 ? 0.0 : lvmin - 7.0 + (lvmax - lvmin + 14.0) * a / 48.0;
        for (int b = 1; b <= 40; ++b) {
            double ex = 0.1 * b, q[4];
            for (size_t i = 0; i < d->n; ++i) {
                double z = pow(d->v[i] / exp(lv), ex);
                f[i] = d->which == 14 ? log1p(z) : 1.0;
                g[i] = exp(-z);
            }
            if (d->which == 140) {
                for (size_t i = 0; i < d->n; ++i)
                    f[i] = pow(d->v[i], ex);
                s_lin2(d, f, NULL, &q[0], NULL);
                q[1] = ex;
            } else if (d->which == 14) {
                double beta;
                s_lin2(d, f, NULL, &beta, NULL);
                q[0] = lv, q[1] = ex, q[2] = beta;
            } else {
                double xi, xa;
                s_lin2(d, f, g, &xi, &xa);
                q[0] = xi, q[1] = xi != 0 ? xa / xi : 0.0, q[2] = lv, q[3] = ex;
            }
            double c = s_cost(d, q);
            if (c < bc) {
                bc = c;
                memcpy(best, q, sizeof best);
            }
        }
    }
    const gsl_multifit_nlinear_type *T = gsl_multifit_nlinear_trust;
    gsl_multifit_nlinear_parameters fp = gsl_multifit_nlinear_default_parameters();
    gsl_multifit_nlinear_workspace *w = gsl_multifit_nlinear_alloc(T, &fp, d->n, np);
    gsl_multifit_nlinear_fdf fdf;
    memset(&fdf, 0, sizeof fdf);
    fdf.f = s_nls_f;
    fdf.df = NULL; /* finite differences */
    fdf.n = d->n;
    fdf.p = np;
    fdf.params = d;
    gsl_vector_view x0 = gsl_vector_view_array(best, np);
    gsl_error_handler_t *old = gsl_set_error_handler_off();
    int info = 0;
    gsl_multifit_nlinear_init(&x0.vector, &fdf, w);
    int st = gsl_multifit_nlinear_driver(500, 1e-10, 1e-10, 1e-12, NULL, NULL, &info, w);
    if (getenv("VAFM_FIT_DEBUG"))
        fprintf(stderr, "fit: status %d (%s), info %d, iterations %zu\n", st, gsl_strerror(st), info, gsl_multifit_nlinear_niter(w));
    gsl_matrix *J = gsl_multifit_nlinear_jac(w), *cov = gsl_matrix_alloc(np, np);
    gsl_multifit_nlinear_covar(J, 0.0, cov);
    gsl_vector *res = gsl_multifit_nlinear_residual(w);
    double chi2;
    gsl_blas_ddot(res, res, &chi2);
    out->chi2_dof = chi2 / out->dof;
    double q[4] = { 0 };
    for (int i = 0; i < np; ++i)
        q[i] = gsl_vector_get(w->x, i);
    s_ext(d, q, out->p);
    /* unweighted: scale by the residual variance; weighted: the data's own errors */
    double scale = d->sigma ? 1.0 : out->chi2_dof;
    int ok = st == GSL_SUCCESS;
    for (int i = 0; i < np; ++i) {
        double var = gsl_matrix_get(cov, i, i) * scale;
        double se = var >= 0 ? sqrt(var) : NAN;
        int is_log = (d->which == 14 && i == 0) || (d->which == 15 && i == 2); /* fitted as ln v */
        out->se[i] = is_log ? out->p[i] * se : se; /* delta method for v0, v_t */
        if (!isfinite(out->se[i]))
            ok = 0;
    }
    for (int i = 0; i < np; ++i)
        if (!isfinite(out->p[i]))
            ok = 0;
    gsl_set_error_handler(old);
    gsl_matrix_free(cov);
    gsl_multifit_nlinear_free(w);
    out->converged = ok;
    return ok ? 0 : -1;
}

/* When the best Eq. 14 fit puts v0 beyond 10× the fastest speed (or does not converge), the data only
 * show the onset, where {1 + (v/v0)^α}^β → exp(c·v^α) with c = β·v0^(−α): v0 and β are then not
 * separately determined (a flat valley: LM wanders along it). Fit the onset form instead. */
int vafm_fit_eq14(const double *v, const double *f, const double *sigma, size_t n, vafm_fit_nls *out)
{
    s_nls d = { v, f, sigma, n, 14 };
    int rc = s_fit(&d, 3, out);
    double vmax = 0.0;
    for (size_t i = 0; i < n; ++i)
        vmax = fmax(vmax, v[i]);
    if (rc == 0 && out->p[0] <= 10.0 * vmax)
        return 0;
    s_nls d2 = { v, f, sigma, n, 140 };
    rc = s_fit(&d2, 2, out);
    out->onset = 1;
    return rc;
}

/* When Eq. 15's fit does not converge or puts v_t more than 3 decades outside the data, or leaves a
 * parameter with a relative error above 10, the data show only the logarithmic middle of Eq. 15 (small
 * β_t: exp[−(v/v_t)^β_t] ≈ e⁻¹(1 − β_t ln(v/v_t))), where its four parameters are not separately
 * determined. Then the two-parameter form F_t = a + b·ln v is fitted (weighted linear least squares). */
int vafm_fit_eq15(const double *v, const double *ft, const double *sigma, size_t n, vafm_fit_nls *out)
{
    s_nls d = { v, ft, sigma, n, 15 };
    int rc = s_fit(&d, 4, out);
    double vmin = INFINITY, vmax = 0.0;
    for (size_t i = 0; i < n; ++i) {
        vmin = fmin(vmin, v[i]);
        vmax = fmax(vmax, v[i]);
    }
    int bad = rc != 0 || out->p[2] < 1e-3 * vmin || out->p[2] > 1e3 * vmax;
    for (int i = 0; i < 4 && !bad; ++i)
        bad = !(fabs(out->se[i]) <= 10.0 * fabs(out->p[i]));
    if (!bad)
        return 0;
    memset(out, 0, sizeof *out);
    for (int i = 0; i < 4; ++i)
        out->p[i] = out->se[i] = NAN;
    out->np = 2;
    out->onset = 1;
    out->dof = (int)n - 2;
    if (out->dof < 1)
        return -1;
    double S = 0, Sx = 0, Sxx = 0, Sy = 0, Sxy = 0;
    for (size_t i = 0; i < n; ++i) {
        double w = sigma ? 1.0 / (sigma[i] * sigma[i]) : 1.0, x = log(v[i]);
        S += w;
        Sx += w * x;
        Sxx += w * x * x;
        Sy += w * ft[i];
        Sxy += w * x * ft[i];
    }
    double det = S * Sxx - Sx * Sx;
    if (!(det > 0.0))
        return -1;
    out->p[0] = (Sxx * Sy - Sx * Sxy) / det;
    out->p[1] = (S * Sxy - Sx * Sy) / det;
    double chi2 = 0.0;
    for (size_t i = 0; i < n; ++i) {
        double r = (ft[i] - out->p[0] - out->p[1] * log(v[i])) / (sigma ? sigma[i] : 1.0);
        chi2 += r * r;
    }
    out->chi2_dof = chi2 / out->dof;
    double scale = sigma ? 1.0 : out->chi2_dof;
    out->se[0] = sqrt(Sxx / det * scale);
    out->se[1] = sqrt(S / det * scale);
    out->converged = 1;
    return 0;
}
