/* SPDX-License-Identifier: MIT */
/*
 * The always-on controller, control thread's side (design: live.h; pacing and decimation: live.c): hello's
 * channel list, the status snapshot, the controller commands (pushed through the ring, waiting for the
 * simulation thread's ack), get/set of the ctrl_* settings and the live configuration. It never touches the
 * controller itself. Split out of live.c (issue #25: no source file over 1000 lines).
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

/* The controller's settings that get/set reach as ctrl_<field>. */
typedef struct s_cset {
    const char *name; /* the field; the setting is "ctrl_" name */
    size_t off;       /* double fields; (size_t)-1: setpoint_unit, -2: setpoint_relative */
    const char *unit, *doc;
} s_cset;
#define S_D(f, u, doc) { #f, offsetof(vafm_ctrl_params, f), u, doc }
static const s_cset s_csets[] = {
    S_D(motor_z0_m, "m", "start height of the coarse motor above the substrate, [-1e-2, 1e-1] m"),
    S_D(motor_min_m, "m", "lowest motor height, [-1e-2, 1e-1] m: an engage that would step below it fails"),
    S_D(motor_max_m, "m", "highest motor height, (motor_min_m, 1e-1] m"),
    S_D(motor_step_m, "m", "motor step of an engage, (0, 1e-3] m"),
    S_D(motor_speed_m_per_s, "m/s", "motor speed during a step, (0, 1e-2] m/s"),
    S_D(piezo_range_m, "m", "piezo Z range, (0, 1e-3] m"),
    S_D(xy_range_m, "m", "XY scanner range (full side, centred on 0), (0, 1e-2] m"),
    S_D(xy_speed_m_per_s, "m/s", "default lateral speed of a move, (0, 1e-2] m/s"),
    S_D(z_speed_m_per_s, "m/s", "piezo speed of retracts, withdraws and z moves, (0, 1e-2] m/s"),
    S_D(engage_speed_m_per_s, "m/s", "piezo extension speed of the engage's search, (0, 1e-2] m/s"),
    S_D(engage_timeout_s, "s", "an engage gives up after this, (0, 1e5] s"),
    S_D(force_limit_N, "N", "a force beyond this is a crash, (0, 1e-3] N (above the setpoint)"),
    S_D(setpoint, "N or V", "feedback setpoint in ctrl_setpoint_unit, [-100, 100]"),
    { "setpoint_unit", (size_t)-1, "", "\"N\" (force) or \"V\" (deflection signal)" },
    { "setpoint_relative", (size_t)-2, "", "true: relative to the free baseline an engage measures" },
    S_D(fb_p_m_per_N, "m/N", "proportional gain, [0, 1e3] m/N"),
    S_D(fb_i_m_per_N_s, "m/(N s)", "integral gain, [0, 1e12] m/(N s) (0: from ctrl_fb_tau_s)"),
    S_D(fb_tau_s, "s", "integral time constant (gain 1/(k tau)) when the integral gain is 0, [0, 1e3] s "
                       "(0: 10 sample intervals)"),
    S_D(sum_V, "V", "photodiode sum signal, [0, 100] V (reported)"),
};
#undef S_D
#define S_NCSET (sizeof s_csets / sizeof s_csets[0])
#define S_MONITOR_MAX 1e5

/* ================================== control thread ================================== */

static json_t *s_num(double v)
{
    return isfinite(v) ? json_real(v) : json_null();
}

json_t *vafmd_live_hello_json(void)
{
    json_t *ch = json_array();
    for (size_t k = 0; k < S_NCH; k++)
        json_array_append_new(ch, json_pack("{s:s,s:s,s:s}", "name", s_live_channels[k].name, "unit",
                                            s_live_channels[k].unit, "dtype", "<f8"));
    return json_pack("{s:s,s:o}", "topic", "live", "channels", ch);
}

