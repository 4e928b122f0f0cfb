/* SPDX-License-Identifier: MIT */
/*
 * Conformance checker: every rule of protocol/hdf5.md, applied to the raw HDF5 objects with exact types
 * (where the reader is lenient, the checker is not). Rules L* hold for every file of the layout; rules
 * V* for files that carry "vafm format version". The first violation is reported as
 * "[rule] file: object: what is wrong".
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "h5/h5_internal.h"

typedef struct s_ctx {
    const char *path;
    vafm_error *err;
    hid_t file;
    int is_vafm;  /* "vafm format version" present */
    int has_prov; /* "vafm scene" present */
    uint64_t ncurves;
    int64_t *point_count; /* per curve, for V4 */
    double *spring;       /* per curve, for V4 */
    int format_minor;     /* of "vafm format version" */
    int nsegs;            /* segments of "vafm segments" (V6), 0: none */
    int cnsegs;           /* segments of the curve in check's own list ("vafm segments <i>", V7), 0: none */
    uint64_t clists;      /* root attributes "vafm segments <i>" (V7) */
    uint64_t clists_seen; /* of them, those a curve group had */
    int map;              /* the grid is a force map's ("map" in "vafm grid", V5) */
    vafm_h5_meta grid0;   /* curve 0's grid attributes (V5) */
} s_ctx;

/* Refuse under a rule of protocol/hdf5.md: report through vafm_h5i_err, or vafm_h5i_err_hdf5 to append HDF5's
 * reason (its detail is cut shorter, to leave that reason room). */
#define S_FAIL_VIA(report, cap, rule, obj, ...)                                                 \
    do {                                                                                        \
        char m_[cap];                                                                           \
        snprintf(m_, sizeof m_, __VA_ARGS__);                                                   \
        report(x->err, VAFM_EFORMAT, obj, "[%s] %s: %s: %s", rule, x->path, obj, m_);           \
        return VAFM_EFORMAT;                                                                    \
    } while (0)
#define FAIL(rule, obj, ...) S_FAIL_VIA(vafm_h5i_err, 280, rule, obj, __VA_ARGS__)
#define FAIL_H5(rule, obj, ...) S_FAIL_VIA(vafm_h5i_err_hdf5, 240, rule, obj, __VA_ARGS__)

/* A scalar variable-length string attribute; *out (malloc'd) receives its value. */
static int s_vlen_str(s_ctx *x, const char *rule, hid_t loc, const char *obj, const char *name, char **out)
{
    vafm_h5i_val v;
    *out = NULL;
    htri_t ex = H5Aexists(loc, name);
    if (ex < 0) /* a damaged header is not a missing attribute */
        FAIL_H5(rule, obj, "attribute '%s' cannot be looked up (damaged file)", name);
    if (ex == 0)
        FAIL(rule, obj, "attribute '%s' is missing", name);
    if (vafm_h5i_attr_get(loc, name, &v))
        FAIL_H5(rule, obj, "attribute '%s' cannot be read", name);
    int ok = v.cls == H5T_STRING && v.vlen && v.scalar;
    int cls = v.cls, vlen = v.vlen, scalar = v.scalar;
    if (!ok) {
        vafm_h5i_val_free(&v);
        FAIL(rule, obj, "attribute '%s' is %s%s (strings are scalar variable-length strings)", name,
             cls != H5T_STRING ? "not a string" : !vlen ? "a fixed-length string" : "a string",
             cls == H5T_STRING && vlen && !scalar ? " with a non-scalar dataspace" : "");
    }
    *out = v.s;
    return 0;
}

