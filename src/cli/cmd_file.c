/* SPDX-License-Identifier: MIT */
/* `vafm info` and `vafm export`: HDF5 force-curve files, vafm's or another program's. */
#include "cli/cli.h"
#include "core/channels.h"

/* ---- vafm info ------------------------------------------------------------------------------------ */

static int s_need_file(const vafm_cli_args *a)
{
    if (a->file)
        return 0;
    vafm_cli_error("vafm %s: FILE (an HDF5 force-curve file) is required (see vafm %s --help)", a->cmd->name,
            a->cmd->name);
    return VAFM_CLI_EXIT_USAGE;
}

static int s_open_reader(const char *path, vafm_h5_reader **r)
{
    vafm_error err;
    memset(&err, 0, sizeof err);
    int rc = vafm_h5_reader_open(r, path, &err);
    if (rc) {
        vafm_cli_error("%s", err.message[0] ? err.message : vafm_strerror(rc));
        return VAFM_CLI_EXIT_RUNTIME; /* not this layout, damaged, truncated: the file is at fault, not the call */
    }
    return 0;
}

/* "%12.6g" of v·scale, or "-" when absent. */
static const char *s_num(char *buf, size_t len, double v, double scale)
{
    if (isnan(v))
        snprintf(buf, len, "-");
    else
        snprintf(buf, len, "%.6g", v * scale);
    return buf;
}

static void s_print_list(FILE *o, const char *name, const double *v, size_t n, const char *unit)
{
    fprintf(o, " %s ", name);
    if (!n)
        fputs("(the scene's)", o);
    for (size_t i = 0; i < n; i++)
        fprintf(o, "%s%.6g", i ? "," : "", v[i]);
    if (n)
        fprintf(o, " %s", unit);
    fputc(';', o);
}

typedef struct s_info_prov {
    int scene_ok, grid_ok, is_map;
    vafm_params p;
    vafm_scene_grid grid;
    vafm_campaign_spec spec;
} s_info_prov;

#define S_INFO_TEXT_MAX 120 /* bytes of a file's free text printed on one line */

/* Text from a file, on one line: control characters (C0, DEL, C1) as '?' (no escape sequence reaches the terminal), at most
 * S_INFO_TEXT_MAX bytes (cut at a UTF-8 character boundary) and then its length. 0.6.2 printed a
 * 'software' of any size in full. */
static void s_info_text(FILE *o, const char *s)
{
    size_t n = strlen(s), k = n;
    if (n > S_INFO_TEXT_MAX) {
        k = S_INFO_TEXT_MAX;
        while (k > 0 && ((unsigned char)s[k] & 0xC0) == 0x80) /* s[k] continues a character: cut before it */
            k--;
    }
    for (size_t i = 0; i < k; i++) {
        unsigned char b = (unsigned char)s[i];
        if (b == 0xC2 && i + 1 < k && (unsigned char)s[i + 1] >= 0x80 && (unsigned char)s[i + 1] <= 0x9F) {
            fputc('?', o); /* a C1 control (U+0080-U+009F: U+009B is a CSI to some terminals) */
            i++;
        } else
            fputc(b < 0x20 || b == 0x7f ? '?' : b, o);
    }
    if (k < n)
        fprintf(o, "... (%zu bytes)", n);
}

