/* SPDX-License-Identifier: MIT */
/*
 * Fault injection on the simulation thread (design: sim_thread.h; the plan: faults.h, protocol/faults.md).
 * It decides which faults strike a block and applies those that alter its samples; at a block's release it
 * returns what the loop must do (release, hold, or end the run silently) instead of ending the run itself.
 */
#include "daemon/sim_thread.h"

/* ---- Fault injection (faults.h, protocol/faults.md) -------------------------------------------------
 * Without a plan (x->fp NULL) every hook below is skipped by one predictable branch. With one, transport
 * faults are decided once per block at its release (vafmd_st_fault_release), controller faults once per block
 * when its computation completes (vafmd_st_fault_compute); decisions are stateless hashes of (seed, kind, run,
 * block), so a plan with a seed reproduces its faults. Each injected fault is recorded after it took
 * effect: published on the `faults` topic, handed to the control thread (status) and, with logging on,
 * to the log writer. None of it allocates (jansson's JSON for the topic aside, as for events). */


void vafmd_st_fault_record(vafmd_st *x, vafmd_fault_rec *fr)
{
    fr->n = ++x->fault_n;
    fr->session = (uint32_t)atomic_load_explicit(&x->d->sh.session, memory_order_relaxed);
    vafmd_st_send_json(x, "faults", vafmd_fault_rec_json(fr));
    vafmd_ring_push(&x->d->fault_ring, fr); /* full (control thread far behind): status misses it, counted */
    if (atomic_load_explicit(&x->d->log.state, memory_order_acquire) == VAFMD_LOG_ON)
        vafmd_ring_push(&x->d->log.fault_ring, fr);
}

/* A record of kind k at block bi of the current run. */
static void s_fault_rec_init(vafmd_st *x, vafmd_fault_rec *fr, int k, uint64_t bi, double p0, double p1, int scripted)
{
    vafmd_st_run *r = &x->run;
    memset(fr, 0, sizeof *fr);
    fr->kind = k;
    fr->time_s = (double)(vafmd_st_now() - x->t_boot) / 1e9;
    fr->run_id = r->cmd.run_id;
    fr->block = (int64_t)bi;
    fr->run_time_s = (double)(bi * r->block_n) / vafmd_st_run_fs(r);
    fr->seq = -1;
    fr->p0 = p0;
    fr->p1 = p1;
    fr->scripted = (uint32_t)scripted;
}

/* Does fault kind k strike block bi of the current run? Its parameters then go to *p0, *p1. */
static int s_fault_due(vafmd_st *x, int k, uint64_t bi, double *p0, double *p1, int *scripted)
{
    const vafmd_fault_plan *p = x->fp;
    const vafmd_st_run *r = &x->run;
    for (size_t i = 0; i < p->n_script; i++) {
        const vafmd_fault_entry *en = &p->script[i];
        if (en->kind != k || (en->run && en->run != r->cmd.run_id))
            continue;
        uint64_t b = en->block >= 0 ? (uint64_t)en->block
                                    : (uint64_t)floor(en->time_s * vafmd_st_run_fs(r) / (double)r->block_n);
        if (b == bi) {
            *p0 = en->p0;
            *p1 = en->p1;
            *scripted = 1;
            return 1;
        }
    }
    const vafmd_fault_random *rr = &p->rnd[k];
    if (!(rr->rate > 0))
        return 0;
    *p0 = rr->p0;
    *p1 = rr->p1;
    *scripted = 0;
    if (rr->per == VAFMD_FPER_BLOCK)
        return vafmd_fault_u01(p->seed, k, r->cmd.run_id, bi + 2) < rr->rate;
    return rr->per == VAFMD_FPER_RUN && r->frun_block[k] == (int64_t)bi;
}

/* A no_trigger fault for the curve starting now: a scripted entry for this run (or any run; its block and time
 * do not matter), or the per-run random rate. Its record is published with the block where the approach
 * turns (at its travel limit): after the fault took effect. */
