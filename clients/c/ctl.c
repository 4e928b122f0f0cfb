/* SPDX-License-Identifier: MIT */
/* vafm-ctl: command-line control of a running vafmd (protocol/wire.md) through the C client.
 * Kept apart from the vafm CLI so that the core CLI does not depend on ZeroMQ. Exit status: 0 success,
 * 1 runtime failure (no reply, daemon error, gap in a recording), 2 usage. */
#include <errno.h>
#include <inttypes.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "vafm/client.h"

enum { S_EXIT_OK = 0, S_EXIT_RUNTIME = 1, S_EXIT_USAGE = 2 };
#define S_TIMEOUT_MS 10000

static const char *s_usage =
    "usage: vafm-ctl [--endpoint E] [--pub E] [--timeout MS] COMMAND [ARGS]\n"
    "commands:\n"
    "  hello | status | presets | abort | shutdown   send the command, print the reply (JSON)\n"
    "  get [NAME...]                 values of scene parameters/settings (all without NAME)\n"
    "  set NAME=VALUE...             set values (VALUE as JSON if it parses, else a string);\n"
    "                                preset=NAME applies a preset first\n"
    "  curve [--index I] [--wait]    start a force curve; --wait prints its run.end\n"
    "  tune SECONDS [--index I] [--wait]   start a thermal tune\n"
    "  record --out FILE.csv [--index I]   start a curve and write its samples as CSV\n"
    "                                (columns of protocol/csv.md `vafm samples`, plus vDeflection_V)\n"
    "options:\n"
    "  --endpoint E   command endpoint (default " VAFM_CLIENT_DEFAULT_REP ")\n"
    "  --pub E        stream endpoint (default: for tcp://HOST:PORT the next port, else " VAFM_CLIENT_DEFAULT_PUB ")\n"
    "  --timeout MS   reply timeout (default 10000)\n"
    "  --curve FILE   CURVE keys (a daemon with curve_secret_key): JSON {\"server_public_key\": Z85,\n"
    "                 \"public_key\": Z85, \"secret_key\": Z85} (a file, so the secret is not in `ps`)\n";

static int s_usage_error(const char *what)
{
    fprintf(stderr, "vafm-ctl: %s\n%s", what, s_usage);
    return S_EXIT_USAGE;
}

/* The stream endpoint next to a tcp command endpoint (vafmd's defaults are 5555/5556). */
static char *s_default_pub(const char *rep)
{
    if (!rep || strncmp(rep, "tcp://", 6))
        return NULL;
    const char *colon = strrchr(rep, ':');
    char *end;
    long port = colon ? strtol(colon + 1, &end, 10) : 0;
    if (!colon || *end || port <= 0 || port >= 65535)
        return NULL;
    size_t n = (size_t)(colon - rep) + 8;
    char *p = malloc(n);
    if (p)
        snprintf(p, n, "%.*s:%ld", (int)(colon - rep), rep, port + 1);
    return p;
}

typedef struct s_ctx {
    vafm_client *c;
    int timeout_ms;
} s_ctx;

/* Send a request object (stolen), print the reply; 0 or exit status. Keeps the reply if reply_out. */
static int s_send(s_ctx *x, json_t *req, json_t **reply_out, int print)
{
    char *text = json_dumps(req, JSON_COMPACT);
    json_decref(req);
    if (!text) {
        fprintf(stderr, "vafm-ctl: out of memory\n");
        return S_EXIT_RUNTIME;
    }
    char *reply = NULL;
    vafm_error e = {0};
    int rc = vafm_client_request(x->c, text, x->timeout_ms, &reply, &e);
    free(text);
    if (rc) {
        fprintf(stderr, "vafm-ctl: %s%s%s%s\n", e.message, e.field[0] ? " (field " : "", e.field,
                e.field[0] ? ")" : "");
        free(reply);
        return S_EXIT_RUNTIME;
    }
    json_t *j = json_loads(reply, 0, NULL);
    free(reply);
    if (print) {
        char *pretty = json_dumps(j, JSON_INDENT(2) | JSON_PRESERVE_ORDER);
        if (pretty)
            puts(pretty);
        free(pretty);
    }
    if (reply_out)
        *reply_out = j;
    else
        json_decref(j);
    return S_EXIT_OK;
}

