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
 * Pure computation: no allocation, no I/O; the caller owns the state.
 */
#ifndef VAFM_DETECTOR_H
#define VAFM_DETECTOR_H

#include <stdint.h>
#include "vafm/common.h"
#include "vafm/params.h"
#include "vafm/rng.h"

#ifdef __cplusplus
extern "C" {
#endif

/** The detector noise stream's key is seed ^ this constant ("DETECTR"). */
#define VAFM_DETECTOR_KEY UINT64_C(0x0044455445435452)

/** The state of one curve's measured chain (caller-owned; vafm_detector_begin fills it). */
typedef struct vafm_detector {
    int on;              /**< 0: the chain changes nothing (no noise, no ADC, no offset) */
    double sens;         /**< sensitivity, m/V */
    double noise;        /**< noise floor, V rms */
    double offset;       /**< baseline offset, V */
    double k;            /**< spring constant, N/m */
    double q;            /**< ADC step, V (0: no ADC) */
    double code_min, code_max; /**< ADC code range */
    int clipped;         /**< 1 once a sample saturated the ADC */
    vafm_rng rng;        /**< the noise stream */
} vafm_detector;

/** @return 1 when the scene's detector settings change the signal (noise, ADC or offset), else 0. */
VAFM_API int vafm_detector_on(const vafm_params *p);

/** Start the measured chain of curve `index` of scene p (its detector settings, seed and spring
 *  constant). */
VAFM_API void vafm_detector_begin(vafm_detector *d, const vafm_params *p, uint64_t index);

/** One sample: the true deflection (m) in; the detector voltage (V), the measured deflection (m) and
 *  force (N) out. With the chain off: volts = deflection / sensitivity, the rest unchanged. Any output
 *  pointer may be NULL. */
VAFM_API void vafm_detector_apply(vafm_detector *d, double deflection_m, double *volts, double *deflection_out,
                                  double *force_out);

#ifdef __cplusplus
}
#endif
#endif
