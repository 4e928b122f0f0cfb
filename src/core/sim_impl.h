/* SPDX-License-Identifier: MIT */
/*
 * The simulation object's private state, shared by the files of its scenes (not installed): sim.c (the
 * curve, the thermal tune and the live scene of vafm/ctrl.h, the sample loop), sim_segments.c (segment
 * lists) and sim_well.c (the exact contact-well step).
 *
 * A scene is a state machine advanced one output sample at a time by sim.c's sample loop; its phase
 * decides the segment label and what happens at each sample boundary (s_phase_logic for the curve and
 * the tune; vafm_sim_live_logic for the live scene, whose support motion a caller commands). Everything
 * here is allocated in vafm_sim_new: no scene allocates, locks or does I/O while it runs.
 */
#ifndef VAFM_CORE_SIM_IMPL_H
#define VAFM_CORE_SIM_IMPL_H

#include "vafm/segments.h"
#include "vafm/sim.h"
#include "core/internal.h"
#include "core/kernel.h"
#include "core/piezo.h"

#define S_BLOCK 512
/* Integrator steps per sample from which the exact well step pays: it costs ~0.15-0.2 µs (closed-form
 * transition, an equilibrium Newton update, three normals, one contact solve), an in-contact step ~35 ns
 * (bench_step). */
#define S_WELL_MIN_STEPS 8

enum { S_SCENE_NONE = 0, S_SCENE_CURVE, S_SCENE_TUNE, S_SCENE_LIVE };

enum { S_PH_APPROACH = 0, S_PH_DWELL, S_PH_RETRACT, S_PH_TUNE, S_PH_LIVE, S_PH_DONE };

/* The contact branch's equilibrium for one support position, with the branch's stiffness and curvature
 * there (the exact well step's linearisation). */
typedef struct s_weq {
    double uspr;     /* support position it belongs to */
    double t;        /* s − s_m at the equilibrium (contact_jkr.c's t-form) */
    double ueq;      /* equilibrium indentation */
    double dF, F2, F3; /* dF/du, d²F/du² and d³F/du³ of the contact force there */
    int ok;
} s_weq;

struct vafm_sim {
    vafm_params p;
    vafm_numerics nm;
    const vafm_integrator_type *it;
    vafm_kernel K;
    vafm_free_ou ou;
    vafm_jkr_table jtab;
    long n_free;        /* exact free steps per sample */
    double sigma_free;  /* √(kT/k): thermal spread of the free cantilever */
    int mode_free;      /* the last sample interval used exact free steps */
    int mode_well;      /* the last sample interval used the exact contact well */
    int adaptive;       /* two step sizes: nm.dt near the instability, nm.dt_far elsewhere in contact */
    int well_ok;        /* the exact contact-well step may be used */
    double dt_cur;      /* the integrator step in use */
    double guard_dt[2]; /* the steps the stiffness guard's thresholds belong to (0: none computed yet) */
    double guard_u[2];  /* for u ≤ guard_u[i] the guard at guard_dt[i] passes without a contact solve (s_guard_u) */
    int guard_next;     /* the entry the next threshold replaces */
    s_weq weq;          /* the last well equilibrium (the next interval starts where it ends); reset per curve */
    long sub_left;      /* integrator steps left in the current sample interval (> 0 only while one runs, or
                         * when a step budget paused it: the next call goes on from there) */
    int need_prepare;   /* the integrator's cached force is stale */
    int batch_yield;    /* an advance for the batch kernel (batch.h): hand plain in-contact gjf runs out */
    long batch_want;    /* the steps of the run handed out */
    int batch_back;     /* the batch kernel ran them: the interval goes on (or ends) where it stopped */
    /* scene */
    int scene, phase;
    uint64_t index, sample_index, tune_samples;
    uint64_t scene_samples; /* sample intervals of the scene's rate completed since the scene began */
    uint64_t clock_samples; /* ... up to the end of the last output sample (vafm_sim_clock_samples) */
    long dwell_left;
    double uspr_start, uspr_turn, uspr_trigger, uspr_zlimit, retract_travel_max, margin, F_set;
    double base_sum;    /* relative setpoint: sum of the baseline samples so far */
    int base_n;         /* ... and their number (≤ VAFM_BASELINE_SAMPLES) */
    double F_hold;      /* constant-force dwell: the force the feedback holds (reduced) */
    double fb_gain;     /* constant-force dwell: piezo speed per unit force error, 1/(k·τ) (reduced) */
    int trigger_off;    /* fault injection: the trigger never fires (vafm_sim_set_trigger) */
    int tune_only;      /* made by vafm_sim_new_tune: a curve's cost was not checked, curves are refused */
    int touched, detached_in_retract, flags, retract_samples;
    double uspr_detach, fs_detach, t_detach, t_retract0, sample_min_force, fs_min_retract;
    double touch_t, touch_uspr;
    double surf0_m;     /* artefacts: the curve's contact point above the reference plane, m (vafm/detector.h) */
    double drift_m_per_s, v_drift; /* the sample's drift, m/s and reduced (added to the support's speed) */
    vafm_piezo pz;      /* the piezo's hysteresis and creep (pz.on: the support follows the actual extension) */
    double v_cmd;       /* the command's speed in the current phase (reduced, as the support's) */
    double ucmd_now, ucmd_next; /* with pz.on: the command at this sample boundary and at the next (reduced) */
    vafm_error err;     /* detail of the error that ended the scene (err.code 0: none) */
    /* the live scene (vafm_sim_live_begin): the caller commands the support at each sample boundary */
    vafm_live_fn live_fn;
    void *live_user;
    double live_h0_m;   /* the support's height above the surface at the start, m */
    int live_contact;   /* 1: the lever starts on the contact branch even above the surface (a carried state) */
    vafm_free_ou ou_live; /* exact free transition over a whole sample interval (live scene, far from the surface) */
    /* a segment list (vafm_sim_segments_begin; list = 0: the plain curve). The phase follows the segment's
     * motion (APPROACH: extend, DWELL: pause or modulate, RETRACT: retract) so that contact events, the
     * retract's observables and the step choice treat it as the curve treats its own segments. */
    int list;
    size_t nseg, iseg;      /* the list's length and the running segment */
    vafm_segment_spec seg[VAFM_SEGMENTS_MAX];
    int seg_label;          /* the running segment's label (the samples' segment channel) */
    long seg_left;          /* pause, modulate: samples left */
    double seg_u0, seg_t0;  /* the command and the time at the segment's start (reduced) */
    double seg_ulim;        /* extend: command ≥ this ends it; retract (end travel): command ≤ this */
    double seg_thr;         /* trigger threshold: force (reduced, baseline not added), command (reduced), time */
    int seg_ch, seg_op;     /* trigger channel and comparison in use (NONE when off) */
    int seg_force_trig;     /* the last extend ended on its force-type trigger (a pause may hold that level) */
    long dec, dec_n;        /* decimation of the running segment, and base samples accumulated */
    double dec_sum[7];      /* their sums (t, h, h measured, deflection, force, tip; reduced force) */
    /* output block */
    size_t nblk;
    double *bt, *bh, *bd, *bf, *btip, *bha;
    uint8_t *bseg;
};

