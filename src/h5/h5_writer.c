/* SPDX-License-Identifier: MIT */
/*
 * Writing force-curve files of afmformats' HDF5 layout, with vafm's provenance in root attributes,
 * durable flushes and resume after a kill (the durability argument is in h5_internal.h; the resume itself
 * is in h5_resume.c).
 *
 * A curve is checked completely before anything is written, so a refused curve leaves no trace. The
 * ground-truth table is kept in memory: each flush adds one root attribute with the rows appended
 * since the previous flush; a clean close (and a resume) merges all rows into "vafm ground truth".
 */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

#include "h5/h5_internal.h"

#define S_TAG 0x76683577u /* "vh5w" */
#define S_JSON_MAX 65536
/* one chunk per channel: HDF5 limits a chunk to 4 GiB */
#define S_MAX_SAMPLES ((size_t)VAFM_H5_MAX_SAMPLES)

void vafm_h5_writer_opts_default(vafm_h5_writer_opts *o)
{
    memset(o, 0, sizeof *o);
    o->fletcher32 = 1;
    o->stamp_time = 1;
}

static int s_has_suffix(const char *path, const char *suf)
{
    size_t n = strlen(path), m = strlen(suf);
    return n > m && !strcmp(path + n - m, suf);
}

hid_t vafm_h5i_writer_fapl(void)
{
    hid_t fapl = H5Pcreate(H5P_FILE_ACCESS);
    if (fapl < 0)
        return -1;
    /* 1.8 format: checksummed metadata, and no superblock-v3 "open for write" flag that would keep a
     * killed file locked until h5clear (h5_internal.h) */
    if (H5Pset_libver_bounds(fapl, H5F_LIBVER_V18, H5F_LIBVER_V18) < 0 ||
        H5Pset_fclose_degree(fapl, H5F_CLOSE_STRONG) < 0 || vafm_h5i_fapl_journal(fapl)) {
        H5Pclose(fapl);
        return -1;
    }
    return fapl;
}

static void s_now(char date[16], char tod[16], char iso[32])
{
    time_t t = time(NULL);
    struct tm tm;
    gmtime_r(&t, &tm);
    if (date)
        strftime(date, 16, "%Y-%m-%d", &tm);
    if (tod)
        strftime(tod, 16, "%H:%M:%S", &tm);
    if (iso)
        strftime(iso, 32, "%Y-%m-%dT%H:%M:%SZ", &tm);
}

/* ---- ground-truth table --------------------------------------------------------------------------- */

int vafm_h5i_writer_rows_reserve(vafm_h5_writer *w, size_t n)
{
    if (n <= w->caprows)
        return 0;
    size_t cap = w->caprows ? w->caprows : 64;
    while (cap < n)
        cap *= 2;
    vafm_h5i_row *v = realloc(w->rows, cap * sizeof *v);
    if (!v)
        return -1;
    w->rows = v;
    w->caprows = cap;
    return 0;
}

static int s_write_rows(hid_t file, const char *name, const vafm_h5i_row *rows, size_t n)
{
    hsize_t dim = n;
    hid_t ft = vafm_h5i_row_type(1), mt = vafm_h5i_row_type(0), sp = H5Screate_simple(1, &dim, NULL), a = -1;
    int rc = -1;
    if (ft < 0 || mt < 0 || sp < 0)
        goto done;
    if (H5Aexists(file, name) > 0 && H5Adelete(file, name) < 0)
        goto done;
    a = H5Acreate2(file, name, ft, sp, H5P_DEFAULT, H5P_DEFAULT);
    if (a < 0 || H5Awrite(a, mt, rows) < 0)
        goto done;
    rc = 0;
done:
    if (a >= 0 && H5Aclose(a) < 0)
        rc = -1;
    VAFM_H5I_CLOSE(sp, mt, ft);
    return rc;
}

/* Replace every ground-truth attribute by one merged table. */
int vafm_h5i_writer_merge_rows(vafm_h5_writer *w)
{
    char **names = NULL;
    size_t nn = 0;
    if (vafm_h5i_truth_attr_names(w->file, &names, &nn))
        return -1;
    int rc = 0;
    for (size_t i = 0; i < nn; i++) {
        if (H5Adelete(w->file, names[i]) < 0)
            rc = -1;
        free(names[i]);
    }
    free(names);
    if (!rc && w->nrows)
        rc = s_write_rows(w->file, VAFM_H5I_A_TRUTH, w->rows, w->nrows);
    if (!rc) {
        w->rows_in_file = w->nrows;
        w->parts_in_file = 0;
    }
    return rc;
}

/* ---- open, create (resume: h5_resume.c) ------------------------------------------------------------------ */