static int s_dataset(s_ctx *x, hid_t g, const char *gname, const char *name, int ci, size_t *n, int *have_n,
                     void **data)
{
    const vafm_h5i_chan *c = &vafm_h5i_chans[ci];
    char obj[96];
    snprintf(obj, sizeof obj, "/%s/%s", gname, name);
    *data = NULL;
    hid_t o = H5Oopen(g, name, H5P_DEFAULT);
    if (o < 0)
        FAIL_H5("L5", obj, "cannot be opened");
    int rc = 0;
    hid_t sp = -1, t = -1;
    char *unit = NULL;
    if (H5Iget_type(o) != H5I_DATASET) {
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L5] %s: %s: is not a dataset (no subgroups in a curve group)",
                     x->path, obj);
        goto done;
    }
    const char *foreign = vafm_h5i_storage_foreign(o); /* before its shape: nothing outside the file is opened */
    if (foreign) {
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L2] %s: %s: is %s", x->path, obj, foreign);
        goto done;
    }
    sp = H5Dget_space(o);
    t = H5Dget_type(o);
    hsize_t dim = 0;
    if (sp < 0 || t < 0 || H5Sget_simple_extent_type(sp) != H5S_SIMPLE || H5Sget_simple_extent_ndims(sp) != 1 ||
        H5Sget_simple_extent_dims(sp, &dim, NULL) != 1) {
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L7] %s: %s: is not a 1-D dataset", x->path, obj);
        goto done;
    }
    if (dim < 1) {
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L7] %s: %s: holds no samples (a channel has at least 1)",
                     x->path, obj);
        goto done;
    }
    if (*have_n && dim != *n) {
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj,
                     "[L7] %s: %s: %llu samples where the group's other channels have %zu (same length)", x->path, obj,
                     (unsigned long long)dim, *n);
        goto done;
    }
    if (dim > VAFM_H5_MAX_SAMPLES) { /* before any allocation: a small file can declare terabytes */
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj,
                     "%s: %s: declares %llu samples, more than a curve may have (%llu, VAFM_H5_MAX_SAMPLES): not read",
                     x->path, obj, (unsigned long long)dim, (unsigned long long)VAFM_H5_MAX_SAMPLES);
        goto done;
    }
    *n = (size_t)dim;
    *have_n = 1;
    hid_t want = c->is_segment ? H5T_STD_U8LE : H5T_IEEE_F64LE;
    if (H5Tequal(t, want) <= 0) {
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L7] %s: %s: datatype is not %s", x->path, obj,
                     c->is_segment ? "uint8 (little-endian)" : "float64 (IEEE, little-endian)");
        goto done;
    }
    if ((rc = s_vlen_str(x, "L8", o, obj, "unit", &unit)))
        goto done;
    if (strcmp(unit, c->unit)) {
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L8] %s: %s: unit is '%s', the layout says '%s'", x->path, obj,
                     unit, c->unit);
        goto done;
    }
    if (vafm_h5i_storage_complete(o, dim)) { /* before the allocation: data that is not there is not read */
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L2] %s: %s: part of the data has no storage (damaged chunk index)",
                     x->path, obj);
        goto done;
    }
    *data = malloc(*n * (c->is_segment ? 1 : 8));
    if (!*data) {
        vafm_h5i_err(x->err, rc = VAFM_ENOMEM, obj, "%s: %s: out of memory", x->path, obj);
        goto done;
    }
    if (H5Dread(o, c->is_segment ? H5T_NATIVE_UINT8 : H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, *data) < 0) {
        vafm_h5i_err_hdf5(x->err, rc = VAFM_EFORMAT, obj, "[L2] %s: %s: data cannot be read (damaged)", x->path, obj);
        goto done;
    }
done:
    if (rc) {
        free(*data);
        *data = NULL;
    }
    free(unit);
    VAFM_H5I_CLOSE(t, sp, o);
    return rc;
}

