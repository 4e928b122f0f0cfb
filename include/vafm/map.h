/* SPDX-License-Identifier: MIT */
/**
 * @file map.h
 * Force maps: a grid of force curves over a heterogeneous sample (issue #15). A map spec places nx × ny
 * pixels on a scan area and a sample pattern on it: each pixel gets a material (contact model, E*, γ)
 * and a surface height. vafm_map_pixel() turns a base scene into the pixel's scene and gives the pixel's
 * ground truth; the sample model does no I/O and draws no random numbers at run time (the `domains`
 * pattern is a pure function of its seed and the position).
 *
 * Pixel (ix, iy) sits at the centre of its cell: x = center_x − size_x/2 + (ix + ½)·size_x/nx (and so
 * for y), afmformats' convention (its "grid size" spans the whole image, boundaries of the pixels
 * included). Its curve index is iy·nx + ix (scan order: x fastest), its random stream (seed, index).
 *
 * Topography: the pixel's scene has surface_height_m = the local surface height, so every piezo height of
 * its curve is measured from the substrate and the contact point sits at that height. The approach
 * starts (start mode):
 *  - `surface` (the default): start_height_m above the local surface, the same travel to contact on
 *    every pixel;
 *  - `fixed`: at start_height_m above the substrate (a fixed piezo height, as an instrument scans), so a
 *    higher surface is reached sooner; a height trigger (trigger_height_m) is then above the substrate too.
 */
#ifndef VAFM_MAP_H
#define VAFM_MAP_H

#include "vafm/campaign.h"
#include "vafm/common.h"
#include "vafm/contact.h"
#include "vafm/params.h"

