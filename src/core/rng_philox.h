/* SPDX-License-Identifier: MIT */
/*
 * Internal: inlinable Philox4x32-10 stream and ziggurat normal behind vafm/rng.h.
 *
 * Design. A stream is (key = seed, counter = {block lo, block hi, stream lo, stream hi}); each block is
 * one Philox4x32-10 call (Salmon et al. SC'11) giving 4 words consumed in order, so draw n is a pure
 * function of (seed, stream, n). u64 = first word | second word << 32; uniform = (u64 >> 11) * 2^-53.
 *
 * Normal: 256-level ziggurat (Marsaglia & Tsang 2000, layout as in their paper; r = 3.6541528853610088,
 * v = 4.928673233974655e-3) on one 64-bit draw u: bits 0-7 pick layer i, bit 8 is the sign and the top
 * 53 bits j = u >> 11 give the abscissa x = j * 2^-53 * X[i]. Index, sign and abscissa use disjoint bits
 * (Doornik 2005's fix for the original's correlated index). Fast path (98.5 % of draws): integer
 * compare j < K[i] with K[i] = ceil(2^53 X[i+1]/X[i]), then one multiply - exact and branch-light.
 * The rest goes to vafm_rng_normal_slow(): wedge test against exp(), or for i = 0 the tail beyond r
 * by Marsaglia's exponential rejection with log(). Rejections draw a fresh 64-bit word.
 *
 * Tables are compile-time constants generated offline with 80-digit arithmetic (mpmath) and pasted
 * into rng_philox.c as hex floats: no initialisation, no mutable global state, thread-safe.
 * Bit-for-bit determinism: the fast path is integer ops plus one IEEE multiply; the slow path's
 * values depend on libm exp()/log() only through accept/reject and the tail's log(), so results are
 * reproducible for a given libm (and are identical under -ffp-contract=off at any -O level).
 *
 * The tables and vafm_rng_normal_slow() have hidden visibility: the inline functions are usable
 * inside libvafm and by anything linked against the static core (tests), not through the .so.
 */
#ifndef VAFM_CORE_RNG_PHILOX_H
#define VAFM_CORE_RNG_PHILOX_H

#include <stdint.h>

#include "vafm/rng.h"

#if defined(__GNUC__)
#define VAFM_RNG_HIDDEN __attribute__((visibility("hidden")))
#define VAFM_RNG_COLD __attribute__((cold, noinline))
#define VAFM_RNG_LIKELY(c) __builtin_expect(!!(c), 1)
#else
#define VAFM_RNG_HIDDEN
#define VAFM_RNG_COLD
#define VAFM_RNG_LIKELY(c) (c)
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* Philox4x32 constants (Random123): round multipliers and Weyl key increments. */
#define VAFM_PHILOX_M0 UINT32_C(0xD2511F53)
#define VAFM_PHILOX_M1 UINT32_C(0xCD9E8D57)
#define VAFM_PHILOX_W0 UINT32_C(0x9E3779B9)
#define VAFM_PHILOX_W1 UINT32_C(0xBB67AE85)

/* Ziggurat tables (rng_philox.c). Layer i = 0 is the base strip (with the tail), i = 255 the top. */
extern VAFM_RNG_HIDDEN const uint64_t vafm_zig_k[256]; /**< fast-accept threshold on j = u >> 11 */
extern VAFM_RNG_HIDDEN const double vafm_zig_w[256];   /**< X[i] * 2^-53: x = j * w[i] */
extern VAFM_RNG_HIDDEN const double vafm_zig_f[257];   /**< exp(-X[i]^2 / 2), f[256] = 1 */

/** Rest of the ziggurat for a draw u that missed the fast path (wedges, tail, rejections). */
VAFM_RNG_HIDDEN VAFM_RNG_COLD double vafm_rng_normal_slow(vafm_rng *r, uint64_t u);