static int s_group_attrs(s_ctx *x, hid_t g, const char *gname, size_t n, vafm_h5_meta *m, char **strs, int *nstr)
{
    char obj[32];
    snprintf(obj, sizeof obj, "/%s", gname);
    vafm_h5i_names l = { 0 };
    if (H5Aiterate2(g, H5_INDEX_NAME, H5_ITER_NATIVE, NULL, vafm_h5i_attr_cb, &l) < 0) {
        vafm_h5i_names_free(&l);
        FAIL_H5("L2", obj, "attributes cannot be listed");
    }
    int rc = 0;
    for (size_t i = 0; i < l.n && !rc; i++) {
        const vafm_h5i_key *k = vafm_h5i_key_find(l.v[i]);
        if (!k) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj,
                         "[L9] %s: %s: attribute '%s' is not in the layout's list (afmformats fails on unknown keys)",
                         x->path, obj, l.v[i]);
            break;
        }
        char *f = (char *)m + k->offset;
        if (k->kind == VAFM_H5I_STR) {
            char *s = NULL;
            if ((rc = s_vlen_str(x, "L9", g, obj, k->name, &s)))
                break;
            strs[(*nstr)++] = s;
            *(const char **)f = s;
            continue;
        }
        vafm_h5i_val v;
        if (vafm_h5i_attr_get(g, k->name, &v)) {
            vafm_h5i_err_hdf5(x->err, rc = VAFM_EFORMAT, obj, "[L2] %s: %s: attribute '%s' cannot be read", x->path, obj,
                              k->name);
            break;
        }
        vafm_h5i_val_free(&v);
        if (!v.scalar) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L9] %s: %s: attribute '%s' is not scalar", x->path, obj, k->name);
        } else if (k->kind == VAFM_H5I_REAL && !(v.cls == H5T_FLOAT && v.size == 8)) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L9] %s: %s: attribute '%s' is not a float64 number (%s)",
                         x->path, obj, k->name, k->unit);
        } else if (k->kind == VAFM_H5I_INT && v.cls != H5T_INTEGER) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L9] %s: %s: attribute '%s' is not an integer", x->path, obj,
                         k->name);
        } else if (k->kind == VAFM_H5I_REAL && !isfinite(v.d)) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L9] %s: %s: attribute '%s' is not finite", x->path, obj, k->name);
        } else if (k->kind == VAFM_H5I_INT && v.i < 0) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L9] %s: %s: attribute '%s' is negative", x->path, obj, k->name);
        } else if (k->kind == VAFM_H5I_REAL) {
            *(double *)f = v.d;
        } else {
            *(int64_t *)f = v.i;
        }
    }
    vafm_h5i_names_free(&l);
    if (rc)
        return rc;
    if (!m->imaging_mode || strcmp(m->imaging_mode, "force-distance"))
        FAIL("L10", obj, "'imaging mode' is %s%s%s (must be \"force-distance\")", m->imaging_mode ? "'" : "",
             m->imaging_mode ? m->imaging_mode : "missing", m->imaging_mode ? "'" : "");
    if (m->point_count >= 0 && (uint64_t)m->point_count != (uint64_t)n)
        FAIL("L11", obj, "'point count' is %lld, the datasets have %zu samples", (long long)m->point_count, n);
    if (m->date && !vafm_h5i_date_ok(m->date))
        FAIL("L15", obj, "'date' is '%s', not YYYY-MM-DD", m->date);
    if (m->time && !vafm_h5i_time_ok(m->time))
        FAIL("L15", obj, "'time' is '%s', not HH:MM:SS[.fraction]", m->time);
    if (m->feedback_mode && strcmp(m->feedback_mode, "contact") && strcmp(m->feedback_mode, "force-modulation"))
        FAIL("L15", obj, "'feedback mode' is '%s' (afmformats knows contact and force-modulation)", m->feedback_mode);
    if (!isnan(m->spring_constant_N_per_m) && !(m->spring_constant_N_per_m > 0))
        FAIL("L15", obj, "'spring constant' is not positive");
    /* afmformats' map attributes: a shape of whole pixels, an index inside it, a positive size */
    if (m->grid_shape_x == 0 || m->grid_shape_y == 0)
        FAIL("L17", obj, "'grid shape %s' is 0 (a map has at least one pixel)", m->grid_shape_x == 0 ? "x" : "y");
    if (m->grid_shape_x > 0 && m->grid_index_x >= m->grid_shape_x)
        FAIL("L17", obj, "'grid index x' %lld lies outside 'grid shape x' %lld", (long long)m->grid_index_x,
             (long long)m->grid_shape_x);
    if (m->grid_shape_y > 0 && m->grid_index_y >= m->grid_shape_y)
        FAIL("L17", obj, "'grid index y' %lld lies outside 'grid shape y' %lld", (long long)m->grid_index_y,
             (long long)m->grid_shape_y);
    if (!(isnan(m->grid_size_x_m) || m->grid_size_x_m > 0) || !(isnan(m->grid_size_y_m) || m->grid_size_y_m > 0))
        FAIL("L17", obj, "'grid size %s' is not positive", !(isnan(m->grid_size_x_m) || m->grid_size_x_m > 0) ? "x" : "y");
    return 0;
}

/* V5: a vafm force map. Every curve carries the ten map attributes, with curve 0's shape, centre and size;
 * curve i is pixel (i mod nx, i div nx) and sits at the centre of its cell. */
