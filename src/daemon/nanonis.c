/* SPDX-License-Identifier: MIT */
/*
 * The Nanonis TCP transport (nanonis.h, docs/nanonis.md): listener, connections, framing, the bridge to
 * the control loop and the stream reader.
 *
 * Threads: one listener thread polls the listening socket and the stream (a SUB socket on the daemon's
 * inproc stream endpoint); each accepted connection gets a thread of its own that reads a request, serves
 * it (nanonis_cmds.c) and writes the response before it reads the next: commands on one connection are
 * served in order, connections side by side. A connection thread talks to the daemon only through its own
 * DEALER socket on the control loop's inproc endpoint, as a JSON client.
 */
#include "daemon/nanonis.h"
#include <arpa/inet.h>
#include <errno.h>
#include <math.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>
#include <zmq.h>
#include "vafm/wire.h"

#define S_HEADER 40
#define S_NAME 32
#define S_REPLY_TIMEOUT_S 30.0 /* a JSON reply later than this: treated as lost (no Nanonis response) */
#define S_REQUEST_TIMEOUT_S 10.0 /* a request begun must be whole (header and body) within this, or the
                                    connection is closed: a partial header held open cannot keep a slot */

struct nn_conn {
    int fd;
    int slot;
    void *dealer;
    uint64_t seq;
    char cmd[S_NAME + 1];
    pthread_t th;
    atomic_int done; /* the thread has finished (the slot can be joined and reused) */
};

static struct {
    void *zctx;
    int lfd;
    void *sub;
    pthread_t th;
    int started;
    double request_s; /* S_REQUEST_TIMEOUT_S ($VAFMD_TEST_NANONIS_REQUEST_S in the tests) */
    atomic_int quit;
    pthread_mutex_t mu; /* guards the connection slots, live and the collector */
    pthread_cond_t cv;
    nn_conn *conn[VAFMD_NANONIS_MAX_CONN];
    double live[NN_CH_N];
    int live_valid, live_hmeas;
    /* the collector */
    int armed;
    size_t cap;
    nn_run run;
} s;

double nn_now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int nn_quitting(void) { return atomic_load(&s.quit); }

/* ---- response and request buffers ----------------------------------------------------------------- */

void nn_put_bytes(nn_buf *b, const void *p, size_t n)
{
    if (b->oom)
        return;
    if (b->n + n > VAFMD_NANONIS_MAX_RESPONSE) {
        b->oom = 1;
        return;
    }
    if (b->n + n > b->cap) {
        size_t cap = b->cap ? b->cap : 256;
        while (cap < b->n + n)
            cap *= 2;
        unsigned char *q = realloc(b->p, cap);
        if (!q) {
            b->oom = 1;
            return;
        }
        b->p = q;
        b->cap = cap;
    }
    if (n)
        memcpy(b->p + b->n, p, n);
    b->n += n;
}

void nn_put_u16(nn_buf *b, uint16_t v)
{
    unsigned char x[2] = { (unsigned char)(v >> 8), (unsigned char)v };
    nn_put_bytes(b, x, 2);
}

void nn_put_u32(nn_buf *b, uint32_t v)
{
    unsigned char x[4] = { (unsigned char)(v >> 24), (unsigned char)(v >> 16), (unsigned char)(v >> 8),
                           (unsigned char)v };
    nn_put_bytes(b, x, 4);
}

void nn_put_i32(nn_buf *b, int32_t v) { nn_put_u32(b, (uint32_t)v); }

void nn_put_f32(nn_buf *b, float v)
{
    uint32_t u;
    memcpy(&u, &v, 4);
    nn_put_u32(b, u);
}

void nn_put_f64(nn_buf *b, double v)
{
    uint64_t u;
    memcpy(&u, &v, 8);
    nn_put_u32(b, (uint32_t)(u >> 32));
    nn_put_u32(b, (uint32_t)u);
}

size_t nn_strings_bytes(const char *const *str, size_t n)
{
    size_t t = 0;
    for (size_t i = 0; i < n; i++)
        t += 4 + strlen(str[i]);
    return t;
}

