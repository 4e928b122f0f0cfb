/* SPDX-License-Identifier: MIT */
/*
 * Force maps (vafm/map.h): the sample model. One table lists the spec's fields (name, kind, unit, range)
 * for setting by name, validation and JSON; the patterns are pure functions of the pixel position.
 */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "vafm/map.h"
#include "core/internal.h"
#include "core/models.h"

enum { S_INT, S_REAL, S_SEED, S_PATTERN, S_START, S_CONTACT };

typedef struct s_mfield {
    const char *name;
    int kind;
    size_t offset;
    const char *unit;
    double min, max;
    int nan_ok; /* NaN allowed: "the base scene's value" */
} s_mfield;

#define MF(name, kind, unit, lo, hi) { #name, kind, offsetof(vafm_map_spec, name), unit, lo, hi, 0 }
#define MAT(pfx, i)                                                                                                \
    { pfx "contact", S_CONTACT, offsetof(vafm_map_spec, material[i].contact), "", 0, 0, 0 },                     \
    { pfx "E_star_Pa", S_REAL, offsetof(vafm_map_spec, material[i].E_star_Pa), "Pa", 1e3, 1e13, 1 },            \
    { pfx "gamma_J_per_m2", S_REAL, offsetof(vafm_map_spec, material[i].gamma_J_per_m2), "J/m^2", 0, 100, 1 }

static const s_mfield s_fields[] = {
    MF(nx, S_INT, "pixels", 1, VAFM_MAP_MAX_SIDE),
    MF(ny, S_INT, "pixels", 1, VAFM_MAP_MAX_SIDE),
    MF(size_x_m, S_REAL, "m", 0, 1e-2),
    MF(size_y_m, S_REAL, "m", 0, 1e-2),
    MF(center_x_m, S_REAL, "m", -1e-2, 1e-2),
    MF(center_y_m, S_REAL, "m", -1e-2, 1e-2),
    MF(pattern, S_PATTERN, "", 0, 0),
    MF(start, S_START, "", 0, 0),
    MAT("a_", 0),
    MAT("b_", 1),
    MF(period_m, S_REAL, "m", 0, 1e-2),
    MF(radius_m, S_REAL, "m", 0, 1e-2),
    MF(height_m, S_REAL, "m", 0, 1e-4),
    /* at least a picometre: the noise's lattice index floor(2x / domain_m) stays below 3e10 for any pixel
     * (|x| <= |center| + size/2 <= 1.5e-2 m), far inside int64 and exact in a double (1e-300 overflowed the
     * conversion, undefined behaviour, and made a degenerate map) */
    MF(domain_m, S_REAL, "m", 1e-12, 1e-2),
    MF(domain_seed, S_SEED, "", 0, 0),
    MF(fraction, S_REAL, "", 0, 1),
};
#undef MF
#undef MAT
#define S_NFIELDS ((int)(sizeof s_fields / sizeof s_fields[0]))

/* lengths that must be > 0 (their range's lower bound is open) */
static int s_open_low(const s_mfield *f)
{
    return f->kind == S_REAL && f->min == 0 && !strcmp(f->unit, "m") && strcmp(f->name, "height_m");
}

static const char *const s_patterns[] = { "uniform", "stripes", "disc", "dome", "domains", "grid" };
#define S_NPATTERNS ((int)(sizeof s_patterns / sizeof s_patterns[0]))
static const char *const s_starts[] = { "surface", "fixed" };

void vafm_map_spec_default(vafm_map_spec *s)
{
    if (!s)
        return;
    memset(s, 0, sizeof *s);
    s->nx = s->ny = 32;
    s->size_x_m = s->size_y_m = 10e-6;
    s->pattern = VAFM_MAP_UNIFORM;
    s->material[0].contact = NULL;
    s->material[0].E_star_Pa = NAN;
    s->material[0].gamma_J_per_m2 = NAN;
    s->material[1].contact = NULL;
    s->material[1].E_star_Pa = 1e9;
    s->material[1].gamma_J_per_m2 = 0.02;
    s->period_m = 5e-6;
    s->radius_m = 3e-6;
    s->height_m = 0.5e-6;
    s->domain_m = 1e-6;
    s->domain_seed = 1;
    s->fraction = 0.5;
    s->start = VAFM_MAP_START_SURFACE;
}

