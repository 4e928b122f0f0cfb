/* SPDX-License-Identifier: MIT */
/*
 * Force curves against closed forms (physics notes, "JKR contact", "Quasi-static pull-off with a
 * spring", "Observables"):
 *  1. athermal slow pulls against the quasi-static instability (u_spr*, F_det, F_JKR);
 *  2. the energy lost at touch (0.3 c^{10/3}) and at detachment (0.031498 c^{10/3}) in a noise-free,
 *     friction-free run of the stepping kernel;
 *  3. the curve mechanics: force trigger, dwell, segments, time and height channels;
 *  4. Hertz (γ = 0): F = (4/3)E*√R δ^{3/2} on approach, no pull-off.
 * Everything here is deterministic (T = 0); tolerances are numerical, derived in each test.
 */
#include "harness.h"

#include "vafm/contact.h"
#include "vafm/integrator.h"
#include "vafm/params.h"
#include "vafm/sim.h"
#include "vafm/theory.h"
#include "vafm/units.h"
#include "core/kernel.h"
#include "hertz.h"
#include "trace.h"

/* A scene given by reduced values on E* = 1 GPa, R = 16 nm, m = 1e-12 kg (the paper-fig4 frame),
 * athermal, gjf, height trigger right below a start at the contact point. */
static void t_scene(vafm_params *p, double gamma, double k, double m, double v)
{
    vafm_params_default(p);
    p->E_star_Pa = 1e9;
    p->R_m = 16e-9;
    p->m_kg = 1e-12;
    vafm_reduced r = {.m = m, .eta_cont = 0.0, .k = k, .kT = 0.0, .gamma = gamma, .v_approach = v, .v_retract = v};
    vafm_units_from_reduced(p, &r);
    p->T_K = 0.0;
    p->integrator = vafm_integrator_gjf;
    p->contact = gamma > 0 ? vafm_contact_jkr : vafm_contact_hertz;
}

/* ---- 1. quasi-static pull-off ------------------------------------------------------------------- */

/* One athermal curve: start at the contact point (the body sits at its equilibrium on the contact
 * branch), the height trigger ends the approach after one sample, the retract pulls at ṽ.
 *
 * Why it starts at u_spr = 0 and not near u_spr*: a curve starting below the contact point
 * (u_spr < 0) starts out of contact (JKR hysteresis), so the whole pull from u_spr = 0 to u_spr* must be
 * simulated. At γ̃ = 0.229 that is 11.1 (k̃ = 0.1) and 1.73 (k̃ = 0.8) length units, i.e. 1.1e7 and
 * 1.7e6 time units at ṽ = 1e-6. To afford it, omega_dt = 1.5 (stable: < 2 at the stiffest contact):
 * at T = 0 GJF's fixed points are exact at any dt, so the quasi-static path does not depend on dt;
 * test_qs_dt_insensitive() checks that the step moves the results by < 15% of their small distance
 * from the quasi-static limit. */
static int t_qs_run(double gamma, double k, double v, double omega_dt, vafm_curve_result *res, double *dt_red)
{
    vafm_params p;
    t_scene(&p, gamma, k, 0.01, v);
    vafm_scale sc = vafm_units_scale(&p);
    p.trigger = VAFM_TRIGGER_HEIGHT;
    p.start_height_m = 0.0;
    p.trigger_height_m = -1e-9 * sc.length_m;
    p.omega_dt = omega_dt;
    /* the sample interval (100 time units at ṽ = 1e-6) only sets the output and the trigger latency */
    const double Ts = fmax(1.0, 1e-4 / v);
    p.sample_rate_Hz = 1.0 / (Ts * sc.time_s);
    p.retract_margin_m = 2.0 * v * Ts * sc.length_m;
    vafm_error err;
    memset(&err, 0, sizeof err);
    vafm_sim *s = NULL;
    int r = vafm_sim_new(&s, &p, &err);
    ENSURE_MSG(r == 0, "%s: %s", err.field, err.message);
    if (r)
        return r;
    if (dt_red)
        *dt_red = vafm_sim_dt(s) / sc.time_s;
    r = vafm_sim_curve(s, 0, NULL, NULL, res);
    vafm_sim_destroy(&s);
    /* back to reduced units: forces / (E*R²), heights / R */
    res->pulloff_sampled_N /= sc.force_N;
    res->pulloff_spring_N /= sc.force_N;
    res->detach_force_N /= sc.force_N;
    res->detach_eq_force_N /= sc.force_N;
    res->detach_height_m /= sc.length_m;
    return r;
}

/* For each (γ̃, k̃) of the notes' table: at ṽ = 1e-4, 1e-5, 1e-6
 *  - the spring position at detachment −detach_height/R is within 1e-3 relative of u_spr* at 1e-6
 *    (it lags by v·t_snap: the spring keeps moving during the snap; notes: 5e-4 at k̃ = 0.4);
 *  - the detachment force decreases monotonically toward F_det from above, within 1% at 1e-6 (notes:
 *    0.8% above at ṽ = 1e-6 for γ̃ = 1.2e-4, k̃ = 0.4);
 *  - the most tensile spring force is F_JKR within 1e-4 at 1e-6 (the body passes the force minimum
 *    quasi-statically; the lag there is ζv/k = 1e-7 in u);
 *  - the flags are clean and the equilibrium force at the detachment height exists only short of u_spr*.
 * The table values themselves are checked in test_theory; here they are the reference. */
