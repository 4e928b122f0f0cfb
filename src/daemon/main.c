/* SPDX-License-Identifier: MIT */
/*
 * vafmd: the virtual AFM as an instrument daemon. Commands (JSON) on a REP socket, the sample stream on
 * an XPUB socket (protocol/wire.md). The main thread runs the control loop; one thread simulates.
 */
#include <errno.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>
#include <jansson.h>
#include <zmq.h>
#include "daemon/cmd_json.h"
#include "daemon/daemon.h"
#include "daemon/nanonis.h"
#include "vafm/wire.h"

static volatile sig_atomic_t s_stop;

static void s_on_signal(int sig)
{
    (void)sig;
    s_stop = 1;
}

static const char s_usage[] =
    "vafmd " VAFMD_VERSION ": the virtual AFM instrument daemon (ZeroMQ commands and sample stream)\n"
    "\nUSAGE\n  vafmd [OPTIONS]\n"
    "\nOPTIONS (applied in this order: defaults, config file, flags)\n"
    "  --rep ENDPOINT     command socket, REP (default " VAFMD_DEFAULT_REP ")\n"
    "  --pub ENDPOINT     stream socket, XPUB (default " VAFMD_DEFAULT_PUB ")\n"
    "                     tcp:// on a loopback address (127.x.x.x, localhost, [::1]) or ipc://PATH;\n"
    "                     any other address needs CURVE security (config keys below)\n"
    "  --config FILE      JSON object: {\"rep\": EP, \"pub\": EP, \"hwm\": N, \"preset\": NAME,\n"
    "                     \"values\": {PARAMETER-OR-SETTING: value, ...} (ctrl_*, ctrl_sample and\n"
    "                     monitor_rate_Hz too: the first controller is built with them),\n"
    "                     \"curve_secret_key\": Z85, \"curve_public_key\": Z85 (optional, checked),\n"
    "                     \"curve_clients\": [Z85, ...], \"curve_required\": BOOL} (all keys optional)\n"
    "                     With curve_secret_key, both sockets require CURVE (40-character Z85 keys as from\n"
    "                     zmq_curve_keypair) and only clients whose public key is listed are served.\n"
    "  --curve-required   refuse to start unless CURVE is configured (also on loopback)\n"
    "  --nanonis [HOST:]PORT  also serve the Nanonis TCP programming interface there (docs/nanonis.md;\n"
    "                     its usual port is 6501; HOST default 127.0.0.1). Config: \"nanonis\": \"[HOST:]PORT\"\n"
    "  --nanonis-allow-remote  allow a non-loopback HOST for --nanonis: the protocol has NO authentication,\n"
    "                     anyone who reaches the port drives the instrument (config \"nanonis_allow_remote\")\n"
    "  --nanonis-with-curve  allow --nanonis although CURVE is configured: the Nanonis port bypasses the\n"
    "                     curve_clients allow-list (refused without it; config \"nanonis_with_curve\")\n"
    "  --preset NAME      scene preset (replaces the config file's; default " VAFM_TOOLS_DEFAULT_PRESET ")\n"
    "  --speed F          pacing speed factor in [0.01, 1000] (1: real time)\n"
    "  --free-run         no pacing: release blocks as fast as they are computed\n"
    "  --sensitivity S    detector sensitivity (InvOLS), m/V (default: the preset's; " VAFM_TOOLS_DEFAULT_PRESET ": 6e-8)\n"
    "  --hwm N            stream send high-water mark per subscriber, messages (default 1000; a run\n"
    "                     of large messages gets fewer: at most 256 MiB queued per subscriber)\n"
    "  -h, --help         this text\n"
    "  --version          print the version\n"
    "\nSETTINGS (get/set like scene parameters): speed, free_run, block_s, hwm, lookahead_s (s of\n"
    "  samples computed ahead of their release, [0, 10], default 1; 0: off). The detector chain is part\n"
    "  of the scene (also in --config \"values\"): sensitivity_m_per_V (InvOLS), noise_V_rms (V rms),\n"
    "  adc_bits (0 or 4-24), adc_range_V (full span, V), baseline_offset_V (V)\n"
    "\nCOMMANDS (JSON on the REP socket, protocol/wire.md)\n";