size_t vafm_map_pixels(const vafm_map_spec *s)
{
    if (!s || s->nx < 1 || s->ny < 1 || s->nx > VAFM_MAP_MAX_SIDE || s->ny > VAFM_MAP_MAX_SIDE)
        return 0;
    return (size_t)s->nx * (size_t)s->ny;
}

const char *vafm_map_pattern_name(int p)
{
    return p >= 0 && p < S_NPATTERNS ? s_patterns[p] : NULL;
}

int vafm_map_pattern_find(const char *name, vafm_error *err)
{
    for (int i = 0; name && i < S_NPATTERNS; i++)
        if (!strcmp(name, s_patterns[i]))
            return i;
    vafm_err_set(err, VAFM_ENOTFOUND, "pattern", "pattern '%s' is not known (uniform, stripes, disc, dome, domains, grid)",
                 name ? name : "");
    return VAFM_ENOTFOUND;
}

static const s_mfield *s_find(const char *name)
{
    for (int i = 0; i < S_NFIELDS; i++)
        if (!strcmp(name, s_fields[i].name))
            return &s_fields[i];
    return NULL;
}

/* One field's own range. */
static int s_check_field(const vafm_map_spec *s, const s_mfield *f, vafm_error *err)
{
    const char *base = (const char *)s + f->offset;
    switch (f->kind) {
    case S_INT: {
        int v = *(const int *)base;
        if (v < (int)f->min || v > (int)f->max) {
            vafm_err_set(err, VAFM_EINVAL, f->name, "%s = %d is outside the allowed range [%.0f, %.0f] %s", f->name, v,
                         f->min, f->max, f->unit);
            return VAFM_EINVAL;
        }
        return 0;
    }
    case S_REAL: {
        double v = *(const double *)base;
        if (f->nan_ok && isnan(v))
            return 0;
        int low_ok = s_open_low(f) ? v > f->min : v >= f->min;
        if (!isfinite(v) || !low_ok || v > f->max) {
            vafm_err_set(err, VAFM_EINVAL, f->name, "%s = %.6g %s is outside the allowed range %s%.6g, %.6g] %s%s",
                         f->name, v, f->unit, s_open_low(f) ? "(" : "[", f->min, f->max, f->unit,
                         f->nan_ok ? " (or NaN: the base scene's)" : "");
            return VAFM_EINVAL;
        }
        return 0;
    }
    case S_PATTERN: {
        int v = *(const int *)base;
        if (v < 0 || v >= S_NPATTERNS) {
            vafm_err_set(err, VAFM_EINVAL, f->name, "pattern = %d is not one of uniform|stripes|disc|dome|domains|grid", v);
            return VAFM_EINVAL;
        }
        return 0;
    }
    case S_START: {
        int v = *(const int *)base;
        if (v != VAFM_MAP_START_SURFACE && v != VAFM_MAP_START_FIXED) {
            vafm_err_set(err, VAFM_EINVAL, f->name, "start = %d is not one of surface|fixed", v);
            return VAFM_EINVAL;
        }
        return 0;
    }
    default:
        return 0;
    }
}

