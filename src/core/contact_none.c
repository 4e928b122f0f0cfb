/* SPDX-License-Identifier: MIT */
/*
 * No sample: a free cantilever. Never in contact (u_touch = u_detach = +inf), F = 0, U = 0.
 */
#include "vafm/contact.h"

#include <math.h>

static double s_none_force(const vafm_contact *ct, double u, double *s_io, double *dFdu)
{
    (void)ct;
    (void)u;
    if (s_io)
        *s_io = 0.0;
    if (dFdu)
        *dFdu = 0.0;
    return 0.0;
}

static double s_none_energy(const vafm_contact *ct, double u)
{
    (void)ct;
    (void)u;
    return 0.0;
}

static int s_none_init(vafm_contact *c, double gamma)
{
    (void)gamma; /* ignored: no sample, no adhesion */
    c->u_touch = INFINITY;
    c->u_detach = INFINITY;
    return VAFM_OK;
}

static const vafm_contact_type s_none_type = {
    .name = "none",
    .description = "no sample: free cantilever, never in contact",
    .force = s_none_force,
    .energy = s_none_energy,
    .flags = 0,
    .init = s_none_init,
    .at_force = NULL,
};

VAFM_API const vafm_contact_type *const vafm_contact_none = &s_none_type;
