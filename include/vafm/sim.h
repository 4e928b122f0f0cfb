/* SPDX-License-Identifier: MIT */
/**
 * @file sim.h
 * The simulation object and its scenes: a force curve (approach → trigger → dwell → retract) and a
 * thermal tune (free cantilever at rest). Scenes are resumable state machines so that a paced caller
 * (the daemon) can advance them block by block; vafm_sim_curve() runs one to the end.
 *
 * Output channels, per sample (SI): time, piezo height (decreases toward the sample), deflection
 * (positive away from the sample), force = k·deflection (positive repulsive), true tip position
 * (= height + deflection, the tip's height above the undeformed surface) and segment.
 * The simulation does no I/O: samples go to a caller's sink callback in blocks.
 */
#ifndef VAFM_SIM_H
#define VAFM_SIM_H

#include "vafm/common.h"
#include "vafm/params.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct vafm_sim vafm_sim;

/** Segment labels of a force curve (the afmformats convention, plus dwell = 2, vafm's choice). */
enum vafm_segment { VAFM_SEG_APPROACH = 0, VAFM_SEG_RETRACT = 1, VAFM_SEG_DWELL = 2, VAFM_SEG_TUNE = 3,
                   VAFM_SEG_LIVE = 4 /**< the live scene (vafm_sim_live_begin) */ };

/** A block of output samples. Arrays are owned by the simulation and valid during the callback. */
typedef struct vafm_samples {
    size_t n;                   /**< number of samples in the block */
    uint64_t first;             /**< index of the first sample in the run */
    const double *time_s;       /**< time since the run started, s */
    const double *height_m;     /**< piezo height above the contact point, m */
    const double *deflection_m; /**< cantilever deflection, m, positive away from the sample */
    const double *force_N;      /**< k·deflection, N, positive repulsive */
    const double *tip_m;        /**< true tip height above the undeformed surface, m */
    const uint8_t *segment;     /**< enum vafm_segment */
    const double *height_measured_m; /**< the piezo's height as its z sensor reads it, m, as height_m: from the
                                          simulation, where the actuator actually is (hysteresis, creep: an
                                          ideal sensor), through vafm_detector_height for a real one; NULL:
                                          equal to height_m (an ideal piezo) */
} vafm_samples;

/** Receives sample blocks. @return 0 to go on, non-zero to stop the run (VAFM_EABORT). */
typedef int (*vafm_sample_fn)(void *user, const vafm_samples *block);

/** Flags of a curve result. */
enum vafm_curve_flag {
    VAFM_CURVE_NO_CONTACT = 1,      /**< the body never touched the sample */
    VAFM_CURVE_EARLY_DETACH = 2,    /**< contact was lost before the retract began (thermal escape) */
    VAFM_CURVE_NO_DETACH = 4,       /**< still in contact at the retract travel limit */
    VAFM_CURVE_NO_TRIGGER = 8,      /**< the approach reached z_range_m without the trigger */
    VAFM_CURVE_RECONTACT = 16,      /**< the body touched again during the retract after detaching */
};

/** Per-curve observables (physics notes, "what pull-off force means"). Forces: tensile magnitudes
 *  (positive numbers), N. Heights: piezo heights above the contact point, m. */
typedef struct vafm_curve_result {
    uint64_t index;           /**< curve index (the RNG stream) */
    int flags;                /**< enum vafm_curve_flag, or-ed */
    double pulloff_sampled_N; /**< 1: most tensile output sample of the retract (what a user reads) */
    double pulloff_spring_N;  /**< 2: most tensile spring force of any step of the retract */
    double detach_force_N;    /**< 3: spring force when the body passed u_detach (last detachment) */
    double detach_height_m;   /**< 3: piezo height then */
    double detach_eq_force_N; /**< 4: noise-free equilibrium spring force at that piezo height
                                   (NaN where no equilibrium exists: beyond the instability) */
    double detach_time_s;     /**< time from the start of the retract to the detachment, s */
    double touch_time_s;      /**< time of the first touch, s (NaN: none) */
    double touch_height_m;    /**< piezo height at the first touch, m */
    double retract_start_s;   /**< time the retract began, s */
    double duration_s;        /**< simulated duration of the curve, s */
    uint64_t samples;         /**< output samples written */
    uint64_t steps;           /**< integrator steps taken (all kinds) */
    uint64_t steps_contact;   /**< of which in contact */
    uint64_t steps_free;      /**< of which exact free-cantilever steps */
    double surface_height_m;  /**< the curve's contact point above the reference plane at t = 0, m
                                   (surface_height_m plus the random contact point, contact_point_sd_m) */
} vafm_curve_result;

