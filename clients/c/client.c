/* SPDX-License-Identifier: MIT */
/* C client of vafmd (include/vafm/client.h, protocol/wire.md). */
#include "vafm/client.h"
#include "core/err_fill.h"

#include <errno.h>
#include <jansson.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zmq.h>

struct vafm_client {
    void *ctx;
    void *req;  /* REQ socket; reopened after a lost reply (a REQ socket cannot send twice) */
    void *sub;  /* SUB socket, NULL until subscribed */
    char *rep_ep, *pub_ep;
    int retries;
    int have_seq;  /* a data seq has been seen: gap detection starts there */
    uint64_t last_seq, gaps;
    int64_t session; /* the publisher's stream session (heartbeats, data headers), -1: none seen; a change is a
                        publisher restart: sequence numbers start again, so gap detection starts afresh */
    char code[32]; /* daemon error code of the last request */
    int curve;     /* CURVE keys set: applied to every socket before it connects */
    char server_pub[41], client_pub[41], client_sec[41];
};

/* CURVE client options go on before connect: the handshake starts with the connection. */
static int s_apply_curve(const vafm_client *c, void *sock)
{
    if (!c->curve)
        return 0;
    return zmq_setsockopt(sock, ZMQ_CURVE_SERVERKEY, c->server_pub, 40) ||
                   zmq_setsockopt(sock, ZMQ_CURVE_PUBLICKEY, c->client_pub, 40) ||
                   zmq_setsockopt(sock, ZMQ_CURVE_SECRETKEY, c->client_sec, 40)
               ? -1
               : 0;
}

static void s_err(vafm_error *err, int code, const char *field, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vafm_err_vset(err, code, field, fmt, ap);
    va_end(ap);
}

static char *s_strdup(const char *s)
{
    size_t n = strlen(s) + 1;
    char *d = malloc(n);
    if (d)
        memcpy(d, s, n);
    return d;
}

static int s_open_req(vafm_client *c)
{
    if (c->req)
        zmq_close(c->req);
    c->req = zmq_socket(c->ctx, ZMQ_REQ);
    if (!c->req)
        return -1;
    int linger = 0;
    zmq_setsockopt(c->req, ZMQ_LINGER, &linger, sizeof linger); /* never hang on exit over a dead daemon */
    if (s_apply_curve(c, c->req))
        return -1;
    return zmq_connect(c->req, c->rep_ep);
}

int vafm_client_new(vafm_client **out, const char *rep_endpoint, const char *pub_endpoint, vafm_error *err)
{
    if (!out) {
        s_err(err, VAFM_EINVAL, "out", "out is NULL");
        return VAFM_EINVAL;
    }
    *out = NULL;
    vafm_client *c = calloc(1, sizeof *c);
    if (!c || !(c->rep_ep = s_strdup(rep_endpoint ? rep_endpoint : VAFM_CLIENT_DEFAULT_REP)) ||
        !(c->pub_ep = s_strdup(pub_endpoint ? pub_endpoint : VAFM_CLIENT_DEFAULT_PUB))) {
        vafm_client_destroy(&c);
        s_err(err, VAFM_ENOMEM, NULL, "out of memory");
        return VAFM_ENOMEM;
    }
    c->session = -1;
    c->ctx = zmq_ctx_new();
    if (!c->ctx || s_open_req(c) != 0) {
        s_err(err, VAFM_EIO, "endpoint", "cannot connect to '%s': %s", c->rep_ep, zmq_strerror(zmq_errno()));
        vafm_client_destroy(&c);
        return VAFM_EIO;
    }
    *out = c;
    return 0;
}

void vafm_client_destroy(vafm_client **client_p)
{
    if (!client_p || !*client_p)
        return;
    vafm_client *c = *client_p;
    if (c->req)
        zmq_close(c->req);
    if (c->sub)
        zmq_close(c->sub);
    if (c->ctx)
        zmq_ctx_term(c->ctx);
    free(c->rep_ep);
    free(c->pub_ep);
    memset(c->client_sec, 0, sizeof c->client_sec); /* no secret left in freed memory */
    free(c);
    *client_p = NULL;
}

