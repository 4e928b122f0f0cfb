/* SPDX-License-Identifier: MIT */
/*
 * `vafm replay FILE`: ask a running vafmd to replay an HDF5 file of protocol/hdf5.md's layout through
 * its live stream (the `replay` command of protocol/wire.md), through the C client library, and print
 * the daemon's reply as JSON. The daemon reads the file, so a path that exists here is made absolute
 * (a local daemon then finds it whatever its working directory); any other path is sent as given.
 * With --wait it subscribes first (so no message of the run is missed) and prints the run's run.end.
 * Exit status: 0 the replay started (--wait: ended ok), 1 runtime failure (no reply, daemon error, the
 * run did not end ok), 2 usage.
 */
#include <errno.h>
#include <jansson.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cli/cli.h"
#include "vafm/client.h"

static const char *s_usage_text =
    "usage: vafm replay FILE [--curves SEL] [--speed X] [--loop N|forever] [--client-run-id ID]\n"
    "                        [--wait] [--endpoint E] [--pub E] [--timeout MS]\n"
    "Replay the force curves of an HDF5 file (protocol/hdf5.md layout: vafm logs, instrument exports)\n"
    "through a running vafmd's stream, paced at the recorded sample rate (protocol/wire.md, `replay`).\n"
    "Prints the daemon's reply (JSON); the samples go to the daemon's subscribers (e.g. `vafm listen`).\n"
    "  --curves SEL        curves to replay: \"all\" (default), or \"0,3,5-9,12-\" (inclusive ranges)\n"
    "  --speed X           pacing speed factor, 0.01 to 1000 (default: the daemon's `speed` setting)\n"
    "  --loop N|forever    passes over the selection (default 1); forever: until `vafm ctl cmd=abort`\n"
    "  --client-run-id ID  makes a retried start idempotent (1 to 64 characters)\n"
    "  --wait              subscribe first, then print the run's run.end when it comes (exit 1 unless ok)\n"
    "  --endpoint E        command endpoint (default " VAFM_CLIENT_DEFAULT_REP ")\n"
    "  --pub E             stream endpoint for --wait (default: for tcp://HOST:PORT the next port, else\n"
    "                      " VAFM_CLIENT_DEFAULT_PUB ")\n"
    "  --timeout MS        reply timeout (default 30000: the daemon reads the file before it replies)\n"
    "exit status: 0 the replay started (--wait: and ended ok), 1 runtime failure (no reply, daemon error,\n"
    "             --wait: the run did not end ok or the stream went silent for 10 s), 2 usage\n";

/* The ranges vafmd takes (src/daemon/cmd_json.c: the `speed` setting, replay's "loop"): checked here so
 * that a bad value is a usage error naming the option before anything is sent. */
#define S_SPEED_MIN 0.01
#define S_SPEED_MAX 1000.0
#define S_LOOP_MAX 1000000

static int s_usage(const char *what)
{
    fprintf(stderr, "vafm replay: %s\n%s", what, s_usage_text);
    return 2;
}

/* Set key to a new JSON value, or refuse: jansson's constructors return NULL for a non-finite real or text
 * that is not UTF-8, and json_object_set_new then drops the key without a word (0.6.1 replayed at the
 * default speed when given --speed nan). @return 0 or the usage exit status. */
static int s_set(json_t *req, const char *key, json_t *value, const char *what)
{
    if (!value || json_object_set_new(req, key, value)) {
        json_decref(req);
        return s_usage(what);
    }
    return 0;
}

