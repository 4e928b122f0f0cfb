/* SPDX-License-Identifier: MIT */
/*
 * Reopening a writer's file after a kill (vafm_h5_writer_open with resume; the durability argument is in
 * h5_internal.h). The file must be a vafm file of this format version, not in use, and readable down to
 * its root list; the longest prefix 0..c-1 of curve groups that pass the layout check (and have a
 * ground-truth row when the file has a scene) is kept, the last two read back through their checksums;
 * the rest is deleted and the rows are merged into one table. With keep_intact, a bad curve followed by
 * intact ones refuses the resume instead (nothing changed), so no intact curve is ever dropped.
 */
#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "h5/h5_internal.h"

static int s_read_root_str(hid_t file, const char *name, char **out)
{
    *out = NULL;
    htri_t ex = H5Aexists(file, name);
    if (ex < 0)
        return -1; /* cannot be looked up: a damaged header, not a missing attribute */
    if (ex == 0)
        return 0;
    vafm_h5i_val v;
    if (vafm_h5i_attr_get(file, name, &v))
        return -1;
    if (v.cls != H5T_STRING || v.npoints != 1) {
        vafm_h5i_val_free(&v);
        return -1;
    }
    *out = v.s;
    return 0;
}

/* The root's curve groups: their names (the h5 layer's name list) and their numbers. names.bad/bad_name
 * record the first root object that is not a curve group. */
typedef struct s_linklist {
    vafm_h5i_names names;
    uint64_t *num; /* num[i]: the number of names.v[i] */
} s_linklist;

static herr_t s_root_link_cb(hid_t g, const char *name, const H5L_info_t *info, void *data)
{
    vafm_h5i_names *l = data;
    uint64_t num;
    if (!vafm_h5i_group_name(name, &num)) {
        if (!l->bad)
            snprintf(l->bad_name, sizeof l->bad_name, "%s", name);
        l->bad = 1;
        return 0;
    }
    return vafm_h5i_names_push(l, name) ? -1 : 0;
}

/* List the root's curve groups into l. @return 0, -1 when the root cannot be listed, -2 out of memory. */
static int s_linklist_read(hid_t file, s_linklist *l)
{
    if (H5Literate(file, H5_INDEX_NAME, H5_ITER_NATIVE, NULL, s_root_link_cb, &l->names) < 0)
        return -1;
    if (!(l->num = calloc(l->names.n + 1, sizeof *l->num)))
        return -2;
    for (size_t i = 0; i < l->names.n; i++)
        vafm_h5i_group_name(l->names.v[i], &l->num[i]);
    return 0;
}

static void s_linklist_free(s_linklist *l)
{
    vafm_h5i_names_free(&l->names);
    free(l->num);
    memset(l, 0, sizeof *l);
}

/* Resume with keep_intact: the groups from c on would be deleted; refuse (nothing changed) when one after the
 * first bad curve c still reads (structure and attributes), naming c, why it is bad, and the intact ones. */
static int s_keep_intact(vafm_h5_writer *w, const s_linklist *l, const uint8_t *present, const vafm_h5i_row *rows,
                         size_t nrows, uint64_t c, uint64_t file_size, vafm_h5i_curvebuf *buf, vafm_error *err)
{
    uint64_t intact = 0, last = 0;
    vafm_h5_curve cv;
    for (size_t i = 0; i < l->names.n; i++)
        if (l->num[i] > c && !vafm_h5i_curve_read(w->file, w->path, l->num[i], 0, file_size, buf, &cv, NULL)) {
            intact++;
            last = l->num[i] > last ? l->num[i] : last;
        }
    if (!intact)
        return 0; /* only a damaged tail goes: what a kill can leave */
    char why[200];
    vafm_error e;
    memset(&e, 0, sizeof e);
    if (c >= l->names.n || !present[c])
        snprintf(why, sizeof why, "is missing");
    else if (w->has_prov && !(c < nrows && rows[c].curve == c))
        snprintf(why, sizeof why, "has no ground-truth row");
    else if (vafm_h5i_curve_read(w->file, w->path, c, 1, file_size, buf, &cv, &e))
        snprintf(why, sizeof why, "is damaged (%.150s)", e.message);
    else
        snprintf(why, sizeof why, "is followed by a damaged one"); /* c read back; a later one of the two did not */
    vafm_h5i_err(err, VAFM_EFORMAT, "", "%s: cannot be resumed: curve %" PRIu64 " %s, and %" PRIu64 " intact curve(s) "
                 "follow it (up to curve %" PRIu64 "), which resume would drop; nothing was changed: log to a new file "
                 "(the intact curves stay readable here)", w->path, c, why, intact, last);
    return VAFM_EFORMAT;
}

