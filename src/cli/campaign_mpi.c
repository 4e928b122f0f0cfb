/* SPDX-License-Identifier: MIT */
/*
 * `vafm campaign` on MPI: rank 0 is the dispenser and the writer, every rank (rank 0 too) computes.
 *
 * Why this design: the HDF5 file must equal the single-process file, curve order and provenance
 * included, and the single-process writer appends curves in index order with journaled flushes (the
 * --resume guarantee). Keeping one writer on rank 0 (Debian's serial HDF5) reuses that writer and its
 * crash story unchanged; parallel HDF5 would need a second, collective writer, a different Debian
 * package, and collective appends of curves whose sizes differ. A curve is a few hundred kB against
 * 10^7-10^8 integrator steps, so one writer is far from being the bottleneck.
 *
 * Balancing: indices go out one at a time on request (dynamic self-scheduling), so a rank that drew
 * slow curves simply asks less often. Each rank keeps one request in flight ahead of its threads, to
 * hide the round trip. Rank 0 hands each rank at most `quota` indices it has not written yet (the rank's
 * campaign window, its send queue and its prefetched index, with slack), which bounds the curves it
 * buffers for reordering to ranks x quota. A quota per rank, not one window for all: with one window a
 * fast rank could take all of it while a slow rank's batch worker held the next curve to write in a lane;
 * that worker then asked for an index to fill another lane, waited for it, and so never finished the
 * curve rank 0 was waiting for (0.6.1: `mpirun -np 2 vafm map`, 8 x 8, hung in a third of the runs).
 * Within its quota a rank's request is answered at once, and a rank whose quota is used up has curves
 * waiting at rank 0 only behind another rank's curve, which that rank can always finish.
 *
 * Messages: REQ rank→0 "one more index"; IDX 0→rank (on a duplicate of MPI_COMM_WORLD, so rank 0's
 * service thread never probes its own replies), the index or S_NONE; CURVE
 * rank→0, one packed curve (header, 5 double channels, segment bytes); FIN rank→0 after the rank's
 * campaign returned. Rank 0's service thread ends when every rank sent FIN.
 *
 * Threads: every MPI call of a process is made under one mutex (MPI_THREAD_SERIALIZED). Waits are
 * MPI_Test/MPI_Iprobe polls with a short sleep, the lock released in between, so rank 0's service
 * thread and every rank's threads share MPI, and idle ranks do not spin a core (OpenMPI's blocking
 * calls busy-poll, which would steal a core from the computing threads). The only blocking calls are
 * rank 0's receive of a message already arriving and its tiny index replies to posted receives. A
 * sender thread per rank ships the finished curves and tests each send often, which both frees the
 * compute threads from the network and drives large transfers (moved in fragments, one per test).
 */
#include <errno.h>
#include <inttypes.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "cli/campaign_mpi.h"
#include "core/channels.h"

int vafm_cli_mpi_launched(void)
{
    static const char *const vars[] = { "OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE" };
    for (size_t i = 0; i < sizeof vars / sizeof vars[0]; i++)
        if (getenv(vars[i]))
            return 1;
    return 0;
}

#ifndef VAFM_HAVE_MPI

struct vafm_cli_mpi {
    int unused;
};

int vafm_cli_mpi_begin(int required, vafm_cli_mpi **out)
{
    *out = NULL;
    if (!required && !vafm_cli_mpi_launched())
        return 0;
    fprintf(stderr, "vafm: campaign: %s, but this vafm was built without MPI support.\n"
                    "vafm: to run campaigns on MPI install OpenMPI (Debian/Ubuntu: apt install libopenmpi-dev "
                    "openmpi-bin) and rebuild:\n"
                    "vafm:   meson setup --reconfigure BUILDDIR -Dmpi=enabled && ninja -C BUILDDIR\n"
                    "vafm: (started without mpirun and --mpi, vafm campaign runs on this machine's cores)\n",
            required ? "--mpi asks for MPI" : "launched by an MPI launcher (mpirun/srun)");
    return 2;
}

int vafm_cli_mpi_rank(const vafm_cli_mpi *m) { return 0; }
int vafm_cli_mpi_size(const vafm_cli_mpi *m) { return 1; }

