/* SPDX-License-Identifier: MIT */
/*
 * HDF5 force-curve files in afmformats' layout (issue #3, protocol/hdf5.md).
 *
 * - round trip: synthetic and simulated curves written, read back bit for bit (channels, metadata,
 *   ground truth, provenance), for each storage option; the conformance checker passes every file
 *   the tests write with vafm's writer;
 * - 1 vs 2 threads: a campaign written with 1 and with 2 worker threads gives the same file content;
 * - a reference file written here with raw HDF5 calls (instrument-like metadata, no "time" column,
 *   gzip + Fletcher-32 like afmformats' exporter) is read correctly;
 * - hand-made non-conforming files are refused by the reader and the checker, each with a message
 *   naming the file, the object and the rule; the writer refuses curves that break the layout;
 * - damaged files (truncated at several lengths, random bytes flipped, each read in a forked child)
 *   never crash the reader: they are refused with a message or read back identical;
 * - kill -9 of a writing child at random moments, resume, and comparison with an uninterrupted run.
 * No physics is asserted here (test_curve does that); the values compared are the ones written.
 *
 * Run with "--make-files DIR" it only writes a vafm file and the reference file into DIR (for
 * tests/test_h5_tools.sh, which checks them with h5dump, h5ls and, when available, h5py); with
 * "--fuzz FILE TRIALS SEED" it only damages copies of FILE (for diagnosis).
 */
#include <errno.h>
#include <fcntl.h>
#include <hdf5.h>
#include <math.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "harness.h"
#include "vafm/campaign.h"
#include "h5/h5.h"
#include "record/record.h" /* vafm_h5_curve_from_sim */

/* ---- small helpers -------------------------------------------------------------------------------- */

static uint64_t s_rng = 0x9E3779B97F4A7C15ull;
static uint64_t s_next(void)
{
    /* xorshift64*: fixed seed, reproducible choice of damage */
    s_rng ^= s_rng >> 12;
    s_rng ^= s_rng << 25;
    s_rng ^= s_rng >> 27;
    return s_rng * 2685821657736338717ull;
}

static double s_unif(void)
{
    return (double)(s_next() >> 11) * (1.0 / 9007199254740992.0);
}

static int s_same_d(double a, double b)
{
    return !memcmp(&a, &b, sizeof a);
}

static int s_same_str(const char *a, const char *b)
{
    return (!a && !b) || (a && b && !strcmp(a, b));
}

static int s_chan_eq(const double *a, const double *b, size_t n)
{
    if (!a || !b)
        return a == b;
    return !memcmp(a, b, n * sizeof *a);
}

