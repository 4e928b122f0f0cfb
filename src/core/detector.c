/* SPDX-License-Identifier: MIT */
/* The measured chain (vafm/detector.h). The operations and their order are vafmd's since 0.2 (a
 * division by the sensitivity, then offset, noise, rounding to the ADC code, clipping, back to metres
 * and newtons), so its streams are unchanged bit for bit; the artefacts (0.5) add their terms after the
 * offset and before the white noise, each only when it is on, so that a scene without them is unchanged. */
#include <math.h>
#include <string.h>
#include "vafm/detector.h"

/* 1/f noise: poles from 1 mHz up to ten times the corner (so that the spectrum is 1/f through the corner,
 * where it meets the white floor), at most the Nyquist frequency; three per decade keep the ripple of the
 * sum of Lorentzians about the 1/f line below 1%. */
#define S_FLICKER_F_LOW 1e-3
#define S_FLICKER_PER_DECADE 3

static int s_artefacts_on(const vafm_params *p)
{
    return p->drift_V_per_s != 0 || p->drift_walk_V_per_sqrt_s > 0 || p->virtual_deflection_V_per_m != 0 ||
           p->interference_V > 0 || p->flicker_corner_Hz > 0 || p->mains_V > 0;
}

static int s_zsensor_on(const vafm_params *p)
{
    return p->zsensor_noise_m > 0 || p->zsensor_bandwidth_Hz > 0;
}

int vafm_detector_on(const vafm_params *p)
{
    return p->noise_V_rms > 0 || p->adc_bits > 0 || p->baseline_offset_V != 0 || s_artefacts_on(p) ||
           s_zsensor_on(p);
}

int vafm_detector_height_differs(const vafm_params *p)
{
    return p->piezo_hysteresis > 0 || p->piezo_creep > 0 || s_zsensor_on(p);
}

/* The AR(1) bank of the 1/f noise. A first-order process of rate λ = 2π f_j and variance σ² has the one-sided
 * spectrum (2σ²/π)·f_j/(f_j² + f²); poles spaced by a factor r in frequency sum to σ²/(f·ln r) between the
 * lowest and the highest, so σ² = S_w·f_c·ln r gives S_w·f_c/f. Each starts from its stationary law. */
static void s_flicker_begin(vafm_detector *d, const vafm_params *p)
{
    const double fs = p->sample_rate_Hz, S_w = 2.0 * p->noise_V_rms * p->noise_V_rms / fs;
    double f_top = fmin(10.0 * p->flicker_corner_Hz, 0.5 * fs);
    if (!(f_top > S_FLICKER_F_LOW))
        return;
    const double r = pow(10.0, 1.0 / S_FLICKER_PER_DECADE), sigma = sqrt(S_w * p->flicker_corner_Hz * log(r));
    int n = 0;
    for (double f = f_top; f >= S_FLICKER_F_LOW && n < VAFM_FLICKER_POLES_MAX; f /= r, n++) {
        double a = exp(-2.0 * M_PI * f / fs);
        d->pole_a[n] = a;
        d->pole_c[n] = sigma * sqrt(1.0 - a * a);
        d->pole_x[n] = sigma * vafm_rng_normal(&d->rng_flicker);
    }
    d->n_poles = n;
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
    d->artefacts = s_artefacts_on(p);
    d->drift = p->drift_V_per_s;
    d->vdefl = p->virtual_deflection_V_per_m;
    d->walk_sigma = p->drift_walk_V_per_sqrt_s;
    d->walk_t = NAN; /* the walk starts at 0 at the first sample */
    if (d->walk_sigma > 0)
        vafm_rng_init(&d->rng_walk, p->seed ^ VAFM_ARTEFACT_WALK_KEY, index);
    if (p->interference_V > 0 || p->mains_V > 0) {
        vafm_rng ph;
        vafm_rng_init(&ph, p->seed ^ VAFM_ARTEFACT_PHASE_KEY, index);
        d->interf_phase = 2.0 * M_PI * vafm_rng_uniform(&ph);
        for (int h = 0; h < 3; h++)
            d->mains_phase[h] = 2.0 * M_PI * vafm_rng_uniform(&ph);
    }
    if (p->interference_V > 0) {
        d->interf_amp = p->interference_V;
        d->interf_k = 2.0 * M_PI / p->interference_period_m;
    }
    if (p->mains_V > 0) {
        d->mains_amp = p->mains_V;
        d->mains_w = 2.0 * M_PI * p->mains_Hz;
    }
    if (s_zsensor_on(p)) {
        d->zs_on = 1;
        d->zs_noise = p->zsensor_noise_m;
        d->zs_bw = p->zsensor_bandwidth_Hz;
        d->zs_t = NAN;
        if (d->zs_noise > 0)
            vafm_rng_init(&d->rng_zs, p->seed ^ VAFM_ARTEFACT_ZSENSOR_KEY, index);
    }
    if (p->flicker_corner_Hz > 0 && p->noise_V_rms > 0) {
        vafm_rng_init(&d->rng_flicker, p->seed ^ VAFM_ARTEFACT_FLICKER_KEY, index);
        s_flicker_begin(d, p);
    }
}

