/* SPDX-License-Identifier: MIT */
/*
 * `vafm listen`: subscribe to a running vafmd and write the runs that arrive to CSV (the columns of
 * `vafm samples`, protocol/csv.md, plus vDeflection_V and run_id) or to an HDF5 file of protocol/hdf5.md
 * (one curve group per force curve, with the run's scene as provenance and its curve result as ground
 * truth). A run's columns are the rows of core/channels.h. A run with lost data blocks (a jump in the
 * header's seq, or run.end's last_seq/samples beyond what arrived) is never written: listen names it on
 * stderr and exits 1.
 */
#include <errno.h>
#include <inttypes.h>
#include <jansson.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cli/cli.h"
#include "cli/client_conn.h"
#include "cli/cmd_client.h"
#include "core/channels.h"
#include "h5/h5.h"
#include "record/record.h"
#include "record/scene.h"
#include "vafm/params.h"

/* ---- vafm listen ---------------------------------------------------------------------------------- */

static const char *s_listen_usage =
    "usage: vafm listen [CONNECTION] [--out FILE.csv|FILE.h5|-] [--runs N] [--start curve|tune]\n"
    "                   [--index I] [--duration S] [--overwrite]\n"
    "Subscribe to a running vafmd and record the runs that arrive.\n"
    "  -o, --out FILE     FILE.h5: one curve group per force curve in the layout of protocol/hdf5.md (the\n"
    "                     run's scene as provenance, its curve result as ground truth; tunes are not\n"
    "                     written there); anything else: CSV (default '-': stdout) with the columns of\n"
    "                     `vafm samples` (protocol/csv.md) plus vDeflection_V and run_id, every run\n"
    "                     (a replay: the file's time column if it has one; cells of channels the file\n"
    "                     lacks are empty)\n"
    "  --runs N           stop after N complete runs (default 1; 0: until SIGINT/SIGTERM)\n"
    "  --start KIND       after subscribing, start one run (curve or tune) and record it\n"
    "  --index I          with --start: the run's random stream index (default 0)\n"
    "  --duration S       with --start tune: its duration in s (default: the scene's)\n"
    "  --overwrite        replace an existing FILE.h5 or FILE.csv\n"
    "Runs already in progress when listen subscribes are skipped (their start was missed). A run with\n"
    "lost data blocks (a sequence gap) is not written; listen names it on stderr, goes on, and exits 1.\n";

static volatile sig_atomic_t s_stop;
static void s_on_signal(int sig)
{
    (void)sig;
    s_stop = 1;
}

/* The columns of a run are the rows of core/channels.h: every live run streams the VAFM_CHF_LIVE ones, a
 * scene with a piezo model or a z sensor the measured height, a replay of a file with a time column time_s
 * (else the times are the sample clock's). */
enum { S_NCH = VAFM_CH_COUNT };

typedef struct s_run {
    int64_t run_id;        /* -1: none in progress */
    int active, skip;      /* skip: joined mid-run, or failed */
    int map[S_NCH];        /* stream channel of each row, -1: absent (a replay of a file without it) */
    json_t *start;         /* run.start */
    double fs, t_off;
    uint64_t gaps;
    int restarted;         /* the publisher restarted (a new session) while the run was received */
    uint64_t clipped;      /* blocks flagged CLIPPED (ADC saturation) */
    int altered;           /* a saturate or dropout fault record of this run: its force is not the physics' */
    double *col[S_NCH];    /* col[VAFM_CH_TIME]: the sample times, streamed or from the clock */
    uint8_t *seg;
    size_t n, cap;
} s_run;

static int s_run_grow(s_run *r, size_t need)
{
    if (need <= r->cap)
        return 0;
    size_t cap = r->cap ? r->cap : 8192;
    while (cap < need)
        cap *= 2;
    for (int k = 0; k < S_NCH; k++) {
        double *p = realloc(r->col[k], cap * sizeof *p);
        if (!p)
            return -1;
        r->col[k] = p;
    }
    uint8_t *s = realloc(r->seg, cap);
    if (!s)
        return -1;
    r->seg = s;
    r->cap = cap;
    return 0;
}

