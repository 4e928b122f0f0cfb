/* SPDX-License-Identifier: MIT */
/*
 * `vafm study distribution`: the pull-off force distribution of paper-fig1 at five temperatures (quick: two),
 * with fits, theory beside every point and a quarter-step bias check. Shared pieces: study_common.c.
 */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cli/cli.h"
#include "cli/study_common.h"
#include "cli/study_fit.h"
#include "vafm/stats.h"
#include "vafm/integrator.h"
#include "vafm/theory.h"
#include "vafm/units.h"

int vafm_study_distribution(vafm_study_ctx *ctx)
{
    const double mult_full[] = { 0.25, 0.5, 1.0, 2.0, 4.0 }, mult_quick[] = { 1.0, 4.0 };
    const double *mult = ctx->quick ? mult_quick : mult_full;
    size_t nT = ctx->quick ? 2 : 5;
    vafm_study_run r;
    memset(&r, 0, sizeof r);
    vafm_preset_apply(&r.base, "paper-fig1", NULL);
    r.base.omega_dt = 0.6;
    vafm_reduced red;
    vafm_units_reduce(&r.base, &red);
    vafm_scale sc = vafm_units_scale(&r.base);
    for (size_t i = 0; i < nT; ++i)
        r.T[i] = r.base.T_K * mult[i];
    r.nT = nT;
    r.v = r.base.v_retract_m_per_s;
    r.N = ctx->n_override ? ctx->n_override : ctx->quick ? 12 : 2000;
    if (vafm_study_path(r.file, ctx->out, "distribution.h5") || vafm_study_campaign(ctx, &r))
        return 1;

    vafm_quasistatic q;
    vafm_theory_quasistatic(red.gamma, red.k, &q);
    const double FJ = q.F_jkr * sc.force_N;
    char path[VAFM_STUDY_PATH_LEN];
    FILE *c = NULL, *f = NULL;
    if (!vafm_study_path(path, ctx->out, "distribution_curves.csv"))
        c = vafm_study_open(path);
    if (c && !vafm_study_path(path, ctx->out, "distribution_fits.csv"))
        f = vafm_study_open(path);
    double *x = malloc(r.N * sizeof *x), *y = malloc(r.N * sizeof *y), *z = malloc(r.N * sizeof *z);
    if (c && f && !(x && y && z))
        vafm_cli_error("study: out of memory");
    if (!c || !f || !x || !y || !z) {
        if (c)
            fclose(c);
        if (f)
            fclose(f);
        free(x);
        free(y);
        free(z);
        vafm_study_run_free(&r);
        return 1;
    }
    fprintf(c, "T_K,kT_reduced,pulloff_sampled_nN,pulloff_spring_nN,detach_nN,F_JKR_nN\n");
    fprintf(f, "T_K,kT_reduced,observable,n,mean_nN,sd_nN,se_nN,xi_nN,se_xi_nN,omega_nN,se_omega_nN,alpha,se_alpha,"
               "converged\n");
    FILE *o = ctx->rep;
    fprintf(o, "## Pull-off force distribution (paper Figs. 2 and 3)\n\n");
    fprintf(o, "Scene: paper-fig1 (m̃ = 5e-5, ṽ = 1e-4, k̃ = 2e-5, γ̃ = 1.2e-4; E* = 20 GPa, R = 15.7 nm, "
               "k = %.3g N/m, v = %.4g nm/s), full loading–unloading curves, gjf at ω·dt = 0.6. N = %" PRIu64
               " curves per temperature, T = %s × %.1f K. F_JKR = %.4f nN.\n\n",
            r.base.k_N_per_m, r.v * 1e9, r.N, ctx->quick ? "{1, 4}" : "{0.25, 0.5, 1, 2, 4}", r.base.T_K, FJ * 1e9);
    fprintf(o, "**Observable.** Figure `distribution.png` and the skew-normal fits use `pulloff_spring_N`, the most "
               "tensile spring force of any step of the retract (the paper's definition, Eq. 10). The table also "
               "gives `pulloff_sampled_N` (what an AFM user reads from the 2 kHz box-car-filtered output) and "
               "`detach_force_N` (spring force when contact is lost). At this compliant spring the three agree "
               "to within their errors (physics notes: the noise bias of the spring-force maximum is negligible "
               "for k̃ = 2e-5).\n\n");
    fprintf(o, "Skew-normal fits: maximum penalised likelihood (GSL Nelder–Mead; the Azzalini–Arellano-Valle "
               "penalty 0.876·ln(1 + 0.856α²), which keeps the shape α finite in small samples, where the plain "
               "MLE diverges with positive probability, and regularises the singular information at α = 0; its "
               "weight relative to ln L falls as 1/n), errors from the inverse Hessian of the penalised −ln L. "
               "Forces in nN.\n\n");
    fprintf(o, "| T (K) | k_BT̃ | observable | n | flagged | mean ± se | sd | ξ ± se | ω ± se | α ± se | fit |\n"
               "|---|---|---|---|---|---|---|---|---|---|---|\n");
    int all_conv = 1;
    const char *oname[] = { "pulloff_sampled_N", "pulloff_spring_N", "detach_force_N" };
    double mean_ref = NAN, sd_ref = NAN, mT[8], sT[8], aT[8];
    for (size_t pt = 0; pt < nT; ++pt) {
        double kT = red.kT * mult[pt];
        size_t n = vafm_study_collect(&r, pt, VAFM_OBS_PULLOFF_SPRING, 1e9, x);
        size_t ny = vafm_study_collect(&r, pt, VAFM_OBS_PULLOFF_SAMPLED, 1e9, y), nz = vafm_study_collect(&r, pt, VAFM_OBS_DETACH_FORCE, 1e9, z);
        if (ny < n)
            n = ny;
        if (nz < n)
            n = nz;
        for (size_t i = 0; i < n; ++i)
            fprintf(c, "%.6g,%.6g,%.9g,%.9g,%.9g,%.9g\n", r.T[pt], kT, y[i], x[i], z[i], FJ * 1e9);
        double *arr[3] = { y, x, z };
        for (int ob = 0; ob < 3; ++ob) {
            vafm_study_stat s = vafm_study_stats(arr[ob], n);
            vafm_fit_skewnorm fit;
            int ok = vafm_fit_skewnorm_ml(arr[ob], n, &fit) == 0;
            if (ob == 1) {
                all_conv &= ok;
                if (!(s.se / (FJ * 1e9) >= ctx->min_se))
                    ctx->min_se = s.se / (FJ * 1e9);
                mT[pt] = s.mean;
                sT[pt] = s.sd;
                aT[pt] = ok ? fit.alpha : NAN;
                if (mult[pt] == 1.0) {
                    mean_ref = s.mean;
                    sd_ref = s.sd;
                }
            }
            fprintf(f, "%.6g,%.6g,%s,%zu,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%d\n", r.T[pt], kT, oname[ob], n,
                    s.mean, s.sd, s.se, fit.xi, fit.se_xi, fit.omega, fit.se_omega, fit.alpha, fit.se_alpha, ok);
            fprintf(o, "| %.1f | %.3g | %s | %zu | %zu | %.4f ± %.4f | %.4f | %.4f ± %.4f | %.4f ± %.4f | %.2f ± %.2f | %s |\n",
                    r.T[pt], kT, oname[ob], n, vafm_study_flagged(&r, pt), s.mean, s.se, s.sd, fit.xi, fit.se_xi, fit.omega,
                    fit.se_omega, fit.alpha, fit.se_alpha, ok ? "converged" : "**not converged**");
        }
    }
    fclose(c);
    fclose(f);
    free(x);
    free(y);

    /* Time-step bias of this scene, measured (full runs only): the first Nb curves of the lowest
     * temperature again at a quarter of the step, with the same (seed, index) streams. The same stream
     * at another step is another noise history, so pairing gains nothing: the report says so with the
     * spread of the differences. */
    if (!ctx->quick) {
        vafm_study_run rb;
        memset(&rb, 0, sizeof rb);
        rb.base = r.base;
        rb.base.omega_dt = 0.15;
        rb.T[0] = r.T[0];
        rb.nT = 1;
        rb.v = r.v;
        rb.N = r.N < 100 ? r.N : 100;
        if (vafm_study_path(rb.file, ctx->out, "distribution-dt4.h5") || vafm_study_campaign(ctx, &rb)) {
            free(z);
            vafm_study_run_free(&r);
            return 1;
        }
        double *d = malloc(rb.N * sizeof *d);
        if (!d) {
            vafm_cli_error("study: out of memory");
            vafm_study_run_free(&rb);
            free(z);
            vafm_study_run_free(&r);
            return 1;
        }
        size_t nd = 0;
        for (uint64_t i = 0; i < rb.N; ++i) {
            const vafm_curve_result *a = &r.truth[i].result, *b = &rb.truth[i].result;
            if (!a->flags && !b->flags && !r.truth[i].status && !rb.truth[i].status)
                d[nd++] = (a->pulloff_spring_N - b->pulloff_spring_N) / FJ;
        }
        vafm_study_stat sd_ = vafm_study_stats(d, nd);
        free(d);
        fprintf(o, "\n**Time-step bias (measured).** The first %zu curves of T = %.1f K rerun at ω·dt = 0.15 (a "
                   "quarter step), same random streams: mean difference of `pulloff_spring_N` (ω·dt 0.6 − 0.15) "
                   "= %+.2g ± %.2g F_JKR (standard error of the per-curve differences; their sd %.2g F_JKR "
                   "against the distribution's sd %.2g F_JKR: the same stream at another step is another noise "
                   "history, so pairing does not reduce the error).\n",
                nd, rb.T[0], sd_.mean, sd_.se, sd_.sd, sT[0] / (FJ * 1e9));
        vafm_study_run_free(&rb);
    }

    /* references */
    double v_red = red.v_retract, zeta = red.m;
    fprintf(o, "\n**Theory.** Quasi-static: F* = %.6f F_JKR (jump), F_det = %.6f F_JKR (spring force when the body "
               "reaches u_min), maximum tensile force along the path = F_JKR = %.4f nN.\n",
            q.F_star / q.F_jkr, q.F_det / q.F_jkr, FJ * 1e9);
    fprintf(o, "Overdamped references at each temperature (ζ = m̃ = %.3g; y = spring position past the instability, "
               "F = F_det − k·y):\n\n| T (K) | DHS ⟨F⟩ (nN) | MFPT ⟨F⟩ ± sd (nN) | simulated ⟨detach_force⟩ (nN) |\n"
               "|---|---|---|---|\n", zeta);
    for (size_t pt = 0; pt < nT; ++pt) {
        double kT = red.kT * mult[pt];
        vafm_theory_pull tp;
        double yd = vafm_theory_dhs_mean_y(&q, red.k, kT, v_red, zeta);
        int ok = vafm_theory_mfpt_pull(red.gamma, red.k, kT, zeta, red.m, 0.0, &v_red, 1, &tp) == 0;
        size_t n = vafm_study_collect(&r, pt, VAFM_OBS_DETACH_FORCE, 1e9, z);
        vafm_study_stat s = vafm_study_stats(z, n);
        char mfpt[64] = "n/a (the theory call failed)"; /* never a NaN in the report */
        if (ok && isfinite(tp.mean_F) && isfinite(tp.sd_F))
            snprintf(mfpt, sizeof mfpt, "%.4f ± %.4f", tp.mean_F * sc.force_N * 1e9, tp.sd_F * sc.force_N * 1e9);
        fprintf(o, "| %.1f | %.4f | %s | %.4f ± %.4f |\n", r.T[pt], (q.F_det - red.k * yd) * sc.force_N * 1e9, mfpt,
                s.mean, s.se);
    }
    /* the regime (as `vafm theory`): energy lost per oscillation at the barrier, δ = η·(36/5)ΔV/(ω·kT) */
    vafm_theory_pull tp;
    memset(&tp, 0, sizeof tp); /* a failed call leaves it unset: the regime is then not stated */
    int tp_ok = vafm_theory_mfpt_pull(red.gamma, red.k, red.kT, zeta, red.m, 0.0, &v_red, 1, &tp) == 0;
    double y0 = tp.mean_y > 0 ? tp.mean_y : 0.0, w = sqrt(sqrt(2.0 * q.F2 * red.k * y0) / red.m);
    double delta = 7.2 * vafm_theory_barrier(&q, red.k, y0) / w / red.kT;
    if (!tp_ok || !isfinite(w) || !isfinite(delta) || w <= 0)
        fprintf(o, "\nThe regime at the reference temperature cannot be stated: the MFPT theory call failed there.\n\n");
    else {
        fprintf(o, "\nDHS assumes overdamped motion; the MFPT column multiplies the exact overdamped rate by Kramers' "
                   "spatial-diffusion factor for the mass. Here, at the reference temperature, the well frequency at "
                   "the rupture point is ω/η = %.3g (so DHS does not apply) and the energy lost per oscillation at the "
                   "barrier is δ = %.2g k_BT: %s\n\n",
                w, delta, delta > 5.0 ? "spatial diffusion, where the MFPT rate with Kramers' factor applies."
                          : "Kramers' turnover / energy-diffusion regime, where even the corrected rate overestimates "
                            "escape; the theory columns are for scale, and the simulation should detach later (at "
                            "higher force) than they say.");
    }
    fprintf(o, "**Paper comparison.** The paper shows (Fig. 2) an asymmetric bell-shaped distribution for this "
               "scene from > 2000 curves and (Fig. 3) lower and broader distributions at higher temperature, fitted "
               "by skew-Gaussian densities; it gives no numbers for the fits. Here, at the reference temperature, "
               "mean %.4f nN and sd %.4f nN (%.3f and %.4f F_JKR).\n\n",
            mean_ref, sd_ref, mean_ref / (FJ * 1e9), sd_ref / (FJ * 1e9));
    int falls = 1, grows = 1, neg = 1;
    for (size_t pt = 0; pt < nT; ++pt) {
        if (pt && !(mT[pt] < mT[pt - 1]))
            falls = 0;
        if (pt && !(sT[pt] > sT[pt - 1]))
            grows = 0;
        if (!(aT[pt] < 0.0))
            neg = 0;
    }
    fprintf(o, "Measured against the paper's claims (`pulloff_spring_N`): the mean %s with temperature (%.4f → %.4f nN "
               "from %.0f to %.0f K), the width %s (sd %.4f → %.4f nN), and the fitted shape α is %s (%s).\n\n",
            falls ? "falls monotonically" : "does **not** fall monotonically", mT[0], mT[nT - 1], r.T[0], r.T[nT - 1],
            grows ? "grows monotonically" : "does **not** grow monotonically", sT[0], sT[nT - 1],
            neg ? "negative at every temperature" : "not negative at every temperature",
            neg ? "a tail toward low forces: the asymmetric bell of Fig. 2" : "see the table; small samples resolve α poorly");
    fprintf(o, "Fits converged: %s.\n\n", all_conv ? "all" : "**not all**");
    free(z);
    vafm_study_run_free(&r);
    return all_conv ? 0 : 4;
}
