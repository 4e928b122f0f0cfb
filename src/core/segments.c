/* SPDX-License-Identifier: MIT */
/*
 * Segment lists (vafm/segments.h): defaults, validation, and today's force curve as a list. The list runs
 * in sim.c's curve scene (s_list_* there); this file only checks and builds lists.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "vafm/segments.h"
#include "vafm/sim.h"
#include "core/internal.h"

void vafm_segment_spec_default(vafm_segment_spec *g)
{
    if (!g)
        return;
    memset(g, 0, sizeof *g);
    g->kind = VAFM_SEGMENT_EXTEND;
    g->speed_m_per_s = 1e-6;
    g->distance_m = 0.0;
    g->trigger = VAFM_SEGMENT_TRIGGER_NONE;
    g->trigger_op = VAFM_SEGMENT_ABOVE;
    g->end = VAFM_SEGMENT_END_TRAVEL;
    g->pause_mode = VAFM_PAUSE_HEIGHT;
    g->hold_force_N = NAN;
    g->amplitude_m = 1e-9;
    g->frequency_Hz = 100.0;
    g->label = -1;
}

static const char *const s_kind_names[] = { "extend", "retract", "pause", "modulate" };

/* a real field in [lo, hi] (lo_open: lo excluded) */
static int s_range(vafm_error *err, size_t i, const char *kind, const char *field, double v, double lo, int lo_open,
                   double hi, const char *unit)
{
    if (isfinite(v) && (lo_open ? v > lo : v >= lo) && v <= hi)
        return 0;
    char name[64];
    snprintf(name, sizeof name, "segments[%zu].%s", i, field);
    vafm_err_set(err, VAFM_EINVAL, name, "segment %zu (%s): %s = %g %s is outside %s%g, %g] %s", i, kind, field, v, unit,
                 lo_open ? "(" : "[", lo, hi, unit);
    return VAFM_EINVAL;
}

static int s_bad(vafm_error *err, size_t i, const char *kind, const char *field, const char *what)
{
    char name[64];
    snprintf(name, sizeof name, "segments[%zu].%s", i, field);
    vafm_err_set(err, VAFM_EINVAL, name, "segment %zu (%s): %s", i, kind, what);
    return VAFM_EINVAL;
}

/* The simulated time a checked list takes at most, as a scene's curve is costed before it runs (its samples
 * at the scene's rate, VAFM_SIM_MAX_SAMPLES): a move's travel over its speed (an extend to the approach
 * limit: the scene's z_range_m, its ramp, or the start height; a retract to the start or to detachment: the
 * travel extended so far), a pause's or modulation's duration, each cut by a time trigger. *slowest: the
 * segment that takes longest. */
static double s_list_time(const vafm_segment_spec *segs, size_t n, const vafm_params *p, size_t *slowest)
{
    const double limit = p->z_range_m > 0 ? p->z_range_m : p->ramp_size_m > 0 ? 2.0 * p->ramp_size_m
                                                                                : fabs(p->start_height_m);
    double total = 0.0, extended = 0.0, worst = -1.0;
    for (size_t i = 0; i < n; i++) {
        const vafm_segment_spec *g = &segs[i];
        double t;
        if (g->kind == VAFM_SEGMENT_EXTEND || g->kind == VAFM_SEGMENT_RETRACT) {
            double travel = g->distance_m > 0                                        ? g->distance_m
                            : g->kind == VAFM_SEGMENT_EXTEND                         ? limit
                            : g->end != VAFM_SEGMENT_END_TRAVEL                       ? extended
                                                                                      : 0.0;
            extended += g->kind == VAFM_SEGMENT_EXTEND ? travel : -fmin(travel, extended);
            t = travel / g->speed_m_per_s;
        } else
            t = g->duration_s;
        if (g->trigger == VAFM_SEGMENT_TRIGGER_TIME)
            t = fmin(t, g->trigger_value);
        if (t > worst) {
            worst = t;
            *slowest = i;
        }
        total += t;
    }
    return total;
}

