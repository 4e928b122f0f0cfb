/* SPDX-License-Identifier: MIT */
/*
 * Reading force-curve files of afmformats' HDF5 layout, vafm's or another program's.
 *
 * The reader accepts what afmformats accepts and refuses what makes afmformats fail or misread a file:
 * an unknown curve attribute or dataset, a subgroup, datasets of different lengths, a "point count"
 * that disagrees with them, a missing or wrong "unit", a string where a number belongs. It is lenient
 * where afmformats is: fixed-length strings are read as text, numbers of any width are converted, the
 * group numbers may have gaps, "time" and "tip position" may be absent, and afmformats' own storage
 * keys ("enum", "path", "format") are ignored. Strictness about vafm's own output is the checker's job
 * (h5_check.c). Every length a file claims is bounded by the file's size before memory is allocated, so a
 * damaged header cannot make the reader allocate without limit.
 */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "h5/h5_internal.h"

#define S_TAG 0x76683572u /* "vh5r" */

struct vafm_h5_reader {
    uint32_t tag;
    char *path;
    hid_t file;
    uint64_t file_size;
    uint64_t *groups; /* group numbers, sorted */
    size_t n;
    vafm_h5i_curvebuf buf;
    char *software, *software_version, *scene, *grid, *created;
    char *segments; /* "vafm segments" (format 1.2), NULL: none */
    char *cseg;     /* the last curve list vafm_h5_reader_curve_segments read (format 1.3) */
    int nsegs;
    int is_vafm, fmt_major, fmt_minor;
    uint64_t seed;
    vafm_h5i_row *rows; /* sorted by curve */
    size_t nrows;
};

void vafm_h5_meta_default(vafm_h5_meta *m)
{
    memset(m, 0, sizeof *m);
    for (int i = 0; i < vafm_h5i_nkeys; i++) {
        const vafm_h5i_key *k = &vafm_h5i_keys[i];
        char *f = (char *)m + k->offset;
        if (k->kind == VAFM_H5I_REAL)
            *(double *)f = NAN;
        else if (k->kind == VAFM_H5I_INT)
            *(int64_t *)f = -1;
    }
}

/* ---- name lists ----------------------------------------------------------------------------------- */


int vafm_h5i_truth_attr_names(hid_t file, char ***names, size_t *n)
{
    vafm_h5i_names all = { 0 }, keep = { 0 };
    *names = NULL;
    *n = 0;
    if (H5Aiterate2(file, H5_INDEX_NAME, H5_ITER_NATIVE, NULL, vafm_h5i_attr_cb, &all) < 0) {
        vafm_h5i_names_free(&all);
        return -1;
    }
    size_t plen = strlen(VAFM_H5I_A_TRUTH_PART);
    for (size_t i = 0; i < all.n; i++)
        if (!strcmp(all.v[i], VAFM_H5I_A_TRUTH) || !strncmp(all.v[i], VAFM_H5I_A_TRUTH_PART, plen))
            if (vafm_h5i_names_push(&keep, all.v[i])) {
                vafm_h5i_names_free(&all);
                vafm_h5i_names_free(&keep);
                return -1;
            }
    vafm_h5i_names_free(&all);
    *names = keep.v;
    *n = keep.n;
    return 0;
}

/* ---- ground-truth rows ---------------------------------------------------------------------------- */

static int s_row_cmp(const void *a, const void *b)
{
    uint64_t x = ((const vafm_h5i_row *)a)->curve, y = ((const vafm_h5i_row *)b)->curve;
    return x < y ? -1 : x > y;
}

/* Read one ground-truth attribute, appending to *rows. @return 0 or −1 (HDF5 error on the stack, or a
 * shape/type the layout does not have: *why is set then). */
static int s_rows_one(hid_t file, const char *name, vafm_h5i_row **rows, size_t *n, size_t *cap,
                      const char **why)
{
    *why = NULL;
    hid_t t, sp, mt = -1, a = vafm_h5i_attr_open(file, name, &t, &sp);
    if (a < 0)
        return -1;
    int rc = -1;
    if (t < 0 || sp < 0)
        goto done;
    if (H5Tget_class(t) != H5T_COMPOUND) {
        *why = "is not a compound (table) attribute";
        goto done;
    }
    int rank = H5Sget_simple_extent_ndims(sp);
    hssize_t m = H5Sget_simple_extent_npoints(sp);
    if (rank != 1 || m < 0) {
        *why = "is not a 1-D table";
        goto done;
    }
    /* the attribute's storage bounds m (a checksummed header holds its dimensions, but be safe) */
    if ((uint64_t)m > (uint64_t)1 << 32) {
        *why = "claims an impossible number of rows";
        goto done;
    }
    if (*n + (size_t)m > *cap) {
        size_t nc = *cap ? *cap : 64;
        while (nc < *n + (size_t)m)
            nc *= 2;
        vafm_h5i_row *v = realloc(*rows, nc * sizeof *v);
        if (!v)
            goto done;
        *rows = v;
        *cap = nc;
    }
    if (m > 0) {
        mt = vafm_h5i_row_type(0);
        memset(*rows + *n, 0, (size_t)m * sizeof **rows);
        if (mt < 0 || H5Aread(a, mt, *rows + *n) < 0)
            goto done;
        /* a table of format 1.0 has no sample fields: NaN, "not recorded" */
        if (H5Tget_member_index(t, "E_star_Pa") < 0)
            for (hssize_t i = 0; i < m; i++)
                vafm_h5i_row_absent(*rows + *n + i, 0);
    }
    *n += (size_t)m;
    rc = 0;
done:
    VAFM_H5I_CLOSE(mt, t, sp, a);
    return rc;
}