json_t *vafmd_live_status_json(vafmd *d)
{
    vafmd_live *L = d->live;
    s_snap s;
    pthread_mutex_lock(&L->mu);
    s = L->snap;
    pthread_mutex_unlock(&L->mu);
    json_t *j = json_object();
    json_object_set_new(j, "available", json_boolean(s.have));
    json_object_set_new(j, "generation", json_integer((json_int_t)s.generation));
    json_object_set_new(j, "live", json_pack("{s:I,s:f,s:I,s:I}", "seq", (json_int_t)s.seq, "monitor_rate_Hz",
                                             s.monitor_rate_Hz, "decimation", (json_int_t)s.decimation, "dropped",
                                             (json_int_t)s.dropped));
    json_object_set_new(j, "held_commands", json_integer(s.held));
    if (!s.have) {
        json_object_set_new(j, "state", json_null());
        json_object_set_new(j, "error", json_string(s.why));
        return j;
    }
    const vafm_ctrl_status *t = &s.st;
    json_object_set_new(j, "state", json_string(vafm_ctrl_state_name(t->state)));
    static const char *const phases[] = { "none", "baseline", "extend", "retract", "motor" };
    json_object_set_new(j, "engage_phase", json_string(t->engage_phase >= 0 && t->engage_phase <= 4
                                                        ? phases[t->engage_phase] : "?"));
    json_object_set_new(j, "last_fail", t->last_fail ? json_string(vafm_ctrl_fail_name(t->last_fail)) : json_null());
    json_object_set_new(j, "sample", json_integer((json_int_t)t->sample));
    json_object_set_new(j, "time_s", json_real(t->time_s));
    json_object_set_new(j, "sample_rate_Hz", json_real(s.fs));
    json_object_set_new(j, "motor_z_m", s_num(t->motor_z_m));
    json_object_set_new(j, "piezo_z_m", s_num(t->piezo_z_m));
    json_object_set_new(j, "x_m", s_num(t->x_m));
    json_object_set_new(j, "y_m", s_num(t->y_m));
    json_object_set_new(j, "target_x_m", s_num(t->target_x_m));
    json_object_set_new(j, "target_y_m", s_num(t->target_y_m));
    json_object_set_new(j, "moving", json_boolean(t->moving));
    json_object_set_new(j, "surface_m", s_num(t->surface_m));
    json_object_set_new(j, "gap_m", s_num(t->gap_m));
    json_object_set_new(j, "in_contact", json_boolean(t->in_contact));
    json_object_set_new(j, "feedback", json_boolean(t->feedback));
    json_object_set_new(j, "saturated", json_boolean(t->saturated));
    json_object_set_new(j, "setpoint_N", s_num(t->setpoint_N));
    json_object_set_new(j, "baseline_N", s_num(t->baseline_N));
    json_object_set_new(j, "error_N", s_num(t->error_N));
    json_object_set_new(j, "force_N", s_num(t->force_N));
    json_object_set_new(j, "deflection_m", s_num(t->deflection_m));
    json_object_set_new(j, "signal_V", s_num(t->signal_V));
    json_object_set_new(j, "sum_V", s_num(t->sum_V));
    json_object_set_new(j, "invols_m_per_V", s_num(t->invols_m_per_V));
    json_object_set_new(j, "crash_force_N", s_num(t->crash_force_N));
    json_object_set_new(j, "motor_steps", json_integer((json_int_t)t->motor_steps));
    json_object_set_new(j, "gains", json_pack("{s:f,s:f,s:f}", "p_m_per_N", s.cp.fb_p_m_per_N, "i_m_per_N_s",
                                              s.cp.fb_i_m_per_N_s, "tau_s", s.cp.fb_tau_s));
    json_object_set_new(j, "setpoint", json_pack("{s:f,s:s,s:b}", "value", s.cp.setpoint, "unit",
                                                 s.cp.setpoint_unit == VAFM_CTRL_UNIT_V ? "V" : "N", "relative",
                                                 s.cp.setpoint_relative));
    return j;
}

/* Push an op and, without at_s, wait for the simulation thread's answer (the control thread may wait). */
static int s_request(vafmd *d, vafmd_live_op *op, int wait, vafmd_err *e)
{
    vafmd_live *L = d->live;
    op->req = ++L->next_req;
    vafmd_sim_cmd sc;
    memset(&sc, 0, sizeof sc);
    sc.type = VAFMD_SIM_CTRL;
    sc.live = *op;
    if (!vafmd_ring_push(&d->ring, &sc)) {
        vafmd_err_set(e, VAFMD_E_BUSY, "", "the simulation thread does not take commands now; retry");
        return -1;
    }
    if (!wait)
        return 0;
    struct timespec t0, t;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (;;) {
        if (atomic_load_explicit(&L->ack, memory_order_acquire) == op->req)
            break;
        clock_gettime(CLOCK_MONOTONIC, &t);
        if ((t.tv_sec - t0.tv_sec) * S_NS + (t.tv_nsec - t0.tv_nsec) > S_ACK_WAIT_NS) {
            vafmd_err_set(e, VAFMD_E_BUSY, "", "the simulation thread did not answer within 1 s (it will still apply "
                          "the command); query status");
            return -1;
        }
        nanosleep(&(struct timespec){ 0, 50000 }, NULL);
    }
    if (L->ack_rc) {
        *e = L->ack_err;
        return -1;
    }
    return 0;
}