int vafm_client_set_curve(vafm_client *c, const char *server_public, const char *client_public,
                          const char *client_secret, vafm_error *err)
{
    if (!c || !server_public || !client_public || !client_secret || strlen(server_public) != 40 ||
        strlen(client_public) != 40 || strlen(client_secret) != 40) {
        s_err(err, VAFM_EINVAL, "curve", "CURVE keys must be 40 characters of Z85");
        return VAFM_EINVAL;
    }
    if (c->sub) {
        s_err(err, VAFM_ESTATE, "curve", "set the CURVE keys before subscribing");
        return VAFM_ESTATE;
    }
    if (!zmq_has("curve")) {
        s_err(err, VAFM_ENOTSUP, "curve", "this libzmq has no CURVE support");
        return VAFM_ENOTSUP;
    }
    memcpy(c->server_pub, server_public, 41);
    memcpy(c->client_pub, client_public, 41);
    memcpy(c->client_sec, client_secret, 41);
    c->curve = 1;
    if (s_open_req(c) != 0) {
        s_err(err, VAFM_EIO, "curve", "cannot apply the CURVE keys: %s", zmq_strerror(zmq_errno()));
        return VAFM_EIO;
    }
    return 0;
}

void vafm_client_set_retries(vafm_client *c, int retries)
{
    if (c)
        c->retries = retries < 0 ? 0 : retries;
}

const char *vafm_client_reply_code(const vafm_client *c)
{
    return c ? c->code : "";
}

uint64_t vafm_client_gaps(const vafm_client *c)
{
    return c ? c->gaps : 0;
}

/* A table from the wire's words (error codes, topics) to this library's numbers. */
typedef struct s_word {
    const char *name;
    int value;
} s_word;

/* The value of the n-byte word w in t[0..len), or dflt. */
static int s_word_find(const s_word *t, size_t len, const void *w, size_t n, int dflt)
{
    for (size_t i = 0; i < len; i++)
        if (strlen(t[i].name) == n && !memcmp(t[i].name, w, n))
            return t[i].value;
    return dflt;
}

static int s_map_code(const char *code)
{
    static const s_word map[] = { { "not_found", VAFM_ENOTFOUND }, { "state", VAFM_ESTATE }, { "busy", VAFM_ESTATE },
                                  { "not_implemented", VAFM_ENOTSUP }, { "internal", VAFM_EIO } };
    /* every other code names a bad request */
    return s_word_find(map, sizeof map / sizeof map[0], code, strlen(code), VAFM_EINVAL);
}

/* Receive one whole message (all frames) into a malloc'ed NUL-terminated buffer of its first frame. */
static int s_recv_text(void *sock, char **text)
{
    zmq_msg_t m;
    zmq_msg_init(&m);
    if (zmq_msg_recv(&m, sock, 0) < 0) {
        zmq_msg_close(&m);
        return VAFM_EIO;
    }
    size_t n = zmq_msg_size(&m);
    char *t = malloc(n + 1);
    if (t) {
        memcpy(t, zmq_msg_data(&m), n);
        t[n] = '\0';
    }
    int more = zmq_msg_more(&m);
    zmq_msg_close(&m);
    while (more) { /* a reply is one frame (wire.md §2.1); drain anything else */
        zmq_msg_init(&m);
        if (zmq_msg_recv(&m, sock, 0) < 0)
            more = 0;
        else
            more = zmq_msg_more(&m);
        zmq_msg_close(&m);
    }
    if (!t)
        return VAFM_ENOMEM;
    *text = t;
    return 0;
}