/* Parse I of --index I. */
static int s_parse_index(const char *s, json_int_t *out)
{
    char *end;
    errno = 0;
    long long v = strtoll(s, &end, 10);
    if (errno || *end || end == s || v < 0)
        return -1;
    *out = v;
    return 0;
}

/* Wait for run `run_id`'s run.end and print it. */
static int s_wait_end(s_ctx *x, int64_t run_id)
{
    vafm_client_msg m = {0};
    vafm_error e = {0};
    int rc;
    for (;;) {
        if ((rc = vafm_client_receive(x->c, &m, 30000, &e)) != 0) {
            fprintf(stderr, "vafm-ctl: waiting for the end of run %" PRId64 ": %s\n", run_id, e.message);
            break;
        }
        if (m.kind == VAFM_MSG_RUN_END && m.run_id == run_id) {
            json_t *j = json_loads(m.json, 0, NULL);
            char *pretty = json_dumps(j, JSON_INDENT(2) | JSON_PRESERVE_ORDER);
            if (pretty)
                puts(pretty);
            free(pretty);
            json_decref(j);
            rc = strcmp(m.status, "ok") ? 1 : 0;
            if (rc)
                fprintf(stderr, "vafm-ctl: run %" PRId64 " ended with status %s\n", run_id, m.status);
            break;
        }
    }
    vafm_client_msg_clear(&m);
    return rc ? S_EXIT_RUNTIME : S_EXIT_OK;
}

/* curve/tune/record share argument parsing: --index I, --wait, --out FILE. */
typedef struct s_run_args {
    json_int_t index;
    int have_index, wait;
    const char *out;
} s_run_args;

static int s_parse_run_args(int argc, char **argv, s_run_args *ra, int allow_out)
{
    for (int i = 0; i < argc; i++) {
        if (!strcmp(argv[i], "--index") && i + 1 < argc) {
            if (s_parse_index(argv[++i], &ra->index))
                return s_usage_error("--index needs a non-negative integer");
            ra->have_index = 1;
        } else if (!strcmp(argv[i], "--wait") && !allow_out) {
            ra->wait = 1;
        } else if (!strcmp(argv[i], "--out") && allow_out && i + 1 < argc) {
            ra->out = argv[++i];
        } else {
            char msg[160];
            snprintf(msg, sizeof msg, "unexpected argument '%s'", argv[i]);
            return s_usage_error(msg);
        }
    }
    return 0;
}

static int s_start_run(s_ctx *x, json_t *req, const s_run_args *ra, int64_t *run_id, int print)
{
    if (ra->have_index)
        json_object_set_new(req, "index", json_integer(ra->index));
    json_t *reply = NULL;
    int rc = s_send(x, req, &reply, print);
    if (rc)
        return rc;
    *run_id = json_integer_value(json_object_get(reply, "run_id"));
    json_decref(reply);
    return 0;
}

static int s_subscribe(s_ctx *x)
{
    vafm_error e = {0};
    if (vafm_client_subscribe(x->c, x->timeout_ms, &e)) {
        fprintf(stderr, "vafm-ctl: %s\n", e.message);
        return S_EXIT_RUNTIME;
    }
    return 0;
}

/* ---- record ------------------------------------------------------------------------------------- */

typedef struct s_rec {
    double *col[5]; /* height, deflection, force, vDeflection, tip */
    int *seg;
    size_t n, cap;
} s_rec;

static int s_rec_grow(s_rec *r, size_t need)
{
    if (need <= r->cap)
        return 0;
    size_t cap = r->cap ? r->cap : 4096;
    while (cap < need)
        cap *= 2;
    for (int k = 0; k < 5; k++) {
        double *p = realloc(r->col[k], cap * sizeof *p);
        if (!p)
            return -1;
        r->col[k] = p;
    }
    int *s = realloc(r->seg, cap * sizeof *s);
    if (!s)
        return -1;
    r->seg = s;
    r->cap = cap;
    return 0;
}

