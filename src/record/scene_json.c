/* SPDX-License-Identifier: MIT */
/*
 * JSON scene files: parse with jansson, then hand every value to vafm_params_set as text, so that the
 * library stays the only judge of names, ranges and choices. Values are turned into text without loss
 * (%.17g for reals), which is what makes `vafm params --json` → --scene an exact round trip.
 * JSON types are checked per parameter kind first, by one rule for every program (the CLI's scene
 * files, vafmd's commands, the scenes in files and streams): a string where a number belongs, an
 * integer where a boolean belongs, a negative or fractional seed are errors, not silent conversions.
 * The same code reads the scene and the campaign grid that vafm stores in its HDF5 files (vafm info).
 */
#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include <jansson.h>

#include "record/json_num.h"
#include "record/scene_value.h"
#include "record/scene.h"

void vafm_scene_param_allowed(const vafm_param_info *info, char *buf, size_t len)
{
    switch (info->kind) {
    case VAFM_PARAM_REAL:
        snprintf(buf, len, "a number in [%.6g, %.6g]%s%s", info->min, info->max, info->unit[0] ? " " : "",
                 info->unit);
        break;
    case VAFM_PARAM_CHOICE: snprintf(buf, len, "one of %s", info->choices); break;
    case VAFM_PARAM_BOOL: snprintf(buf, len, "a boolean (true|false|1|0)"); break;
    case VAFM_PARAM_INT:
        snprintf(buf, len, "a whole number in [%.0f, %.0f]%s%s", info->min, info->max, info->unit[0] ? " " : "",
                 info->unit);
        break;
    case VAFM_PARAM_SEED: snprintf(buf, len, "an integer in [0, 2^64 - 1]"); break;
    default: snprintf(buf, len, "(unknown kind)"); break;
    }
}

static const char *s_type_name(const json_t *v)
{
    switch (json_typeof(v)) {
    case JSON_OBJECT: return "an object";
    case JSON_ARRAY: return "an array";
    case JSON_STRING: return "a string";
    case JSON_INTEGER: return "an integer";
    case JSON_REAL: return "a real number";
    case JSON_TRUE:
    case JSON_FALSE: return "a boolean";
    case JSON_NULL: return "null";
    default: return "an unknown JSON type";
    }
}

/* Fill err with code, field and "<path>: <reason>", the reason formatted from fmt (at most the message's size).
 * @return code. */
#if defined(__GNUC__)
__attribute__((format(printf, 5, 6)))
#endif
static int s_fail(vafm_error *err, int code, const char *field, const char *path, const char *fmt, ...)
{
    if (!err)
        return code;
    char what[sizeof err->message];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(what, sizeof what, fmt, ap);
    va_end(ap);
    err->code = code;
    snprintf(err->field, sizeof err->field, "%s", field);
    /* The file name is cut rather than the reason when the two do not fit. */
    int room = (int)sizeof err->message - (int)strlen(what) - 3;
    if (snprintf(err->message, sizeof err->message, "%.*s: %s", room > 16 ? room : 16, path, what) < 0)
        err->message[0] = '\0';
    return code;
}

const char *vafm_scene_value_text(const vafm_param_info *info, const json_t *v, char *buf, size_t len)
{
    switch (info->kind) {
    case VAFM_PARAM_REAL:
        /* plain SI numbers; the one named value, omega_dt "paper" (the paper's step), as the CLI takes it */
        if (json_is_string(v) && !strcmp(info->name, "omega_dt") && !strcmp(json_string_value(v), "paper")) {
            snprintf(buf, len, "paper");
            return buf;
        }
        if (!json_is_number(v))
            return NULL;
        snprintf(buf, len, "%.17g", json_number_value(v));
        return buf;
    case VAFM_PARAM_SEED:
        /* a non-negative integer, or its decimal digits as a string (JSON integers end at 2^63 - 1) */
        if (json_is_integer(v) && json_integer_value(v) >= 0)
            snprintf(buf, len, "%" JSON_INTEGER_FORMAT, json_integer_value(v));
        else if (json_is_string(v) && json_string_length(v) > 0 && json_string_length(v) <= 20 &&
                 strspn(json_string_value(v), "0123456789") == json_string_length(v))
            snprintf(buf, len, "%s", json_string_value(v));
        else
            return NULL;
        return buf;
    case VAFM_PARAM_INT:
        if (!json_is_integer(v)) /* 8.5 bits is the wrong type, not an out-of-range number */
            return NULL;
        snprintf(buf, len, "%" JSON_INTEGER_FORMAT, json_integer_value(v));
        return buf;
    case VAFM_PARAM_BOOL:
        if (!json_is_boolean(v))
            return NULL;
        snprintf(buf, len, "%s", json_is_true(v) ? "true" : "false");
        return buf;
    case VAFM_PARAM_CHOICE:
        /* no embedded NUL, and short enough to be a choice name */
        if (!json_is_string(v) || json_string_length(v) >= len || strlen(json_string_value(v)) != json_string_length(v))
            return NULL;
        snprintf(buf, len, "%s", json_string_value(v));
        return buf;
    default: return NULL;
    }
}

