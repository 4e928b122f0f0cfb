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

/* |a − b| ≤ tol·|b| */
#define ENSURE_REL(a, b, tol)                                                            \
    do {                                                                                 \
        double ea_ = (a), eb_ = (b), et_ = (tol);                                        \
        h_checks++;                                                                      \
        if (!(fabs(ea_ - eb_) <= et_ * fabs(eb_))) {                                     \
            h_failed++;                                                                  \
            fprintf(stderr, "%s:%d: FAILED: %s = %.12g vs %s = %.12g (rel %.3g > %.3g)\n",  \
                    __FILE__, __LINE__, #a, ea_, #b, eb_, fabs(ea_ - eb_) / fabs(eb_), et_); \
        }                                                                                \
    } while (0)

/* |a − b| ≤ tol */
#define ENSURE_ABS(a, b, tol)                                                            \
    do {                                                                                 \
        double ea_ = (a), eb_ = (b), et_ = (tol);                                        \
        h_checks++;                                                                      \
        if (!(fabs(ea_ - eb_) <= et_)) {                                                 \
            h_failed++;                                                                  \
            fprintf(stderr, "%s:%d: FAILED: %s = %.12g vs %s = %.12g (abs %.3g > %.3g)\n",  \
                    __FILE__, __LINE__, #a, ea_, #b, eb_, fabs(ea_ - eb_), et_);          \
        }                                                                                \
    } while (0)

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