/* One Philox4x32 round (Random123's philox4x32round) followed by the Weyl key bump. */
#define VAFM_PHILOX_ROUND_(c0, c1, c2, c3, k0, k1)                                                    \
    do {                                                                                              \
        const uint64_t p0_ = (uint64_t)VAFM_PHILOX_M0 * (c0);                                         \
        const uint64_t p1_ = (uint64_t)VAFM_PHILOX_M1 * (c2);                                         \
        (c0) = (uint32_t)(p1_ >> 32) ^ (c1) ^ (k0);                                                   \
        (c1) = (uint32_t)p1_;                                                                         \
        (c2) = (uint32_t)(p0_ >> 32) ^ (c3) ^ (k1);                                                   \
        (c3) = (uint32_t)p0_;                                                                         \
        (k0) += VAFM_PHILOX_W0;                                                                       \
        (k1) += VAFM_PHILOX_W1;                                                                       \
    } while (0)

/** Philox4x32-10 bijection. out may alias ctr or key. Rounds written out: gcc -O2 does not unroll a
 *  loop here, and the unrolled form is about twice as fast (the rounds' multiplies overlap). */
static inline void s_philox4x32_10(const uint32_t ctr[4], const uint32_t key[2], uint32_t out[4])
{
    uint32_t c0 = ctr[0], c1 = ctr[1], c2 = ctr[2], c3 = ctr[3];
    uint32_t k0 = key[0], k1 = key[1];
    VAFM_PHILOX_ROUND_(c0, c1, c2, c3, k0, k1); /* 1 */
    VAFM_PHILOX_ROUND_(c0, c1, c2, c3, k0, k1);
    VAFM_PHILOX_ROUND_(c0, c1, c2, c3, k0, k1);
    VAFM_PHILOX_ROUND_(c0, c1, c2, c3, k0, k1);
    VAFM_PHILOX_ROUND_(c0, c1, c2, c3, k0, k1); /* 5 */
    VAFM_PHILOX_ROUND_(c0, c1, c2, c3, k0, k1);
    VAFM_PHILOX_ROUND_(c0, c1, c2, c3, k0, k1);
    VAFM_PHILOX_ROUND_(c0, c1, c2, c3, k0, k1);
    VAFM_PHILOX_ROUND_(c0, c1, c2, c3, k0, k1);
    VAFM_PHILOX_ROUND_(c0, c1, c2, c3, k0, k1); /* 10 (its key bump is dead) */
    out[0] = c0;
    out[1] = c1;
    out[2] = c2;
    out[3] = c3;
}

/** Compute the block at the current counter into buf, then advance the 64-bit block counter. */
static inline void vafm_rng_refill_inline(vafm_rng *r)
{
    s_philox4x32_10(r->ctr, r->key, r->buf);
    if (++r->ctr[0] == 0)
        ++r->ctr[1];
    r->pos = 0;
}

static inline uint32_t vafm_rng_u32_inline(vafm_rng *r)
{
    if (r->pos >= 4)
        vafm_rng_refill_inline(r);
    return r->buf[r->pos++];
}

static inline uint64_t vafm_rng_u64_inline(vafm_rng *r)
{
    if (VAFM_RNG_LIKELY(r->pos <= 2)) {
        const uint64_t v = (uint64_t)r->buf[r->pos] | (uint64_t)r->buf[r->pos + 1] << 32;
        r->pos += 2;
        return v;
    }
    const uint64_t lo = vafm_rng_u32_inline(r); /* pos 3 (odd) straddles blocks; pos 4 refills */
    const uint64_t hi = vafm_rng_u32_inline(r);
    return lo | hi << 32;
}

static inline double vafm_rng_uniform_inline(vafm_rng *r)
{
    return (double)(vafm_rng_u64_inline(r) >> 11) * 0x1.0p-53;
}

/** The ziggurat's fast path on one 64-bit draw u (98.5 % of draws): 1 with *x the normal, 0 when u needs the
 *  rest (vafm_rng_normal_slow). Integer tests and one multiply: exact. */
