/* SPDX-License-Identifier: MIT */
/*
 * The always-on controller in vafmd: its live stream, its commands, its settings and its status (design:
 * live.h; the wire: protocol/wire.md "live"; the behaviour: docs/instrument.md "The daemon").
 *
 * Pacing: while no run is in progress the simulation thread calls vafmd_live_idle about every millisecond; it
 * advances the controller to anchor_sample + (now − anchor)·fs·speed. The anchor is taken again after any gap
 * of more than S_GAP_NS (a run, a stall) — the controller's state is held, not caught up — and whenever the
 * controller cannot keep up within S_BUDGET_NS of work per call (the live scene then runs slower than asked,
 * never bursts). Free run changes nothing here: the live scene has no end to run to, so it is paced at `speed`
 * × real time; a scripted session gives its commands a controller time (`at_s`) instead, which makes it
 * reproducible whatever the machine's speed.
 *
 * Decimation: monitor point j is the MEAN of the controller samples [j·m, (j+1)·m) (m = round(fs / rate)),
 * aligned on the controller's own sample index; `state` is the state after the point's last sample. A message
 * holds the points of about 0.1 s of controller time (at least 1, at most S_MAX_PTS).
 */
#include <inttypes.h>
#include <math.h>
#include <pthread.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <zmq.h>
#include "daemon/cmd_json.h"
#include "daemon/daemon.h"
#include "daemon/live.h"
#include "daemon/live_int.h"
#include "vafm/wire.h"

/* ================================== both sides ================================== */

static uint64_t s_fnv(const char *s)
{
    uint64_t h = 1469598103934665603ull;
    for (; *s; s++)
        h = (h ^ (unsigned char)*s) * 1099511628211ull;
    return h;
}

uint64_t vafmd_live_scene_hash(const vafm_params *p)
{
    char *buf = malloc(65536);
    uint64_t h = 0;
    if (buf && vafm_params_to_json(p, buf, 65536) > 0)
        h = s_fnv(buf);
    free(buf);
    return h;
}

/* Build a controller over the scene (control thread, or main before the threads). */
vafm_ctrl *vafmd_live_build(const vafm_params *scene, const vafm_ctrl_params *cp, const vafm_map_spec *map,
                            char *why, size_t whylen)
{
    vafm_ctrl *c = NULL;
    vafm_error err;
    memset(&err, 0, sizeof err);
    int rc = vafm_ctrl_new(&c, scene, cp, map, &err);
    if (rc) {
        snprintf(why, whylen, "the scene cannot host the controller: %.40s%s%.100s", err.field[0] ? err.field : "",
                 err.field[0] ? ": " : "", err.message[0] ? err.message : vafm_strerror(rc));
        return NULL;
    }
    why[0] = 0;
    return c;
}

int vafmd_live_init(vafmd *d, const vafmd_live_config *c)
{
    vafmd_live_config def;
    if (!c) {
        vafmd_live_config_default(&def);
        c = &def;
    }
    vafmd_live *L = calloc(1, sizeof *L);
    if (!L)
        return -1;
    L->d = d;
    pthread_mutex_init(&L->mu, NULL);
    L->cp = c->cp;
    L->rate_ctl = L->rate = c->monitor_rate_Hz;
    L->speed = d->set.speed;
    L->scene_hash = vafmd_live_scene_hash(&d->scene);
    if (c->has_sample) {
        L->map = malloc(sizeof *L->map);
        if (!L->map) {
            pthread_mutex_destroy(&L->mu);
            free(L);
            return -1;
        }
        *L->map = c->sample;
        L->sample = c->sample;
        L->has_sample = 1;
        snprintf(L->sample_text, sizeof L->sample_text, "%s", c->sample_text);
    }
    L->ctrl = vafmd_live_build(&d->scene, &L->cp, L->map, L->why, sizeof L->why);
    L->generation = 1;
    atomic_init(&L->ack, 0);
    d->live = L;
    return 0;
}

void vafmd_live_free(vafmd *d)
{
    vafmd_live *L = d->live;
    if (!L)
        return;
    vafm_ctrl_destroy(&L->ctrl);
    free(L->map);
    pthread_mutex_destroy(&L->mu);
    free(L);
    d->live = NULL;
}

/* ================================== simulation thread ================================== */

