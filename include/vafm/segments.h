/* SPDX-License-Identifier: MIT */
/**
 * @file segments.h
 * Programmable force curves (JPK's segment editor, Asylum's force ramp designer): a run is a list of
 * segments, each an extend or a retract (by a distance, or until a trigger, at a speed), a pause (at
 * constant height or constant force, for a time) or a modulation (a sine on Z), with its own sample rate
 * and its own trigger on force, deflection (V), height or time with > or <.
 *
 * Today's force curve is one such list (vafm_segments_from_params): run through vafm_sim_segments_begin
 * it gives the curve of vafm_sim_curve_begin bit for bit, every channel and the result. Other lists run on
 * the same machinery (integrator, exact free and well steps, piezo model, drift).
 *
 * Every output sample carries its segment in vafm_samples.segment: the segment's label, by default its
 * position in the list (0, 1, 2, …: afmformats' multi-segment convention, protocol/hdf5.md). The core does
 * no I/O: a JSON list is parsed outside it (src/record, vafm_segments_from_json).
 */
#ifndef VAFM_SEGMENTS_H
#define VAFM_SEGMENTS_H

#include "vafm/common.h"
#include "vafm/params.h"
#include "vafm/sim.h"

#ifdef __cplusplus
extern "C" {
#endif

/** The most segments of a list (labels fit a uint8 channel; the list is copied into the simulation). */
#define VAFM_SEGMENTS_MAX 64
/** The largest decimation of a segment's sample rate (scene rate / segment rate). */
#define VAFM_SEGMENT_DECIMATION_MAX 65536

/** What a segment does. */
enum vafm_segment_kind {
    VAFM_SEGMENT_EXTEND = 0,   /**< the piezo moves toward the sample at speed_m_per_s */
    VAFM_SEGMENT_RETRACT = 1,  /**< the piezo moves away from the sample at speed_m_per_s */
    VAFM_SEGMENT_PAUSE = 2,    /**< the piezo holds its height, or a feedback loop holds the force, duration_s */
    VAFM_SEGMENT_MODULATE = 3, /**< a sine on the piezo height about where the segment starts: height =
                                    h0 + amplitude_m·sin(2π·frequency_Hz·t), for duration_s */
};

/** The channel a trigger watches (each as the output sample shows it, filtered by the anti-alias filter,
 *  before the detector chain: noise, ADC and artefacts of vafm/detector.h are added downstream). */
enum vafm_segment_channel {
    VAFM_SEGMENT_TRIGGER_NONE = 0,         /**< no trigger */
    VAFM_SEGMENT_TRIGGER_FORCE = 1,        /**< force k·deflection, N, positive repulsive */
    VAFM_SEGMENT_TRIGGER_DEFLECTION_V = 2, /**< deflection signal, V: deflection / sensitivity_m_per_V +
                                                baseline_offset_V (as setpoint_V) */
    VAFM_SEGMENT_TRIGGER_HEIGHT = 3,       /**< piezo height (the command) above the contact point, m (as
                                                trigger_height_m: decreases toward the sample) */
    VAFM_SEGMENT_TRIGGER_TIME = 4,         /**< time since the segment began, s (op must be '>') */
};

/** A trigger's comparison: it fires at the first sample whose value reaches the threshold. */
enum vafm_segment_op {
    VAFM_SEGMENT_ABOVE = 0, /**< '>': value ≥ threshold */
    VAFM_SEGMENT_BELOW = 1, /**< '<': value ≤ threshold */
};

/** How an extend or a retract ends (besides its trigger). */
enum vafm_segment_end {
    VAFM_SEGMENT_END_TRAVEL = 0, /**< after distance_m of travel (with a trigger: at most that far) */
    VAFM_SEGMENT_END_DETACH = 1, /**< retract: today's curve: retract_margin_m past the last detachment, at most
                                      retract_max_m (0: 4× the travel to the quasi-static detachment) */
    VAFM_SEGMENT_END_START = 2,  /**< retract: back to the run's start height (a fixed ramp, ramp_size_m) */
};

/** What a pause holds. */
enum vafm_pause_mode {
    VAFM_PAUSE_HEIGHT = 0, /**< constant height: the piezo stands still */
    VAFM_PAUSE_FORCE = 1,  /**< constant force: an integral loop on the output force moves the piezo,
                                dz/dt = (F_hold − F)/(k·τ), once per sample */
};

/** One segment. Fields a kind does not use are ignored (and not validated). SI units. */
typedef struct vafm_segment_spec {
    int kind;                /**< enum vafm_segment_kind. Default EXTEND */
    double speed_m_per_s;    /**< extend, retract: piezo speed, m/s, in (0, 1e3]. Default 1e-6 */
    double distance_m;       /**< extend, retract with end TRAVEL: travel, m, in [0, 1e-3]; with a trigger the
                                  most it travels, and 0 on an extend means the scene's approach limit (z_range_m,
                                  or automatic; a fixed ramp's), counted from the run's start. Default 0 */
    int trigger;             /**< enum vafm_segment_channel. Default NONE */
    int trigger_op;          /**< enum vafm_segment_op. Default ABOVE */
    double trigger_value;    /**< the threshold in the channel's unit (N, V, m, s), finite, |value| ≤ 1 (force,
                                  height), ≤ 1e3 (V), in (0, 1e4] (time). Default 0 */
    int trigger_relative;    /**< force, deflection: 1 counts the threshold from the baseline, the mean of the
                                  segment's first VAFM_BASELINE_SAMPLES samples before the current one (the
                                  first sample cannot fire). Default 0 */
    int end;                 /**< extend, retract: enum vafm_segment_end (DETACH and START: retract only).
                                  Default TRAVEL */
    double duration_s;       /**< pause, modulate: duration, s, in [0, 1e4] (rounded to whole samples of the
                                  scene's rate; 0 skips the segment). Default 0 */
    int pause_mode;          /**< pause: enum vafm_pause_mode. Default HEIGHT */
    double hold_force_N;     /**< constant-force pause: the force held, N, |F| ≤ 1; NaN: the previous segment's
                                  force trigger level (its baseline added) if it ended on one, else the force
                                  of the pause's first sample. Default NaN */
    double feedback_s;       /**< constant-force pause: the loop's time constant τ, s (0: the scene's
                                  dwell_feedback_s rule; else ≥ 2 samples of the scene's rate, ≤ 1e4). Default 0 */
    double amplitude_m;      /**< modulate: amplitude, m, in (0, 1e-4]. Default 1e-9 */
    double frequency_Hz;     /**< modulate: frequency, Hz, in (0, rate/4] (≥ 4 samples a period at the scene's
                                  rate). Default 100 */
    double sample_rate_Hz;   /**< the segment's output rate, Hz: 0 the scene's sample_rate_Hz; else the scene's
                                  rate divided by a whole number d in [1, VAFM_SEGMENT_DECIMATION_MAX] (to 1e-9):
                                  the simulation and the triggers run at the scene's rate, and each output
                                  sample is the mean of d (antialias mean) or the last of d (point). Default 0 */
    int label;               /**< the value of the samples' segment channel: −1 its position in the list, else
                                  0–254. Default −1 */
    uint8_t reserved[32];
} vafm_segment_spec;

/** Fill g with the defaults above. */
VAFM_API void vafm_segment_spec_default(vafm_segment_spec *g);

/** Check a list against scene p (its sample rate, sensitivity): n in [1, VAFM_SEGMENTS_MAX], every field
 *  of every segment in its range. @return 0 or VAFM_EINVAL, err->field "segments[i].field" and a message
 *  naming the value and the allowed range. */
VAFM_API int vafm_segments_validate(const vafm_segment_spec *segs, size_t n, const vafm_params *p,
                                    vafm_error *err);

/** Today's force curve of scene p as a list: an extend at v_approach_m_per_s until the force trigger
 *  (setpoint_N, relative with setpoint_mode) or the height trigger (trigger_height_m), at most the scene's
 *  approach limit; a pause of dwell_s (if > 0) at dwell_mode; a retract at v_retract_m_per_s to the
 *  detachment plus retract_margin_m (a fixed ramp: to the start height). Labels 0, 2, 1 (approach, dwell,
 *  retract: the curve's segment channel). @return the number of segments written (2 or 3), or VAFM_EINVAL
 *  if cap is too small. */
VAFM_API int vafm_segments_from_params(const vafm_params *p, vafm_segment_spec *out, size_t cap);

/** Start run `index` (its random stream, as a curve's) of the list segs (copied; validated against the
 *  simulation's scene): the lever starts where the scene's curve starts (start_height_m, start_in_contact,
 *  the fixed ramp's start, the contact point's scatter, drift and piezo as a curve). vafm_sim_advance runs it;
 *  vafm_sim_result reports it as a curve (the retract observables from the retract segments).
 *  @return 0, or VAFM_EINVAL (vafm_sim_error names the segment and field). Since API 0.7. */
VAFM_API int vafm_sim_segments_begin(vafm_sim *s, uint64_t index, const vafm_segment_spec *segs, size_t n);

/** The list's segment the simulation is in (its position), or −1 when no list runs or it ended. */
VAFM_API int vafm_sim_segment_current(const vafm_sim *s);

/** The run's clock at its last output sample: the sample intervals of the scene's rate (sample_rate_Hz)
 *  from the scene's start to the end of the last output sample handed to the callback (0 before the
 *  first, or without a scene). The simulated time of the samples so far is this / sample_rate_Hz, whatever
 *  the segments' output rates: a segment decimated by d adds d a sample (its last sample, what it gathered
 *  when the segment ended). At the scene's rate (a plain curve, a tune, a live scene) it is the number of
 *  output samples. For a caller that paces the output to real time (vafmd). Since API 0.8. */
VAFM_API uint64_t vafm_sim_clock_samples(const vafm_sim *s);

/** Run a list to the end (vafm_sim_segments_begin, then vafm_sim_advance). fn may be NULL.
 *  @return 0 or a negative VAFM_E* code. */
VAFM_API int vafm_sim_segments(vafm_sim *s, uint64_t index, const vafm_segment_spec *segs, size_t n,
                               vafm_sample_fn fn, void *user, vafm_curve_result *out);

#ifdef __cplusplus
}
#endif
#endif
