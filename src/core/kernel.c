/* SPDX-License-Identifier: MIT */
/* The kernel's out-of-line helpers that every integrator's loop calls (kernel.h). They sit apart from the
 * integrator registry (integrators.c), which refers to the integrators: the loops call down to this file,
 * the registry calls up to the loops, and no two files call each other. */
#include "core/kernel.h"

int vafm_kernel_baseline = 0;

VAFM_KCOLD vafm_kfs vafm_kernel_contact_eval(const vafm_kernel *K, double u, double s)
{
    vafm_kfs r;
    r.s = s;
    if (K->jtab)
        r.F = vafm_jkr_table_force(K->jtab, &K->contact, u, &r.s);
    else if (K->is_jkr)
        r.F = vafm_jkr_force_inline(&K->contact, u, &r.s, NULL);
    else
        r.F = K->cforce(&K->contact, u, &r.s, NULL);
    return r;
}

VAFM_KCOLD vafm_kfs vafm_kernel_table_far(const vafm_kernel *K, double u, double s)
{
    vafm_kfs r;
    r.s = s;
    r.F = vafm_jkr_force_inline(&K->contact, u, &r.s, NULL);
    return r;
}
