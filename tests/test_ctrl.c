/* SPDX-License-Identifier: MIT */
/*
 * The simulation's live scene against theory.
 *
 * Scene: the contact-silica preset (k = 0.1 N/m, f0 = 13 kHz, Q = 30, JKR on silica, 298 K, 10 kHz sampling)
 * with end-point samples (antialias none), so that a sample is the lever's state at an instant.
 * Statistics: fixed seeds; block averages over S_NB = 50 blocks, each far longer than the correlation time
 * (Q/(π f0) = 0.7 ms = 7 samples free, about the same in contact), standard error sd(block means)/√S_NB;
 * checks at 5σ of it unless stated.
 */
#include "harness.h"

#include <math.h>
#include <stdint.h>
#include <string.h>
#include <time.h>

#include "vafm/params.h"
#include "vafm/sim.h"
#include "vafm/theory.h"

#define S_NB 50
#define S_KB 1.380649e-23

static void s_scene(vafm_params *p)
{
    vafm_params_default(p);
    ENSURE(vafm_preset_apply(p, "contact-silica", NULL) == 0);
    p->antialias = VAFM_ANTIALIAS_POINT;
}

static double s_cpu(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* block statistics of a series: mean, its standard error, mean square about a given centre */
typedef struct s_blk {
    long per, cnt;
    int nb;
    double sum, sum2, bm[S_NB], bm2[S_NB];
} s_blk;

static void s_blk_init(s_blk *b, long n)
{
    memset(b, 0, sizeof *b);
    b->per = n / S_NB > 0 ? n / S_NB : 1;
}

static void s_blk_push(s_blk *b, double v)
{
    if (b->nb >= S_NB)
        return;
    b->sum += v;
    b->sum2 += v * v;
    if (++b->cnt == b->per) {
        b->bm[b->nb] = b->sum / (double)b->per;
        b->bm2[b->nb++] = b->sum2 / (double)b->per;
        b->sum = b->sum2 = 0.0;
        b->cnt = 0;
    }
}

/* mean and standard error of the block means of x (which = 0) or of x² (which = 1) */
static void s_blk_stat(const s_blk *b, int which, double *mean, double *se)
{
    const double *v = which ? b->bm2 : b->bm;
    double m = 0.0, s2 = 0.0;
    for (int i = 0; i < b->nb; i++)
        m += v[i];
    m /= b->nb;
    for (int i = 0; i < b->nb; i++)
        s2 += (v[i] - m) * (v[i] - m);
    *mean = m;
    *se = sqrt(s2 / (b->nb - 1) / b->nb);
}

/* ---- the live scene ------------------------------------------------------------------------------ */

typedef struct s_free_run {
    double h;
    s_blk b;
    uint64_t n;
} s_free_run;

static double s_hold(void *user, const vafm_live_sample *smp)
{
    s_free_run *r = user;
    s_blk_push(&r->b, smp->deflection_m);
    r->n++;
    return r->h;
}

/* A free live lever 1 µm above the surface: <d²> = kT/k, <d> = 0 (exact free transitions, one per sample). */
static void test_live_free(void)
{
    vafm_params p;
    s_scene(&p);
    vafm_sim *s = NULL;
    ENSURE(vafm_sim_new(&s, &p, NULL) == 0);
    const long N = LONG_OR(400000, 200000);
    s_free_run r = { .h = 1e-6 };
    s_blk_init(&r.b, N);
    ENSURE(vafm_sim_live_begin(s, 0, r.h, s_hold, &r) == 0);
    double c0 = s_cpu();
    ENSURE(vafm_sim_advance(s, (size_t)N, NULL, NULL) == 1);
    double cpu = s_cpu() - c0;
    double m, se, m2, se2;
    s_blk_stat(&r.b, 0, &m, &se);
    s_blk_stat(&r.b, 1, &m2, &se2);
    const double var = S_KB * p.T_K / p.k_N_per_m;
    fprintf(stderr, "  live free: N %ld <d> %.3g ± %.2g m, <d²>/(kT/k) %.5f ± %.5f, %.0f ns/sample\n", N, m, se,
            m2 / var, se2 / var, 1e9 * cpu / N);
    ENSURE(r.n == (uint64_t)N);
    ENSURE(fabs(m) < 5.0 * se);
    ENSURE(fabs(m2 - var) < 5.0 * se2);
    ENSURE(se2 < 0.02 * var); /* the test can see a 10% error */
    vafm_sim_destroy(&s);
}

int main(void)
{
    RUN_TEST(test_live_free);
    return harness_done();
}