int vafm_client_request(vafm_client *c, const char *request, int timeout_ms, char **reply_out, vafm_error *err)
{
    if (reply_out)
        *reply_out = NULL;
    if (!c || !request || timeout_ms <= 0) {
        s_err(err, VAFM_EINVAL, "request", "bad arguments (client, request or timeout_ms ≤ 0)");
        return VAFM_EINVAL;
    }
    c->code[0] = '\0';
    char *text = NULL;
    int rc = VAFM_EIO;
    for (int attempt = 0; attempt <= c->retries; attempt++) {
        if (!c->req && s_open_req(c) != 0)
            break;
        if (zmq_send(c->req, request, strlen(request), 0) < 0) {
            s_open_req(c);
            continue;
        }
        zmq_pollitem_t it = {c->req, 0, ZMQ_POLLIN, 0};
        if (zmq_poll(&it, 1, timeout_ms) == 1 && (it.revents & ZMQ_POLLIN)) {
            rc = s_recv_text(c->req, &text);
            break;
        }
        /* Lazy pirate: the reply is lost or late; a REQ socket waiting for it cannot send again. */
        s_open_req(c);
    }
    if (rc) {
        if (rc == VAFM_EIO)
            s_err(err, rc, NULL, "no reply from '%s' within %d ms (%d attempt%s)", c->rep_ep, timeout_ms,
                  c->retries + 1, c->retries ? "s" : "");
        else
            s_err(err, rc, NULL, "out of memory");
        return rc;
    }
    json_error_t je;
    json_t *j = json_loads(text, 0, &je);
    if (!json_is_object(j)) {
        s_err(err, VAFM_EFORMAT, NULL, "reply is not a JSON object: %s", j ? "wrong type" : je.text);
        json_decref(j);
        free(text);
        return VAFM_EFORMAT;
    }
    const char *status = json_string_value(json_object_get(j, "status"));
    rc = 0;
    if (!status || strcmp(status, "ok")) {
        const char *code = json_string_value(json_object_get(j, "code"));
        const char *msg = json_string_value(json_object_get(j, "message"));
        snprintf(c->code, sizeof c->code, "%s", code ? code : "internal");
        rc = s_map_code(c->code);
        s_err(err, rc, json_string_value(json_object_get(j, "field")), "%s: %s", c->code,
              msg ? msg : "(no message)");
    }
    json_decref(j);
    if (reply_out)
        *reply_out = text;
    else
        free(text);
    return rc;
}

int vafm_client_subscribe(vafm_client *c, int timeout_ms, vafm_error *err)
{
    if (!c) {
        s_err(err, VAFM_EINVAL, NULL, "client is NULL");
        return VAFM_EINVAL;
    }
    if (c->sub) {
        s_err(err, VAFM_ESTATE, NULL, "already subscribed");
        return VAFM_ESTATE;
    }
    c->sub = zmq_socket(c->ctx, ZMQ_SUB);
    int linger = 0;
    if (!c->sub || zmq_setsockopt(c->sub, ZMQ_LINGER, &linger, sizeof linger) ||
        zmq_setsockopt(c->sub, ZMQ_SUBSCRIBE, "", 0) || s_apply_curve(c, c->sub) ||
        zmq_connect(c->sub, c->pub_ep)) {
        s_err(err, VAFM_EIO, "endpoint", "cannot subscribe to '%s': %s", c->pub_ep, zmq_strerror(zmq_errno()));
        if (c->sub)
            zmq_close(c->sub);
        c->sub = NULL;
        return VAFM_EIO;
    }
    /* Wait for the greeting heartbeat; anything before it (a run.start of a run in progress) may be
     * dropped here: a joining client resynchronises on the next run.start anyway. */
    for (;;) {
        vafm_client_msg m;
        memset(&m, 0, sizeof m);
        int rc = vafm_client_receive(c, &m, timeout_ms, err);
        int kind = m.kind;
        vafm_client_msg_clear(&m);
        if (rc == VAFM_EABORT) {
            s_err(err, VAFM_EIO, "endpoint", "no heartbeat from '%s' within %d ms", c->pub_ep, timeout_ms);
            return VAFM_EIO;
        }
        if (rc == 0 && kind == VAFM_MSG_HEARTBEAT)
            return 0;
    }
}

void vafm_client_msg_clear(vafm_client_msg *msg)
{
    if (!msg)
        return;
    free(msg->json);
    free(msg->channels[0]); /* one allocation holds every channel */
    memset(msg, 0, sizeof *msg);
    msg->run_id = msg->index = msg->samples = msg->last_seq = msg->event_sample = -1;
    msg->segment_to = -1;
}

static int64_t s_int(json_t *o, const char *key)
{
    json_t *v = json_object_get(o, key);
    return json_is_integer(v) ? (int64_t)json_integer_value(v) : -1;
}

static void s_str(json_t *o, const char *key, char *dst, size_t n)
{
    const char *s = json_string_value(json_object_get(o, key));
    snprintf(dst, n, "%s", s ? s : "");
}

