/* SPDX-License-Identifier: MIT */
/*
 * The simulation object and its scenes (force curve, thermal tune) as resumable state machines.
 *
 * A scene advances one output sample at a time. Within a sample interval the body moves by one of:
 * - exact free-cantilever steps (out of contact and provably far from the surface: the surface is more
 *   than the deterministic excursion bound plus 8 thermal standard deviations away for the whole
 *   interval);
 * - one exact step of the linearised contact well (well_exact.h: in contact, far from the pull-off
 *   instability, with the thermal spread and the current excursion small against the distance to the
 *   branch's soft point, so the force is linear over the body's whole range);
 * - the scene's integrator at the step dt (a whole fraction of the interval) everywhere else. Contact
 * events end an integrator run early and are recorded here. Phase changes (trigger, dwell, end)
 * happen at sample boundaries, as an instrument that acts on its filtered output would.
 *
 * Files: this one holds the object, the curve's and the tune's phases, the live scene's boundary and the one
 * sample loop; sim_segments.c the segment lists' boundaries and decimation (vafm/segments.h); sim_well.c the
 * exact contact-well step; sim_impl.h the state they share.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "vafm/detector.h"
#include "vafm/integrator.h"
#include "vafm/segments.h"
#include "vafm/sim.h"
#include "vafm/theory.h"
#include "core/batch.h"
#include "core/internal.h"
#include "core/guard.h"
#include "core/kernel.h"
#include "core/piezo.h"
#include "core/well_exact.h"

#include "core/sim_impl.h"


int vafm_sim_estimate_cost(const vafm_params *p, vafm_sim_estimate *out, vafm_error *err)
{
    if (!p || !out) {
        vafm_err_set(err, VAFM_EINVAL, "", "vafm_sim_estimate_cost: no scene or output given");
        return VAFM_EINVAL;
    }
    memset(out, 0, sizeof *out);
    vafm_numerics nm;
    memset(&nm, 0, sizeof nm);
    int rc = vafm_numerics_check(p, &nm, NULL); /* derives the numerics even when a limit is exceeded */
    if (rc != VAFM_EUNSTABLE && isfinite(nm.dt) && nm.dt > 0)
        vafm_numerics_estimate(p, &nm, out);
    return vafm_params_validate(p, err);
}

static int s_sim_new(vafm_sim **out, const vafm_params *p, int tune_only, vafm_error *err)
{
    if (!out) {
        vafm_err_set(err, VAFM_EINVAL, "", "vafm_sim_new: out is NULL");
        return VAFM_EINVAL;
    }
    *out = NULL;
    int r = vafm_params_validate_scene(p, tune_only, err);
    if (r)
        return r;
    vafm_sim *s = calloc(1, sizeof *s);
    if (!s)
        return VAFM_ENOMEM;
    s->p = *p;
    s->tune_only = tune_only;
    vafm_numerics_check_scene(p, &s->nm, tune_only, NULL);
    s->it = p->integrator;
    void *buf = malloc(S_BLOCK * (6 * sizeof(double) + 1));
    if (!buf) {
        free(s);
        return VAFM_ENOMEM;
    }
    s->bt = buf;
    s->bh = s->bt + S_BLOCK;
    s->bd = s->bh + S_BLOCK;
    s->bf = s->bd + S_BLOCK;
    s->btip = s->bf + S_BLOCK;
    s->bha = s->btip + S_BLOCK;
    s->bseg = (uint8_t *)(s->bha + S_BLOCK);

    vafm_kernel *K = &s->K;
    const vafm_reduced *rd = &s->nm.r;
    K->m = rd->m;
    K->k = rd->k;
    K->kT = rd->kT;
    K->eta_c = rd->eta_cont;
    K->contact = s->nm.contact;
    K->cforce = K->contact.type->force;
    K->is_jkr = (K->contact.type->flags & VAFM_CONTACT_JKR_BRANCH) != 0;
    K->jtab = NULL;
    if (p->contact_table && K->is_jkr && K->contact.gamma > 0) {
        int rt = vafm_jkr_table_init(&s->jtab, &K->contact, s->nm.u_deep);
        if (rt == VAFM_ENOMEM) {
            free(buf);
            free(s);
            return VAFM_ENOMEM;
        }
        if (rt == 0)
            K->jtab = &s->jtab;
    }
    K->thermal = rd->kT > 0;
    K->uniform_noise = p->noise == VAFM_NOISE_UNIFORM;
    vafm_kernel_set_dt(K, s->nm.dt);

    const double Ts = s->nm.Ts;
    double h_target = s->it->overdamped ? 0.25 * s->K.co[0].zeta / rd->k : 0.25 / fmax(1.0, sqrt(rd->k / rd->m));
    long nf = (long)ceil(Ts / h_target);
    if (nf > s->nm.n_sub)
        nf = s->nm.n_sub;
    s->n_free = nf < 1 ? 1 : nf;
    vafm_free_ou_setup(&s->ou, K, Ts / (double)s->n_free, s->it->overdamped);
    vafm_free_ou_setup(&s->ou_live, K, Ts, s->it->overdamped);
    if (p->antialias == VAFM_ANTIALIAS_MEAN) {
        vafm_free_ou_integrate(&s->ou, K);
        vafm_free_ou_integrate(&s->ou_live, K);
    }
    s->sigma_free = sqrt(rd->kT / rd->k);
    s->adaptive = s->nm.n_sub_far != s->nm.n_sub;
    /* The exact well step costs about as much as a few integrator steps: it is used only where an output
     * sample spans more steps than that. */
    s->well_ok = p->well_exact && !s->it->overdamped && (K->contact.type->flags & VAFM_CONTACT_WELL) &&
                 s->nm.n_sub >= S_WELL_MIN_STEPS;
    *out = s;
    return 0;
}

