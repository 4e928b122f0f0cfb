/* SPDX-License-Identifier: MIT */
/**
 * @file integrator.h
 * Integrators as type objects (GSL style). Their step loops are internal; a scene selects one by
 * pointer (vafm_params.integrator) or by name.
 */
#ifndef VAFM_INTEGRATOR_H
#define VAFM_INTEGRATOR_H

#include "vafm/common.h"

#ifdef __cplusplus
extern "C" {
#endif

struct vafm_kernel;
typedef struct vafm_integrator_type vafm_integrator_type;

struct vafm_integrator_type {
    const char *name;        /**< "gjf", "baoab", "paper-vv", "brownian" */
    const char *description; /**< one line for --help */
    int overdamped;          /**< 1: no inertia (the mass only sets the friction ζ = mη) */
    /** Hard stability limit: ω_max·dt (underdamped) or K_max·dt/ζ (overdamped) must stay below it. */
    double stability_limit;
    /** Internal: prepare cached forces after the state changed outside the loop. */
    void (*prepare)(struct vafm_kernel *K);
    /** Internal: advance up to n steps; stops early after a step that changed the contact state.
     *  Never allocates, locks or does I/O. @return the number of steps done. */
    long (*run)(struct vafm_kernel *K, long n);
    /** Internal: fill this integrator's own step coefficients of both contact states for the step
     *  K->dt (the shared ones, the friction rate and ζ, are set before). */
    void (*set_dt)(struct vafm_kernel *K);
    /** The widest batch of curves the batch kernel (SIMD lanes) steps with this integrator side by
     *  side; 0: none, it runs in its scalar loop only. */
    int batch_lanes;
    /** Friction limit: the total friction rate times the step, η·dt (with the contact friction in
     *  contact), must stay below it; 0: none (the paper's VV: 2). */
    double eta_dt_limit;
};

VAFM_API extern const vafm_integrator_type *const vafm_integrator_gjf;      /**< Grønbech-Jensen–Farago 2013 */
VAFM_API extern const vafm_integrator_type *const vafm_integrator_baoab;    /**< Leimkuhler–Matthews 2013 */
VAFM_API extern const vafm_integrator_type *const vafm_integrator_paper_vv; /**< the paper's VV, Eq. 7 */
VAFM_API extern const vafm_integrator_type *const vafm_integrator_brownian; /**< overdamped Euler, Eq. 12 */

/** @return the integrator named `name`, or NULL. */
VAFM_API const vafm_integrator_type *vafm_integrator_find(const char *name);
/** Number of integrators and access by index (for listings). */
VAFM_API int vafm_integrator_count(void);
VAFM_API const vafm_integrator_type *vafm_integrator_at(int i);

#ifdef __cplusplus
}
#endif
#endif