json_t *vafmd_live_cmd(vafmd *d, const vafmd_cmd *c, json_t *ok, vafmd_err *e)
{
    vafmd_live *L = d->live;
    if (d->jobs_started != atomic_load_explicit(&d->sh.jobs_done, memory_order_acquire)) {
        vafmd_err_set(e, VAFMD_E_STATE, "cmd", "a run is in progress: the controller's state is held until it ends "
                      "(abort it or wait)");
        json_decref(ok);
        return NULL;
    }
    vafmd_live_op op = c->ctrl;
    /* the scanner's ranges from the settings in force, before anything is handed over */
    const vafm_ctrl_params *cp = &L->cp;
    if (op.op == VAFMD_LIVE_OP_Z && !(op.z_m <= cp->piezo_range_m)) {
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "z_m", "z_m = %.17g m is outside the piezo range [0, %g] m "
                      "(ctrl_piezo_range_m)", op.z_m, cp->piezo_range_m);
        json_decref(ok);
        return NULL;
    }
    if (op.has_at && op.op == VAFMD_LIVE_OP_MOVE) {
        const double half = 0.5 * cp->xy_range_m;
        const int bx = !(fabs(op.x_m) <= half);
        if (bx || !(fabs(op.y_m) <= half)) {
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, bx ? "x_m" : "y_m", "%s = %.17g m is beyond the scanner's range "
                          "[%g, %g] m (ctrl_xy_range_m)", bx ? "x_m" : "y_m", bx ? op.x_m : op.y_m, -half, half);
            json_decref(ok);
            return NULL;
        }
    }
    if (s_request(d, &op, 1, e)) {
        json_decref(ok);
        return NULL;
    }
    if (op.op == VAFMD_LIVE_OP_FEEDBACK && op.has_set) { /* the next controller keeps the new feedback */
        if (!isnan(op.setpoint))
            L->cp.setpoint = op.setpoint;
        if (op.unit >= 0)
            L->cp.setpoint_unit = op.unit;
        if (op.relative >= 0)
            L->cp.setpoint_relative = op.relative;
        if (!isnan(op.p_m_per_N))
            L->cp.fb_p_m_per_N = op.p_m_per_N;
        if (!isnan(op.i_m_per_N_s))
            L->cp.fb_i_m_per_N_s = op.i_m_per_N_s;
        if (!isnan(op.tau_s))
            L->cp.fb_tau_s = op.tau_s;
    }
    json_object_set_new(ok, "scheduled", json_boolean(op.has_at));
    if (op.has_at) { /* late: the controller's clock had passed at_s when it arrived (applied at once) */
        json_object_set_new(ok, "at_s", json_real(op.at_s));
        json_object_set_new(ok, "late", json_boolean(L->ack_late));
    }
    json_object_set_new(ok, "ctrl", vafmd_live_status_json(d));
    return ok;
}

static const s_cset *s_cset_find(const char *name)
{
    if (strncmp(name, "ctrl_", 5))
        return NULL;
    for (size_t i = 0; i < S_NCSET; i++)
        if (!strcmp(s_csets[i].name, name + 5))
            return &s_csets[i];
    return NULL;
}

static json_t *s_cset_value(const vafm_ctrl_params *cp, const s_cset *f)
{
    if (f->off == (size_t)-1)
        return json_string(cp->setpoint_unit == VAFM_CTRL_UNIT_V ? "V" : "N");
    if (f->off == (size_t)-2)
        return json_boolean(cp->setpoint_relative);
    return json_real(*(const double *)(const void *)((const char *)cp + f->off));
}

static json_t *s_cset_info(const s_cset *f)
{
    return json_pack("{s:s,s:s,s:s}", "unit", f->unit, "kind", f->off == (size_t)-1 ? "choice" : f->off == (size_t)-2
                     ? "bool" : "real", "doc", f->doc);
}

