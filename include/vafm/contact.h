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

struct vafm_contact_type {
    const char *name;        /**< "jkr", "hertz", "none" */
    const char *description; /**< one line for --help */
    /** Contact force on the branch for u ≥ u_detach. *s_io is a warm start for √a (≤ 0: none) and
     *  receives √a. Never allocates; safe in the hot step. @return F; *dFdu may be NULL. */
    double (*force)(const vafm_contact *c, double u, double *s_io, double *dFdu);
    /** Contact energy U(u) on the branch (reduced, unit E*R³), U = 0 when detached. */
    double (*energy)(const vafm_contact *c, double u);
};

VAFM_API extern const vafm_contact_type *const vafm_contact_jkr;   /**< JKR, robust t-form solver */
VAFM_API extern const vafm_contact_type *const vafm_contact_hertz; /**< Hertz (γ = 0), closed form */
VAFM_API extern const vafm_contact_type *const vafm_contact_none;  /**< no sample: free cantilever */

/** Bind a model to a reduced work of adhesion gamma (≥ 0; Hertz and none require / ignore it).
 *  @return 0 or VAFM_EINVAL. */
VAFM_API int vafm_contact_init(vafm_contact *c, const vafm_contact_type *type, double gamma);

/** Evaluate a, F, dF/du on the contact branch (u ≥ u_detach); VAFM_EINVAL below u_detach. */
VAFM_API int vafm_contact_eval_at(const vafm_contact *c, double u, vafm_contact_eval *out);

/** @return the contact type named `name`, or NULL. */
VAFM_API const vafm_contact_type *vafm_contact_type_find(const char *name);

#ifdef __cplusplus
}
#endif
#endif