/* The artefacts' part of the signal at (t, h), V; advances the random walk and the 1/f bank by one sample. */
static double s_artefacts(vafm_detector *d, double t, double h)
{
    double v = 0.0;
    if (d->drift != 0)
        v += d->drift * t;
    if (d->walk_sigma > 0) {
        if (!isnan(d->walk_t) && t > d->walk_t)
            d->walk += d->walk_sigma * sqrt(t - d->walk_t) * vafm_rng_normal(&d->rng_walk);
        d->walk_t = t;
        v += d->walk;
    }
    if (d->vdefl != 0)
        v += d->vdefl * h;
    if (d->interf_amp > 0)
        v += d->interf_amp * sin(d->interf_k * h + d->interf_phase);
    if (d->mains_amp > 0)
        for (int n = 1; n <= 3; n++)
            v += d->mains_amp / n * sin(n * d->mains_w * t + d->mains_phase[n - 1]);
    for (int j = 0; j < d->n_poles; j++) {
        d->pole_x[j] = d->pole_a[j] * d->pole_x[j] + d->pole_c[j] * vafm_rng_normal(&d->rng_flicker);
        v += d->pole_x[j];
    }
    return v;
}

void vafm_detector_apply(vafm_detector *d, double t_s, double height_m, double deflection_m, double *volts,
                         double *deflection_out, double *force_out)
{
    /* a division, not a multiplication by the inverse: bit-exact with deflection / sensitivity */
    double v = deflection_m / d->sens;
    if (!d->on) {
        if (volts)
            *volts = v;
        return;
    }
    v += d->offset;
    if (d->artefacts)
        v += s_artefacts(d, t_s, height_m);
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

double vafm_detector_height(vafm_detector *d, double t_s, double height_m)
{
    if (!d->zs_on)
        return height_m;
    if (d->zs_bw > 0) {
        /* first order, exact for a height that holds over each interval (zero-order hold of the samples) */
        if (isnan(d->zs_t))
            d->zs_y = height_m;
        else
            d->zs_y += (1.0 - exp(-2.0 * M_PI * d->zs_bw * (t_s - d->zs_t))) * (height_m - d->zs_y);
        d->zs_t = t_s;
    } else {
        d->zs_y = height_m;
    }
    return d->zs_noise > 0 ? d->zs_y + d->zs_noise * vafm_rng_normal(&d->rng_zs) : d->zs_y;
}

void vafm_detector_sample(vafm_detector *d, const vafm_samples *b, size_t i, double *volts, double *deflection_m,
                          double *force_N, double *height_measured_m)
{
    if (d->on) {
        vafm_detector_apply(d, b->time_s[i], b->height_m[i], b->deflection_m[i], volts, deflection_m, force_N);
    } else {
        if (force_N)
            *force_N = b->force_N[i];
        if (b->deflection_m) {
            if (deflection_m)
                *deflection_m = b->deflection_m[i];
            if (volts) /* a division, not a multiplication by the inverse: bit-exact with deflection / sensitivity */
                *volts = b->deflection_m[i] / d->sens;
        }
    }
    if (height_measured_m)
        *height_measured_m =
            vafm_detector_height(d, b->time_s[i], b->height_measured_m ? b->height_measured_m[i] : b->height_m[i]);
}

double vafm_artefact_contact_point(const vafm_params *p, uint64_t index)
{
    double z = p->surface_height_m;
    if (p->contact_point_sd_m > 0) {
        vafm_rng r;
        vafm_rng_init(&r, p->seed ^ VAFM_ARTEFACT_SAMPLE_KEY, index);
        z += p->contact_point_sd_m * vafm_rng_normal(&r);
    }
    return z;
}