static void s_info_provenance(FILE *o, const char *path, const vafm_h5_provenance *pv, s_info_prov *ip)
{
    memset(ip, 0, sizeof *ip);
    fputs("software     ", o);
    s_info_text(o, pv->software ? pv->software : "");
    fputc(' ', o);
    s_info_text(o, pv->software_version ? pv->software_version : "");
    fputc('\n', o);
    if (!pv->is_vafm) {
        fprintf(o, "provenance   none (no root attribute 'vafm format version': not written by vafm)\n");
        return;
    }
    fprintf(o, "vafm format  %d.%d, created %s, seed %" PRIu64 ", ground truth for %zu curve(s)\n", pv->format_major,
            pv->format_minor, pv->created ? pv->created : "(unknown)", pv->seed, pv->truth_rows);
    char origin[512];
    vafm_error err;
    memset(&err, 0, sizeof err);
    if (pv->grid_json) {
        snprintf(origin, sizeof origin, "%s: root attribute 'vafm grid'", path);
        ip->grid_ok = !vafm_scene_grid_parse(pv->grid_json, origin, &ip->grid, &err);
        ip->is_map = strstr(pv->grid_json, "\"map\": {") != NULL;
        if (ip->grid_ok && ip->is_map) {
            const char *pat = strstr(pv->grid_json, "\"pattern\": \""), *st = strstr(pv->grid_json, "\"start\": \"");
            fprintf(o, "grid         a force map (vafm map), pattern %.*s, start %.*s: one curve per pixel (map below)\n",
                    pat ? (int)strcspn(pat + 12, "\"") : 1, pat ? pat + 12 : "?", st ? (int)strcspn(st + 10, "\"") : 1,
                    st ? st + 10 : "?");
        } else if (ip->grid_ok) {
            vafm_campaign_spec *sp = &ip->spec;
            sp->T_K = ip->grid.T_K;
            sp->n_T = ip->grid.n_T;
            sp->v_m_per_s = ip->grid.v_m_per_s;
            sp->n_v = ip->grid.n_v;
            sp->k_N_per_m = ip->grid.k_N_per_m;
            sp->n_k = ip->grid.n_k;
            sp->curves_per_point = ip->grid.curves_per_point;
            fprintf(o, "grid         %zu point(s) x ", vafm_campaign_points(sp));
            if (sp->curves_per_point)
                fprintf(o, "%" PRIu64 " curves = %" PRIu64 " curves;", sp->curves_per_point,
                        sp->curves_per_point * (uint64_t)vafm_campaign_points(sp));
            else
                fputs("? curves;", o);
            for (int ax = 0; ax < VAFM_CAMPAIGN_NAXES; ax++) {
                const double *v;
                size_t n = vafm_campaign_axis_values(sp, ax, &v);
                s_print_list(o, vafm_campaign_axis_at(ax)->symbol, v, n, vafm_campaign_axis_at(ax)->unit);
            }
            fputc('\n', o);
        } else {
            fprintf(o, "grid         cannot be read: %s\n", err.message);
        }
    }
    if (!pv->scene_json) {
        fprintf(o, "scene        (none recorded)\n");
        return;
    }
    snprintf(origin, sizeof origin, "%s: root attribute 'vafm scene'", path);
    vafm_params_default(&ip->p);
    ip->scene_ok = !vafm_scene_parse(&ip->p, pv->scene_json, origin, &err);
    if (ip->scene_ok) {
        fprintf(o, "scene        as stored in the file (vafm info --json prints all of it as a --scene file)\n");
        vafm_cli_print_scene_si(o, &ip->p);
    } else {
        fprintf(o, "scene        cannot be read: %s\n", err.message);
    }
}

static void s_info_curve_line(FILE *o, const vafm_h5_curve *c, const vafm_h5_reader *r, int is_vafm)
{
    size_t nseg[3] = { 0, 0, 0 };
    for (size_t j = 0; j < c->n; j++)
        if (c->segment[j] < 3)
            nseg[c->segment[j]]++;
    const vafm_h5_meta *m = &c->meta;
    char b[5][32];
    fprintf(o, "  %6" PRIu64 " %8zu %8zu %8zu %6zu %12s %12s %12s %12s", c->group, c->n, nseg[0], nseg[1], nseg[2],
            s_num(b[0], sizeof b[0], m->spring_constant_N_per_m, 1.0),
            s_num(b[1], sizeof b[1], m->speed_approach_m_per_s, 1.0),
            s_num(b[2], sizeof b[2], m->speed_retract_m_per_s, 1.0), s_num(b[3], sizeof b[3], m->duration_s, 1.0));
    vafm_h5_truth t;
    if (is_vafm && !vafm_h5_reader_truth(r, c->group, &t))
        fprintf(o, " | %5" PRIu64 " %6d %5d %12s %12s", t.point, t.status, t.result.flags,
                s_num(b[0], sizeof b[0], t.result.pulloff_sampled_N, 1e9),
                s_num(b[1], sizeof b[1], t.result.detach_force_N, 1e9));
    else if (is_vafm)
        fputs(" | (no ground truth)", o);
    fputc('\n', o);
}

