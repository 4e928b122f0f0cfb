/* SPDX-License-Identifier: MIT */
/* The batch kernel (batch.h): the lanes' shared scalar parts and the run-time choice of the vector loop. */
#include <stdint.h>
#include <string.h>

#include "core/backend.h"
#include "core/batch.h"
#include "core/kernel.h"
#include "core/table8.h"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define S_X86 1
#else
#define S_X86 0
#endif

#define S_NB 64    /* steps per chunk: the normals drawn ahead per lane */
#ifndef S_GROUPS
#define S_GROUPS 2
#endif
// /* vectors of lanes stepped side by side (batch_lanes.h) */

/* The lane's stream before a chunk's normals were drawn, to draw again exactly those the lane used. */
typedef struct s_lane_snap {
    vafm_rng rng;
    vafm_rngq rq;
} s_lane_snap;

/* The scalar loop's m noise terms of a lane, drawn one by one (none without temperature). */
static void s_noise_scalar(vafm_kernel *K, double *out, long m)
{
    if (!K->thermal) {
        for (long j = 0; j < m; j++)
            out[j] = 0.0;
        return;
    }
    for (long j = 0; j < m; j++)
        out[j] = s_kernel_noise(K);
}

/* the lane used m < the drawn noise terms (its contact ended): rewind and draw m */
static void s_lane_redraw(vafm_kernel *K, const s_lane_snap *sn, long m)
{
    if (!K->thermal)
        return;
    K->rng = sn->rng;
    K->rq = sn->rq;
    for (long j = 0; j < m; j++)
        (void)s_kernel_noise(K);
}

/* Write a lane's end state back: as s_khot_store() after the scalar loop ran `steps` steps. */
static void s_lane_store(vafm_kernel *K, long steps, int ended, double u, double w, double s, double Fc, double f,
                         double us, double au, double aus, double fmin)
{
    vafm_khot h;
    s_khot_load(K, &h);
    h.n += steps;
    h.u = u;
    h.w = w;
    h.s = s;
    h.Fc = Fc;
    h.f = f;
    h.u_spr = us;
    h.acc_u = au;
    h.acc_uspr = aus;
    h.acc_n += steps;
    h.fs_min = fmin;
    if (h.in_contact) { /* the step that detaches counts as out of contact */
        h.steps_contact += (uint64_t)(steps - (ended ? 1 : 0));
        if (ended) {
            h.in_contact = 0;
            h.event = -1;
        }
    } else if (ended) { /* the step that touches counts as in contact */
        h.steps_contact++;
        h.in_contact = 1;
        h.event = 1;
    }
    s_khot_store(K, &h, steps);
}

#if S_X86
/* m normals of K's stream into out, as m calls of vafm_rngq_normal() would draw them: the queue's words are
 * read 8 draws at a time and the ziggurat's fast path (rng_philox.h) runs in 8 lanes; from the first draw
 * that misses it, the scalar code takes that draw (the slow path may read further words) and the vector
 * goes on behind it. The same integer tests, the same exact conversion, the same one multiply. */
static __attribute__((target("avx512f,avx512dq"))) void s_normals_avx512(vafm_kernel *K, double *out, long m)
{
    vafm_rngq *q = &K->rq;
    vafm_rng *r = &K->rng;
    const __m512i m8 = _mm512_set1_epi64(0xff), one = _mm512_set1_epi64(1);
    long j = 0;
    while (j < m) {
        if (m - j >= 8) {
            if (q->len - q->pos < 16)
                vafm_rngq_top_up(q, r);
            const __m512i u = _mm512_loadu_si512((const void *)(q->w + q->pos)); /* w[p] | w[p + 1] << 32 */
            const __m512i i = _mm512_and_si512(u, m8);
            const __m512i jj = _mm512_srli_epi64(u, 11);
            const __m512i kk = _mm512_i64gather_epi64(i, (const void *)vafm_zig_k, 8);
            const __mmask8 pass = _mm512_cmplt_epu64_mask(jj, kk);
            const __m512i sg = _mm512_sub_epi64(_mm512_setzero_si512(), _mm512_and_si512(_mm512_srli_epi64(u, 8), one));
            const __m512i sj = _mm512_sub_epi64(_mm512_xor_si512(jj, sg), sg);
            const __m512d x = _mm512_mul_pd(_mm512_cvtepi64_pd(sj), _mm512_i64gather_pd(i, (const void *)vafm_zig_w, 8));
            if (pass == 0xff) {
                _mm512_storeu_pd(out + j, x);
                q->pos += 16;
                j += 8;
                continue;
            }
            const int f = __builtin_ctz(~(unsigned)pass);
            _mm512_mask_storeu_pd(out + j, (__mmask8)((1u << f) - 1u), x);
            q->pos += 2u * (unsigned)f;
            j += f;
        }
        out[j++] = vafm_rngq_normal(q, r);
    }
}