int vafm_segments_validate(const vafm_segment_spec *segs, size_t n, const vafm_params *p, vafm_error *err)
{
    if (!segs || !p) {
        vafm_err_set(err, VAFM_EINVAL, "segments", "no segment list or no scene given");
        return VAFM_EINVAL;
    }
    if (n < 1 || n > VAFM_SEGMENTS_MAX) {
        vafm_err_set(err, VAFM_EINVAL, "segments", "a segment list has 1 to %d segments (got %zu)", VAFM_SEGMENTS_MAX, n);
        return VAFM_EINVAL;
    }
    const double rate = p->sample_rate_Hz;
    if (!(rate > 0) || !isfinite(rate)) {
        vafm_err_set(err, VAFM_EINVAL, "sample_rate_Hz", "the scene has no sample rate (%g Hz)", rate);
        return VAFM_EINVAL;
    }
    for (size_t i = 0; i < n; i++) {
        const vafm_segment_spec *g = &segs[i];
        if (g->kind < VAFM_SEGMENT_EXTEND || g->kind > VAFM_SEGMENT_MODULATE) {
            char name[64];
            snprintf(name, sizeof name, "segments[%zu].kind", i);
            vafm_err_set(err, VAFM_EINVAL, name, "segment %zu: kind %d is none of extend (0), retract (1), pause (2), "
                         "modulate (3)", i, g->kind);
            return VAFM_EINVAL;
        }
        const char *k = s_kind_names[g->kind];
        const int moves = g->kind == VAFM_SEGMENT_EXTEND || g->kind == VAFM_SEGMENT_RETRACT;
        int r;
        if (g->trigger < VAFM_SEGMENT_TRIGGER_NONE || g->trigger > VAFM_SEGMENT_TRIGGER_TIME)
            return s_bad(err, i, k, "trigger", "trigger must be none, force, deflection_V, height or time");
        if (g->trigger != VAFM_SEGMENT_TRIGGER_NONE) {
            if (g->trigger_op != VAFM_SEGMENT_ABOVE && g->trigger_op != VAFM_SEGMENT_BELOW)
                return s_bad(err, i, k, "trigger_op", "trigger_op must be '>' (0) or '<' (1)");
            switch (g->trigger) {
            case VAFM_SEGMENT_TRIGGER_FORCE:
                r = s_range(err, i, k, "trigger_value", g->trigger_value, -1.0, 0, 1.0, "N");
                break;
            case VAFM_SEGMENT_TRIGGER_DEFLECTION_V:
                if (!(p->sensitivity_m_per_V > 0))
                    return s_bad(err, i, k, "trigger", "a deflection trigger (V) needs the scene's sensitivity_m_per_V > 0");
                r = s_range(err, i, k, "trigger_value", g->trigger_value, -1e3, 0, 1e3, "V");
                break;
            case VAFM_SEGMENT_TRIGGER_HEIGHT:
                r = s_range(err, i, k, "trigger_value", g->trigger_value, -1.0, 0, 1.0, "m");
                break;
            default:
                if (g->trigger_op != VAFM_SEGMENT_ABOVE)
                    return s_bad(err, i, k, "trigger_op", "a time trigger fires once time exceeds it: op must be '>'");
                r = s_range(err, i, k, "trigger_value", g->trigger_value, 0.0, 1, 1e4, "s");
                break;
            }
            if (r)
                return r;
            if (g->trigger_relative != 0 && g->trigger_relative != 1)
                return s_bad(err, i, k, "trigger_relative", "trigger_relative must be 0 or 1");
            if (g->trigger_relative && g->trigger != VAFM_SEGMENT_TRIGGER_FORCE &&
                g->trigger != VAFM_SEGMENT_TRIGGER_DEFLECTION_V)
                return s_bad(err, i, k, "trigger_relative", "only a force or deflection trigger can be relative");
        }
        if (moves) {
            if ((r = s_range(err, i, k, "speed_m_per_s", g->speed_m_per_s, 0.0, 1, 1e3, "m/s")))
                return r;
            if ((r = s_range(err, i, k, "distance_m", g->distance_m, 0.0, 0, 1e-3, "m")))
                return r;
            if (g->end < VAFM_SEGMENT_END_TRAVEL || g->end > VAFM_SEGMENT_END_START)
                return s_bad(err, i, k, "end", "end must be travel (0), detach (1) or start (2)");
            if (g->end != VAFM_SEGMENT_END_TRAVEL && g->kind != VAFM_SEGMENT_RETRACT)
                return s_bad(err, i, k, "end", "end 'detach' and 'start' are a retract's");
            if (g->end == VAFM_SEGMENT_END_TRAVEL && !(g->distance_m > 0) &&
                !(g->kind == VAFM_SEGMENT_EXTEND && g->trigger != VAFM_SEGMENT_TRIGGER_NONE))
                return s_bad(err, i, k, "distance_m",
                             g->kind == VAFM_SEGMENT_EXTEND
                                 ? "an extend needs a distance_m > 0 or a trigger (then 0: the scene's approach limit)"
                                 : "a retract with end 'travel' needs a distance_m > 0 (with a trigger: the most it travels)");
        } else {
            if ((r = s_range(err, i, k, "duration_s", g->duration_s, 0.0, 0, 1e4, "s")))
                return r;
        }
        if (g->kind == VAFM_SEGMENT_PAUSE) {
            if (g->pause_mode != VAFM_PAUSE_HEIGHT && g->pause_mode != VAFM_PAUSE_FORCE)
                return s_bad(err, i, k, "pause_mode", "pause_mode must be height (0) or force (1)");
            if (g->pause_mode == VAFM_PAUSE_FORCE) {
                if (!isnan(g->hold_force_N) && (r = s_range(err, i, k, "hold_force_N", g->hold_force_N, -1.0, 0, 1.0, "N")))
                    return r;
                if (g->feedback_s != 0.0 && (r = s_range(err, i, k, "feedback_s", g->feedback_s, 0.0, 1, 1e4, "s")))
                    return r;
                if (g->feedback_s != 0.0 && g->feedback_s * rate < 2.0) /* as the scene's dwell_feedback_s */
                    return s_bad(err, i, k, "feedback_s", "feedback_s is shorter than 2 sample intervals of the scene: "
                                 "the loop acts once per sample and would ring (0: the scene's rule)");
            }
        }
        if (g->kind == VAFM_SEGMENT_MODULATE) {
            if ((r = s_range(err, i, k, "amplitude_m", g->amplitude_m, 0.0, 1, 1e-4, "m")))
                return r;
            if ((r = s_range(err, i, k, "frequency_Hz", g->frequency_Hz, 0.0, 1, rate / 4.0, "Hz")))
                return r;
        }
        if (g->sample_rate_Hz != 0.0) {
            if ((r = s_range(err, i, k, "sample_rate_Hz", g->sample_rate_Hz, rate / VAFM_SEGMENT_DECIMATION_MAX, 0, rate,
                             "Hz")))
                return r;
            double d = rate / g->sample_rate_Hz, dr = round(d);
            if (fabs(d - dr) > 1e-9 * d) {
                char name[64];
                snprintf(name, sizeof name, "segments[%zu].sample_rate_Hz", i);
                vafm_err_set(err, VAFM_EINVAL, name, "segment %zu (%s): sample_rate_Hz = %g Hz is not the scene's rate "
                             "%g Hz divided by a whole number (%g): the segment's samples are means of whole numbers of "
                             "the scene's", i, k, g->sample_rate_Hz, rate, d);
                return VAFM_EINVAL;
            }
        }
        if (g->label < -1 || g->label > 254)
            return s_bad(err, i, k, "label", "label must be -1 (the segment's position) or 0 to 254");
    }
    size_t slow = 0;
    const double t = s_list_time(segs, n, p, &slow), samples = t * rate;
    if (!(samples <= (double)VAFM_SIM_MAX_SAMPLES)) {
        const vafm_segment_spec *g = &segs[slow];
        const int moves = g->kind == VAFM_SEGMENT_EXTEND || g->kind == VAFM_SEGMENT_RETRACT;
        char name[64];
        snprintf(name, sizeof name, "segments[%zu].%s", slow, moves ? "speed_m_per_s" : "duration_s");
        vafm_err_set(err, VAFM_EINVAL, name, "the list runs ~%.3g s (simulated; segment %zu (%s) the longest) and would "
                     "have ~%.3g samples at the scene's sample_rate_Hz = %.6g Hz: more than a curve may have (%llu, "
                     "VAFM_SIM_MAX_SAMPLES); shorten it (%s)", t, slow, s_kind_names[g->kind], samples, rate,
                     (unsigned long long)VAFM_SIM_MAX_SAMPLES, name);
        return VAFM_EINVAL;
    }
    return 0;
}

