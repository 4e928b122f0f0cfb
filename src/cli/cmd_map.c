/* SPDX-License-Identifier: MIT */
/* `vafm map`: a force map (vafm/map.h), one curve per pixel over a heterogeneous sample, into one HDF5 file
 * through the campaign machinery and the recorder that `vafm campaign` uses (vafm_cli_rec_*). */
#include "cli/cli.h"

/* The map's spec from --nx, --ny, --size, --pattern and --pattern-param, in that order. */
static int s_map_parse(const vafm_cli_args *a, vafm_map_spec *s)
{
    vafm_map_spec_default(s);
    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = 0;
    char buf[256];
    if (a->val[O_NX] && (r = vafm_map_set(s, "nx", a->val[O_NX], &err)))
        goto bad;
    if (a->val[O_NY] && (r = vafm_map_set(s, "ny", a->val[O_NY], &err)))
        goto bad;
    if (a->val[O_SIZE]) { /* one size for both, or "X,Y" */
        snprintf(buf, sizeof buf, "%s", a->val[O_SIZE]);
        char *comma = strchr(buf, ',');
        if (comma)
            *comma = '\0';
        if ((r = vafm_map_set(s, "size_x_m", buf, &err)) ||
            (r = vafm_map_set(s, "size_y_m", comma ? comma + 1 : buf, &err)))
            goto bad;
    }
    if (a->val[O_PATTERN] && (r = vafm_map_set(s, "pattern", a->val[O_PATTERN], &err)))
        goto bad;
    if (a->val[O_PPARAM]) { /* name=value,name=value,... */
        const char *p = a->val[O_PPARAM];
        while (*p) {
            size_t len = strcspn(p, ",");
            if (len >= sizeof buf) {
                vafm_cli_error("vafm map: --pattern-param: '%.*s...' is too long", 40, p);
                return VAFM_CLI_EXIT_USAGE;
            }
            memcpy(buf, p, len);
            buf[len] = '\0';
            char *eq = strchr(buf, '=');
            if (!eq || eq == buf) {
                vafm_cli_error("vafm map: --pattern-param: '%s' is not NAME=VALUE", buf);
                return VAFM_CLI_EXIT_USAGE;
            }
            *eq = '\0';
            if ((r = vafm_map_set(s, buf, eq + 1, &err)))
                goto bad;
            p += len + (p[len] == ',');
        }
    }
    return 0;
bad:
    vafm_cli_error("vafm map: %s", err.message[0] ? err.message : vafm_strerror(r));
    return VAFM_CLI_EXIT_USAGE;
}

static void s_map_summary(FILE *o, const vafm_cli_scene *sc, const vafm_map_spec *ms, const vafm_cli_rec_opts *co,
                          const vafm_cli_rec *cp, const vafm_recorder_report *rep, uint64_t first, double wall)
{
    double mb = vafm_cli_file_mb(co->out);
    vafm_cli_print_provenance(o, sc);
    fprintf(o, "file         %s: %" PRIu64 " curves (%" PRIu64 " kept from before, %" PRIu64 " new), %.4g MB written, "
               "%.4g MB on disk\n",
            co->out, first + cp->done, first, cp->done, mb - co->mb_before, mb);
    fprintf(o, "force map    %d x %d pixels, pattern %s, start %s; %" PRIu64 " curve(s) run in %.3f s (%.4g curves/s)\n",
            ms->nx, ms->ny, vafm_map_pattern_name(ms->pattern), ms->start == VAFM_MAP_START_FIXED ? "fixed" : "surface",
            cp->done, wall, wall > 0 ? (double)cp->done / wall : 0.0);
    fprintf(o, "writer       %.3f s in open, append, flush and close = %.2f%% of the wall time; %" PRIu64 " flush(es)\n",
            rep->writer_s, wall > 0 ? 100.0 * rep->writer_s / wall : 0.0, rep->flushes);
    vafm_h5_reader *r = NULL;
    vafm_error err;
    memset(&err, 0, sizeof err);
    if (!vafm_h5_reader_open(&r, co->out, &err)) {
        if (vafm_cli_print_map(o, r) < 0)
            fprintf(o, "map          n/a: out of memory\n");
    } else {
        fprintf(o, "map          n/a: %s\n", err.message);
    }
    vafm_h5_reader_destroy(&r);
}

/* One map, single-process (mpi NULL) or as one MPI rank (campaign_mpi.h), as vafm campaign: every rank
 * builds the same grid from the same arguments and checks it against rank 0's; rank 0 alone writes. */
static int s_map_run(const vafm_cli_args *a, vafm_cli_mpi *mpi, const vafm_map_grid *mg);

