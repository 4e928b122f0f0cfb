/* SPDX-License-Identifier: MIT */
/*
 * `vafm status`: the daemon's hello and status as a page for humans (state, runs, pacing, log, faults,
 * authentication).
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
    vafm_cli_conn x = {.cmd = "status", .timeout_ms = VAFM_CLI_CONN_TIMEOUT_MS};
    int as_json = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--help")) {
            printf("%s%s", s_status_usage, vafm_cli_conn_help);
            return VAFM_CLI_CONN_OK;
        }
        if (!strcmp(argv[i], "--json")) {
            as_json = 1;
            continue;
        }
        int r = vafm_cli_conn_opt(&x, argc, argv, &i, s_status_usage);
        if (r < 0)
            return VAFM_CLI_CONN_USAGE;
        if (r == 0) {
            char m[160];
            snprintf(m, sizeof m, "unexpected argument '%s'", argv[i]);
            return vafm_cli_conn_usage(&x, s_status_usage, m);
        }
    }
    int rc = vafm_cli_conn_open(&x);
    json_t *st = NULL, *hello = NULL;
    if (!rc)
        rc = vafm_cli_conn_send(&x, json_pack("{s:s}", "cmd", "status"), &st);
    if (!rc && !as_json)
        rc = vafm_cli_conn_send(&x, json_pack("{s:s}", "cmd", "hello"), &hello);
    if (!rc && as_json)
        vafm_cli_conn_print_json(st);
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
    vafm_cli_conn_close(&x);
    return rc;
}

