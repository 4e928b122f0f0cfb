/* SPDX-License-Identifier: MIT */
/*
 * Contact models: JKR identities and the reference points of the physics notes, the t-form solver
 * (round trip, warm start, γ → 0), derivatives by finite differences, the Hertz and none type objects,
 * vafm_contact_init / eval_at / type_find.
 *
 * Reduced units E* = R = 1; s = √a, c = √(2πγ): u = s⁴ − c·s, F = (4/3)s⁶ − 2c·s³,
 * U = (8/15)s¹⁰ − (4/3)c·s⁷ + (c²/2)s⁴, s_m = (c/4)^{1/3}, u_min = −3s_m⁴, F_JKR = 3πγ/2.
 */
#include "harness.h"

#include "vafm/contact.h"
#include "core/internal.h"

#include <float.h>
#include <time.h>

#define T_PI 3.14159265358979323846

/* Adhesion values swept by the generic tests: from nearly Hertz to very adhesive, including the
 * paper's two scenes (1.2e-4 and 0.229). */
static const double t_gammas[] = {1e-8, 1e-6, 1.2e-4, 1e-2, 0.229, 1.0, 10.0};
#define T_NGAMMA (sizeof t_gammas / sizeof t_gammas[0])

static vafm_contact t_jkr(double gamma)
{
    vafm_contact c;
    int rc = vafm_contact_init(&c, vafm_contact_jkr, gamma);
    ENSURE(rc == VAFM_OK);
    return c;
}

/* Force at u from a cold start; *s_out (may be NULL) receives √a. */
static double t_force(const vafm_contact *c, double u, double *dFdu, double *s_out)
{
    double s = 0.0;
    double F = c->type->force(c, u, &s, dFdu);
    if (s_out)
        *s_out = s;
    return F;
}

/* u(s) on the branch, the forward map the solver inverts. */
static double t_u_of_s(double c, double s)
{
    return s * s * s * s - c * s;
}

/* ---------------------------------------------------------------------------------------------- */

static void test_init_fields(void)
{
    for (size_t i = 0; i < T_NGAMMA; ++i) {
        double g = t_gammas[i];
        vafm_contact c = t_jkr(g);
        ENSURE(c.type == vafm_contact_jkr);
        ENSURE(c.gamma == g);
        /* closed forms of the notes, each evaluated independently: a few ulp apart at most */
        ENSURE_REL(c.c, sqrt(2.0 * T_PI * g), 1e-15);
        ENSURE_REL(c.s_m, pow(c.c / 4.0, 1.0 / 3.0), 1e-15);
        ENSURE_REL(c.u_detach, -0.75 * cbrt(T_PI * T_PI * g * g), 1e-14);
        ENSURE_REL(c.a0, pow(2.0 * T_PI * g, 1.0 / 3.0), 1e-15);
        ENSURE_REL(c.F_jkr, 1.5 * T_PI * g, 1e-15);
        ENSURE(c.u_touch == 0.0);
    }
    vafm_contact c = t_jkr(0.0); /* γ = 0 is allowed for jkr: it is Hertz */
    ENSURE(c.c == 0.0 && c.s_m == 0.0 && c.u_detach == 0.0 && c.F_jkr == 0.0 && c.a0 == 0.0);

    ENSURE(vafm_contact_init(&c, vafm_contact_hertz, 0.0) == VAFM_OK);
    ENSURE(c.type == vafm_contact_hertz && c.u_touch == 0.0 && c.u_detach == 0.0 && c.c == 0.0);
    ENSURE(vafm_contact_init(&c, vafm_contact_none, 0.0) == VAFM_OK);
    ENSURE(c.type == vafm_contact_none);
    ENSURE(isinf(c.u_touch) && c.u_touch > 0.0 && isinf(c.u_detach) && c.u_detach > 0.0);
    ENSURE(vafm_contact_init(&c, vafm_contact_none, 0.5) == VAFM_OK); /* none ignores γ */
    ENSURE(c.F_jkr == 0.0 && isinf(c.u_detach));
}

