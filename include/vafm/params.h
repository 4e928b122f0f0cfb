/* SPDX-License-Identifier: MIT */
/**
 * @file params.h
 * Scene parameters in SI, named presets, validation, and the field table that the CLI, JSON scene
 * files, the daemon and the HDF5 provenance all read (one place lists names, units, ranges, docs).
 *
 * The core works in reduced units (units.h): units.c makes the scale and the reduced scene; every other
 * core file scales a value through the vafm_scale_<quantity>_si/_red helpers declared with vafm_scale.
 */
#ifndef VAFM_PARAMS_H
#define VAFM_PARAMS_H

#include "vafm/common.h"
#include "vafm/contact.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct vafm_integrator_type vafm_integrator_type;

/** How the approach ends. */
enum vafm_trigger {
    VAFM_TRIGGER_FORCE = 0,  /**< when the (output-filtered) force reaches setpoint_N */
    VAFM_TRIGGER_HEIGHT = 1, /**< when the piezo height reaches trigger_height_m */
};

/** Random force distribution. */
enum vafm_noise {
    VAFM_NOISE_GAUSSIAN = 0, /**< normal deviates (exact for the OU steps of gjf/baoab) */
    VAFM_NOISE_UNIFORM = 1,  /**< uniform deviates of matched variance (the paper's Eq. 7) */
};

/** Where a fixed-length ramp (ramp_size_m > 0) starts. */
enum vafm_ramp_start {
    VAFM_RAMP_START_SURFACE = 0, /**< start_height_m above the contact point */
    VAFM_RAMP_START_TRIGGER = 1, /**< ramp_size_m above the quasi-static trigger point (as instruments that
                                      find the surface first and then ramp from above it) */
};

/** What the setpoint is measured against. */
enum vafm_setpoint_mode {
    VAFM_SETPOINT_ABSOLUTE = 0, /**< the force (or the deflection signal, setpoint_V) itself */
    VAFM_SETPOINT_RELATIVE = 1, /**< relative to the baseline measured over the approach's first
                                     VAFM_BASELINE_SAMPLES samples */
};

/** Samples of the approach that measure the baseline of a relative setpoint. */
#define VAFM_BASELINE_SAMPLES 64

/** What the piezo does during the dwell. */
enum vafm_dwell_mode {
    VAFM_DWELL_HEIGHT = 0, /**< constant height: the piezo stands still */
    VAFM_DWELL_FORCE = 1,  /**< constant force: a feedback loop moves the piezo to hold the trigger force */
};

/** How output samples are formed from the simulation steps. */
enum vafm_antialias {
    VAFM_ANTIALIAS_MEAN = 0,  /**< average over the sample interval (a box-car anti-alias filter) */
    VAFM_ANTIALIAS_POINT = 1, /**< instantaneous value at the end of the interval */
};

