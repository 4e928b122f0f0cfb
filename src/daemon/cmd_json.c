/* SPDX-License-Identifier: MIT */
/*
 * The command decoder. Every request is checked completely (types, names, ranges) before anything is
 * executed, so the control loop only ever runs well-formed commands and a bad request changes nothing.
 */
#include "daemon/cmd_json.h"
#include "record/scene_value.h"
#include "record/scene.h"
#include "record/record.h"
#include "record/json_num.h"
#include "vafm/segments.h"
#include <inttypes.h>
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void vafmd_settings_default(vafmd_settings *s)
{
    s->speed = 1.0;
    s->free_run = 0;
    s->block_s = 5e-3;
    s->hwm = 1000;
    s->lookahead_s = 1.0;
    s->kernel = VAFMD_KERNEL_SCALAR;
}

void vafmd_err_set(vafmd_err *e, const char *code, const char *field, const char *fmt, ...)
{
    e->code = code;
    snprintf(e->field, sizeof e->field, "%s", field ? field : "");
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(e->message, sizeof e->message, fmt, ap);
    va_end(ap);
}

/* ---- daemon settings: a small field table of their own, next to the core's ---------------------- */

enum { S_SET_REAL, S_SET_BOOL, S_SET_INT, S_SET_CHOICE };
typedef struct s_setting {
    const char *name;
    int kind;
    const char *unit;
    double min, max;
    int read_only; /* fixed once the sockets are bound */
    const char *doc;
} s_setting;

static const s_setting s_settings[] = {
    { "speed", S_SET_REAL, "", 0.01, 1000, 0, "pacing speed factor (1: real time; applies from the next run)" },
    { "free_run", S_SET_BOOL, "", 0, 1, 0, "true: no pacing, blocks are released as fast as computed" },
    { "block_s", S_SET_REAL, "s", 1e-3, 1e-2, 0, "duration of the samples of one data block" },
    { "hwm", S_SET_INT, "messages", 1, 1e7, 1, "stream send high-water mark per subscriber (--hwm; read-only; at most 256 MiB queued per subscriber)" },
    { "kernel", S_SET_CHOICE, "", 0, 0, 0,
      "scalar|batch: how a campaign's curves are computed; batch (free run, not a map): ahead, several at once in "
      "SIMD lanes, the same curves bit for bit" },
    { "lookahead_s", S_SET_REAL, "s", 0, 10, 0,
      "compute ahead: seconds of samples computed before their release (0: none); at most 256 MiB per run" },
    { "segment_channel", S_SET_BOOL, "", 0, 1, 0,
      "true: runs from the next on stream the channel segment (each sample's segment, 0 approach, 1 retract, ...)" },
};
#define S_N_SETTINGS (sizeof s_settings / sizeof s_settings[0])

static const s_setting *s_setting_find(const char *name)
{
    for (size_t i = 0; i < S_N_SETTINGS; i++)
        if (!strcmp(s_settings[i].name, name))
            return &s_settings[i];
    return NULL;
}

static json_t *s_setting_value(const vafmd_settings *s, const s_setting *f)
{
    if (!strcmp(f->name, "speed"))
        return json_real(s->speed);
    if (!strcmp(f->name, "free_run"))
        return json_boolean(s->free_run);
    if (!strcmp(f->name, "segment_channel"))
        return json_boolean(s->segment_channel);
    if (!strcmp(f->name, "block_s"))
        return json_real(s->block_s);
    if (!strcmp(f->name, "lookahead_s"))
        return json_real(s->lookahead_s);
    if (!strcmp(f->name, "kernel"))
        return json_string(s->kernel == VAFMD_KERNEL_BATCH ? "batch" : "scalar");
    return json_integer(s->hwm);
}

static int s_setting_apply(vafmd_settings *s, const s_setting *f, json_t *v, vafmd_err *e)
{
    if (f->read_only) {
        vafmd_err_set(e, VAFMD_E_READ_ONLY, f->name, "'%s' is fixed at start-up (command-line option)", f->name);
        return -1;
    }
    if (f->kind == S_SET_CHOICE) { /* kernel */
        const char *t = json_is_string(v) ? json_string_value(v) : NULL;
        vafm_campaign_spec k = { 0 }; /* the kernel names' table (core/backend.h): the daemon takes two of them */
        if (!t || vafm_campaign_kernel_parse(t, &k) || k.kernel == VAFM_CAMPAIGN_KERNEL_AUTO || k.batch_width) {
            vafmd_err_set(e, t ? VAFMD_E_OUT_OF_RANGE : VAFMD_E_WRONG_TYPE, f->name,
                          "'%s' must be \"scalar\" or \"batch\"", f->name);
            return -1;
        }
        s->kernel = strcmp(t, "batch") ? VAFMD_KERNEL_SCALAR : VAFMD_KERNEL_BATCH;
        return 0;
    }
    if (f->kind == S_SET_BOOL) {
        if (!json_is_boolean(v)) {
            vafmd_err_set(e, VAFMD_E_WRONG_TYPE, f->name, "'%s' must be true or false", f->name);
            return -1;
        }
        if (!strcmp(f->name, "segment_channel"))
            s->segment_channel = json_is_true(v);
        else
            s->free_run = json_is_true(v);
        return 0;
    }
    if (!json_is_number(v)) {
        vafmd_err_set(e, VAFMD_E_WRONG_TYPE, f->name, "'%s' must be a number (%s)", f->name, f->unit);
        return -1;
    }
    if (f->kind == S_SET_INT && !json_is_integer(v)) {
        vafmd_err_set(e, VAFMD_E_WRONG_TYPE, f->name, "'%s' must be an integer (%s)", f->name, f->unit);
        return -1;
    }
    double x = json_number_value(v);
    if (!(x >= f->min && x <= f->max)) {
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, f->name, "%s = %.17g is outside [%g, %g] %s", f->name, x, f->min,
                      f->max, f->unit);
        return -1;
    }
    if (!strcmp(f->name, "speed"))
        s->speed = x;
    else if (!strcmp(f->name, "block_s"))
        s->block_s = x;
    else if (!strcmp(f->name, "lookahead_s"))
        s->lookahead_s = x;
    return 0;
}

