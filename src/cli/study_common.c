/* SPDX-License-Identifier: MIT */
/*
 * What the studies share (study_common.h): one campaign run into its HDF5 file with every curve's ground
 * truth kept in memory (resumable), the per-point statistics of that truth, the paper-fig4 scene of the
 * velocity studies and their speed grid, and the output paths under --out.
 */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <limits.h>
#include <sys/stat.h>
#include <unistd.h>
#include <stdarg.h>

#include "cli/cli.h"
#include "cli/study_common.h"
#include "vafm/campaign.h"
#include "h5/h5.h"
#include "record/record.h"
#include "vafm/stats.h"
#include "vafm/units.h"

/* the pulling speeds of both velocity studies' full grids, reduced */
const double vafm_study_v_full[VAFM_STUDY_N_V_FULL] = { 1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.2, 0.5 };

static void s_spec(const vafm_study_run *r, vafm_campaign_spec *sp)
{
    memset(sp, 0, sizeof *sp);
    vafm_campaign_axis_set(sp, VAFM_CAMPAIGN_AXIS_T, r->nT ? r->T : NULL, r->nT);
    vafm_campaign_axis_set(sp, VAFM_CAMPAIGN_AXIS_V, &r->v, 1);
    vafm_campaign_axis_set(sp, VAFM_CAMPAIGN_AXIS_K, r->nk ? r->k : NULL, r->nk);
    sp->curves_per_point = r->N;
}

static int s_cb(void *user, const vafm_campaign_curve *c)
{
    vafm_study_run *r = user;
    if (c->status || !c->samples.n) {
        r->werr = c->status ? c->status : VAFM_EINVAL;
        snprintf(r->e.message, sizeof r->e.message, "curve %" PRIu64 " failed: %s", c->index, vafm_strerror(r->werr));
        return 1;
    }
    vafm_record_curve rc = { .samples = &c->samples, .params = c->params, .result = &c->result,
                             .point = c->point, .sensitivity_m_per_V = NAN };
    int e = vafm_recorder_append(r->rec, &rc, &r->e);
    if (e || (e = vafm_recorder_truth(r->rec, c->index, &r->truth[c->index])) != 0) {
        r->werr = e;
        return 1;
    }
    if (r->samples_csv) {
        const vafm_samples *s = &c->samples;
        for (size_t i = 0; i < s->n; ++i)
            fprintf(r->samples_csv, "%.9g,%.9g,%.9g,%.9g,%d\n", s->time_s[i], s->height_m[i], s->force_N[i],
                    s->tip_m[i], s->segment[i]);
    }
    return 0;
}

void vafm_study_run_free(vafm_study_run *r)
{
    free(r->truth);
    r->truth = NULL;
}

/* buf = DIR/NAME, NAME from fmt. The --out length is checked up front, so this does not truncate; the
 * check stays so that a longer name added later is refused instead of cut short. @return 0, or 1 with
 * the error printed. */
int vafm_study_path(char buf[VAFM_STUDY_PATH_LEN], const char *out, const char *fmt, ...)
{
    int n = snprintf(buf, VAFM_STUDY_PATH_LEN, "%s/", out), m = -1;
    if (n > 0 && n < VAFM_STUDY_PATH_LEN) {
        va_list ap;
        va_start(ap, fmt);
        m = vsnprintf(buf + n, (size_t)(VAFM_STUDY_PATH_LEN - n), fmt, ap);
        va_end(ap);
    }
    if (m < 0 || m >= VAFM_STUDY_PATH_LEN - n) {
        vafm_cli_error("study: --out: a file name in the %zu-byte directory name would make a path longer than %d "
                       "bytes", strlen(out), VAFM_STUDY_PATH_LEN - 1);
        return 1;
    }
    return 0;
}

/* fopen(path, "w"), printing why it failed. */
FILE *vafm_study_open(const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f)
        vafm_cli_error("study: cannot write %s: %s", path, strerror(errno));
    return f;
}

/* Run one campaign into r->file (or continue it: --resume) and keep every curve's ground truth in
 * r->truth. @return 0, or 1 with the error printed and r->truth freed, so that a caller's error path
 * frees only its other runs. */