int vafm_h5i_rows_read(hid_t file, const char *path, int skip_damaged, vafm_h5i_row **rows, size_t *n,
                       vafm_error *err)
{
    char **names = NULL;
    size_t nn = 0, cap = 0;
    *rows = NULL;
    *n = 0;
    if (vafm_h5i_truth_attr_names(file, &names, &nn)) {
        vafm_h5i_err_hdf5(err, VAFM_EFORMAT, "/", "%s: the root attributes cannot be listed (damaged file)", path);
        return VAFM_EFORMAT;
    }
    int rc = 0;
    for (size_t i = 0; i < nn && !rc; i++) {
        const char *why = NULL;
        if (s_rows_one(file, names[i], rows, n, &cap, &why) && !skip_damaged) {
            if (why)
                vafm_h5i_err(err, VAFM_EFORMAT, "/", "%s: root attribute '%s' (vafm ground truth) %s", path,
                             names[i], why);
            else
                vafm_h5i_err_hdf5(err, VAFM_EFORMAT, "/",
                                  "%s: root attribute '%s' (vafm ground truth) cannot be read (damaged file)",
                                  path, names[i]);
            rc = VAFM_EFORMAT;
        }
    }
    for (size_t i = 0; i < nn; i++)
        free(names[i]);
    free(names);
    if (rc) {
        free(*rows);
        *rows = NULL;
        *n = 0;
        return rc;
    }
    if (*n > 1) {
        qsort(*rows, *n, sizeof **rows, s_row_cmp);
        size_t w = 1;
        for (size_t i = 1; i < *n; i++) {
            if ((*rows)[i].curve == (*rows)[w - 1].curve) {
                if (!skip_damaged) {
                    vafm_h5i_err(err, VAFM_EFORMAT, "/", "%s: two ground-truth rows for curve %llu (one row per curve)",
                                 path, (unsigned long long)(*rows)[i].curve);
                    free(*rows);
                    *rows = NULL;
                    *n = 0;
                    return VAFM_EFORMAT;
                }
                continue;
            }
            (*rows)[w++] = (*rows)[i];
        }
        *n = w;
    }
    return 0;
}

/* ---- one curve group ------------------------------------------------------------------------------ */

void vafm_h5i_curvebuf_free(vafm_h5i_curvebuf *b)
{
    for (int i = 0; i < VAFM_H5I_NCHAN; i++)
        free(b->d[i]);
    free(b->seg);
    for (int i = 0; i < b->nstr; i++)
        free(b->str[i]);
    memset(b, 0, sizeof *b);
}

static const char *s_class_name(H5T_class_t c)
{
    switch (c) {
    case H5T_INTEGER: return "an integer";
    case H5T_FLOAT: return "a floating-point number";
    case H5T_STRING: return "a string";
    case H5T_COMPOUND: return "a compound";
    case H5T_ENUM: return "an enumeration";
    case H5T_ARRAY: return "an array";
    default: return "of an unsupported HDF5 class";
    }
}

/* A conversion to the reader's type that would clamp a value (HDF5's default) aborts the read instead. */
typedef struct s_conv_range {
    int hit, low;
} s_conv_range;

static H5T_conv_ret_t s_conv_abort(H5T_conv_except_t e, hid_t src, hid_t dst, void *sbuf, void *dbuf, void *user)
{
    (void)src, (void)dst, (void)sbuf, (void)dbuf;
    s_conv_range *r = user;
    if (e != H5T_CONV_EXCEPT_RANGE_HI && e != H5T_CONV_EXCEPT_RANGE_LOW)
        return H5T_CONV_UNHANDLED;
    r->hit = 1;
    r->low = e == H5T_CONV_EXCEPT_RANGE_LOW;
    return H5T_CONV_ABORT;
}

