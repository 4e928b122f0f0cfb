/* SPDX-License-Identifier: MIT */
/*
 * The arithmetic of the gjf step on the tabulated JKR branch, written once for every kernel: the scalar
 * table force (jkr_table.h), the scalar step loops (kernel.h's s_kinv_table_force, integrator_gjf.c) and
 * each backend's vector loop (batch_lanes.h) expand these macros, so their agreement, bit for bit, holds
 * by construction rather than by the tests (which still check it: test_batch, test_kernel).
 *
 * Each macro is one expression over its arguments, lane-generic: the arguments are doubles in the scalar
 * loops and GCC vectors of doubles (one curve per lane) in the batch kernel, where each operator is the
 * lane-wise IEEE operation. The operations and their order are the expression's, in every instantiation
 * (the build has -ffp-contract=off: no FMA contraction). The arguments are plain values (each may be
 * evaluated more than once). What differs between scalar and vector code stays outside: the square root
 * (sqrt or the lanes'), the interval index and fraction, the table load, and the control flow (branches
 * in the scalar loop, lane masks in the vector one).
 */
#ifndef VAFM_CORE_GJF_STEP_H
#define VAFM_CORE_GJF_STEP_H

/* integrator_gjf.c's position update u' = u + b (dt w + (dt²/2m) f + (dt/2m) β);
 * hdmdt = (dt/2m)·dt and hdm = dt/2m, as the loops keep them */
#define VAFM_GJF_MOVE(u, w, f, beta, b, dt, hdmdt, hdm) ((u) + (b) * ((dt) * (w) + (hdmdt) * (f) + (hdm) * (beta)))

/* and its velocity update w' = a w + (dt/2m)(a f + f' + m η v_spr) + (b/m) β; binvm = b·(1/m) */
#define VAFM_GJF_KICK(w, f, fnew, beta, a, hdm, drift, binvm)                                                     \
    ((a) * (w) + (hdm) * ((a) * (f) + (fnew) + (drift)) + (binvm) * (beta))

/* The table's variable in node spacings, x = √(u − u_detach)/h; SQRT is the square root of the caller's type */
#define VAFM_JKR_TABLE_X(u, u_detach, inv_h, SQRT) (SQRT((u) - (u_detach)) * (inv_h))

/* The cubic Hermite interpolation t = g²(1+2f)·t0 + f²(1+2g)·t1 + f·g·(g·m0 − f·m1) on one interval:
 * f the fraction, g = 1 − f, p0..p3 the interval's t0, m0, t1, m1 (m = h·dt/dξ) */
#define VAFM_JKR_HERMITE(f, g, p0, p1, p2, p3)                                                                    \
    ((g) * (g) * (1.0 + 2.0 * (f)) * (p0) + (f) * (f) * (1.0 + 2.0 * (g)) * (p2) + (f) * (g) * ((g) * (p1) - (f) * (p3)))

/* s³ of s = √a */
#define VAFM_JKR_CUBE(s) ((s) * (s) * (s))

/* The JKR contact force from s³ = a^{3/2}: F = s³ (4/3 s³ − 2c); c2 = 2c */
#define VAFM_JKR_FORCE(s3, c2) ((s3) * ((4.0 / 3.0) * (s3) - (c2)))

/* The spring force k (u_spr − u) */
#define VAFM_SPRING_FORCE(k, u_spr, u) ((k) * ((u_spr) - (u)))

#endif
