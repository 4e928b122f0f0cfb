/* SPDX-License-Identifier: MIT */
/*
 * A measured map as a virtual sample (vafm/map.h, pattern grid): an HDF5 file of 2-D float64 datasets on a
 * regular grid (protocol/hdf5.md, "Map grids"). Everything an input can size is bounded before it is read:
 * at most 2^24 points, each dataset exactly ny × nx, every value finite and in its physical range.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "h5/h5_internal.h"
#include "vafm/map.h"

#define S_MAX_POINTS ((size_t)1 << 24)

/* The grid and the arrays it points to, in one allocation; what vafm_h5_map_grid_load hands out. */
typedef struct s_grid {
    vafm_map_grid g;
    char source[256];
    double data[];
} s_grid;

static int s_scalar(hid_t f, const char *path, const char *name, double *out, vafm_error *err)
{
    vafm_h5i_val v;
    if (vafm_h5i_attr_get(f, name, &v)) {
        vafm_h5i_err(err, VAFM_EFORMAT, name, "%s: root attribute '%s' (float, m) is missing or unreadable", path, name);
        return VAFM_EFORMAT;
    }
    int ok = (v.cls == H5T_FLOAT || v.cls == H5T_INTEGER) && v.npoints == 1;
    double x = v.cls == H5T_FLOAT ? v.d : (double)v.i;
    vafm_h5i_val_free(&v);
    if (!ok || !isfinite(x)) {
        vafm_h5i_err(err, VAFM_EFORMAT, name, "%s: root attribute '%s' must be a finite number", path, name);
        return VAFM_EFORMAT;
    }
    *out = x;
    return 0;
}

/* Dataset `name` (absent: 0, *present = 0): exactly 2-D, ny × nx (the first one sets them), float-convertible,
 * read as doubles into dst when dst is given. */
static int s_dataset(hid_t f, const char *path, const char *name, int *ny, int *nx, double *dst, int *present,
                     vafm_error *err)
{
    *present = 0;
    htri_t ex = H5Lexists(f, name, H5P_DEFAULT);
    if (ex <= 0)
        return 0;
    /* the link's type before it is followed, as the curve reader does: a soft or external link would be opened
     * elsewhere (an external link to a FIFO blocks forever) */
    H5L_info_t li;
    if (H5Lget_info(f, name, &li, H5P_DEFAULT) < 0 || li.type != H5L_TYPE_HARD) {
        vafm_h5i_err(err, VAFM_EFORMAT, name, "%s: '%s' is %s; a map grid's datasets are stored in the file itself "
                     "(hard links, protocol/hdf5.md)", path, name,
                     li.type == H5L_TYPE_EXTERNAL ? "an external link (to another file), not followed"
                     : li.type == H5L_TYPE_SOFT   ? "a soft link, not followed"
                                                  : "a link that cannot be read");
        return VAFM_EFORMAT;
    }
    hid_t d = H5Dopen2(f, name, H5P_DEFAULT);
    if (d < 0) {
        vafm_h5i_err_hdf5(err, VAFM_EFORMAT, name, "%s: '%s' is not a readable dataset", path, name);
        return VAFM_EFORMAT;
    }
    const char *foreign = vafm_h5i_storage_foreign(d); /* before its shape: nothing outside the file is opened */
    if (foreign) {
        vafm_h5i_err(err, VAFM_EFORMAT, name, "%s: '%s' is %s; a map grid's datasets hold their data in the file",
                     path, name, foreign);
        H5Dclose(d);
        return VAFM_EFORMAT;
    }
    hid_t sp = H5Dget_space(d), ty = H5Dget_type(d);
    hsize_t dims[2] = { 0, 0 };
    int rank = sp >= 0 ? H5Sget_simple_extent_ndims(sp) : -1;
    int rc = 0;
    if (rank != 2 || H5Sget_simple_extent_dims(sp, dims, NULL) != 2 || ty < 0 || H5Tget_class(ty) != H5T_FLOAT) {
        vafm_h5i_err(err, VAFM_EFORMAT, name, "%s: '%s' must be a 2-D float dataset [ny][nx]", path, name);
        rc = VAFM_EFORMAT;
    } else if (dims[0] < 2 || dims[1] < 2 || dims[0] > 65536 || dims[1] > 65536 ||
               (size_t)dims[0] * (size_t)dims[1] > S_MAX_POINTS) {
        vafm_h5i_err(err, VAFM_EFORMAT, name, "%s: '%s' is %llu x %llu: a grid has 2 to 65536 points a side and at most "
                     "2^24 in all", path, name, (unsigned long long)dims[0], (unsigned long long)dims[1]);
        rc = VAFM_EFORMAT;
    } else if (*ny && (dims[0] != (hsize_t)*ny || dims[1] != (hsize_t)*nx)) {
        vafm_h5i_err(err, VAFM_EFORMAT, name, "%s: '%s' is %llu x %llu, the other datasets %d x %d", path, name,
                     (unsigned long long)dims[0], (unsigned long long)dims[1], *ny, *nx);
        rc = VAFM_EFORMAT;
    } else {
        *ny = (int)dims[0];
        *nx = (int)dims[1];
        *present = 1;
        if (dst && H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, dst) < 0) {
            vafm_h5i_err_hdf5(err, VAFM_EIO, name, "%s: '%s' cannot be read", path, name);
            rc = VAFM_EIO;
        }
    }
    VAFM_H5I_CLOSE(ty, sp, d);
    return rc;
}

