/* SPDX-License-Identifier: MIT */
/*
 * `vafm campaign` on MPI (issue #8). MPI only changes who computes which curve: every rank runs the
 * library's campaign (vafm_campaign_run_source, threads within the rank as usual) over indices that
 * rank 0 hands out one at a time; the finished curves travel to rank 0, which feeds them, in index
 * order, to the same callback that writes the single-process file. So the file is the single-process
 * file, curve for curve. Without MPI (meson -Dmpi=disabled or libopenmpi-dev missing) these functions
 * are stubs that explain how to get MPI support when it is asked for.
 */
#ifndef VAFM_CLI_CAMPAIGN_MPI_H
#define VAFM_CLI_CAMPAIGN_MPI_H

#include <stdint.h>
#include <stdio.h>

#include "vafm/campaign.h"
#include "vafm/common.h"
#include "vafm/params.h"

typedef struct vafm_cli_mpi vafm_cli_mpi;

/** 1 when an MPI launcher started this process (OMPI_COMM_WORLD_SIZE, PMIX_RANK, PMI_RANK or PMI_SIZE
 *  in the environment), else 0. */
int vafm_cli_mpi_launched(void);

/** Start MPI when launched by mpirun/srun or `required` (--mpi); *out stays NULL otherwise (plain
 *  single-process campaign). @return 0, or 2 with a message on stderr (MPI asked for, not built in, or
 *  it failed to start). */
int vafm_cli_mpi_begin(int required, vafm_cli_mpi **out);

/** This process's rank and the number of ranks. */
int vafm_cli_mpi_rank(const vafm_cli_mpi *m);
int vafm_cli_mpi_size(const vafm_cli_mpi *m);

/** Collective. Every rank brings its status so far (0 or an exit code) and, when rc is 0, its scene and
 *  grid: a rank whose scene or grid differs from rank 0's fails with a message (2). @return the largest
 *  status of all ranks, the same on every rank. */
int vafm_cli_mpi_agree(vafm_cli_mpi *m, int rc, const vafm_params *base, const vafm_campaign_spec *spec);

/** Collective: run the campaign. Rank 0 hands out the indices spec->first_curve .. count-1 and calls fn
 *  for every curve in index order, one at a time (from a service thread); every rank, rank 0 included,
 *  computes curves. spec->threads 0 means the rank's share of its node's cores. Other ranks ignore fn.
 *  @return as vafm_campaign_run on rank 0 (VAFM_EABORT when fn stopped the campaign); other ranks 0 or
 *  their own failure. */
int vafm_cli_mpi_run(vafm_cli_mpi *m, const vafm_params *base, const vafm_campaign_spec *spec,
                     vafm_campaign_fn fn, void *user, vafm_error *err);

/** One line for the campaign summary: ranks, threads, curves computed per rank. */
void vafm_cli_mpi_describe(const vafm_cli_mpi *m, FILE *o);

/** Collective: wait for every rank (without spinning), finalise MPI, free *m (NULL-safe). @return rc. */
int vafm_cli_mpi_end(vafm_cli_mpi **m, int rc);

#endif
