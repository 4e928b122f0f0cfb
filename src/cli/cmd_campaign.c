/* SPDX-License-Identifier: MIT */
/* `vafm curves` (N curves per grid point: statistics, CSV) and `vafm campaign` (the same into one HDF5 file, resumable, on MPI too). */
#include "cli/cli.h"
#include "vafm/detector.h"

/* ---- vafm curves: the campaign ----------------------------------------------------------------- */

typedef struct s_curves {
    FILE *csv;
    vafm_point_stats *stats;
    vafm_cli_progress pg;
    uint64_t done, total;
    int fail_status, io_error;
    uint64_t fail_index;
} s_curves;

static int s_csv_row(FILE *f, const vafm_campaign_curve *c)
{
    const vafm_curve_result *r = &c->result;
    const vafm_params *p = c->params;
    return fprintf(f,
                   "%" PRIu64 ",%zu,%.17g,%.17g,%.17g,%d,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,"
                   "%" PRIu64 ",%" PRIu64 ",%" PRIu64 ",%" PRIu64 ",%.17g\n",
                   c->index, c->point, p->T_K, p->v_retract_m_per_s, p->k_N_per_m, r->flags, r->pulloff_sampled_N,
                   r->pulloff_spring_N, r->detach_force_N, r->detach_height_m, r->detach_eq_force_N,
                   r->detach_time_s, r->touch_time_s, r->touch_height_m, r->retract_start_s, r->samples, r->steps,
                   r->steps_contact, r->steps_free, r->duration_s);
}

static const char s_csv_header[] =
    "index,point,T_K,v_m_per_s,k_N_per_m,flags,pulloff_sampled_N,pulloff_spring_N,detach_force_N,"
    "detach_height_m,detach_eq_force_N,detach_time_s,touch_time_s,touch_height_m,retract_start_s,samples,"
    "steps,steps_contact,steps_free,duration_s\n";

static void s_curves_progress(s_curves *cv)
{
    vafm_cli_progress_curves(&cv->pg, cv->done, cv->total);
}

/* Called in index order, one at a time. A failed curve stops the campaign: it is a runtime error. */
static int s_on_curve(void *user, const vafm_campaign_curve *c)
{
    s_curves *cv = user;
    if (c->status) {
        cv->fail_status = c->status;
        cv->fail_index = c->index;
        return 1;
    }
    if (cv->csv && s_csv_row(cv->csv, c) < 0) {
        cv->io_error = 1;
        return 1;
    }
    vafm_point_stats_add(&cv->stats[c->point], 0, &c->result);
    cv->done++;
    s_curves_progress(cv);
    return 0;
}

typedef struct s_grid {
    vafm_campaign_spec spec;
    double *list[VAFM_CAMPAIGN_NAXES]; /* --T, --v, --k: the grid's axes, in the table's order */
} s_grid;

/* option O_T + axis is the axis' list */
_Static_assert(O_V == O_T + VAFM_CAMPAIGN_AXIS_V && O_K == O_T + VAFM_CAMPAIGN_AXIS_K, "--T --v --k follow the axes");

static void s_grid_free(s_grid *g)
{
    for (int ax = 0; ax < VAFM_CAMPAIGN_NAXES; ax++)
        free(g->list[ax]);
}

