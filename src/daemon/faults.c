/* SPDX-License-Identifier: MIT */
/*
 * Fault plans: decoding and checking (protocol/faults.md), the record's JSON, the stateless deviates.
 * No I/O and no global state (the decoder is part of the fuzzed command library).
 */
#include "daemon/faults.h"
#include "daemon/cmd_json.h"
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A parameter of a kind: its key, where it goes (0: p0, 1: p1), range, default, integer or choice. */
typedef struct s_param {
    const char *key;
    int slot;
    double min, max, dflt;
    int integer;          /* 1: a whole number */
    int lo_open;          /* 1: min itself is not allowed */
    const char *unit;
} s_param;

typedef struct s_kind {
    const char *name;
    int where;            /* VAFMD_FW_* */
    int implemented;
    s_param par[2];
    const char *choice;   /* dropout: "value" is a choice ("nan"|"stuck") into slot 1 */
} s_kind;

static const s_kind s_kinds[VAFMD_F_N] = {
    [VAFMD_F_LATE] = { "late", VAFMD_FW_STREAM, 1, { { "delay_s", 0, 0, 10, 0.1, 0, 1, "s" } }, NULL },
    [VAFMD_F_JITTER] = { "jitter", VAFMD_FW_STREAM, 1, { { "max_s", 0, 0, 1, 0.02, 0, 1, "s" } }, NULL },
    [VAFMD_F_DROP] = { "drop", VAFMD_FW_STREAM, 1, { { "blocks", 0, 1, 1000, 1, 1, 0, "blocks" } }, NULL },
    [VAFMD_F_TRUNCATE] = { "truncate", VAFMD_FW_STREAM, 1, { { 0 } }, NULL },
    [VAFMD_F_STALL] = { "stall", VAFMD_FW_STREAM, 1, { { "duration_s", 0, 0, 60, 1, 0, 1, "s" } }, NULL },
    [VAFMD_F_RESTART] = { "restart", VAFMD_FW_STREAM, 1, { { 0 } }, NULL },
    [VAFMD_F_SATURATE] = { "saturate", VAFMD_FW_STREAM, 1,
                           { { "samples", 0, 1, 1e7, 100, 1, 0, "samples" }, { "level_V", 1, -100, 100, 10, 0, 0, "V" } },
                           NULL },
    [VAFMD_F_DROPOUT] = { "dropout", VAFMD_FW_STREAM, 1, { { "samples", 0, 1, 1e7, 100, 1, 0, "samples" } },
                          "value" },
    [VAFMD_F_NO_TRIGGER] = { "no_trigger", VAFMD_FW_STREAM, 1, { { 0 } }, NULL },
    [VAFMD_F_KILL] = { "kill", VAFMD_FW_STREAM, 1, { { "status", 0, 3, 125, 3, 1, 0, "" } }, NULL },
    [VAFMD_F_REPLY_DELAY] = { "reply_delay", VAFMD_FW_COMMAND, 1, { { "delay_s", 0, 0, 30, 1, 0, 1, "s" } }, NULL },
    [VAFMD_F_NO_REPLY] = { "no_reply", VAFMD_FW_COMMAND, 1, { { 0 } }, NULL },
    [VAFMD_F_BUSY] = { "busy", VAFMD_FW_COMMAND, 1, { { 0 } }, NULL },
};

const char *vafmd_fault_name(int kind)
{
    return kind >= 0 && kind < VAFMD_F_N ? s_kinds[kind].name : "?";
}

int vafmd_fault_where(int kind)
{
    return kind >= 0 && kind < VAFMD_F_N ? s_kinds[kind].where : VAFMD_FW_STREAM;
}

static int s_kind_find(const char *name)
{
    for (int k = 0; k < VAFMD_F_N; k++)
        if (!strcmp(s_kinds[k].name, name))
            return k;
    return -1;
}

static const char *s_kind_list(void)
{
    return "late, jitter, drop, truncate, stall, restart, saturate, dropout, no_trigger, kill, reply_delay, "
           "no_reply, busy";
}

/* splitmix64 finaliser: a good 64-bit mix, enough for fault decisions (not the physics' Philox). */
static uint64_t s_mix(uint64_t z)
{
    z += 0x9e3779b97f4a7c15ULL;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}