int vafm_sim_new(vafm_sim **out, const vafm_params *p, vafm_error *err)
{
    return s_sim_new(out, p, 0, err);
}

int vafm_sim_new_tune(vafm_sim **out, const vafm_params *p, vafm_error *err)
{
    if (!p) {
        vafm_err_set(err, VAFM_EINVAL, "", "no parameters given");
        return VAFM_EINVAL;
    }
    /* the tune's rate: a force curve at that rate would often exceed a curve's limits, and is never run */
    vafm_params q;
    vafm_params_tune_scene(p, &q);
    return s_sim_new(out, &q, 1, err);
}

void vafm_sim_destroy(vafm_sim **s)
{
    if (!s || !*s)
        return;
    free((*s)->bt);
    vafm_jkr_table_free(&(*s)->jtab);
    free(*s);
    *s = NULL;
}

const vafm_params *vafm_sim_params(const vafm_sim *s)
{
    return &s->p;
}

double vafm_sim_dt(const vafm_sim *s)
{
    return vafm_scale_time_si(&s->nm.sc, s->nm.dt);
}

/* ---- scene start ------------------------------------------------------------------------------ */

/* Equilibrium of the body on the contact branch for a support at uspr ≥ 0 (Hertz or JKR). */
static double s_contact_equilibrium(const vafm_sim *s, double uspr, double *K_loc)
{
    const vafm_kernel *K = &s->K;
    double lo = fmin(K->contact.u_detach, 0.0), hi = uspr;
    double ueq = uspr, F_eq;
    if ((K->contact.type->flags & VAFM_CONTACT_JKR_BRANCH) && K->contact.gamma > 0 &&
        vafm_theory_equilibrium(K->contact.gamma, K->k, uspr, &ueq, &F_eq) == 0) {
        /* done */
    } else {
        for (int i = 0; i < 200 && hi - lo > 1e-15 * fmax(1.0, fabs(hi)); i++) {
            double mid = 0.5 * (lo + hi), sq = 0.0;
            double g = K->k * (uspr - mid) - K->cforce(&K->contact, mid, &sq, NULL);
            if (g > 0)
                lo = mid;
            else
                hi = mid;
        }
        ueq = 0.5 * (lo + hi);
    }
    double sq = 0.0, dF = 0.0;
    K->cforce(&K->contact, ueq, &sq, &dF);
    *K_loc = K->k + dF;
    return ueq;
}

/* The support position at which the quasi-static tip reaches the trigger (ramp_start = trigger): the height
 * trigger's own, or, for the force trigger, u + F_set/k where the contact branch carries F_set. On the JKR
 * branch F(u) falls from u_detach to the force-controlled pull-off and rises after it, so a positive F_set
 * is met once: a bisection on [u_detach, u_hi] with F(u_detach) < F_set ≤ F(u_hi) finds it. */
static double s_trigger_point(const vafm_sim *s)
{
    const vafm_kernel *K = &s->K;
    if (s->p.trigger == VAFM_TRIGGER_HEIGHT)
        return s->uspr_trigger;
    double sq = 0.0, lo = fmin(K->contact.u_detach, 0.0), hi = fmax(1.0, fabs(lo));
    for (int i = 0; i < 200 && K->cforce(&K->contact, hi, &sq, NULL) < s->F_set; i++)
        hi *= 2.0;
    for (int i = 0; i < 200 && hi - lo > 1e-14 * fmax(1.0, fabs(hi)); i++) {
        double mid = 0.5 * (lo + hi);
        sq = 0.0;
        if (K->cforce(&K->contact, mid, &sq, NULL) < s->F_set)
            lo = mid;
        else
            hi = mid;
    }
    return hi + s->F_set / K->k;
}

/* A height above the contact point at time t_s as the curve reports it: above the reference plane (the curve's
 * contact point, surface_height_m plus its random part, and the sample's drift since t = 0; nothing is added on
 * a flat, still sample, so those curves stay bit for bit what they were, -0.0 included). */
static inline double s_height(const vafm_sim *s, double above_contact_m, double t_s)
{
    if (s->drift_m_per_s != 0.0)
        return above_contact_m + s->surf0_m + s->drift_m_per_s * t_s;
    return s->surf0_m != 0.0 ? above_contact_m + s->surf0_m : above_contact_m;
}

/* The piezo's next sample interval: the command goes on at v_cmd, the actuator (hysteresis, creep) decides
 * where the support gets to by the interval's end, and the support moves there at a constant speed (the
 * surface's drift added). Called at every sample boundary while the piezo model is on. */
static void s_piezo_next(vafm_sim *s)
{
    vafm_kernel *K = &s->K;
    const vafm_scale *sc = &s->nm.sc;
    const double Ts = s->nm.Ts;
    s->ucmd_now = s->ucmd_next;
    s->ucmd_next = s->ucmd_now + s->v_cmd * Ts;
    double ea = vafm_piezo_step(&s->pz, vafm_scale_length_si(sc, s->ucmd_next), vafm_scale_time_si(sc, Ts));
    double target = vafm_scale_length_red(sc, ea) + s->v_drift * (K->t + Ts);
    s_kernel_phase(K, (target - K->u_spr) / Ts);
    s->need_prepare = 1;
}

