/* SPDX-License-Identifier: MIT */
/*
 * The contact models' registry (models.h) and the functions every model shares: binding a model to its
 * parameters through its init hook, evaluating it, finding it by name.
 */
#include "vafm/contact.h"

#include <math.h>
#include <string.h>

#include "core/models.h"

#define S_ROW(id, name, help) &vafm_contact_##id
#define S_COMMA ,
static const vafm_contact_type *const *const s_all[] = {VAFM_CONTACT_MODELS(S_ROW, S_COMMA)};
#undef S_ROW
#undef S_COMMA
#define S_N ((int)(sizeof s_all / sizeof s_all[0]))

VAFM_API int vafm_contact_init(vafm_contact *c, const vafm_contact_type *type, double gamma)
{
    if (!c || !type || !type->init || !type->force || !type->energy)
        return VAFM_EINVAL; /* a model without its hooks: its touch/detach points are not known */
    if ((type->flags & VAFM_CONTACT_SURFACE) && !type->at_force)
        return VAFM_EINVAL;
    if (!(gamma >= 0.0) || !isfinite(gamma))
        return VAFM_EINVAL;
    vafm_contact out = {.type = type};
    int rc = type->init(&out, gamma);
    if (rc)
        return rc;
    *c = out;
    return VAFM_OK;
}

VAFM_API int vafm_contact_eval_at(const vafm_contact *c, double u, vafm_contact_eval *out)
{
    if (!c || !c->type || !c->type->force || !out)
        return VAFM_EINVAL;
    if (!isfinite(u) || !(u >= c->u_detach))
        return VAFM_EINVAL;
    double s = 0.0, dFdu = 0.0;
    double F = c->type->force(c, u, &s, &dFdu);
    out->a = s * s;
    out->F = F;
    out->dFdu = dFdu;
    return VAFM_OK;
}

VAFM_API int vafm_contact_type_count(void)
{
    return S_N;
}

VAFM_API const vafm_contact_type *vafm_contact_type_at(int i)
{
    return i >= 0 && i < S_N ? *s_all[i] : NULL;
}

VAFM_API const vafm_contact_type *vafm_contact_type_find(const char *name)
{
    if (!name)
        return NULL;
    for (int i = 0; i < S_N; ++i)
        if (strcmp((*s_all[i])->name, name) == 0)
            return *s_all[i];
    return NULL;
}