/* After the commands (printed from commands.def between the two). */
static const char s_usage_tail[] =
    "\nSTREAM topics: data, run.start, run.end, campaign.end, event, heartbeat (1 Hz)\n"
    "\nFAULTS: a fault plan in the config file (\"faults\": {\"seed\", \"script\", \"random\"}, protocol/faults.md)\n"
    "  or the `faults` command makes the daemon misbehave on purpose, for testing acquisition software\n"
    "\nSIGNALS: SIGINT/SIGTERM end the run in progress (run.end \"aborted\") and exit 0\n"
    "\nEXIT STATUS: 0 clean shutdown, 1 runtime error (cannot bind), 2 usage or configuration error,\n"
    "  3-125 a `kill` fault's status\n";

/* Without CURVE, loopback or local transports only: an open port would be an unauthenticated
 * instrument on the network. */
static int s_endpoint_allowed(const char *ep)
{
    if (!strncmp(ep, "ipc://", 6) || !strncmp(ep, "inproc://", 9))
        return 1;
    if (strncmp(ep, "tcp://", 6))
        return 0;
    const char *h = ep + 6;
    return !strncmp(h, "127.", 4) || !strncmp(h, "localhost:", 10) || !strncmp(h, "[::1]:", 6);
}

static void s_bind_address(const char *ep, char *out, size_t len)
{
    if (!strncmp(ep, "tcp://localhost:", 16))
        snprintf(out, len, "tcp://127.0.0.1:%s", ep + 16);
    else
        snprintf(out, len, "%s", ep);
}

/* One info object of `get`: "(unit, kind[, min..max][: choices]) doc" on one line. */
static void s_help_line(const char *name, json_t *f)
{
    const char *unit = json_string_value(json_object_get(f, "unit"));
    const char *kind = json_string_value(json_object_get(f, "kind"));
    const char *choices = json_string_value(json_object_get(f, "choices"));
    json_t *mn = json_object_get(f, "min"), *mx = json_object_get(f, "max");
    printf("  %-26s (%s%s%s", name, kind ? kind : "?", unit && unit[0] ? ", " : "", unit && unit[0] ? unit : "");
    if (json_is_number(mn) && json_is_number(mx))
        printf(", [%g, %g]", json_number_value(mn), json_number_value(mx));
    if (choices)
        printf(": %s", choices);
    if (json_is_true(json_object_get(f, "read_only")))
        printf(", read-only");
    printf(") %s\n", json_string_value(json_object_get(f, "doc")) ? json_string_value(json_object_get(f, "doc")) : "");
}

/* Every name `get` and `set` take, from the tables that define them (the scene's parameter table, the daemon's
 * settings, the controller's): what `get` with "info": true answers. @return 0, or 1 (out of memory). */
static int s_help_settings(void)
{
    vafm_params p;
    vafm_params_default(&p);
    vafmd_settings set;
    memset(&set, 0, sizeof set);
    vafmd_settings_default(&set);
    vafmd_cmd c;
    memset(&c, 0, sizeof c);
    c.info = 1;
    vafmd_err e;
    memset(&e, 0, sizeof e);
    json_t *v = vafmd_get_values(&p, &set, &c, &e), *live = vafmd_live_settings_info();
    json_t *info = json_object_get(v, "info");
    if (!info || !live) {
        json_decref(v);
        json_decref(live);
        fprintf(stderr, "vafmd: out of memory\n");
        return 1;
    }
    printf("\nPARAMETERS AND SETTINGS (all get/set and --config \"values\" take; as get with \"info\": true)\n");
    const char *k;
    json_t *f;
    json_object_foreach(info, k, f) s_help_line(k, f);
    json_object_foreach(live, k, f) s_help_line(k, f);
    json_decref(v);
    json_decref(live);
    return 0;
}

static int s_usage_error(const char *fmt, const char *a)
{
    fprintf(stderr, "vafmd: ");
    fprintf(stderr, fmt, a);
    fprintf(stderr, "\n(vafmd --help for usage)\n");
    return 2;
}