void vafm_scene_json_allowed(const vafm_param_info *info, char *buf, size_t len)
{
    switch (info->kind) {
    case VAFM_PARAM_BOOL: snprintf(buf, len, "true or false"); break;
    case VAFM_PARAM_SEED: snprintf(buf, len, "an integer in [0, 2^64 - 1] (a number or a string of decimal digits)"); break;
    case VAFM_PARAM_CHOICE: snprintf(buf, len, "a string, one of %s", info->choices); break;
    default: vafm_scene_param_allowed(info, buf, len); break;
    }
}

static int s_apply_key(vafm_params *p, const char *path, const char *key, const json_t *v, vafm_error *err)
{
    const vafm_param_info *info = vafm_params_field_find(key);
    if (!info)
        return s_fail(err, VAFM_ENOTFOUND, key, path, "unknown key '%.64s' (not a parameter; see vafm --help)", key);
    char text[256], allowed[160];
    if (!vafm_scene_value_text(info, v, text, sizeof text)) {
        vafm_scene_json_allowed(info, allowed, sizeof allowed);
        return s_fail(err, VAFM_EINVAL, key, path, "key '%s' is %s, but must be %s", key, s_type_name(v), allowed);
    }
    vafm_error e;
    memset(&e, 0, sizeof e);
    int r = vafm_params_set(p, key, text, &e);
    if (r)
        s_fail(err, r, key, path, "key '%s': %.200s", key, e.message);
    return r;
}

static int s_apply_preset(vafm_params *p, const char *path, const json_t *root, char *preset, size_t preset_len,
                          vafm_error *err)
{
    const json_t *v = json_object_get(root, "preset");
    if (!v)
        return 0;
    if (!json_is_string(v))
        return s_fail(err, VAFM_EINVAL, "preset", path, "key 'preset' is %s, but must be a preset name (see vafm presets)",
                      s_type_name(v));
    vafm_error e;
    memset(&e, 0, sizeof e);
    int r = vafm_preset_apply(p, json_string_value(v), &e);
    if (r)
        return s_fail(err, r, "preset", path, "key 'preset': %.200s", e.message);
    if (preset)
        snprintf(preset, preset_len, "%s", json_string_value(v));
    return 0;
}

/* Apply a parsed scene object (its preset first, then every other key). */
static int s_apply_root(vafm_params *p, const char *path, json_t *root, char *preset, size_t preset_len,
                        vafm_error *err)
{
    if (!json_is_object(root))
        return s_fail(err, VAFM_EFORMAT, "scene", path, "a scene file must hold one JSON object {\"name\": value, ...}, "
                      "not %s", s_type_name(root));
    int r = s_apply_preset(p, path, root, preset, preset_len, err);
    const char *key;
    json_t *v;
    json_object_foreach(root, key, v) {
        if (r)
            break;
        if (strcmp(key, "preset") != 0)
            r = s_apply_key(p, path, key, v, err);
    }
    return r;
}