static void test_init_rejects(void)
{
    vafm_contact c;
    const vafm_contact_type *types[] = {vafm_contact_jkr, vafm_contact_hertz, vafm_contact_none};
    for (size_t i = 0; i < 3; ++i) {
        ENSURE(vafm_contact_init(&c, types[i], -1e-3) == VAFM_EINVAL);
        ENSURE(vafm_contact_init(&c, types[i], -0.0 - 1e-300) == VAFM_EINVAL);
        ENSURE(vafm_contact_init(&c, types[i], NAN) == VAFM_EINVAL);
        ENSURE(vafm_contact_init(&c, types[i], INFINITY) == VAFM_EINVAL);
    }
    ENSURE(vafm_contact_init(&c, vafm_contact_hertz, 1e-3) == VAFM_EINVAL);
    ENSURE(vafm_contact_init(&c, vafm_contact_hertz, 1e-300) == VAFM_EINVAL);
    ENSURE(vafm_contact_init(&c, NULL, 0.1) == VAFM_EINVAL);
    ENSURE(vafm_contact_init(NULL, vafm_contact_jkr, 0.1) == VAFM_EINVAL);
    /* a failed init leaves the record untouched */
    ENSURE(vafm_contact_init(&c, vafm_contact_jkr, 0.229) == VAFM_OK);
    vafm_contact keep = c;
    ENSURE(vafm_contact_init(&c, vafm_contact_jkr, -1.0) == VAFM_EINVAL);
    ENSURE(memcmp(&keep, &c, sizeof c) == 0);
}

static void test_find(void)
{
    ENSURE(vafm_contact_type_find("jkr") == vafm_contact_jkr);
    ENSURE(vafm_contact_type_find("hertz") == vafm_contact_hertz);
    ENSURE(vafm_contact_type_find("none") == vafm_contact_none);
    ENSURE(vafm_contact_type_find("dmt") == NULL);
    ENSURE(vafm_contact_type_find("") == NULL);
    ENSURE(vafm_contact_type_find("jkrx") == NULL);
    ENSURE(vafm_contact_type_find(NULL) == NULL);
    ENSURE(strcmp(vafm_contact_jkr->name, "jkr") == 0);
    ENSURE(strcmp(vafm_contact_hertz->name, "hertz") == 0);
    ENSURE(strcmp(vafm_contact_none->name, "none") == 0);
    ENSURE(vafm_contact_jkr->description && vafm_contact_hertz->description &&
           vafm_contact_none->description);
}

/* The four reference points of the notes, for several γ. Closed forms (derived from s alone):
 *   u = 0:         s³ = c,       F = −(2/3)c² = −(8/9)F_JKR,  U = −0.3 c^{10/3}
 *   F = 0:         s³ = 3c/2,    u = c·s/2,                   U = −0.3·(3/2)^{4/3} c^{10/3} = −0.515121…
 *   force minimum: s³ = 3c/4,    u = −c·s/4, F = −F_JKR,      U = −0.2·(3/4)^{4/3} c^{10/3} = −0.136284…
 *   u_min:         s = s_m,      F = −(5/9)F_JKR,             U = 3.2 (c/4)^{10/3} c^{0} = +0.031498… c^{10/3}
 * Against the exact closed forms: 1e-10 relative (the solver is good to ~1e-15 here; the points are
 * far from the double root except u_min itself, which is hit exactly: t = 0). Against the tabled
 * 6-digit decimals: half a unit in the 6th decimal, 5e-7 absolute in units of c^{10/3}. */