int vafm_cli_mpi_agree(vafm_cli_mpi *m, int rc, const vafm_params *base, const vafm_campaign_spec *spec)
{
    return rc;
}

int vafm_cli_mpi_run(vafm_cli_mpi *m, const vafm_params *base, const vafm_campaign_spec *spec,
                     vafm_campaign_fn fn, void *user, vafm_error *err)
{
    return vafm_campaign_run(base, spec, fn, user, err);
}

void vafm_cli_mpi_describe(const vafm_cli_mpi *m, FILE *o) {}

int vafm_cli_mpi_end(vafm_cli_mpi **m, int rc)
{
    return rc;
}

#else /* VAFM_HAVE_MPI */

/* OpenMPI's mpi.h is not -Wpedantic clean in every version. */
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpedantic"
#include <mpi.h>
#pragma GCC diagnostic pop

enum { S_TAG_REQ = 101, S_TAG_IDX, S_TAG_CURVE, S_TAG_FIN };
#define S_NONE UINT64_MAX
#define S_POLL_MIN_NS 20000L    /* first sleep of a poll loop */
#define S_POLL_MAX_NS 1000000L  /* longest: an idle rank wakes 1000 times a second */
#define S_POLL_SEND_NS 50000L   /* a curve on its way: the sender's tests drive the transfer */
#define S_SENDS 8               /* curves a rank may queue for rank 0 before its threads wait */

struct vafm_cli_mpi {
    int rank, size;
    int local_size;          /* ranks on this node (MPI_COMM_TYPE_SHARED) */
    pthread_mutex_t mu;      /* every MPI call */
    MPI_Comm replies;        /* rank 0's index replies: apart from what its service thread probes for */
    int threads_total;       /* sum of the ranks' worker threads (after run) */
    uint64_t *per_rank;      /* rank 0: curves received from each rank (after run) */
};

/* ---- polling without spinning ------------------------------------------------------------------- */

static void s_nap(long *ns, long max_ns)
{
    struct timespec ts = { 0, *ns };
    nanosleep(&ts, NULL);
    *ns = *ns * 2 > max_ns ? max_ns : *ns * 2;
}

/* Wait for a request, taking the MPI lock only for each test, sleeping at most max_ns between tests. */
static int s_wait_max(vafm_cli_mpi *m, MPI_Request *r, long max_ns)
{
    long ns = S_POLL_MIN_NS;
    for (;;) {
        int done = 0;
        pthread_mutex_lock(&m->mu);
        int e = MPI_Test(r, &done, MPI_STATUS_IGNORE);
        pthread_mutex_unlock(&m->mu);
        if (e != MPI_SUCCESS)
            return VAFM_EIO;
        if (done)
            return 0;
        s_nap(&ns, max_ns);
    }
}

static int s_wait(vafm_cli_mpi *m, MPI_Request *r)
{
    return s_wait_max(m, r, S_POLL_MAX_NS);
}

static int s_allreduce(vafm_cli_mpi *m, const void *in, void *out, int n, MPI_Datatype t, MPI_Op op)
{
    MPI_Request r;
    pthread_mutex_lock(&m->mu);
    int e = MPI_Iallreduce(in, out, n, t, op, MPI_COMM_WORLD, &r);
    pthread_mutex_unlock(&m->mu);
    return e == MPI_SUCCESS ? s_wait(m, &r) : VAFM_EIO;
}

/* ---- start, agree, end --------------------------------------------------------------------------- */