static void test_quasistatic(void)
{
    static const double table[4][4] = {
        /* γ̃, k̃, u_spr*, F_det/F_JKR (physics notes) */
        {0.229, 0.1, -11.094265, 0.97226725},
        {0.229, 0.8, -1.7260349, 0.83315916},
        {1.2e-4, 0.1, -0.0083206038, 0.77926737},
        {1.2e-4, 0.8, -0.0043345123, 0.59497302},
    };
    for (int i = 0; i < 4; i++) {
        const double g = table[i][0], k = table[i][1];
        vafm_quasistatic q;
        ENSURE(vafm_theory_quasistatic(g, k, &q) == 0);
        ENSURE_REL(q.u_spr_star, table[i][2], 1e-6);
        ENSURE_REL(q.F_det / q.F_jkr, table[i][3], 1e-7);
        /* ṽ = 1e-6 costs 1.2e8 steps at γ̃ = 0.229, k̃ = 0.1 (~4 s optimised): under the sanitizer
         * build the big-γ rows stop at 1e-5 (their force excess there is already ≤ 1e-4). */
        const int nv = g > 0.1 ? LONG_OR(3, 2) : 3;
        const double vs[3] = {1e-4, 1e-5, 1e-6};
        double Fprev = INFINITY;
        for (int j = 0; j < nv; j++) {
            vafm_curve_result r;
            ENSURE(t_qs_run(g, k, vs[j], 1.5, &r, NULL) == 0);
            const double uspr_det = -r.detach_height_m;
            fprintf(stderr, "  gamma %-6g k %-4g v %-6g: u_spr_det/u_spr* - 1 = %+.3e  F_det excess %+.3e  "
                    "F_spring/F_JKR - 1 = %+.3e  sampled/F_JKR - 1 = %+.3e\n",
                    g, k, vs[j], uspr_det / q.u_spr_star - 1.0, r.detach_force_N / q.F_det - 1.0,
                    r.pulloff_spring_N / q.F_jkr - 1.0, r.pulloff_sampled_N / q.F_jkr - 1.0);
            ENSURE_MSG(r.flags == 0, "flags %d", r.flags);
            /* detachment is at or beyond the instability (the spring has passed u_spr*) */
            ENSURE(uspr_det <= q.u_spr_star);
            /* F_det from above, monotonically in ṽ */
            ENSURE_MSG(r.detach_force_N > q.F_det, "gamma %g k %g v %g: F %.10g <= F_det %.10g", g, k, vs[j],
                       r.detach_force_N, q.F_det);
            ENSURE_MSG(r.detach_force_N < Fprev, "gamma %g k %g v %g: F_det not decreasing", g, k, vs[j]);
            Fprev = r.detach_force_N;
            /* the recorded force is the spring force at the recorded position: k(u_spr − u_min) */
            ENSURE_REL(r.detach_force_N, -k * (-r.detach_height_m - q.u_min), 1e-9);
            /* beyond u_spr* there is no equilibrium: NaN; the sampled pull-off never exceeds the spring's */
            ENSURE(isnan(r.detach_eq_force_N));
            ENSURE(r.pulloff_sampled_N <= r.pulloff_spring_N * (1.0 + 1e-12));
            ENSURE(r.pulloff_spring_N >= q.F_jkr * (1.0 - 1e-9)); /* the force minimum was passed */
            if (vs[j] == 1e-6) {
                ENSURE_REL(uspr_det, q.u_spr_star, 1e-3);
                ENSURE_REL(r.detach_force_N, q.F_det, 1e-2);
                ENSURE_REL(r.pulloff_spring_N, q.F_jkr, 1e-4);
            } else if (vs[j] == 1e-5) {
                /* what the sanitizer build asserts for the big-γ rows (notes: 0.6% above at k̃ = 0.8,
                 * γ̃ = 0.229, ṽ = 1e-5 from an independent code at m̃ = 0.01) */
                ENSURE_REL(r.detach_force_N, q.F_det, 2e-2);
                ENSURE_REL(r.pulloff_spring_N, q.F_jkr, 1e-4);
            }
        }
    }
}

/* The slow athermal observables hardly depend on the time step (GJF's fixed points are exact; only
 * the timing of the snap, which sets the small excess over the quasi-static limit, sees dt): between
 * omega_dt 0.157 (the paper's rule) and 1.5 the spring position and force at detachment move by less
 * than 15% of their distance from u_spr* and F_det (measured: 7% at γ̃ = 1.2e-4, k̃ = 0.8, ṽ = 1e-5;
 * 1% at γ̃ = 0.229, k̃ = 0.8, ṽ = 1e-4), and the most tensile spring force by < 1e-6. So the bounds of
 * test_quasistatic, which have ≥ 3× margin over the measured excess, hold for either step. */
static void test_qs_dt_insensitive(void)
{
    const double cases[2][3] = {{1.2e-4, 0.8, 1e-5}, {0.229, 0.8, 1e-4}};
    for (int i = 0; i < 2; i++) {
        vafm_quasistatic q;
        ENSURE(vafm_theory_quasistatic(cases[i][0], cases[i][1], &q) == 0);
        vafm_curve_result a, b;
        double dta = 0, dtb = 0;
        ENSURE(t_qs_run(cases[i][0], cases[i][1], cases[i][2], 0.157, &a, &dta) == 0);
        ENSURE(t_qs_run(cases[i][0], cases[i][1], cases[i][2], 1.5, &b, &dtb) == 0);
        ENSURE(dtb > 5.0 * dta);
        const double lag_u = -a.detach_height_m - q.u_spr_star, lag_F = a.detach_force_N - q.F_det;
        fprintf(stderr, "  gamma %g k %g v %g: omega_dt 0.157 -> 1.5 moves u_spr_det by %.3f of its lag, "
                "F_det by %.3f of its excess\n", cases[i][0], cases[i][1], cases[i][2],
                fabs(b.detach_height_m - a.detach_height_m) / fabs(lag_u),
                fabs(b.detach_force_N - a.detach_force_N) / fabs(lag_F));
        ENSURE_ABS(b.detach_height_m, a.detach_height_m, 0.15 * fabs(lag_u));
        ENSURE_ABS(b.detach_force_N, a.detach_force_N, 0.15 * fabs(lag_F));
        ENSURE_REL(b.pulloff_spring_N, a.pulloff_spring_N, 1e-6);
    }
}