static void s_run_reset(s_run *r)
{
    json_decref(r->start);
    r->start = NULL;
    r->run_id = -1;
    r->active = r->skip = 0;
    r->gaps = 0;
    r->restarted = 0;
    r->clipped = 0;
    r->altered = 0;
    r->n = 0;
}

static void s_run_free(s_run *r)
{
    s_run_reset(r);
    for (int k = 0; k < S_NCH; k++)
        free(r->col[k]);
    free(r->seg);
}

typedef struct s_listen {
    vafm_cli_conn *x;
    const char *out;
    int h5;
    FILE *csv;
    vafm_recorder *w;
    uint64_t runs_done, runs_bad, curves_written, tunes_skipped;
} s_listen;

static double s_jnum(json_t *o, const char *k)
{
    json_t *v = json_object_get(o, k);
    return json_is_number(v) ? json_number_value(v) : NAN; /* null: a non-finite value (wire.md §3.3) */
}

static uint64_t s_ju64(json_t *o, const char *k)
{
    json_t *v = json_object_get(o, k);
    return json_is_integer(v) && json_integer_value(v) > 0 ? (uint64_t)json_integer_value(v) : 0;
}

/* run.end's "result" as a vafm_curve_result (fields a daemon does not send: NaN / 0). */
static void s_result_from_json(json_t *j, vafm_curve_result *r)
{
    memset(r, 0, sizeof *r);
    r->index = s_ju64(j, "index");
    r->flags = (int)json_integer_value(json_object_get(j, "flags"));
    r->pulloff_sampled_N = s_jnum(j, "pulloff_sampled_N");
    r->pulloff_spring_N = s_jnum(j, "pulloff_spring_N");
    r->detach_force_N = s_jnum(j, "detach_force_N");
    r->detach_height_m = s_jnum(j, "detach_height_m");
    r->detach_eq_force_N = s_jnum(j, "detach_eq_force_N");
    r->detach_time_s = s_jnum(j, "detach_time_s");
    r->touch_time_s = s_jnum(j, "touch_time_s");
    r->touch_height_m = s_jnum(j, "touch_height_m");
    r->retract_start_s = s_jnum(j, "retract_start_s");
    r->duration_s = s_jnum(j, "duration_s");
    r->samples = s_ju64(j, "samples");
    r->steps = s_ju64(j, "steps");
    r->steps_contact = s_ju64(j, "steps_contact");
    r->steps_free = s_ju64(j, "steps_free");
}

/* One CSV cell: empty where the run has no such channel (protocol/csv.md), else %.17g (round trip). */
static int s_csv_cell(FILE *f, const s_run *r, int k, size_t i)
{
    return r->map[k] < 0 ? 0 : fprintf(f, "%.17g", r->col[k][i]);
}

static int s_write_csv(s_listen *L, const s_run *r)
{
    int bad = 0;
    /* the samples CSV's columns up to the segment (core/channels.h), then vDeflection_V and run_id */
    int order[VAFM_CH_SEGMENT_CSV - 1];
    for (int c = 1; c < VAFM_CH_SEGMENT_CSV; c++)
        order[c - 1] = vafm_channel_at_csv(c);
    for (size_t i = 0; i < r->n && !bad; i++) {
        bad |= fprintf(L->csv, "%.17g", r->col[order[0]][i]) < 0; /* time: always there */
        for (int c = 1; c < VAFM_CH_SEGMENT_CSV - 1; c++)
            bad |= fputc(',', L->csv) == EOF || s_csv_cell(L->csv, r, order[c], i) < 0;
        bad |= fprintf(L->csv, ",%u,", (unsigned)r->seg[i]) < 0 || s_csv_cell(L->csv, r, VAFM_CH_VDEFLECTION, i) < 0;
        bad |= fprintf(L->csv, ",%" PRId64 "\n", r->run_id) < 0;
    }
    bad |= fflush(L->csv) != 0;
    if (bad)
        vafm_cli_conn_err(L->x, "writing '%s' failed", L->out);
    return bad ? VAFM_CLI_CONN_RUNTIME : 0;
}

