/* SPDX-License-Identifier: MIT */
/*
 * `vafm ctl`, `vafm status` and `vafm listen`: the vafm CLI as a client of a running vafmd
 * (protocol/wire.md), through the C client library (include/vafm/client.h).
 *
 * ctl sends any command (KEY=VALUE arguments become the request's keys) and prints the reply as JSON;
 * status prints the daemon's state for humans; listen subscribes and writes the runs that arrive to CSV
 * (the columns of `vafm samples`, protocol/csv.md, plus vDeflection_V and run_id) or to an HDF5 file of
 * protocol/hdf5.md (one curve group per force curve, with the run's scene as provenance and its curve
 * result as ground truth). A run with lost data blocks (a jump in the header's seq, or run.end's
 * last_seq/samples beyond what arrived) is never written: listen names it on stderr and exits 1.
 * Exit status: 0 success, 1 runtime failure (no reply, daemon error, lost data), 2 usage.
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
#include "cli/cmd_client.h"
#include "record/scene.h"
#include "vafm/client.h"
#include "h5/h5.h"
#include "record/record.h"
#include "vafm/params.h"

enum { S_OK = 0, S_RUNTIME = 1, S_USAGE = 2 };
#define S_TIMEOUT_MS 10000
#define S_STREAM_SILENCE_MS 5000 /* heartbeats come at 1 Hz: 5 s of silence means the daemon is gone */

/* ---- connection options shared by the three commands ----------------------------------------------- */

typedef struct s_conn {
    const char *cmd; /* "ctl", "status", "listen": the prefix of messages */
    const char *rep, *pub, *curve;
    int timeout_ms;
    vafm_client *c;
    char *pub_default;
} s_conn;

static const char *s_conn_help =
    "connection options:\n"
    "  --endpoint E   command endpoint (default " VAFM_CLIENT_DEFAULT_REP "; --rep is the same)\n"
    "  --pub E        stream endpoint (default: for tcp://HOST:PORT the next port, else the one the daemon\n"
    "                 names in its hello)\n"
    "  --timeout MS   reply timeout (default 10000)\n"
    "  --curve FILE   CURVE keys for a daemon with curve_secret_key: JSON {\"server_public_key\": Z85,\n"
    "                 \"public_key\": Z85, \"secret_key\": Z85} (a file, so the secret is not in `ps`)\n"
    "exit status: 0 success, 1 runtime failure (no reply, daemon error, lost data), 2 usage\n";

static void s_err(const s_conn *x, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void s_err(const s_conn *x, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "vafm %s: ", x->cmd);
    vfprintf(stderr, fmt, ap);
    fputc('\n', stderr);
    va_end(ap);
}

