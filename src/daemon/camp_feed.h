/* SPDX-License-Identifier: MIT */
/*
 * A daemon campaign's curves computed ahead by the batch kernel (the `kernel` setting "batch", free run).
 *
 * Why: a free-run campaign streams curves as fast as they are computed, so its throughput is the
 * kernel's; the batch kernel steps several curves at once (core/batch.h), which the simulation thread,
 * one curve at a time, cannot. The feeder is its own thread running vafm_campaign_run() over the
 * campaign's grid with the batch kernel, every sample kept; it hands each finished curve, in index
 * order, through a lock-free single-producer single-consumer ring to the simulation thread, which
 * streams, logs and reports it exactly as one it computed itself (the same curve bit for bit).
 *
 * The simulation thread never waits: vafmd_feed_take() returns NULL while the next curve is not ready
 * (the thread looks again within a millisecond), and vafmd_feed_release() only tells the feeder to stop.
 * The feeder waits when the ring holds VAFMD_FEED_MAX_BYTES of samples (or VAFMD_FEED_RING curves), and
 * stops after its curves in flight once released; whichever side lets go last frees the feed (a
 * reference count), so neither joins the other. A curve taken out of the ring belongs to the taker.
 */
#ifndef VAFMD_CAMP_FEED_H
#define VAFMD_CAMP_FEED_H

#include <stddef.h>
#include <stdint.h>

#include "vafm/campaign.h"
#include "vafm/params.h"

#define VAFMD_FEED_RING 64u                     /* curves the ring holds */
#define VAFMD_FEED_MAX_BYTES (256.0 * 1024 * 1024) /* samples the ring holds (the feeder waits beyond) */

/* One finished curve: its samples (one allocation) and its ground truth. */
typedef struct vafmd_feed_curve {
    uint64_t index;
    int status;                 /* 0, or the VAFM_E* code the curve ended with */
    vafm_error error;           /* status ≠ 0: its detail (field, message) */
    vafm_curve_result result;
    size_t n;                   /* samples */
    vafm_samples samples;       /* the curve's arrays (core/channels.h's rows, in the allocation after
                                   this struct); height_measured_m NULL: the scene has no piezo model */
    size_t bytes;
} vafmd_feed_curve;

typedef struct vafmd_feed vafmd_feed;

/** Start computing the curves of spec (its first_curve on) from base, on one thread of its own. The lists
 *  spec points to are copied. @return 0, VAFM_ENOMEM, or VAFM_EINVAL (a grid given point by point). */
int vafmd_feed_start(vafmd_feed **out, const vafm_params *base, const vafm_campaign_spec *spec);

/** The next curve in index order, or NULL while it is not ready. Never waits. When NULL and the feeder has
 *  ended (no more curves will come), *ended is 1 and *rc the campaign's result (0: all delivered). */
vafmd_feed_curve *vafmd_feed_take(vafmd_feed *f, int *ended, int *rc);

/** Free a curve taken from the feed. */
void vafmd_feed_curve_free(vafmd_feed_curve **c);

/** Stop the feeder and let go of the feed (*f becomes NULL). Never waits. */
void vafmd_feed_release(vafmd_feed **f);

#endif