static int s_parse_json(vafm_client *c, vafm_client_msg *m, vafm_error *err)
{
    json_error_t je;
    json_t *j = json_loads(m->json, 0, &je);
    if (!json_is_object(j)) {
        s_err(err, VAFM_EFORMAT, m->topic, "%s message is not a JSON object", m->topic);
        json_decref(j);
        return VAFM_EFORMAT;
    }
    m->run_id = s_int(j, "run_id");
    switch (m->kind) {
    case VAFM_MSG_RUN_START: {
        m->sample_rate_Hz = json_number_value(json_object_get(j, "sample_rate_Hz"));
        m->sensitivity_m_per_V = json_number_value(json_object_get(j, "sensitivity_m_per_V"));
        s_str(j, "kind", m->run_kind, sizeof m->run_kind);
        m->index = s_int(j, "index");
        json_t *ch = json_object_get(j, "channels");
        size_t i;
        json_t *v;
        json_array_foreach(ch, i, v)
        {
            if (i >= VAFM_CLIENT_MAX_CHANNELS)
                break;
            s_str(v, "name", m->channel_names[i], sizeof m->channel_names[i]);
            m->n_channel_names = i + 1;
        }
        break;
    }
    case VAFM_MSG_RUN_END:
        s_str(j, "kind", m->run_kind, sizeof m->run_kind);
        s_str(j, "status", m->status, sizeof m->status);
        m->samples = s_int(j, "samples");
        m->last_seq = s_int(j, "last_seq");
        /* blocks lost at the very end of a run show only here */
        if (m->last_seq >= 0 && c->have_seq && (uint64_t)m->last_seq > c->last_seq) {
            m->gap = (uint64_t)m->last_seq - c->last_seq;
            c->gaps += m->gap;
            c->last_seq = (uint64_t)m->last_seq;
        }
        break;
    case VAFM_MSG_EVENT: {
        s_str(j, "kind", m->event_kind, sizeof m->event_kind);
        if (!strcmp(m->event_kind, "segment")) {
            m->event_sample = s_int(j, "sample");
            static const char *names[] = {"approach", "retract", "dwell", "tune"};
            const char *to = json_string_value(json_object_get(j, "to"));
            for (int k = 0; to && k < 4; k++)
                if (!strcmp(to, names[k]))
                    m->segment_to = k;
        }
        break;
    }
    case VAFM_MSG_HEARTBEAT: {
        json_int_t sess = json_integer_value(json_object_get(j, "session"));
        if (sess > 0 && sess != c->session) {
            if (c->session >= 0)
                c->have_seq = 0; /* a restarted publisher: its sequence numbers start again */
            c->session = sess;
        }
        s_str(j, "state", m->status, sizeof m->status);
        m->samples = s_int(j, "samples");
        m->last_seq = s_int(j, "last_seq");
        break;
    }
    default:
        break;
    }
    json_decref(j);
    return 0;
}