/* ---- 2. energy lost at touch and detachment ------------------------------------------------------ */

static double t_energy(const vafm_kernel *K)
{
    const double U = K->in_contact ? K->contact.type->energy(&K->contact, K->u) : 0.0;
    const double y = K->u_spr - K->u;
    return 0.5 * K->m * K->w * K->w + 0.5 * K->k * y * y + U;
}

/* A friction-free, noise-free body on a static spring, launched from out of contact toward the
 * surface: it touches, bounces off the repulsive core, is pulled back by the spring through u_min and
 * detaches, and cycles until it has lost too much energy to detach. E = ½mw² + ½k(u_spr − u)² + U (U
 * on the branch while in contact, 0 out of contact) is conserved by velocity Verlet between events to
 * O(dt²) and jumps at each event by −0.3 c^{10/3} (touch) or −0.031498 c^{10/3} (detach). Measured jump
 * = E after the event step − E before it; its error is O(dt) (the event happens somewhere inside the
 * step: the force switches up to one step late). Returns the largest |error| / c^{10/3} of each kind. */
static void t_energy_run(double gamma, double k, double m, double uspr, double amp, double dt, double *err_touch,
                         double *err_detach, int *n_touch, int *n_detach)
{
    vafm_kernel K;
    memset(&K, 0, sizeof K);
    K.m = m;
    K.k = k;
    K.kT = 0.0;
    K.thermal = 0;
    ENSURE(vafm_contact_init(&K.contact, vafm_contact_jkr, gamma) == 0);
    K.cforce = K.contact.type->force;
    vafm_kernel_set_dt(&K, dt);
    /* paper-vv with zero friction and zero noise is plain velocity Verlet (symplectic) */
    for (int i = 0; i < 2; i++) {
        K.co[i].zeta = 0.0;
        K.co[i].vv_sig = 0.0;
    }
    K.t = 0.0;
    K.u_spr = uspr;
    s_kernel_phase(&K, 0.0);
    K.u = uspr - amp; /* at rest, spring stretched away from the surface */
    K.w = 0.0;
    K.in_contact = 0;
    K.Fc = 0.0;
    K.fs_min = INFINITY;
    const vafm_integrator_type *it = vafm_integrator_paper_vv;
    it->prepare(&K);
    const double E10 = pow(K.contact.c, 10.0 / 3.0);
    double E = t_energy(&K), t_last = 0.0;
    *err_touch = *err_detach = 0.0;
    *n_touch = *n_detach = 0;
    const long max_steps = (long)(200.0 / dt);
    long short_runs = 0;
    for (long i = 0; i < max_steps; i++) {
        short_runs += it->run(&K, 1) != 1;
        const double E2 = t_energy(&K);
        if (K.event) {
            const double jump = (E2 - E) / E10;
            if (K.event > 0) {
                *err_touch = fmax(*err_touch, fabs(jump + 0.3));
                (*n_touch)++;
            } else {
                *err_detach = fmax(*err_detach, fabs(jump + 0.031498));
                (*n_detach)++;
            }
            K.event = 0;
            t_last = K.t;
        } else if (K.t - t_last > 20.0) {
            break; /* trapped in contact for good (or never touching) */
        }
        E = E2;
    }
    ENSURE(short_runs == 0);
    ENSURE(isfinite(E));
}

/* Two scenes (γ̃ = 0.229 and 1.2e-4) at dt = 1e-4 and 1e-5 (ω_contact·dt ≤ 2e-3): at the smaller dt every
 * jump is within 1% of the exact value (measured: ≤ 0.2%), and the error falls at least 3× for the 10×
 * smaller step (O(dt): 10×; the random phase of the event in its step makes single maxima noisy). */
static void test_energy_events(void)
{
    const double sc[2][5] = {
        /* γ̃, k̃, m̃, u_spr, amplitude: several touch/detach cycles before the body is trapped */
        {0.229, 0.1, 0.01, -5.0, 10.0},
        {1.2e-4, 0.1, 0.01, -0.01, 0.02},
    };
    for (int i = 0; i < 2; i++) {
        double et[2], ed[2];
        int nt[2], nd[2];
        const double dts[2] = {1e-4, 1e-5};
        for (int j = 0; j < 2; j++)
            t_energy_run(sc[i][0], sc[i][1], sc[i][2], sc[i][3], sc[i][4], dts[j], &et[j], &ed[j], &nt[j], &nd[j]);
        fprintf(stderr, "  gamma %g: %d touches, %d detachments; max |error|/c^(10/3): touch %.2e -> %.2e, "
                "detach %.2e -> %.2e\n", sc[i][0], nt[1], nd[1], et[0], et[1], ed[0], ed[1]);
        ENSURE(nt[1] >= 3 && nd[1] >= 3);
        ENSURE(nt[0] == nt[1] && nd[0] == nd[1]);
        ENSURE_MSG(et[1] <= 0.01 * 0.3, "touch jump error %.3g", et[1]);
        ENSURE_MSG(ed[1] <= 0.01 * 0.031498, "detach jump error %.3g", ed[1]);
        ENSURE_MSG(et[1] <= et[0] / 3.0, "touch: no O(dt) convergence (%.3g -> %.3g)", et[0], et[1]);
        ENSURE_MSG(ed[1] <= ed[0] / 3.0, "detach: no O(dt) convergence (%.3g -> %.3g)", ed[0], ed[1]);
    }
    /* the energies of the reference points themselves (exact: the notes' values in units c^{10/3}) */
    vafm_contact c;
    ENSURE(vafm_contact_init(&c, vafm_contact_jkr, 0.229) == 0);
    const double E10 = pow(c.c, 10.0 / 3.0);
    ENSURE_REL(c.type->energy(&c, 0.0) / E10, -0.3, 1e-9);
    ENSURE_REL(c.type->energy(&c, c.u_detach) / E10, 0.031498, 1e-4);
}