static __attribute__((target("avx512f,avx512dq"))) void s_noise_avx512(vafm_kernel *K, double *out, long m)
{
    if (!K->thermal || K->uniform_noise)
        s_noise_scalar(K, out, m);
    else
        s_normals_avx512(K, out, m);
}
#endif

/* Draw a lane's next m noise terms into out and keep its stream as it was before them. */
static void s_lane_fill(vafm_kernel *K, s_lane_snap *sn, double *out, long m, int wide)
{
    if (K->thermal) {
        sn->rng = K->rng;
        sn->rq = K->rq;
    }
#if S_X86
    if (wide) {
        s_noise_avx512(K, out, m);
        return;
    }
#endif
    (void)wide;
    s_noise_scalar(K, out, m);
}

/* what lanes off the table read (their values are not used) */
static const double s_table_dummy[4] __attribute__((aligned(32)));

#define S_SEL(m, x, y) ((__typeof__(x))(((BVL)(x) & (m)) | ((BVL)(y) & ~(m))))

#if S_X86
/* AVX-512: 8 lanes */
typedef double s_vd8 __attribute__((vector_size(64)));
typedef long long s_vl8 __attribute__((vector_size(64)));
#define BW 8
#define BATTR __attribute__((target("avx512f,avx512dq")))
#define BFN s_steps_avx512
#define BGRP s_grp8
#define BLOAD s_load8
#define BSTEP s_step8
#define BVD s_vd8
#define BVL s_vl8
#define BSQRT(x) ((s_vd8)_mm512_sqrt_pd((__m512d)(x)))
#define BTRUNC(x) _mm512_cvttpd_epi32((__m512d)(x))
#define BI2D(i) ((s_vd8)_mm512_cvtepi32_pd(i))
#define BI2L(i) ((s_vl8)_mm512_cvtepi32_epi64(i))
/* 8 lanes' 4 table doubles (core/table8.h) */
#define BTABLE(a, p0, p1, p2, p3)                                                                               \
    do {                                                                                                        \
        __m512d q0_, q1_, q2_, q3_;                                                                             \
        vafm_table8_load((__m512i)(a), &q0_, &q1_, &q2_, &q3_);                                                 \
        (p0) = (s_vd8)q0_;                                                                                      \
        (p1) = (s_vd8)q1_;                                                                                      \
        (p2) = (s_vd8)q2_;                                                                                      \
        (p3) = (s_vd8)q3_;                                                                                      \
    } while (0)
#define BANY(m) (_mm512_movepi64_mask((__m512i)(m)) != 0)
#define BWIDE 1
#include "core/batch_lanes.h"
#undef BW
#undef BATTR
#undef BFN
#undef BGRP
#undef BLOAD
#undef BSTEP
#undef BVD
#undef BVL
#undef BSQRT
#undef BTRUNC
#undef BI2D
#undef BI2L
#undef BTABLE
#undef BANY
#undef BWIDE

/* AVX2: 4 lanes */
typedef double s_vd4 __attribute__((vector_size(32)));
typedef long long s_vl4 __attribute__((vector_size(32)));
#define BW 4
#define BATTR __attribute__((target("avx2")))
#define BFN s_steps_avx2
#define BGRP s_grp4
#define BLOAD s_load4
#define BSTEP s_step4
#define BVD s_vd4
#define BVL s_vl4
#define BSQRT(x) ((s_vd4)_mm256_sqrt_pd((__m256d)(x)))
#define BTRUNC(x) _mm256_cvttpd_epi32((__m256d)(x))
#define BI2D(i) ((s_vd4)_mm256_cvtepi32_pd(i))
#define BI2L(i) ((s_vl4)_mm256_cvtepi32_epi64(i))
/* 4 lanes' 4 table doubles: one 32-byte load per lane, then a 4×4 transpose */
#define BTABLE(a, p0, p1, p2, p3)                                                                               \
    do {                                                                                                        \
        long long ad_[4];                                                                                       \
        memcpy(ad_, &(a), sizeof ad_);                                                                          \
        const __m256d r0_ = _mm256_loadu_pd((const double *)ad_[0]), r1_ = _mm256_loadu_pd((const double *)ad_[1]); \
        const __m256d r2_ = _mm256_loadu_pd((const double *)ad_[2]), r3_ = _mm256_loadu_pd((const double *)ad_[3]); \
        const __m256d t0_ = _mm256_unpacklo_pd(r0_, r1_), t1_ = _mm256_unpackhi_pd(r0_, r1_);                  \
        const __m256d t2_ = _mm256_unpacklo_pd(r2_, r3_), t3_ = _mm256_unpackhi_pd(r2_, r3_);                  \
        (p0) = (s_vd4)_mm256_permute2f128_pd(t0_, t2_, 0x20);                                                   \
        (p2) = (s_vd4)_mm256_permute2f128_pd(t0_, t2_, 0x31);                                                   \
        (p1) = (s_vd4)_mm256_permute2f128_pd(t1_, t3_, 0x20);                                                   \
        (p3) = (s_vd4)_mm256_permute2f128_pd(t1_, t3_, 0x31);                                                   \
    } while (0)
