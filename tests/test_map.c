/* SPDX-License-Identifier: MIT */
/*
 * Force maps (issue #15, vafm/map.h): bad specs name their field; a uniform map is the single curve pixel for
 * pixel, bit for bit, on 1 and 2 threads; a two-region stripes map of Hertz materials gives back both moduli
 * from a Hertz fit of the approach; topography shifts the contact point by the surface height (start mode
 * surface: every other channel unchanged; fixed: reached sooner) to within a sample interval; a map file's
 * grid attributes and ground truth round-trip through the reader and pass the conformance check.
 */
#include <inttypes.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include "harness.h"
#include "vafm/campaign.h"
#include "h5/h5.h"
#include "vafm/map.h"
#include "record/record.h"
#include "trace.h"

/* ---- bad input ----------------------------------------------------------------------------------- */

static void test_bad_input(void)
{
    vafm_map_spec s;
    vafm_params base;
    vafm_error e;
    vafm_preset_apply(&base, "contact-silica", NULL);
    vafm_map_spec_default(&s);
    ENSURE(vafm_map_validate(&s, &base, &e) == 0);

    memset(&e, 0, sizeof e);
    ENSURE(vafm_map_set(&s, "nx", "0", &e) == VAFM_EINVAL);
    ENSURE_MSG(!strcmp(e.field, "nx") && strstr(e.message, "[1, 1024]"), "%s", e.message);
    s.nx = 0; /* set directly: validation names it too */
    ENSURE(vafm_map_validate(&s, &base, &e) == VAFM_EINVAL && !strcmp(e.field, "nx"));
    ENSURE(vafm_map_pixel(&s, &base, 0, 0, NULL, NULL, &e) == VAFM_EINVAL && !strcmp(e.field, "nx"));
    vafm_map_spec_default(&s);
    s.nx = s.ny = 1024;
    ENSURE(vafm_map_validate(&s, &base, &e) == VAFM_EINVAL);
    ENSURE_MSG(!strcmp(e.field, "nx") && strstr(e.message, "262144"), "%s", e.message);
    vafm_map_spec_default(&s);
    ENSURE(vafm_map_set(&s, "pattern", "checkerboard", &e) == VAFM_ENOTFOUND);
    ENSURE_MSG(!strcmp(e.field, "pattern") && strstr(e.message, "stripes"), "%s", e.message);
    ENSURE(vafm_map_pattern_find("dome", NULL) == VAFM_MAP_DOME);
    ENSURE(vafm_map_set(&s, "size_x_m", "-1e-6", &e) == VAFM_EINVAL);
    ENSURE_MSG(!strcmp(e.field, "size_x_m") && strstr(e.message, "(0, 0.01]"), "%s", e.message);
    ENSURE(s.size_x_m == 10e-6); /* unchanged */
    s.size_y_m = -1e-6;
    ENSURE(vafm_map_validate(&s, &base, &e) == VAFM_EINVAL && !strcmp(e.field, "size_y_m"));
    vafm_map_spec_default(&s);
    ENSURE(vafm_map_set(&s, "no_such", "1", &e) == VAFM_ENOTFOUND && strstr(e.message, "period_m"));
    ENSURE(vafm_map_set(&s, "b_contact", "glue", &e) == VAFM_EINVAL && !strcmp(e.field, "b_contact"));
    ENSURE(vafm_map_set(&s, "start", "sideways", &e) == VAFM_EINVAL && !strcmp(e.field, "start"));
    /* domains of 1e-300 m: x / domain_m overflowed the noise's int64 lattice index (0.6.2 accepted it) */
    ENSURE(vafm_map_set(&s, "domain_m", "1e-300", &e) == VAFM_EINVAL);
    ENSURE_MSG(!strcmp(e.field, "domain_m") && strstr(e.message, "[1e-12, 0.01] m"), "%s", e.message);
    ENSURE(s.domain_m == 1e-6); /* unchanged */
    ENSURE(vafm_map_set(&s, "domain_m", "1e-12", &e) == 0 && s.domain_m == 1e-12);
    s.pattern = VAFM_MAP_DOMAINS;
    s.domain_m = 1e-300; /* set directly: validation and the pixel refuse it too */
    ENSURE(vafm_map_validate(&s, &base, &e) == VAFM_EINVAL && !strcmp(e.field, "domain_m"));
    ENSURE(vafm_map_pixel(&s, &base, 0, 0, NULL, NULL, &e) == VAFM_EINVAL && !strcmp(e.field, "domain_m"));
    vafm_map_spec_default(&s);
    /* a dome higher than its radius; a fixed start below the body's top; a pixel's bad scene names the pixel */
    s.pattern = VAFM_MAP_DOME;
    s.height_m = 4e-6;
    ENSURE(vafm_map_validate(&s, &base, &e) == VAFM_EINVAL && !strcmp(e.field, "height_m"));
    s.height_m = 0.5e-6;
    s.start = VAFM_MAP_START_FIXED;
    ENSURE(vafm_map_validate(&s, &base, &e) == VAFM_EINVAL && !strcmp(e.field, "start_height_m"));
    s.start = VAFM_MAP_START_SURFACE;
    s.material[1].E_star_Pa = 1.0; /* below E*'s range: the map's field is named */
    ENSURE(vafm_map_validate(&s, &base, &e) == VAFM_EINVAL);
    ENSURE_MSG(!strcmp(e.field, "b_E_star_Pa") && strstr(e.message, "[1000, 1e+13]"), "%s", e.message);
    /* a step stable on the substrate (53 GPa) but not on a 1e13 Pa body: the pixel and its material named */
    s.material[1].E_star_Pa = 1e13;
    vafm_params fixed_dt = base;
    fixed_dt.dt_s = 4e-7;
    ENSURE(vafm_params_validate(&fixed_dt, NULL) == 0);
    int r = vafm_map_validate(&s, &fixed_dt, &e);
    ENSURE_MSG(r == VAFM_EUNSTABLE && strstr(e.message, "pixel (") && strstr(e.message, "material b"), "%d %s", r,
               e.message);
    char js[4096];
    vafm_map_spec_default(&s);
    ENSURE(vafm_map_to_json(&s, js, sizeof js) > 0 && strstr(js, "\"pattern\": \"uniform\"") &&
           strstr(js, "\"a_E_star_Pa\": null"));
    ENSURE(vafm_map_to_json(&s, js, 10) == VAFM_EINVAL);
    const int nj = vafm_map_to_json(&s, js, sizeof js); /* the exact room: the text and its NUL */
    ENSURE(nj > 0 && vafm_map_to_json(&s, js, (size_t)nj) == VAFM_EINVAL);
    ENSURE(vafm_map_to_json(&s, js, (size_t)nj + 1) == nj && (int)strlen(js) == nj);
}

