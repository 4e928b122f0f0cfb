/* SPDX-License-Identifier: MIT */
/*
 * The Nanonis TCP programming interface on vafmd (docs/nanonis.md; the vendor's TCPProtocol_SPM).
 *
 * The transport and the command modules, one responsibility each:
 *   nanonis.c       the transport: a TCP listener, up to four connection threads (the spec's four
 *                   ports' worth), framing (40-byte big-endian headers), bounds; the bridge that turns a
 *                   Nanonis command into the daemon's own JSON commands, sent to the control loop over
 *                   inproc as any client's (so the fault plan applies and the request shows as one); the
 *                   stream reader that keeps the live signal values and collects a Z spectroscopy's run.
 *   nanonis_cmds.c  the dispatcher and the helpers of the command modules (nanonis_cmds.h lists them:
 *                   nanonis_signals.c, nanonis_zspectr.c, nanonis_ctrl.c): each Nanonis command's argument
 *                   and return layout, and what it does in vafm.
 *
 * The Nanonis threads never touch the daemon's state (struct vafmd): they only talk to it as a client.
 */
#ifndef VAFMD_NANONIS_H
#define VAFMD_NANONIS_H
#include <jansson.h>
#include <stddef.h>
#include <stdint.h>

#define VAFMD_NANONIS_DEFAULT_PORT 6501
#define VAFMD_NANONIS_MAX_CONN 4          /* simultaneous connections (the spec: one to four) */
#define VAFMD_NANONIS_MAX_BODY 65536      /* a request body larger than this: an error, connection closed */
#define VAFMD_NANONIS_CMD_EP "inproc://vafmd-nanonis-cmd" /* the control loop's socket, also bound here */
#define VAFMD_NANONIS_PUB_EP "inproc://vafmd-nanonis-pub" /* the stream, also bound here */
#define VAFMD_NANONIS_MAX_RUN_SAMPLES ((size_t)1 << 20) /* samples a Z spectroscopy collects per sweep
                                                           (6 channels: 48 MiB) */

struct vafmd;

/* main.c: open the listener on [HOST:]PORT (loopback unless allow_remote) and start the threads; the
 * daemon's sockets must already be bound to the two inproc endpoints above. @return 0, or -1 with a message
 * in err (2: a usage error, the address; 1: a runtime error, the bind). */
int vafmd_nanonis_start(void *zctx, const char *hostport, int allow_remote, char *err, size_t errlen, int *exit_code);
/* main.c: stop and join every Nanonis thread (they close their sockets): before zmq_ctx_term. */
void vafmd_nanonis_stop(void);

/* ---- between nanonis.c and nanonis_cmds.c ------------------------------------------------------------- */

/* A response body under construction (bounded: VAFMD_NANONIS_MAX_RESPONSE). */
#define VAFMD_NANONIS_MAX_RESPONSE ((size_t)64 << 20)
typedef struct nn_buf {
    unsigned char *p;
    size_t n, cap;
    int oom; /* an append failed (memory, or the bound): the body is unusable */
} nn_buf;
void nn_put_u16(nn_buf *b, uint16_t v);
void nn_put_u32(nn_buf *b, uint32_t v);
void nn_put_i32(nn_buf *b, int32_t v);
void nn_put_f32(nn_buf *b, float v);
void nn_put_f64(nn_buf *b, double v);
void nn_put_bytes(nn_buf *b, const void *p, size_t n);
/* a 1D array of strings, each prefixed by its size (the caller sends the sizes before it) */
void nn_put_strings(nn_buf *b, const char *const *s, size_t n);
size_t nn_strings_bytes(const char *const *s, size_t n); /* its size in bytes */

/* Reading a request body: a short body sets bad and names the argument. */
typedef struct nn_rd {
    const unsigned char *p;
    size_t n, off;
    int bad;
    char why[160];
} nn_rd;
uint16_t nn_get_u16(nn_rd *r, const char *arg);
uint32_t nn_get_u32(nn_rd *r, const char *arg);
int32_t nn_get_i32(nn_rd *r, const char *arg);
float nn_get_f32(nn_rd *r, const char *arg);

/* One connection's bridge to the control loop (its own DEALER socket). */
typedef struct nn_conn nn_conn;
enum { NN_OK = 0, NN_EREPLY = -1, NN_ENOREPLY = -2 };
/* Send one JSON request (req is consumed; its "id" is set) and wait for its reply. @return NN_OK (reply
 * "ok": *reply owned by the caller, may be NULL to drop it), NN_EREPLY (an error reply: its message in msg),
 * NN_ENOREPLY (no reply in time, or the daemon is stopping: the Nanonis request gets no response either). */
int nn_call(nn_conn *c, json_t *req, json_t **reply, char *msg, size_t msglen);
const char *nn_conn_cmd(const nn_conn *c); /* the Nanonis command being served */
int nn_quitting(void);

/* The live signals: the last stream sample (valid 0 before any). Channels as on the stream. */
enum { NN_CH_HEIGHT = 0, NN_CH_DEFL_M, NN_CH_FORCE, NN_CH_DEFL_V, NN_CH_TIP, NN_CH_HMEAS, NN_CH_N };
int nn_live(double v[NN_CH_N], int *has_hmeas);

/* The run collector: one Z spectroscopy at a time. arm() before the `curve` command: the next run's
 * samples (whichever run starts next) are kept, at most cap samples. wait() until its run.end, the
 * deadline (monotonic s) or the daemon stopping. */
#define NN_RUN_SEGS 8 /* the segments of a list whose starts the collector keeps */
typedef struct nn_run {
    uint64_t run_id;
    size_t n;                   /* samples kept */
    double *v[NN_CH_N];         /* per channel (NN_CH_HMEAS: NULL unless the run streams it) */
    int64_t dwell_at, retract_at; /* sample index where the dwell / retract segment begins (-1: not seen) */
    int64_t seg_at[NN_RUN_SEGS]; /* a segment list's run: where the segment at position i begins (-1: not seen) */
    int ended;                  /* run.end seen */
    char status[16];            /* run.end "status" */
    int overflow;               /* more samples than cap (not kept) */
} nn_run;
int nn_collect_arm(size_t cap);
int nn_collect_wait(nn_run *out, double deadline_s); /* 0 ended, -1 timed out/quitting (out: what came) */
void nn_collect_disarm(void);
void nn_run_free(nn_run *r);
double nn_now_s(void);

/* nanonis_cmds.c: serve one request. @return 0: send out (return arguments and the error part), 1: no
 * response at all (the bridge got none: the `no_reply` fault). */
int nn_dispatch(nn_conn *c, const char *name, const unsigned char *body, size_t n, nn_buf *out);
void nn_cmds_init(void);
#endif