static int s_apply_set_json(vafmd *d, json_t *obj, const char *origin)
{
    vafmd_cmd c;
    vafmd_err e = { 0 };
    json_object_set_new(obj, "cmd", json_string("set"));
    if (vafmd_cmd_decode_json(obj, &c, &e) || vafmd_apply_set(&d->scene, &d->set, &c, &e)) {
        fprintf(stderr, "vafmd: %s: %s: %s%s%s\n", origin, e.code, e.message, e.field[0] ? " (field " : "",
                e.field[0] ? e.field : "");
        if (e.field[0])
            fprintf(stderr, ")\n");
        if (c.root)
            vafmd_cmd_free(&c);
        return -1;
    }
    vafmd_cmd_free(&c);
    return 0;
}

/* A Z85 key: 40 characters that decode to 32 bytes. @return 0 or -1. */
static int s_z85_key(const json_t *v, unsigned char out[32])
{
    if (!json_is_string(v) || json_string_length(v) != 40 || strlen(json_string_value(v)) != 40)
        return -1;
    return zmq_z85_decode(out, json_string_value(v)) ? 0 : -1;
}

/* CURVE keys from the config: all or nothing, every key checked. @return 0 or 2 (message printed). */
static int s_curve_config(vafmd *d, const json_t *secret, const json_t *pub, const json_t *clients)
{
    if (!secret && !pub && !clients)
        return 0;
    unsigned char key[32];
    if (!secret || s_z85_key(secret, key)) {
        fprintf(stderr, "vafmd: config: \"curve_secret_key\" must be the server's secret key, 40 Z85 characters\n");
        return 2;
    }
    snprintf(d->auth.secret_z85, sizeof d->auth.secret_z85, "%s", json_string_value(secret));
    if (zmq_curve_public(d->auth.public_z85, d->auth.secret_z85)) {
        fprintf(stderr, "vafmd: config: \"curve_secret_key\": this libzmq has no CURVE support\n");
        return 2;
    }
    if (pub && (s_z85_key(pub, key) || strcmp(json_string_value(pub), d->auth.public_z85))) {
        fprintf(stderr, "vafmd: config: \"curve_public_key\" is not the public key of \"curve_secret_key\"\n");
        return 2;
    }
    size_t n = json_is_array(clients) ? json_array_size(clients) : 0;
    if (n < 1 || n > VAFMD_MAX_CLIENT_KEYS) {
        fprintf(stderr, "vafmd: config: \"curve_clients\" must list 1 to %d client public keys (Z85)\n",
                VAFMD_MAX_CLIENT_KEYS);
        return 2;
    }
    if (!(d->auth.clients = calloc(n, sizeof *d->auth.clients)))
        return 2;
    for (size_t i = 0; i < n; i++)
        if (s_z85_key(json_array_get(clients, i), d->auth.clients[i])) {
            fprintf(stderr, "vafmd: config: \"curve_clients\"[%zu] is not a 40-character Z85 key\n", i);
            return 2;
        }
    d->auth.n_clients = n;
    d->auth.on = 1;
    return 0;
}

/* Close the sockets and the context when the set-up fails after they were made. @return 1, main's exit status. */
static int s_sockets_close(vafmd *d)
{
    if (d->auth.zap)
        zmq_close(d->auth.zap);
    zmq_close(d->rep);
    zmq_close(d->pub);
    zmq_ctx_term(d->zctx);
    return 1;
}

/* A true/false key of the --config file: true sets *flag (a switch given on the command line stays set).
 * @return 0, or -1 (said on stderr) when it is not a boolean. */
static int s_config_flag(const json_t *cfg, const char *key, const char *config, int *flag)
{
    json_t *v = json_object_get(cfg, key);
    if (v && !json_is_boolean(v)) {
        fprintf(stderr, "vafmd: config '%s': \"%s\" must be true or false\n", config, key);
        return -1;
    }
    *flag |= json_is_true(v);
    return 0;
}

