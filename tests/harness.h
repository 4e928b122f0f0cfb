/* SPDX-License-Identifier: MIT */
/*
 * Minimal test harness (after Box2D's test_macros.h). Each test executable is one module; checks
 * print a line on failure with the file, line and values, and main() returns non-zero if any failed.
 * VAFM_LONG_TESTS (meson option long_tests) selects full statistics; without it, stochastic tests
 * run with fewer samples and tolerances derived from that smaller N.
 */
#ifndef VAFM_TESTS_HARNESS_H
#define VAFM_TESTS_HARNESS_H

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int h_checks, h_failed;

#define ENSURE(c)                                                                        \
    do {                                                                                 \
        h_checks++;                                                                      \
        if (!(c)) {                                                                      \
            h_failed++;                                                                  \
            fprintf(stderr, "%s:%d: FAILED: %s\n", __FILE__, __LINE__, #c);              \
        }                                                                                \
    } while (0)

#define ENSURE_MSG(c, ...)                                                               \
    do {                                                                                 \
        h_checks++;                                                                      \
        if (!(c)) {                                                                      \
            h_failed++;                                                                  \
            fprintf(stderr, "%s:%d: FAILED: %s: ", __FILE__, __LINE__, #c);              \
            fprintf(stderr, __VA_ARGS__);                                                \
            fputc('\n', stderr);                                                         \
        }                                                                                \
    } while (0)

/* One check of |a − b| ≤ tol·scale: scale |b| ("rel") or 1 ("abs"), the deviation reported in the same unit. */
static inline void h_ensure_near(const char *file, int line, const char *sa, double a, const char *sb, double b,
                                 double tol, int rel)
{
    const double scale = rel ? fabs(b) : 1.0;
    h_checks++;
    if (!(fabs(a - b) <= tol * scale)) {
        h_failed++;
        fprintf(stderr, "%s:%d: FAILED: %s = %.12g vs %s = %.12g (%s %.3g > %.3g)\n", file, line, sa, a, sb, b,
                rel ? "rel" : "abs", fabs(a - b) / scale, tol);
    }
}

/* |a − b| ≤ tol·|b| */
#define ENSURE_REL(a, b, tol) h_ensure_near(__FILE__, __LINE__, #a, (a), #b, (b), (tol), 1)

/* |a − b| ≤ tol */
#define ENSURE_ABS(a, b, tol) h_ensure_near(__FILE__, __LINE__, #a, (a), #b, (b), (tol), 0)

#define RUN_TEST(fn)                                                                     \
    do {                                                                                 \
        int before_ = h_failed;                                                          \
        fn();                                                                            \
        fprintf(stderr, "%-4s %s\n", h_failed == before_ ? "ok" : "FAIL", #fn);          \
    } while (0)

static inline int harness_done(void)
{
    fprintf(stderr, "%d checks, %d failed\n", h_checks, h_failed);
    return h_failed ? 1 : 0;
}

#ifdef VAFM_LONG_TESTS
#define LONG_OR(long_value, short_value) (long_value)
#else
#define LONG_OR(long_value, short_value) (short_value)
#endif

#endif