static void s_begin(vafm_sim *s, uint64_t index, int scene)
{
    vafm_kernel *K = &s->K;
    const vafm_reduced *rd = &s->nm.r;
    s_kernel_rng_init(K, scene == S_SCENE_LIVE ? s->p.seed ^ VAFM_SIM_LIVE_KEY : s->p.seed, index);
    s->scene = scene;
    s->index = index;
    memset(&s->err, 0, sizeof s->err);
    s->sample_index = 0;
    s->scene_samples = 0;
    s->clock_samples = 0;
    s->nblk = 0;
    s->flags = 0;
    s->touched = 0;
    s->detached_in_retract = 0;
    s->retract_samples = 0;
    s->sample_min_force = INFINITY;
    s->fs_min_retract = INFINITY;
    s->touch_t = NAN;
    s->touch_uspr = NAN;
    s->uspr_detach = s->fs_detach = s->t_detach = NAN;
    s->t_retract0 = NAN;
    s->mode_free = 0;
    s->mode_well = 0;
    s->weq.ok = 0; /* a curve never starts from another curve's warm start: (seed, index) alone decides it */
    s->sub_left = 0;
    s->batch_back = 0;
    s->need_prepare = 1;

    const vafm_scale *sc = &s->nm.sc;
    /* the sample's artefacts: where its surface is for this curve, and how fast it rises (a tune has neither) */
    s->surf0_m = scene == S_SCENE_CURVE  ? vafm_artefact_contact_point(&s->p, index)
                 : scene == S_SCENE_LIVE ? 0.0 /* the commander owns the geometry */
                                         : s->p.surface_height_m;
    s->drift_m_per_s = scene == S_SCENE_CURVE ? s->p.sample_drift_m_per_s : 0.0;
    s->v_drift = vafm_scale_speed_red(sc, s->drift_m_per_s);
    s->uspr_start = vafm_scale_length_red(sc, -(scene == S_SCENE_LIVE ? s->live_h0_m : s->p.start_height_m));
    s->F_set = vafm_scale_force_red(sc, s->p.setpoint_N);
    s->uspr_trigger = vafm_scale_length_red(sc, -s->p.trigger_height_m);
    s->margin = vafm_scale_length_red(sc, s->p.retract_margin_m);
    double zr = s->p.z_range_m > 0 ? vafm_scale_length_red(sc, s->p.z_range_m)
                                   : fmax(0.0, -s->uspr_start) + 2.0 * s->F_set / rd->k + 20.0 * s->sigma_free + 1.0;
    if (s->p.ramp_size_m > 0) {
        /* a fixed ramp: from the start height down by at most the ramp size (from the trigger point's ramp
         * size above it, up to twice that: the thermal tip meets the setpoint earlier or later) */
        zr = vafm_scale_length_red(sc, s->p.ramp_size_m);
        if (scene == S_SCENE_CURVE && s->p.ramp_start == VAFM_RAMP_START_TRIGGER) {
            s->uspr_start = s_trigger_point(s) - zr;
            zr *= 2.0;
        }
    }
    s->uspr_zlimit = s->uspr_start + zr;
    s->base_sum = 0.0;
    s->base_n = 0;
    s->F_hold = s->F_set;
    double tau = s->p.dwell_feedback_s > 0 ? s->p.dwell_feedback_s : 10.0 / s->p.sample_rate_Hz;
    s->fb_gain = 1.0 / vafm_scale_time_red(sc, rd->k * tau); /* (k̃·τ)/T, the gain's order of operations */

    K->t = 0.0;
    K->u_spr = s->uspr_start;
    /* the support's speed in the first phase (the body's initial velocity is drawn about it): the approach's,
     * or the first segment's of a list */
    double v0 = scene != S_SCENE_CURVE ? 0.0 : !s->list ? rd->v_approach
                : s->seg[0].kind == VAFM_SEGMENT_EXTEND  ? vafm_scale_speed_red(sc, s->seg[0].speed_m_per_s)
                : s->seg[0].kind == VAFM_SEGMENT_RETRACT ? -vafm_scale_speed_red(sc, s->seg[0].speed_m_per_s)
                                                         : 0.0;
    s->pz.on = 0;
    if (scene == S_SCENE_CURVE && vafm_piezo_on(&s->p))
        vafm_piezo_begin(&s->pz, &s->p, vafm_scale_length_si(sc, s->uspr_start));
    s->ucmd_now = s->ucmd_next = s->uspr_start;
    s_set_speed(s, v0);
    vafm_kernel_set_dt(K, s->nm.dt);
    s->dt_cur = s->nm.dt;
    K->event = 0;
    K->steps = K->steps_contact = K->steps_free = 0;
    K->fs_min = INFINITY;
    K->in_contact = 0;
    K->s = 0.0;
    const int has_contact = (K->contact.type->flags & VAFM_CONTACT_SURFACE) != 0;
    /* Start in contact at equilibrium (pressed in, or start_in_contact), else free at the support; a
     * thermal draw of position then velocity either way. */
    const int start_pressed = has_contact && (s->uspr_start >= K->contact.u_touch ||
                                              (scene != S_SCENE_LIVE ? s->p.start_in_contact : s->live_contact));
    double sigma_u = s->sigma_free;
    if (start_pressed) {
        double K_loc;
        K->u = s_contact_equilibrium(s, s->uspr_start, &K_loc);
        K->w = 0.0;
        sigma_u = K_loc > 0 ? sqrt(K->kT / K_loc) : 0.0;
    } else {
        K->u = s->uspr_start;
        K->w = v0;
    }
    if (K->thermal && sigma_u > 0) {
        K->u += sigma_u * s_kernel_normal(K);
        if (!s->it->overdamped)
            K->w += sqrt(K->kT / K->m) * s_kernel_normal(K);
    }
    /* pressed in, the body stays on the branch unless the draw took it below u_detach; free, it is in
     * contact only if the draw reached the surface */
    K->in_contact = has_contact && (start_pressed ? K->u >= K->contact.u_detach : K->u >= K->contact.u_touch);
    K->Fc = 0.0;
    if (K->in_contact) {
        K->Fc = K->cforce(&K->contact, K->u, &K->s, NULL);
        s->touched = 1;
        s->touch_t = 0.0;
        s->touch_uspr = K->u_spr;
    }
    K->f = K->k * (K->u_spr - K->u) - K->Fc;
    if (s->pz.on)
        s_piezo_next(s);
    s->phase = scene == S_SCENE_CURVE ? S_PH_APPROACH : scene == S_SCENE_LIVE ? S_PH_LIVE : S_PH_TUNE;
    if (scene == S_SCENE_TUNE)
        s->tune_samples = (uint64_t)llround(s->p.tune_duration_s * s->p.sample_rate_Hz);
}

