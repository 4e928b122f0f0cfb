/* SPDX-License-Identifier: MIT */
/* `vafm run` (one curve, a readable summary) and `vafm samples` (one curve or tune as CSV). */
#include "cli/cli.h"
#include "core/channels.h"
#include "vafm/detector.h"
#include "vafm/segments.h"
#include "record/record.h"

/* ---- vafm run ------------------------------------------------------------------------------------ */

static int s_index_arg(const vafm_cli_args *a, uint64_t *index)
{
    *index = 0;
    return a->val[O_INDEX] ? vafm_cli_parse_u64("--index", a->val[O_INDEX], 0, UINT64_MAX, index) : 0;
}

/* Begin curve `index`, or with --segments the file's list (into segs, *n; *n = 0 without). @return 0, a VAFM_E*
 * code of the simulation, or VAFM_CLI_EXIT_USAGE + 1000 when the file is unreadable or refused (reported). */
static int s_begin_run(const vafm_cli_args *a, vafm_sim *sim, uint64_t index, vafm_segment_spec *segs, size_t *n)
{
    *n = 0;
    if (!a->val[O_SEGMENTS])
        return vafm_sim_curve_begin(sim, index);
    vafm_error err;
    int r = vafm_segments_load_file(a->val[O_SEGMENTS], segs, VAFM_SEGMENTS_MAX, n, &err);
    int invalid = !r && (r = vafm_segments_validate(segs, *n, vafm_sim_params(sim), &err)) != 0;
    if (r) {
        vafm_cli_error("%s%s%s", invalid ? a->val[O_SEGMENTS] : "", invalid ? ": " : "", err.message);
        return 1000 + VAFM_CLI_EXIT_USAGE;
    }
    return vafm_sim_segments_begin(sim, index, segs, *n);
}

/* A run's samples, gathered for `vafm run --out` (at most VAFM_H5_MAX_SAMPLES). */
typedef struct s_gather {
    size_t n, cap;
    double *t, *h, *d, *f, *tip, *hm;
    uint8_t *seg;
    int hm_on, full; /* height_measured_m given; the run outgrew VAFM_H5_MAX_SAMPLES or memory */
} s_gather;

static void s_gather_free(s_gather *g)
{
    free(g->t), free(g->h), free(g->d), free(g->f), free(g->tip), free(g->hm), free(g->seg);
}

static int s_gather_fn(void *user, const vafm_samples *b)
{
    s_gather *g = user;
    if (b->n > VAFM_H5_MAX_SAMPLES - g->n)
        return g->full = 1;
    if (g->n + b->n > g->cap) {
        size_t cap = g->cap ? g->cap : 4096;
        while (cap < g->n + b->n)
            cap *= 2;
        if (cap > VAFM_H5_MAX_SAMPLES)
            cap = VAFM_H5_MAX_SAMPLES;
        double **arr[] = { &g->t, &g->h, &g->d, &g->f, &g->tip, &g->hm };
        for (size_t k = 0; k < sizeof arr / sizeof arr[0]; k++) {
            double *q = realloc(*arr[k], cap * sizeof *q);
            if (!q)
                return g->full = 2;
            *arr[k] = q;
        }
        uint8_t *q = realloc(g->seg, cap);
        if (!q)
            return g->full = 2;
        g->seg = q;
        g->cap = cap;
    }
    size_t m = b->n * sizeof(double);
    memcpy(g->t + g->n, b->time_s, m);
    memcpy(g->h + g->n, b->height_m, m);
    memcpy(g->d + g->n, b->deflection_m, m);
    memcpy(g->f + g->n, b->force_N, m);
    memcpy(g->tip + g->n, b->tip_m, m);
    memcpy(g->hm + g->n, b->height_measured_m ? b->height_measured_m : b->height_m, m);
    memcpy(g->seg + g->n, b->segment, b->n);
    g->hm_on |= b->height_measured_m != NULL;
    g->n += b->n;
    return 0;
}

/* `vafm run --out FILE.h5`: the run as a one-curve file (protocol/hdf5.md; a segment list: format 1.2 with
 * "vafm segments"), through the scene's measured chain as vafm campaign records it. @return an exit code. */