static int s_create(vafm_h5_writer *w, vafm_error *err)
{
    hid_t fcpl = H5Pcreate(H5P_FILE_CREATE), fapl = vafm_h5i_writer_fapl();
    if (fcpl < 0 || fapl < 0 || H5Pset_attr_phase_change(fcpl, 0, 0) < 0) {
        if (fcpl >= 0)
            H5Pclose(fcpl);
        if (fapl >= 0)
            H5Pclose(fapl);
        vafm_h5i_err_hdf5(err, VAFM_EIO, "", "%s: HDF5 property lists cannot be set up", w->path);
        return VAFM_EIO;
    }
    /* root attributes in dense storage from the start: the scene JSON and the ground-truth table
     * exceed the 64 KiB limit of attributes kept in the object header */
    struct stat st;
    int rc = 0;
    if (!w->o.overwrite && !stat(w->path, &st))
        vafm_h5i_err(err, rc = VAFM_EIO, "", "%s: exists already (resume it, or allow overwriting)", w->path);
    else if (w->o.overwrite && !stat(w->path, &st))
        rc = vafm_h5i_check_path(w->path, 1, err); /* never truncate a file in use (the driver locks first too) */
    else
        rc = vafm_h5i_check_dir_writable(w->path, err); /* a read-only place is named so, not "cannot be created" */
    if (rc) {
        H5Pclose(fcpl);
        H5Pclose(fapl);
        return rc;
    }
    w->file = H5Fcreate(w->path, w->o.overwrite ? H5F_ACC_TRUNC : H5F_ACC_EXCL, fcpl, fapl);
    H5Pclose(fcpl);
    H5Pclose(fapl);
    if (w->file < 0) {
        vafm_h5i_err_hdf5(err, VAFM_EIO, "", "%s: cannot be created", w->path);
        return VAFM_EIO;
    }
    char ver[32];
    snprintf(ver, sizeof ver, "%d.%d", VAFM_H5_FORMAT_MAJOR, VAFM_H5_FORMAT_MINOR);
    if (vafm_h5i_put_str(w->file, "software", "vafm") ||
        vafm_h5i_put_str(w->file, "software version", vafm_version()) ||
        vafm_h5i_put_str(w->file, VAFM_H5I_A_FORMAT, ver) || H5Fflush(w->file, H5F_SCOPE_GLOBAL) < 0) {
        vafm_h5i_err_hdf5(err, VAFM_EIO, "/", "%s: root attributes cannot be written", w->path);
        return VAFM_EIO;
    }
    w->minor = VAFM_H5_FORMAT_MINOR;
    return 0;
}

void vafm_h5_writer_destroy(vafm_h5_writer **wp)
{
    if (!wp || !*wp)
        return;
    vafm_h5_writer *w = *wp;
    vafm_h5i_quiet q;
    vafm_h5i_quiet_begin(&q);
    if (w->file >= 0)
        H5Fclose(w->file);
    vafm_h5i_quiet_end(&q);
    free(w->path);
    free(w->scene);
    free(w->grid);
    free(w->rows);
    free(w->segs);
    free(w->cseg);
    w->tag = 0xdeadbeefu;
    free(w);
    *wp = NULL;
}

int vafm_h5_writer_open(vafm_h5_writer **out, const char *path, const vafm_h5_writer_opts *opts, vafm_error *err)
{
    if (!out || !path) {
        vafm_h5i_err(err, VAFM_EINVAL, "", "vafm_h5_writer_open: no %s given", out ? "path" : "output pointer");
        return VAFM_EINVAL;
    }
    *out = NULL;
    if (!s_has_suffix(path, ".h5")) {
        vafm_h5i_err(err, VAFM_EINVAL, "path", "%s: the file name must end in .h5 (afmformats recognises the format by it)",
                     path);
        return VAFM_EINVAL;
    }
    vafm_h5_writer_opts o;
    if (opts)
        o = *opts;
    else
        vafm_h5_writer_opts_default(&o);
    if (o.gzip_level < 0 || o.gzip_level > 9) {
        vafm_h5i_err(err, VAFM_EINVAL, "gzip_level", "gzip_level is %d, allowed 0 (off) to 9", o.gzip_level);
        return VAFM_EINVAL;
    }
    vafm_h5_writer *w = calloc(1, sizeof *w);
    if (!w || !(w->path = strdup(path))) {
        free(w);
        vafm_h5i_err(err, VAFM_ENOMEM, "", "%s: out of memory", path);
        return VAFM_ENOMEM;
    }
    w->tag = S_TAG;
    w->file = -1;
    w->o = o;
    vafm_h5i_quiet q;
    vafm_h5i_quiet_begin(&q);
    int rc = o.resume ? vafm_h5i_writer_resume(w, err) : s_create(w, err);
    vafm_h5i_quiet_end(&q);
    if (rc) {
        vafm_h5_writer_destroy(&w);
        return rc;
    }
    *out = w;
    return 0;
}

/* ---- provenance ----------------------------------------------------------------------------------- */

static int s_json_list(char *buf, size_t len, size_t *pos, const char *name, const double *v, size_t n)
{
    int k = snprintf(buf + *pos, len - *pos, "%s\"%s\": [", *pos > 1 ? ", " : "", name);
    if (k < 0 || (size_t)k >= len - *pos)
        return -1;
    *pos += (size_t)k;
    for (size_t i = 0; i < n; i++) {
        k = snprintf(buf + *pos, len - *pos, "%s%.17g", i ? ", " : "", v[i]);
        if (k < 0 || (size_t)k >= len - *pos)
            return -1;
        *pos += (size_t)k;
    }
    k = snprintf(buf + *pos, len - *pos, "]");
    if (k < 0 || (size_t)k >= len - *pos)
        return -1;
    *pos += (size_t)k;
    return 0;
}

static int s_grid_json(const vafm_campaign_spec *g, char *buf, size_t len)
{
    size_t pos = 0;
    int k = snprintf(buf, len, "{");
    pos = (size_t)k;
    if (!g) {
        k = snprintf(buf + pos, len - pos, "\"points\": 1}");
        return k < 0 || (size_t)k >= len - pos ? -1 : 0;
    }
    if (g->point_fn) { /* a grid given point by point: a force map carries its spec */
        size_t points = vafm_campaign_points(g);
        k = snprintf(buf + pos, len - pos, "\"curves_per_point\": 1, \"points\": %zu, \"curves\": %zu%s%s}", points,
                     points, g->map_json ? ", \"map\": " : "", g->map_json ? g->map_json : "");
        return k < 0 || (size_t)k >= len - pos ? -1 : 0;
    }
    if (s_json_list(buf, len, &pos, "T_K", g->T_K, g->T_K ? g->n_T : 0) ||
        s_json_list(buf, len, &pos, "v_m_per_s", g->v_m_per_s, g->v_m_per_s ? g->n_v : 0) ||
        s_json_list(buf, len, &pos, "k_N_per_m", g->k_N_per_m, g->k_N_per_m ? g->n_k : 0))
        return -1;
    size_t points = vafm_campaign_points(g);
    k = snprintf(buf + pos, len - pos, ", \"curves_per_point\": %llu, \"points\": %zu, \"curves\": %llu}",
                 (unsigned long long)g->curves_per_point, points,
                 (unsigned long long)(g->curves_per_point * (uint64_t)points));
    return k < 0 || (size_t)k >= len - pos ? -1 : 0;
}