/* ---- scene parameters through the core's field table ------------------------------------------ */

json_t *vafmd_param_value(const vafm_params *p, const vafm_param_info *f)
{
    char buf[128];
    if (vafm_params_get(p, f->name, buf, sizeof buf))
        return json_null();
    switch (f->kind) {
    case VAFM_PARAM_REAL: return json_real(strtod(buf, NULL));
    case VAFM_PARAM_INT: return json_integer((json_int_t)strtol(buf, NULL, 10));
    case VAFM_PARAM_BOOL: return json_boolean(!strcmp(buf, "true"));
    default: return json_string(buf); /* CHOICE names; SEED as decimal text (JSON numbers lose 2^64) */
    }
}

/* Apply one scene value: the JSON type must fit the field's kind, by the rules every vafm program
 * shares (src/record/scene_value.h); then the core judges the value. */
static int s_param_apply(vafm_params *p, const vafm_param_info *f, json_t *v, vafmd_err *e)
{
    char text[64], allowed[160];
    vafm_scene_json_allowed(f, allowed, sizeof allowed);
    if (f->kind == VAFM_PARAM_SEED && json_is_integer(v) && json_integer_value(v) < 0) {
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, f->name, "'%s' = %" JSON_INTEGER_FORMAT " is negative: expected %s",
                      f->name, json_integer_value(v), allowed);
        return -1;
    }
    if (!vafm_scene_value_text(f, v, text, sizeof text)) {
        vafmd_err_set(e, VAFMD_E_WRONG_TYPE, f->name, "'%s' has the wrong type: expected %s", f->name, allowed);
        return -1;
    }
    vafm_error verr = { 0 };
    int rc = vafm_params_set(p, f->name, text, &verr);
    if (rc) {
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, f->name, "%s (allowed: %s)",
                      verr.message[0] ? verr.message : "invalid value", allowed);
        return -1;
    }
    return 0;
}

/* ---- decoding ------------------------------------------------------------------------------------ */

/* The map spec's fields that say where and how finely to scan and how each curve starts, not what the sample
 * is: a `map` that gives only these maps the controller's sample (ctrl_sample), if one is set. */
#define S_GRID_FIELD(f) { #f, offsetof(vafm_map_spec, f), sizeof(((vafm_map_spec *)0)->f) }
static const struct {
    const char *name;
    size_t offset, size;
} s_map_grid_keys[] = { S_GRID_FIELD(nx), S_GRID_FIELD(ny), S_GRID_FIELD(size_x_m), S_GRID_FIELD(size_y_m),
                        S_GRID_FIELD(center_x_m), S_GRID_FIELD(center_y_m), S_GRID_FIELD(start) };
#undef S_GRID_FIELD
#define S_MAP_GRID_KEYS (sizeof s_map_grid_keys / sizeof s_map_grid_keys[0])

void vafmd_map_grid_merge(vafm_map_spec *dst, const vafm_map_spec *req, unsigned given)
{
    for (unsigned i = 0; i < S_MAP_GRID_KEYS; i++)
        if (given & 1u << i)
            memcpy((char *)dst + s_map_grid_keys[i].offset, (const char *)req + s_map_grid_keys[i].offset,
                   s_map_grid_keys[i].size);
}

/* `map`: the spec's fields by vafm_map_set's names (numbers for numbers, strings for the pattern, the start
 * mode and the materials' contact models), first_index below the pixel count, the lateral speed. */
