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

#include "cli/cli.h"
#include "cli/study.h"
#include "record/scene.h"
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

/* The most speeds one call tabulates (each is a row of the table). */
#define S_V_MAX 64

/* The speeds to tabulate, reduced, into *out (owned by the caller): --v LIST (m/s, with units as for vafm
 * curves and campaign), --v-reduced LIST (R*eta), or, with no list (opt NULL), v_default (reduced).
 * Each must lie in the retract speed's range in m/s (the parameter table's), as a scene's speed must: an
 * infinite or huge speed only gives the integrals nothing to compute. @return 0 or an exit status (printed). */
static int s_speeds(const char *opt, const char *text, double v_default, double speed_unit, double **out, size_t *n)
{
    const vafm_param_info *f = vafm_params_field_find("v_retract_m_per_s");
    *out = NULL;
    *n = 0;
    if (!opt) {
        if (!(*out = malloc(sizeof **out))) {
            vafm_cli_error("out of memory");
            return VAFM_CLI_EXIT_RUNTIME;
        }
        (*out)[0] = v_default;
        *n = 1;
        return 0;
    }
    size_t count = 1;
    for (const char *c = text; *c; c++)
        count += *c == ',';
    if (count > S_V_MAX) {
        vafm_cli_error("theory: %s: %zu speeds; at most %d", opt, count, S_V_MAX);
        return VAFM_CLI_EXIT_USAGE;
    }
    int si = !strcmp(opt, "--v");
    int rc = vafm_cli_parse_list(opt, si ? f->name : "v_reduced", text, out, n);
    if (rc)
        return rc;
    for (size_t i = 0; i < *n; i++) {
        double x = (*out)[i], x_si = si ? x : x * speed_unit;
        if (!(x_si >= f->min && x_si <= f->max)) {
            if (si)
                vafm_cli_error("theory: --v: element %zu of '%s' is %g m/s, outside the speed's range [%g, %g] m/s (%s)",
                               i + 1, text, x, f->min, f->max, f->name);
            else
                vafm_cli_error("theory: --v-reduced: element %zu of '%s' is %g R*eta = %g m/s, outside the speed's "
                               "range [%g, %g] m/s (%s), i.e. [%g, %g] R*eta for this scene",
                               i + 1, text, x, x_si, f->min, f->max, f->name, f->min / speed_unit, f->max / speed_unit);
            free(*out);
            *out = NULL;
            return VAFM_CLI_EXIT_USAGE;
        }
        if (si)
            (*out)[i] = x / speed_unit; /* m/s → reduced */
    }
    return 0;
}

/* x as printf's "%*.*<conv>" (conv 'f' or 'g') into buf, or "n/a" where the theory gives no value (NaN: outside
 * its domain, e.g. DHS at Λ ≤ 1): a NaN is never printed as if it were a result. */
static const char *s_num(char *buf, size_t len, int width, int prec, char conv, double x)
{
    if (!isfinite(x))
        snprintf(buf, len, "%*s", width, "n/a");
    else if (conv == 'f')
        snprintf(buf, len, "%*.*f", width, prec, x);
    else
        snprintf(buf, len, "%*.*g", width, prec, x);
    return buf;
}

static void s_help(FILE *o)
{
    fputs("vafm theory [SCENE] [--v LIST | --v-reduced LIST]\n"
          "  Quasi-static and thermal references for a scene, without simulating (reduced and SI units):\n"
          "  the quasi-static jump (instability) force and spring position, the force at detachment, the\n"
          "  maximum tensile force along the quasi-static path (F_JKR), the overdamped Dudko-Hummer-Szabo\n"
          "  prediction and the exact 1D mean-first-passage rate integrated along the pull.\n"
          "  SCENE: --preset NAME, --scene FILE.json, --NAME=VALUE overrides (as vafm run).\n"
          "  --v LIST             pulling speeds to tabulate, m/s (or with a unit: 1um/s), as for vafm curves\n"
          "                       and campaign: at most " VAFM_CLI_XSTR(S_V_MAX) ", each in [1e-12, 1000] m/s (default: the scene's\n"
          "                       retract speed)\n"
          "  --v-reduced LIST     the same in reduced units (R*eta), as the paper quotes them\n"
          "  A reference the theory cannot give (DHS at Lambda <= 1, an MFPT pull that never escapes) is n/a.\n",
          o);
}