static int s_map_curve(s_ctx *x, const char *obj, uint64_t num, const vafm_h5_meta *m)
{
    if (!x->map)
        return 0;
    if (num == 0)
        x->grid0 = *m;
    const vafm_h5_meta *g = &x->grid0;
    const char *miss = m->grid_shape_x < 0 ? "grid shape x" : m->grid_shape_y < 0 ? "grid shape y"
                       : m->grid_index_x < 0 ? "grid index x" : m->grid_index_y < 0 ? "grid index y"
                       : isnan(m->grid_center_x_m) ? "grid center x" : isnan(m->grid_center_y_m) ? "grid center y"
                       : isnan(m->grid_size_x_m) ? "grid size x" : isnan(m->grid_size_y_m) ? "grid size y"
                       : isnan(m->position_x_m) ? "position x" : isnan(m->position_y_m) ? "position y" : NULL;
    if (miss)
        FAIL("V5", obj, "a vafm map writes '%s' in every curve", miss);
    if (m->grid_shape_x != g->grid_shape_x || m->grid_shape_y != g->grid_shape_y ||
        m->grid_center_x_m != g->grid_center_x_m || m->grid_center_y_m != g->grid_center_y_m ||
        m->grid_size_x_m != g->grid_size_x_m || m->grid_size_y_m != g->grid_size_y_m)
        FAIL("V5", obj, "the grid (shape, center, size) differs from curve 0's");
    if ((uint64_t)m->grid_index_y * (uint64_t)m->grid_shape_x + (uint64_t)m->grid_index_x != num)
        FAIL("V5", obj, "pixel (%lld, %lld) is not curve %llu (curve = grid index y * grid shape x + grid index x)",
             (long long)m->grid_index_x, (long long)m->grid_index_y, (unsigned long long)num);
    double px = m->grid_center_x_m - 0.5 * m->grid_size_x_m +
                ((double)m->grid_index_x + 0.5) * (m->grid_size_x_m / (double)m->grid_shape_x);
    double py = m->grid_center_y_m - 0.5 * m->grid_size_y_m +
                ((double)m->grid_index_y + 0.5) * (m->grid_size_y_m / (double)m->grid_shape_y);
    if (fabs(px - m->position_x_m) > 1e-9 * m->grid_size_x_m || fabs(py - m->position_y_m) > 1e-9 * m->grid_size_y_m)
        FAIL("V5", obj, "'position x|y' (%.9g, %.9g) m is not the centre of its pixel (%.9g, %.9g) m", m->position_x_m,
             m->position_y_m, px, py);
    return 0;
}

/* V7: the curve's own segment list, "vafm segments <num>" (format 1.3), into x->cnsegs (0: none). */
static int s_curve_list(s_ctx *x, const char *gname)
{
    char an[64];
    snprintf(an, sizeof an, VAFM_H5I_A_CURVE_SEGMENTS "%s", gname);
    x->cnsegs = 0;
    if (!x->clists || H5Aexists(x->file, an) <= 0)
        return 0;
    char *s = NULL;
    int rc = s_vlen_str(x, "V7", x->file, "/", an, &s);
    if (rc)
        return rc;
    x->cnsegs = vafm_h5i_segments_count(s);
    free(s);
    if (x->cnsegs < 1)
        FAIL("V7", "/", "'%s' is not a segment list {\"segments\": [1 to %d objects]}", an, VAFM_H5_SEGMENTS_MAX);
    x->clists_seen++;
    return 0;
}

static herr_t s_count_lists(hid_t loc, const char *name, const H5A_info_t *info, void *op)
{
    (void)loc;
    (void)info;
    if (!strncmp(name, VAFM_H5I_A_CURVE_SEGMENTS, strlen(VAFM_H5I_A_CURVE_SEGMENTS)))
        ++*(uint64_t *)op;
    return 0;
}

