/* SPDX-License-Identifier: MIT */
#include <stdlib.h>

#include "core/jkr_table.h"

/* t(ξ) and h·dt/dξ from the exact solver; dt/dξ = 2ξ/P'(t), with its limit 1/(√6 s_m) at ξ = 0. */
static void s_node(const vafm_contact *c, double xi, double h, double *t, double *m)
{
    const double s_m = c->s_m;
    double tt = vafm_jkr_solve_t(s_m, xi * xi, 0.0);
    double dp = tt * (4.0 * tt * tt + 12.0 * s_m * tt + 12.0 * s_m * s_m);
    *t = tt;
    *m = h * (tt > 0.0 ? 2.0 * xi / dp : 1.0 / (sqrt(6.0) * s_m));
}

static int s_build(vafm_jkr_table *T, const vafm_contact *c, int n)
{
    double *node = malloc(sizeof(double) * 2 * (size_t)n);
    if (!node)
        return VAFM_ENOMEM;
    T->n = n;
    T->h = T->xi_max / (double)(n - 2);
    T->inv_h = 1.0 / T->h;
    for (int i = 0; i < n; i++)
        s_node(c, T->h * i, T->h, &node[2 * i], &node[2 * i + 1]);
    free(T->node);
    T->node = node;
    /* self-check at every interval midpoint against the exact solver */
    double worst = 0.0;
    for (int i = 0; i < n - 2; i++) {
        double xi = T->h * (i + 0.5), s_tab = 0.0;
        double u = xi * xi + c->u_detach;
        vafm_jkr_table_force(T, c, u, &s_tab);
        double s_ex = c->s_m + vafm_jkr_solve_t(c->s_m, xi * xi, 0.0);
        double e = fabs(s_tab - s_ex) / s_ex;
        if (e > worst)
            worst = e;
    }
    T->max_err = worst;
    return 0;
}

int vafm_jkr_table_init(vafm_jkr_table *T, const vafm_contact *c, double u_max)
{
    T->node = NULL;
    T->n = 0;
    if (!c || !c->type || !(c->type->flags & VAFM_CONTACT_JKR_BRANCH) || !(c->s_m > 0.0) || !(u_max > c->u_detach))
        return VAFM_EINVAL;
    T->xi_max = sqrt(u_max - c->u_detach);
    for (int n = 256; n <= (1 << 17); n *= 2) {
        int r = s_build(T, c, n);
        if (r)
            return r;
        if (T->max_err < 1e-13)
            return 0;
    }
    return 0; /* the finest table; its max_err is reported (tests assert on it) */
}

void vafm_jkr_table_free(vafm_jkr_table *T)
{
    if (!T)
        return;
    free(T->node);
    T->node = NULL;
    T->n = 0;
}
