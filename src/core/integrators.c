/* SPDX-License-Identifier: MIT */
/* The integrator registry (models.h) and the step size: the shared friction, then each integrator's own
 * coefficients (its set_dt hook). */
#include <math.h>
#include <string.h>

#include "core/kernel.h"
#include "core/models.h"

#define S_ROW(id, name, help) &vafm_integrator_##id
#define S_COMMA ,
static const vafm_integrator_type *const *const s_all[] = {VAFM_INTEGRATORS(S_ROW, S_COMMA)};
#undef S_ROW
#undef S_COMMA
#define S_NINTEGRATORS ((int)(sizeof s_all / sizeof s_all[0]))

int vafm_integrator_count(void)
{
    return S_NINTEGRATORS;
}

const vafm_integrator_type *vafm_integrator_at(int i)
{
    return i >= 0 && i < S_NINTEGRATORS ? *s_all[i] : NULL;
}

const vafm_integrator_type *vafm_integrator_find(const char *name)
{
    for (int i = 0; name && i < S_NINTEGRATORS; i++)
        if (!strcmp((*s_all[i])->name, name))
            return *s_all[i];
    return NULL;
}

/* Every registered integrator's coefficients are filled, so that a kernel may be handed to any of them
 * (the tests step one kernel with several); each integrator owns its own (its set_dt hook). */
void vafm_kernel_set_dt(vafm_kernel *K, double dt)
{
    K->dt = dt;
    for (int i = 0; i < 2; i++) {
        vafm_kcoef *c = &K->co[i];
        c->eta_tot = 1.0 + (i ? K->eta_c : 0.0);
        c->zeta = K->m * c->eta_tot;
    }
    for (int j = 0; j < S_NINTEGRATORS; j++)
        (*s_all[j])->set_dt(K);
}