static void s_rec_free(s_rec *r)
{
    for (int k = 0; k < 5; k++)
        free(r->col[k]);
    free(r->seg);
}

static int s_record(s_ctx *x, int argc, char **argv)
{
    s_run_args ra = {0};
    int rc = s_parse_run_args(argc, argv, &ra, 1);
    if (rc)
        return rc;
    if (!ra.out)
        return s_usage_error("record needs --out FILE.csv");
    if ((rc = s_subscribe(x)) != 0)
        return rc;
    int64_t run_id = -1;
    if ((rc = s_start_run(x, json_pack("{s:s}", "cmd", "curve"), &ra, &run_id, 0)) != 0)
        return rc;

    static const char *names[5] = {"height_m", "deflection_m", "force_N", "vDeflection_V", "tip_m"};
    int map[5] = {-1, -1, -1, -1, -1}; /* stream channel of each column */
    s_rec r = {0};
    double fs = 0, t_off = 0.5; /* antialias=mean: a sample is the centre of its interval */
    int started = 0;
    vafm_client_msg m = {0};
    vafm_error e = {0};
    rc = S_EXIT_RUNTIME;
    for (;;) {
        if (vafm_client_receive(x->c, &m, 30000, &e)) {
            fprintf(stderr, "vafm-ctl: recording run %" PRId64 ": %s\n", run_id, e.message);
            break;
        }
        if (m.run_id != run_id)
            continue;
        if (m.gap) {
            fprintf(stderr, "vafm-ctl: %" PRIu64 " data block(s) lost (sequence gap): the recording is incomplete\n",
                    m.gap);
            break;
        }
        if (m.kind == VAFM_MSG_RUN_START && !started) {
            started = 1;
            fs = m.sample_rate_Hz;
            for (int k = 0; k < 5; k++)
                for (size_t i = 0; i < m.n_channel_names; i++)
                    if (!strcmp(m.channel_names[i], names[k]))
                        map[k] = (int)i;
            json_t *j = json_loads(m.json, 0, NULL);
            const char *aa = json_string_value(json_object_get(json_object_get(j, "scene"), "antialias"));
            if (aa && !strcmp(aa, "point"))
                t_off = 1.0; /* point sampling: the value at the end of the interval */
            json_decref(j);
            for (int k = 0; k < 5; k++)
                if (map[k] < 0) {
                    fprintf(stderr, "vafm-ctl: the stream has no channel %s\n", names[k]);
                    goto out;
                }
        } else if (m.kind == VAFM_MSG_DATA && started) {
            const vafm_wire_header *h = &m.header;
            if (h->first_sample != r.n) {
                fprintf(stderr, "vafm-ctl: block %" PRIu64 " starts at sample %" PRIu64 ", expected %zu\n",
                        h->block_index, h->first_sample, r.n);
                goto out;
            }
            if (s_rec_grow(&r, r.n + h->n_samples)) {
                fprintf(stderr, "vafm-ctl: out of memory\n");
                goto out;
            }
            for (int k = 0; k < 5; k++) {
                if ((size_t)map[k] >= m.n_channels) {
                    fprintf(stderr, "vafm-ctl: data block without channel %s\n", names[k]);
                    goto out;
                }
                memcpy(r.col[k] + r.n, m.channels[map[k]], h->n_samples * sizeof(double));
            }
            for (size_t i = 0; i < h->n_samples; i++)
                r.seg[r.n + i] = h->segment;
            r.n += h->n_samples;
        } else if (m.kind == VAFM_MSG_EVENT && started && m.event_sample >= 0 && m.segment_to >= 0) {
            /* a segment change inside a block: the event follows that block (wire.md §3.4) */
            for (size_t i = (size_t)m.event_sample; i < r.n; i++)
                r.seg[i] = m.segment_to;
        } else if (m.kind == VAFM_MSG_RUN_END) {
            if (strcmp(m.status, "ok")) {
                fprintf(stderr, "vafm-ctl: run %" PRId64 " ended with status %s\n", run_id, m.status);
                goto out;
            }
            if (m.samples != (int64_t)r.n) {
                fprintf(stderr, "vafm-ctl: received %zu samples, run.end says %" PRId64 "\n", r.n, m.samples);
                goto out;
            }
            rc = S_EXIT_OK;
            break;
        }
    }
out:
    vafm_client_msg_clear(&m);
    if (rc == S_EXIT_OK) {
        FILE *f = strcmp(ra.out, "-") ? fopen(ra.out, "w") : stdout;
        if (!f) {
            fprintf(stderr, "vafm-ctl: cannot open '%s': %s\n", ra.out, strerror(errno));
            rc = S_EXIT_RUNTIME;
        } else {
            int bad = fputs("time_s,height_m,deflection_m,force_N,tip_m,segment,vDeflection_V\n", f) < 0;
            for (size_t i = 0; i < r.n && !bad; i++)
                bad = fprintf(f, "%.17g,%.17g,%.17g,%.17g,%.17g,%d,%.17g\n", ((double)i + t_off) / fs, r.col[0][i],
                              r.col[1][i], r.col[2][i], r.col[4][i], r.seg[i], r.col[3][i]) < 0;
            bad |= f == stdout ? fflush(f) != 0 : fclose(f) != 0;
            if (bad) {
                fprintf(stderr, "vafm-ctl: writing '%s' failed\n", ra.out);
                rc = S_EXIT_RUNTIME;
            } else if (f != stdout) {
                fprintf(stderr, "vafm-ctl: run %" PRId64 ": %zu samples written to %s\n", run_id, r.n, ra.out);
            }
        }
    }
    s_rec_free(&r);
    return rc;
}