/* ---- 3. trigger, dwell and channel mechanics ---------------------------------------------------- */

/* The paper-fig4 scene (thermal) at ṽ = 1e-2 with the force trigger and a dwell of 10.4 samples
 * (→ 10). With point sampling every channel is an instantaneous value at the sample's end, so time and
 * height are exact linear functions up to rounding; with mean sampling the sample time is the middle of
 * the interval and the height the mean over the steps (offset ≤ half a step's travel). */
static void t_mechanics(int antialias)
{
    vafm_params p;
    vafm_preset_apply(&p, "paper-fig4", NULL);
    vafm_reduced rd;
    vafm_units_reduce(&p, &rd);
    rd.v_approach = 1e-2;
    rd.v_retract = 2e-2; /* different speeds: each ramp has its own slope */
    vafm_units_from_reduced(&p, &rd);
    p.antialias = antialias;
    ENSURE(p.trigger == VAFM_TRIGGER_FORCE);
    const double Ts = 1.0 / p.sample_rate_Hz;
    p.dwell_s = 10.4 * Ts;
    const long n_dwell = lround(p.dwell_s * p.sample_rate_Hz);
    ENSURE(n_dwell == 10);
    vafm_sim *s = NULL;
    vafm_error err = {0};
    ENSURE_MSG(vafm_sim_new(&s, &p, &err) == 0, "%s", err.message);
    if (!s)
        return;
    t_trace c;
    memset(&c, 0, sizeof c);
    vafm_curve_result r;
    ENSURE(vafm_sim_curve(s, 2, t_collect, &c, &r) == 0);
    const double dt_s = vafm_sim_dt(s);
    vafm_sim_destroy(&s);
    ENSURE(c.n == r.samples && c.n > 50);

    /* segments: 0…0 2…2 1…1 */
    size_t na = 0, nd = 0, nr = 0, i = 0;
    while (i < c.n && c.seg[i] == VAFM_SEG_APPROACH)
        na++, i++;
    while (i < c.n && c.seg[i] == VAFM_SEG_DWELL)
        nd++, i++;
    while (i < c.n && c.seg[i] == VAFM_SEG_RETRACT)
        nr++, i++;
    ENSURE_MSG(i == c.n, "segments out of order at sample %zu (%d)", i, i < c.n ? c.seg[i] : -1);
    ENSURE(na > 0 && nr > 0);
    ENSURE_MSG(nd == (size_t)n_dwell, "dwell samples %zu, want %ld", nd, n_dwell);

    /* force trigger: every approach sample but the last is below the setpoint, the last reaches it
     * (the trigger compares the reduced force; 1e-12 covers the conversion's rounding) */
    double fmax_a = -INFINITY;
    for (i = 0; i < na; i++)
        fmax_a = fmax(fmax_a, c.f[i]);
    ENSURE(fmax_a >= p.setpoint_N * (1.0 - 1e-12));
    ENSURE(c.f[na - 1] >= p.setpoint_N * (1.0 - 1e-12));
    for (i = 0; i + 1 < na; i++)
        ENSURE_MSG(c.f[i] < p.setpoint_N * (1.0 + 1e-12), "approach sample %zu above the setpoint", i);

    /* time: continuous, step 1/rate; point: (i + 1)/rate, mean: (i + ½)/rate */
    const double off = antialias == VAFM_ANTIALIAS_POINT ? 1.0 : 0.5;
    int bad_t = 0;
    for (i = 0; i < c.n; i++) {
        if (fabs(c.t[i] - (i + off) * Ts) > 1e-12 * (i + 1) * Ts)
            bad_t++;
        if (i && !(c.t[i] > c.t[i - 1]))
            bad_t++;
    }
    ENSURE_MSG(bad_t == 0, "%d time samples off the 1/rate grid", bad_t);

    /* height: h0 − v_a·t on approach, constant during the dwell, h_turn + v_r·(t − t_turn) on retract.
     * Point sampling: exact up to rounding (1e-9 of the travel covers the phase restarts, each
     * t0 + n·dt with relative rounding ~1e-16 per operation). Mean: the mean of the support over the
     * steps ending in the interval is its value half a step after the middle: ≤ v·(step)/2 away,
     * with a step ≤ Ts (integrator or exact free steps). */
    const double va = p.v_approach_m_per_s, vr = p.v_retract_m_per_s, h0 = p.start_height_m;
    const double travel = fabs(h0) + va * c.t[na - 1] + vr * (c.t[c.n - 1] - c.t[na - 1]);
    const double tol_a = antialias == VAFM_ANTIALIAS_POINT ? 1e-9 * travel : 0.5 * va * Ts + 1e-9 * travel;
    const double tol_r = antialias == VAFM_ANTIALIAS_POINT ? 1e-9 * travel : 0.5 * vr * Ts + 1e-9 * travel;
    int bad_h = 0;
    double worst = 0.0;
    for (i = 0; i < na; i++) {
        double e = fabs(c.h[i] - (h0 - va * c.t[i]));
        worst = fmax(worst, e / tol_a);
        bad_h += e > tol_a;
    }
    /* the piezo stops at the end of the approach interval: the turn height (point: the last approach
     * sample's own height) */
    const double t_turn = antialias == VAFM_ANTIALIAS_POINT ? c.t[na - 1] : c.t[na - 1] + 0.5 * Ts;
    const double h_turn = h0 - va * t_turn;
    for (i = na; i < na + nd; i++) {
        double e = fabs(c.h[i] - h_turn);
        worst = fmax(worst, e / tol_a);
        bad_h += e > tol_a;
    }
    const double t_ret = t_turn + (double)nd * Ts;
    for (i = na + nd; i < c.n; i++) {
        double e = fabs(c.h[i] - (h_turn + vr * (c.t[i] - t_ret)));
        worst = fmax(worst, e / tol_r);
        bad_h += e > tol_r;
    }
    ENSURE_MSG(bad_h == 0, "%d heights off the ramp (worst %.3g of the tolerance)", bad_h, worst);
    ENSURE_REL(r.retract_start_s, t_ret, 1e-12);

    /* channel identities: tip = height + deflection, force = k·deflection */
    int bad_c = 0;
    for (i = 0; i < c.n; i++) {
        double scale = fabs(c.h[i]) + fabs(c.d[i]) + fabs(c.tip[i]);
        if (fabs(c.h[i] + c.d[i] - c.tip[i]) > 1e-12 * scale)
            bad_c++;
        if (fabs(c.f[i] - p.k_N_per_m * c.d[i]) > 1e-12 * fabs(c.f[i]))
            bad_c++;
    }
    ENSURE_MSG(bad_c == 0, "%d samples break tip = height + deflection or force = k*deflection", bad_c);

    /* the result agrees with the samples: the sampled pull-off is the most tensile retract sample */
    double fmin_r = INFINITY;
    for (i = na + nd; i < c.n; i++)
        fmin_r = fmin(fmin_r, c.f[i]);
    ENSURE_REL(r.pulloff_sampled_N, -fmin_r, 1e-14);
    ENSURE(r.flags == 0);
    ENSURE(r.touch_time_s > 0 && r.touch_time_s < c.t[na - 1] + Ts);
    ENSURE(r.detach_time_s > 0 && r.retract_start_s + r.detach_time_s <= c.t[c.n - 1] + Ts);
    ENSURE(r.steps >= r.steps_contact + r.steps_free);
    ENSURE(r.steps_contact > 0);
    ENSURE(dt_s > 0 && dt_s <= Ts);
    ENSURE_REL(r.duration_s, (c.n) * Ts, 1e-12);
    t_trace_free(&c);
}