#ifdef __cplusplus
extern "C" {
#endif

/** The most pixels along x or y. */
#define VAFM_MAP_MAX_SIDE 1024
/** The most pixels of a map (nx·ny): 512 × 512. */
#define VAFM_MAP_MAX_PIXELS 262144

/** Sample patterns. Material 0 is the substrate (or the first phase), material 1 the body (or the second). */
enum vafm_map_pattern {
    VAFM_MAP_UNIFORM = 0, /**< material 0 everywhere, flat */
    VAFM_MAP_STRIPES = 1, /**< stripes along y of period period_m from the scan's left edge: material 0 on the first
                               half of each period, material 1 on the second; flat */
    VAFM_MAP_DISC = 2,    /**< a body of material 1 of radius radius_m at the scan centre, a flat top height_m high,
                               on a substrate of material 0 */
    VAFM_MAP_DOME = 3,    /**< the same body as a spherical cap: base radius radius_m, height height_m at the centre
                               (a cell on a hard substrate) */
    VAFM_MAP_DOMAINS = 4, /**< a random two-phase blend: smoothed value noise on a lattice of spacing domain_m from
                               domain_seed, material 1 where it is below `fraction` (about that area fraction); flat */
    VAFM_MAP_GRID = 5,    /**< a measured map (vafm_map_spec.grid, e.g. from vafm_h5_map_grid_load): E*, γ and the
                               surface height interpolated bilinearly at each pixel (clamped at the grid's edges), on
                               material 0's contact model; a value the grid lacks is material 0's (height: 0). Pixel
                               centres that miss the grid's points in x or y are refused (VAFM_EINVAL, field grid) */
};

/** A measured map to sample from (pattern "grid"): values on a regular grid of points. */
typedef struct vafm_map_grid {
    int nx, ny;                   /**< grid points along x and y, ≥ 2 each */
    double x0_m, y0_m;            /**< position of point (0, 0), m */
    double dx_m, dy_m;            /**< spacing of the points along x and y, m, > 0 */
    const double *E_star_Pa;      /**< nx·ny contact moduli, Pa, row-major [iy·nx + ix]; NULL: material 0's */
    const double *gamma_J_per_m2; /**< nx·ny surface energies, J/m²; NULL: material 0's */
    const double *height_m;       /**< nx·ny surface heights above the substrate, m; NULL: flat */
    const char *source;           /**< where it came from (a file name; recorded in the map's JSON), or NULL */
} vafm_map_grid;

/** How each pixel's approach starts. */
enum vafm_map_start {
    VAFM_MAP_START_SURFACE = 0, /**< start_height_m above the local surface (default) */
    VAFM_MAP_START_FIXED = 1,   /**< start_height_m above the substrate: a higher surface is reached sooner */
};

/** A material: the contact model and its constants. NULL or NaN take the base scene's value. */
typedef struct vafm_map_material {
    const vafm_contact_type *contact; /**< contact model (jkr, hertz, none); NULL: the base scene's */
    double E_star_Pa;                 /**< contact modulus E*, Pa; NaN: the base scene's */
    double gamma_J_per_m2;            /**< JKR surface energy γ, J/m²; NaN: the base scene's. Hertz and none have
                                           no surface energy: γ is 0 for them whatever is set */
} vafm_map_material;

/** A map: the grid, the scan area, the pattern and its parameters. */
typedef struct vafm_map_spec {
    int nx, ny;              /**< pixels along x and y, 1..VAFM_MAP_MAX_SIDE each, nx·ny ≤ VAFM_MAP_MAX_PIXELS
                                  (default 32 × 32) */
    double size_x_m;         /**< scan size along x, m, (0, 1e-2] (default 10e-6) */
    double size_y_m;         /**< scan size along y, m, (0, 1e-2] (default 10e-6) */
    double center_x_m;       /**< scan centre x, m, [−1e-2, 1e-2] (default 0) */
    double center_y_m;       /**< scan centre y, m, [−1e-2, 1e-2] (default 0) */
    int pattern;             /**< enum vafm_map_pattern (default uniform) */
    vafm_map_material material[2]; /**< [0]: substrate / first phase (default: the base scene's material);
                                        [1]: body / second phase (default: the base scene's contact model,
                                        E* = 1 GPa, γ = 0.02 J/m²) */
    double period_m;         /**< stripes: period along x, m, (0, 1e-2] (default 5e-6) */
    double radius_m;         /**< disc, dome: radius of the body's footprint, m, (0, 1e-2] (default 3e-6) */
    double height_m;         /**< disc, dome: height of the body above the substrate, m, [0, 1e-4]
                                  (default 0.5e-6; a dome needs height_m ≤ radius_m) */
    double domain_m;         /**< domains: lattice spacing of the noise (typical domain size), m, [1e-12, 1e-2]
                                  (default 1e-6) */
    uint64_t domain_seed;    /**< domains: seed of the pattern (default 1) */
    double fraction;         /**< domains: threshold of the noise, about the area fraction of material 1,
                                  [0, 1] (default 0.5) */
    int start;               /**< enum vafm_map_start (default surface) */
    const vafm_map_grid *grid; /**< pattern grid: the measured map (borrowed: it must outlive the spec's use) */
    uint8_t reserved[24];
} vafm_map_spec;

/** Ground truth of one pixel. */
typedef struct vafm_map_truth {
    int ix, iy;                       /**< pixel indices, 0 ≤ ix < nx, 0 ≤ iy < ny */
    uint64_t index;                   /**< curve index iy·nx + ix */
    double x_m, y_m;                  /**< position of the pixel's centre, m */
    int material;                     /**< 0 or 1 (the spec's material[]) */
    const vafm_contact_type *contact; /**< the pixel's contact model */
    double E_star_Pa;                 /**< the pixel's contact modulus E*, Pa */
    double gamma_J_per_m2;            /**< the pixel's surface energy γ, J/m² (0 for hertz, none) */
    double surface_height_m;          /**< height of the surface above the substrate, m */
    uint8_t reserved[16];
} vafm_map_truth;

/** Fill s with the defaults (32 × 32 pixels over 10 µm × 10 µm, uniform, start mode surface). */
VAFM_API void vafm_map_spec_default(vafm_map_spec *s);

/** @return the number of pixels nx·ny (0 when either is out of range). */
VAFM_API size_t vafm_map_pixels(const vafm_map_spec *s);

/** Pattern names ("uniform", "stripes", "disc", "dome", "domains"). @return the name of pattern p, or NULL. */
VAFM_API const char *vafm_map_pattern_name(int p);
/** @return the pattern named `name`, or VAFM_ENOTFOUND (err names the known patterns). */
VAFM_API int vafm_map_pattern_find(const char *name, vafm_error *err);

/**
 * Set a spec field from text, by name: nx, ny, size_x_m, size_y_m, center_x_m, center_y_m, pattern,
 * period_m, radius_m, height_m, domain_m, domain_seed, fraction, start (surface|fixed), and each
 * material's a_contact, a_E_star_Pa, a_gamma_J_per_m2 (material 0) and b_... (material 1).
 * Checks the field's own range (vafm_map_validate checks the combination).
 * @return 0, VAFM_ENOTFOUND (no such field; err lists them) or VAFM_EINVAL (err names field and range).
 */
VAFM_API int vafm_map_set(vafm_map_spec *s, const char *name, const char *value, vafm_error *err);

/**
 * Check the spec and every pixel's scene over `base` (vafm_params_validate).
 * @return 0, or VAFM_EINVAL / VAFM_EUNSTABLE with err->field the spec field ("nx") or the scene parameter
 *         and err->message naming the value and the allowed range (for a pixel's scene: which pixel and
 *         material).
 */
VAFM_API int vafm_map_validate(const vafm_map_spec *s, const vafm_params *base, vafm_error *err);

/**
 * The scene and ground truth of pixel (ix, iy): `base` with the local material (contact, E*, γ) and the
 * local surface height (surface_height_m; start mode fixed also lowers start_height_m and
 * trigger_height_m by it). The scene is not validated here (vafm_map_validate does it for all).
 * @param out   receives the pixel's scene (may be NULL)
 * @param truth receives the pixel's ground truth (may be NULL)
 * @return 0 or VAFM_EINVAL (a spec field out of range, or the pixel outside the grid; err names it).
 */
VAFM_API int vafm_map_pixel(const vafm_map_spec *s, const vafm_params *base, int ix, int iy, vafm_params *out,
                            vafm_map_truth *truth, vafm_error *err);

/** The scene and ground truth at any point (x_m, y_m) of the scan plane, by vafm_map_pixel's rule (at a pixel's
 *  centre the two agree bit for bit): the scene of a curve taken where the live controller's tip is
 *  (vafm/ctrl.h). truth->ix, iy are the pixel that holds the point (−1, −1 and index UINT64_MAX outside the
 *  grid). @return 0 or VAFM_EINVAL (a spec field out of range, no base, a coordinate not finite). */
VAFM_API int vafm_map_point(const vafm_map_spec *s, const vafm_params *base, double x_m, double y_m, vafm_params *out,
                            vafm_map_truth *truth, vafm_error *err);

/** The sample at any point (x_m, y_m) of the scan plane, not only at pixel centres (the live controller's
 *  surface under the tip, vafm/ctrl.h): its material (0 or 1) and its surface height above the substrate, m.
 *  Pure and allocation-free; the spec is not validated here. Either output may be NULL.
 *  @return 0, or VAFM_EINVAL (no spec, or a coordinate not finite). */
VAFM_API int vafm_map_surface_at(const vafm_map_spec *s, double x_m, double y_m, int *material, double *height_m);

/**
 * A campaign over the map's pixels (vafm/campaign.h): one curve per pixel, curve index = point =
 * iy·nx + ix. Sets grid->n_points, point_fn, point_user (= s, which must outlive the campaign) and
 * curves_per_point = 1; the other fields (threads, keep_samples, first_curve) are left as they are.
 * @return 0 or VAFM_EINVAL (nx or ny out of range).
 */
VAFM_API int vafm_map_campaign(const vafm_map_spec *s, vafm_campaign_spec *grid);

/** The spec as one JSON object (every field, SI, reals with %.17g, materials by name; files keep it as the
 *  map's provenance) into buf, NUL-terminated. @return the length, or VAFM_EINVAL when len is too small. */
VAFM_API int vafm_map_to_json(const vafm_map_spec *s, char *buf, size_t len);

#ifdef __cplusplus
}
#endif
#endif