static void test_reference_points(void)
{
    for (size_t i = 0; i < T_NGAMMA; ++i) {
        const double g = t_gammas[i];
        const vafm_contact c = t_jkr(g);
        const double cc = c.c, E = pow(cc, 10.0 / 3.0), FJ = c.F_jkr;
        const vafm_contact_type *T = c.type;
        double s, dF;

        /* u = 0 */
        double F = t_force(&c, 0.0, &dF, &s);
        ENSURE_REL(s * s, c.a0, 1e-12);
        ENSURE_REL(F, -(8.0 / 9.0) * FJ, 1e-10);
        ENSURE_REL(T->energy(&c, 0.0), -0.3 * E, 1e-10);

        /* F = 0 */
        double s0 = cbrt(1.5 * cc), u0 = 0.5 * cc * s0;
        F = t_force(&c, u0, &dF, &s);
        ENSURE_ABS(F / FJ, 0.0, 1e-12);
        ENSURE_REL(s, s0, 1e-12);
        ENSURE_REL(T->energy(&c, u0), -0.3 * pow(1.5, 4.0 / 3.0) * E, 1e-10);
        ENSURE_ABS(T->energy(&c, u0) / E, -0.515121, 5e-7);
        ENSURE(dF > 0.0);

        /* force minimum: F = −F_JKR and dF/du = 0 (relative to the Hertz stiffness scale 2a) */
        double sf = cbrt(0.75 * cc), uf = -0.25 * cc * sf;
        F = t_force(&c, uf, &dF, &s);
        ENSURE_REL(F, -FJ, 1e-10);
        ENSURE_ABS(dF / (2.0 * s * s), 0.0, 1e-9);
        ENSURE_REL(T->energy(&c, uf), -0.2 * pow(0.75, 4.0 / 3.0) * E, 1e-10);
        ENSURE_ABS(T->energy(&c, uf) / E, -0.136284, 5e-7);

        /* u_min, exactly at the branch end */
        F = t_force(&c, c.u_detach, &dF, &s);
        ENSURE(s == c.s_m);
        ENSURE_REL(F, -(5.0 / 9.0) * FJ, 1e-10);
        ENSURE(isinf(dF) && dF < 0.0);
        ENSURE_REL(T->energy(&c, c.u_detach), 3.2 * pow(cc / 4.0, 10.0 / 3.0), 1e-10);
        ENSURE_ABS(T->energy(&c, c.u_detach) / E, 0.031498, 5e-7);

        /* energy lost on touching (0.3) and on detaching (0.031498), see the notes' hysteresis */
        ENSURE(T->energy(&c, nextafter(c.u_detach, -INFINITY)) == 0.0);
        ENSURE(T->energy(&c, -1e300) == 0.0);
    }
}

/* "Depth equal to unity": U(u_min) − U(F=0) = 0.546619… c^{10/3} = 1 gives γ̃ = 0.228670. γ is given to
 * 6 digits (relative rounding ≤ 0.5e-6/0.22867 = 2.2e-6) and the depth scales as γ^{5/3}: 4e-6. */
static void test_unit_depth(void)
{
    const vafm_contact c = t_jkr(0.228670);
    double s0 = cbrt(1.5 * c.c), u0 = 0.5 * c.c * s0;
    double depth = c.type->energy(&c, c.u_detach) - c.type->energy(&c, u0);
    ENSURE_REL(depth, 1.0, 4e-6);
    /* and exactly: the γ of unit depth rounds to 0.228670 */
    double k = 3.2 * pow(0.25, 10.0 / 3.0) + 0.3 * pow(1.5, 4.0 / 3.0); /* depth / c^{10/3} */
    double g = pow(k, -0.6) / (2.0 * T_PI);
    ENSURE_ABS(g, 0.228670, 5e-7);
}

/* Round trip |u(a(u)) − u| over Δu = u − u_min from 1e-14 to 1e3 (log-spaced). The error is judged
 * against the size of the terms of u = s⁴ − c·s (evaluating u(s) in double carries eps·(s⁴ + cs) by
 * itself): ≤ 1e-13·max(1, s⁴ + cs), i.e. a few ulp of the terms. Also s is monotone in u and ≥ s_m. */
static void test_round_trip(void)
{
    double worst = 0.0;
    for (size_t i = 0; i < T_NGAMMA; ++i) {
        const vafm_contact c = t_jkr(t_gammas[i]);
        double s_prev = 0.0;
        const int n = 341;
        for (int j = 0; j < n; ++j) {
            double du = pow(10.0, -14.0 + 17.0 * j / (n - 1));
            double u = c.u_detach + du;
            double s = vafm_jkr_sqrt_a(c.c, c.s_m, u, 0.0);
            double scale = fmax(1.0, s * s * s * s + c.c * s);
            double err = fabs(t_u_of_s(c.c, s) - u) / scale;
            if (err > worst)
                worst = err;
            ENSURE_MSG(err <= 1e-13, "gamma %g du %g: err %g", t_gammas[i], du, err);
            ENSURE(s >= c.s_m && s >= s_prev);
            s_prev = s;
        }
    }
    fprintf(stderr, "     round trip: worst |u(a(u)) - u| / max(1, s^4 + cs) = %.2g\n", worst);
}

/* Solver edge cases: exactly u_min gives s_m; below u_min and NaN give NaN; bad c or s_m give NaN;
 * γ = 0 gives u^{1/4} to an ulp; huge Δu works. */