/* ---- main --------------------------------------------------------------------------------------- */

/* NAME=VALUE: VALUE as JSON when it parses as a scalar (numbers, true/false), else as a string. */
static json_t *s_value(const char *v)
{
    json_t *j = json_loads(v, JSON_DECODE_ANY, NULL);
    if (j && (json_is_number(j) || json_is_boolean(j) || json_is_null(j)))
        return j;
    json_decref(j);
    return json_string(v);
}

static int s_dispatch(s_ctx *x, int argc, char **argv)
{
    const char *cmd = argv[0];
    static const char *const simple[] = {"hello", "status", "presets", "abort", "shutdown"};
    for (size_t i = 0; i < sizeof simple / sizeof simple[0]; i++)
        if (!strcmp(cmd, simple[i])) {
            if (argc > 1)
                return s_usage_error("this command takes no arguments");
            return s_send(x, json_pack("{s:s}", "cmd", cmd), NULL, 1);
        }
    if (!strcmp(cmd, "get")) {
        json_t *req = json_pack("{s:s}", "cmd", "get");
        if (argc > 1) {
            json_t *names = json_array();
            for (int i = 1; i < argc; i++)
                json_array_append_new(names, json_string(argv[i]));
            json_object_set_new(req, "names", names);
        }
        return s_send(x, req, NULL, 1);
    }
    if (!strcmp(cmd, "set")) {
        if (argc < 2)
            return s_usage_error("set needs NAME=VALUE");
        json_t *req = json_pack("{s:s}", "cmd", "set"), *values = json_object();
        for (int i = 1; i < argc; i++) {
            const char *eq = strchr(argv[i], '=');
            if (!eq || eq == argv[i]) {
                json_decref(req);
                json_decref(values);
                return s_usage_error("set arguments are NAME=VALUE");
            }
            char name[128];
            snprintf(name, sizeof name, "%.*s", (int)(eq - argv[i]), argv[i]);
            if (!strcmp(name, "preset"))
                json_object_set_new(req, "preset", json_string(eq + 1));
            else
                json_object_set_new(values, name, s_value(eq + 1));
        }
        if (json_object_size(values))
            json_object_set_new(req, "values", values);
        else
            json_decref(values);
        return s_send(x, req, NULL, 1);
    }
    if (!strcmp(cmd, "curve") || !strcmp(cmd, "tune")) {
        int tune = cmd[0] == 't';
        if (tune && argc < 2)
            return s_usage_error("tune needs SECONDS");
        json_t *req = json_pack("{s:s}", "cmd", cmd);
        if (tune) {
            char *end;
            double d = strtod(argv[1], &end);
            if (*end || end == argv[1]) {
                json_decref(req);
                return s_usage_error("tune SECONDS must be a number");
            }
            json_object_set_new(req, "duration_s", json_real(d));
        }
        s_run_args ra = {0};
        int rc = s_parse_run_args(argc - 1 - tune, argv + 1 + tune, &ra, 0);
        if (rc || (ra.wait && (rc = s_subscribe(x)) != 0)) {
            json_decref(req);
            return rc;
        }
        int64_t run_id;
        if ((rc = s_start_run(x, req, &ra, &run_id, 1)) != 0)
            return rc;
        return ra.wait ? s_wait_end(x, run_id) : S_EXIT_OK;
    }
    if (!strcmp(cmd, "record"))
        return s_record(x, argc - 1, argv + 1);
    char msg[160];
    snprintf(msg, sizeof msg, "unknown command '%s'", cmd);
    return s_usage_error(msg);
}