int vafm_cli_mpi_begin(int required, vafm_cli_mpi **out)
{
    *out = NULL;
    if (!required && !vafm_cli_mpi_launched())
        return 0;
    int provided = 0;
    if (MPI_Init_thread(NULL, NULL, MPI_THREAD_SERIALIZED, &provided) != MPI_SUCCESS) {
        fprintf(stderr, "vafm: campaign: MPI_Init_thread failed\n");
        return 2;
    }
    if (provided < MPI_THREAD_SERIALIZED) {
        fprintf(stderr, "vafm: campaign: this MPI library offers thread level %d; vafm needs "
                        "MPI_THREAD_SERIALIZED (%d)\n", provided, MPI_THREAD_SERIALIZED);
        MPI_Abort(MPI_COMM_WORLD, 2);
        return 2;
    }
    vafm_cli_mpi *m = calloc(1, sizeof *m);
    if (!m) {
        fprintf(stderr, "vafm: out of memory\n");
        MPI_Abort(MPI_COMM_WORLD, 1);
        return 1;
    }
    pthread_mutex_init(&m->mu, NULL);
    MPI_Comm_rank(MPI_COMM_WORLD, &m->rank);
    MPI_Comm_size(MPI_COMM_WORLD, &m->size);
    if (MPI_Comm_dup(MPI_COMM_WORLD, &m->replies) != MPI_SUCCESS) {
        fprintf(stderr, "vafm: campaign: MPI_Comm_dup failed\n");
        MPI_Abort(MPI_COMM_WORLD, 1);
    }
    MPI_Comm node;
    m->local_size = 1;
    if (MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node) == MPI_SUCCESS) {
        MPI_Comm_size(node, &m->local_size);
        MPI_Comm_free(&node);
    }
    *out = m;
    return 0;
}

int vafm_cli_mpi_rank(const vafm_cli_mpi *m)
{
    return m ? m->rank : 0;
}

int vafm_cli_mpi_size(const vafm_cli_mpi *m)
{
    return m ? m->size : 1;
}

/* FNV-1a of the scene (JSON of every field) and the grid, as the file's provenance would record them. */
static uint64_t s_fingerprint(const vafm_params *p, const vafm_campaign_spec *s)
{
    char buf[16384];
    int n = vafm_params_to_json(p, buf, sizeof buf);
    size_t len = n > 0 ? (size_t)n : 0;
    const struct { const double *v; size_t n; } lists[3] = { { s->T_K, s->n_T }, { s->v_m_per_s, s->n_v },
                                                             { s->k_N_per_m, s->n_k } };
    for (int l = 0; l < 3; l++) {
        len += (size_t)snprintf(buf + len, sizeof buf - len, "|%zu:", lists[l].n);
        for (size_t i = 0; i < lists[l].n && len < sizeof buf; i++)
            len += (size_t)snprintf(buf + len, sizeof buf - len, "%.17g,", lists[l].v[i]);
        if (len >= sizeof buf)
            len = sizeof buf - 1;
    }
    len += (size_t)snprintf(buf + len, sizeof buf - len, "|N=%" PRIu64 "|P=%zu|%.4000s", s->curves_per_point,
                            s->point_fn ? s->n_points : 0, s->map_json ? s->map_json : "");
    if (len >= sizeof buf)
        len = sizeof buf - 1;
    uint64_t h = 1469598103934665603ULL;
    for (size_t i = 0; i < len; i++)
        h = (h ^ (unsigned char)buf[i]) * 1099511628211ULL;
    return h;
}

int vafm_cli_mpi_agree(vafm_cli_mpi *m, int rc, const vafm_params *base, const vafm_campaign_spec *spec)
{
    if (!m)
        return rc;
    unsigned long long mine = (!rc && base && spec) ? s_fingerprint(base, spec) : 0, root = mine;
    MPI_Request r;
    pthread_mutex_lock(&m->mu);
    int e = MPI_Ibcast(&root, 1, MPI_UNSIGNED_LONG_LONG, 0, MPI_COMM_WORLD, &r);
    pthread_mutex_unlock(&m->mu);
    if (e != MPI_SUCCESS || s_wait(m, &r))
        rc = rc ? rc : 1;
    if (!rc && root && mine != root) {
        fprintf(stderr, "vafm: campaign: rank %d: the scene or grid differs from rank 0's (different scene "
                        "files or arguments on this node?)\n", m->rank);
        rc = 2;
    }
    int all = rc;
    if (s_allreduce(m, &rc, &all, 1, MPI_INT, MPI_MAX))
        all = rc ? rc : 1;
    return all;
}