static void test_solver_edges(void)
{
    const vafm_contact c = t_jkr(0.229);
    ENSURE(vafm_jkr_sqrt_a(c.c, c.s_m, c.u_detach, 0.0) == c.s_m);
    ENSURE(vafm_jkr_sqrt_a(c.c, c.s_m, c.u_detach, 1.3) == c.s_m);
    ENSURE(isnan(vafm_jkr_sqrt_a(c.c, c.s_m, nextafter(c.u_detach, -INFINITY), 0.0)));
    ENSURE(isnan(vafm_jkr_sqrt_a(c.c, c.s_m, NAN, 0.0)));
    ENSURE(isnan(vafm_jkr_sqrt_a(-1.0, c.s_m, 0.0, 0.0)));
    ENSURE(isnan(vafm_jkr_sqrt_a(c.c, NAN, 0.0, 0.0)));
    ENSURE(isnan(vafm_jkr_sqrt_a(NAN, c.s_m, 0.0, 0.0)));
    ENSURE_REL(vafm_jkr_sqrt_a(0.0, 0.0, 16.0, 0.0), 2.0, 1e-16);
    ENSURE(vafm_jkr_sqrt_a(0.0, 0.0, 0.0, 0.0) == 0.0);
    double s = vafm_jkr_sqrt_a(c.c, c.s_m, 1e12, 0.0);
    ENSURE_REL(t_u_of_s(c.c, s), 1e12, 1e-15);
    /* force() below the branch: NaN, and a NaN in *s_io turns the next call into a cold start */
    double sio = 1.0, dF = 0.0;
    double F = c.type->force(&c, c.u_detach - 1.0, &sio, &dF);
    ENSURE(isnan(F) && isnan(sio));
    F = c.type->force(&c, 0.0, &sio, &dF);
    ENSURE_REL(F, -(8.0 / 9.0) * c.F_jkr, 1e-12);
    /* NULL s_io and NULL dFdu are accepted */
    ENSURE_REL(c.type->force(&c, 0.0, NULL, NULL), -(8.0 / 9.0) * c.F_jkr, 1e-12);
}

/* dF/du against a centred difference (F(u+h) − F(u−h))/2h. With h = 1e-5·|u − u_min| (the scale on
 * which dF/du varies) truncation is ~(h/Δu)² ~ 1e-10 and rounding ~eps·|F|/(h·|dF/du|) ≲ 1e-9 where
 * both are not small (dividing by the exact spacing u₊ − u₋: near u_min, |u| ≫ h and the rounded 2h
 * alone would be off by eps·|u_min|/h ~ 1e-5); compare to 1e-6 of |dF/du| + 2a (2a: the Hertz stiffness, the natural scale where
 * dF/du crosses 0 at the force minimum). Points from just above u_min (Δu ≥ 1e-6·|u_min|) to u = 100. */
static void test_dFdu_fd(void)
{
    double worst = 0.0;
    for (size_t i = 0; i < T_NGAMMA; ++i) {
        const vafm_contact c = t_jkr(t_gammas[i]);
        double umin = c.u_detach;
        for (int j = 0; j <= 60; ++j) {
            double du = fabs(umin) * pow(10.0, -6.0 + 10.0 * j / 60.0);
            double u = umin + du;
            if (u > 100.0)
                break;
            double h = 1e-5 * du, dF, s;
            t_force(&c, u, &dF, &s);
            double up = u + h, um = u - h; /* divide by the exact up − um, not by the rounded 2h */
            double fd = (t_force(&c, up, NULL, NULL) - t_force(&c, um, NULL, NULL)) / (up - um);
            double err = fabs(fd - dF) / (fabs(dF) + 2.0 * s * s);
            if (err > worst)
                worst = err;
            ENSURE_MSG(err <= 1e-6, "gamma %g du %g: dFdu %.10g fd %.10g", t_gammas[i], du, dF, fd);
        }
        /* −∞ only at u_min itself; finite (large) one ulp above */
        double dF;
        t_force(&c, nextafter(umin, INFINITY), &dF, NULL);
        ENSURE(isfinite(dF) && dF < 0.0);
        /* large a: → Hertz 2a */
        double s;
        t_force(&c, 1e6, &dF, &s);
        ENSURE_REL(dF, 2.0 * s * s, 1e-3 * fmax(1.0, c.c));
    }
    fprintf(stderr, "     dF/du vs centred difference: worst rel %.2g\n", worst);
}

/* dU/du = F by a centred difference of energy(): same step rule and error budget as above; compared
 * to 1e-6 of |F| + F_scale, F_scale = F_JKR + (4/3)a³ (F crosses 0 on the branch). */
