/* SPDX-License-Identifier: MIT */
/*
 * Fault injection (protocol/faults.md): a plan of faults the daemon commits on purpose, so that
 * acquisition software can be tested against them, and the record of every fault injected (the ground
 * truth a test compares a client's reports with).
 *
 * A plan is decoded and checked here (vafmd_faults_decode: every field, its type and range, errors in the
 * codes of wire.md §2.2), then compiled into a fixed-size vafmd_fault_plan. Each thread keeps its own
 * copy: the control thread (command faults: reply_delay, no_reply, busy) and the simulation thread
 * (stream faults: late, jitter, drop, truncate, stall, restart, kill; controller faults: saturate,
 * dropout). The control thread hands the simulation thread a heap copy through the command ring and
 * gets the replaced one back through the retire ring, so the simulation thread never allocates or frees.
 *
 * Decisions are stateless hashes of (plan seed, kind, run, block or command number): the same plan with
 * the same seed commits the same faults on the same sequence of runs. With no plan the simulation
 * thread tests one pointer per block (a single predictable branch) and does nothing else.
 *
 * Every fault injected becomes a vafmd_fault_rec: published on the `faults` topic after it took effect,
 * kept by the control thread for `status`/`faults` (a count and the last VAFMD_FAULT_LAST), and handed to
 * the log writer (root attribute "vafm faults" of the HDF5 log).
 */
#ifndef VAFMD_FAULTS_H
#define VAFMD_FAULTS_H
#include <jansson.h>
#include <stdint.h>
struct vafmd_err;

enum vafmd_fault_kind {
    VAFMD_F_LATE = 0, VAFMD_F_JITTER, VAFMD_F_DROP, VAFMD_F_TRUNCATE, VAFMD_F_STALL, VAFMD_F_RESTART,
    VAFMD_F_SATURATE, VAFMD_F_DROPOUT, VAFMD_F_NO_TRIGGER, VAFMD_F_KILL, VAFMD_F_REPLY_DELAY,
    VAFMD_F_NO_REPLY, VAFMD_F_BUSY, VAFMD_F_N
};

/* Where a kind acts. */
enum { VAFMD_FW_STREAM = 0, VAFMD_FW_COMMAND = 1 };

#define VAFMD_FAULT_SCRIPT_MAX 256 /* entries of a scripted plan */
#define VAFMD_FAULT_LAST 32        /* records kept for status and the faults query */

typedef struct vafmd_fault_entry {
    int kind;            /* enum vafmd_fault_kind */
    uint64_t run;        /* stream kinds: the run id, 0: every run */
    int64_t block;       /* stream kinds: the block index in the run, -1: by time_s */
    double time_s;       /* stream kinds: run time, s (block = the one holding that sample time) */
    char cmd[16];        /* command kinds: the command name, "": any */
    uint64_t nth;        /* command kinds: the nth matching request after the plan was set (from 1) */
    double p0, p1;       /* parameters (faults.md): late delay_s; jitter max_s; drop blocks; stall duration_s;
                            saturate samples, level_V; dropout samples, mode (0 nan, 1 stuck); kill status;
                            reply_delay delay_s */
} vafmd_fault_entry;

typedef struct vafmd_fault_random {
    double rate;         /* probability per unit, 0: off */
    int per;             /* VAFMD_FPER_* */
    char cmd[16];        /* command kinds: "" any */
    double p0, p1;       /* parameters as for entries */
} vafmd_fault_random;

enum { VAFMD_FPER_BLOCK = 1, VAFMD_FPER_RUN = 2, VAFMD_FPER_COMMAND = 3 };

typedef struct vafmd_fault_plan {
    uint64_t seed;
    size_t n_script;
    vafmd_fault_entry script[VAFMD_FAULT_SCRIPT_MAX];
    vafmd_fault_random rnd[VAFMD_F_N];
    int any_stream, any_command; /* 1: some entry or rate of that side */
} vafmd_fault_plan;

/* One injected fault (fixed size: it travels through SPSC rings). */
typedef struct vafmd_fault_rec {
    uint64_t n;          /* number of the fault since start-up, from 1 (assigned by the simulation thread) */
    int kind;
    double time_s;       /* daemon uptime when it took effect, s */
    double run_time_s;   /* run time of the block (stream kinds), NaN otherwise */
    uint64_t run_id;     /* 0: none */
    int64_t block;       /* block index in the run, -1: none */
    int64_t seq;         /* the data seq it concerned (drop: the first seq not sent), -1: none */
    uint32_t session;    /* the stream session after it (restart: the new one) */
    uint32_t scripted;   /* 1: a script entry, 0: a random rate */
    double p0, p1;       /* its parameters (jitter: the delay drawn) */
    char cmd[16];        /* command kinds: the command */
} vafmd_fault_rec;

const char *vafmd_fault_name(int kind);
int vafmd_fault_where(int kind);

/** Decode and check a plan object (faults.md): every error names the field (e.g. "script[2].delay_s")
 *  and the allowed range. @return 0 or -1 with e filled. */
int vafmd_faults_decode(json_t *plan, vafmd_fault_plan *out, struct vafmd_err *e);

/** The record as JSON (the `faults` topic, status, the HDF5 attribute). New reference. */
json_t *vafmd_fault_rec_json(const vafmd_fault_rec *r);

/** A uniform deviate in [0, 1) from (seed, kind, a, b): stateless, allocation-free. */
double vafmd_fault_u01(uint64_t seed, int kind, uint64_t a, uint64_t b);
#endif
