/* SPDX-License-Identifier: MIT */
/*
 * Test helper: the campaign grid the campaign tests run, over a temperature and a speed list. Shared by
 * every test that builds a vafm_campaign_spec by hand, so that each states only what it varies.
 */
#ifndef VAFM_TESTS_CAMPAIGN_SPEC_H
#define VAFM_TESTS_CAMPAIGN_SPEC_H

#include <stdint.h>
#include <string.h>

#include "vafm/campaign.h"

/* n curves a point over the n_T temperatures T and the n_v speeds v (a list of 0: the base scene's value);
 * every other field zero: no k list, all online cores, the auto kernel, samples not kept, from curve 0. */
static inline vafm_campaign_spec t_campaign_spec(const double *T, size_t n_T, const double *v, size_t n_v,
                                                 uint64_t n)
{
    vafm_campaign_spec sp;
    memset(&sp, 0, sizeof sp);
    sp.T_K = T;
    sp.n_T = n_T;
    sp.v_m_per_s = v;
    sp.n_v = n_v;
    sp.curves_per_point = n;
    return sp;
}

#endif