/* ---- the campaign over a map, collected in memory ------------------------------------------------- */

typedef struct t_curve {
    vafm_params p;
    vafm_curve_result r;
    t_trace s;
} t_curve;

static int t_keep(void *user, const vafm_campaign_curve *c)
{
    t_curve *all = user, *k = &all[c->index];
    k->p = *c->params;
    k->r = c->result;
    return t_collect(&k->s, &c->samples) || c->status != 0;
}

static void t_free(t_curve *all, size_t n)
{
    for (size_t i = 0; i < n; i++)
        t_trace_free(&all[i].s);
    free(all);
}

static t_curve *t_run_map(const vafm_map_spec *s, const vafm_params *base, int threads)
{
    vafm_campaign_spec g;
    memset(&g, 0, sizeof g);
    ENSURE(vafm_map_campaign(s, &g) == 0);
    g.threads = threads;
    g.keep_samples = 1;
    size_t n = vafm_map_pixels(s);
    t_curve *all = calloc(n, sizeof *all);
    vafm_error e;
    memset(&e, 0, sizeof e);
    int r = vafm_campaign_run(base, &g, t_keep, all, &e);
    ENSURE_MSG(r == 0, "campaign: %s", e.message);
    return all;
}

static void test_uniform_is_single_curve(void)
{
    vafm_params base;
    vafm_preset_apply(&base, "contact-silica", NULL);
    base.seed = 7;
    vafm_map_spec s;
    vafm_map_spec_default(&s);
    s.nx = 4;
    s.ny = 3;
    t_curve *a = t_run_map(&s, &base, 1), *b = t_run_map(&s, &base, 2);
    vafm_sim *sim = NULL;
    ENSURE(vafm_sim_new(&sim, &base, NULL) == 0);
    int same = 1, same_threads = 1;
    for (size_t i = 0; i < 12; i++) {
        vafm_curve_result r;
        t_trace one = { 0 };
        const t_trace *ai = &a[i].s, *bi = &b[i].s;
        ENSURE(vafm_sim_curve(sim, i, t_collect, &one, &r) == 0);
        same &= one.n == ai->n && !memcmp(one.h, ai->h, one.n * sizeof(double)) &&
                !memcmp(one.f, ai->f, one.n * sizeof(double)) && !memcmp(one.tip, ai->tip, one.n * sizeof(double)) &&
                !memcmp(&r.pulloff_sampled_N, &a[i].r.pulloff_sampled_N, sizeof(double)) && r.steps == a[i].r.steps;
        same_threads &= ai->n == bi->n && !memcmp(ai->f, bi->f, ai->n * sizeof(double)) &&
                        !memcmp(ai->h, bi->h, ai->n * sizeof(double));
        t_trace_free(&one);
        ENSURE(!memcmp(&a[i].p, &base, offsetof(vafm_params, reserved))); /* the pixel's scene is the base scene */
    }
    ENSURE_MSG(same, "a uniform map's pixels are the single curves (seed, index iy*nx + ix) bit for bit");
    ENSURE_MSG(same_threads, "1 and 2 threads give the same map bit for bit");
    vafm_sim_destroy(&sim);
    t_free(a, 12);
    t_free(b, 12);
}

