/* SPDX-License-Identifier: MIT */
/*
 * The simulation thread's side of the log (design: sim_thread.h; the writer: log.c): the pool of log
 * blocks it copies released samples into without calling malloc, handing items to the writer's ring, and a
 * free run waiting for the writer instead of dropping curves.
 */
#include "daemon/sim_thread.h"

/* ---- The log block pool ----------------------------------------------------------------------------
 * The simulation thread calls no malloc/free per block (glibc's allocator may take a lock another thread
 * holds): a logged run's block is copied, at its release, into a log block taken from a pool, and the
 * writer thread gives each block back through the free ring (SPSC, writer → simulation thread) once it
 * has copied it into its curve. An empty pool is handled exactly like a full log ring: the block is
 * dropped, an overflow counted and the curve marked broken (not written); the other curves are intact.
 *
 * When: the pool is allocated at the start of a logged run, not when logging is switched on, because
 * the block size (sample_rate_Hz · block_s) is known only then and may change between runs while
 * logging stays on; run start already allocates (the compute-ahead FIFO, run.start), so nothing moves
 * into the paced block loop. The pool is kept from run to run while the block size stays (a campaign, a
 * series of curves), replaced when it changes, and released at the first run start after logging was
 * switched off (or at exit).
 * Size: the log ring's capacity + 1 blocks (what the ring and the writer's hand can hold, so that the
 * pool runs empty only when the ring is full anyway), at most VAFMD_LOG_POOL_MAX_BYTES of samples (with
 * large blocks the pool, not the ring, bounds the blocks in flight), at least 1; $VAFMD_TEST_LOG_POOL
 * (tests only) makes it smaller. The lookahead FIFO stages its blocks' own copies (time and segment
 * next to the channels), so the pool does not grow with the lookahead.
 * Lifetime: a replaced pool with blocks still at the writer is retired; its blocks come home through
 * the free ring (each block knows its pool) and it is freed at a run start once all are home. The free
 * ring has room for 2 · (ring capacity + 1) blocks: when a pool is replaced at most a ring's worth + 1
 * of blocks are out (this thread holds none between runs), plus the new pool's, so the writer's push
 * never fails. At exit this thread frees the pools that are home and leaves the others to the writer
 * thread (vafmd_log.orphans), which exits after it and frees them with the free ring's slots. */

static size_t s_pool_stride(size_t cap) /* bytes of one block's samples, 64-byte aligned */
{
    return (((size_t)vafm_channels_filed() * sizeof(double) + 1) * cap + 63) & ~(size_t)63;
}

static size_t s_pool_head(size_t n) /* the pool header, block headers and free stack, 64-byte aligned */
{
    return (sizeof(vafmd_log_pool) + n * (sizeof(vafmd_log_block) + sizeof(vafmd_log_block *)) + 63) & ~(size_t)63;
}

/* Blocks of a pool for blocks of block_n samples (see above). */
static size_t s_pool_size(const vafmd_st *x, size_t block_n)
{
    size_t n = x->d->log.ring.cap + 1, most = VAFMD_LOG_POOL_MAX_BYTES / s_pool_stride(block_n);
    if (n > most)
        n = most;
    if (x->pool_test_n && n > x->pool_test_n)
        n = x->pool_test_n;
    return n ? n : 1;
}

/* One allocation (free(p) releases it whole); the sample memory is not touched here (only the blocks
 * in use get their pages). Block 0 is on top of the free stack, and the stack is LIFO, so a writer that
 * keeps up makes the same few blocks go round. */
static vafmd_log_pool *s_pool_new(size_t n, size_t cap)
{
    size_t head = s_pool_head(n), stride = s_pool_stride(cap);
    if (stride && n > (SIZE_MAX - head) / stride)
        return NULL;
    unsigned char *m = malloc(head + n * stride);
    if (!m)
        return NULL;
    vafmd_log_pool *p = (vafmd_log_pool *)m;
    p->next = NULL;
    p->n_blocks = n;
    p->block_cap = cap;
    p->blocks = (vafmd_log_block *)(m + sizeof *p);
    p->free = (vafmd_log_block **)(p->blocks + n);
    for (size_t k = 0; k < n; k++) {
        vafmd_log_block *b = &p->blocks[k];
        double *d = (double *)(m + head + k * stride);
        b->n = 0;
        for (int c = 0; c < VAFM_CH_COUNT; c++) {
            b->ch[c] = vafm_channels[c].file ? d : NULL;
            d += vafm_channels[c].file ? cap : 0;
        }
        b->segment = (uint8_t *)d;
        b->pool = p;
        p->free[n - 1 - k] = b;
    }
    p->n_free = n;
    return p;
}

static void s_pool_put(vafmd_log_block *b)
{
    b->pool->free[b->pool->n_free++] = b;
}

/* Every block the writer gave back onto its pool's free stack: lock-free, bounded by the blocks of the
 * live pools. */
void vafmd_st_pool_reclaim(vafmd_log *L)
{
    vafmd_log_block *b;
    while (L->free_store && vafmd_ring_pop(&L->free_ring, &b))
        s_pool_put(b);
}

/* A free block of the current pool, or NULL (empty: the caller counts an overflow). No waiting. */
static vafmd_log_block *s_pool_get(vafmd_st *x)
{
    vafmd_log_pool *p = x->pool;
    if (!p)
        return NULL;
    if (!p->n_free)
        vafmd_st_pool_reclaim(&x->d->log);
    return p->n_free ? p->free[--p->n_free] : NULL;
}

void vafmd_st_pool_retire(vafmd_st *x)
{
    if (x->pool) {
        x->pool->next = x->retired;
        x->retired = x->pool;
        x->pool = NULL;
    }
}