void nn_put_strings(nn_buf *b, const char *const *str, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        size_t l = strlen(str[i]);
        nn_put_i32(b, (int32_t)l);
        nn_put_bytes(b, str[i], l);
    }
}

static const unsigned char *s_take(nn_rd *r, size_t k, const char *arg)
{
    if (r->bad)
        return NULL;
    if (r->n - r->off < k) {
        r->bad = 1;
        snprintf(r->why, sizeof r->why, "argument '%s' is missing: the body has %zu bytes, it needs at least %zu",
                 arg, r->n, r->off + k);
        return NULL;
    }
    const unsigned char *p = r->p + r->off;
    r->off += k;
    return p;
}

uint16_t nn_get_u16(nn_rd *r, const char *arg)
{
    const unsigned char *p = s_take(r, 2, arg);
    return p ? (uint16_t)((p[0] << 8) | p[1]) : 0;
}

uint32_t nn_get_u32(nn_rd *r, const char *arg)
{
    const unsigned char *p = s_take(r, 4, arg);
    return p ? ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | p[3] : 0;
}

int32_t nn_get_i32(nn_rd *r, const char *arg) { return (int32_t)nn_get_u32(r, arg); }

float nn_get_f32(nn_rd *r, const char *arg)
{
    uint32_t u = nn_get_u32(r, arg);
    float f;
    memcpy(&f, &u, 4);
    return f;
}

/* ---- the bridge: JSON requests to the control loop ------------------------------------------------- */

const char *nn_conn_cmd(const nn_conn *c) { return c->cmd; }

int nn_call(nn_conn *c, json_t *req, json_t **reply, char *msg, size_t msglen)
{
    if (reply)
        *reply = NULL;
    char id[96];
    snprintf(id, sizeof id, "nanonis:%d:%llu:%s", c->slot, (unsigned long long)++c->seq, c->cmd);
    json_object_set_new(req, "id", json_string(id));
    char *text = json_dumps(req, JSON_COMPACT);
    json_decref(req);
    if (!text) {
        snprintf(msg, msglen, "out of memory");
        return NN_EREPLY;
    }
    int rc = zmq_send(c->dealer, "", 0, ZMQ_SNDMORE) < 0 || zmq_send(c->dealer, text, strlen(text), 0) < 0;
    free(text);
    if (rc) {
        snprintf(msg, msglen, "cannot reach the control loop: %s", zmq_strerror(errno));
        return NN_EREPLY;
    }
    double deadline = nn_now_s() + S_REPLY_TIMEOUT_S;
    while (!nn_quitting() && nn_now_s() < deadline) {
        zmq_pollitem_t it = { c->dealer, 0, ZMQ_POLLIN, 0 };
        if (zmq_poll(&it, 1, 100) <= 0)
            continue;
        /* [empty][json]; anything else, or a reply to an earlier request that timed out, is skipped */
        char *body = NULL;
        size_t blen = 0;
        int frames = 0, more = 1;
        while (more) {
            zmq_msg_t m;
            zmq_msg_init(&m);
            if (zmq_msg_recv(&m, c->dealer, 0) < 0) {
                zmq_msg_close(&m);
                break;
            }
            more = zmq_msg_more(&m);
            if (frames++ == 1 && !body && (body = malloc(zmq_msg_size(&m) + 1))) {
                blen = zmq_msg_size(&m);
                memcpy(body, zmq_msg_data(&m), blen);
                body[blen] = 0;
            }
            zmq_msg_close(&m);
        }
        json_t *r = body ? json_loadb(body, blen, 0, NULL) : NULL;
        free(body);
        json_t *rid = json_object_get(r, "id");
        if (!r || !json_is_string(rid) || strcmp(json_string_value(rid), id)) {
            json_decref(r);
            continue;
        }
        const char *st = json_string_value(json_object_get(r, "status"));
        if (st && !strcmp(st, "ok")) {
            if (reply)
                *reply = r;
            else
                json_decref(r);
            return NN_OK;
        }
        const char *m = json_string_value(json_object_get(r, "message"));
        const char *code = json_string_value(json_object_get(r, "code"));
        const char *field = json_string_value(json_object_get(r, "field"));
        snprintf(msg, msglen, "%s%s%s%s%s", m ? m : "error", code ? " (" : "", code ? code : "",
                 field && field[0] ? ", field " : "", field && field[0] ? field : "");
        if (code) {
            size_t l = strlen(msg);
            if (l + 1 < msglen)
                snprintf(msg + l, msglen - l, ")");
        }
        json_decref(r);
        return NN_EREPLY;
    }
    snprintf(msg, msglen, "no reply from the daemon");
    return NN_ENOREPLY;
}