/* A send's outcome on the counters: a message that did not go out (a full subscriber under XPUB_NODROP refuses
 * the whole message at its first frame) counts one drop. */
static void s_sent(vafmd_live *L, int rc)
{
    if (rc == VAFM_EIO)
        L->dropped++;
}

static void s_send(vafmd_live *L, const void *const *part, const size_t *len, int n)
{
    if (!L->dead)
        s_sent(L, vafmd_pub_send(L->d->pub, NULL, part, len, n));
}

static void s_send_json(vafmd_live *L, const char *topic, json_t *j)
{
    if (L->dead)
        json_decref(j);
    else
        s_sent(L, vafmd_pub_send_json(L->d->pub, NULL, topic, j));
}

void vafmd_live_subscription(vafmd *d, const char *topic, size_t n, int on)
{
    vafmd_live *L = d->live;
    if (!L || n < 1 || n > 4 || memcmp(topic, "live", n))
        return;
    L->subs = on ? L->subs | 1u << (n - 1) : L->subs & ~(1u << (n - 1));
}

static void s_flush(vafmd_live *L)
{
    if (!L->out_n)
        return;
    if (!L->subs) { /* nobody asked for the topic: nothing is sent, nor counted */
        L->out_n = 0;
        return;
    }
    json_t *names = json_array();
    for (size_t k = 0; k < S_NCH; k++)
        json_array_append_new(names, json_string(s_live_channels[k].name));
    json_t *h = json_object();
    json_object_set_new(h, "seq", json_integer((json_int_t)L->seq));
    json_object_set_new(h, "session", json_integer(atomic_load_explicit(&L->d->sh.session, memory_order_relaxed)));
    json_object_set_new(h, "generation", json_integer((json_int_t)L->generation));
    json_object_set_new(h, "first_sample", json_integer((json_int_t)L->out_first));
    json_object_set_new(h, "points", json_integer((json_int_t)L->out_n));
    json_object_set_new(h, "decimation", json_integer((json_int_t)L->decim));
    json_object_set_new(h, "sample_rate_Hz", json_real(L->fs));
    json_object_set_new(h, "monitor_rate_Hz", json_real(L->fs / (double)L->decim));
    json_object_set_new(h, "state", json_string(vafm_ctrl_state_name((int)L->out[S_STATE_CH][L->out_n - 1])));
    json_object_set_new(h, "channels", names);
    char *text = json_dumps(h, JSON_COMPACT);
    json_decref(h);
    if (text) {
        const void *part[2 + S_NCH];
        size_t len[2 + S_NCH];
        part[0] = "live";
        len[0] = 4;
        part[1] = text;
        len[1] = strlen(text);
        for (size_t k = 0; k < S_NCH; k++) {
            part[2 + k] = L->out[k];
            len[2 + k] = L->out_n * sizeof(double);
        }
        s_send(L, part, len, (int)(2 + S_NCH));
        free(text);
    }
    L->seq++;
    L->out_n = 0;
}

/* The decimation of the current monitor rate: samples per point, and points per message (~0.1 s). */
static void s_decimation(vafmd_live *L)
{
    L->acc_n = 0;
    memset(L->acc, 0, sizeof L->acc);
    L->out_n = 0;
    if (!(L->rate > 0) || !(L->fs > 0)) {
        L->decim = 0;
        return;
    }
    double m = floor(L->fs / L->rate + 0.5);
    L->decim = m < 1 ? 1 : (uint64_t)m;
    double pts = ceil(0.1 * L->fs / (double)L->decim);
    L->out_target = pts < 1 ? 1 : pts > S_MAX_PTS ? S_MAX_PTS : (size_t)pts;
}

static void s_sink(void *user, const vafm_ctrl_samples *b)
{
    vafmd_live *L = user;
    if (!L->decim)
        return;
    for (size_t i = 0; i < b->n; i++) {
        const uint64_t idx = b->first + i;
        if (idx % L->decim == 0) { /* a point begins */
            L->acc_n = 0;
            memset(L->acc, 0, sizeof L->acc);
        }
        for (size_t k = 0; k < S_NCH; k++) {
            if (k == S_STATE_CH)
                continue;
            const double *a = *(const double *const *)(const void *)((const char *)b + s_live_channels[k].off);
            L->acc[k] += a[i];
        }
        L->acc_n++;
        if ((idx + 1) % L->decim == 0 && L->acc_n == L->decim) { /* a whole point ends */
            if (!L->out_n) /* (a message flushed at a new controller may leave a point under way) */
                L->out_first = idx + 1 - L->decim;
            for (size_t k = 0; k < S_NCH; k++)
                L->out[k][L->out_n] = k == S_STATE_CH ? (double)b->state[i] : L->acc[k] / (double)L->acc_n;
            if (++L->out_n >= L->out_target)
                s_flush(L);
        }
    }
}