static int s_group(s_ctx *x, uint64_t num)
{
    char gname[24], obj[32];
    snprintf(gname, sizeof gname, "%llu", (unsigned long long)num);
    snprintf(obj, sizeof obj, "/%s", gname);
    int lrc = s_curve_list(x, gname);
    if (lrc)
        return lrc;
    hid_t g = H5Gopen2(x->file, gname, H5P_DEFAULT);
    if (g < 0)
        FAIL_H5("L4", obj, "curve group cannot be opened");
    int rc = 0;
    vafm_h5i_names l = { 0 };
    void *data[VAFM_H5I_NCHAN] = { 0 };
    char *strs[16];
    int nstr = 0;
    vafm_h5_meta m;
    vafm_h5_meta_default(&m);
    if (H5Literate(g, H5_INDEX_NAME, H5_ITER_NATIVE, NULL, vafm_h5i_link_cb, &l) < 0) {
        vafm_h5i_err_hdf5(x->err, rc = VAFM_EFORMAT, obj, "[L2] %s: %s: objects cannot be listed", x->path, obj);
        goto done;
    }
    if (l.bad) {
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L5] %s: %s: '%s' is a soft or external link", x->path, obj,
                     l.bad_name);
        goto done;
    }
    size_t n = 0;
    int have_n = 0;
    for (size_t i = 0; i < l.n && !rc; i++) {
        int ci = vafm_h5i_chan_find(l.v[i]);
        if (ci < 0) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj,
                         "[L5] %s: %s: object '%s' is not one of the layout's datasets (force, height (measured), "
                         "height (piezo), segment, time, tip position)",
                         x->path, obj, l.v[i]);
            break;
        }
        rc = s_dataset(x, g, gname, l.v[i], ci, &n, &have_n, &data[ci]);
    }
    if (rc)
        goto done;
    static const int required[] = { VAFM_H5I_FORCE, VAFM_H5I_HMEAS, VAFM_H5I_HPIEZO, VAFM_H5I_SEGMENT };
    for (int i = 0; i < 4; i++)
        if (!data[required[i]]) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L6] %s: %s: dataset '%s' is missing", x->path, obj,
                         vafm_h5i_chans[required[i]].name);
            goto done;
        }
    /* V2: no 'tip position' where force is a measured signal (the detector chain, a controller fault):
     * 0.6.1 required it and so failed vafmd's own detector logs */
    if (x->has_prov && !data[VAFM_H5I_TIME]) {
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[V2] %s: %s: vafm writes 'time' in every curve", x->path, obj);
        goto done;
    }
    if ((rc = s_group_attrs(x, g, gname, n, &m, strs, &nstr)))
        goto done;
    size_t at = 0;
    const char *rule;
    for (int i = 0; i < VAFM_H5I_NCHAN; i++) {
        if (!data[i] || vafm_h5i_chans[i].is_segment)
            continue;
        if ((rule = vafm_h5i_rule_finite(data[i], n, &at))) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L16] %s: %s/%s: sample %zu: %s", x->path, obj,
                         vafm_h5i_chans[i].name, at, rule);
            goto done;
        }
    }
    if ((rule = vafm_h5i_rule_segment(data[VAFM_H5I_SEGMENT], n, m.segment_count, x->nsegs > 0 || x->cnsegs > 0, &at))) {
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L12] %s: %s/segment: sample %zu is %u: %s", x->path, obj, at,
                     ((uint8_t *)data[VAFM_H5I_SEGMENT])[at], rule);
        goto done;
    }
    if (data[VAFM_H5I_TIME] && (rule = vafm_h5i_rule_time(data[VAFM_H5I_TIME], n, &at))) {
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L13] %s: %s/time: sample %zu: %s", x->path, obj, at, rule);
        goto done;
    }
    if (data[VAFM_H5I_TIP] && (rule = vafm_h5i_rule_tip(data[VAFM_H5I_TIP], data[VAFM_H5I_HMEAS], data[VAFM_H5I_FORCE],
                                                        m.spring_constant_N_per_m, n, &at))) {
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[L14] %s: %s/tip position: sample %zu: %s", x->path, obj, at, rule);
        goto done;
    }
    if (x->has_prov) {
        const char *miss = isnan(m.spring_constant_N_per_m) ? "spring constant"
                           : m.point_count < 0              ? "point count"
                           : !m.software                    ? "software"
                           : !m.software_version            ? "software version"
                           : m.segment_count < 0            ? "segment count"
                                                            : NULL;
        if (miss) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[V2] %s: %s: vafm writes '%s' in every curve", x->path, obj, miss);
            goto done;
        }
        if (x->nsegs && m.segment_count != x->nsegs) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[V6] %s: %s: 'segment count' is %lld, the file's segment list "
                         "('" VAFM_H5I_A_SEGMENTS "') has %d", x->path, obj, (long long)m.segment_count, x->nsegs);
            goto done;
        }
        if (x->cnsegs && m.segment_count != x->cnsegs) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[V7] %s: %s: 'segment count' is %lld, the curve's segment "
                         "list ('" VAFM_H5I_A_CURVE_SEGMENTS "%s') has %d", x->path, obj, (long long)m.segment_count,
                         gname, x->cnsegs);
            goto done;
        }
        if (!x->nsegs && !x->cnsegs && m.segment_count != 2) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, obj, "[V2] %s: %s: 'segment count' is %lld (force-distance: 2; "
                         "another count needs a segment list, '" VAFM_H5I_A_SEGMENTS "', format 1.%d: V6)", x->path, obj,
                         (long long)m.segment_count, VAFM_H5_FORMAT_MINOR_SEGMENTS);
            goto done;
        }
    }
    if (x->has_prov && (rc = s_map_curve(x, obj, num, &m)))
        goto done;
    if (num < x->ncurves) {
        x->point_count[num] = m.point_count;
        x->spring[num] = m.spring_constant_N_per_m;
    }
done:
    for (int i = 0; i < VAFM_H5I_NCHAN; i++)
        free(data[i]);
    for (int i = 0; i < nstr; i++)
        free(strs[i]);
    vafm_h5i_names_free(&l);
    H5Gclose(g);
    return rc;
}