static int s_decode_map(json_t *root, vafmd_cmd *c, vafmd_err *e)
{
    json_t *m = json_object_get(root, "map"), *v;
    if (!m) {
        vafmd_err_set(e, VAFMD_E_MISSING_FIELD, "map", "'map' needs \"map\": {\"nx\": ..., \"ny\": ..., \"size_x_m\": "
                      "..., \"pattern\": ...} (the fields of vafm map's spec)");
        return -1;
    }
    if (!json_is_object(m)) {
        vafmd_err_set(e, VAFMD_E_WRONG_TYPE, "map", "\"map\" must be an object of the map's fields");
        return -1;
    }
    vafm_map_spec_default(&c->map);
    const char *key;
    json_object_foreach(m, key, v) {
        char text[64];
        if (json_is_string(v))
            snprintf(text, sizeof text, "%s", json_string_value(v));
        else if (json_is_integer(v))
            snprintf(text, sizeof text, "%" JSON_INTEGER_FORMAT, json_integer_value(v));
        else if (json_is_real(v))
            snprintf(text, sizeof text, "%.17g", json_real_value(v));
        else {
            vafmd_err_set(e, VAFMD_E_WRONG_TYPE, key, "map.%.40s must be a number or a string", key);
            return -1;
        }
        vafm_error verr = { 0 };
        int r = vafm_map_set(&c->map, key, text, &verr);
        if (r) {
            vafmd_err_set(e, r == VAFM_ENOTFOUND ? VAFMD_E_UNKNOWN_FIELD : VAFMD_E_OUT_OF_RANGE, key, "map.%s",
                          verr.message);
            return -1;
        }
        unsigned g = 0;
        while (g < S_MAP_GRID_KEYS && strcmp(key, s_map_grid_keys[g].name))
            g++;
        if (g < S_MAP_GRID_KEYS)
            c->map_grid_given |= 1u << g;
        else
            c->map_own_sample = 1;
    }
    /* a map of the grid only may map the controller's sample, whose grid may be larger: its first_index is
     * checked against the grid mapped, by the control thread (control_runs.c) */
    size_t pixels = c->map_own_sample ? vafm_map_pixels(&c->map) : (size_t)VAFM_MAP_MAX_PIXELS;
    c->camp_n = 1;
    if ((v = json_object_get(root, "first_index")) != NULL) {
        if (!json_is_integer(v) || json_integer_value(v) < 0 || (uint64_t)json_integer_value(v) >= pixels) {
            vafmd_err_set(e, json_is_integer(v) ? VAFMD_E_OUT_OF_RANGE : VAFMD_E_WRONG_TYPE, "first_index",
                          "\"first_index\" must be an integer in [0, %zu] (the map's pixels, iy*nx + ix)",
                          pixels ? pixels - 1 : 0);
            return -1;
        }
        c->camp_first = (uint64_t)json_integer_value(v);
    }
    c->map_lateral_speed = 20e-6; /* a typical force-map lateral move */
    if ((v = json_object_get(root, "lateral_speed_m_per_s")) != NULL) {
        double x = json_is_number(v) ? json_number_value(v) : NAN;
        if (!json_is_number(v) || !(x >= 1e-9 && x <= 1e-2)) {
            vafmd_err_set(e, json_is_number(v) ? VAFMD_E_OUT_OF_RANGE : VAFMD_E_WRONG_TYPE, "lateral_speed_m_per_s",
                          "lateral_speed_m_per_s must be a number in [1e-09, 0.01] m/s");
            return -1;
        }
        c->map_lateral_speed = x;
    }
    return 0;
}

/* The command table (commands.def): name, argument keys, flags and help per enum vafmd_cmd_kind. */
typedef struct s_command {
    const char *name;
    const char *keys; /* besides "cmd" and "id", each enclosed in spaces */
    unsigned flags;
    const char *help;
} s_command;

static const s_command s_commands[VAFMD_CMD_N] = {
#define VAFMD_COMMAND(ID, NAME, KEYS, FLAGS, HANDLER, HELP) [VAFMD_CMD_##ID] = { NAME, KEYS, FLAGS, HELP },
#include "daemon/commands.def"
};

static int s_kind_ok(int kind)
{
    return kind >= 0 && kind < VAFMD_CMD_N;
}

const char *vafmd_cmd_name(int kind)
{
    return s_kind_ok(kind) ? s_commands[kind].name : "?";
}

unsigned vafmd_cmd_flags(int kind)
{
    return s_kind_ok(kind) ? s_commands[kind].flags : 0;
}

const char *vafmd_cmd_keys(int kind)
{
    return s_kind_ok(kind) ? s_commands[kind].keys : NULL;
}

const char *vafmd_cmd_help(int kind)
{
    return s_kind_ok(kind) ? s_commands[kind].help : NULL;
}

static int s_key_allowed(int kind, const char *key)
{
    if (!strcmp(key, "cmd") || !strcmp(key, "id"))
        return 1;
    const char *keys = s_commands[kind].keys;
    size_t n = strlen(key);
    if (n == 0 || n > 32 || strchr(key, ' '))
        return 0;
    char pat[40];
    snprintf(pat, sizeof pat, " %s ", key);
    return strstr(keys, pat) != NULL;
}

/* A number of valid JSON text buf that underflows: a nonzero literal that the decoder reads as 0 or a
 * subnormal (|x| < DBL_MIN; jansson takes "1e-400" as 0 without a word, so set setpoint_N=1e-400 set 0).
 * @return 1 with e set (out_of_range, field = the key before it), else 0. */