static int s_check_spec(const vafm_map_spec *s, vafm_error *err)
{
    if (!s) {
        vafm_err_set(err, VAFM_EINVAL, "", "no map spec given");
        return VAFM_EINVAL;
    }
    for (int i = 0; i < S_NFIELDS; i++) {
        int r = s_check_field(s, &s_fields[i], err);
        if (r)
            return r;
    }
    if ((size_t)s->nx * (size_t)s->ny > VAFM_MAP_MAX_PIXELS) {
        vafm_err_set(err, VAFM_EINVAL, "nx", "nx x ny = %d x %d = %zu pixels is more than the %d a map may have", s->nx,
                     s->ny, (size_t)s->nx * (size_t)s->ny, VAFM_MAP_MAX_PIXELS);
        return VAFM_EINVAL;
    }
    if (s->pattern == VAFM_MAP_GRID) {
        const vafm_map_grid *g = s->grid;
        if (!g || g->nx < 2 || g->ny < 2 || !(g->dx_m > 0) || !(g->dy_m > 0) || !isfinite(g->x0_m) ||
            !isfinite(g->y0_m) || (size_t)g->nx * (size_t)g->ny > ((size_t)1 << 24)) {
            vafm_err_set(err, VAFM_EINVAL, "grid", "pattern grid needs a measured map: at least 2 x 2 points (at most "
                         "2^24), positive spacings and a finite origin (vafm_h5_map_grid_load reads one)");
            return VAFM_EINVAL;
        }
        /* the pixels' centres against the grid's points: without overlap every pixel would take the nearest
         * edge's value (clamped), a uniform map that says nothing of the grid */
        double wx = s->size_x_m / s->nx, wy = s->size_y_m / s->ny; /* a pixel's width and height */
        double px0 = s->center_x_m - 0.5 * s->size_x_m + 0.5 * wx, px1 = px0 + (s->nx - 1) * wx;
        double py0 = s->center_y_m - 0.5 * s->size_y_m + 0.5 * wy, py1 = py0 + (s->ny - 1) * wy;
        double gx1 = g->x0_m + (g->nx - 1) * g->dx_m, gy1 = g->y0_m + (g->ny - 1) * g->dy_m;
        if (px1 < g->x0_m || px0 > gx1 || py1 < g->y0_m || py0 > gy1) {
            vafm_err_set(err, VAFM_EINVAL, "grid", "the map's pixels (centres x [%.6g, %.6g] m, y [%.6g, %.6g] m) do not "
                         "overlap the sample grid (x [%.6g, %.6g] m, y [%.6g, %.6g] m): every pixel would take an edge's "
                         "value; move the map (center_x_m, center_y_m) or the grid (x0_m, y0_m)", px0, px1, py0, py1,
                         g->x0_m, gx1, g->y0_m, gy1);
            return VAFM_EINVAL;
        }
    }
    if (s->pattern == VAFM_MAP_DOME && s->height_m > s->radius_m) {
        vafm_err_set(err, VAFM_EINVAL, "height_m",
                     "height_m = %.6g m: a dome (spherical cap) is at most as high as its radius_m = %.6g m",
                     s->height_m, s->radius_m);
        return VAFM_EINVAL;
    }
    return 0;
}

/* The spec, and a base scene to apply it to. */
static int s_check_spec_base(const vafm_map_spec *s, const vafm_params *base, vafm_error *err)
{
    int r = s_check_spec(s, err);
    if (r)
        return r;
    if (!base) {
        vafm_err_set(err, VAFM_EINVAL, "", "no base scene given");
        return VAFM_EINVAL;
    }
    return 0;
}

/* ---- the patterns ---------------------------------------------------------------------------------- */

/* A uniform number in [0, 1) from (seed, i, j): splitmix64 of a combined key. */
static double s_lattice(uint64_t seed, int64_t i, int64_t j)
{
    uint64_t z = seed ^ ((uint64_t)i * 0x9E3779B97F4A7C15ULL) ^ ((uint64_t)j * 0xC2B2AE3D27D4EB4FULL);
    for (int r = 0; r < 2; r++) {
        z += 0x9E3779B97F4A7C15ULL;
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
        z ^= z >> 31;
    }
    return (double)(z >> 11) * 0x1.0p-53;
}