int vafm_sim_set_trigger(vafm_sim *s, int enabled)
{
    if (!s)
        return VAFM_EINVAL;
    s->trigger_off = !enabled;
    return 0;
}

int vafm_sim_curve_begin(vafm_sim *s, uint64_t index)
{
    if (!s)
        return VAFM_EINVAL;
    if (s->tune_only) {
        memset(&s->err, 0, sizeof s->err);
        vafm_err_set(&s->err, VAFM_EINVAL, "", "this simulation runs thermal tunes only (vafm_sim_new_tune): its "
                     "scene is at the tune's sample rate, and a force curve's cost there was not checked");
        return VAFM_EINVAL;
    }
    s->list = 0;
    s_begin(s, index, S_SCENE_CURVE);
    return 0;
}

int vafm_sim_tune_begin(vafm_sim *s, uint64_t index)
{
    if (!s)
        return VAFM_EINVAL;
    memset(&s->err, 0, sizeof s->err);
    int rc = vafm_numerics_check_tune(&s->p, &s->nm, s->tune_only, &s->err);
    if (rc)
        return rc;
    s->list = 0;
    s_begin(s, index, S_SCENE_TUNE);
    return 0;
}

/* ---- one sample ------------------------------------------------------------------------------- */

static int s_free_safe(const vafm_sim *s)
{
    const vafm_kernel *K = &s->K;
    if (!s->p.free_exact || K->in_contact)
        return 0;
    if (!(K->contact.type->flags & VAFM_CONTACT_SURFACE))
        return 1;
    double y = K->u - K->u_spr, z = s->it->overdamped ? 0.0 : K->w - K->v_spr;
    double A = sqrt(y * y + K->m * z * z / K->k); /* energy bound of the deterministic excursion */
    double gap0 = K->contact.u_touch - K->u_spr;
    double gap1 = K->contact.u_touch - (K->u_spr + K->v_spr * s->nm.Ts);
    return fmin(gap0, gap1) > A + 8.0 * s->sigma_free;
}

static void s_event(vafm_sim *s)
{
    vafm_kernel *K = &s->K;
    if (K->event > 0) {
        if (!s->touched) {
            s->touched = 1;
            s->touch_t = K->t;
            s->touch_uspr = K->u_spr;
        }
        if (s->phase == S_PH_RETRACT && s->detached_in_retract)
            s->flags |= VAFM_CURVE_RECONTACT;
    } else if (K->event < 0) {
        if (s->phase == S_PH_RETRACT) {
            /* The body passed u_detach during the last step: go back to the crossing along the step's
             * velocity, so the recorded spring force and position are those at the crossing itself
             * rather than up to one step (with the body snapping fast) beyond it. */
            double back = K->w < 0 ? (K->u - K->contact.u_detach) / K->w : 0.0;
            if (!(back >= 0.0))
                back = 0.0;
            if (back > K->dt)
                back = K->dt;
            double uspr_x = K->u_spr - K->v_spr * back;
            s->detached_in_retract = 1;
            s->uspr_detach = uspr_x;
            s->fs_detach = K->k * (uspr_x - K->contact.u_detach);
            s->t_detach = K->t - back - s->t_retract0;
        } else {
            s->flags |= VAFM_CURVE_EARLY_DETACH;
        }
    }
    K->event = 0;
}


static void s_budget_take(uint64_t *budget, uint64_t n)
{
    if (budget)
        *budget = *budget > n ? *budget - n : 0;
}

/* The integrator steps left in the sample interval (s->sub_left), within *budget (NULL: none). An
 * integrator run split in pieces steps exactly as one run (the state round-trips through the kernel;
 * contact events split runs anyway). @return 1 if the budget ran out first, else 0. */
static int s_integrate(vafm_sim *s, uint64_t *budget)
{
    vafm_kernel *K = &s->K;
    while (s->sub_left > 0) {
        long want = s->sub_left;
        if (budget) {
            if (*budget == 0)
                return 1;
            if ((uint64_t)want > *budget)
                want = (long)*budget;
        } else if (s->batch_yield && s->it->batch_lanes > 1 && (!K->in_contact || K->jtab)) {
            s->batch_want = want;
            return 3; /* the batch kernel runs these steps (vafm_sim_batch_done) */
        }
        long d = s->it->run(K, want);
        s->sub_left -= d;
        if (budget)
            *budget -= (uint64_t)d;
        if (K->event)
            s_event(s);
    }
    return 0;
}