/* ---- the stream reader: live values and the run collector ----------------------------------------- */

int nn_live(double v[NN_CH_N], int *has_hmeas)
{
    pthread_mutex_lock(&s.mu);
    memcpy(v, s.live, sizeof s.live);
    int ok = s.live_valid;
    if (has_hmeas)
        *has_hmeas = s.live_hmeas;
    pthread_mutex_unlock(&s.mu);
    return ok;
}

void nn_run_free(nn_run *r)
{
    for (int k = 0; k < NN_CH_N; k++)
        free(r->v[k]);
    memset(r, 0, sizeof *r);
}

int nn_collect_arm(size_t cap)
{
    nn_run fresh;
    memset(&fresh, 0, sizeof fresh);
    for (int k = 0; k < NN_CH_N; k++) {
        if (!(fresh.v[k] = malloc(cap * sizeof(double)))) {
            nn_run_free(&fresh);
            return -1;
        }
        for (size_t i = 0; i < cap; i++) /* a sample lost on the way stays NaN */
            fresh.v[k][i] = NAN;
    }
    fresh.dwell_at = fresh.retract_at = -1;
    for (int k = 0; k < NN_RUN_SEGS; k++)
        fresh.seg_at[k] = -1;
    pthread_mutex_lock(&s.mu);
    nn_run_free(&s.run);
    s.run = fresh;
    s.cap = cap;
    s.armed = 1;
    pthread_mutex_unlock(&s.mu);
    return 0;
}

void nn_collect_disarm(void)
{
    pthread_mutex_lock(&s.mu);
    s.armed = 0;
    nn_run_free(&s.run);
    pthread_mutex_unlock(&s.mu);
}

int nn_collect_wait(nn_run *out, double deadline_s)
{
    pthread_mutex_lock(&s.mu);
    while (!s.run.ended && !nn_quitting() && nn_now_s() < deadline_s) {
        struct timespec ts;
        clock_gettime(CLOCK_REALTIME, &ts);
        ts.tv_nsec += 100000000;
        if (ts.tv_nsec >= 1000000000) {
            ts.tv_sec++;
            ts.tv_nsec -= 1000000000;
        }
        pthread_cond_timedwait(&s.cv, &s.mu, &ts);
    }
    int rc = s.run.ended ? 0 : -1;
    *out = s.run; /* ownership passes */
    memset(&s.run, 0, sizeof s.run);
    s.armed = 0;
    pthread_mutex_unlock(&s.mu);
    return rc;
}

static void s_on_data(zmq_msg_t *parts, int n)
{
    vafm_wire_header h;
    if (n < 2 || vafm_wire_header_decode(zmq_msg_data(&parts[1]), zmq_msg_size(&parts[1]), &h))
        return;
    int nch = n - 2;
    if (nch < 5 || h.n_samples == 0)
        return;
    for (int k = 0; k < nch && k < NN_CH_N; k++)
        if (zmq_msg_size(&parts[2 + k]) != (size_t)h.n_samples * 8)
            return;
    pthread_mutex_lock(&s.mu);
    size_t last = h.n_samples - 1;
    for (int k = 0; k < NN_CH_N; k++) {
        if (k >= nch) {
            s.live[k] = s.live[NN_CH_HEIGHT];
            continue;
        }
        const unsigned char *p = zmq_msg_data(&parts[2 + k]);
        s.live[k] = vafm_wire_get_f64(p + 8 * last);
    }
    s.live_hmeas = nch > NN_CH_HMEAS;
    s.live_valid = 1;
    if (s.armed && !s.run.ended && (s.run.run_id == 0 || s.run.run_id == h.run_id)) {
        s.run.run_id = h.run_id;
        for (uint32_t i = 0; i < h.n_samples; i++) {
            uint64_t at = h.first_sample + i;
            if (at >= s.cap) {
                s.run.overflow = 1;
                break;
            }
            for (int k = 0; k < NN_CH_N; k++) {
                const unsigned char *p = zmq_msg_data(&parts[2 + (k < nch ? k : NN_CH_HEIGHT)]);
                s.run.v[k][at] = vafm_wire_get_f64(p + 8 * (size_t)i);
            }
            if (at + 1 > s.run.n)
                s.run.n = (size_t)at + 1;
        }
    }
    pthread_mutex_unlock(&s.mu);
}

