/* SPDX-License-Identifier: MIT */
/**
 * @file client.h
 * C client of the vafmd daemon (protocol/wire.md): JSON commands with a timeout, and the sample stream
 * decoded into channel arrays with sequence-gap detection.
 *
 * A vafm_client owns one ZeroMQ context, a REQ socket for commands and (after vafm_client_subscribe) a
 * SUB socket for the stream. It is not thread-safe: use one client per thread. Every function returns 0
 * or a negative VAFM_E* code and fills the optional vafm_error with the reason; a daemon error reply
 * carries the daemon's stable `code` in vafm_client_reply_code() and its `field` in vafm_error.field.
 */
#ifndef VAFM_CLIENT_H
#define VAFM_CLIENT_H

#include <stddef.h>
#include <stdint.h>

#include "vafm/common.h"
#include "vafm/wire.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Defaults of vafmd (protocol/wire.md §1). */
#define VAFM_CLIENT_DEFAULT_REP "tcp://127.0.0.1:5555"
#define VAFM_CLIENT_DEFAULT_PUB "tcp://127.0.0.1:5556"
/** Channel frames a data message may carry that this client decodes; extra ones are ignored. */
#define VAFM_CLIENT_MAX_CHANNELS 16

typedef struct vafm_client vafm_client;

/** Kind of a stream message (its topic). */
enum vafm_client_msg_kind {
    VAFM_MSG_OTHER = 0,  /**< a topic this client does not know (ignore it: wire.md §6) */
    VAFM_MSG_DATA,       /**< a data block: header + channel arrays */
    VAFM_MSG_RUN_START,  /**< run.start JSON */
    VAFM_MSG_RUN_END,    /**< run.end JSON */
    VAFM_MSG_EVENT,      /**< event JSON */
    VAFM_MSG_HEARTBEAT,  /**< heartbeat JSON */
};

/** One received stream message. Fields not used by its kind are zero/empty/-1.
 *  Owned by the caller: zero it (or vafm_client_msg_clear it) before the first receive; each receive
 *  releases what it held before; release the last with vafm_client_msg_clear(). */
typedef struct vafm_client_msg {
    int kind;                 /**< enum vafm_client_msg_kind */
    char topic[32];           /**< the topic frame, NUL-terminated (truncated if longer) */
    char *json;               /**< JSON text of a non-data message (NUL-terminated; for VAFM_MSG_OTHER the
                                   unparsed second frame, e.g. campaign.end), else NULL */
    int64_t run_id;           /**< run id (data, run.start, run.end, event); -1 if none */
    /* data */
    vafm_wire_header header;  /**< decoded header (data only); header.session is the stream session */
    size_t n_channels;        /**< decoded channel arrays (≤ VAFM_CLIENT_MAX_CHANNELS) */
    double *channels[VAFM_CLIENT_MAX_CHANNELS]; /**< header.n_samples values each, host order */
    uint64_t gap;             /**< data messages lost just before this one (seq jump − 1), or missing
                                   at the end of a run (run.end's last_seq beyond the last one seen) */
    /* run.start */
    double sample_rate_Hz;    /**< run.start: output sample rate; data: header's */
    double sensitivity_m_per_V; /**< run.start: detector sensitivity */
    char run_kind[16];        /**< run.start/run.end: "curve" or "tune" */
    int64_t index;            /**< run.start: curve index; -1 otherwise */
    char channel_names[VAFM_CLIENT_MAX_CHANNELS][32]; /**< run.start: channel names in order */
    size_t n_channel_names;   /**< run.start: number of channel names */
    /* run.end */
    char status[16];          /**< run.end: "ok", "aborted", "error"; heartbeat: state */
    int64_t samples;          /**< run.end/heartbeat: samples published; -1 if absent */
    int64_t last_seq;         /**< run.end/heartbeat: last data seq, -1 if null */
    /* event */
    char event_kind[16];      /**< event: "segment", "detach", "overrun", "curve", "logged", "log_failed" */
    int64_t event_sample;     /**< event segment: first sample of the new segment; -1 otherwise */
    int segment_to;           /**< event segment: the new segment (0 approach, 1 retract, 2 dwell, 3 tune); -1 */
} vafm_client_msg;

/**
 * Create a client for a daemon. Connecting is lazy in ZeroMQ: this does not wait for the daemon.
 * @param out receives the client (NULL on failure)
 * @param rep_endpoint command endpoint, NULL for VAFM_CLIENT_DEFAULT_REP
 * @param pub_endpoint stream endpoint, NULL for VAFM_CLIENT_DEFAULT_PUB
 * @param err optional detail
 * @return 0, VAFM_ENOMEM or VAFM_EIO
 */