/* Name the first JSON key at which a and b differ: the last key of a that starts at or before the first
 * differing character (the key whose value holds the difference, or the key name that differs: 0.6.1
 * said '?' when the first key's name itself differed). */
static void s_first_diff_key(const char *a, const char *b, char *key, size_t len)
{
    size_t i = 0;
    while (a[i] && a[i] == b[i])
        i++;
    snprintf(key, len, "?");
    for (size_t j = 0; a[j] && j <= i; j++) {
        if (a[j] != '"')
            continue;
        size_t e = j + 1; /* the string's closing quote */
        while (a[e] && a[e] != '"')
            e += a[e] == '\\' && a[e + 1] ? 2 : 1;
        size_t k = a[e] ? e + 1 : e;
        while (a[k] == ' ')
            k++;
        if (a[k] == ':') { /* a key */
            size_t m = e - (j + 1) < len - 1 ? e - (j + 1) : len - 1;
            memcpy(key, a + j + 1, m);
            key[m] = 0;
        }
        if (!a[e])
            break;
        j = e;
    }
}

/* A resumed file's stored scene and grid against the caller's (JSON texts). @return 0 or VAFM_EINVAL
 * naming the first differing key. */
static int s_prov_compare(const char *path, const char *stored_scene, const char *stored_grid, const char *sj,
                          const char *gj, vafm_error *err)
{
    const char *which = NULL, *a = NULL, *b = NULL;
    if (!stored_scene || strcmp(stored_scene, sj)) {
        which = "scene";
        a = stored_scene ? stored_scene : "";
        b = sj;
    } else if (!stored_grid || strcmp(stored_grid, gj)) {
        which = "grid";
        a = stored_grid ? stored_grid : "";
        b = gj;
    }
    if (!which)
        return 0;
    char key[64];
    s_first_diff_key(a, b, key, sizeof key);
    if (!strcmp(key, "values_hash")) { /* vafm/map.h: a measured grid's values, not named by any other key */
        vafm_h5i_err(err, VAFM_EINVAL, key, "%s: the map's sample grid (--sample) holds other values than the one the "
                     "file was written with (its values_hash differs); resume needs the same sample", path);
        return VAFM_EINVAL;
    }
    vafm_h5i_err(err, VAFM_EINVAL, key,
                 "%s: the %s differs from the one the file was written with (first at '%s'); resume needs the same "
                 "campaign", path, which, key);
    return VAFM_EINVAL;
}

int vafm_h5_provenance_check(const vafm_params *scene, const vafm_campaign_spec *grid, vafm_error *err)
{
    char *sj = malloc(S_JSON_MAX), *gj = malloc(S_JSON_MAX);
    int rc = 0;
    if (!sj || !gj) {
        vafm_h5i_err(err, rc = VAFM_ENOMEM, "", "out of memory");
    } else if (scene && vafm_params_to_json(scene, sj, S_JSON_MAX) < 0) {
        vafm_h5i_err(err, rc = VAFM_EINVAL, "scene", "the scene does not fit in %d bytes of JSON", S_JSON_MAX);
    } else if (s_grid_json(grid, gj, S_JSON_MAX)) {
        /* name the longest list: the one to shorten */
        const char *f = "grid";
        size_t n = 0;
        if (grid && grid->T_K && grid->n_T > n)
            f = "T_K", n = grid->n_T;
        if (grid && grid->v_m_per_s && grid->n_v > n)
            f = "v_m_per_s", n = grid->n_v;
        if (grid && grid->k_N_per_m && grid->n_k > n)
            f = "k_N_per_m", n = grid->n_k;
        vafm_h5i_err(err, rc = VAFM_EINVAL, f,
                     "the grid's lists (T_K %zu, v_m_per_s %zu, k_N_per_m %zu values) do not fit in the %d bytes of "
                     "the file's 'vafm grid' (about 2500 values in all); %s has the most", grid ? grid->n_T : 0,
                     grid ? grid->n_v : 0, grid ? grid->n_k : 0, S_JSON_MAX, f);
    }
    free(sj);
    free(gj);
    return rc;
}

int vafm_h5_resume_check(const char *path, const vafm_params *scene, const vafm_campaign_spec *grid, vafm_error *err)
{
    return vafm_h5_resume_check_segments(path, scene, grid, NULL, err);
}