static int s_underflow(const char *b, size_t len, vafmd_err *e)
{
    char key[64], lit[42];
    size_t line;
    double x;
    if (!vafm_rec_json_underflow(b, len, 1, key, sizeof key, lit, sizeof lit, &line, &x))
        return 0;
    vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, key, "the number %.40s%s%s%s%s underflows: a nonzero value must be at least "
                  "%.17g in magnitude (it would read as %g)", lit, strlen(lit) > 40 ? "..." : "", key[0] ? " of '" : "",
                  key, key[0] ? "'" : "", DBL_MIN, x);
    return 1;
}

int vafmd_cmd_decode(const void *buf, size_t len, vafmd_cmd *c, vafmd_err *e)
{
    memset(c, 0, sizeof *c);
    if (len > VAFMD_MAX_CMD_BYTES) {
        vafmd_err_set(e, VAFMD_E_TOO_LARGE, "", "request of %zu bytes exceeds the limit of %d bytes", len,
                      VAFMD_MAX_CMD_BYTES);
        return -1;
    }
    json_error_t jerr;
    json_t *root = json_loadb(buf, len, JSON_REJECT_DUPLICATES, &jerr);
    if (!root) {
        if (json_error_code(&jerr) == json_error_numeric_overflow) {
            /* valid JSON, a number beyond doubles or 64-bit integers: out of range, not malformed; the
             * field is the key just before it */
            char key[64] = "";
            vafm_rec_json_key_before(buf, jerr.position >= 0 && (size_t)jerr.position < len ? (size_t)jerr.position : len, 1,
                                     key, sizeof key);
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, key, "the number %s%s%sat line %d, column %d is out of range (beyond "
                          "64-bit integers or double precision)", key[0] ? "of '" : "", key, key[0] ? "' " : "",
                          jerr.line, jerr.column);
            return -1;
        }
        vafmd_err_set(e, VAFMD_E_MALFORMED, "", "not valid JSON: %s (line %d, column %d)", jerr.text, jerr.line,
                      jerr.column);
        return -1;
    }
    int rc = vafmd_cmd_decode_json(root, c, e);
    if (rc == 0 && s_underflow(buf, len, e))
        rc = -1; /* after the decoding: c keeps the request, so the error echoes its id */
    json_decref(root);
    return rc;
}

#define S_TYPE(t) (1u << (t)) /* JSON types (JSON_*) as a mask */
#define S_NUMBER (S_TYPE(JSON_INTEGER) | S_TYPE(JSON_REAL))
#define S_BOOLEAN (S_TYPE(JSON_TRUE) | S_TYPE(JSON_FALSE))

/* The optional argument `name` of a request into *v (NULL: absent). A value of a JSON type outside `types`
 * is wrong_type, "\"name\" must be <what>". @return 0, or -1 with e set. */
static int s_opt(json_t *root, const char *name, unsigned types, const char *what, json_t **v, vafmd_err *e)
{
    *v = json_object_get(root, name);
    if (*v && !(types & S_TYPE(json_typeof(*v)))) {
        vafmd_err_set(e, VAFMD_E_WRONG_TYPE, name, "\"%s\" must be %s", name, what);
        return -1;
    }
    return 0;
}

/* Same for a required argument: absent, it is missing_field with the message `missing`. */
static int s_need(json_t *root, const char *name, unsigned types, const char *what, const char *missing, json_t **v,
                  vafmd_err *e)
{
    if (!json_object_get(root, name)) {
        *v = NULL;
        vafmd_err_set(e, VAFMD_E_MISSING_FIELD, name, "%s", missing);
        return -1;
    }
    return s_opt(root, name, types, what, v, e);
}

/* A string argument v (`name`) holds 1 to max characters and no NUL, else out_of_range. @return 0 or -1. */
static int s_text_len(const json_t *v, const char *name, int max, vafmd_err *e)
{
    size_t n = json_string_length(v);
    if (n < 1 || n > (size_t)max || strlen(json_string_value(v)) != n) {
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, name, "\"%s\" must have 1 to %d characters (no NUL)", name, max);
        return -1;
    }
    return 0;
}

/* Same for an argument that counts from 0: an integer >= 0. A negative integer has the right type but not the
 * right value (out_of_range, wire.md §2.2), another type is wrong_type; both "\"name\" must be <what>". */
static int s_opt_from0(json_t *root, const char *name, const char *what, json_t **v, vafmd_err *e)
{
    *v = json_object_get(root, name);
    if (*v && (!json_is_integer(*v) || json_integer_value(*v) < 0)) {
        vafmd_err_set(e, json_is_integer(*v) ? VAFMD_E_OUT_OF_RANGE : VAFMD_E_WRONG_TYPE, name, "\"%s\" must be %s",
                      name, what);
        return -1;
    }
    return 0;
}