static void test_dUdu_fd(void)
{
    double worst = 0.0;
    for (size_t i = 0; i < T_NGAMMA; ++i) {
        const vafm_contact c = t_jkr(t_gammas[i]);
        double umin = c.u_detach;
        for (int j = 0; j <= 60; ++j) {
            double du = fabs(umin) * pow(10.0, -4.0 + 8.0 * j / 60.0);
            double u = umin + du;
            if (u > 100.0)
                break;
            double h = 1e-5 * du, s;
            double F = t_force(&c, u, NULL, &s);
            double up = u + h, um = u - h;
            double fd = (c.type->energy(&c, up) - c.type->energy(&c, um)) / (up - um);
            double err = fabs(fd - F) / (fabs(F) + c.F_jkr + (4.0 / 3.0) * s * s * s * s * s * s);
            if (err > worst)
                worst = err;
            ENSURE_MSG(err <= 1e-6, "gamma %g du %g: F %.10g fd %.10g", t_gammas[i], du, F, fd);
        }
    }
    fprintf(stderr, "     dU/du vs centred difference: worst rel %.2g\n", worst);
}

/* γ → 0 is Hertz. γ = 0 through the jkr type: identical to the Hertz closed form to a few ulp (the
 * solver returns u^{1/4} directly). γ = 1e-14: c = 2.5e-7, and F differs from Hertz by 2c·s³ plus the
 * shift of u by c·s; both ≲ 1e-6 relative at u ≥ 1e-2. */
static void test_hertz_limit(void)
{
    vafm_contact h, j0 = t_jkr(0.0), jt = t_jkr(1e-14);
    ENSURE(vafm_contact_init(&h, vafm_contact_hertz, 0.0) == VAFM_OK);
    for (int i = 0; i <= 40; ++i) {
        double u = pow(10.0, -6.0 + 0.25 * i);
        double dFh, dF0, dFt, sh, s0, st;
        double Fh = t_force(&h, u, &dFh, &sh);
        double F0 = t_force(&j0, u, &dF0, &s0);
        ENSURE_REL(F0, Fh, 1e-14);
        ENSURE_REL(dF0, dFh, 1e-14);
        ENSURE_REL(s0, sh, 1e-15);
        ENSURE_REL(j0.type->energy(&j0, u), h.type->energy(&h, u), 1e-14);
        ENSURE_REL(Fh, (4.0 / 3.0) * pow(u, 1.5), 1e-14);
        ENSURE_REL(h.type->energy(&h, u), (8.0 / 15.0) * pow(u, 2.5), 1e-14);
        if (u >= 1e-2) {
            double Ft = t_force(&jt, u, &dFt, &st);
            ENSURE_REL(Ft, Fh, 1e-5);
            ENSURE_REL(dFt, dFh, 1e-5);
            ENSURE_REL(jt.type->energy(&jt, u), h.type->energy(&h, u), 1e-5);
        }
    }
    /* γ = 0 at u = 0: F = 0 and dF/du = 0, not −∞ (no adhesion, no branch end singularity) */
    double dF, s;
    double F = t_force(&j0, 0.0, &dF, &s);
    ENSURE(F == 0.0 && dF == 0.0 && s == 0.0);
    /* γ = 1e-14 still has a (tiny) branch end with −∞ stiffness */
    F = t_force(&jt, jt.u_detach, &dF, &s);
    ENSURE(isinf(dF) && dF < 0.0);
    ENSURE_REL(F, -(5.0 / 9.0) * jt.F_jkr, 1e-10);
}

