/* SPDX-License-Identifier: MIT */
/*
 * Test helper: a force-triggered curve's approach against Hertz, F = (4/3)E*√R δ^{3/2}. Shared by test_curve
 * (the hertz contact) and test_hardcases (JKR as γ → 0): the same protocol, the same measurement.
 */
#ifndef VAFM_TESTS_HERTZ_H
#define VAFM_TESTS_HERTZ_H

#include <math.h>

#include "vafm/params.h"
#include "vafm/units.h"
#include "trace.h"

/* The protocol, in p's reduced units: a force trigger at F̃ = 0.5 from 0.05 above the contact point, a point
 * sample every 20 time units, the retract 0.02 past the start. */
static inline void t_hertz_protocol(vafm_params *p)
{
    const vafm_scale sc = vafm_units_scale(p);
    p->trigger = VAFM_TRIGGER_FORCE;
    p->start_height_m = 0.05 * sc.length_m;
    p->setpoint_N = 0.5 * sc.force_N;
    p->sample_rate_Hz = 1.0 / (20.0 * sc.time_s);
    p->antialias = VAFM_ANTIALIAS_POINT;
    p->retract_margin_m = 0.02 * sc.length_m;
}

/* The approach samples of c with a force of F_min or more against Hertz on p's E* and R: *n of them, *bad
 * off by more than tol relative (NaN counts as off), *worst the largest relative deviation. */
static inline void t_hertz_approach(const t_trace *c, const vafm_params *p, double F_min, double tol, int *n,
                                    int *bad, double *worst)
{
    const double pref = (4.0 / 3.0) * p->E_star_Pa * sqrt(p->R_m);
    *n = *bad = 0;
    *worst = 0.0;
    for (size_t i = 0; i < c->n && c->seg[i] == VAFM_SEG_APPROACH; i++) {
        if (c->f[i] < F_min)
            continue;
        const double d = -c->tip[i], F = pref * d * sqrt(d), e = fabs(c->f[i] - F) / F;
        *worst = fmax(*worst, e);
        *bad += !(e <= tol);
        (*n)++;
    }
}

#endif