int vafm_cli_mpi_end(vafm_cli_mpi **mp, int rc)
{
    vafm_cli_mpi *m = mp ? *mp : NULL;
    if (!m)
        return rc;
    /* Rank 0 may still be closing the file: wait for it here without spinning, then finalise. */
    MPI_Request r;
    pthread_mutex_lock(&m->mu);
    int e = MPI_Ibarrier(MPI_COMM_WORLD, &r);
    pthread_mutex_unlock(&m->mu);
    if (e == MPI_SUCCESS)
        s_wait(m, &r);
    MPI_Comm_free(&m->replies);
    MPI_Finalize();
    pthread_mutex_destroy(&m->mu);
    free(m->per_rank);
    free(m);
    *mp = NULL;
    return rc;
}

void vafm_cli_mpi_describe(const vafm_cli_mpi *m, FILE *o)
{
    if (!m)
        return;
    fprintf(o, "mpi          %d rank(s), %d worker thread(s) in all; curves computed per rank:", m->size,
            m->threads_total);
    for (int i = 0; i < m->size && m->per_rank; i++)
        fprintf(o, " %" PRIu64, m->per_rank[i]);
    fputc('\n', o);
}

/* ---- a curve on the wire -------------------------------------------------------------------------- */

typedef struct s_hdr {
    uint64_t index;
    uint64_t n;      /* samples */
    int32_t status;
    uint32_t chmask; /* the channels packed after it (bits of core/channels.h's rows) */
    vafm_curve_result result;
} s_hdr;

_Static_assert(sizeof(s_hdr) % sizeof(double) == 0, "the channels after the header stay aligned");

/* The arrays a packed curve carries: every row of core/channels.h that is a vafm_samples array the curve
 * has (the measured height only with a piezo model), in row order, then the segments. */
static uint32_t s_chmask(const vafm_samples *s)
{
    uint32_t m = 0;
    for (int i = 0; i < VAFM_CH_COUNT; i++)
        if (vafm_channels[i].field >= 0 && vafm_channel_samples(s, i))
            m |= 1u << i;
    return m;
}

static size_t s_packed_size(uint64_t n, uint32_t chmask)
{
    return sizeof(s_hdr) + (size_t)n * ((size_t)__builtin_popcount(chmask) * sizeof(double) + 1);
}

/* ---- every rank: the source of indices and the sender of curves -------------------------------- */

typedef struct s_rank {
    vafm_cli_mpi *m;
    int outstanding;      /* a REQ is on its way, its reply not yet in */
    MPI_Request rreq;     /* the reply */
    uint64_t reply;
    int req_token;        /* the REQ's (empty) payload */
    int have;             /* `reply` holds an index not yet handed to a thread */
    int none;             /* rank 0 said: no more */
    _Atomic int failed;   /* set by any thread of the rank */
    /* The sender thread: packed curves queue here (FIFO) and it sends them one by one. */
    pthread_mutex_t qmu;
    pthread_cond_t qcv;
    char *q[S_SENDS];
    size_t qsize[S_SENDS];
    int qhead, qcount, qstop;
} s_rank;

/* With the MPI lock held. */
static int s_request(s_rank *rk)
{
    MPI_Request sreq;
    if (MPI_Irecv(&rk->reply, 1, MPI_UINT64_T, 0, S_TAG_IDX, rk->m->replies, &rk->rreq) != MPI_SUCCESS ||
        MPI_Isend(&rk->req_token, 1, MPI_INT, 0, S_TAG_REQ, MPI_COMM_WORLD, &sreq) != MPI_SUCCESS)
        return VAFM_EIO;
    MPI_Request_free(&sreq); /* completes with the reply: rank 0 answers only what it received */
    rk->outstanding = 1;
    return 0;
}