/** Create a simulation for a validated scene. @return 0, VAFM_EINVAL/VAFM_EUNSTABLE (err filled) or
 *  VAFM_ENOMEM. On success *out is owned by the caller (vafm_sim_destroy). */
/** The most output samples a curve or a thermal tune may have (2^25 = 33,554,432: a 3.4 s curve at
 *  8 MS/s has 27 M; the CLI keeps a campaign curve's samples in memory at 41 bytes each, 1.4 GB here).
 *  vafm_params_validate refuses a scene whose typical curve (vafm_sim_estimate) or tune exceeds it. */
#define VAFM_SIM_MAX_SAMPLES ((uint64_t)1 << 25)
/** The most integrator steps a typical curve or tune may take (hours of CPU at ~35 ns a step). */
#define VAFM_SIM_MAX_STEPS 1e12

/** What a curve and a thermal tune of a scene cost, estimated before running them. */
typedef struct vafm_sim_estimate {
    double duration_s;     /**< simulated duration of a typical curve: approach to the expected trigger,
                                dwell, retract to the quasi-static detachment and the margin, s */
    double duration_max_s; /**< the longest a curve can run (approach to its travel limit, retract to
                                retract_max_m or the automatic limit), s */
    double samples;        /**< output samples of a typical curve */
    double samples_max;    /**< output samples of the longest curve */
    double steps;          /**< integrator steps of a typical curve at the plain step (the exact free and
                                well steps take fewer) */
    double tune_samples;   /**< output samples of a thermal tune (tune_duration_s) */
    double tune_steps;     /**< integrator steps of a thermal tune at the plain step */
    uint8_t reserved[32];
} vafm_sim_estimate;

/** Estimate a scene's cost without running it (no allocation). @return 0, or the scene's validation
 *  error (out is filled whenever the numerics could be derived). */
VAFM_API int vafm_sim_estimate_cost(const vafm_params *p, vafm_sim_estimate *out, vafm_error *err);

VAFM_API int vafm_sim_new(vafm_sim **out, const vafm_params *p, vafm_error *err);

/** Create a simulation for thermal tunes of scene p. It runs p's tune scene (vafm_params_tune_scene: the
 *  sample rate tune_rate_Hz, or sample_rate_Hz raised to show the resonance), checked as vafm_sim_new checks
 *  a scene, except that a force curve's cost limits, which depend on the speeds and grow with the rate, give
 *  way to the tune's own: tune_duration_s at the tune's rate within VAFM_SIM_MAX_SAMPLES and
 *  VAFM_SIM_MAX_STEPS (VAFM_EINVAL naming tune_duration_s and tune_rate_Hz). vafm_sim_tune_begin runs on
 *  it; vafm_sim_curve_begin refuses (VAFM_EINVAL). @return as vafm_sim_new. */
VAFM_API int vafm_sim_new_tune(vafm_sim **out, const vafm_params *p, vafm_error *err);

/** Destroy a simulation; NULL-safe; sets *s to NULL. */
VAFM_API void vafm_sim_destroy(vafm_sim **s);

/** The scene the simulation was built with (a copy). */
VAFM_API const vafm_params *vafm_sim_params(const vafm_sim *s);

/** The time step in use, s, and whether out-of-contact steps are exact. */
VAFM_API double vafm_sim_dt(const vafm_sim *s);

/** Controller fault injection (a trigger that never fires): with enabled = 0 the curves begun afterwards
 *  ignore their trigger, the approach runs to its travel limit (z_range_m, or the ramp size) and the curve
 *  is flagged VAFM_CURVE_NO_TRIGGER. Default 1. @return 0 or VAFM_EINVAL. */
VAFM_API int vafm_sim_set_trigger(vafm_sim *s, int enabled);

/** Start force curve `index` (its random stream). Any running scene is discarded. */
VAFM_API int vafm_sim_curve_begin(vafm_sim *s, uint64_t index);

/** Start a thermal tune (free cantilever, piezo at start height) of p->tune_duration_s. */
VAFM_API int vafm_sim_tune_begin(vafm_sim *s, uint64_t index);