int vafm_h5_resume_check_segments(const char *path, const vafm_params *scene, const vafm_campaign_spec *grid,
                                  const char *segments_json, vafm_error *err)
{
    if (!path || !scene) {
        vafm_h5i_err(err, VAFM_EINVAL, "", "vafm_h5_resume_check: no path or scene given");
        return VAFM_EINVAL;
    }
    vafm_h5_reader *r = NULL;
    int rc = vafm_h5_reader_open(&r, path, err);
    if (rc)
        return rc;
    vafm_h5_provenance pv;
    vafm_h5_reader_provenance(r, &pv);
    char *sj = malloc(S_JSON_MAX), *gj = malloc(S_JSON_MAX);
    if (!sj || !gj)
        vafm_h5i_err(err, rc = VAFM_ENOMEM, "", "%s: out of memory", path);
    else if (!pv.is_vafm || pv.format_major != VAFM_H5_FORMAT_MAJOR)
        vafm_h5i_err(err, rc = VAFM_EFORMAT, "/", "%s: cannot be resumed: not a vafm file of format %d.x", path,
                     VAFM_H5_FORMAT_MAJOR);
    else if (pv.format_minor != (pv.segments_json ? VAFM_H5_FORMAT_MINOR_SEGMENTS : VAFM_H5_FORMAT_MINOR) &&
             (segments_json || pv.format_minor != VAFM_H5_FORMAT_MINOR_CURVE_SEGMENTS))
        vafm_h5i_err(err, rc = VAFM_EFORMAT, "/", "%s: cannot be resumed: written in format %d.%d, this vafm writes "
                     "%d.%d (%d.%d with a segment list); resume it with the vafm version that wrote it", path,
                     pv.format_major, pv.format_minor, VAFM_H5_FORMAT_MAJOR, VAFM_H5_FORMAT_MINOR, VAFM_H5_FORMAT_MAJOR,
                     VAFM_H5_FORMAT_MINOR_SEGMENTS);
    else if (!pv.segments_json != !segments_json || (segments_json && strcmp(pv.segments_json, segments_json)))
        vafm_h5i_err(err, rc = VAFM_EINVAL, "segments", "%s: cannot be resumed: %s", path,
                     !pv.segments_json ? "the file holds no segment list ('" VAFM_H5I_A_SEGMENTS "'), this run has one"
                     : !segments_json ? "the file holds a segment list ('" VAFM_H5I_A_SEGMENTS "'), this run has none"
                                      : "this run's segment list differs from the file's ('" VAFM_H5I_A_SEGMENTS "')");
    else if (vafm_params_to_json(scene, sj, S_JSON_MAX) < 0 || s_grid_json(grid, gj, S_JSON_MAX))
        vafm_h5i_err(err, rc = VAFM_EINVAL, "", "%s: the scene or grid does not fit in %d bytes of JSON", path,
                     S_JSON_MAX);
    else if (pv.scene_json) /* a file without provenance yet takes the caller's */
        rc = s_prov_compare(path, pv.scene_json, pv.grid_json, sj, gj, err);
    free(sj);
    free(gj);
    vafm_h5_reader_destroy(&r);
    return rc;
}

int vafm_h5_writer_set_provenance(vafm_h5_writer *w, const vafm_params *scene, const vafm_campaign_spec *grid,
                                  vafm_error *err)
{
    if (!w || w->tag != S_TAG || !scene) {
        vafm_h5i_err(err, VAFM_EINVAL, "", "vafm_h5_writer_set_provenance: no writer or scene given");
        return VAFM_EINVAL;
    }
    char *sj = malloc(S_JSON_MAX), *gj = malloc(S_JSON_MAX);
    int rc = 0;
    if (!sj || !gj) {
        vafm_h5i_err(err, rc = VAFM_ENOMEM, "", "%s: out of memory", w->path);
        goto done;
    }
    if (vafm_params_to_json(scene, sj, S_JSON_MAX) < 0 || s_grid_json(grid, gj, S_JSON_MAX)) {
        vafm_h5i_err(err, rc = VAFM_EINVAL, "", "%s: the scene or grid does not fit in %d bytes of JSON", w->path,
                     S_JSON_MAX);
        goto done;
    }
    if (w->has_prov) { /* resume: the run must continue the same campaign */
        if (w->segs && !w->segs_given)
            vafm_h5i_err(err, rc = VAFM_EINVAL, "segments", "%s: cannot be resumed: the file holds a segment list ('"
                         VAFM_H5I_A_SEGMENTS "'), this run has none", w->path);
        else
            rc = s_prov_compare(w->path, w->scene, w->grid, sj, gj, err);
        goto done;
    }
    if (w->count > 0) {
        vafm_h5i_err(err, rc = VAFM_ESTATE, "", "%s: provenance must be set before the first curve", w->path);
        goto done;
    }
    char iso[32];
    s_now(NULL, NULL, iso);
    vafm_h5i_quiet q;
    vafm_h5i_quiet_begin(&q);
    if (vafm_h5i_put_str(w->file, VAFM_H5I_A_SCENE, sj) || vafm_h5i_put_str(w->file, VAFM_H5I_A_GRID, gj) ||
        vafm_h5i_put_u64(w->file, VAFM_H5I_A_SEED, scene->seed) ||
        vafm_h5i_put_str(w->file, VAFM_H5I_A_CREATED, iso) || H5Fflush(w->file, H5F_SCOPE_GLOBAL) < 0) {
        vafm_h5i_err_hdf5(err, rc = VAFM_EIO, "/", "%s: provenance attributes cannot be written", w->path);
    } else {
        w->has_prov = 1;
        free(w->scene);
        free(w->grid);
        w->scene = sj;
        w->grid = gj;
        sj = gj = NULL;
    }
    vafm_h5i_quiet_end(&q);
done:
    free(sj);
    free(gj);
    return rc;
}