/* The support's position in the piezo's own frame (the command): its position relative to the surface less
 * what the drifting surface added. Travel limits, height triggers and the fixed ramp's end are the piezo's. */
static inline double s_ucmd(const vafm_sim *s)
{
    if (s->pz.on)
        return s->ucmd_now;
    return s->v_drift != 0.0 ? s->K.u_spr - s->v_drift * s->K.t : s->K.u_spr;
}

/* The command's speed for the phase that starts now (reduced): the support follows it, with the sample's
 * drift, directly or through the piezo model (then at the next boundary's s_piezo_next). */
static inline void s_set_speed(vafm_sim *s, double v)
{
    s->v_cmd = v;
    if (!s->pz.on)
        s_kernel_phase(&s->K, v + s->v_drift);
}

/* The retract starts now at speed v_retract (reduced): the curve's phase and a list's retract segment. */
static inline void s_start_retract_at(vafm_sim *s, double v_retract)
{
    vafm_kernel *K = &s->K;
    s_set_speed(s, -v_retract);
    s->need_prepare = 1; /* the drift term changed with v_spr */
    s->t_retract0 = K->t;
    s->uspr_turn = s_ucmd(s);
    K->fs_min = INFINITY;
    s->phase = S_PH_RETRACT;
    double end = isfinite(s->nm.u_spr_star) ? s->nm.u_spr_star : fmin(0.0, K->contact.u_detach);
    s->retract_travel_max = s->p.retract_max_m > 0 ? vafm_scale_length_red(&s->nm.sc, s->p.retract_max_m)
                                                   : 4.0 * fmax(s->uspr_turn - end, 0.0) + s->margin + 1.0;
}

/* One output sample is complete (force: its force, reduced): count it, move the pacing clock to the scene
 * samples it covers, and keep the retract's sampled minimum (a plain sample and a decimated one alike). */
static inline void s_sample_done(vafm_sim *s, double force, int in_retract)
{
    s->sample_index++;
    s->clock_samples = s->scene_samples;
    if (in_retract) {
        s->retract_samples++;
        if (force < s->sample_min_force)
            s->sample_min_force = force;
    }
}

/* sim_segments.c: a list run's sample boundary (force: the sample's, reduced); a segment's decimation: add
 * block slot j to the running sums (@return 1 once the output sample is complete), then write it to slot j. */
void vafm_sim_list_logic(vafm_sim *s, double force);
/* Enter segment i of the list at this boundary (first: the run's start, whose speed sim.c's s_begin set). */
void vafm_sim_list_enter(vafm_sim *s, size_t i, double force, int first);
int vafm_sim_dec_add(vafm_sim *s, size_t j, double force);
void vafm_sim_dec_emit(vafm_sim *s, size_t j, int seg, int in_retract);

/** The exact contact-well step over the current sample interval (sim_well.c), when it applies.
 *  @return 1 if the interval was done this way, 0 if it does not apply (nothing changed). */
int vafm_sim_well_interval(vafm_sim *s);

#endif
