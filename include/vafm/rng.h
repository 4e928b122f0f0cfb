/* SPDX-License-Identifier: MIT */
/**
 * @file rng.h
 * Counter-based random numbers: Philox4x32-10 (Salmon et al., SC'11, "Random123").
 *
 * A stream is keyed by (seed, stream): in vafm the stream is the curve index, so any curve can be
 * reproduced alone, bit for bit, whatever order or thread it runs in. Draw n of a stream is a pure
 * function of (seed, stream, n): block n/4 is Philox(key = seed, counter = {block, stream}).
 * Normals use a 256-level ziggurat on 64-bit draws (deterministic; no state beyond the stream).
 */
#ifndef VAFM_RNG_H
#define VAFM_RNG_H

#include "vafm/common.h"

#ifdef __cplusplus
extern "C" {
#endif

/** A Philox4x32-10 stream. Plain data: copy it to snapshot a stream. */
typedef struct vafm_rng {
    uint32_t key[2];  /**< seed, low and high words */
    uint32_t ctr[4];  /**< ctr[0..1]: block counter (64 bit), ctr[2..3]: stream id (64 bit) */
    uint32_t buf[4];  /**< the current output block */
    unsigned pos;     /**< next unused word of buf (4 = empty) */
} vafm_rng;

/** The bare Philox4x32 bijection with 10 rounds (the published known-answer vectors apply to it). */
VAFM_API void vafm_philox4x32_10(const uint32_t ctr[4], const uint32_t key[2], uint32_t out[4]);

/** Start stream `stream` of `seed` at draw 0. */
VAFM_API void vafm_rng_init(vafm_rng *r, uint64_t seed, uint64_t stream);

/** @return the next 32 random bits. */
VAFM_API uint32_t vafm_rng_u32(vafm_rng *r);

/** @return the next 64 random bits (two consecutive 32-bit words, first one low). */
VAFM_API uint64_t vafm_rng_u64(vafm_rng *r);

/** @return a uniform double in [0, 1) with 53 random bits (one 64-bit draw). */
VAFM_API double vafm_rng_uniform(vafm_rng *r);

/** @return a standard normal deviate (mean 0, variance 1). */
VAFM_API double vafm_rng_normal(vafm_rng *r);

#ifdef __cplusplus
}
#endif
#endif