int vafmd_st_no_trigger_due(vafmd_st *x)
{
    const vafmd_fault_plan *p = x->fp;
    vafmd_st_run *r = &x->run;
    r->no_trig = 0;
    if (__builtin_expect(p == NULL, 1))
        return 0;
    int hit = 0, sc = 0;
    double p0 = 0, p1 = 0;
    for (size_t i = 0; i < p->n_script && !hit; i++) {
        const vafmd_fault_entry *en = &p->script[i];
        if (en->kind == VAFMD_F_NO_TRIGGER && (!en->run || en->run == r->cmd.run_id))
            hit = sc = 1;
    }
    const vafmd_fault_random *rr = &p->rnd[VAFMD_F_NO_TRIGGER];
    if (!hit && rr->rate > 0 && rr->per != VAFMD_FPER_COMMAND)
        hit = vafmd_fault_u01(p->seed, VAFMD_F_NO_TRIGGER, r->cmd.run_id, 0) < rr->rate;
    if (hit) {
        r->no_trig = 1;
        s_fault_rec_init(x, &r->no_trig_rec, VAFMD_F_NO_TRIGGER, 0, p0, p1, sc);
    }
    return hit;
}

/* At run start: where this run's per-run random faults strike (a block drawn over the last run's length). */
void vafmd_st_fault_run_begin(vafmd_st *x)
{
    vafmd_st_run *r = &x->run;
    const vafmd_fault_plan *p = x->fp;
    uint64_t nb = x->last_run_blocks ? x->last_run_blocks : 16;
    for (int k = 0; k < VAFMD_F_N; k++) {
        r->frun_block[k] = -1;
        const vafmd_fault_random *rr = &p->rnd[k];
        if (rr->per == VAFMD_FPER_RUN && vafmd_fault_u01(p->seed, k, r->cmd.run_id, 0) < rr->rate)
            r->frun_block[k] = (int64_t)(vafmd_fault_u01(p->seed, k, r->cmd.run_id, 1) * (double)nb);
    }
}

/* Controller faults on a block just computed (index bi): ADC saturation and detector dropout act on the
 * measured chain (vDeflection_V, then deflection_m and force_N derived from it; height and the ground
 * truth tip_m stay), for `samples` samples from the block's first on, into the following blocks. */
void vafmd_st_fault_compute(vafmd_st *x, vafmd_st_block *b, uint64_t bi)
{
    vafmd_st_run *r = &x->run;
    double *volts = b->ch[VAFM_CH_VDEFLECTION], *defl = b->ch[VAFM_CH_DEFLECTION], *force = b->ch[VAFM_CH_FORCE];
    if (r->cmd.replay || !defl || !force || !volts)
        return; /* a replay streams what was recorded */
    double p0, p1;
    int sc;
    b->n_frec = 0;
    if (s_fault_due(x, VAFMD_F_SATURATE, bi, &p0, &p1, &sc)) {
        r->sat_left = (uint64_t)p0;
        r->sat_level = p1;
        s_fault_rec_init(x, &b->frec[b->n_frec++], VAFMD_F_SATURATE, bi, p0, p1, sc);
    }
    if (s_fault_due(x, VAFMD_F_DROPOUT, bi, &p0, &p1, &sc)) {
        r->dout_left = (uint64_t)p0;
        r->dout_stuck = p1 != 0;
        s_fault_rec_init(x, &b->frec[b->n_frec++], VAFMD_F_DROPOUT, bi, p0, p1, sc);
    }
    if (r->no_trig && (b->flags & (VAFM_WIRE_FLAG_SEG_CHANGE | VAFM_WIRE_FLAG_LAST))) {
        r->no_trig_rec.block = (int64_t)bi; /* the approach ended at its limit in this block */
        r->no_trig_rec.run_time_s = (double)(bi * r->block_n) / vafmd_st_run_fs(r);
        b->frec[b->n_frec++] = r->no_trig_rec;
        r->no_trig = 0;
    }
    double k = vafm_sim_params(r->cmd.sim)->k_N_per_m;
    size_t i = 0;
    if (r->sat_left) {
        for (; i < b->n && r->sat_left; i++, r->sat_left--) {
            volts[i] = r->sat_level;
            defl[i] = r->sat_level * r->sens;
            force[i] = k * defl[i];
        }
        b->flags |= VAFM_WIRE_FLAG_CLIPPED;
        r->force_altered = 1;
    }
    if (r->dout_left) {
        if (bi == 0 && !r->dout_stuck) /* nothing before: NaN; stuck at the first sample's values */
            r->last_v[0] = r->last_v[1] = r->last_v[2] = NAN;
        else if (bi == 0)
            r->last_v[0] = volts[0], r->last_v[1] = defl[0], r->last_v[2] = force[0];
        r->force_altered = 1;
        for (i = 0; i < b->n && r->dout_left; i++, r->dout_left--) {
            volts[i] = r->dout_stuck ? r->last_v[0] : NAN;
            defl[i] = r->dout_stuck ? r->last_v[1] : NAN;
            force[i] = r->dout_stuck ? r->last_v[2] : NAN;
        }
    }
    if (b->n) {
        r->last_v[0] = volts[b->n - 1];
        r->last_v[1] = defl[b->n - 1];
        r->last_v[2] = force[b->n - 1];
    }
}