double vafmd_fault_u01(uint64_t seed, int kind, uint64_t a, uint64_t b)
{
    uint64_t h = s_mix(seed ^ s_mix((uint64_t)kind + 0x100 * 0x51ed27ULL));
    h = s_mix(h ^ a);
    h = s_mix(h ^ (b * 0x2545f4914f6cdd1dULL));
    return (double)(h >> 11) * 0x1.0p-53;
}

/* The parameters of kind k from object o into *p0, *p1 (defaults where absent). where: the field prefix. */
static int s_params(int k, json_t *o, const char *where, double *p0, double *p1, vafmd_err *e)
{
    const s_kind *K = &s_kinds[k];
    double v[2] = { 0, 0 };
    for (int i = 0; i < 2; i++) {
        const s_param *P = &K->par[i];
        if (!P->key)
            continue;
        v[P->slot] = P->dflt;
        json_t *x = json_object_get(o, P->key);
        if (!x)
            continue;
        char field[64];
        snprintf(field, sizeof field, "%s.%s", where, P->key);
        if (!json_is_number(x) || (P->integer && !json_is_integer(x))) {
            vafmd_err_set(e, VAFMD_E_WRONG_TYPE, field, "'%s' of a %s fault must be %s (%s)", P->key, K->name,
                          P->integer ? "an integer" : "a number", P->unit[0] ? P->unit : "no unit");
            return -1;
        }
        double d = json_number_value(x);
        if (!(d >= P->min && d <= P->max) || (P->lo_open && !(d > P->min))) {
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, field, "%s = %.17g is outside %s%g, %g] %s", field, d,
                          P->lo_open ? "(" : "[", P->min, P->max, P->unit);
            return -1;
        }
        v[P->slot] = d;
    }
    if (K->choice) {
        v[1] = 0;
        json_t *x = json_object_get(o, K->choice);
        if (x) {
            char field[64];
            snprintf(field, sizeof field, "%s.%s", where, K->choice);
            if (!json_is_string(x)) {
                vafmd_err_set(e, VAFMD_E_WRONG_TYPE, field, "'%s' of a %s fault must be \"nan\" or \"stuck\"",
                              K->choice, K->name);
                return -1;
            }
            if (!strcmp(json_string_value(x), "nan"))
                v[1] = 0;
            else if (!strcmp(json_string_value(x), "stuck"))
                v[1] = 1;
            else {
                vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, field, "%s = '%.32s' is not one of nan|stuck", field,
                              json_string_value(x));
                return -1;
            }
        }
    }
    *p0 = v[0];
    *p1 = v[1];
    return 0;
}

/* Is key a parameter of kind k? */
static int s_is_param(int k, const char *key)
{
    const s_kind *K = &s_kinds[k];
    for (int i = 0; i < 2; i++)
        if (K->par[i].key && !strcmp(K->par[i].key, key))
            return 1;
    return K->choice && !strcmp(K->choice, key);
}

/* The command name of a command fault's "cmd" (a known command, or absent: any). */
static int s_cmd_name(json_t *o, const char *where, char out[16], vafmd_err *e)
{
    out[0] = 0;
    json_t *x = json_object_get(o, "cmd");
    if (!x)
        return 0;
    char field[64];
    snprintf(field, sizeof field, "%s.cmd", where);
    if (!json_is_string(x)) {
        vafmd_err_set(e, VAFMD_E_WRONG_TYPE, field, "'cmd' must be a command name (string)");
        return -1;
    }
    const char *s = json_string_value(x);
    /* every command flagged faultable in commands.def, that is all but `faults`, which is never faulted
     * (so a plan can always be cleared): 0.6.1 took `faults` (an entry that never fires) and refused `map`
     * (after it in the table) */
    for (int i = 0; i < VAFMD_CMD_N; i++) {
        if (strcmp(s, vafmd_cmd_name(i)))
            continue;
        if (!(vafmd_cmd_flags(i) & VAFMD_CF_FAULTABLE)) {
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, field, "%s = '%s': the %s command is never faulted", field, s, s);
            return -1;
        }
        snprintf(out, 16, "%s", s);
        return 0;
    }
    vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, field, "%s = '%.32s' names no command", field, s);
    return -1;
}