/* ---- Hertz stripes: both moduli back from the approach ---------------------------------------------- */

/* Least-squares E* of F = (4/3) E* sqrt(R) d^(3/2) over the approach samples with F above a fifth of the
 * setpoint (d = -tip: the indentation), and its standard error from the residuals. */
static void t_hertz_fit(const t_trace *c, double R, double F_min, double *E, double *se)
{
    double sgg = 0, sfg = 0, sff = 0;
    size_t m = 0;
    for (size_t i = 0; i < c->n; i++) {
        if (c->seg[i] != 0 || c->f[i] < F_min || c->tip[i] >= 0)
            continue;
        double d = -c->tip[i], g = 4.0 / 3.0 * sqrt(R) * d * sqrt(d);
        sgg += g * g;
        sfg += c->f[i] * g;
        sff += c->f[i] * c->f[i];
        m++;
    }
    *E = sfg / sgg;
    double ss = sff - sfg * sfg / sgg; /* residual sum of squares */
    *se = m > 1 ? sqrt(fmax(ss, 0.0) / (double)(m - 1) / sgg) : INFINITY;
}

static void test_stripes_hertz_moduli(void)
{
    vafm_params base;
    vafm_preset_apply(&base, "cell-liquid", NULL); /* Hertz, E* = 6.7 kPa, R = 20 nm, 0.5 nN setpoint, 37 C */
    vafm_map_spec s;
    vafm_map_spec_default(&s);
    s.nx = 8;
    s.ny = 4;
    s.pattern = VAFM_MAP_STRIPES;
    s.period_m = 5e-6; /* 10 um: a a a a b b b b along x in two periods */
    s.material[1].contact = vafm_contact_hertz;
    s.material[1].E_star_Pa = 30e3;
    ENSURE(vafm_map_validate(&s, &base, NULL) == 0);
    t_curve *all = t_run_map(&s, &base, 0);
    double Etrue[2] = { base.E_star_Pa, 30e3 }, sum[2] = { 0, 0 }, sum2[2] = { 0, 0 }, sesum[2] = { 0, 0 };
    int cnt[2] = { 0, 0 };
    for (int i = 0; i < 32; i++) {
        vafm_map_truth t;
        ENSURE(vafm_map_pixel(&s, &base, i % 8, i / 8, NULL, &t, NULL) == 0);
        ENSURE(t.E_star_Pa == Etrue[t.material] && all[i].p.E_star_Pa == t.E_star_Pa);
        double E, se;
        t_hertz_fit(&all[i].s, base.R_m, 0.2 * base.setpoint_N, &E, &se);
        sum[t.material] += E;
        sum2[t.material] += E * E;
        sesum[t.material] += se;
        cnt[t.material]++;
    }
    ENSURE(cnt[0] == 16 && cnt[1] == 16);
    for (int k = 0; k < 2; k++) {
        double mean = sum[k] / cnt[k], sd = sqrt(fmax(sum2[k] / cnt[k] - mean * mean, 0.0) * cnt[k] / (cnt[k] - 1));
        double sem = sd / sqrt((double)cnt[k]);
        /* the tolerance from the noise: 5 sem of the pixel fits, plus 1% for what the Hertz law of the
         * box-car means leaves out (the mean of F(d) is not F of the mean d; friction in the liquid) */
        double tol = 5.0 * sem + 0.01 * Etrue[k];
        printf("  material %c: E* true %.6g Pa, recovered %.6g +- %.3g Pa (sem of %d pixels; mean fit se %.3g Pa)\n",
               'a' + k, Etrue[k], mean, sem, cnt[k], sesum[k] / cnt[k]);
        ENSURE_MSG(fabs(mean - Etrue[k]) < tol, "material %c: E* %.6g recovered as %.6g (tolerance %.3g)", 'a' + k,
                   Etrue[k], mean, tol);
    }
    t_free(all, 32);
}

