/* SPDX-License-Identifier: MIT */
/**
 * @file detector.h
 * The measured chain: what an AFM controller records of the cantilever's deflection. The photodiode
 * signal vDeflection = deflection / sensitivity (InvOLS) + baseline offset + white noise, digitised by an
 * ADC of adc_bits over adc_range_V (codes saturate at its ends: "clipped"), then turned back into the
 * measured deflection (× sensitivity) and force (× k), as instrument software does. One stage for every
 * program (vafmd's stream and log, `vafm samples`, `vafm campaign` files), so they record the same.
 *
 * Its noise has its own random stream, Philox stream `index` of the key seed ^ VAFM_DETECTOR_KEY: the
 * physics samples do not depend on whether the detector is on, and (seed, index) reproduces both. With
 * every setting at its default (no noise, no ADC, no offset) the stage is off and changes nothing.
 *
 * The instrument's artefacts of the signal (issue #14) live here too, each off at 0 and each with its own
 * stream: a baseline that drifts (linear, V/s, and a random walk, V/√s), virtual deflection (a slope in V
 * per m of piezo height), laser interference (A sin(2π h/P + φ), φ random per curve), 1/f noise (a bank of
 * AR(1) processes, three per decade from 1 mHz to the corner, weighted so that the one-sided spectrum is
 * S_w·f_c/f with S_w = 2·noise²/f_s the white floor's), mains pickup (50/60 Hz and harmonics 2, 3 at 1/2 and
 * 1/3 of its amplitude, random phases per curve).
 * Pure computation: no allocation, no I/O; the caller owns the state.
 */
#ifndef VAFM_DETECTOR_H
#define VAFM_DETECTOR_H

#include <stdint.h>
#include "vafm/common.h"
#include "vafm/params.h"
#include "vafm/rng.h"
#include "vafm/sim.h"