/* V4: the ground-truth table. */
static int s_truth(s_ctx *x)
{
    char **names = NULL;
    size_t nn = 0;
    if (vafm_h5i_truth_attr_names(x->file, &names, &nn))
        FAIL_H5("L2", "/", "root attributes cannot be listed");
    int rc = 0;
    int nf = vafm_h5i_row_nfields_of(x->format_minor);
    for (size_t i = 0; i < nn && !rc; i++) {
        hid_t t, sp, a = vafm_h5i_attr_open(x->file, names[i], &t, &sp);
        if (t < 0 || sp < 0) {
            vafm_h5i_err_hdf5(x->err, rc = VAFM_EFORMAT, "/", "[V4] %s: /: attribute '%s' cannot be read", x->path,
                              names[i]);
        } else if (H5Tget_class(t) != H5T_COMPOUND || H5Tget_nmembers(t) != nf || H5Sget_simple_extent_ndims(sp) != 1) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, "/",
                         "[V4] %s: /: attribute '%s' is not a 1-D compound table with the %d documented fields", x->path,
                         names[i], nf);
        } else {
            for (int j = 0; j < nf && !rc; j++)
                if (H5Tget_member_index(t, vafm_h5i_row_field(j)) < 0)
                    vafm_h5i_err(x->err, rc = VAFM_EFORMAT, "/", "[V4] %s: /: attribute '%s' lacks the field '%s'",
                                 x->path, names[i], vafm_h5i_row_field(j));
        }
        VAFM_H5I_CLOSE(sp, t, a);
    }
    for (size_t i = 0; i < nn; i++)
        free(names[i]);
    free(names);
    if (rc)
        return rc;
    vafm_h5i_row *rows = NULL;
    size_t nr = 0;
    vafm_error e2;
    if (vafm_h5i_rows_read(x->file, x->path, 0, &rows, &nr, &e2))
        FAIL("V4", "/", "ground truth: %.200s", e2.message);
    if (nr != x->ncurves) {
        free(rows);
        FAIL("V4", "/", "%zu ground-truth rows for %llu curves (one row per curve)", nr, (unsigned long long)x->ncurves);
    }
    for (size_t i = 0; i < nr; i++) {
        const vafm_h5i_row *r = &rows[i];
        char why[160] = "";
        if (r->curve != i)
            snprintf(why, sizeof why, "row %zu is of curve %llu (rows cover curves 0..%llu once)", i,
                     (unsigned long long)r->curve, (unsigned long long)x->ncurves - 1);
        else if ((int64_t)r->samples != x->point_count[i])
            snprintf(why, sizeof why, "curve %zu: 'samples' %llu differs from its 'point count' %lld", i,
                     (unsigned long long)r->samples, (long long)x->point_count[i]);
        else if (r->k_N_per_m != x->spring[i])
            snprintf(why, sizeof why, "curve %zu: k_N_per_m %.17g differs from its 'spring constant' %.17g", i,
                     r->k_N_per_m, x->spring[i]);
        else if (x->format_minor >= 1 && !(r->E_star_Pa >= 0 && isfinite(r->E_star_Pa) && r->gamma_J_per_m2 >= 0 &&
                                           isfinite(r->gamma_J_per_m2) && isfinite(r->surface_height_m)))
            snprintf(why, sizeof why, "curve %zu: E_star_Pa %.6g, gamma_J_per_m2 %.6g, surface_height_m %.6g (E* and "
                     "gamma >= 0, all finite)", i, r->E_star_Pa, r->gamma_J_per_m2, r->surface_height_m);
        if (why[0]) {
            free(rows);
            FAIL("V4", "/", "ground truth: %s", why);
        }
    }
    free(rows);
    return 0;
}