int vafm_h5_map_grid_load(const char *path, vafm_map_grid **out, vafm_error *err)
{
    static const char *const names[3] = { "E_star_Pa", "gamma_J_per_m2", "height_m" };
    static const double lo[3] = { 1e3, 0, -1e-4 }, hi[3] = { 1e13, 100, 1e-4 }; /* the scene's and the map's ranges */
    if (!out || !path) {
        vafm_h5i_err(err, VAFM_EINVAL, "", "vafm_h5_map_grid_load: no file or output given");
        return VAFM_EINVAL;
    }
    *out = NULL;
    int rc = vafm_h5i_check_path(path, 0, err);
    if (rc)
        return rc;
    vafm_h5i_quiet q;
    vafm_h5i_quiet_begin(&q);
    hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    if (f < 0) {
        vafm_h5i_err_hdf5(err, VAFM_EFORMAT, "", "%s: not an HDF5 file that can be read", path);
        vafm_h5i_quiet_end(&q);
        return VAFM_EFORMAT;
    }
    int nx = 0, ny = 0, present[3] = { 0, 0, 0 }, any = 0;
    for (int k = 0; k < 3 && !rc; k++) /* shapes first: nothing is allocated before they are known and bounded */
        rc = s_dataset(f, path, names[k], &ny, &nx, NULL, &present[k], err);
    for (int k = 0; k < 3; k++)
        any |= present[k];
    if (!rc && !any) {
        vafm_h5i_err(err, VAFM_EFORMAT, "E_star_Pa", "%s: a map grid holds at least one of the 2-D datasets E_star_Pa, "
                     "gamma_J_per_m2, height_m", path);
        rc = VAFM_EFORMAT;
    }
    s_grid *g = NULL;
    size_t np = (size_t)nx * (size_t)ny;
    if (!rc && !(g = calloc(1, sizeof *g + 3 * np * sizeof(double)))) {
        vafm_h5i_err(err, VAFM_ENOMEM, "", "%s: out of memory for a %d x %d grid", path, ny, nx);
        rc = VAFM_ENOMEM;
    }
    const double *arr[3] = { NULL, NULL, NULL };
    for (int k = 0; k < 3 && !rc; k++) {
        if (!present[k])
            continue;
        double *dst = g->data + (size_t)k * np;
        int pr;
        rc = s_dataset(f, path, names[k], &ny, &nx, dst, &pr, err);
        for (size_t i = 0; i < np && !rc; i++)
            if (!isfinite(dst[i]) || dst[i] < lo[k] || dst[i] > hi[k]) {
                vafm_h5i_err(err, VAFM_EFORMAT, names[k], "%s: %s[%zu][%zu] = %.6g is outside [%.6g, %.6g]", path,
                             names[k], i / (size_t)nx, i % (size_t)nx, dst[i], lo[k], hi[k]);
                rc = VAFM_EFORMAT;
            }
        arr[k] = dst;
    }
    if (!rc) {
        rc = s_scalar(f, path, "x0_m", &g->g.x0_m, err);
        if (!rc)
            rc = s_scalar(f, path, "y0_m", &g->g.y0_m, err);
        if (!rc)
            rc = s_scalar(f, path, "dx_m", &g->g.dx_m, err);
        if (!rc)
            rc = s_scalar(f, path, "dy_m", &g->g.dy_m, err);
        if (!rc && !(g->g.dx_m > 0 && g->g.dy_m > 0 && g->g.dx_m <= 1e-2 && g->g.dy_m <= 1e-2)) {
            vafm_h5i_err(err, VAFM_EFORMAT, "dx_m", "%s: dx_m = %.6g m and dy_m = %.6g m must lie in (0, 1e-2] m", path,
                         g->g.dx_m, g->g.dy_m);
            rc = VAFM_EFORMAT;
        }
    }
    H5Fclose(f);
    vafm_h5i_quiet_end(&q);
    if (rc) {
        free(g);
        return rc;
    }
    g->g.nx = nx;
    g->g.ny = ny;
    g->g.E_star_Pa = arr[0];
    g->g.gamma_J_per_m2 = arr[1];
    g->g.height_m = arr[2];
    snprintf(g->source, sizeof g->source, "%s", path);
    g->g.source = g->source;
    *out = &g->g;
    return 0;
}

void vafm_h5_map_grid_free(vafm_map_grid **g)
{
    if (!g || !*g)
        return;
    free((s_grid *)(void *)*g); /* the grid is the first member of its allocation */
    *g = NULL;
}
