/* SPDX-License-Identifier: MIT */
/*
 * The batch kernel: several curves' in-contact gjf steps at once, one curve per SIMD lane.
 *
 * Why: an in-contact step is one long chain of dependent operations (≈ 100 cycles of latency, see
 * docs/speed-and-accuracy.md); one curve leaves the core's pipelines mostly idle. W independent curves
 * in the W lanes of a vector register fill them: W = 8 with AVX-512, 4 with AVX2, 1 (the scalar loop)
 * otherwise, chosen at run time (the library is built with the default flags; the vector loops are
 * compiled for their instruction set with target attributes and run only where the CPU has it).
 *
 * Bit for bit: each lane does the scalar loop's operations (integrator_gjf.c with the table's
 * post-move, kernel.h) in the same order, without contraction into FMAs (-ffp-contract=off) and with
 * IEEE square roots, and draws the same normals of its own curve's stream. A curve run in a batch is
 * therefore the same, sample for sample, as the scalar kernel's, whatever W and whatever other curves
 * share the batch. Rare cases leave the vector path for that lane and step: a point beyond the contact
 * table (the exact solver) runs the scalar code for the lane.
 *
 * The split of work: a simulation advanced by vafm_sim_advance_batch() stops where it would run the
 * gjf integrator in contact with the tabulated JKR branch (the near zone of the retract, where a
 * curve's time goes) and hands its kernel and the run's step count out (VAFM_SIM_BATCH_WAIT); a driver
 * collects up to W such kernels, runs them with vafm_batch_steps() and gives each its step count back
 * (vafm_sim_batch_done); every other phase runs in the scalar path as before.
 */
#ifndef VAFM_CORE_BATCH_H
#define VAFM_CORE_BATCH_H

#include <stddef.h>

#include "vafm/sim.h"

struct vafm_kernel;

/* vafm_sim_advance_batch's "waiting for the batch kernel" (positive, apart from 0 done and 1 more) */
#define VAFM_SIM_BATCH_WAIT 3

/** vafm_sim_advance(), except that a plain in-contact gjf run on the contact table is handed out:
 *  @return VAFM_SIM_BATCH_WAIT then (vafm_sim_batch_kernel, vafm_sim_batch_done), else as vafm_sim_advance. */
int vafm_sim_advance_batch(vafm_sim *s, size_t max_samples, vafm_sample_fn fn, void *user);
/** The kernel of a waiting simulation and the steps it wants run. */
struct vafm_kernel *vafm_sim_batch_kernel(vafm_sim *s, long *want);
/** The batch kernel ran `steps` of the steps wanted (fewer when the contact ended). */
void vafm_sim_batch_done(vafm_sim *s, long steps);

/** Widest batch this CPU runs: 8 (AVX-512F/DQ), 4 (AVX2) or 1. */
int vafm_batch_width_max(void);
/** A supported width not above `want` (0: the widest): 8, 4 or 1. */
int vafm_batch_width(int want);

/** Lanes one vafm_batch_steps() call steps side by side at a width (two vectors of lanes; 1 at width 1). */
int vafm_batch_lanes_per_call(int width);

/** Run kernel K[l] (in contact, gjf, contact table) for up to want[l] steps or until its contact ends,
 *  for l < n, in batches of `width` lanes (a vafm_batch_width value); done[l] receives the steps run.
 *  Each kernel ends exactly as the scalar gjf run of the same steps leaves it. Never allocates. */
void vafm_batch_steps(struct vafm_kernel *const *K, const long *want, long *done, int n, int width);

#endif
