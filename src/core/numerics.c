/* SPDX-License-Identifier: MIT */
/*
 * What a scene needs before it runs: reduced model, the stiffest contact it will reach, the time step
 * (given, or the paper's Eq. 8 rule: a fraction of the fastest period and of the retract time to the
 * pull-off) and the stability check against it. One function, used by validation and by vafm_sim_new.
 */
#include <math.h>
#include <string.h>

#include "vafm/integrator.h"
#include "vafm/theory.h"
#include "core/internal.h"

void vafm_numerics_estimate(const vafm_params *p, const vafm_numerics *nm, vafm_sim_estimate *out)
{
    const vafm_reduced *r = &nm->r;
    const vafm_scale *sc = &nm->sc;
    memset(out, 0, sizeof *out);
    /* a typical curve: approach from the start to the trigger, dwell, retract to the quasi-static
     * detachment and the margin after it (sim.c: s_begin, s_start_retract) */
    double uspr_start = vafm_scale_length_red(sc, -p->start_height_m);
    double approach = fmax(0.0, nm->u_spr_turn - uspr_start), margin = vafm_scale_length_red(sc, p->retract_margin_m);
    double t = approach / r->v_approach + vafm_scale_time_red(sc, p->dwell_s) + (nm->u_c + margin) / r->v_retract;
    /* the longest: the approach to its travel limit, the retract to its own */
    double sigma = r->k > 0 ? sqrt(r->kT / r->k) : 0.0;
    double zr = p->z_range_m > 0 ? vafm_scale_length_red(sc, p->z_range_m)
                                 : fmax(0.0, -uspr_start) + 2.0 * vafm_scale_force_red(sc, p->setpoint_N) / r->k + 20.0 * sigma + 1.0;
    double ret = p->retract_max_m > 0 ? vafm_scale_length_red(sc, p->retract_max_m) : 4.0 * fmax(zr + uspr_start - (nm->u_spr_turn - nm->u_c), 0.0) + margin + 1.0;
    double tmax = zr / r->v_approach + vafm_scale_time_red(sc, p->dwell_s) + (zr + ret) / r->v_retract;
    if (p->ramp_size_m > 0) {
        /* a fixed ramp: the ramp down (to the trigger, here taken at its end) and back up; from the trigger
         * point up to twice the ramp */
        double ramp = vafm_scale_length_red(sc, p->ramp_size_m), span = p->ramp_start == VAFM_RAMP_START_TRIGGER ? 2.0 * ramp : ramp;
        t = ramp / r->v_approach + vafm_scale_time_red(sc, p->dwell_s) + ramp / r->v_retract;
        tmax = span / r->v_approach + vafm_scale_time_red(sc, p->dwell_s) + span / r->v_retract;
    }
    out->duration_s = vafm_scale_time_si(sc, t);
    out->duration_max_s = vafm_scale_time_si(sc, fmax(t, tmax));
    out->samples = t / nm->Ts;
    out->samples_max = vafm_scale_time_red(sc, out->duration_max_s) / nm->Ts;
    out->steps = t / nm->dt;
    out->tune_samples = p->tune_duration_s * p->sample_rate_Hz;
    out->tune_steps = vafm_scale_time_red(sc, p->tune_duration_s) / nm->dt;
}

/* Refuse a scene whose curve or tune would exceed the documented cost limits (vafm/sim.h), naming the
 * field that drives it. @return 0 or VAFM_EINVAL. */