static const char s_monitor_doc[] = "live topic: monitor points per second (block means of the controller's samples), "
                                    "[0, 1e5] Hz, 0: off";

static const char s_sample_doc[] = "the sample under the controller and under a curve started from it: \"\" (a flat "
                                   "uniform sample of the scene's material) or a map's fields as name=value pairs "
                                   "(\"pattern=stripes,period_m=4e-6,b_E_star_Pa=5e9\"), at most 1024 characters";

/* Every setting of the controller's side, in `get`'s order: the ctrl_* table, monitor_rate_Hz, ctrl_sample. */
static json_t *s_setting_names(void)
{
    json_t *a = json_array();
    for (size_t i = 0; a && i < S_NCSET; i++) {
        char nm[64];
        snprintf(nm, sizeof nm, "ctrl_%s", s_csets[i].name);
        json_array_append_new(a, json_string(nm));
    }
    json_array_append_new(a, json_string("monitor_rate_Hz"));
    json_array_append_new(a, json_string("ctrl_sample"));
    return a;
}

/* `get`'s info of one of them (unit, kind, doc). */
static json_t *s_setting_info(const char *name)
{
    const s_cset *f = s_cset_find(name);
    if (f)
        return s_cset_info(f);
    if (!strcmp(name, "ctrl_sample"))
        return json_pack("{s:s,s:s,s:s}", "unit", "", "kind", "text", "doc", s_sample_doc);
    return json_pack("{s:s,s:s,s:s}", "unit", "Hz", "kind", "real", "doc", s_monitor_doc);
}

json_t *vafmd_live_get(vafmd *d, const vafmd_cmd *c, vafmd_err *e)
{
    vafmd_live *L = d->live;
    vafmd_cmd c2 = *c;
    json_t *names = NULL, *extra = c->names ? json_array() : s_setting_names();
    if (c->names) { /* split the names: the controller's here, the rest to vafmd_get_values */
        names = json_array();
        size_t i;
        json_t *n;
        json_array_foreach(c->names, i, n) {
            const char *s = json_string_value(n);
            json_array_append(s_cset_find(s) || !strcmp(s, "monitor_rate_Hz") || !strcmp(s, "ctrl_sample") ? extra
                              : names, n);
        }
        c2.names = names;
    }
    json_t *v = vafmd_get_values(&d->scene, &d->set, &c2, e);
    json_decref(names);
    if (!v) {
        json_decref(extra);
        return NULL;
    }
    json_t *vals = json_object_get(v, "values"), *info = json_object_get(v, "info");
    size_t i;
    json_t *n;
    json_array_foreach(extra, i, n) {
        const char *s = json_string_value(n);
        const s_cset *f = s_cset_find(s);
        json_object_set_new(vals, s, f ? s_cset_value(&L->cp, f)
                                       : !strcmp(s, "ctrl_sample") ? json_string(L->sample_text) : json_real(L->rate_ctl));
        if (info)
            json_object_set_new(info, s, s_setting_info(s));
    }
    json_decref(extra);
    return v;
}

/* Apply one ctrl_* value to cp. @return 0 or -1. */
static int s_cset_apply(vafm_ctrl_params *cp, const char *name, const s_cset *f, json_t *v, vafmd_err *e)
{
    if (f->off == (size_t)-1) {
        const char *u = json_is_string(v) ? json_string_value(v) : NULL;
        if (!u || (strcmp(u, "N") && strcmp(u, "V"))) {
            vafmd_err_set(e, u ? VAFMD_E_OUT_OF_RANGE : VAFMD_E_WRONG_TYPE, name, "'%s' must be \"N\" or \"V\"", name);
            return -1;
        }
        cp->setpoint_unit = !strcmp(u, "V") ? VAFM_CTRL_UNIT_V : VAFM_CTRL_UNIT_N;
        return 0;
    }
    if (f->off == (size_t)-2) {
        if (!json_is_boolean(v)) {
            vafmd_err_set(e, VAFMD_E_WRONG_TYPE, name, "'%s' must be true or false", name);
            return -1;
        }
        cp->setpoint_relative = json_is_true(v);
        return 0;
    }
    if (!json_is_number(v)) {
        vafmd_err_set(e, VAFMD_E_WRONG_TYPE, name, "'%s' must be a number (%s)", name, f->unit);
        return -1;
    }
    *(double *)(void *)((char *)cp + f->off) = json_number_value(v);
    return 0;
}