/* The guard's threshold for the step in use (guard.h), computed once per step size; two are kept (the
 * adaptive step alternates between nm.dt and nm.dt_far). */
static double s_guard_u(vafm_sim *s)
{
    if (!(s->dt_cur > 0))
        return -INFINITY;
    for (int i = 0; i < 2; i++)
        if (s->guard_dt[i] == s->dt_cur)
            return s->guard_u[i];
    const int i = s->guard_next;
    s->guard_next = 1 - i;
    s->guard_u[i] = vafm_guard_threshold(&s->K, s->it, s->dt_cur);
    s->guard_dt[i] = s->dt_cur;
    return s->guard_u[i];
}

/* One sample interval; *budget (integrator steps, NULL: none) may pause it inside its integrator run,
 * and the next call then goes on from there. @return 0 done, 2 paused, 3 handed to the batch kernel,
 * or a negative VAFM_E* code. */
static int s_step_interval(vafm_sim *s, uint64_t *budget)
{
    vafm_kernel *K = &s->K;
    if (s->sub_left == 0 && !s->batch_back) {
        K->acc_u = K->acc_uspr = 0.0;
        K->acc_n = 0;
        /* far from the instability: in contact, not yet near u_spr* on the retract */
        const int far = K->in_contact && (s->phase != S_PH_RETRACT || !(K->u_spr - s->nm.u_spr_star <= s->nm.y_near));
        if (s_free_safe(s)) {
            /* the live scene takes one exact transition per sample (its dead travel is long, nobody needs the
             * spring force between samples); a curve keeps its sub-steps (the retract's most tensile force) */
            const int live = s->scene == S_SCENE_LIVE;
            const vafm_free_ou *ou = live ? &s->ou_live : &s->ou;
            const long nf = live ? 1 : s->n_free;
            if (!s->mode_free) {
                s_kernel_phase(K, K->v_spr);
                K->dt = ou->h;
                s->mode_free = 1;
                s->mode_well = 0;
            }
            vafm_free_ou_steps(K, ou, nf);
            s_budget_take(budget, (uint64_t)nf);
        } else if (far && s->well_ok && vafm_sim_well_interval(s)) {
            s->mode_well = 1;
            s->mode_free = 0;
            s->need_prepare = 1;
            s_budget_take(budget, 1);
        } else {
            /* the larger step far from the instability (adaptive), the fine one near it */
            const int big = s->adaptive && far;
            double dt_want = big ? s->nm.dt_far : s->nm.dt;
            if (s->mode_free || s->mode_well || dt_want != s->dt_cur) {
                s_kernel_phase(K, K->v_spr);
                if (dt_want != s->dt_cur)
                    vafm_kernel_set_dt(K, dt_want);
                K->dt = dt_want;
                s->dt_cur = dt_want;
                s->mode_free = 0;
                s->mode_well = 0;
                s->need_prepare = 1;
            }
            if (s->need_prepare) {
                s->it->prepare(K);
                s->need_prepare = 0;
            }
            s->sub_left = big ? s->nm.n_sub_far : s->nm.n_sub;
        }
    }
    s->batch_back = 0;
    int ir = s_integrate(s, budget);
    if (ir)
        return ir == 3 ? 3 : 2;
    if (!isfinite(K->u) || !isfinite(K->w)) {
        vafm_err_set(&s->err, VAFM_EUNSTABLE, s->p.dt_s > 0 ? "dt_s" : "omega_dt",
                     "curve %llu: the state became non-finite at t = %.6g s: the step %.6g s is unstable for the "
                     "contact reached; lower %s", (unsigned long long)s->index, vafm_scale_time_si(&s->nm.sc, K->t),
                     vafm_scale_time_si(&s->nm.sc, s->dt_cur), s->p.dt_s > 0 ? "dt_s" : "omega_dt");
        return VAFM_EUNSTABLE;
    }
    if (K->in_contact && !(K->u <= s_guard_u(s))) {
        /* runtime guard: the contact reached may be stiffer than the scene predicted */
        double sq = K->s, Kl = 0.0;
        const double stab = vafm_guard_measure(K, s->it, s->dt_cur, K->u, &sq, &Kl);
        if (Kl > 0) {
            if (!(stab < s->it->stability_limit)) {
                vafm_err_set(&s->err, VAFM_EUNSTABLE, s->p.dt_s > 0 ? "dt_s" : "omega_dt",
                             "curve %llu at t = %.6g s: the contact reached (stiffness %.4g N/m, force %.4g N) gives "
                             "%s = %.4g >= %.3g with the step %.6g s; lower %s (the scene predicted %.4g N/m at most)",
                             (unsigned long long)s->index, vafm_scale_time_si(&s->nm.sc, K->t),
                             vafm_scale_stiffness_si(&s->nm.sc, Kl), vafm_scale_force_si(&s->nm.sc, K->Fc),
                             s->it->overdamped ? "K*dt/zeta" : "omega*dt", stab, s->it->stability_limit,
                             vafm_scale_time_si(&s->nm.sc, s->dt_cur), s->p.dt_s > 0 ? "dt_s" : "omega_dt",
                             vafm_scale_stiffness_si(&s->nm.sc, s->nm.K_max));
                return VAFM_EUNSTABLE;
            }
        }
    }
    return 0;
}

static void s_flush(vafm_sim *s, vafm_sample_fn fn, void *user, int *stop)
{
    if (s->nblk == 0)
        return;
    if (fn) {
        vafm_samples b = { s->nblk, s->sample_index - s->nblk, s->bt, s->bh, s->bd, s->bf, s->btip, s->bseg,
                           s->pz.on ? s->bha : NULL };
        if (fn(user, &b))
            *stop = 1;
    }
    s->nblk = 0;
}