/** The live scene's Philox key: seed ^ this constant ("LIVESCN"), so that its stream is none of the curves'. */
#define VAFM_SIM_LIVE_KEY UINT64_C(0x004c49564553434e)

/** One output sample of the live scene as its commander sees it (SI; as vafm_samples). */
typedef struct vafm_live_sample {
    uint64_t index;      /**< sample index since vafm_sim_live_begin */
    double time_s;       /**< time since vafm_sim_live_begin, s (the sample's own time: mid-interval for the
                              mean anti-alias filter, the interval's end otherwise) */
    double height_m;     /**< the support's (undeflected tip's) height above the local surface, m */
    double deflection_m; /**< cantilever deflection, m, positive away from the sample */
    double force_N;      /**< k·deflection, N, positive repulsive */
    double tip_m;        /**< the tip's height above the undeformed local surface, m */
    int in_contact;      /**< 1 if the tip touches the surface at the interval's end */
} vafm_live_sample;

/** The live scene's commander: called at every sample boundary (after the sample is made, before it is
 *  handed to the sink) with that sample. @return the support's height above the local surface at the end
 *  of the next sample interval, m (the support moves there at a constant speed: a change of the surface
 *  under the tip, as an XY move over topography, is a change of this height); NaN ends the scene.
 *  It runs on the advancing thread and must not block. */
typedef double (*vafm_live_fn)(void *user, const vafm_live_sample *smp);

/** Start the live scene (the always-on controller's lever, vafm/ctrl.h): the support at height0_m above
 *  the local surface, the lever at thermal equilibrium there (in contact at equilibrium when height0_m ≤ 0
 *  on a surface model), random stream `stream` of seed ^ VAFM_SIM_LIVE_KEY. It runs until fn returns NaN;
 *  the lever's state carries from one sample to the next. Far from the surface (the gap beyond the
 *  deterministic excursion plus 8 thermal standard deviations over the whole interval) a sample is one exact
 *  free transition (a few normal draws); near or in contact the curve's machinery (integrator, exact well
 *  step) runs. No piezo model, drift or contact-point scatter: the commander owns the geometry. Segment
 *  VAFM_SEG_LIVE. Any running scene is discarded.
 *  @return 0, or VAFM_EINVAL (no fn, height0_m not finite, or a tune-only simulation). */
VAFM_API int vafm_sim_live_begin(vafm_sim *s, uint64_t stream, double height0_m, vafm_live_fn fn, void *user);

/** Advance the running scene by up to max_samples output samples, handing them to fn (may be NULL).
 *  Never allocates. @return 1 while the scene goes on, 0 when it ended, or a negative VAFM_E* code. */
VAFM_API int vafm_sim_advance(vafm_sim *s, size_t max_samples, vafm_sample_fn fn, void *user);

/** vafm_sim_advance() that also returns after at most max_steps integrator steps (an exact free step or
 *  an exact well step counts as one; a sample of those is finished once started), if need be inside an
 *  output sample: the next call (of either function) goes on
 *  from there, and the samples are the same bit for bit however the work is split. For callers that
 *  must come back within a bounded time (vafmd releases blocks between pieces of work: one output sample
 *  can span ~25 000 steps, ~1 ms). max_steps = 0 returns at once. Since API 0.3. @return as
 *  vafm_sim_advance(). */
VAFM_API int vafm_sim_advance_steps(vafm_sim *s, size_t max_samples, uint64_t max_steps, vafm_sample_fn fn,
                                    void *user);

/** Detail of the error that ended the last scene (field and message), or NULL if it did not fail. */
VAFM_API const vafm_error *vafm_sim_error(const vafm_sim *s);

/** The result of the last (or running) curve. */
VAFM_API int vafm_sim_result(const vafm_sim *s, vafm_curve_result *out);

/** Run force curve `index` to the end. fn may be NULL. @return 0 or a negative VAFM_E* code. */
VAFM_API int vafm_sim_curve(vafm_sim *s, uint64_t index, vafm_sample_fn fn, void *user,
                            vafm_curve_result *out);

/** Run a thermal tune to the end. */
VAFM_API int vafm_sim_tune(vafm_sim *s, uint64_t index, vafm_sample_fn fn, void *user);

#ifdef __cplusplus
}
#endif
#endif
