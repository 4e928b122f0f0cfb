/* SPDX-License-Identifier: MIT */
/* Campaign statistics (vafm/stats.h): observables by name, the pull-off rule, running moments. */
#include <math.h>
#include <stddef.h>
#include <string.h>
#include "vafm/stats.h"

static const struct {
    vafm_observable_info info;
    size_t offset;
} s_obs[VAFM_OBS_COUNT] = {
    [VAFM_OBS_PULLOFF_SAMPLED] = { { "pulloff_sampled_N", 1,
                                     "most tensile output sample of the retract (what an AFM user reads)" },
                                   offsetof(vafm_curve_result, pulloff_sampled_N) },
    [VAFM_OBS_PULLOFF_SPRING] = { { "pulloff_spring_N", 1, "most tensile spring force of any step of the retract" },
                                  offsetof(vafm_curve_result, pulloff_spring_N) },
    [VAFM_OBS_DETACH_FORCE] = { { "detach_force_N", 1, "spring force when the body passed u_min (ground truth)" },
                                offsetof(vafm_curve_result, detach_force_N) },
    [VAFM_OBS_DETACH_HEIGHT] = { { "detach_height_m", 0, "piezo height above the contact point then" },
                                 offsetof(vafm_curve_result, detach_height_m) },
    [VAFM_OBS_DETACH_EQ_FORCE] = { { "detach_eq_force_N", 1, "noise-free equilibrium spring force at that height" },
                                   offsetof(vafm_curve_result, detach_eq_force_N) },
};

const vafm_observable_info *vafm_stats_observable(int obs)
{
    return obs >= 0 && obs < VAFM_OBS_COUNT ? &s_obs[obs].info : NULL;
}

double vafm_stats_value(const vafm_curve_result *r, int obs)
{
    if (!r || obs < 0 || obs >= VAFM_OBS_COUNT)
        return NAN;
    double v;
    memcpy(&v, (const char *)r + s_obs[obs].offset, sizeof v);
    return v;
}

int vafm_stats_is_pulloff(int status, const vafm_curve_result *r)
{
    return status == 0 && r && !(r->flags & VAFM_STATS_EXCLUDING_FLAGS);
}

void vafm_moments_add(vafm_moments *m, double x)
{
    double n1 = (double)m->n, n = n1 + 1.0;
    double d = x - m->mean, dn = d / n, t = d * dn * n1;
    m->mean += dn;
    m->m3 += t * dn * (n - 2.0) - 3.0 * dn * m->m2;
    m->m2 += t;
    m->n++;
}

double vafm_moments_sd(const vafm_moments *m)
{
    return m->n > 1 ? sqrt(m->m2 / ((double)m->n - 1.0)) : NAN;
}

double vafm_moments_sem(const vafm_moments *m)
{
    return vafm_moments_sd(m) / sqrt((double)m->n);
}

double vafm_moments_skewness(const vafm_moments *m)
{
    return m->n > 2 && m->m2 > 0 ? sqrt((double)m->n) * m->m3 / pow(m->m2, 1.5) : NAN;
}

static const struct {
    const char *word, *doc;
} s_flags[VAFM_STATS_NFLAGS] = {
    { "no-contact", "the tip never touched" },
    { "early-detach", "contact lost before the retract began" },
    { "no-detach", "still in contact at the retract travel limit" },
    { "no-trigger", "the approach reached z_range_m without the trigger" },
    { "recontact", "touched again after detaching" },
};

const char *vafm_stats_flag_word(int i, const char **doc)
{
    if (i < 0 || i >= VAFM_STATS_NFLAGS)
        return NULL;
    if (doc)
        *doc = s_flags[i].doc;
    return s_flags[i].word;
}

void vafm_point_stats_add(vafm_point_stats *st, int status, const vafm_curve_result *r)
{
    st->curves++;
    if (status) {
        st->failed++;
        return;
    }
    for (int i = 0; i < VAFM_STATS_NFLAGS; i++)
        st->flag_count[i] += (r->flags & (1 << i)) != 0;
    if (!vafm_stats_is_pulloff(status, r))
        return;
    st->used++;
    for (int i = 0; i < VAFM_OBS_COUNT; i++) {
        double v = vafm_stats_value(r, i);
        if (isfinite(v))
            vafm_moments_add(&st->obs[i], v);
    }
}

double vafm_stats_f_jkr_N(const vafm_params *p)
{
    return 1.5 * M_PI * p->gamma_J_per_m2 * p->R_m;
}