static int s_write_run(const vafm_cli_args *a, const vafm_params *p, s_gather *g, const vafm_curve_result *res,
                       uint64_t index, const vafm_segment_spec *segs, size_t nseg)
{
    vafm_samples s = { .n = g->n, .time_s = g->t, .height_m = g->h, .deflection_m = g->d, .force_N = g->f,
                       .tip_m = g->tip, .segment = g->seg, .height_measured_m = g->hm_on ? g->hm : NULL };
    vafm_record_curve rc = { .samples = &s, .params = p, .result = res, .sensitivity_m_per_V = p->sensitivity_m_per_V };
    if (vafm_detector_on(p)) { /* the instrument's force and deflection (and z sensor), as vafm campaign */
        vafm_detector det;
        vafm_detector_begin(&det, p, index);
        for (size_t i = 0; i < g->n; i++)
            vafm_detector_apply(&det, g->t[i], g->h[i], g->d[i], NULL, &g->d[i], &g->f[i]);
        if (det.zs_on) {
            for (size_t i = 0; i < g->n; i++)
                g->hm[i] = vafm_detector_height(&det, g->t[i], g->hm[i]);
            s.height_measured_m = g->hm;
        }
        rc.measured_force = 1;
    }
    vafm_recorder_opts ro;
    vafm_recorder_opts_default(&ro);
    ro.mode = a->on[O_OVERWRITE] ? VAFM_RECORD_OVERWRITE : VAFM_RECORD_CREATE;
    char *json = nseg ? vafm_segments_to_json(segs, nseg) : NULL;
    vafm_error err;
    memset(&err, 0, sizeof err);
    if (nseg && !json) {
        vafm_cli_error("%s: the segment list cannot be written as JSON (out of memory)", a->val[O_OUT]);
        return VAFM_CLI_EXIT_RUNTIME;
    }
    ro.segments_json = json;
    vafm_recorder *rec = NULL;
    int r = vafm_recorder_open(&rec, a->val[O_OUT], &ro, p, NULL, &err);
    free(json);
    if (!r)
        r = vafm_recorder_append(rec, &rc, &err);
    vafm_error ce;
    memset(&ce, 0, sizeof ce);
    int cr = rec ? vafm_recorder_close(&rec, NULL, &ce) : 0;
    if (r)
        return vafm_cli_report(&err, r);
    if (cr)
        return vafm_cli_report(&ce, cr);
    printf("file         %s: 1 curve, %zu samples%s\n", a->val[O_OUT], g->n,
           nseg ? " (segment list: format 1.2, 'vafm segments')" : "");
    return VAFM_CLI_EXIT_OK;
}

/* The common start of vafm run and vafm samples: the scene, the --index and a simulation for it. */
typedef struct s_start {
    vafm_cli_scene sc;
    uint64_t index;
    vafm_sim *sim;
} s_start;

/* Fill st (st->sim NULL on an error). @return 0 or the exit status, reported. */
static int s_open_sim(const vafm_cli_args *a, s_start *st)
{
    vafm_cli_scene *sc = &st->sc;
    vafm_sim **sim = &st->sim;
    *sim = NULL;
    /* a tune runs no force curve: it is checked at its own rate (tune_rate_Hz) against its own limits
     * (tune_duration_s) by vafm_sim_new_tune, not against a curve's at either rate */
    int rc = vafm_cli_resolve_scene(a, sc, !a->on[O_TUNE]);
    if (rc || (rc = s_index_arg(a, &st->index)) != 0)
        return rc;
    if (!a->on[O_TUNE])
        return vafm_cli_new_sim(&sc->p, sim);
    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = vafm_sim_new_tune(sim, &sc->p, &err);
    if (r)
        return vafm_cli_report(&err, r);
    sc->p = *vafm_sim_params(*sim); /* the tune's scene, at the tune's sample rate (the detector's too) */
    return 0;
}

int vafm_cli_cmd_run(const vafm_cli_args *a)
{
    s_start st;
    int rc = s_open_sim(a, &st);
    if (rc)
        return rc;
    vafm_cli_print_provenance(stdout, &st.sc);
    vafm_cli_print_scene_si(stdout, &st.sc.p);
    vafm_cli_print_scene_reduced(stdout, &st.sc.p, vafm_sim_dt(st.sim));
    fflush(stdout);
    vafm_cli_progress pg;
    vafm_cli_progress_init(&pg, a);
    if (a->on[O_TUNE] && a->val[O_SEGMENTS]) {
        vafm_cli_error("--segments and --tune exclude each other");
        vafm_sim_destroy(&st.sim);
        return VAFM_CLI_EXIT_USAGE;
    }
    vafm_segment_spec segs[VAFM_SEGMENTS_MAX];
    size_t nseg = 0;
    int r = s_begin_run(a, st.sim, st.index, segs, &nseg);
    if (r >= 1000) {
        vafm_sim_destroy(&st.sim);
        return r - 1000;
    }
    s_gather g = { 0 };
    if (!r)
        r = vafm_cli_advance_all(st.sim, a->val[O_OUT] ? s_gather_fn : NULL, &g, &pg);
    if (r == VAFM_EABORT && g.full) {
        vafm_cli_error("%s: the run %s", a->val[O_OUT],
                       g.full == 1 ? "has more samples than a file's curve may hold (VAFM_H5_MAX_SAMPLES, 2^25)"
                                   : "does not fit in memory");
        s_gather_free(&g);
        vafm_sim_destroy(&st.sim);
        return VAFM_CLI_EXIT_RUNTIME;
    }
    double wall = vafm_cli_now() - pg.t0;
    vafm_curve_result res;
    vafm_sim_result(st.sim, &res);
    if (r) {
        const vafm_error *e = vafm_sim_error(st.sim);
        vafm_cli_error("curve %" PRIu64 " failed after %.6g s simulated: %s", st.index, res.duration_s,
                e ? e->message : vafm_strerror(r));
        s_gather_free(&g);
        vafm_sim_destroy(&st.sim);
        return VAFM_CLI_EXIT_RUNTIME;
    }
    vafm_sim_destroy(&st.sim);
    vafm_cli_print_run_result(stdout, &st.sc.p, &res, wall);
    rc = a->val[O_OUT] ? s_write_run(a, &st.sc.p, &g, &res, st.index, segs, nseg) : VAFM_CLI_EXIT_OK;
    s_gather_free(&g);
    return rc;
}