/* ---- topography ------------------------------------------------------------------------------------- */

/* The piezo height where the approach's force first reaches half the setpoint, interpolated. */
static double t_contact_height(const t_trace *c, double F)
{
    for (size_t i = 1; i < c->n; i++)
        if (c->seg[i] == 0 && c->f[i] >= F && c->f[i - 1] < F)
            return c->h[i - 1] + (c->h[i] - c->h[i - 1]) * (F - c->f[i - 1]) / (c->f[i] - c->f[i - 1]);
    return NAN;
}

static void test_topography(void)
{
    vafm_params base;
    vafm_preset_apply(&base, "cell-liquid", NULL);
    vafm_map_spec s;
    vafm_map_spec_default(&s);
    s.nx = 5;
    s.ny = 1;
    s.size_x_m = 10e-6;
    s.size_y_m = 2e-6;
    s.pattern = VAFM_MAP_DOME;
    s.radius_m = 3.5e-6; /* pixels at x = -4, -2, 0, 2, 4 um: flat, dome, top, dome, flat */
    s.height_m = 200e-9;
    s.material[1].E_star_Pa = NAN; /* the same material: topography alone */
    s.material[1].gamma_J_per_m2 = NAN;
    const double sample_dz = base.v_approach_m_per_s / base.sample_rate_Hz; /* piezo travel per sample */
    for (int mode = 0; mode < 2; mode++) {
        s.start = mode;
        base.start_height_m = mode ? 600e-9 : 300e-9; /* fixed: above the dome's top */
        base.T_K = 0; /* athermal: every pixel's curve is the same up to the topography, whatever its stream */
        t_curve *all = t_run_map(&s, &base, 0);
        vafm_map_truth t0;
        ENSURE(vafm_map_pixel(&s, &base, 0, 0, NULL, &t0, NULL) == 0 && t0.surface_height_m == 0);
        double c0 = t_contact_height(&all[0].s, 0.5 * base.setpoint_N);
        for (int ix = 1; ix < 5; ix++) {
            vafm_map_truth t;
            ENSURE(vafm_map_pixel(&s, &base, ix, 0, NULL, &t, NULL) == 0);
            double c = t_contact_height(&all[ix].s, 0.5 * base.setpoint_N);
            /* within one sample interval's piezo travel (fixed start: the samples fall at another phase of the
             * ramp); the centre pixel sits on the dome's top */
            ENSURE_MSG(fabs(c - c0 - t.surface_height_m) <= sample_dz,
                       "start %s, pixel %d: contact at %.6g m, flat %.6g m, surface %.6g m (one sample: %.3g m)",
                       mode ? "fixed" : "surface", ix, c, c0, t.surface_height_m, sample_dz);
            if (ix == 2)
                ENSURE_REL(t.surface_height_m, 200e-9, 1e-12);
            if (mode == 0) { /* surface: the same curve shifted, the forces bit for bit */
                ENSURE(all[ix].s.n == all[0].s.n && !memcmp(all[ix].s.f, all[0].s.f, all[0].s.n * sizeof(double)));
                ENSURE_REL(all[ix].r.touch_height_m - all[0].r.touch_height_m, t.surface_height_m, 1e-6);
                ENSURE(all[ix].r.touch_time_s == all[0].r.touch_time_s);
            } else if (t.surface_height_m > 0) { /* fixed: a higher surface is reached sooner */
                ENSURE_REL(all[0].r.touch_time_s - all[ix].r.touch_time_s,
                           t.surface_height_m / base.v_approach_m_per_s, 0.05);
            }
        }
        t_free(all, 5);
    }
}