static int s_source(void *user, uint64_t *index)
{
    s_rank *rk = user;
    vafm_cli_mpi *m = rk->m;
    if (rk->failed)
        return VAFM_EIO;
    if (!rk->have && !rk->none) {
        if (!rk->outstanding) {
            pthread_mutex_lock(&m->mu);
            int r = s_request(rk);
            pthread_mutex_unlock(&m->mu);
            if (r) {
                rk->failed = 1;
                return r;
            }
        }
        if (s_wait(m, &rk->rreq)) {
            rk->failed = 1;
            return VAFM_EIO;
        }
        rk->outstanding = 0;
        if (rk->reply == S_NONE)
            rk->none = 1;
        else
            rk->have = 1;
    }
    if (!rk->have)
        return 0;
    *index = rk->reply;
    rk->have = 0;
    /* Ask for the next one now: its round trip overlaps this curve's computation. */
    pthread_mutex_lock(&m->mu);
    int r = s_request(rk);
    pthread_mutex_unlock(&m->mu);
    if (r)
        rk->failed = 1;
    return 1;
}

/* The sender thread. A large message moves in fragments, each pushed by one of the sender's MPI calls:
 * a thread that tests it often gets it to rank 0 promptly (rank 0 receives it blocking), while the
 * compute threads go on computing. */
static void *s_sender(void *arg)
{
    s_rank *rk = arg;
    pthread_mutex_lock(&rk->qmu);
    for (;;) {
        if (!rk->qcount) {
            if (rk->qstop)
                break;
            pthread_cond_wait(&rk->qcv, &rk->qmu);
            continue;
        }
        char *buf = rk->q[rk->qhead];
        size_t size = rk->qsize[rk->qhead];
        pthread_mutex_unlock(&rk->qmu);
        MPI_Request r;
        int bad = rk->failed;
        if (!bad) {
            pthread_mutex_lock(&rk->m->mu);
            int e = MPI_Isend(buf, (int)size, MPI_BYTE, 0, S_TAG_CURVE, MPI_COMM_WORLD, &r);
            pthread_mutex_unlock(&rk->m->mu);
            bad = e != MPI_SUCCESS || s_wait_max(rk->m, &r, S_POLL_SEND_NS);
        }
        free(buf);
        pthread_mutex_lock(&rk->qmu);
        if (bad)
            rk->failed = 1;
        rk->qhead = (rk->qhead + 1) % S_SENDS;
        rk->qcount--;
        pthread_cond_broadcast(&rk->qcv);
    }
    pthread_mutex_unlock(&rk->qmu);
    return NULL;
}

/* The campaign's callback on every rank: pack the curve and queue it for the sender thread (waiting
 * only when S_SENDS are queued already). */
static int s_send_curve(void *user, const vafm_campaign_curve *c)
{
    s_rank *rk = user;
    uint64_t n = c->samples.n;
    const uint32_t chmask = s_chmask(&c->samples);
    size_t size = s_packed_size(n, chmask);
    char *buf = size <= (size_t)INT32_MAX ? malloc(size) : NULL;
    if (!buf) {
        fprintf(stderr, "vafm: rank %d: curve %" PRIu64 " (%" PRIu64 " samples): %s\n", rk->m->rank, c->index, n,
                size > (size_t)INT32_MAX ? "too large for one MPI message (2 GB)" : "out of memory");
        free(buf);
        rk->failed = 1;
        return 1;
    }
    s_hdr h;
    memset(&h, 0, sizeof h);
    h.index = c->index;
    h.n = n;
    h.status = c->status;
    h.chmask = chmask;
    h.result = c->result;
    memcpy(buf, &h, sizeof h);
    double *ch = (double *)(void *)(buf + sizeof h);
    size_t k = 0;
    for (int i = 0; i < VAFM_CH_COUNT; i++)
        if (chmask & (1u << i)) {
            if (n)
                memcpy(ch + k * n, vafm_channel_samples(&c->samples, i), n * sizeof(double));
            k++;
        }
    if (n)
        memcpy(ch + k * n, c->samples.segment, n);
    pthread_mutex_lock(&rk->qmu);
    while (rk->qcount == S_SENDS && !rk->failed)
        pthread_cond_wait(&rk->qcv, &rk->qmu);
    int bad = rk->failed;
    if (!bad) {
        int tail = (rk->qhead + rk->qcount) % S_SENDS;
        rk->q[tail] = buf;
        rk->qsize[tail] = size;
        rk->qcount++;
        pthread_cond_broadcast(&rk->qcv);
    }
    pthread_mutex_unlock(&rk->qmu);
    if (bad)
        free(buf);
    return bad;
}

