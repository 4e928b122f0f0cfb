/* SPDX-License-Identifier: MIT */
/*
 * Tests of the Philox4x32-10 streams and the ziggurat normal (vafm/rng.h, src/core/rng_philox.h).
 * Statistical checks use fixed seeds, so each outcome is deterministic; tolerances are 5 standard
 * errors of the estimator at the sample size N in use (the sigma is written next to each check).
 */
#include <inttypes.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "core/rng_philox.h"
#include "harness.h"
#include "vafm/rng.h"

/* ---------------------------------------------------------------------------------------------- */
/* Known answers                                                                                   */

/*
 * Philox4x32-10 known-answer vectors of the Random123 distribution (file kat_vectors; the same three
 * lines are reproduced in D. E. Shaw Research's Random123-Boost, libs/random/test/test_philox.cpp).
 * Format there: ctr[0..3] key[0..1] -> out[0..3].
 */
static void test_philox_kat(void)
{
    static const struct {
        uint32_t ctr[4], key[2], out[4];
    } kat[] = {
        {{0x00000000u, 0x00000000u, 0x00000000u, 0x00000000u},
         {0x00000000u, 0x00000000u},
         {0x6627e8d5u, 0xe169c58du, 0xbc57ac4cu, 0x9b00dbd8u}},
        {{0xffffffffu, 0xffffffffu, 0xffffffffu, 0xffffffffu},
         {0xffffffffu, 0xffffffffu},
         {0x408f276du, 0x41c83b0eu, 0xa20bc7c6u, 0x6d5451fdu}},
        {{0x243f6a88u, 0x85a308d3u, 0x13198a2eu, 0x03707344u},
         {0xa4093822u, 0x299f31d0u},
         {0xd16cfe09u, 0x94fdccebu, 0x5001e420u, 0x24126ea1u}},
    };
    for (size_t t = 0; t < sizeof kat / sizeof kat[0]; t++) {
        uint32_t out[4], out_inline[4], alias[4];
        vafm_philox4x32_10(kat[t].ctr, kat[t].key, out);
        s_philox4x32_10(kat[t].ctr, kat[t].key, out_inline);
        memcpy(alias, kat[t].ctr, sizeof alias);
        vafm_philox4x32_10(alias, kat[t].key, alias); /* out aliasing ctr is allowed */
        for (int k = 0; k < 4; k++) {
            ENSURE_MSG(out[k] == kat[t].out[k], "vector %zu word %d: %08" PRIx32 " != %08" PRIx32, t, k,
                       out[k], kat[t].out[k]);
            ENSURE(out_inline[k] == kat[t].out[k]);
            ENSURE(alias[k] == kat[t].out[k]);
        }
    }
}

/* ---------------------------------------------------------------------------------------------- */
/* Stream layout and determinism                                                                   */

/* Word n of stream (seed, stream), straight from the documented layout. */
static uint32_t ref_word(uint64_t seed, uint64_t stream, uint64_t n)
{
    const uint64_t block = n / 4;
    const uint32_t ctr[4] = {(uint32_t)block, (uint32_t)(block >> 32), (uint32_t)stream,
                             (uint32_t)(stream >> 32)};
    const uint32_t key[2] = {(uint32_t)seed, (uint32_t)(seed >> 32)};
    uint32_t out[4];
    vafm_philox4x32_10(ctr, key, out);
    return out[n % 4];
}