int vafm_cmd_theory(int argc, char **argv)
{
    vafm_params p;
    vafm_preset_apply(&p, VAFM_TOOLS_DEFAULT_PRESET, NULL);
    char desc[1024] = "";
    const char *v_opt = NULL, *v_text = NULL; /* the last --v or --v-reduced, parsed once the scene is known */
    for (int i = 1; i < argc;) {
        if (!strcmp(argv[i], "-h") || !strcmp(argv[i], "--help")) {
            s_help(stdout);
            return 0;
        }
        /* one meaning per flag name: --v is m/s everywhere in vafm; reduced speeds have their own flag */
        if ((!strcmp(argv[i], "--v") || !strcmp(argv[i], "--v-reduced")) && i + 1 < argc) {
            v_opt = argv[i];
            v_text = argv[i + 1];
            i += 2;
            continue;
        }
        int r = vafm_study_scene_arg(argc, argv, &i, &p, desc, sizeof desc);
        if (r == 2)
            return 2;
        if (r == 0) {
            vafm_cli_error("theory: unknown option '%s' (see vafm theory --help)", argv[i]);
            return 2;
        }
    }
    vafm_error err;
    memset(&err, 0, sizeof err);
    if (vafm_params_validate(&p, &err)) {
        vafm_cli_error("theory: %s", err.message);
        return 2;
    }
    if (!(p.contact->flags & VAFM_CONTACT_JKR_BRANCH) || !(p.gamma_J_per_m2 > 0.0)) {
        vafm_cli_error("theory: the references need the JKR contact with gamma_J_per_m2 > 0");
        return 2;
    }
    vafm_reduced r;
    vafm_units_reduce(&p, &r);
    vafm_scale sc = vafm_units_scale(&p);
    double *vlist;
    size_t n_v;
    int rc = s_speeds(v_opt, v_text, r.v_retract, sc.speed_m_per_s, &vlist, &n_v); /* default: the scene's */
    if (rc)
        return rc;
    const double zeta = r.m; /* ζ = mη in reduced units (η = 1) */
    const double mass = p.integrator->overdamped ? 0.0 : r.m; /* 0: overdamped */
    vafm_quasistatic q;
    if (vafm_theory_quasistatic(r.gamma, r.k, &q)) {
        vafm_cli_error("theory: no quasi-static solution for this scene");
        free(vlist);
        return 1;
    }
    /* the pulls before any output, so that a failure leaves no partial table */
    vafm_theory_pull *o = NULL;
    if (r.kT > 0.0) {
        o = calloc(n_v, sizeof *o);
        int e = o ? vafm_theory_mfpt_pull(r.gamma, r.k, r.kT, zeta, mass, 0.0, vlist, n_v, o) : VAFM_ENOMEM;
        if (e) {
            vafm_cli_error("theory: the MFPT integration failed for this scene: %s", vafm_strerror(e));
            free(o);
            free(vlist);
            return 1;
        }
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
        free(vlist);
        return 0;
    }
    printf("\nthermal references at kT = %.6g (reduced), zeta = %.6g; y = u_spr - u_spr* at escape (> 0: before the jump)\n",
           r.kT, zeta);
    printf("  F_3 = spring force at detachment = F_det - k*y; F_4 = noise-free equilibrium spring force at u_spr* + y\n");
    printf("  both include the support-frame friction's shift zeta*v/k of the escape position\n");
    printf("  MFPT: exact overdamped 1D rate%s, integrated along the pull\n",
           mass > 0.0 ? " times Kramers' spatial-diffusion factor for the mass" : "");
    printf("  %10s %10s | %10s %10s %10s | %10s %10s %10s %10s %9s\n", "v", "Lambda", "DHS <y>", "DHS F_3", "F_3/F_JKR",
           "MFPT <y>", "sd_y", "F_3/F_JKR", "F_4/F_JKR", "unescaped");
    int na_dhs = 0, na_mfpt = 0, na_F4 = 0;
    for (size_t i = 0; i < n_v; ++i) {
        double Lam = fabs(q.F2) * r.kT / (4.0 * 3.14159265358979323846 * zeta * r.k * vlist[i]);
        double yd = vafm_theory_dhs_mean_y(&q, r.k, r.kT, vlist[i], zeta) + zeta * vlist[i] / r.k;
        double F4 = NAN, ueq, Feq;
        if (o[i].mean_y >= 0.0 && !vafm_theory_equilibrium(r.gamma, r.k, q.u_spr_star + o[i].mean_y, &ueq, &Feq))
            F4 = -Feq;
        na_dhs |= !isfinite(yd);
        na_mfpt |= !isfinite(o[i].mean_y);
        na_F4 |= isfinite(o[i].mean_y) && !isfinite(F4);
        char b[7][32];
        printf("  %10.4g %10.4g | %s %s %s | %s %s %s %s %9.2g\n", vlist[i], Lam, s_num(b[0], 32, 10, 5, 'g', yd),
               s_num(b[1], 32, 10, 5, 'g', q.F_det - r.k * yd), s_num(b[2], 32, 10, 6, 'f', (q.F_det - r.k * yd) / q.F_jkr),
               s_num(b[3], 32, 10, 5, 'g', o[i].mean_y), s_num(b[4], 32, 10, 5, 'g', o[i].sd_y),
               s_num(b[5], 32, 10, 6, 'f', o[i].mean_F / q.F_jkr), s_num(b[6], 32, 10, 6, 'f', F4 / q.F_jkr),
               o[i].p_unescaped);
    }
    if (na_dhs)
        printf("  DHS n/a: Lambda <= 1, where DHS has no solution (it needs Lambda >~ 20)\n");
    if (na_mfpt)
        printf("  MFPT n/a: the pull never escaped inside the integration window (unescaped = 1): kT = %.3g (reduced;\n"
               "  T_K = %g K) is too small for the MFPT integral at this speed; the quasi-static references above are\n"
               "  its T -> 0 limit\n",
               r.kT, p.T_K);
    if (na_F4)
        printf("  F_4 n/a: MFPT <y> < 0, past the jump, where there is no equilibrium\n");
    /* regime (at the first speed's ⟨y⟩, cubic fold): overdamped DHS needs η ≫ ω (ω the well frequency
     * √(V″/m), V″ ≈ √(2F″k·y)); the MFPT rate with Kramers' factor needs spatial diffusion, i.e. the energy
     * lost per oscillation at the barrier energy, δ = η·S/kT with the cubic's action S = (36/5)ΔV/ω, well
     * above 1 (Kramers turnover near δ ~ 1, energy diffusion below) */
    if (!isfinite(o[0].mean_y)) {
        printf("\n  regime at v = %g: n/a (no MFPT escape position)\n", vlist[0]);
        free(o);
        free(vlist);
        return 0;
    }
    double y0 = o[0].mean_y > 0.0 ? o[0].mean_y : 0.0;
    double V2 = sqrt(2.0 * fabs(q.F2) * r.k * y0);
    double y_clip = (q.F_det - (5.0 / 9.0) * q.F_jkr) / r.k; /* top at u_min beyond (F(u_min) = −(5/9)F_JKR) */
    if (mass > 0.0 && y0 > y_clip)
        printf("\n  note: <y> = %.4g is beyond y = %.4g, where the barrier top reaches the branch end u_min: no barrier\n"
               "  curvature, Kramers' factor not applied; the overdamped rate overestimates escape with inertia\n",
               y0, y_clip);
    if (mass > 0.0 && !(y0 > 0.0)) {
        printf("\n  regime at v = %g: n/a (MFPT <y> <= 0: the escape is at or past the jump, where there is no\n"
               "  barrier to oscillate in)\n",
               vlist[0]);
    } else if (mass > 0.0) {
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
    free(vlist);
    return 0;
}