/* The file's segment list (format 1.2, "vafm segments"), one segment a line: what each position ran. */
static void s_info_segments(FILE *o, const vafm_h5_provenance *pv)
{
    static const char *const kinds[] = { "extend", "retract", "pause", "modulate" };
    static const char *const chans[] = { "none", "force", "deflection_V", "height", "time" };
    vafm_segment_spec segs[VAFM_SEGMENTS_MAX];
    size_t n = 0;
    vafm_error err;
    if (vafm_segments_from_json(pv->segments_json, segs, VAFM_SEGMENTS_MAX, &n, &err)) {
        fprintf(o, "segments     %d, every curve runs the list of root attribute 'vafm segments' (it does not parse "
                   "here: %s)\n", pv->segment_count, err.message);
        return;
    }
    fprintf(o, "segments     %zu, every curve runs this list; segment = the position (afmformats' multi-segment "
               "convention), 'segment count' %zu\n", n, n);
    for (size_t i = 0; i < n; i++) {
        const vafm_segment_spec *g = &segs[i];
        fprintf(o, "  %2zu %-8s", i, g->kind >= 0 && g->kind <= 3 ? kinds[g->kind] : "?");
        if (g->kind <= VAFM_SEGMENT_RETRACT)
            fprintf(o, " %g m/s", g->speed_m_per_s);
        if (g->kind <= VAFM_SEGMENT_RETRACT && g->distance_m > 0)
            fprintf(o, ", %g m", g->distance_m);
        if (g->kind == VAFM_SEGMENT_RETRACT && g->end != VAFM_SEGMENT_END_TRAVEL)
            fprintf(o, ", to the %s", g->end == VAFM_SEGMENT_END_DETACH ? "detachment" : "start height");
        if (g->kind >= VAFM_SEGMENT_PAUSE)
            fprintf(o, " %g s", g->duration_s);
        if (g->kind == VAFM_SEGMENT_PAUSE)
            fprintf(o, " at constant %s", g->pause_mode == VAFM_PAUSE_FORCE ? "force" : "height");
        if (g->kind == VAFM_SEGMENT_MODULATE)
            fprintf(o, ", %g m at %g Hz", g->amplitude_m, g->frequency_Hz);
        if (g->trigger > 0 && g->trigger <= 4)
            fprintf(o, ", until %s %s %g%s", chans[g->trigger], g->trigger_op ? "<" : ">", g->trigger_value,
                    g->trigger_relative ? " (relative)" : "");
        if (g->sample_rate_Hz > 0)
            fprintf(o, ", %g Hz", g->sample_rate_Hz);
        fputc('\n', o);
    }
}

/* A format 1.3 file (a daemon's log): the curves that carry their own list ("vafm segments <i>"), one a line
 * with its segments' kinds; the first 20, then a count. @return 1 if the file has such curves. */
static int s_info_curve_lists(FILE *o, vafm_h5_reader *r, const vafm_h5_provenance *pv)
{
    static const char *const kinds[] = { "extend", "retract", "pause", "modulate" };
    if (!pv->is_vafm || pv->format_minor < VAFM_H5_FORMAT_MINOR_CURVE_SEGMENTS || pv->segments_json)
        return 0;
    size_t n = vafm_h5_reader_count(r), listed = 0, more = 0;
    vafm_segment_spec segs[VAFM_SEGMENTS_MAX];
    fprintf(o, "segments     curves with their own segment list (format 1.3; segment = the position); others "
               "force-distance\n");
    for (size_t i = 0; i < n; i++) {
        const char *json = NULL;
        vafm_error err;
        memset(&err, 0, sizeof err);
        if (vafm_h5_reader_curve_segments(r, i, &json, &err) || !json)
            continue;
        if (listed == 20) {
            more++;
            continue;
        }
        listed++;
        size_t ns = 0;
        if (vafm_segments_from_json(json, segs, VAFM_SEGMENTS_MAX, &ns, &err)) {
            fprintf(o, "  curve %" PRIu64 ": a list that does not parse here (%s)\n", vafm_h5_reader_group(r, i),
                    err.message);
            continue;
        }
        fprintf(o, "  curve %" PRIu64 ": %zu segments:", vafm_h5_reader_group(r, i), ns);
        for (size_t k = 0; k < ns; k++)
            fprintf(o, " %s", segs[k].kind >= 0 && segs[k].kind <= 3 ? kinds[segs[k].kind] : "?");
        fputc('\n', o);
    }
    if (more)
        fprintf(o, "  ... and %zu more\n", more);
    return 1;
}