/* Metadata equal field for field (reals bit for bit); date and time only if with_clock. */
static int s_meta_eq(const vafm_h5_meta *a, const vafm_h5_meta *b, int with_clock, char *why, size_t len)
{
#define S_STR(f)                                                                                   \
    if (!s_same_str(a->f, b->f)) {                                                                 \
        snprintf(why, len, "%s: '%s' vs '%s'", #f, a->f ? a->f : "(absent)", b->f ? b->f : "(absent)"); \
        return 0;                                                                                  \
    }
#define S_REAL(f)                                                                                  \
    if (!s_same_d(a->f, b->f)) {                                                                   \
        snprintf(why, len, "%s: %.17g vs %.17g", #f, a->f, b->f);                                  \
        return 0;                                                                                  \
    }
#define S_INT(f)                                                                                   \
    if (a->f != b->f) {                                                                            \
        snprintf(why, len, "%s: %lld vs %lld", #f, (long long)a->f, (long long)b->f);              \
        return 0;                                                                                  \
    }
    S_STR(imaging_mode) S_STR(feedback_mode) S_STR(instrument) S_STR(software) S_STR(software_version)
    S_STR(session_id) S_STR(curve_id)
    if (with_clock) {
        S_STR(date) S_STR(time)
    }
    S_REAL(spring_constant_N_per_m) S_REAL(sensitivity_m_per_V) S_REAL(setpoint_N) S_REAL(rate_approach_Hz)
    S_REAL(rate_retract_Hz) S_REAL(speed_approach_m_per_s) S_REAL(speed_retract_m_per_s) S_REAL(duration_s)
    S_REAL(duration_approach_s) S_REAL(duration_retract_s) S_REAL(z_range_m) S_REAL(position_x_m)
    S_REAL(position_y_m) S_REAL(grid_center_x_m) S_REAL(grid_center_y_m) S_REAL(grid_size_x_m)
    S_REAL(grid_size_y_m)
    S_INT(point_count) S_INT(segment_count) S_INT(grid_shape_x) S_INT(grid_shape_y) S_INT(grid_index_x)
    S_INT(grid_index_y)
#undef S_STR
#undef S_REAL
#undef S_INT
    return 1;
}

/* Curves equal: length, every channel bit for bit, and metadata. */
static int s_curve_eq(const vafm_h5_curve *a, const vafm_h5_curve *b, int with_clock, char *why, size_t len)
{
    if (a->n != b->n) {
        snprintf(why, len, "n %zu vs %zu", a->n, b->n);
        return 0;
    }
    if (!s_chan_eq(a->force_N, b->force_N, a->n) || !s_chan_eq(a->height_measured_m, b->height_measured_m, a->n) ||
        !s_chan_eq(a->height_piezo_m, b->height_piezo_m, a->n) || !s_chan_eq(a->time_s, b->time_s, a->n) ||
        !s_chan_eq(a->tip_position_m, b->tip_position_m, a->n)) {
        snprintf(why, len, "a float64 channel differs");
        return 0;
    }
    if (!a->segment || !b->segment || memcmp(a->segment, b->segment, a->n)) {
        snprintf(why, len, "segment differs");
        return 0;
    }
    return s_meta_eq(&a->meta, &b->meta, with_clock, why, len);
}

static int s_truth_eq(const vafm_h5_truth *a, const vafm_h5_truth *b)
{
    const vafm_curve_result *x = &a->result, *y = &b->result;
    return a->point == b->point && a->status == b->status && s_same_d(a->T_K, b->T_K) &&
           s_same_d(a->v_m_per_s, b->v_m_per_s) && s_same_d(a->k_N_per_m, b->k_N_per_m) && x->index == y->index &&
           x->flags == y->flags && s_same_d(x->pulloff_sampled_N, y->pulloff_sampled_N) &&
           s_same_d(x->pulloff_spring_N, y->pulloff_spring_N) && s_same_d(x->detach_force_N, y->detach_force_N) &&
           s_same_d(x->detach_height_m, y->detach_height_m) && s_same_d(x->detach_eq_force_N, y->detach_eq_force_N) &&
           s_same_d(x->detach_time_s, y->detach_time_s) && s_same_d(x->touch_time_s, y->touch_time_s) &&
           s_same_d(x->touch_height_m, y->touch_height_m) && s_same_d(x->retract_start_s, y->retract_start_s) &&
           s_same_d(x->duration_s, y->duration_s) && x->samples == y->samples && x->steps == y->steps &&
           x->steps_contact == y->steps_contact && x->steps_free == y->steps_free;
}

/* The message of a refusal names the file. */
static int s_msg_names(const vafm_error *e, const char *path)
{
    return e->code < 0 && strstr(e->message, path) != NULL;
}

/* ---- synthetic curves ------------------------------------------------------------------------------ */

typedef struct syn {
    size_t n;
    double *f, *hm, *hp, *t, *tip;
    uint8_t *seg;
    char curve_id[48];
    vafm_h5_curve c;
    vafm_h5_truth truth;
} syn;

/* An approach–dwell–retract ramp with a linear contact and small deterministic noise. */
static void syn_make(syn *s, size_t n, double k, uint64_t index)
{
    memset(s, 0, sizeof *s);
    s->n = n;
    s->f = malloc(n * sizeof *s->f);
    s->hm = malloc(n * sizeof *s->hm);
    s->hp = malloc(n * sizeof *s->hp);
    s->t = malloc(n * sizeof *s->t);
    s->tip = malloc(n * sizeof *s->tip);
    s->seg = malloc(n);
    size_t na = n * 4 / 10, nd = n / 10;
    const double rate = 1e4, z0 = 1e-6, zc = 2e-7;
    for (size_t i = 0; i < n; i++) {
        double z;
        if (i < na) {
            z = z0 * (1.0 - (double)i / (double)na);
            s->seg[i] = 0;
        } else if (i < na + nd) {
            z = 0;
            s->seg[i] = 2;
        } else {
            z = z0 * (double)(i - na - nd) / (double)(n - na - nd);
            s->seg[i] = 1;
        }
        s->hp[i] = z;
        s->hm[i] = z + 1e-10 * sin((double)i); /* a sensor that differs from the piezo */
        s->t[i] = ((double)i + 0.5) / rate;
        s->f[i] = (z < zc ? 0.5 * k * (zc - z) : 0.0) + 1e-11 * sin(0.37 * (double)i + (double)index);
        s->tip[i] = s->hm[i] + s->f[i] / k;
    }
    vafm_h5_curve *c = &s->c;
    c->n = n;
    c->force_N = s->f;
    c->height_measured_m = s->hm;
    c->height_piezo_m = s->hp;
    c->segment = s->seg;
    c->time_s = s->t;
    c->tip_position_m = s->tip;
    vafm_h5_meta *m = &c->meta;
    vafm_h5_meta_default(m);
    snprintf(s->curve_id, sizeof s->curve_id, "session-42_%llu", (unsigned long long)index);
    m->imaging_mode = "force-distance";
    m->feedback_mode = "contact";
    m->instrument = "vafm virtual AFM";
    m->software = "vafm";
    m->software_version = vafm_version();
    m->date = "2024-02-29";
    m->time = "13:45:07.25";
    m->session_id = "session-42";
    m->curve_id = s->curve_id;
    m->spring_constant_N_per_m = k;
    m->sensitivity_m_per_V = 5.5e-8;
    m->setpoint_N = 1e-9;
    m->rate_approach_Hz = m->rate_retract_Hz = rate;
    m->speed_approach_m_per_s = 2e-6;
    m->speed_retract_m_per_s = 2.5e-6;
    m->duration_s = (double)n / rate;
    m->duration_approach_s = (double)na / rate;
    m->duration_retract_s = (double)(n - na - nd) / rate;
    m->z_range_m = z0;
    m->position_x_m = 1e-6 * (double)(index % 4);
    m->position_y_m = 1e-6 * (double)(index / 4);
    m->grid_center_x_m = m->grid_center_y_m = 2e-6;
    m->grid_size_x_m = m->grid_size_y_m = 4e-6;
    m->grid_shape_x = m->grid_shape_y = 4;
    m->grid_index_x = (int64_t)(index % 4);
    m->grid_index_y = (int64_t)((index / 4) % 4); /* inside the shape (L17) */
    m->point_count = (int64_t)n;
    m->segment_count = 2;
    vafm_h5_truth *t = &s->truth;
    memset(t, 0, sizeof *t);
    t->point = index / 2;
    t->status = index == 3 ? -3 : 0;
    t->T_K = 300 + 50.0 * (double)(index / 2);
    t->v_m_per_s = 2e-6;
    t->k_N_per_m = k;
    t->result.index = index;
    t->result.flags = (int)index;
    t->result.pulloff_sampled_N = 1e-9 * (double)(index + 1);
    t->result.pulloff_spring_N = 1.1e-9;
    t->result.detach_force_N = index == 1 ? NAN : 0.9e-9;
    t->result.detach_height_m = -3e-9;
    t->result.detach_eq_force_N = NAN;
    t->result.detach_time_s = 0.01;
    t->result.touch_time_s = 0.002;
    t->result.touch_height_m = 0;
    t->result.retract_start_s = 0.05;
    t->result.duration_s = (double)n / rate;
    t->result.samples = n;
    t->result.steps = 1000 * n + index;
    t->result.steps_contact = 300 * n;
    t->result.steps_free = 600 * n;
}

static void syn_free(syn *s)
{
    free(s->f);
    free(s->hm);
    free(s->hp);
    free(s->t);
    free(s->tip);
    free(s->seg);
    memset(s, 0, sizeof *s);
}

static void s_fig4(vafm_params *p)
{
    vafm_preset_apply(p, "paper-fig4", NULL);
    p->seed = 20240501;
}

/* Write `count` synthetic curves with provenance; flush after every `flush_every`. @return 0. */
static int syn_file(const char *path, const vafm_h5_writer_opts *o, int count, vafm_error *e)
{
    vafm_params p;
    s_fig4(&p);
    double T[2] = { 300, 350 };
    vafm_campaign_spec g = { 0 };
    g.T_K = T;
    g.n_T = 2;
    g.curves_per_point = 2;
    vafm_h5_writer *w = NULL;
    int rc = vafm_h5_writer_open(&w, path, o, e);
    if (!rc)
        rc = vafm_h5_writer_set_provenance(w, &p, &g, e);
    for (int i = 0; i < count && !rc; i++) {
        syn s;
        syn_make(&s, 500 + 37 * (size_t)i, 0.05 + 0.01 * i, (uint64_t)i);
        rc = vafm_h5_writer_append(w, &s.c, &s.truth, e);
        syn_free(&s);
        if (!rc && i == 1)
            rc = vafm_h5_writer_flush(w, e);
    }
    int rc2 = vafm_h5_writer_close(&w, e);
    return rc ? rc : rc2;
}

/* A file just written: conformant, then opened for reading (each a check); NULL where it does not open. */
static vafm_h5_reader *s_check_open(const char *path, vafm_error *e)
{
    int rc = vafm_h5_check(path, e);
    ENSURE_MSG(rc == 0, "conformance: %s", e->message);
    vafm_h5_reader *r = NULL;
    rc = vafm_h5_reader_open(&r, path, e);
    ENSURE_MSG(rc == 0, "%s", e->message);
    return rc ? NULL : r;
}

/* ---- round trip of synthetic curves ------------------------------------------------------------------- */

static void test_roundtrip_synthetic(void)
{
    for (int variant = 0; variant < 3; variant++) {
        char path[64];
        snprintf(path, sizeof path, "t_h5_rt_%d.h5", variant);
        remove(path);
        vafm_h5_writer_opts o;
        vafm_h5_writer_opts_default(&o);
        if (variant == 1)
            o.gzip_level = 4; /* shuffle + deflate + Fletcher-32, like afmformats' exporter */
        if (variant == 2)
            o.fletcher32 = 0; /* contiguous storage */
        vafm_error e = { 0 };
        int rc = syn_file(path, &o, 4, &e);
        ENSURE_MSG(rc == 0, "%s", e.message);
        vafm_h5_reader *r = s_check_open(path, &e);
        if (!r)
            continue;
        ENSURE(vafm_h5_reader_count(r) == 4);
        vafm_h5_provenance pv;
        ENSURE(vafm_h5_reader_provenance(r, &pv) == 0);
        vafm_params p;
        s_fig4(&p);
        char scene[16384];
        vafm_params_to_json(&p, scene, sizeof scene);
        ENSURE(pv.is_vafm && pv.format_major == VAFM_H5_FORMAT_MAJOR && pv.format_minor == VAFM_H5_FORMAT_MINOR);
        ENSURE(s_same_str(pv.software, "vafm") && s_same_str(pv.software_version, vafm_version()));
        ENSURE(s_same_str(pv.scene_json, scene));
        ENSURE(pv.grid_json && strstr(pv.grid_json, "\"T_K\": [300, 350]") && strstr(pv.grid_json, "\"curves\": 4"));
        ENSURE(pv.seed == p.seed);
        ENSURE(pv.created && strlen(pv.created) == 20 && pv.created[19] == 'Z');
        ENSURE(pv.truth_rows == 4);
        for (size_t i = 0; i < 4; i++) {
            syn s;
            syn_make(&s, 500 + 37 * i, 0.05 + 0.01 * (double)i, i);
            vafm_h5_curve c;
            rc = vafm_h5_reader_curve(r, i, &c, &e);
            ENSURE_MSG(rc == 0, "%s", e.message);
            char why[200] = "";
            ENSURE_MSG(!rc && c.group == i && s_curve_eq(&c, &s.c, 1, why, sizeof why), "variant %d curve %zu: %s",
                       variant, i, why);
            vafm_h5_truth t;
            ENSURE(vafm_h5_reader_truth(r, i, &t) == 0 && s_truth_eq(&t, &s.truth));
            syn_free(&s);
        }
        vafm_h5_truth t;
        ENSURE(vafm_h5_reader_truth(r, 4, &t) == VAFM_ENOTFOUND);
        vafm_h5_curve c;
        ENSURE(vafm_h5_reader_curve(r, 4, &c, &e) == VAFM_EINVAL);
        vafm_h5_reader_destroy(&r);
        ENSURE(r == NULL);
    }
    /* a file with provenance but no curve yet opens with 0 curves */
    remove("t_h5_empty.h5");
    vafm_error e = { 0 };
    ENSURE(syn_file("t_h5_empty.h5", NULL, 0, &e) == 0);
    vafm_h5_reader *r = NULL;
    ENSURE(vafm_h5_reader_open(&r, "t_h5_empty.h5", &e) == 0 && vafm_h5_reader_count(r) == 0);
    vafm_h5_reader_destroy(&r);
    ENSURE_MSG(vafm_h5_check("t_h5_empty.h5", &e) == 0, "%s", e.message);
}

/* ---- simulated curves through the campaign -------------------------------------------------------- */

typedef struct stored {
    size_t n;
    double *f, *h, *t, *tip;
    uint8_t *seg;
    vafm_h5_truth truth;
    vafm_h5_curve c;
    char cid[48];
} stored;

typedef struct camp_ctx {
    vafm_h5_writer *w;
    int flush_each;
    int notify_fd;
    stored *store; /* if not NULL: keep copies of what was handed to the writer */
    size_t nstore;
    int fail;
    vafm_error err;
} camp_ctx;

static void s_dup(double **dst, const double *src, size_t n)
{
    *dst = malloc(n * sizeof **dst);
    memcpy(*dst, src, n * sizeof **dst);
}

static int camp_cb(void *user, const vafm_campaign_curve *cc)
{
    camp_ctx *x = user;
    vafm_h5_curve c;
    vafm_h5_curve_from_sim(&c, &cc->samples, cc->params, &cc->result);
    char cid[48];
    snprintf(cid, sizeof cid, "vafm-test_%llu", (unsigned long long)cc->index);
    c.meta.session_id = "vafm-test";
    c.meta.curve_id = cid;
    vafm_h5_truth t = { 0 };
    t.point = cc->point;
    t.status = cc->status;
    t.T_K = cc->params->T_K;
    t.v_m_per_s = cc->params->v_approach_m_per_s;
    t.k_N_per_m = cc->params->k_N_per_m;
    t.result = cc->result;
    int rc = vafm_h5_writer_append(x->w, &c, &t, &x->err);
    if (!rc && x->flush_each)
        rc = vafm_h5_writer_flush(x->w, &x->err);
    if (rc) {
        x->fail = rc;
        return 1;
    }
    if (x->store && cc->index < x->nstore) {
        stored *s = &x->store[cc->index];
        s->n = c.n;
        s_dup(&s->f, c.force_N, c.n);
        s_dup(&s->h, c.height_piezo_m, c.n);
        s_dup(&s->t, c.time_s, c.n);
        s_dup(&s->tip, c.tip_position_m, c.n);
        s->seg = malloc(c.n);
        memcpy(s->seg, c.segment, c.n);
        s->truth = t;
        snprintf(s->cid, sizeof s->cid, "%s", cid);
        s->c = c;
        s->c.force_N = s->f;
        s->c.height_measured_m = s->c.height_piezo_m = s->h;
        s->c.time_s = s->t;
        s->c.tip_position_m = s->tip;
        s->c.segment = s->seg;
        s->c.meta.curve_id = s->cid;
        s->c.meta.point_count = (int64_t)c.n;
    }
    if (x->notify_fd >= 0) {
        uint64_t idx = cc->index;
        if (write(x->notify_fd, &idx, sizeof idx) != (ssize_t)sizeof idx)
            return 1;
    }
    return 0;
}

/* Three speeds of the paper-fig4 scene (shortened by faster ramps), N curves each. */
static double s_speeds[2];
static void camp_spec(vafm_params *p, vafm_campaign_spec *s, int threads)
{
    s_fig4(p);
    s_speeds[0] = 3 * p->v_approach_m_per_s;
    s_speeds[1] = 6 * p->v_approach_m_per_s;
    memset(s, 0, sizeof *s);
    s->v_m_per_s = s_speeds;
    s->n_v = 2;
    s->curves_per_point = LONG_OR(4, 3);
    s->threads = threads;
    s->keep_samples = 1;
}

/* Run (or continue) the campaign into path. @return 0 or a VAFM_E* code. */
static int camp_write(const char *path, int threads, int resume, int flush_each, int notify_fd, stored *store,
                      size_t nstore, vafm_error *e)
{
    vafm_params p;
    vafm_campaign_spec s;
    camp_spec(&p, &s, threads);
    vafm_h5_writer_opts o;
    vafm_h5_writer_opts_default(&o);
    o.resume = resume;
    o.overwrite = !resume;
    camp_ctx x = { 0 };
    x.flush_each = flush_each;
    x.notify_fd = notify_fd;
    x.store = store;
    x.nstore = nstore;
    int rc = vafm_h5_writer_open(&x.w, path, &o, e);
    if (rc)
        return rc;
    rc = vafm_h5_writer_set_provenance(x.w, &p, &s, e);
    s.first_curve = vafm_h5_writer_count(x.w);
    if (!rc && s.first_curve < s.curves_per_point * vafm_campaign_points(&s)) {
        rc = vafm_campaign_run(&p, &s, camp_cb, &x, e);
        if (x.fail) {
            rc = x.fail;
            *e = x.err;
        }
    }
    int rc2 = vafm_h5_writer_close(&x.w, rc ? NULL : e);
    return rc ? rc : rc2;
}

static size_t camp_total(void)
{
    vafm_params p;
    vafm_campaign_spec s;
    camp_spec(&p, &s, 1);
    return (size_t)(s.curves_per_point * vafm_campaign_points(&s));
}

/* Compare two files curve for curve (metadata without date and time), truth and provenance. */
static int s_files_eq(const char *a, const char *b, char *why, size_t len)
{
    vafm_h5_reader *ra = NULL, *rb = NULL;
    vafm_error e = { 0 };
    int ok = 0;
    if (vafm_h5_reader_open(&ra, a, &e) || vafm_h5_reader_open(&rb, b, &e)) {
        snprintf(why, len, "open: %.150s", e.message);
        goto done;
    }
    if (vafm_h5_reader_count(ra) != vafm_h5_reader_count(rb)) {
        snprintf(why, len, "%zu vs %zu curves", vafm_h5_reader_count(ra), vafm_h5_reader_count(rb));
        goto done;
    }
    vafm_h5_provenance pa, pb;
    vafm_h5_reader_provenance(ra, &pa);
    vafm_h5_reader_provenance(rb, &pb);
    if (!s_same_str(pa.scene_json, pb.scene_json) || !s_same_str(pa.grid_json, pb.grid_json) || pa.seed != pb.seed ||
        pa.truth_rows != pb.truth_rows) {
        snprintf(why, len, "provenance differs");
        goto done;
    }
    for (size_t i = 0; i < vafm_h5_reader_count(ra); i++) {
        vafm_h5_curve ca, cb;
        if (vafm_h5_reader_curve(ra, i, &ca, &e) || vafm_h5_reader_curve(rb, i, &cb, &e)) {
            snprintf(why, len, "curve %zu: %.150s", i, e.message);
            goto done;
        }
        char w2[160] = "";
        if (ca.group != cb.group || !s_curve_eq(&ca, &cb, 0, w2, sizeof w2)) {
            snprintf(why, len, "curve %zu: %s", i, w2);
            goto done;
        }
        vafm_h5_truth ta, tb;
        if (vafm_h5_reader_truth(ra, i, &ta) || vafm_h5_reader_truth(rb, i, &tb) || !s_truth_eq(&ta, &tb)) {
            snprintf(why, len, "ground truth of curve %zu differs", i);
            goto done;
        }
    }
    ok = 1;
done:
    vafm_h5_reader_destroy(&ra);
    vafm_h5_reader_destroy(&rb);
    return ok;
}

static void test_campaign_roundtrip(void)
{
    size_t total = camp_total();
    stored *st = calloc(total, sizeof *st);
    vafm_error e = { 0 };
    int rc = camp_write("t_h5_camp1.h5", 1, 0, 1, -1, st, total, &e);
    ENSURE_MSG(rc == 0, "%s", e.message);
    rc = camp_write("t_h5_camp2.h5", 2, 0, 0, -1, NULL, 0, &e);
    ENSURE_MSG(rc == 0, "%s", e.message);
    ENSURE_MSG(vafm_h5_check("t_h5_camp1.h5", &e) == 0, "%s", e.message);
    ENSURE_MSG(vafm_h5_check("t_h5_camp2.h5", &e) == 0, "%s", e.message);

    /* what the campaign handed over is what is read back, bit for bit */
    vafm_h5_reader *r = NULL;
    rc = vafm_h5_reader_open(&r, "t_h5_camp1.h5", &e);
    ENSURE_MSG(rc == 0, "%s", e.message);
    ENSURE(vafm_h5_reader_count(r) == total);
    for (size_t i = 0; r && i < total && i < vafm_h5_reader_count(r); i++) {
        vafm_h5_curve c;
        rc = vafm_h5_reader_curve(r, i, &c, &e);
        ENSURE_MSG(rc == 0, "%s", e.message);
        char why[200] = "";
        ENSURE_MSG(!rc && s_curve_eq(&c, &st[i].c, 0, why, sizeof why), "curve %zu: %s", i, why);
        ENSURE(!rc && c.meta.date && c.meta.time); /* stamped */
        vafm_h5_truth t;
        ENSURE(vafm_h5_reader_truth(r, i, &t) == 0 && s_truth_eq(&t, &st[i].truth));
        ENSURE(t.status == 0 && t.result.samples == c.n);
    }
    vafm_h5_reader_destroy(&r);
    /* 1 and 2 worker threads give the same curves (per-curve random streams) */
    char why[200] = "";
    ENSURE_MSG(s_files_eq("t_h5_camp1.h5", "t_h5_camp2.h5", why, sizeof why), "1 vs 2 threads: %s", why);
    for (size_t i = 0; i < total; i++) {
        free(st[i].f);
        free(st[i].h);
        free(st[i].t);
        free(st[i].tip);
        free(st[i].seg);
    }
    free(st);
}

/* ---- hand-written files (raw HDF5, not vafm's writer) ------------------------------------------------ */

static void h_str(hid_t loc, const char *name, const char *v, int fixed)
{
    hid_t t = H5Tcopy(H5T_C_S1), sp = H5Screate(H5S_SCALAR);
    if (fixed)
        H5Tset_size(t, strlen(v) + 1);
    else
        H5Tset_size(t, H5T_VARIABLE);
    H5Tset_cset(t, H5T_CSET_UTF8);
    hid_t a = H5Acreate2(loc, name, t, sp, H5P_DEFAULT, H5P_DEFAULT);
    if (fixed)
        H5Awrite(a, t, v);
    else
        H5Awrite(a, t, &v);
    H5Aclose(a);
    H5Sclose(sp);
    H5Tclose(t);
}

static void h_num(hid_t loc, const char *name, hid_t ftype, hid_t mtype, const void *v)
{
    hid_t sp = H5Screate(H5S_SCALAR);
    hid_t a = H5Acreate2(loc, name, ftype, sp, H5P_DEFAULT, H5P_DEFAULT);
    H5Awrite(a, mtype, v);
    H5Aclose(a);
    H5Sclose(sp);
}

static void h_f64(hid_t loc, const char *name, double v)
{
    h_num(loc, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &v);
}

static void h_i64(hid_t loc, const char *name, int64_t v)
{
    h_num(loc, name, H5T_STD_I64LE, H5T_NATIVE_INT64, &v);
}

static void h_dset(hid_t g, const char *name, hid_t ftype, hid_t mtype, const void *data, hsize_t n, const char *unit,
                   int gzip)
{
    hid_t sp = H5Screate_simple(1, &n, NULL), dcpl = H5Pcreate(H5P_DATASET_CREATE);
    if (gzip) {
        H5Pset_chunk(dcpl, 1, &n);
        H5Pset_deflate(dcpl, 4);
        H5Pset_fletcher32(dcpl);
    }
    hid_t d = H5Dcreate2(g, name, ftype, sp, H5P_DEFAULT, dcpl, H5P_DEFAULT);
    H5Dwrite(d, mtype, H5S_ALL, H5S_ALL, H5P_DEFAULT, data);
    if (unit)
        h_str(d, "unit", unit, 0);
    H5Dclose(d);
    H5Pclose(dcpl);
    H5Sclose(sp);
}

/* The reference curves: like an instrument export converted by afmformats (no time column). */
typedef struct refc {
    size_t n;
    double f[400], hm[400], hp[400];
    uint8_t seg[400];
} refc;

static void ref_curve(refc *c, int i)
{
    c->n = 300 + 50 * (size_t)i;
    for (size_t j = 0; j < c->n; j++) {
        int appr = j < c->n / 2;
        double z = appr ? 2e-6 * (1 - 2.0 * (double)j / (double)c->n) : 2e-6 * (2.0 * (double)j / (double)c->n - 1);
        c->hp[j] = z + 1e-5; /* instrument piezo range offset */
        c->hm[j] = z + 1e-5 + 3e-9 * cos((double)j);
        c->f[j] = z < 5e-7 ? 0.02 * (5e-7 - z) : 1e-12 * (double)(j % 7);
        c->seg[j] = (uint8_t)!appr;
    }
}

static void ref_meta(vafm_h5_meta *m, int i)
{
    static char cid[3][32];
    vafm_h5_meta_default(m);
    snprintf(cid[i], sizeof cid[i], "map-2021-03-04_%d", i);
    m->imaging_mode = "force-distance";
    m->feedback_mode = "contact";
    m->instrument = "JPK00912";
    m->software = "JPK";
    m->software_version = "6.1.99";
    m->date = "2021-03-04";
    m->time = "14:03:22.5";
    m->session_id = "map-2021-03-04";
    m->curve_id = cid[i];
    m->spring_constant_N_per_m = 0.0471;
    m->sensitivity_m_per_V = 7.32e-8;
    m->setpoint_N = 2e-9;
    m->rate_approach_Hz = 2048;
    m->rate_retract_Hz = 2048;
    m->speed_approach_m_per_s = 5e-6;
    m->speed_retract_m_per_s = 5e-6;
    m->duration_s = 0.4;
    m->z_range_m = 4e-6;
    m->position_x_m = 1.5e-6 * i;
    m->position_y_m = -2e-6;
    m->grid_center_x_m = 1.5e-6;
    m->grid_center_y_m = -2e-6;
    m->grid_size_x_m = 4.5e-6;
    m->grid_size_y_m = 1.5e-6;
    m->grid_shape_x = 3;
    m->grid_shape_y = 1;
    m->grid_index_x = i;
    m->grid_index_y = 0;
    m->segment_count = 2;
}

/* afmformats_extras: also the storage keys afmformats' own exporter writes ("enum", "path"). */
static void write_reference(const char *path, int afmformats_extras)
{
    remove(path);
    hid_t f = H5Fcreate(path, H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    h_str(f, "software", "afmformats", 0);
    h_str(f, "software version", "0.18.0", 0);
    for (int i = 0; i < 3; i++) {
        char name[8];
        snprintf(name, sizeof name, "%d", i);
        hid_t g = H5Gcreate2(f, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
        refc c;
        ref_curve(&c, i);
        h_dset(g, "force", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, c.f, c.n, "N", 1);
        h_dset(g, "height (measured)", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, c.hm, c.n, "m", 1);
        h_dset(g, "height (piezo)", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, c.hp, c.n, "m", 1);
        h_dset(g, "segment", H5T_STD_U8LE, H5T_NATIVE_UINT8, c.seg, c.n, "", 1);
        vafm_h5_meta m;
        ref_meta(&m, i);
        h_str(g, "imaging mode", m.imaging_mode, 0);
        h_str(g, "feedback mode", m.feedback_mode, 0);
        h_str(g, "instrument", m.instrument, 0);
        h_str(g, "software", m.software, 0);
        h_str(g, "software version", m.software_version, 0);
        h_str(g, "date", m.date, 0);
        h_str(g, "time", m.time, 0);
        h_str(g, "session id", m.session_id, 0);
        h_str(g, "curve id", m.curve_id, 0);
        h_f64(g, "spring constant", m.spring_constant_N_per_m);
        h_f64(g, "sensitivity", m.sensitivity_m_per_V);
        h_f64(g, "setpoint", m.setpoint_N);
        h_f64(g, "rate approach", m.rate_approach_Hz);
        h_f64(g, "rate retract", m.rate_retract_Hz);
        h_f64(g, "speed approach", m.speed_approach_m_per_s);
        h_f64(g, "speed retract", m.speed_retract_m_per_s);
        h_f64(g, "duration", m.duration_s);
        h_f64(g, "z range", m.z_range_m);
        h_f64(g, "position x", m.position_x_m);
        h_f64(g, "position y", m.position_y_m);
        h_f64(g, "grid center x", m.grid_center_x_m);
        h_f64(g, "grid center y", m.grid_center_y_m);
        h_f64(g, "grid size x", m.grid_size_x_m);
        h_f64(g, "grid size y", m.grid_size_y_m);
        h_i64(g, "point count", (int64_t)c.n);
        h_i64(g, "segment count", 2);
        h_i64(g, "grid shape x", 3);
        h_i64(g, "grid shape y", 1);
        h_i64(g, "grid index x", i);
        h_i64(g, "grid index y", 0);
        if (afmformats_extras) {
            h_i64(g, "enum", i);
            h_str(g, "path", "/data/2021-03-04/map.jpk-force-map", 0);
        }
        H5Gclose(g);
    }
    H5Fclose(f);
}

static void test_reference_file(void)
{
    for (int extras = 0; extras < 2; extras++) {
        const char *path = extras ? "t_h5_ref_afmformats.h5" : "t_h5_ref.h5";
        write_reference(path, extras);
        vafm_error e = { 0 };
        vafm_h5_reader *r = NULL;
        int rc = vafm_h5_reader_open(&r, path, &e);
        ENSURE_MSG(rc == 0, "%s", e.message);
        if (rc)
            continue;
        ENSURE(vafm_h5_reader_count(r) == 3);
        vafm_h5_provenance pv;
        vafm_h5_reader_provenance(r, &pv);
        ENSURE(!pv.is_vafm && s_same_str(pv.software, "afmformats") && s_same_str(pv.software_version, "0.18.0"));
        ENSURE(pv.truth_rows == 0 && pv.scene_json == NULL);
        for (int i = 0; i < 3; i++) {
            vafm_h5_curve c;
            rc = vafm_h5_reader_curve(r, (size_t)i, &c, &e);
            ENSURE_MSG(rc == 0, "%s", e.message);
            if (rc)
                continue;
            refc want;
            ref_curve(&want, i);
            vafm_h5_curve wc = { 0 };
            wc.n = want.n;
            wc.force_N = want.f;
            wc.height_measured_m = want.hm;
            wc.height_piezo_m = want.hp;
            wc.segment = want.seg;
            ref_meta(&wc.meta, i);
            wc.meta.point_count = (int64_t)want.n;
            char why[200] = "";
            ENSURE_MSG(c.group == (uint64_t)i && s_curve_eq(&c, &wc, 1, why, sizeof why), "reference curve %d: %s", i, why);
            ENSURE(c.time_s == NULL && c.tip_position_m == NULL);
            vafm_h5_truth t;
            ENSURE(vafm_h5_reader_truth(r, (uint64_t)i, &t) == VAFM_ENOTFOUND);
        }
        vafm_h5_reader_destroy(&r);
        /* the instrument-like file conforms; afmformats' own "enum"/"path" keys are outside the list */
        rc = vafm_h5_check(path, &e);
        if (!extras)
            ENSURE_MSG(rc == 0, "%s", e.message);
        else
            ENSURE_MSG(rc == VAFM_EFORMAT && strstr(e.message, "[L9]") && strstr(e.message, "'enum'"), "%s", e.message);
        /* resume refuses a file that is not vafm's */
        vafm_h5_writer_opts o;
        vafm_h5_writer_opts_default(&o);
        o.resume = 1;
        vafm_h5_writer *w = NULL;
        rc = vafm_h5_writer_open(&w, path, &o, &e);
        ENSURE_MSG(rc == VAFM_EFORMAT && s_msg_names(&e, path) && strstr(e.message, "vafm format version"), "%s",
                   e.message);
        ENSURE(w == NULL);
    }
}

/* ---- non-conforming files ------------------------------------------------------------------------ */

enum {
    B_NONE, B_K_STRING, B_UNIT_INT, B_POINT_COUNT, B_EXTRA_DSET, B_SUBGROUP, B_ROOT_OBJ, B_UNKNOWN_ATTR, B_LENGTHS,
    B_2D, B_SEG_FLOAT, B_NO_SWVERSION, B_FIXED_STR, B_SEG_VALUE, B_CREEP, B_SW_INT, B_UNIT_NN, B_F32, B_NAME_01,
    B_SOFTLINK, B_NO_FORCE, B_TIME_BACK, B_TIP_WRONG, B_DATE, B_FORMAT2, B_SEG_NEG, B_EMPTY, B_HUGE, B_EXTERNAL,
    B_VIRTUAL, B_FORMAT_NEG, B_POINT_NEG, B_COUNT
};

typedef struct bad_case {
    int kind;
    int reader_rc;       /* 0: the lenient reader accepts it */
    const char *needle;  /* the object or attribute the reader's message names */
    const char *rule;    /* the checker's rule */
    const char *cneedle; /* the object the checker's message names */
} bad_case;

static const bad_case s_bad[] = {
    { B_NONE, 0, NULL, NULL, NULL },
    { B_K_STRING, VAFM_EFORMAT, "'spring constant'", "[L9]", "/0" },
    { B_UNIT_INT, VAFM_EFORMAT, "/0/force: attribute 'unit'", "[L8]", "/0/force" },
    { B_POINT_COUNT, VAFM_EFORMAT, "'point count'", "[L11]", "/0" },
    { B_EXTRA_DSET, VAFM_EFORMAT, "'deflection'", "[L5]", "deflection" },
    { B_SUBGROUP, VAFM_EFORMAT, "'extra'", "[L5]", "extra" },
    { B_ROOT_OBJ, VAFM_EFORMAT, "'metadata'", "[L4]", "metadata" },
    { B_UNKNOWN_ATTR, VAFM_EFORMAT, "'temperature'", "[L9]", "temperature" },
    { B_LENGTHS, VAFM_EFORMAT, "same length", "[L7]", "/0/" },
    { B_2D, VAFM_EFORMAT, "/0/force is not 1-D", "[L7]", "/0/force" },
    { B_SEG_FLOAT, VAFM_EFORMAT, "/0/segment is a floating-point", "[L7]", "/0/segment" },
    { B_NO_SWVERSION, VAFM_EFORMAT, "'software version' is missing", "[L3]", "software version" },
    { B_FIXED_STR, 0, NULL, "[L9]", "fixed-length" },
    { B_SEG_VALUE, VAFM_EFORMAT, "/0/segment: value 5", "[L12]", "/0/segment" },
    { B_CREEP, VAFM_ENOTSUP, "creep-compliance", "[L10]", "/0" },
    { B_SW_INT, VAFM_EFORMAT, "'software' is an integer", "[L3]", "'software'" },
    { B_UNIT_NN, VAFM_EFORMAT, "'nN'", "[L8]", "/0/force" },
    { B_F32, 0, NULL, "[L7]", "/0/force" },
    { B_NAME_01, VAFM_EFORMAT, "'01'", "[L4]", "'01'" },
    { B_SOFTLINK, VAFM_EFORMAT, "'1' is a soft", "[L4]", "'1'" },
    { B_NO_FORCE, VAFM_EFORMAT, "lacks 'force'", "[L6]", "force" },
    { B_TIME_BACK, 0, NULL, "[L13]", "/0/time" },
    { B_TIP_WRONG, 0, NULL, "[L14]", "/0/tip position" },
    { B_DATE, 0, NULL, "[L15]", "'date'" },
    { B_FORMAT2, VAFM_EFORMAT, "format version 2.0", "[V1]", "vafm format version" },
    /* 0.6.1: HDF5 clamped -1 to 0 (an approach sample); a zero-length curve was read; the checker allocated
     * what a dataset declared (1e12 samples: 8 TB) before looking for its data */
    { B_SEG_NEG, VAFM_EFORMAT, "/0/segment holds a value outside 0-255 (negative", "[L7]", "/0/segment" },
    { B_EMPTY, VAFM_EFORMAT, "/0/force holds no samples", "[L7]", "/0/force: holds no samples" },
    { B_HUGE, VAFM_EFORMAT, "declares 1000000000000 samples", "VAFM_H5_MAX_SAMPLES", "/0/force" },
    /* 0.6.2 said "part of the data has no storage (damaged chunk index)" of raw data in an external file;
     * both point at a FIFO (S_FIFO), which blocks whoever opens it: the data must never be read */
    { B_EXTERNAL, VAFM_EFORMAT, "/0/force is stored in an external file (not read)", "[L2]",
      "/0/force: is stored in an external file" },
    { B_VIRTUAL, VAFM_EFORMAT, "/0/force is a virtual dataset", "[L2]", "/0/force: is a virtual dataset" },
    /* 0.6.1 read "1.-0" as 1.0 (sscanf's %d takes a sign) */
    { B_FORMAT_NEG, VAFM_EFORMAT, "is not \"MAJOR.MINOR\"", "[V1]", "vafm format version" },
    { B_POINT_NEG, VAFM_EFORMAT, "'point count' is negative", "[L9]", "'point count' is negative" }, /* 0.6.1: "is an integer" */
};

#define S_FIFO "t_h5_bad.fifo" /* a FIFO without a writer: opening it to read blocks */

static void write_bad(const char *path, int kind)
{
    remove(path);
    hid_t f = H5Fcreate(path, H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    if (kind == B_SW_INT)
        h_i64(f, "software", 7);
    else
        h_str(f, "software", "handmade", 0);
    if (kind != B_NO_SWVERSION)
        h_str(f, "software version", "1", 0);
    if (kind == B_FORMAT2)
        h_str(f, "vafm format version", "2.0", 0);
    if (kind == B_FORMAT_NEG)
        h_str(f, "vafm format version", "1.-0", 0);
    hid_t g = H5Gcreate2(f, kind == B_NAME_01 ? "01" : "0", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    enum { N = 64 };
    const hsize_t nn = kind == B_EMPTY ? 0 : N;
    double fo[N], h[N], t[N], tip[N], k = 0.1;
    uint8_t seg[N];
    for (int i = 0; i < N; i++) {
        h[i] = 1e-7 * (double)(N - i);
        fo[i] = 1e-10 * i;
        t[i] = (i + 0.5) * 1e-3;
        seg[i] = i >= N / 2;
        tip[i] = h[i] + fo[i] / k;
    }
    if (kind == B_TIME_BACK)
        t[10] = t[9];
    if (kind == B_TIP_WRONG)
        tip[5] += 1e-9;
    if (kind == B_SEG_VALUE)
        seg[7] = 5;
    if (kind == B_HUGE) { /* declared, chunked, never written: 7 kB on disk */
        hsize_t big = 1000000000000ull, chunk = 1u << 20;
        hid_t sp = H5Screate_simple(1, &big, NULL), dcpl = H5Pcreate(H5P_DATASET_CREATE);
        H5Pset_chunk(dcpl, 1, &chunk);
        hid_t d = H5Dcreate2(g, "force", H5T_IEEE_F64LE, sp, H5P_DEFAULT, dcpl, H5P_DEFAULT);
        h_str(d, "unit", "N", 0);
        H5Dclose(d);
        H5Pclose(dcpl);
        H5Sclose(sp);
    } else if (kind == B_EXTERNAL || kind == B_VIRTUAL) { /* the data "in" S_FIFO */
        hsize_t nf = N;
        hid_t sp = H5Screate_simple(1, &nf, NULL), dcpl = H5Pcreate(H5P_DATASET_CREATE);
        if (kind == B_EXTERNAL)
            H5Pset_external(dcpl, S_FIFO, 0, N * sizeof(double));
        else
            H5Pset_virtual(dcpl, sp, S_FIFO, "force", sp);
        hid_t d = H5Dcreate2(g, "force", H5T_IEEE_F64LE, sp, H5P_DEFAULT, dcpl, H5P_DEFAULT);
        h_str(d, "unit", "N", 0);
        H5Dclose(d);
        H5Pclose(dcpl);
        H5Sclose(sp);
    } else if (kind == B_2D) {
        hsize_t d2[2] = { N / 2, 2 };
        hid_t sp = H5Screate_simple(2, d2, NULL);
        hid_t d = H5Dcreate2(g, "force", H5T_IEEE_F64LE, sp, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
        H5Dwrite(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, fo);
        h_str(d, "unit", "N", 0);
        H5Dclose(d);
        H5Sclose(sp);
    } else if (kind == B_UNIT_INT) {
        h_dset(g, "force", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, fo, N, NULL, 0);
        hid_t d = H5Dopen2(g, "force", H5P_DEFAULT);
        h_i64(d, "unit", 1);
        H5Dclose(d);
    } else if (kind != B_NO_FORCE) {
        h_dset(g, "force", kind == B_F32 ? H5T_IEEE_F32LE : H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, fo, nn,
               kind == B_UNIT_NN ? "nN" : "N", 0);
    }
    h_dset(g, "height (measured)", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, h, nn, "m", 0);
    h_dset(g, "height (piezo)", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, h, kind == B_LENGTHS ? nn - 1 : nn, "m", 0);
    if (kind == B_SEG_FLOAT) {
        h_dset(g, "segment", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, h, nn, "", 0);
    } else if (kind == B_SEG_NEG) {
        int64_t s64[N];
        for (int i = 0; i < N; i++)
            s64[i] = i == 7 ? -1 : seg[i];
        h_dset(g, "segment", H5T_STD_I64LE, H5T_NATIVE_INT64, s64, nn, "", 0);
    } else {
        h_dset(g, "segment", H5T_STD_U8LE, H5T_NATIVE_UINT8, seg, nn, "", 0);
    }
    h_dset(g, "time", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, t, nn, "s", 0);
    h_dset(g, "tip position", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, tip, nn, "m", 0);
    if (kind == B_EXTRA_DSET)
        h_dset(g, "deflection", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, h, N, "m", 0);
    if (kind == B_SUBGROUP)
        H5Gclose(H5Gcreate2(g, "extra", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT));
    h_str(g, "imaging mode", kind == B_CREEP ? "creep-compliance" : "force-distance", kind == B_FIXED_STR);
    if (kind == B_K_STRING)
        h_str(g, "spring constant", "0.1", 0);
    else
        h_f64(g, "spring constant", k);
    h_i64(g, "point count", kind == B_POINT_COUNT ? N + 1 : kind == B_POINT_NEG ? -5 : (int64_t)nn);
    if (kind == B_UNKNOWN_ATTR)
        h_f64(g, "temperature", 300);
    h_str(g, "date", kind == B_DATE ? "04/03/2021" : "2021-03-04", 0);
    H5Gclose(g);
    if (kind == B_ROOT_OBJ)
        H5Gclose(H5Gcreate2(f, "metadata", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT));
    if (kind == B_SOFTLINK)
        H5Lcreate_soft("/0", f, "1", H5P_DEFAULT, H5P_DEFAULT);
    H5Fclose(f);
}

/* Open and read every curve; @return the first error (0 if all read). */
static int s_read_all(const char *path, vafm_error *e)
{
    vafm_h5_reader *r = NULL;
    int rc = vafm_h5_reader_open(&r, path, e);
    for (size_t i = 0; !rc && i < vafm_h5_reader_count(r); i++) {
        vafm_h5_curve c;
        rc = vafm_h5_reader_curve(r, i, &c, e);
    }
    vafm_h5_reader_destroy(&r);
    return rc;
}

static void test_bad_files(void)
{
    const char *path = "t_h5_bad.h5";
    remove(S_FIFO);
    ENSURE(mkfifo(S_FIFO, 0600) == 0);
    alarm(60); /* a read of S_FIFO would block: fail instead of hanging */
    for (size_t i = 0; i < sizeof s_bad / sizeof s_bad[0]; i++) {
        const bad_case *b = &s_bad[i];
        write_bad(path, b->kind);
        vafm_error e = { 0 };
        int rc = s_read_all(path, &e);
        if (b->reader_rc)
            ENSURE_MSG(rc == b->reader_rc && s_msg_names(&e, path) && strstr(e.message, b->needle),
                       "case %d: rc %d, message: %s", b->kind, rc, e.message);
        else
            ENSURE_MSG(rc == 0, "case %d: %s", b->kind, e.message);
        memset(&e, 0, sizeof e);
        rc = vafm_h5_check(path, &e);
        if (b->rule)
            ENSURE_MSG(rc == VAFM_EFORMAT && s_msg_names(&e, path) && strstr(e.message, b->rule) &&
                           strstr(e.message, b->cneedle),
                       "case %d: checker rc %d: %s", b->kind, rc, e.message);
        else
            ENSURE_MSG(rc == 0, "case %d: checker: %s", b->kind, e.message);
    }
    alarm(0);
    remove(S_FIFO);
    /* not HDF5 at all */
    FILE *f = fopen(path, "w");
    fputs("# force-distance curve, tab separated\n1\t2\n", f);
    fclose(f);
    vafm_error e = { 0 };
    ENSURE_MSG(s_read_all(path, &e) == VAFM_EFORMAT && s_msg_names(&e, path) && strstr(e.message, "not an HDF5"), "%s",
               e.message);
    ENSURE(vafm_h5_check(path, &e) == VAFM_EFORMAT && strstr(e.message, "[L2]"));
    f = fopen(path, "w");
    fclose(f);
    ENSURE(s_read_all(path, &e) == VAFM_EFORMAT && s_msg_names(&e, path));
    ENSURE(s_read_all("t_h5_does_not_exist.h5", &e) == VAFM_EIO && s_msg_names(&e, "t_h5_does_not_exist.h5"));
    /* the suffix */
    write_bad("t_h5_bad.hdf5", B_NONE);
    ENSURE(vafm_h5_check("t_h5_bad.hdf5", &e) == VAFM_EFORMAT && strstr(e.message, "[L1]"));
    remove("t_h5_bad.hdf5");
}

/* ---- the writer refuses what breaks the layout ---------------------------------------------------- */

static void test_writer_refusals(void)
{
    const char *path = "t_h5_refuse.h5";
    remove(path);
    vafm_error e = { 0 };
    vafm_h5_writer *w = NULL;
    ENSURE(vafm_h5_writer_open(&w, "t_h5_refuse.hdf5", NULL, &e) == VAFM_EINVAL && strstr(e.message, ".h5"));
    vafm_h5_writer_opts o;
    vafm_h5_writer_opts_default(&o);
    o.gzip_level = 10;
    ENSURE(vafm_h5_writer_open(&w, path, &o, &e) == VAFM_EINVAL && !strcmp(e.field, "gzip_level"));
    ENSURE(vafm_h5_writer_open(&w, path, NULL, &e) == 0);
    vafm_params p;
    s_fig4(&p);
    ENSURE(vafm_h5_writer_set_provenance(w, &p, NULL, &e) == 0);
    syn s;
    syn_make(&s, 200, 0.05, 0);
    ENSURE(vafm_h5_writer_append(w, &s.c, NULL, &e) == VAFM_EINVAL && !strcmp(e.field, "truth"));
    s.truth.result.index = 1;
    ENSURE(vafm_h5_writer_append(w, &s.c, &s.truth, &e) == VAFM_EINVAL && strstr(e.message, "index order"));
    s.truth.result.index = 0;
    struct {
        const char *what;
        void (*apply)(syn *);
    } cases[] = {
        { "segment", NULL }, { "time", NULL }, { "tip position", NULL }, { "date", NULL }, { "point count", NULL },
        { "force", NULL }, { "time", NULL }, { "imaging mode", NULL }, { "feedback mode", NULL }, { "n", NULL },
    };
    for (int i = 0; i < (int)(sizeof cases / sizeof cases[0]); i++) {
        syn b;
        syn_make(&b, 200, 0.05, 0);
        switch (i) {
        case 0: b.seg[17] = 3; break;
        case 1: b.t[50] = b.t[49]; break;
        case 2: b.tip[3] += 1e-9; break;
        case 3: b.c.meta.date = "2024-13-01"; break;
        case 4: b.c.meta.point_count = 199; break;
        case 5: b.f[9] = NAN; break;
        case 6: b.c.meta.time = "2024-02-29T13:45:07"; break;
        case 7: b.c.meta.imaging_mode = "creep-compliance"; break;
        case 8: b.c.meta.feedback_mode = "tapping"; break;
        case 9: b.c.n = 0; break;
        }
        memset(&e, 0, sizeof e);
        int rc = vafm_h5_writer_append(w, &b.c, &b.truth, &e);
        ENSURE_MSG(rc == VAFM_EINVAL && !strcmp(e.field, cases[i].what) && s_msg_names(&e, path),
                   "case %d: rc %d field '%s': %s", i, rc, e.field, e.message);
        syn_free(&b);
    }
    ENSURE(vafm_h5_writer_count(w) == 0);
    ENSURE(vafm_h5_writer_append(w, &s.c, &s.truth, &e) == 0 && vafm_h5_writer_count(w) == 1);
    ENSURE(vafm_h5_writer_set_provenance(w, &p, NULL, &e) == 0); /* same scene: accepted, nothing written */
    ENSURE(vafm_h5_writer_close(&w, &e) == 0 && w == NULL);
    ENSURE_MSG(vafm_h5_check(path, &e) == 0, "%s", e.message);
    /* creating over an existing file needs overwrite */
    ENSURE(vafm_h5_writer_open(&w, path, NULL, &e) == VAFM_EIO && strstr(e.message, "exists"));
    /* resume needs the same scene, and names the field that differs */
    o.gzip_level = 0;
    o.resume = 1;
    ENSURE(vafm_h5_writer_open(&w, path, &o, &e) == 0 && vafm_h5_writer_count(w) == 1);
    vafm_params q = p;
    q.k_N_per_m *= 2;
    ENSURE_MSG(vafm_h5_writer_set_provenance(w, &q, NULL, &e) == VAFM_EINVAL && !strcmp(e.field, "k_N_per_m"),
               "field '%s': %s", e.field, e.message);
    vafm_campaign_spec g = { 0 };
    g.curves_per_point = 3;
    ENSURE_MSG(vafm_h5_writer_set_provenance(w, &p, &g, &e) == VAFM_EINVAL && strstr(e.message, "grid") &&
                   !strstr(e.message, "'?'"),
               "%s", e.message);
    ENSURE(vafm_h5_writer_set_provenance(w, &p, NULL, &e) == 0);
    syn_free(&s);
    syn_make(&s, 250, 0.05, 1);
    ENSURE(vafm_h5_writer_append(w, &s.c, &s.truth, &e) == 0 && vafm_h5_writer_count(w) == 2);
    ENSURE(vafm_h5_writer_close(&w, &e) == 0);
    ENSURE_MSG(vafm_h5_check(path, &e) == 0, "%s", e.message);
    syn_free(&s);
    /* a file with its scene and no curve yet (killed before its first curve, a daemon log started and
     * stopped): resumed from curve 0 (0.6.1 passed the rows' NULL to memcpy: UBSan) */
    const char *path0 = "t_h5_zero_curves.h5";
    o.resume = 0;
    o.overwrite = 1;
    ENSURE(vafm_h5_writer_open(&w, path0, &o, &e) == 0 && vafm_h5_writer_set_provenance(w, &p, NULL, &e) == 0);
    ENSURE(vafm_h5_writer_close(&w, &e) == 0);
    o.resume = 1;
    o.overwrite = 0;
    ENSURE_MSG(vafm_h5_writer_open(&w, path0, &o, &e) == 0, "%s", e.message);
    ENSURE(w && vafm_h5_writer_count(w) == 0 && vafm_h5_writer_set_provenance(w, &p, NULL, &e) == 0);
    syn_make(&s, 200, 0.05, 0);
    ENSURE_MSG(w && vafm_h5_writer_append(w, &s.c, &s.truth, &e) == 0 && vafm_h5_writer_count(w) == 1, "%s",
               e.message);
    ENSURE(vafm_h5_writer_close(&w, &e) == 0);
    ENSURE_MSG(vafm_h5_check(path0, &e) == 0, "%s", e.message);
    syn_free(&s);
    vafm_h5_writer_destroy(&w); /* NULL-safe */
    vafm_h5_reader_destroy(NULL);
}

/* ---- damaged files --------------------------------------------------------------------------------- */

static unsigned char *s_slurp(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return NULL;
    fseek(f, 0, SEEK_END);
    long len = ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *b = malloc((size_t)len + 1);
    *n = fread(b, 1, (size_t)len, f);
    fclose(f);
    return b;
}

static void s_spit(const char *path, const unsigned char *b, size_t n)
{
    FILE *f = fopen(path, "wb");
    if (n)
        fwrite(b, 1, n, f);
    fclose(f);
}

/* In a child: read the damaged file and compare with the original.
 * Exit codes: 0 read back identical (channels, numbers, truth), 10 refused at open with a message naming
 * the file, 11 a curve refused likewise, 12 read without error but different (silent damage),
 * 13 an error without a proper message, 14 the original could not be read. */
static int dmg_child(const char *orig, const char *bad)
{
    vafm_error e = { 0 };
    vafm_h5_reader *r = NULL, *o = NULL;
    if (vafm_h5_reader_open(&r, bad, &e))
        return s_msg_names(&e, bad) ? 10 : 13;
    if (vafm_h5_reader_open(&o, orig, &e))
        return 14;
    int code = 0;
    vafm_h5_provenance pr, po;
    vafm_h5_reader_provenance(r, &pr);
    vafm_h5_reader_provenance(o, &po);
    if (vafm_h5_reader_count(r) != vafm_h5_reader_count(o) || pr.truth_rows != po.truth_rows || pr.seed != po.seed)
        code = 12;
    for (size_t i = 0; !code && i < vafm_h5_reader_count(r); i++) {
        vafm_h5_curve a, b;
        if (vafm_h5_reader_curve(r, i, &a, &e)) {
            code = s_msg_names(&e, bad) ? 11 : 13;
            break;
        }
        if (vafm_h5_reader_curve(o, i, &b, &e)) {
            code = 14;
            break;
        }
        /* strings live in HDF5's global heap, which has no checksum: compare channels and numbers */
        b.meta.imaging_mode = a.meta.imaging_mode;
        b.meta.feedback_mode = a.meta.feedback_mode;
        b.meta.instrument = a.meta.instrument;
        b.meta.software = a.meta.software;
        b.meta.software_version = a.meta.software_version;
        b.meta.date = a.meta.date;
        b.meta.time = a.meta.time;
        b.meta.session_id = a.meta.session_id;
        b.meta.curve_id = a.meta.curve_id;
        char why[160];
        vafm_h5_truth ta, tb;
        int ha = vafm_h5_reader_truth(r, a.group, &ta), hb = vafm_h5_reader_truth(o, b.group, &tb);
        if (a.group != b.group || !s_curve_eq(&a, &b, 0, why, sizeof why) || ha != hb || (!ha && !s_truth_eq(&ta, &tb)))
            code = 12;
    }
    vafm_h5_reader_destroy(&r);
    vafm_h5_reader_destroy(&o);
    return code;
}

/* Run one damaged copy in a child. @return the child's exit code, or 100 + signal if it crashed. */
static int dmg_run(const char *orig, const char *bad)
{
    fflush(NULL);
    pid_t pid = fork();
    if (pid == 0)
        _exit(dmg_child(orig, bad));
    int st = 0;
    waitpid(pid, &st, 0);
    if (WIFSIGNALED(st))
        return 100 + WTERMSIG(st);
    return WEXITSTATUS(st);
}

/* Byte ranges of the raw data (chunks) of a file, to aim half the damage at metadata. */
typedef struct ranges {
    uint64_t a[64], b[64];
    int n;
} ranges;

static herr_t s_raw_cb(hid_t g, const char *name, const H5L_info_t *info, void *data)
{
    ranges *rg = data;
    hid_t o = H5Oopen(g, name, H5P_DEFAULT);
    if (o < 0)
        return 0;
    if (H5Iget_type(o) == H5I_GROUP) {
        H5Literate(o, H5_INDEX_NAME, H5_ITER_NATIVE, NULL, s_raw_cb, rg);
    } else if (H5Iget_type(o) == H5I_DATASET && rg->n < 64) {
        haddr_t addr = HADDR_UNDEF;
        hsize_t size = 0, off[1] = { 0 };
        unsigned mask = 0;
        hid_t dcpl = H5Dget_create_plist(o);
        if (H5Pget_layout(dcpl) == H5D_CHUNKED) {
            hid_t sp = H5Dget_space(o);
            H5Dget_chunk_info(o, sp, 0, off, &mask, &addr, &size);
            H5Sclose(sp);
        } else {
            addr = H5Dget_offset(o);
            size = H5Dget_storage_size(o);
        }
        H5Pclose(dcpl);
        if (addr != HADDR_UNDEF) {
            rg->a[rg->n] = addr;
            rg->b[rg->n++] = addr + size;
        }
    }
    H5Oclose(o);
    return 0;
}

static int s_in_raw(const ranges *rg, uint64_t pos)
{
    for (int i = 0; i < rg->n; i++)
        if (pos >= rg->a[i] && pos < rg->b[i])
            return 1;
    return 0;
}

static void dmg_file(const char *orig, int trials)
{
    size_t n = 0;
    unsigned char *b = s_slurp(orig, &n);
    ENSURE(b && n > 4096);
    if (!b || n <= 4096)
        return;
    ranges rg = { .n = 0 };
    hid_t f = H5Fopen(orig, H5F_ACC_RDONLY, H5P_DEFAULT);
    H5Literate(f, H5_INDEX_NAME, H5_ITER_NATIVE, NULL, s_raw_cb, &rg);
    H5Fclose(f);
    ENSURE(rg.n > 0);
    const char *bad = "t_h5_damaged.h5";
    int counts[128] = { 0 };
    /* truncation: HDF5 records the end of file; every shorter file is refused */
    size_t cuts[] = { 0, 1, 7, 8, 64, 512, n / 10, n / 3, n / 2, n - 4096, n - 1 };
    for (size_t i = 0; i < sizeof cuts / sizeof cuts[0]; i++) {
        s_spit(bad, b, cuts[i]);
        int code = dmg_run(orig, bad);
        ENSURE_MSG(code == 10 || code == 11, "%s truncated to %zu bytes: child code %d", orig, cuts[i], code);
    }
    /* flipped bytes: half anywhere (mostly channel data), half in the metadata between them */
    unsigned char *c = malloc(n);
    for (int t = 0; t < trials; t++) {
        memcpy(c, b, n);
        int nflip = 1 + (int)(s_next() % 3);
        size_t where[3];
        for (int j = 0; j < nflip; j++) {
            size_t pos;
            int meta = t % 2;
            do
                pos = (size_t)(s_next() % n);
            while (meta && s_in_raw(&rg, pos));
            where[j] = pos;
            c[pos] ^= (unsigned char)(1 + s_next() % 255);
        }
        s_spit(bad, c, n);
        int code = dmg_run(orig, bad);
        counts[code < 128 ? code : 127]++;
        if (code != 0 && code != 10 && code != 11) {
            char keep[64];
            snprintf(keep, sizeof keep, "t_h5_damaged_fail_%d.h5", t);
            s_spit(keep, c, n); /* kept for diagnosis */
        }
        ENSURE_MSG(code == 0 || code == 10 || code == 11, "%s: bytes flipped at %zu%s: child code %d (%s)", orig,
                   where[0], nflip > 1 ? " and more" : "", code,
                   code >= 100 ? "crash" : code == 12 ? "silent damage" : code == 13 ? "message without the file" : "?");
    }
    fprintf(stderr, "  %s (%zu bytes, %d trials): identical %d, refused at open %d, refused at a curve %d\n", orig, n,
            trials, counts[0], counts[10], counts[11]);
    /* most damage must be detected: a flip in unused bytes or padding is harmless, but raw data are
     * covered by Fletcher-32 and metadata by HDF5's checksums */
    ENSURE(counts[10] + counts[11] >= trials / 2);
    ENSURE(counts[0] + counts[10] + counts[11] == trials);
    free(c);
    free(b);
    remove(bad);
}

static void test_damaged_files(void)
{
    vafm_error e = { 0 };
    remove("t_h5_dmg_src.h5");
    ENSURE_MSG(syn_file("t_h5_dmg_src.h5", NULL, 4, &e) == 0, "%s", e.message);
    dmg_file("t_h5_dmg_src.h5", LONG_OR(400, 120));
    vafm_h5_writer_opts o;
    vafm_h5_writer_opts_default(&o);
    o.gzip_level = 6;
    remove("t_h5_dmg_gz.h5");
    ENSURE_MSG(syn_file("t_h5_dmg_gz.h5", &o, 4, &e) == 0, "%s", e.message);
    dmg_file("t_h5_dmg_gz.h5", LONG_OR(200, 60));
    /* another program's file in HDF5's earliest format (h5py's default) has no metadata checksums, and
     * HDF5 1.10 itself can crash on flipped bytes there; truncation it refuses cleanly */
    write_reference("t_h5_dmg_ref.h5", 0);
    dmg_file("t_h5_dmg_ref.h5", 0);
    /* a wrong attribute type after the fact: rewrite "spring constant" of curve 1 as a string */
    remove("t_h5_dmg_type.h5");
    ENSURE(syn_file("t_h5_dmg_type.h5", NULL, 4, &e) == 0);
    hid_t f = H5Fopen("t_h5_dmg_type.h5", H5F_ACC_RDWR, H5P_DEFAULT);
    hid_t g = H5Gopen2(f, "1", H5P_DEFAULT);
    H5Adelete(g, "spring constant");
    h_str(g, "spring constant", "0.06 N/m", 0);
    H5Gclose(g);
    H5Fclose(f);
    vafm_h5_reader *r = NULL;
    ENSURE(vafm_h5_reader_open(&r, "t_h5_dmg_type.h5", &e) == 0);
    vafm_h5_curve c;
    ENSURE(vafm_h5_reader_curve(r, 0, &c, &e) == 0);
    ENSURE_MSG(vafm_h5_reader_curve(r, 1, &c, &e) == VAFM_EFORMAT && strstr(e.message, "'spring constant' is a string") &&
                   !strcmp(e.field, "/1"),
               "%s", e.message);
    vafm_h5_reader_destroy(&r);
    ENSURE(vafm_h5_check("t_h5_dmg_type.h5", &e) == VAFM_EFORMAT && strstr(e.message, "[L9]"));
}

/* ---- kill -9 and resume ---------------------------------------------------------------------------- */

/* Fork a writer child running fn(path, resume, write end of a pipe) (fn never returns); the parent keeps
 * the read end in pfd[0]. @return the child's pid, or −1 (no pipe). */
static pid_t s_spawn_writer(void (*fn)(const char *, int, int), const char *path, int resume, int pfd[2])
{
    if (pipe(pfd))
        return -1;
    fflush(NULL);
    pid_t pid = fork();
    if (pid == 0) {
        close(pfd[0]);
        fn(path, resume, pfd[1]);
    }
    close(pfd[1]);
    return pid;
}

/* Child: run (or resume) the campaign into path with a flush after each curve, reporting each flushed
 * curve's index on fd. */
static void kill_child(const char *path, int resume, int fd)
{
    vafm_error e = { 0 };
    int rc = camp_write(path, 2, resume, 1, fd, NULL, 0, &e);
    if (rc)
        fprintf(stderr, "kill child: %s\n", e.message);
    _exit(rc ? 1 : 0);
}

static void test_kill_resume(void)
{
    size_t total = camp_total();
    vafm_error e = { 0 };
    /* the uninterrupted run, 1 thread */
    int rc = camp_write("t_h5_uninterrupted.h5", 1, 0, 0, -1, NULL, 0, &e);
    ENSURE_MSG(rc == 0, "%s", e.message);
    const char *path = "t_h5_killed.h5";
    remove(path);
    uint64_t flushed = 0; /* curves reported flushed before the kill */
    int kills = 0, rounds = 0;
    for (; rounds < 12; rounds++) {
        int pfd[2];
        pid_t pid = s_spawn_writer(kill_child, path, rounds > 0, pfd);
        if (pid < 0)
            break;
        /* kill after 1–2 more flushes and a random delay (0–25 ms: inside a curve, a write or a flush),
         * except in the last round, which runs to the end */
        int last = kills >= 4;
        uint64_t want = 1 + s_next() % 2, got = 0, idx;
        int child_done = 0;
        while (!last && got < want) {
            ssize_t k = read(pfd[0], &idx, sizeof idx);
            if (k != (ssize_t)sizeof idx) {
                child_done = 1;
                break;
            }
            got++;
            flushed = idx + 1;
        }
        if (!last && !child_done) {
            struct timespec ts = { 0, (long)(s_unif() * 25e6) };
            nanosleep(&ts, NULL);
            kill(pid, SIGKILL);
            kills++;
        }
        /* drain what the child reported before it died */
        ssize_t k;
        while ((k = read(pfd[0], &idx, sizeof idx)) == (ssize_t)sizeof idx)
            flushed = idx + 1;
        close(pfd[0]);
        int st = 0;
        waitpid(pid, &st, 0);
        int exited_ok = WIFEXITED(st) && WEXITSTATUS(st) == 0;
        ENSURE_MSG(exited_ok || (WIFSIGNALED(st) && WTERMSIG(st) == SIGKILL), "round %d: child status %d", rounds, st);
        /* the file opens and holds every curve flushed before the kill */
        vafm_h5_reader *r = NULL;
        rc = vafm_h5_reader_open(&r, path, &e);
        ENSURE_MSG(rc == 0, "round %d, after kill: %s", rounds, e.message);
        if (!rc) {
            ENSURE_MSG(vafm_h5_reader_count(r) >= flushed, "round %d: %zu curves in the file, %llu flushed", rounds,
                       vafm_h5_reader_count(r), (unsigned long long)flushed);
            for (size_t i = 0; i < flushed && i < vafm_h5_reader_count(r); i++) {
                vafm_h5_curve c;
                vafm_h5_truth t;
                int rr = vafm_h5_reader_curve(r, i, &c, &e);
                ENSURE_MSG(rr == 0, "round %d curve %zu: %s", rounds, i, e.message);
                ENSURE(vafm_h5_reader_truth(r, i, &t) == 0);
            }
        }
        vafm_h5_reader_destroy(&r);
        if (exited_ok)
            break;
    }
    ENSURE(kills >= 1);
    fprintf(stderr, "  %d kills in %d rounds, %zu curves\n", kills, rounds + 1, total);
    char why[200] = "";
    ENSURE_MSG(vafm_h5_check(path, &e) == 0, "%s", e.message);
    ENSURE_MSG(s_files_eq(path, "t_h5_uninterrupted.h5", why, sizeof why), "resumed vs uninterrupted: %s", why);
    /* resuming a complete file keeps everything and adds nothing */
    rc = camp_write(path, 1, 1, 1, -1, NULL, 0, &e);
    ENSURE_MSG(rc == 0, "%s", e.message);
    ENSURE(s_files_eq(path, "t_h5_uninterrupted.h5", why, sizeof why));
}

/* Kills that land inside appends and flushes: a child appends small synthetic curves with a flush
 * after each, and is killed 0–3 ms after its first flush, round after round. HDF5 writes a flush's
 * metadata in place and in no crash-safe order; the journaling driver (h5_journal.c) must keep every
 * file readable with every flushed curve, and the final file must equal the synthetic curves. */
static void flush_child(const char *path, int resume, int fd)
{
    vafm_error e = { 0 };
    vafm_h5_writer *w = NULL;
    vafm_h5_writer_opts o;
    vafm_h5_writer_opts_default(&o);
    o.resume = resume;
    o.overwrite = !resume;
    vafm_params p;
    s_fig4(&p);
    if (vafm_h5_writer_open(&w, path, &o, &e) || vafm_h5_writer_set_provenance(w, &p, NULL, &e)) {
        fprintf(stderr, "flush child: %s\n", e.message);
        _exit(1);
    }
    for (uint64_t i = vafm_h5_writer_count(w);; i++) {
        syn s;
        syn_make(&s, 400, 0.05, i);
        if (vafm_h5_writer_append(w, &s.c, &s.truth, &e) || vafm_h5_writer_flush(w, &e)) {
            fprintf(stderr, "flush child: %s\n", e.message);
            _exit(1);
        }
        syn_free(&s);
        if (write(fd, &i, sizeof i) != (ssize_t)sizeof i)
            _exit(1);
    }
}

static void test_kill_during_flush(void)
{
    const char *path = "t_h5_killflush.h5";
    remove(path);
    vafm_error e = { 0 };
    uint64_t flushed = 0;
    int rounds = LONG_OR(80, 30), bad = 0;
    for (int r = 0; r < rounds && !bad; r++) {
        int pfd[2];
        pid_t pid = s_spawn_writer(flush_child, path, r > 0, pfd);
        if (pid < 0)
            break;
        uint64_t idx;
        if (read(pfd[0], &idx, sizeof idx) == (ssize_t)sizeof idx)
            flushed = idx + 1;
        struct timespec ts = { 0, (long)(s_unif() * 3e6) };
        nanosleep(&ts, NULL);
        kill(pid, SIGKILL);
        while (read(pfd[0], &idx, sizeof idx) == (ssize_t)sizeof idx)
            flushed = idx + 1;
        close(pfd[0]);
        int st = 0;
        waitpid(pid, &st, 0);
        ENSURE_MSG(WIFSIGNALED(st) && WTERMSIG(st) == SIGKILL, "round %d: child status %d", r, st);
        vafm_h5_reader *rd = NULL;
        int rc = vafm_h5_reader_open(&rd, path, &e);
        ENSURE_MSG(rc == 0, "round %d: %s", r, e.message);
        if (rc) {
            bad = 1;
            break;
        }
        ENSURE(vafm_h5_reader_count(rd) >= flushed);
        vafm_h5_curve c;
        vafm_h5_truth t;
        if (flushed) {
            rc = vafm_h5_reader_curve(rd, flushed - 1, &c, &e);
            ENSURE_MSG(rc == 0, "round %d, curve %llu: %s", r, (unsigned long long)flushed - 1, e.message);
            ENSURE(vafm_h5_reader_truth(rd, flushed - 1, &t) == 0);
        }
        vafm_h5_reader_destroy(&rd);
    }
    vafm_h5_writer_opts o;
    vafm_h5_writer_opts_default(&o);
    o.resume = 1;
    vafm_h5_writer *w = NULL;
    int rc = vafm_h5_writer_open(&w, path, &o, &e);
    ENSURE_MSG(rc == 0, "%s", e.message);
    uint64_t n = vafm_h5_writer_count(w);
    ENSURE(n >= flushed && n <= flushed + 1);
    ENSURE(vafm_h5_writer_close(&w, &e) == 0);
    ENSURE_MSG(vafm_h5_check(path, &e) == 0, "%s", e.message);
    vafm_h5_reader *rd = NULL;
    ENSURE(vafm_h5_reader_open(&rd, path, &e) == 0);
    for (uint64_t i = 0; rd && i < n; i++) {
        syn s;
        syn_make(&s, 400, 0.05, i);
        vafm_h5_curve c;
        vafm_h5_truth t;
        char why[200] = "";
        rc = vafm_h5_reader_curve(rd, (size_t)i, &c, &e);
        ENSURE_MSG(rc == 0 && s_curve_eq(&c, &s.c, 1, why, sizeof why), "curve %llu: %s %s", (unsigned long long)i,
                   rc ? e.message : "", why);
        ENSURE(vafm_h5_reader_truth(rd, i, &t) == 0 && s_truth_eq(&t, &s.truth));
        syn_free(&s);
    }
    vafm_h5_reader_destroy(&rd);
    fprintf(stderr, "  %d kills inside appends and flushes, %llu curves kept\n", rounds, (unsigned long long)n);
}

/* The journal step by step: a child dies at each step of a flush's commit (h5_journal.c). Before the
 * trailer is complete the file holds the previous flush; after it, vafm replays the journal (a reader in
 * memory, a resume on disk) and the file holds the new one. */
extern int vafm_h5i_journal_crash_at;

static void test_journal_steps(void)
{
    for (int step = 1; step <= 4; step++) {
        char path[64];
        snprintf(path, sizeof path, "t_h5_journal_%d.h5", step);
        remove(path);
        fflush(NULL);
        pid_t pid = fork();
        if (pid == 0) {
            vafm_error e = { 0 };
            vafm_h5_writer *w = NULL;
            vafm_params p;
            s_fig4(&p);
            if (vafm_h5_writer_open(&w, path, NULL, &e) || vafm_h5_writer_set_provenance(w, &p, NULL, &e))
                _exit(1);
            for (uint64_t i = 0; i < 12; i++) {
                syn s;
                syn_make(&s, 300, 0.05, i);
                if (vafm_h5_writer_append(w, &s.c, &s.truth, &e))
                    _exit(1);
                syn_free(&s);
                if (i == 10 && vafm_h5_writer_flush(w, &e))
                    _exit(1);
            }
            vafm_h5i_journal_crash_at = step; /* the next flush dies at this step */
            vafm_h5_writer_flush(w, &e);
            _exit(2);
        }
        int st = 0;
        waitpid(pid, &st, 0);
        ENSURE_MSG(WIFEXITED(st) && WEXITSTATUS(st) == 0, "step %d: child status %d", step, st);
        size_t want = step == 1 ? 11 : 12;
        vafm_error e = { 0 };
        vafm_h5_reader *r = NULL;
        int rc = vafm_h5_reader_open(&r, path, &e);
        ENSURE_MSG(rc == 0, "step %d: %s", step, e.message);
        vafm_h5_provenance pv = { 0 };
        if (!rc)
            vafm_h5_reader_provenance(r, &pv);
        ENSURE_MSG(!rc && vafm_h5_reader_count(r) >= want && pv.truth_rows == want, "step %d: %zu curves, %zu rows",
                   step, r ? vafm_h5_reader_count(r) : 0, pv.truth_rows);
        for (size_t i = 0; !rc && i < want; i++) {
            vafm_h5_curve c;
            int rr = vafm_h5_reader_curve(r, i, &c, &e);
            ENSURE_MSG(rr == 0, "step %d curve %zu: %s", step, i, e.message);
        }
        vafm_h5_reader_destroy(&r);
        vafm_h5_writer_opts o;
        vafm_h5_writer_opts_default(&o);
        o.resume = 1;
        vafm_h5_writer *w = NULL;
        rc = vafm_h5_writer_open(&w, path, &o, &e);
        ENSURE_MSG(rc == 0 && vafm_h5_writer_count(w) == want, "step %d: resume %s", step, e.message);
        ENSURE(vafm_h5_writer_close(&w, &e) == 0);
        ENSURE_MSG(vafm_h5_check(path, &e) == 0, "step %d: %s", step, e.message);
        /* after the resume the file is plain HDF5 again: HDF5's own driver reads it */
        hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
        ENSURE(f >= 0);
        hsize_t n = 0;
        if (f >= 0) {
            H5Gget_info_by_name(f, "/", &(H5G_info_t){ 0 }, H5P_DEFAULT);
            H5G_info_t gi;
            if (H5Gget_info(f, &gi) >= 0)
                n = gi.nlinks;
            H5Fclose(f);
        }
        ENSURE(n == want);
    }
}

/* A writer destroyed without close (what a crash leaves, minus the kill): the flushed curves and their
 * rows survive, the unflushed trailing curve is dropped on resume. */
static void test_resume_trailing(void)
{
    const char *path = "t_h5_trailing.h5";
    remove(path);
    vafm_error e = { 0 };
    vafm_h5_writer *w = NULL;
    vafm_params p;
    s_fig4(&p);
    ENSURE(vafm_h5_writer_open(&w, path, NULL, &e) == 0 && vafm_h5_writer_set_provenance(w, &p, NULL, &e) == 0);
    for (int i = 0; i < 3; i++) {
        syn s;
        syn_make(&s, 300, 0.05, (uint64_t)i);
        ENSURE(vafm_h5_writer_append(w, &s.c, &s.truth, &e) == 0);
        if (i == 1)
            ENSURE(vafm_h5_writer_flush(w, &e) == 0);
        syn_free(&s);
    }
    vafm_h5_writer_destroy(&w); /* curve 2 appended, its row never flushed */
    vafm_h5_reader *r = NULL;
    ENSURE(vafm_h5_reader_open(&r, path, &e) == 0);
    vafm_h5_provenance pv;
    vafm_h5_reader_provenance(r, &pv);
    ENSURE(vafm_h5_reader_count(r) == 3 && pv.truth_rows == 2);
    vafm_h5_reader_destroy(&r);
    ENSURE(vafm_h5_check(path, &e) == VAFM_EFORMAT && strstr(e.message, "[V4]")); /* row missing */
    vafm_h5_writer_opts o;
    vafm_h5_writer_opts_default(&o);
    o.resume = 1;
    ENSURE(vafm_h5_writer_open(&w, path, &o, &e) == 0);
    ENSURE(vafm_h5_writer_count(w) == 2);
    ENSURE(vafm_h5_writer_close(&w, &e) == 0);
    ENSURE_MSG(vafm_h5_check(path, &e) == 0, "%s", e.message);
    ENSURE(vafm_h5_reader_open(&r, path, &e) == 0 && vafm_h5_reader_count(r) == 2);
    vafm_h5_reader_destroy(&r);
}

/* ---- main ------------------------------------------------------------------------------------------- */

/* ---- segment lists (issue #26 §4): format 1.2, 'vafm segments', rules L12/V2/V6 ---------------------------- */

#define S_SEG4 "{\"segments\": [{\"kind\": \"pause\"}, {\"kind\": \"extend\"}, {\"kind\": \"pause\"}, {\"kind\": \"retract\"}]}"

/* A synthetic curve as a 4-segment list's: sample i in segment 4i/n (its position), 'segment count' 4. */
static void seg4_make(syn *s, size_t n, uint64_t index)
{
    syn_make(s, n, 0.05, index);
    for (size_t i = 0; i < n; i++)
        s->seg[i] = (uint8_t)(4 * i / n);
    s->c.meta.segment_count = 4;
}

/* A copy of src at dst, opened read-write with plain HDF5 for a test to damage. */
static hid_t s_copy_rw(const char *src, const char *dst)
{
    size_t n = 0;
    unsigned char *b = s_slurp(src, &n);
    s_spit(dst, b, n);
    free(b);
    hid_t f = H5Fopen(dst, H5F_ACC_RDWR, H5P_DEFAULT);
    ENSURE(f >= 0);
    return f;
}

/* The file says format version v (an older one than its content needs, for the hostile edits). */
static void s_say_version(hid_t f, const char *v)
{
    H5Adelete(f, "vafm format version");
    h_str(f, "vafm format version", v, 0);
}

/* A 4-segment list file of `count` curves (resume: continue it). @return 0 or the first error. */
static int seg4_file(const char *path, int resume, int count, const char *list, vafm_error *e)
{
    vafm_params p;
    s_fig4(&p);
    vafm_h5_writer_opts o;
    vafm_h5_writer_opts_default(&o);
    o.resume = resume;
    vafm_h5_writer *w = NULL;
    int rc = vafm_h5_writer_open(&w, path, &o, e);
    if (!rc && list)
        rc = vafm_h5_writer_set_segments(w, list, e);
    if (!rc)
        rc = vafm_h5_writer_set_provenance(w, &p, NULL, e);
    for (int i = (int)(w ? vafm_h5_writer_count(w) : 0); i < count && !rc; i++) {
        syn s;
        seg4_make(&s, 400 + 13 * (size_t)i, (uint64_t)i);
        rc = vafm_h5_writer_append(w, &s.c, &s.truth, e);
        syn_free(&s);
    }
    int rc2 = w ? vafm_h5_writer_close(&w, e) : 0;
    return rc ? rc : rc2;
}

/* Edit a copy of a list file with plain HDF5: kind 0 sets sample 7 of curve 1 to 4 (≥ the count); 1 drops the
 * list and says 1.1 (a count with no list); 2 keeps the list and says 1.1; 3 drops the list and keeps 1.2. */
static void seg4_hostile(const char *src, const char *dst, int kind)
{
    hid_t f = s_copy_rw(src, dst);
    if (kind == 0) {
        hid_t d = H5Dopen2(f, "1/segment", H5P_DEFAULT);
        uint8_t v[4000];
        hid_t sp = H5Dget_space(d);
        hssize_t np = H5Sget_simple_extent_npoints(sp);
        ENSURE(np > 7 && np <= 4000);
        H5Dread(d, H5T_NATIVE_UINT8, H5S_ALL, H5S_ALL, H5P_DEFAULT, v);
        v[7] = 4;
        ENSURE(H5Dwrite(d, H5T_NATIVE_UINT8, H5S_ALL, H5S_ALL, H5P_DEFAULT, v) >= 0);
        H5Sclose(sp);
        H5Dclose(d);
    }
    if (kind == 1 || kind == 3)
        ENSURE(H5Adelete(f, "vafm segments") >= 0);
    if (kind == 1 || kind == 2)
        s_say_version(f, "1.1");
    H5Fclose(f);
}

static void test_segment_lists(void)
{
    const char *path = "t_h5_seg4.h5", *bad = "t_h5_seg4_bad.h5";
    remove(path);
    vafm_error e = { 0 };
    int rc = seg4_file(path, 0, 2, S_SEG4, &e);
    ENSURE_MSG(rc == 0, "%s", e.message);
    /* read back bit for bit, with the list and format 1.2 */
    vafm_h5_reader *r = s_check_open(path, &e);
    if (r) {
        vafm_h5_provenance pv;
        vafm_h5_reader_provenance(r, &pv);
        ENSURE(pv.format_major == 1 && pv.format_minor == VAFM_H5_FORMAT_MINOR_SEGMENTS);
        ENSURE(s_same_str(pv.segments_json, S_SEG4) && pv.segment_count == 4);
        ENSURE(vafm_h5_reader_count(r) == 2);
        for (size_t i = 0; i < 2; i++) {
            syn s;
            seg4_make(&s, 400 + 13 * i, i);
            vafm_h5_curve c;
            rc = vafm_h5_reader_curve(r, i, &c, &e);
            ENSURE_MSG(rc == 0, "%s", e.message);
            char why[200] = "";
            ENSURE_MSG(!rc && s_curve_eq(&s.c, &c, 0, why, sizeof why), "curve %zu: %s", i, why);
            ENSURE(!rc && c.segment[0] == 0 && c.segment[c.n - 1] == 3 && c.meta.segment_count == 4);
            syn_free(&s);
        }
        vafm_h5_reader_destroy(&r);
    }
    /* resume: the same list continues it, another or none is refused */
    ENSURE(vafm_h5_resume_check_segments(path, &(vafm_params){ 0 }, NULL, "{\"segments\": [{}]}", &e) != 0);
    rc = seg4_file(path, 1, 3, "{\"segments\": [{\"kind\": \"pause\"}]}", &e);
    ENSURE_MSG(rc == VAFM_EINVAL && strstr(e.message, "differs from the file's"), "%d %s", rc, e.message);
    rc = seg4_file(path, 1, 3, NULL, &e);
    ENSURE_MSG(rc == VAFM_EINVAL && strstr(e.message, "holds a segment list"), "%d %s", rc, e.message);
    rc = seg4_file(path, 1, 3, S_SEG4, &e);
    ENSURE_MSG(rc == 0, "%s", e.message);
    rc = vafm_h5_check(path, &e);
    ENSURE_MSG(rc == 0, "conformance after resume: %s", e.message);
    rc = vafm_h5_reader_open(&r, path, &e);
    ENSURE(rc == 0 && vafm_h5_reader_count(r) == 3);
    vafm_h5_reader_destroy(&r);
    /* the writer refuses a value ≥ the count, another count, a count ≠ 2 without a list, a bad list */
    {
        vafm_params p;
        s_fig4(&p);
        for (int k = 0; k < 4; k++) {
            const char *f = "t_h5_seg4_w.h5";
            remove(f);
            vafm_h5_writer *w = NULL;
            ENSURE(vafm_h5_writer_open(&w, f, NULL, &e) == 0);
            if (k < 2)
                ENSURE(vafm_h5_writer_set_segments(w, S_SEG4, &e) == 0);
            if (k == 3) {
                rc = vafm_h5_writer_set_segments(w, "{\"segments\": []}", &e);
                ENSURE_MSG(rc == VAFM_EINVAL && strstr(e.message, "1 to 255"), "%d %s", rc, e.message);
            }
            ENSURE(vafm_h5_writer_set_provenance(w, &p, NULL, &e) == 0);
            syn s;
            seg4_make(&s, 400, 0);
            if (k == 0)
                s.seg[9] = 4;
            if (k == 1)
                s.c.meta.segment_count = 3;
            rc = vafm_h5_writer_append(w, &s.c, &s.truth, &e);
            ENSURE_MSG(rc == VAFM_EINVAL && strstr(e.message, k == 0 ? "below 'segment count'" : "'segment count'"),
                       "case %d: %d %s", k, rc, e.message);
            syn_free(&s);
            vafm_h5_writer_destroy(&w);
        }
    }
    /* hostile files: the checker names the rule, the reader refuses a value ≥ the count */
    static const char *const rule[] = { "[L12]", "[V2]", "[V6]", "[V6]" };
    for (int k = 0; k < 4; k++) {
        seg4_hostile(path, bad, k);
        rc = vafm_h5_check(bad, &e);
        ENSURE_MSG(rc == VAFM_EFORMAT && strstr(e.message, rule[k]), "case %d: %d %s", k, rc, e.message);
        if (k == 0) {
            ENSURE(vafm_h5_reader_open(&r, bad, &e) == 0);
            vafm_h5_curve c;
            rc = vafm_h5_reader_curve(r, 1, &c, &e);
            ENSURE_MSG(rc == VAFM_EFORMAT && strstr(e.message, "below 'segment count'"), "%d %s", rc, e.message);
            vafm_h5_reader_destroy(&r);
        }
    }
    /* a file without a list stays 1.1, count 2 */
    remove("t_h5_seg0.h5");
    rc = syn_file("t_h5_seg0.h5", NULL, 1, &e);
    ENSURE(rc == 0 && vafm_h5_reader_open(&r, "t_h5_seg0.h5", &e) == 0);
    vafm_h5_provenance pv;
    vafm_h5_reader_provenance(r, &pv);
    ENSURE(pv.format_minor == VAFM_H5_FORMAT_MINOR && !pv.segments_json && pv.segment_count == 0);
    vafm_h5_reader_destroy(&r);
}

/* ---- curves with their own segment lists (issue #26, log): format 1.3, 'vafm segments <i>', rule V7 ---------- */

#define S_SEG3 "{\"segments\": [{\"kind\": \"extend\"}, {\"kind\": \"pause\"}, {\"kind\": \"retract\"}]}"

/* Curve i of the mixed file: 0 and 3 plain (segment count 2), 1 a 4-segment list's, 2 a 3-segment list's. */
static void cseg_make(syn *s, size_t i)
{
    size_t n = 400 + 13 * i;
    if (i == 1) {
        seg4_make(s, n, i);
        return;
    }
    syn_make(s, n, 0.05, i);
    if (i == 2) {
        for (size_t j = 0; j < n; j++)
            s->seg[j] = (uint8_t)(3 * j / n);
        s->c.meta.segment_count = 3;
    }
}

static const char *cseg_list(size_t i)
{
    return i == 1 ? S_SEG4 : i == 2 ? S_SEG3 : NULL;
}

/* Curves [from, to) of the mixed file, into a new file or a resumed one; flush: 0 leaves the last curve unflushed
 * and the writer destroyed (what a kill leaves). @return 0 or the first error. */
static int cseg_file(const char *path, int resume, size_t to, int flush, vafm_error *e)
{
    vafm_params p;
    s_fig4(&p);
    vafm_h5_writer_opts o;
    vafm_h5_writer_opts_default(&o);
    o.resume = resume;
    o.keep_intact = 1;
    vafm_h5_writer *w = NULL;
    int rc = vafm_h5_writer_open(&w, path, &o, e);
    if (!rc)
        rc = vafm_h5_writer_set_provenance(w, &p, NULL, e);
    for (size_t i = w ? (size_t)vafm_h5_writer_count(w) : 0; i < to && !rc; i++) {
        syn s;
        cseg_make(&s, i);
        if (cseg_list(i))
            rc = vafm_h5_writer_set_curve_segments(w, cseg_list(i), e);
        if (!rc)
            rc = vafm_h5_writer_append(w, &s.c, &s.truth, e);
        if (!rc && (flush || i + 1 < to))
            rc = vafm_h5_writer_flush(w, e);
        syn_free(&s);
    }
    if (!flush) {
        vafm_h5_writer_destroy(&w);
        return rc;
    }
    int rc2 = w ? vafm_h5_writer_close(&w, e) : 0;
    return rc ? rc : rc2;
}

/* The curves and their lists read back (count curves of the mixed file, bit for bit). */
static void cseg_read_back(const char *path, size_t count)
{
    vafm_error e = { 0 };
    vafm_h5_reader *r = NULL;
    int rc = vafm_h5_reader_open(&r, path, &e);
    ENSURE_MSG(rc == 0, "%s", e.message);
    if (rc)
        return;
    vafm_h5_provenance pv;
    vafm_h5_reader_provenance(r, &pv);
    ENSURE(pv.format_minor == VAFM_H5_FORMAT_MINOR_CURVE_SEGMENTS && !pv.segments_json && pv.segment_count == 0);
    ENSURE(vafm_h5_reader_count(r) == count);
    for (size_t i = 0; i < count && i < vafm_h5_reader_count(r); i++) {
        const char *list = "unset";
        rc = vafm_h5_reader_curve_segments(r, i, &list, &e);
        ENSURE_MSG(rc == 0 && s_same_str(list, cseg_list(i)), "curve %zu: %d %s", i, rc, list ? list : "(none)");
        syn s;
        cseg_make(&s, i);
        vafm_h5_curve c;
        rc = vafm_h5_reader_curve(r, i, &c, &e);
        char why[200] = "";
        ENSURE_MSG(rc == 0 && s_curve_eq(&s.c, &c, 0, why, sizeof why), "curve %zu: %s %s", i, e.message, why);
        ENSURE(rc || c.meta.segment_count == (i == 1 ? 4 : i == 2 ? 3 : 2));
        syn_free(&s);
    }
    vafm_h5_reader_destroy(&r);
}

/* Edit a copy of the mixed file with plain HDF5: 0 deletes curve 1's list (a count of 4 without one), 1 adds a
 * list for a curve that is not there, 2 says 1.1, 3 gives curve 2 a 4-segment list (its count is 3). */
static void cseg_hostile(const char *src, const char *dst, int kind)
{
    hid_t f = s_copy_rw(src, dst);
    if (kind == 0)
        ENSURE(H5Adelete(f, "vafm segments 1") >= 0);
    if (kind == 1)
        h_str(f, "vafm segments 9", S_SEG3, 0);
    if (kind == 2)
        s_say_version(f, "1.1");
    if (kind == 3) {
        H5Adelete(f, "vafm segments 2");
        h_str(f, "vafm segments 2", S_SEG4, 0);
    }
    H5Fclose(f);
}

static void test_curve_segment_lists(void)
{
    const char *path = "t_h5_cseg.h5", *bad = "t_h5_cseg_bad.h5";
    remove(path);
    vafm_error e = { 0 };
    /* plain, 4-segment, 3-segment, plain: format 1.3, each list read back with its curve */
    int rc = cseg_file(path, 0, 4, 1, &e);
    ENSURE_MSG(rc == 0, "%s", e.message);
    rc = vafm_h5_check(path, &e);
    ENSURE_MSG(rc == 0, "conformance: %s", e.message);
    cseg_read_back(path, 4);
    /* a kill after curve 2's append: resume keeps 0 and 1 and drops curve 2 with its list, then appends it */
    remove(path);
    rc = cseg_file(path, 0, 3, 0, &e);
    ENSURE_MSG(rc == 0, "%s", e.message);
    rc = cseg_file(path, 1, 2, 1, &e);
    ENSURE_MSG(rc == 0, "%s", e.message);
    hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    ENSURE(f >= 0 && H5Aexists(f, "vafm segments 1") > 0 && H5Aexists(f, "vafm segments 2") == 0);
    H5Fclose(f);
    rc = vafm_h5_check(path, &e);
    ENSURE_MSG(rc == 0, "conformance after resume: %s", e.message);
    cseg_read_back(path, 2);
    rc = cseg_file(path, 1, 4, 1, &e);
    ENSURE_MSG(rc == 0 && vafm_h5_check(path, &e) == 0, "%s", e.message);
    cseg_read_back(path, 4);
    /* the writer refuses a count other than the curve's list's, a value ≥ it, a bad list, a list in a 1.2 file */
    {
        vafm_params p;
        s_fig4(&p);
        for (int k = 0; k < 4; k++) {
            const char *wf = "t_h5_cseg_w.h5";
            remove(wf);
            vafm_h5_writer *w = NULL;
            ENSURE(vafm_h5_writer_open(&w, wf, NULL, &e) == 0);
            if (k == 3)
                ENSURE(vafm_h5_writer_set_segments(w, S_SEG4, &e) == 0);
            ENSURE(vafm_h5_writer_set_provenance(w, &p, NULL, &e) == 0);
            rc = vafm_h5_writer_set_curve_segments(w, k == 2 ? "{\"segments\": []}" : S_SEG4, &e);
            if (k >= 2) {
                ENSURE_MSG(rc == (k == 2 ? VAFM_EINVAL : VAFM_ESTATE), "case %d: %d %s", k, rc, e.message);
                vafm_h5_writer_destroy(&w);
                continue;
            }
            ENSURE(rc == 0);
            syn s;
            seg4_make(&s, 400, 0);
            if (k == 0)
                s.c.meta.segment_count = 2;
            if (k == 1)
                s.seg[9] = 4;
            rc = vafm_h5_writer_append(w, &s.c, &s.truth, &e);
            ENSURE_MSG(rc == VAFM_EINVAL && strstr(e.message, k == 0 ? "the curve's segment list has 4" : "below"),
                       "case %d: %d %s", k, rc, e.message);
            /* the list was for that append only: the next curve is a plain one */
            syn_free(&s);
            syn_make(&s, 300, 0.05, 0);
            rc = vafm_h5_writer_append(w, &s.c, &s.truth, &e);
            ENSURE_MSG(rc == 0, "case %d: %s", k, e.message);
            syn_free(&s);
            ENSURE(vafm_h5_writer_close(&w, &e) == 0);
            ENSURE_MSG(vafm_h5_check(wf, &e) == 0, "case %d: a file of plain curves: %s", k, e.message);
            vafm_h5_reader *r = NULL;
            ENSURE(vafm_h5_reader_open(&r, wf, &e) == 0);
            vafm_h5_provenance pv;
            vafm_h5_reader_provenance(r, &pv);
            ENSURE_MSG(pv.format_minor == VAFM_H5_FORMAT_MINOR, "case %d: format 1.%d", k, pv.format_minor);
            vafm_h5_reader_destroy(&r);
        }
    }
    /* hostile files: the checker names the rule */
    static const char *const rule[] = { "[V2]", "[V7]", "[V7]", "[V7]" };
    rc = cseg_file(path, 1, 4, 1, &e);
    for (int k = 0; k < 4; k++) {
        cseg_hostile(path, bad, k);
        rc = vafm_h5_check(bad, &e);
        ENSURE_MSG(rc == VAFM_EFORMAT && strstr(e.message, rule[k]), "case %d: %d %s", k, rc, e.message);
    }
}

static int make_files(const char *dir)
{
    char a[512], b[512];
    snprintf(a, sizeof a, "%s/vafm.h5", dir);
    snprintf(b, sizeof b, "%s/reference.h5", dir);
    remove(a);
    vafm_error e = { 0 };
    vafm_h5_writer_opts o;
    vafm_h5_writer_opts_default(&o);
    o.gzip_level = 4;
    if (syn_file(a, &o, 4, &e)) {
        fprintf(stderr, "%s\n", e.message);
        return 1;
    }
    write_reference(b, 0);
    return vafm_h5_check(a, &e) || vafm_h5_check(b, &e);
}

int main(int argc, char **argv)
{
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL); /* the hand-made damage makes HDF5 complain */
    if (argc == 3 && !strcmp(argv[1], "--make-files"))
        return make_files(argv[2]);
    if (argc == 5 && !strcmp(argv[1], "--fuzz")) {
        /* diagnosis: --fuzz FILE TRIALS SEED damages a copy of FILE TRIALS times */
        s_rng = strtoull(argv[4], NULL, 0) | 1;
        dmg_file(argv[2], atoi(argv[3]));
        return harness_done();
    }
    const char *only = argc == 3 && !strcmp(argv[1], "--only") ? argv[2] : NULL; /* --only NAME: one test */
#define S_RUN(fn)                                  \
    if (!only || !strcmp(only, #fn))               \
        RUN_TEST(fn)
    S_RUN(test_roundtrip_synthetic);
    S_RUN(test_reference_file);
    S_RUN(test_bad_files);
    S_RUN(test_writer_refusals);
    S_RUN(test_resume_trailing);
    S_RUN(test_segment_lists);
    S_RUN(test_curve_segment_lists);
    S_RUN(test_journal_steps);
    S_RUN(test_campaign_roundtrip);
    S_RUN(test_damaged_files);
    S_RUN(test_kill_resume);
    S_RUN(test_kill_during_flush);
    return harness_done();
}
