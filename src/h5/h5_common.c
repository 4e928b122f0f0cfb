/* SPDX-License-Identifier: MIT */
/*
 * Tables and helpers shared by the HDF5 writer, reader and checker: afmformats' metadata keys, the
 * channels, the ground-truth row type, attribute input/output, HDF5 error capture and the defences against
 * damage HDF5 does not catch itself. The value rules (dates, JSON, group names, segments, time, tip) are in
 * h5_rules.c, the checks of a file's path (regular, not in use, writable) in h5_path.c.
 */
#include <ctype.h>
#include <fcntl.h>
#include <math.h>
#include <stddef.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <errno.h>
#include <unistd.h>

#include "h5/h5_internal.h"

#define K_STR(n, f) { n, VAFM_H5I_STR, offsetof(vafm_h5_meta, f), "" }
#define K_REAL(n, f, u) { n, VAFM_H5I_REAL, offsetof(vafm_h5_meta, f), u }
#define K_INT(n, f) { n, VAFM_H5I_INT, offsetof(vafm_h5_meta, f), "" }

/* The list, which is afmformats' META_FIELDS for force-distance without "enum", "path" and
 * "format" (storage keys afmformats fills in itself on load). */
const vafm_h5i_key vafm_h5i_keys[] = {
    K_STR("imaging mode", imaging_mode),
    K_STR("feedback mode", feedback_mode),
    K_STR("instrument", instrument),
    K_STR("software", software),
    K_STR("software version", software_version),
    K_STR("date", date),
    K_STR("time", time),
    K_STR("session id", session_id),
    K_STR("curve id", curve_id),
    K_REAL("spring constant", spring_constant_N_per_m, "N/m"),
    K_REAL("sensitivity", sensitivity_m_per_V, "m/V"),
    K_REAL("setpoint", setpoint_N, "N"),
    K_REAL("rate approach", rate_approach_Hz, "Hz"),
    K_REAL("rate retract", rate_retract_Hz, "Hz"),
    K_REAL("speed approach", speed_approach_m_per_s, "m/s"),
    K_REAL("speed retract", speed_retract_m_per_s, "m/s"),
    K_REAL("duration", duration_s, "s"),
    K_REAL("duration approach", duration_approach_s, "s"),
    K_REAL("duration retract", duration_retract_s, "s"),
    K_REAL("z range", z_range_m, "m"),
    K_REAL("position x", position_x_m, "m"),
    K_REAL("position y", position_y_m, "m"),
    K_REAL("grid center x", grid_center_x_m, "m"),
    K_REAL("grid center y", grid_center_y_m, "m"),
    K_REAL("grid size x", grid_size_x_m, "m"),
    K_REAL("grid size y", grid_size_y_m, "m"),
    K_INT("point count", point_count),
    K_INT("segment count", segment_count),
    K_INT("grid shape x", grid_shape_x),
    K_INT("grid shape y", grid_shape_y),
    K_INT("grid index x", grid_index_x),
    K_INT("grid index y", grid_index_y),
};
const int vafm_h5i_nkeys = (int)(sizeof vafm_h5i_keys / sizeof vafm_h5i_keys[0]);

const vafm_h5i_key *vafm_h5i_key_find(const char *name)
{
    for (int i = 0; i < vafm_h5i_nkeys; i++)
        if (!strcmp(name, vafm_h5i_keys[i].name))
            return &vafm_h5i_keys[i];
    return NULL;
}

int vafm_h5i_key_tolerated(const char *name)
{
    return !strcmp(name, "enum") || !strcmp(name, "path") || !strcmp(name, "format");
}

const vafm_h5i_chan vafm_h5i_chans[VAFM_H5I_NCHAN] = {
    { "force", "N", 0, offsetof(vafm_h5_curve, force_N) },
    { "height (measured)", "m", 0, offsetof(vafm_h5_curve, height_measured_m) },
    { "height (piezo)", "m", 0, offsetof(vafm_h5_curve, height_piezo_m) },
    { "segment", "", 1, offsetof(vafm_h5_curve, segment) },
    { "time", "s", 0, offsetof(vafm_h5_curve, time_s) },
    { "tip position", "m", 0, offsetof(vafm_h5_curve, tip_position_m) },
};

