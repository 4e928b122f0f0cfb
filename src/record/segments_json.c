/* SPDX-License-Identifier: MIT */
/*
 * Segment lists as JSON (vafm/segments.h; the layout in docs/instrument.md, "Segments"): parsed with jansson
 * here, outside the core, which takes the struct. Either {"segments": [...]} or a bare array; each segment
 * an object with "kind" and the fields of vafm_segment_spec by name; a trigger as
 * {"channel": "force"|"deflection_V"|"height"|"time", "op": ">"|"<", "value": x, "relative": bool}; the
 * enumerations by name ("extend", "pause", "force", "detach", ...). Unknown keys are refused, naming them.
 */
#include <float.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <jansson.h>

#include "record/json_num.h"
#include "record/record.h"
#include "vafm/segments.h"

static int s_err(vafm_error *err, const char *field, const char *fmt, const char *a, const char *b)
{
    if (err) {
        err->code = VAFM_EINVAL;
        size_t l = strlen(field);
        if (l >= sizeof err->field)
            l = sizeof err->field - 1; /* a long unknown key: its name is cut here, whole in the message */
        memcpy(err->field, field, l);
        err->field[l] = '\0';
        snprintf(err->message, sizeof err->message, fmt, a, b);
    }
    return VAFM_EINVAL;
}

/* index of name in the '|'-separated list, or -1 */
static int s_choice(const char *list, const char *name)
{
    int i = 0;
    size_t n = strlen(name);
    for (const char *p = list; *p; i++) {
        const char *e = strchr(p, '|');
        size_t len = e ? (size_t)(e - p) : strlen(p);
        if (len == n && !strncmp(p, name, n))
            return i;
        if (!e)
            break;
        p = e + 1;
    }
    return -1;
}

static int s_enum(const json_t *v, const char *list, const char *field, int *out, vafm_error *err)
{
    int c = json_is_string(v) ? s_choice(list, json_string_value(v)) : -1;
    if (c < 0)
        return s_err(err, field, "%s: want one of %s", field, list);
    *out = c;
    return 0;
}

static int s_real(const json_t *v, const char *field, double *out, vafm_error *err)
{
    if (json_is_null(v)) { /* hold_force_N: null is "the trigger level or the force at the start" */
        *out = NAN;
        return 0;
    }
    if (!json_is_number(v))
        return s_err(err, field, "%s: want a number in SI units%s", field, "");
    *out = json_number_value(v);
    return 0;
}

static int s_trigger(const json_t *t, vafm_segment_spec *g, const char *pre, vafm_error *err)
{
    char f[96];
    if (!json_is_object(t)) {
        snprintf(f, sizeof f, "%s.trigger", pre);
        return s_err(err, f, "%s: want an object {\"channel\", \"op\", \"value\", \"relative\"}%s", f, "");
    }
    const char *key;
    json_t *v;
    json_object_foreach((json_t *)t, key, v) {
        snprintf(f, sizeof f, "%s.trigger.%s", pre, key);
        int rc = 0;
        if (!strcmp(key, "channel"))
            rc = s_enum(v, "none|force|deflection_V|height|time", f, &g->trigger, err);
        else if (!strcmp(key, "op"))
            rc = s_enum(v, ">|<", f, &g->trigger_op, err);
        else if (!strcmp(key, "value"))
            rc = s_real(v, f, &g->trigger_value, err);
        else if (!strcmp(key, "relative")) {
            if (!json_is_boolean(v))
                return s_err(err, f, "%s: want true or false%s", f, "");
            g->trigger_relative = json_is_true(v);
        } else
            return s_err(err, f, "%s: unknown key (known: channel, op, value, relative)%s", f, "");
        if (rc)
            return rc;
    }
    return 0;
}

/* A nonzero number that underflows (record/json_num.h): jansson reads "1e-400" as 0 without a word, and 0
 * means something else here (an extend's distance_m 0 is the approach limit, a pause of 0 s is skipped). */
static int s_underflow(const char *text, vafm_error *err)
{
    char key[48], lit[48], f[64], msg[200];
    size_t line;
    double x;
    if (!vafm_rec_json_underflow(text, strlen(text), 0, key, sizeof key, lit, sizeof lit, &line, &x))
        return 0;
    snprintf(f, sizeof f, "segments%s%s", key[0] ? "." : "", key);
    snprintf(msg, sizeof msg, "line %zu: the number %s underflows: a nonzero value must be at least %.17g in magnitude "
             "(it would read as %g)", line, lit, DBL_MIN, x);
    return s_err(err, f, "%s: %s", f, msg);
}

/* The keys of a segment object, in the order the "unknown key" message lists them: a number (null allowed:
 * s_real), a name of a '|'-separated list (s_enum), the trigger object, or the label (an integer). */