int vafm_cli_replay(int argc, char **argv)
{
    const char *file = NULL, *curves = NULL, *speed = NULL, *loop = NULL, *crid = NULL;
    const char *endpoint = VAFM_CLIENT_DEFAULT_REP, *pub = NULL, *timeout = NULL;
    int wait = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            fputs(s_usage_text, stdout);
            return 0;
        }
        if (!strcmp(a, "--wait")) {
            wait = 1;
            continue;
        }
        const char **dst = !strcmp(a, "--curves")          ? &curves
                           : !strcmp(a, "--speed")         ? &speed
                           : !strcmp(a, "--loop")          ? &loop
                           : !strcmp(a, "--client-run-id") ? &crid
                           : !strcmp(a, "--endpoint")      ? &endpoint
                           : !strcmp(a, "--rep")           ? &endpoint
                           : !strcmp(a, "--pub")           ? &pub
                           : !strcmp(a, "--timeout")       ? &timeout
                                                           : NULL;
        if (dst) {
            if (i + 1 >= argc) {
                char m[80];
                snprintf(m, sizeof m, "%.40s needs a value", a);
                return s_usage(m);
            }
            *dst = argv[++i];
        } else if (a[0] == '-' && a[1]) {
            char m[120];
            snprintf(m, sizeof m, "unknown option '%.60s'", a);
            return s_usage(m);
        } else if (file)
            return s_usage("one FILE only");
        else
            file = a;
    }
    if (!file)
        return s_usage("FILE is missing");
    json_t *req = json_pack("{s:s}", "cmd", "replay");
    char abs[PATH_MAX];
    json_object_set_new(req, "path", json_string(realpath(file, abs) ? abs : file));
    if (!json_object_get(req, "path")) {
        json_decref(req);
        return s_usage("FILE is not valid UTF-8");
    }
    if (curves && s_set(req, "curves", json_string(curves), "--curves is not valid UTF-8"))
        return 2;
    char *end;
    if (speed) {
        double x = strtod(speed, &end);
        char m[160];
        snprintf(m, sizeof m, "--speed needs a number in [%g, %g], not '%.60s'", S_SPEED_MIN, S_SPEED_MAX, speed);
        if (end == speed || *end || !(x >= S_SPEED_MIN && x <= S_SPEED_MAX)) { /* NaN fails too */
            json_decref(req);
            return s_usage(m);
        }
        if (s_set(req, "speed", json_real(x), m))
            return 2;
    }
    if (loop) {
        char m[160];
        snprintf(m, sizeof m, "--loop needs a number of passes, 1 to %d, or 'forever', not '%.60s'", S_LOOP_MAX, loop);
        if (!strcmp(loop, "forever")) {
            if (s_set(req, "loop", json_string("forever"), m))
                return 2;
        } else {
            errno = 0;
            long long n = strtoll(loop, &end, 10);
            if (end == loop || *end || errno || n < 1 || n > S_LOOP_MAX) {
                json_decref(req);
                return s_usage(m);
            }
            if (s_set(req, "loop", json_integer(n), m))
                return 2;
        }
    }
    if (crid && s_set(req, "client_run_id", json_string(crid), "--client-run-id is not valid UTF-8"))
        return 2;
    long tmo = 30000;
    if (timeout) {
        tmo = strtol(timeout, &end, 10);
        if (end == timeout || *end || tmo <= 0 || tmo > 3600000) {
            json_decref(req);
            return s_usage("--timeout needs milliseconds, 1 to 3600000");
        }
    }
    char *text = json_dumps(req, JSON_COMPACT);
    json_decref(req);
    vafm_client *c = NULL;
    vafm_error err;
    memset(&err, 0, sizeof err);
    char pub_buf[300];
    if (wait && !pub && !strncmp(endpoint, "tcp://", 6)) { /* vafmd's defaults: the stream on the next port */
        const char *colon = strrchr(endpoint, ':');
        long port = colon ? strtol(colon + 1, &end, 10) : 0;
        if (colon && !*end && port > 0 && port < 65535 && colon - endpoint < 250) {
            snprintf(pub_buf, sizeof pub_buf, "%.*s:%ld", (int)(colon - endpoint), endpoint, port + 1);
            pub = pub_buf;
        }
    }
    int rc = text ? vafm_client_new(&c, endpoint, pub, &err) : VAFM_ENOMEM;
    if (!rc && wait)
        rc = vafm_client_subscribe(c, (int)tmo, &err);
    char *reply = NULL;
    if (!rc)
        rc = vafm_client_request(c, text, (int)tmo, &reply, &err);
    free(text);
    if (reply)
        printf("%s\n", reply);
    if (rc)
        fprintf(stderr, "vafm replay: %s%s%s\n", err.message[0] ? err.message : vafm_strerror(rc),
                c && vafm_client_reply_code(c)[0] ? " -- " : "", c ? vafm_client_reply_code(c) : "");
    if (!rc && wait) { /* the run's run.end; heartbeats (1 Hz) tell a long replay from a dead daemon */
        json_t *rj = json_loads(reply, 0, NULL);
        int64_t run_id = json_integer_value(json_object_get(rj, "run_id"));
        json_decref(rj);
        vafm_client_msg m;
        memset(&m, 0, sizeof m);
        for (;;) {
            rc = vafm_client_receive(c, &m, 10000, &err);
            if (rc == VAFM_EFORMAT)
                continue; /* a malformed message is not ours to judge here */
            if (rc) {
                fprintf(stderr, "vafm replay: %s\n", rc == VAFM_EABORT ? "the stream went silent for 10 s" :
                        err.message[0] ? err.message : vafm_strerror(rc));
                break;
            }
            if (m.kind == VAFM_MSG_RUN_END && m.run_id == run_id) {
                printf("%s\n", m.json);
                rc = strcmp(m.status, "ok") ? VAFM_EABORT : 0;
                break;
            }
        }
        vafm_client_msg_clear(&m);
    }
    free(reply);
    vafm_client_destroy(&c);
    return rc ? 1 : 0;
}