static void s_start_retract(vafm_sim *s)
{
    s_start_retract_at(s, s->nm.r.v_retract);
}

static void s_phase_logic(vafm_sim *s, double force)
{
    vafm_kernel *K = &s->K;
    if (s->list) {
        vafm_sim_list_logic(s, force);
        return;
    }
    switch (s->phase) {
    case S_PH_APPROACH: {
        /* a relative setpoint counts from the baseline: the mean of the approach's first samples (before this
         * one); the first sample has no baseline yet and cannot trigger */
        double base = 0.0;
        int armed = 1;
        if (s->p.setpoint_mode == VAFM_SETPOINT_RELATIVE) {
            armed = s->base_n > 0;
            base = armed ? s->base_sum / s->base_n : 0.0;
            if (s->base_n < VAFM_BASELINE_SAMPLES) {
                s->base_sum += force;
                s->base_n++;
            }
        }
        int trig = s->p.trigger == VAFM_TRIGGER_FORCE ? armed && force - base >= s->F_set : s_ucmd(s) >= s->uspr_trigger;
        trig = trig && !s->trigger_off;
        s->F_hold = s->p.trigger == VAFM_TRIGGER_FORCE ? s->F_set + base : force;
        if (!trig && s_ucmd(s) >= s->uspr_zlimit) {
            s->flags |= VAFM_CURVE_NO_TRIGGER;
            trig = 1;
        }
        if (trig) {
            s->dwell_left = lround(s->p.dwell_s * s->p.sample_rate_Hz);
            if (s->dwell_left > 0) {
                s_set_speed(s, s->p.dwell_mode == VAFM_DWELL_FORCE ? s->fb_gain * (s->F_hold - force) : 0.0);
                s->need_prepare = 1;
                s->phase = S_PH_DWELL;
            } else {
                s_start_retract(s);
            }
        }
        break;
    }
    case S_PH_DWELL:
        if (--s->dwell_left <= 0)
            s_start_retract(s);
        else if (s->p.dwell_mode == VAFM_DWELL_FORCE) {
            /* an integral loop on the filtered deflection, acting once per sample: dz/dt = (F_hold − F)/(k τ) */
            s_set_speed(s, s->fb_gain * (s->F_hold - force));
            s->need_prepare = 1;
        }
        break;
    case S_PH_RETRACT: {
        double travel = s->uspr_turn - s_ucmd(s);
        if (s->p.ramp_size_m > 0) {
            /* a fixed ramp returns to its start height, whatever the tip did on the way */
            if (s_ucmd(s) <= s->uspr_start) {
                if (K->in_contact)
                    s->flags |= VAFM_CURVE_NO_DETACH;
                s->phase = S_PH_DONE;
            }
        } else if (!K->in_contact && s->detached_in_retract && s->uspr_detach - K->u_spr >= s->margin)
            s->phase = S_PH_DONE;
        else if (!K->in_contact && !s->detached_in_retract &&
                 s_ucmd(s) <= fmin(s->uspr_start, s->uspr_turn) - s->margin)
            s->phase = S_PH_DONE;
        else if (travel >= s->retract_travel_max) {
            if (K->in_contact)
                s->flags |= VAFM_CURVE_NO_DETACH;
            s->phase = S_PH_DONE;
        }
        break;
    }
    case S_PH_TUNE:
        if (s->sample_index >= s->tune_samples)
            s->phase = S_PH_DONE;
        break;
    default: break;
    }
}

int vafm_sim_segments_begin(vafm_sim *s, uint64_t index, const vafm_segment_spec *segs, size_t n)
{
    if (!s)
        return VAFM_EINVAL;
    memset(&s->err, 0, sizeof s->err);
    if (s->tune_only) {
        vafm_err_set(&s->err, VAFM_EINVAL, "", "this simulation runs thermal tunes only (vafm_sim_new_tune)");
        return VAFM_EINVAL;
    }
    int r = vafm_segments_validate(segs, n, &s->p, &s->err);
    if (r)
        return r;
    memcpy(s->seg, segs, n * sizeof *segs);
    s->nseg = n;
    s->list = 1;
    s->dec_n = 0;
    s_begin(s, index, S_SCENE_CURVE);
    vafm_sim_list_enter(s, 0, s->K.f, 1);
    return 0;
}

/* The live scene's sample boundary: the commander sees sample j of the block and says where the support is
 * at the end of the next interval; the support moves there at a constant speed. */
static void s_live_logic(vafm_sim *s, size_t j)
{
    vafm_kernel *K = &s->K;
    const vafm_scale *sc = &s->nm.sc;
    const vafm_live_sample smp = { s->sample_index - 1, s->bt[j], s->bh[j], s->bd[j], s->bf[j], s->btip[j],
                                   K->in_contact };
    const double h = s->live_fn(s->live_user, &smp);
    if (!isfinite(h)) {
        s->phase = S_PH_DONE;
        return;
    }
    s_set_speed(s, (vafm_scale_length_red(sc, -h) - K->u_spr) / s->nm.Ts);
    s->need_prepare = 1;
}

int vafm_sim_live_begin(vafm_sim *s, uint64_t stream, double height0_m, vafm_live_fn fn, void *user)
{
    return vafm_sim_live_begin_contact(s, stream, height0_m, 0, fn, user);
}