int vafm_h5i_chan_find(const char *name)
{
    for (int i = 0; i < VAFM_H5I_NCHAN; i++)
        if (!strcmp(name, vafm_h5i_chans[i].name))
            return i;
    return -1;
}

/* ---- ground-truth rows ---------------------------------------------------------------------------- */

enum { F_U64, F_I32, F_F64 };
typedef struct s_rowfield {
    const char *name;
    int type;
    size_t offset;
} s_rowfield;

#define RF(name, type) { #name, type, offsetof(vafm_h5i_row, name) }
static const s_rowfield s_rowfields[] = {
    RF(curve, F_U64),
    RF(point, F_U64),
    RF(status, F_I32),
    RF(flags, F_I32),
    RF(T_K, F_F64),
    RF(v_m_per_s, F_F64),
    RF(k_N_per_m, F_F64),
    RF(pulloff_sampled_N, F_F64),
    RF(pulloff_spring_N, F_F64),
    RF(detach_force_N, F_F64),
    RF(detach_height_m, F_F64),
    RF(detach_eq_force_N, F_F64),
    RF(detach_time_s, F_F64),
    RF(touch_time_s, F_F64),
    RF(touch_height_m, F_F64),
    RF(retract_start_s, F_F64),
    RF(duration_s, F_F64),
    RF(samples, F_U64),
    RF(steps, F_U64),
    RF(steps_contact, F_U64),
    RF(steps_free, F_U64),
    RF(E_star_Pa, F_F64), /* format 1.1 */
    RF(gamma_J_per_m2, F_F64),
    RF(surface_height_m, F_F64),
};
#define S_NROWFIELDS_1_0 21
#define S_NROWFIELDS ((int)(sizeof s_rowfields / sizeof s_rowfields[0]))

int vafm_h5i_row_nfields(void)
{
    return S_NROWFIELDS;
}

int vafm_h5i_row_nfields_of(int minor)
{
    return minor >= 1 ? S_NROWFIELDS : S_NROWFIELDS_1_0;
}

void vafm_h5i_row_absent(vafm_h5i_row *row, int minor)
{
    if (minor < 1)
        row->E_star_Pa = row->gamma_J_per_m2 = row->surface_height_m = NAN;
}

const char *vafm_h5i_row_field(int i)
{
    return i >= 0 && i < S_NROWFIELDS ? s_rowfields[i].name : NULL;
}

hid_t vafm_h5i_row_type(int file)
{
    size_t size = 0;
    if (file) {
        for (int i = 0; i < S_NROWFIELDS; i++)
            size += s_rowfields[i].type == F_I32 ? 4 : 8;
    } else {
        size = sizeof(vafm_h5i_row);
    }
    hid_t t = H5Tcreate(H5T_COMPOUND, size);
    if (t < 0)
        return -1;
    size_t off = 0;
    for (int i = 0; i < S_NROWFIELDS; i++) {
        const s_rowfield *f = &s_rowfields[i];
        hid_t ft = f->type == F_U64 ? (file ? H5T_STD_U64LE : H5T_NATIVE_UINT64)
                   : f->type == F_I32 ? (file ? H5T_STD_I32LE : H5T_NATIVE_INT32)
                                      : (file ? H5T_IEEE_F64LE : H5T_NATIVE_DOUBLE);
        if (H5Tinsert(t, f->name, file ? off : f->offset, ft) < 0) {
            H5Tclose(t);
            return -1;
        }
        off += f->type == F_I32 ? 4 : 8;
    }
    return t;
}