static void test_mechanics(void)
{
    t_mechanics(VAFM_ANTIALIAS_POINT);
    t_mechanics(VAFM_ANTIALIAS_MEAN);
}

/* Curve `index` of scene p collected whole into *c, its result in *r; a refused scene or a failed curve is a
 * failed check. @return 0 or the error. */
static int t_run(const vafm_params *p, uint64_t index, t_trace *c, vafm_curve_result *r)
{
    vafm_sim *s = NULL;
    vafm_error err;
    memset(&err, 0, sizeof err);
    memset(c, 0, sizeof *c);
    int rc = vafm_sim_new(&s, p, &err);
    ENSURE_MSG(rc == 0, "scene refused: %s", err.message);
    if (rc)
        return rc;
    rc = vafm_sim_curve(s, index, t_collect, c, r);
    vafm_sim_destroy(&s);
    ENSURE(rc == 0);
    return rc;
}

/* ---- 4. Hertz ---------------------------------------------------------------------------------- */

/* γ = 0, contact hertz, athermal, ṽ = 1e-4, k̃ = 1, setpoint F̃ = 0.5 (δ̃ ≈ 0.52), point sampling.
 * Quasi-static error of the spring force against the contact force: friction ζ(w − v) with
 * w = v·k/(k + K_c): ≤ m̃ṽ = 1e-6 absolute, ≤ 2e-5 relative above F̃ = 0.05 (where the check starts);
 * ringing from the touch is damped (η = 1) long before: the Hertz stiffness starts at 0. So 1e-3 has
 * ample margin. Without adhesion the only tensile force left is that drag: pull-off ≤ 2m̃ṽ. */