static const char *s_event_kind(int type, const char **key)
{
    *key = "value";
    switch (type) {
    case VAFM_CTRL_EV_ENGAGED: *key = "force_N"; return "engaged";
    case VAFM_CTRL_EV_FAILED: *key = "motor_z_m"; return "engage_failed";
    case VAFM_CTRL_EV_CRASH: *key = "force_N"; return "crash";
    case VAFM_CTRL_EV_Z_SATURATED: *key = "piezo_z_m"; return "z_saturated";
    case VAFM_CTRL_EV_Z_RECOVERED: return "z_recovered";
    case VAFM_CTRL_EV_XY_RANGE: *key = "coordinate_m"; return "xy_range";
    case VAFM_CTRL_EV_WITHDRAWN: *key = "motor_z_m"; return "withdrawn";
    case VAFM_CTRL_EV_MOVED: *key = "distance_m"; return "moved";
    case VAFM_CTRL_EV_Z_REACHED: *key = "piezo_z_m"; return "z_reached";
    case VAFM_CTRL_EV_LOST_CONTACT: *key = "force_N"; return "lost_contact";
    case VAFM_CTRL_EV_SIM_ERROR: return "sim_error";
    case VAFM_CTRL_EV_OVERFLOW: *key = "count"; return "events_dropped";
    default: return "?";
    }
}

static void s_publish(vafmd_live *L, int wait);

static void s_events(vafmd_live *L)
{
    vafm_ctrl_event ev;
    int first = 1;
    while (L->ctrl && vafm_ctrl_event_pop(L->ctrl, &ev)) {
        if (first) /* status shows the state after the event before a client can read the event */
            s_publish(L, 1);
        first = 0;
        const char *key;
        const char *kind = s_event_kind(ev.type, &key);
        json_t *j = json_pack("{s:i,s:s,s:s,s:I,s:I,s:f}", "run_id", 0, "source", "ctrl", "kind", kind, "generation",
                              (json_int_t)L->generation, "sample", (json_int_t)ev.sample, "time_s", ev.time_s);
        json_object_set_new(j, key, json_real(ev.value));
        if (ev.type == VAFM_CTRL_EV_FAILED)
            json_object_set_new(j, "reason", json_string(vafm_ctrl_fail_name(ev.reason)));
        if (ev.type == VAFM_CTRL_EV_SIM_ERROR)
            json_object_set_new(j, "code", json_integer(ev.reason));
        s_send_json(L, "event", j);
    }
}

/* The status snapshot. The simulation thread never waits for the lock: it tries (wait: up to 256 times; the
 * control thread holds it for one copy of the snapshot), else the next call publishes. */
static void s_publish(vafmd_live *L, int wait)
{
    int tries = wait ? 256 : 1;
    while (pthread_mutex_trylock(&L->mu))
        if (--tries <= 0)
            return;
    s_snap *s = &L->snap;
    s->have = L->ctrl != NULL;
    snprintf(s->why, sizeof s->why, "%s", L->why);
    if (L->ctrl) {
        vafm_ctrl_status_get(L->ctrl, &s->st);
        s->cp = *vafm_ctrl_params_get(L->ctrl);
    }
    s->fs = L->fs;
    s->monitor_rate_Hz = L->decim ? L->fs / (double)L->decim : 0.0;
    s->generation = L->generation;
    s->seq = L->seq;
    s->dropped = L->dropped;
    s->decimation = L->decim;
    s->held = (int)L->n_pend;
    pthread_mutex_unlock(&L->mu);
}