/* ---- vafm samples ------------------------------------------------------------------------------ */

typedef struct s_out {
    FILE *f;
    vafm_detector det; /* the scene's measured chain: deflection and force as the instrument records them */
    int hm;            /* a 7th column: the measured height (piezo hysteresis/creep or a z sensor) */
} s_out;

static int s_write_samples(void *user, const vafm_samples *b)
{
    s_out *o = user;
    for (size_t i = 0; i < b->n; i++) {
        double defl, force, hm;
        vafm_detector_sample(&o->det, b, i, NULL, &defl, &force, o->hm ? &hm : NULL);
        if (fprintf(o->f, "%.17g,%.17g,%.17g,%.17g,%.17g,%u", b->time_s[i], b->height_m[i], defl, force,
                    b->tip_m[i], (unsigned)b->segment[i]) < 0)
            return 1; /* stop: the output is broken */
        if (o->hm && fprintf(o->f, ",%.17g", hm) < 0)
            return 1;
        if (fputc('\n', o->f) == EOF)
            return 1;
    }
    return 0;
}

int vafm_cli_cmd_samples(const vafm_cli_args *a)
{
    s_start st;
    int rc = s_open_sim(a, &st);
    if (rc)
        return rc;
    FILE *f = vafm_cli_open_out(a->val[O_CSV]);
    if (!f) {
        vafm_sim_destroy(&st.sim);
        return VAFM_CLI_EXIT_RUNTIME;
    }
    vafm_cli_progress pg;
    vafm_cli_progress_init(&pg, a);
    if (a->on[O_TUNE] && a->val[O_SEGMENTS]) {
        vafm_cli_error("--segments and --tune exclude each other");
        vafm_cli_close_out(f, a->val[O_CSV], 1);
        vafm_sim_destroy(&st.sim);
        return VAFM_CLI_EXIT_USAGE;
    }
    vafm_segment_spec segs[VAFM_SEGMENTS_MAX];
    size_t nseg = 0;
    int r = a->on[O_TUNE] ? vafm_sim_tune_begin(st.sim, st.index) : s_begin_run(a, st.sim, st.index, segs, &nseg);
    if (r >= 1000) {
        vafm_cli_close_out(f, a->val[O_CSV], 1);
        vafm_sim_destroy(&st.sim);
        return r - 1000;
    }
    int began = r == 0; /* a scene refused at the start (a tune too long) is a parameter error */
    s_out o = { .f = f };
    o.hm = vafm_detector_height_differs(&st.sc.p);
    /* the columns of core/channels.h up to the segment, and the measured height's after it */
    vafm_channels_csv_head(f, o.hm ? vafm_channels[VAFM_CH_HEIGHT_MEASURED].csv : VAFM_CH_SEGMENT_CSV);
    fputc('\n', f);
    vafm_detector_begin(&o.det, &st.sc.p, st.index);
    if (!r)
        r = vafm_cli_advance_all(st.sim, s_write_samples, &o, &pg);
    rc = vafm_cli_close_out(f, a->val[O_CSV], r == VAFM_EABORT);
    if (r && r != VAFM_EABORT) {
        const vafm_error *e = vafm_sim_error(st.sim);
        vafm_cli_error("%s %" PRIu64 " failed: %s", a->on[O_TUNE] ? "tune" : "curve", st.index,
                e && e->message[0] ? e->message : vafm_strerror(r));
        vafm_sim_destroy(&st.sim);
        return began ? VAFM_CLI_EXIT_RUNTIME : vafm_cli_exit_of(r);
    }
    vafm_sim_destroy(&st.sim);
    return rc;
}
