/* SPDX-License-Identifier: MIT */
/*
 * The batch kernel's backends, declared once (OpenMM's platform/kernel split): each row is one way of
 * running the gjf in-contact table steps of several curves, with its name, the curves it steps side by
 * side in one vector (lanes), whether this CPU runs it, and its step function. The rows are ordered by
 * lanes, narrowest first; row 0 is the scalar kernel, the reference every other row is tested against
 * (tests/test_batch.c, bit for bit on whole curves).
 *
 * Derived from the table: the batch widths (vafm_batch_width*), the kernel names `batch<lanes>` that
 * `vafm campaign --kernel` and `vafm study --kernel` accept and list, the campaign's batch_width check,
 * the daemon's `kernel` setting check, vafm_campaign_kernel_describe() and vafm_batch_steps()'s dispatch.
 * A new backend is a row in batch.c (docs/architecture.md, "Recipe: a new kernel backend").
 */
#ifndef VAFM_CORE_BACKEND_H
#define VAFM_CORE_BACKEND_H

#include "vafm/common.h"

struct vafm_kernel;

typedef struct vafm_backend {
    const char *name;     /* "scalar", "avx2", "avx512": the row's name */
    const char *describe; /* vafm_campaign_kernel_describe()'s words for a batch campaign on this row */
    int lanes;            /* curves per vector: 1 (scalar), 4, 8 */
    int (*available)(void); /* nonzero: this CPU runs the row */
    /* Run K[l] for up to want[l] steps (or until its contact ends), l < n ≤ vafm_batch_lanes_per_call(lanes);
     * done[l] receives the steps run. NULL where the row is not compiled in (another architecture). */
    void (*steps)(struct vafm_kernel *const *K, const long *want, long *done, int n);
} vafm_backend;

/** The rows, narrowest first. */
int vafm_backend_count(void);
const vafm_backend *vafm_backend_at(int i);

/** The row called `name`. @return 0 (*out set), VAFM_ENOTFOUND (no such row) or VAFM_ENOTSUP (this CPU
 *  does not run it; *out unchanged). */
int vafm_backend_find(const char *name, const vafm_backend **out);

/** Whether row i runs here: its available() and not masked by vafm_backend_off. */
int vafm_backend_usable(int i);

/** Test hook: bit i set makes row i (i ≥ 1) unavailable, as on a CPU without its instruction set. */
extern unsigned vafm_backend_off;

#endif
