/* SPDX-License-Identifier: MIT */
/*
 * `vafm study velocity-thermal`: the thermal pull-off force against the pulling speed (paper-fig4 scenes at
 * several temperatures, each with its T = 0 companion), fitted and compared with theory.
 * Shared pieces (the campaign runner, the velocity grid): study_common.c.
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

static const double s_vt_quick[] = { 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 0.1 };

int vafm_study_velocity_thermal(vafm_study_ctx *ctx)
{
    const double kT_full[] = { 0.003, 0.01, 0.03 }, kT_quick[] = { 0.01 };
    const double *kTl = ctx->quick ? kT_quick : kT_full, *vl = ctx->quick ? s_vt_quick : vafm_study_v_full;
    size_t nT = ctx->quick ? 1 : 3, nv = ctx->quick ? 7 : 11;
    const double gamma = 0.229, k = 0.1;
    uint64_t N = ctx->n_override ? ctx->n_override : ctx->quick ? 8 : 200;
    vafm_quasistatic q;
    vafm_theory_quasistatic(gamma, k, &q);
    char path[VAFM_STUDY_PATH_LEN];
    FILE *c = NULL;
    if (vafm_study_path(path, ctx->out, "thermal.csv") || !(c = vafm_study_open(path)))
        return 1;
    fprintf(c, "dynamics,kT,v,n,F0_spring,Fp_spring,se_Fp_spring,Ft_spring,F0_detach,Fp_detach,se_Fp_detach,Ft_detach,"
               "y_mean,se_y,mfpt_y,mfpt_sd_y,mfpt_F_detach,dhs_y\n");
    FILE *o = ctx->rep;
    fprintf(o, "## Thermal reduction against speed (paper Figs. 5 and 6, Eq. 15)\n\n");
    fprintf(o, "Scene: γ̃ = 0.229, k̃ = 0.1, k_BT̃ ∈ {");
    for (size_t i = 0; i < nT; ++i)
        fprintf(o, "%s%g", i ? ", " : "", kTl[i]);
    fprintf(o, "}, N = %" PRIu64 " curves per point, ṽ as in the table; Langevin m̃ = 0.01 (gjf, ω·dt = 0.6) "
               "and Brownian ζ = 1. F̃_t = F̃₀ − F̃_p (Eq. 13) with F̃₀ from a T = 0 curve at the same speed.\n\n",
            N);
    fprintf(o, "**Observables.** The paper's F̃_p is the most tensile spring force (`pulloff_spring_N`): F̃_t(spring) "
               "below. With noise this maximum is biased upward at k̃ = 0.1 (physics notes: +2–3%% of F_JKR) — "
               "the maximum of a noisy signal, not a property of the escape — so the reduction is also given for "
               "the ground truth at detachment (`detach_force_N`): F̃_t(detach), which the rate theories predict. "
               "ȳ is the spring position at detachment past the quasi-static instability (u_spr − u_spr*, > 0: "
               "before it), from `detach_height_m`.\n\n");
    fprintf(o, "Theory beside every point: the exact 1D MFPT rate (overdamped, ζ = mη = 0.01 Langevin / 1 Brownian; "
               "for Langevin times Kramers' spatial-diffusion factor for the mass) integrated along the pull, and "
               "DHS; both give y at escape, hence the detachment force F_det − k·y. Both include the shift ζṽ/k "
               "of the support-frame friction (the pull adds a force ζṽ on the body; physics notes, Eq. 1), "
               "which dominates for Brownian dynamics at fast speeds. MFPT F̃_t(detach) = F̃₀(detach, simulated "
               "at T = 0) − MFPT ⟨F_detach⟩.\n\n");
    fprintf(o, "| dyn | k_BT̃ | ṽ | n | F̃_p(spring)/F_JKR | F̃_t(spring) | F̃_t(detach) | ȳ ± se | MFPT ȳ ± sd | "
               "DHS ȳ | MFPT F̃_t(detach) |\n|---|---|---|---|---|---|---|---|---|---|---|\n");
    int all_conv = 1;
    double Ft2[2][4][16], se2[2][4][16], Ft3[2][4][16], se3[2][4][16];
    double zsum[2][4] = { { 0 } }, zsq[2][4] = { { 0 } }, dbias[2] = { 0, 0 };
    int zn[2][4] = { { 0 } }, dn_[2] = { 0, 0 };
    for (int dyn = 0; dyn < 2; ++dyn) {
        for (size_t iv = 0; iv < nv; ++iv) {
            vafm_study_run r0, r;
            memset(&r0, 0, sizeof r0);
            memset(&r, 0, sizeof r);
            vafm_study_fig4_scene(&r0.base, dyn, vl[iv]);
            r0.base.T_K = 0.0;
            r0.v = r0.base.v_retract_m_per_s;
            r0.N = 1;
            vafm_study_fig4_scene(&r.base, dyn, vl[iv]);
            for (size_t i = 0; i < nT; ++i)
                r.T[i] = vafm_study_kT_to_K(&r.base, kTl[i]);
            r.nT = nT;
            r.v = r.base.v_retract_m_per_s;
            r.N = N;
            if (vafm_study_path(r0.file, ctx->out, "thermal-%s-v%g-T0.h5", dyn ? "brownian" : "langevin", vl[iv]) ||
                vafm_study_path(r.file, ctx->out, "thermal-%s-v%g.h5", dyn ? "brownian" : "langevin", vl[iv]) ||
                vafm_study_campaign(ctx, &r0)) {
                fclose(c);
                return 1;
            }
            if (vafm_study_campaign(ctx, &r)) {
                vafm_study_run_free(&r0);
                fclose(c);
                return 1;
            }
            vafm_scale sc = vafm_units_scale(&r.base);
            double FJ = q.F_jkr * sc.force_N;
            double F0s = r0.truth[0].result.pulloff_spring_N / FJ, F0d = r0.truth[0].result.detach_force_N / FJ;
            double *x = malloc(N * sizeof *x);
            if (!x) {
                vafm_cli_error("study: out of memory");
                vafm_study_run_free(&r0);
                vafm_study_run_free(&r);
                fclose(c);
                return 1;
            }
            for (size_t it = 0; it < nT; ++it) {
                size_t n = vafm_study_collect(&r, it, VAFM_OBS_PULLOFF_SPRING, 1.0 / FJ, x);
                vafm_study_stat s2 = vafm_study_stats(x, n);
                vafm_study_stat s3 = vafm_study_stats(x, vafm_study_collect(&r, it, VAFM_OBS_DETACH_FORCE, 1.0 / FJ, x));
                n = vafm_study_collect(&r, it, VAFM_OBS_DETACH_HEIGHT, 1.0 / sc.length_m, x);
                for (size_t i = 0; i < n; ++i)
                    x[i] = -x[i] - q.u_spr_star; /* y = u_spr − u_spr*, u_spr = −height */
                vafm_study_stat sy = vafm_study_stats(x, n);
                double zeta = dyn ? 1.0 : 0.01;
                vafm_theory_pull tp;
                int ok = vafm_theory_mfpt_pull(gamma, k, kTl[it], zeta, dyn ? 0.0 : 0.01, 0.0, &vl[iv], 1, &tp) == 0;
                if (!ok) /* the CSV then says NaN, never an unset value */
                    tp.mean_y = tp.sd_y = tp.mean_F = NAN;
                double yd = vafm_theory_dhs_mean_y(&q, k, kTl[it], vl[iv], zeta) + zeta * vl[iv] / k;
                if (!(s2.se >= ctx->min_se))
                    ctx->min_se = s2.se;
                Ft2[dyn][it][iv] = F0s - s2.mean;
                se2[dyn][it][iv] = s2.se;
                Ft3[dyn][it][iv] = F0d - s3.mean;
                se3[dyn][it][iv] = s3.se;
                double mF = ok ? F0d - tp.mean_F / q.F_jkr : NAN;
                if (ok && vl[iv] <= 1e-2 && sy.se > 0.0) { /* slow pulls: where the adiabatic theory should hold */
                    double z = (sy.mean - tp.mean_y) / sy.se;
                    zsum[dyn][it] += z;
                    zsq[dyn][it] += z * z;
                    zn[dyn][it]++;
                }
                dbias[dyn] += (F0s - s2.mean) - (F0d - s3.mean);
                dn_[dyn]++;
                fprintf(c, "%s,%g,%g,%zu,%.8g,%.8g,%.3g,%.8g,%.8g,%.8g,%.3g,%.8g,%.6g,%.3g,%.6g,%.6g,%.8g,%.6g\n",
                        dyn ? "brownian" : "langevin", kTl[it], vl[iv], n, F0s, s2.mean, s2.se, F0s - s2.mean, F0d,
                        s3.mean, s3.se, F0d - s3.mean, sy.mean, sy.se, tp.mean_y, tp.sd_y, tp.mean_F / q.F_jkr, yd);
                /* what the theory cannot give (DHS where Λ ≤ 1, a failed MFPT call) is n/a in the report, never nan */
                char th[64] = "n/a", dhs[32] = "n/a", mf[32] = "n/a";
                if (ok && isfinite(tp.mean_y) && isfinite(tp.sd_y))
                    snprintf(th, sizeof th, "%.4f ± %.4f", tp.mean_y, tp.sd_y);
                if (isfinite(yd))
                    snprintf(dhs, sizeof dhs, "%.4f", yd);
                if (isfinite(mF))
                    snprintf(mf, sizeof mf, "%.4f", mF);
                fprintf(o, "| %s | %g | %g | %zu | %.4f ± %.4f | %.4f | %.4f ± %.4f | %.4f ± %.4f | %s | %s | %s |\n",
                        dyn ? "BD" : "LD", kTl[it], vl[iv], n, s2.mean, s2.se, F0s - s2.mean, F0d - s3.mean, s3.se,
                        sy.mean, sy.se, th, dhs, mf);
            }
            free(x);
            vafm_study_run_free(&r0);
            vafm_study_run_free(&r);
        }
    }
    fclose(c);
    FILE *f = NULL;
    if (vafm_study_path(path, ctx->out, "thermal_fits.csv") || !(f = vafm_study_open(path)))
        return 1;
    fprintf(f, "dynamics,kT,observable,xi,se_xi,alpha_t,se_alpha_t,v_t,se_v_t,beta_t,se_beta_t,log_a,se_log_a,log_b,"
               "se_log_b,log_only,chi2_dof,converged\n");
    fprintf(o, "\n**Eq. 15 fits** F̃_t = ξ{1 + α_t exp[−(ṽ/v_t)^β_t]}, weighted by the standard errors of the "
               "means (GSL Levenberg–Marquardt from a grid start). Where the fit does not converge, puts v_t more "
               "than 3 decades outside the speeds, or leaves a parameter with a relative error above 10, the "
               "data show only the logarithmic middle of Eq. 15 (small β_t), where its four parameters are not "
               "separately determined; then F̃_t = a + b·ln ṽ is fitted instead (\"log only\"; DHS predicts "
               "F̃_t ∝ (ln Λ)^{2/3}, close to linear in ln ṽ over a few decades).\n\n"
               "| dyn | k_BT̃ | observable | ξ | α_t | v_t | β_t | a | b | χ²/dof | fit |\n"
               "|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (int dyn = 0; dyn < 2; ++dyn)
        for (size_t it = 0; it < nT; ++it)
            for (int ob = 0; ob < 2; ++ob) {
                vafm_fit_nls fit;
                double *y = ob ? Ft3[dyn][it] : Ft2[dyn][it], *sg = ob ? se3[dyn][it] : se2[dyn][it], sgc[16];
                for (size_t i = 0; i < nv; ++i)
                    sgc[i] = fmax(sg[i], 1e-6); /* a point with zero spread (n = 1) would get infinite weight */
                int ok = vafm_fit_eq15(vl, y, sgc, nv, &fit) == 0;
                all_conv &= ok;
                const char *on = ob ? "detach" : "spring";
                const char *dn = dyn ? "brownian" : "langevin";
                if (fit.onset) {
                    fprintf(f, "%s,%g,%s,nan,nan,nan,nan,nan,nan,nan,nan,%.8g,%.3g,%.8g,%.3g,1,%.3g,%d\n", dn, kTl[it], on,
                            fit.p[0], fit.se[0], fit.p[1], fit.se[1], fit.chi2_dof, ok);
                    fprintf(o, "| %s | %g | %s | – | – | – | – | %.4g ± %.2g | %.4g ± %.2g | %.3g | %s (log only) |\n",
                            dyn ? "BD" : "LD", kTl[it], on, fit.p[0], fit.se[0], fit.p[1], fit.se[1], fit.chi2_dof,
                            ok ? "converged" : "**not converged**");
                } else {
                    fprintf(f, "%s,%g,%s,%.8g,%.3g,%.8g,%.3g,%.8g,%.3g,%.8g,%.3g,nan,nan,nan,nan,0,%.3g,%d\n", dn, kTl[it],
                            on, fit.p[0], fit.se[0], fit.p[1], fit.se[1], fit.p[2], fit.se[2], fit.p[3], fit.se[3],
                            fit.chi2_dof, ok);
                    fprintf(o, "| %s | %g | %s | %.4g ± %.2g | %.4g ± %.2g | %.4g ± %.2g | %.4g ± %.2g | – | – | %.3g | %s |\n",
                            dyn ? "BD" : "LD", kTl[it], on, fit.p[0], fit.se[0], fit.p[1], fit.se[1], fit.p[2],
                            fit.se[2], fit.p[3], fit.se[3], fit.chi2_dof, ok ? "converged" : "**not converged**");
                }
            }
    fclose(f);
    fprintf(o, "\n**Theory against simulation.** Slow pulls (ṽ ≤ 0.01), spring position at detachment, "
               "z = (ȳ_sim − ȳ_MFPT)/se (agreement within the statistics: mean ≈ 0, rms ≈ 1):");
    for (int dyn = 0; dyn < 2; ++dyn)
        for (size_t it = 0; it < nT; ++it)
            if (zn[dyn][it])
                fprintf(o, " %s k_BT̃ = %g: mean %+.2f, rms %.2f (%d points);", dyn ? "Brownian" : "Langevin", kTl[it],
                        zsum[dyn][it] / zn[dyn][it], sqrt(zsq[dyn][it] / zn[dyn][it]), zn[dyn][it]);
    /* the barrier top reaches the branch end u_min (F there = −(5/9)F_JKR) for y above this */
    double y_clip = (q.F_det - (5.0 / 9.0) * q.F_jkr) / k;
    fprintf(o, " Where the Langevin rms is large the MFPT rate overestimates escape (ȳ_MFPT > ȳ_sim). The cause: "
               "for y > %.3g (k̃ = %g) the barrier top is no longer inside the branch but at its end u_min "
               "(where the contact force is −(5/9)F_JKR), so there is no barrier curvature, Kramers' "
               "spatial-diffusion factor is undefined and the rate stays the overdamped one (factor 1), which "
               "overestimates escape for the underdamped Langevin motion (ζ = 0.01). The affected rows are "
               "those with ȳ near or above %.3g; Brownian dynamics (no inertia) is not affected.\n",
            y_clip, k, y_clip);
    fprintf(o, "Observable effect: F̃_t(spring) − F̃_t(detach) averages %+.4f (Langevin) and %+.4f (Brownian) F_JKR: "
               "the spring-force maximum of a noisy curve lies above the force at detachment (physics notes: "
               "+2–3%% of F_JKR at k̃ = 0.1), so the paper's observable understates the thermal reduction.\n",
            dn_[0] ? dbias[0] / dn_[0] : NAN, dn_[1] ? dbias[1] / dn_[1] : NAN);
    int falls = 1, rises = 1;
    for (int dyn = 0; dyn < 2; ++dyn)
        for (size_t it = 0; it < nT; ++it) {
            if (!(Ft2[dyn][it][nv - 1] < Ft2[dyn][it][0]))
                falls = 0;
            if (it && !(Ft2[dyn][it][0] > Ft2[dyn][it - 1][0]))
                rises = 0;
        }
    fprintf(o, "\nMeasured against the paper's trends (F̃_t from `pulloff_spring_N`): F̃_t at ṽ = %g is %s than at "
               "ṽ = %g for every temperature and both dynamics; at ṽ = %g it %s with temperature.\n",
            vl[nv - 1], falls ? "smaller" : "**not always smaller**", vl[0], vl[0],
            nT > 1 ? (rises ? "rises monotonically" : "does **not** rise monotonically") : "(one temperature: not tested)");
    fprintf(o, "\n**Paper comparison.** The paper (Figs. 5, 6) finds F̃_t falling with speed and rising toward F̃₀ "
               "with temperature, fitted by Eq. 15; it quotes no fitted values. Both trends can be read from the "
               "table. The MFPT column is an adiabatic theory (the rate at a frozen spring, instantaneous slide "
               "to u_min): it should agree with the simulated detachment at slow speeds and high barriers, and "
               "it misses the dynamic lag at fast speeds, where F̃_t(detach) → 0 in the simulation.\n\n");
    fprintf(o, "Fits converged: %s.\n\n", all_conv ? "all" : "**not all**");
    return all_conv ? 0 : 4;
}