static inline int vafm_zig_fast(uint64_t u, double *x)
{
    const unsigned i = (unsigned)(u & 0xffu);
    const uint64_t j = u >> 11;
    if (!(j < vafm_zig_k[i]))
        return 0;
    const int64_t s = -(int64_t)((u >> 8) & 1u);   /* 0 or -1 */
    const int64_t sj = ((int64_t)j ^ s) - s;       /* +-j, exact */
    *x = (double)sj * vafm_zig_w[i];
    return 1;
}

static inline double vafm_rng_normal_inline(vafm_rng *r)
{
    const uint64_t u = vafm_rng_u64_inline(r);
    double x;
    if (VAFM_RNG_LIKELY(vafm_zig_fast(u, &x)))
        return x;
    return vafm_rng_normal_slow(r, u);
}

/* ---- draws ahead: the kernel's queue ------------------------------------------------------------
 *
 * A vafm_rngq holds words of a stream computed ahead, VAFM_RNGQ_BLOCKS Philox blocks at a time (the
 * blocks are independent, so their rounds run side by side: SSE2 on x86-64, two blocks per vector).
 * The stream seen through a queue q on a generator r is q's unread words followed by r's stream: the
 * same words in the same order as r alone would give, only computed earlier. Whoever reads r through a
 * queue must read it only through that queue; an all-zero queue is empty (reads start at r as it is),
 * and re-initialising r requires emptying the queue (vafm_rngq_reset). */
#define VAFM_RNGQ_BLOCKS 16

typedef struct vafm_rngq {
    unsigned pos, len;                     /* next unread word, words held */
    uint32_t w[4 * VAFM_RNGQ_BLOCKS + 20]; /* room for up to 15 unread words kept in front (vafm_rngq_top_up) and
                                              the leftover words of a partly read block */
} vafm_rngq;

static inline void vafm_rngq_reset(vafm_rngq *q)
{
    q->pos = q->len = 0;
}

/** Refill q from r (keeps q's unread words in front) and return the next 64-bit draw. */
VAFM_RNG_HIDDEN uint64_t vafm_rngq_u64_slow(vafm_rngq *q, vafm_rng *r);
/** Refill q when it holds fewer than 16 unread words: those stay in front, VAFM_RNGQ_BLOCKS blocks follow
 *  (the stream is unchanged; a reader of 8 draws at a time then finds 16 words in a row). */
VAFM_RNG_HIDDEN void vafm_rngq_top_up(vafm_rngq *q, vafm_rng *r);
/** The rest of the ziggurat through a queue (as vafm_rng_normal_slow). */
VAFM_RNG_HIDDEN VAFM_RNG_COLD double vafm_rngq_normal_slow(vafm_rngq *q, vafm_rng *r, uint64_t u);
/** nb (a multiple of 4) consecutive blocks from counter ctr (the 64-bit block counter carries), key: out[4·nb]. */
VAFM_RNG_HIDDEN void vafm_philox4x32_10_blocks(const uint32_t ctr[4], const uint32_t key[2], unsigned nb, uint32_t *out);

static inline uint64_t vafm_rngq_u64(vafm_rngq *q, vafm_rng *r)
{
    const unsigned p = q->pos;
    if (VAFM_RNG_LIKELY(p + 2 <= q->len)) {
        q->pos = p + 2;
        return (uint64_t)q->w[p] | (uint64_t)q->w[p + 1] << 32;
    }
    return vafm_rngq_u64_slow(q, r);
}

static inline double vafm_rngq_uniform(vafm_rngq *q, vafm_rng *r)
{
    return (double)(vafm_rngq_u64(q, r) >> 11) * 0x1.0p-53;
}

/** vafm_rng_normal_inline() through a queue: the same transform of the same draws. */
static inline double vafm_rngq_normal(vafm_rngq *q, vafm_rng *r)
{
    const uint64_t u = vafm_rngq_u64(q, r);
    double x;
    if (VAFM_RNG_LIKELY(vafm_zig_fast(u, &x)))
        return x;
    return vafm_rngq_normal_slow(q, r, u);
}

#ifdef __cplusplus
}
#endif
#endif