int vafm_sim_live_begin_contact(vafm_sim *s, uint64_t stream, double height0_m, int in_contact, vafm_live_fn fn,
                                void *user)
{
    if (!s)
        return VAFM_EINVAL;
    memset(&s->err, 0, sizeof s->err);
    if (!fn || !isfinite(height0_m) || fabs(height0_m) > 1.0) {
        vafm_err_set(&s->err, VAFM_EINVAL, "height0_m", "the live scene needs a commander and a finite start height "
                     "within [-1, 1] m (got %g)", height0_m);
        return VAFM_EINVAL;
    }
    if (s->tune_only) {
        vafm_err_set(&s->err, VAFM_EINVAL, "", "this simulation runs thermal tunes only (vafm_sim_new_tune)");
        return VAFM_EINVAL;
    }
    s->live_fn = fn;
    s->live_user = user;
    s->live_h0_m = height0_m;
    s->live_contact = in_contact ? 1 : 0;
    s->list = 0;
    s_begin(s, stream, S_SCENE_LIVE);
    return 0;
}

void vafm_sim_live_commander(vafm_sim *s, vafm_live_fn fn, void *user)
{
    s->live_fn = fn;
    s->live_user = user;
}

static int s_advance(vafm_sim *s, size_t max_samples, uint64_t *budget, vafm_sample_fn fn, void *user);

int vafm_sim_advance(vafm_sim *s, size_t max_samples, vafm_sample_fn fn, void *user)
{
    return s_advance(s, max_samples, NULL, fn, user);
}

int vafm_sim_advance_steps(vafm_sim *s, size_t max_samples, uint64_t max_steps, vafm_sample_fn fn, void *user)
{
    return s_advance(s, max_samples, &max_steps, fn, user);
}

static int s_advance(vafm_sim *s, size_t max_samples, uint64_t *budget, vafm_sample_fn fn, void *user)
{
    if (!s)
        return VAFM_EINVAL;
    if (s->scene == S_SCENE_NONE)
        return VAFM_ESTATE;
    vafm_kernel *K = &s->K;
    const vafm_scale *sc = &s->nm.sc;
    int stop = 0;
    for (size_t i = 0; i < max_samples && s->phase != S_PH_DONE && !stop; i++) {
        if (budget && *budget == 0 && s->sub_left == 0)
            break; /* the step budget is spent: stop at this sample boundary */
        if (s->phase == S_PH_TUNE && s->sample_index >= s->tune_samples) {
            s->phase = S_PH_DONE;
            break;
        }
        int seg = s->list                   ? s->seg_label
                  : s->phase == S_PH_APPROACH ? VAFM_SEG_APPROACH
                  : s->phase == S_PH_DWELL  ? VAFM_SEG_DWELL
                  : s->phase == S_PH_TUNE   ? VAFM_SEG_TUNE
                  : s->phase == S_PH_LIVE   ? VAFM_SEG_LIVE
                                            : VAFM_SEG_RETRACT;
        /* a list's retract segments carry the curve's retract observables, whatever their label */
        const int in_retract = s->list ? s->phase == S_PH_RETRACT : seg == VAFM_SEG_RETRACT;
        int r = s_step_interval(s, budget);
        if (r == 3)
            return VAFM_SIM_BATCH_WAIT; /* the samples stay in the block: the batch kernel runs this interval on */
        if (r == 2) { /* the step budget ran out inside this sample: hand over the complete ones */
            s_flush(s, fn, user, &stop);
            if (stop) {
                s->phase = S_PH_DONE;
                s->sub_left = 0;
                return VAFM_EABORT;
            }
            return 1;
        }
        if (r) {
            s_flush(s, fn, user, &stop);
            s->phase = S_PH_DONE;
            return r;
        }
        s->scene_samples++;
        double u_m, uspr_m, t_m;
        if (s->p.antialias == VAFM_ANTIALIAS_MEAN && K->acc_n > 0) {
            u_m = K->acc_u / (double)K->acc_n;
            uspr_m = K->acc_uspr / (double)K->acc_n;
            t_m = K->t - 0.5 * s->nm.Ts;
        } else {
            u_m = K->u;
            uspr_m = K->u_spr;
            t_m = K->t;
        }
        double defl = uspr_m - u_m, force = K->k * defl;
        size_t j = s->nblk;
        s->bt[j] = vafm_scale_time_si(sc, t_m);
        s->bh[j] = s_height(s, vafm_scale_length_si(sc, -uspr_m), s->bt[j]);
        if (s->pz.on) { /* the files' piezo height is the command; where the support was is the actual one */
            double uc = s->p.antialias == VAFM_ANTIALIAS_MEAN ? 0.5 * (s->ucmd_now + s->ucmd_next) : s->ucmd_next;
            s->bha[j] = s->bh[j];
            s->bh[j] = vafm_scale_length_si(sc, -uc) + s->surf0_m;
        }
        s->bd[j] = vafm_scale_length_si(sc, defl);
        s->bf[j] = vafm_scale_force_si(sc, force);
        s->btip[j] = s_height(s, vafm_scale_length_si(sc, -u_m), s->bt[j]);
        s->bseg[j] = (uint8_t)seg;
        if (s->list && (s->dec > 1 || s->dec_n > 0)) {
            /* a segment at a lower rate: its output sample gathers dec samples of the scene's rate (the triggers
             * act on each of them, as a controller's fast loop) */
            if (vafm_sim_dec_add(s, j, force)) {
                vafm_sim_dec_emit(s, j, seg, in_retract);
                s->nblk++;
            }
        } else {
            s->nblk++;
            s_sample_done(s, force, in_retract);
        }
        const size_t iseg0 = s->iseg;
        if (s->phase == S_PH_LIVE)
            s_live_logic(s, j);
        else
            s_phase_logic(s, force);
        if (s->list && s->dec_n > 0 && (s->iseg != iseg0 || s->phase == S_PH_DONE)) {
            /* the segment ended inside an output sample: the part gathered is its last sample */
            vafm_sim_dec_emit(s, s->nblk, seg, in_retract);
            s->nblk++;
        }
        if (s->pz.on && s->phase != S_PH_DONE)
            s_piezo_next(s);
        if (s->nblk == S_BLOCK)
            s_flush(s, fn, user, &stop);
    }
    s_flush(s, fn, user, &stop);
    if (stop) {
        s->phase = S_PH_DONE;
        return VAFM_EABORT;
    }
    return s->phase == S_PH_DONE ? 0 : 1;
}

