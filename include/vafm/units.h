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