static int s_write_h5(s_listen *L, const s_run *r, json_t *end)
{
    vafm_params p;
    vafm_params_default(&p);
    vafm_error e = {0};
    char *scene = json_dumps(json_object_get(r->start, "scene"), JSON_COMPACT);
    int rc = scene ? vafm_scene_parse(&p, scene, "run.start scene", &e) : VAFM_EFORMAT;
    free(scene);
    if (rc) {
        vafm_cli_conn_err(L->x, "run %" PRId64 ": its scene does not load: %s", r->run_id, e.message);
        return VAFM_CLI_CONN_RUNTIME;
    }
    vafm_curve_result res;
    s_result_from_json(json_object_get(end, "result"), &res);
    vafm_samples s = {.n = r->n, .first = 0, .segment = r->seg};
    for (int k = 0; k < S_NCH; k++) /* the time is always there; the measured height only if streamed */
        vafm_channel_set_samples(&s, k, k != VAFM_CH_HEIGHT_MEASURED || r->map[k] >= 0 ? r->col[k] : NULL);
    /* with the detector signals on, force is the measured (noisy) one: no tip position = height + force/k
     * column then (hdf5.md L14), as in vafmd's own log (wire.md §3.1.1); so with a saturate (CLIPPED
     * blocks) or stuck-dropout fault of the run (its record on the "faults" topic), which alters the
     * force and not the ground-truth tip (0.6.1 refused those curves); the file's provenance is the
     * scene of its first curve, as vafmd's log does */
    vafm_record_curve rec = { .samples = &s, .params = &p, .result = &res,
                              .point = s_ju64(json_object_get(r->start, "campaign"), "point"),
                              .run_id = (uint64_t)r->run_id,
                              .client_run_id = json_string_value(json_object_get(r->start, "client_run_id")),
                              .sensitivity_m_per_V = s_jnum(r->start, "sensitivity_m_per_V"),
                              .measured_force = json_is_true(json_object_get(json_object_get(r->start, "detector"), "on")) ||
                                                r->clipped || r->altered };
    res.index = s_ju64(r->start, "index");
    if ((rc = vafm_recorder_append(L->w, &rec, &e)) != 0) {
        vafm_cli_conn_err(L->x, "%s: run %" PRId64 ": %s%s%s", L->out, r->run_id, e.message, e.field[0] ? " at " : "",
              e.field);
        return VAFM_CLI_CONN_RUNTIME;
    }
    L->curves_written++;
    return 0;
}

