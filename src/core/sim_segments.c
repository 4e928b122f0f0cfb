/* SPDX-License-Identifier: MIT */
/*
 * Segment lists (vafm/segments.h) on the force-curve scene: a run is a list of segments (extend or retract by
 * a distance or until a trigger, pause at constant height or force, modulate), each with its own sample rate.
 *
 * Design: sim.c's sample loop stays the one loop of every scene; at each output sample boundary it hands a
 * list run to vafm_sim_list_logic (here), which tests the running segment's trigger and end and enters the
 * next segment by setting the support's speed (s_set_speed, sim_impl.h) exactly as the curve's own phases do,
 * so a one-extend-one-retract list is today's curve. Layering: this file uses only sim_impl.h; sim.c calls
 * it (vafm_sim_segments_begin starts the scene, then vafm_sim_list_enter), never the other way round. A
 * segment's own sample rate is a decimation of the scene's samples (vafm_sim_dec_add / _emit: the mean, or
 * the last with antialias point), done by the loop at the same boundaries. Split from sim.c without a change of arithmetic (the build has -ffp-contract=off,
 * so moving code between files changes no result: the segments and golden tests are bit for bit).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "vafm/segments.h"
#include "vafm/sim.h"
#include "core/internal.h"
#include "core/kernel.h"
#include "core/sim_impl.h"

/* The command at this sample boundary (with the piezo model: the one the actuator is driven to now). */
static inline double s_ucmd_boundary(const vafm_sim *s)
{
    return s->pz.on ? s->ucmd_next : s_ucmd(s);
}

static inline int s_force_type(int ch)
{
    return ch == VAFM_SEGMENT_TRIGGER_FORCE || ch == VAFM_SEGMENT_TRIGGER_DEFLECTION_V;
}

/* A modulation's next interval: the command goes to h0 + A·sin(2π f τ) at the next boundary. */
static void s_list_modulate(vafm_sim *s, const vafm_segment_spec *g)
{
    const vafm_scale *sc = &s->nm.sc;
    const double Ts = s->nm.Ts;
    const double tau_s = vafm_scale_time_si(sc, s->K.t + Ts - s->seg_t0);
    const double target = s->seg_u0 - vafm_scale_length_red(sc, g->amplitude_m) * sin(2.0 * M_PI * g->frequency_Hz * tau_s);
    s_set_speed(s, (target - s_ucmd_boundary(s)) / Ts);
    s->need_prepare = 1;
}

/* Enter segment i of the list at this sample boundary (force: the sample's, reduced); pauses and
 * modulations of no whole sample are skipped; past the last segment the run is done. first: the run's
 * start (s_begin set the first phase's speed). */
