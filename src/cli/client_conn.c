/* SPDX-License-Identifier: MIT */
/*
 * What `vafm ctl`, `vafm status` and `vafm listen` share as clients of a running vafmd (protocol/wire.md):
 * the connection options, connecting (with CURVE keys, the stream endpoint guessed or asked from hello),
 * one request and its reply, subscribing, and the argument parsers two of them use. Design: client_conn.h.
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
#include "vafm/params.h"

const char *const vafm_cli_conn_help =
    "connection options:\n"
    "  --endpoint E   command endpoint (default " VAFM_CLIENT_DEFAULT_REP "; --rep is the same)\n"
    "  --pub E        stream endpoint (default: for tcp://HOST:PORT the next port, else the one the daemon\n"
    "                 names in its hello)\n"
    "  --timeout MS   reply timeout (default 10000)\n"
    "  --curve FILE   CURVE keys for a daemon with curve_secret_key: JSON {\"server_public_key\": Z85,\n"
    "                 \"public_key\": Z85, \"secret_key\": Z85} (a file, so the secret is not in `ps`)\n"
    "exit status: 0 success, 1 runtime failure (no reply, daemon error, lost data), 2 usage\n";

void vafm_cli_conn_err(const vafm_cli_conn *x, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "vafm %s: ", x->cmd);
    vfprintf(stderr, fmt, ap);
    fputc('\n', stderr);
    va_end(ap);
}

int vafm_cli_conn_usage(const vafm_cli_conn *x, const char *usage, const char *what)
{
    vafm_cli_conn_err(x, "%s", what);
    fprintf(stderr, "%s%s", usage, vafm_cli_conn_help);
    return VAFM_CLI_CONN_USAGE;
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
int vafm_cli_conn_opt(vafm_cli_conn *x, int argc, char **argv, int *i, const char *usage)
{
    const char *o = argv[*i];
    if (strcmp(o, "--endpoint") && strcmp(o, "--rep") && strcmp(o, "--pub") && strcmp(o, "--curve") &&
        strcmp(o, "--timeout"))
        return 0;
    if (*i + 1 >= argc) {
        char m[96];
        snprintf(m, sizeof m, "%s needs a value", o);
        vafm_cli_conn_usage(x, usage, m);
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
            vafm_cli_conn_usage(x, usage, "--timeout needs milliseconds in [1, 3600000]");
            return -1;
        }
        x->timeout_ms = (int)t;
    }
    return 1;
}

static int s_set_curve(vafm_cli_conn *x)
{
    json_error_t je;
    json_t *j = json_load_file(x->curve, 0, &je);
    if (!j) {
        vafm_cli_conn_err(x, "--curve %s: %s", x->curve, je.text);
        return VAFM_CLI_CONN_USAGE;
    }
    const char *sp = json_string_value(json_object_get(j, "server_public_key"));
    const char *cp = json_string_value(json_object_get(j, "public_key"));
    const char *cs = json_string_value(json_object_get(j, "secret_key"));
    vafm_error e = {0};
    int rc = sp && cp && cs ? vafm_client_set_curve(x->c, sp, cp, cs, &e) : VAFM_EINVAL;
    json_decref(j);
    if (rc) {
        vafm_cli_conn_err(x, "--curve %s: %s", x->curve,
              sp && cp && cs ? e.message : "needs server_public_key, public_key and secret_key (Z85)");
        return rc == VAFM_EINVAL ? VAFM_CLI_CONN_USAGE : VAFM_CLI_CONN_RUNTIME;
    }
    return 0;
}

/* Without --pub and with nothing to guess from (an ipc:// command endpoint; for tcp the next port is the
 * daemon's default), the stream endpoint comes from the daemon itself: hello's "stream". */
static void s_stream_from_hello(vafm_cli_conn *x)
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

int vafm_cli_conn_open(vafm_cli_conn *x)
{
    x->pub_default = x->pub ? NULL : s_default_pub(x->rep);
    vafm_error e = {0};
    if (vafm_client_new(&x->c, x->rep, x->pub ? x->pub : x->pub_default, &e)) {
        vafm_cli_conn_err(x, "%s", e.message);
        return VAFM_CLI_CONN_RUNTIME;
    }
    int rc = x->curve ? s_set_curve(x) : 0;
    if (!rc && !x->pub && !x->pub_default) { /* no tcp port to guess from (ipc://): ask the daemon */
        s_stream_from_hello(x);
        if (x->curve && x->c)
            rc = s_set_curve(x); /* the new client needs its keys too */
    }
    return rc;
}

void vafm_cli_conn_close(vafm_cli_conn *x)
{
    vafm_client_destroy(&x->c);
    free(x->pub_default);
    x->pub_default = NULL;
}

/* Send a request object (stolen); *reply_out gets the parsed ok reply (or NULL). 0 or an exit status. */
int vafm_cli_conn_send(vafm_cli_conn *x, json_t *req, json_t **reply_out)
{
    if (reply_out)
        *reply_out = NULL;
    char *text = req ? json_dumps(req, JSON_COMPACT) : NULL;
    json_decref(req);
    if (!text) {
        vafm_cli_conn_err(x, "out of memory");
        return VAFM_CLI_CONN_RUNTIME;
    }
    char *reply = NULL;
    vafm_error e = {0};
    int rc = vafm_client_request(x->c, text, x->timeout_ms, &reply, &e);
    free(text);
    if (rc) {
        const char *code = vafm_client_reply_code(x->c); /* e.message may already start with it */
        int with_code = code[0] && strncmp(e.message, code, strlen(code));
        vafm_cli_conn_err(x, "%s%s%s%s%s%s", with_code ? code : "", with_code ? ": " : "", e.message,
              e.field[0] ? " (field " : "", e.field, e.field[0] ? ")" : "");
        free(reply);
        return VAFM_CLI_CONN_RUNTIME;
    }
    json_t *j = json_loads(reply, 0, NULL);
    free(reply);
    if (reply_out)
        *reply_out = j;
    else
        json_decref(j);
    return VAFM_CLI_CONN_OK;
}

void vafm_cli_conn_print_json(json_t *j)
{
    char *pretty = json_dumps(j, JSON_INDENT(2) | JSON_PRESERVE_ORDER);
    if (pretty)
        puts(pretty);
    free(pretty);
}

int vafm_cli_conn_subscribe(vafm_cli_conn *x)
{
    vafm_error e = {0};
    if (vafm_client_subscribe(x->c, x->timeout_ms, &e)) {
        vafm_cli_conn_err(x, "subscribing to the stream: %s", e.message);
        return VAFM_CLI_CONN_RUNTIME;
    }
    return 0;
}

/* A duration in seconds as a tune takes it: finite, within tune_duration_s's range (the daemon's check,
 * made here so that nothing is sent); lo_open: 0 itself is refused. @return 0, or -1 (message in m). */
int vafm_cli_conn_parse_duration(const char *opt, const char *text, int lo_open, double *out, char *m, size_t mlen)
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

int vafm_cli_conn_parse_u64(const char *s, json_int_t *out)
{
    char *end;
    errno = 0;
    long long v = strtoll(s, &end, 10);
    if (errno || *end || end == s || v < 0)
        return -1;
    *out = v;
    return 0;
}