/* ctrl_sample: "" (a flat uniform sample of the scene's material) or the fields of a map's spec as
 * "name=value" pairs separated by commas or spaces (vafm_map_set's names: "pattern=stripes,period_m=4e-6,
 * b_E_star_Pa=5e9"), as `map` takes them. The text is kept for `get`. @return 0 or -1. */
static int s_sample_parse(json_t *v, vafm_map_spec *sp, int *has, char *text, vafmd_err *e)
{
    const char *t = json_is_string(v) ? json_string_value(v) : NULL;
    if (!t) {
        vafmd_err_set(e, VAFMD_E_WRONG_TYPE, "ctrl_sample", "'ctrl_sample' must be a string: \"\" (a flat uniform "
                      "sample) or the map's fields as name=value pairs, e.g. \"pattern=stripes,period_m=4e-6\"");
        return -1;
    }
    size_t n = strlen(t);
    if (n > S_SAMPLE_MAX) {
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "ctrl_sample", "ctrl_sample is %zu characters long; at most %d", n,
                      S_SAMPLE_MAX);
        return -1;
    }
    char buf[S_SAMPLE_MAX + 1];
    memcpy(buf, t, n + 1);
    vafm_map_spec s;
    vafm_map_spec_default(&s);
    int any = 0;
    char *save = NULL;
    for (char *tok = strtok_r(buf, ", \t", &save); tok; tok = strtok_r(NULL, ", \t", &save)) {
        char *eq = strchr(tok, '=');
        if (!eq || eq == tok || !eq[1]) {
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "ctrl_sample", "ctrl_sample: '%.60s' is not name=value (the map's "
                          "fields, e.g. pattern=stripes)", tok);
            return -1;
        }
        *eq = 0;
        vafm_error err;
        memset(&err, 0, sizeof err);
        int r = vafm_map_set(&s, tok, eq + 1, &err);
        if (r) {
            vafmd_err_set(e, r == VAFM_ENOTFOUND ? VAFMD_E_UNKNOWN_FIELD : VAFMD_E_OUT_OF_RANGE, "ctrl_sample",
                          "ctrl_sample: %.200s", err.message);
            return -1;
        }
        any = 1;
    }
    *sp = s;
    *has = any;
    memcpy(text, t, n + 1);
    return 0;
}