VAFM_API int vafm_client_new(vafm_client **out, const char *rep_endpoint, const char *pub_endpoint,
                             vafm_error *err);

/** Destroy a client (NULL-safe); *client_p is set to NULL. */
VAFM_API void vafm_client_destroy(vafm_client **client_p);

/**
 * Use CURVE security on both sockets (a daemon configured with curve_secret_key, protocol/wire.md §1.1).
 * Call before vafm_client_subscribe; the REQ socket is reopened with the keys.
 * @param c client
 * @param server_public the daemon's public key, 40 characters Z85
 * @param client_public this client's public key (listed in the daemon's curve_clients), Z85
 * @param client_secret this client's secret key, Z85
 * @param err optional detail
 * @return 0, VAFM_EINVAL (a key is not 40 characters), VAFM_ESTATE (already subscribed), VAFM_ENOTSUP
 *         (libzmq without CURVE), VAFM_EIO
 * @note a daemon that refuses the keys sends nothing: requests time out (VAFM_EIO).
 */
VAFM_API int vafm_client_set_curve(vafm_client *c, const char *server_public, const char *client_public,
                                   const char *client_secret, vafm_error *err);

/** Retries of vafm_client_request after a lost reply (lazy pirate: the REQ socket is closed and reopened
 *  before each retry). Default 0, because a repeated command is only safe when it is idempotent (all but
 *  `curve`/`tune` without a client_run_id, `abort`, `shutdown`). */
VAFM_API void vafm_client_set_retries(vafm_client *c, int retries);

/**
 * Send one JSON request and wait for its reply.
 * @param c client
 * @param request a JSON object, e.g. {"cmd": "status"}
 * @param timeout_ms wait for the reply at most this long per attempt (> 0)
 * @param reply_out receives the reply text (malloc'ed, caller frees), also for an error reply; may be NULL
 * @param err optional detail: for a daemon error its message and field
 * @return 0 on "status": "ok"; for a daemon error reply VAFM_EINVAL (malformed, too_large,
 *         unknown_command, missing_field, unknown_field, wrong_type, out_of_range, invalid_scene,
 *         read_only), VAFM_ENOTFOUND (not_found), VAFM_ESTATE (state, busy), VAFM_ENOTSUP
 *         (not_implemented), VAFM_EIO (internal); VAFM_EIO on no reply within the timeout (the socket
 *         is reopened so the next request works), VAFM_EFORMAT on a reply that is not a JSON object
 */
VAFM_API int vafm_client_request(vafm_client *c, const char *request, int timeout_ms, char **reply_out,
                                 vafm_error *err);

/** @return the daemon's error `code` of the last request ("out_of_range"...), or "" after success or a
 *  transport failure. Valid until the next request. */
VAFM_API const char *vafm_client_reply_code(const vafm_client *c);

/**
 * Subscribe to every topic of the stream and wait until the subscription is in place (the daemon greets
 * each new subscription with a heartbeat, which is consumed here), so that a run started afterwards is
 * seen from its first message.
 * @param c client
 * @param timeout_ms wait at most this long for the greeting heartbeat
 * @param err optional detail
 * @return 0, VAFM_EIO (no heartbeat), VAFM_ESTATE (already subscribed)
 */
VAFM_API int vafm_client_subscribe(vafm_client *c, int timeout_ms, vafm_error *err);

/**
 * Receive and decode the next stream message.
 * @param c a subscribed client
 * @param msg zeroed or previously received into: released, then filled; release with vafm_client_msg_clear()
 * @param timeout_ms wait at most this long (≥ 0; 0 polls)
 * @param err optional detail
 * @return 0, VAFM_EABORT on timeout (nothing received), VAFM_EFORMAT on a malformed message (bad header,
 *         wrong frame sizes, invalid JSON: msg->topic says which), VAFM_ESTATE if not subscribed,
 *         VAFM_ENOMEM, VAFM_EIO
 */
VAFM_API int vafm_client_receive(vafm_client *c, vafm_client_msg *msg, int timeout_ms, vafm_error *err);

/** Free what msg owns and zero it (NULL-safe). */
VAFM_API void vafm_client_msg_clear(vafm_client_msg *msg);

/** @return data messages lost since subscribing (sum of all gaps reported so far). */
VAFM_API uint64_t vafm_client_gaps(const vafm_client *c);

#ifdef __cplusplus
}
#endif
#endif
