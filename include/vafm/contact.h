/* SPDX-License-Identifier: MIT */
/**
 * @file contact.h
 * Contact models as type objects (GSL style), in reduced units (E* = R = 1; see units.h).
 *
 * Conventions (physics notes, settled): u is the indentation of the elastic body, positive in
 * compression; F is the contact force on the body, positive when repulsive; U(u) is the contact energy
 * along the contact branch with dU/du = F, U = 0 out of contact.
 * Hysteresis: a body out of contact touches when u reaches u_touch (0); a body in contact stays on the
 * contact branch until u falls below u_detach (JKR: u_min < 0; Hertz: 0).
 */
#ifndef VAFM_CONTACT_H
#define VAFM_CONTACT_H

#include "vafm/common.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct vafm_contact_type vafm_contact_type;

/** A contact model bound to its (reduced) parameters. Plain data, built by vafm_contact_init(). */
typedef struct vafm_contact {
    const vafm_contact_type *type; /**< the model */
    double gamma;    /**< reduced work of adhesion γ/(E*R) (the paper's surface energy); 0 for hertz */
    double c;        /**< √(2πγ): u = s⁴ − c·s with s = √a (reduced) */
    double s_m;      /**< (c/4)^(1/3): √a where the two branches meet (at u_min) */
    double u_touch;  /**< indentation at which an approaching body touches (0; +inf for none) */
    double u_detach; /**< indentation below which contact is lost (u_min for JKR, 0 Hertz, +inf none) */
    double a0;       /**< contact radius at u = 0 on the contact branch: (2πγ)^(1/3) */
    double F_jkr;    /**< 3πγ/2: the JKR pull-off force under load control (reduced) */
} vafm_contact;

/** Result of evaluating a contact model on its contact branch. */
typedef struct vafm_contact_eval {
    double a;    /**< contact radius (reduced, unit R) */
    double F;    /**< contact force on the body, repulsive positive (unit E*R²) */
    double dFdu; /**< contact stiffness dF/du (unit E*R); −inf at u_min for JKR */
} vafm_contact_eval;

/** @name Capability flags of a contact model (vafm_contact_type.flags)
 *  The simulation asks these, never which model it holds: a model without a flag never enters the path
 *  that needs it. @{ */
/** It has a surface: the tip can touch it (every model but `none`). */
#define VAFM_CONTACT_SURFACE 0x1u
/** It takes a work of adhesion γ > 0 (the scene's gamma_J_per_m2 is passed to its init hook; a model
 *  with a surface and without this flag requires gamma_J_per_m2 = 0). */
#define VAFM_CONTACT_ADHESIVE 0x2u
/** Its branch is JKR's, u = s⁴ − c·s with c = √(2πγ): the closed-form references (theory.h: the
 *  quasi-static pull-off, the equilibrium), the tabulated force (contact_table) and the inlined solver
 *  apply. */
#define VAFM_CONTACT_JKR_BRANCH 0x4u
/** The exact well step (well_exact) may propagate its deep well: the step linearises the branch in the
 *  JKR t-form (s_m, c; Hertz is c = 0), so only a model of that family may set it. */
#define VAFM_CONTACT_WELL 0x8u
/** Its stiffness dF/du grows strictly along the branch: the runtime stiffness guard may then skip
 *  indentations below a threshold it computes once (guard.h). */
#define VAFM_CONTACT_MONOTONE 0x10u
/** @} */

struct vafm_contact_type {
    const char *name;        /**< "jkr", "hertz", "none" */
    const char *description; /**< one line for --help */
    /** Contact force on the branch for u ≥ u_detach. *s_io is a warm start for √a (≤ 0: none) and
     *  receives √a. Never allocates; safe in the hot step. @return F; *dFdu may be NULL. */
    double (*force)(const vafm_contact *c, double u, double *s_io, double *dFdu);
    /** Contact energy U(u) on the branch (reduced, unit E*R³), U = 0 when detached. */
    double (*energy)(const vafm_contact *c, double u);
    unsigned flags; /**< VAFM_CONTACT_* capabilities */
    /** Fill the model's fields of *c (type already set, the rest 0) for a reduced work of adhesion
     *  gamma (finite, ≥ 0; 0 unless VAFM_CONTACT_ADHESIVE). @return 0 or VAFM_EINVAL. */
    int (*init)(vafm_contact *c, double gamma);
    /** Where the stable branch carries a repulsive force F ≥ 0: the indentation *u and the stiffness
     *  *dFdu (the time step is chosen from it). Required with VAFM_CONTACT_SURFACE, else NULL. */
    void (*at_force)(const vafm_contact *c, double F, double *u, double *dFdu);
};

VAFM_API extern const vafm_contact_type *const vafm_contact_jkr;   /**< JKR, robust t-form solver */
VAFM_API extern const vafm_contact_type *const vafm_contact_hertz; /**< Hertz (γ = 0), closed form */
VAFM_API extern const vafm_contact_type *const vafm_contact_none;  /**< no sample: free cantilever */

/** Bind a model to a reduced work of adhesion gamma (≥ 0; Hertz and none require / ignore it) through
 *  its init hook; any type object with force, energy and init hooks (and at_force with a surface) may be
 *  bound, listed in the registry or not. @return 0 or VAFM_EINVAL. */
VAFM_API int vafm_contact_init(vafm_contact *c, const vafm_contact_type *type, double gamma);

/** Evaluate a, F, dF/du on the contact branch (u ≥ u_detach); VAFM_EINVAL below u_detach. */
VAFM_API int vafm_contact_eval_at(const vafm_contact *c, double u, vafm_contact_eval *out);

/** @return the contact type named `name`, or NULL. */
VAFM_API const vafm_contact_type *vafm_contact_type_find(const char *name);
/** Number of contact models and access by index (for listings); NULL outside [0, count). */
VAFM_API int vafm_contact_type_count(void);
VAFM_API const vafm_contact_type *vafm_contact_type_at(int i);

#ifdef __cplusplus
}
#endif
#endif