int vafm_client_receive(vafm_client *c, vafm_client_msg *msg, int timeout_ms, vafm_error *err)
{
    if (!c || !msg) {
        s_err(err, VAFM_EINVAL, NULL, "client or msg is NULL");
        return VAFM_EINVAL;
    }
    vafm_client_msg_clear(msg);
    if (!c->sub) {
        s_err(err, VAFM_ESTATE, NULL, "not subscribed");
        return VAFM_ESTATE;
    }
    zmq_pollitem_t it = {c->sub, 0, ZMQ_POLLIN, 0};
    int pr = zmq_poll(&it, 1, timeout_ms);
    if (pr < 0) {
        s_err(err, VAFM_EIO, NULL, "poll failed: %s", zmq_strerror(zmq_errno()));
        return VAFM_EIO;
    }
    if (pr == 0) {
        s_err(err, VAFM_EABORT, NULL, "nothing received within %d ms", timeout_ms);
        return VAFM_EABORT;
    }
    /* Read every frame of the message first so that an error never leaves the socket mid-message. */
    enum { MAXF = 2 + VAFM_CLIENT_MAX_CHANNELS };
    zmq_msg_t f[MAXF];
    int nf = 0, more = 1, rc = 0;
    while (more) {
        zmq_msg_t tmp;
        zmq_msg_init(&tmp);
        if (zmq_msg_recv(&tmp, c->sub, 0) < 0) {
            zmq_msg_close(&tmp);
            rc = VAFM_EIO;
            break;
        }
        more = zmq_msg_more(&tmp);
        if (nf < MAXF)
            f[nf++] = tmp; /* zmq_msg_t may be moved by value once received */
        else
            zmq_msg_close(&tmp);
    }
    if (rc) {
        s_err(err, rc, NULL, "receive failed: %s", zmq_strerror(zmq_errno()));
        goto done;
    }
    size_t tl = zmq_msg_size(&f[0]);
    snprintf(msg->topic, sizeof msg->topic, "%.*s", (int)(tl < sizeof msg->topic ? tl : sizeof msg->topic - 1),
             (const char *)zmq_msg_data(&f[0]));
    static const s_word kinds[] = { { "data", VAFM_MSG_DATA },   { "run.start", VAFM_MSG_RUN_START },
                                    { "run.end", VAFM_MSG_RUN_END }, { "event", VAFM_MSG_EVENT },
                                    { "heartbeat", VAFM_MSG_HEARTBEAT } };
    msg->kind = s_word_find(kinds, sizeof kinds / sizeof kinds[0], zmq_msg_data(&f[0]), tl, VAFM_MSG_OTHER);
    if (msg->kind == VAFM_MSG_OTHER) { /* a newer topic (campaign.end...): keep its body text, unparsed */
        if (nf >= 2 && (msg->json = malloc(zmq_msg_size(&f[1]) + 1)) != NULL) {
            memcpy(msg->json, zmq_msg_data(&f[1]), zmq_msg_size(&f[1]));
            msg->json[zmq_msg_size(&f[1])] = '\0';
        }
        goto done;
    }
    if (nf < 2) {
        rc = VAFM_EFORMAT;
        s_err(err, rc, msg->topic, "%s message without a body", msg->topic);
        goto done;
    }
    if (msg->kind != VAFM_MSG_DATA) {
        size_t n = zmq_msg_size(&f[1]);
        if (!(msg->json = malloc(n + 1))) {
            rc = VAFM_ENOMEM;
            s_err(err, rc, NULL, "out of memory");
            goto done;
        }
        memcpy(msg->json, zmq_msg_data(&f[1]), n);
        msg->json[n] = '\0';
        rc = s_parse_json(c, msg, err);
        goto done;
    }
    vafm_wire_header *h = &msg->header;
    if (vafm_wire_header_decode(zmq_msg_data(&f[1]), zmq_msg_size(&f[1]), h) != 0) {
        rc = VAFM_EFORMAT;
        s_err(err, rc, "header", "bad data header (size %zu, magic or version)", zmq_msg_size(&f[1]));
        goto done;
    }
    if ((int)h->n_channels != nf - 2 && !(h->n_channels > VAFM_CLIENT_MAX_CHANNELS && nf == MAXF)) {
        rc = VAFM_EFORMAT;
        s_err(err, rc, "n_channels", "header says %u channels, message has %d frames", h->n_channels, nf - 2);
        goto done;
    }
    msg->run_id = (int64_t)h->run_id;
    msg->sample_rate_Hz = h->sample_rate_Hz;
    msg->n_channels = h->n_channels < VAFM_CLIENT_MAX_CHANNELS ? h->n_channels : VAFM_CLIENT_MAX_CHANNELS;
    size_t n = h->n_samples;
    for (size_t k = 0; k < msg->n_channels; k++)
        if (zmq_msg_size(&f[2 + k]) != 8 * n) {
            rc = VAFM_EFORMAT;
            s_err(err, rc, "n_samples", "channel %zu has %zu bytes, expected %zu", k, zmq_msg_size(&f[2 + k]),
                  8 * n);
            goto done;
        }
    size_t total = msg->n_channels * n;
    double *buf = malloc((total > 0 ? total : 1) * sizeof *buf);
    if (!buf) {
        rc = VAFM_ENOMEM;
        s_err(err, rc, NULL, "out of memory");
        goto done;
    }
    for (size_t k = 0; k < msg->n_channels; k++) {
        msg->channels[k] = buf + k * n;
        const unsigned char *src = zmq_msg_data(&f[2 + k]);
        for (size_t i = 0; i < n; i++) /* explicit little-endian loads: right on any host */
            msg->channels[k][i] = vafm_wire_get_f64(src + 8 * i);
    }
    if (h->session && (int64_t)h->session != c->session) { /* the header's last field: the session */
        if (c->session >= 0)
            c->have_seq = 0; /* a restarted publisher (wire.md §4): no gap across it */
        c->session = h->session;
    }
    if (c->have_seq && h->seq > c->last_seq + 1) {
        msg->gap = h->seq - c->last_seq - 1;
        c->gaps += msg->gap;
    }
    if (!c->have_seq || h->seq > c->last_seq)
        c->last_seq = h->seq;
    c->have_seq = 1;
done:
    for (int i = 0; i < nf; i++)
        zmq_msg_close(&f[i]);
    return rc;
}
