/* SPDX-License-Identifier: MIT */
/*
 * A tabulated JKR branch for the hot step: the in-contact step's largest cost is the Newton solve of
 * u = s⁴ − c·s for s = √a (1–4 iterations, each with a division, more when the body moves far per
 * step). The table replaces it by one square root and a cubic Hermite interpolation.
 *
 * Variable: ξ = √(u − u_min). The solver's t = s − s_m is an analytic function of ξ (t ≈ ξ/(√6 s_m)
 * near the branch end, ~√ξ far from it), while as a function of u it has a square-root singularity
 * at u_min. Nodes are uniform in ξ on [0, ξ_max]; each holds t and dt/dξ = 2ξ/P'(t) from the exact
 * solver. The table is built at scene creation (never in the step) and checks itself: it doubles the
 * node count until the interpolation error at every interval midpoint is below 1e-13 relative in s.
 * Beyond ξ_max (a contact deeper than the scene was built for) the exact solver takes over.
 */
#ifndef VAFM_CORE_JKR_TABLE_H
#define VAFM_CORE_JKR_TABLE_H

#include <math.h>

#include "vafm/contact.h"
#include "core/gjf_step.h"
#include "core/jkr_inline.h"

typedef struct vafm_jkr_table {
    double inv_h;   /* 1/h, h the node spacing in ξ */
    double h;
    double xi_max;  /* the table covers 0 ≤ ξ < xi_max */
    double max_err; /* worst relative midpoint error in s found at build time */
    int n;          /* nodes */
    double *node;   /* 2n values: t_i, h·dt/dξ_i interleaved (one cache line per interval) */
} vafm_jkr_table;

/** Build a table for contact c covering u ≤ u_max. @return 0, VAFM_EINVAL (not JKR with γ > 0) or
 *  VAFM_ENOMEM. */
int vafm_jkr_table_init(vafm_jkr_table *T, const vafm_contact *c, double u_max);
void vafm_jkr_table_free(vafm_jkr_table *T);

/** Contact force on the branch (u ≥ u_min) with √a in *s_io (used as warm start by the fallback). */
static inline double vafm_jkr_table_force(const vafm_jkr_table *T, const vafm_contact *c, double u, double *s_io)
{
    const double x = VAFM_JKR_TABLE_X(u, c->u_detach, T->inv_h, sqrt);
    if (!(x < (double)(T->n - 1))) /* beyond the table, or NaN */
        return vafm_jkr_force_inline(c, u, s_io, NULL);
    const int i = (int)x;
    const double f = x - (double)i, g = 1.0 - f;
    const double *p = T->node + 2 * i;
    const double t = VAFM_JKR_HERMITE(f, g, p[0], p[1], p[2], p[3]); /* core/gjf_step.h, as every kernel */
    const double s = c->s_m + t, s3 = VAFM_JKR_CUBE(s);
    *s_io = s;
    return VAFM_JKR_FORCE(s3, 2.0 * c->c);
}

#endif