int vafmd_live_set(vafmd *d, const vafmd_cmd *c, vafmd_err *e)
{
    vafmd_live *L = d->live;
    vafm_ctrl_params cp = L->cp;
    double rate = L->rate_ctl;
    int ctrl_given = 0, rate_given = 0, sample_given = 0, has_sample = L->has_sample;
    vafm_map_spec sample = L->sample;
    char sample_text[S_SAMPLE_MAX + 1];
    snprintf(sample_text, sizeof sample_text, "%s", L->sample_text);
    json_t *rest = NULL;
    vafmd_cmd c2 = *c;
    if (c->values) {
        rest = json_object();
        const char *key;
        json_t *v;
        json_object_foreach(c->values, key, v) {
            const s_cset *f = s_cset_find(key);
            if (!strcmp(key, "ctrl_sample")) {
                if (s_sample_parse(v, &sample, &has_sample, sample_text, e)) {
                    json_decref(rest);
                    return -1;
                }
                sample_given = 1;
            } else if (f) {
                if (s_cset_apply(&cp, key, f, v, e)) {
                    json_decref(rest);
                    return -1;
                }
                ctrl_given = 1;
            } else if (!strcmp(key, "monitor_rate_Hz")) {
                double x = json_is_number(v) ? json_number_value(v) : NAN;
                if (!json_is_number(v) || !(x >= 0 && x <= S_MONITOR_MAX)) {
                    vafmd_err_set(e, json_is_number(v) ? VAFMD_E_OUT_OF_RANGE : VAFMD_E_WRONG_TYPE, key,
                                  "monitor_rate_Hz = %.17g is outside [0, %g] Hz (0: off)", x, S_MONITOR_MAX);
                    json_decref(rest);
                    return -1;
                }
                rate = x;
                rate_given = 1;
            } else
                json_object_set(rest, key, v);
        }
        c2.values = rest;
    }
    vafm_params scene = d->scene;
    vafmd_settings set = d->set;
    int rc = vafmd_apply_set(&scene, &set, &c2, e);
    json_decref(rest);
    if (rc)
        return -1;
    if (ctrl_given) {
        vafm_error err;
        memset(&err, 0, sizeof err);
        if (vafm_ctrl_params_validate(&cp, &scene, &err)) {
            char f[80];
            snprintf(f, sizeof f, "ctrl_%.60s", err.field);
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, err.field[0] ? f : "", "%s (the setting is ctrl_%s)", err.message,
                          err.field);
            return -1;
        }
    }
    if (has_sample) { /* every point of the sample must host a curve of the (new) scene, as `map` checks it */
        vafm_error err;
        memset(&err, 0, sizeof err);
        if (vafm_map_validate(&sample, &scene, &err)) {
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "ctrl_sample", "ctrl_sample: %.40s%s%.180s", err.field,
                          err.field[0] ? ": " : "", err.message);
            return -1;
        }
    }
    /* the settings first: a new controller then goes on with the new decimation */
    if (rate_given || set.speed != d->set.speed) {
        vafmd_live_op op;
        memset(&op, 0, sizeof op);
        op.op = VAFMD_LIVE_OP_SETTINGS;
        op.speed = set.speed;
        op.monitor_rate_Hz = rate;
        if (s_request(d, &op, 1, e))
            return -1;
    }
    const uint64_t h = vafmd_live_scene_hash(&scene);
    if (ctrl_given || sample_given || h != L->scene_hash) { /* a new controller over the new scene: the simulation
                                                                 * thread carries the state into it (vafm_ctrl_carry) */
        vafmd_live_op op;
        memset(&op, 0, sizeof op);
        op.op = VAFMD_LIVE_OP_NEW;
        /* afresh: a new seed (a new simulated world) or a new ctrl_motor_z0_m (where the controller starts: asking
         * for it is asking for a start there) */
        op.fresh = scene.seed != d->scene.seed || cp.motor_z0_m != L->cp.motor_z0_m;
        /* the feedback's settings the set changes; the others stay the running controller's: a `feedback`
         * command held for its at_s has put its values in L->cp already, the controller takes them at at_s */
        const vafm_ctrl_params *o = &L->cp;
        op.fb_given = (cp.setpoint != o->setpoint ? VAFMD_LIVE_FB_SETPOINT : 0u) |
                      (cp.setpoint_unit != o->setpoint_unit ? VAFMD_LIVE_FB_UNIT : 0u) |
                      (cp.setpoint_relative != o->setpoint_relative ? VAFMD_LIVE_FB_RELATIVE : 0u) |
                      (cp.fb_p_m_per_N != o->fb_p_m_per_N ? VAFMD_LIVE_FB_P : 0u) |
                      (cp.fb_i_m_per_N_s != o->fb_i_m_per_N_s ? VAFMD_LIVE_FB_I : 0u) |
                      (cp.fb_tau_s != o->fb_tau_s ? VAFMD_LIVE_FB_TAU : 0u);
        if (has_sample && !(op.map = malloc(sizeof *op.map))) {
            vafmd_err_set(e, VAFMD_E_BUSY, "", "out of memory for the controller's sample; retry");
            return -1;
        }
        if (op.map)
            *op.map = sample;
        op.ctrl = vafmd_live_build(&scene, &cp, op.map, op.why, sizeof op.why);
        if (s_request(d, &op, 1, e)) { /* answered: status shows the new controller from the reply on */
            if (!strcmp(e->code, VAFMD_E_BUSY) && strstr(e->message, "not take")) {
                vafm_ctrl_destroy(&op.ctrl); /* not handed over */
                free(op.map);
            }
            return -1;
        }
        L->scene_hash = h;
        L->sample = sample;
        L->has_sample = has_sample;
        snprintf(L->sample_text, sizeof L->sample_text, "%s", sample_text);
    }
    d->scene = scene;
    d->set = set;
    L->cp = cp;
    L->rate_ctl = rate;
    return 0;
}

