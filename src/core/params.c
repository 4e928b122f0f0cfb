/* SPDX-License-Identifier: MIT */
/*
 * Scene parameters: the field table (names, units, ranges, docs), setting and getting fields by name,
 * JSON, and validation of single fields; the named presets live in presets.c. Checks that need the
 * physics (time step against the stability limit) are numerics.c's, which vafm_params_validate() calls.
 */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "vafm/integrator.h"
#include "vafm/params.h"
#include "vafm/units.h"
#include "core/internal.h"
#include "core/models.h"

enum s_choice { S_NONE = 0, S_CONTACT, S_INTEGRATOR, S_TRIGGER, S_NOISE, S_ANTIALIAS, S_RAMP_START, S_SETPOINT_MODE,
                S_DWELL_MODE };

typedef struct s_field {
    vafm_param_info info;
    size_t offset; /* of the double / int / uint64 member */
    int choice;    /* enum s_choice for CHOICE fields */
} s_field;

/* A field of vafm_params by its member name: its kind, unit, range (BOOL 0-1, CHOICE none) and doc. */
#define S_FIELD(name, kind, unit, lo, hi, choices, sel, doc) \
    { { #name, kind, unit, lo, hi, choices, doc }, offsetof(vafm_params, name), sel }
#define REAL(name, unit, lo, hi, doc) S_FIELD(name, VAFM_PARAM_REAL, unit, lo, hi, NULL, S_NONE, doc)
#define INT(name, unit, lo, hi, doc) S_FIELD(name, VAFM_PARAM_INT, unit, lo, hi, NULL, S_NONE, doc)
#define BOOL(name, doc) S_FIELD(name, VAFM_PARAM_BOOL, "", 0, 1, NULL, S_NONE, doc)
#define CHOICE(name, sel, choices, doc) S_FIELD(name, VAFM_PARAM_CHOICE, "", 0, 0, choices, sel, doc)

static const s_field s_fields[] = {
    REAL(E_star_Pa, "Pa", 1e3, 1e13, "contact modulus E* of tip and sample"),
    REAL(R_m, "m", 1e-10, 1e-3, "tip radius R"),
    REAL(gamma_J_per_m2, "J/m^2", 0, 100, "surface energy gamma of the JKR model (0 with contact=hertz)"),
    { { "contact", VAFM_PARAM_CHOICE, "", 0, 0, VAFM_CONTACT_CHOICES, VAFM_CONTACT_DOC }, 0, S_CONTACT },
    REAL(k_N_per_m, "N/m", 1e-6, 1e4, "cantilever spring constant k"),
    REAL(m_kg, "kg", 1e-20, 1e-3, "effective mass m of the cantilever"),
    REAL(eta_per_s, "1/s", 1e-3, 1e13, "friction rate eta of the cantilever in its medium (damping m*eta)"),
    REAL(f0_Hz, "Hz", 0, 1e9, "resonance frequency of the free cantilever (> 0: sets the mass k/(2 pi f0)^2; 0: m_kg)"),
    REAL(Q, "", 0, 1e6, "quality factor of the free cantilever (> 0: sets the friction 2 pi f0/Q; 0: eta_per_s)"),
    REAL(eta_cont_per_s, "1/s", 0, 1e13, "extra friction rate while in contact (the paper's Gamma_cont)"),
    REAL(T_K, "K", 0, 1e9, "temperature (0: athermal, no random numbers drawn)"),
    REAL(v_approach_m_per_s, "m/s", 1e-12, 1e3, "piezo approach speed"),
    REAL(v_retract_m_per_s, "m/s", 1e-12, 1e3, "piezo retract speed"),
    REAL(start_height_m, "m", -1e-3, 1e-3, "piezo height at t = 0 above the contact point (negative: pressed in)"),
    BOOL(start_in_contact,
         "start with the tip in adhesive contact at equilibrium (a retract-only curve can then start anywhere "
         "above the instability, e.g. with a height trigger just below start_height_m)"),
    CHOICE(trigger, S_TRIGGER, "force|height",
           "what ends the approach: the filtered force reaching setpoint_N, or the piezo reaching trigger_height_m"),
    REAL(setpoint_N, "N", 0, 1, "force trigger: repulsive force that ends the approach"),
    REAL(trigger_height_m, "m", -1e-3, 1e-3, "height trigger: piezo height that ends the approach"),
    REAL(z_range_m, "m", 0, 1e-2, "approach travel limit (0: automatic)"),
    REAL(dwell_s, "s", 0, 1e4, "pause between approach and retract (rounded to whole samples)"),
    REAL(retract_margin_m, "m", 0, 1e-2, "retract distance after the detachment before the curve ends"),
    REAL(retract_max_m, "m", 0, 1e-1, "retract travel limit (0: automatic, 4x the quasi-static travel)"),
    REAL(ramp_size_m, "m", 0, 1e-3,
         "ramp size (z length) of a fixed symmetric ramp: the approach travels at most this far, the retract "
         "returns to the start height (0: adaptive ramp, ending retract_margin_m after the detachment)"),
    CHOICE(ramp_start, S_RAMP_START, "surface|trigger",
           "fixed ramp: start start_height_m above the surface, or ramp_size_m above the quasi-static trigger point"),
    REAL(ramp_rate_Hz, "Hz", 0, 1e6,
         "ramp rate: one approach and one retract of ramp_size_m per period, speeds 2*ramp_size*rate (0: speeds)"),
    REAL(extend_time_s, "s", 0, 1e5, "extend (approach) time of ramp_size_m: sets v_approach (0: the speed)"),
    REAL(retract_time_s, "s", 0, 1e5, "retract time of ramp_size_m: sets v_retract (0: the speed)"),
    INT(segment_samples, "samples", 0, 16777216,
        "samples per approach of ramp_size_m: sets sample_rate_Hz (0: sample_rate_Hz)"),
    CHOICE(setpoint_mode, S_SETPOINT_MODE, "absolute|relative",
           "force trigger: absolute, or relative to the baseline of the approach's first 64 samples"),
    REAL(setpoint_V, "V", 0, 100,
         "force trigger in volts of deflection signal: setpoint_N = k*InvOLS*V (absolute: V less "
         "baseline_offset_V) (0: setpoint_N)"),
    CHOICE(dwell_mode, S_DWELL_MODE, "height|force",
           "dwell at constant height (piezo still) or constant force (feedback on the deflection)"),
    REAL(dwell_feedback_s, "s", 0, 1e3,
         "constant-force dwell: time constant of the feedback loop (0: 10 sample intervals; else >= 2)"),
    REAL(sample_rate_Hz, "Hz", 1e-3, 1e10, "output sample rate"),
    CHOICE(antialias, S_ANTIALIAS, "mean|point",
           "output samples: mean over the sample interval (box-car anti-alias) or point samples"),
    REAL(tune_duration_s, "s", 0, 1e5, "thermal tune: recorded duration"),
    REAL(tune_rate_Hz, "Hz", 0, 1e10,
         "thermal tune: sample rate (0: automatic: sample_rate_Hz, raised to the first 1-2-5 value >= 4 f0 so the "
         "resonance shows)"),
    { { "integrator", VAFM_PARAM_CHOICE, "", 0, 0, VAFM_INTEGRATOR_CHOICES, VAFM_INTEGRATOR_DOC }, 0, S_INTEGRATOR },
    CHOICE(noise, S_NOISE, "gaussian|uniform",
           "random force distribution: gaussian, or uniform of matched variance (the paper's Eq. 7)"),
    REAL(dt_s, "s", 0, 1,
         "time step (0: automatic from omega_dt, as the paper's Eq. 8); rounded down to a whole fraction of the "
         "sample interval"),
    REAL(omega_dt, "", 1e-6, 1.99,
         "automatic time step: omega_max*dt at the stiffest contact reached (default: the paper's 2*pi/40 = "
         "0.157, also named 'paper'); brownian: K_max*dt/zeta"),
    REAL(omega_dt_far, "", 0, 1.99,
         "adaptive step: omega_max*dt while in contact and far from the pull-off instability "
         "(0: no adaptation, omega_dt everywhere)"),
    REAL(near_barrier_kT, "", 1, 1e6,
         "adaptive step: the spring is near the instability when the quasi-static barrier is below this many "
         "k_BT (or within 10% of the quasi-static pull-off force)"),
    BOOL(free_exact, "propagate the free cantilever exactly (linear SDE) instead of plain steps"),
    BOOL(contact_table,
         "tabulate the JKR branch for the step (relative error < 1e-13) instead of a Newton solve per step"),
    BOOL(well_exact,
         "far from the pull-off instability, propagate the deep contact well exactly (linearised about the "
         "moving equilibrium, one step per sample) instead of integrator steps"),
    S_FIELD(seed, VAFM_PARAM_SEED, "", 0, 18446744073709551615.0, NULL, S_NONE,
            "random seed: (seed, curve index) reproduces a curve bit for bit"),
    REAL(sensitivity_m_per_V, "m/V", 1e-12, 1e-3, "deflection sensitivity (InvOLS): vDeflection = deflection / it"),
    REAL(noise_V_rms, "V", 0, 10, "detector: white noise floor of the deflection signal (0: none)"),
    INT(adc_bits, "bits", 0, 24, "detector: ADC resolution (0: no ADC, else 4-24)"),
    REAL(adc_range_V, "V", 1e-3, 100, "detector: ADC full range, peak to peak (codes saturate beyond it)"),
    REAL(baseline_offset_V, "V", -100, 100, "detector: offset of the deflection signal"),
    REAL(drift_V_per_s, "V/s", -100, 100, "artefact: linear drift of the deflection signal's baseline"),
    REAL(drift_walk_V_per_sqrt_s, "V/s^0.5", 0, 100, "artefact: random walk of the baseline (own random stream)"),
    REAL(virtual_deflection_V_per_m, "V/m", -1e9, 1e9,
         "artefact: virtual deflection, a baseline slope with the piezo height (typical 1e3-1e5 V/m)"),
    REAL(interference_V, "V", 0, 100, "artefact: laser interference on the baseline, amplitude of a sinusoid in height"),
    REAL(interference_period_m, "m", 0, 1e-3,
         "artefact: period of the interference in piezo height (about half the laser wavelength)"),
    REAL(flicker_corner_Hz, "Hz", 0, 1e9,
         "artefact: 1/f noise, the frequency where it equals the white floor noise_V_rms (1/f down to 1 mHz)"),
    REAL(mains_V, "V", 0, 100, "artefact: mains pickup, amplitude of the fundamental (harmonics 2, 3 at 1/2, 1/3)"),
    REAL(mains_Hz, "Hz", 0, 1000, "artefact: mains frequency (50 or 60 Hz)"),
    REAL(contact_point_sd_m, "m", 0, 1e-4,
         "artefact: each curve's surface at a random height (normal, this sd; own random stream)"),
    REAL(sample_drift_m_per_s, "m/s", -1e-3, 1e-3, "artefact: the sample surface rises at this speed during a curve"),
    REAL(piezo_hysteresis, "", 0, 0.5,
         "artefact: piezo hysteresis (Bouc-Wen) strength H: a loop 2*H*L_s wide between command and actual height"),
    REAL(piezo_hysteresis_length_m, "m", 0, 1e-3, "artefact: the hysteresis' saturation length L_s"),
    REAL(piezo_creep, "", 0, 0.5, "artefact: piezo creep after a move, as a fraction of the move per decade of time"),
    REAL(piezo_creep_t0_s, "s", 0, 1e3, "artefact: the creep's reference time t0 (creep ~ log10(1 + t/t0))"),
    REAL(zsensor_noise_m, "m", 0, 1e-6, "artefact: z sensor white noise on height (measured), rms"),
    REAL(zsensor_bandwidth_Hz, "Hz", 0, 1e9, "artefact: z sensor first-order bandwidth (0: unlimited)"),
    REAL(surface_height_m, "m", -1e-3, 1e-3,
         "height of the sample surface above the reference plane (a force map's substrate): the piezo heights "
         "a curve reports are measured from that plane; start_height_m and trigger_height_m stay relative to "
         "the contact point"),
};
#undef REAL

#define S_NFIELDS ((int)(sizeof s_fields / sizeof s_fields[0]))

/* ---- field table ------------------------------------------------------------------------------ */

int vafm_params_field_count(void)
{
    return S_NFIELDS;
}

const vafm_param_info *vafm_params_field_at(int i)
{
    return i >= 0 && i < S_NFIELDS ? &s_fields[i].info : NULL;
}

static const s_field *s_find(const char *name)
{
    for (int i = 0; i < S_NFIELDS; i++)
        if (name && !strcmp(name, s_fields[i].info.name))
            return &s_fields[i];
    return NULL;
}

const vafm_param_info *vafm_params_field_find(const char *name)
{
    const s_field *f = s_find(name);
    return f ? &f->info : NULL;
}

static const char *const s_trigger_names[] = { "force", "height" };
static const char *const s_noise_names[] = { "gaussian", "uniform" };
static const char *const s_antialias_names[] = { "mean", "point" };
static const char *const s_ramp_start_names[] = { "surface", "trigger" };
static const char *const s_setpoint_mode_names[] = { "absolute", "relative" };
static const char *const s_dwell_mode_names[] = { "height", "force" };

static int s_index_of(const char *const *names, int n, const char *v)
{
    for (int i = 0; i < n; i++)
        if (!strcmp(names[i], v))
            return i;
    return -1;
}

static int s_check_real(const s_field *f, double v, vafm_error *err)
{
    if (!isfinite(v) || v < f->info.min || v > f->info.max) {
        vafm_err_set(err, VAFM_EINVAL, f->info.name, "%s = %.6g %s is outside the allowed range [%.6g, %.6g] %s",
                     f->info.name, v, f->info.unit, f->info.min, f->info.max, f->info.unit);
        return VAFM_EINVAL;
    }
    return 0;
}

/* An INT field's range; adc_bits also excludes 1-3 (0 means "no ADC"). */
static int s_check_int(const s_field *f, int v, vafm_error *err)
{
    if (v < (int)f->info.min || v > (int)f->info.max) {
        vafm_err_set(err, VAFM_EINVAL, f->info.name, "%s = %d is outside [%.0f, %.0f] %s", f->info.name, v,
                     f->info.min, f->info.max, f->info.unit);
        return VAFM_EINVAL;
    }
    if (!strcmp(f->info.name, "adc_bits") && v > 0 && v < 4) {
        vafm_err_set(err, VAFM_EINVAL, f->info.name, "adc_bits = %d: 0 (no ADC) or 4 to 24 bits", v);
        return VAFM_EINVAL;
    }
    return 0;
}

int vafm_params_set(vafm_params *p, const char *name, const char *value, vafm_error *err)
{
    const s_field *f = s_find(name);
    if (!f) {
        vafm_err_set(err, VAFM_ENOTFOUND, name ? name : "", "unknown parameter '%s' (see vafm --help)",
                     name ? name : "(null)");
        return VAFM_ENOTFOUND;
    }
    if (!value)
        value = "";
    char *end = NULL;
    switch (f->info.kind) {
    case VAFM_PARAM_REAL: {
        double v = 0.0;
        vafm_error perr;
        int r = 0;
        if (f->offset == offsetof(vafm_params, omega_dt) && !strcmp(value, "paper"))
            v = VAFM_OMEGA_DT_PAPER; /* the paper's step by name */
        else
            r = vafm_units_parse(f->info.name, value, f->info.unit, &v, &perr); /* "1e-9", "1nN", "25C" */
        if (r) {
            vafm_err_set(err, r, f->info.name, "%s (allowed range [%.6g, %.6g] %s)", perr.message, f->info.min,
                         f->info.max, f->info.unit);
            return r;
        }
        r = s_check_real(f, v, err);
        if (r)
            return r;
        *(double *)((char *)p + f->offset) = v;
        return 0;
    }
    case VAFM_PARAM_SEED: {
        errno = 0;
        /* strtoull would skip white space and wrap a minus sign around: accept plain digits only */
        if (value[0] < '0' || value[0] > '9')
            goto bad_seed;
        /* decimal, or hexadecimal with 0x; never octal ("010" is ten) */
        int base = (value[0] == '0' && (value[1] == 'x' || value[1] == 'X')) ? 16 : 10;
        unsigned long long v = strtoull(value, &end, base);
        if (*end != '\0' || errno == ERANGE)
            goto bad_seed;
        p->seed = (uint64_t)v;
        return 0;
    bad_seed:
        vafm_err_set(err, VAFM_EINVAL, f->info.name, "seed: '%s' is not an integer in [0, 2^64 - 1]", value);
        return VAFM_EINVAL;
    }
    case VAFM_PARAM_INT: {
        errno = 0;
        long v = strtol(value, &end, 10);
        if (end == value || *end != '\0' || errno == ERANGE || v < (long)f->info.min || v > (long)f->info.max) {
            vafm_err_set(err, VAFM_EINVAL, f->info.name, "%s: '%s' is not a whole number in [%.0f, %.0f] %s",
                         f->info.name, value, f->info.min, f->info.max, f->info.unit);
            return VAFM_EINVAL;
        }
        int r = s_check_int(f, (int)v, err);
        if (r)
            return r;
        *(int *)((char *)p + f->offset) = (int)v;
        return 0;
    }
    case VAFM_PARAM_BOOL: {
        int v;
        if (!strcmp(value, "1") || !strcasecmp(value, "true") || !strcasecmp(value, "yes") || !strcasecmp(value, "on"))
            v = 1;
        else if (!strcmp(value, "0") || !strcasecmp(value, "false") || !strcasecmp(value, "no") ||
                 !strcasecmp(value, "off"))
            v = 0;
        else {
            vafm_err_set(err, VAFM_EINVAL, f->info.name, "%s: '%s' is not a boolean (true|false|1|0)", f->info.name,
                         value);
            return VAFM_EINVAL;
        }
        *(int *)((char *)p + f->offset) = v;
        return 0;
    }
    case VAFM_PARAM_CHOICE: {
        int idx = -1;
        switch (f->choice) {
        case S_CONTACT: {
            const vafm_contact_type *t = vafm_contact_type_find(value);
            if (t) {
                p->contact = t;
                return 0;
            }
            break;
        }
        case S_INTEGRATOR: {
            const vafm_integrator_type *t = vafm_integrator_find(value);
            if (t) {
                p->integrator = t;
                return 0;
            }
            break;
        }
        case S_TRIGGER: idx = s_index_of(s_trigger_names, 2, value); break;
        case S_NOISE: idx = s_index_of(s_noise_names, 2, value); break;
        case S_ANTIALIAS: idx = s_index_of(s_antialias_names, 2, value); break;
        case S_RAMP_START: idx = s_index_of(s_ramp_start_names, 2, value); break;
        case S_SETPOINT_MODE: idx = s_index_of(s_setpoint_mode_names, 2, value); break;
        case S_DWELL_MODE: idx = s_index_of(s_dwell_mode_names, 2, value); break;
        default: break;
        }
        if (idx >= 0) {
            *(int *)((char *)p + f->offset) = idx;
            return 0;
        }
        vafm_err_set(err, VAFM_EINVAL, f->info.name, "%s: '%s' is not one of %s", f->info.name, value,
                     f->info.choices);
        return VAFM_EINVAL;
    }
    default: return VAFM_EINVAL;
    }
}

static const char *s_choice_value(const vafm_params *p, const s_field *f)
{
    int v;
    switch (f->choice) {
    case S_CONTACT: return p->contact ? p->contact->name : "(unset)";
    case S_INTEGRATOR: return p->integrator ? p->integrator->name : "(unset)";
    case S_TRIGGER: v = p->trigger; return v >= 0 && v < 2 ? s_trigger_names[v] : "(invalid)";
    case S_NOISE: v = p->noise; return v >= 0 && v < 2 ? s_noise_names[v] : "(invalid)";
    case S_ANTIALIAS: v = p->antialias; return v >= 0 && v < 2 ? s_antialias_names[v] : "(invalid)";
    case S_RAMP_START: v = p->ramp_start; return v >= 0 && v < 2 ? s_ramp_start_names[v] : "(invalid)";
    case S_SETPOINT_MODE: v = p->setpoint_mode; return v >= 0 && v < 2 ? s_setpoint_mode_names[v] : "(invalid)";
    case S_DWELL_MODE: v = p->dwell_mode; return v >= 0 && v < 2 ? s_dwell_mode_names[v] : "(invalid)";
    default: return "";
    }
}

/* The shortest %g text that reads back as exactly v (200000, not 199999.99999999997 … or 2e+05 when that is
 * exact): people read it, and files and JSON still round-trip bit for bit. */
static void s_fmt_shortest(char *buf, size_t len, double v)
{
    if (v == floor(v) && fabs(v) < 1e7) { /* whole numbers as people write them: 13000, not 1.3e+04 */
        snprintf(buf, len, "%.0f", v);
        return;
    }
    for (int prec = 1; prec <= 17; prec++) {
        snprintf(buf, len, "%.*g", prec, v);
        if (strtod(buf, NULL) == v)
            return;
    }
    snprintf(buf, len, "%.17g", v); /* NaN, inf */
}

int vafm_params_get(const vafm_params *p, const char *name, char *buf, size_t len)
{
    const s_field *f = s_find(name);
    if (!f)
        return VAFM_ENOTFOUND;
    switch (f->info.kind) {
    case VAFM_PARAM_REAL: s_fmt_shortest(buf, len, *(const double *)((const char *)p + f->offset)); break;
    case VAFM_PARAM_SEED: snprintf(buf, len, "%" PRIu64, p->seed); break;
    case VAFM_PARAM_BOOL: snprintf(buf, len, "%s", *(const int *)((const char *)p + f->offset) ? "true" : "false"); break;
    case VAFM_PARAM_INT: snprintf(buf, len, "%d", *(const int *)((const char *)p + f->offset)); break;
    default: snprintf(buf, len, "%s", s_choice_value(p, f)); break;
    }
    return 0;
}

int vafm_params_to_json(const vafm_params *p, char *buf, size_t len)
{
    size_t n = 0;
    char val[64];
    if (vafm_buf_appendf(buf, len, &n, "{"))
        return VAFM_EINVAL;
    for (int i = 0; i < S_NFIELDS; i++) {
        const s_field *f = &s_fields[i];
        vafm_params_get(p, f->info.name, val, sizeof val);
        /* seeds are quoted: JSON readers (jansson) reject integers above INT64_MAX */
        int quoted = f->info.kind == VAFM_PARAM_CHOICE || f->info.kind == VAFM_PARAM_SEED;
        if (vafm_buf_appendf(buf, len, &n, "%s\"%s\": %s%s%s", i ? ", " : "", f->info.name, quoted ? "\"" : "",
                             val, quoted ? "\"" : ""))
            return VAFM_EINVAL;
    }
    if (vafm_buf_appendf(buf, len, &n, "}"))
        return VAFM_EINVAL;
    return (int)n;
}

double vafm_params_tune_rate_Hz(const vafm_params *p)
{
    if (p->tune_rate_Hz > 0)
        return p->tune_rate_Hz;
    double f0 = sqrt(p->k_N_per_m / vafm_params_mass_kg(p)) / (2.0 * M_PI), want = 4.0 * f0;
    if (!(p->sample_rate_Hz < want) || !isfinite(want))
        return p->sample_rate_Hz;
    double dec = pow(10.0, floor(log10(want)));
    static const double steps[] = { 1, 2, 5, 10 };
    for (int i = 0; i < 4; i++)
        if (steps[i] * dec >= want * (1.0 - 1e-12))
            return steps[i] * dec;
    return 10.0 * dec;
}

void vafm_params_tune_scene(const vafm_params *p, vafm_params *out)
{
    vafm_params q = *p;
    q.sample_rate_Hz = vafm_params_tune_rate_Hz(p);
    q.segment_samples = 0;
    *out = q;
}

/* ---- the instrument's settings → the fields underneath --------------------------------------- */

/* The speed and sample rate that ramp_rate_Hz / extend_time_s / retract_time_s / segment_samples imply
 * (NaN where the setting is off), and setpoint_N from setpoint_V. */
typedef struct s_derived {
    double v_approach, v_retract, sample_rate, setpoint_N;
} s_derived;

static int s_derive(const vafm_params *p, s_derived *d, vafm_error *err)
{
    d->v_approach = d->v_retract = d->sample_rate = d->setpoint_N = NAN;
    const char *need = p->ramp_rate_Hz > 0     ? "ramp_rate_Hz"
                       : p->extend_time_s > 0  ? "extend_time_s"
                       : p->retract_time_s > 0 ? "retract_time_s"
                       : p->segment_samples > 0 ? "segment_samples"
                                                : NULL;
    if (need && !(p->ramp_size_m > 0)) {
        vafm_err_set(err, VAFM_EINVAL, need, "%s needs a ramp: set ramp_size_m (the z length, > 0 m)", need);
        return VAFM_EINVAL;
    }
    if (p->ramp_rate_Hz > 0 && (p->extend_time_s > 0 || p->retract_time_s > 0)) {
        vafm_err_set(err, VAFM_EINVAL, "ramp_rate_Hz",
                     "ramp_rate_Hz = %.6g Hz and extend_time_s/retract_time_s both set the speeds: give one of them",
                     p->ramp_rate_Hz);
        return VAFM_EINVAL;
    }
    if (p->ramp_rate_Hz > 0)
        d->v_approach = d->v_retract = 2.0 * p->ramp_size_m * p->ramp_rate_Hz;
    if (p->extend_time_s > 0)
        d->v_approach = p->ramp_size_m / p->extend_time_s;
    if (p->retract_time_s > 0)
        d->v_retract = p->ramp_size_m / p->retract_time_s;
    if (p->segment_samples > 0) {
        double va = isnan(d->v_approach) ? p->v_approach_m_per_s : d->v_approach;
        d->sample_rate = (double)p->segment_samples * va / p->ramp_size_m;
    }
    if (p->setpoint_V > 0) {
        double volts = p->setpoint_mode == VAFM_SETPOINT_RELATIVE ? p->setpoint_V
                                                                  : p->setpoint_V - p->baseline_offset_V;
        d->setpoint_N = p->k_N_per_m * p->sensitivity_m_per_V * volts;
        if (!(d->setpoint_N > 0)) {
            vafm_err_set(err, VAFM_EINVAL, "setpoint_V",
                         "setpoint_V = %.6g V is at or below the signal's baseline_offset_V = %.6g V: an absolute "
                         "setpoint must lie above it (or use setpoint_mode = relative)",
                         p->setpoint_V, p->baseline_offset_V);
            return VAFM_EINVAL;
        }
    }
    return 0;
}

int vafm_params_resolve(vafm_params *p, vafm_error *err)
{
    if (!p) {
        vafm_err_set(err, VAFM_EINVAL, "", "no parameters given");
        return VAFM_EINVAL;
    }
    s_derived d;
    int r = s_derive(p, &d, err);
    if (r)
        return r;
    if (!isnan(d.v_approach))
        p->v_approach_m_per_s = d.v_approach;
    if (!isnan(d.v_retract))
        p->v_retract_m_per_s = d.v_retract;
    if (!isnan(d.sample_rate))
        p->sample_rate_Hz = d.sample_rate;
    if (!isnan(d.setpoint_N))
        p->setpoint_N = d.setpoint_N;
    return 0;
}

/* A derived field that disagrees with its setting: resolve was not called after the last change, or a field
 * underneath was changed afterwards (a campaign axis over v with a ramp rate set). */
static int s_check_derived(const char *field, double have, const char *setting, double want, const char *unit,
                           vafm_error *err)
{
    if (isnan(want) || fabs(have - want) <= 1e-12 * fabs(want))
        return 0;
    vafm_err_set(err, VAFM_EINVAL, field,
                 "%s = %.9g %s disagrees with %s, which makes it %.9g %s: set %s to 0 to give %s directly "
                 "(or resolve the scene after the last setting)",
                 field, have, unit, setting, want, unit, setting, field);
    return VAFM_EINVAL;
}

int vafm_params_validate(const vafm_params *p, vafm_error *err)
{
    return vafm_params_validate_scene(p, 0, err);
}

int vafm_params_validate_scene(const vafm_params *p, int tune_scene, vafm_error *err)
{
    if (!p) {
        vafm_err_set(err, VAFM_EINVAL, "", "no parameters given");
        return VAFM_EINVAL;
    }
    for (int i = 0; i < S_NFIELDS; i++) {
        const s_field *f = &s_fields[i];
        if (f->info.kind == VAFM_PARAM_REAL) {
            int r = s_check_real(f, *(const double *)((const char *)p + f->offset), err);
            if (r)
                return r;
        } else if (f->info.kind == VAFM_PARAM_CHOICE) {
            if (!strncmp(s_choice_value(p, f), "(", 1)) {
                vafm_err_set(err, VAFM_EINVAL, f->info.name, "%s is not set to one of %s", f->info.name,
                             f->info.choices);
                return VAFM_EINVAL;
            }
        } else if (f->info.kind == VAFM_PARAM_INT) {
            int r = s_check_int(f, *(const int *)((const char *)p + f->offset), err);
            if (r)
                return r;
        } else if (f->info.kind == VAFM_PARAM_BOOL) {
            int v = *(const int *)((const char *)p + f->offset);
            if (v != 0 && v != 1) {
                vafm_err_set(err, VAFM_EINVAL, f->info.name, "%s = %d is not a boolean (0 or 1)", f->info.name, v);
                return VAFM_EINVAL;
            }
        }
    }
    if (p->contact && (p->contact->flags & (VAFM_CONTACT_SURFACE | VAFM_CONTACT_ADHESIVE)) == VAFM_CONTACT_SURFACE &&
        p->gamma_J_per_m2 != 0) {
        vafm_err_set(err, VAFM_EINVAL, "gamma_J_per_m2",
                     "gamma_J_per_m2 = %.6g J/m^2 must be 0 with contact = %s (use jkr for adhesion)",
                     p->gamma_J_per_m2, p->contact->name);
        return VAFM_EINVAL;
    }
    /* f0 and Q set the mass and the friction: those must lie in m_kg's and eta_per_s's ranges */
    const s_field *fm = s_find("m_kg"), *fe = s_find("eta_per_s");
    double m = vafm_params_mass_kg(p), eta = vafm_params_eta_per_s(p);
    if (p->f0_Hz > 0 && !(m >= fm->info.min && m <= fm->info.max)) {
        vafm_err_set(err, VAFM_EINVAL, "f0_Hz", "f0_Hz = %.6g Hz with k = %.6g N/m gives a mass of %.6g kg, outside "
                     "[%.3g, %.3g] kg", p->f0_Hz, p->k_N_per_m, m, fm->info.min, fm->info.max);
        return VAFM_EINVAL;
    }
    if (p->Q > 0 && !(eta >= fe->info.min && eta <= fe->info.max)) {
        vafm_err_set(err, VAFM_EINVAL, "Q", "Q = %.6g gives a friction rate of %.6g 1/s, outside [%.3g, %.3g] 1/s",
                     p->Q, eta, fe->info.min, fe->info.max);
        return VAFM_EINVAL;
    }
    s_derived d;
    int rd = s_derive(p, &d, err);
    if (rd)
        return rd;
    const char *vset = p->ramp_rate_Hz > 0 ? "ramp_rate_Hz" : "extend_time_s";
    if ((rd = s_check_derived("v_approach_m_per_s", p->v_approach_m_per_s, vset, d.v_approach, "m/s", err)) ||
        (rd = s_check_derived("v_retract_m_per_s", p->v_retract_m_per_s,
                              p->ramp_rate_Hz > 0 ? "ramp_rate_Hz" : "retract_time_s", d.v_retract, "m/s", err)) ||
        (rd = s_check_derived("sample_rate_Hz", p->sample_rate_Hz, "segment_samples", d.sample_rate, "Hz", err)) ||
        (rd = s_check_derived("setpoint_N", p->setpoint_N, "setpoint_V", d.setpoint_N, "N", err)))
        return rd;
    if (p->dwell_feedback_s > 0 && p->dwell_feedback_s * p->sample_rate_Hz < 2.0) {
        vafm_err_set(err, VAFM_EINVAL, "dwell_feedback_s",
                     "dwell_feedback_s = %.6g s is shorter than 2 sample intervals (%.6g s): the constant-force "
                     "loop acts once per sample and would ring (0: automatic, 10 intervals)",
                     p->dwell_feedback_s, 2.0 / p->sample_rate_Hz);
        return VAFM_EINVAL;
    }
    if (p->ramp_size_m > 0 && p->ramp_start == VAFM_RAMP_START_TRIGGER &&
        (p->start_in_contact || !(p->contact->flags & VAFM_CONTACT_SURFACE))) {
        vafm_err_set(err, VAFM_EINVAL, "ramp_start",
                     "ramp_start = trigger needs a surface to find (contact jkr or hertz) and a free start "
                     "(start_in_contact = false)");
        return VAFM_EINVAL;
    }
    if (p->flicker_corner_Hz > 0 && !(p->noise_V_rms > 0)) {
        vafm_err_set(err, VAFM_EINVAL, "flicker_corner_Hz",
                     "flicker_corner_Hz = %.6g Hz is where 1/f noise meets the white floor: set noise_V_rms > 0 V",
                     p->flicker_corner_Hz);
        return VAFM_EINVAL;
    }
    if (p->interference_V > 0 && !(p->interference_period_m >= 1e-9)) {
        vafm_err_set(err, VAFM_EINVAL, "interference_period_m",
                     "interference_period_m = %.6g m: the interference needs a period of at least 1e-09 m",
                     p->interference_period_m);
        return VAFM_EINVAL;
    }
    if (p->piezo_hysteresis > 0 && !(p->piezo_hysteresis_length_m >= 1e-9)) {
        vafm_err_set(err, VAFM_EINVAL, "piezo_hysteresis_length_m",
                     "piezo_hysteresis_length_m = %.6g m: the hysteresis needs a saturation length of at least 1e-09 m",
                     p->piezo_hysteresis_length_m);
        return VAFM_EINVAL;
    }
    if (p->piezo_creep > 0 && !(p->piezo_creep_t0_s >= 1e-6)) {
        vafm_err_set(err, VAFM_EINVAL, "piezo_creep_t0_s",
                     "piezo_creep_t0_s = %.6g s: the creep needs a reference time of at least 1e-06 s", p->piezo_creep_t0_s);
        return VAFM_EINVAL;
    }
    if (p->mains_V > 0 && !(p->mains_Hz >= 1)) {
        vafm_err_set(err, VAFM_EINVAL, "mains_Hz", "mains_Hz = %.6g Hz: mains pickup needs a frequency in [1, 1000] Hz",
                     p->mains_Hz);
        return VAFM_EINVAL;
    }
    if (p->setpoint_mode == VAFM_SETPOINT_RELATIVE && p->start_in_contact) {
        vafm_err_set(err, VAFM_EINVAL, "setpoint_mode",
                     "setpoint_mode = relative measures the baseline at the start of the approach: it needs a free "
                     "start (start_in_contact = false)");
        return VAFM_EINVAL;
    }
    if (p->trigger == VAFM_TRIGGER_HEIGHT && !(p->trigger_height_m < p->start_height_m)) {
        vafm_err_set(err, VAFM_EINVAL, "trigger_height_m",
                     "trigger_height_m = %.6g m must lie below start_height_m = %.6g m", p->trigger_height_m,
                     p->start_height_m);
        return VAFM_EINVAL;
    }
    return vafm_numerics_check_scene(p, NULL, tune_scene, err);
}
