/* SPDX-License-Identifier: MIT */
/*
 * CURVE security (protocol/wire.md, "Security"): the ZAP handler thread (RFC 27) that admits a client
 * only if its CURVE public key is in the allow-list. libzmq asks the handler bound at
 * inproc://zeromq.zap.01 about every handshake on a CURVE server socket; without a "200" reply the
 * connection is closed before any message passes, so an unlisted client never reaches the command
 * decoder nor receives a sample.
 */
#include <errno.h>
#include <string.h>
#include <zmq.h>
#include "daemon/daemon.h"

#define S_ZAP_EP "inproc://zeromq.zap.01"

int vafmd_auth_bind(vafmd *d)
{
    vafmd_auth *a = &d->auth;
    a->zap = zmq_socket(d->zctx, ZMQ_REP);
    if (!a->zap)
        return -1;
    int zero = 0;
    zmq_setsockopt(a->zap, ZMQ_LINGER, &zero, sizeof zero);
    if (zmq_bind(a->zap, S_ZAP_EP)) {
        zmq_close(a->zap);
        a->zap = NULL;
        return -1;
    }
    return 0;
}

/* Make a server socket require CURVE with the daemon's key pair. */
int vafmd_auth_secure(vafmd *d, void *sock)
{
    int one = 1;
    if (zmq_setsockopt(sock, ZMQ_CURVE_SERVER, &one, sizeof one) ||
        zmq_setsockopt(sock, ZMQ_CURVE_SECRETKEY, d->auth.secret_z85, 40) ||
        zmq_setsockopt(sock, ZMQ_ZAP_DOMAIN, "vafmd", 5))
        return -1;
    return 0;
}

static int s_listed(const vafmd_auth *a, const unsigned char *key)
{
    for (size_t i = 0; i < a->n_clients; i++)
        if (!memcmp(a->clients[i], key, 32))
            return 1;
    return 0;
}

/* Receive one ZAP request (up to 8 frames) and answer it. */
static void s_serve_one(vafmd_auth *a)
{
    char fr[8][256];
    size_t len[8];
    int n = 0, more = 1;
    while (more) {
        int rc = zmq_recv(a->zap, n < 8 ? fr[n] : fr[7], sizeof fr[0], 0);
        if (rc < 0)
            return;
        if (n < 8)
            len[n++] = (size_t)rc > sizeof fr[0] ? sizeof fr[0] : (size_t)rc;
        int m = 0;
        size_t ms = sizeof m;
        zmq_getsockopt(a->zap, ZMQ_RCVMORE, &m, &ms);
        more = m;
    }
    /* frames: version, request id, domain, address, identity, mechanism, credentials... */
    int ok = n >= 7 && len[0] == 3 && !memcmp(fr[0], "1.0", 3) && len[5] == 5 && !memcmp(fr[5], "CURVE", 5) &&
             len[6] == 32 && s_listed(a, (const unsigned char *)fr[6]);
    if (ok)
        atomic_fetch_add_explicit(&a->accepted, 1, memory_order_relaxed);
    else
        atomic_fetch_add_explicit(&a->refused, 1, memory_order_relaxed);
    char uid[41] = "";
    if (ok)
        zmq_z85_encode(uid, (const uint8_t *)fr[6], 32);
    zmq_send(a->zap, "1.0", 3, ZMQ_SNDMORE);
    zmq_send(a->zap, n >= 2 ? fr[1] : "", n >= 2 ? len[1] : 0, ZMQ_SNDMORE);
    zmq_send(a->zap, ok ? "200" : "400", 3, ZMQ_SNDMORE);
    const char *text = ok ? "OK" : "client key not in the allow-list";
    zmq_send(a->zap, text, strlen(text), ZMQ_SNDMORE);
    zmq_send(a->zap, uid, strlen(uid), ZMQ_SNDMORE); /* user id: the client's key */
    zmq_send(a->zap, "", 0, 0);                      /* metadata: none */
}

void *vafmd_auth_main(void *arg)
{
    vafmd *d = arg;
    vafmd_auth *a = &d->auth;
    while (!atomic_load_explicit(&a->quit, memory_order_acquire)) {
        zmq_pollitem_t it = { a->zap, 0, ZMQ_POLLIN, 0 };
        int n = zmq_poll(&it, 1, 100);
        if (n < 0 && errno != EINTR)
            break;
        if (n > 0 && (it.revents & ZMQ_POLLIN))
            s_serve_one(a);
    }
    zmq_close(a->zap);
    a->zap = NULL;
    return NULL;
}