static void t_hertz(int jkr_gamma_zero, double gamma_J)
{
    vafm_params p;
    t_scene(&p, 0.0, 1.0, 0.01, 1e-4);
    if (jkr_gamma_zero) {
        p.contact = vafm_contact_jkr;
        p.gamma_J_per_m2 = gamma_J;
    }
    t_hertz_protocol(&p);
    const vafm_scale sc = vafm_units_scale(&p);
    t_trace c;
    vafm_curve_result r;
    if (t_run(&p, 0, &c, &r)) {
        t_trace_free(&c);
        return;
    }
    int n_checked, bad;
    double worst;
    t_hertz_approach(&c, &p, 0.05 * sc.force_N, 1e-3, &n_checked, &bad, &worst);
    fprintf(stderr, "  %s: %d approach samples vs Hertz, worst rel %.2e; pull-off sampled %.3g, spring %.3g "
            "(units E*R^2)\n", jkr_gamma_zero ? "jkr gamma ~ 0" : "hertz", n_checked, worst,
            r.pulloff_sampled_N / sc.force_N, r.pulloff_spring_N / sc.force_N);
    ENSURE(n_checked > 100);
    ENSURE_MSG(bad == 0, "%d samples off Hertz by > 1e-3 (worst %.3g)", bad, worst);
    const double drag = 2.0 * 0.01 * 1e-4 * sc.force_N; /* 2 m̃ṽ in N */
    ENSURE_MSG(r.pulloff_sampled_N <= drag, "pull-off %.3g N > %.3g N", r.pulloff_sampled_N, drag);
    ENSURE_MSG(r.pulloff_spring_N <= drag, "spring pull-off %.3g N > %.3g N", r.pulloff_spring_N, drag);
    ENSURE(r.flags == 0);
    ENSURE(isfinite(r.detach_force_N) && fabs(r.detach_force_N) <= drag);
    ENSURE(isnan(r.detach_eq_force_N));
    t_trace_free(&c);
}

static void test_hertz(void)
{
    t_hertz(0, 0.0);
}

/* The instrument presets (issue #16) run as the instruments they describe, at room temperature:
 * contact-silica pulls off at 80-100% of F_JKR (thermal activation lowers it: measured 0.90 at 25 C, seed 1),
 * its trigger fires at the setpoint, its free cantilever has f0 = 13 kHz and Q = 30; cell-liquid indents the
 * soft cell as Hertz says at the setpoint (no adhesion, its viscous and thermal forces are below 1% there). */
static void test_instrument_presets(void)
{
    vafm_params p;
    ENSURE(vafm_preset_apply(&p, "contact-silica", NULL) == 0);
    double w0 = sqrt(p.k_N_per_m / vafm_params_mass_kg(&p));
    ENSURE_REL(w0 / (2.0 * M_PI), 13e3, 1e-12);
    ENSURE_REL(w0 / vafm_params_eta_per_s(&p), 30.0, 1e-12);
    vafm_sim *s = NULL;
    vafm_curve_result r;
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    t_trace c;
    memset(&c, 0, sizeof c);
    ENSURE(s && vafm_sim_curve(s, 0, t_collect, &c, &r) == 0);
    vafm_sim_destroy(&s);
    double F_jkr = 1.5 * M_PI * p.gamma_J_per_m2 * p.R_m;
    ENSURE_MSG(r.flags == 0 && r.pulloff_spring_N > 0.8 * F_jkr && r.pulloff_spring_N < 1.0 * F_jkr,
               "contact-silica: flags %d, pull-off %g of F_JKR", r.flags, r.pulloff_spring_N / F_jkr);
    t_trace_free(&c);

    ENSURE(vafm_preset_apply(&p, "cell-liquid", NULL) == 0);
    p.T_K = 0; /* the Hertz check without thermal noise (0.4 nm rms against ~550 nm of indentation) */
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    memset(&c, 0, sizeof c);
    ENSURE(s && vafm_sim_curve(s, 0, t_collect, &c, &r) == 0);
    vafm_sim_destroy(&s);
    ENSURE_MSG(!(r.flags & (VAFM_CURVE_NO_TRIGGER | VAFM_CURVE_NO_CONTACT)), "cell-liquid: flags %d", r.flags);
    size_t i = 0;
    while (i < c.n && c.seg[i] == VAFM_SEG_APPROACH && c.f[i] < p.setpoint_N)
        i++;
    ENSURE(i < c.n);
    if (i < c.n) {
        double delta = -c.tip[i], F = 4.0 / 3.0 * p.E_star_Pa * sqrt(p.R_m) * delta * sqrt(delta);
        ENSURE_MSG(delta > 400e-9 && fabs(F / c.f[i] - 1.0) < 0.03, "cell-liquid: indentation %g m, Hertz %g N vs %g N",
                   delta, F, c.f[i]);
    }
    t_trace_free(&c);
}

/* Index of the last approach sample (where the trigger fired). */
static size_t t_turn(const t_trace *c)
{
    size_t i = 0;
    while (i + 1 < c->n && c->seg[i + 1] == VAFM_SEG_APPROACH)
        i++;
    return i;
}

/* A fixed ramp (issue #16): the approach starts at the start height and travels at most ramp_size_m, the
 * retract returns to the start height (a long baseline on both segments), within one sample's travel. */
