/* SPDX-License-Identifier: MIT */
/*
 * Clocks and the machine's load for the C benchmarks. Benchmarks report wall and CPU time side by side and
 * the load average around a run: on a shared machine wall times include waiting for the CPU, CPU times do not.
 */
#ifndef VAFM_BENCH_UTIL_H
#define VAFM_BENCH_UTIL_H
#include <math.h>
#include <stdio.h>
#include <time.h>

/* A clock's reading in seconds (CLOCK_MONOTONIC: wall, CLOCK_PROCESS_CPUTIME_ID: CPU of all threads). */
static inline double bench_clock_s(clockid_t id)
{
    struct timespec ts;
    clock_gettime(id, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
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
#endif