static int s_read_channel(hid_t g, const char *path, const char *gname, const char *name, int ci, int read_data,
                          uint64_t file_size, size_t *n, int *have_n, vafm_h5i_curvebuf *buf, vafm_h5_curve *out,
                          vafm_error *err)
{
    const vafm_h5i_chan *c = &vafm_h5i_chans[ci];
    char obj[96];
    snprintf(obj, sizeof obj, "/%s/%s", gname, name);
    hid_t o = H5Oopen(g, name, H5P_DEFAULT);
    if (o < 0) {
        vafm_h5i_err_hdf5(err, VAFM_EFORMAT, obj, "%s: %s cannot be opened (damaged file)", path, obj);
        return VAFM_EFORMAT;
    }
    int rc = VAFM_EFORMAT;
    hid_t sp = -1, t = -1;
    vafm_h5i_val unit = { 0 };
    if (H5Iget_type(o) != H5I_DATASET) {
        vafm_h5i_err(err, rc, obj, "%s: %s is not a dataset (a curve group holds only channel datasets, no subgroups)",
                     path, obj);
        goto done;
    }
    const char *foreign = vafm_h5i_storage_foreign(o); /* before its shape: nothing outside the file is opened */
    if (foreign) {
        vafm_h5i_err(err, rc, obj, "%s: %s is %s", path, obj, foreign);
        goto done;
    }
    sp = H5Dget_space(o);
    t = H5Dget_type(o);
    if (sp < 0 || t < 0) {
        vafm_h5i_err_hdf5(err, rc, obj, "%s: %s: shape or type cannot be read (damaged file)", path, obj);
        goto done;
    }
    hsize_t dims[2] = { 0, 0 };
    if (H5Sget_simple_extent_type(sp) != H5S_SIMPLE || H5Sget_simple_extent_ndims(sp) != 1 ||
        H5Sget_simple_extent_dims(sp, dims, NULL) != 1) {
        vafm_h5i_err(err, rc, obj, "%s: %s is not 1-D (every channel is a 1-D dataset)", path, obj);
        goto done;
    }
    H5T_class_t cls = H5Tget_class(t);
    int ok = c->is_segment ? cls == H5T_INTEGER : (cls == H5T_FLOAT || cls == H5T_INTEGER);
    if (!ok) {
        vafm_h5i_err(err, rc, obj, "%s: %s is %s (the layout wants %s)", path, obj, s_class_name(cls),
                     c->is_segment ? "uint8 segment labels" : "float64 values");
        goto done;
    }
    if (H5Aexists(o, "unit") <= 0) {
        vafm_h5i_err(err, rc, obj, "%s: %s has no attribute 'unit' (every channel names its unit, here '%s')", path,
                     obj, c->unit);
        goto done;
    }
    if (vafm_h5i_attr_get(o, "unit", &unit)) {
        vafm_h5i_err_hdf5(err, rc, obj, "%s: %s: attribute 'unit' cannot be read (damaged file)", path, obj);
        goto done;
    }
    if (unit.npoints != 1) {
        vafm_h5i_err(err, rc, obj, "%s: %s: attribute 'unit' holds %lld values, the layout wants the single string '%s'",
                     path, obj, (long long)unit.npoints, c->unit);
        goto done;
    }
    if (unit.cls != H5T_STRING || strcmp(unit.s, c->unit)) {
        vafm_h5i_err(err, rc, obj, "%s: %s: attribute 'unit' is %s%s%s, the layout wants the string '%s'", path, obj,
                     unit.cls == H5T_STRING ? "'" : s_class_name(unit.cls), unit.cls == H5T_STRING && unit.s ? unit.s : "",
                     unit.cls == H5T_STRING ? "'" : "", c->unit);
        goto done;
    }
    if (*have_n && dims[0] != *n) {
        vafm_h5i_err(err, rc, obj, "%s: %s has %llu samples, other channels of the group %llu (all channels have the same length)",
                     path, obj, (unsigned long long)dims[0], (unsigned long long)*n);
        goto done;
    }
    if (dims[0] == 0) {
        vafm_h5i_err(err, rc, obj, "%s: %s holds no samples (L7: a channel has at least 1)", path, obj);
        goto done;
    }
    size_t esize = c->is_segment ? 1 : 8;
    /* gzip compresses at most ~1030:1: a longer claim is damage, not data */
    if (dims[0] > VAFM_H5_MAX_SAMPLES) { /* checked before any data is read: a small file of deflated zeros
                                           can declare gigabytes (a decompression bomb) */
        vafm_h5i_err(err, rc = VAFM_EFORMAT, obj, "%s: %s declares %llu samples, more than a curve may have (%llu; "
                     "VAFM_H5_MAX_SAMPLES): refused before reading", path, obj, (unsigned long long)dims[0],
                     (unsigned long long)VAFM_H5_MAX_SAMPLES);
        goto done;
    }
    if ((double)dims[0] * (double)esize > 1100.0 * ((double)file_size + 4096.0) || dims[0] > ((hsize_t)1 << 40)) {
        vafm_h5i_err(err, rc, obj, "%s: %s claims %llu samples, more than a file of %llu bytes can hold (damaged file)",
                     path, obj, (unsigned long long)dims[0], (unsigned long long)file_size);
        goto done;
    }
    *n = (size_t)dims[0];
    *have_n = 1;
    if (read_data) {
        size_t need = *n; /* ≥ 1: an empty channel is refused above */
        if (c->is_segment) {
            uint8_t *p = realloc(buf->seg, need);
            if (!p) {
                rc = VAFM_ENOMEM;
                vafm_h5i_err(err, rc, obj, "%s: %s: out of memory for %zu samples", path, obj, *n);
                goto done;
            }
            buf->seg = p;
        } else if (buf->cap[ci] < need) {
            double *p = realloc(buf->d[ci], need * sizeof *p);
            if (!p) {
                rc = VAFM_ENOMEM;
                vafm_h5i_err(err, rc, obj, "%s: %s: out of memory for %zu samples", path, obj, *n);
                goto done;
            }
            buf->d[ci] = p;
            buf->cap[ci] = need;
        }
        void *dst = c->is_segment ? (void *)buf->seg : (void *)buf->d[ci];
        if (vafm_h5i_storage_complete(o, (hsize_t)*n)) {
            vafm_h5i_err(err, rc, obj, "%s: %s: part of the data has no storage (damaged chunk index)", path, obj);
            goto done;
        }
        /* segment labels of a wider or signed type: a value outside 0-255 stops the read (HDF5 would clamp
         * it, and -1 would pass as 0, the approach) */
        s_conv_range conv = { 0 };
        hid_t dx = c->is_segment ? H5Pcreate(H5P_DATASET_XFER) : H5P_DEFAULT;
        if (dx < 0 || (c->is_segment && H5Pset_type_conv_cb(dx, s_conv_abort, &conv) < 0)) {
            if (dx >= 0 && dx != H5P_DEFAULT)
                H5Pclose(dx);
            vafm_h5i_err_hdf5(err, rc, obj, "%s: %s: cannot be read", path, obj);
            goto done;
        }
        herr_t rrc = H5Dread(o, c->is_segment ? H5T_NATIVE_UINT8 : H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, dx, dst);
        if (dx != H5P_DEFAULT)
            H5Pclose(dx);
        if (rrc < 0 && conv.hit) {
            vafm_h5i_err(err, rc, obj, "%s: %s holds a value outside 0-255 (%s; segment labels are 0 approach, 1 "
                         "retract, 2 dwell)", path, obj, conv.low ? "negative" : "above 255");
            goto done;
        }
        if (rrc < 0) {
            vafm_h5i_err_hdf5(err, rc, obj, "%s: %s: data cannot be read (damaged file or checksum mismatch)", path, obj);
            goto done;
        }
        *(const void **)((char *)out + c->offset) = dst;
    }
    rc = 0;
done:
    vafm_h5i_val_free(&unit);
    VAFM_H5I_CLOSE(t, sp, o);
    return rc;
}