int vafm_cli_cmd_info(const vafm_cli_args *a)
{
    vafm_h5_reader *r = NULL;
    int rc = s_need_file(a);
    if (rc || (rc = s_open_reader(a->file, &r)) != 0)
        return rc;
    vafm_h5_provenance pv;
    vafm_h5_reader_provenance(r, &pv);
    if (a->on[O_JSON]) {
        if (pv.scene_json)
            puts(pv.scene_json);
        else
            vafm_cli_error("%s: no vafm scene in this file (root attribute 'vafm scene')", a->file);
        vafm_h5_reader_destroy(&r);
        return pv.scene_json ? VAFM_CLI_EXIT_OK : VAFM_CLI_EXIT_RUNTIME;
    }
    size_t n = vafm_h5_reader_count(r);
    printf("file         %s, %.4g MB, %zu curve(s)\n", a->file, vafm_cli_file_mb(a->file), n);
    s_info_prov ip;
    s_info_provenance(stdout, a->file, &pv, &ip);
    if (pv.segments_json)
        s_info_segments(stdout, &pv);
    int own = s_info_curve_lists(stdout, r, &pv);
    printf("curves       points per segment (%s); SI%s\n",
           pv.segments_json ? "the list's first three: positions 0, 1, 2"
           : own            ? "0 approach, 1 retract, 2 dwell; a curve of its own list: positions 0, 1, 2"
                            : "0 approach, 1 retract, 2 dwell",
           pv.is_vafm ? "; ground truth: pull-off forces tensile, nN" : "");
    int seg = pv.segments_json || own;
    printf("  %6s %8s %8s %8s %6s %12s %12s %12s %12s", "curve", "points", seg ? "seg 0" : "approach",
           seg ? "seg 1" : "retract", seg ? "seg 2" : "dwell", "k_N_per_m", "v_appr_m/s",
           "v_retr_m/s", "duration_s");
    if (pv.is_vafm)
        printf(" | %5s %6s %5s %12s %12s", "point", "status", "flags", "pulloff_samp", "detach_force");
    putchar('\n');
    uint64_t damaged = 0;
    for (size_t i = 0; i < n; i++) {
        vafm_h5_curve c;
        vafm_error err;
        memset(&err, 0, sizeof err);
        int cr = vafm_h5_reader_curve(r, i, &c, &err);
        if (cr) {
            /* the first VAFM_CLI_MAX_CURVE_ERRORS are named; a file of a million damaged groups is summed up */
            if (damaged < VAFM_CLI_MAX_CURVE_ERRORS) {
                fflush(stdout);
                vafm_cli_error("%s", err.message[0] ? err.message : vafm_strerror(cr));
            }
            damaged++;
            continue;
        }
        s_info_curve_line(stdout, &c, r, pv.is_vafm);
    }
    if (damaged > VAFM_CLI_MAX_CURVE_ERRORS)
        vafm_cli_error("%s: ... and %" PRIu64 " more curve(s) that cannot be read (only the first %d are named)", a->file,
                damaged - VAFM_CLI_MAX_CURVE_ERRORS, VAFM_CLI_MAX_CURVE_ERRORS);
    int map = vafm_cli_print_map(stdout, r);
    if (map < 0)
        printf("map          n/a: out of memory\n");
    if (pv.is_vafm && ip.scene_ok && ip.grid_ok && !ip.is_map && n) {
        size_t np = vafm_campaign_points(&ip.spec);
        /* the grid comes from the file: its lists size the table (0.6.1 allocated 3000³ points for a 0.5 MB
         * file) */
        const double npd = vafm_cli_grid_points(&ip.spec);
        vafm_point_stats *stats = npd <= VAFM_CLI_MAX_POINTS ? calloc(np, sizeof *stats) : NULL;
        if (npd > VAFM_CLI_MAX_POINTS)
            printf("statistics   not summed up: the grid has %.6g points (info sums up at most %d)\n", npd,
                   VAFM_CLI_MAX_POINTS);
        if (stats) {
            uint64_t missing = vafm_cli_truth_stats(r, np, stats);
            vafm_cli_print_statistics(stdout, &ip.p, &ip.spec, stats);
            if (missing)
                printf("  (%" PRIu64 " curve(s) without a ground-truth row left out)\n", missing);
            free(stats);
        }
    }
    vafm_scene_grid_free(&ip.grid);
    vafm_h5_reader_destroy(&r);
    vafm_error cerr;
    memset(&cerr, 0, sizeof cerr);
    int ck = vafm_h5_check(a->file, &cerr);
    if (!ck)
        printf("conformance  ok: every rule of protocol/hdf5.md (L1-L17%s)\n", pv.is_vafm ? ", V1-V7" : "");
    else
        printf("conformance  FAILED: %s\n", cerr.message[0] ? cerr.message : vafm_strerror(ck));
    if (damaged) {
        vafm_cli_error("%s: %" PRIu64 " of %zu curve(s) cannot be read", a->file, damaged, n);
        return VAFM_CLI_EXIT_RUNTIME;
    }
    return VAFM_CLI_EXIT_OK;
}