/* replay: path (required), curves, speed, loop (protocol/wire.md, "replay"). */
static int s_decode_replay(json_t *root, vafmd_cmd *c, vafmd_err *e)
{
    json_t *v;
    if (s_need(root, "path", S_TYPE(JSON_STRING), "a file name (string)", "'replay' needs \"path\": the HDF5 file to "
               "replay", &v, e) || s_text_len(v, "path", VAFMD_LOG_PATH_MAX, e))
        return -1;
    c->replay_path = json_string_value(v);
    if ((v = json_object_get(root, "curves")) != NULL) {
        int ok = json_is_string(v) && json_string_length(v) >= 1 && json_string_length(v) <= 4096 &&
                 strlen(json_string_value(v)) == json_string_length(v);
        int negative = 0;
        if (json_is_array(v)) {
            size_t i;
            json_t *x;
            ok = 1;
            json_array_foreach(v, i, x) {
                if (!json_is_integer(x))
                    ok = 0;
                else if (json_integer_value(x) < 0)
                    negative = 1;
            }
        }
        if (ok && negative) {
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "curves", "\"curves\" lists a negative curve number (curve "
                          "groups are numbered from 0)");
            return -1;
        }
        if (!ok) {
            vafmd_err_set(e, VAFMD_E_WRONG_TYPE, "curves", "\"curves\" must be \"all\", a string like \"0,3,5-9\" "
                          "(1 to 4096 characters) or an array of curve numbers (integers >= 0)");
            return -1;
        }
        c->replay_curves = v;
    }
    if (s_opt(root, "speed", S_NUMBER, "a number", &v, e))
        return -1;
    if (v) {
        const s_setting *f = s_setting_find("speed");
        double x = json_number_value(v);
        if (!(x >= f->min && x <= f->max)) {
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "speed", "speed = %.17g is outside [%g, %g]", x, f->min, f->max);
            return -1;
        }
        c->has_speed = 1;
        c->speed = x;
    }
    if ((v = json_object_get(root, "loop")) != NULL) {
        if (json_is_string(v) && !strcmp(json_string_value(v), "forever") && json_string_length(v) == 7)
            c->replay_loop = 0;
        else if (json_is_integer(v) && json_integer_value(v) >= 1 && json_integer_value(v) <= 1000000)
            c->replay_loop = (int64_t)json_integer_value(v);
        else {
            vafmd_err_set(e, json_is_integer(v) ? VAFMD_E_OUT_OF_RANGE : VAFMD_E_WRONG_TYPE, "loop",
                          "\"loop\" must be the number of passes over the selection, 1 to 1000000, or \"forever\" "
                          "(until abort)");
            return -1;
        }
        c->replay_has_loop = 1;
    }
    return 0;
}