/* Value noise: the lattice values interpolated with a smoothstep, at (x, y) in lattice units; |x|, |y| are at
 * most 3e10 (domain_m's lower bound), so the conversions to int64 and i + 1 cannot overflow. */
static double s_noise(uint64_t seed, double x, double y)
{
    double fx = floor(x), fy = floor(y);
    double tx = x - fx, ty = y - fy;
    int64_t i = (int64_t)fx, j = (int64_t)fy;
    double sx = tx * tx * (3.0 - 2.0 * tx), sy = ty * ty * (3.0 - 2.0 * ty);
    double a = s_lattice(seed, i, j), b = s_lattice(seed, i + 1, j);
    double c = s_lattice(seed, i, j + 1), d = s_lattice(seed, i + 1, j + 1);
    double lo = a + (b - a) * sx, hi = c + (d - c) * sx;
    return lo + (hi - lo) * sy;
}

/* A measured grid's value at (x, y): bilinear between the four points around it, clamped at the edges. */
static double s_grid_at(const vafm_map_grid *g, const double *v, double x, double y)
{
    double u = (x - g->x0_m) / g->dx_m, w = (y - g->y0_m) / g->dy_m;
    u = fmin(fmax(u, 0.0), (double)(g->nx - 1));
    w = fmin(fmax(w, 0.0), (double)(g->ny - 1));
    int i = (int)fmin(floor(u), (double)(g->nx - 2)), j = (int)fmin(floor(w), (double)(g->ny - 2));
    double tu = u - i, tw = w - j;
    const double *r0 = v + (size_t)j * (size_t)g->nx, *r1 = r0 + g->nx;
    double lo = r0[i] + (r0[i + 1] - r0[i]) * tu, hi = r1[i] + (r1[i + 1] - r1[i]) * tu;
    return lo + (hi - lo) * tw;
}

/* The material and surface height at (x, y). */
static void s_sample_at(const vafm_map_spec *s, double x, double y, int *mat, double *h)
{
    *mat = 0;
    *h = 0.0;
    switch (s->pattern) {
    case VAFM_MAP_STRIPES: {
        double ph = (x - (s->center_x_m - 0.5 * s->size_x_m)) / s->period_m;
        *mat = ph - floor(ph) >= 0.5;
        break;
    }
    case VAFM_MAP_DISC:
    case VAFM_MAP_DOME: {
        double r = hypot(x - s->center_x_m, y - s->center_y_m);
        if (r < s->radius_m) {
            *mat = 1;
            if (s->pattern == VAFM_MAP_DISC || s->height_m <= 0) {
                *h = s->height_m;
            } else { /* a spherical cap of base radius R and height H: sphere radius (R² + H²)/2H */
                double R = s->radius_m, H = s->height_m, Rs = (R * R + H * H) / (2.0 * H);
                *h = fmax(0.0, sqrt(Rs * Rs - r * r) - (Rs - H));
            }
        }
        break;
    }
    case VAFM_MAP_DOMAINS: {
        /* two octaves, so domains are not lattice squares */
        double u = x / s->domain_m, v = y / s->domain_m;
        double n = (2.0 * s_noise(s->domain_seed, u, v) + s_noise(s->domain_seed ^ 0x5bd1e995ULL, 2.0 * u, 2.0 * v)) / 3.0;
        *mat = n < s->fraction;
        break;
    }
    case VAFM_MAP_GRID:
        if (s->grid && s->grid->height_m)
            *h = s_grid_at(s->grid, s->grid->height_m, x, y);
        break;
    default:
        break;
    }
}

int vafm_map_surface_at(const vafm_map_spec *s, double x_m, double y_m, int *material, double *height_m)
{
    if (!s || !isfinite(x_m) || !isfinite(y_m))
        return VAFM_EINVAL;
    int mat;
    double h;
    s_sample_at(s, x_m, y_m, &mat, &h);
    if (material)
        *material = mat;
    if (height_m)
        *height_m = h;
    return 0;
}