void vafm_h5i_row_from_truth(vafm_h5i_row *row, uint64_t curve, const vafm_h5_truth *t)
{
    const vafm_curve_result *r = &t->result;
    memset(row, 0, sizeof *row);
    row->curve = curve;
    row->point = t->point;
    row->status = t->status;
    row->flags = r->flags;
    row->T_K = t->T_K;
    row->v_m_per_s = t->v_m_per_s;
    row->k_N_per_m = t->k_N_per_m;
    row->pulloff_sampled_N = r->pulloff_sampled_N;
    row->pulloff_spring_N = r->pulloff_spring_N;
    row->detach_force_N = r->detach_force_N;
    row->detach_height_m = r->detach_height_m;
    row->detach_eq_force_N = r->detach_eq_force_N;
    row->detach_time_s = r->detach_time_s;
    row->touch_time_s = r->touch_time_s;
    row->touch_height_m = r->touch_height_m;
    row->retract_start_s = r->retract_start_s;
    row->duration_s = r->duration_s;
    row->samples = r->samples;
    row->steps = r->steps;
    row->steps_contact = r->steps_contact;
    row->steps_free = r->steps_free;
    row->E_star_Pa = t->E_star_Pa;
    row->gamma_J_per_m2 = t->gamma_J_per_m2;
    row->surface_height_m = t->surface_height_m;
}

void vafm_h5i_truth_from_row(vafm_h5_truth *t, const vafm_h5i_row *row)
{
    vafm_curve_result *r = &t->result;
    memset(t, 0, sizeof *t);
    t->point = row->point;
    t->status = row->status;
    t->T_K = row->T_K;
    t->v_m_per_s = row->v_m_per_s;
    t->k_N_per_m = row->k_N_per_m;
    r->index = row->curve;
    r->flags = row->flags;
    r->pulloff_sampled_N = row->pulloff_sampled_N;
    r->pulloff_spring_N = row->pulloff_spring_N;
    r->detach_force_N = row->detach_force_N;
    r->detach_height_m = row->detach_height_m;
    r->detach_eq_force_N = row->detach_eq_force_N;
    r->detach_time_s = row->detach_time_s;
    r->touch_time_s = row->touch_time_s;
    r->touch_height_m = row->touch_height_m;
    r->retract_start_s = row->retract_start_s;
    r->duration_s = row->duration_s;
    r->samples = row->samples;
    r->steps = row->steps;
    r->steps_contact = row->steps_contact;
    r->steps_free = row->steps_free;
    t->E_star_Pa = row->E_star_Pa;
    t->gamma_J_per_m2 = row->gamma_J_per_m2;
    t->surface_height_m = row->surface_height_m;
}

/* ---- HDF5 errors ---------------------------------------------------------------------------------- */

/* Before HDF5's first call: no library shutdown at exit. HDF5 1.10 keeps a file whose close failed (a
 * full disk during the final flush) half destroyed in its table of open files, and closing it again at
 * exit reads a NULL pointer inside the library (H5F__close_cb): a full disk ended every run in a
 * segfault after the error was reported. The process ends anyway; the files hold their last flush. */
static pthread_once_t s_init_once = PTHREAD_ONCE_INIT;

static void s_init(void)
{
    H5dont_atexit();
}

void vafm_h5i_quiet_begin(vafm_h5i_quiet *q)
{
    pthread_once(&s_init_once, s_init);
    vafm_h5i_io_errno = 0;
    q->fn = NULL;
    q->data = NULL;
    H5Eget_auto2(H5E_DEFAULT, &q->fn, &q->data);
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
    H5Eclear2(H5E_DEFAULT);
}

void vafm_h5i_quiet_end(const vafm_h5i_quiet *q)
{
    H5Eclear2(H5E_DEFAULT);
    H5Eset_auto2(H5E_DEFAULT, q->fn, q->data);
}

void vafm_h5i_close_ids(const hid_t *ids, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        if (ids[i] < 0)
            continue;
        switch (H5Iget_type(ids[i])) {
        case H5I_ATTR: H5Aclose(ids[i]); break;
        case H5I_DATASPACE: H5Sclose(ids[i]); break;
        case H5I_DATATYPE: H5Tclose(ids[i]); break;
        case H5I_DATASET: H5Dclose(ids[i]); break;
        case H5I_GROUP: H5Gclose(ids[i]); break;
        case H5I_GENPROP_LST: H5Pclose(ids[i]); break;
        case H5I_FILE: H5Fclose(ids[i]); break;
        default: break;
        }
    }
}