static int s_read_attr(hid_t g, const char *path, const char *gname, const char *name, vafm_h5i_curvebuf *buf,
                       vafm_h5_meta *m, vafm_error *err)
{
    char obj[96];
    snprintf(obj, sizeof obj, "/%s", gname);
    const vafm_h5i_key *k = vafm_h5i_key_find(name);
    if (!k) {
        if (vafm_h5i_key_tolerated(name))
            return 0;
        vafm_h5i_err(err, VAFM_EFORMAT, obj,
                     "%s: curve group '%s': attribute '%s' is not in afmformats' metadata list (afmformats fails on it)",
                     path, gname, name);
        return VAFM_EFORMAT;
    }
    vafm_h5i_val v;
    if (vafm_h5i_attr_get(g, name, &v)) {
        vafm_h5i_err_hdf5(err, VAFM_EFORMAT, obj, "%s: curve group '%s': attribute '%s' cannot be read (damaged file)",
                          path, gname, name);
        return VAFM_EFORMAT;
    }
    int rc = VAFM_EFORMAT;
    char *f = (char *)m + k->offset;
    if (v.npoints != 1) {
        vafm_h5i_err(err, rc, obj, "%s: curve group '%s': attribute '%s' holds %lld values (metadata are single values)",
                     path, gname, name, (long long)v.npoints);
        goto done;
    }
    if (k->kind == VAFM_H5I_STR) {
        if (v.cls != H5T_STRING) {
            vafm_h5i_err(err, rc, obj, "%s: curve group '%s': attribute '%s' is %s (afmformats wants a string)", path,
                         gname, name, s_class_name(v.cls));
            goto done;
        }
        if (buf->nstr >= (int)(sizeof buf->str / sizeof buf->str[0])) {
            vafm_h5i_err(err, rc, obj, "%s: curve group '%s': too many string attributes", path, gname);
            goto done;
        }
        buf->str[buf->nstr++] = v.s;
        *(const char **)f = v.s;
        v.s = NULL;
    } else if (k->kind == VAFM_H5I_REAL) {
        if (v.cls != H5T_FLOAT && v.cls != H5T_INTEGER) {
            vafm_h5i_err(err, rc, obj, "%s: curve group '%s': attribute '%s' is %s (afmformats wants a number, %s)", path,
                         gname, name, s_class_name(v.cls), k->unit);
            goto done;
        }
        if (!isfinite(v.d)) { /* absent is how a reader says "not known"; a stored NaN or inf is no value */
            vafm_h5i_err(err, rc, obj, "%s: curve group '%s': attribute '%s' is %g (a finite number in %s, or absent)",
                         path, gname, name, v.d, k->unit);
            goto done;
        }
        *(double *)f = v.d;
    } else {
        if (!(v.cls == H5T_INTEGER || (v.cls == H5T_FLOAT && v.integral)) || v.i < 0) {
            vafm_h5i_err(err, rc, obj,
                         "%s: curve group '%s': attribute '%s' is %s (afmformats wants a non-negative integer)", path,
                         gname, name, v.i < 0 && (v.cls == H5T_INTEGER || v.integral) ? "negative"
                                      : v.cls == H5T_FLOAT ? "a fractional number" : s_class_name(v.cls));
            goto done;
        }
        *(int64_t *)f = v.i;
    }
    rc = 0;
done:
    vafm_h5i_val_free(&v);
    return rc;
}

