/* SPDX-License-Identifier: MIT */
/**
 * @file units.h
 * The reduced model and the one place where SI converts to it (physics notes, "Units").
 *
 * Reduced units set η, R, E* and k_B to 1: length unit R, time unit 1/η, force unit E*R²,
 * energy unit E*R³. m̃ = mη²/(E*R), ṽ = v/(Rη), k̃ = k/(E*R), k_BT̃ = k_BT/(E*R³), γ̃ = γ/(E*R).
 */
#ifndef VAFM_UNITS_H
#define VAFM_UNITS_H

#include "vafm/common.h"
#include "vafm/params.h"

#ifdef __cplusplus
extern "C" {
#endif

#define VAFM_KB_J_PER_K 1.380649e-23 /**< Boltzmann constant (exact, SI 2019), J/K */

/** Scale factors from reduced to SI (multiply a reduced value by these to get SI). */
typedef struct vafm_scale {
    double length_m;  /**< R */
    double time_s;    /**< 1/η */
    double force_N;   /**< E*R² */
    double energy_J;  /**< E*R³ */
    double speed_m_per_s; /**< Rη */
    double stiffness_N_per_m; /**< E*R */
} vafm_scale;

/* Reduced ↔ SI, declared once. Outside units.c the core scales a value only through these: `_si` is one
 * multiplication by the factor (reduced → SI), `_red` one division by it (SI → reduced), so a call is
 * the same double as the expression `x * s->factor` or `x / s->factor` it stands for (x*f and x/f are
 * not the same double as each other: a site keeps the operation it had). */
static inline double vafm_scale_length_si(const vafm_scale *s, double x) { return x * s->length_m; }
static inline double vafm_scale_length_red(const vafm_scale *s, double x_m) { return x_m / s->length_m; }
static inline double vafm_scale_time_si(const vafm_scale *s, double x) { return x * s->time_s; }
static inline double vafm_scale_time_red(const vafm_scale *s, double x_s) { return x_s / s->time_s; }
static inline double vafm_scale_force_si(const vafm_scale *s, double x) { return x * s->force_N; }
static inline double vafm_scale_force_red(const vafm_scale *s, double x_N) { return x_N / s->force_N; }
static inline double vafm_scale_energy_si(const vafm_scale *s, double x) { return x * s->energy_J; }
static inline double vafm_scale_energy_red(const vafm_scale *s, double x_J) { return x_J / s->energy_J; }
static inline double vafm_scale_speed_si(const vafm_scale *s, double x) { return x * s->speed_m_per_s; }
static inline double vafm_scale_speed_red(const vafm_scale *s, double x_m_per_s) { return x_m_per_s / s->speed_m_per_s; }
static inline double vafm_scale_stiffness_si(const vafm_scale *s, double x) { return x * s->stiffness_N_per_m; }
static inline double vafm_scale_stiffness_red(const vafm_scale *s, double x_N_per_m)
{
    return x_N_per_m / s->stiffness_N_per_m;
}

/** A scene's physics in reduced units. */
typedef struct vafm_reduced {
    double m;        /**< m̃ = mη²/(E*R) */
    double eta_cont; /**< contact friction rate / η */
    double k;        /**< k̃ */
    double kT;       /**< k_BT̃ */
    double gamma;    /**< γ̃ */
    double v_approach, v_retract; /**< ṽ */
} vafm_reduced;

/** @return the scale factors of a scene. */
VAFM_API vafm_scale vafm_units_scale(const vafm_params *p);

/** Convert a scene's physics to reduced units. */
VAFM_API void vafm_units_reduce(const vafm_params *p, vafm_reduced *out);

/** Set the SI fields of p (γ, k, m, η, T, speeds) from reduced values, keeping E*, R and m_kg.
 *  η follows from m̃ and m_kg: η = √(m̃E*R/m). */
VAFM_API void vafm_units_from_reduced(vafm_params *p, const vafm_reduced *r);

/** Read a value typed with its unit, as people type it where a field has a fixed SI unit: a number alone
 *  (already in `unit`), or a number followed by `unit` with an optional SI prefix (f p n u µ μ m k M G T)
 *  and at most one space: "1nN" for N, "2um/s" for m/s, "70kHz" for Hz, "50mJ/m^2" (also "J/m2") for
 *  J/m^2. Temperatures (unit "K") also take Celsius: "25C" or "25degC" is 298.15 K. Strict: any other
 *  suffix is an error, so a value meant for another field (a length typed as a force) never passes.
 *  @return 0 with *out in SI, or VAFM_EINVAL (err names `field`, the unit and the prefixes allowed). */
VAFM_API int vafm_units_parse(const char *field, const char *text, const char *unit, double *out,
                              vafm_error *err);

#ifdef __cplusplus
}
#endif
#endif