static void test_fixed_ramp(void)
{
    vafm_params p;
    vafm_preset_apply(&p, "contact-silica", NULL);
    p.ramp_size_m = 300e-9; /* the 5 nN setpoint lies ~150 nm below the 100 nm start */
    double step = p.v_approach_m_per_s / p.sample_rate_Hz;
    t_trace c;
    vafm_curve_result r;
    if (t_run(&p, 0, &c, &r))
        return;
    ENSURE_MSG(r.flags == 0, "flags %d", r.flags);
    ENSURE_MSG(fabs(c.h[0] - p.start_height_m) <= step, "first height %g m", c.h[0]);
    ENSURE_MSG(fabs(c.h[c.n - 1] - p.start_height_m) <= step, "last height %g m, start %g m", c.h[c.n - 1],
               p.start_height_m);
    size_t it = t_turn(&c);
    ENSURE_MSG(c.f[it] >= p.setpoint_N && c.f[it - 1] < p.setpoint_N, "trigger at %g N", c.f[it]);
    /* the retract's free baseline: from the detachment (~ -25 nm at 2.4 nN) back to +100 nm */
    size_t free_ret = 0;
    for (size_t i = it; i < c.n; i++)
        free_ret += c.seg[i] == VAFM_SEG_RETRACT && fabs(c.f[i]) < 0.2e-9 && c.h[i] > 20e-9; /* thermal: 20 pN rms */
    ENSURE_MSG(free_ret * step > 70e-9, "retract baseline %g m", free_ret * step);
    t_trace_free(&c);

    /* a ramp shorter than the way to the setpoint: the approach ends at its full size, flagged, and the
     * retract still returns to the start */
    p.ramp_size_m = 80e-9;
    if (t_run(&p, 0, &c, &r))
        return;
    ENSURE_MSG(r.flags & VAFM_CURVE_NO_TRIGGER, "flags %d", r.flags);
    it = t_turn(&c);
    ENSURE_MSG(fabs(c.h[it] - (p.start_height_m - p.ramp_size_m)) <= step, "turn at %g m", c.h[it]);
    ENSURE_MSG(fabs(c.h[c.n - 1] - p.start_height_m) <= step, "last height %g m", c.h[c.n - 1]);
    t_trace_free(&c);

    /* the ramp starts ramp_size_m above the quasi-static trigger point: athermal and slow (1 um/s against a
     * 13 kHz lever, a lag of ~1e-14 m), the turn lies one ramp below the start to within a sample's travel */
    vafm_preset_apply(&p, "contact-silica", NULL);
    p.T_K = 0;
    p.ramp_size_m = 200e-9;
    p.ramp_start = VAFM_RAMP_START_TRIGGER;
    if (t_run(&p, 0, &c, &r))
        return;
    ENSURE_MSG(r.flags == 0, "flags %d", r.flags);
    it = t_turn(&c);
    ENSURE_MSG(fabs(c.h[0] - c.h[it] - p.ramp_size_m) <= 1.5 * step, "start %g m, turn %g m: travel %g m", c.h[0],
               c.h[it], c.h[0] - c.h[it]);
    ENSURE_MSG(fabs(c.h[c.n - 1] - c.h[0]) <= step, "returns to %g m of %g m", c.h[c.n - 1], c.h[0]);
    t_trace_free(&c);
}

/* A relative setpoint counts from the baseline of the approach's first 64 samples, as instruments do; a
 * setpoint in volts is k·InvOLS·V, less the signal's offset when absolute. The test replays the rule on the
 * curve's own (thermal) samples: the trigger fires at the first sample that meets it. */
static void t_check_trigger(const t_trace *c, double F_set, int relative)
{
    size_t it = t_turn(c);
    double sum = 0.0;
    size_t first = c->n;
    for (size_t j = 0; j <= it; j++) {
        double base = relative ? (j ? sum / (double)(j < VAFM_BASELINE_SAMPLES ? j : VAFM_BASELINE_SAMPLES) : 0.0) : 0.0;
        int armed = !relative || j > 0;
        if (armed && c->f[j] - base >= F_set && first == c->n)
            first = j;
        if (j < VAFM_BASELINE_SAMPLES)
            sum += c->f[j];
    }
    ENSURE_MSG(first == it, "trigger at sample %zu, the rule says %zu (setpoint %g N, %s)", it, first, F_set,
               relative ? "relative" : "absolute");
}

static void test_setpoint_modes(void)
{
    vafm_params p;
    vafm_preset_apply(&p, "contact-silica", NULL);
    p.ramp_size_m = 300e-9;
    t_trace c;
    vafm_curve_result r;
    for (int rel = 0; rel <= 1; rel++) {
        p.setpoint_mode = rel;
        if (t_run(&p, 3, &c, &r))
            return;
        t_check_trigger(&c, p.setpoint_N, rel);
        t_trace_free(&c);
    }
    p.baseline_offset_V = 0.2;
    p.setpoint_V = 0.5;
    for (int rel = 0; rel <= 1; rel++) {
        p.setpoint_mode = rel;
        ENSURE(vafm_params_resolve(&p, NULL) == 0);
        double want = p.k_N_per_m * p.sensitivity_m_per_V * (rel ? 0.5 : 0.3);
        ENSURE_REL(p.setpoint_N, want, 1e-15);
        if (t_run(&p, 3, &c, &r))
            return;
        t_check_trigger(&c, want, rel);
        t_trace_free(&c);
    }
    /* a real baseline: in the scenes above the force's baseline is ≈ 0 (the offset is the signal's, not the
     * force's; the lever's drag is relative to its moving support), so both modes fire on the same sample.
     * Here the approach starts in contact (cell-liquid, Hertz, athermal, 300 nm below the contact point:
     * ~0.2 nN of repulsion against a 0.5 nN setpoint), so the 64 baseline samples average ~0.2 nN and the
     * relative setpoint must fire later, where force − baseline reaches 0.5 nN */
    vafm_preset_apply(&p, "cell-liquid", NULL);
    p.T_K = 0;
    p.start_height_m = -300e-9;
    size_t turn[2] = { 0, 0 };
    double base = 0.0, f_turn[2] = { 0.0, 0.0 };
    for (int rel = 0; rel <= 1; rel++) {
        p.setpoint_mode = rel;
        if (t_run(&p, 0, &c, &r))
            return;
        t_check_trigger(&c, p.setpoint_N, rel);
        turn[rel] = t_turn(&c);
        f_turn[rel] = c.f[turn[rel]];
        base = 0.0;
        for (size_t j = 0; j < VAFM_BASELINE_SAMPLES && j < c.n; j++)
            base += c.f[j] / VAFM_BASELINE_SAMPLES;
        t_trace_free(&c);
    }
    fprintf(stderr, "  baseline %.4g N, setpoint %.4g N: trigger at sample %zu, %.4g N (absolute), %zu, %.4g N "
                    "(relative)\n", base, p.setpoint_N, turn[0], f_turn[0], turn[1], f_turn[1]);
    ENSURE_MSG(base > 0.2 * p.setpoint_N, "baseline %g N", base);
    ENSURE_MSG(turn[1] > turn[0] + 10, "relative trigger at sample %zu, absolute at %zu", turn[1], turn[0]);
}