static void s_verr(vafm_error *err, int code, const char *object, const char *suffix, const char *fmt,
                   va_list ap)
{
    if (!err)
        return;
    err->code = code;
    snprintf(err->field, sizeof err->field, "%s", object ? object : "");
    int n = vsnprintf(err->message, sizeof err->message, fmt, ap);
    if (suffix && n >= 0 && (size_t)n < sizeof err->message)
        snprintf(err->message + n, sizeof err->message - (size_t)n, "%s", suffix);
}

void vafm_h5i_err(vafm_error *err, int code, const char *object, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    s_verr(err, code, object, NULL, fmt, ap);
    va_end(ap);
}

static herr_t s_walk_first(unsigned n, const H5E_error2_t *e, void *data)
{
    char *buf = data;
    if (n == 0 && e->desc)
        snprintf(buf, 160, "%s", e->desc);
    return 0;
}

void vafm_h5i_reason(char *buf, size_t len)
{
    if (vafm_h5i_io_errno && len) { /* the operating system's reason beats HDF5's generic one */
        snprintf(buf, len, "%s", strerror(vafm_h5i_io_errno));
        return;
    }
    char inner[160] = "";
    /* Walking upward starts at the innermost (most specific) entry. */
    H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, s_walk_first, inner);
    if (inner[0] && len)
        snprintf(buf, len, "%s", inner);
}

void vafm_h5i_err_hdf5(vafm_error *err, int code, const char *object, const char *fmt, ...)
{
    char inner[160] = "", suffix[200] = "";
    vafm_h5i_reason(inner, sizeof inner);
    if (inner[0])
        snprintf(suffix, sizeof suffix, vafm_h5i_io_errno ? ": %s" : " (HDF5: %s)", inner);
    va_list ap;
    va_start(ap, fmt);
    s_verr(err, code, object, suffix, fmt, ap);
    va_end(ap);
    H5Eclear2(H5E_DEFAULT);
}

/* ---- attributes ----------------------------------------------------------------------------------- */

hid_t vafm_h5i_attr_open(hid_t loc, const char *name, hid_t *t, hid_t *sp)
{
    hid_t a = H5Aopen(loc, name, H5P_DEFAULT);
    *t = a >= 0 ? H5Aget_type(a) : -1;
    *sp = a >= 0 ? H5Aget_space(a) : -1;
    return a;
}

void vafm_h5i_val_free(vafm_h5i_val *v)
{
    free(v->s);
    v->s = NULL;
}

