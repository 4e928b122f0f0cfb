/* SPDX-License-Identifier: MIT */
/*
 * A bounded single-producer single-consumer ring of fixed-size items (C11 atomics).
 *
 * The control thread pushes commands, the simulation thread pops them without ever blocking: the
 * simulation's pacing must not depend on how busy the control thread is. The same ring carries the log
 * items (simulation → writer thread) and the log pool's free blocks back (writer → simulation thread).
 * Each index is written by one side only; acquire/release pairs publish the item bytes together with
 * the index.
 */
#ifndef VAFMD_SPSC_RING_H
#define VAFMD_SPSC_RING_H
#include <stdatomic.h>
#include <stddef.h>
#include <string.h>

#define VAFMD_RING_CAP 64u /* the command ring's capacity (power of two) */

typedef struct vafmd_ring {
    _Alignas(64) atomic_size_t head; /* next slot to write; written by the producer only */
    _Alignas(64) atomic_size_t tail; /* next slot to read; written by the consumer only */
    size_t item_size;
    size_t cap;           /* slots, a power of two */
    unsigned char *items; /* cap * item_size bytes, owned by the caller */
} vafmd_ring;

static inline void vafmd_ring_init(vafmd_ring *r, void *storage, size_t item_size, size_t cap)
{
    atomic_init(&r->head, 0);
    atomic_init(&r->tail, 0);
    r->item_size = item_size;
    r->cap = cap;
    r->items = storage;
}

/** Producer side. @return 1 if pushed, 0 if the ring is full. */
static inline int vafmd_ring_push(vafmd_ring *r, const void *item)
{
    size_t h = atomic_load_explicit(&r->head, memory_order_relaxed);
    size_t t = atomic_load_explicit(&r->tail, memory_order_acquire);
    if (h - t >= r->cap)
        return 0;
    memcpy(r->items + (h & (r->cap - 1)) * r->item_size, item, r->item_size);
    atomic_store_explicit(&r->head, h + 1, memory_order_release);
    return 1;
}

/** Producer side: free slots now (the consumer may free more at any time, never fewer). */
static inline size_t vafmd_ring_room(vafmd_ring *r)
{
    size_t h = atomic_load_explicit(&r->head, memory_order_relaxed);
    size_t t = atomic_load_explicit(&r->tail, memory_order_acquire);
    return r->cap - (h - t);
}

/** Consumer side. @return 1 if an item was popped into out, 0 if the ring is empty. */
static inline int vafmd_ring_pop(vafmd_ring *r, void *out)
{
    size_t t = atomic_load_explicit(&r->tail, memory_order_relaxed);
    size_t h = atomic_load_explicit(&r->head, memory_order_acquire);
    if (t == h)
        return 0;
    memcpy(out, r->items + (t & (r->cap - 1)) * r->item_size, r->item_size);
    atomic_store_explicit(&r->tail, t + 1, memory_order_release);
    return 1;
}
#endif