static int s_set_curve(vafm_client *c, const char *path)
{
    json_error_t je;
    json_t *j = json_load_file(path, 0, &je);
    if (!j) {
        fprintf(stderr, "vafm-ctl: --curve %s: %s\n", path, je.text);
        return S_EXIT_USAGE;
    }
    const char *sp = json_string_value(json_object_get(j, "server_public_key"));
    const char *cp = json_string_value(json_object_get(j, "public_key"));
    const char *cs = json_string_value(json_object_get(j, "secret_key"));
    vafm_error e = {0};
    int rc = sp && cp && cs ? vafm_client_set_curve(c, sp, cp, cs, &e) : VAFM_EINVAL;
    json_decref(j);
    if (rc) {
        fprintf(stderr, "vafm-ctl: --curve %s: %s\n", path,
                sp && cp && cs ? e.message : "needs server_public_key, public_key and secret_key (Z85)");
        return rc == VAFM_EINVAL ? S_EXIT_USAGE : S_EXIT_RUNTIME;
    }
    return 0;
}

int main(int argc, char **argv)
{
    const char *rep = NULL, *pub = NULL, *curve = NULL;
    s_ctx x = {NULL, S_TIMEOUT_MS};
    int i = 1;
    for (; i < argc && argv[i][0] == '-' && argv[i][1] == '-'; i++) {
        if (!strcmp(argv[i], "--help")) {
            fputs(s_usage, stdout);
            return S_EXIT_OK;
        }
        if (i + 1 >= argc)
            return s_usage_error("option needs a value");
        if (!strcmp(argv[i], "--endpoint"))
            rep = argv[++i];
        else if (!strcmp(argv[i], "--pub"))
            pub = argv[++i];
        else if (!strcmp(argv[i], "--curve"))
            curve = argv[++i];
        else if (!strcmp(argv[i], "--timeout")) {
            char *end;
            long t = strtol(argv[++i], &end, 10);
            if (*end || t <= 0 || t > 3600000)
                return s_usage_error("--timeout needs milliseconds in [1, 3600000]");
            x.timeout_ms = (int)t;
        } else {
            char msg[160];
            snprintf(msg, sizeof msg, "unknown option '%s'", argv[i]);
            return s_usage_error(msg);
        }
    }
    if (i >= argc)
        return s_usage_error("no command");
    char *pub_default = pub ? NULL : s_default_pub(rep);
    vafm_error e = {0};
    if (vafm_client_new(&x.c, rep, pub ? pub : pub_default, &e)) {
        fprintf(stderr, "vafm-ctl: %s\n", e.message);
        free(pub_default);
        return S_EXIT_RUNTIME;
    }
    int rc = curve ? s_set_curve(x.c, curve) : 0;
    if (!rc)
        rc = s_dispatch(&x, argc - i, argv + i);
    vafm_client_destroy(&x.c);
    free(pub_default);
    return rc;
}