int vafm_h5i_curve_read(hid_t file, const char *path, uint64_t group, int read_data, uint64_t file_size,
                        vafm_h5i_curvebuf *buf, vafm_h5_curve *out, vafm_error *err)
{
    char gname[24], obj[32];
    snprintf(gname, sizeof gname, "%llu", (unsigned long long)group);
    snprintf(obj, sizeof obj, "/%s", gname);
    for (int i = 0; i < buf->nstr; i++)
        free(buf->str[i]);
    buf->nstr = 0;
    memset(out, 0, sizeof *out);
    vafm_h5_meta_default(&out->meta);
    out->group = group;

    hid_t g = H5Gopen2(file, gname, H5P_DEFAULT);
    if (g < 0) {
        vafm_h5i_err_hdf5(err, VAFM_EFORMAT, obj, "%s: curve group '%s' cannot be opened (damaged file)", path, gname);
        return VAFM_EFORMAT;
    }
    int rc = 0;
    vafm_h5i_names links = { 0 }, attrs = { 0 };
    if (H5Literate(g, H5_INDEX_NAME, H5_ITER_NATIVE, NULL, vafm_h5i_link_cb, &links) < 0) {
        vafm_h5i_err_hdf5(err, rc = VAFM_EFORMAT, obj, "%s: curve group '%s': its objects cannot be listed (damaged file)",
                          path, gname);
        goto done;
    }
    if (links.bad) {
        vafm_h5i_err(err, rc = VAFM_EFORMAT, obj, "%s: curve group '%s': '%s' is a soft or external link (channels are datasets)",
                     path, gname, links.bad_name);
        goto done;
    }
    size_t n = 0;
    int have_n = 0, have[VAFM_H5I_NCHAN] = { 0 };
    for (size_t i = 0; i < links.n && !rc; i++) {
        int ci = vafm_h5i_chan_find(links.v[i]);
        if (ci < 0) {
            vafm_h5i_err(err, rc = VAFM_EFORMAT, obj,
                         "%s: curve group '%s': object '%s' is not one of afmformats' columns (force, height (measured), "
                         "height (piezo), segment, time, tip position)",
                         path, gname, links.v[i]);
            break;
        }
        have[ci] = 1;
        rc = s_read_channel(g, path, gname, links.v[i], ci, read_data, file_size, &n, &have_n, buf, out, err);
    }
    if (rc)
        goto done;
    if (!have[VAFM_H5I_FORCE] || !have[VAFM_H5I_SEGMENT] || !(have[VAFM_H5I_HMEAS] || have[VAFM_H5I_HPIEZO])) {
        vafm_h5i_err(err, rc = VAFM_EFORMAT, obj,
                     "%s: curve group '%s' lacks '%s' (a force-distance curve needs force, segment and a height)", path,
                     gname, !have[VAFM_H5I_FORCE] ? "force" : !have[VAFM_H5I_SEGMENT] ? "segment" : "height (measured)");
        goto done;
    }
    out->n = n;
    if (H5Aiterate2(g, H5_INDEX_NAME, H5_ITER_NATIVE, NULL, vafm_h5i_attr_cb, &attrs) < 0) {
        vafm_h5i_err_hdf5(err, rc = VAFM_EFORMAT, obj, "%s: curve group '%s': its attributes cannot be listed (damaged file)",
                          path, gname);
        goto done;
    }
    for (size_t i = 0; i < attrs.n && !rc; i++)
        rc = s_read_attr(g, path, gname, attrs.v[i], buf, &out->meta, err);
    if (rc)
        goto done;
    if (!out->meta.imaging_mode) {
        vafm_h5i_err(err, rc = VAFM_EFORMAT, obj,
                     "%s: curve group '%s' has no 'imaging mode' (afmformats recognises curves by it)", path, gname);
        goto done;
    }
    if (strcmp(out->meta.imaging_mode, "force-distance")) {
        vafm_h5i_err(err, rc = VAFM_ENOTSUP, obj, "%s: curve group '%s': imaging mode '%s' (vafm reads force-distance curves)",
                     path, gname, out->meta.imaging_mode);
        goto done;
    }
    if (out->meta.point_count >= 0 && (uint64_t)out->meta.point_count != (uint64_t)n) {
        vafm_h5i_err(err, rc = VAFM_EFORMAT, obj,
                     "%s: curve group '%s': 'point count' is %lld but the channels have %zu samples (they must agree)", path,
                     gname, (long long)out->meta.point_count, n);
        goto done;
    }
    if (read_data) {
        size_t at = 0;
        const char *rule = vafm_h5i_rule_segment(out->segment, n, out->meta.segment_count, 0, &at);
        if (rule) {
            vafm_h5i_err(err, rc = VAFM_EFORMAT, obj, "%s: /%s/segment: value %u at sample %zu (%s)", path, gname,
                         out->segment[at], at, rule);
            goto done;
        }
    }
done:
    vafm_h5i_names_free(&links);
    vafm_h5i_names_free(&attrs);
    H5Gclose(g);
    return rc;
}

