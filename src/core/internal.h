/* SPDX-License-Identifier: MIT */
/*
 * Internal helpers shared by the core's files (not installed).
 *
 * vafm_numerics is everything a scene derives from its SI parameters before it runs: the reduced
 * model, the bound contact model, the stiffest contact the scene is expected to reach and from it the
 * time step and its stability number. params.c validates a scene through vafm_numerics_check(), and
 * sim.c builds its kernel from the same numbers, so the check and the run can never disagree.
 */
#ifndef VAFM_CORE_INTERNAL_H
#define VAFM_CORE_INTERNAL_H

#include "vafm/common.h"
#include "vafm/contact.h"
#include "vafm/params.h"
#include "vafm/sim.h"
#include "vafm/units.h"

#if defined(__GNUC__)
#define VAFM_PRINTF(a, b) __attribute__((format(printf, a, b)))
#else
#define VAFM_PRINTF(a, b)
#endif

/** Fill err (if not NULL) with a code, a field and a formatted message. */
void vafm_err_set(vafm_error *err, int code, const char *field, const char *fmt, ...) VAFM_PRINTF(4, 5);

/** Append formatted text at buf + *n (buf holds len bytes, NUL-terminated) and advance *n.
 *  @return 0, or VAFM_EINVAL if it does not fit (or fails): the text written so far is cut there. */
int vafm_buf_appendf(char *buf, size_t len, size_t *n, const char *fmt, ...) VAFM_PRINTF(4, 5);

typedef struct vafm_numerics {
    vafm_reduced r;       /* the physics in reduced units */
    vafm_scale sc;        /* reduced → SI */
    vafm_contact contact; /* the bound contact model */
    double Ts;            /* output sample interval (reduced time) */
    double F_max;         /* largest repulsive contact force the scene is expected to reach */
    double K_max;         /* k + dF/du there: the stiffest total stiffness */
    double u_deep;        /* indentation at 4·F_max: the range the contact table covers */
    double u_c;           /* spring travel from the turn to the quasi-static detachment */
    double u_spr_star;    /* quasi-static instability (NaN without adhesion) */
    double dt;            /* time step (reduced), a whole fraction of Ts */
    long n_sub;           /* steps per output sample */
    double stab;          /* ω_max·dt (underdamped) or K_max·dt/ζ (overdamped) */
    double dt_far;        /* the larger step far from the instability (= dt without adaptation) */
    long n_sub_far;       /* steps per output sample there */
    double y_near;        /* spring distance u_spr − u_spr* below which the retract is "near" */
    double u_soft;        /* indentation where the branch's stiffness vanishes (JKR force minimum) */
    double u_spr_turn;    /* spring position where the approach is expected to turn (the trigger) */
} vafm_numerics;

/** Derive the numerics of a scene and check them (time step against the stability limit, step count).
 *  out may be NULL. @return 0 or VAFM_EUNSTABLE / VAFM_EINVAL with err filled. */
int vafm_numerics_check(const vafm_params *p, vafm_numerics *out, vafm_error *err);
/** vafm_numerics_check for a force curve (tune_scene 0) or for a scene that runs thermal tunes only
 *  (vafm_sim_new_tune): there the curve's cost limits give way to the tune's (vafm_numerics_check_tune). */
int vafm_numerics_check_scene(const vafm_params *p, vafm_numerics *out, int tune_scene, vafm_error *err);
/** vafm_params_validate of a curve scene (tune_scene 0) or of a tune-only scene (vafm_numerics_check_scene). */
int vafm_params_validate_scene(const vafm_params *p, int tune_scene, vafm_error *err);

/** The JKR solver (contact_jkr.c): √a(u) on the physical branch (reduced), for u ≥ u_min; NaN below.
 *  s_guess ≤ 0: cold start. Internal (the tests reach it through the static core). */
double vafm_jkr_sqrt_a(double c, double s_m, double u, double s_guess);

/** A thermal tune of the scene within VAFM_SIM_MAX_SAMPLES and VAFM_SIM_MAX_STEPS? @return 0 or
 *  VAFM_EINVAL naming tune_duration_s (and the rate to lower: tune_rate_Hz for a tune scene, tune_scene 1,
 *  else sample_rate_Hz). (Checked when a tune starts, and by vafm_sim_new_tune, not by validation: a scene
 *  for fast curves at a high sample rate is valid though its default tune would not be.) */
int vafm_numerics_check_tune(const vafm_params *p, const vafm_numerics *nm, int tune_scene, vafm_error *err);

/** vafm_sim_live_begin whose lever, with in_contact 1, starts at equilibrium on the contact branch even with the
 *  support above the surface (an adhesive contact held there: the state vafm_ctrl_carry hands on; the thermal
 *  draw may still take it off the branch). in_contact 0 is vafm_sim_live_begin. (sim.c) */
int vafm_sim_live_begin_contact(vafm_sim *s, uint64_t stream, double height0_m, int in_contact, vafm_live_fn fn,
                                void *user);

/** Hand a running live scene to another commander (its lever's state and stream go on; vafm_ctrl_carry). */
void vafm_sim_live_commander(vafm_sim *s, vafm_live_fn fn, void *user);

/** The cost estimate of a scene from its numerics (vafm_sim_estimate). */
void vafm_numerics_estimate(const vafm_params *p, const vafm_numerics *nm, vafm_sim_estimate *out);

#endif