/* A run.end arrived for the run being recorded: check it is complete, write it. 0 or an exit status. */
static int s_run_end(s_listen *L, s_run *r, const vafm_client_msg *m)
{
    json_t *end = json_loads(m->json, 0, NULL);
    int rc = 0;
    const char *kind = json_string_value(json_object_get(r->start, "kind"));
    if (m->gap)
        r->gaps += m->gap; /* blocks lost at the very end show only in run.end's last_seq */
    size_t nan = 0; /* samples with a NaN measured signal: a detector dropout, recorded as it came */
    for (size_t i = 0; i < r->n; i++)
        nan += isnan(r->col[VAFM_CH_DEFLECTION][i]) || isnan(r->col[VAFM_CH_FORCE][i]) ||
               (r->map[VAFM_CH_VDEFLECTION] >= 0 && isnan(r->col[VAFM_CH_VDEFLECTION][i]));
    if (r->gaps) {
        vafm_cli_conn_err(L->x, "run %" PRId64 ": %" PRIu64 " data block(s) lost (sequence gap): not written", r->run_id,
              r->gaps);
        rc = VAFM_CLI_CONN_RUNTIME;
    } else if (r->restarted) {
        vafm_cli_conn_err(L->x, "run %" PRId64 ": the publisher restarted (new session) during the run: not written", r->run_id);
        rc = VAFM_CLI_CONN_RUNTIME;
    } else if (nan && L->h5 && kind && !strcmp(kind, "curve")) {
        vafm_cli_conn_err(L->x, "run %" PRId64 ": %zu sample(s) have NaN measured signals (detector dropout): not written (the "
              "HDF5 layout holds finite values only, hdf5.md L16; record to CSV to keep them as they are)",
              r->run_id, nan);
        rc = VAFM_CLI_CONN_RUNTIME;
    } else if (strcmp(m->status, "ok")) {
        vafm_cli_conn_err(L->x, "run %" PRId64 " ended with status %s: not written", r->run_id, m->status);
        rc = VAFM_CLI_CONN_RUNTIME;
    } else if (m->samples != (int64_t)r->n) {
        vafm_cli_conn_err(L->x, "run %" PRId64 ": received %zu samples, run.end says %" PRId64 ": not written", r->run_id,
              r->n, m->samples);
        rc = VAFM_CLI_CONN_RUNTIME;
    } else if (L->h5 && (!kind || strcmp(kind, "curve"))) {
        L->tunes_skipped++;
        fprintf(stderr, "vafm listen: run %" PRId64 " is a %s: not written (the HDF5 layout holds force curves)\n",
                r->run_id, kind ? kind : "run of unknown kind");
    } else if (r->n == 0) {
        vafm_cli_conn_err(L->x, "run %" PRId64 " has no samples: not written", r->run_id);
        rc = VAFM_CLI_CONN_RUNTIME;
    } else
        rc = L->h5 ? s_write_h5(L, r, end) : s_write_csv(L, r);
    if (!rc && nan)
        fprintf(stderr, "vafm listen: run %" PRId64 ": %zu sample(s) with NaN measured signals (detector dropout), "
                "recorded as they came (nan)\n", r->run_id, nan);
    if (!rc && r->clipped)
        fprintf(stderr, "vafm listen: run %" PRId64 ": %" PRIu64 " block(s) flagged CLIPPED (ADC saturation), "
                "recorded as they came\n", r->run_id, r->clipped);
    if (!rc && L->out && strcmp(L->out, "-"))
        fprintf(stderr, "vafm listen: run %" PRId64 " (%s, index %" PRIu64 "): %zu samples%s\n", r->run_id,
                kind ? kind : "?", s_ju64(r->start, "index"), r->n,
                L->h5 && kind && strcmp(kind, "curve") ? "" : " written");
    if (rc)
        L->runs_bad++;
    json_decref(end);
    return rc;
}

/* The run's kind from its run.start ("curve", "tune", "replay"), "" if unknown. */
static const char *s_run_kind(const s_run *r)
{
    const char *k = json_string_value(json_object_get(r->start, "kind"));
    return k ? k : "";
}

/* run.start of a run: begin recording it (unless it started before we subscribed). */
static int s_run_start(s_listen *L, s_run *r, const vafm_client_msg *m)
{
    s_run_reset(r);
    r->run_id = m->run_id;
    r->active = 1;
    r->start = json_loads(m->json, 0, NULL);
    r->fs = m->sample_rate_Hz;
    /* the time `vafm samples` prints: the centre of the interval with antialias=mean, its end with point */
    const char *aa = json_string_value(json_object_get(json_object_get(r->start, "scene"), "antialias"));
    r->t_off = aa && !strcmp(aa, "point") ? 1.0 : 0.5;
    for (int k = 0; k < S_NCH; k++) {
        r->map[k] = -1;
        for (size_t i = 0; i < m->n_channel_names; i++)
            if (!strcmp(m->channel_names[i], vafm_channels[k].name))
                r->map[k] = (int)i;
        /* live runs stream every VAFM_CHF_LIVE row; a replay streams what its file has (wire.md, replay),
         * at least height and force */
        if (r->map[k] < 0 && (vafm_channels[k].flags & VAFM_CHF_LIVE) &&
            (k == VAFM_CH_HEIGHT || k == VAFM_CH_FORCE || strcmp(s_run_kind(r), "replay"))) {
            vafm_cli_conn_err(L->x, "run %" PRId64 ": the stream has no channel %s", r->run_id, vafm_channels[k].name);
            r->skip = 1;
            return VAFM_CLI_CONN_RUNTIME;
        }
    }
    return 0;
}