/* Transport faults at the release of the head block (index r->block_index), decided once per block.
 * @return VAFMD_ST_FA_RELEASE: release it (vafmd_st_release then drops it or restarts the session as
 * decided); VAFMD_ST_FA_HOLD: not now (late, jitter, stall); VAFMD_ST_FA_END: the run is over (truncate,
 * kill): the caller ends it silently, then records *end (and a kill ends the daemon). */
int vafmd_st_fault_release(vafmd_st *x, int64_t now, vafmd_fault_rec *end)
{
    vafmd_st_run *r = &x->run;
    uint64_t bi = r->block_index;
    if (r->fdecided > bi)
        return VAFMD_ST_FA_RELEASE;
    r->fdecided = bi + 1;
    double p0, p1;
    int sc;
    if (s_fault_due(x, VAFMD_F_KILL, bi, &p0, &p1, &sc) || s_fault_due(x, VAFMD_F_TRUNCATE, bi, &p0, &p1, &sc)) {
        int kill = s_fault_due(x, VAFMD_F_KILL, bi, &p0, &p1, &sc);
        s_fault_rec_init(x, end, kill ? VAFMD_F_KILL : VAFMD_F_TRUNCATE, bi, p0, p1, sc);
        end->seq = (int64_t)atomic_load_explicit(&x->d->sh.seq, memory_order_relaxed);
        r->fault_silent = 1; /* silent: no run.end, not logged; a campaign goes on (not after a kill) */
        return VAFMD_ST_FA_END;
    }
    int held = 0;
    if (s_fault_due(x, VAFMD_F_STALL, bi, &p0, &p1, &sc)) {
        s_fault_rec_init(x, &x->stall_rec, VAFMD_F_STALL, bi, p0, p1, sc);
        x->stall_until = now + (int64_t)llround(p0 * 1e9);
        held = 1;
    }
    r->n_held = 0;
    if (s_fault_due(x, VAFMD_F_LATE, bi, &p0, &p1, &sc)) {
        s_fault_rec_init(x, &r->held[r->n_held++], VAFMD_F_LATE, bi, p0, p1, sc);
        r->hold_until = now + (int64_t)llround(p0 * 1e9);
        held = 1;
    }
    if (s_fault_due(x, VAFMD_F_JITTER, bi, &p0, &p1, &sc)) {
        double dly = p0 * vafmd_fault_u01(x->fp->seed, VAFMD_F_JITTER, r->cmd.run_id, bi + (1ULL << 40));
        s_fault_rec_init(x, &r->held[r->n_held++], VAFMD_F_JITTER, bi, p0, dly, sc);
        int64_t t = now + (int64_t)llround(dly * 1e9);
        if (t > r->hold_until)
            r->hold_until = t;
        held = 1;
    }
    if ((r->restart_due = s_fault_due(x, VAFMD_F_RESTART, bi, &p0, &p1, &sc)) != 0)
        s_fault_rec_init(x, &r->restart_rec, VAFMD_F_RESTART, bi, p0, p1, sc);
    if (!r->drop_left && s_fault_due(x, VAFMD_F_DROP, bi, &p0, &p1, &sc)) {
        r->drop_left = (uint64_t)p0;
        s_fault_rec_init(x, &r->drop_rec, VAFMD_F_DROP, bi, p0, p1, sc);
    }
    return held ? VAFMD_ST_FA_HOLD : VAFMD_ST_FA_RELEASE;
}

/* After the head block went out (or was dropped): the records of the faults that took effect with it. */
void vafmd_st_fault_released(vafmd_st *x, vafmd_st_block *b)
{
    vafmd_st_run *r = &x->run;
    for (int i = 0; i < r->n_held; i++)
        vafmd_st_fault_record(x, &r->held[i]);
    r->n_held = 0;
    if (r->restart_due) {
        r->restart_due = 0;
        vafmd_st_fault_record(x, &r->restart_rec);
    }
    for (int i = 0; i < b->n_frec; i++)
        vafmd_st_fault_record(x, &b->frec[i]);
    b->n_frec = 0;
}