/* The scene and truth at (x, y) of the scan plane: vafm_map_pixel's rule, shared with vafm_map_point. */
static void s_scene_at(const vafm_map_spec *s, const vafm_params *base, double x, double y, int ix, int iy,
                       vafm_params *out, vafm_map_truth *truth)
{
    int mat;
    double h;
    s_sample_at(s, x, y, &mat, &h);
    const vafm_map_material *m = &s->material[mat];
    const vafm_contact_type *ct = m->contact ? m->contact : base->contact;
    double E = isnan(m->E_star_Pa) ? base->E_star_Pa : m->E_star_Pa;
    const int adhesive = ct && (ct->flags & VAFM_CONTACT_ADHESIVE);
    double g = adhesive ? (isnan(m->gamma_J_per_m2) ? base->gamma_J_per_m2 : m->gamma_J_per_m2) : 0.0;
    if (s->pattern == VAFM_MAP_GRID && s->grid) { /* the measured map's values where it has them */
        if (s->grid->E_star_Pa)
            E = s_grid_at(s->grid, s->grid->E_star_Pa, x, y);
        if (s->grid->gamma_J_per_m2 && adhesive)
            g = s_grid_at(s->grid, s->grid->gamma_J_per_m2, x, y);
    }
    if (out) {
        *out = *base;
        out->contact = ct;
        out->E_star_Pa = E;
        out->gamma_J_per_m2 = g;
        out->surface_height_m = h;
        if (s->start == VAFM_MAP_START_FIXED) {
            out->start_height_m = base->start_height_m - h;
            out->trigger_height_m = base->trigger_height_m - h;
        }
    }
    if (truth) {
        memset(truth, 0, sizeof *truth);
        truth->ix = ix;
        truth->iy = iy;
        truth->index = ix >= 0 && iy >= 0 ? (uint64_t)iy * (uint64_t)s->nx + (uint64_t)ix : UINT64_MAX;
        truth->x_m = x;
        truth->y_m = y;
        truth->material = mat;
        truth->contact = ct;
        truth->E_star_Pa = E;
        truth->gamma_J_per_m2 = g;
        truth->surface_height_m = h;
    }
}

int vafm_map_pixel(const vafm_map_spec *s, const vafm_params *base, int ix, int iy, vafm_params *out,
                   vafm_map_truth *truth, vafm_error *err)
{
    int r = s_check_spec_base(s, base, err);
    if (r)
        return r;
    if (ix < 0 || ix >= s->nx || iy < 0 || iy >= s->ny) {
        vafm_err_set(err, VAFM_EINVAL, ix < 0 || ix >= s->nx ? "ix" : "iy",
                     "pixel (%d, %d) is outside the %d x %d grid", ix, iy, s->nx, s->ny);
        return VAFM_EINVAL;
    }
    double x = s->center_x_m - 0.5 * s->size_x_m + ((double)ix + 0.5) * (s->size_x_m / (double)s->nx);
    double y = s->center_y_m - 0.5 * s->size_y_m + ((double)iy + 0.5) * (s->size_y_m / (double)s->ny);
    s_scene_at(s, base, x, y, ix, iy, out, truth);
    return 0;
}