static int s_run_data(s_listen *L, s_run *r, const vafm_client_msg *m)
{
    const vafm_wire_header *h = &m->header;
    r->gaps += m->gap;
    if (h->flags & VAFM_WIRE_FLAG_CLIPPED)
        r->clipped++;
    if (m->gap)
        vafm_cli_conn_err(L->x, "run %" PRId64 ": data blocks seq %" PRIu64 "..%" PRIu64 " lost (sequence gap)", r->run_id,
              h->seq - m->gap, h->seq - 1);
    if (h->first_sample != r->n) {
        if (r->n == 0 && !r->gaps) { /* subscribed mid-run: run.start was re-sent, the blocks before lost */
            fprintf(stderr, "vafm listen: run %" PRId64 " was in progress when listen subscribed: skipped\n",
                    r->run_id);
            r->skip = 1;
            return 0;
        }
        if (!r->gaps)
            vafm_cli_conn_err(L->x, "run %" PRId64 ": block %" PRIu64 " starts at sample %" PRIu64 ", expected %zu", r->run_id,
                  h->block_index, h->first_sample, r->n);
        r->gaps += r->gaps ? 0 : 1;
        return 0; /* reported at run.end */
    }
    if (s_run_grow(r, r->n + h->n_samples)) {
        vafm_cli_conn_err(L->x, "out of memory");
        return VAFM_CLI_CONN_RUNTIME;
    }
    const int mt = r->map[VAFM_CH_TIME];
    for (int k = 0; k < S_NCH; k++) {
        if (k == VAFM_CH_TIME) { /* a replay's recorded times, else the sample clock's (below) */
            if (mt >= 0 && (size_t)mt < m->n_channels)
                memcpy(r->col[k] + r->n, m->channels[mt], h->n_samples * sizeof(double));
            continue;
        }
        if (r->map[k] < 0) { /* absent from this replay: NaN here, an empty CSV cell */
            for (size_t i = 0; i < h->n_samples; i++)
                r->col[k][r->n + i] = NAN;
            continue;
        }
        if ((size_t)r->map[k] >= m->n_channels) {
            vafm_cli_conn_err(L->x, "run %" PRId64 ": data block without channel %s", r->run_id, vafm_channels[k].name);
            return VAFM_CLI_CONN_RUNTIME;
        }
        memcpy(r->col[k] + r->n, m->channels[r->map[k]], h->n_samples * sizeof(double));
    }
    for (size_t i = 0; i < h->n_samples; i++) {
        r->seg[r->n + i] = (uint8_t)h->segment;
        if (mt < 0)
            r->col[VAFM_CH_TIME][r->n + i] = ((double)(r->n + i) + r->t_off) / r->fs;
    }
    r->n += h->n_samples;
    return 0;
}