int vafmd_cmd_decode_json(json_t *root, vafmd_cmd *c, vafmd_err *e)
{
    memset(c, 0, sizeof *c);
    if (!json_is_object(root)) {
        vafmd_err_set(e, VAFMD_E_MALFORMED, "", "a request must be a JSON object {\"cmd\": NAME, ...}");
        return -1;
    }
    /* from here on the request could be read: its "id" is echoed by every reply, an error's too (wire.md
     * §2.2), so c keeps the request (and id) even when decoding fails; vafmd_cmd_free releases it */
    c->root = json_incref(root);
    c->id = json_object_get(root, "id");
    json_t *cmd;
    if (s_need(root, "cmd", S_TYPE(JSON_STRING), "a string", "the request has no \"cmd\"", &cmd, e))
        return -1;
    int kind = -1;
    for (int i = 0; i < VAFMD_CMD_N; i++)
        if (!strcmp(json_string_value(cmd), s_commands[i].name) && strlen(s_commands[i].name) == json_string_length(cmd))
            kind = i;
    if (kind < 0) {
        char known[256] = ""; /* from the table, so the list cannot miss one (0.6.1's lacked map) */
        for (int i = 0; i < VAFMD_CMD_N; i++)
            snprintf(known + strlen(known), sizeof known - strlen(known), "%s%s", known[0] ? " " : "", s_commands[i].name);
        vafmd_err_set(e, VAFMD_E_UNKNOWN_COMMAND, "cmd", "unknown command '%.64s' (known: %s)",
                      json_string_value(cmd), known);
        return -1;
    }
    const char *key;
    json_t *v;
    json_object_foreach(root, key, v) {
        if (!s_key_allowed(kind, key)) {
            vafmd_err_set(e, VAFMD_E_UNKNOWN_FIELD, key, "'%s' does not take the argument '%.64s'",
                          s_commands[kind].name, key);
            return -1;
        }
    }
    c->kind = kind;
    if (s_opt(root, "names", S_TYPE(JSON_ARRAY), "an array of strings", &v, e))
        return -1;
    if (v) {
        size_t i;
        json_t *n;
        json_array_foreach(v, i, n) if (!json_is_string(n))
        {
            vafmd_err_set(e, VAFMD_E_WRONG_TYPE, "names", "\"names\" must be an array of strings");
            return -1;
        }
        c->names = v;
    }
    if (s_opt(root, "info", S_BOOLEAN, "true or false", &v, e))
        return -1;
    if (v)
        c->info = json_is_true(v);
    if (s_opt(root, "preset", S_TYPE(JSON_STRING), "a preset name (string)", &v, e))
        return -1;
    if (v)
        c->preset = json_string_value(v);
    if (s_opt(root, "values", S_TYPE(JSON_OBJECT), "an object {name: value}", &v, e))
        return -1;
    c->values = v;
    if (kind == VAFMD_CMD_SET && !c->preset && !c->values) {
        vafmd_err_set(e, VAFMD_E_MISSING_FIELD, "values", "'set' needs \"values\" and/or \"preset\"");
        return -1;
    }
    if (s_opt_from0(root, "index", "an integer in [0, 2^63-1]", &v, e))
        return -1;
    if (v) {
        c->has_index = 1;
        c->index = (uint64_t)json_integer_value(v);
    }
    if (s_opt(root, "client_run_id", S_TYPE(JSON_STRING), "a string", &v, e))
        return -1;
    if (v && s_text_len(v, "client_run_id", VAFMD_CLIENT_RUN_ID_MAX, e))
        return -1;
    if (v)
        memcpy(c->client_run_id, json_string_value(v), json_string_length(v) + 1);
    if (s_opt(root, "segments", S_TYPE(JSON_ARRAY) | S_TYPE(JSON_OBJECT), "an array of segments (or {\"segments\": "
              "[...]}), as `vafm run --segments` reads them", &v, e))
        return -1;
    if (v) { /* curve: a segment list (vafm/segments.h) */
        json_t *w = json_is_array(v) ? json_pack("{s:O}", "segments", v) : json_incref(v);
        char *text = w ? json_dumps(w, JSON_COMPACT) : NULL;
        json_decref(w);
        c->segs = malloc(VAFM_SEGMENTS_MAX * sizeof *c->segs);
        vafm_error verr;
        memset(&verr, 0, sizeof verr);
        int r = text && c->segs ? vafm_segments_from_json(text, c->segs, VAFM_SEGMENTS_MAX, &c->nseg, &verr)
                                : VAFM_ENOMEM;
        free(text);
        if (r) {
            vafmd_err_set(e, r == VAFM_ENOMEM ? VAFMD_E_BUSY : VAFMD_E_OUT_OF_RANGE,
                          verr.field[0] ? verr.field : "segments", "%s",
                          r == VAFM_ENOMEM ? "out of memory; retry" : verr.message);
            return -1;
        }
    }
    if (s_opt(root, "duration_s", S_NUMBER, "a number (s)", &v, e))
        return -1;
    if (v) {
        const vafm_param_info *f = vafm_params_field_find("tune_duration_s");
        double x = json_number_value(v);
        if (f && !(x >= f->min && x <= f->max)) {
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "duration_s", "duration_s = %.17g is outside [%g, %g] s", x,
                          f->min, f->max);
            return -1;
        }
        c->has_duration = 1;
        c->duration_s = x;
    }
    if (kind == VAFMD_CMD_CAMPAIGN) {
        if (s_need(root, "n", S_TYPE(JSON_INTEGER), "an integer (curves per grid point)", "'campaign' needs \"n\" "
                   "(curves per grid point)", &v, e))
            return -1;
        if (json_integer_value(v) < 1 || json_integer_value(v) > 1000000000) {
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "n", "n = %" JSON_INTEGER_FORMAT " is outside [1, 1e9]",
                          json_integer_value(v));
            return -1;
        }
        c->camp_n = (uint64_t)json_integer_value(v);
        uint64_t points = 1;
        for (int l = 0; l < VAFM_CAMPAIGN_NAXES; l++) { /* camp_list[l]: the grid's axis l */
            const char *const name = vafm_campaign_axis_at(l)->name;
            if (!(v = json_object_get(root, name)))
                continue;
            size_t i, n = json_is_array(v) ? json_array_size(v) : 0;
            json_t *x;
            if (!json_is_array(v)) {
                vafmd_err_set(e, VAFMD_E_WRONG_TYPE, name, "\"%s\" must be an array of numbers", name);
                return -1;
            }
            json_array_foreach(v, i, x) if (!json_is_number(x))
            {
                vafmd_err_set(e, VAFMD_E_WRONG_TYPE, name, "\"%s\" must be an array of numbers", name);
                return -1;
            }
            if (n < 1 || n > VAFMD_CAMPAIGN_LIST_MAX) {
                vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, name, "\"%s\" must have 1 to %d values (omit it for "
                              "the scene's value)", name, VAFMD_CAMPAIGN_LIST_MAX);
                return -1;
            }
            c->camp_list[l] = v;
            points *= n;
        }
        if (points > VAFMD_CAMPAIGN_POINTS_MAX) {
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, vafm_campaign_axis_at(0)->name, "the grid has %" PRIu64 " points, more than %d", points,
                          VAFMD_CAMPAIGN_POINTS_MAX);
            return -1;
        }
        if (s_opt_from0(root, "first_index", "an integer >= 0", &v, e))
            return -1;
        if (v) {
            c->camp_first = (uint64_t)json_integer_value(v);
            if (c->camp_first >= points * c->camp_n) {
                vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "first_index", "first_index = %" PRIu64 " is beyond the "
                              "campaign's %" PRIu64 " curves (0 to %" PRIu64 ")", c->camp_first, points * c->camp_n,
                              points * c->camp_n - 1);
                return -1;
            }
        }
    }
    if (kind == VAFMD_CMD_MAP && s_decode_map(root, c, e))
        return -1;
    if (kind == VAFMD_CMD_LOG) {
        static const char *const flags[] = { "overwrite", "resume", "stop" };
        int *dst[] = { &c->log_overwrite, &c->log_resume, &c->log_stop };
        for (int i = 0; i < 3; i++) {
            if (s_opt(root, flags[i], S_BOOLEAN, "true or false", &v, e))
                return -1;
            if (v)
                *dst[i] = json_is_true(v);
        }
        if (s_opt(root, "path", S_TYPE(JSON_STRING), "a file name (string)", &v, e))
            return -1;
        if (v && s_text_len(v, "path", VAFMD_LOG_PATH_MAX, e))
            return -1;
        if (v)
            c->log_path = json_string_value(v);
        if (c->log_stop && (c->log_path || c->log_overwrite || c->log_resume)) {
            vafmd_err_set(e, VAFMD_E_UNKNOWN_FIELD, c->log_path ? "path" : c->log_overwrite ? "overwrite" : "resume",
                          "'log' with \"stop\": true takes no other argument");
            return -1;
        }
        if (!c->log_stop && !c->log_path) {
            vafmd_err_set(e, VAFMD_E_MISSING_FIELD, "path", "'log' needs \"path\" (start) or \"stop\": true");
            return -1;
        }
        if (c->log_overwrite && c->log_resume) {
            vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "resume", "\"overwrite\" and \"resume\" exclude each other");
            return -1;
        }
    }
    if (kind == VAFMD_CMD_REPLAY && s_decode_replay(root, c, e))
        return -1;
    if ((kind == VAFMD_CMD_ENGAGE || kind == VAFMD_CMD_WITHDRAW || kind == VAFMD_CMD_MOVE || kind == VAFMD_CMD_Z ||
         kind == VAFMD_CMD_FEEDBACK) && vafmd_live_decode(root, c, e))
        return -1;
    if (kind == VAFMD_CMD_FAULTS) { /* the plan itself is checked by vafmd_faults_decode (faults.c) */
        if (s_opt(root, "clear", S_BOOLEAN, "true or false", &v, e))
            return -1;
        if (v)
            c->fault_clear = json_is_true(v);
        if ((v = json_object_get(root, "plan")) != NULL) {
            if (c->fault_clear) {
                vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, "clear", "\"clear\": true takes no \"plan\" (a plan replaces the "
                              "one in force anyway)");
                return -1;
            }
            if (!json_is_object(v)) {
                vafmd_err_set(e, VAFMD_E_WRONG_TYPE, "plan", "\"plan\" must be an object {\"seed\", \"script\", "
                              "\"random\"}");
                return -1;
            }
            c->fault_plan = v;
        }
    }
    return 0;
}

