/* SPDX-License-Identifier: MIT */
/*
 * Clocks, the machine's load and the report files for the C benchmarks. Benchmarks report wall and CPU time
 * side by side and the load average around a run: on a shared machine wall times include waiting for the CPU,
 * CPU times do not.
 */
#ifndef VAFM_BENCH_UTIL_H
#define VAFM_BENCH_UTIL_H
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

/* A clock's reading in seconds (CLOCK_MONOTONIC: wall, CLOCK_PROCESS_CPUTIME_ID: CPU of all threads). */
static inline double bench_clock_s(clockid_t id)
{
    struct timespec ts;
    clock_gettime(id, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* qsort's order of doubles (NaN-free input). */
static inline int bench_cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* The median of v[0..n) (n ≥ 1; sorts v). */
static inline double bench_median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, bench_cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* The 1-minute load average, NaN where /proc/loadavg cannot be read. */
static inline double bench_loadavg(void)
{
    double l = NAN;
    FILE *f = fopen("/proc/loadavg", "r");
    if (f) {
        if (fscanf(f, "%lf", &l) != 1)
            l = NAN;
        fclose(f);
    }
    return l;
}

/* dir/name opened for writing; NULL after saying so on stderr, as "prog: cannot write PATH". */
static inline FILE *bench_open(const char *prog, const char *dir, const char *name)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    FILE *f = fopen(path, "w");
    if (!f)
        fprintf(stderr, "%s: cannot write %s\n", prog, path);
    return f;
}
#endif