int vafm_h5_writer_set_segments(vafm_h5_writer *w, const char *json, vafm_error *err)
{
    if (!w || w->tag != S_TAG || !json) {
        vafm_h5i_err(err, VAFM_EINVAL, "segments", "vafm_h5_writer_set_segments: no writer or list given");
        return VAFM_EINVAL;
    }
    int n = vafm_h5i_segments_count(json);
    if (n < 1 || strlen(json) >= S_JSON_MAX) {
        vafm_h5i_err(err, VAFM_EINVAL, "segments", "%s: a segment list is a JSON object {\"segments\": [...]} of 1 to %d "
                     "objects, at most %d bytes", w->path, VAFM_H5_SEGMENTS_MAX, S_JSON_MAX - 1);
        return VAFM_EINVAL;
    }
    if (w->o.resume && (w->has_prov || w->segs)) { /* the stored list, if any, was read by the resume */
        if (!w->segs || strcmp(w->segs, json)) {
            vafm_h5i_err(err, VAFM_EINVAL, "segments", "%s: cannot be resumed: %s", w->path,
                         w->segs ? "this run's segment list differs from the file's ('" VAFM_H5I_A_SEGMENTS "')"
                                 : "the file holds no segment list ('" VAFM_H5I_A_SEGMENTS "'), this run has one");
            return VAFM_EINVAL;
        }
        w->segs_given = 1;
        return 0;
    }
    if (w->has_prov || w->count > 0 || w->segs) {
        vafm_h5i_err(err, VAFM_ESTATE, "segments", "%s: the segment list must be set once, before the provenance and "
                     "the first curve", w->path);
        return VAFM_ESTATE;
    }
    char *copy = strdup(json);
    if (!copy) {
        vafm_h5i_err(err, VAFM_ENOMEM, "", "%s: out of memory", w->path);
        return VAFM_ENOMEM;
    }
    char ver[32];
    snprintf(ver, sizeof ver, "%d.%d", VAFM_H5_FORMAT_MAJOR, VAFM_H5_FORMAT_MINOR_SEGMENTS);
    vafm_h5i_quiet q;
    vafm_h5i_quiet_begin(&q);
    int rc = 0;
    if (vafm_h5i_put_str(w->file, VAFM_H5I_A_SEGMENTS, json) || vafm_h5i_put_str(w->file, VAFM_H5I_A_FORMAT, ver) ||
        H5Fflush(w->file, H5F_SCOPE_GLOBAL) < 0) {
        vafm_h5i_err_hdf5(err, rc = VAFM_EIO, "/", "%s: the segment list cannot be written", w->path);
        free(copy);
    } else {
        w->segs = copy;
        w->nsegs = n;
        w->segs_given = 1;
        w->minor = VAFM_H5_FORMAT_MINOR_SEGMENTS;
    }
    vafm_h5i_quiet_end(&q);
    return rc;
}

int vafm_h5_writer_set_curve_segments(vafm_h5_writer *w, const char *json, vafm_error *err)
{
    if (!w || w->tag != S_TAG) {
        vafm_h5i_err(err, VAFM_EINVAL, "segments", "vafm_h5_writer_set_curve_segments: no writer given");
        return VAFM_EINVAL;
    }
    free(w->cseg);
    w->cseg = NULL;
    w->ncseg = 0;
    if (!json)
        return 0;
    int n = vafm_h5i_segments_count(json);
    if (n < 1 || strlen(json) >= S_JSON_MAX) {
        vafm_h5i_err(err, VAFM_EINVAL, "segments", "%s: a segment list is a JSON object {\"segments\": [...]} of 1 to %d "
                     "objects, at most %d bytes", w->path, VAFM_H5_SEGMENTS_MAX, S_JSON_MAX - 1);
        return VAFM_EINVAL;
    }
    if (w->segs) {
        vafm_h5i_err(err, VAFM_ESTATE, "segments", "%s: the file's curves all run one list ('" VAFM_H5I_A_SEGMENTS
                     "', format 1.%d); a curve of its own list needs a file without one", w->path,
                     VAFM_H5_FORMAT_MINOR_SEGMENTS);
        return VAFM_ESTATE;
    }
    if (!(w->cseg = strdup(json))) {
        vafm_h5i_err(err, VAFM_ENOMEM, "", "%s: out of memory", w->path);
        return VAFM_ENOMEM;
    }
    w->ncseg = n;
    return 0;
}

/* ---- appending curves ----------------------------------------------------------------------------- */

/* The "segment count" curve c gets: a file with a list: the list's length (−1 asks for it). */
static int64_t s_seg_count(const vafm_h5_writer *w, const vafm_h5_curve *c)
{
    int list = w->nsegs ? w->nsegs : w->ncseg; /* the file's list, or the curve's own */
    return list && c->meta.segment_count < 0 ? list : c->meta.segment_count;
}