/* ---- a map file: grid attributes and ground truth round-trip ---------------------------------------- */

typedef struct t_rec {
    vafm_recorder *rec;
    const vafm_map_spec *s;
    const vafm_params *base;
    int err;
} t_rec;

static int t_rec_curve(void *user, const vafm_campaign_curve *c)
{
    t_rec *tr = user;
    vafm_map_truth px;
    vafm_map_pixel(tr->s, tr->base, (int)(c->index % (uint64_t)tr->s->nx), (int)(c->index / (uint64_t)tr->s->nx), NULL,
                   &px, NULL);
    vafm_record_curve rc = { .samples = &c->samples, .params = c->params, .result = &c->result, .point = c->point,
                             .sensitivity_m_per_V = NAN, .map = tr->s, .pixel = &px };
    vafm_error e;
    int r = vafm_recorder_append(tr->rec, &rc, &e);
    if (r)
        tr->err = r;
    return r != 0;
}

static void test_file_roundtrip(void)
{
    const char *path = "t_map_rt.h5";
    unlink(path);
    vafm_params base;
    vafm_preset_apply(&base, "cell-liquid", NULL);
    vafm_map_spec s;
    vafm_map_spec_default(&s);
    s.nx = 3;
    s.ny = 2;
    s.size_x_m = 3e-6;
    s.size_y_m = 4e-6;
    s.center_x_m = 1e-6;
    s.center_y_m = -2e-6;
    s.pattern = VAFM_MAP_DISC;
    s.radius_m = 1.2e-6;
    s.height_m = 100e-9;
    s.material[1].E_star_Pa = 20e3;
    vafm_campaign_spec g;
    memset(&g, 0, sizeof g);
    char js[4096];
    ENSURE(vafm_map_to_json(&s, js, sizeof js) > 0 && vafm_map_campaign(&s, &g) == 0);
    g.map_json = js;
    g.keep_samples = 1;
    vafm_recorder_opts o;
    vafm_recorder_opts_default(&o);
    vafm_error e;
    memset(&e, 0, sizeof e);
    t_rec tr = { NULL, &s, &base, 0 };
    ENSURE_MSG(vafm_recorder_open(&tr.rec, path, &o, &base, &g, &e) == 0, "%s", e.message);
    ENSURE(vafm_campaign_run(&base, &g, t_rec_curve, &tr, &e) == 0 && tr.err == 0);
    ENSURE(vafm_recorder_close(&tr.rec, NULL, &e) == 0);
    ENSURE_MSG(vafm_h5_check(path, &e) == 0, "conformance: %s", e.message);
    vafm_h5_reader *r = NULL;
    ENSURE(vafm_h5_reader_open(&r, path, &e) == 0);
    ENSURE(vafm_h5_reader_count(r) == 6);
    vafm_h5_provenance pv;
    vafm_h5_reader_provenance(r, &pv);
    ENSURE(pv.format_minor == 1 && pv.grid_json && strstr(pv.grid_json, "\"map\": {") &&
           strstr(pv.grid_json, "\"pattern\": \"disc\""));
    int in_body = 0;
    for (size_t i = 0; i < 6; i++) {
        vafm_h5_curve c;
        vafm_h5_truth t;
        vafm_map_truth px;
        ENSURE(vafm_h5_reader_curve_info(r, i, &c, &e) == 0);
        ENSURE(vafm_map_pixel(&s, &base, (int)(i % 3), (int)(i / 3), NULL, &px, NULL) == 0);
        const vafm_h5_meta *m = &c.meta;
        ENSURE(m->grid_shape_x == 3 && m->grid_shape_y == 2 && m->grid_index_x == (int64_t)(i % 3) &&
               m->grid_index_y == (int64_t)(i / 3));
        ENSURE(m->grid_size_x_m == 3e-6 && m->grid_size_y_m == 4e-6 && m->grid_center_x_m == 1e-6 &&
               m->grid_center_y_m == -2e-6);
        ENSURE(m->position_x_m == px.x_m && m->position_y_m == px.y_m);
        ENSURE(px.x_m == 1e-6 - 1.5e-6 + ((double)(i % 3) + 0.5) * 1e-6); /* centre of its cell */
        ENSURE(vafm_h5_reader_truth(r, i, &t) == 0);
        ENSURE(t.E_star_Pa == px.E_star_Pa && t.gamma_J_per_m2 == px.gamma_J_per_m2 &&
               t.surface_height_m == px.surface_height_m);
        in_body += px.material;
    }
    ENSURE(in_body == 2); /* the two pixels at x = 1 um: r = 1 um < 1.2 um */
    vafm_h5_reader_destroy(&r);
    /* resume of the finished map: the same map is kept; another pattern is refused naming it */
    o.mode = VAFM_RECORD_RESUME;
    ENSURE(vafm_recorder_open(&tr.rec, path, &o, &base, &g, &e) == 0 && vafm_recorder_count(tr.rec) == 6);
    ENSURE(vafm_recorder_close(&tr.rec, NULL, &e) == 0);
    s.pattern = VAFM_MAP_DOME;
    ENSURE(vafm_map_to_json(&s, js, sizeof js) > 0);
    ENSURE(vafm_recorder_open(&tr.rec, path, &o, &base, &g, &e) == VAFM_EINVAL && strstr(e.message, "pattern"));
    unlink(path);
}

