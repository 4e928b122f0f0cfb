/* SPDX-License-Identifier: MIT */
/*
 * JSON scene files: parse with jansson, then hand every value to vafm_params_set as text, so that the
 * library stays the only judge of names, ranges and choices. Values are turned into text without loss
 * (%.17g for reals), which is what makes `vafm params --json` → --scene an exact round trip.
 * JSON types are checked per parameter kind first: a string where a number belongs is an error here,
 * not a silent conversion.
 * The same code reads the scene and the campaign grid that vafm stores in its HDF5 files (vafm info).
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include <jansson.h>

#include "cli/scene_json.h"

void vafm_cli_param_allowed(const vafm_param_info *info, char *buf, size_t len)
{
    switch (info->kind) {
    case VAFM_PARAM_REAL:
        snprintf(buf, len, "a number in [%.6g, %.6g]%s%s", info->min, info->max, info->unit[0] ? " " : "",
                 info->unit);
        break;
    case VAFM_PARAM_CHOICE: snprintf(buf, len, "one of %s", info->choices); break;
    case VAFM_PARAM_BOOL: snprintf(buf, len, "a boolean (true|false|1|0)"); break;
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

static void s_fail(vafm_error *err, int code, const char *field, const char *path, const char *what)
{
    if (!err)
        return;
    err->code = code;
    snprintf(err->field, sizeof err->field, "%s", field);
    /* The file name is cut rather than the reason when the two do not fit. */
    int room = (int)sizeof err->message - (int)strlen(what) - 3;
    if (snprintf(err->message, sizeof err->message, "%.*s: %s", room > 16 ? room : 16, path, what) < 0)
        err->message[0] = '\0';
}

/* The text form of a JSON value for a parameter of kind `kind`, or NULL if the JSON type is wrong. */
static const char *s_value_text(const json_t *v, int kind, char *buf, size_t len)
{
    switch (kind) {
    case VAFM_PARAM_REAL:
        if (json_is_real(v))
            snprintf(buf, len, "%.17g", json_real_value(v));
        else if (json_is_integer(v))
            snprintf(buf, len, "%" JSON_INTEGER_FORMAT, json_integer_value(v));
        else
            return NULL;
        return buf;
    case VAFM_PARAM_SEED:
        /* Strings carry seeds beyond jansson's signed 64-bit integers. */
        if (json_is_integer(v))
            snprintf(buf, len, "%" JSON_INTEGER_FORMAT, json_integer_value(v));
        else if (json_is_string(v))
            snprintf(buf, len, "%s", json_string_value(v));
        else
            return NULL;
        return buf;
    case VAFM_PARAM_BOOL:
        if (json_is_boolean(v))
            snprintf(buf, len, "%s", json_is_true(v) ? "true" : "false");
        else if (json_is_integer(v))
            snprintf(buf, len, "%" JSON_INTEGER_FORMAT, json_integer_value(v));
        else
            return NULL;
        return buf;
    case VAFM_PARAM_CHOICE:
        if (!json_is_string(v))
            return NULL;
        snprintf(buf, len, "%s", json_string_value(v));
        return buf;
    default: return NULL;
    }
}

static int s_apply_key(vafm_params *p, const char *path, const char *key, const json_t *v, vafm_error *err)
{
    char what[sizeof err->message];
    const vafm_param_info *info = vafm_param_find(key);
    if (!info) {
        snprintf(what, sizeof what, "unknown key '%.64s' (not a parameter; see vafm --help)", key);
        s_fail(err, VAFM_ENOTFOUND, key, path, what);
        return VAFM_ENOTFOUND;
    }
    char text[256], allowed[160];
    if (!s_value_text(v, info->kind, text, sizeof text)) {
        vafm_cli_param_allowed(info, allowed, sizeof allowed);
        snprintf(what, sizeof what, "key '%s' is %s, but must be %s", key, s_type_name(v), allowed);
        s_fail(err, VAFM_EINVAL, key, path, what);
        return VAFM_EINVAL;
    }
    vafm_error e;
    memset(&e, 0, sizeof e);
    int r = vafm_params_set(p, key, text, &e);
    if (r) {
        snprintf(what, sizeof what, "key '%s': %.200s", key, e.message);
        s_fail(err, r, key, path, what);
    }
    return r;
}