static int s_check_curve(const vafm_h5_writer *w, const vafm_h5_curve *c, const vafm_h5_truth *truth,
                         vafm_error *err)
{
    const char *p = w->path;
    unsigned long long g = (unsigned long long)w->count;
    int64_t sc = s_seg_count(w, c);
    if (w->ncseg && sc != w->ncseg) {
        vafm_h5i_err(err, VAFM_EINVAL, "segment count", "%s: curve %llu: 'segment count' is %lld, the curve's segment "
                     "list has %d (hdf5.md V7)", p, g, (long long)sc, w->ncseg);
        return VAFM_EINVAL;
    }
    if (!w->ncseg && (w->nsegs ? sc != w->nsegs : w->has_prov && sc >= 0 && sc != 2)) {
        if (w->nsegs)
            vafm_h5i_err(err, VAFM_EINVAL, "segment count", "%s: curve %llu: 'segment count' is %lld, the file's segment "
                         "list has %d (hdf5.md V6)", p, g, (long long)sc, w->nsegs);
        else
            vafm_h5i_err(err, VAFM_EINVAL, "segment count", "%s: curve %llu: 'segment count' is %lld in a file without a "
                         "segment list (force-distance: 2; a list: vafm_h5_writer_set_segments, hdf5.md V2)", p, g,
                         (long long)sc);
        return VAFM_EINVAL;
    }
    if (!c->force_N || !c->segment || !(c->height_measured_m || c->height_piezo_m)) {
        vafm_h5i_err(err, VAFM_EINVAL, !c->force_N ? "force" : !c->segment ? "segment" : "height (measured)",
                     "%s: curve %llu: force, segment and a height are required", p, g);
        return VAFM_EINVAL;
    }
    if (c->n < 1 || c->n > S_MAX_SAMPLES) {
        vafm_h5i_err(err, VAFM_EINVAL, "n", "%s: curve %llu: %zu samples (allowed 1 to %zu)", p, g, c->n, S_MAX_SAMPLES);
        return VAFM_EINVAL;
    }
    size_t at = 0;
    for (int i = 0; i < VAFM_H5I_NCHAN; i++) {
        const vafm_h5i_chan *ch = &vafm_h5i_chans[i];
        const void *data = *(const void *const *)((const char *)c + ch->offset);
        if (!data)
            continue;
        const char *rule = ch->is_segment ? vafm_h5i_rule_segment(data, c->n, s_seg_count(w, c), w->nsegs > 0 || w->ncseg > 0, &at)
                           : i == VAFM_H5I_TIME ? vafm_h5i_rule_time(data, c->n, &at)
                                                : vafm_h5i_rule_finite(data, c->n, &at);
        if (rule) {
            vafm_h5i_err(err, VAFM_EINVAL, ch->name, "%s: curve %llu: '%s' at sample %zu: %s", p, g, ch->name, at, rule);
            return VAFM_EINVAL;
        }
    }
    const vafm_h5_meta *m = &c->meta;
    if (c->tip_position_m) {
        const double *hm = c->height_measured_m ? c->height_measured_m : NULL;
        if (!hm) {
            vafm_h5i_err(err, VAFM_EINVAL, "tip position",
                         "%s: curve %llu: tip position needs 'height (measured)' (tip = height (measured) + force/k)", p, g);
            return VAFM_EINVAL;
        }
        const char *rule = vafm_h5i_rule_tip(c->tip_position_m, hm, c->force_N, m->spring_constant_N_per_m, c->n, &at);
        if (rule) {
            vafm_h5i_err(err, VAFM_EINVAL, "tip position", "%s: curve %llu: 'tip position' at sample %zu: %s", p, g, at,
                         rule);
            return VAFM_EINVAL;
        }
    }
    for (int i = 0; i < vafm_h5i_nkeys; i++) {
        const vafm_h5i_key *k = &vafm_h5i_keys[i];
        const char *f = (const char *)m + k->offset;
        if (k->kind == VAFM_H5I_REAL) {
            double v = *(const double *)f;
            if (!isnan(v) && !isfinite(v)) {
                vafm_h5i_err(err, VAFM_EINVAL, k->name, "%s: curve %llu: '%s' is infinite", p, g, k->name);
                return VAFM_EINVAL;
            }
        } else if (k->kind == VAFM_H5I_INT) {
            int64_t v = *(const int64_t *)f;
            if (v < -1) {
                vafm_h5i_err(err, VAFM_EINVAL, k->name, "%s: curve %llu: '%s' is %lld (−1 absent, else ≥ 0)", p, g,
                             k->name, (long long)v);
                return VAFM_EINVAL;
            }
        }
    }
    if (m->point_count >= 0 && (uint64_t)m->point_count != (uint64_t)c->n) {
        vafm_h5i_err(err, VAFM_EINVAL, "point count", "%s: curve %llu: 'point count' %lld differs from the %zu samples", p,
                     g, (long long)m->point_count, c->n);
        return VAFM_EINVAL;
    }
    if (m->imaging_mode && strcmp(m->imaging_mode, "force-distance")) {
        vafm_h5i_err(err, VAFM_EINVAL, "imaging mode", "%s: curve %llu: imaging mode '%s' (vafm writes force-distance)", p,
                     g, m->imaging_mode);
        return VAFM_EINVAL;
    }
    if (m->feedback_mode && strcmp(m->feedback_mode, "contact") && strcmp(m->feedback_mode, "force-modulation")) {
        vafm_h5i_err(err, VAFM_EINVAL, "feedback mode",
                     "%s: curve %llu: feedback mode '%s' (afmformats knows 'contact' and 'force-modulation')", p, g,
                     m->feedback_mode);
        return VAFM_EINVAL;
    }
    if (m->date && !vafm_h5i_date_ok(m->date)) {
        vafm_h5i_err(err, VAFM_EINVAL, "date", "%s: curve %llu: date '%s' is not YYYY-MM-DD", p, g, m->date);
        return VAFM_EINVAL;
    }
    if (m->time && !vafm_h5i_time_ok(m->time)) {
        vafm_h5i_err(err, VAFM_EINVAL, "time", "%s: curve %llu: time '%s' is not HH:MM:SS[.fraction]", p, g, m->time);
        return VAFM_EINVAL;
    }
    if (w->has_prov && !truth) {
        vafm_h5i_err(err, VAFM_EINVAL, "truth", "%s: curve %llu: a file with vafm provenance needs each curve's ground truth",
                     p, g);
        return VAFM_EINVAL;
    }
    if (truth && truth->result.index != w->count) {
        vafm_h5i_err(err, VAFM_EINVAL, "truth",
                     "%s: curve %llu: the ground truth is of curve %llu (curves are appended in index order)", p, g,
                     (unsigned long long)truth->result.index);
        return VAFM_EINVAL;
    }
    return 0;
}