/* ---- rank 0: the dispenser and the writer's feed ---------------------------------------------- */

typedef struct s_slot {
    char *buf; /* the packed curve, NULL: not in yet */
    int owner; /* the rank the index went to */
} s_slot;

typedef struct s_server {
    vafm_cli_mpi *m;
    const vafm_params *point_params;
    uint64_t N, total, next, deliver_next;
    size_t window;         /* ranks x quota: the indices in [deliver_next, next) never exceed it */
    uint64_t quota;        /* indices a rank may hold that are not written yet */
    uint64_t *held;        /* per rank: its indices in [deliver_next, next) */
    s_slot *slots;
    int *pending;          /* ranks waiting for an index, FIFO */
    int n_pending;
    int fins, stop, error;
    vafm_campaign_fn fn;
    void *user;
    uint64_t *per_rank;
} s_server;

static void s_deliver(s_server *sv)
{
    while (sv->deliver_next < sv->total) {
        s_slot *sl = &sv->slots[sv->deliver_next % sv->window];
        if (!sl->buf)
            return;
        s_hdr h;
        memcpy(&h, sl->buf, sizeof h);
        if (!sv->stop) {
            const double *ch = (const double *)(const void *)(sl->buf + sizeof h);
            size_t n = (size_t)h.n;
            vafm_campaign_curve c;
            memset(&c, 0, sizeof c);
            c.index = h.index;
            c.point = (size_t)(h.index / sv->N);
            c.params = &sv->point_params[c.point];
            c.status = h.status;
            c.result = h.result;
            c.samples.n = n;
            size_t k = 0;
            for (int i = 0; i < VAFM_CH_COUNT; i++)
                if (h.chmask & (1u << i))
                    vafm_channel_set_samples(&c.samples, i, ch + k++ * n);
            c.samples.segment = (const uint8_t *)(ch + k * n);
            if (sv->fn && sv->fn(sv->user, &c))
                sv->stop = 1;
        }
        free(sl->buf);
        sl->buf = NULL;
        sv->held[sl->owner]--;
        sv->deliver_next++;
    }
}

/* With the MPI lock held: answer the waiting ranks their quotas allow. */
static void s_answer(s_server *sv)
{
    int kept = 0;
    for (int i = 0; i < sv->n_pending; i++) {
        int to = sv->pending[i];
        uint64_t idx;
        if (sv->stop || sv->error || sv->next >= sv->total) {
            idx = S_NONE;
        } else if (sv->held[to] < sv->quota) { /* then next − deliver_next < ranks x quota = window */
            idx = sv->next++;
            sv->slots[idx % sv->window].owner = to;
            sv->held[to]++;
        } else {
            sv->pending[kept++] = to;
            continue;
        }
        /* The rank posted its receive before its request: this small send completes at once. */
        if (MPI_Send(&idx, 1, MPI_UINT64_T, to, S_TAG_IDX, sv->m->replies) != MPI_SUCCESS)
            sv->error = VAFM_EIO;
    }
    sv->n_pending = kept;
}