static int s_usage(const s_conn *x, const char *usage, const char *what)
{
    s_err(x, "%s", what);
    fprintf(stderr, "%s%s", usage, s_conn_help);
    return S_USAGE;
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

/* Consume a connection option at argv[*i]: 1 consumed, 0 not one, -1 usage error (printed). */
static int s_conn_opt(s_conn *x, int argc, char **argv, int *i, const char *usage)
{
    const char *o = argv[*i];
    if (strcmp(o, "--endpoint") && strcmp(o, "--rep") && strcmp(o, "--pub") && strcmp(o, "--curve") &&
        strcmp(o, "--timeout"))
        return 0;
    if (*i + 1 >= argc) {
        char m[96];
        snprintf(m, sizeof m, "%s needs a value", o);
        s_usage(x, usage, m);
        return -1;
    }
    const char *v = argv[++*i];
    if (!strcmp(o, "--endpoint") || !strcmp(o, "--rep"))
        x->rep = v;
    else if (!strcmp(o, "--pub"))
        x->pub = v;
    else if (!strcmp(o, "--curve"))
        x->curve = v;
    else {
        char *end;
        long t = strtol(v, &end, 10);
        if (*end || end == v || t <= 0 || t > 3600000) {
            s_usage(x, usage, "--timeout needs milliseconds in [1, 3600000]");
            return -1;
        }
        x->timeout_ms = (int)t;
    }
    return 1;
}

static int s_set_curve(s_conn *x)
{
    json_error_t je;
    json_t *j = json_load_file(x->curve, 0, &je);
    if (!j) {
        s_err(x, "--curve %s: %s", x->curve, je.text);
        return S_USAGE;
    }
    const char *sp = json_string_value(json_object_get(j, "server_public_key"));
    const char *cp = json_string_value(json_object_get(j, "public_key"));
    const char *cs = json_string_value(json_object_get(j, "secret_key"));
    vafm_error e = {0};
    int rc = sp && cp && cs ? vafm_client_set_curve(x->c, sp, cp, cs, &e) : VAFM_EINVAL;
    json_decref(j);
    if (rc) {
        s_err(x, "--curve %s: %s", x->curve,
              sp && cp && cs ? e.message : "needs server_public_key, public_key and secret_key (Z85)");
        return rc == VAFM_EINVAL ? S_USAGE : S_RUNTIME;
    }
    return 0;
}

/* Without --pub and with nothing to guess from (an ipc:// command endpoint; for tcp the next port is the
 * daemon's default), the stream endpoint comes from the daemon itself: hello's "stream". */
static void s_stream_from_hello(s_conn *x)
{
    char *reply = NULL;
    vafm_error e = {0};
    int t = x->timeout_ms > 0 && x->timeout_ms < 2000 ? x->timeout_ms : 2000;
    if (vafm_client_request(x->c, "{\"cmd\": \"hello\"}", t, &reply, &e) || !reply)
        return;
    json_t *j = json_loads(reply, 0, NULL);
    free(reply);
    const char *stream = json_string_value(json_object_get(j, "stream"));
    if (stream && (!x->pub_default || strcmp(stream, x->pub_default))) {
        char *dup = strdup(stream);
        vafm_client *c = NULL;
        if (dup && !vafm_client_new(&c, x->rep, dup, &e)) {
            vafm_client_destroy(&x->c);
            x->c = c;
            free(x->pub_default);
            x->pub_default = dup;
            dup = NULL;
        }
        free(dup);
    }
    json_decref(j);
}

static int s_connect(s_conn *x)
{
    x->pub_default = x->pub ? NULL : s_default_pub(x->rep);
    vafm_error e = {0};
    if (vafm_client_new(&x->c, x->rep, x->pub ? x->pub : x->pub_default, &e)) {
        s_err(x, "%s", e.message);
        return S_RUNTIME;
    }
    int rc = x->curve ? s_set_curve(x) : 0;
    if (!rc && !x->pub && !x->pub_default) { /* no tcp port to guess from (ipc://): ask the daemon */
        s_stream_from_hello(x);
        if (x->curve && x->c)
            rc = s_set_curve(x); /* the new client needs its keys too */
    }
    return rc;
}

static void s_disconnect(s_conn *x)
{
    vafm_client_destroy(&x->c);
    free(x->pub_default);
    x->pub_default = NULL;
}

/* Send a request object (stolen); *reply_out gets the parsed ok reply (or NULL). 0 or an exit status. */
static int s_send(s_conn *x, json_t *req, json_t **reply_out)
{
    if (reply_out)
        *reply_out = NULL;
    char *text = req ? json_dumps(req, JSON_COMPACT) : NULL;
    json_decref(req);
    if (!text) {
        s_err(x, "out of memory");
        return S_RUNTIME;
    }
    char *reply = NULL;
    vafm_error e = {0};
    int rc = vafm_client_request(x->c, text, x->timeout_ms, &reply, &e);
    free(text);
    if (rc) {
        const char *code = vafm_client_reply_code(x->c); /* e.message may already start with it */
        int with_code = code[0] && strncmp(e.message, code, strlen(code));
        s_err(x, "%s%s%s%s%s%s", with_code ? code : "", with_code ? ": " : "", e.message,
              e.field[0] ? " (field " : "", e.field, e.field[0] ? ")" : "");
        free(reply);
        return S_RUNTIME;
    }
    json_t *j = json_loads(reply, 0, NULL);
    free(reply);
    if (reply_out)
        *reply_out = j;
    else
        json_decref(j);
    return S_OK;
}

static void s_print_json(json_t *j)
{
    char *pretty = json_dumps(j, JSON_INDENT(2) | JSON_PRESERVE_ORDER);
    if (pretty)
        puts(pretty);
    free(pretty);
}

static int s_subscribe(s_conn *x)
{
    vafm_error e = {0};
    if (vafm_client_subscribe(x->c, x->timeout_ms, &e)) {
        s_err(x, "subscribing to the stream: %s", e.message);
        return S_RUNTIME;
    }
    return 0;
}

/* ---- vafm ctl ------------------------------------------------------------------------------------- */

static const char *s_ctl_usage =
    "usage: vafm ctl [CONNECTION] COMMAND [ARGS] [--wait]\n"
    "Send one command to a running vafmd and print its reply as JSON (protocol/wire.md).\n"
    "  COMMAND [KEY=VALUE...]        any command; each KEY=VALUE becomes a key of the request (VALUE as\n"
    "                                JSON when it parses: numbers, true/false, [lists]; else a string),\n"
    "                                e.g. vafm ctl log path=/tmp/x.h5 overwrite=true\n"
    "  '{\"cmd\": ...}'                a whole request as JSON\n"
    "  get [NAME...]                 scene parameters/settings (all without NAME)\n"
    "  set NAME=VALUE...             set values; preset=NAME applies a preset first; a value with its\n"
    "                                unit (setpoint_N=1nN, v_approach_m_per_s=2um/s) is sent in SI\n"
    "  curve [--index I]             start a force curve\n"
    "  tune [SECONDS] [--index I]    start a thermal tune\n"
    "  --wait                        (curve, tune, replay, campaign) subscribe first and print the run.end\n"
    "                                (campaign: campaign.end) when it comes; exit 1 unless status ok\n"
    "Commands (protocol/wire.md; vafmd --help says what each does):\n "
#define VAFMD_COMMAND(ID, NAME, KEYS, FLAGS, HANDLER, HELP) " " NAME
#include "daemon/commands.def"
    "\n";

/* VALUE as JSON when it parses as a number, boolean, null, array or object, else as a string. NULL when it
 * cannot be sent as it was meant: a number beyond a double (1e400: jansson refuses it, and sent as the
 * string "1e400" it would be the daemon's type error instead of ours), or text that is not UTF-8. */
static json_t *s_value(const char *v)
{
    json_error_t je;
    json_t *j = json_loads(v, JSON_DECODE_ANY, &je);
    if (j && !json_is_string(j))
        return j;
    json_decref(j);
#if JANSSON_VERSION_HEX >= 0x020b00
    if (!j && json_error_code(&je) == json_error_numeric_overflow)
        return NULL;
#endif
    return json_string(v);
}

/* set: a scene value typed with its unit ("1nN", "2um/s") goes out as the SI number the CLI's options make of
 * it (vafm_units_parse); anything else (a choice, "paper", a typo) goes out as the string, for the daemon to
 * judge. 0.6.2 sent "1nN" as a string and the daemon answered "expected a number". Takes v, returns one. */
static json_t *s_set_units(const char *key, json_t *v)
{
    const vafm_param_info *f = vafm_params_field_find(key);
    double d;
    if (f && f->kind == VAFM_PARAM_REAL && f->unit[0] && !vafm_units_parse(key, json_string_value(v), f->unit, &d, NULL)) {
        json_t *n = json_real(d);
        if (n) {
            json_decref(v);
            return n;
        }
    }
    return v;
}

/* A duration in seconds as a tune takes it: finite, within tune_duration_s's range (the daemon's check,
 * made here so that nothing is sent); lo_open: 0 itself is refused. @return 0, or -1 (message in m). */
static int s_parse_duration(const char *opt, const char *text, int lo_open, double *out, char *m, size_t mlen)
{
    const vafm_param_info *f = vafm_params_field_find("tune_duration_s");
    double lo = f ? f->min : 0.0, hi = f ? f->max : 1e5;
    char *end;
    double d = strtod(text, &end);
    if (end == text || *end || !(d >= lo && d <= hi) || (lo_open && !(d > lo))) { /* NaN fails too */
        snprintf(m, mlen, "%s needs seconds in %s%g, %g], not '%.60s'", opt, lo_open ? "(" : "[", lo, hi, text);
        return -1;
    }
    *out = d;
    return 0;
}

static int s_parse_u64(const char *s, json_int_t *out)
{
    char *end;
    errno = 0;
    long long v = strtoll(s, &end, 10);
    if (errno || *end || end == s || v < 0)
        return -1;
    *out = v;
    return 0;
}

/* Wait for the end of run `run_id` (or of campaign `campaign_id` ≥ 0) and print it. */
static int s_wait_end(s_conn *x, int64_t run_id, int64_t campaign_id)
{
    vafm_client_msg m = {0};
    vafm_error e = {0};
    int rc = S_RUNTIME;
    for (;;) {
        if (vafm_client_receive(x->c, &m, S_STREAM_SILENCE_MS, &e)) {
            s_err(x, "waiting for the end of %s %" PRId64 ": %s", campaign_id >= 0 ? "campaign" : "run",
                  campaign_id >= 0 ? campaign_id : run_id, e.message);
            break;
        }
        json_t *j = NULL;
        if (campaign_id < 0 && m.kind == VAFM_MSG_RUN_END && m.run_id == run_id)
            j = json_loads(m.json, 0, NULL);
        else if (campaign_id >= 0 && m.kind == VAFM_MSG_OTHER && !strcmp(m.topic, "campaign.end") && m.json) {
            j = json_loads(m.json, 0, NULL);
            if (json_integer_value(json_object_get(j, "campaign_id")) != campaign_id) {
                json_decref(j);
                j = NULL;
            }
        }
        if (!j)
            continue;
        s_print_json(j);
        const char *st = json_string_value(json_object_get(j, "status"));
        rc = st && !strcmp(st, "ok") ? S_OK : S_RUNTIME;
        if (rc)
            s_err(x, "%s ended with status %s", campaign_id >= 0 ? "campaign" : "run", st ? st : "(none)");
        json_decref(j);
        break;
    }
    vafm_client_msg_clear(&m);
    return rc;
}

static int s_ctl_run(s_conn *x, int argc, char **argv)
{
    const char *cmd = argv[0];
    json_t *req;
    int wait = 0;
    if (argv[0][0] == '{') {
        json_error_t je;
        req = json_loads(argv[0], 0, &je);
        if (!json_is_object(req)) {
            json_decref(req);
            char m[240];
            snprintf(m, sizeof m, "the request is not a JSON object: %s", je.text);
            return s_usage(x, s_ctl_usage, m);
        }
        cmd = json_string_value(json_object_get(req, "cmd"));
        cmd = cmd ? cmd : "";
    } else
        req = json_pack("{s:s}", "cmd", cmd);
    int is_set = !strcmp(cmd, "set"), is_get = !strcmp(cmd, "get"), is_tune = !strcmp(cmd, "tune");
    int waitable = !strcmp(cmd, "curve") || is_tune || !strcmp(cmd, "campaign") || !strcmp(cmd, "replay");
    json_t *values = is_set ? json_object() : NULL, *names = is_get ? json_array() : NULL;
    int rc = 0;
    for (int i = 1; i < argc && !rc; i++) {
        const char *a = argv[i], *eq = strchr(a, '=');
        char msg[200];
        if (!strcmp(a, "--wait") && waitable)
            wait = 1;
        else if (!strcmp(a, "--index") && waitable && i + 1 < argc) {
            json_int_t v;
            if (s_parse_u64(argv[++i], &v))
                rc = s_usage(x, s_ctl_usage, "--index needs a non-negative integer");
            else
                json_object_set_new(req, "index", json_integer(v));
        } else if (is_get && !eq && a[0] != '-') {
            if (json_array_append_new(names, json_string(a))) /* NULL for text that is not UTF-8 */
                rc = s_usage(x, s_ctl_usage, "get: a NAME is not UTF-8 text");
        } else if (is_tune && i == 1 && !eq && strncmp(a, "--", 2)) { /* -1 too: refused with the range */
            /* json_real(NaN or inf) is NULL and json_object_set_new drops the key: 0.6.1 sent no duration
             * then, and the daemon ran the scene's tune */
            double d;
            if (s_parse_duration("tune SECONDS", a, 0, &d, msg, sizeof msg))
                rc = s_usage(x, s_ctl_usage, msg);
            else
                json_object_set_new(req, "duration_s", json_real(d));
        } else if (eq && eq != a) {
            char key[128];
            snprintf(key, sizeof key, "%.*s", (int)(eq - a), a);
            json_t *v = s_value(eq + 1);
            if (is_set && json_is_string(v))
                v = s_set_units(key, v);
            if (!v || json_object_set_new(is_set && strcmp(key, "preset") ? values : req, key, v)) {
                json_t *text = json_string(eq + 1); /* NULL: not UTF-8; else a number beyond a double */
                if (text)
                    snprintf(msg, sizeof msg, "%.60s=%.60s: a number beyond the range of a double (numbers must "
                             "be finite)", key, eq + 1);
                else
                    snprintf(msg, sizeof msg, "%.60s: the value is not UTF-8 text", key);
                json_decref(text);
                rc = s_usage(x, s_ctl_usage, msg);
            }
        } else {
            snprintf(msg, sizeof msg, "unexpected argument '%s' (arguments are KEY=VALUE)", a);
            rc = s_usage(x, s_ctl_usage, msg);
        }
    }
    if (!rc && is_set && !json_object_size(values) && !json_object_get(req, "preset"))
        rc = s_usage(x, s_ctl_usage, "set needs NAME=VALUE");
    if (values && json_object_size(values))
        json_object_set(req, "values", values);
    if (names && json_array_size(names))
        json_object_set(req, "names", names);
    json_decref(values);
    json_decref(names);
    if (rc) {
        json_decref(req);
        return rc;
    }
    if ((rc = s_connect(x)) != 0 || (wait && (rc = s_subscribe(x)) != 0)) {
        json_decref(req);
        return rc;
    }
    json_t *reply = NULL;
    if ((rc = s_send(x, req, &reply)) != 0)
        return rc;
    s_print_json(reply);
    fflush(stdout);
    if (wait) {
        json_t *cid = json_object_get(reply, "campaign_id");
        rc = s_wait_end(x, json_integer_value(json_object_get(reply, "run_id")),
                        json_is_integer(cid) ? json_integer_value(cid) : -1);
    }
    json_decref(reply);
    return rc;
}

int vafm_cli_ctl(int argc, char **argv)
{
    s_conn x = {.cmd = "ctl", .timeout_ms = S_TIMEOUT_MS};
    int i = 1;
    for (; i < argc && argv[i][0] == '-' && argv[i][1] == '-'; i++) {
        if (!strcmp(argv[i], "--help")) {
            printf("%s%s", s_ctl_usage, s_conn_help);
            return S_OK;
        }
        int r = s_conn_opt(&x, argc, argv, &i, s_ctl_usage);
        if (r < 0)
            return S_USAGE;
        if (r == 0) {
            char m[160];
            snprintf(m, sizeof m, "unknown option '%s'", argv[i]);
            return s_usage(&x, s_ctl_usage, m);
        }
    }
    if (i >= argc)
        return s_usage(&x, s_ctl_usage, "no command");
    int rc = s_ctl_run(&x, argc - i, argv + i);
    s_disconnect(&x);
    return rc;
}

/* ---- vafm status ---------------------------------------------------------------------------------- */

static const char *s_status_usage =
    "usage: vafm status [CONNECTION] [--json]\n"
    "The state of a running vafmd: run in progress, counters, pacing, logging, security.\n"
    "  --json   print the daemon's status reply as it is\n";

static double s_num(json_t *o, const char *k)
{
    json_t *v = json_object_get(o, k);
    return json_is_number(v) ? json_number_value(v) : NAN;
}

static const char *s_text(json_t *o, const char *k, const char *dflt)
{
    const char *s = json_string_value(json_object_get(o, k));
    return s ? s : dflt;
}

int vafm_cli_status(int argc, char **argv)
{
    s_conn x = {.cmd = "status", .timeout_ms = S_TIMEOUT_MS};
    int as_json = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--help")) {
            printf("%s%s", s_status_usage, s_conn_help);
            return S_OK;
        }
        if (!strcmp(argv[i], "--json")) {
            as_json = 1;
            continue;
        }
        int r = s_conn_opt(&x, argc, argv, &i, s_status_usage);
        if (r < 0)
            return S_USAGE;
        if (r == 0) {
            char m[160];
            snprintf(m, sizeof m, "unexpected argument '%s'", argv[i]);
            return s_usage(&x, s_status_usage, m);
        }
    }
    int rc = s_connect(&x);
    json_t *st = NULL, *hello = NULL;
    if (!rc)
        rc = s_send(&x, json_pack("{s:s}", "cmd", "status"), &st);
    if (!rc && !as_json)
        rc = s_send(&x, json_pack("{s:s}", "cmd", "hello"), &hello);
    if (!rc && as_json)
        s_print_json(st);
    else if (!rc) {
        const char *rep = x.rep ? x.rep : VAFM_CLIENT_DEFAULT_REP;
        printf("daemon       %s %s (protocol %d, library %s) at %s\n", s_text(hello, "daemon", "?"),
               s_text(hello, "daemon_version", "?"), (int)s_num(hello, "protocol_version"),
               s_text(hello, "library_version", "?"), rep);
        json_t *run = json_object_get(st, "run_id"), *last = json_object_get(st, "last_run_id");
        printf("state        %s", s_text(st, "state", "?"));
        if (json_is_integer(run))
            printf(", run %" JSON_INTEGER_FORMAT " (%.0f samples so far)", json_integer_value(run),
                   s_num(st, "run_samples"));
        else if (json_is_integer(last))
            printf(", last run %" JSON_INTEGER_FORMAT " (%.0f samples)", json_integer_value(last),
                   s_num(st, "run_samples"));
        printf("\nruns         %.0f started, %.0f done\n", s_num(st, "runs_started"), s_num(st, "runs_done"));
        printf("stream       %.0f samples in %.0f blocks, %.0f late (worst %.3g ms), %.0f overflows\n",
               s_num(st, "samples"), s_num(st, "blocks"), s_num(st, "late_blocks"),
               s_num(st, "worst_late_ns") * 1e-6, s_num(st, "dropped"));
        json_t *camp = json_object_get(st, "campaign");
        if (json_is_object(camp)) {
            json_t *cur = json_object_get(camp, "curve");
            printf("campaign     %.0f: %s, %.0f of %.0f curves done", s_num(camp, "campaign_id"),
                   json_is_true(json_object_get(camp, "running")) ? "running" : "ended", s_num(camp, "curves_done"),
                   s_num(camp, "curves"));
            if (json_is_integer(cur))
                printf(", curve %" JSON_INTEGER_FORMAT " in progress", json_integer_value(cur));
            putchar('\n');
        }
        json_t *fr = json_object_get(st, "free_run");
        printf("pacing       %s, speed %g\n", json_is_true(fr) ? "free run" : "real time", s_num(st, "speed"));
        json_t *log = json_object_get(st, "log");
        if (json_is_object(log)) {
            printf("log          %s", s_text(log, "state", "?"));
            if (json_is_string(json_object_get(log, "path")))
                printf(" %s", s_text(log, "path", ""));
            printf(": %.0f curves written, %.0f dropped, %.0f skipped, %.0f overflows", s_num(log, "curves"),
                   s_num(log, "curves_dropped"), s_num(log, "curves_skipped"), s_num(log, "overflows"));
            if (json_is_string(json_object_get(log, "error")))
                printf(", last error: %s", s_text(log, "error", ""));
            putchar('\n');
        }
        json_t *flt = json_object_get(st, "faults");
        if (json_is_object(flt)) { /* fault injection (protocol/faults.md): the plan and what it did */
            json_t *last = json_object_get(flt, "last");
            size_t nl = json_is_array(last) ? json_array_size(last) : 0;
            printf("faults       %s, %.0f injected", json_is_null(json_object_get(flt, "plan")) ? "no plan" : "a plan",
                   s_num(flt, "count"));
            if (nl)
                printf(", the last: %s", s_text(json_array_get(last, nl - 1), "kind", "?"));
            putchar('\n');
        }
        json_t *auth = json_object_get(st, "auth");
        if (json_is_object(auth))
            printf("security     %s, %.0f allowed client keys, %.0f accepted, %.0f refused\n",
                   s_text(auth, "mechanism", "?"), s_num(auth, "clients"), s_num(auth, "accepted"),
                   s_num(auth, "refused"));
    }
    json_decref(st);
    json_decref(hello);
    s_disconnect(&x);
    return rc;
}

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