static void s_on_json(const char *topic, zmq_msg_t *body)
{
    json_t *j = json_loadb(zmq_msg_data(body), zmq_msg_size(body), 0, NULL);
    if (!j)
        return;
    uint64_t run_id = (uint64_t)json_integer_value(json_object_get(j, "run_id"));
    pthread_mutex_lock(&s.mu);
    if (s.armed && s.run.run_id && run_id == s.run.run_id) {
        if (!strcmp(topic, "run.end")) {
            const char *st = json_string_value(json_object_get(j, "status"));
            snprintf(s.run.status, sizeof s.run.status, "%s", st ? st : "?");
            s.run.ended = 1;
            pthread_cond_broadcast(&s.cv);
        } else {
            const char *kind = json_string_value(json_object_get(j, "kind"));
            const char *to = json_string_value(json_object_get(j, "to"));
            json_int_t at = json_integer_value(json_object_get(j, "sample"));
            json_t *pos = json_object_get(j, "to_segment"); /* a segment list's: the position */
            if (kind && !strcmp(kind, "segment") && json_is_integer(pos) && json_integer_value(pos) >= 0 &&
                json_integer_value(pos) < NN_RUN_SEGS && s.run.seg_at[json_integer_value(pos)] < 0)
                s.run.seg_at[json_integer_value(pos)] = at;
            if (kind && !strcmp(kind, "segment") && to) {
                if (!strcmp(to, "dwell"))
                    s.run.dwell_at = at;
                else if (!strcmp(to, "retract"))
                    s.run.retract_at = at;
            }
        }
    }
    pthread_mutex_unlock(&s.mu);
    json_decref(j);
}

static void s_stream_read(void)
{
    enum { MAXP = 2 + NN_CH_N + 2 };
    zmq_msg_t parts[MAXP];
    int n = 0, more = 1;
    while (more) {
        zmq_msg_t m;
        zmq_msg_init(&m);
        if (zmq_msg_recv(&m, s.sub, ZMQ_DONTWAIT) < 0) {
            zmq_msg_close(&m);
            break;
        }
        more = zmq_msg_more(&m);
        if (n < MAXP) {
            zmq_msg_init(&parts[n]);
            zmq_msg_move(&parts[n++], &m);
        }
        zmq_msg_close(&m);
    }
    if (n >= 1) {
        size_t tl = zmq_msg_size(&parts[0]);
        const char *t = zmq_msg_data(&parts[0]);
        if (tl == 4 && !memcmp(t, "data", 4))
            s_on_data(parts, n);
        else if (n >= 2 && tl == 7 && !memcmp(t, "run.end", 7))
            s_on_json("run.end", &parts[1]);
        else if (n >= 2 && tl == 5 && !memcmp(t, "event", 5))
            s_on_json("event", &parts[1]);
    }
    for (int i = 0; i < n; i++)
        zmq_msg_close(&parts[i]);
}

/* ---- connections ------------------------------------------------------------------------------------ */

/* Read exactly n bytes, by deadline (monotonic s; 0: none). @return 1 read, 0 the peer closed (or the
 * daemon stops), -1 an error or the deadline passed. */