/* ---- reader --------------------------------------------------------------------------------------- */

static int s_root_string(hid_t file, const char *path, const char *name, int required, char **out, vafm_error *err)
{
    *out = NULL;
    htri_t ex = H5Aexists(file, name);
    if (ex < 0) {
        vafm_h5i_err_hdf5(err, VAFM_EFORMAT, "/", "%s: root attribute '%s' cannot be looked up (damaged file)", path,
                          name);
        return VAFM_EFORMAT;
    }
    if (!ex) {
        if (!required)
            return 0;
        vafm_h5i_err(err, VAFM_EFORMAT, "/", "%s: root attribute '%s' is missing (the afmformats layout requires it)",
                     path, name);
        return VAFM_EFORMAT;
    }
    vafm_h5i_val v;
    if (vafm_h5i_attr_get(file, name, &v)) {
        vafm_h5i_err_hdf5(err, VAFM_EFORMAT, "/", "%s: root attribute '%s' cannot be read (damaged file)", path, name);
        return VAFM_EFORMAT;
    }
    if (v.cls != H5T_STRING || v.npoints != 1) {
        vafm_h5i_err(err, VAFM_EFORMAT, "/", "%s: root attribute '%s' is %s (the layout wants one string)", path, name,
                     v.npoints != 1 ? "not a single value" : s_class_name(v.cls));
        vafm_h5i_val_free(&v);
        return VAFM_EFORMAT;
    }
    *out = v.s;
    return 0;
}

void vafm_h5_reader_destroy(vafm_h5_reader **rp)
{
    if (!rp || !*rp)
        return;
    vafm_h5_reader *r = *rp;
    vafm_h5i_quiet q;
    vafm_h5i_quiet_begin(&q);
    if (r->file >= 0)
        H5Fclose(r->file);
    vafm_h5i_quiet_end(&q);
    vafm_h5i_curvebuf_free(&r->buf);
    free(r->path);
    free(r->groups);
    free(r->software);
    free(r->software_version);
    free(r->scene);
    free(r->grid);
    free(r->created);
    free(r->segments);
    free(r->cseg);
    free(r->rows);
    r->tag = 0xdeadbeefu;
    free(r);
    *rp = NULL;
}