enum { S_REAL, S_ENUM, S_TRIGGER, S_LABEL };
typedef struct s_key {
    const char *name;
    int kind;
    size_t offset;       /* of the double (S_REAL) or int (S_ENUM) in vafm_segment_spec */
    const char *choices; /* S_ENUM */
} s_key;
#define S_AT(field) offsetof(vafm_segment_spec, field)
static const s_key s_keys[] = {
    { "kind", S_ENUM, S_AT(kind), "extend|retract|pause|modulate" },
    { "speed_m_per_s", S_REAL, S_AT(speed_m_per_s), NULL },
    { "distance_m", S_REAL, S_AT(distance_m), NULL },
    { "trigger", S_TRIGGER, 0, NULL },
    { "end", S_ENUM, S_AT(end), "travel|detach|start" },
    { "duration_s", S_REAL, S_AT(duration_s), NULL },
    { "mode", S_ENUM, S_AT(pause_mode), "height|force" },
    { "hold_force_N", S_REAL, S_AT(hold_force_N), NULL },
    { "feedback_s", S_REAL, S_AT(feedback_s), NULL },
    { "amplitude_m", S_REAL, S_AT(amplitude_m), NULL },
    { "frequency_Hz", S_REAL, S_AT(frequency_Hz), NULL },
    { "sample_rate_Hz", S_REAL, S_AT(sample_rate_Hz), NULL },
    { "label", S_LABEL, S_AT(label), NULL },
};
#define S_NKEYS (sizeof s_keys / sizeof s_keys[0])

int vafm_segments_from_json(const char *text, vafm_segment_spec *out, size_t cap, size_t *n, vafm_error *err)
{
    if (err)
        memset(err, 0, sizeof *err);
    if (!text || !out || !n)
        return s_err(err, "segments", "no text or no output given%s%s", "", "");
    *n = 0;
    json_error_t je;
    json_t *root = json_loads(text, JSON_REJECT_DUPLICATES, &je);
    if (!root) {
        char where[64];
        snprintf(where, sizeof where, "line %d column %d", je.line, je.column);
        return s_err(err, "segments", "not JSON (%s): %s", where, je.text);
    }
    if (s_underflow(text, err)) {
        json_decref(root);
        return VAFM_EINVAL;
    }
    json_t *arr = json_is_object(root) ? json_object_get(root, "segments") : root;
    int rc = 0;
    if (json_is_object(root) && json_object_size(root) != 1)
        rc = s_err(err, "segments", "a segment file is {\"segments\": [...]} and nothing else%s%s", "", "");
    else if (!json_is_array(arr) || json_array_size(arr) < 1 || json_array_size(arr) > cap ||
             json_array_size(arr) > VAFM_SEGMENTS_MAX) {
        char lim[32];
        snprintf(lim, sizeof lim, "%d", VAFM_SEGMENTS_MAX);
        rc = s_err(err, "segments", "want an array of 1 to %s segments%s", lim, "");
    }
    for (size_t i = 0; !rc && i < json_array_size(arr); i++) {
        vafm_segment_spec *g = &out[i];
        vafm_segment_spec_default(g);
        json_t *o = json_array_get(arr, i);
        char pre[48], f[96];
        snprintf(pre, sizeof pre, "segments[%zu]", i);
        if (!json_is_object(o)) {
            rc = s_err(err, pre, "%s: want an object with \"kind\"%s", pre, "");
            break;
        }
        const char *key;
        json_t *v;
        json_object_foreach(o, key, v) {
            snprintf(f, sizeof f, "%s.%s", pre, key);
            const s_key *k = s_keys;
            while (k < s_keys + S_NKEYS && strcmp(key, k->name))
                k++;
            if (k == s_keys + S_NKEYS) {
                char known[256] = "";
                for (k = s_keys; k < s_keys + S_NKEYS; k++)
                    snprintf(known + strlen(known), sizeof known - strlen(known), "%s%s", k == s_keys ? "" : ", ",
                             k->name);
                rc = s_err(err, f, "%s: unknown key (known: %s)", f, known);
            } else if (k->kind == S_REAL)
                rc = s_real(v, f, (double *)((char *)g + k->offset), err);
            else if (k->kind == S_ENUM)
                rc = s_enum(v, k->choices, f, (int *)((char *)g + k->offset), err);
            else if (k->kind == S_TRIGGER)
                rc = s_trigger(v, g, pre, err);
            else if (!json_is_integer(v) || json_integer_value(v) < -1 || json_integer_value(v) > 254)
                rc = s_err(err, f, "%s: want an integer from -1 to 254%s", f, ""); /* label */
            else
                g->label = (int)json_integer_value(v);
            if (rc)
                break;
        }
        if (!rc && !json_object_get(o, "kind"))
            rc = s_err(err, pre, "%s: \"kind\" is required (extend, retract, pause, modulate)%s", pre, "");
        if (!rc)
            *n = i + 1;
    }
    json_decref(root);
    if (rc)
        *n = 0;
    return rc;
}

