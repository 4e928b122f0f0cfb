/* SPDX-License-Identifier: MIT */
/*
 * One batch width's vector loop (batch.h), included by batch.c once per instruction set with:
 *   BW            lanes (doubles per vector)
 *   BATTR         the function attribute that compiles it for that set (target("..."))
 *   BFN           the function's name; BGRP, BLOAD, BSTEP: names of its group type and helpers
 *   BVD, BVL      GCC vector types of BW doubles and of BW 64-bit integers
 *   BSQRT(x)      lane-wise IEEE square root
 *   BTRUNC(x)     the lanes truncated to 32-bit integers; BI2D(i), BI2L(i): those back to doubles and
 *                 widened to 64-bit integers
 *   BTABLE(a, p0, p1, p2, p3)  each lane loads the 4 doubles at its address a (BVL) into p0..p3
 *   BANY(m)       whether any lane of mask m is set
 *   BWIDE         1: the lanes' normals are drawn by the AVX-512 ziggurat (batch.c), 0: one by one
 *
 * The arithmetic is written with GCC's vector extensions: each operator is the lane-wise IEEE
 * operation, so each lane computes exactly what the scalar loop computes, in the same order: the step's
 * formulas (position and velocity update, table variable, Hermite cubic, contact and spring force) are
 * core/gjf_step.h's macros, the same the scalar loop (integrator_gjf.c, kernel.h) expands.
 *
 * Two groups of BW lanes step side by side (S_GROUPS): a step is a chain of ≈ 40 dependent operations
 * (square root and table gather included), so one vector alone leaves the core waiting on latency;
 * two independent chains overlap.
 */

typedef struct BGRP {
    /* the lanes' constants */
    BVD dt, hdm, hdmdt, drift, sig, a, b, binvm, uspr0, vspr, kk, udet, utouch, invh, xend, sm, c2;
    BVL node, icm;
    /* their state */
    BVD u, w, s, Fc, hf, us, nd, au, aus, fmin;
    BVL evm;       /* lanes whose contact state changed (their run ended) */
    BVD lenv, cnt; /* this chunk: steps each lane runs, steps run */
    vafm_kernel *const *Kp;
    int n;         /* live lanes */
} BGRP;

/* Load lanes Kp[0..n) (n ≤ BW; the rest idle). */
static BATTR void BLOAD(BGRP *g, vafm_kernel *const *Kp, int n)
{
    double c[17][BW];
    long long c_node[BW], c_ic[BW];
    memset(c, 0, sizeof c);
    for (int l = 0; l < BW; l++) {
        c_node[l] = c_ic[l] = 0; /* idle lanes: no table (they read s_table_dummy) */
        if (l >= n)
            continue;
        const vafm_kernel *K = Kp[l];
        const vafm_kcoef co = K->co[K->in_contact];
        const double dt = K->dt, half_dt_m = 0.5 * dt / K->m, inv_m = 1.0 / K->m;
        vafm_kinv v;
        s_kinv_load(K, &v);
        const double row[17] = { dt, half_dt_m, half_dt_m * dt, K->m * K->v_spr, K->thermal ? co.gjf_sig : 0.0,
                                 co.gjf_a, co.gjf_b, co.gjf_b * inv_m, v.uspr0, v.v_spr, v.k, v.u_detach, v.u_touch,
                                 v.inv_h, v.x_end, v.s_m, v.c2 };
        for (int r = 0; r < 17; r++)
            c[r][l] = row[r];
        c_node[l] = (long long)(uintptr_t)v.node;
        c_ic[l] = K->in_contact ? -1 : 0;
    }
    BVD *const dst[17] = { &g->dt, &g->hdm, &g->hdmdt, &g->drift, &g->sig, &g->a, &g->b, &g->binvm, &g->uspr0,
                           &g->vspr, &g->kk, &g->udet, &g->utouch, &g->invh, &g->xend, &g->sm, &g->c2 };
    for (int r = 0; r < 17; r++)
        memcpy(dst[r], c[r], sizeof(BVD));
    memcpy(&g->node, c_node, sizeof g->node);
    memcpy(&g->icm, c_ic, sizeof g->icm);
    double x[10][BW];
    memset(x, 0, sizeof x);
    for (int l = 0; l < n; l++) {
        const vafm_kernel *K = Kp[l];
        const double row[10] = { K->u, K->w, K->s, K->Fc, K->f, K->u_spr, (double)K->n, K->acc_u, K->acc_uspr, K->fs_min };
        for (int r = 0; r < 10; r++)
            x[r][l] = row[r];
    }
    BVD *const st[10] = { &g->u, &g->w, &g->s, &g->Fc, &g->hf, &g->us, &g->nd, &g->au, &g->aus, &g->fmin };
    for (int r = 0; r < 10; r++)
        memcpy(st[r], x[r], sizeof(BVD));
    g->evm = (BVL)(g->dt < g->dt); /* all zero */
    g->Kp = Kp;
    g->n = n;
}