/* "kind": a known, implemented kind. */
static int s_kind_of(json_t *o, const char *where, vafmd_err *e)
{
    char field[64];
    snprintf(field, sizeof field, "%s.kind", where);
    json_t *x = json_object_get(o, "kind");
    if (!x) {
        vafmd_err_set(e, VAFMD_E_MISSING_FIELD, field, "a fault needs \"kind\" (one of %s)", s_kind_list());
        return -1;
    }
    if (!json_is_string(x)) {
        vafmd_err_set(e, VAFMD_E_WRONG_TYPE, field, "\"kind\" must be a string (one of %s)", s_kind_list());
        return -1;
    }
    int k = s_kind_find(json_string_value(x));
    if (k < 0) {
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, field, "%s = '%.32s' is not one of %s", field, json_string_value(x),
                      s_kind_list());
        return -1;
    }
    if (!s_kinds[k].implemented) {
        vafmd_err_set(e, VAFMD_E_NOT_IMPLEMENTED, field, "fault kind '%s' is not implemented in this daemon",
                      s_kinds[k].name);
        return -1;
    }
    return k;
}

static int s_u64(json_t *x, const char *field, uint64_t min, uint64_t *out, vafmd_err *e)
{
    if (!json_is_integer(x)) {
        vafmd_err_set(e, VAFMD_E_WRONG_TYPE, field, "'%s' must be an integer >= %" PRIu64, field, min);
        return -1;
    }
    if (json_integer_value(x) < (json_int_t)min) {
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, field, "%s = %" JSON_INTEGER_FORMAT " is below %" PRIu64, field,
                      json_integer_value(x), min);
        return -1;
    }
    *out = (uint64_t)json_integer_value(x);
    return 0;
}

static int s_entry(json_t *o, size_t i, vafmd_fault_entry *en, vafmd_err *e)
{
    char where[32];
    snprintf(where, sizeof where, "script[%zu]", i);
    if (!json_is_object(o)) {
        vafmd_err_set(e, VAFMD_E_WRONG_TYPE, where, "%s must be an object {\"kind\": K, ...}", where);
        return -1;
    }
    int k = s_kind_of(o, where, e);
    if (k < 0)
        return -1;
    memset(en, 0, sizeof *en);
    en->kind = k;
    en->block = 0;
    const char *key;
    json_t *v;
    int stream = s_kinds[k].where == VAFMD_FW_STREAM;
    json_object_foreach(o, key, v) {
        int ok = !strcmp(key, "kind") || s_is_param(k, key) ||
                 (stream ? !strcmp(key, "run") || !strcmp(key, "block") || !strcmp(key, "time_s")
                         : !strcmp(key, "cmd") || !strcmp(key, "nth"));
        if (!ok) {
            char field[80];
            snprintf(field, sizeof field, "%s.%.40s", where, key);
            vafmd_err_set(e, VAFMD_E_UNKNOWN_FIELD, field, "a %s fault does not take '%.40s' (it takes %s%s%s%s)",
                          s_kinds[k].name, key, stream ? "run, block or time_s" : "cmd, nth",
                          s_kinds[k].par[0].key ? ", " : "", s_kinds[k].par[0].key ? s_kinds[k].par[0].key : "",
                          s_kinds[k].par[1].key ? ", ..." : s_kinds[k].choice ? ", value" : "");
            return -1;
        }
    }
    char field[64];
    if (stream) {
        json_t *run = json_object_get(o, "run"), *blk = json_object_get(o, "block"), *t = json_object_get(o, "time_s");
        if (run) {
            snprintf(field, sizeof field, "%s.run", where);
            if (s_u64(run, field, 1, &en->run, e))
                return -1;
        }
        if (blk && t) {
            snprintf(field, sizeof field, "%s.time_s", where);
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, field, "give \"block\" or \"time_s\", not both");
            return -1;
        }
        if (blk) {
            uint64_t b;
            snprintf(field, sizeof field, "%s.block", where);
            if (s_u64(blk, field, 0, &b, e))
                return -1;
            if (b > (uint64_t)1 << 40) {
                vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, field, "%s = %" PRIu64 " is outside [0, 2^40]", field, b);
                return -1;
            }
            en->block = (int64_t)b;
        }
        if (t) {
            snprintf(field, sizeof field, "%s.time_s", where);
            if (!json_is_number(t)) {
                vafmd_err_set(e, VAFMD_E_WRONG_TYPE, field, "'time_s' must be a number (s of run time)");
                return -1;
            }
            double d = json_number_value(t);
            if (!(d >= 0 && d <= 1e6)) {
                vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, field, "%s = %.17g is outside [0, 1e6] s", field, d);
                return -1;
            }
            en->block = -1;
            en->time_s = d;
        }
    } else {
        if (s_cmd_name(o, where, en->cmd, e))
            return -1;
        en->nth = 1;
        json_t *n = json_object_get(o, "nth");
        snprintf(field, sizeof field, "%s.nth", where);
        if (n && s_u64(n, field, 1, &en->nth, e))
            return -1;
    }
    return s_params(k, o, where, &en->p0, &en->p1, e);
}