/** A scene: sample, tip, cantilever, ramp protocol, output and numerics. All SI. */
typedef struct vafm_params {
    /* sample and tip */
    double E_star_Pa;      /**< contact modulus E*, Pa */
    double R_m;            /**< tip radius R, m */
    double gamma_J_per_m2; /**< surface energy γ of the JKR model (the paper's γ), J/m² */
    const vafm_contact_type *contact; /**< contact model (jkr, hertz, none) */
    /* cantilever */
    double k_N_per_m;      /**< spring constant k, N/m */
    double m_kg;           /**< effective mass m, kg */
    double eta_per_s;      /**< friction rate η of the cantilever in its medium (damping mη), 1/s */
    double f0_Hz;          /**< resonance frequency of the free cantilever, Hz: when > 0 the mass is k/(2π f0)²
                                (m_kg is not used); 0: from m_kg */
    double Q;              /**< quality factor of the free cantilever in its medium: when > 0 the friction rate
                                is 2π f0 / Q (eta_per_s is not used); 0: from eta_per_s */
    double eta_cont_per_s; /**< extra friction rate while in contact (the paper's Γ_cont channel), 1/s */
    double T_K;            /**< temperature, K (0: athermal, no random numbers drawn) */
    /* ramp protocol */
    double v_approach_m_per_s; /**< piezo approach speed, m/s */
    double v_retract_m_per_s;  /**< piezo retract speed, m/s */
    double start_height_m; /**< piezo height at t = 0 above the contact point (spring relaxed, u = 0), m */
    int start_in_contact;  /**< 1: the tip starts in contact at equilibrium (needs an equilibrium there) */
    int trigger;           /**< enum vafm_trigger */
    double setpoint_N;     /**< force trigger: repulsive force that ends the approach, N */
    double trigger_height_m; /**< height trigger: piezo height that ends the approach, m */
    double z_range_m;      /**< approach travel limit, m (0: automatic from start height and setpoint) */
    double dwell_s;        /**< pause between approach and retract, s */
    double retract_margin_m; /**< retract distance after detachment before the curve ends, m */
    double retract_max_m;  /**< retract travel limit, m (0: automatic: 4× the travel to detach) */
    /* output */
    double sample_rate_Hz; /**< output sample rate, Hz */
    int antialias;         /**< enum vafm_antialias */
    double tune_duration_s; /**< thermal tune: recorded duration, s */
    /* numerics */
    const vafm_integrator_type *integrator; /**< gjf (default), baoab, paper-vv, brownian */
    int noise;             /**< enum vafm_noise */
    double dt_s;           /**< time step, s (0: automatic from omega_dt, the paper's Eq. 8 rule) */
    double omega_dt;       /**< automatic step: ω_max·dt at the stiffest contact reached (paper: 2π/40) */
    double omega_dt_far;   /**< ω_max·dt while far from the pull-off instability (0: same as omega_dt) */
    double near_barrier_kT; /**< "near" the instability: quasi-static barrier below this many k_BT */
    int free_exact;        /**< 1: propagate the free cantilever exactly (linear SDE), 0: plain steps */
    int contact_table;     /**< 1: tabulated JKR branch in the step (error < 1e-13), 0: Newton solve */
    int well_exact;        /**< 1: far from the instability, propagate the contact well exactly (linearised);
                                used where a sample spans ≥ 8 integrator steps (cheaper there) */
    uint64_t seed;         /**< random seed; (seed, curve index) reproduces a curve bit for bit */
    /* the measured chain (vafm/detector.h): off while noise_V_rms = 0, adc_bits = 0, baseline_offset_V = 0 */
    double sensitivity_m_per_V; /**< deflection sensitivity (InvOLS), m/V: vDeflection = deflection / it */
    double noise_V_rms;    /**< white noise floor of the deflection signal, V rms (0: none) */
    int adc_bits;          /**< ADC resolution, bits (0: no ADC; 4–24) */
    double adc_range_V;    /**< ADC full range, V (peak to peak; codes saturate beyond ±range/2) */
    double baseline_offset_V; /**< offset of the deflection signal, V */
    /* the instrument's ramp settings (vafm_params_resolve derives the speeds, the sample rate and
     * setpoint_N from them; 0 leaves the field underneath in charge) */
    double ramp_size_m;    /**< fixed-length symmetric ramp, m: the approach travels at most this far, the
                                retract returns to the start height (a long baseline on both segments);
                                0: adaptive (z_range_m, retract_margin_m, retract_max_m) */
    int ramp_start;        /**< enum vafm_ramp_start (with ramp_size_m > 0) */
    double ramp_rate_Hz;   /**< ramp frequency, Hz: an approach and a retract of ramp_size_m per period
                                (both speeds 2·ramp_size_m·ramp_rate_Hz); 0: speeds or times */
    double extend_time_s;  /**< approach (extend) time of ramp_size_m, s (v_approach = ramp/time); 0: speed */
    double retract_time_s; /**< retract time of ramp_size_m, s (v_retract = ramp/time); 0: speed */
    int segment_samples;   /**< samples per approach segment of ramp_size_m (sample_rate_Hz = samples /
                                extend time); 0: sample_rate_Hz */
    int setpoint_mode;     /**< enum vafm_setpoint_mode */
    double setpoint_V;     /**< setpoint in volts of deflection signal (setpoint_N = k·InvOLS·V, absolute:
                                less the baseline_offset_V); 0: setpoint_N */
    int dwell_mode;        /**< enum vafm_dwell_mode */
    double dwell_feedback_s; /**< constant-force dwell: time constant of the feedback loop, s (0: 10 sample
                                  intervals; else at least 2) */
    double tune_rate_Hz;   /**< thermal tune sample rate, Hz (0: automatic, vafm_params_tune_rate_Hz) */
    /* topography (a force map's pixel, vafm/map.h) */
    double surface_height_m; /**< height of the sample surface (the contact point) above the reference plane
                                  (a map's substrate), m: every piezo height a curve reports (samples, touch and
                                  detach heights) is measured from that plane; start_height_m and
                                  trigger_height_m stay relative to the contact point. Default 0 */
    /* instrument artefacts (off at 0): the measured signal (vafm/detector.h; the physics is untouched) */
    double drift_V_per_s;  /**< linear drift of the deflection signal's baseline, V/s */
    double drift_walk_V_per_sqrt_s; /**< random walk of the baseline, V/√s (its own stream) */
    double virtual_deflection_V_per_m; /**< baseline slope with the piezo height (virtual deflection), V/m */
    double interference_V; /**< laser interference on the baseline: amplitude, V (a sinusoid in height) */
    double interference_period_m; /**< its period in piezo height, m (near half the laser wavelength) */
    double flicker_corner_Hz; /**< 1/f noise of the signal: the frequency where it equals the white floor
                                   noise_V_rms, Hz (the 1/f band reaches down to 1 mHz) */
    double mains_V;        /**< mains pickup: amplitude of the fundamental, V (harmonics 2 and 3 at 1/2, 1/3) */
    double mains_Hz;       /**< mains frequency, Hz (50 or 60) */
    /* ... and of the sample (they move the surface the tip meets) */
    double contact_point_sd_m; /**< each curve's surface at a random height: normal with this sd, m */
    double sample_drift_m_per_s; /**< the sample surface rises at this speed during a curve, m/s */
    /* ... and of the piezo (the support goes where the actuator takes it; the files' height (piezo) is the
     * command, height (measured) the z sensor's reading of the actual height) */
    double piezo_hysteresis; /**< Bouc–Wen hysteresis strength H: the loop is 2·H·L_s wide (0: none) */
    double piezo_hysteresis_length_m; /**< its saturation length L_s, m */
    double piezo_creep;    /**< logarithmic creep after a move: fraction of the move per decade of time (0: none) */
    double piezo_creep_t0_s; /**< its reference time t0, s (creep ∝ log10(1 + t/t0)) */
    double zsensor_noise_m; /**< closed-loop z sensor: white noise of the measured height, m rms (0: none) */
    double zsensor_bandwidth_Hz; /**< its first-order bandwidth, Hz (0: unlimited) */
    uint8_t reserved[24];
} vafm_params;