int vafm_map_point(const vafm_map_spec *s, const vafm_params *base, double x_m, double y_m, vafm_params *out,
                   vafm_map_truth *truth, vafm_error *err)
{
    int r = s_check_spec_base(s, base, err);
    if (r)
        return r;
    if (!isfinite(x_m) || !isfinite(y_m)) {
        vafm_err_set(err, VAFM_EINVAL, isfinite(x_m) ? "y_m" : "x_m", "the point (%g, %g) m is not finite", x_m, y_m);
        return VAFM_EINVAL;
    }
    /* the pixel that holds the point, or -1 outside the grid */
    const double fx = (x_m - (s->center_x_m - 0.5 * s->size_x_m)) / (s->size_x_m / (double)s->nx);
    const double fy = (y_m - (s->center_y_m - 0.5 * s->size_y_m)) / (s->size_y_m / (double)s->ny);
    const int ix = fx >= 0 && fx < (double)s->nx ? (int)fx : -1, iy = fy >= 0 && fy < (double)s->ny ? (int)fy : -1;
    s_scene_at(s, base, x_m, y_m, ix < 0 || iy < 0 ? -1 : ix, ix < 0 || iy < 0 ? -1 : iy, out, truth);
    return 0;
}

int vafm_map_validate(const vafm_map_spec *s, const vafm_params *base, vafm_error *err)
{
    int r = s_check_spec_base(s, base, err);
    if (r)
        return r;
    /* every pixel's scene (the errors name the pixel and its material) */
    vafm_params prev;
    int have_prev = 0;
    for (int iy = 0; iy < s->ny; iy++)
        for (int ix = 0; ix < s->nx; ix++) {
            vafm_params p;
            vafm_map_truth t;
            vafm_map_pixel(s, base, ix, iy, &p, &t, NULL);
            if (s->start == VAFM_MAP_START_FIXED && !(p.start_height_m > 0) && !base->start_in_contact) {
                vafm_err_set(err, VAFM_EINVAL, "start_height_m",
                             "start mode fixed: start_height_m = %.6g m above the substrate must lie above the map's "
                             "highest surface (%.6g m at pixel (%d, %d)); raise it or use start mode surface",
                             base->start_height_m, t.surface_height_m, ix, iy);
                return VAFM_EINVAL;
            }
            if (have_prev && !memcmp(&p, &prev, sizeof p))
                continue; /* the scene of the pixel before (most pixels of a pattern share one) */
            r = vafm_params_validate(&p, err);
            prev = p;
            have_prev = 1;
            if (r) {
                if (err) {
                    char msg[sizeof err->message + 96];
                    snprintf(msg, sizeof msg, "pixel (%d, %d), material %c (%s, E* = %.4g Pa, gamma = %.4g J/m^2): %s",
                             ix, iy, 'a' + t.material, t.contact ? t.contact->name : "?", t.E_star_Pa,
                             t.gamma_J_per_m2, err->message[0] ? err->message : vafm_strerror(r));
                    snprintf(err->message, sizeof err->message, "%.*s", (int)(sizeof err->message - 1), msg);
                }
                return r;
            }
        }
    return 0;
}

/* ---- campaigns over a map --------------------------------------------------------------------------- */

static int s_point(void *user, const vafm_params *base, size_t point, vafm_params *out)
{
    const vafm_map_spec *s = user;
    return vafm_map_pixel(s, base, (int)(point % (size_t)s->nx), (int)(point / (size_t)s->nx), out, NULL, NULL);
}

int vafm_map_campaign(const vafm_map_spec *s, vafm_campaign_spec *grid)
{
    size_t n = vafm_map_pixels(s);
    if (!n || !grid || n > VAFM_MAP_MAX_PIXELS)
        return VAFM_EINVAL;
    grid->T_K = grid->v_m_per_s = grid->k_N_per_m = NULL;
    grid->n_T = grid->n_v = grid->n_k = 0;
    grid->curves_per_point = 1;
    grid->n_points = n;
    grid->point_fn = s_point;
    grid->point_user = (void *)s;
    return 0;
}

/* ---- setting by name, JSON -------------------------------------------------------------------------- */

static void s_list_fields(char *buf, size_t len)
{
    size_t n = 0;
    buf[0] = 0;
    for (int i = 0; i < S_NFIELDS && n < len; i++) {
        int w = snprintf(buf + n, len - n, "%s%s", i ? ", " : "", s_fields[i].name);
        if (w < 0)
            break;
        n += (size_t)w;
    }
}