/* Hertz and none type objects on their own. */
static void test_hertz_none_types(void)
{
    vafm_contact h, n;
    ENSURE(vafm_contact_init(&h, vafm_contact_hertz, 0.0) == VAFM_OK);
    ENSURE(vafm_contact_init(&n, vafm_contact_none, 0.0) == VAFM_OK);
    double s = -1.0, dF = -1.0;
    /* exact binary values: a = 1/2 at u = 1/4 */
    double F = h.type->force(&h, 0.25, &s, &dF);
    ENSURE_REL(F, (4.0 / 3.0) * 0.125, 1e-16);
    ENSURE(dF == 1.0);
    ENSURE_REL(s * s, 0.5, 4e-16); /* s = √√(1/4): two roundings */
    ENSURE_REL(h.type->energy(&h, 0.25), (8.0 / 15.0) / 32.0, 1e-16);
    ENSURE(h.type->energy(&h, -1.0) == 0.0);
    ENSURE(h.type->force(&h, 0.0, &s, &dF) == 0.0 && dF == 0.0 && s == 0.0);
    ENSURE(isnan(h.type->force(&h, -1.0, &s, &dF)));
    /* dF/du and dU/du by differences (closed forms, so only truncation ~1e-10 and rounding) */
    double u = 0.7, hh = 1e-5;
    h.type->force(&h, u, &s, &dF);
    ENSURE_REL((h.type->force(&h, u + hh, NULL, NULL) - h.type->force(&h, u - hh, NULL, NULL)) / (2 * hh),
               dF, 1e-8);
    ENSURE_REL((h.type->energy(&h, u + hh) - h.type->energy(&h, u - hh)) / (2 * hh),
               h.type->force(&h, u, NULL, NULL), 1e-8);

    s = 3.0;
    dF = 3.0;
    const double us[] = {-1e3, -1.0, 0.0, 1.0, 1e6};
    for (size_t i = 0; i < sizeof us / sizeof us[0]; ++i) {
        ENSURE(n.type->force(&n, us[i], &s, &dF) == 0.0 && s == 0.0 && dF == 0.0);
        ENSURE(n.type->energy(&n, us[i]) == 0.0);
        ENSURE(n.type->force(&n, us[i], NULL, NULL) == 0.0);
    }
}

/* vafm_contact_eval_at: the branch evaluation with range checks. */
static void test_eval_at(void)
{
    vafm_contact j = t_jkr(0.229), h, n;
    ENSURE(vafm_contact_init(&h, vafm_contact_hertz, 0.0) == VAFM_OK);
    ENSURE(vafm_contact_init(&n, vafm_contact_none, 0.0) == VAFM_OK);
    vafm_contact_eval e;
    ENSURE(vafm_contact_eval_at(&j, 0.0, &e) == VAFM_OK);
    ENSURE_REL(e.a, j.a0, 1e-12);
    ENSURE_REL(e.F, -(8.0 / 9.0) * j.F_jkr, 1e-12);
    ENSURE(isfinite(e.dFdu));
    ENSURE(vafm_contact_eval_at(&j, j.u_detach, &e) == VAFM_OK);
    ENSURE(e.a == j.s_m * j.s_m && isinf(e.dFdu) && e.dFdu < 0.0);
    ENSURE(vafm_contact_eval_at(&j, nextafter(j.u_detach, -INFINITY), &e) == VAFM_EINVAL);
    ENSURE(vafm_contact_eval_at(&j, NAN, &e) == VAFM_EINVAL);
    ENSURE(vafm_contact_eval_at(&j, INFINITY, &e) == VAFM_EINVAL);
    ENSURE(vafm_contact_eval_at(&j, 0.0, NULL) == VAFM_EINVAL);
    ENSURE(vafm_contact_eval_at(NULL, 0.0, &e) == VAFM_EINVAL);
    ENSURE(vafm_contact_eval_at(&h, 1.0, &e) == VAFM_OK);
    ENSURE(e.a == 1.0 && e.dFdu == 2.0);
    ENSURE_REL(e.F, 4.0 / 3.0, 1e-16);
    ENSURE(vafm_contact_eval_at(&h, 0.0, &e) == VAFM_OK && e.F == 0.0);
    ENSURE(vafm_contact_eval_at(&h, -1e-300, &e) == VAFM_EINVAL);
    ENSURE(vafm_contact_eval_at(&n, 0.0, &e) == VAFM_EINVAL);
    ENSURE(vafm_contact_eval_at(&n, 1e300, &e) == VAFM_EINVAL);
}

/* Warm starts agree with cold starts: a random walk of u (small steps, as in the simulator), jumps in
 * both directions, and absurd guesses (tiny, huge, below s_m, NaN). Both stop within an ulp of the
 * root (see S_TOL in contact_jkr.c), so they may differ by a couple of ulp: 8 ulp allowed. */
