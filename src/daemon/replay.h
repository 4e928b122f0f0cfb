/* SPDX-License-Identifier: MIT */
/*
 * Replay of recorded force curves (HDF5 files of protocol/hdf5.md's layout) through the live stream.
 *
 * Two sides, two threads. The control thread loads the whole selection into one in-memory object
 * (vafmd_replay_prepare: file I/O, checks, memory bound, the run.start message); ownership then passes
 * to the simulation thread with the START command, which streams from memory through
 * vafmd_replay_advance. That function has the contract of vafm_sim_advance (same sample callback,
 * returns 1 more to come / 0 done with the last sample / <0 error), never allocates and never touches
 * the file, so the block, header and pacing code of live runs serves replays unchanged.
 */
#ifndef VAFMD_REPLAY_H
#define VAFMD_REPLAY_H
#include <stddef.h>
#include <stdint.h>
#include "daemon/cmd_json.h"
#include "daemon/daemon.h"

/* Bounds of one replay (all selected curves of one pass are held in memory, ≤ 49 bytes a sample). */
#define VAFMD_REPLAY_MAX_SAMPLES (1u << 21) /* 2 097 152 samples, ~100 MiB */
#define VAFMD_REPLAY_MAX_CURVES 4096u       /* entries of a selection */
#define VAFMD_REPLAY_MAX_PASSES 1000000     /* "loop": passes over the selection; 0 = until abort */
#define VAFMD_REPLAY_MAX_EVENTS 64          /* curve events kept between two blocks */
/* Bounds of run.start: one string attribute (a curve's, or the root's software/software version), and
 * the attributes of replay.curves, JSON-encoded, summed over the selection's entries (repeats count). */
#define VAFMD_REPLAY_MAX_ATTR_BYTES 65536u      /* 64 KiB */
#define VAFMD_REPLAY_MAX_ATTRS_TOTAL (8u << 20) /* 8 MiB */

/* Channel bits of a run: bit i = row i of core/channels.h (time_s only in replays, height_measured_m when
 * a live run's scene has a piezo model or a z sensor). */
#include "core/channels.h"

typedef struct vafmd_replay vafmd_replay;

/* A curve of the selection began at run sample `sample` (published as an `event` of kind "curve"). */
typedef struct vafmd_replay_event {
    uint64_t sample;    /* run index of the curve's first sample */
    uint64_t curve;     /* group number in the file */
    uint64_t selection; /* position in the selection, from 0 */
    uint64_t pass;      /* pass over the selection, from 0 */
    uint64_t samples;   /* samples of the curve */
} vafmd_replay_event;

/**
 * Control thread: open and check the file, load the selected curves, build the run.start message.
 * @param c the decoded `replay` command (path, curves, speed, loop, client_run_id)
 * @param set the daemon settings (speed unless c sets one, free_run, block_s)
 * @param run_id the run id the daemon will assign
 * @param out receives the replay (owned by the caller until handed to the simulation thread)
 * @param start_json receives the run.start text (malloc'ed)
 * @param block_n receives the samples per data block
 * @return 0 or -1 with e filled (io_error, bad_file, out_of_range naming the field).
 */
int vafmd_replay_prepare(const vafmd_cmd *c, const vafmd_settings *set, uint64_t run_id, vafmd_replay **out,
                         char **start_json, size_t *block_n, vafmd_err *e);

/** Free a replay; NULL-safe, sets *rp to NULL. */
void vafmd_replay_free(vafmd_replay **rp);

/** Streamed channels (bits of core/channels.h rows) and the nominal sample rate of the run (header, block size). */
unsigned vafmd_replay_channels(const vafmd_replay *rp);
double vafmd_replay_rate_Hz(const vafmd_replay *rp);

/**
 * Simulation thread: deliver up to max samples to fn, all of one curve (a batch never spans two
 * curves), as vafm_samples with first = the run sample index. *sens receives the sensitivity (m/V) of
 * the batch's curve before fn is called (vDeflection = deflection / sensitivity).
 * @return 1 more to come, 0 the run's last sample was delivered, VAFM_EABORT if fn returned non-zero.
 */
int vafmd_replay_advance(vafmd_replay *rp, size_t max, vafm_sample_fn fn, void *user, double *sens);

/** Pacing: seconds from the run start until the last delivered sample was "measured" (recorded
 *  time, passes and curves back to back), at speed 1. */
double vafmd_replay_clock_s(const vafmd_replay *rp);

/** Take the curve starts recorded since the last call (at most max). @return how many. */
int vafmd_replay_take_events(vafmd_replay *rp, vafmd_replay_event *out, int max);
#endif