static void test_stream_layout(void)
{
    const uint64_t seed = UINT64_C(0x0123456789abcdef), stream = UINT64_C(0xfedcba9876543210);
    vafm_rng r;
    vafm_rng_init(&r, seed, stream);
    ENSURE(r.key[0] == 0x89abcdefu && r.key[1] == 0x01234567u);
    ENSURE(r.ctr[0] == 0 && r.ctr[1] == 0 && r.ctr[2] == 0x76543210u && r.ctr[3] == 0xfedcba98u);
    ENSURE(r.pos == 4);

    enum { NW = 1031 };
    static uint32_t seq[NW];
    int bad = 0;
    for (uint64_t n = 0; n < NW; n++) {
        seq[n] = vafm_rng_u32(&r);
        bad += seq[n] != ref_word(seed, stream, n);
    }
    ENSURE_MSG(bad == 0, "%d of %d words differ from Philox(key=seed, ctr={n/4, stream})[n%%4]", bad, NW);
    ENSURE(r.ctr[0] == (NW + 3) / 4 && r.ctr[1] == 0);

    /* Draw n reached by re-init + jumping the block counter + discarding n % 4 words. */
    static const uint64_t jumps[] = {0, 1, 3, 4, 7, 517, 1026, NW - 1};
    for (size_t t = 0; t < sizeof jumps / sizeof jumps[0]; t++) {
        const uint64_t n = jumps[t];
        vafm_rng q;
        vafm_rng_init(&q, seed, stream);
        q.ctr[0] = (uint32_t)(n / 4);
        q.ctr[1] = (uint32_t)((n / 4) >> 32);
        for (uint64_t k = 0; k < n % 4; k++)
            (void)vafm_rng_u32(&q);
        ENSURE_MSG(vafm_rng_u32(&q) == seq[n], "jump to draw %" PRIu64, n);
    }

    /* The 64-bit block counter carries from ctr[0] into ctr[1], never into the stream words. */
    vafm_rng c;
    vafm_rng_init(&c, seed, stream);
    c.ctr[0] = 0xffffffffu;
    c.ctr[1] = 5;
    const uint64_t b0 = UINT64_C(5) << 32 | 0xffffffffu;
    for (uint64_t k = 0; k < 8; k++)
        ENSURE(vafm_rng_u32(&c) == ref_word(seed, stream, 4 * b0 + k));
    ENSURE(c.ctr[0] == 1 && c.ctr[1] == 6 && c.ctr[2] == 0x76543210u && c.ctr[3] == 0xfedcba98u);

    /* u64 = first word | second word << 32, also across a block boundary (odd position). */
    vafm_rng a, b;
    vafm_rng_init(&a, seed, stream);
    vafm_rng_init(&b, seed, stream);
    for (int k = 0; k < 3; k++)
        ENSURE(vafm_rng_u32(&a) == vafm_rng_u32(&b));
    for (int k = 0; k < 5; k++) {
        const uint64_t lo = vafm_rng_u32(&b), hi = vafm_rng_u32(&b);
        ENSURE(vafm_rng_u64(&a) == (lo | hi << 32));
    }
    /* uniform = (u64 >> 11) 2^-53, in [0, 1) */
    for (int k = 0; k < 5; k++) {
        const double u = vafm_rng_uniform(&a);
        ENSURE(u == (double)(vafm_rng_u64(&b) >> 11) * 0x1.0p-53);
        ENSURE(u >= 0.0 && u < 1.0);
    }
    vafm_rng z;
    vafm_rng_init(&z, 0, 0);
    ENSURE(vafm_rng_u64(&z) == (UINT64_C(0xe169c58d) << 32 | 0x6627e8d5u)); /* KAT ctr = 0, key = 0 */
}

static int count_equal_words(uint64_t s1, uint64_t t1, uint64_t s2, uint64_t t2, int n)
{
    vafm_rng a, b;
    vafm_rng_init(&a, s1, t1);
    vafm_rng_init(&b, s2, t2);
    int eq = 0;
    for (int k = 0; k < n; k++)
        eq += vafm_rng_u32(&a) == vafm_rng_u32(&b);
    return eq;
}

