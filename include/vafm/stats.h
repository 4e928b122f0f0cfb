/* SPDX-License-Identifier: MIT */
/**
 * @file stats.h
 * Statistics of force-curve campaigns, in one place for every program (the CLI's `curves` and
 * `campaign` summaries, `vafm info`, the paper study): the per-curve observables by name, the one rule
 * for which curves count as a pull-off, running moments that fit any N in constant memory, and the
 * per-grid-point table. Pure computation: no I/O, no allocation.
 */
#ifndef VAFM_STATS_H
#define VAFM_STATS_H

#include <stdint.h>
#include "vafm/common.h"
#include "vafm/params.h"
#include "vafm/sim.h"

#ifdef __cplusplus
extern "C" {
#endif

/** The per-curve observables that statistics are taken of (fields of vafm_curve_result). */
typedef enum vafm_observable {
    VAFM_OBS_PULLOFF_SAMPLED = 0, /**< pulloff_sampled_N: most tensile output sample of the retract, N */
    VAFM_OBS_PULLOFF_SPRING,      /**< pulloff_spring_N: most tensile spring force of any step, N */
    VAFM_OBS_DETACH_FORCE,        /**< detach_force_N: spring force when the body passed u_min, N */
    VAFM_OBS_DETACH_HEIGHT,       /**< detach_height_m: piezo height above the contact point then, m */
    VAFM_OBS_DETACH_EQ_FORCE,     /**< detach_eq_force_N: noise-free equilibrium spring force there, N */
    VAFM_OBS_COUNT
} vafm_observable;

/** Name, kind and one-line meaning of an observable. */
typedef struct vafm_observable_info {
    const char *name; /**< the result field's name, e.g. "pulloff_spring_N" */
    int is_force;     /**< 1: a tensile force magnitude in N; 0: a height in m */
    const char *doc;  /**< one line */
} vafm_observable_info;

/** @return the description of observable `obs`, or NULL outside [0, VAFM_OBS_COUNT). */
VAFM_API const vafm_observable_info *vafm_stats_observable(int obs);

/** @return observable `obs` of a curve result (NaN outside the range). */
VAFM_API double vafm_stats_value(const vafm_curve_result *r, int obs);

/** The curve flags (VAFM_CURVE_*) that exclude a curve from the pull-off statistics: every flag but
 *  VAFM_CURVE_RECONTACT. A curve that never touched, lost contact before the retract, never let go, or
 *  never reached its trigger has no pull-off of the scene's kind to average. */
#define VAFM_STATS_EXCLUDING_FLAGS (VAFM_CURVE_NO_CONTACT | VAFM_CURVE_EARLY_DETACH | VAFM_CURVE_NO_DETACH | \
                                    VAFM_CURVE_NO_TRIGGER)

/** The one rule: a curve counts as a pull-off when it ended without error (status 0) and carries none
 *  of VAFM_STATS_EXCLUDING_FLAGS. @return 1 or 0. */
VAFM_API int vafm_stats_is_pulloff(int status, const vafm_curve_result *r);

/** Running central moments (Welford/Pébay update). Zero-initialise. */
typedef struct vafm_moments {
    uint64_t n;  /**< values added */
    double mean; /**< running mean */
    double m2;   /**< sum of squared deviations */
    double m3;   /**< sum of cubed deviations */
} vafm_moments;

/** Add one value. */
VAFM_API void vafm_moments_add(vafm_moments *m, double x);
/** @return the sample standard deviation (n − 1), NaN for n < 2. */
VAFM_API double vafm_moments_sd(const vafm_moments *m);
/** @return the standard error of the mean, NaN for n < 2. */
VAFM_API double vafm_moments_sem(const vafm_moments *m);
/** @return the sample skewness √n·m3/m2^1.5, NaN for n < 3 or no spread. */
VAFM_API double vafm_moments_skewness(const vafm_moments *m);

/** Number of curve flags counted per point (VAFM_CURVE_NO_CONTACT … VAFM_CURVE_RECONTACT, bit order). */
#define VAFM_STATS_NFLAGS 5

/** Statistics of one grid point. Zero-initialise. */
typedef struct vafm_point_stats {
    uint64_t curves;                         /**< curves added */
    uint64_t failed;                         /**< of them, curves that ended with an error */
    uint64_t used;                           /**< of them, curves with a pull-off (vafm_stats_is_pulloff) */
    uint64_t flag_count[VAFM_STATS_NFLAGS];  /**< curves carrying flag 1 << i */
    vafm_moments obs[VAFM_OBS_COUNT];        /**< moments of each observable over the pull-off curves */
} vafm_point_stats;

/** Add one curve (its status and result) to a point's statistics. */
VAFM_API void vafm_point_stats_add(vafm_point_stats *st, int status, const vafm_curve_result *r);

/** @return a short word for curve flag 1 << i ("no-contact", …) and, in *doc, its meaning; NULL
 *  outside [0, VAFM_STATS_NFLAGS). doc may be NULL. */
VAFM_API const char *vafm_stats_flag_word(int i, const char **doc);

/** @return the JKR pull-off force of a rigid-support quasi-static pull, F_JKR = (3/2)·π·γ·R, in N: the
 *  force scale the statistics are quoted in. */
VAFM_API double vafm_stats_f_jkr_N(const vafm_params *p);

#ifdef __cplusplus
}
#endif
#endif