#ifdef __cplusplus
extern "C" {
#endif

/** The detector noise stream's key is seed ^ this constant ("DETECTR"). */
#define VAFM_DETECTOR_KEY UINT64_C(0x0044455445435452)
/** The artefacts' streams (each its own, so that turning one on changes nothing else): seed ^ these. */
#define VAFM_ARTEFACT_WALK_KEY UINT64_C(0x0041524457414c4b)    /**< "ARDWALK": baseline random walk */
#define VAFM_ARTEFACT_FLICKER_KEY UINT64_C(0x0041524631464e53) /**< "ARF1FNS": 1/f noise */
#define VAFM_ARTEFACT_PHASE_KEY UINT64_C(0x0041525048415345)   /**< "ARPHASE": mains and interference phases */
#define VAFM_ARTEFACT_SAMPLE_KEY UINT64_C(0x00415253414d504c)  /**< "ARSAMPL": the curve's contact point */
#define VAFM_ARTEFACT_ZSENSOR_KEY UINT64_C(0x00415a53454e534f) /**< "AZSENSO": the z sensor's noise */

/** Poles of the 1/f noise: three per decade from 1 mHz to the corner (at most 40). */
#define VAFM_FLICKER_POLES_MAX 40

/** The state of one curve's measured chain (caller-owned; vafm_detector_begin fills it). */
typedef struct vafm_detector {
    int on;              /**< 0: the chain changes nothing (no noise, no ADC, no offset, no artefact) */
    double sens;         /**< sensitivity, m/V */
    double noise;        /**< noise floor, V rms */
    double offset;       /**< baseline offset, V */
    double k;            /**< spring constant, N/m */
    double q;            /**< ADC step, V (0: no ADC) */
    double code_min, code_max; /**< ADC code range */
    int clipped;         /**< 1 once a sample saturated the ADC */
    vafm_rng rng;        /**< the noise stream */
    /* artefacts of the signal (params.h): drift, virtual deflection, interference, 1/f noise, mains */
    int artefacts;       /**< 1: at least one of them is on */
    double drift, walk_sigma, walk, walk_t, vdefl;
    double interf_amp, interf_k, interf_phase;
    double mains_amp, mains_w, mains_phase[3];
    int n_poles;                               /**< 1/f: first-order (AR(1)) processes in the bank */
    double pole_a[VAFM_FLICKER_POLES_MAX];     /**< per-sample decay e^{−2π f_j / f_s} */
    double pole_c[VAFM_FLICKER_POLES_MAX];     /**< innovation sd σ√(1 − a²) */
    double pole_x[VAFM_FLICKER_POLES_MAX];     /**< state, V */
    vafm_rng rng_walk, rng_flicker;
    /* the closed-loop z sensor: white noise and a first-order bandwidth on the measured height */
    double zs_noise, zs_bw, zs_y, zs_t;
    int zs_on;
    vafm_rng rng_zs;
} vafm_detector;

/** @return 1 when the scene's detector settings change the signal (noise, ADC, offset or an artefact of the
 *  signal), else 0. */
VAFM_API int vafm_detector_on(const vafm_params *p);
/** @return 1 when a curve's measured height differs from its piezo command (height_m): the piezo's hysteresis
 *  or creep (the simulation's vafm_samples.height_measured_m) or a z sensor (vafm_detector_height). */
VAFM_API int vafm_detector_height_differs(const vafm_params *p);
/** Start the measured chain of curve `index` of scene p (its detector and artefact settings, seed, spring
 *  constant and sample rate). */
VAFM_API void vafm_detector_begin(vafm_detector *d, const vafm_params *p, uint64_t index);
/** One sample at time t_s and piezo height height_m (as the curve reports them): the true deflection (m)
 *  in; the detector voltage (V), the measured deflection (m) and force (N) out. The voltage is
 *  deflection / sensitivity + offset + drift·t + walk(t) + virtual deflection·height + interference(height)
 *  + mains(t) + white noise + 1/f noise, then the ADC. With the chain off: volts = deflection / sensitivity,
 *  the rest unchanged. Any output pointer may be NULL. Samples come in time order. */
VAFM_API void vafm_detector_apply(vafm_detector *d, double t_s, double height_m, double deflection_m, double *volts,
                                  double *deflection_out, double *force_out);

/** The z sensor's reading at time t_s of the piezo's actual height (m; vafm_samples.height_measured_m, or
 *  height_m for an ideal piezo): a first-order low-pass of zsensor_bandwidth_Hz (from the first sample on)
 *  plus white noise of zsensor_noise_m rms from its own stream. Unchanged without a z-sensor setting. */
VAFM_API double vafm_detector_height(vafm_detector *d, double t_s, double height_m);

/** Sample i of a block through the measured chain: the one function every recorder of measured signals
 *  calls (vafmd's stream and log, `vafm samples`, `vafm campaign` files), so that they record the same.
 *  With the chain on: vafm_detector_apply's volts, deflection and force; off: the block's deflection and
 *  force unchanged and volts = deflection / d->sens. The measured height is vafm_detector_height of the
 *  piezo's actual height (b->height_measured_m, or b->height_m). Any output pointer may be NULL: its stage is
 *  skipped (the z sensor's noise stream advances only when the height is asked for); a block without a
 *  deflection array (a replayed file) leaves deflection and volts untouched. */
VAFM_API void vafm_detector_sample(vafm_detector *d, const vafm_samples *b, size_t i, double *volts,
                                   double *deflection_m, double *force_N, double *height_measured_m);

/** The contact point of curve `index`: the height of the sample surface above the reference plane at t = 0,
 *  m: surface_height_m plus, with contact_point_sd_m > 0, a normal deviate of that sd from the curve's own
 *  stream (VAFM_ARTEFACT_SAMPLE_KEY). */
VAFM_API double vafm_artefact_contact_point(const vafm_params *p, uint64_t index);

#ifdef __cplusplus
}
#endif
#endif