static void test_stream_determinism(void)
{
    enum { N = 4000 };
    /* Same (seed, stream): the same mixed sequence. */
    vafm_rng a, b;
    vafm_rng_init(&a, 42, 7);
    vafm_rng_init(&b, 42, 7);
    int bad = 0;
    for (int k = 0; k < N; k++) {
        switch (k % 4) {
        case 0: bad += vafm_rng_u32(&a) != vafm_rng_u32(&b); break;
        case 1: bad += vafm_rng_u64(&a) != vafm_rng_u64(&b); break;
        case 2: bad += vafm_rng_uniform(&a) != vafm_rng_uniform(&b); break;
        default: bad += vafm_rng_normal(&a) != vafm_rng_normal(&b); break;
        }
    }
    ENSURE(bad == 0);

    /* Different streams / seeds: unrelated words (expected equal count N / 2^32 ~ 1e-6). */
    ENSURE(count_equal_words(42, 7, 42, 8, N) <= 1);
    ENSURE(count_equal_words(42, 7, 43, 7, N) <= 1);
    ENSURE(count_equal_words(42, 7, 7, 42, N) <= 1);
    ENSURE(count_equal_words(42, 0, 42, UINT64_C(1) << 32, N) <= 1);
    ENSURE(count_equal_words(0, 0, UINT64_C(1) << 32, 0, N) <= 1);

    /* A copy of the struct, taken mid-block, continues identically. */
    vafm_rng_init(&a, 42, 7);
    for (int k = 0; k < 3; k++)
        (void)vafm_rng_u32(&a);
    (void)vafm_rng_normal(&a);
    vafm_rng snap = a;
    double xa[64], xs[64];
    for (int k = 0; k < 64; k++)
        xa[k] = (k & 1) ? vafm_rng_normal(&a) : (double)vafm_rng_u32(&a);
    for (int k = 0; k < 64; k++)
        xs[k] = (k & 1) ? vafm_rng_normal(&snap) : (double)vafm_rng_u32(&snap);
    ENSURE(memcmp(xa, xs, sizeof xa) == 0);

    /* The inline versions of rng_philox.h are the same functions as the public ones. */
    vafm_rng_init(&a, 99, 3);
    vafm_rng_init(&b, 99, 3);
    bad = 0;
    for (int k = 0; k < N; k++) {
        bad += vafm_rng_u32(&a) != vafm_rng_u32_inline(&b);
        bad += vafm_rng_u64(&a) != vafm_rng_u64_inline(&b);
        bad += vafm_rng_uniform(&a) != vafm_rng_uniform_inline(&b);
        bad += vafm_rng_normal(&a) != vafm_rng_normal_inline(&b);
    }
    ENSURE(bad == 0);
}

/*
 * Regression pin: the first four normals of (seed = 42, stream = 7), printed once from this
 * implementation (not an external reference): -2.0024250012430942, 0.71248140506789104,
 * -0.76011816271730714, 0.10737378107754783. A change means every stochastic result of vafm changes.
 */
static void test_normal_golden(void)
{
    static const double golden[4] = {-0x1.004f76628413ap+1, 0x1.6cca5cdb8ca83p-1, -0x1.852e3533eed15p-1,
                                     0x1.b7cd91e2d09dap-4};
    vafm_rng r;
    vafm_rng_init(&r, 42, 7);
    for (int k = 0; k < 4; k++) {
        const double x = vafm_rng_normal(&r);
        ENSURE_MSG(x == golden[k], "normal %d of (42, 7): %a (%.17g) != %a", k, x, x, golden[k]);
    }
}

/* ---------------------------------------------------------------------------------------------- */
/* Distributions                                                                                   */

static void test_uniform_moments(void)
{
    /* N = 1e6 draws of U[0,1): mean 1/2, sd of the mean sqrt(1/12 / N) = 2.89e-4; variance 1/12,
     * sd of the sample variance sqrt((mu4 - sigma^4) / N) = sqrt((1/80 - 1/144) / N) = sqrt(1/180 / N)
     * = 7.45e-5. Tolerances: 5 sd. */
    const long n = 1000000;
    vafm_rng r;
    vafm_rng_init(&r, 2024, 1);
    double s1 = 0, s2 = 0, lo = 1, hi = 0;
    for (long k = 0; k < n; k++) {
        const double u = vafm_rng_uniform(&r);
        s1 += u;
        s2 += u * u;
        lo = u < lo ? u : lo;
        hi = u > hi ? u : hi;
    }
    const double mean = s1 / n, var = s2 / n - mean * mean;
    ENSURE(lo >= 0.0 && hi < 1.0);
    ENSURE_ABS(mean, 0.5, 5 * sqrt(1.0 / 12.0 / n));
    ENSURE_ABS(var, 1.0 / 12.0, 5 * sqrt(1.0 / 180.0 / n));
}