static int s_read_full(int fd, unsigned char *p, size_t n, double deadline)
{
    size_t got = 0;
    while (got < n) {
        if (nn_quitting())
            return 0;
        if (deadline > 0 && nn_now_s() > deadline)
            return -1;
        struct pollfd pf = { fd, POLLIN, 0 };
        int pr = poll(&pf, 1, 100);
        if (pr < 0 && errno != EINTR)
            return -1;
        if (pr <= 0)
            continue;
        ssize_t k = recv(fd, p + got, n - got, 0);
        if (k == 0)
            return 0;
        if (k < 0) {
            if (errno == EINTR || errno == EAGAIN)
                continue;
            return -1;
        }
        got += (size_t)k;
    }
    return 1;
}

static int s_write_full(int fd, const unsigned char *p, size_t n)
{
    while (n) {
        ssize_t k = send(fd, p, n, MSG_NOSIGNAL);
        if (k < 0) {
            if (errno == EINTR)
                continue;
            if (errno == EAGAIN) {
                struct pollfd pf = { fd, POLLOUT, 0 };
                if (nn_quitting())
                    return -1;
                poll(&pf, 1, 100);
                continue;
            }
            return -1;
        }
        p += k;
        n -= (size_t)k;
    }
    return 0;
}

/* A response: the 40-byte header (the command name, the body size, 4 unused bytes) and the body. */
static int s_respond(int fd, const unsigned char name[S_NAME], const nn_buf *body)
{
    unsigned char h[S_HEADER];
    memset(h, 0, sizeof h);
    memcpy(h, name, S_NAME);
    uint32_t n = (uint32_t)body->n;
    h[32] = (unsigned char)(n >> 24);
    h[33] = (unsigned char)(n >> 16);
    h[34] = (unsigned char)(n >> 8);
    h[35] = (unsigned char)n;
    if (s_write_full(fd, h, sizeof h))
        return -1;
    return body->n ? s_write_full(fd, body->p, body->n) : 0;
}

static void s_error_body(nn_buf *b, const char *msg)
{
    b->n = 0;
    b->oom = 0;
    nn_put_u32(b, 1);
    nn_put_i32(b, (int32_t)strlen(msg));
    nn_put_bytes(b, msg, strlen(msg));
}

static void *s_conn_main(void *arg)
{
    nn_conn *c = arg;
    unsigned char h[S_HEADER];
    unsigned char *body = NULL;
    nn_buf out = { 0 };
    for (;;) {
        /* idle between requests for as long as the client likes; once one begins, it must be whole within
         * request_s (else four partial headers held open would turn every other client away) */
        if (s_read_full(c->fd, h, 1, 0) != 1)
            break;
        double deadline = nn_now_s() + s.request_s;
        if (s_read_full(c->fd, h + 1, sizeof h - 1, deadline) != 1)
            break;
        /* the command name: up to its first NUL (32 bytes without one are a name of 32 characters) */
        size_t nl = 0;
        while (nl < S_NAME && h[nl])
            nl++;
        memcpy(c->cmd, h, nl);
        c->cmd[nl] = 0;
        int32_t size = (int32_t)(((uint32_t)h[32] << 24) | ((uint32_t)h[33] << 16) | ((uint32_t)h[34] << 8) | h[35]);
        int want = ((h[36] << 8) | h[37]) != 0;
        if (size < 0 || size > VAFMD_NANONIS_MAX_BODY) {
            /* the next request's start cannot be found (negative), or the body is not worth reading: an
             * error response, then the connection is closed */
            char msg[160];
            snprintf(msg, sizeof msg, "body size %d is %s: the connection is closed", (int)size,
                     size < 0 ? "negative" : "larger than the limit of 65536 bytes");
            out.n = 0;
            s_error_body(&out, msg);
            if (want)
                s_respond(c->fd, h, &out);
            break;
        }
        unsigned char *nb = realloc(body, (size_t)size + 1);
        if (!nb)
            break;
        body = nb;
        if (size && s_read_full(c->fd, body, (size_t)size, deadline) != 1)
            break;
        out.n = 0;
        out.oom = 0;
        int silent = nn_dispatch(c, c->cmd, body, (size_t)size, &out);
        if (out.oom)
            s_error_body(&out, "the response is too large (or out of memory)");
        if (!silent && want && s_respond(c->fd, h, &out))
            break;
    }
    free(body);
    free(out.p);
    close(c->fd);
    c->fd = -1;
    atomic_store(&c->done, 1);
    return NULL;
}