#define BANY(m) (_mm256_movemask_pd((__m256d)(m)) != 0)
#define BWIDE 0
#include "core/batch_lanes.h"
#endif

/* ---- the backend table (backend.h) -------------------------------------------------------------- */

static void s_steps_scalar(vafm_kernel *const *K, const long *want, long *done, int n)
{
    for (int l = 0; l < n; l++)
        done[l] = vafm_integrator_gjf->run(K[l], want[l]);
}

static int s_avail_scalar(void)
{
    return 1;
}

static int s_avail_avx2(void)
{
#if S_X86
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2");
#else
    return 0;
#endif
}

static int s_avail_avx512(void)
{
#if S_X86
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq");
#else
    return 0;
#endif
}

#if !S_X86
#define s_steps_avx2 NULL
#define s_steps_avx512 NULL
#endif

/* narrowest first; row 0 the scalar reference */
static const vafm_backend s_backends[] = {
    { "scalar", "batch, 1 lane (no AVX2 on this CPU)", 1, s_avail_scalar, s_steps_scalar },
    { "avx2", "batch, 4 lanes (AVX2)", 4, s_avail_avx2, s_steps_avx2 },
    { "avx512", "batch, 8 lanes (AVX-512)", 8, s_avail_avx512, s_steps_avx512 },
};
#define S_NBACKENDS ((int)(sizeof s_backends / sizeof s_backends[0]))

unsigned vafm_backend_off = 0;

int vafm_backend_count(void)
{
    return S_NBACKENDS;
}

const vafm_backend *vafm_backend_at(int i)
{
    return i >= 0 && i < S_NBACKENDS ? &s_backends[i] : NULL;
}

int vafm_backend_usable(int i)
{
    if (i < 0 || i >= S_NBACKENDS || !s_backends[i].steps)
        return 0;
    if (i > 0 && (vafm_backend_off >> i & 1u))
        return 0;
    return s_backends[i].available();
}

int vafm_backend_find(const char *name, const vafm_backend **out)
{
    for (int i = 0; name && i < S_NBACKENDS; i++)
        if (!strcmp(name, s_backends[i].name)) {
            if (!vafm_backend_usable(i))
                return VAFM_ENOTSUP;
            if (out)
                *out = &s_backends[i];
            return 0;
        }
    return VAFM_ENOTFOUND;
}

/* The usable row of exactly `width` lanes, else the scalar row. */
static const vafm_backend *s_backend_of_width(int width)
{
    for (int i = S_NBACKENDS - 1; i > 0; i--)
        if (s_backends[i].lanes == width && vafm_backend_usable(i))
            return &s_backends[i];
    return &s_backends[0];
}

int vafm_batch_width_max(void)
{
    for (int i = S_NBACKENDS - 1; i > 0; i--)
        if (vafm_backend_usable(i))
            return s_backends[i].lanes;
    return 1;
}

int vafm_batch_lanes_per_call(int width)
{
    return width > 1 ? width * S_GROUPS : 1;
}

int vafm_batch_width(int want)
{
    const int max = vafm_batch_width_max();
    if (want <= 0 || want >= max)
        return max;
    for (int i = S_NBACKENDS - 1; i > 0; i--) /* the widest usable row not above want */
        if (s_backends[i].lanes <= want && vafm_backend_usable(i))
            return s_backends[i].lanes;
    return 1;
}

void vafm_batch_steps(vafm_kernel *const *K, const long *want, long *done, int n, int width)
{
    const vafm_backend *b = s_backend_of_width(width); /* an unusable width runs the scalar row */
    const int per = vafm_batch_lanes_per_call(b->lanes);
    for (int i = 0; i < n; i += per) {
        const int m = n - i < per ? n - i : per;
        b->steps(K + i, want + i, done + i, m);
    }
}