static int s_reader_open(vafm_h5_reader *r, const char *path, vafm_error *err)
{
    struct stat st;
    if (stat(path, &st)) {
        vafm_h5i_err(err, VAFM_EIO, "", "%s: cannot open: %s", path, strerror(errno));
        return VAFM_EIO;
    }
    r->file_size = (uint64_t)st.st_size;
    int crc = vafm_h5i_check_path(path, 0, err);
    if (crc)
        return crc;
    htri_t is = H5Fis_hdf5(path);
    if (is <= 0) {
        vafm_h5i_err(err, VAFM_EFORMAT, "", "%s: not an HDF5 file (no HDF5 signature)", path);
        return VAFM_EFORMAT;
    }
    hid_t fapl = H5Pcreate(H5P_FILE_ACCESS);
    if (fapl >= 0 && (H5Pset_fclose_degree(fapl, H5F_CLOSE_STRONG) < 0 || vafm_h5i_fapl_journal(fapl))) {
        H5Pclose(fapl);
        fapl = -1;
    }
    r->file = H5Fopen(path, H5F_ACC_RDONLY, fapl >= 0 ? fapl : H5P_DEFAULT);
    if (fapl >= 0)
        H5Pclose(fapl);
    if (r->file < 0) {
        vafm_h5i_err_hdf5(err, VAFM_EFORMAT, "", "%s: damaged or truncated HDF5 file, cannot be opened", path);
        return VAFM_EFORMAT;
    }
    char why[200];
    int g = vafm_h5i_gheap_check(r->file, path, why, sizeof why);
    if (g) {
        vafm_h5i_err(err, g == -1 ? VAFM_EFORMAT : VAFM_EIO, "", "%s: %s", path, g == -1 ? why : "cannot be read");
        return g == -1 ? VAFM_EFORMAT : VAFM_EIO;
    }
    int rc;
    if ((rc = s_root_string(r->file, path, "software", 1, &r->software, err)) ||
        (rc = s_root_string(r->file, path, "software version", 1, &r->software_version, err)))
        return rc;

    /* vafm's provenance */
    char *fmt = NULL;
    if ((rc = s_root_string(r->file, path, VAFM_H5I_A_FORMAT, 0, &fmt, err)))
        return rc;
    if (fmt) {
        int ma = -1, mi = -1;
        int ok = !vafm_h5i_format_parse(fmt, &ma, &mi);
        free(fmt);
        if (!ok) {
            vafm_h5i_err(err, VAFM_EFORMAT, "/", "%s: root attribute '" VAFM_H5I_A_FORMAT "' is not \"MAJOR.MINOR\"", path);
            return VAFM_EFORMAT;
        }
        if (ma != VAFM_H5_FORMAT_MAJOR) {
            vafm_h5i_err(err, VAFM_EFORMAT, "/", "%s: vafm format version %d.%d is not supported (this vafm reads %d.x)",
                         path, ma, mi, VAFM_H5_FORMAT_MAJOR);
            return VAFM_EFORMAT;
        }
        r->is_vafm = 1;
        r->fmt_major = ma;
        r->fmt_minor = mi;
        if ((rc = s_root_string(r->file, path, VAFM_H5I_A_SCENE, 1, &r->scene, err)) ||
            (rc = s_root_string(r->file, path, VAFM_H5I_A_GRID, 0, &r->grid, err)) ||
            (rc = s_root_string(r->file, path, VAFM_H5I_A_CREATED, 0, &r->created, err)) ||
            (rc = s_root_string(r->file, path, VAFM_H5I_A_SEGMENTS, 0, &r->segments, err)))
            return rc;
        if (r->segments && (r->nsegs = vafm_h5i_segments_count(r->segments)) < 1) {
            vafm_h5i_err(err, VAFM_EFORMAT, "/", "%s: root attribute '" VAFM_H5I_A_SEGMENTS "' is not a segment list "
                         "{\"segments\": [...]} (hdf5.md V6)", path);
            return VAFM_EFORMAT;
        }
        if (H5Aexists(r->file, VAFM_H5I_A_SEED) > 0) {
            vafm_h5i_val v;
            if (vafm_h5i_attr_get(r->file, VAFM_H5I_A_SEED, &v)) {
                vafm_h5i_err_hdf5(err, VAFM_EFORMAT, "/", "%s: root attribute '" VAFM_H5I_A_SEED "' cannot be read", path);
                return VAFM_EFORMAT;
            }
            int ok = v.cls == H5T_INTEGER && v.npoints == 1;
            r->seed = v.u;
            vafm_h5i_val_free(&v);
            if (!ok) {
                vafm_h5i_err(err, VAFM_EFORMAT, "/", "%s: root attribute '" VAFM_H5I_A_SEED "' is not one integer", path);
                return VAFM_EFORMAT;
            }
        }
        if ((rc = vafm_h5i_rows_read(r->file, path, 0, &r->rows, &r->nrows, err)))
            return rc;
    }

    /* the curve groups */
    vafm_h5i_names links = { 0 };
    if (H5Literate(r->file, H5_INDEX_NAME, H5_ITER_NATIVE, NULL, vafm_h5i_link_cb, &links) < 0) {
        vafm_h5i_names_free(&links);
        vafm_h5i_err_hdf5(err, VAFM_EFORMAT, "/", "%s: the root group cannot be listed (damaged file)", path);
        return VAFM_EFORMAT;
    }
    rc = 0;
    if (links.bad) {
        vafm_h5i_err(err, rc = VAFM_EFORMAT, "/", "%s: root object '%s' is a soft or external link (curves are groups)",
                     path, links.bad_name);
        goto done;
    }
    r->groups = malloc((links.n ? links.n : 1) * sizeof *r->groups);
    if (!r->groups) {
        vafm_h5i_err(err, rc = VAFM_ENOMEM, "/", "%s: out of memory", path);
        goto done;
    }
    for (size_t i = 0; i < links.n; i++) {
        if (!vafm_h5i_group_name(links.v[i], &r->groups[i])) {
            vafm_h5i_err(err, rc = VAFM_EFORMAT, "/",
                         "%s: root object '%s': only curve groups named 0, 1, 2, ... may sit at the root", path,
                         links.v[i]);
            goto done;
        }
        H5O_type_t ty = H5O_TYPE_UNKNOWN;
        hid_t o = H5Oopen(r->file, links.v[i], H5P_DEFAULT);
        if (o >= 0) {
            H5I_type_t it = H5Iget_type(o);
            ty = it == H5I_GROUP ? H5O_TYPE_GROUP : it == H5I_DATASET ? H5O_TYPE_DATASET : H5O_TYPE_NAMED_DATATYPE;
            H5Oclose(o);
        }
        if (o < 0) {
            vafm_h5i_err_hdf5(err, rc = VAFM_EFORMAT, "/", "%s: root object '%s' cannot be opened (damaged file)", path,
                              links.v[i]);
            goto done;
        }
        if (ty != H5O_TYPE_GROUP) {
            vafm_h5i_err(err, rc = VAFM_EFORMAT, "/", "%s: root object '%s' is not a group (each curve is a group)", path,
                         links.v[i]);
            goto done;
        }
    }
    r->n = links.n;
    qsort(r->groups, r->n, sizeof *r->groups, vafm_h5i_u64_cmp);
done:
    vafm_h5i_names_free(&links);
    return rc;
}

int vafm_h5_reader_open(vafm_h5_reader **out, const char *path, vafm_error *err)
{
    if (!out || !path) {
        vafm_h5i_err(err, VAFM_EINVAL, "", "vafm_h5_reader_open: no %s given", out ? "path" : "output pointer");
        return VAFM_EINVAL;
    }
    *out = NULL;
    vafm_h5_reader *r = calloc(1, sizeof *r);
    if (!r || !(r->path = strdup(path))) {
        free(r);
        vafm_h5i_err(err, VAFM_ENOMEM, "", "%s: out of memory", path);
        return VAFM_ENOMEM;
    }
    r->tag = S_TAG;
    r->file = -1;
    vafm_h5i_quiet q;
    vafm_h5i_quiet_begin(&q);
    int rc = s_reader_open(r, path, err);
    vafm_h5i_quiet_end(&q);
    if (rc) {
        vafm_h5_reader_destroy(&r);
        return rc;
    }
    *out = r;
    return 0;
}