static int s_grid_parse(const vafm_cli_args *a, s_grid *g)
{
    memset(g, 0, sizeof *g);
    uint64_t N = 1, threads = 0, first = 0;
    int rc = 0;
    if (!a->val[O_N]) {
        vafm_cli_error("vafm %s: -n N (curves per grid point) is required", a->cmd->name);
        return VAFM_CLI_EXIT_USAGE;
    }
    if ((rc = vafm_cli_parse_u64("-n", a->val[O_N], 1, 1000000000ULL, &N)) ||
        (a->val[O_THREADS] && (rc = vafm_cli_parse_u64("--threads", a->val[O_THREADS], 0, 256, &threads))) ||
        (a->val[O_FIRST] && (rc = vafm_cli_parse_u64("--first", a->val[O_FIRST], 0, UINT64_MAX, &first))))
        return rc;
    for (int ax = 0; ax < VAFM_CAMPAIGN_NAXES; ax++) {
        const vafm_campaign_axis *x = vafm_campaign_axis_at(ax);
        const char *text = a->val[O_T + ax];
        char opt[16];
        size_t n = 0;
        snprintf(opt, sizeof opt, "--%s", x->symbol);
        if (text && (rc = vafm_cli_parse_list(opt, x->param, text, &g->list[ax], &n)))
            return rc;
        vafm_campaign_axis_set(&g->spec, ax, g->list[ax], n);
    }
    if ((rc = vafm_cli_parse_kernel(a->val[O_KERNEL], &g->spec)))
        return rc;
    g->spec.curves_per_point = N;
    g->spec.threads = (int)threads;
    g->spec.first_curve = first;
    /* each point has its statistics and is validated before the first curve (0.6.1 tried to allocate 1e9
     * points' statistics) */
    const double npd = vafm_cli_grid_points(&g->spec);
    if (npd > VAFM_CLI_MAX_POINTS) {
        vafm_cli_error("vafm %s: the grid --T x --v x --k has %.6g points (%zu x %zu x %zu values); at most %d",
                       a->cmd->name, npd, g->spec.n_T ? g->spec.n_T : 1, g->spec.n_v ? g->spec.n_v : 1,
                       g->spec.n_k ? g->spec.n_k : 1, VAFM_CLI_MAX_POINTS);
        return VAFM_CLI_EXIT_USAGE;
    }
    size_t np = vafm_campaign_points(&g->spec);
    if ((double)np * (double)N > (double)VAFM_CLI_MAX_TOTAL_CURVES) {
        vafm_cli_error("vafm %s: %zu grid points x %" PRIu64 " curves is too many", a->cmd->name, np, N);
        return VAFM_CLI_EXIT_USAGE;
    }
    if (first > N * np) {
        vafm_cli_error("--first: %" PRIu64 " is beyond the campaign's %" PRIu64 " curves", first, N * (uint64_t)np);
        return VAFM_CLI_EXIT_USAGE;
    }
    return 0;
}


static void s_print_campaign_line(FILE *o, const vafm_campaign_spec *spec, uint64_t done, double wall)
{
    fprintf(o, "campaign     %zu grid point(s) x %" PRIu64 " curves, %" PRIu64 " run in %.3f s (%.4g curves/s)\n",
            vafm_campaign_points(spec), spec->curves_per_point, done, wall, wall > 0 ? (double)done / wall : 0.0);
    fprintf(o, "kernel       %s\n", vafm_campaign_kernel_describe(spec));
}

static void s_print_curves_summary(FILE *o, const vafm_cli_scene *sc, const s_grid *g, const s_curves *cv, double wall)
{
    vafm_cli_print_provenance(o, sc);
    s_print_campaign_line(o, &g->spec, cv->done, wall);
    vafm_cli_print_statistics(o, &sc->p, &g->spec, cv->stats);
}

/* With no grid lists the base scene is the only point: check it here for a plain error message
 * (the campaign's own check prefixes the grid point). */
static int s_curves_check(const vafm_cli_args *a, vafm_cli_scene *sc, const s_grid *g)
{
    int grid = 0;
    for (int ax = 0; ax < VAFM_CAMPAIGN_NAXES; ax++)
        grid |= vafm_campaign_axis_values(&g->spec, ax, NULL) != 0;
    return vafm_cli_resolve_scene(a, sc, !grid);
}

static int s_curves_finish(const s_curves *cv, int r, const vafm_error *err)
{
    if (cv->fail_status) {
        vafm_cli_error("curve %" PRIu64 " failed: %s", cv->fail_index, vafm_strerror(cv->fail_status));
        return VAFM_CLI_EXIT_RUNTIME;
    }
    if (cv->io_error)
        return VAFM_CLI_EXIT_RUNTIME; /* reported when the file is closed */
    if (r)
        return vafm_cli_report(err, r);
    return VAFM_CLI_EXIT_OK;
}