/* surface_height_m alone: every height a curve reports moves by it, nothing else changes */
static void test_surface_height_param(void)
{
    vafm_params p;
    vafm_preset_apply(&p, "contact-silica", NULL);
    t_trace a = { 0 }, b = { 0 };
    vafm_curve_result ra, rb;
    vafm_sim *sim = NULL;
    ENSURE(vafm_sim_new(&sim, &p, NULL) == 0 && vafm_sim_curve(sim, 3, t_collect, &a, &ra) == 0);
    vafm_sim_destroy(&sim);
    p.surface_height_m = 250e-9;
    ENSURE(vafm_params_validate(&p, NULL) == 0);
    ENSURE(vafm_sim_new(&sim, &p, NULL) == 0 && vafm_sim_curve(sim, 3, t_collect, &b, &rb) == 0);
    vafm_sim_destroy(&sim);
    ENSURE(a.n == b.n && !memcmp(a.f, b.f, a.n * sizeof(double)));
    double worst = 0;
    for (size_t i = 0; i < a.n; i++) {
        worst = fmax(worst, fabs(b.h[i] - a.h[i] - 250e-9));
        worst = fmax(worst, fabs(b.tip[i] - a.tip[i] - 250e-9));
    }
    ENSURE_MSG(worst < 1e-20, "heights shifted by the surface height to %.3g m", worst);
    ENSURE_ABS(rb.detach_height_m - ra.detach_height_m, 250e-9, 1e-20);
    ENSURE(rb.pulloff_sampled_N == ra.pulloff_sampled_N);
    p.surface_height_m = 2e-3;
    ENSURE(vafm_params_validate(&p, NULL) == VAFM_EINVAL);
    t_trace_free(&a);
    t_trace_free(&b);
}

/* the patterns: stripes' layout, a disc's footprint, domains deterministic from their seed */
static int t_material(const vafm_map_spec *s, const vafm_params *base, int ix, int iy)
{
    vafm_map_truth t;
    return vafm_map_pixel(s, base, ix, iy, NULL, &t, NULL) ? -1 : t.material;
}

static void test_patterns(void)
{
    vafm_params base;
    vafm_preset_apply(&base, "contact-silica", NULL);
    vafm_map_spec s;
    vafm_map_spec_default(&s);
    s.nx = 8;
    s.ny = 2;
    s.pattern = VAFM_MAP_STRIPES;
    s.period_m = 5e-6; /* 2 periods over 10 um: a a b b a a b b */
    int want[8] = { 0, 0, 1, 1, 0, 0, 1, 1 }, ok = 1;
    for (int ix = 0; ix < 8; ix++)
        ok &= t_material(&s, &base, ix, 0) == want[ix] && t_material(&s, &base, ix, 1) == want[ix];
    ENSURE_MSG(ok, "stripes: a a b b a a b b");
    vafm_map_truth t;
    vafm_params p;
    ENSURE(vafm_map_pixel(&s, &base, 2, 0, &p, &t, NULL) == 0);
    ENSURE(p.E_star_Pa == 1e9 && p.gamma_J_per_m2 == 0.02 && p.contact == base.contact && t.surface_height_m == 0);
    s.material[1].contact = vafm_contact_hertz; /* hertz: no surface energy */
    ENSURE(vafm_map_pixel(&s, &base, 2, 0, &p, &t, NULL) == 0 && p.gamma_J_per_m2 == 0 && t.gamma_J_per_m2 == 0);
    /* domains: the same seed the same blend, another seed another; fraction 0 and 1 the pure phases */
    vafm_map_spec_default(&s);
    s.nx = s.ny = 64;
    s.pattern = VAFM_MAP_DOMAINS;
    s.domain_m = 1e-6;
    int n1 = 0, diff = 0;
    vafm_map_spec s2 = s;
    s2.domain_seed = 2;
    for (int iy = 0; iy < 64; iy++)
        for (int ix = 0; ix < 64; ix++) {
            int m = t_material(&s, &base, ix, iy);
            ENSURE(m == t_material(&s, &base, ix, iy));
            n1 += m;
            diff += m != t_material(&s2, &base, ix, iy);
        }
    printf("  domains 64 x 64, fraction 0.5: %d pixels of b, %d differ with another seed\n", n1, diff);
    ENSURE(n1 > 64 * 64 / 5 && n1 < 64 * 64 * 4 / 5 && diff > 64 * 64 / 5);
    s.fraction = 0;
    ENSURE(t_material(&s, &base, 10, 10) == 0);
    s.fraction = 1;
    ENSURE(t_material(&s, &base, 10, 10) == 1);
}