int vafm_h5i_attr_get(hid_t loc, const char *name, vafm_h5i_val *v)
{
    memset(v, 0, sizeof *v);
    v->cls = H5T_NO_CLASS;
    hid_t t, sp, mt = -1, a = vafm_h5i_attr_open(loc, name, &t, &sp);
    if (a < 0)
        return -1;
    int rc = -1;
    if (t < 0 || sp < 0)
        goto done;
    v->cls = H5Tget_class(t);
    v->size = H5Tget_size(t);
    v->order = H5Tget_order(t);
    H5S_class_t sc = H5Sget_simple_extent_type(sp);
    v->scalar = sc == H5S_SCALAR;
    v->npoints = H5Sget_simple_extent_npoints(sp);
    if (v->npoints < 0)
        goto done;
    if (v->npoints != 1) {
        rc = 0; /* shape refused by the callers, value not read */
        goto done;
    }
    if (v->cls == H5T_STRING) {
        htri_t vl = H5Tis_variable_str(t);
        if (vl < 0)
            goto done;
        v->vlen = vl > 0;
        v->cset = H5Tget_cset(t);
        if (v->vlen) {
            char *p = NULL;
            mt = H5Tcopy(H5T_C_S1);
            if (mt < 0 || H5Tset_size(mt, H5T_VARIABLE) < 0 || H5Tset_cset(mt, v->cset) < 0)
                goto done;
            if (H5Aread(a, mt, &p) < 0)
                goto done;
            v->s = strdup(p ? p : "");
            if (p)
                H5free_memory(p);
        } else {
            if (v->size == 0 || v->size > (1u << 24))
                goto done;
            v->s = calloc(1, v->size + 1);
            mt = H5Tcopy(H5T_C_S1);
            /* one byte more than stored, NUL-terminated: HDF5 converts NULLPAD/SPACEPAD strings; the
             * character set must match, HDF5 does not convert between ASCII and UTF-8 */
            if (!v->s || mt < 0 || H5Tset_size(mt, v->size + 1) < 0 || H5Tset_strpad(mt, H5T_STR_NULLTERM) < 0 ||
                H5Tset_cset(mt, v->cset) < 0 || H5Aread(a, mt, v->s) < 0)
                goto done;
        }
        if (!v->s)
            goto done;
        rc = 0;
    } else if (v->cls == H5T_INTEGER) {
        v->sign = H5Tget_sign(t);
        if (v->sign == H5T_SGN_NONE) {
            if (H5Aread(a, H5T_NATIVE_UINT64, &v->u) < 0)
                goto done;
            v->i = v->u > (uint64_t)INT64_MAX ? INT64_MAX : (int64_t)v->u;
        } else {
            if (H5Aread(a, H5T_NATIVE_INT64, &v->i) < 0)
                goto done;
            v->u = v->i < 0 ? 0 : (uint64_t)v->i;
        }
        v->d = v->sign == H5T_SGN_NONE ? (double)v->u : (double)v->i;
        v->integral = 1;
        rc = 0;
    } else if (v->cls == H5T_FLOAT) {
        if (H5Aread(a, H5T_NATIVE_DOUBLE, &v->d) < 0)
            goto done;
        v->integral = isfinite(v->d) && v->d == floor(v->d) && fabs(v->d) < 9.2e18;
        if (v->integral) {
            v->i = (int64_t)v->d;
            v->u = v->i < 0 ? 0 : (uint64_t)v->i;
        }
        rc = 0;
    } else {
        rc = 0; /* other classes: refused by the callers */
    }
done:
    VAFM_H5I_CLOSE(mt, t, sp, a);
    if (rc)
        vafm_h5i_val_free(v);
    return rc;
}

hid_t vafm_h5i_str_type(void)
{
    hid_t t = H5Tcopy(H5T_C_S1);
    if (t < 0)
        return -1;
    if (H5Tset_size(t, H5T_VARIABLE) < 0 || H5Tset_cset(t, H5T_CSET_UTF8) < 0) {
        H5Tclose(t);
        return -1;
    }
    return t;
}

static int s_put(hid_t loc, const char *name, hid_t ftype, hid_t mtype, const void *buf)
{
    if (H5Aexists(loc, name) > 0 && H5Adelete(loc, name) < 0)
        return -1;
    hid_t sp = H5Screate(H5S_SCALAR);
    if (sp < 0)
        return -1;
    hid_t a = H5Acreate2(loc, name, ftype, sp, H5P_DEFAULT, H5P_DEFAULT);
    H5Sclose(sp);
    if (a < 0)
        return -1;
    int rc = H5Awrite(a, mtype, buf) < 0 ? -1 : 0;
    if (H5Aclose(a) < 0)
        rc = -1;
    return rc;
}

int vafm_h5i_put_str(hid_t loc, const char *name, const char *value)
{
    hid_t t = vafm_h5i_str_type();
    if (t < 0)
        return -1;
    int rc = s_put(loc, name, t, t, &value);
    H5Tclose(t);
    return rc;
}

int vafm_h5i_put_f64(hid_t loc, const char *name, double value)
{
    return s_put(loc, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &value);
}

int vafm_h5i_put_i64(hid_t loc, const char *name, int64_t value)
{
    return s_put(loc, name, H5T_STD_I64LE, H5T_NATIVE_INT64, &value);
}

int vafm_h5i_put_u64(hid_t loc, const char *name, uint64_t value)
{
    return s_put(loc, name, H5T_STD_U64LE, H5T_NATIVE_UINT64, &value);
}

/* ---- defences ------------------------------------------------------------------------------------- */

static uint64_t s_le(const unsigned char *p, int n)
{
    uint64_t v = 0;
    for (int i = n - 1; i >= 0; i--)
        v = v << 8 | p[i];
    return v;
}