static int s_check_cost(const vafm_params *p, const vafm_numerics *nm, vafm_error *e)
{
    vafm_sim_estimate est;
    vafm_numerics_estimate(p, nm, &est);
    const vafm_scale *sc = &nm->sc;
    /* the part of the typical curve's time that dominates names the field */
    double t_dwell = p->dwell_s, t_ret = est.duration_s - t_dwell, t_app = 0.0;
    double uspr_start = vafm_scale_length_red(sc, -p->start_height_m);
    t_app = p->ramp_size_m > 0 ? vafm_scale_time_si(sc, vafm_scale_length_red(sc, p->ramp_size_m) / nm->r.v_approach)
                               : vafm_scale_time_si(sc, fmax(0.0, nm->u_spr_turn - uspr_start) / nm->r.v_approach);
    t_ret -= t_app;
    const char *slow = t_dwell >= t_app && t_dwell >= t_ret ? "dwell_s"
                       : t_app >= t_ret                       ? "v_approach_m_per_s"
                                                              : "v_retract_m_per_s";
    if (est.samples > (double)VAFM_SIM_MAX_SAMPLES) {
        /* the field to change: the sample rate, unless the curve is too long even at 1 MS/s */
        const char *field = est.duration_s * 1e6 > (double)VAFM_SIM_MAX_SAMPLES ? slow : "sample_rate_Hz";
        vafm_err_set(e, VAFM_EINVAL, field,
                     "a curve of this scene runs ~%.3g s (simulated; %s sets most of it) and would have ~%.3g samples "
                     "at sample_rate_Hz = %.6g Hz: more than a curve may have (%llu, VAFM_SIM_MAX_SAMPLES; ~%.0f MB "
                     "in memory); lower sample_rate_Hz or shorten the curve (%s)",
                     est.duration_s, slow, est.samples, p->sample_rate_Hz, (unsigned long long)VAFM_SIM_MAX_SAMPLES,
                     est.samples * 41e-6, slow);
        return VAFM_EINVAL;
    }
    /* (a tune's own limits are checked when a tune starts: vafm_numerics_check_tune) */
    if (est.steps > VAFM_SIM_MAX_STEPS) {
        int tune = 0;
        vafm_err_set(e, VAFM_EINVAL, tune ? "tune_duration_s" : slow,
                     "a %s of this scene runs ~%.3g s (simulated) at a time step of %.3g s: ~%.3g integrator steps, "
                     "more than %.0e (VAFM_SIM_MAX_STEPS, hours of CPU); %s",
                     tune ? "thermal tune" : "curve", tune ? p->tune_duration_s : est.duration_s, vafm_scale_time_si(sc, nm->dt),
                     tune ? est.tune_steps : est.steps, VAFM_SIM_MAX_STEPS,
                     tune ? "shorten tune_duration_s" : "raise the speeds or shorten dwell_s");
        return VAFM_EINVAL;
    }
    return 0;
}

int vafm_numerics_check_tune(const vafm_params *p, const vafm_numerics *nm, int tune_scene, vafm_error *err)
{
    vafm_sim_estimate est;
    vafm_numerics_estimate(p, nm, &est);
    if (est.tune_samples > (double)VAFM_SIM_MAX_SAMPLES || est.tune_steps > VAFM_SIM_MAX_STEPS) {
        /* a tune scene's rate is the tune's own (tune_rate_Hz, or sample_rate_Hz raised to show f0) */
        const char *rate = tune_scene ? "the tune rate (tune_rate_Hz; 0: sample_rate_Hz raised to 4 f0)"
                                      : "sample_rate_Hz";
        vafm_err_set(err, VAFM_EINVAL, "tune_duration_s",
                     "a thermal tune of tune_duration_s = %.6g s at %.6g Hz, %s, would have %.3g samples and %.3g "
                     "steps: more than %llu samples (VAFM_SIM_MAX_SAMPLES) or %.0e steps (VAFM_SIM_MAX_STEPS); "
                     "shorten tune_duration_s or lower %s",
                     p->tune_duration_s, p->sample_rate_Hz, rate, est.tune_samples, est.tune_steps,
                     (unsigned long long)VAFM_SIM_MAX_SAMPLES, VAFM_SIM_MAX_STEPS,
                     tune_scene ? "tune_rate_Hz" : "sample_rate_Hz");
        return VAFM_EINVAL;
    }
    return 0;
}

int vafm_numerics_check(const vafm_params *p, vafm_numerics *out, vafm_error *err)
{
    return vafm_numerics_check_scene(p, out, 0, err);
}