int vafm_h5i_writer_resume(vafm_h5_writer *w, vafm_error *err)
{
    struct stat st;
    if (stat(w->path, &st)) {
        vafm_h5i_err(err, VAFM_EIO, "", "%s: cannot be resumed: %s", w->path, strerror(errno));
        return VAFM_EIO;
    }
    int crc = vafm_h5i_check_path(w->path, 1, err);
    if (crc)
        return crc;
    if (H5Fis_hdf5(w->path) <= 0) {
        vafm_h5i_err(err, VAFM_EFORMAT, "", "%s: cannot be resumed: not an HDF5 file", w->path);
        return VAFM_EFORMAT;
    }
    hid_t fapl = vafm_h5i_writer_fapl();
    w->file = H5Fopen(w->path, H5F_ACC_RDWR, fapl >= 0 ? fapl : H5P_DEFAULT);
    if (fapl >= 0)
        H5Pclose(fapl);
    if (w->file < 0) {
        vafm_h5i_err_hdf5(err, VAFM_EFORMAT, "", "%s: cannot be resumed: damaged HDF5 file", w->path);
        return VAFM_EFORMAT;
    }
    char why[200];
    if (vafm_h5i_gheap_check(w->file, w->path, why, sizeof why)) {
        vafm_h5i_err(err, VAFM_EFORMAT, "", "%s: cannot be resumed: %s", w->path, why);
        return VAFM_EFORMAT;
    }
    char *fmt = NULL;
    int ma = -1, mi = -1;
    if (s_read_root_str(w->file, VAFM_H5I_A_FORMAT, &fmt)) {
        vafm_h5i_err_hdf5(err, VAFM_EFORMAT, "/", "%s: cannot be resumed: the root attributes cannot be read (damaged "
                          "file header)", w->path);
        return VAFM_EFORMAT;
    }
    if (!fmt || vafm_h5i_format_parse(fmt, &ma, &mi) || ma != VAFM_H5_FORMAT_MAJOR) {
        vafm_h5i_err(err, VAFM_EFORMAT, "/", "%s: cannot be resumed: not a vafm file of format %d.x (root attribute '"
                     VAFM_H5I_A_FORMAT "' is %s)", w->path, VAFM_H5_FORMAT_MAJOR, fmt ? fmt : "missing");
        free(fmt);
        return VAFM_EFORMAT;
    }
    if (s_read_root_str(w->file, VAFM_H5I_A_SEGMENTS, &w->segs)) {
        vafm_h5i_err_hdf5(err, VAFM_EFORMAT, "/", "%s: cannot be resumed: the stored segment list cannot be read",
                          w->path);
        free(fmt);
        return VAFM_EFORMAT;
    }
    /* a file with a segment list is 1.2, one without 1.1 or 1.3 (curves with lists of their own): an older
     * minor's rows and scene lack fields this version writes */
    if (mi != (w->segs ? VAFM_H5_FORMAT_MINOR_SEGMENTS : VAFM_H5_FORMAT_MINOR) &&
        (w->segs || mi != VAFM_H5_FORMAT_MINOR_CURVE_SEGMENTS)) {
        vafm_h5i_err(err, VAFM_EFORMAT, "/", "%s: cannot be resumed: written in format %s%s, this vafm writes %d.%d "
                     "(%d.%d with a segment list); resume it with the vafm version that wrote it", w->path, fmt,
                     w->segs ? " with a segment list" : "", VAFM_H5_FORMAT_MAJOR, VAFM_H5_FORMAT_MINOR,
                     VAFM_H5_FORMAT_MAJOR, VAFM_H5_FORMAT_MINOR_SEGMENTS);
        free(fmt);
        return VAFM_EFORMAT;
    }
    if (w->segs && (w->nsegs = vafm_h5i_segments_count(w->segs)) < 1) {
        vafm_h5i_err(err, VAFM_EFORMAT, "/", "%s: cannot be resumed: root attribute '" VAFM_H5I_A_SEGMENTS "' is not a "
                     "segment list {\"segments\": [...]} (hdf5.md V6)", w->path);
        free(fmt);
        return VAFM_EFORMAT;
    }
    free(fmt);
    w->minor = mi;
    if (s_read_root_str(w->file, VAFM_H5I_A_SCENE, &w->scene) || s_read_root_str(w->file, VAFM_H5I_A_GRID, &w->grid)) {
        vafm_h5i_err_hdf5(err, VAFM_EFORMAT, "/", "%s: cannot be resumed: the stored scene cannot be read", w->path);
        return VAFM_EFORMAT;
    }
    w->has_prov = w->scene != NULL;

    vafm_h5i_row *rows = NULL;
    size_t nrows = 0;
    int rc = vafm_h5i_rows_read(w->file, w->path, 1, &rows, &nrows, err);
    if (rc)
        return rc;
    s_linklist l = { 0 };
    int lr = s_linklist_read(w->file, &l);
    if (lr == -1) {
        vafm_h5i_err_hdf5(err, rc = VAFM_EFORMAT, "/", "%s: cannot be resumed: the root group cannot be listed", w->path);
        goto done;
    }
    if (lr) {
        vafm_h5i_err(err, rc = VAFM_ENOMEM, "", "%s: out of memory", w->path);
        goto done;
    }
    if (l.names.bad) {
        vafm_h5i_err(err, rc = VAFM_EFORMAT, "/", "%s: cannot be resumed: root object '%s' is not a curve group", w->path,
                     l.names.bad_name);
        goto done;
    }
    /* numbers → presence map over 0..n−1 (numbers ≥ n cannot be part of the complete prefix) */
    uint8_t *present = calloc(l.names.n + 1, 1);
    if (!present) {
        vafm_h5i_err(err, rc = VAFM_ENOMEM, "", "%s: out of memory", w->path);
        goto done;
    }
    for (size_t i = 0; i < l.names.n; i++)
        if (l.num[i] < l.names.n)
            present[l.num[i]] = 1;
    uint64_t file_size = (uint64_t)st.st_size;
    vafm_h5i_curvebuf buf = { 0 };
    vafm_h5_curve cv;
    uint64_t c = 0;
    /* the complete prefix: structure of every group, plus a ground-truth row when the file has a scene */
    while (c < l.names.n && present[c] && (!w->has_prov || (c < nrows && rows[c].curve == c)) &&
           !vafm_h5i_curve_read(w->file, w->path, c, 0, file_size, &buf, &cv, NULL))
        c++;
    /* the last curves kept were written last: read their data back through their checksums */
    for (uint64_t ok = 0; c > 0 && ok < 2 && ok < c;) {
        uint64_t j = c - 1 - ok;
        if (vafm_h5i_curve_read(w->file, w->path, j, 1, file_size, &buf, &cv, NULL)) {
            c = j;
            ok = 0;
        } else {
            ok++;
        }
    }
    if (w->o.keep_intact && (rc = s_keep_intact(w, &l, present, rows, nrows, c, file_size, &buf, err))) {
        vafm_h5i_curvebuf_free(&buf);
        free(present);
        goto done;
    }
    vafm_h5i_curvebuf_free(&buf);
    free(present);
    for (size_t i = 0; i < l.names.n; i++) {
        if (l.num[i] < c)
            continue;
        char an[64]; /* format 1.3: the dropped curve's own segment list goes with it */
        snprintf(an, sizeof an, VAFM_H5I_A_CURVE_SEGMENTS "%s", l.names.v[i]);
        if (H5Ldelete(w->file, l.names.v[i], H5P_DEFAULT) < 0 || (H5Aexists(w->file, an) > 0 && H5Adelete(w->file, an) < 0)) {
            vafm_h5i_err_hdf5(err, rc = VAFM_EIO, "/", "%s: cannot be resumed: incomplete curve '%s' cannot be removed",
                              w->path, l.names.v[i]);
            goto done;
        }
    }
    w->count = c;
    w->nrows = 0;
    if (w->has_prov) {
        if (vafm_h5i_writer_rows_reserve(w, (size_t)c + 1)) {
            vafm_h5i_err(err, rc = VAFM_ENOMEM, "", "%s: out of memory", w->path);
            goto done;
        }
        if (c) /* a file killed before its first curve has no rows (rows NULL) */
            memcpy(w->rows, rows, (size_t)c * sizeof *rows);
        w->nrows = (size_t)c;
    }
    if (vafm_h5i_writer_merge_rows(w) || H5Fflush(w->file, H5F_SCOPE_GLOBAL) < 0) {
        vafm_h5i_err_hdf5(err, rc = VAFM_EIO, "/", "%s: cannot be resumed: the ground truth cannot be rewritten", w->path);
        goto done;
    }
done:
    s_linklist_free(&l);
    free(rows);
    return rc;
}