int vafmd_live_curve_scene(vafmd *d, vafm_params *p, json_t **info, vafmd_err *e)
{
    vafmd_live *L = d->live;
    *info = NULL;
    if (!L || !L->has_sample)
        return 0; /* a curve as before: the scene as it is */
    s_snap s;
    pthread_mutex_lock(&L->mu);
    s = L->snap;
    pthread_mutex_unlock(&L->mu);
    if (!s.have) {
        vafmd_err_set(e, VAFMD_E_STATE, "ctrl_sample", "ctrl_sample is set but there is no controller (%s): the tip's "
                      "position is unknown", s.why);
        return -1;
    }
    vafm_map_truth t;
    vafm_error err;
    memset(&err, 0, sizeof err);
    if (vafm_map_point(&L->sample, &d->scene, s.st.x_m, s.st.y_m, p, &t, &err)) {
        vafmd_err_set(e, VAFMD_E_INVALID_SCENE, "ctrl_sample", "the sample under the tip: %s", err.message);
        return -1;
    }
    char buf[4096];
    json_t *spec = vafm_map_to_json(&L->sample, buf, sizeof buf) > 0 ? json_loads(buf, 0, NULL) : NULL;
    *info = json_pack("{s:f,s:f,s:i,s:i,s:i,s:s,s:f,s:f,s:f,s:s,s:o*}", "x_m", t.x_m, "y_m", t.y_m, "ix", t.ix, "iy",
                      t.iy, "material", t.material, "contact", t.contact ? t.contact->name : "", "E_star_Pa",
                      t.E_star_Pa, "gamma_J_per_m2", t.gamma_J_per_m2, "surface_height_m", t.surface_height_m,
                      "ctrl_sample", L->sample_text, "map", spec);
    return 1;
}

int vafmd_live_sample(vafmd *d, vafm_map_spec *spec, const char **text)
{
    vafmd_live *L = d->live;
    if (!L || !L->has_sample)
        return 0;
    *spec = L->sample;
    *text = L->sample_text;
    return 1;
}

void vafmd_live_config_default(vafmd_live_config *c)
{
    memset(c, 0, sizeof *c);
    vafm_ctrl_params_default(&c->cp);
    c->monitor_rate_Hz = 100.0;
    vafm_map_spec_default(&c->sample);
}

int vafmd_live_config_key(const char *name)
{
    return s_cset_find(name) || !strcmp(name, "ctrl_sample") || !strcmp(name, "monitor_rate_Hz");
}

json_t *vafmd_live_settings_info(void)
{
    json_t *o = json_object(), *names = s_setting_names(), *n;
    size_t i;
    json_array_foreach(names, i, n)
        json_object_set_new(o, json_string_value(n), s_setting_info(json_string_value(n)));
    json_decref(names);
    return o;
}

int vafmd_live_config_parse(const vafmd *d, json_t *values, vafmd_live_config *c, vafmd_err *e)
{
    const char *key;
    json_t *v;
    void *tmp;
    int ctrl_given = 0;
    json_object_foreach_safe(values, tmp, key, v) {
        if (!vafmd_live_config_key(key))
            continue;
        const s_cset *f = s_cset_find(key);
        if (!strcmp(key, "ctrl_sample")) {
            if (s_sample_parse(v, &c->sample, &c->has_sample, c->sample_text, e))
                return -1;
        } else if (f) {
            if (s_cset_apply(&c->cp, key, f, v, e))
                return -1;
            ctrl_given = 1;
        } else {
            double x = json_is_number(v) ? json_number_value(v) : NAN;
            if (!(x >= 0 && x <= S_MONITOR_MAX)) {
                vafmd_err_set(e, json_is_number(v) ? VAFMD_E_OUT_OF_RANGE : VAFMD_E_WRONG_TYPE, key,
                              "monitor_rate_Hz = %.17g is outside [0, %g] Hz (0: off)", x, S_MONITOR_MAX);
                return -1;
            }
            c->monitor_rate_Hz = x;
        }
        json_object_del(values, key);
    }
    vafm_error err;
    memset(&err, 0, sizeof err);
    if (ctrl_given && vafm_ctrl_params_validate(&c->cp, &d->scene, &err)) {
        char fld[80];
        snprintf(fld, sizeof fld, "ctrl_%.60s", err.field);
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, err.field[0] ? fld : "", "%s (the setting is ctrl_%s)", err.message,
                      err.field);
        return -1;
    }
    if (c->has_sample && vafm_map_validate(&c->sample, &d->scene, &err)) {
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "ctrl_sample", "ctrl_sample: %.40s%s%.180s", err.field,
                      err.field[0] ? ": " : "", err.message);
        return -1;
    }
    return 0;
}