int vafm_numerics_check_scene(const vafm_params *p, vafm_numerics *out, int tune_scene, vafm_error *err)
{
    vafm_numerics nm_local, *nm = out ? out : &nm_local;
    vafm_units_reduce(p, &nm->r);
    nm->sc = vafm_units_scale(p);
    const vafm_scale *sc = &nm->sc;
    const vafm_reduced *r = &nm->r;
    const unsigned cf = p->contact ? p->contact->flags : 0u;
    if (vafm_contact_init(&nm->contact, p->contact, (cf & VAFM_CONTACT_ADHESIVE) ? r->gamma : 0.0)) {
        vafm_err_set(err, VAFM_EINVAL, "gamma_J_per_m2", "gamma_J_per_m2 = %.6g J/m^2 is not valid for contact %s",
                     p->gamma_J_per_m2, p->contact->name);
        return VAFM_EINVAL;
    }
    const vafm_contact *c = &nm->contact;
    const int has_contact = (cf & VAFM_CONTACT_SURFACE) != 0;
    nm->Ts = vafm_scale_time_red(sc, 1.0 / p->sample_rate_Hz);

    /* The stiffest contact: at the largest repulsive force expected, with room for the overshoot of
     * the jump into contact and of the trigger's latency (one sample). */
    const double F_set = vafm_scale_force_red(sc, p->setpoint_N);
    double u_spr_turn;
    if (p->trigger == VAFM_TRIGGER_FORCE) {
        nm->F_max = F_set + fmax(c->F_jkr, 0.25 * F_set) + r->k * r->v_approach * nm->Ts;
        u_spr_turn = F_set / r->k; /* + indentation at F_set, added below */
    } else {
        u_spr_turn = vafm_scale_length_red(sc, -p->trigger_height_m);
        nm->F_max = r->k * fmax(0.0, u_spr_turn - fmin(0.0, c->u_detach)) + c->F_jkr;
    }
    nm->K_max = r->k;
    nm->u_deep = 0.0;
    if (has_contact) { /* the model's own branch (its at_force hook) */
        double dFdu, u_set;
        c->type->at_force(c, 4.0 * nm->F_max + c->F_jkr, &nm->u_deep, NULL);
        c->type->at_force(c, nm->F_max, NULL, &dFdu);
        nm->K_max += dFdu;
        if (p->trigger == VAFM_TRIGGER_FORCE) {
            c->type->at_force(c, F_set, &u_set, NULL);
            u_spr_turn += u_set;
        }
    }
    nm->u_spr_star = NAN;
    double u_end = has_contact ? fmin(0.0, c->u_detach) : 0.0;
    const int jkr_theory = (cf & VAFM_CONTACT_JKR_BRANCH) && r->gamma > 0; /* theory.h's references apply */
    if (jkr_theory) {
        vafm_quasistatic q;
        if (vafm_theory_quasistatic(r->gamma, r->k, &q) == 0) {
            nm->u_spr_star = q.u_spr_star;
            u_end = q.u_spr_star;
        }
    }
    nm->u_c = fmax(u_spr_turn - u_end, 0.0);
    nm->u_spr_turn = u_spr_turn;
    if (p->start_in_contact) {
        /* an equilibrium on the contact branch exists for spring positions above the instability */
        double uspr0 = vafm_scale_length_red(sc, -p->start_height_m);
        double lowest = isfinite(nm->u_spr_star) ? nm->u_spr_star : 0.0;
        if (!has_contact || !(uspr0 > lowest)) {
            vafm_err_set(err, VAFM_EINVAL, "start_height_m",
                         "start_in_contact: start_height_m = %.6g m has no contact equilibrium; with contact %s it "
                         "must be below %.6g m (the quasi-static pull-off instability)",
                         p->start_height_m, p->contact->name, vafm_scale_length_si(sc, -lowest));
            return VAFM_EINVAL;
        }
    }

    const vafm_integrator_type *it = p->integrator;
    const double zeta_min = r->m; /* out of contact ζ = mη; in contact larger */
    double dt;
    if (p->dt_s > 0) {
        dt = vafm_scale_time_red(sc, p->dt_s);
    } else {
        if (it->overdamped)
            dt = fmin(0.05, p->omega_dt * zeta_min / nm->K_max); /* the paper: dt = 1/(20η) */
        else
            dt = p->omega_dt / sqrt(nm->K_max / r->m);
        double vmax = fmax(r->v_approach, r->v_retract);
        if (nm->u_c > 0)
            dt = fmin(dt, nm->u_c / (40.0 * vmax)); /* the paper's Eq. 8, second term */
    }
    nm->n_sub = (long)ceil(nm->Ts / dt * (1.0 - 1e-12));
    if (nm->n_sub < 1)
        nm->n_sub = 1;
    if ((double)nm->n_sub > 9e15) {
        vafm_err_set(err, VAFM_EINVAL, "sample_rate_Hz",
                     "sample_rate_Hz = %.6g Hz needs %.3g steps per sample at dt = %.3g s; raise the sample rate",
                     p->sample_rate_Hz, nm->Ts / dt, vafm_scale_time_si(sc, dt));
        return VAFM_EINVAL;
    }
    nm->dt = nm->Ts / (double)nm->n_sub;
    dt = nm->dt;
    nm->stab = it->overdamped ? nm->K_max * dt / zeta_min : sqrt(nm->K_max / r->m) * dt;
    if (!(nm->stab < it->stability_limit)) {
        double dt_stable = vafm_scale_time_si(sc, it->overdamped ? it->stability_limit * zeta_min / nm->K_max
                                                              : it->stability_limit / sqrt(nm->K_max / r->m));
        vafm_err_set(err, VAFM_EUNSTABLE, "dt_s",
                     "dt_s = %.6g s (step used %.6g s) is beyond the %s stability limit: %s = %.4g at the stiffest "
                     "contact reached (%.4g N/m, force %.4g N) must be < %.3g, i.e. dt_s < %.4g s; "
                     "lower dt_s (or 0 for automatic)",
                     p->dt_s, vafm_scale_time_si(sc, dt), it->name, it->overdamped ? "K_max*dt/zeta" : "omega_max*dt",
                     nm->stab, vafm_scale_stiffness_si(sc, nm->K_max), vafm_scale_force_si(sc, nm->F_max),
                     it->stability_limit, dt_stable);
        return VAFM_EUNSTABLE;
    }
    /* Adaptive step: far from the instability (in contact, before the retract gets near it) the well is
     * close to harmonic and deep, where GJF/BAOAB sample configurations exactly at any ω dt < 2; near
     * it the escape dynamics need the fine step. */
    nm->dt_far = dt;
    nm->n_sub_far = nm->n_sub;
    /* "near" the instability: the quasi-static barrier below near_barrier_kT·kT or the spring force
     * within 10% of F*. Without adhesion there is no instability: never near. */
    nm->y_near = -INFINITY;
    nm->u_soft = has_contact ? fmin(0.0, c->u_detach) : 0.0;
    if (jkr_theory) {
        vafm_quasistatic q;
        if (vafm_theory_quasistatic(r->gamma, r->k, &q) == 0) {
            /* ΔV(y) = (4√2/3)(ky)^{3/2}/√F″ = B·kT  ⇒  k·y_B = [3B·kT√F″/(4√2)]^{2/3} */
            double kyB = pow(3.0 * p->near_barrier_kT * r->kT * sqrt(fabs(q.F2)) / (4.0 * sqrt(2.0)), 2.0 / 3.0);
            nm->y_near = fmax(kyB, 0.1 * q.F_star) / r->k;
        }
        double xf = 0.75 * c->c, sf = cbrt(xf); /* the force minimum: the stiffness of the branch is 0 there */
        nm->u_soft = sf * sf * sf * sf - c->c * sf;
    }
    if (p->omega_dt_far > p->omega_dt && p->dt_s == 0 && !it->overdamped) {
        double dtf = p->omega_dt_far / sqrt(nm->K_max / r->m);
        long nf = (long)ceil(nm->Ts / dtf * (1.0 - 1e-12));
        nm->n_sub_far = nf < 1 ? 1 : nf;
        nm->dt_far = nm->Ts / (double)nm->n_sub_far;
    }
    /* a tune scene runs no force curve: its curve at the tune rate may be as long as it likes, its tune may not */
    if (tune_scene ? vafm_numerics_check_tune(p, nm, 1, err) : s_check_cost(p, nm, err))
        return VAFM_EINVAL;
    if (it->eta_dt_limit > 0) {
        double eta_dt = (1.0 + (has_contact ? r->eta_cont : 0.0)) * dt;
        if (!(eta_dt < it->eta_dt_limit)) {
            vafm_err_set(err, VAFM_EUNSTABLE, "dt_s",
                         "dt_s = %.6g s gives eta*dt = %.4g: integrator %s is unstable for eta*dt >= %g",
                         vafm_scale_time_si(sc, dt), eta_dt, it->name, it->eta_dt_limit);
            return VAFM_EUNSTABLE;
        }
    }
    return 0;
}