static int s_check(s_ctx *x)
{
    const char *path = x->path;
    size_t len = strlen(path);
    if (len < 4 || strcmp(path + len - 3, ".h5"))
        FAIL("L1", "", "the file name does not end in .h5");
    struct stat st;
    if (stat(path, &st)) {
        vafm_h5i_err(x->err, VAFM_EIO, "", "[L2] %s: cannot be opened", path);
        return VAFM_EIO;
    }
    int crc = vafm_h5i_check_path(path, 0, x->err);
    if (crc)
        return crc;
    if (H5Fis_hdf5(path) <= 0)
        FAIL("L2", "", "not an HDF5 file");
    hid_t fapl = H5Pcreate(H5P_FILE_ACCESS);
    if (fapl >= 0 && vafm_h5i_fapl_journal(fapl)) {
        H5Pclose(fapl);
        fapl = -1;
    }
    x->file = H5Fopen(path, H5F_ACC_RDONLY, fapl >= 0 ? fapl : H5P_DEFAULT);
    if (fapl >= 0)
        H5Pclose(fapl);
    if (x->file < 0)
        FAIL_H5("L2", "", "damaged HDF5 file");
    char why[200];
    if (vafm_h5i_gheap_check(x->file, path, why, sizeof why))
        FAIL("L2", "", "%s", why);
    int rc;
    char *s = NULL;
    if ((rc = s_vlen_str(x, "L3", x->file, "/", "software", &s)))
        return rc;
    free(s);
    if ((rc = s_vlen_str(x, "L3", x->file, "/", "software version", &s)))
        return rc;
    free(s);
    x->is_vafm = H5Aexists(x->file, VAFM_H5I_A_FORMAT) > 0;
    if (x->is_vafm) {
        if ((rc = s_vlen_str(x, "V1", x->file, "/", VAFM_H5I_A_FORMAT, &s)))
            return rc;
        int ma = -1, mi = -1;
        int ok = !vafm_h5i_format_parse(s, &ma, &mi) && ma == VAFM_H5_FORMAT_MAJOR;
        char v[32];
        snprintf(v, sizeof v, "%.24s", s);
        free(s);
        if (!ok)
            FAIL("V1", "/", "'" VAFM_H5I_A_FORMAT "' is '%s', not \"%d.MINOR\"", v, VAFM_H5_FORMAT_MAJOR);
        x->format_minor = mi;
        /* V6: a segment list is a format 1.2 file's, and a 1.2 file has one */
        int has_segs = H5Aexists(x->file, VAFM_H5I_A_SEGMENTS) > 0;
        if (has_segs && mi < VAFM_H5_FORMAT_MINOR_SEGMENTS)
            FAIL("V6", "/", "'" VAFM_H5I_A_SEGMENTS "' in a format %s file (a segment list needs format %d.%d: a reader "
                 "of 1.%d would read a list's segment 1 as the retract)", v, VAFM_H5_FORMAT_MAJOR,
                 VAFM_H5_FORMAT_MINOR_SEGMENTS, VAFM_H5_FORMAT_MINOR);
        /* V7: curves' own lists ("vafm segments <i>") are a format 1.3 file's, and a 1.3 file has one */
        hsize_t idx = 0;
        if (H5Aiterate2(x->file, H5_INDEX_NAME, H5_ITER_NATIVE, &idx, s_count_lists, &x->clists) < 0)
            FAIL_H5("L2", "/", "the root attributes cannot be listed");
        if (x->clists && mi != VAFM_H5_FORMAT_MINOR_CURVE_SEGMENTS)
            FAIL("V7", "/", "%llu curve segment list(s) ('" VAFM_H5I_A_CURVE_SEGMENTS "<i>') in a format %s file (they "
                 "need format %d.%d)", (unsigned long long)x->clists, v, VAFM_H5_FORMAT_MAJOR,
                 VAFM_H5_FORMAT_MINOR_CURVE_SEGMENTS);
        if (mi == VAFM_H5_FORMAT_MINOR_CURVE_SEGMENTS && (has_segs || !x->clists))
            FAIL("V7", "/", "format %s %s (1.%d is the format of files whose curves carry their own lists, '"
                 VAFM_H5I_A_CURVE_SEGMENTS "<i>', and only those)", v, has_segs ? "with one list for every curve, '"
                 VAFM_H5I_A_SEGMENTS "'" : "without any curve's segment list", VAFM_H5_FORMAT_MINOR_CURVE_SEGMENTS);
        if (!has_segs && mi == VAFM_H5_FORMAT_MINOR_SEGMENTS)
            FAIL("V6", "/", "format %s without '" VAFM_H5I_A_SEGMENTS "' (1.%d is the format of files with a segment "
                 "list; others are 1.%d)", v, VAFM_H5_FORMAT_MINOR_SEGMENTS, VAFM_H5_FORMAT_MINOR);
        if (has_segs) {
            if ((rc = s_vlen_str(x, "V6", x->file, "/", VAFM_H5I_A_SEGMENTS, &s)))
                return rc;
            x->nsegs = vafm_h5i_segments_count(s);
            free(s);
            if (x->nsegs < 1)
                FAIL("V6", "/", "'" VAFM_H5I_A_SEGMENTS "' is not a segment list {\"segments\": [1 to %d objects]}",
                     VAFM_H5_SEGMENTS_MAX);
        }
        x->has_prov = H5Aexists(x->file, VAFM_H5I_A_SCENE) > 0;
        if (x->has_prov) {
            static const char *json[] = { VAFM_H5I_A_SCENE, VAFM_H5I_A_GRID };
            for (int i = 0; i < 2; i++) {
                if ((rc = s_vlen_str(x, "V3", x->file, "/", json[i], &s)))
                    return rc;
                ok = vafm_h5i_json_object_ok(s);
                if (i == 1 && ok && strstr(s, "\"map\": {"))
                    x->map = 1;
                free(s);
                if (!ok)
                    FAIL("V3", "/", "'%s' is not a JSON object", json[i]);
            }
            if ((rc = s_vlen_str(x, "V3", x->file, "/", VAFM_H5I_A_CREATED, &s)))
                return rc;
            free(s);
            vafm_h5i_val v2;
            if (H5Aexists(x->file, VAFM_H5I_A_SEED) <= 0 || vafm_h5i_attr_get(x->file, VAFM_H5I_A_SEED, &v2))
                FAIL("V3", "/", "'" VAFM_H5I_A_SEED "' is missing or unreadable");
            vafm_h5i_val_free(&v2);
            if (!(v2.cls == H5T_INTEGER && v2.sign == H5T_SGN_NONE && v2.size == 8 && v2.scalar))
                FAIL("V3", "/", "'" VAFM_H5I_A_SEED "' is not a scalar uint64");
        }
    }
    vafm_h5i_names l = { 0 };
    if (H5Literate(x->file, H5_INDEX_NAME, H5_ITER_NATIVE, NULL, vafm_h5i_link_cb, &l) < 0) {
        vafm_h5i_names_free(&l);
        FAIL_H5("L2", "/", "the root group cannot be listed");
    }
    uint64_t *num = malloc((l.n ? l.n : 1) * sizeof *num);
    rc = 0;
    if (!num) {
        vafm_h5i_err(x->err, rc = VAFM_ENOMEM, "/", "%s: out of memory", path);
        goto done;
    }
    if (l.bad) {
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, "/", "[L4] %s: /: '%s' is a soft or external link", path, l.bad_name);
        goto done;
    }
    for (size_t i = 0; i < l.n; i++)
        if (!vafm_h5i_group_name(l.v[i], &num[i])) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, "/",
                         "[L4] %s: /: root object '%s': only groups named 0, 1, 2, ... may sit at the root", path, l.v[i]);
            goto done;
        }
    qsort(num, l.n, sizeof *num, vafm_h5i_u64_cmp);
    for (size_t i = 0; i < l.n; i++)
        if (num[i] != i) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, "/", "[L4] %s: /: curve group %zu is missing (groups are numbered 0..%zu)",
                         path, i, l.n - 1);
            goto done;
        }
    x->ncurves = l.n;
    x->point_count = calloc(l.n + 1, sizeof *x->point_count);
    x->spring = calloc(l.n + 1, sizeof *x->spring);
    if (!x->point_count || !x->spring) {
        vafm_h5i_err(x->err, rc = VAFM_ENOMEM, "/", "%s: out of memory", path);
        goto done;
    }
    for (size_t i = 0; i < l.n && !rc; i++) {
        char nm[24];
        snprintf(nm, sizeof nm, "%zu", i);
        hid_t o = H5Oopen(x->file, nm, H5P_DEFAULT);
        if (o < 0) {
            vafm_h5i_err_hdf5(x->err, rc = VAFM_EFORMAT, "/", "[L4] %s: /%s: cannot be opened", path, nm);
            break;
        }
        int is_group = H5Iget_type(o) == H5I_GROUP;
        H5Oclose(o);
        if (!is_group) {
            vafm_h5i_err(x->err, rc = VAFM_EFORMAT, "/", "[L4] %s: /%s: is not a group", path, nm);
            break;
        }
        rc = s_group(x, i);
    }
    if (!rc && x->clists != x->clists_seen)
        vafm_h5i_err(x->err, rc = VAFM_EFORMAT, "/", "[V7] %s: /: %llu of the %llu curve segment lists ('"
                     VAFM_H5I_A_CURVE_SEGMENTS "<i>') name no curve group", path,
                     (unsigned long long)(x->clists - x->clists_seen), (unsigned long long)x->clists);
    if (!rc && x->has_prov)
        rc = s_truth(x);
done:
    free(num);
    vafm_h5i_names_free(&l);
    return rc;
}

int vafm_h5_check(const char *path, vafm_error *err)
{
    if (!path) {
        vafm_h5i_err(err, VAFM_EINVAL, "", "vafm_h5_check: no path given");
        return VAFM_EINVAL;
    }
    s_ctx x = { .path = path, .err = err, .file = -1 };
    vafm_h5i_quiet q;
    vafm_h5i_quiet_begin(&q);
    int rc = s_check(&x);
    if (x.file >= 0)
        H5Fclose(x.file);
    vafm_h5i_quiet_end(&q);
    free(x.point_count);
    free(x.spring);
    return rc;
}
