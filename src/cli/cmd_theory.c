/* SPDX-License-Identifier: MIT */
/*
 * `vafm theory [SCENE]`: the references of theory.h for a scene, without simulating. Everything is
 * computed in reduced units (η = R = E* = k_B = 1) and printed in both reduced and SI units.
 * The friction ζ = mη of the overdamped theories is the scene's (for Brownian dynamics the same
 * product: only ζ matters there).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cli/study.h"
#include "vafm/scene.h"
#include "vafm/integrator.h"
#include "vafm/theory.h"
#include "vafm/units.h"

int vafm_study_scene_arg(int argc, char **argv, int *i, vafm_params *p, char *desc, size_t desc_len)
{
    const char *a = argv[*i];
    vafm_error err;
    memset(&err, 0, sizeof err);
    size_t dl = strlen(desc);
    if (!strcmp(a, "--preset") || !strcmp(a, "--scene")) {
        if (*i + 1 >= argc) {
            fprintf(stderr, "vafm %s: %s needs a value\n", argv[0], a);
            return 2;
        }
        const char *val = argv[++*i];
        int r = !strcmp(a, "--preset") ? vafm_preset_apply(p, val, &err)
                                       : vafm_scene_load_file(p, val, NULL, 0, &err);
        if (r) {
            fprintf(stderr, "vafm %s: %s\n", argv[0], err.message);
            return 2;
        }
        snprintf(desc + dl, desc_len - dl, "%s%s %s", dl ? ", " : "", a + 2, val);
        ++*i;
        return 1;
    }
    if (strncmp(a, "--", 2))
        return 0;
    char name[128];
    const char *eq = strchr(a, '='), *val = NULL;
    size_t n = eq ? (size_t)(eq - a - 2) : strlen(a + 2);
    if (n >= sizeof name)
        return 0;
    memcpy(name, a + 2, n);
    name[n] = 0;
    if (!vafm_params_field_find(name))
        return 0;
    if (eq) {
        val = eq + 1;
    } else if (*i + 1 < argc) {
        val = argv[++*i];
    } else {
        fprintf(stderr, "vafm %s: --%s needs a value\n", argv[0], name);
        return 2;
    }
    if (vafm_params_set(p, name, val, &err)) {
        fprintf(stderr, "vafm %s: %s\n", argv[0], err.message);
        return 2;
    }
    snprintf(desc + dl, desc_len - dl, "%s--%s=%s", dl ? ", " : "", name, val);
    ++*i;
    return 1;
}

static void s_help(FILE *o)
{
    fputs("vafm theory [SCENE] [--v LIST | --v-reduced LIST]\n"
          "  Quasi-static and thermal references for a scene, without simulating (reduced and SI units):\n"
          "  the quasi-static jump (instability) force and spring position, the force at detachment, the\n"
          "  maximum tensile force along the quasi-static path (F_JKR), the overdamped Dudko-Hummer-Szabo\n"
          "  prediction and the exact 1D mean-first-passage rate integrated along the pull.\n"
          "  SCENE: --preset NAME, --scene FILE.json, --NAME=VALUE overrides (as vafm run).\n"
          "  --v LIST             pulling speeds to tabulate, m/s, as for vafm curves and campaign (default:\n"
          "                       the scene's retract speed)\n"
          "  --v-reduced LIST     the same in reduced units (R*eta), as the paper quotes them\n",
          o);
}

int vafm_cmd_theory(int argc, char **argv)
{
    vafm_params p;
    vafm_preset_apply(&p, VAFM_TOOLS_DEFAULT_PRESET, NULL);
    char desc[1024] = "";
    double vlist[64];
    size_t n_v = 0;
    int v_si = 1; /* vlist in m/s (--v) or reduced (--v-reduced) */
    for (int i = 1; i < argc;) {
        if (!strcmp(argv[i], "-h") || !strcmp(argv[i], "--help")) {
            s_help(stdout);
            return 0;
        }
        /* one meaning per flag name: --v is m/s everywhere in vafm; reduced speeds have their own flag */
        if ((!strcmp(argv[i], "--v") || !strcmp(argv[i], "--v-reduced")) && i + 1 < argc) {
            v_si = !strcmp(argv[i], "--v");
            char *s = argv[i + 1], *end;
            n_v = 0;
            while (*s && n_v < 64) {
                double x = strtod(s, &end);
                if (end == s || !(x > 0.0)) {
                    fprintf(stderr, "vafm theory: %s: '%s' is not a list of positive %s\n", argv[i], argv[i + 1],
                            v_si ? "speeds in m/s" : "reduced speeds");
                    return 2;
                }
                vlist[n_v++] = x;
                s = *end == ',' ? end + 1 : end;
                if (*end && *end != ',') {
                    fprintf(stderr, "vafm theory: %s: '%s' is not a comma-separated list\n", argv[i], argv[i + 1]);
                    return 2;
                }
            }
            i += 2;
            continue;
        }
        int r = vafm_study_scene_arg(argc, argv, &i, &p, desc, sizeof desc);
        if (r == 2)
            return 2;
        if (r == 0) {
            fprintf(stderr, "vafm theory: unknown option '%s' (see vafm theory --help)\n", argv[i]);
            return 2;
        }
    }
    vafm_error err;
    memset(&err, 0, sizeof err);
    if (vafm_params_validate(&p, &err)) {
        fprintf(stderr, "vafm theory: %s\n", err.message);
        return 2;
    }
    if (p.contact != vafm_contact_jkr || !(p.gamma_J_per_m2 > 0.0)) {
        fprintf(stderr, "vafm theory: the references need the JKR contact with gamma_J_per_m2 > 0\n");
        return 2;
    }
    vafm_reduced r;
    vafm_units_reduce(&p, &r);
    vafm_scale sc = vafm_units_scale(&p);
    if (!n_v)
        vlist[n_v++] = r.v_retract;
    else if (v_si)
        for (size_t k = 0; k < n_v; k++)
            vlist[k] /= sc.speed_m_per_s; /* m/s → reduced */
    const double zeta = r.m; /* ζ = mη in reduced units (η = 1) */
    const double mass = p.integrator == vafm_integrator_brownian ? 0.0 : r.m; /* 0: overdamped */
    vafm_quasistatic q;
    if (vafm_theory_quasistatic(r.gamma, r.k, &q)) {
        fprintf(stderr, "vafm theory: no quasi-static solution for this scene\n");
        return 1;
    }
    const double fN = sc.force_N * 1e9, ln = sc.length_m * 1e9;
    printf("scene        %s\n", desc[0] ? desc : "preset " VAFM_TOOLS_DEFAULT_PRESET " (default)");
    printf("reduced      gamma %.6g, k %.6g, m %.6g (zeta = m*eta = %.6g), kT %.6g, v_retract %.6g, integrator %s\n",
           r.gamma, r.k, r.m, zeta, r.kT, r.v_retract, p.integrator->name);
    printf("units        force E*R^2 = %.6g nN, length R = %.6g nm, time 1/eta = %.6g s, speed R*eta = %.6g m/s\n", fN,
           ln, sc.time_s, sc.speed_m_per_s);
    printf("\nquasi-static (athermal, v -> 0); forces are tensile magnitudes; heights = piezo height above contact\n");
    printf("  F_JKR = 3*pi*gamma*R/2 (max tensile force along the path)  %12.6g  = %10.6g nN\n", q.F_jkr, q.F_jkr * fN);
    printf("  F* (contact force at the jump instability)                 %12.6g  = %10.6g nN  = %.8f F_JKR\n", q.F_star,
           q.F_star * fN, q.F_star / q.F_jkr);
    printf("  spring position at the jump u_spr* (height -u_spr*)        %12.6g  = %10.6g nm\n", q.u_spr_star,
           -q.u_spr_star * ln);
    printf("  F_det (spring force when the body reaches u_min)           %12.6g  = %10.6g nN  = %.8f F_JKR\n", q.F_det,
           q.F_det * fN, q.F_det / q.F_jkr);
    printf("  u_min (contact lost), u* (instability), F'' there          %12.6g, %.6g, %.6g\n", q.u_min, q.u_star, q.F2);
    if (!(r.kT > 0.0)) {
        printf("\nthermal references: none (T = 0)\n");
        return 0;
    }
    printf("\nthermal references at kT = %.6g (reduced), zeta = %.6g; y = u_spr - u_spr* at escape (> 0: before the jump)\n",
           r.kT, zeta);
    printf("  F_3 = spring force at detachment = F_det - k*y; F_4 = noise-free equilibrium spring force at u_spr* + y\n");
    printf("  both include the support-frame friction's shift zeta*v/k of the escape position\n");
    printf("  MFPT: exact overdamped 1D rate%s, integrated along the pull\n",
           mass > 0.0 ? " times Kramers' spatial-diffusion factor for the mass" : "");
    vafm_theory_pull *o = calloc(n_v, sizeof *o);
    if (!o || vafm_theory_mfpt_pull(r.gamma, r.k, r.kT, zeta, mass, 0.0, vlist, n_v, o)) {
        free(o);
        fprintf(stderr, "vafm theory: the MFPT integration failed for this scene\n");
        return 1;
    }
    printf("  %10s %10s | %10s %10s %10s | %10s %10s %10s %10s %9s\n", "v", "Lambda", "DHS <y>", "DHS F_3", "F_3/F_JKR",
           "MFPT <y>", "sd_y", "F_3/F_JKR", "F_4/F_JKR", "unescaped");
    for (size_t i = 0; i < n_v; ++i) {
        double Lam = fabs(q.F2) * r.kT / (4.0 * 3.14159265358979323846 * zeta * r.k * vlist[i]);
        double yd = vafm_theory_dhs_mean_y(&q, r.k, r.kT, vlist[i], zeta) + zeta * vlist[i] / r.k;
        double F4 = NAN, ueq, Feq;
        if (o[i].mean_y >= 0.0 && !vafm_theory_equilibrium(r.gamma, r.k, q.u_spr_star + o[i].mean_y, &ueq, &Feq))
            F4 = -Feq;
        printf("  %10.4g %10.4g | %10.5g %10.5g %10.6f | %10.5g %10.5g %10.6f %10.6f %9.2g\n", vlist[i], Lam, yd,
               q.F_det - r.k * yd, (q.F_det - r.k * yd) / q.F_jkr, o[i].mean_y, o[i].sd_y, o[i].mean_F / q.F_jkr,
               F4 / q.F_jkr, o[i].p_unescaped);
    }
    /* regime (at the first speed's ⟨y⟩, cubic fold): overdamped DHS needs η ≫ ω (ω the well frequency
     * √(V″/m), V″ ≈ √(2F″k·y)); the MFPT rate with Kramers' factor needs spatial diffusion, i.e. the energy
     * lost per oscillation at the barrier energy, δ = η·S/kT with the cubic's action S = (36/5)ΔV/ω, well
     * above 1 (Kramers turnover near δ ~ 1, energy diffusion below) */
    double y0 = o[0].mean_y > 0.0 ? o[0].mean_y : 0.0;
    double V2 = sqrt(2.0 * fabs(q.F2) * r.k * y0);
    double y_clip = (q.F_det - (5.0 / 9.0) * q.F_jkr) / r.k; /* top at u_min beyond (F(u_min) = −(5/9)F_JKR) */
    if (mass > 0.0 && y0 > y_clip)
        printf("\n  note: <y> = %.4g is beyond y = %.4g, where the barrier top reaches the branch end u_min: no barrier\n"
               "  curvature, Kramers' factor not applied; the overdamped rate overestimates escape with inertia\n",
               y0, y_clip);
    if (mass > 0.0) {
        double w = sqrt(V2 / mass), dV = vafm_theory_barrier(&q, r.k, y0);
        double delta = (36.0 / 5.0) * dV / w / r.kT; /* η = 1 */
        printf("\n  regime at v = %g: well frequency / eta = %.3g (DHS assumes << 1: %s); energy loss per\n"
               "  oscillation at the barrier delta = %.3g kT (%s)\n",
               vlist[0], w, w < 0.3 ? "applies" : "does not apply", delta,
               delta > 5.0  ? "spatial diffusion: the MFPT rate with Kramers' factor applies"
               : delta > 1.0 ? "Kramers turnover: the MFPT rate overestimates the escape rate"
                             : "energy diffusion: the MFPT rate does not apply");
    } else {
        printf("\n  regime: overdamped dynamics; DHS needs Lambda >~ 20 and k*y/F* <~ 0.06 (here %.3g)\n",
               r.k * y0 / q.F_star);
    }
    free(o);
    return 0;
}