static int s_write_channel(vafm_h5_writer *w, hid_t g, const vafm_h5i_chan *ch, const void *data, size_t n)
{
    hsize_t dim = n;
    hid_t sp = H5Screate_simple(1, &dim, NULL), dcpl = H5Pcreate(H5P_DATASET_CREATE), dapl = -1, d = -1;
    int rc = -1;
    if (sp < 0 || dcpl < 0)
        goto done;
    /* no fill values: every element is written right away */
    if (H5Pset_fill_time(dcpl, H5D_FILL_TIME_NEVER) < 0)
        goto done;
    if (w->o.fletcher32 || w->o.gzip_level) {
        if (H5Pset_chunk(dcpl, 1, &dim) < 0)
            goto done;
        if (w->o.gzip_level && (H5Pset_shuffle(dcpl) < 0 || H5Pset_deflate(dcpl, (unsigned)w->o.gzip_level) < 0))
            goto done;
        if (w->o.fletcher32 && H5Pset_fletcher32(dcpl) < 0)
            goto done;
    }
    /* no chunk cache: the one chunk is written once, straight through the filters */
    dapl = H5Pcreate(H5P_DATASET_ACCESS);
    if (dapl < 0 || H5Pset_chunk_cache(dapl, 0, 0, 1.0) < 0)
        goto done;
    d = H5Dcreate2(g, ch->name, ch->is_segment ? H5T_STD_U8LE : H5T_IEEE_F64LE, sp, H5P_DEFAULT, dcpl, dapl);
    if (d < 0)
        goto done;
    if (H5Dwrite(d, ch->is_segment ? H5T_NATIVE_UINT8 : H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0)
        goto done;
    if (vafm_h5i_put_str(d, "unit", ch->unit))
        goto done;
    rc = 0;
done:
    if (d >= 0 && H5Dclose(d) < 0)
        rc = -1;
    VAFM_H5I_CLOSE(dapl, dcpl, sp);
    return rc;
}

static int s_write_meta(vafm_h5_writer *w, hid_t g, const vafm_h5_curve *c)
{
    vafm_h5_meta m = c->meta;
    char date[16], tod[16];
    if (!m.imaging_mode)
        m.imaging_mode = "force-distance";
    m.point_count = (int64_t)c->n;
    m.segment_count = s_seg_count(w, c);
    if (w->o.stamp_time && !m.date && !m.time) {
        s_now(date, tod, NULL);
        m.date = date;
        m.time = tod;
    }
    for (int i = 0; i < vafm_h5i_nkeys; i++) {
        const vafm_h5i_key *k = &vafm_h5i_keys[i];
        const char *f = (const char *)&m + k->offset;
        int r = 0;
        if (k->kind == VAFM_H5I_STR) {
            const char *s = *(const char *const *)f;
            if (s)
                r = vafm_h5i_put_str(g, k->name, s);
        } else if (k->kind == VAFM_H5I_REAL) {
            double v = *(const double *)f;
            if (!isnan(v))
                r = vafm_h5i_put_f64(g, k->name, v);
        } else {
            int64_t v = *(const int64_t *)f;
            if (v >= 0)
                r = vafm_h5i_put_i64(g, k->name, v);
        }
        if (r)
            return -1;
    }
    return 0;
}

static int s_append(vafm_h5_writer *w, const vafm_h5_curve *c, const vafm_h5_truth *truth, vafm_error *err);

int vafm_h5_writer_append(vafm_h5_writer *w, const vafm_h5_curve *c, const vafm_h5_truth *truth, vafm_error *err)
{
    if (!w || w->tag != S_TAG || !c) {
        vafm_h5i_err(err, VAFM_EINVAL, "", "vafm_h5_writer_append: no writer or curve given");
        return VAFM_EINVAL;
    }
    int rc = s_append(w, c, truth, err);
    free(w->cseg); /* a curve's own list is for one append */
    w->cseg = NULL;
    w->ncseg = 0;
    return rc;
}

/* The curve's own list (format 1.3): its root attribute, and the version at the file's first one; written with
 * the group, so that the same flush makes them durable. @return 0 or -1. */
static int s_write_curve_segments(vafm_h5_writer *w, const char *group)
{
    char name[64], ver[32];
    snprintf(name, sizeof name, VAFM_H5I_A_CURVE_SEGMENTS "%s", group);
    snprintf(ver, sizeof ver, "%d.%d", VAFM_H5_FORMAT_MAJOR, VAFM_H5_FORMAT_MINOR_CURVE_SEGMENTS);
    if (vafm_h5i_put_str(w->file, name, w->cseg))
        return -1;
    if (w->minor != VAFM_H5_FORMAT_MINOR_CURVE_SEGMENTS) {
        if (vafm_h5i_put_str(w->file, VAFM_H5I_A_FORMAT, ver))
            return -1;
        w->minor = VAFM_H5_FORMAT_MINOR_CURVE_SEGMENTS;
    }
    return 0;
}

static int s_append(vafm_h5_writer *w, const vafm_h5_curve *c, const vafm_h5_truth *truth, vafm_error *err)
{
    int rc = s_check_curve(w, c, truth, err);
    if (rc)
        return rc;
    if (truth && vafm_h5i_writer_rows_reserve(w, w->nrows + 1)) {
        vafm_h5i_err(err, VAFM_ENOMEM, "", "%s: out of memory", w->path);
        return VAFM_ENOMEM;
    }
    char name[24];
    snprintf(name, sizeof name, "%llu", (unsigned long long)w->count);
    vafm_h5i_quiet q;
    vafm_h5i_quiet_begin(&q);
    hid_t g = H5Gcreate2(w->file, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    int ok = g >= 0;
    for (int i = 0; ok && i < VAFM_H5I_NCHAN; i++) {
        const vafm_h5i_chan *ch = &vafm_h5i_chans[i];
        const void *data = *(const void *const *)((const char *)c + ch->offset);
        if (data)
            ok = !s_write_channel(w, g, ch, data, c->n);
    }
    ok = ok && !s_write_meta(w, g, c);
    ok = ok && (!w->cseg || !s_write_curve_segments(w, name));
    char why[160] = "";
    if (!ok)
        vafm_h5i_reason(why, sizeof why); /* before H5Gclose clears the stack */
    if (g >= 0 && H5Gclose(g) < 0) {
        if (ok)
            vafm_h5i_reason(why, sizeof why);
        ok = 0;
    }
    if (!ok) {
        vafm_h5i_err(err, rc = VAFM_EIO, name, "%s: curve group '%s' cannot be written%s%s%s", w->path, name,
                     why[0] ? (vafm_h5i_io_errno ? ": " : " (HDF5: ") : "", why,
                     why[0] && !vafm_h5i_io_errno ? ")" : "");
        if (g >= 0)
            H5Ldelete(w->file, name, H5P_DEFAULT); /* leave no half-written curve behind */
        if (w->cseg) {
            char an[64];
            snprintf(an, sizeof an, VAFM_H5I_A_CURVE_SEGMENTS "%s", name);
            if (H5Aexists(w->file, an) > 0)
                H5Adelete(w->file, an);
        }
    } else {
        if (truth)
            vafm_h5i_row_from_truth(&w->rows[w->nrows++], w->count, truth);
        w->count++;
    }
    vafm_h5i_quiet_end(&q);
    return rc;
}

int vafm_h5_writer_set_note(vafm_h5_writer *w, const char *name, const char *text, vafm_error *err)
{
    if (!w || w->tag != S_TAG || !name || !text) {
        vafm_h5i_err(err, VAFM_EINVAL, "", "vafm_h5_writer_set_note: no writer, name or text given");
        return VAFM_EINVAL;
    }
    static const char *const own[] = { VAFM_H5I_A_FORMAT, VAFM_H5I_A_SCENE, VAFM_H5I_A_GRID, VAFM_H5I_A_SEED,
                                       VAFM_H5I_A_CREATED, VAFM_H5I_A_TRUTH };
    int bad = strncmp(name, "vafm ", 5) != 0 || !strncmp(name, VAFM_H5I_A_TRUTH_PART, strlen(VAFM_H5I_A_TRUTH_PART)) ||
              !strncmp(name, VAFM_H5I_A_SEGMENTS, strlen(VAFM_H5I_A_SEGMENTS));
    for (size_t i = 0; i < sizeof own / sizeof own[0]; i++)
        bad |= !strcmp(name, own[i]);
    if (bad) {
        vafm_h5i_err(err, VAFM_EINVAL, "name", "%s: '%s' is not a free note name (\"vafm ...\", not one of the "
                     "provenance attributes)", w->path, name);
        return VAFM_EINVAL;
    }
    vafm_h5i_quiet q;
    vafm_h5i_quiet_begin(&q);
    int rc = vafm_h5i_put_str(w->file, name, text) ? VAFM_EIO : 0;
    if (rc)
        vafm_h5i_err_hdf5(err, rc, "/", "%s: root attribute '%s' cannot be written", w->path, name);
    vafm_h5i_quiet_end(&q);
    return rc;
}

int vafm_h5_writer_flush(vafm_h5_writer *w, vafm_error *err)
{
    if (!w || w->tag != S_TAG) {
        vafm_h5i_err(err, VAFM_EINVAL, "", "vafm_h5_writer_flush: no writer given");
        return VAFM_EINVAL;
    }
    int rc = 0;
    vafm_h5i_quiet q;
    vafm_h5i_quiet_begin(&q);
    if (w->nrows > w->rows_in_file) {
        char name[96];
        snprintf(name, sizeof name, VAFM_H5I_A_TRUTH_PART "%llu", (unsigned long long)w->rows[w->rows_in_file].curve);
        if (s_write_rows(w->file, name, w->rows + w->rows_in_file, w->nrows - w->rows_in_file)) {
            vafm_h5i_err_hdf5(err, rc = VAFM_EIO, "/", "%s: ground-truth rows cannot be written", w->path);
        } else {
            w->rows_in_file = w->nrows;
            w->parts_in_file = 1;
        }
    }
    if (!rc && H5Fflush(w->file, H5F_SCOPE_GLOBAL) < 0)
        vafm_h5i_err_hdf5(err, rc = VAFM_EIO, "", "%s: flush failed", w->path);
    vafm_h5i_quiet_end(&q);
    return rc;
}

uint64_t vafm_h5_writer_count(const vafm_h5_writer *w)
{
    return w ? w->count : 0;
}

int vafm_h5_writer_close(vafm_h5_writer **wp, vafm_error *err)
{
    if (!wp || !*wp)
        return 0;
    vafm_h5_writer *w = *wp;
    int rc = 0;
    vafm_h5i_quiet q;
    vafm_h5i_quiet_begin(&q);
    if ((w->parts_in_file || w->nrows > w->rows_in_file) && vafm_h5i_writer_merge_rows(w))
        vafm_h5i_err_hdf5(err, rc = VAFM_EIO, "/", "%s: the ground-truth table cannot be written", w->path);
    if (H5Fflush(w->file, H5F_SCOPE_GLOBAL) < 0 && !rc)
        vafm_h5i_err_hdf5(err, rc = VAFM_EIO, "", "%s: flush failed", w->path);
    if (H5Fclose(w->file) < 0 && !rc)
        vafm_h5i_err_hdf5(err, rc = VAFM_EIO, "", "%s: close failed", w->path);
    w->file = -1;
    vafm_h5i_quiet_end(&q);
    vafm_h5_writer_destroy(wp);
    return rc;
}

int vafm_h5_writer_truth(const vafm_h5_writer *w, uint64_t curve, vafm_h5_truth *out)
{
    if (!w || !out)
        return VAFM_EINVAL;
    if (curve >= w->nrows || w->rows[curve].curve != curve)
        return VAFM_ENOTFOUND;
    vafm_h5i_truth_from_row(out, &w->rows[curve]);
    return 0;
}