static int s_random(const char *name, json_t *o, vafmd_fault_plan *p, vafmd_err *e)
{
    char where[48];
    snprintf(where, sizeof where, "random.%.32s", name);
    int k = s_kind_find(name);
    if (k < 0) {
        vafmd_err_set(e, VAFMD_E_UNKNOWN_FIELD, where, "'%.32s' is not a fault kind (one of %s)", name, s_kind_list());
        return -1;
    }
    if (!s_kinds[k].implemented) {
        vafmd_err_set(e, VAFMD_E_NOT_IMPLEMENTED, where, "fault kind '%s' is not implemented in this daemon", name);
        return -1;
    }
    if (!json_is_object(o)) {
        vafmd_err_set(e, VAFMD_E_WRONG_TYPE, where, "%s must be an object {\"per_block\"|\"per_run\"|\"per_command\": "
                      "rate, parameters...}", where);
        return -1;
    }
    vafmd_fault_random *r = &p->rnd[k];
    memset(r, 0, sizeof *r);
    int stream = s_kinds[k].where == VAFMD_FW_STREAM, n_rates = 0;
    const char *key;
    json_t *v;
    json_object_foreach(o, key, v) {
        char field[96];
        snprintf(field, sizeof field, "%s.%.40s", where, key);
        int per = !strcmp(key, "per_block") ? VAFMD_FPER_BLOCK : !strcmp(key, "per_run") ? VAFMD_FPER_RUN
                  : !strcmp(key, "per_command") ? VAFMD_FPER_COMMAND : 0;
        if (per) {
            if ((per == VAFMD_FPER_COMMAND) == stream) {
                vafmd_err_set(e, VAFMD_E_UNKNOWN_FIELD, field, "a %s fault takes a rate %s", name,
                              stream ? "per_block or per_run" : "per_command");
                return -1;
            }
            if (!json_is_number(v)) {
                vafmd_err_set(e, VAFMD_E_WRONG_TYPE, field, "'%s' must be a probability (number in [0, 1])", key);
                return -1;
            }
            double x = json_number_value(v);
            if (!(x >= 0 && x <= 1)) {
                vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, field, "%s = %.17g is outside [0, 1]", field, x);
                return -1;
            }
            r->rate = x;
            r->per = per;
            n_rates++;
        } else if (!(s_is_param(k, key) || (!stream && !strcmp(key, "cmd")))) {
            vafmd_err_set(e, VAFMD_E_UNKNOWN_FIELD, field, "a random %s fault does not take '%.40s'", name, key);
            return -1;
        }
    }
    if (n_rates != 1) {
        vafmd_err_set(e, n_rates ? VAFMD_E_OUT_OF_RANGE : VAFMD_E_MISSING_FIELD, where,
                      "%s needs exactly one rate: %s", where, stream ? "per_block or per_run" : "per_command");
        return -1;
    }
    if (!stream && s_cmd_name(o, where, r->cmd, e))
        return -1;
    return s_params(k, o, where, &r->p0, &r->p1, e);
}