/* Join finished connection threads and free their slots (listener thread). */
static void s_reap(int all)
{
    for (int i = 0; i < VAFMD_NANONIS_MAX_CONN; i++) {
        nn_conn *c = s.conn[i];
        if (!c || (!all && !atomic_load(&c->done)))
            continue;
        pthread_join(c->th, NULL);
        zmq_close(c->dealer);
        pthread_mutex_lock(&s.mu);
        s.conn[i] = NULL;
        pthread_mutex_unlock(&s.mu);
        free(c);
    }
}

static void s_accept(void)
{
    int fd = accept(s.lfd, NULL, NULL);
    if (fd < 0)
        return;
    int slot = -1;
    /* a connection the client closed just before holds its slot until its thread has seen the end: wait
     * for that a moment (up to 0.5 s) before a new one is turned away */
    for (int t = 0; t < 50 && slot < 0 && !nn_quitting(); t++) {
        s_reap(0);
        for (int i = 0; i < VAFMD_NANONIS_MAX_CONN && slot < 0; i++)
            if (!s.conn[i])
                slot = i;
        if (slot < 0)
            nanosleep(&(struct timespec){ 0, 10000000 }, NULL);
    }
    nn_conn *c = slot >= 0 ? calloc(1, sizeof *c) : NULL;
    if (!c) { /* a fifth connection: closed at once (the server has four) */
        close(fd);
        return;
    }
    int one = 1;
    setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    c->fd = fd;
    c->slot = slot;
    c->dealer = zmq_socket(s.zctx, ZMQ_DEALER);
    int linger = 0;
    if (c->dealer)
        zmq_setsockopt(c->dealer, ZMQ_LINGER, &linger, sizeof linger);
    if (!c->dealer || zmq_connect(c->dealer, VAFMD_NANONIS_CMD_EP) ||
        pthread_create(&c->th, NULL, s_conn_main, c)) {
        if (c->dealer)
            zmq_close(c->dealer);
        close(fd);
        free(c);
        return;
    }
    s.conn[slot] = c;
}

static void *s_listener_main(void *arg)
{
    (void)arg;
    while (!nn_quitting()) {
        zmq_pollitem_t it[2] = { { NULL, s.lfd, ZMQ_POLLIN, 0 }, { s.sub, 0, ZMQ_POLLIN, 0 } };
        int n = zmq_poll(it, 2, 100);
        if (n <= 0) {
            s_reap(0);
            continue;
        }
        if (it[1].revents & ZMQ_POLLIN)
            for (int k = 0; k < 256; k++) {
                int ev = 0;
                size_t el = sizeof ev;
                zmq_getsockopt(s.sub, ZMQ_EVENTS, &ev, &el);
                if (!(ev & ZMQ_POLLIN))
                    break;
                s_stream_read();
            }
        if (it[0].revents & ZMQ_POLLIN)
            s_accept();
    }
    s_reap(1);
    return NULL;
}

/* ---- start and stop ------------------------------------------------------------------------------- */

static int s_is_loopback(const struct sockaddr *sa)
{
    if (sa->sa_family == AF_INET)
        return (ntohl(((const struct sockaddr_in *)sa)->sin_addr.s_addr) >> 24) == 127;
    if (sa->sa_family == AF_INET6) {
        const struct in6_addr *a = &((const struct sockaddr_in6 *)sa)->sin6_addr;
        return IN6_IS_ADDR_LOOPBACK(a) ||
               (IN6_IS_ADDR_V4MAPPED(a) && a->s6_addr[12] == 127);
    }
    return 0;
}