int vafm_cli_listen(int argc, char **argv)
{
    vafm_cli_conn x = {.cmd = "listen", .timeout_ms = VAFM_CLI_CONN_TIMEOUT_MS};
    s_listen L = {.x = &x, .out = "-"};
    long long runs = 1;
    const char *start = NULL, *duration = NULL;
    double duration_s = 0;
    json_int_t index = 0;
    int overwrite = 0, have_index = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        int has_v = i + 1 < argc;
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            printf("%s%s", s_listen_usage, vafm_cli_conn_help);
            return VAFM_CLI_CONN_OK;
        }
        int r = vafm_cli_conn_opt(&x, argc, argv, &i, s_listen_usage);
        if (r < 0)
            return VAFM_CLI_CONN_USAGE;
        if (r > 0)
            continue;
        if ((!strcmp(a, "--out") || !strcmp(a, "-o")) && has_v)
            L.out = argv[++i];
        else if (!strcmp(a, "--runs") && has_v) {
            json_int_t v;
            if (vafm_cli_conn_parse_u64(argv[++i], &v))
                return vafm_cli_conn_usage(&x, s_listen_usage, "--runs needs a non-negative integer");
            runs = v;
        } else if (!strcmp(a, "--start") && has_v) {
            start = argv[++i];
            if (strcmp(start, "curve") && strcmp(start, "tune"))
                return vafm_cli_conn_usage(&x, s_listen_usage, "--start is curve or tune");
        } else if (!strcmp(a, "--index") && has_v) {
            if (vafm_cli_conn_parse_u64(argv[++i], &index))
                return vafm_cli_conn_usage(&x, s_listen_usage, "--index needs a non-negative integer");
            have_index = 1;
        } else if (!strcmp(a, "--duration") && has_v) {
            char m[160];
            if (vafm_cli_conn_parse_duration("--duration", argv[++i], 1, &duration_s, m, sizeof m))
                return vafm_cli_conn_usage(&x, s_listen_usage, m); /* inf passed "> 0" in 0.6.1 and was dropped */
            duration = argv[i];
        } else if (!strcmp(a, "--overwrite"))
            overwrite = 1;
        else {
            char m[200];
            snprintf(m, sizeof m, "unexpected argument '%s'", a);
            return vafm_cli_conn_usage(&x, s_listen_usage, m);
        }
    }
    if ((have_index || duration) && !start)
        return vafm_cli_conn_usage(&x, s_listen_usage, "--index and --duration go with --start");
    if (duration && strcmp(start, "tune"))
        return vafm_cli_conn_usage(&x, s_listen_usage, "--duration goes with --start tune");
    if (start)
        runs = 1;
    size_t ol = strlen(L.out);
    L.h5 = ol > 3 && !strcmp(L.out + ol - 3, ".h5");

    /* the output first: a bad path fails before anything is started */
    if (L.h5) {
        vafm_recorder_opts ro;
        vafm_recorder_opts_default(&ro);
        ro.mode = overwrite ? VAFM_RECORD_OVERWRITE : VAFM_RECORD_CREATE; /* durable after every curve */
        vafm_error e = {0};
        if (vafm_recorder_open(&L.w, L.out, &ro, NULL, NULL, &e)) {
            vafm_cli_conn_err(&x, "%s", e.message);
            return VAFM_CLI_CONN_RUNTIME;
        }
    } else {
        /* an existing file is kept unless --overwrite says otherwise (as for FILE.h5) */
        L.csv = strcmp(L.out, "-") ? fopen(L.out, overwrite ? "w" : "wx") : stdout;
        if (!L.csv) {
            if (errno == EEXIST)
                return vafm_cli_conn_usage(&x, s_listen_usage, "the output file exists already; --overwrite replaces it");
            vafm_cli_conn_err(&x, "cannot open '%s' for writing: %s", L.out, strerror(errno));
            return VAFM_CLI_CONN_RUNTIME;
        }
        vafm_channels_csv_head(L.csv, VAFM_CH_SEGMENT_CSV); /* core/channels.h's columns, then listen's */
        fprintf(L.csv, ",%s,run_id\n", vafm_channels[VAFM_CH_VDEFLECTION].name);
    }
    struct sigaction sa, old_int, old_term;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = s_on_signal;
    sigaction(SIGINT, &sa, &old_int);
    sigaction(SIGTERM, &sa, &old_term);

    int rc = vafm_cli_conn_open(&x);
    if (!rc)
        rc = vafm_cli_conn_subscribe(&x);
    if (!rc)
        fprintf(stderr, "vafm listen: subscribed to %s\n", x.pub ? x.pub : x.pub_default ? x.pub_default
                                                                         : VAFM_CLIENT_DEFAULT_PUB);
    int64_t want = -1; /* with --start: the run to record */
    if (!rc && start) {
        json_t *req = json_pack("{s:s,s:I}", "cmd", start, "index", index), *reply = NULL;
        if (duration)
            json_object_set_new(req, "duration_s", json_real(duration_s)); /* finite: checked above */
        if ((rc = vafm_cli_conn_send(&x, req, &reply)) == 0)
            want = json_integer_value(json_object_get(reply, "run_id"));
        json_decref(reply);
    }
    s_run r = {.run_id = -1};
    vafm_client_msg m = {0};
    int failed = 0, silent_ms = 0;
    int64_t session = -1; /* the publisher's stream session: a change is a restart (protocol/faults.md) */
    double hb_uptime = -1; /* the last heartbeat's uptime_s: beats keep a 1 s grid, a stall skips some */
    while (!rc && !s_stop && (runs == 0 || L.runs_done < (uint64_t)runs)) {
        vafm_error e = {0};
        int q = vafm_client_receive(x.c, &m, 250, &e);
        silent_ms = q == VAFM_EABORT ? silent_ms + 250 : 0;
        if (q == VAFM_EABORT) {
            if (silent_ms >= VAFM_CLI_CONN_SILENCE_MS) { /* no heartbeat either: the daemon is gone */
                vafm_cli_conn_err(&x, "nothing received for %d s (no heartbeat): is vafmd running?",
                                  VAFM_CLI_CONN_SILENCE_MS / 1000);
                rc = VAFM_CLI_CONN_RUNTIME;
            }
            continue;
        }
        if (q) {
            vafm_cli_conn_err(&x, "%s", e.message);
            rc = VAFM_CLI_CONN_RUNTIME;
            break;
        }
        /* faults the stream shows (protocol/faults.md): a publisher restart, a stall, a truncated run */
        int64_t sess = -1;
        double up = -1;
        if (m.kind == VAFM_MSG_DATA)
            sess = m.header.session ? (int64_t)m.header.session : -1;
        else if (m.kind == VAFM_MSG_HEARTBEAT && m.json) {
            json_t *hb = json_loads(m.json, 0, NULL);
            if (json_is_integer(json_object_get(hb, "session")))
                sess = json_integer_value(json_object_get(hb, "session"));
            if (json_is_number(json_object_get(hb, "uptime_s")))
                up = json_number_value(json_object_get(hb, "uptime_s"));
            json_decref(hb);
        }
        if (sess > 0 && sess != session) {
            if (session >= 0) {
                vafm_cli_conn_err(&x, "the publisher restarted: stream session %" PRId64 " -> %" PRId64 " (sequence numbers start "
                      "again)", session, sess);
                if (r.active && !r.skip)
                    r.restarted = 1;
            }
            session = sess;
        }
        if (up >= 0) {
            if (hb_uptime >= 0 && up - hb_uptime >= 1.5)
                vafm_cli_conn_err(&x, "the stream stalled: no message for %.1f s (heartbeats included)", up - hb_uptime);
            hb_uptime = up;
        }
        if (m.kind == VAFM_MSG_OTHER && !strcmp(m.topic, "faults") && m.json) {
            /* a controller fault that altered the force of the run being recorded (the client library
             * leaves this topic unparsed: run_id -1) */
            json_t *fr = json_loads(m.json, 0, NULL);
            const char *kind = json_string_value(json_object_get(fr, "kind"));
            const json_t *rid = json_object_get(fr, "run_id");
            if (r.active && !r.skip && json_is_integer(rid) && json_integer_value(rid) == r.run_id && kind &&
                (!strcmp(kind, "saturate") || !strcmp(kind, "dropout")))
                r.altered = 1;
            json_decref(fr);
            continue;
        }
        if (r.active && !r.skip && m.run_id != r.run_id &&
            (m.kind == VAFM_MSG_RUN_START || m.kind == VAFM_MSG_HEARTBEAT ||
             (m.kind == VAFM_MSG_OTHER && !strcmp(m.topic, "campaign.end")))) {
            /* the daemon is past the run (idle, or another run) and its run.end never came */
            vafm_cli_conn_err(&x, "run %" PRId64 ": no run.end (the stream stopped mid-run: truncated, or its end was lost) "
                  "after %zu samples: not written", r.run_id, r.n);
            failed = 1;
            L.runs_done++;
            L.runs_bad++;
            s_run_reset(&r);
            if (runs && L.runs_done >= (uint64_t)runs)
                break;
        }
        if (m.run_id < 0 || (want >= 0 && m.run_id != want)) {
            if (m.gap) { /* maybe with the run.start of a run we then miss */
                vafm_cli_conn_err(&x, "%" PRIu64 " data block(s) lost (sequence gap before seq %" PRIu64
                      ") outside a run being recorded", m.gap, m.kind == VAFM_MSG_DATA ? m.header.seq
                                                                                      : (uint64_t)m.last_seq + 1);
                failed = 1;
            }
            continue;
        }
        if (m.kind == VAFM_MSG_RUN_START) {
            if (!(r.active && r.run_id == m.run_id)) /* a repeated run.start (a new subscriber) is ignored */
                failed |= s_run_start(&L, &r, &m) != 0;
        } else if (!r.active || r.run_id != m.run_id || r.skip) {
            if (m.gap) { /* data, or a run.end whose last_seq reveals blocks lost at the end */
                vafm_cli_conn_err(&x, "%" PRIu64 " data block(s) lost (sequence gap before seq %" PRIu64
                      ") outside a run being recorded", m.gap, m.kind == VAFM_MSG_DATA ? m.header.seq
                                                                                      : (uint64_t)m.last_seq + 1);
                failed = 1;
            }
            if (m.kind == VAFM_MSG_RUN_END && r.run_id == m.run_id)
                s_run_reset(&r); /* a skipped run */
        } else if (m.kind == VAFM_MSG_DATA) {
            rc = s_run_data(&L, &r, &m);
        } else if (m.kind == VAFM_MSG_EVENT && m.event_sample >= 0 && m.segment_to >= 0) {
            /* a segment change inside a block: the event follows that block (wire.md §3.4) */
            for (size_t i = (size_t)m.event_sample; i < r.n; i++)
                r.seg[i] = (uint8_t)m.segment_to;
        } else if (m.kind == VAFM_MSG_RUN_END) {
            failed |= s_run_end(&L, &r, &m) != 0;
            L.runs_done++;
            s_run_reset(&r);
        }
    }
    if (!rc && s_stop && r.active)
        fprintf(stderr, "vafm listen: interrupted during run %" PRId64 ": not written\n", r.run_id);
    vafm_client_msg_clear(&m);
    s_run_free(&r);
    vafm_cli_conn_close(&x);
    sigaction(SIGINT, &old_int, NULL);
    sigaction(SIGTERM, &old_term, NULL);
    if (L.w) {
        vafm_error e = {0};
        if (vafm_recorder_close(&L.w, NULL, &e)) {
            vafm_cli_conn_err(&x, "closing %s: %s", L.out, e.message);
            rc = VAFM_CLI_CONN_RUNTIME;
        }
    } else if (L.csv && L.csv != stdout && fclose(L.csv)) {
        vafm_cli_conn_err(&x, "writing '%s' failed", L.out);
        rc = VAFM_CLI_CONN_RUNTIME;
    }
    if (L.out && strcmp(L.out, "-"))
        fprintf(stderr, "vafm listen: %" PRIu64 " run(s) received, %" PRIu64 " incomplete or failed, %" PRIu64
                " written to %s\n", L.runs_done, L.runs_bad, L.h5 ? L.curves_written : L.runs_done - L.runs_bad,
                L.out);
    return rc ? rc : failed ? VAFM_CLI_CONN_RUNTIME : VAFM_CLI_CONN_OK;
}