/* ---- vafm export ---------------------------------------------------------------------------------- */

/* One value of a CSV cell: %.17g (reads back bit for bit), or empty when absent. */
static int s_cell(FILE *f, const char *sep, double v, int present)
{
    return present ? fprintf(f, "%s%.17g", sep, v) : fprintf(f, "%s", sep);
}

static int s_export_rows(FILE *f, const vafm_h5_curve *c)
{
    double k = c->meta.spring_constant_N_per_m;
    int has_k = isfinite(k) && k > 0;
    const double *h = c->height_piezo_m ? c->height_piezo_m : c->height_measured_m;
    const double *hm = c->height_measured_m ? c->height_measured_m : c->height_piezo_m;
    for (size_t i = 0; i < c->n; i++) {
        double fi = c->force_N[i];
        /* tip position as stored; else nanite's convention, height (measured) + force / k (protocol/csv.md) */
        double tip = c->tip_position_m ? c->tip_position_m[i] : has_k && hm ? hm[i] + fi / k : NAN;
        if (s_cell(f, "", c->time_s ? c->time_s[i] : 0.0, c->time_s != NULL) < 0 ||
            s_cell(f, ",", h ? h[i] : 0.0, h != NULL) < 0 || s_cell(f, ",", has_k ? fi / k : 0.0, has_k) < 0 ||
            s_cell(f, ",", fi, 1) < 0 || s_cell(f, ",", tip, !isnan(tip)) < 0 ||
            fprintf(f, ",%u\n", (unsigned)c->segment[i]) < 0)
            return -1;
    }
    return 0;
}

int vafm_cli_cmd_export(const vafm_cli_args *a)
{
    int rc = s_need_file(a);
    if (rc)
        return rc;
    if (!a->val[O_CURVE]) {
        vafm_cli_error("vafm export: --curve I (the curve to export; vafm info lists them) is required");
        return VAFM_CLI_EXIT_USAGE;
    }
    vafm_h5_reader *r = NULL;
    if ((rc = s_open_reader(a->file, &r)) != 0)
        return rc;
    size_t n = vafm_h5_reader_count(r), i = 0;
    uint64_t group = 0;
    if (!n) {
        vafm_cli_error("--curve: %s holds no curves", a->file);
        rc = VAFM_CLI_EXIT_USAGE;
    } else if (!(rc = vafm_cli_parse_u64("--curve", a->val[O_CURVE], 0, UINT64_MAX - 1, &group)) &&
               vafm_h5_reader_find(r, group, &i)) {
        /* curves are named by their group, as vafm info lists them (a file may have gaps) */
        uint64_t lo = vafm_h5_reader_group(r, 0), hi = vafm_h5_reader_group(r, n - 1);
        vafm_cli_error("--curve: %s has no curve group '%" PRIu64 "' (its %zu groups are numbered %" PRIu64 " to %" PRIu64
                "%s; vafm info lists them)", a->file, group, n, lo, hi, hi - lo + 1 > n ? ", with gaps" : "");
        rc = VAFM_CLI_EXIT_USAGE;
    }
    vafm_h5_curve c;
    vafm_error err;
    memset(&err, 0, sizeof err);
    int cr = rc ? 0 : vafm_h5_reader_curve(r, i, &c, &err);
    if (!rc && cr) {
        vafm_cli_error("%s", err.message[0] ? err.message : vafm_strerror(cr));
        rc = VAFM_CLI_EXIT_RUNTIME;
    }
    FILE *f = NULL;
    if (!rc && !(f = vafm_cli_open_out(a->val[O_CSV])))
        rc = VAFM_CLI_EXIT_RUNTIME;
    if (!rc) {
        vafm_channels_csv_head(f, VAFM_CH_SEGMENT_CSV); /* core/channels.h's columns */
        fputc('\n', f);
        int bad = s_export_rows(f, &c) < 0;
        rc = vafm_cli_close_out(f, a->val[O_CSV], bad);
    }
    vafm_h5_reader_destroy(&r);
    return rc;
}