void vafm_sim_list_enter(vafm_sim *s, size_t i, double force, int first)
{
    vafm_kernel *K = &s->K;
    const vafm_scale *sc = &s->nm.sc;
    const double rate = s->p.sample_rate_Hz;
    const int prev_force_trig = i > 0 && s->seg[i - 1].kind == VAFM_SEGMENT_EXTEND && s_force_type(s->seg[i - 1].trigger);
    for (; i < s->nseg; i++, first = 0) {
        const vafm_segment_spec *g = &s->seg[i];
        s->iseg = i;
        s->seg_label = g->label >= 0 ? g->label : (int)i;
        s->seg_u0 = s_ucmd(s);
        s->seg_t0 = K->t;
        s->base_sum = 0.0;
        s->base_n = 0;
        s->dec = g->sample_rate_Hz > 0 ? lround(rate / g->sample_rate_Hz) : 1;
        s->seg_ch = g->trigger;
        s->seg_op = g->trigger_op;
        switch (g->trigger) {
        case VAFM_SEGMENT_TRIGGER_FORCE: s->seg_thr = vafm_scale_force_red(sc, g->trigger_value); break;
        case VAFM_SEGMENT_TRIGGER_DEFLECTION_V:
            s->seg_thr = vafm_scale_force_red(sc, (g->trigger_value - (g->trigger_relative ? 0.0 : s->p.baseline_offset_V)) *
                                                      s->p.sensitivity_m_per_V * s->p.k_N_per_m);
            break;
        case VAFM_SEGMENT_TRIGGER_HEIGHT: s->seg_thr = vafm_scale_length_red(sc, -g->trigger_value); break;
        case VAFM_SEGMENT_TRIGGER_TIME: s->seg_thr = vafm_scale_time_red(sc, g->trigger_value); break;
        default: s->seg_thr = 0.0; break;
        }
        const double v = vafm_scale_speed_red(sc, g->speed_m_per_s);
        switch (g->kind) {
        case VAFM_SEGMENT_EXTEND:
            if (!first) {
                s_set_speed(s, v);
                s->need_prepare = 1;
            }
            s->seg_ulim = g->distance_m > 0 ? s->seg_u0 + vafm_scale_length_red(sc, g->distance_m) : s->uspr_zlimit;
            s->phase = S_PH_APPROACH;
            return;
        case VAFM_SEGMENT_RETRACT:
            if (g->end != VAFM_SEGMENT_END_TRAVEL) {
                s_start_retract_at(s, v);
            } else {
                s_set_speed(s, -v);
                s->need_prepare = 1;
                s->t_retract0 = K->t;
                s->uspr_turn = s_ucmd(s);
                K->fs_min = INFINITY;
                s->phase = S_PH_RETRACT;
                s->seg_ulim = s->seg_u0 - vafm_scale_length_red(sc, g->distance_m);
            }
            return;
        case VAFM_SEGMENT_PAUSE: {
            s->seg_left = lround(g->duration_s * rate);
            if (s->seg_left <= 0)
                continue;
            const double tau = g->feedback_s > 0         ? g->feedback_s
                               : s->p.dwell_feedback_s > 0 ? s->p.dwell_feedback_s
                                                           : 10.0 / rate;
            s->fb_gain = 1.0 / vafm_scale_time_red(sc, s->nm.r.k * tau);
            if (!isnan(g->hold_force_N))
                s->F_hold = vafm_scale_force_red(sc, g->hold_force_N);
            else if (!prev_force_trig)
                s->F_hold = force;
            s_set_speed(s, g->pause_mode == VAFM_PAUSE_FORCE ? s->fb_gain * (s->F_hold - force) : 0.0);
            s->need_prepare = 1;
            s->phase = S_PH_DWELL;
            return;
        }
        default: /* modulate */
            s->seg_left = lround(g->duration_s * rate);
            if (s->seg_left <= 0)
                continue;
            s->seg_u0 = s_ucmd_boundary(s);
            s->phase = S_PH_DWELL;
            s_list_modulate(s, g);
            return;
        }
    }
    s->iseg = s->nseg;
    s->phase = S_PH_DONE;
}