static void test_normal_moments(void)
{
    /* N = 4e6 (long) or 1e6 draws. Standard errors for a normal sample: mean 1/sqrt(N), variance
     * sqrt(2/N), skewness sqrt(6/N), kurtosis sqrt(24/N); at N = 1e6: 1.0e-3, 1.41e-3, 2.45e-3, 4.90e-3.
     * Tolerances: 5 sd. */
    const long n = (long)LONG_OR(4e6, 1e6);
    vafm_rng r;
    vafm_rng_init(&r, 12345, 0);
    double s1 = 0, s2 = 0, s3 = 0, s4 = 0;
    for (long k = 0; k < n; k++) {
        const double x = vafm_rng_normal(&r), x2 = x * x;
        s1 += x;
        s2 += x2;
        s3 += x2 * x;
        s4 += x2 * x2;
    }
    const double m = s1 / n, e2 = s2 / n, e3 = s3 / n, e4 = s4 / n;
    const double c2 = e2 - m * m;
    const double c3 = e3 - 3 * m * e2 + 2 * m * m * m;
    const double c4 = e4 - 4 * m * e3 + 6 * m * m * e2 - 3 * m * m * m * m;
    const double skew = c3 / pow(c2, 1.5), kurt = c4 / (c2 * c2);
    ENSURE_ABS(m, 0.0, 5 * sqrt(1.0 / n));
    ENSURE_ABS(c2, 1.0, 5 * sqrt(2.0 / n));
    ENSURE_ABS(skew, 0.0, 5 * sqrt(6.0 / n));
    ENSURE_ABS(kurt, 3.0, 5 * sqrt(24.0 / n));
}

static void test_normal_tails(void)
{
    /* Counts of |x| > t among N draws are binomial(N, p), p = erfc(t / sqrt 2); sd sqrt(N p (1 - p)).
     * At N = 1e6: t = 3: N p = 2699.8, sd 51.9; t = r = 3.6542 (ziggurat tail start): N p = 258.0,
     * sd 16.1; t = 4: N p = 63.3, sd 7.96. Tolerances: 5 sd. The sign is checked too (p = 1/2). */
    const long n = (long)LONG_OR(4e6, 1e6);
    static const double t[3] = {3.0, 3.6541528853610088, 4.0};
    long cnt[3] = {0, 0, 0}, neg = 0, neg_tail = 0;
    vafm_rng r;
    vafm_rng_init(&r, 777, 5);
    for (long k = 0; k < n; k++) {
        const double x = vafm_rng_normal(&r), ax = fabs(x);
        neg += x < 0;
        neg_tail += x < -t[1];
        for (int q = 0; q < 3; q++)
            cnt[q] += ax > t[q];
    }
    for (int q = 0; q < 3; q++) {
        const double p = erfc(t[q] / sqrt(2.0));
        ENSURE_MSG(fabs(cnt[q] - n * p) <= 5 * sqrt(n * p * (1 - p)), "P(|x| > %g): %ld vs %.1f", t[q],
                   cnt[q], n * p);
    }
    ENSURE_ABS((double)neg, 0.5 * n, 5 * sqrt(0.25 * n));
    ENSURE_ABS((double)neg_tail, 0.5 * cnt[1], 5 * sqrt(0.25 * cnt[1]));
}

static double phi_cdf(double z) { return 0.5 * erfc(-z / sqrt(2.0)); }

static void test_normal_cdf(void)
{
    const long n = (long)LONG_OR(4e6, 1e6);
    /* Fine histogram: 80 bins of width 0.1 on [-4, 4) plus the two tails (82 bins, 81 dof; smallest
     * expected count, bin [3.9, 4), is 16.4 at N = 1e6). */
    enum { NB = 82 };
    static long bins[NB];
    memset(bins, 0, sizeof bins);
    /* KS-type points: empirical CDF F_N(z) vs Phi(z), sd sqrt(Phi (1 - Phi) / N) (<= 5e-4 at N = 1e6). */
    static const double zs[] = {-3.0, -2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0, 3.0};
    enum { NZ = sizeof zs / sizeof zs[0] };
    long below[NZ] = {0};
    vafm_rng r;
    vafm_rng_init(&r, 31337, 2);
    for (long k = 0; k < n; k++) {
        const double x = vafm_rng_normal(&r);
        for (int q = 0; q < NZ; q++)
            below[q] += x < zs[q];
        int b;
        if (x < -4.0)
            b = 0;
        else if (x >= 4.0)
            b = NB - 1;
        else {
            b = 1 + (int)floor((x + 4.0) * 10.0);
            b = b < 1 ? 1 : (b > NB - 2 ? NB - 2 : b);
        }
        bins[b]++;
    }
    for (int q = 0; q < NZ; q++) {
        const double p = phi_cdf(zs[q]), fn = (double)below[q] / n;
        ENSURE_MSG(fabs(fn - p) <= 5 * sqrt(p * (1 - p) / n), "F_N(%g) = %.6f vs Phi = %.6f", zs[q], fn, p);
    }
    double chi2 = 0;
    for (int b = 0; b < NB; b++) {
        const double plo = b == 0 ? 0.0 : phi_cdf(-4.0 + 0.1 * (b - 1));
        const double phi = b == NB - 1 ? 1.0 : phi_cdf(-4.0 + 0.1 * b);
        const double e = n * (phi - plo);
        chi2 += (bins[b] - e) * (bins[b] - e) / e;
    }
    /* chi-square, 81 dof: mean 81, sd 12.7; P(chi2 > 161.3) = 2.87e-7 (the one-sided 5 sigma level;
     * computed with mpmath's regularised incomplete gamma). */
    ENSURE_MSG(chi2 < 161.3, "chi2 = %.1f with 81 dof", chi2);
}

