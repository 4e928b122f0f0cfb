/* SPDX-License-Identifier: MIT */
/*
 * The always-on controller (vafm/ctrl.h) and the simulation's live scene against theory.
 *
 * Scene: the contact-silica preset (k = 0.1 N/m, f0 = 13 kHz, Q = 30, JKR on silica, 298 K, 10 kHz sampling)
 * with end-point samples (antialias none), so that a sample is the lever's state at an instant.
 * Statistics: fixed seeds; block averages over S_NB = 50 blocks, each far longer than the correlation time
 * (Q/(π f0) = 0.7 ms = 7 samples free, about the same in contact), standard error sd(block means)/√S_NB;
 * checks at 5σ of it unless stated.
 */
#include "harness.h"

#include <math.h>
#include <stdint.h>
#include <string.h>
#include <time.h>

#include "vafm/ctrl.h"
#include "vafm/map.h"
#include "vafm/params.h"
#include "vafm/sim.h"
#include "vafm/theory.h"

#define S_NB 50
#define S_KB 1.380649e-23

static void s_scene(vafm_params *p)
{
    vafm_params_default(p);
    ENSURE(vafm_preset_apply(p, "contact-silica", NULL) == 0);
    p->antialias = VAFM_ANTIALIAS_POINT;
}

static double s_cpu(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* block statistics of a series: mean, its standard error, mean square about a given centre */
typedef struct s_blk {
    long per, cnt;
    int nb;
    double sum, sum2, bm[S_NB], bm2[S_NB];
} s_blk;

static void s_blk_init(s_blk *b, long n)
{
    memset(b, 0, sizeof *b);
    b->per = n / S_NB > 0 ? n / S_NB : 1;
}

static void s_blk_push(s_blk *b, double v)
{
    if (b->nb >= S_NB)
        return;
    b->sum += v;
    b->sum2 += v * v;
    if (++b->cnt == b->per) {
        b->bm[b->nb] = b->sum / (double)b->per;
        b->bm2[b->nb++] = b->sum2 / (double)b->per;
        b->sum = b->sum2 = 0.0;
        b->cnt = 0;
    }
}

/* mean and standard error of the block means of x (which = 0) or of x² (which = 1) */
static void s_blk_stat(const s_blk *b, int which, double *mean, double *se)
{
    const double *v = which ? b->bm2 : b->bm;
    double m = 0.0, s2 = 0.0;
    for (int i = 0; i < b->nb; i++)
        m += v[i];
    m /= b->nb;
    for (int i = 0; i < b->nb; i++)
        s2 += (v[i] - m) * (v[i] - m);
    *mean = m;
    *se = sqrt(s2 / (b->nb - 1) / b->nb);
}

/* JKR (SI): the contact stiffness dF/du on the stable branch where the contact force is F. F(a) =
 * (4E* / 3R)a³ − √(8πγE*)a^{3/2} and u(a) = a²/R − √(2πγa/E*) (physics notes); a by bisection above the force
 * minimum, dF/du = (dF/da)/(du/da). */
static double s_jkr_stiffness(const vafm_params *p, double F)
{
    const double E = p->E_star_Pa, R = p->R_m, g = p->gamma_J_per_m2;
    const double A = 4.0 * E / (3.0 * R), B = sqrt(8.0 * M_PI * g * E);
    double lo = pow(B / (2.0 * A), 2.0 / 3.0), hi = 1e-6; /* dF/da = 0 at a^{3/2} = B/(2A) */
    for (int i = 0; i < 200; i++) {
        const double mid = 0.5 * (lo + hi);
        if (A * mid * mid * mid - B * pow(mid, 1.5) < F)
            lo = mid;
        else
            hi = mid;
    }
    const double a = 0.5 * (lo + hi);
    const double dFda = 3.0 * A * a * a - 1.5 * B * sqrt(a), duda = 2.0 * a / R - 0.5 * sqrt(2.0 * M_PI * g / (E * a));
    return dFda / duda;
}

/* ---- the live scene ------------------------------------------------------------------------------ */

typedef struct s_free_run {
    double h;
    s_blk b;
    uint64_t n;
} s_free_run;

static double s_hold(void *user, const vafm_live_sample *smp)
{
    s_free_run *r = user;
    s_blk_push(&r->b, smp->deflection_m);
    r->n++;
    return r->h;
}

/* A free live lever 1 µm above the surface: <d²> = kT/k, <d> = 0 (exact free transitions, one per sample). */
static void test_live_free(void)
{
    vafm_params p;
    s_scene(&p);
    vafm_sim *s = NULL;
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    const long N = LONG_OR(400000, 200000);
    s_free_run r = { .h = 1e-6 };
    s_blk_init(&r.b, N);
    ENSURE(vafm_sim_live_begin(s, 0, r.h, s_hold, &r) == 0);
    double c0 = s_cpu();
    ENSURE(vafm_sim_advance(s, (size_t)N, NULL, NULL) == 1);
    double cpu = s_cpu() - c0;
    double m, se, m2, se2;
    s_blk_stat(&r.b, 0, &m, &se);
    s_blk_stat(&r.b, 1, &m2, &se2);
    const double var = S_KB * p.T_K / p.k_N_per_m;
    fprintf(stderr, "  live free: N %ld <d> %.3g ± %.2g m, <d²>/(kT/k) %.5f ± %.5f, %.0f ns/sample\n", N, m, se,
            m2 / var, se2 / var, 1e9 * cpu / N);
    ENSURE(r.n == (uint64_t)N);
    ENSURE(fabs(m) < 5.0 * se);
    ENSURE(fabs(m2 - var) < 5.0 * se2);
    ENSURE(se2 < 0.02 * var); /* the test can see a 10% error */
    vafm_sim_destroy(&s);
}

/* ---- the controller ------------------------------------------------------------------------------ */

typedef struct s_rec {
    s_blk f;       /* force while engaged */
    long skip;     /* samples to skip after the engage */
    double centre; /* forces are recorded about it (the setpoint), so the variance does not cancel */
    int engaged_seen;
} s_rec;

static void s_sink(void *user, const vafm_ctrl_samples *b)
{
    s_rec *r = user;
    if (!r)
        return;
    for (size_t i = 0; i < b->n; i++) {
        if (b->state[i] != VAFM_CTRL_ENGAGED)
            continue;
        if (r->skip > 0) {
            r->skip--;
            continue;
        }
        s_blk_push(&r->f, b->force_N[i] - r->centre);
    }
}

/* Run until an event of `type` (or any FAILED/CRASH when stop_bad) or max_s of simulated time. */
static int s_until(vafm_ctrl *c, int type, double max_s, vafm_ctrl_event *got, vafm_ctrl_sample_fn fn, void *user)
{
    const double Ts = vafm_ctrl_sample_interval_s(c);
    long left = (long)(max_s / Ts);
    while (left > 0) {
        long n = vafm_ctrl_advance(c, 100, fn, user); /* status within 100 samples of an event */
        if (n < 0)
            return (int)n;
        left -= n;
        vafm_ctrl_event ev;
        while (vafm_ctrl_event_pop(c, &ev)) {
            if (ev.type == type) {
                if (got)
                    *got = ev;
                return 1;
            }
            if (ev.type == VAFM_CTRL_EV_FAILED || ev.type == VAFM_CTRL_EV_CRASH) {
                if (got)
                    *got = ev;
                return 2;
            }
        }
    }
    return 0;
}

/* Engage from 200 µm: reaches the setpoint and reports engaged, with little CPU. */
static void test_engage(void)
{
    vafm_params p;
    s_scene(&p);
    vafm_ctrl_params cp;
    vafm_ctrl_params_default(&cp);
    cp.fb_tau_s = 100.0 / p.sample_rate_Hz;
    vafm_ctrl *c = NULL;
    vafm_error err;
    ENSURE(vafm_ctrl_new(&c, &p, &cp, NULL, &err) == 0);
    double c0 = s_cpu();
    vafm_ctrl_event ev;
    int r = s_until(c, VAFM_CTRL_EV_ENGAGED, 0.01, &ev, NULL, NULL);
    ENSURE(r == 0);
    ENSURE(vafm_ctrl_engage(c) == 0);
    r = s_until(c, VAFM_CTRL_EV_ENGAGED, 200.0, &ev, NULL, NULL);
    double cpu = s_cpu() - c0;
    vafm_ctrl_status st;
    vafm_ctrl_status_get(c, &st);
    fprintf(stderr, "  engage: r %d at t %.3f s, force %.4g N, motor %.4g m, piezo %.4g m, steps %llu, cpu %.3f s\n",
            r, ev.time_s, ev.value, st.motor_z_m, st.piezo_z_m, (unsigned long long)st.motor_steps, cpu);
    ENSURE(r == 1);
    ENSURE(st.state == VAFM_CTRL_ENGAGED && st.feedback && st.in_contact);
    ENSURE(cpu < 5.0);
    /* engaged: the mean force holds the setpoint with the thermal spread */
    s_rec rec;
    memset(&rec, 0, sizeof rec);
    const long N = LONG_OR(400000, 100000);
    rec.skip = 2000;
    rec.centre = st.setpoint_N;
    s_blk_init(&rec.f, N);
    c0 = s_cpu();
    const long skip = rec.skip;
    ENSURE(vafm_ctrl_advance(c, (size_t)(N + skip), s_sink, &rec) == N + skip);
    cpu = s_cpu() - c0;
    vafm_ctrl_status_get(c, &st);
    double m, se, m2, se2;
    s_blk_stat(&rec.f, 0, &m, &se);
    s_blk_stat(&rec.f, 1, &m2, &se2);
    const double var = m2 - m * m;
    m += rec.centre;
    fprintf(stderr, "  engaged: setpoint %.6g N, <F> %.6g ± %.2g N, sd %.4g N, %.0f ns/sample\n", st.setpoint_N, m,
            se, sqrt(var), 1e9 * cpu / N);
    /* thermal spread of an end-point force sample in the contact well: σ² = k²·kT/(k + k_c); the integral loop
     * x_{n+1} = x_n − G(a x_n + ξ_n) (G = Ts/(kτ), a = k·k_c/(k + k_c) the force per m of piezo) adds
     * a²Var(x) = σ²·g/(2 − g), g = G·a: Var F = σ²·2/(2 − g). With τ = 100 samples g ≈ 0.01, so the noise's
     * colour (in-contact Q ≈ 900: ringing over ~7 samples) changes the prediction by < 1%: the check allows that
     * plus 5 standard errors. */
    const double kc = s_jkr_stiffness(&p, m), kT = S_KB * p.T_K, k = p.k_N_per_m;
    const double sig2 = k * k * kT / (k + kc), g = (1.0 / p.sample_rate_Hz) / (k * cp.fb_tau_s) * (k * kc / (k + kc));
    const double pred = sig2 * 2.0 / (2.0 - g);
    const double var_se = se2;
    fprintf(stderr, "  engaged: k_c %.4g N/m, g %.4g, sd predicted %.4g N, var/pred %.4f ± %.4f\n", kc, g, sqrt(pred),
            var / pred, var_se / pred);
    ENSURE(fabs(m - st.setpoint_N) < 5.0 * se + 1e-15);
    ENSURE(fabs(var - pred) < 5.0 * var_se + 0.01 * pred);
    vafm_ctrl_destroy(&c);
}


static vafm_ctrl *s_new(vafm_params *p, vafm_ctrl_params *cp, const vafm_map_spec *map)
{
    vafm_ctrl *c = NULL;
    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = vafm_ctrl_new(&c, p, cp, map, &err);
    ENSURE_MSG(r == 0, "vafm_ctrl_new: %d %s: %s", r, err.field, err.message);
    return c;
}

/* Settings: the defaults pass; a bad field is named with its range. */
static void test_params(void)
{
    vafm_params p;
    s_scene(&p);
    vafm_ctrl_params cp;
    vafm_ctrl_params_default(&cp);
    vafm_error err;
    ENSURE(vafm_ctrl_params_validate(&cp, &p, &err) == 0);
    cp.motor_step_m = 0.0;
    ENSURE(vafm_ctrl_params_validate(&cp, &p, &err) == VAFM_EINVAL);
    ENSURE(strcmp(err.field, "motor_step_m") == 0 && strstr(err.message, "(0, 0.001]"));
    vafm_ctrl_params_default(&cp);
    cp.force_limit_N = 1e-9; /* below the 2 nN setpoint */
    ENSURE(vafm_ctrl_params_validate(&cp, &p, &err) == VAFM_EINVAL);
    ENSURE(strcmp(err.field, "force_limit_N") == 0);
    vafm_ctrl_params_default(&cp);
    cp.motor_z0_m = 20e-3; /* beyond motor_max_m */
    ENSURE(vafm_ctrl_params_validate(&cp, &p, &err) == VAFM_EINVAL);
    ENSURE(strcmp(err.field, "motor_z0_m") == 0);
    vafm_ctrl_params_default(&cp);
    cp.setpoint_unit = 7;
    ENSURE(vafm_ctrl_params_validate(&cp, &p, &err) == VAFM_EINVAL && strcmp(err.field, "setpoint_unit") == 0);
    vafm_ctrl *c = NULL;
    ENSURE(vafm_ctrl_new(&c, &p, &cp, NULL, &err) == VAFM_EINVAL && c == NULL);
}

/* A motor step longer than the piezo range skips the surface: the motor presses the tip in, past the force limit:
 * a crash, reported with the force reached; engage is refused until a withdraw. */
static void test_crash(void)
{
    vafm_params p;
    s_scene(&p);
    vafm_ctrl_params cp;
    vafm_ctrl_params_default(&cp);
    cp.motor_z0_m = 50e-6;
    cp.motor_step_m = 30e-6; /* 50 -> 20 (the sweep reaches 10 µm) -> -10 µm: through the surface */
    cp.motor_min_m = -1e-3;
    vafm_ctrl *c = s_new(&p, &cp, NULL);
    ENSURE(vafm_ctrl_engage(c) == 0);
    vafm_ctrl_event ev;
    int r = s_until(c, VAFM_CTRL_EV_CRASH, 30.0, &ev, NULL, NULL);
    ENSURE(r == 2 && ev.type == VAFM_CTRL_EV_FAILED && ev.reason == VAFM_CTRL_FAIL_CRASH);
    ENSURE(vafm_ctrl_event_pop(c, &ev) == 1 && ev.type == VAFM_CTRL_EV_CRASH);
    vafm_ctrl_status st;
    vafm_ctrl_status_get(c, &st);
    fprintf(stderr, "  crash at t %.4f s: force %.4g N (limit %.3g N), motor %.4g m\n", ev.time_s, ev.value,
            cp.force_limit_N, st.motor_z_m);
    ENSURE(ev.value > cp.force_limit_N && ev.value < 1.2 * cp.force_limit_N);
    ENSURE(st.state == VAFM_CTRL_CRASHED && st.last_fail == VAFM_CTRL_FAIL_CRASH && !st.feedback);
    ENSURE(vafm_ctrl_engage(c) == VAFM_ESTATE);
    ENSURE(vafm_ctrl_advance(c, 20000, NULL, NULL) == 20000);
    vafm_ctrl_status_get(c, &st);
    ENSURE(st.crash_force_N >= ev.value && !st.in_contact); /* the motor backed off */
    ENSURE(vafm_ctrl_withdraw(c, 0) == 0);
    ENSURE(s_until(c, VAFM_CTRL_EV_WITHDRAWN, 5.0, &ev, NULL, NULL) == 1);
    ENSURE(vafm_ctrl_engage(c) == 0);
    vafm_ctrl_destroy(&c);
}

/* Engage failures: the timeout, and the motor's range. */
static void test_engage_fail(void)
{
    vafm_params p;
    s_scene(&p);
    vafm_ctrl_params cp;
    vafm_ctrl_params_default(&cp);
    cp.engage_timeout_s = 2.0;
    vafm_ctrl *c = s_new(&p, &cp, NULL);
    ENSURE(vafm_ctrl_engage(c) == 0);
    vafm_ctrl_event ev;
    ENSURE(s_until(c, VAFM_CTRL_EV_ENGAGED, 10.0, &ev, NULL, NULL) == 2);
    ENSURE(ev.type == VAFM_CTRL_EV_FAILED && ev.reason == VAFM_CTRL_FAIL_TIMEOUT);
    ENSURE(ev.time_s > 2.0 && ev.time_s < 2.0 + 2.0 / p.sample_rate_Hz);
    vafm_ctrl_status st;
    vafm_ctrl_status_get(c, &st);
    ENSURE(st.state == VAFM_CTRL_IDLE && st.last_fail == VAFM_CTRL_FAIL_TIMEOUT);
    vafm_ctrl_destroy(&c);

    vafm_ctrl_params_default(&cp);
    cp.motor_min_m = 150e-6; /* the sample lies below what the motor reaches */
    c = s_new(&p, &cp, NULL);
    ENSURE(vafm_ctrl_engage(c) == 0);
    ENSURE(s_until(c, VAFM_CTRL_EV_ENGAGED, 60.0, &ev, NULL, NULL) == 2);
    ENSURE(ev.type == VAFM_CTRL_EV_FAILED && ev.reason == VAFM_CTRL_FAIL_MOTOR_RANGE);
    ENSURE(ev.value >= cp.motor_min_m && ev.value - cp.motor_step_m < cp.motor_min_m);
    vafm_ctrl_destroy(&c);
}

/* Engage next to a dome, then follow it under feedback. */
typedef struct s_track {
    double ref;           /* support height above the surface when the move began */
    double max_err, max_surf;
    int on;
} s_track;

static void s_track_sink(void *user, const vafm_ctrl_samples *b)
{
    s_track *t = user;
    for (size_t i = 0; i < b->n; i++) {
        const double H = b->motor_z_m[i] - b->piezo_z_m[i];
        if (!t->on) {
            t->ref = H - b->surface_m[i];
            t->on = 1;
        }
        const double e = fabs(H - b->surface_m[i] - t->ref);
        t->max_err = fmax(t->max_err, e);
        t->max_surf = fmax(t->max_surf, b->surface_m[i]);
    }
}

static vafm_ctrl *s_engaged(vafm_params *p, vafm_ctrl_params *cp, const vafm_map_spec *map)
{
    vafm_ctrl *c = s_new(p, cp, map);
    ENSURE(vafm_ctrl_engage(c) == 0);
    vafm_ctrl_event ev;
    ENSURE(s_until(c, VAFM_CTRL_EV_ENGAGED, 100.0, &ev, NULL, NULL) == 1);
    ENSURE(vafm_ctrl_advance(c, 2000, NULL, NULL) == 2000); /* settle */
    return c;
}

/* Over a dome (0.5 µm high, 5 µm base radius, slope up to 0.2) under feedback, the piezo follows the topography;
 * an integral loop of time constant τ lags a surface rising at slope·v by slope·v·τ (k_c ≫ k), so the error of
 * the support's height above the surface grows with the speed: predicted ≤ 0.2·v·τ (0.4 nm at 2 µm/s, 4 nm at
 * 20 µm/s, τ = 1 ms), plus the thermal jitter (≈ 10 pm). */
static void test_move_dome(void)
{
    vafm_params p;
    s_scene(&p);
    vafm_map_spec map;
    vafm_map_spec_default(&map);
    map.pattern = VAFM_MAP_DOME;
    map.center_x_m = 10e-6;
    map.radius_m = 5e-6;
    map.height_m = 0.5e-6;
    vafm_ctrl_params cp;
    vafm_ctrl_params_default(&cp);
    cp.motor_z0_m = 30e-6;
    const double tau = 10.0 / p.sample_rate_Hz, slope = 5.0 / sqrt(25.25 * 25.25 - 25.0);
    double err_v[2];
    const double v[2] = { 2e-6, 20e-6 };
    for (int i = 0; i < 2; i++) {
        vafm_ctrl *c = s_engaged(&p, &cp, &map);
        vafm_error err;
        ENSURE(vafm_ctrl_move(c, 20e-6, 0.0, v[i], &err) == 0);
        s_track t;
        memset(&t, 0, sizeof t);
        vafm_ctrl_event ev;
        memset(&ev, 0, sizeof ev);
        ENSURE(s_until(c, VAFM_CTRL_EV_MOVED, 30.0, &ev, s_track_sink, &t) == 1);
        ENSURE_REL(ev.value, 20e-6, 1e-9);
        vafm_ctrl_status st;
        vafm_ctrl_status_get(c, &st);
        const double pred = slope * v[i] * tau;
        fprintf(stderr, "  move over a dome at %.0f µm/s: top %.4g m, max |error| %.3g m (slope·v·τ %.3g m), "
                "state %s\n", v[i] * 1e6, t.max_surf, t.max_err, pred, vafm_ctrl_state_name(st.state));
        ENSURE_REL(t.max_surf, 0.5e-6, 1e-3); /* the tip went over the top */
        ENSURE(st.state == VAFM_CTRL_ENGAGED && st.in_contact && !st.saturated);
        ENSURE(t.max_err < 1.5 * pred + 5e-11);
        err_v[i] = t.max_err;
        vafm_ctrl_destroy(&c);
    }
    ENSURE(err_v[1] > 5.0 * err_v[0]); /* the lag grows with the speed */
}

/* A dome taller than the piezo's remaining retraction: the feedback saturates at full retraction (reported), and
 * the tip is pressed on until the force limit (a crash). A move beyond the scanner's range is refused. */
static void test_saturation(void)
{
    vafm_params p;
    s_scene(&p);
    vafm_map_spec map;
    vafm_map_spec_default(&map);
    map.pattern = VAFM_MAP_DOME;
    map.center_x_m = 30e-6;
    map.radius_m = 20e-6;
    map.height_m = 8e-6;
    vafm_ctrl_params cp;
    vafm_ctrl_params_default(&cp);
    cp.motor_z0_m = 30e-6;
    vafm_ctrl *c = s_engaged(&p, &cp, &map);
    vafm_ctrl_status st;
    vafm_ctrl_status_get(c, &st);
    const double z0 = st.piezo_z_m;
    vafm_error err;
    ENSURE(vafm_ctrl_move(c, 1e-3, 0.0, 0.0, &err) == VAFM_EINVAL && strcmp(err.field, "x_m") == 0);
    vafm_ctrl_event ev;
    ENSURE(vafm_ctrl_event_pop(c, &ev) == 1 && ev.type == VAFM_CTRL_EV_XY_RANGE && ev.value == 1e-3);
    ENSURE(vafm_ctrl_move(c, 30e-6, 0.0, 5e-6, &err) == 0);
    ENSURE(s_until(c, VAFM_CTRL_EV_Z_SATURATED, 10.0, &ev, NULL, NULL) == 1);
    vafm_ctrl_status_get(c, &st);
    fprintf(stderr, "  saturated at x = %.4g m (surface %.4g m, piezo was at %.4g m)\n", st.x_m, st.surface_m, z0);
    ENSURE(ev.value == 0.0 && st.saturated && st.piezo_z_m == 0.0);
    ENSURE_REL(st.surface_m, z0, 0.01); /* the piezo ran out when the surface had risen by its extension */
    ENSURE(s_until(c, VAFM_CTRL_EV_CRASH, 10.0, &ev, NULL, NULL) == 1);
    ENSURE(ev.value > cp.force_limit_N);
    vafm_ctrl_destroy(&c);
}

/* A scripted session (the same commands at the same sample indices) is the same bit for bit; another seed
 * differs. */
static uint64_t s_fnv(uint64_t h, const void *d, size_t n)
{
    const unsigned char *b = d;
    for (size_t i = 0; i < n; i++)
        h = (h ^ b[i]) * 1099511628211ULL;
    return h;
}

static void s_hash_sink(void *user, const vafm_ctrl_samples *b)
{
    uint64_t *h = user;
    *h = s_fnv(*h, b->force_N, b->n * sizeof(double));
    *h = s_fnv(*h, b->piezo_z_m, b->n * sizeof(double));
    *h = s_fnv(*h, b->motor_z_m, b->n * sizeof(double));
    *h = s_fnv(*h, b->state, b->n);
}

/* The scripted sessions' set-up: the scene with this seed over a disc 50 nm high, the motor at 25 µm. */
static vafm_ctrl *s_disc_session(vafm_params *p, vafm_map_spec *map, vafm_ctrl_params *cp, uint64_t seed)
{
    s_scene(p);
    p->seed = seed;
    vafm_map_spec_default(map);
    map->pattern = VAFM_MAP_DISC;
    map->center_x_m = 5e-6;
    map->radius_m = 2e-6;
    map->height_m = 50e-9;
    vafm_ctrl_params_default(cp);
    cp->motor_z0_m = 25e-6;
    return s_new(p, cp, map);
}

static uint64_t s_session(uint64_t seed)
{
    vafm_params p;
    vafm_map_spec map;
    vafm_ctrl_params cp;
    vafm_ctrl *c = s_disc_session(&p, &map, &cp, seed);
    uint64_t h = 1469598103934665603ULL;
    vafm_error err;
    vafm_ctrl_advance(c, 1000, s_hash_sink, &h);
    ENSURE(vafm_ctrl_engage(c) == 0);
    vafm_ctrl_advance(c, 40000, s_hash_sink, &h);
    vafm_ctrl_status st;
    vafm_ctrl_status_get(c, &st);
    ENSURE(st.state == VAFM_CTRL_ENGAGED);
    ENSURE(vafm_ctrl_move(c, 7e-6, 0.0, 10e-6, &err) == 0);
    vafm_ctrl_advance(c, 10000, s_hash_sink, &h);
    ENSURE(vafm_ctrl_feedback_set(c, 4e-9, VAFM_CTRL_UNIT_N, 1, NAN, NAN, NAN, &err) == 0);
    vafm_ctrl_advance(c, 5000, s_hash_sink, &h);
    ENSURE(vafm_ctrl_withdraw(c, 1) == 0);
    vafm_ctrl_advance(c, 5000, s_hash_sink, &h);
    vafm_ctrl_status_get(c, &st);
    ENSURE(st.state == VAFM_CTRL_WITHDRAWN);
    ENSURE(vafm_ctrl_z(c, 1e-6, &err) == 0);
    vafm_ctrl_advance(c, 2000, s_hash_sink, &h);
    vafm_ctrl_event ev;
    while (vafm_ctrl_event_pop(c, &ev)) {
        h = s_fnv(h, &ev.type, sizeof ev.type);
        h = s_fnv(h, &ev.sample, sizeof ev.sample);
        h = s_fnv(h, &ev.value, sizeof ev.value);
    }
    vafm_ctrl_destroy(&c);
    return h;
}

/* The seed-7 session pinned (as test_determinism pins a curve; the build has -ffp-contract=off), so that a
 * change to the controller's commands or loop that moves any sample or event shows: taken 2026-11-27 from the
 * session before and after the commands' piezo moves became one helper (the same hash). Re-pin only if the
 * controller's numerics change on purpose. */
#define S_SESSION_HASH UINT64_C(0xdb6f008b1e874d9f)

static void test_reproducible(void)
{
    const uint64_t a = s_session(7), b = s_session(7), d = s_session(8);
    fprintf(stderr, "  session hashes: seed 7 %016llx %016llx, seed 8 %016llx\n", (unsigned long long)a,
            (unsigned long long)b, (unsigned long long)d);
    ENSURE(a == b);
    ENSURE(a != d);
    ENSURE_MSG(a == S_SESSION_HASH, "hash 0x%016llx != pinned 0x%016llx", (unsigned long long)a,
               (unsigned long long)S_SESSION_HASH);
}

/* ---- carry: the state goes on in a controller built over new settings (issue #27) ---------------- */

/* The carry tests' start: the scene over a flat surface, the motor at 30 µm, engaged and settled. */
static vafm_ctrl *s_engaged_flat(vafm_params *p, vafm_ctrl_params *cp)
{
    s_scene(p);
    vafm_ctrl_params_default(cp);
    cp->motor_z0_m = 30e-6;
    return s_engaged(p, cp, NULL);
}

static vafm_ctrl *s_carried(vafm_ctrl *old, vafm_params *p, vafm_ctrl_params *cp, const vafm_map_spec *map)
{
    vafm_ctrl *c = s_new(p, cp, map);
    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = vafm_ctrl_carry(c, old, &err);
    ENSURE_MSG(r == 0, "vafm_ctrl_carry: %d %s", r, err.message);
    return c;
}

typedef struct s_carry_rec {
    s_blk f;
    long not_engaged;
} s_carry_rec;

static void s_carry_sink(void *user, const vafm_ctrl_samples *b)
{
    s_carry_rec *r = user;
    for (size_t i = 0; i < b->n; i++) {
        r->not_engaged += b->state[i] != VAFM_CTRL_ENGAGED;
        s_blk_push(&r->f, b->force_N[i]);
    }
}

/* Advance a carried controller by n samples: the mean force with its standard error (S_NB blocks) in m and se.
 * @return the samples not in the engaged state. */
static long s_carry_run(vafm_ctrl *c, long n, double *m, double *se)
{
    s_carry_rec rec;
    memset(&rec, 0, sizeof rec);
    s_blk_init(&rec.f, n);
    ENSURE(vafm_ctrl_advance(c, (size_t)n, s_carry_sink, &rec) == n);
    s_blk_stat(&rec.f, 0, m, se);
    return rec.not_engaged;
}

/* Engaged at 10 kHz and 298 K, carried into a controller over 20 kHz and 350 K: still engaged at once, the motor
 * and piezo where they were, the clock going on (time continues, the new interval from there), and the feedback
 * holds the setpoint: over N = 100 000 samples (5 s; S_NB blocks of 2000, far beyond the correlation time) the
 * mean force is the setpoint within 5 standard errors, and no sample leaves the engaged state. */
static void test_carry_engaged(void)
{
    vafm_params p;
    vafm_ctrl_params cp;
    vafm_ctrl *old = s_engaged_flat(&p, &cp);
    vafm_ctrl_status a, b;
    vafm_ctrl_status_get(old, &a);
    ENSURE(a.state == VAFM_CTRL_ENGAGED && a.feedback && a.in_contact);
    vafm_params p2 = p;
    p2.sample_rate_Hz = 2.0 * p.sample_rate_Hz;
    p2.T_K = 350.0;
    vafm_ctrl *c = s_carried(old, &p2, &cp, NULL);
    vafm_ctrl_destroy(&old);
    vafm_ctrl_status_get(c, &b);
    ENSURE(b.state == VAFM_CTRL_ENGAGED && b.feedback && b.in_contact);
    ENSURE(b.motor_z_m == a.motor_z_m && b.piezo_z_m == a.piezo_z_m && b.x_m == a.x_m && b.y_m == a.y_m);
    ENSURE(b.setpoint_N == a.setpoint_N && b.baseline_N == a.baseline_N && b.motor_steps == a.motor_steps);
    ENSURE(b.sample == a.sample && b.time_s == a.time_s);
    ENSURE(b.clock_base_s == a.time_s && b.clock_base_sample == a.sample);
    vafm_ctrl_event ev;
    ENSURE(vafm_ctrl_event_pop(c, &ev) == 0); /* nothing to report */
    const long N = 100000;
    double m, se;
    const long not_engaged = s_carry_run(c, N, &m, &se);
    vafm_ctrl_status_get(c, &b);
    fprintf(stderr, "  carried into 20 kHz, 350 K: <F> %.6g ± %.2g N (setpoint %.6g N), piezo %.6g -> %.6g m, "
            "t %.6f -> %.6f s, %ld samples not engaged\n", m, se, b.setpoint_N, a.piezo_z_m, b.piezo_z_m, a.time_s,
            b.time_s, not_engaged);
    ENSURE(not_engaged == 0 && b.state == VAFM_CTRL_ENGAGED);
    ENSURE(fabs(m - b.setpoint_N) < 5.0 * se);
    ENSURE(b.sample == a.sample + (uint64_t)N);
    ENSURE_REL(b.time_s, a.time_s + (double)N / p2.sample_rate_Hz, 1e-12);
    while (vafm_ctrl_event_pop(c, &ev))
        ENSURE_MSG(ev.type != VAFM_CTRL_EV_FAILED && ev.type != VAFM_CTRL_EV_CRASH &&
                   ev.type != VAFM_CTRL_EV_LOST_CONTACT && ev.type != VAFM_CTRL_EV_Z_SATURATED,
                   "event %s after the carry", vafm_ctrl_event_name(ev.type));
    ENSURE(vafm_ctrl_carry(c, c, NULL) == VAFM_EINVAL);
    vafm_ctrl *d = s_new(&p, &cp, NULL);
    ENSURE(vafm_ctrl_carry(c, d, NULL) == VAFM_ESTATE); /* c has run: carry only into a fresh controller */
    vafm_ctrl_destroy(&d);
    vafm_ctrl_destroy(&c);
}

/* Settings that make the state impossible clamp it and say so: a piezo range below the engaged extension (the piezo
 * at the new range, the feedback saturated, a z_saturated event), an XY range that no longer holds the tip (at the
 * edge, an xy_range event with the coordinate it had), a surface far above the tip (a crash). */
static void test_carry_clamp(void)
{
    vafm_params p;
    vafm_ctrl_params cp;
    vafm_ctrl *old = s_engaged_flat(&p, &cp);
    vafm_error err;
    ENSURE(vafm_ctrl_move(old, 30e-6, -10e-6, 1e-2, &err) == 0);
    vafm_ctrl_event ev;
    ENSURE(s_until(old, VAFM_CTRL_EV_MOVED, 1.0, &ev, NULL, NULL) == 1);
    vafm_ctrl_status a, b;
    vafm_ctrl_status_get(old, &a);
    ENSURE(a.state == VAFM_CTRL_ENGAGED && a.piezo_z_m > 0 && a.x_m == 30e-6);
    vafm_ctrl_params cp2 = cp;
    cp2.piezo_range_m = 0.5 * a.piezo_z_m;
    cp2.xy_range_m = 40e-6;
    vafm_ctrl *c = s_carried(old, &p, &cp2, NULL);
    vafm_ctrl_status_get(c, &b);
    fprintf(stderr, "  clamp: piezo %.4g -> %.4g m, x %.4g -> %.4g m, state %s\n", a.piezo_z_m, b.piezo_z_m, a.x_m,
            b.x_m, vafm_ctrl_state_name(b.state));
    ENSURE(b.piezo_z_m == cp2.piezo_range_m && b.saturated && b.feedback);
    ENSURE(b.x_m == 20e-6 && b.y_m == -10e-6);
    int sat = 0, xy = 0;
    while (vafm_ctrl_event_pop(c, &ev)) {
        if (ev.type == VAFM_CTRL_EV_Z_SATURATED && ev.value == cp2.piezo_range_m)
            sat++;
        if (ev.type == VAFM_CTRL_EV_XY_RANGE && ev.value == 30e-6)
            xy++;
    }
    ENSURE(sat == 1 && xy == 1);
    vafm_ctrl_destroy(&c);
    /* a dome 5 µm high under the tip: the support would be ~5 µm below the new surface, far past the force limit */
    vafm_map_spec map;
    vafm_map_spec_default(&map);
    map.pattern = VAFM_MAP_DOME;
    map.center_x_m = 30e-6;
    map.center_y_m = -10e-6;
    map.radius_m = 10e-6;
    map.height_m = 5e-6;
    c = s_carried(old, &p, &cp, &map);
    vafm_ctrl_status_get(c, &b);
    int crash = 0;
    while (vafm_ctrl_event_pop(c, &ev))
        if (ev.type == VAFM_CTRL_EV_CRASH && ev.value > cp.force_limit_N)
            crash++;
    fprintf(stderr, "  a surface above the tip: gap %.4g m, state %s, crash force %.4g N\n", b.gap_m,
            vafm_ctrl_state_name(b.state), b.crash_force_N);
    ENSURE(crash == 1 && b.state == VAFM_CTRL_CRASHED && !b.feedback && b.crash_force_N > cp.force_limit_N);
    ENSURE(vafm_ctrl_advance(c, 1000, NULL, NULL) == 1000); /* the simulation copes: the piezo retracts */
    vafm_ctrl_destroy(&c);
    vafm_ctrl_destroy(&old);
}

/* sample by sample (however the advances split the blocks) */
static void s_hash_time_sink(void *user, const vafm_ctrl_samples *b)
{
    uint64_t *h = user;
    for (size_t i = 0; i < b->n; i++) {
        const double v[6] = { b->time_s[i], b->force_N[i], b->piezo_z_m[i], b->motor_z_m[i], b->x_m[i],
                              b->gap_m[i] };
        *h = s_fnv(*h, v, sizeof v);
        *h = s_fnv(*h, &b->state[i], 1);
    }
}

/* advance by n samples, carrying the state into a controller over a scene changed in curve-only values (start
 * height, dwell) and a ctrl setting that does not act here (the engage timeout, raised) when sample `at` comes */
static void s_advance_carry(vafm_ctrl **c, long n, uint64_t at, vafm_params *p, vafm_ctrl_params *cp,
                            const vafm_map_spec *map, uint64_t *h)
{
    vafm_ctrl_status st;
    vafm_ctrl_status_get(*c, &st);
    if (at > st.sample && at < st.sample + (uint64_t)n) {
        const long first = (long)(at - st.sample);
        ENSURE(vafm_ctrl_advance(*c, (size_t)first, s_hash_time_sink, h) == first);
        n -= first;
        vafm_params p2 = *p;
        p2.dwell_s = 0.5;
        p2.start_height_m = 2.0 * p->start_height_m;
        vafm_ctrl_params cp2 = *cp;
        cp2.engage_timeout_s = 500.0;
        vafm_ctrl *d = s_carried(*c, &p2, &cp2, map);
        vafm_ctrl_destroy(c);
        *c = d;
    }
    ENSURE(vafm_ctrl_advance(*c, (size_t)n, s_hash_time_sink, h) == n);
}

/* s_session's script with a carry at sample `at` (0: none) */
static uint64_t s_session_carry(uint64_t at)
{
    vafm_params p;
    vafm_map_spec map;
    vafm_ctrl_params cp;
    vafm_ctrl *c = s_disc_session(&p, &map, &cp, 7);
    uint64_t h = 1469598103934665603ULL;
    vafm_error err;
    s_advance_carry(&c, 1000, at, &p, &cp, &map, &h);
    ENSURE(vafm_ctrl_engage(c) == 0);
    s_advance_carry(&c, 40000, at, &p, &cp, &map, &h);
    ENSURE(vafm_ctrl_move(c, 7e-6, 0.0, 10e-6, &err) == 0);
    s_advance_carry(&c, 10000, at, &p, &cp, &map, &h);
    ENSURE(vafm_ctrl_withdraw(c, 1) == 0);
    s_advance_carry(&c, 5000, at, &p, &cp, &map, &h);
    vafm_ctrl_event ev;
    while (vafm_ctrl_event_pop(c, &ev)) {
        h = s_fnv(h, &ev.type, sizeof ev.type);
        h = s_fnv(h, &ev.sample, sizeof ev.sample);
        h = s_fnv(h, &ev.time_s, sizeof ev.time_s);
        h = s_fnv(h, &ev.value, sizeof ev.value);
    }
    vafm_ctrl_status st;
    vafm_ctrl_status_get(c, &st);
    ENSURE(st.state == VAFM_CTRL_WITHDRAWN);
    vafm_ctrl_destroy(&c);
    return h;
}

/* A change the lever does not feel (curve-only scene values, a ctrl setting not acting) changes nothing: the
 * session with a carry during the approach, while engaged or during the withdraw is the same bit for bit (every
 * sample's force, piezo, motor, state and time, every event) as without one. */
static void test_carry_bit_for_bit(void)
{
    const uint64_t none = s_session_carry(0);
    const uint64_t at[3] = { 5000, 30123, 55555 };
    for (int i = 0; i < 3; i++) {
        const uint64_t h = s_session_carry(at[i]);
        fprintf(stderr, "  session hash: no carry %016llx, carried at sample %llu %016llx\n",
                (unsigned long long)none, (unsigned long long)at[i], (unsigned long long)h);
        ENSURE(h == none);
    }
}

/* The contact branch carries: held by the feedback at a tensile force (−1 nN, within JKR's pull-off on silica),
 * the support is above the surface and the tip sticks; carried into 300 K (the lever restarts at equilibrium
 * there) it starts on the contact branch and stays in contact, engaged, with no lost_contact — a free start at
 * that height would have the tip off the surface. */
static void test_carry_adhesive_contact(void)
{
    vafm_params p;
    vafm_ctrl_params cp;
    vafm_ctrl *old = s_engaged_flat(&p, &cp);
    vafm_error err;
    ENSURE(vafm_ctrl_feedback_set(old, -1e-9, VAFM_CTRL_UNIT_N, 0, NAN, NAN, NAN, &err) == 0);
    ENSURE(vafm_ctrl_advance(old, 20000, NULL, NULL) == 20000);
    vafm_ctrl_status a, b;
    vafm_ctrl_status_get(old, &a);
    vafm_ctrl_event ev;
    while (vafm_ctrl_event_pop(old, &ev))
        ENSURE_MSG(ev.type != VAFM_CTRL_EV_LOST_CONTACT, "lost contact before the carry");
    fprintf(stderr, "  adhesive hold: gap %.4g m, force %.4g N, in contact %d\n", a.gap_m, a.force_N, a.in_contact);
    ENSURE(a.state == VAFM_CTRL_ENGAGED && a.in_contact && a.gap_m > 0);
    vafm_params p2 = p;
    p2.T_K = 300.0;
    vafm_ctrl_params cp2 = *vafm_ctrl_params_get(old); /* the settings in force: the tensile setpoint */
    vafm_ctrl *c = s_carried(old, &p2, &cp2, NULL);
    vafm_ctrl_destroy(&old);
    double m, se;
    const long not_engaged = s_carry_run(c, 20000, &m, &se);
    vafm_ctrl_status_get(c, &b);
    int lost = 0;
    while (vafm_ctrl_event_pop(c, &ev))
        lost += ev.type == VAFM_CTRL_EV_LOST_CONTACT;
    fprintf(stderr, "  carried into 300 K: in contact %d, lost_contact events %d, <F> %.4g ± %.2g N\n", b.in_contact,
            lost, m, se);
    ENSURE(lost == 0 && b.in_contact && b.state == VAFM_CTRL_ENGAGED && not_engaged == 0);
    ENSURE(fabs(m - b.setpoint_N) < 5.0 * se);
    vafm_ctrl_destroy(&c);
}

int main(void)
{
    RUN_TEST(test_params);
    RUN_TEST(test_live_free);
    RUN_TEST(test_engage);
    RUN_TEST(test_engage_fail);
    RUN_TEST(test_crash);
    RUN_TEST(test_move_dome);
    RUN_TEST(test_saturation);
    RUN_TEST(test_reproducible);
    RUN_TEST(test_carry_engaged);
    RUN_TEST(test_carry_clamp);
    RUN_TEST(test_carry_bit_for_bit);
    RUN_TEST(test_carry_adhesive_contact);
    return harness_done();
}