/* Validate the collection at byte pos (its signature already seen). @return 0 valid or not a collection
 * (HDF5 refuses a wrong version by itself), −1 damaged. */
static int s_rd(int fd, const char *path, void **jstate, unsigned char *buf, size_t n, uint64_t off)
{
    /* what HDF5 will see: the file, with a journal left by a killed flush overlaid */
    if (pread(fd, buf, n, (off_t)off) != (ssize_t)n)
        return -1;
    return vafm_h5i_journal_overlay(path, buf, off, n, jstate);
}

static int s_gcol(int fd, const char *path, void **js, uint64_t pos, uint64_t fsize, char *why, size_t len)
{
    unsigned char h[16];
    if (pos + 16 > fsize || s_rd(fd, path, js, h, 16, pos) || memcmp(h, "GCOL", 4) || h[4] != 1)
        return 0;
    uint64_t size = s_le(h + 8, 8);
    if (size < 16 || size > fsize - pos) {
        snprintf(why, len, "global heap collection at byte %llu claims %llu bytes, past the end of the file",
                 (unsigned long long)pos, (unsigned long long)size);
        return -1;
    }
    unsigned char *c = malloc((size_t)size);
    if (!c || s_rd(fd, path, js, c, (size_t)size, pos)) {
        free(c);
        snprintf(why, len, "global heap collection at byte %llu cannot be read", (unsigned long long)pos);
        return -1;
    }
    int rc = 0;
    uint64_t p = 16, prev = 0;
    while (p < size) {
        if (p + 16 > size)
            break; /* a tail too small for an object header is free space */
        uint64_t idx = s_le(c + p, 2), osize = s_le(c + p + 8, 8), need;
        if (idx == 0) {
            need = osize; /* free space, header included; it comes last */
            if (need < 16 || need != size - p) {
                rc = -1;
                break;
            }
        } else {
            if (osize > size || idx <= prev) {
                rc = -1;
                break;
            }
            need = 16 + ((osize + 7) & ~(uint64_t)7);
            if (need > size - p) {
                rc = -1;
                break;
            }
            prev = idx;
        }
        p += need;
    }
    if (rc)
        snprintf(why, len, "global heap collection at byte %llu (variable-length strings) is damaged: object at offset %llu",
                 (unsigned long long)pos, (unsigned long long)p);
    free(c);
    return rc;
}

int vafm_h5i_gheap_check(hid_t file, const char *path, char *why, size_t len)
{
    haddr_t eoa = HADDR_UNDEF;
    if (H5Fget_eoa(file, &eoa) < 0 || eoa == HADDR_UNDEF)
        return -2;
    int fd = open(path, O_RDONLY);
    struct stat st;
    if (fd < 0 || fstat(fd, &st)) {
        if (fd >= 0)
            close(fd);
        return -2;
    }
    uint64_t fsize = (uint64_t)st.st_size < (uint64_t)eoa ? (uint64_t)st.st_size : (uint64_t)eoa;
    enum { BLK = 1 << 20 };
    unsigned char *b = malloc(BLK + 4);
    int rc = b ? 0 : -2;
    void *js = NULL;
    for (uint64_t off = 0; !rc && off < fsize; off += BLK) {
        size_t want = (size_t)(fsize - off < BLK + 3 ? fsize - off : BLK + 3);
        if (s_rd(fd, path, &js, b, want, off)) {
            rc = -2;
            break;
        }
        ssize_t got = (ssize_t)want;
        /* signatures starting in this block (the 3 extra bytes catch one that straddles blocks) */
        const unsigned char *p = b, *end = b + got;
        while (!rc && (p = memmem(p, (size_t)(end - p), "GCOL", 4)) != NULL) {
            uint64_t at = off + (uint64_t)(p - b);
            if (p - b >= BLK)
                break;
            rc = s_gcol(fd, path, &js, at, fsize, why, len);
            p++;
        }
    }
    vafm_h5i_journal_overlay(path, NULL, 0, 0, &js);
    free(b);
    close(fd);
    return rc;
}