static void *s_serve(void *arg)
{
    s_server *sv = arg;
    vafm_cli_mpi *m = sv->m;
    long ns = S_POLL_MIN_NS;
    while (sv->fins < m->size) {
        int flag = 0, got_curve = 0;
        MPI_Status st;
        char *buf = NULL;
        pthread_mutex_lock(&m->mu);
        if (MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, MPI_COMM_WORLD, &flag, &st) != MPI_SUCCESS) {
            sv->error = VAFM_EIO;
            flag = 0;
        }
        int count = 0;
        if (flag) {
            MPI_Get_count(&st, MPI_BYTE, &count);
            int token = 0;
            if (st.MPI_TAG == S_TAG_CURVE && !(buf = malloc(count > 0 ? (size_t)count : 1))) {
                fprintf(stderr, "vafm: out of memory\n");
                MPI_Abort(MPI_COMM_WORLD, 1);
            }
            int e = buf ? MPI_Recv(buf, count, MPI_BYTE, st.MPI_SOURCE, st.MPI_TAG, MPI_COMM_WORLD, MPI_STATUS_IGNORE)
                        : MPI_Recv(&token, 1, MPI_INT, st.MPI_SOURCE, st.MPI_TAG, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
            if (e != MPI_SUCCESS)
                sv->error = VAFM_EIO;
            if (st.MPI_TAG == S_TAG_REQ && sv->n_pending < m->size)
                sv->pending[sv->n_pending++] = st.MPI_SOURCE;
            else if (st.MPI_TAG == S_TAG_FIN)
                sv->fins++;
            else if (st.MPI_TAG == S_TAG_CURVE)
                got_curve = 1;
        }
        pthread_mutex_unlock(&m->mu);
        if (got_curve) {
            s_hdr h;
            memset(&h, 0, sizeof h);
            if ((size_t)count >= sizeof h)
                memcpy(&h, buf, sizeof h);
            /* Only a whole curve of an index handed out and not yet written can arrive. */
            if ((size_t)count >= sizeof h && h.n < ((uint64_t)1 << 40) && h.chmask < (1u << VAFM_CH_COUNT) &&
                (size_t)count == s_packed_size(h.n, h.chmask) &&
                h.index >= sv->deliver_next && h.index < sv->next && !sv->slots[h.index % sv->window].buf) {
                sv->slots[h.index % sv->window].buf = buf;
                sv->per_rank[st.MPI_SOURCE]++;
                s_deliver(sv); /* the writer runs without the MPI lock */
            } else {
                free(buf);
                sv->error = VAFM_EFORMAT;
            }
        }
        pthread_mutex_lock(&m->mu);
        s_answer(sv);
        pthread_mutex_unlock(&m->mu);
        if (flag)
            ns = S_POLL_MIN_NS;
        else
            s_nap(&ns, S_POLL_MAX_NS);
    }
    return NULL;
}