int vafm_segments_from_params(const vafm_params *p, vafm_segment_spec *out, size_t cap)
{
    if (!p || !out || cap < 3)
        return VAFM_EINVAL;
    size_t n = 0;
    vafm_segment_spec *g = &out[n++];
    vafm_segment_spec_default(g);
    g->kind = VAFM_SEGMENT_EXTEND;
    g->speed_m_per_s = p->v_approach_m_per_s;
    g->distance_m = 0.0; /* the scene's approach limit */
    if (p->trigger == VAFM_TRIGGER_HEIGHT) {
        g->trigger = VAFM_SEGMENT_TRIGGER_HEIGHT;
        g->trigger_op = VAFM_SEGMENT_BELOW;
        g->trigger_value = p->trigger_height_m;
    } else {
        g->trigger = VAFM_SEGMENT_TRIGGER_FORCE;
        g->trigger_op = VAFM_SEGMENT_ABOVE;
        g->trigger_value = p->setpoint_N;
        g->trigger_relative = p->setpoint_mode == VAFM_SETPOINT_RELATIVE;
    }
    g->label = VAFM_SEG_APPROACH;
    if (p->dwell_s > 0) {
        g = &out[n++];
        vafm_segment_spec_default(g);
        g->kind = VAFM_SEGMENT_PAUSE;
        g->duration_s = p->dwell_s;
        g->pause_mode = p->dwell_mode == VAFM_DWELL_FORCE ? VAFM_PAUSE_FORCE : VAFM_PAUSE_HEIGHT;
        g->feedback_s = p->dwell_feedback_s;
        g->label = VAFM_SEG_DWELL;
    }
    g = &out[n++];
    vafm_segment_spec_default(g);
    g->kind = VAFM_SEGMENT_RETRACT;
    g->speed_m_per_s = p->v_retract_m_per_s;
    g->end = p->ramp_size_m > 0 ? VAFM_SEGMENT_END_START : VAFM_SEGMENT_END_DETACH;
    g->label = VAFM_SEG_RETRACT;
    return (int)n;
}