int vafmd_nanonis_start(void *zctx, const char *hostport, int allow_remote, char *err, size_t errlen, int *exit_code)
{
    char host[256] = "127.0.0.1", port[16];
    const char *colon = strrchr(hostport, ':');
    const char *p = colon ? colon + 1 : hostport;
    *exit_code = 2;
    if (colon) {
        size_t hl = (size_t)(colon - hostport);
        if (hl >= sizeof host || hl == 0) {
            snprintf(err, errlen, "--nanonis '%s': HOST must be 1 to 255 characters", hostport);
            return -1;
        }
        memcpy(host, hostport, hl);
        host[hl] = 0;
        if (host[0] == '[' && hl > 2 && host[hl - 1] == ']') { /* [::1] */
            memmove(host, host + 1, hl - 2);
            host[hl - 2] = 0;
        }
    }
    char *end;
    long pn = strtol(p, &end, 10);
    if (!*p || *end || pn < 1 || pn > 65535) {
        snprintf(err, errlen, "--nanonis '%s': PORT must be an integer in [1, 65535]", hostport);
        return -1;
    }
    snprintf(port, sizeof port, "%ld", pn);
    struct addrinfo hints, *ai = NULL;
    memset(&hints, 0, sizeof hints);
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV | (strcmp(host, "localhost") ? AI_NUMERICHOST : 0);
    int gai = getaddrinfo(host, port, &hints, &ai);
    if (gai || !ai) {
        snprintf(err, errlen, "--nanonis '%s': HOST must be a numeric address or localhost (%s)", hostport,
                 gai_strerror(gai));
        return -1;
    }
    if (!s_is_loopback(ai->ai_addr) && !allow_remote) {
        snprintf(err, errlen, "refusing to open the Nanonis port on '%s': the protocol has no authentication, so "
                              "only a loopback address is allowed unless --nanonis-allow-remote is given "
                              "(docs/nanonis.md)", hostport);
        freeaddrinfo(ai);
        return -1;
    }
    *exit_code = 1;
    int fd = socket(ai->ai_family, SOCK_STREAM | SOCK_CLOEXEC, 0);
    int one = 1;
    if (fd >= 0)
        setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    if (fd < 0 || bind(fd, ai->ai_addr, ai->ai_addrlen) || listen(fd, 8)) {
        snprintf(err, errlen, "cannot open the Nanonis port '%s': %s", hostport, strerror(errno));
        if (fd >= 0)
            close(fd);
        freeaddrinfo(ai);
        return -1;
    }
    freeaddrinfo(ai);
    memset(&s, 0, sizeof s);
    s.zctx = zctx;
    s.lfd = fd;
    s.request_s = S_REQUEST_TIMEOUT_S;
    const char *env = getenv("VAFMD_TEST_NANONIS_REQUEST_S");
    if (env && atof(env) > 0 && atof(env) <= S_REQUEST_TIMEOUT_S)
        s.request_s = atof(env);
    pthread_mutex_init(&s.mu, NULL);
    pthread_cond_init(&s.cv, NULL);
    s.sub = zmq_socket(zctx, ZMQ_SUB);
    int hwm = 100000; /* messages: ~8 min of 5 ms blocks, bounded */
    if (!s.sub || zmq_setsockopt(s.sub, ZMQ_RCVHWM, &hwm, sizeof hwm) ||
        zmq_setsockopt(s.sub, ZMQ_SUBSCRIBE, "data", 4) || zmq_setsockopt(s.sub, ZMQ_SUBSCRIBE, "run.end", 7) ||
        zmq_setsockopt(s.sub, ZMQ_SUBSCRIBE, "event", 5) || zmq_connect(s.sub, VAFMD_NANONIS_PUB_EP)) {
        snprintf(err, errlen, "cannot subscribe to the stream: %s", zmq_strerror(errno));
        if (s.sub)
            zmq_close(s.sub);
        close(fd);
        return -1;
    }
    nn_cmds_init();
    if (pthread_create(&s.th, NULL, s_listener_main, NULL)) {
        snprintf(err, errlen, "cannot start the Nanonis thread");
        zmq_close(s.sub);
        close(fd);
        return -1;
    }
    s.started = 1;
    return 0;
}

void vafmd_nanonis_stop(void)
{
    if (!s.started)
        return;
    atomic_store(&s.quit, 1);
    pthread_join(s.th, NULL); /* it joins the connection threads */
    zmq_close(s.sub);
    close(s.lfd);
    nn_run_free(&s.run);
    pthread_mutex_destroy(&s.mu);
    pthread_cond_destroy(&s.cv);
    s.started = 0;
}