int main(int argc, char **argv)
{
    static vafmd d;
    json_t *cfg_faults = NULL; /* the config file's fault plan, installed once the rings exist */
    json_t *live_vals = NULL;  /* the config's controller settings (ctrl_*, ctrl_sample, monitor_rate_Hz) */
    const char *rep_ep = VAFMD_DEFAULT_REP, *pub_ep = VAFMD_DEFAULT_PUB, *config = NULL, *preset = NULL;
    const char *speed = NULL, *sens = NULL, *hwm = NULL, *nanonis = NULL;
    int free_run = 0, curve_required = 0, nanonis_remote = 0, nanonis_curve = 0;
    char nanonis_buf[300];
    char rep_buf[512], pub_buf[512];
    /* the options after -h/--help and --version: a switch sets its flag, the others take a value */
    const struct {
        const char *name;
        int *flag;
        const char **value;
    } opts[] = {
        { "--free-run", &free_run, NULL },
        { "--curve-required", &curve_required, NULL },
        { "--nanonis", NULL, &nanonis },
        { "--nanonis-allow-remote", &nanonis_remote, NULL },
        { "--nanonis-with-curve", &nanonis_curve, NULL },
        { "--rep", NULL, &rep_ep },
        { "--pub", NULL, &pub_ep },
        { "--config", NULL, &config },
        { "--preset", NULL, &preset },
        { "--speed", NULL, &speed },
        { "--sensitivity", NULL, &sens },
        { "--hwm", NULL, &hwm },
    };
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            fputs(s_usage, stdout);
            for (int k = 0; k < VAFMD_CMD_N; k++)
                printf("  %-10s %s\n", vafmd_cmd_name(k), vafmd_cmd_help(k));
            int hrc = s_help_settings();
            fputs(s_usage_tail, stdout);
            return hrc;
        } else if (!strcmp(a, "--version")) {
            printf("vafmd %s (library %s)\n", VAFMD_VERSION, vafm_version());
            return 0;
        }
        size_t k = 0;
        while (k < sizeof opts / sizeof opts[0] && strcmp(a, opts[k].name))
            k++;
        if (k == sizeof opts / sizeof opts[0])
            return s_usage_error("unknown option '%s'", a);
        if (opts[k].flag)
            *opts[k].flag = 1;
        if (opts[k].value) {
            if (i + 1 >= argc)
                return s_usage_error("option '%s' needs a value", a);
            *opts[k].value = argv[++i];
        }
    }
    vafm_preset_apply(&d.scene, VAFM_TOOLS_DEFAULT_PRESET, NULL); /* an instrument, not the paper's scene */
    vafmd_settings_default(&d.set);
    if (config) {
        json_error_t jerr;
        json_t *cfg = json_load_file(config, JSON_REJECT_DUPLICATES, &jerr);
        if (!cfg || !json_is_object(cfg)) {
            fprintf(stderr, "vafmd: config '%s': %s (line %d, column %d)\n", config,
                    cfg ? "not a JSON object" : jerr.text, jerr.line, jerr.column);
            json_decref(cfg);
            return 2;
        }
        json_t *v;
        if ((v = json_object_get(cfg, "rep")) && json_is_string(v)) {
            snprintf(rep_buf, sizeof rep_buf, "%s", json_string_value(v));
            rep_ep = rep_buf;
        }
        if ((v = json_object_get(cfg, "pub")) && json_is_string(v)) {
            snprintf(pub_buf, sizeof pub_buf, "%s", json_string_value(v));
            pub_ep = pub_buf;
        }
        if ((v = json_object_get(cfg, "hwm")) && json_is_integer(v) && json_integer_value(v) >= 1 &&
            json_integer_value(v) <= 10000000)
            d.set.hwm = (int)json_integer_value(v);
        else if (v) {
            fprintf(stderr, "vafmd: config '%s': \"hwm\" must be an integer in [1, 1e7]\n", config);
            json_decref(cfg);
            return 2;
        }
        if (s_config_flag(cfg, "curve_required", config, &curve_required)) {
            json_decref(cfg);
            return 2;
        }
        if ((v = json_object_get(cfg, "nanonis")) != NULL) { /* the Nanonis port (docs/nanonis.md) */
            if (json_is_string(v) && strlen(json_string_value(v)) < sizeof nanonis_buf)
                snprintf(nanonis_buf, sizeof nanonis_buf, "%s", json_string_value(v));
            else if (json_is_integer(v))
                snprintf(nanonis_buf, sizeof nanonis_buf, "%lld", (long long)json_integer_value(v));
            else {
                fprintf(stderr, "vafmd: config '%s': \"nanonis\" must be \"[HOST:]PORT\" or a port number\n", config);
                json_decref(cfg);
                return 2;
            }
            if (!nanonis) /* the flag wins */
                nanonis = nanonis_buf;
        }
        if (s_config_flag(cfg, "nanonis_allow_remote", config, &nanonis_remote) ||
            s_config_flag(cfg, "nanonis_with_curve", config, &nanonis_curve)) {
            json_decref(cfg);
            return 2;
        }
        if (s_curve_config(&d, json_object_get(cfg, "curve_secret_key"), json_object_get(cfg, "curve_public_key"),
                           json_object_get(cfg, "curve_clients"))) {
            json_decref(cfg);
            return 2;
        }
        json_t *set = json_object();
        const char *key;
        json_object_foreach(cfg, key, v) {
            if (!strcmp(key, "rep") || !strcmp(key, "pub") || !strcmp(key, "hwm") || !strncmp(key, "curve_", 6) ||
                !strcmp(key, "faults") || !strncmp(key, "nanonis", 7))
                continue;
            if (!strcmp(key, "values") && json_is_object(v)) { /* the controller's keys wait for the scene */
                json_t *rest = json_deep_copy(v), *x;
                const char *k2;
                void *tmp;
                json_object_foreach_safe(rest, tmp, k2, x) {
                    if (vafmd_live_config_key(k2)) {
                        if (!live_vals)
                            live_vals = json_object();
                        json_object_set(live_vals, k2, x);
                        json_object_del(rest, k2);
                    }
                }
                if (json_object_size(rest))
                    json_object_set(set, key, rest);
                json_decref(rest);
                continue;
            }
            json_object_set(set, key, v);
        }
        if ((v = json_object_get(cfg, "faults")) != NULL) { /* a fault plan (protocol/faults.md): checked now */
            vafmd_fault_plan *fp = malloc(sizeof *fp);
            vafmd_err fe = { 0 };
            if (!fp || vafmd_faults_decode(v, fp, &fe)) {
                fprintf(stderr, "vafmd: config '%s': \"faults\": %s (field %s)\n", config, fp ? fe.message : "out of memory",
                        fe.field[0] ? fe.field : "plan");
                free(fp);
                json_decref(set);
                json_decref(cfg);
                json_decref(live_vals);
                return 2;
            }
            free(fp);
            cfg_faults = json_incref(v);
        }
        if (preset)
            json_object_set_new(set, "preset", json_string(preset));
        int bad = json_object_size(set) && s_apply_set_json(&d, set, config);
        json_decref(set);
        json_decref(cfg);
        if (bad) {
            json_decref(live_vals);
            return 2;
        }
    } else if (preset) {
        json_t *set = json_pack("{s:s}", "preset", preset);
        int bad = s_apply_set_json(&d, set, "--preset");
        json_decref(set);
        if (bad) {
            json_decref(live_vals);
            return 2;
        }
    }
    json_t *vals = json_object();
    const struct {
        const char *text, *name, *bad;
    } nums[] = { { speed, "speed", "--speed '%s' is not a number" },
                 { sens, "sensitivity_m_per_V", "--sensitivity '%s' is not a number" } };
    for (size_t k = 0; k < sizeof nums / sizeof nums[0]; k++) {
        if (!nums[k].text)
            continue;
        char *end;
        double x = strtod(nums[k].text, &end);
        if (*end || end == nums[k].text) {
            json_decref(live_vals);
            return s_usage_error(nums[k].bad, nums[k].text);
        }
        json_object_set_new(vals, nums[k].name, json_real(x));
    }
    if (free_run)
        json_object_set_new(vals, "free_run", json_true());
    if (json_object_size(vals)) {
        json_t *set = json_pack("{s:O}", "values", vals);
        int bad = s_apply_set_json(&d, set, "command line");
        json_decref(set);
        if (bad) {
            json_decref(vals);
            json_decref(live_vals);
            return 2;
        }
    }
    json_decref(vals);
    vafmd_live_config live_cfg; /* the config's controller settings, checked over the final scene */
    vafmd_live_config_default(&live_cfg);
    if (live_vals) {
        vafmd_err e = { 0 };
        int bad = vafmd_live_config_parse(&d, live_vals, &live_cfg, &e);
        json_decref(live_vals);
        if (bad) {
            fprintf(stderr, "vafmd: config '%s': %s: %s%s%s%s\n", config, e.code, e.message,
                    e.field[0] ? " (field " : "", e.field, e.field[0] ? ")" : "");
            return 2;
        }
    }
    if (hwm) {
        char *end;
        long x = strtol(hwm, &end, 10);
        if (*end || end == hwm || x < 1 || x > 10000000)
            return s_usage_error("--hwm '%s' must be an integer in [1, 1e7]", hwm);
        d.set.hwm = (int)x;
    }
    if (curve_required && !d.auth.on) {
        fprintf(stderr, "vafmd: CURVE is required (--curve-required) but not configured: give "
                        "\"curve_secret_key\" and \"curve_clients\" in the --config file\n");
        return 2;
    }
    /* the Nanonis port reaches the control loop over inproc, where no ZAP handshake takes place: with CURVE
     * it would be the one unauthenticated way in, so it takes an explicit option */
    if (nanonis && d.auth.on && !nanonis_curve) {
        fprintf(stderr, "vafmd: refusing --nanonis with CURVE configured: the Nanonis protocol has no "
                        "authentication and bypasses the curve_clients allow-list; give --nanonis-with-curve "
                        "(config \"nanonis_with_curve\": true) to open it anyway (docs/nanonis.md)\n");
        return 2;
    }
    if (!d.auth.on && (!s_endpoint_allowed(rep_ep) || !s_endpoint_allowed(pub_ep))) {
        fprintf(stderr, "vafmd: refusing to bind '%s': without CURVE security only loopback tcp:// and ipc:// "
                        "endpoints are allowed (configure curve_secret_key and curve_clients)\n",
                s_endpoint_allowed(rep_ep) ? pub_ep : rep_ep);
        return 2;
    }

    d.zctx = zmq_ctx_new();
    snprintf(d.pub_endpoint, sizeof d.pub_endpoint, "%s", pub_ep);
    d.rep = zmq_socket(d.zctx, ZMQ_ROUTER); /* REP to clients; see control.c */
    d.pub = zmq_socket(d.zctx, ZMQ_XPUB);
    int64_t maxmsg = 1 << 20; /* beyond 1 MiB the connection is dropped; 64 KiB..1 MiB get "too_large" */
    int linger = 1000, zero = 0;
    zmq_setsockopt(d.rep, ZMQ_MAXMSGSIZE, &maxmsg, sizeof maxmsg);
    zmq_setsockopt(d.rep, ZMQ_LINGER, &linger, sizeof linger);
    zmq_setsockopt(d.pub, ZMQ_SNDHWM, &d.set.hwm, sizeof d.set.hwm);
    zmq_setsockopt(d.pub, ZMQ_LINGER, &zero, sizeof zero);
    zmq_setsockopt(d.pub, ZMQ_RCVHWM, &zero, sizeof zero);
    /* every subscription, also a repeated topic, reaches the simulation thread: each new subscriber gets
     * its greeting heartbeat and the current run.start */
    int one = 1;
    zmq_setsockopt(d.pub, ZMQ_XPUB_VERBOSE, &one, sizeof one);
    /* CURVE: the ZAP handler is bound before the sockets, so that no handshake finds it missing */
    if (d.auth.on && (vafmd_auth_bind(&d) || vafmd_auth_secure(&d, d.rep) || vafmd_auth_secure(&d, d.pub))) {
        fprintf(stderr, "vafmd: cannot set up CURVE security: %s\n", zmq_strerror(errno));
        return s_sockets_close(&d);
    }
    /* ZeroMQ binds to interfaces and addresses, not host names: tcp://localhost:P is bound as 127.0.0.1 */
    char rep_bind[4200], pub_bind[4200];
    s_bind_address(rep_ep, rep_bind, sizeof rep_bind);
    s_bind_address(pub_ep, pub_bind, sizeof pub_bind);
    const char *failed = zmq_bind(d.rep, rep_bind) ? rep_ep : zmq_bind(d.pub, pub_bind) ? pub_ep : NULL;
    /* the Nanonis interface (nanonis.h) is a client of both sockets, over inproc */
    if (!failed && nanonis)
        failed = zmq_bind(d.rep, VAFMD_NANONIS_CMD_EP) ? VAFMD_NANONIS_CMD_EP
                 : zmq_bind(d.pub, VAFMD_NANONIS_PUB_EP) ? VAFMD_NANONIS_PUB_EP : NULL;
    if (failed) {
        fprintf(stderr, "vafmd: cannot bind %s: %s\n", failed, zmq_strerror(errno));
        return s_sockets_close(&d);
    }
    vafmd_ring_init(&d.ring, d.ring_store, sizeof(vafmd_sim_cmd), VAFMD_RING_CAP);
    /* Test hooks (tests/test_daemon.py, log overflow): a smaller log ring ($VAFMD_TEST_LOG_RING, a power of
     * two in [2, VAFMD_LOG_RING_CAP]) and a writer stalled while a file exists ($VAFMD_TEST_LOG_STALL). */
    size_t log_cap = VAFMD_LOG_RING_CAP;
    const char *env = getenv("VAFMD_TEST_LOG_RING");
    if (env) {
        unsigned long v = strtoul(env, NULL, 10);
        if (v >= 2 && v <= VAFMD_LOG_RING_CAP && !(v & (v - 1)))
            log_cap = v;
    }
    env = getenv("VAFMD_TEST_LOG_STALL");
    d.log.test_stall = env && env[0] ? env : NULL;
    d.log.ring_store = calloc(log_cap, sizeof(vafmd_log_item));
    if (!d.log.ring_store) {
        fprintf(stderr, "vafmd: out of memory\n");
        return 1;
    }
    vafmd_ring_init(&d.log.ring, d.log.ring_store, sizeof(vafmd_log_item), log_cap);
    vafmd_ring_init(&d.log.notice_ring, d.log.notice_store, sizeof(vafmd_log_notice), VAFMD_LOG_NOTICE_CAP);
    atomic_init(&d.log.state, VAFMD_LOG_OFF);
    vafmd_ring_init(&d.log.fault_ring, d.log.fault_store, sizeof(vafmd_fault_rec),
                    sizeof d.log.fault_store / sizeof d.log.fault_store[0]);
    pthread_mutex_init(&d.log.err_mu, NULL);
    pthread_mutex_init(&d.log.jmu, NULL);
    d.next_run_id = 1;
    d.stop = &s_stop;
    vafmd_ring_init(&d.fault_ring, d.fault_store, sizeof(vafmd_fault_rec), sizeof d.fault_store / sizeof d.fault_store[0]);
    vafmd_ring_init(&d.retire_ring, d.retire_store, sizeof(vafmd_fault_plan *),
                    sizeof d.retire_store / sizeof d.retire_store[0]);
    { /* the stream session (faults.md): a nonzero number that changes with each start-up and restart fault */
        struct timespec ts;
        clock_gettime(CLOCK_REALTIME, &ts);
        uint32_t s = (uint32_t)(ts.tv_nsec ^ (ts.tv_sec << 12) ^ ((uint64_t)getpid() << 20));
        atomic_init(&d.sh.session, s ? s : 1);
    }
    if (cfg_faults) {
        vafmd_err fe = { 0 };
        int bad = vafmd_faults_configure(&d, cfg_faults, &fe);
        json_decref(cfg_faults);
        if (bad) {
            fprintf(stderr, "vafmd: config: \"faults\": %s\n", fe.message);
            return 2;
        }
    }

    /* Only the control thread takes SIGINT/SIGTERM: the simulation thread inherits them blocked. */
    sigset_t block, old;
    sigemptyset(&block);
    sigaddset(&block, SIGINT);
    sigaddset(&block, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &block, &old);
    /* a file-size limit is a log write error (EFBIG, status.log.error), not a kill (SIGXFSZ) */
    signal(SIGXFSZ, SIG_IGN);
    pthread_t th, lth, ath;
    if (vafmd_live_init(&d, &live_cfg)) { /* the always-on controller (live.c), owned by the simulation thread from here */
        fprintf(stderr, "vafmd: out of memory\n");
        return 1;
    }
    int trc = pthread_create(&th, NULL, vafmd_sim_main, &d);
    int ltrc = trc ? -1 : pthread_create(&lth, NULL, vafmd_log_main, &d);
    int atrc = ltrc || !d.auth.on ? 0 : pthread_create(&ath, NULL, vafmd_auth_main, &d);
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = s_on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    pthread_sigmask(SIG_SETMASK, &old, NULL);
    if (trc || ltrc || atrc) {
        fprintf(stderr, "vafmd: cannot start the simulation or the writer thread\n");
        return 1;
    }
    if (nanonis) {
        char nerr[512];
        int ncode = 1;
        if (vafmd_nanonis_start(d.zctx, nanonis, nanonis_remote, nerr, sizeof nerr, &ncode)) {
            fprintf(stderr, "vafmd: %s\n", nerr);
            d.exit_status = ncode;
            *d.stop = 1; /* stop as a signal does: the threads are running */
        } else
            fprintf(stderr, "vafmd: Nanonis TCP interface on %s%s\n", nanonis,
                    nanonis_remote ? " (remote hosts allowed: no authentication)" : "");
    }
    fprintf(stderr, "vafmd %s: commands on %s, stream on %s\n", VAFMD_VERSION, rep_ep, pub_ep);
    int rc = d.exit_status ? 0 : vafmd_control_loop(&d);
    vafmd_nanonis_stop();

    vafmd_sim_cmd q;
    memset(&q, 0, sizeof q);
    q.type = VAFMD_SIM_QUIT;
    atomic_store_explicit(&d.quitting, 1, memory_order_release);
    while (!vafmd_ring_push(&d.ring, &q))
        nanosleep(&(struct timespec){ 0, 1000000 }, NULL);
    pthread_join(th, NULL);
    vafmd_live_free(&d);
    /* The simulation thread has pushed the end of the last run: the writer appends what is complete,
     * flushes, closes the file and exits. */
    int lon = VAFMD_LOG_ON;
    atomic_compare_exchange_strong(&d.log.state, &lon, VAFMD_LOG_STOPPING);
    atomic_store_explicit(&d.log.quit, 1, memory_order_release);
    pthread_join(lth, NULL);
    free(d.log.ring_store);
    pthread_mutex_destroy(&d.log.err_mu);
    pthread_mutex_destroy(&d.log.jmu);
    json_decref(d.log.jpend);
    json_decref(d.log.jnote);
    /* Commands still in the ring after QUIT cannot exist (QUIT is pushed last), so nothing leaks.
     * The last run.end is still queued: give it a bounded time to leave (a stalled subscriber must
     * not hold up the exit). pthread_join is the barrier that lets this thread use the socket. */
    int flush_ms = 500;
    zmq_setsockopt(d.pub, ZMQ_LINGER, &flush_ms, sizeof flush_ms);
    zmq_close(d.pub);
    zmq_close(d.rep);
    if (d.auth.on) { /* the ZAP thread closes its socket; zmq_ctx_term waits for every socket */
        atomic_store_explicit(&d.auth.quit, 1, memory_order_release);
        pthread_join(ath, NULL);
    }
    free(d.auth.clients);
    zmq_ctx_term(d.zctx);
    fprintf(stderr, "vafmd: stopped\n");
    json_decref(d.fplan_json);
    free(d.fplan);
    return rc ? 1 : d.exit_status;
}