int vafm_cli_mpi_run(vafm_cli_mpi *m, const vafm_params *base, const vafm_campaign_spec *spec,
                     vafm_campaign_fn fn, void *user, vafm_error *err)
{
    vafm_campaign_spec sp = *spec;
    if (sp.threads <= 0) {
        /* The rank's share of the node: ranks x threads = cores, as a single process would use. */
        long cores = sysconf(_SC_NPROCESSORS_ONLN);
        sp.threads = (int)(cores / (m->local_size > 0 ? m->local_size : 1));
        if (sp.threads < 1)
            sp.threads = 1;
    }
    int total_threads = sp.threads;
    if (s_allreduce(m, &sp.threads, &total_threads, 1, MPI_INT, MPI_SUM))
        return VAFM_EIO;
    m->threads_total = total_threads;
    /* the indices every rank's campaign may hold ahead of delivery (the batch kernel keeps several curves
     * per thread in flight): rank 0 must hand out that many ahead, or a rank waits on it forever */
    int ahead = (int)vafm_campaign_window(base, &sp), max_ahead = ahead;
    if (s_allreduce(m, &ahead, &max_ahead, 1, MPI_INT, MPI_MAX))
        return VAFM_EIO;

    s_server sv;
    memset(&sv, 0, sizeof sv);
    pthread_t server;
    int serving = 0;
    vafm_params *pp = NULL;
    if (m->rank == 0) {
        size_t np = vafm_campaign_points(&sp);
        sv.m = m;
        sv.N = sp.curves_per_point;
        sv.total = sv.N * (uint64_t)np;
        sv.next = sv.deliver_next = sp.first_curve < sv.total ? sp.first_curve : sv.total;
        /* A rank's quota: its campaign's window (every thread busy with its curves in flight), the curves
         * its sender may queue, its prefetched index and slack for uneven curves. */
        sv.quota = (uint64_t)max_ahead + S_SENDS + 4;
        sv.window = (size_t)sv.quota * (size_t)m->size;
        sv.held = calloc((size_t)m->size, sizeof *sv.held);
        sv.fn = fn;
        sv.user = user;
        pp = calloc(np, sizeof *pp);
        sv.slots = calloc(sv.window, sizeof *sv.slots);
        sv.pending = calloc((size_t)m->size, sizeof *sv.pending);
        sv.per_rank = calloc((size_t)m->size, sizeof *sv.per_rank);
        if (!pp || !sv.slots || !sv.pending || !sv.per_rank || !sv.held) {
            fprintf(stderr, "vafm: out of memory\n");
            MPI_Abort(MPI_COMM_WORLD, 1);
        }
        for (size_t i = 0; i < np; i++)
            vafm_campaign_point_params(base, &sp, i, &pp[i]);
        sv.point_params = pp;
        serving = pthread_create(&server, NULL, s_serve, &sv) == 0;
        if (!serving) {
            fprintf(stderr, "vafm: cannot start the MPI service thread\n");
            MPI_Abort(MPI_COMM_WORLD, 1);
        }
    }

    /* Every rank, rank 0 included, computes through the library's campaign. */
    s_rank rk;
    memset(&rk, 0, sizeof rk);
    rk.m = m;
    pthread_mutex_init(&rk.qmu, NULL);
    pthread_cond_init(&rk.qcv, NULL);
    pthread_t sender;
    if (pthread_create(&sender, NULL, s_sender, &rk) != 0) {
        fprintf(stderr, "vafm: rank %d: cannot start the sender thread\n", m->rank);
        MPI_Abort(MPI_COMM_WORLD, 1);
    }
    vafm_error lerr;
    memset(&lerr, 0, sizeof lerr);
    int r = vafm_campaign_run_source(base, &sp, s_source, &rk, s_send_curve, &rk, &lerr);
    if (r || rk.failed) {
        /* This rank lost curves it was handed (out of memory, a curve too large to send, MPI failing):
         * rank 0 would wait for them forever. End the job as a lost rank ends it; --resume goes on. */
        fprintf(stderr, "vafm: rank %d: %s; ending the MPI job (vafm campaign --resume continues the file)\n",
                m->rank, lerr.message[0] ? lerr.message : vafm_strerror(r ? r : VAFM_EIO));
        MPI_Abort(MPI_COMM_WORLD, 1);
        return r ? r : VAFM_EIO;
    }
    pthread_mutex_lock(&rk.qmu); /* every curve sent before FIN */
    rk.qstop = 1;
    pthread_cond_broadcast(&rk.qcv);
    pthread_mutex_unlock(&rk.qmu);
    pthread_join(sender, NULL);
    pthread_mutex_destroy(&rk.qmu);
    pthread_cond_destroy(&rk.qcv);
    if (rk.failed) {
        fprintf(stderr, "vafm: rank %d: a curve could not be sent; ending the MPI job\n", m->rank);
        MPI_Abort(MPI_COMM_WORLD, 1);
    }
    int fin = 0;
    MPI_Request fr;
    pthread_mutex_lock(&m->mu);
    int e = MPI_Isend(&fin, 1, MPI_INT, 0, S_TAG_FIN, MPI_COMM_WORLD, &fr);
    pthread_mutex_unlock(&m->mu);
    if (e != MPI_SUCCESS || s_wait(m, &fr)) {
        fprintf(stderr, "vafm: rank %d: cannot reach rank 0\n", m->rank);
        MPI_Abort(MPI_COMM_WORLD, 1);
    }
    if (m->rank != 0)
        return 0;

    pthread_join(server, NULL);
    for (size_t i = 0; i < sv.window; i++)
        free(sv.slots[i].buf);
    free(sv.slots);
    free(sv.held);
    free(sv.pending);
    free(pp);
    m->per_rank = sv.per_rank;
    if (sv.stop)
        return VAFM_EABORT; /* the callback stopped the campaign: it knows why */
    if (sv.error || sv.deliver_next < sv.total) {
        int code = sv.error ? sv.error : VAFM_EIO;
        if (err && !err->message[0]) {
            err->code = code;
            snprintf(err->message, sizeof err->message,
                     "MPI campaign: %s; %" PRIu64 " of %" PRIu64 " curves written (vafm campaign --resume runs the "
                     "rest)", vafm_strerror(code), sv.deliver_next, sv.total);
        }
        return code;
    }
    return 0;
}

#endif /* VAFM_HAVE_MPI */