int vafm_scene_load_file(vafm_params *p, const char *path, char *preset, size_t preset_len, vafm_error *err)
{
    if (preset && preset_len)
        preset[0] = '\0';
    struct stat st;
    if (stat(path, &st) == 0 && !S_ISREG(st.st_mode)) /* a FIFO would block the read forever */
        return s_fail(err, VAFM_EIO, "scene", path, "%s", S_ISDIR(st.st_mode) ? "is a directory, not a JSON scene file"
                                                         : "is not a regular file (a FIFO, device or socket)");
    if (stat(path, &st) == 0 && (uintmax_t)st.st_size > VAFM_SCENE_MAX_FILE_BYTES)
        return s_fail(err, VAFM_EIO, "scene", path, "is %ju bytes, larger than a scene file can be (%u bytes)",
                      (uintmax_t)st.st_size, VAFM_SCENE_MAX_FILE_BYTES);
    /* read whole (bounded), so that the number literals can be checked as written */
    FILE *f = fopen(path, "rb");
    char *text = f ? malloc((size_t)VAFM_SCENE_MAX_FILE_BYTES + 1) : NULL;
    size_t n = text ? fread(text, 1, (size_t)VAFM_SCENE_MAX_FILE_BYTES + 1, f) : 0;
    int en = errno, bad = !f || !text || ferror(f);
    if (f)
        fclose(f);
    if (bad || n > VAFM_SCENE_MAX_FILE_BYTES) {
        if (n > VAFM_SCENE_MAX_FILE_BYTES)
            s_fail(err, VAFM_EIO, "scene", path, "is larger than a scene file can be (%u bytes)", VAFM_SCENE_MAX_FILE_BYTES);
        else
            s_fail(err, VAFM_EIO, "scene", path, "cannot read the scene file: %.200s",
                   text || !f ? strerror(en) : "out of memory");
        free(text);
        return VAFM_EIO;
    }
    json_error_t je;
    json_t *root = json_loadb(text, n, JSON_REJECT_DUPLICATES, &je);
    if (!root) {
        free(text);
        return s_fail(err, VAFM_EFORMAT, "scene", path, "line %d, column %d: %.200s", je.line, je.column, je.text);
    }
    /* a nonzero number that underflows reads as 0 (or a subnormal): refused, as the CLI's and vafmd's */
    char key[64], lit[48];
    size_t line;
    double x;
    int uf = vafm_rec_json_underflow(text, n, 0, key, sizeof key, lit, sizeof lit, &line, &x);
    free(text);
    if (uf) {
        s_fail(err, VAFM_EINVAL, key[0] ? key : "scene", path, "line %zu: %s%s%sthe number %s underflows: a nonzero "
               "value must be at least %.17g in magnitude (it would read as %g)", line, key, key[0] ? ": " : "", "", lit,
               DBL_MIN, x);
        json_decref(root);
        return VAFM_EINVAL;
    }
    int r = s_apply_root(p, path, root, preset, preset_len, err);
    json_decref(root);
    return r;
}

int vafm_scene_parse(vafm_params *p, const char *text, const char *origin, vafm_error *err)
{
    json_error_t je;
    json_t *root = json_loads(text, JSON_REJECT_DUPLICATES, &je);
    if (!root)
        return s_fail(err, VAFM_EFORMAT, "scene", origin, "line %d, column %d: %.200s", je.line, je.column, je.text);
    int r = s_apply_root(p, origin, root, NULL, 0, err);
    json_decref(root);
    return r;
}

/* ---- campaign grids ------------------------------------------------------------------------------ */

/* A JSON list of numbers into a malloc'd array (NULL for an absent or empty list). */
static int s_grid_list(const json_t *root, const char *key, double **out, size_t *n)
{
    *out = NULL;
    *n = 0;
    const json_t *a = json_object_get(root, key);
    if (!a)
        return 0;
    if (!json_is_array(a))
        return -1;
    size_t m = json_array_size(a);
    if (!m)
        return 0;
    double *v = calloc(m, sizeof *v);
    if (!v)
        return -1;
    for (size_t i = 0; i < m; i++) {
        const json_t *x = json_array_get(a, i);
        if (!json_is_number(x)) {
            free(v);
            return -1;
        }
        v[i] = json_number_value(x);
    }
    *out = v;
    *n = m;
    return 0;
}