/** The paper's automatic step, ω_max·dt = 2π/40 (its Eq. 8; 0.157): the default omega_dt of every preset,
 *  chosen by evidence (docs/speed-and-accuracy.md, "The default step"). The text value "paper" of
 *  omega_dt (vafm_params_set, `--omega_dt paper`) names it. */
#define VAFM_OMEGA_DT_PAPER (2.0 * 3.14159265358979323846 / 40.0)

/** The scene the tools (vafm, vafmd, make demo) start from: an instrument at room temperature. */
#define VAFM_TOOLS_DEFAULT_PRESET "contact-silica"

/** Fill p with the library's reference scene (preset "paper-fig1", the paper's reduced Fig. 1/2 scene). */
VAFM_API void vafm_params_default(vafm_params *p);

/** Number of presets; names and one-line descriptions by index. */
VAFM_API int vafm_preset_count(void);
VAFM_API const char *vafm_preset_name(int i);
VAFM_API const char *vafm_preset_description(int i);

/** Overwrite p with preset `name`. @return 0 or VAFM_ENOTFOUND (err names the known presets). */
VAFM_API int vafm_preset_apply(vafm_params *p, const char *name, vafm_error *err);

/** Derive the fields underneath from the instrument's settings: the speeds from ramp_rate_Hz or
 *  extend_time_s / retract_time_s (with ramp_size_m), sample_rate_Hz from segment_samples, setpoint_N from
 *  setpoint_V. Call it after the last setting and before validation (the time-based settings win over
 *  speeds given as well); idempotent. @return 0 or VAFM_EINVAL (err names the setting that cannot apply). */