/* A list's sample boundary: the running segment's trigger and end (force: the sample's, reduced). */
void vafm_sim_list_logic(vafm_sim *s, double force)
{
    vafm_kernel *K = &s->K;
    const vafm_segment_spec *g = &s->seg[s->iseg];
    double base = 0.0;
    int armed = 1;
    if (g->trigger_relative) {
        /* the baseline: the mean of the segment's first samples before this one (as the curve's relative setpoint) */
        armed = s->base_n > 0;
        base = armed ? s->base_sum / s->base_n : 0.0;
        if (s->base_n < VAFM_BASELINE_SAMPLES) {
            s->base_sum += force;
            s->base_n++;
        }
    }
    int trig = 0;
    switch (s->seg_ch) {
    case VAFM_SEGMENT_TRIGGER_FORCE:
    case VAFM_SEGMENT_TRIGGER_DEFLECTION_V:
        trig = armed && (s->seg_op == VAFM_SEGMENT_ABOVE ? force - base >= s->seg_thr : force - base <= s->seg_thr);
        break;
    case VAFM_SEGMENT_TRIGGER_HEIGHT: /* height falls as the command u rises */
        trig = s->seg_op == VAFM_SEGMENT_BELOW ? s_ucmd(s) >= s->seg_thr : s_ucmd(s) <= s->seg_thr;
        break;
    case VAFM_SEGMENT_TRIGGER_TIME: trig = K->t - s->seg_t0 >= s->seg_thr; break;
    default: break;
    }
    if (s->seg_ch != VAFM_SEGMENT_TRIGGER_TIME)
        trig = trig && !s->trigger_off; /* fault injection: a trigger that never fires */
    int done = 0;
    switch (g->kind) {
    case VAFM_SEGMENT_EXTEND:
        s->F_hold = s_force_type(s->seg_ch) ? s->seg_thr + base : force;
        if (!trig && s_ucmd(s) >= s->seg_ulim) {
            if (s->seg_ch != VAFM_SEGMENT_TRIGGER_NONE)
                s->flags |= VAFM_CURVE_NO_TRIGGER;
            trig = 1;
        }
        done = trig;
        break;
    case VAFM_SEGMENT_RETRACT:
        if (trig)
            done = 1;
        else if (g->end == VAFM_SEGMENT_END_START) {
            /* back to the run's start height, whatever the tip did on the way (a fixed ramp) */
            if (s_ucmd(s) <= s->uspr_start) {
                if (K->in_contact)
                    s->flags |= VAFM_CURVE_NO_DETACH;
                done = 1;
            }
        } else if (g->end == VAFM_SEGMENT_END_DETACH) {
            const double travel = s->uspr_turn - s_ucmd(s);
            if (!K->in_contact && s->detached_in_retract && s->uspr_detach - K->u_spr >= s->margin)
                done = 1;
            else if (!K->in_contact && !s->detached_in_retract &&
                     s_ucmd(s) <= fmin(s->uspr_start, s->uspr_turn) - s->margin)
                done = 1;
            else if (travel >= s->retract_travel_max) {
                if (K->in_contact)
                    s->flags |= VAFM_CURVE_NO_DETACH;
                done = 1;
            }
        } else if (s_ucmd(s) <= s->seg_ulim)
            done = 1;
        break;
    case VAFM_SEGMENT_PAUSE:
        if (trig || --s->seg_left <= 0)
            done = 1;
        else if (g->pause_mode == VAFM_PAUSE_FORCE) {
            s_set_speed(s, s->fb_gain * (s->F_hold - force));
            s->need_prepare = 1;
        }
        break;
    default: /* modulate */
        if (trig || --s->seg_left <= 0)
            done = 1;
        else
            s_list_modulate(s, g);
        break;
    }
    if (done)
        vafm_sim_list_enter(s, s->iseg + 1, force, 0);
}

int vafm_sim_segment_current(const vafm_sim *s)
{
    if (!s || !s->list || s->scene != S_SCENE_CURVE || s->phase == S_PH_DONE)
        return -1;
    return (int)s->iseg;
}

uint64_t vafm_sim_clock_samples(const vafm_sim *s)
{
    return s && s->scene != S_SCENE_NONE ? s->clock_samples : 0;
}

/* Decimation of a list's segment: add the sample in block slot j (reduced force: force) to the running sums.
 * @return 1 once the output sample is complete (dec samples). */
int vafm_sim_dec_add(vafm_sim *s, size_t j, double force)
{
    const double v[7] = { s->bt[j], s->bh[j], s->pz.on ? s->bha[j] : 0.0, s->bd[j], s->bf[j], s->btip[j], force };
    const int mean = s->p.antialias == VAFM_ANTIALIAS_MEAN;
    for (int c = 0; c < 7; c++)
        s->dec_sum[c] = mean && s->dec_n > 0 ? s->dec_sum[c] + v[c] : v[c];
    s->dec_n++;
    return s->dec_n >= s->dec;
}

/* Write the gathered output sample (the mean of the dec_n samples, or the last of them with antialias
 * point) into block slot j, labelled seg. */
void vafm_sim_dec_emit(vafm_sim *s, size_t j, int seg, int in_retract)
{
    const double w = s->p.antialias == VAFM_ANTIALIAS_MEAN ? 1.0 / (double)s->dec_n : 1.0;
    s->bt[j] = s->dec_sum[0] * w;
    s->bh[j] = s->dec_sum[1] * w;
    if (s->pz.on)
        s->bha[j] = s->dec_sum[2] * w;
    s->bd[j] = s->dec_sum[3] * w;
    s->bf[j] = s->dec_sum[4] * w;
    s->btip[j] = s->dec_sum[5] * w;
    s->bseg[j] = (uint8_t)seg;
    const double force = s->dec_sum[6] * w;
    s->dec_n = 0;
    s_sample_done(s, force, in_retract);
}
