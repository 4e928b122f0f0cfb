/* SPDX-License-Identifier: MIT */
/*
 * The CLI as a client of vafmd: one connection object for the three client commands, each in a file of
 * its own (cmd_ctl.c: send any command; cmd_status.c: the daemon's state for humans; cmd_listen.c: record
 * the runs of the stream). This module owns the connection options (--endpoint, --pub, --timeout,
 * --curve), the C client (include/vafm/client.h) and the messages' prefix ("vafm ctl: ..."); the commands
 * own their arguments and output. Exit status of all three: 0 success, 1 runtime failure (no reply,
 * daemon error, lost data), 2 usage.
 */
#ifndef VAFM_CLI_CLIENT_CONN_H
#define VAFM_CLI_CLIENT_CONN_H

#include <jansson.h>
#include <stddef.h>
#include "vafm/client.h"

enum { VAFM_CLI_CONN_OK = 0, VAFM_CLI_CONN_RUNTIME = 1, VAFM_CLI_CONN_USAGE = 2 };
#define VAFM_CLI_CONN_TIMEOUT_MS 10000
#define VAFM_CLI_CONN_SILENCE_MS 5000 /* heartbeats come at 1 Hz: 5 s of silence means the daemon is gone */

typedef struct vafm_cli_conn {
    const char *cmd; /* "ctl", "status", "listen": the prefix of messages */
    const char *rep, *pub, *curve;
    int timeout_ms;
    vafm_client *c;
    char *pub_default;
} vafm_cli_conn;

/** The connection options' help (after a command's own usage). */
extern const char *const vafm_cli_conn_help;

/** "vafm <cmd>: <message>" on stderr. */
void vafm_cli_conn_err(const vafm_cli_conn *x, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/** A usage error: the message and the usage on stderr. @return VAFM_CLI_CONN_USAGE. */
int vafm_cli_conn_usage(const vafm_cli_conn *x, const char *usage, const char *what);
/** Consume a connection option at argv[*i]: 1 consumed, 0 not one, -1 usage error (printed). */
int vafm_cli_conn_opt(vafm_cli_conn *x, int argc, char **argv, int *i, const char *usage);
/** Connect to the command endpoint (and learn the stream endpoint). @return 0 or an exit status. */
int vafm_cli_conn_open(vafm_cli_conn *x);
/** Disconnect; safe to call twice. */
void vafm_cli_conn_close(vafm_cli_conn *x);
/** Send a request object (stolen); *reply_out gets the parsed ok reply (or NULL). 0 or an exit status. */
int vafm_cli_conn_send(vafm_cli_conn *x, json_t *req, json_t **reply_out);
/** Print a JSON value, indented, on stdout. */
void vafm_cli_conn_print_json(json_t *j);
/** Subscribe to the stream. @return 0 or an exit status. */
int vafm_cli_conn_subscribe(vafm_cli_conn *x);
/** A duration in seconds as a tune takes it (tune_duration_s's range; lo_open: 0 itself is refused).
 *  @return 0, or -1 with the message in m. */
int vafm_cli_conn_parse_duration(const char *opt, const char *text, int lo_open, double *out, char *m, size_t mlen);
/** A non-negative decimal integer. @return 0, or -1. */
int vafm_cli_conn_parse_u64(const char *s, json_int_t *out);

#endif