int vafm_map_set(vafm_map_spec *s, const char *name, const char *value, vafm_error *err)
{
    if (!s || !name || !value) {
        vafm_err_set(err, VAFM_EINVAL, "", "vafm_map_set: no spec, name or value");
        return VAFM_EINVAL;
    }
    const s_mfield *f = s_find(name);
    if (!f) {
        char names[300];
        s_list_fields(names, sizeof names);
        vafm_err_set(err, VAFM_ENOTFOUND, name, "'%s' is not a map parameter (%s)", name, names);
        return VAFM_ENOTFOUND;
    }
    char *base = (char *)s + f->offset;
    char *end = NULL;
    errno = 0;
    switch (f->kind) {
    case S_INT: {
        long v = strtol(value, &end, 10);
        if (end == value || *end || errno || v < (long)f->min || v > (long)f->max) {
            vafm_err_set(err, VAFM_EINVAL, f->name, "%s = '%s' is not an integer in [%.0f, %.0f] %s", f->name, value,
                         f->min, f->max, f->unit);
            return VAFM_EINVAL;
        }
        *(int *)base = (int)v;
        return 0;
    }
    case S_REAL: {
        double v = strtod(value, &end);
        if (end == value || *end) {
            vafm_err_set(err, VAFM_EINVAL, f->name, "%s = '%s' is not a number (%s)", f->name, value, f->unit);
            return VAFM_EINVAL;
        }
        double old = *(double *)base;
        *(double *)base = v;
        int r = s_check_field(s, f, err);
        if (r)
            *(double *)base = old;
        return r;
    }
    case S_SEED: {
        if (value[0] == '-') {
            vafm_err_set(err, VAFM_EINVAL, f->name, "%s = '%s' is not a non-negative integer", f->name, value);
            return VAFM_EINVAL;
        }
        unsigned long long v = strtoull(value, &end, 10);
        if (end == value || *end || errno) {
            vafm_err_set(err, VAFM_EINVAL, f->name, "%s = '%s' is not an integer in [0, 2^64-1]", f->name, value);
            return VAFM_EINVAL;
        }
        *(uint64_t *)base = (uint64_t)v;
        return 0;
    }
    case S_PATTERN: {
        int p = vafm_map_pattern_find(value, err);
        if (p < 0)
            return p;
        *(int *)base = p;
        return 0;
    }
    case S_START:
        for (int i = 0; i < 2; i++)
            if (!strcmp(value, s_starts[i])) {
                *(int *)base = i;
                return 0;
            }
        vafm_err_set(err, VAFM_EINVAL, f->name, "start = '%s' is not one of surface|fixed", value);
        return VAFM_EINVAL;
    case S_CONTACT: {
        const vafm_contact_type *t = vafm_contact_type_find(value);
        if (!t) {
            vafm_err_set(err, VAFM_EINVAL, f->name, "%s = '%s' is not one of " VAFM_CONTACT_CHOICES, f->name, value);
            return VAFM_EINVAL;
        }
        *(const vafm_contact_type **)base = t;
        return 0;
    }
    default:
        return VAFM_EINVAL;
    }
}

/* A 64-bit hash of a measured grid's shape and values (their bit patterns, NULL arrays marked as absent): the map's
 * JSON records it, so a resume with other values in the same geometry (and file name) is refused. Each step is
 * a bijection of the state (splitmix64's finaliser of state ^ word), so one changed value always changes it. */
