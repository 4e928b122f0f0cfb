/* SPDX-License-Identifier: MIT */
/* The measured chain (vafm/detector.h). The operations and their order are vafmd's since 0.2 (a
 * division by the sensitivity, then offset, noise, rounding to the ADC code, clipping, back to metres
 * and newtons), so its streams are unchanged bit for bit. */
#include <math.h>
#include <string.h>
#include "vafm/detector.h"

int vafm_detector_on(const vafm_params *p)
{
    return p->noise_V_rms > 0 || p->adc_bits > 0 || p->baseline_offset_V != 0;
}

void vafm_detector_begin(vafm_detector *d, const vafm_params *p, uint64_t index)
{
    memset(d, 0, sizeof *d);
    d->on = vafm_detector_on(p);
    d->sens = p->sensitivity_m_per_V;
    d->noise = p->noise_V_rms;
    d->offset = p->baseline_offset_V;
    d->k = p->k_N_per_m;
    if (p->adc_bits > 0) {
        d->q = ldexp(p->adc_range_V, -p->adc_bits);
        d->code_max = ldexp(1.0, p->adc_bits - 1) - 1;
        d->code_min = -ldexp(1.0, p->adc_bits - 1);
    }
    if (d->on)
        vafm_rng_init(&d->rng, p->seed ^ VAFM_DETECTOR_KEY, index);
}

void vafm_detector_apply(vafm_detector *d, double deflection_m, double *volts, double *deflection_out,
                         double *force_out)
{
    /* a division, not a multiplication by the inverse: bit-exact with deflection / sensitivity */
    double v = deflection_m / d->sens;
    if (!d->on) {
        if (volts)
            *volts = v;
        return;
    }
    v += d->offset;
    if (d->noise > 0)
        v += d->noise * vafm_rng_normal(&d->rng);
    if (d->q > 0) {
        double code = floor(v / d->q + 0.5);
        if (code > d->code_max) {
            code = d->code_max;
            d->clipped = 1;
        } else if (code < d->code_min) {
            code = d->code_min;
            d->clipped = 1;
        }
        v = code * d->q;
    }
    double defl = v * d->sens;
    if (volts)
        *volts = v;
    if (deflection_out)
        *deflection_out = defl;
    if (force_out)
        *force_out = d->k * defl;
}