static void test_warm_start(void)
{
    for (size_t i = 0; i < T_NGAMMA; ++i) {
        const vafm_contact c = t_jkr(t_gammas[i]);
        double umin = c.u_detach, span = fabs(umin) + 1.0;
        unsigned long long x = 0x9E3779B97F4A7C15ull + i;
        double u = 0.5 * umin, s = 0.0, worst = 0.0;
        for (int step = 0; step < 20000; ++step) {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            double r = (double)(x >> 11) / 9007199254740992.0 - 0.5; /* [−0.5, 0.5) */
            double scale = (step % 1000 == 999) ? 0.5 : 1e-4;       /* occasional big jumps */
            u += scale * span * r;
            if (u < umin)
                u = umin + (umin - u);
            if (u > umin + 3.0 * span)
                u = umin + 3.0 * span;
            double dFw, dFc, sc = 0.0;
            double Fw = c.type->force(&c, u, &s, &dFw);
            double Fc = c.type->force(&c, u, &sc, &dFc);
            double rel = fabs(s - sc) / sc;
            if (rel > worst)
                worst = rel;
            ENSURE_MSG(rel <= 8 * DBL_EPSILON, "gamma %g u %.17g: warm %.17g cold %.17g", t_gammas[i],
                       u, s, sc);
            ENSURE(fabs(Fw - Fc) <= 1e-13 * (fabs(Fc) + c.F_jkr + 1e-300));
        }
        const double u0 = umin + 0.37 * span;
        const double sc = vafm_jkr_sqrt_a(c.c, c.s_m, u0, 0.0);
        const double guesses[] = {1e-300, c.s_m * (1 + 1e-15), 0.5 * sc, 0.999 * sc, 1.001 * sc,
                                  2.0 * sc, 1e300, -1.0, NAN, INFINITY, c.s_m};
        for (size_t gi = 0; gi < sizeof guesses / sizeof guesses[0]; ++gi) {
            double sw = vafm_jkr_sqrt_a(c.c, c.s_m, u0, guesses[gi]);
            ENSURE_MSG(fabs(sw - sc) <= 8 * DBL_EPSILON * sc, "guess %g: %.17g vs %.17g", guesses[gi],
                       sw, sc);
        }
        if (i == T_NGAMMA - 1 || worst > 2 * DBL_EPSILON)
            fprintf(stderr, "     warm vs cold (gamma %g): worst rel difference of sqrt(a) %.2g\n",
                    t_gammas[i], worst);
    }
}

static double t_now(void)
{
    struct timespec ts;
    timespec_get(&ts, TIME_UTC);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Informal timing of the hot call: force() with a warm start when u moves a little per call (a slow
 * ramp plus a small jitter, relative change ~1e-5 per call, as in a simulation step), against cold
 * starts. The best of 3 runs each. No pass/fail on the time itself (machines and sanitizer builds
 * differ); only a sanity check that warm starts are not slower than cold ones (measured ~2.4x faster). */
static double t_time_force(const vafm_contact *c, int n, int warm, double *acc)
{
    double s = 0.0, dF = 0.0, sum = 0.0;
    double t0 = t_now();
    for (int i = 0; i < n; ++i) {
        double u = 0.5 + 1e-5 * (double)(i % 1000) + 1e-6 * (double)(i & 7);
        if (!warm)
            s = 0.0;
        sum += c->type->force(c, u, &s, &dF) + dF;
    }
    double dt = (t_now() - t0) / n;
    *acc += sum;
    return dt;
}

static void test_warm_timing(void)
{
    const vafm_contact c = t_jkr(0.229);
    const int n = LONG_OR(2000000, 300000);
    double acc = 0.0, t_warm = INFINITY, t_cold = INFINITY;
    for (int rep = 0; rep < 3; ++rep) {
        t_warm = fmin(t_warm, t_time_force(&c, n, 1, &acc));
        t_cold = fmin(t_cold, t_time_force(&c, n, 0, &acc));
    }
    ENSURE(isfinite(acc)); /* keeps the loops alive */
    fprintf(stderr, "     force(): %.1f ns/call warm, %.1f ns/call cold\n", 1e9 * t_warm, 1e9 * t_cold);
    ENSURE(t_warm <= t_cold);
}

int main(void)
{
    RUN_TEST(test_init_fields);
    RUN_TEST(test_init_rejects);
    RUN_TEST(test_find);
    RUN_TEST(test_reference_points);
    RUN_TEST(test_unit_depth);
    RUN_TEST(test_round_trip);
    RUN_TEST(test_solver_edges);
    RUN_TEST(test_dFdu_fd);
    RUN_TEST(test_dUdu_fd);
    RUN_TEST(test_hertz_limit);
    RUN_TEST(test_hertz_none_types);
    RUN_TEST(test_eval_at);
    RUN_TEST(test_warm_start);
    RUN_TEST(test_warm_timing);
    return harness_done();
}