/* Apply one command to the controller. @return 0 or -1 with e filled. */
static int s_apply(vafmd_live *L, const vafmd_live_op *op, vafmd_err *e)
{
    vafm_ctrl *c = L->ctrl;
    if (!c) {
        vafmd_err_set(e, VAFMD_E_STATE, "cmd", "no controller: %s", L->why);
        return -1;
    }
    vafm_ctrl_status st;
    vafm_ctrl_status_get(c, &st);
    const char *sn = vafm_ctrl_state_name(st.state);
    vafm_error err;
    memset(&err, 0, sizeof err);
    int rc = 0;
    switch (op->op) {
    case VAFMD_LIVE_OP_ENGAGE:
        if ((rc = vafm_ctrl_engage(c)) == VAFM_ESTATE) {
            vafmd_err_set(e, VAFMD_E_STATE, "cmd", "engage is refused while %s%s", sn,
                          st.state == VAFM_CTRL_CRASHED ? " (withdraw first)" : "");
            return -1;
        }
        break;
    case VAFMD_LIVE_OP_WITHDRAW:
        if ((rc = vafm_ctrl_withdraw(c, op->motor_steps)) == VAFM_EINVAL) {
            const vafm_ctrl_params *cp = vafm_ctrl_params_get(c);
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "motor_steps", "motor_steps = %u would take the motor from %g m past "
                          "ctrl_motor_max_m = %g m (at most %.0f steps of %g m)", op->motor_steps, st.motor_z_m,
                          cp->motor_max_m, floor((cp->motor_max_m - st.motor_z_m) / cp->motor_step_m), cp->motor_step_m);
            return -1;
        }
        break;
    case VAFMD_LIVE_OP_MOVE:
        rc = vafm_ctrl_move(c, op->x_m, op->y_m, op->speed_m_per_s, &err);
        break;
    case VAFMD_LIVE_OP_Z:
        rc = vafm_ctrl_z(c, op->z_m, &err);
        break;
    case VAFMD_LIVE_OP_FEEDBACK:
        if (op->has_set) {
            const vafm_ctrl_params *cp = vafm_ctrl_params_get(c);
            rc = vafm_ctrl_feedback_set(c, op->setpoint, op->unit >= 0 ? op->unit : cp->setpoint_unit,
                                        op->relative >= 0 ? op->relative : cp->setpoint_relative, op->p_m_per_N,
                                        op->i_m_per_N_s, op->tau_s, &err);
            if (rc) {
                vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, err.field[0] ? err.field : "setpoint", "%s", err.message);
                return -1;
            }
        }
        if (op->on >= 0 && (rc = vafm_ctrl_feedback(c, op->on)) == VAFM_ESTATE) {
            vafmd_err_set(e, VAFMD_E_STATE, "on", "feedback %s is refused while %s", op->on ? "on" : "off", sn);
            return -1;
        }
        break;
    default:
        vafmd_err_set(e, VAFMD_E_INTERNAL, "cmd", "unknown controller operation %d", op->op);
        return -1;
    }
    if (rc == VAFM_EINVAL) {
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, err.field, "%s", err.message);
        return -1;
    }
    if (rc == VAFM_ESTATE) {
        vafmd_err_set(e, VAFMD_E_STATE, "cmd", "%s is refused while %s", op->cmd, sn);
        return -1;
    }
    if (rc) {
        vafmd_err_set(e, VAFMD_E_INTERNAL, "cmd", "%s: %s", op->cmd, vafm_strerror(rc));
        return -1;
    }
    return 0;
}

/* The controller sample at which time at_s comes: the clock goes on across controllers (vafm_ctrl_carry), from
 * its base (t0, s0: 0 and 0 for the first controller) at the current rate. Before the base: the sample before it
 * (the command is late). */
static uint64_t s_at_sample(const vafmd_live *L, double at_s)
{
    double n = ceil((at_s - L->t0) * L->fs - 1e-6);
    if (n > 0)
        return L->s0 + (uint64_t)n;
    return n < 0 && L->s0 > 0 ? L->s0 - 1 : L->s0;
}

/* Apply the held commands whose time has come (in the order they were given). */
static void s_due(vafmd_live *L)
{
    while (L->n_pend && s_at_sample(L, L->pend[0].at_s) <= L->cur) {
        vafmd_err e;
        memset(&e, 0, sizeof e);
        if (s_apply(L, &L->pend[0], &e)) /* a scheduled command refused: its requester learns it here */
            s_send_json(L, "event", json_pack("{s:i,s:s,s:s,s:I,s:s,s:f,s:s,s:s,s:s}", "run_id", 0, "source", "ctrl",
                                              "kind", "ctrl_refused", "generation", (json_int_t)L->generation, "cmd", L->pend[0].cmd, "at_s", L->pend[0].at_s, "code",
                                              e.code ? e.code : "", "field", e.field, "message", e.message));
        memmove(&L->pend[0], &L->pend[1], (L->n_pend - 1) * sizeof L->pend[0]);
        L->n_pend--;
    }
    s_events(L);
}