/* Step j of the chunk for the group's active lanes; nz: their noise terms of this step. */
static inline __attribute__((always_inline)) BATTR void BSTEP(BGRP *g, long j, BVD nz)
{
    const BVD zero = g->dt * 0.0;
    const BVL act = (BVL)(zero + (double)j < g->lenv) & ~g->evm;
    if (!BANY(act))
        return;
    /* f, beta and the position update */
    const BVD f = g->hf + g->drift;
    const BVD beta = g->sig * nz;
    const BVD un = VAFM_GJF_MOVE(g->u, g->w, f, beta, g->b, g->dt, g->hdmdt, g->hdm);
    /* kernel.h, s_khot_post_move_k (table, or free): time, support, contact state, force */
    const BVD ndn = g->nd + 1.0;
    const BVD tau = ndn * g->dt;
    const BVD usn = g->uspr0 + g->vspr * tau;
    const BVL det = g->icm & (BVL)(un < g->udet);       /* in contact: detaches */
    const BVL touch = ~g->icm & (BVL)(un >= g->utouch); /* free: touches */
    const BVD x = VAFM_JKR_TABLE_X(un, g->udet, g->invh, BSQRT);
    const BVL inside = (BVL)(x < g->xend);
    const BVL ok = act & g->icm & ~det & inside;
    const __typeof__(BTRUNC(x)) xi32 = BTRUNC(x); /* the table interval, as (int)x */
    const BVL ix = BI2L(xi32);
    const BVD fr = x - BI2D(xi32);
    const BVD gg = 1.0 - fr;
    const BVL dummy = (BVL)(zero * 0.0) + (long long)(uintptr_t)s_table_dummy;
    const BVL addr = S_SEL(ok, g->node + ix * 16, dummy); /* lanes not on the table read a dummy */
    BVD p0, p1, p2, p3;
    BTABLE(addr, p0, p1, p2, p3);
    const BVD t = VAFM_JKR_HERMITE(fr, gg, p0, p1, p2, p3);
    BVD sn = g->sm + t;
    const BVD s3 = VAFM_JKR_CUBE(sn);
    BVD Fn = VAFM_JKR_FORCE(s3, g->c2);
    if (__builtin_expect(!BANY(~act | ~g->icm | det | ~inside), 1)) {
        /* the common step: every lane active, in contact and on the table (no selects needed) */
        const BVD fs = VAFM_SPRING_FORCE(g->kk, usn, un);
        const BVD hfn = fs - Fn;
        g->w = VAFM_GJF_KICK(g->w, f, hfn, beta, g->a, g->hdm, g->drift, g->binvm);
        g->u = un;
        g->s = sn;
        g->Fc = Fn;
        g->hf = hfn;
        g->us = usn;
        g->nd = ndn;
        g->au = g->au + un;
        g->aus = g->aus + usn;
        g->fmin = S_SEL((BVL)(fs < g->fmin), fs, g->fmin);
        g->cnt = g->cnt + 1.0;
        return;
    }
    Fn = S_SEL(g->icm & ~det, Fn, zero); /* detached or free: no contact force, s kept */
    sn = S_SEL(g->icm & ~det, sn, g->s);
    const BVL fix = (act & g->icm & ~det & ~inside) | (act & touch);
    if (__builtin_expect(BANY(fix), 0)) { /* beyond the table (or a non-finite state), or a touch: scalar solver */
        double a_un[BW], a_s[BW], a_F[BW], a_sn[BW];
        long long a_fix[BW];
        memcpy(a_un, &un, sizeof a_un);
        memcpy(a_s, &g->s, sizeof a_s);
        memcpy(a_F, &Fn, sizeof a_F);
        memcpy(a_sn, &sn, sizeof a_sn);
        memcpy(a_fix, &fix, sizeof a_fix);
        for (int l = 0; l < g->n; l++)
            if (a_fix[l]) {
                vafm_kernel *K = g->Kp[l];
                const vafm_kfs r = K->in_contact ? vafm_kernel_table_far(K, a_un[l], a_s[l])
                                                 : vafm_kernel_contact_eval(K, a_un[l], 0.0);
                a_F[l] = r.F;
                a_sn[l] = r.s;
            }
        memcpy(&Fn, a_F, sizeof Fn);
        memcpy(&sn, a_sn, sizeof sn);
    }
    const BVD fs = VAFM_SPRING_FORCE(g->kk, usn, un);
    const BVD hfn = fs - Fn;
    const BVD wn = VAFM_GJF_KICK(g->w, f, hfn, beta, g->a, g->hdm, g->drift, g->binvm);
    /* commit the active lanes */
    g->u = S_SEL(act, un, g->u);
    g->w = S_SEL(act, wn, g->w);
    g->s = S_SEL(act, sn, g->s);
    g->Fc = S_SEL(act, Fn, g->Fc);
    g->hf = S_SEL(act, hfn, g->hf);
    g->us = S_SEL(act, usn, g->us);
    g->nd = S_SEL(act, ndn, g->nd);
    g->au = S_SEL(act, g->au + un, g->au);
    g->aus = S_SEL(act, g->aus + usn, g->aus);
    g->fmin = S_SEL(act & (BVL)(fs < g->fmin), fs, g->fmin);
    g->cnt = S_SEL(act, g->cnt + 1.0, g->cnt);
    g->evm |= act & (det | touch);
}