/* vafm_map_point: at every pixel centre the scene and truth of vafm_map_pixel, bit for bit; between centres the
 * material and height of vafm_map_surface_at; outside the grid ix = iy = -1; a point not finite is refused. */
static void test_point(void)
{
    vafm_map_spec s;
    vafm_params base;
    vafm_error e;
    vafm_preset_apply(&base, "contact-silica", NULL);
    vafm_map_spec_default(&s);
    ENSURE(vafm_map_set(&s, "pattern", "dome", NULL) == 0);
    ENSURE(vafm_map_set(&s, "nx", "7", NULL) == 0 && vafm_map_set(&s, "ny", "5", NULL) == 0);
    ENSURE(vafm_map_set(&s, "b_E_star_Pa", "3e9", NULL) == 0 && vafm_map_set(&s, "start", "fixed", NULL) == 0);
    for (int iy = 0; iy < s.ny; iy++)
        for (int ix = 0; ix < s.nx; ix++) {
            vafm_params a, b;
            vafm_map_truth ta, tb;
            memset(&a, 0, sizeof a); /* padding compared below */
            memset(&b, 0, sizeof b);
            ENSURE(vafm_map_pixel(&s, &base, ix, iy, &a, &ta, NULL) == 0);
            ENSURE(vafm_map_point(&s, &base, ta.x_m, ta.y_m, &b, &tb, NULL) == 0);
            ENSURE_MSG(!memcmp(&a, &b, sizeof a) && !memcmp(&ta, &tb, sizeof ta), "pixel (%d, %d)", ix, iy);
        }
    int mat = -1;
    double h = NAN;
    vafm_params p;
    vafm_map_truth t;
    ENSURE(vafm_map_surface_at(&s, 0.3e-6, -0.2e-6, &mat, &h) == 0);
    ENSURE(vafm_map_point(&s, &base, 0.3e-6, -0.2e-6, &p, &t, NULL) == 0);
    ENSURE(t.material == mat && t.surface_height_m == h && p.surface_height_m == h && h > 0 && mat == 1);
    ENSURE(p.E_star_Pa == 3e9 && p.start_height_m == base.start_height_m - h);
    ENSURE(vafm_map_point(&s, &base, 6e-6, 0, &p, &t, NULL) == 0 && t.ix == -1 && t.iy == -1);
    ENSURE(t.material == 0 && p.E_star_Pa == base.E_star_Pa && t.index == UINT64_MAX);
    memset(&e, 0, sizeof e);
    ENSURE(vafm_map_point(&s, &base, NAN, 0, &p, NULL, &e) == VAFM_EINVAL && !strcmp(e.field, "x_m"));
    ENSURE(vafm_map_point(&s, NULL, 0, 0, &p, NULL, &e) == VAFM_EINVAL);
}

int main(void)
{
    RUN_TEST(test_bad_input);
    RUN_TEST(test_patterns);
    RUN_TEST(test_surface_height_param);
    RUN_TEST(test_point);
    RUN_TEST(test_uniform_is_single_curve);
    RUN_TEST(test_stripes_hertz_moduli);
    RUN_TEST(test_topography);
    RUN_TEST(test_file_roundtrip);
    return harness_done();
}