static void s_ack(vafmd_live *L, uint64_t req, int rc)
{
    if (!req)
        return;
    L->ack_rc = rc;
    atomic_store_explicit(&L->ack, req, memory_order_release);
}

/* The feedback settings the `set` did not change (fb_given) stay those of the running controller: a `feedback`
 * command changes them there (and one held for its at_s must not act before it). Should the old values not fit
 * the new scene (the set was checked with the new ones), the new ones stay. */
static void s_feedback_keep(vafm_ctrl *to, const vafm_ctrl *from, unsigned given)
{
    const vafm_ctrl_params *o = vafm_ctrl_params_get(from), *n = vafm_ctrl_params_get(to);
    vafm_ctrl_feedback_set(to, given & VAFMD_LIVE_FB_SETPOINT ? n->setpoint : o->setpoint,
                           given & VAFMD_LIVE_FB_UNIT ? n->setpoint_unit : o->setpoint_unit,
                           given & VAFMD_LIVE_FB_RELATIVE ? n->setpoint_relative : o->setpoint_relative,
                           given & VAFMD_LIVE_FB_P ? n->fb_p_m_per_N : o->fb_p_m_per_N,
                           given & VAFMD_LIVE_FB_I ? n->fb_i_m_per_N_s : o->fb_i_m_per_N_s,
                           given & VAFMD_LIVE_FB_TAU ? n->fb_tau_s : o->fb_tau_s, NULL);
}

void vafmd_live_apply(vafmd *d, const vafmd_live_op *op)
{
    vafmd_live *L = d->live;
    memset(&L->ack_err, 0, sizeof L->ack_err);
    if (op->op == VAFMD_LIVE_OP_NEW) {
        s_flush(L);
        /* rare: a scene or settings change (the allocator may be used here). The new controller goes on from the
         * old one's state (vafm_ctrl_carry: position, state, feedback, clock); a new seed (a new simulated world:
         * what a scripted session sets first) or ctrl_motor_z0_m, or a scene that cannot host a controller start
         * afresh */
        int carry_rc = 0;
        vafm_error cerr;
        memset(&cerr, 0, sizeof cerr);
        if (op->ctrl && L->ctrl && !op->fresh) {
            s_feedback_keep(op->ctrl, L->ctrl, op->fb_given);
            carry_rc = vafm_ctrl_carry(op->ctrl, L->ctrl, &cerr);
        }
        vafm_ctrl_destroy(&L->ctrl);
        free(L->map);            /* after the controller that borrowed it */
        L->ctrl = op->ctrl;
        L->map = op->map;
        snprintf(L->why, sizeof L->why, "%s", op->why);
        L->generation++;
        vafm_ctrl_status st;
        memset(&st, 0, sizeof st);
        if (L->ctrl)
            vafm_ctrl_status_get(L->ctrl, &st);
        if (!L->ctrl || carry_rc || op->fresh)
            L->n_pend = 0; /* else the held commands keep their times: the clock goes on */
        L->cur = st.sample;
        L->t0 = st.clock_base_s;
        L->s0 = st.clock_base_sample;
        L->anchored = 0;
        const double fs = L->fs;
        L->fs = L->ctrl ? 1.0 / vafm_ctrl_sample_interval_s(L->ctrl) : 0.0;
        if (L->fs != fs || carry_rc || !L->ctrl || op->fresh)
            s_decimation(L); /* else the point under way goes on: the samples do */
        if (carry_rc) /* cannot happen with a fresh controller; never silent */
            s_send_json(L, "event", json_pack("{s:i,s:s,s:s,s:I,s:i,s:s}", "run_id", 0, "source", "ctrl", "kind",
                                              "sim_error", "generation", (json_int_t)L->generation, "code", carry_rc,
                                              "message", cerr.message));
        s_events(L); /* what the carry clamped (z_saturated, xy_range, crash) */
        s_publish(L, 1);
        s_ack(L, op->req, 0);
        return;
    }
    if (op->op == VAFMD_LIVE_OP_SETTINGS) {
        L->speed = op->speed;
        if (op->monitor_rate_Hz != L->rate) {
            s_flush(L);
            L->rate = op->monitor_rate_Hz;
            s_decimation(L);
        }
        L->anchored = 0;
        s_publish(L, 1);
        s_ack(L, op->req, 0);
        return;
    }
    int rc = 0;
    L->ack_late = op->has_at && L->ctrl && s_at_sample(L, op->at_s) < L->cur;
    if (op->has_at && L->ctrl && s_at_sample(L, op->at_s) > L->cur) {
        if (L->n_pend >= S_PEND) {
            vafmd_err_set(&L->ack_err, VAFMD_E_BUSY, "at_s", "%d commands are already waiting for their time", S_PEND);
            rc = -1;
        } else
            L->pend[L->n_pend++] = *op;
    } else {
        rc = s_apply(L, op, &L->ack_err);
        s_events(L); /* an xy_range refusal is an event too */
    }
    s_publish(L, 1);
    s_ack(L, op->req, rc);
}