static int s_map(const vafm_cli_args *a, vafm_cli_mpi *mpi)
{
    vafm_map_grid *mg = NULL;
    if (a->val[O_SAMPLE]) { /* a measured map as the sample: read (and bounded) before anything else */
        vafm_error gerr;
        memset(&gerr, 0, sizeof gerr);
        int r = vafm_h5_map_grid_load(a->val[O_SAMPLE], &mg, &gerr);
        if (r) {
            vafm_cli_error("vafm map: --sample %s: %s", a->val[O_SAMPLE], gerr.message);
            return vafm_cli_exit_of(r);
        }
    }
    int rc = s_map_run(a, mpi, mg);
    vafm_h5_map_grid_free(&mg);
    return rc;
}

static int s_map_run(const vafm_cli_args *a, vafm_cli_mpi *mpi, const vafm_map_grid *mg)
{
    vafm_map_spec ms;
    vafm_cli_scene sc;
    vafm_cli_rec_opts co;
    uint64_t threads = 0;
    int root = vafm_cli_mpi_rank(mpi) == 0;
    int rc = s_map_parse(a, &ms);
    if (!rc && mg) {
        ms.pattern = VAFM_MAP_GRID;
        ms.grid = mg;
    }
    if (!rc && a->val[O_THREADS])
        rc = vafm_cli_parse_u64("--threads", a->val[O_THREADS], 0, 256, &threads);
    if (!rc)
        rc = vafm_cli_resolve_scene(a, &sc, 1);
    if (!rc && root)
        rc = vafm_cli_rec_parse(a, &co);
    /* every pixel's scene, checked before the file is created (a bad map leaves no file behind) */
    vafm_error err;
    memset(&err, 0, sizeof err);
    int r = rc ? 0 : vafm_map_validate(&ms, &sc.p, &err);
    if (r) {
        vafm_cli_error("vafm map: %s", err.message[0] ? err.message : vafm_strerror(r));
        rc = vafm_cli_exit_of(r);
    }
    char map_json[4096];
    vafm_campaign_spec grid;
    memset(&grid, 0, sizeof grid);
    if (!rc && (vafm_map_to_json(&ms, map_json, sizeof map_json) < 0 || vafm_map_campaign(&ms, &grid))) {
        vafm_cli_error("vafm map: the map's spec cannot be stored");
        rc = VAFM_CLI_EXIT_RUNTIME;
    }
    grid.map_json = map_json;
    grid.threads = (int)threads;
    if (!rc)
        rc = vafm_cli_parse_kernel(a->val[O_KERNEL], &grid);
    grid.keep_samples = 1;
    if (!rc && root)
        rc = vafm_cli_rec_size_check(a, &co, &sc.p, &grid);
    if ((rc = vafm_cli_mpi_agree(mpi, rc, &sc.p, &grid)) != 0)
        return rc;
    if (!root) { /* compute only: rank 0 writes */
        vafm_error werr;
        memset(&werr, 0, sizeof werr);
        if (!(rc = vafm_cli_mpi_agree(mpi, 0, NULL, NULL))) /* rank 0 opened the file */
            rc = vafm_cli_mpi_run(mpi, &sc.p, &grid, NULL, NULL, &werr) ? VAFM_CLI_EXIT_RUNTIME : VAFM_CLI_EXIT_OK;
        return rc;
    }

    vafm_cli_rec cp;
    memset(&cp, 0, sizeof cp);
    cp.map = &ms;
    cp.base = &sc.p;
    vafm_cli_progress_init(&cp.pg, a);
    double t_start = cp.pg.t0;
    rc = vafm_cli_rec_open(&cp, &co, &sc, &grid);
    if (mpi && (rc = vafm_cli_mpi_agree(mpi, rc, NULL, NULL)) != 0 && cp.rec)
        vafm_recorder_close(&cp.rec, NULL, NULL);
    if (rc)
        return rc;
    uint64_t first = vafm_recorder_count(cp.rec), total = vafm_campaign_points(&grid);
    grid.first_curve = first < total ? first : total;
    cp.total = total - grid.first_curve;
    if (co.resume && !a->on[O_QUIET])
        fprintf(stderr, "vafm: %s holds %" PRIu64 " of the map's %" PRIu64 " curves; running the rest\n", co.out, first,
                total);
    memset(&err, 0, sizeof err);
    r = mpi ? vafm_cli_mpi_run(mpi, &sc.p, &grid, vafm_cli_rec_curve, &cp, &err)
            : vafm_campaign_run(&sc.p, &grid, vafm_cli_rec_curve, &cp, &err);
    vafm_cli_progress_end(&cp.pg);
    vafm_recorder_report rep;
    rc = vafm_cli_rec_close(&cp, &co, first, r, &err, &rep);
    double wall = vafm_cli_now() - t_start;
    if (!rc) {
        s_map_summary(stdout, &sc, &ms, &co, &cp, &rep, first, wall);
        vafm_cli_mpi_describe(mpi, stdout);
    }
    return rc;
}

int vafm_cli_cmd_map(const vafm_cli_args *a)
{
    return vafm_cli_with_mpi(a, s_map);
}