/* Dwell at constant force: a fast approach (10 nm per sample) overshoots the setpoint; at constant height
 * the force stays at the overshoot, at constant force the feedback brings it back to the setpoint (20 loop
 * time constants: e^-20) by moving the piezo back by overshoot / k_eff. Athermal: exact to the loop's residue. */
static void test_dwell_force(void)
{
    vafm_params p;
    vafm_preset_apply(&p, "contact-silica", NULL);
    p.T_K = 0;
    p.ramp_size_m = 300e-9;
    p.v_approach_m_per_s = 100e-6;
    p.dwell_s = 0.02; /* 200 samples, the loop's default time constant is 10 */
    t_trace c;
    vafm_curve_result r;
    double hold[2], h_move[2];
    for (int mode = 0; mode <= 1; mode++) {
        p.dwell_mode = mode;
        if (t_run(&p, 0, &c, &r))
            return;
        size_t i0 = c.n, i1 = 0;
        for (size_t i = 0; i < c.n; i++)
            if (c.seg[i] == VAFM_SEG_DWELL) {
                i0 = i < i0 ? i : i0;
                i1 = i;
            }
        ENSURE(i0 < c.n && i1 - i0 + 1 == 200);
        if (i0 >= c.n)
            return;
        hold[mode] = c.f[i1];
        h_move[mode] = c.h[i1] - c.h[i0];
        t_trace_free(&c);
    }
    double over = hold[0] - p.setpoint_N;
    ENSURE_MSG(over > 0.05 * p.setpoint_N, "constant height: overshoot %g N", over);
    ENSURE_MSG(fabs(h_move[0]) < 1e-15, "constant height: the piezo moved %g m", h_move[0]);
    ENSURE_MSG(fabs(hold[1] - p.setpoint_N) < 1e-6 * p.setpoint_N, "constant force: %g N held, setpoint %g N",
               hold[1], p.setpoint_N);
    ENSURE_MSG(h_move[1] > 0.5 * over / p.k_N_per_m && h_move[1] < 1.5 * over / p.k_N_per_m,
               "constant force: the piezo moved back %g m for an overshoot of %g N", h_move[1], over);
}

/* pulloff_sampled_N is the most tensile sample of the retract alone. On ordinary curves the retract holds
 * the curve's minimum anyway; here it cannot: contact-silica (JKR), athermal, 100 kHz, the snap-in on the
 * approach pulls the lever down (tensile samples, −3 pN), then the retract stops after 2 nm (retract_max_m),
 * still pressed in (compressive samples only, ≈ +4.8 nN; flagged NO_DETACH). The result must equal
 * −min(force[retract]) exactly (≈ −4.8 nN), not the approach's snap-in. */
static void test_pulloff_sampled_retract_only(void)
{
    vafm_params p;
    vafm_preset_apply(&p, "contact-silica", NULL);
    p.T_K = 0;
    p.sample_rate_Hz = 100e3;
    p.ramp_size_m = 0; /* the adaptive ramp, which retract_max_m bounds */
    p.retract_max_m = 2e-9;
    t_trace c;
    vafm_curve_result r;
    if (t_run(&p, 0, &c, &r))
        return;
    double min_ret = INFINITY, min_other = INFINITY;
    size_t n_ret = 0;
    for (size_t i = 0; i < c.n; i++) {
        if (c.seg[i] == VAFM_SEG_RETRACT) {
            min_ret = fmin(min_ret, c.f[i]);
            n_ret++;
        } else {
            min_other = fmin(min_other, c.f[i]);
        }
    }
    fprintf(stderr, "  %zu retract samples, min %.4g N; approach and dwell min %.4g N; pulloff_sampled %.4g N, "
                    "flags %d\n", n_ret, min_ret, min_other, r.pulloff_sampled_N, r.flags);
    ENSURE(n_ret > 0);
    ENSURE_MSG(r.flags & VAFM_CURVE_NO_DETACH, "flags %d", r.flags);
    ENSURE_MSG(min_other < 0.0 && min_other < min_ret, "approach/dwell min %g N, retract min %g N: not the scene "
               "meant", min_other, min_ret);
    ENSURE_MSG(r.pulloff_sampled_N == -min_ret, "pulloff_sampled_N %.17g, -min(force[retract]) %.17g",
               r.pulloff_sampled_N, -min_ret);
    t_trace_free(&c);
}

int main(void)
{
    RUN_TEST(test_fixed_ramp);
    RUN_TEST(test_setpoint_modes);
    RUN_TEST(test_pulloff_sampled_retract_only);
    RUN_TEST(test_dwell_force);
    RUN_TEST(test_instrument_presets);
    RUN_TEST(test_mechanics);
    RUN_TEST(test_hertz);
    RUN_TEST(test_energy_events);
    RUN_TEST(test_qs_dt_insensitive);
    RUN_TEST(test_quasistatic);
    return harness_done();
}