int vafmd_faults_decode(json_t *plan, vafmd_fault_plan *p, vafmd_err *e)
{
    memset(p, 0, sizeof *p);
    if (!json_is_object(plan)) {
        vafmd_err_set(e, VAFMD_E_WRONG_TYPE, "plan", "a fault plan is an object {\"seed\": S, \"script\": [...], "
                      "\"random\": {...}}");
        return -1;
    }
    const char *key;
    json_t *v;
    json_object_foreach(plan, key, v) {
        if (strcmp(key, "seed") && strcmp(key, "script") && strcmp(key, "random")) {
            vafmd_err_set(e, VAFMD_E_UNKNOWN_FIELD, key, "a fault plan does not take '%.40s' (seed, script, random)", key);
            return -1;
        }
    }
    if ((v = json_object_get(plan, "seed")) != NULL) {
        if (json_is_integer(v) && json_integer_value(v) >= 0)
            p->seed = (uint64_t)json_integer_value(v);
        else if (json_is_string(v) && json_string_length(v) >= 1 && json_string_length(v) <= 20 &&
                 strspn(json_string_value(v), "0123456789") == json_string_length(v)) {
            char *end;
            errno = 0;
            unsigned long long s = strtoull(json_string_value(v), &end, 10);
            if (errno) {
                vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "seed", "seed '%s' is beyond 2^64-1", json_string_value(v));
                return -1;
            }
            p->seed = s;
        } else {
            vafmd_err_set(e, json_is_integer(v) ? VAFMD_E_OUT_OF_RANGE : VAFMD_E_WRONG_TYPE, "seed",
                          "\"seed\" must be a non-negative integer or a string of digits (any uint64)");
            return -1;
        }
    }
    if ((v = json_object_get(plan, "script")) != NULL) {
        if (!json_is_array(v)) {
            vafmd_err_set(e, VAFMD_E_WRONG_TYPE, "script", "\"script\" must be an array of fault entries");
            return -1;
        }
        if (json_array_size(v) > VAFMD_FAULT_SCRIPT_MAX) {
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "script", "\"script\" has %zu entries, at most %d",
                          json_array_size(v), VAFMD_FAULT_SCRIPT_MAX);
            return -1;
        }
        size_t i;
        json_t *x;
        json_array_foreach(v, i, x) {
            if (s_entry(x, i, &p->script[i], e))
                return -1;
            if (s_kinds[p->script[i].kind].where == VAFMD_FW_STREAM)
                p->any_stream = 1;
            else
                p->any_command = 1;
        }
        p->n_script = json_array_size(v);
    }
    if ((v = json_object_get(plan, "random")) != NULL) {
        if (!json_is_object(v)) {
            vafmd_err_set(e, VAFMD_E_WRONG_TYPE, "random", "\"random\" must be an object {kind: {rate, parameters}}");
            return -1;
        }
        json_t *x;
        json_object_foreach(v, key, x) {
            if (s_random(key, x, p, e))
                return -1;
            int k = s_kind_find(key);
            if (p->rnd[k].rate > 0) {
                if (s_kinds[k].where == VAFMD_FW_STREAM)
                    p->any_stream = 1;
                else
                    p->any_command = 1;
            }
        }
    }
    return 0;
}

static json_t *s_num(double v)
{
    return isfinite(v) ? json_real(v) : json_null();
}

json_t *vafmd_fault_rec_json(const vafmd_fault_rec *r)
{
    json_t *o = json_object();
    json_object_set_new(o, "n", json_integer((json_int_t)r->n));
    json_object_set_new(o, "kind", json_string(vafmd_fault_name(r->kind)));
    json_object_set_new(o, "time_s", s_num(r->time_s));
    json_object_set_new(o, "run_id", r->run_id ? json_integer((json_int_t)r->run_id) : json_null());
    json_object_set_new(o, "block", r->block >= 0 ? json_integer(r->block) : json_null());
    json_object_set_new(o, "run_time_s", s_num(r->run_time_s));
    json_object_set_new(o, "seq", r->seq >= 0 ? json_integer(r->seq) : json_null());
    json_object_set_new(o, "session", json_integer(r->session));
    json_object_set_new(o, "source", json_string(r->scripted ? "script" : "random"));
    json_t *par = json_object();
    const s_kind *K = &s_kinds[r->kind >= 0 && r->kind < VAFMD_F_N ? r->kind : 0];
    for (int i = 0; i < 2; i++)
        if (K->par[i].key)
            json_object_set_new(par, K->par[i].key, K->par[i].integer ? json_integer((json_int_t)(i ? r->p1 : r->p0))
                                                                      : s_num(i ? r->p1 : r->p0));
    if (K->choice)
        json_object_set_new(par, K->choice, json_string(r->p1 ? "stuck" : "nan"));
    if (r->kind == VAFMD_F_JITTER) /* the delay drawn */
        json_object_set_new(par, "delay_s", s_num(r->p1));
    json_object_set_new(o, "params", par);
    json_object_set_new(o, "cmd", r->cmd[0] ? json_string(r->cmd) : json_null());
    return o;
}