VAFM_API int vafm_params_resolve(vafm_params *p, vafm_error *err);

/** Check every field and the combination (e.g. time step against the stability limit).
 *  @return 0 or VAFM_EINVAL / VAFM_EUNSTABLE with err naming the field, its value and the range. */
VAFM_API int vafm_params_validate(const vafm_params *p, vafm_error *err);

/** The cantilever's effective mass, kg: k/(2π f0_Hz)² when f0_Hz > 0, else m_kg. */
VAFM_API double vafm_params_mass_kg(const vafm_params *p);
/** The effective friction rate, 1/s: 2π f0 / Q when Q > 0 (f0 = f0_Hz, or √(k/m)/2π), else eta_per_s. */
VAFM_API double vafm_params_eta_per_s(const vafm_params *p);

/** The sample rate of a thermal tune, Hz: tune_rate_Hz when > 0, else sample_rate_Hz raised, when lower, to
 *  the first 1-2-5 value at or above 4 f0 (a tune must show the resonance: f0 below Nyquist, with room). */
VAFM_API double vafm_params_tune_rate_Hz(const vafm_params *p);
/** The scene a thermal tune runs: p at the tune's sample rate (segment_samples cleared, it is the curve's). */
VAFM_API void vafm_params_tune_scene(const vafm_params *p, vafm_params *out);

/** Kind of a parameter in the field table. */
enum vafm_param_kind {
    VAFM_PARAM_REAL = 0, /**< double, with unit and range */
    VAFM_PARAM_CHOICE,   /**< one of a list of names (integrator, contact, noise, trigger, ...) */
    VAFM_PARAM_SEED,     /**< unsigned 64-bit integer */
    VAFM_PARAM_BOOL,     /**< 0 or 1 */
    VAFM_PARAM_INT,      /**< int, with unit and range (min, max) */
};

/** One row of the field table. */
typedef struct vafm_param_info {
    const char *name;    /**< field name as used in JSON, CLI (--name=value) and files */
    int kind;            /**< enum vafm_param_kind */
    const char *unit;    /**< SI unit ("N/m"), "" if dimensionless */
    double min, max;     /**< allowed closed range (REAL, INT) */
    const char *choices; /**< CHOICE: names separated by '|' */
    const char *doc;     /**< one line of documentation */
} vafm_param_info;

/** @return the number of rows of the field table. */
VAFM_API int vafm_params_field_count(void);
/** @return row i, or NULL. */
VAFM_API const vafm_param_info *vafm_params_field_at(int i);
/** @return the row named `name`, or NULL. */
VAFM_API const vafm_param_info *vafm_params_field_find(const char *name);

/** Set a field from text ("6.3e-3", "gjf", "true"). Checks the field's own range.
 *  @return 0, VAFM_ENOTFOUND (no such field) or VAFM_EINVAL, with err filled. */
VAFM_API int vafm_params_set(vafm_params *p, const char *name, const char *value, vafm_error *err);

/** Format a field's value as text into buf (REAL with %.17g). @return 0 or VAFM_ENOTFOUND. */
VAFM_API int vafm_params_get(const vafm_params *p, const char *name, char *buf, size_t len);

/** Serialise every field as one JSON object {"name": value, ...} into buf (NUL-terminated).
 *  @return the length written, or VAFM_EINVAL when len is too small. */
VAFM_API int vafm_params_to_json(const vafm_params *p, char *buf, size_t len);

#ifdef __cplusplus
}
#endif
#endif