int vafm_scene_grid_parse(const char *text, const char *origin, vafm_scene_grid *g, vafm_error *err)
{
    memset(g, 0, sizeof *g);
    json_error_t je;
    json_t *root = json_loads(text, JSON_REJECT_DUPLICATES, &je);
    if (!root || !json_is_object(root)) {
        if (root)
            s_fail(err, VAFM_EFORMAT, "grid", origin, "the grid is %s, not a JSON object", s_type_name(root));
        else
            s_fail(err, VAFM_EFORMAT, "grid", origin, "line %d, column %d: %.200s", je.line, je.column, je.text);
        json_decref(root);
        return VAFM_EFORMAT;
    }
    const char *bad = NULL;
    if (s_grid_list(root, "T_K", &g->T_K, &g->n_T))
        bad = "T_K";
    else if (s_grid_list(root, "v_m_per_s", &g->v_m_per_s, &g->n_v))
        bad = "v_m_per_s";
    else if (s_grid_list(root, "k_N_per_m", &g->k_N_per_m, &g->n_k))
        bad = "k_N_per_m";
    const json_t *n = json_object_get(root, "curves_per_point");
    if (!bad && n) {
        if (json_is_integer(n) && json_integer_value(n) >= 1)
            g->curves_per_point = (uint64_t)json_integer_value(n);
        else
            bad = "curves_per_point";
    }
    json_decref(root);
    if (bad) {
        s_fail(err, VAFM_EFORMAT, bad, origin, "grid key '%s' is not %s", bad,
               strcmp(bad, "curves_per_point") ? "a list of numbers" : "an integer >= 1");
        vafm_scene_grid_free(g);
        return VAFM_EFORMAT;
    }
    return 0;
}

void vafm_scene_grid_free(vafm_scene_grid *g)
{
    free(g->T_K);
    free(g->v_m_per_s);
    free(g->k_N_per_m);
    memset(g, 0, sizeof *g);
}

int vafm_scene_from_h5(const vafm_h5_reader *r, const char *path, vafm_params *p, vafm_scene_grid *g,
                       vafm_error *err)
{
    if (g)
        memset(g, 0, sizeof *g);
    vafm_h5_provenance pv;
    if (!r || vafm_h5_reader_provenance(r, &pv) || !pv.is_vafm || !pv.scene_json) {
        return s_fail(err, VAFM_ENOTFOUND, "vafm scene", path ? path : "(file)", "records no vafm scene (not a vafm file)");
    }
    char origin[1100];
    snprintf(origin, sizeof origin, "%s: 'vafm scene'", path ? path : "(file)");
    vafm_params_default(p);
    int rc = vafm_scene_parse(p, pv.scene_json, origin, err);
    if (!rc && g && pv.grid_json) {
        snprintf(origin, sizeof origin, "%s: 'vafm grid'", path ? path : "(file)");
        rc = vafm_scene_grid_parse(pv.grid_json, origin, g, err);
    }
    return rc;
}

/* ---- fields the instrument settings derive (vafm_params_resolve) --------------------------------- */

static const struct {
    const char *derived, *setting;
} s_derived_pairs[] = {
    { "v_approach_m_per_s", "ramp_rate_Hz" }, { "v_retract_m_per_s", "ramp_rate_Hz" },
    { "v_approach_m_per_s", "extend_time_s" }, { "v_retract_m_per_s", "retract_time_s" },
    { "sample_rate_Hz", "segment_samples" },   { "setpoint_N", "setpoint_V" },
};

static double s_field_value(const vafm_params *p, const char *name)
{
    char buf[64];
    return vafm_params_get(p, name, buf, sizeof buf) ? NAN : strtod(buf, NULL);
}

int vafm_scene_derived_next(const vafm_params *p, int from, int (*given)(const char *field, void *ctx), void *ctx,
                            vafm_scene_conflict *out)
{
    int n = (int)(sizeof s_derived_pairs / sizeof *s_derived_pairs);
    for (int i = from < 0 ? 0 : from; i < n; i++) {
        const char *d = s_derived_pairs[i].derived, *st = s_derived_pairs[i].setting;
        double sv = s_field_value(p, st);
        if (!(sv > 0) || !given(d, ctx))
            continue;
        vafm_params r = *p;
        double want = vafm_params_resolve(&r, NULL) ? NAN : s_field_value(&r, d), have = s_field_value(p, d);
        if (!isnan(want) && fabs(have - want) <= 1e-12 * fabs(want))
            continue; /* the value given is the one the setting makes (a `get` sent back, a saved scene) */
        *out = (vafm_scene_conflict){ d, st, have, sv, want };
        return i + 1;
    }
    return 0;
}