int vafm_cli_cmd_curves(const vafm_cli_args *a)
{
    s_grid g;
    vafm_cli_scene sc;
    int rc = s_grid_parse(a, &g);
    if (rc || (rc = s_curves_check(a, &sc, &g)) != 0) {
        s_grid_free(&g);
        return rc;
    }
    s_curves cv;
    memset(&cv, 0, sizeof cv);
    size_t np = vafm_campaign_points(&g.spec);
    cv.total = g.spec.curves_per_point * (uint64_t)np - g.spec.first_curve;
    cv.stats = calloc(np, sizeof *cv.stats);
    if (!cv.stats) {
        s_grid_free(&g);
        vafm_cli_error("out of memory");
        return VAFM_CLI_EXIT_RUNTIME;
    }
    const char *csv_path = a->val[O_CSV];
    if (csv_path && !(cv.csv = vafm_cli_open_out(csv_path))) {
        free(cv.stats);
        s_grid_free(&g);
        return VAFM_CLI_EXIT_RUNTIME;
    }
    if (cv.csv)
        fputs(s_csv_header, cv.csv);
    vafm_cli_progress_init(&cv.pg, a);
    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = vafm_campaign_run(&sc.p, &g.spec, s_on_curve, &cv, &err);
    double wall = vafm_cli_now() - cv.pg.t0;
    vafm_cli_progress_end(&cv.pg);
    int crc = cv.csv ? vafm_cli_close_out(cv.csv, csv_path, cv.io_error) : 0;
    rc = s_curves_finish(&cv, r == VAFM_EABORT ? 0 : r, &err);
    /* The summary goes where the CSV does not. */
    int csv_stdout = csv_path && !strcmp(csv_path, "-");
    if (!rc && !crc && !(csv_stdout && a->on[O_QUIET]))
        s_print_curves_summary(csv_stdout ? stderr : stdout, &sc, &g, &cv, wall);
    free(cv.stats);
    s_grid_free(&g);
    return rc ? rc : crc;
}

/* ---- vafm campaign: one HDF5 file ------------------------------------------------------------------ */

/* The recording itself (vafm_cli_rec_*, cli_common.c) is shared with vafm map. */

/* Every grid point's scene, checked before the file is created (so a bad grid leaves no file behind). */
static int s_check_points(const vafm_params *base, const vafm_campaign_spec *spec)
{
    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = vafm_campaign_validate(base, spec, NULL, &err);
    if (r) {
        vafm_cli_error("%s", err.message[0] ? err.message : vafm_strerror(r));
        return vafm_cli_exit_of(r);
    }
    return 0;
}

static void s_camp_summary(FILE *o, const vafm_cli_scene *sc, const vafm_campaign_spec *spec,
                           const vafm_cli_rec_opts *co, const vafm_cli_rec *cp, const vafm_recorder_report *rep, uint64_t first, double wall)
{
    uint64_t in_file = first + cp->done;
    double mb = vafm_cli_file_mb(co->out);
    vafm_cli_print_provenance(o, sc);
    fprintf(o, "file         %s: %" PRIu64 " curves (%" PRIu64 " kept from before, %" PRIu64 " new), %.4g MB written, "
               "%.4g MB on disk\n",
            co->out, in_file, first, cp->done, mb - co->mb_before, mb);
    s_print_campaign_line(o, spec, cp->done, wall);
    fprintf(o, "writer       %.3f s in open, append, flush and close = %.2f%% of the wall time; %" PRIu64
               " flush(es) (every %g s and at the end), %.4g MB/s\n",
            rep->writer_s, wall > 0 ? 100.0 * rep->writer_s / wall : 0.0, rep->flushes, co->interval,
            wall > 0 ? (mb - co->mb_before) / wall : 0.0);
    /* The statistics cover every curve of the file, from its ground truth. */
    vafm_h5_reader *r = NULL;
    vafm_error err;
    memset(&err, 0, sizeof err);
    size_t np = vafm_campaign_points(spec);
    vafm_point_stats *stats = calloc(np, sizeof *stats);
    if (stats && !vafm_h5_reader_open(&r, co->out, &err)) {
        vafm_cli_truth_stats(r, np, stats);
        vafm_cli_print_statistics(o, &sc->p, spec, stats);
    } else {
        fprintf(o, "statistics   n/a: %s\n", stats ? err.message : "out of memory");
    }
    vafm_h5_reader_destroy(&r);
    free(stats);
}