static int s_apply_preset(vafm_params *p, const char *path, const json_t *root, char *preset, size_t preset_len,
                          vafm_error *err)
{
    const json_t *v = json_object_get(root, "preset");
    if (!v)
        return 0;
    char what[sizeof err->message];
    if (!json_is_string(v)) {
        snprintf(what, sizeof what, "key 'preset' is %s, but must be a preset name (see vafm presets)",
                 s_type_name(v));
        s_fail(err, VAFM_EINVAL, "preset", path, what);
        return VAFM_EINVAL;
    }
    vafm_error e;
    memset(&e, 0, sizeof e);
    int r = vafm_params_preset(p, json_string_value(v), &e);
    if (r) {
        snprintf(what, sizeof what, "key 'preset': %.200s", e.message);
        s_fail(err, r, "preset", path, what);
        return r;
    }
    if (preset)
        snprintf(preset, preset_len, "%s", json_string_value(v));
    return 0;
}

/* Apply a parsed scene object (its preset first, then every other key). */
static int s_apply_root(vafm_params *p, const char *path, json_t *root, char *preset, size_t preset_len,
                        vafm_error *err)
{
    char what[sizeof err->message];
    if (!json_is_object(root)) {
        snprintf(what, sizeof what, "a scene file must hold one JSON object {\"name\": value, ...}, not %s",
                 s_type_name(root));
        s_fail(err, VAFM_EFORMAT, "scene", path, what);
        return VAFM_EFORMAT;
    }
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

int vafm_cli_scene_load(vafm_params *p, const char *path, char *preset, size_t preset_len, vafm_error *err)
{
    if (preset && preset_len)
        preset[0] = '\0';
    char what[sizeof err->message];
    struct stat st;
    if (stat(path, &st) == 0 && S_ISDIR(st.st_mode)) {
        s_fail(err, VAFM_EIO, "scene", path, "is a directory, not a JSON scene file");
        return VAFM_EIO;
    }
    json_error_t je;
    json_t *root = json_load_file(path, JSON_REJECT_DUPLICATES, &je);
    if (!root) {
        int io = json_error_code(&je) == json_error_cannot_open_file;
        if (io)
            snprintf(what, sizeof what, "cannot read the scene file: %.200s", je.text);
        else
            snprintf(what, sizeof what, "line %d, column %d: %.200s", je.line, je.column, je.text);
        s_fail(err, io ? VAFM_EIO : VAFM_EFORMAT, "scene", path, what);
        return io ? VAFM_EIO : VAFM_EFORMAT;
    }
    int r = s_apply_root(p, path, root, preset, preset_len, err);
    json_decref(root);
    return r;
}

int vafm_cli_scene_parse(vafm_params *p, const char *text, const char *origin, vafm_error *err)
{
    char what[sizeof err->message];
    json_error_t je;
    json_t *root = json_loads(text, JSON_REJECT_DUPLICATES, &je);
    if (!root) {
        snprintf(what, sizeof what, "line %d, column %d: %.200s", je.line, je.column, je.text);
        s_fail(err, VAFM_EFORMAT, "scene", origin, what);
        return VAFM_EFORMAT;
    }
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

int vafm_cli_grid_parse(const char *text, const char *origin, vafm_cli_grid *g, vafm_error *err)
{
    memset(g, 0, sizeof *g);
    char what[sizeof err->message];
    json_error_t je;
    json_t *root = json_loads(text, JSON_REJECT_DUPLICATES, &je);
    if (!root || !json_is_object(root)) {
        if (root)
            snprintf(what, sizeof what, "the grid is %s, not a JSON object", s_type_name(root));
        else
            snprintf(what, sizeof what, "line %d, column %d: %.200s", je.line, je.column, je.text);
        s_fail(err, VAFM_EFORMAT, "grid", origin, what);
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
        snprintf(what, sizeof what, "grid key '%s' is not %s", bad,
                 strcmp(bad, "curves_per_point") ? "a list of numbers" : "an integer >= 1");
        s_fail(err, VAFM_EFORMAT, bad, origin, what);
        vafm_cli_grid_free(g);
        return VAFM_EFORMAT;
    }
    return 0;
}

void vafm_cli_grid_free(vafm_cli_grid *g)
{
    free(g->T_K);
    free(g->v_m_per_s);
    free(g->k_N_per_m);
    memset(g, 0, sizeof *g);
}