enum { S_NCH = 6 };
/* the five every live run streams, and the measured height of a scene with a piezo model or a z sensor */
static const char *const s_chan_names[S_NCH] = {"height_m", "deflection_m", "force_N", "vDeflection_V", "tip_m",
                                                "height_measured_m"};

typedef struct s_run {
    int64_t run_id;        /* -1: none in progress */
    int active, skip;      /* skip: joined mid-run, or failed */
    int map[S_NCH];        /* stream channel of each column, -1: absent (a replay of a file without it) */
    int map_time;          /* stream channel "time_s" (replays of files with a time column), or -1 */
    json_t *start;         /* run.start */
    double fs, t_off;
    uint64_t gaps;
    int restarted;         /* the publisher restarted (a new session) while the run was received */
    uint64_t clipped;      /* blocks flagged CLIPPED (ADC saturation) */
    int altered;           /* a saturate or dropout fault record of this run: its force is not the physics' */
    double *col[S_NCH], *time_s;
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
    for (int k = 0; k <= S_NCH; k++) {
        double **pp = k < S_NCH ? &r->col[k] : &r->time_s;
        double *p = realloc(*pp, cap * sizeof *p);
        if (!p)
            return -1;
        *pp = p;
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
    free(r->time_s);
    free(r->seg);
}

typedef struct s_listen {
    s_conn *x;
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
    static const int order[4] = { 0, 1, 2, 4 }; /* height, deflection, force, tip; then segment, vDeflection */
    for (size_t i = 0; i < r->n && !bad; i++) {
        bad |= fprintf(L->csv, "%.17g", r->time_s[i]) < 0;
        for (int c = 0; c < 4; c++)
            bad |= fputc(',', L->csv) == EOF || s_csv_cell(L->csv, r, order[c], i) < 0;
        bad |= fprintf(L->csv, ",%u,", (unsigned)r->seg[i]) < 0 || s_csv_cell(L->csv, r, 3, i) < 0;
        bad |= fprintf(L->csv, ",%" PRId64 "\n", r->run_id) < 0;
    }
    bad |= fflush(L->csv) != 0;
    if (bad)
        s_err(L->x, "writing '%s' failed", L->out);
    return bad ? S_RUNTIME : 0;
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
        s_err(L->x, "run %" PRId64 ": its scene does not load: %s", r->run_id, e.message);
        return S_RUNTIME;
    }
    vafm_curve_result res;
    s_result_from_json(json_object_get(end, "result"), &res);
    vafm_samples s = {.n = r->n, .first = 0, .time_s = r->time_s, .height_m = r->col[0],
                      .deflection_m = r->col[1], .force_N = r->col[2], .tip_m = r->col[4], .segment = r->seg,
                      .height_measured_m = r->map[5] >= 0 ? r->col[5] : NULL};
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
        s_err(L->x, "%s: run %" PRId64 ": %s%s%s", L->out, r->run_id, e.message, e.field[0] ? " at " : "",
              e.field);
        return S_RUNTIME;
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
        nan += isnan(r->col[1][i]) || isnan(r->col[2][i]) || (r->map[3] >= 0 && isnan(r->col[3][i]));
    if (r->gaps) {
        s_err(L->x, "run %" PRId64 ": %" PRIu64 " data block(s) lost (sequence gap): not written", r->run_id,
              r->gaps);
        rc = S_RUNTIME;
    } else if (r->restarted) {
        s_err(L->x, "run %" PRId64 ": the publisher restarted (new session) during the run: not written", r->run_id);
        rc = S_RUNTIME;
    } else if (nan && L->h5 && kind && !strcmp(kind, "curve")) {
        s_err(L->x, "run %" PRId64 ": %zu sample(s) have NaN measured signals (detector dropout): not written (the "
              "HDF5 layout holds finite values only, hdf5.md L16; record to CSV to keep them as they are)",
              r->run_id, nan);
        rc = S_RUNTIME;
    } else if (strcmp(m->status, "ok")) {
        s_err(L->x, "run %" PRId64 " ended with status %s: not written", r->run_id, m->status);
        rc = S_RUNTIME;
    } else if (m->samples != (int64_t)r->n) {
        s_err(L->x, "run %" PRId64 ": received %zu samples, run.end says %" PRId64 ": not written", r->run_id,
              r->n, m->samples);
        rc = S_RUNTIME;
    } else if (L->h5 && (!kind || strcmp(kind, "curve"))) {
        L->tunes_skipped++;
        fprintf(stderr, "vafm listen: run %" PRId64 " is a %s: not written (the HDF5 layout holds force curves)\n",
                r->run_id, kind ? kind : "run of unknown kind");
    } else if (r->n == 0) {
        s_err(L->x, "run %" PRId64 " has no samples: not written", r->run_id);
        rc = S_RUNTIME;
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
    r->map_time = -1;
    for (size_t i = 0; i < m->n_channel_names; i++)
        if (!strcmp(m->channel_names[i], "time_s"))
            r->map_time = (int)i;
    for (int k = 0; k < S_NCH; k++) {
        r->map[k] = -1;
        for (size_t i = 0; i < m->n_channel_names; i++)
            if (!strcmp(m->channel_names[i], s_chan_names[k]))
                r->map[k] = (int)i;
        /* live runs stream all five; a replay streams what its file has (wire.md, replay), at least
         * height and force */
        if (r->map[k] < 0 && k < 5 && (k == 0 || k == 2 || strcmp(s_run_kind(r), "replay"))) {
            s_err(L->x, "run %" PRId64 ": the stream has no channel %s", r->run_id, s_chan_names[k]);
            r->skip = 1;
            return S_RUNTIME;
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
        s_err(L->x, "run %" PRId64 ": data blocks seq %" PRIu64 "..%" PRIu64 " lost (sequence gap)", r->run_id,
              h->seq - m->gap, h->seq - 1);
    if (h->first_sample != r->n) {
        if (r->n == 0 && !r->gaps) { /* subscribed mid-run: run.start was re-sent, the blocks before lost */
            fprintf(stderr, "vafm listen: run %" PRId64 " was in progress when listen subscribed: skipped\n",
                    r->run_id);
            r->skip = 1;
            return 0;
        }
        if (!r->gaps)
            s_err(L->x, "run %" PRId64 ": block %" PRIu64 " starts at sample %" PRIu64 ", expected %zu", r->run_id,
                  h->block_index, h->first_sample, r->n);
        r->gaps += r->gaps ? 0 : 1;
        return 0; /* reported at run.end */
    }
    if (s_run_grow(r, r->n + h->n_samples)) {
        s_err(L->x, "out of memory");
        return S_RUNTIME;
    }
    for (int k = 0; k < S_NCH; k++) {
        if (r->map[k] < 0) { /* absent from this replay: NaN here, an empty CSV cell */
            for (size_t i = 0; i < h->n_samples; i++)
                r->col[k][r->n + i] = NAN;
            continue;
        }
        if ((size_t)r->map[k] >= m->n_channels) {
            s_err(L->x, "run %" PRId64 ": data block without channel %s", r->run_id, s_chan_names[k]);
            return S_RUNTIME;
        }
        memcpy(r->col[k] + r->n, m->channels[r->map[k]], h->n_samples * sizeof(double));
    }
    if (r->map_time >= 0 && (size_t)r->map_time < m->n_channels) /* a replay's recorded times */
        memcpy(r->time_s + r->n, m->channels[r->map_time], h->n_samples * sizeof(double));
    for (size_t i = 0; i < h->n_samples; i++) {
        r->seg[r->n + i] = (uint8_t)h->segment;
        if (r->map_time < 0)
            r->time_s[r->n + i] = ((double)(r->n + i) + r->t_off) / r->fs;
    }
    r->n += h->n_samples;
    return 0;
}

int vafm_cli_listen(int argc, char **argv)
{
    s_conn x = {.cmd = "listen", .timeout_ms = S_TIMEOUT_MS};
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
            printf("%s%s", s_listen_usage, s_conn_help);
            return S_OK;
        }
        int r = s_conn_opt(&x, argc, argv, &i, s_listen_usage);
        if (r < 0)
            return S_USAGE;
        if (r > 0)
            continue;
        if ((!strcmp(a, "--out") || !strcmp(a, "-o")) && has_v)
            L.out = argv[++i];
        else if (!strcmp(a, "--runs") && has_v) {
            json_int_t v;
            if (s_parse_u64(argv[++i], &v))
                return s_usage(&x, s_listen_usage, "--runs needs a non-negative integer");
            runs = v;
        } else if (!strcmp(a, "--start") && has_v) {
            start = argv[++i];
            if (strcmp(start, "curve") && strcmp(start, "tune"))
                return s_usage(&x, s_listen_usage, "--start is curve or tune");
        } else if (!strcmp(a, "--index") && has_v) {
            if (s_parse_u64(argv[++i], &index))
                return s_usage(&x, s_listen_usage, "--index needs a non-negative integer");
            have_index = 1;
        } else if (!strcmp(a, "--duration") && has_v) {
            char m[160];
            if (s_parse_duration("--duration", argv[++i], 1, &duration_s, m, sizeof m))
                return s_usage(&x, s_listen_usage, m); /* inf passed "> 0" in 0.6.1 and was dropped */
            duration = argv[i];
        } else if (!strcmp(a, "--overwrite"))
            overwrite = 1;
        else {
            char m[200];
            snprintf(m, sizeof m, "unexpected argument '%s'", a);
            return s_usage(&x, s_listen_usage, m);
        }
    }
    if ((have_index || duration) && !start)
        return s_usage(&x, s_listen_usage, "--index and --duration go with --start");
    if (duration && strcmp(start, "tune"))
        return s_usage(&x, s_listen_usage, "--duration goes with --start tune");
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
            s_err(&x, "%s", e.message);
            return S_RUNTIME;
        }
    } else {
        /* an existing file is kept unless --overwrite says otherwise (as for FILE.h5) */
        L.csv = strcmp(L.out, "-") ? fopen(L.out, overwrite ? "w" : "wx") : stdout;
        if (!L.csv) {
            if (errno == EEXIST)
                return s_usage(&x, s_listen_usage, "the output file exists already; --overwrite replaces it");
            s_err(&x, "cannot open '%s' for writing: %s", L.out, strerror(errno));
            return S_RUNTIME;
        }
        fputs("time_s,height_m,deflection_m,force_N,tip_m,segment,vDeflection_V,run_id\n", L.csv);
    }
    struct sigaction sa, old_int, old_term;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = s_on_signal;
    sigaction(SIGINT, &sa, &old_int);
    sigaction(SIGTERM, &sa, &old_term);

    int rc = s_connect(&x);
    if (!rc)
        rc = s_subscribe(&x);
    if (!rc)
        fprintf(stderr, "vafm listen: subscribed to %s\n", x.pub ? x.pub : x.pub_default ? x.pub_default
                                                                         : VAFM_CLIENT_DEFAULT_PUB);
    int64_t want = -1; /* with --start: the run to record */
    if (!rc && start) {
        json_t *req = json_pack("{s:s,s:I}", "cmd", start, "index", index), *reply = NULL;
        if (duration)
            json_object_set_new(req, "duration_s", json_real(duration_s)); /* finite: checked above */
        if ((rc = s_send(&x, req, &reply)) == 0)
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
            if (silent_ms >= S_STREAM_SILENCE_MS) { /* no heartbeat either: the daemon is gone */
                s_err(&x, "nothing received for %d s (no heartbeat): is vafmd running?", S_STREAM_SILENCE_MS / 1000);
                rc = S_RUNTIME;
            }
            continue;
        }
        if (q) {
            s_err(&x, "%s", e.message);
            rc = S_RUNTIME;
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
                s_err(&x, "the publisher restarted: stream session %" PRId64 " -> %" PRId64 " (sequence numbers start "
                      "again)", session, sess);
                if (r.active && !r.skip)
                    r.restarted = 1;
            }
            session = sess;
        }
        if (up >= 0) {
            if (hb_uptime >= 0 && up - hb_uptime >= 1.5)
                s_err(&x, "the stream stalled: no message for %.1f s (heartbeats included)", up - hb_uptime);
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
            s_err(&x, "run %" PRId64 ": no run.end (the stream stopped mid-run: truncated, or its end was lost) "
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
                s_err(&x, "%" PRIu64 " data block(s) lost (sequence gap before seq %" PRIu64
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
                s_err(&x, "%" PRIu64 " data block(s) lost (sequence gap before seq %" PRIu64
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
    s_disconnect(&x);
    sigaction(SIGINT, &old_int, NULL);
    sigaction(SIGTERM, &old_term, NULL);
    if (L.w) {
        vafm_error e = {0};
        if (vafm_recorder_close(&L.w, NULL, &e)) {
            s_err(&x, "closing %s: %s", L.out, e.message);
            rc = S_RUNTIME;
        }
    } else if (L.csv && L.csv != stdout && fclose(L.csv)) {
        s_err(&x, "writing '%s' failed", L.out);
        rc = S_RUNTIME;
    }
    if (L.out && strcmp(L.out, "-"))
        fprintf(stderr, "vafm listen: %" PRIu64 " run(s) received, %" PRIu64 " incomplete or failed, %" PRIu64
                " written to %s\n", L.runs_done, L.runs_bad, L.h5 ? L.curves_written : L.runs_done - L.runs_bad,
                L.out);
    return rc ? rc : failed ? S_RUNTIME : S_OK;
}