static uint64_t s_mix(uint64_t z)
{
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

static uint64_t s_grid_hash(const vafm_map_grid *g)
{
    const double *a[3] = { g->E_star_Pa, g->gamma_J_per_m2, g->height_m };
    size_t np = (size_t)g->nx * (size_t)g->ny;
    uint64_t h = s_mix(0x9E3779B97F4A7C15ULL ^ ((uint64_t)(uint32_t)g->nx << 32 | (uint32_t)g->ny));
    for (int k = 0; k < 3; k++) {
        h = s_mix(h ^ (a[k] ? 0x5A17ULL + (uint64_t)k : 0xAB5E27ULL + (uint64_t)k));
        for (size_t i = 0; a[k] && i < np; i++) {
            uint64_t w;
            memcpy(&w, &a[k][i], sizeof w);
            h = s_mix(h ^ w);
        }
    }
    return h;
}

int vafm_map_to_json(const vafm_map_spec *s, char *buf, size_t len)
{
    if (!s || !buf || len < 3)
        return VAFM_EINVAL;
    size_t n = 0;
    if (vafm_buf_appendf(buf, len, &n, "{"))
        return VAFM_EINVAL;
    for (int i = 0; i < S_NFIELDS; i++) {
        const s_mfield *f = &s_fields[i];
        const char *base = (const char *)s + f->offset;
        char val[64];
        switch (f->kind) {
        case S_INT:
            snprintf(val, sizeof val, "%d", *(const int *)base);
            break;
        case S_REAL: {
            double v = *(const double *)base;
            if (isnan(v))
                snprintf(val, sizeof val, "null");
            else
                snprintf(val, sizeof val, "%.17g", v);
            break;
        }
        case S_SEED:
            snprintf(val, sizeof val, "\"%" PRIu64 "\"", *(const uint64_t *)base);
            break;
        case S_PATTERN: {
            const char *nm = vafm_map_pattern_name(*(const int *)base);
            snprintf(val, sizeof val, "\"%s\"", nm ? nm : "?");
            break;
        }
        case S_START: {
            int v = *(const int *)base;
            snprintf(val, sizeof val, "\"%s\"", v == 0 || v == 1 ? s_starts[v] : "?");
            break;
        }
        case S_CONTACT: {
            const vafm_contact_type *t = *(const vafm_contact_type *const *)base;
            if (t)
                snprintf(val, sizeof val, "\"%s\"", t->name);
            else
                snprintf(val, sizeof val, "null");
            break;
        }
        default:
            snprintf(val, sizeof val, "null");
        }
        if (vafm_buf_appendf(buf, len, &n, "%s\"%s\": %s", i ? ", " : "", f->name, val))
            return VAFM_EINVAL;
    }
    if (s->pattern == VAFM_MAP_GRID && s->grid) { /* the measured map: its geometry, what it holds, where from */
        const vafm_map_grid *g = s->grid;
        char src[300] = "null";
        if (g->source) { /* a file name: JSON-escape the two characters that need it, drop control characters */
            size_t k = 0;
            src[k++] = '"';
            for (const char *c = g->source; *c && k < sizeof src - 3; c++) {
                if (*c == '"' || *c == '\\')
                    src[k++] = '\\';
                if ((unsigned char)*c >= 0x20)
                    src[k++] = *c;
            }
            src[k++] = '"';
            src[k] = '\0';
        }
        if (vafm_buf_appendf(buf, len, &n, ", \"grid\": {\"nx\": %d, \"ny\": %d, \"x0_m\": %.17g, \"y0_m\": %.17g, \"dx_m\": %.17g, "
                             "\"dy_m\": %.17g, \"E_star_Pa\": %s, \"gamma_J_per_m2\": %s, \"height_m\": %s, \"values_hash\": "
                             "\"%016" PRIx64 "\", \"source\": %s}", g->nx, g->ny, g->x0_m, g->y0_m, g->dx_m, g->dy_m,
                             g->E_star_Pa ? "true" : "false", g->gamma_J_per_m2 ? "true" : "false", g->height_m ? "true" : "false",
                             s_grid_hash(g), src))
            return VAFM_EINVAL;
    }
    if (vafm_buf_appendf(buf, len, &n, "}"))
        return VAFM_EINVAL;
    return (int)n;
}
