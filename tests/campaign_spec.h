/* SPDX-License-Identifier: MIT */
/*
 * Test helper: the campaign grid the campaign tests run, over a temperature and a speed list. Shared by
 * every test that builds a vafm_campaign_spec by hand, so that each states only what it varies.
 */
#ifndef VAFM_TESTS_CAMPAIGN_SPEC_H
#define VAFM_TESTS_CAMPAIGN_SPEC_H

#include <stddef.h>
#include <stdint.h>

#include "vafm/campaign.h"

/* n curves a point over the n_T temperatures T and the n_v speeds v (a list of 0: the base scene's value);
 * every other field zero: no k list, all online cores, the auto kernel, samples not kept, from curve 0. */
static inline vafm_campaign_spec t_campaign_spec(const double *T, size_t n_T, const double *v, size_t n_v,
                                                 uint64_t n)
{
    return (vafm_campaign_spec){ .T_K = T, .n_T = n_T, .v_m_per_s = v, .n_v = n_v, .curves_per_point = n };
}

#endif