int vafm_h5i_storage_complete(hid_t d, hsize_t n)
{
    hid_t dcpl = H5Dget_create_plist(d);
    if (dcpl < 0)
        return -1;
    int rc = 0;
    H5D_layout_t layout = H5Pget_layout(dcpl);
    if (layout == H5D_CHUNKED) {
        hsize_t c = 0;
        if (H5Pget_chunk(dcpl, 1, &c) != 1 || c == 0) {
            rc = -1;
        } else {
            for (hsize_t off = 0; off < n && !rc; off += c) {
                unsigned mask = 0;
                haddr_t addr = HADDR_UNDEF;
                hsize_t size = 0;
                if (H5Dget_chunk_info_by_coord(d, &off, &mask, &addr, &size) < 0 || addr == HADDR_UNDEF || mask != 0 ||
                    size == 0)
                    rc = -1;
            }
        }
    } else if (layout == H5D_CONTIGUOUS) {
        if (n > 0 && H5Dget_offset(d) == HADDR_UNDEF)
            rc = -1;
    } else if (layout != H5D_COMPACT) {
        rc = -1; /* virtual datasets point into other files */
    }
    H5Pclose(dcpl);
    return rc;
}

const char *vafm_h5i_storage_foreign(hid_t d)
{
    hid_t dcpl = H5Dget_create_plist(d);
    if (dcpl < 0)
        return "a dataset whose storage layout cannot be read (not read)";
    const char *why = NULL;
    H5D_layout_t layout = H5Pget_layout(dcpl);
    int next = H5Pget_external_count(dcpl);
    if (layout == H5D_VIRTUAL)
        why = "a virtual dataset, its data in other files (not read)";
    else if (next != 0) /* < 0: the list cannot be read, so where the data lie is not known either */
        why = "stored in an external file (not read)";
    else if (layout != H5D_CONTIGUOUS && layout != H5D_CHUNKED && layout != H5D_COMPACT)
        why = "a dataset whose storage layout cannot be read (not read)";
    H5Pclose(dcpl);
    return why;
}

void vafm_h5i_names_free(vafm_h5i_names *l)
{
    for (size_t i = 0; i < l->n; i++)
        free(l->v[i]);
    free(l->v);
    memset(l, 0, sizeof *l);
}

int vafm_h5i_names_push(vafm_h5i_names *l, const char *name)
{
    if (l->n == l->cap) {
        size_t cap = l->cap ? 2 * l->cap : 16;
        char **v = realloc(l->v, cap * sizeof *v);
        if (!v)
            return -1;
        l->v = v;
        l->cap = cap;
    }
    if (!(l->v[l->n] = strdup(name)))
        return -1;
    l->n++;
    return 0;
}

herr_t vafm_h5i_link_cb(hid_t g, const char *name, const H5L_info_t *info, void *data)
{
    (void)g;
    vafm_h5i_names *l = data;
    if (info->type != H5L_TYPE_HARD && !l->bad) {
        l->bad = 1;
        snprintf(l->bad_name, sizeof l->bad_name, "%s", name);
    }
    return vafm_h5i_names_push(l, name) ? -1 : 0;
}

herr_t vafm_h5i_attr_cb(hid_t loc, const char *name, const H5A_info_t *info, void *data)
{
    (void)loc;
    (void)info;
    return vafm_h5i_names_push(data, name) ? -1 : 0;
}

/* ---- version strings ------------------------------------------------------------------------------ */

static int s_version_part(const char *s, const char **end, int *v)
{
    int n = 0;
    long x = 0;
    while (s[n] >= '0' && s[n] <= '9' && n < 6)
        x = 10 * x + (s[n++] - '0');
    *end = s + n;
    *v = (int)x;
    return n > 0 && !(s[n] >= '0' && s[n] <= '9') ? 0 : -1;
}

int vafm_h5i_format_parse(const char *s, int *major, int *minor)
{
    const char *p;
    if (!s || s_version_part(s, &p, major) || *p != '.' || s_version_part(p + 1, &p, minor) || *p)
        return -1;
    return 0;
}
