/* SPDX-License-Identifier: MIT */
/*
 * The AVX-512 table load of the batch kernel: 8 lanes each read the 4 doubles of their table interval
 * (two nodes' value and slope, 32 bytes from the lane's address) and get them back as 4 vectors of
 * 8 lanes. One 32-byte load per lane and an 8×4 transpose: cheaper on this project's CPUs than four
 * hardware gathers (bench_batch's floors measure both). The lane addresses go through memory: one
 * vector store read back 8 times costs less than 8 lane extracts through the vector-to-integer ports.
 * Shared by batch.c and bench_batch's floor loop, so that the floor measures the kernel's own load.
 */
#ifndef VAFM_CORE_TABLE8_H
#define VAFM_CORE_TABLE8_H

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>

static inline __attribute__((always_inline, target("avx512f,avx512dq"))) void
vafm_table8_load(__m512i addr, __m512d *p0, __m512d *p1, __m512d *p2, __m512d *p3)
{
    long long ad[8] __attribute__((aligned(64)));
    _mm512_store_si512((void *)ad, addr);
    __asm__("" : "+m"(ad)); /* read the addresses back from memory */
    const __m512d z0 = _mm512_insertf64x4(_mm512_castpd256_pd512(_mm256_loadu_pd((const double *)ad[0])),
                                          _mm256_loadu_pd((const double *)ad[4]), 1);
    const __m512d z1 = _mm512_insertf64x4(_mm512_castpd256_pd512(_mm256_loadu_pd((const double *)ad[1])),
                                          _mm256_loadu_pd((const double *)ad[5]), 1);
    const __m512d z2 = _mm512_insertf64x4(_mm512_castpd256_pd512(_mm256_loadu_pd((const double *)ad[2])),
                                          _mm256_loadu_pd((const double *)ad[6]), 1);
    const __m512d z3 = _mm512_insertf64x4(_mm512_castpd256_pd512(_mm256_loadu_pd((const double *)ad[3])),
                                          _mm256_loadu_pd((const double *)ad[7]), 1);
    const __m512d t0 = _mm512_unpacklo_pd(z0, z1), t1 = _mm512_unpackhi_pd(z0, z1);
    const __m512d t2 = _mm512_unpacklo_pd(z2, z3), t3 = _mm512_unpackhi_pd(z2, z3);
    const __m512i ilo = _mm512_set_epi64(13, 12, 5, 4, 9, 8, 1, 0);
    const __m512i ihi = _mm512_set_epi64(15, 14, 7, 6, 11, 10, 3, 2);
    *p0 = _mm512_permutex2var_pd(t0, ilo, t2);
    *p2 = _mm512_permutex2var_pd(t0, ihi, t2);
    *p1 = _mm512_permutex2var_pd(t1, ilo, t3);
    *p3 = _mm512_permutex2var_pd(t1, ihi, t3);
}
#endif

#endif