/* The kernel's queue of blocks computed ahead (rng_philox.h) gives the stream's words in the same order
 * as the generator alone: from a fresh stream, after single words read directly (a block partly read,
 * an odd word straddling into the queue), across the 32-bit carry of the block counter, for u64 draws,
 * normals (slow path included: 1e5 draws take it ~1500 times) and uniforms; and the blocks side by side
 * (SSE2, and AVX2 and AVX-512 where the CPU has them) equal the bijection block by block. */
static void test_queue_stream(void)
{
    const uint32_t key[2] = { 0x01234567u, 0x89abcdefu };
    uint32_t ctr[4] = { 0xfffffffau, 0x7u, 0x55u, 0xaau };
    /* 28 = 16 + 8 + 4 blocks: the AVX-512, AVX2 and SSE2 generators in turn (those the CPU has) */
    const unsigned nbs[4] = { 4, 8, 16, 28 };
    for (int t = 0; t < 4; t++) {
        uint32_t blk[4 * 28];
        vafm_philox4x32_10_blocks(ctr, key, nbs[t], blk);
        for (unsigned j = 0; j < nbs[t]; j++) {
            const uint64_t b = ((uint64_t)ctr[1] << 32 | ctr[0]) + j;
            const uint32_t c[4] = { (uint32_t)b, (uint32_t)(b >> 32), ctr[2], ctr[3] };
            uint32_t o[4];
            vafm_philox4x32_10(c, key, o);
            ENSURE_MSG(memcmp(o, blk + 4 * j, sizeof o) == 0, "%u blocks: block %u", nbs[t], j);
        }
    }
    for (int skip = 0; skip < 4; skip++) {
        vafm_rng a, b;
        vafm_rngq q;
        memset(&q, 0, sizeof q);
        vafm_rng_init(&a, 99, 7);
        vafm_rng_init(&b, 99, 7);
        a.ctr[0] = b.ctr[0] = 0xfffffff0u; /* the carry into ctr[1] comes after 16 blocks */
        for (int k = 0; k < skip; k++)
            ENSURE(vafm_rng_u32(&a) == vafm_rng_u32(&b));
        int bad = 0;
        for (int n = 0; n < 100000; n++) {
            switch (n % 3) {
            case 0: bad += vafm_rng_u64(&a) != vafm_rngq_u64(&q, &b); break;
            case 1: bad += vafm_rng_normal(&a) != vafm_rngq_normal(&q, &b); break;
            default: bad += vafm_rng_uniform(&a) != vafm_rngq_uniform(&q, &b); break;
            }
        }
        ENSURE_MSG(bad == 0, "skip %d: %d draws differ", skip, bad);
        ENSURE(b.ctr[1] == 1u); /* the queue went through the carry */
    }
}

int main(void)
{
    RUN_TEST(test_philox_kat);
    RUN_TEST(test_stream_layout);
    RUN_TEST(test_stream_determinism);
    RUN_TEST(test_normal_golden);
    RUN_TEST(test_uniform_moments);
    RUN_TEST(test_normal_moments);
    RUN_TEST(test_normal_tails);
    RUN_TEST(test_normal_cdf);
    RUN_TEST(test_queue_stream);
    return harness_done();
}
