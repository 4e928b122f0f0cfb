/* SPDX-License-Identifier: MIT */
/*
 * `vafm ctl`: send any command of vafmd's table (src/daemon/commands.def, whose rows its usage lists):
 * KEY=VALUE arguments become the request's keys and the reply is printed as JSON; `ctl curve|tune|
 * campaign ... --wait` waits for the run's end on the stream and prints it.
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
#include "vafm/params.h"

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
    "  CMD KEY=VALUE...              other commands: a value with its unit, for a key that ends in it\n"
    "                                (move x_m=2um speed_m_per_s=1um/s), or feedback setpoint=1nN|0.5V\n"
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

/* Any other command: a value typed with its unit, for a key whose name ends in its SI unit (x_m=2um,
 * speed_m_per_s=1um/s, at_s=500ms, force_N=1nN), goes out in SI; `setpoint` (the controller's `feedback`,
 * in N or V) takes "1nN" or "0.5V" and, unless `unit` is given, sets `unit` to the one typed. Anything else
 * goes out as the string, for the daemon to judge. Takes v, returns one. */
static json_t *s_arg_units(const char *key, json_t *v, json_t *req)
{
    static const struct { const char *suffix, *unit; } tab[] = {
        { "_m_per_s", "m/s" }, { "_m", "m" }, { "_N", "N" }, { "_s", "s" }, { "_Hz", "Hz" }, { "_V", "V" },
    };
    const char *text = json_string_value(v);
    size_t kl = strlen(key);
    double d;
    if (!strcmp(key, "setpoint")) {
        for (int k = 0; k < 2; k++) {
            const char *u = k ? "V" : "N";
            if (text[0] && !vafm_units_parse(key, text, u, &d, NULL) && text[strlen(text) - 1] == u[0]) {
                if (!json_object_get(req, "unit"))
                    json_object_set_new(req, "unit", json_string(u));
                json_decref(v);
                return json_real(d);
            }
        }
        return v;
    }
    for (size_t k = 0; k < sizeof tab / sizeof tab[0]; k++) {
        size_t sl = strlen(tab[k].suffix);
        if (kl > sl && !strcmp(key + kl - sl, tab[k].suffix)) {
            if (!vafm_units_parse(key, text, tab[k].unit, &d, NULL)) {
                json_t *n = json_real(d);
                if (n) {
                    json_decref(v);
                    return n;
                }
            }
            break;
        }
    }
    return v;
}

/* Wait for the end of run `run_id` (or of campaign `campaign_id` ≥ 0) and print it. */
static int s_wait_end(vafm_cli_conn *x, int64_t run_id, int64_t campaign_id)
{
    vafm_client_msg m = {0};
    vafm_error e = {0};
    int rc = VAFM_CLI_CONN_RUNTIME;
    for (;;) {
        if (vafm_client_receive(x->c, &m, VAFM_CLI_CONN_SILENCE_MS, &e)) {
            vafm_cli_conn_err(x, "waiting for the end of %s %" PRId64 ": %s", campaign_id >= 0 ? "campaign" : "run",
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
        vafm_cli_conn_print_json(j);
        const char *st = json_string_value(json_object_get(j, "status"));
        rc = st && !strcmp(st, "ok") ? VAFM_CLI_CONN_OK : VAFM_CLI_CONN_RUNTIME;
        if (rc)
            vafm_cli_conn_err(x, "%s ended with status %s", campaign_id >= 0 ? "campaign" : "run", st ? st : "(none)");
        json_decref(j);
        break;
    }
    vafm_client_msg_clear(&m);
    return rc;
}

static int s_ctl_run(vafm_cli_conn *x, int argc, char **argv)
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
            return vafm_cli_conn_usage(x, s_ctl_usage, m);
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
            if (vafm_cli_conn_parse_u64(argv[++i], &v))
                rc = vafm_cli_conn_usage(x, s_ctl_usage, "--index needs a non-negative integer");
            else
                json_object_set_new(req, "index", json_integer(v));
        } else if (is_get && !eq && a[0] != '-') {
            if (json_array_append_new(names, json_string(a))) /* NULL for text that is not UTF-8 */
                rc = vafm_cli_conn_usage(x, s_ctl_usage, "get: a NAME is not UTF-8 text");
        } else if (is_tune && i == 1 && !eq && strncmp(a, "--", 2)) { /* -1 too: refused with the range */
            /* json_real(NaN or inf) is NULL and json_object_set_new drops the key: 0.6.1 sent no duration
             * then, and the daemon ran the scene's tune */
            double d;
            if (vafm_cli_conn_parse_duration("tune SECONDS", a, 0, &d, msg, sizeof msg))
                rc = vafm_cli_conn_usage(x, s_ctl_usage, msg);
            else
                json_object_set_new(req, "duration_s", json_real(d));
        } else if (eq && eq != a) {
            char key[128];
            snprintf(key, sizeof key, "%.*s", (int)(eq - a), a);
            json_t *v = s_value(eq + 1);
            if (is_set && json_is_string(v))
                v = s_set_units(key, v);
            else if (json_is_string(v) && strcmp(key, "unit"))
                v = s_arg_units(key, v, req);
            if (!v || json_object_set_new(is_set && strcmp(key, "preset") ? values : req, key, v)) {
                json_t *text = json_string(eq + 1); /* NULL: not UTF-8; else a number beyond a double */
                if (text)
                    snprintf(msg, sizeof msg, "%.60s=%.60s: a number beyond the range of a double (numbers must "
                             "be finite)", key, eq + 1);
                else
                    snprintf(msg, sizeof msg, "%.60s: the value is not UTF-8 text", key);
                json_decref(text);
                rc = vafm_cli_conn_usage(x, s_ctl_usage, msg);
            }
        } else {
            snprintf(msg, sizeof msg, "unexpected argument '%s' (arguments are KEY=VALUE)", a);
            rc = vafm_cli_conn_usage(x, s_ctl_usage, msg);
        }
    }
    if (!rc && is_set && !json_object_size(values) && !json_object_get(req, "preset"))
        rc = vafm_cli_conn_usage(x, s_ctl_usage, "set needs NAME=VALUE");
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
    if ((rc = vafm_cli_conn_open(x)) != 0 || (wait && (rc = vafm_cli_conn_subscribe(x)) != 0)) {
        json_decref(req);
        return rc;
    }
    json_t *reply = NULL;
    if ((rc = vafm_cli_conn_send(x, req, &reply)) != 0)
        return rc;
    vafm_cli_conn_print_json(reply);
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
    vafm_cli_conn x = {.cmd = "ctl", .timeout_ms = VAFM_CLI_CONN_TIMEOUT_MS};
    int i = 1;
    for (; i < argc && argv[i][0] == '-' && argv[i][1] == '-'; i++) {
        if (!strcmp(argv[i], "--help")) {
            printf("%s%s", s_ctl_usage, vafm_cli_conn_help);
            return VAFM_CLI_CONN_OK;
        }
        int r = vafm_cli_conn_opt(&x, argc, argv, &i, s_ctl_usage);
        if (r < 0)
            return VAFM_CLI_CONN_USAGE;
        if (r == 0) {
            char m[160];
            snprintf(m, sizeof m, "unknown option '%s'", argv[i]);
            return vafm_cli_conn_usage(&x, s_ctl_usage, m);
        }
    }
    if (i >= argc)
        return vafm_cli_conn_usage(&x, s_ctl_usage, "no command");
    int rc = s_ctl_run(&x, argc - i, argv + i);
    vafm_cli_conn_close(&x);
    return rc;
}