int vafm_segments_load_file(const char *path, vafm_segment_spec *out, size_t cap, size_t *n, vafm_error *err)
{
    enum { S_MAX_BYTES = 1 << 20 }; /* 64 segments take a few kB */
    if (err)
        memset(err, 0, sizeof *err);
    FILE *f = path ? fopen(path, "rb") : NULL;
    if (!f)
        return s_err(err, "segments", "%s: cannot open the segment file%s", path ? path : "(null)", "");
    char *buf = malloc(S_MAX_BYTES + 1);
    size_t len = buf ? fread(buf, 1, S_MAX_BYTES + 1, f) : 0;
    const int bad = ferror(f);
    fclose(f);
    if (!buf)
        return VAFM_ENOMEM;
    int rc;
    if (bad)
        rc = s_err(err, "segments", "%s: cannot read the segment file%s", path, "");
    else if (len > S_MAX_BYTES)
        rc = s_err(err, "segments", "%s: the segment file exceeds 1 MiB%s", path, "");
    else {
        buf[len] = '\0';
        rc = vafm_segments_from_json(buf, out, cap, n, err);
        if (rc && err) { /* prefix the file's name (cut to fit) */
            char msg[sizeof err->message];
            size_t lp = strlen(path), lm = strlen(err->message);
            if (lp > sizeof msg / 4)
                lp = sizeof msg / 4;
            if (lp + 2 + lm >= sizeof msg)
                lm = sizeof msg - lp - 3;
            memcpy(msg, path, lp);
            memcpy(msg + lp, ": ", 2);
            memcpy(msg + lp + 2, err->message, lm);
            msg[lp + 2 + lm] = '\0';
            memcpy(err->message, msg, sizeof msg);
        }
    }
    free(buf);
    return rc;
}

static json_t *s_real_json(double v)
{
    return isnan(v) ? json_null() : json_real(v);
}

char *vafm_segments_to_json(const vafm_segment_spec *segs, size_t n)
{
    static const char *const kinds[] = { "extend", "retract", "pause", "modulate" };
    static const char *const chans[] = { "none", "force", "deflection_V", "height", "time" };
    static const char *const ops[] = { ">", "<" };
    static const char *const ends[] = { "travel", "detach", "start" };
    static const char *const modes[] = { "height", "force" };
    if (!segs || n < 1 || n > VAFM_SEGMENTS_MAX)
        return NULL;
    json_t *root = json_object(), *arr = json_array();
    int bad = !root || !arr || json_object_set_new(root, "segments", arr);
    for (size_t i = 0; !bad && i < n; i++) {
        const vafm_segment_spec *g = &segs[i];
        const double reals[] = { g->speed_m_per_s, g->distance_m, g->trigger_value, g->duration_s, g->feedback_s,
                                 g->amplitude_m, g->frequency_Hz, g->sample_rate_Hz };
        for (size_t k = 0; k < sizeof reals / sizeof reals[0]; k++)
            bad |= !isfinite(reals[k]);
        bad |= !(isnan(g->hold_force_N) || isfinite(g->hold_force_N));
        bad |= g->kind < 0 || g->kind > 3 || g->trigger < 0 || g->trigger > 4 || g->trigger_op < 0 ||
               g->trigger_op > 1 || g->end < 0 || g->end > 2 || g->pause_mode < 0 || g->pause_mode > 1 ||
               g->label < -1 || g->label > 254;
        if (bad)
            break;
        json_t *t = json_pack("{s:s, s:s, s:f, s:b}", "channel", chans[g->trigger], "op", ops[g->trigger_op], "value",
                              g->trigger_value, "relative", g->trigger_relative != 0);
        json_t *o = t ? json_pack("{s:s, s:f, s:f, s:o, s:s, s:f, s:s, s:o, s:f, s:f, s:f, s:f, s:i}", "kind",
                                  kinds[g->kind], "speed_m_per_s", g->speed_m_per_s, "distance_m", g->distance_m,
                                  "trigger", t, "end", ends[g->end], "duration_s", g->duration_s, "mode",
                                  modes[g->pause_mode], "hold_force_N", s_real_json(g->hold_force_N), "feedback_s",
                                  g->feedback_s, "amplitude_m", g->amplitude_m, "frequency_Hz", g->frequency_Hz,
                                  "sample_rate_Hz", g->sample_rate_Hz, "label", g->label)
                      : NULL;
        bad = !o || json_array_append_new(arr, o);
    }
    char *text = bad ? NULL : json_dumps(root, JSON_PRESERVE_ORDER | JSON_REAL_PRECISION(17));
    json_decref(root);
    return text;
}