void vafmd_cmd_free(vafmd_cmd *c)
{
    if (c->root)
        json_decref(c->root);
    free(c->segs);
    memset(c, 0, sizeof *c);
}

static int s_in_values(const char *field, void *values) { return json_object_get(values, field) != NULL; }

int vafmd_apply_set(vafm_params *p, vafmd_settings *s, const vafmd_cmd *c, vafmd_err *e)
{
    vafm_params np = *p;
    vafmd_settings ns = *s;
    if (c->preset) {
        vafm_error verr = { 0 };
        if (strlen(c->preset) != json_string_length(json_object_get(c->root, "preset")) ||
            vafm_preset_apply(&np, c->preset, &verr)) {
            vafmd_err_set(e, VAFMD_E_NOT_FOUND, "preset", "%s", verr.message[0] ? verr.message : "unknown preset");
            return -1;
        }
    }
    if (c->values) {
        const char *key;
        json_t *v;
        json_object_foreach(c->values, key, v) {
            const vafm_param_info *f = vafm_params_field_find(key);
            const s_setting *st = f ? NULL : s_setting_find(key);
            if (f) {
                if (s_param_apply(&np, f, v, e))
                    return -1;
            } else if (st) {
                if (s_setting_apply(&ns, st, v, e))
                    return -1;
            } else {
                vafmd_err_set(e, VAFMD_E_UNKNOWN_FIELD, key, "no parameter or setting named '%.64s'", key);
                return -1;
            }
        }
    }
    vafm_scene_conflict cf; /* a value resolve would overwrite: 0.6.2 dropped it without a word */
    if (c->values && vafm_scene_derived_next(&np, 0, s_in_values, c->values, &cf)) {
        const vafm_param_info *fd = vafm_params_field_find(cf.derived), *fs = vafm_params_field_find(cf.setting);
        int both = json_object_get(c->values, cf.setting) != NULL;
        vafmd_err_set(e, VAFMD_E_OUT_OF_RANGE, both ? cf.setting : cf.derived, "'%s' = %.6g %s conflicts with %s'%s' = "
                      "%g %s, which makes it %.6g %s: set %s to 0 %sto give %s directly", cf.derived, cf.value,
                      fd->unit, both ? "" : "the scene's ", cf.setting, cf.setting_value, fs->unit, cf.derives,
                      fd->unit, cf.setting, both ? "" : "in the same set ", cf.derived);
        return -1;
    }
    vafm_error verr = { 0 };
    int rc = vafm_params_resolve(&np, &verr); /* ramp rate, extend/retract times, segment samples, setpoint_V */
    if (!rc)
        rc = vafm_params_validate(&np, &verr);
    if (rc) {
        vafmd_err_set(e, VAFMD_E_INVALID_SCENE, verr.field, "the resulting scene is invalid: %s", verr.message);
        return -1;
    }
    *p = np;
    *s = ns;
    return 0;
}