/* One campaign, single-process (mpi NULL) or as one MPI rank (campaign_mpi.h): the same checks, the
 * same per-curve computation and the same writer callback; MPI only changes who computes which curve.
 * Rank 0 alone touches the file; the other ranks check their scene against rank 0's, then compute. */
static int s_campaign(const vafm_cli_args *a, vafm_cli_mpi *mpi)
{
    s_grid g;
    vafm_cli_scene sc;
    vafm_cli_rec_opts co;
    int root = vafm_cli_mpi_rank(mpi) == 0;
    int rc = s_grid_parse(a, &g);
    if (!rc && !(rc = s_curves_check(a, &sc, &g)) && !(rc = root ? vafm_cli_rec_parse(a, &co) : 0))
        rc = s_check_points(&sc.p, &g.spec);
    if (!rc && root)
        rc = vafm_cli_rec_size_check(a, &co, &sc.p, &g.spec);
    if ((rc = vafm_cli_mpi_agree(mpi, rc, &sc.p, &g.spec)) != 0) {
        s_grid_free(&g);
        return rc;
    }
    if (!root) {
        vafm_error werr;
        memset(&werr, 0, sizeof werr);
        g.spec.keep_samples = 1;
        if (!(rc = vafm_cli_mpi_agree(mpi, 0, NULL, NULL))) /* rank 0 opened the file */
            rc = vafm_cli_mpi_run(mpi, &sc.p, &g.spec, NULL, NULL, &werr) ? VAFM_CLI_EXIT_RUNTIME : VAFM_CLI_EXIT_OK;
        s_grid_free(&g);
        return rc;
    }
    vafm_cli_rec cp;
    memset(&cp, 0, sizeof cp);
    vafm_cli_progress_init(&cp.pg, a);
    double t_start = cp.pg.t0;
    rc = vafm_cli_rec_open(&cp, &co, &sc, &g.spec);
    if (mpi && (rc = vafm_cli_mpi_agree(mpi, rc, NULL, NULL)) != 0 && cp.rec)
        vafm_recorder_close(&cp.rec, NULL, NULL);
    if (rc) {
        s_grid_free(&g);
        return rc;
    }
    uint64_t first = vafm_recorder_count(cp.rec);
    uint64_t total = g.spec.curves_per_point * (uint64_t)vafm_campaign_points(&g.spec);
    g.spec.first_curve = first < total ? first : total;
    g.spec.keep_samples = 1;
    cp.total = total - g.spec.first_curve;
    if (co.resume && !a->on[O_QUIET])
        fprintf(stderr, "vafm: %s holds %" PRIu64 " of the campaign's %" PRIu64 " curves; running the rest\n", co.out,
                first, total);

    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = mpi ? vafm_cli_mpi_run(mpi, &sc.p, &g.spec, vafm_cli_rec_curve, &cp, &err)
                : vafm_campaign_run(&sc.p, &g.spec, vafm_cli_rec_curve, &cp, &err);
    vafm_cli_progress_end(&cp.pg);
    vafm_recorder_report rep;
    rc = vafm_cli_rec_close(&cp, &co, first, r, &err, &rep);
    double wall = vafm_cli_now() - t_start;
    if (!rc) {
        s_camp_summary(stdout, &sc, &g.spec, &co, &cp, &rep, first, wall);
        vafm_cli_mpi_describe(mpi, stdout);
    }
    s_grid_free(&g);
    return rc;
}

int vafm_cli_cmd_campaign(const vafm_cli_args *a)
{
    return vafm_cli_with_mpi(a, s_campaign);
}