size_t vafm_h5_reader_count(const vafm_h5_reader *r)
{
    return r ? r->n : 0;
}

/* Curve i, with its data (read_data) or only its metadata and length. */
static int s_reader_read(vafm_h5_reader *r, size_t i, int read_data, vafm_h5_curve *out, vafm_error *err)
{
    if (!r || r->tag != S_TAG || !out) {
        vafm_h5i_err(err, VAFM_EINVAL, "", "vafm_h5_reader_curve%s: no reader or output given", read_data ? "" : "_info");
        return VAFM_EINVAL;
    }
    if (i >= r->n) {
        vafm_h5i_err(err, VAFM_EINVAL, "", "%s: curve %zu requested, the file holds %zu", r->path, i, r->n);
        return VAFM_EINVAL;
    }
    vafm_h5i_quiet q;
    vafm_h5i_quiet_begin(&q);
    int rc = vafm_h5i_curve_read(r->file, r->path, r->groups[i], read_data, r->file_size, &r->buf, out, err);
    vafm_h5i_quiet_end(&q);
    return rc;
}

int vafm_h5_reader_curve(vafm_h5_reader *r, size_t i, vafm_h5_curve *out, vafm_error *err)
{
    return s_reader_read(r, i, 1, out, err);
}

uint64_t vafm_h5_reader_group(const vafm_h5_reader *r, size_t i)
{
    return r && i < r->n ? r->groups[i] : UINT64_MAX;
}

int vafm_h5_reader_find(const vafm_h5_reader *r, uint64_t group, size_t *i)
{
    if (!r || !i)
        return VAFM_EINVAL;
    size_t lo = vafm_h5i_u64_lower_bound(r->groups, r->n, group); /* groups are held in ascending order */
    if (lo >= r->n || r->groups[lo] != group)
        return VAFM_ENOTFOUND;
    *i = lo;
    return 0;
}

int vafm_h5_reader_curve_info(vafm_h5_reader *r, size_t i, vafm_h5_curve *out, vafm_error *err)
{
    return s_reader_read(r, i, 0, out, err);
}

int vafm_h5_reader_provenance(const vafm_h5_reader *r, vafm_h5_provenance *out)
{
    if (!r || !out)
        return VAFM_EINVAL;
    memset(out, 0, sizeof *out);
    out->software = r->software;
    out->software_version = r->software_version;
    out->is_vafm = r->is_vafm;
    out->format_major = r->fmt_major;
    out->format_minor = r->fmt_minor;
    out->scene_json = r->scene;
    out->grid_json = r->grid;
    out->created = r->created;
    out->seed = r->seed;
    out->truth_rows = r->nrows;
    out->segments_json = r->segments;
    out->segment_count = r->segments ? r->nsegs : 0;
    return 0;
}

int vafm_h5_reader_curve_segments(vafm_h5_reader *r, size_t i, const char **json, vafm_error *err)
{
    if (!r || !json || i >= r->n) {
        vafm_h5i_err(err, VAFM_EINVAL, "i", "vafm_h5_reader_curve_segments: no reader, or curve %zu of %zu", i,
                     r ? r->n : 0);
        return VAFM_EINVAL;
    }
    *json = r->segments; /* format 1.2: the file's one list; older files: none */
    if (!r->is_vafm || r->fmt_minor < VAFM_H5_FORMAT_MINOR_CURVE_SEGMENTS || r->segments)
        return 0;
    free(r->cseg);
    r->cseg = NULL;
    char name[64];
    snprintf(name, sizeof name, VAFM_H5I_A_CURVE_SEGMENTS "%" PRIu64, r->groups[i]);
    vafm_h5i_quiet q;
    vafm_h5i_quiet_begin(&q);
    int rc = s_root_string(r->file, r->path, name, 0, &r->cseg, err);
    vafm_h5i_quiet_end(&q);
    if (rc)
        return rc;
    if (r->cseg && vafm_h5i_segments_count(r->cseg) < 1) {
        vafm_h5i_err(err, VAFM_EFORMAT, "/", "%s: root attribute '%s' is not a segment list {\"segments\": [1 to %d "
                     "objects]} (hdf5.md V7)", r->path, name, VAFM_H5_SEGMENTS_MAX);
        return VAFM_EFORMAT;
    }
    *json = r->cseg;
    return 0;
}

int vafm_h5_reader_truth(const vafm_h5_reader *r, uint64_t curve, vafm_h5_truth *out)
{
    if (!r || !out)
        return VAFM_EINVAL;
    size_t lo = 0, hi = r->nrows;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (r->rows[mid].curve < curve)
            lo = mid + 1;
        else
            hi = mid;
    }
    if (lo >= r->nrows || r->rows[lo].curve != curve)
        return VAFM_ENOTFOUND;
    vafm_h5i_truth_from_row(out, &r->rows[lo]);
    return 0;
}