const vafm_error *vafm_sim_error(const vafm_sim *s)
{
    return s && s->err.code ? &s->err : NULL;
}

int vafm_sim_result(const vafm_sim *s, vafm_curve_result *out)
{
    if (!s || !out)
        return VAFM_EINVAL;
    const vafm_kernel *K = &s->K;
    const vafm_scale *sc = &s->nm.sc;
    memset(out, 0, sizeof *out);
    out->index = s->index;
    out->flags = s->flags;
    if (!s->touched)
        out->flags |= VAFM_CURVE_NO_CONTACT;
    out->pulloff_sampled_N = s->retract_samples ? vafm_scale_force_si(sc, -s->sample_min_force) : NAN;
    out->pulloff_spring_N = s->phase == S_PH_RETRACT || (s->phase == S_PH_DONE && isfinite(s->t_retract0))
                                ? vafm_scale_force_si(sc, -K->fs_min)
                                : NAN;
    if (s->detached_in_retract) {
        out->detach_force_N = vafm_scale_force_si(sc, -s->fs_detach);
        out->detach_height_m = s_height(s, vafm_scale_length_si(sc, -s->uspr_detach),
                                         vafm_scale_time_si(sc, s->t_detach + s->t_retract0));
        out->detach_time_s = vafm_scale_time_si(sc, s->t_detach);
        double ueq, Feq;
        if ((K->contact.type->flags & VAFM_CONTACT_JKR_BRANCH) && K->contact.gamma > 0 &&
            vafm_theory_equilibrium(K->contact.gamma, K->k, s->uspr_detach, &ueq, &Feq) == 0)
            out->detach_eq_force_N = vafm_scale_force_si(sc, -Feq);
        else
            out->detach_eq_force_N = NAN;
    } else {
        out->detach_force_N = out->detach_height_m = out->detach_time_s = out->detach_eq_force_N = NAN;
    }
    out->touch_time_s = vafm_scale_time_si(sc, s->touch_t);
    out->touch_height_m = s_height(s, vafm_scale_length_si(sc, -s->touch_uspr), vafm_scale_time_si(sc, s->touch_t));
    out->surface_height_m = s->surf0_m;
    out->retract_start_s = vafm_scale_time_si(sc, s->t_retract0);
    out->duration_s = vafm_scale_time_si(sc, K->t);
    out->samples = s->sample_index;
    out->steps = K->steps;
    out->steps_contact = K->steps_contact;
    out->steps_free = K->steps_free;
    return 0;
}

static int s_run_all(vafm_sim *s, vafm_sample_fn fn, void *user)
{
    int r;
    do
        r = vafm_sim_advance(s, 1u << 20, fn, user);
    while (r == 1);
    return r;
}

/* A begun run (begun: its _begin's code) to its end, then its result into out (if given). */
static int s_run_to_result(vafm_sim *s, int begun, vafm_sample_fn fn, void *user, vafm_curve_result *out)
{
    if (begun)
        return begun;
    int r = s_run_all(s, fn, user);
    if (out)
        vafm_sim_result(s, out);
    return r;
}

int vafm_sim_curve(vafm_sim *s, uint64_t index, vafm_sample_fn fn, void *user, vafm_curve_result *out)
{
    return s_run_to_result(s, vafm_sim_curve_begin(s, index), fn, user, out);
}

int vafm_sim_segments(vafm_sim *s, uint64_t index, const vafm_segment_spec *segs, size_t n, vafm_sample_fn fn,
                      void *user, vafm_curve_result *out)
{
    return s_run_to_result(s, vafm_sim_segments_begin(s, index, segs, n), fn, user, out);
}

int vafm_sim_tune(vafm_sim *s, uint64_t index, vafm_sample_fn fn, void *user)
{
    int r = vafm_sim_tune_begin(s, index);
    if (r)
        return r;
    return s_run_all(s, fn, user);
}

/* ---- the batch kernel's side (batch.h) ------------------------------------------------------------- */

int vafm_sim_advance_batch(vafm_sim *s, size_t max_samples, vafm_sample_fn fn, void *user)
{
    if (!s)
        return VAFM_EINVAL;
    s->batch_yield = 1;
    int r = s_advance(s, max_samples, NULL, fn, user);
    s->batch_yield = 0;
    return r;
}

vafm_kernel *vafm_sim_batch_kernel(vafm_sim *s, long *want)
{
    *want = s->batch_want;
    return &s->K;
}

void vafm_sim_batch_done(vafm_sim *s, long steps)
{
    s->sub_left -= steps;
    s->batch_want = 0;
    s->batch_back = 1;
    if (s->K.event)
        s_event(s);
}
