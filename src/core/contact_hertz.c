/* SPDX-License-Identifier: MIT */
/*
 * Hertz contact (no adhesion), reduced units E* = R = 1, closed form:
 *   a = √u,  F = (4/3)u^{3/2},  dF/du = 2√u,  U = (8/15)u^{5/2}  (dU/du = F),
 * for u ≥ u_detach = 0. Below 0 the branch does not exist: force() gives NaN (the caller must not ask),
 * energy() gives 0 (detached).
 */
#include "vafm/contact.h"

#include <math.h>

#include "core/jkr_inline.h"

static double s_hertz_force(const vafm_contact *ct, double u, double *s_io, double *dFdu)
{
    (void)ct;
    const double a = sqrt(u); /* NaN below 0 */
    if (s_io)
        *s_io = sqrt(a);
    if (dFdu)
        *dFdu = 2.0 * a;
    return (4.0 / 3.0) * a * u;
}

static double s_hertz_energy(const vafm_contact *ct, double u)
{
    (void)ct;
    if (isnan(u))
        return u;
    if (u < 0.0)
        return 0.0;
    return (8.0 / 15.0) * u * u * sqrt(u);
}

static int s_hertz_init(vafm_contact *c, double gamma)
{
    if (gamma != 0.0)
        return VAFM_EINVAL;
    c->u_touch = 0.0;
    c->u_detach = 0.0;
    return VAFM_OK;
}

/* Hertz is JKR's branch at c = 0: the same expressions give the same bits as before the hook */
static void s_hertz_at_force(const vafm_contact *ct, double F, double *u, double *dFdu)
{
    vafm_jkr_at_force(ct->c, F, u, dFdu);
}

static const vafm_contact_type s_hertz_type = {
    .name = "hertz",
    .description = "Hertz elastic contact without adhesion (gamma = 0), closed form",
    .force = s_hertz_force,
    .energy = s_hertz_energy,
    .flags = VAFM_CONTACT_SURFACE | VAFM_CONTACT_WELL | VAFM_CONTACT_MONOTONE,
    .init = s_hertz_init,
    .at_force = s_hertz_at_force,
};

VAFM_API const vafm_contact_type *const vafm_contact_hertz = &s_hertz_type;