int vafm_study_campaign(vafm_study_ctx *ctx, vafm_study_run *r)
{
    vafm_campaign_spec sp;
    s_spec(r, &sp);
    size_t points = vafm_campaign_points(&sp);
    /* -n is checked against this bound up front; this guards the studies' own grids as well */
    if (!points || r->N > VAFM_STUDY_TRUTH_BYTES_MAX / sizeof *r->truth / points) {
        vafm_cli_error("study: %s: %" PRIu64 " curves x %zu points would hold more than %zu MiB of results in "
                       "memory", r->file, r->N, points, VAFM_STUDY_TRUTH_BYTES_MAX >> 20);
        return 1;
    }
    r->total = r->N * points;
    r->truth = calloc(r->total, sizeof *r->truth);
    if (!r->truth) {
        vafm_cli_error("study: %s: out of memory for %" PRIu64 " curves", r->file, r->total);
        return 1;
    }
    vafm_error e;
    memset(&e, 0, sizeof e);
    if (vafm_campaign_validate(&r->base, &sp, NULL, &e)) {
        fprintf(stderr, "vafm study: %s, %s\n", r->file, e.message);
        goto fail;
    }
    vafm_recorder_opts o;
    vafm_recorder_opts_default(&o);
    o.gzip_level = 1;         /* the paper-fig1 curves hold ~0.5 MB of samples each; deflate costs ~1% of a curve */
    o.flush_interval_s = 1.0; /* durable about once a second, as `vafm campaign` */
    struct stat st;
    /* a study's directory holds its own outputs: a rerun replaces them, --resume continues them */
    o.mode = ctx->resume && stat(r->file, &st) == 0 && !r->samples_csv ? VAFM_RECORD_RESUME : VAFM_RECORD_OVERWRITE;
    if (vafm_recorder_open(&r->rec, r->file, &o, &r->base, &sp, &e)) {
        fprintf(stderr, "vafm study: %s: %s\n", r->file, e.message);
        goto fail;
    }
    uint64_t have = vafm_recorder_count(r->rec);
    if (have > r->total)
        have = r->total;
    for (uint64_t i = 0; i < have; ++i)
        if (vafm_recorder_truth(r->rec, i, &r->truth[i])) {
            fprintf(stderr, "vafm study: %s: no ground truth for curve %" PRIu64 "\n", r->file, i);
            vafm_recorder_close(&r->rec, NULL, NULL);
            goto fail;
        }
    ctx->curves_kept += have;
    int rc = 0;
    if (have < r->total) {
        sp.first_curve = have;
        sp.threads = ctx->threads;
        sp.kernel = ctx->kernel.kernel;
        sp.batch_width = ctx->kernel.batch_width;
        sp.keep_samples = 1;
        rc = vafm_campaign_run(&r->base, &sp, s_cb, r, &e);
    }
    int cr = vafm_recorder_close(&r->rec, NULL, r->werr ? NULL : &r->e);
    if (r->werr || (rc && rc != VAFM_EABORT) || cr) {
        fprintf(stderr, "vafm study: %s: %s\n", r->file,
                r->e.message[0] ? r->e.message : e.message[0] ? e.message : vafm_strerror(rc ? rc : cr));
        goto fail;
    }
    for (uint64_t i = have; i < r->total; ++i)
        ctx->steps += r->truth[i].result.steps;
    ctx->curves_run += r->total - have;
    if (!ctx->quiet)
        fprintf(stderr, "vafm study: %s: %" PRIu64 " curves (%" PRIu64 " run)\n", r->file, r->total, r->total - have);
    return 0;
fail:
    vafm_study_run_free(r);
    return 1;
}

/* ---- statistics ---------------------------------------------------------------------------------- */

vafm_study_stat vafm_study_stats(const double *x, size_t n)
{
    vafm_study_stat s = { n, NAN, NAN, NAN };
    if (!n)
        return s;
    double m = 0, v = 0;
    for (size_t i = 0; i < n; ++i)
        m += x[i];
    m /= n;
    for (size_t i = 0; i < n; ++i)
        v += (x[i] - m) * (x[i] - m);
    s.mean = m;
    s.sd = n > 1 ? sqrt(v / (n - 1)) : 0.0;
    s.se = n > 1 ? s.sd / sqrt((double)n) : 0.0;
    return s;
}

/* Values of one observable for grid point `pt` (curves with a clean pull-off: flags 0), scaled. */
size_t vafm_study_collect(const vafm_study_run *r, size_t pt, int which, double scale, double *out)
{
    size_t n = 0;
    for (uint64_t i = pt * r->N; i < (pt + 1) * r->N; ++i) {
        const vafm_h5_truth *t = &r->truth[i];
        double x = vafm_stats_value(&t->result, which);
        if (vafm_stats_is_pulloff(t->status, &t->result) && isfinite(x))
            out[n++] = x * scale;
    }
    return n;
}

size_t vafm_study_flagged(const vafm_study_run *r, size_t pt)
{
    size_t n = 0;
    for (uint64_t i = pt * r->N; i < (pt + 1) * r->N; ++i)
        n += r->truth[i].status || (r->truth[i].result.flags & VAFM_STATS_EXCLUDING_FLAGS) ? 1 : 0;
    return n;
}

/* ---- scenes -------------------------------------------------------------------------------------- */

/* The velocity studies' scene: paper-fig4 (Langevin, m̃ = 0.01) or paper-fig4-bd (Brownian, ζ = 1),
 * retract only from an equilibrium 1 R pressed in, sampled every 0.05 R of travel. */
void vafm_study_fig4_scene(vafm_params *p, int brownian, double v_red)
{
    vafm_preset_apply(p, brownian ? "paper-fig4-bd" : "paper-fig4", NULL);
    vafm_scale sc = vafm_units_scale(p);
    if (!brownian)
        p->omega_dt = 0.6;
    p->start_in_contact = 1;
    p->start_height_m = -1.0 * sc.length_m;
    p->trigger = VAFM_TRIGGER_HEIGHT;
    p->trigger_height_m = -1.0001 * sc.length_m;
    p->v_approach_m_per_s = p->v_retract_m_per_s = v_red * sc.speed_m_per_s;
    p->sample_rate_Hz = v_red / (0.05 * sc.time_s);
    p->retract_margin_m = 0.5 * sc.length_m;
}

double vafm_study_kT_to_K(const vafm_params *p, double kT_red)
{
    return kT_red * vafm_units_scale(p).energy_J / VAFM_KB_J_PER_K;
}