static BATTR void BFN(vafm_kernel *const *Kp, const long *want, long *done, int n)
{
    BGRP grp[S_GROUPS];
    double draws[S_NB] __attribute__((aligned(64)));               /* one lane's draws in order */
    double noise[S_GROUPS][S_NB][BW] __attribute__((aligned(64))); /* by step: a vector per step */
    s_lane_snap snap[S_GROUPS][BW];
    long left[S_GROUPS][BW];
    int ev[S_GROUPS][BW];
    for (int q = 0; q < S_GROUPS; q++) {
        const int nq = n - q * BW < 0 ? 0 : n - q * BW > BW ? BW : n - q * BW;
        BLOAD(&grp[q], Kp + q * BW, nq);
        for (int l = 0; l < BW; l++) {
            left[q][l] = l < nq ? want[q * BW + l] : 0;
            ev[q][l] = 0;
            if (l < nq)
                done[q * BW + l] = 0;
        }
    }
    for (;;) {
        /* the next chunk: up to S_NB steps, each live lane's normals drawn ahead */
        long L = 0;
        for (int q = 0; q < S_GROUPS; q++)
            for (int l = 0; l < grp[q].n; l++)
                if (!ev[q][l] && left[q][l] > L)
                    L = left[q][l];
        if (L == 0)
            break;
        if (L > S_NB)
            L = S_NB;
        for (int q = 0; q < S_GROUPS; q++) {
            double len[BW];
            for (int l = 0; l < BW; l++) {
                const long m = l < grp[q].n && !ev[q][l] ? (left[q][l] < L ? left[q][l] : L) : 0;
                len[l] = (double)m;
                if (m > 0)
                    s_lane_fill(Kp[q * BW + l], &snap[q][l], draws, m, BWIDE);
                for (long j = 0; j < m; j++)
                    noise[q][j][l] = draws[j];
                for (long j = m; j < L; j++)
                    noise[q][j][l] = 0.0;
            }
            memcpy(&grp[q].lenv, len, sizeof grp[q].lenv);
            grp[q].cnt = grp[q].dt * 0.0;
        }
        for (long j = 0; j < L; j++) {
            for (int q = 0; q < S_GROUPS; q++) {
                BVD nz;
                memcpy(&nz, noise[q][j], sizeof nz);
                BSTEP(&grp[q], j, nz);
            }
        }
        /* chunk done: a lane whose contact state changed used fewer normals than were drawn: draw those again */
        for (int q = 0; q < S_GROUPS; q++) {
            double a_cnt[BW];
            long long a_ev[BW];
            memcpy(a_cnt, &grp[q].cnt, sizeof a_cnt);
            memcpy(a_ev, &grp[q].evm, sizeof a_ev);
            for (int l = 0; l < grp[q].n; l++) {
                if (ev[q][l] || left[q][l] == 0)
                    continue;
                const long m = (long)a_cnt[l];
                if (a_ev[l]) {
                    ev[q][l] = 1;
                    s_lane_redraw(Kp[q * BW + l], &snap[q][l], m);
                }
                left[q][l] -= m;
                done[q * BW + l] += m;
            }
        }
    }
    for (int q = 0; q < S_GROUPS; q++) {
        const BGRP *g = &grp[q];
        double x[9][BW];
        const BVD *const src[9] = { &g->u, &g->w, &g->s, &g->Fc, &g->hf, &g->us, &g->au, &g->aus, &g->fmin };
        for (int r = 0; r < 9; r++)
            memcpy(x[r], src[r], sizeof(BVD));
        for (int l = 0; l < g->n; l++)
            s_lane_store(Kp[q * BW + l], done[q * BW + l], ev[q][l], x[0][l], x[1][l], x[2][l], x[3][l], x[4][l],
                         x[5][l], x[6][l], x[7][l], x[8][l]);
    }
}