/* At run start (off the block loop): the pool this run needs; retired pools whose blocks are all home
 * are freed. A pool that cannot be allocated costs the run's log (every block overflows), not the run. */
void vafmd_st_pool_prepare(vafmd_st *x, int logged, size_t block_n)
{
    vafmd_log *L = &x->d->log;
    vafmd_st_pool_reclaim(L);
    if (logged) {
        size_t n = s_pool_size(x, block_n);
        if (x->pool && (x->pool->block_cap != block_n || x->pool->n_blocks != n))
            vafmd_st_pool_retire(x);
        if (!x->pool && L->free_store)
            x->pool = s_pool_new(n, block_n);
    } else if (atomic_load_explicit(&L->state, memory_order_acquire) == VAFMD_LOG_OFF)
        vafmd_st_pool_retire(x);
    for (vafmd_log_pool **pp = &x->retired; *pp;) {
        vafmd_log_pool *p = *pp;
        if (p->n_free == p->n_blocks) {
            *pp = p->next;
            free(p);
        } else
            pp = &p->next;
    }
}

/* Hand one item to the writer thread without waiting: a full ring loses it (counted) and the curve. A
 * lost block goes back to its pool, a lost begin/end item is freed (they are allocated once per run, at
 * its start and end, not per block). @return 1 if the writer has it. */
int vafmd_st_log_push(vafmd_st_run *r, int type, void *ptr)
{
    vafmd_log_item it = { type, r->cmd.run_id, ptr };
    if (!ptr || !vafmd_ring_push(&r->log->ring, &it)) {
        if (type == VAFMD_LOG_BLOCK && ptr)
            s_pool_put(ptr);
        else
            free(ptr);
        r->log_broken = 1;
        atomic_fetch_add_explicit(&r->log->overflows, 1, memory_order_relaxed);
        return 0;
    }
    return 1;
}

/* ---- Free run: the simulation waits for the writer ---------------------------------------------------
 * A paced run never waits for the writer (a block that finds no room costs its curve, counted). A free
 * run has no deadline to keep, so it loses nothing: it releases a logged block only when the ring has
 * room for it AND for the curve's end item, and its pool a free block (so the end item always fits,
 * after a block as after the begin item); otherwise the block stays in the FIFO and the loop comes back
 * (commands, notices and heartbeats go on meanwhile). 0.6.2 dropped instead: a 16 x 16 free-run map lost
 * up to 164 of its 256 curves to a busy writer, and their end items with them (issue #29). */
int vafmd_st_log_room(vafmd_st *x, size_t need)
{
    return vafmd_ring_room(&x->d->log.ring) >= need;
}

/* A logged free-run block may be released now (see above). Without a pool (it could not be allocated)
 * every block overflows anyway: nothing to wait for. */
int vafmd_st_log_ready(vafmd_st *x)
{
    vafmd_log_pool *p = x->pool;
    if (!p)
        return 1;
    if (!p->n_free)
        vafmd_st_pool_reclaim(&x->d->log);
    return p->n_free && vafmd_st_log_room(x, 2);
}


/* A free run's begin item: wait until the ring has room for it and the end item (the writer frees a slot
 * within one curve append, milliseconds), publishing the writer's notices meanwhile (the writer may be
 * waiting for room for them). Given up at shutdown (then the item may be lost, counted). */
void vafmd_st_log_wait_room(vafmd_st *x)
{
    while (!vafmd_st_log_room(x, 2) && !atomic_load_explicit(&x->d->quitting, memory_order_acquire) && !*x->d->stop) {
        vafmd_st_log_notices(x);
        vafmd_st_sleep_until(vafmd_st_now() + 100000);
    }
}

/* At release: the block's logged samples (the very doubles just streamed) into a pool block, to the
 * writer. An empty pool counts as a full ring. */
void vafmd_st_log_block(vafmd_st *x, const vafmd_st_block *b)
{
    vafmd_st_run *r = &x->run;
    vafmd_log_block *lb = s_pool_get(x);
    if (lb && (lb->pool->block_cap < b->n || !b->log_t || !b->ch[VAFM_CH_HEIGHT] || !b->ch[VAFM_CH_FORCE] ||
               !b->ch[VAFM_CH_TIP])) {
        s_pool_put(lb); /* cannot happen: the pool is made for the run's blocks, curves stream 0, 2 and 4 */
        lb = NULL;
    }
    if (lb) {
        lb->mask = 0;
        for (int c = 0; c < VAFM_CH_COUNT; c++) { /* the streamed arrays; the times (not streamed live) */
            const double *src = b->ch[c] ? b->ch[c] : c == VAFM_CH_TIME ? b->log_t : NULL;
            if (lb->ch[c] && src) {
                memcpy(lb->ch[c], src, b->n * sizeof(double));
                lb->mask |= 1u << c;
            }
        }
        memcpy(lb->segment, b->log_seg, b->n);
        lb->n = b->n;
    }
    vafmd_st_log_push(r, VAFMD_LOG_BLOCK, lb);
}

/* The writer thread's durability notices, published as events (the simulation thread owns the socket). */
void vafmd_st_log_notices(vafmd_st *x)
{
    vafmd_log_notice n;
    while (vafmd_ring_pop(&x->d->log.notice_ring, &n)) {
        if (n.ok)
            vafmd_st_send_json(x, "event", json_pack("{s:I,s:s,s:I}", "run_id", (json_int_t)n.run_id, "kind", "logged",
                                              "group", (json_int_t)n.group));
        else
            vafmd_st_send_json(x, "event", json_pack("{s:I,s:s}", "run_id", (json_int_t)n.run_id, "kind", "log_failed"));
    }
}