static int64_t s_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * S_NS + ts.tv_nsec;
}

int64_t vafmd_live_idle(vafmd *d, int64_t now, int dead)
{
    vafmd_live *L = d->live;
    L->dead = dead;
    if (!L->ctrl) {
        s_publish(L, 0);
        return now + 1000000;
    }
    if (!L->fs) {
        L->fs = 1.0 / vafm_ctrl_sample_interval_s(L->ctrl);
        s_decimation(L);
    }
    if (!L->anchored || now - L->last_ns > S_GAP_NS) {
        L->anchor_ns = now;
        L->anchor_sample = L->cur;
        L->anchored = 1;
    }
    L->last_ns = now;
    const uint64_t target = L->anchor_sample + (uint64_t)((double)(now - L->anchor_ns) * 1e-9 * L->fs * L->speed);
    s_due(L);
    while (L->cur < target) {
        uint64_t n = target - L->cur;
        if (n > 4096)
            n = 4096;
        if (L->n_pend) {
            uint64_t at = s_at_sample(L, L->pend[0].at_s);
            if (at > L->cur && at - L->cur < n)
                n = at - L->cur;
        }
        long got = vafm_ctrl_advance(L->ctrl, (size_t)n, s_sink, L);
        vafm_ctrl_status st;
        vafm_ctrl_status_get(L->ctrl, &st);
        L->cur = st.sample;
        s_due(L);
        if (got <= 0 && got != (long)n)
            s_events(L);
        int64_t t = s_now();
        if (t - now > S_BUDGET_NS) { /* cannot keep up: fall behind, never burst */
            L->anchor_ns = t;
            L->anchor_sample = L->cur;
            break;
        }
    }
    s_publish(L, 0);
    return now + 1000000;
}

void vafmd_live_run_start(vafmd *d, char **start_json)
{
    vafmd_live *L = d->live;
    if (!L || !*start_json)
        return;
    s_flush(L); /* the points so far go out before the run */
    json_t *j = json_loads(*start_json, 0, NULL);
    if (!j)
        return;
    json_t *c;
    if (!L->ctrl)
        c = json_null();
    else {
        vafm_ctrl_status st;
        vafm_ctrl_status_get(L->ctrl, &st);
        c = json_pack("{s:I,s:s,s:I,s:f,s:f,s:f,s:f,s:f,s:b,s:b,s:f}", "generation", (json_int_t)L->generation, "state",
                      vafm_ctrl_state_name(st.state), "sample", (json_int_t)st.sample, "time_s", st.time_s, "motor_z_m",
                      st.motor_z_m, "piezo_z_m", st.piezo_z_m, "x_m", st.x_m, "y_m", st.y_m, "feedback", st.feedback,
                      "in_contact", st.in_contact, "force_N", st.force_N);
        json_object_set_new(c, "setpoint_N", isfinite(st.setpoint_N) ? json_real(st.setpoint_N) : json_null());
        json_object_set_new(c, "surface_m", json_real(st.surface_m));
    }
    json_object_set_new(j, "ctrl", c);
    char *text = json_dumps(j, JSON_COMPACT);
    json_decref(j);
    if (text) {
        free(*start_json);
        *start_json = text;
    }
}

void vafmd_live_sim_exit(vafmd *d)
{
    vafmd_live *L = d->live;
    if (L)
        s_flush(L);
}

