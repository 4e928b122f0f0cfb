/* SPDX-License-Identifier: MIT */
/* `vafm run` (one curve, a readable summary) and `vafm samples` (one curve or tune as CSV). */
#include "cli/cli.h"
#include "vafm/detector.h"
#include "vafm/segments.h"
#include "record/record.h"

/* ---- vafm run ------------------------------------------------------------------------------------ */

static int s_index_arg(const vafm_cli_args *a, uint64_t *index)
{
    *index = 0;
    return a->val[O_INDEX] ? vafm_cli_parse_u64("--index", a->val[O_INDEX], 0, UINT64_MAX, index) : 0;
}

/* Begin curve `index`, or with --segments the file's list. @return 0, a VAFM_E* code of the simulation, or
 * VAFM_CLI_EXIT_USAGE + 1000 when the file is unreadable or refused (reported). */
static int s_begin_run(const vafm_cli_args *a, vafm_sim *sim, uint64_t index)
{
    if (!a->val[O_SEGMENTS])
        return vafm_sim_curve_begin(sim, index);
    vafm_segment_spec segs[VAFM_SEGMENTS_MAX];
    size_t n = 0;
    vafm_error err;
    int r = vafm_segments_load_file(a->val[O_SEGMENTS], segs, VAFM_SEGMENTS_MAX, &n, &err);
    int invalid = !r && (r = vafm_segments_validate(segs, n, vafm_sim_params(sim), &err)) != 0;
    if (r) {
        vafm_cli_error("%s%s%s", invalid ? a->val[O_SEGMENTS] : "", invalid ? ": " : "", err.message);
        return 1000 + VAFM_CLI_EXIT_USAGE;
    }
    return vafm_sim_segments_begin(sim, index, segs, n);
}

/* The scene, the --index and a simulation for it: the common start of vafm run and vafm samples. */
static int s_open_sim(const vafm_cli_args *a, vafm_cli_scene *sc, uint64_t *index, vafm_sim **sim)
{
    /* a tune runs no force curve: it is checked at its own rate (tune_rate_Hz) against its own limits
     * (tune_duration_s) by vafm_sim_new_tune, not against a curve's at either rate */
    int rc = vafm_cli_resolve_scene(a, sc, !a->on[O_TUNE]);
    if (rc || (rc = s_index_arg(a, index)) != 0)
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
    vafm_cli_scene sc;
    uint64_t index;
    vafm_sim *sim = NULL;
    int rc = s_open_sim(a, &sc, &index, &sim);
    if (rc)
        return rc;
    vafm_cli_print_provenance(stdout, &sc);
    vafm_cli_print_scene_si(stdout, &sc.p);
    vafm_cli_print_scene_reduced(stdout, &sc.p, vafm_sim_dt(sim));
    fflush(stdout);
    vafm_cli_progress pg;
    vafm_cli_progress_init(&pg, a);
    if (a->on[O_TUNE] && a->val[O_SEGMENTS]) {
        vafm_cli_error("--segments and --tune exclude each other");
        vafm_sim_destroy(&sim);
        return VAFM_CLI_EXIT_USAGE;
    }
    int r = s_begin_run(a, sim, index);
    if (r >= 1000) {
        vafm_sim_destroy(&sim);
        return r - 1000;
    }
    if (!r)
        r = vafm_cli_advance_all(sim, NULL, NULL, &pg);
    double wall = vafm_cli_now() - pg.t0;
    vafm_curve_result res;
    vafm_sim_result(sim, &res);
    if (r) {
        const vafm_error *e = vafm_sim_error(sim);
        vafm_cli_error("curve %" PRIu64 " failed after %.6g s simulated: %s", index, res.duration_s,
                e ? e->message : vafm_strerror(r));
        vafm_sim_destroy(&sim);
        return VAFM_CLI_EXIT_RUNTIME;
    }
    vafm_sim_destroy(&sim);
    vafm_cli_print_run_result(stdout, &sc.p, &res, wall);
    return VAFM_CLI_EXIT_OK;
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
        double defl = b->deflection_m[i], force = b->force_N[i];
        if (o->det.on)
            vafm_detector_apply(&o->det, b->time_s[i], b->height_m[i], b->deflection_m[i], NULL, &defl, &force);
        if (fprintf(o->f, "%.17g,%.17g,%.17g,%.17g,%.17g,%u", b->time_s[i], b->height_m[i], defl, force,
                    b->tip_m[i], (unsigned)b->segment[i]) < 0)
            return 1; /* stop: the output is broken */
        if (o->hm) {
            double h = b->height_measured_m ? b->height_measured_m[i] : b->height_m[i];
            if (fprintf(o->f, ",%.17g", vafm_detector_height(&o->det, b->time_s[i], h)) < 0)
                return 1;
        }
        if (fputc('\n', o->f) == EOF)
            return 1;
    }
    return 0;
}

int vafm_cli_cmd_samples(const vafm_cli_args *a)
{
    vafm_cli_scene sc;
    uint64_t index;
    vafm_sim *sim = NULL;
    int rc = s_open_sim(a, &sc, &index, &sim);
    if (rc)
        return rc;
    FILE *f = vafm_cli_open_out(a->val[O_CSV]);
    if (!f) {
        vafm_sim_destroy(&sim);
        return VAFM_CLI_EXIT_RUNTIME;
    }
    vafm_cli_progress pg;
    vafm_cli_progress_init(&pg, a);
    if (a->on[O_TUNE] && a->val[O_SEGMENTS]) {
        vafm_cli_error("--segments and --tune exclude each other");
        vafm_cli_close_out(f, a->val[O_CSV], 1);
        vafm_sim_destroy(&sim);
        return VAFM_CLI_EXIT_USAGE;
    }
    int r = a->on[O_TUNE] ? vafm_sim_tune_begin(sim, index) : s_begin_run(a, sim, index);
    if (r >= 1000) {
        vafm_cli_close_out(f, a->val[O_CSV], 1);
        vafm_sim_destroy(&sim);
        return r - 1000;
    }
    int began = r == 0; /* a scene refused at the start (a tune too long) is a parameter error */
    s_out o = { .f = f };
    o.hm = vafm_detector_height_differs(&sc.p);
    fputs(o.hm ? "time_s,height_m,deflection_m,force_N,tip_m,segment,height_measured_m\n"
               : "time_s,height_m,deflection_m,force_N,tip_m,segment\n", f);
    vafm_detector_begin(&o.det, &sc.p, index);
    if (!r)
        r = vafm_cli_advance_all(sim, s_write_samples, &o, &pg);
    rc = vafm_cli_close_out(f, a->val[O_CSV], r == VAFM_EABORT);
    if (r && r != VAFM_EABORT) {
        const vafm_error *e = vafm_sim_error(sim);
        vafm_cli_error("%s %" PRIu64 " failed: %s", a->on[O_TUNE] ? "tune" : "curve", index,
                e && e->message[0] ? e->message : vafm_strerror(r));
        vafm_sim_destroy(&sim);
        return began ? VAFM_CLI_EXIT_RUNTIME : vafm_cli_exit_of(r);
    }
    vafm_sim_destroy(&sim);
    return rc;
}