static json_t *s_info_param(const vafm_param_info *f)
{
    json_t *o = json_object();
    static const char *const kinds[] = { "real", "choice", "seed", "bool", "integer" };
    json_object_set_new(o, "kind", json_string(f->kind >= 0 && f->kind < 5 ? kinds[f->kind] : "?"));
    json_object_set_new(o, "unit", json_string(f->unit));
    if (f->kind == VAFM_PARAM_REAL || f->kind == VAFM_PARAM_INT) {
        json_object_set_new(o, "min", json_real(f->min));
        json_object_set_new(o, "max", json_real(f->max));
    }
    if (f->kind == VAFM_PARAM_CHOICE)
        json_object_set_new(o, "choices", json_string(f->choices));
    json_object_set_new(o, "doc", json_string(f->doc));
    return o;
}

static json_t *s_info_setting(const s_setting *f)
{
    json_t *o = json_object();
    json_object_set_new(o, "kind", json_string(f->kind == S_SET_BOOL     ? "bool"
                                               : f->kind == S_SET_INT    ? "integer"
                                               : f->kind == S_SET_CHOICE ? "choice"
                                                                         : "real"));
    json_object_set_new(o, "unit", json_string(f->unit));
    if (f->kind == S_SET_CHOICE)
        json_object_set_new(o, "choices", json_string("scalar|batch"));
    else if (f->kind != S_SET_BOOL) {
        json_object_set_new(o, "min", json_real(f->min));
        json_object_set_new(o, "max", json_real(f->max));
    }
    json_object_set_new(o, "read_only", json_boolean(f->read_only));
    json_object_set_new(o, "doc", json_string(f->doc));
    return o;
}

json_t *vafmd_get_values(const vafm_params *p, const vafmd_settings *s, const vafmd_cmd *c, vafmd_err *e)
{
    json_t *vals = json_object(), *info = c->info ? json_object() : NULL;
    if (c->names) {
        size_t i;
        json_t *n;
        json_array_foreach(c->names, i, n) {
            const char *name = json_string_value(n);
            const vafm_param_info *f = vafm_params_field_find(name);
            const s_setting *st = f ? NULL : s_setting_find(name);
            if (!f && !st) {
                vafmd_err_set(e, VAFMD_E_UNKNOWN_FIELD, name, "no parameter or setting named '%.64s'", name);
                json_decref(vals);
                json_decref(info);
                return NULL;
            }
            json_object_set_new(vals, name, f ? vafmd_param_value(p, f) : s_setting_value(s, st));
            if (info)
                json_object_set_new(info, name, f ? s_info_param(f) : s_info_setting(st));
        }
    } else {
        for (int i = 0; i < vafm_params_field_count(); i++) {
            const vafm_param_info *f = vafm_params_field_at(i);
            json_object_set_new(vals, f->name, vafmd_param_value(p, f));
            if (info)
                json_object_set_new(info, f->name, s_info_param(f));
        }
        for (size_t i = 0; i < S_N_SETTINGS; i++) {
            json_object_set_new(vals, s_settings[i].name, s_setting_value(s, &s_settings[i]));
            if (info)
                json_object_set_new(info, s_settings[i].name, s_info_setting(&s_settings[i]));
        }
    }
    json_t *r = json_object();
    json_object_set_new(r, "values", vals);
    if (info)
        json_object_set_new(r, "info", info);
    return r;
}

json_t *vafmd_error_reply(const vafmd_err *e, json_t *id)
{
    json_t *r = json_object();
    json_object_set_new(r, "status", json_string("error"));
    json_object_set_new(r, "code", json_string(e->code ? e->code : VAFMD_E_INTERNAL));
    /* json_string rejects invalid UTF-8 (a message may quote client bytes): fall back to plain text */
    json_t *m = json_string(e->message);
    json_object_set_new(r, "message", m ? m : json_string("(message not representable)"));
    json_t *f = e->field[0] ? json_string(e->field) : json_null();
    json_object_set_new(r, "field", f ? f : json_string("?"));
    if (id)
        json_object_set(r, "id", id);
    return r;
}
