/* SPDX-License-Identifier: MIT */
/*
 * The Nanonis command modules' shared internals (nanonis.h is the transport's interface; docs/nanonis.md).
 *
 * The command table is split by module group, one file each, all built on the helpers here:
 *   nanonis_cmds.c     the helpers (a request's context, the JSON bridge calls, argument checks), the shared
 *                      module state, the dispatcher that finds a command in the modules' tables and writes
 *                      the error part of every response
 *   nanonis_signals.c  the signal table, Signals and Bias
 *   nanonis_zspectr.c  ZSpectr: the properties and the sweep (a `curve` on vafm's physics)
 *   nanonis_ctrl.c     ZCtrl, Motor, AutoApproach, FolMe: the always-on controller's commands in Nanonis words
 *
 * Each module file exports one table (nnc_cmd rows) and its length; every handler is static there. A handler
 * reads its arguments from x->r, writes its return arguments to x->o and returns NNC_OK, NNC_FAIL (message
 * in x->err: the dispatcher then writes the return arguments zero, as the row's `ret` says) or NNC_SILENT
 * (the bridge got no reply: no response at all, the `no_reply` fault).
 */
#ifndef VAFMD_NANONIS_CMDS_H
#define VAFMD_NANONIS_CMDS_H
#include <jansson.h>
#include <pthread.h>
#include <stddef.h>
#include <stdint.h>
#include "daemon/nanonis.h"

#define NNC_ERR 512
#define NNC_MAX_POINTS 100000
#define NNC_MAX_SWEEPS 1000
#define NNC_MAX_CHS 32

/* ---- one request ------------------------------------------------------------------------------------- */
struct nnc_cmd;
typedef struct nnc_ctx {
    nn_conn *c;
    const struct nnc_cmd *cmd; /* the row being served (its arg: a generic handler's table) */
    nn_rd r;
    nn_buf *o;
    char err[NNC_ERR];
} nnc_ctx;

enum { NNC_OK = 0, NNC_FAIL = -1, NNC_SILENT = -2 };

/* A table row. ret: the return arguments written zero on an error (i int32, I uint32, H uint16, f float32,
 * d float64). arg: what a generic handler serves (nnc_props_get/set: an nnc_props). */
typedef struct nnc_cmd {
    const char *name;
    int (*fn)(nnc_ctx *x);
    const char *ret;
    const void *arg;
} nnc_cmd;

int nnc_fail(nnc_ctx *x, const char *fmt, const char *a); /* x->err = fmt % a: NNC_FAIL */
/* One JSON request to the daemon (req consumed): NNC_OK, NNC_FAIL (x->err) or NNC_SILENT (no reply). */
int nnc_call(nnc_ctx *x, json_t *req, json_t **reply);
int nnc_ping(nnc_ctx *x);     /* a `status` request (the reply dropped) */
int nnc_ping_only(nnc_ctx *x); /* a handler: the arguments read, then nnc_ping */
/* `get` of some values: an object {name: value} (the caller frees it), or NULL with rc set. */
json_t *nnc_get(nnc_ctx *x, const char *const *names, size_t n, int *rc);
double nnc_num(json_t *o, const char *k); /* o[k] if a number, else NaN */
int nnc_args_done(nnc_ctx *x);            /* NNC_FAIL (naming the argument) if the body was short */
int nnc_signal_index(nnc_ctx *x, int32_t i, const char *arg);

/* ---- table-driven Get and Set ------------------------------------------------------------------------
 * A module value group: its fields in the order of the command's arguments (Set) or return arguments
 * (Get), each with its spec type, its range and the struct member it lives in (offsetof in the group's
 * struct, under the group's mutex). nnc_props_set reads every argument, checks them in order (the first
 * out of range is the error, naming the field and its range), pings the daemon (the request shows in its
 * records; a fault plan applies), then stores them under the mutex; nnc_props_get pings, then writes the
 * members under the mutex. Integer members are int, f32 members float. */
enum nnc_ftype { NNF_U16 = 'H', NNF_U32 = 'I', NNF_I32 = 'i', NNF_F32 = 'f', NNF_STRINGS = 'S' };
enum nnc_fcheck {
    NNF_ANY = 0,  /* integer: any value; float: finite */
    NNF_RANGE,    /* integer in [lo, hi], or the no-change code; float in [lo, hi] (lo_open: (lo, hi]) */
    NNF_MAGNITUDE,/* float: |v| in [lo, hi] */
    NNF_SIGNAL    /* integer: a signal index, or the no-change code */
};
enum nnc_fstore { NNF_SAME = 0, NNF_IS1, NNF_IS2, NNF_MINUS1, NNF_NONE }; /* the member = v, v == 1, v == 2,
                                                                             v - 1, or not stored */
#define NNF_NO_NC INT64_MIN /* no no-change code */
typedef struct nnc_field {
    char type;                      /* enum nnc_ftype */
    const char *name;               /* the spec's argument name (errors name it) */
    size_t off;                     /* offsetof the member (NNF_STRINGS: unused) */
    char check, store, lo_open;     /* enum nnc_fcheck, enum nnc_fstore; lo_open: float lo excluded */
    double lo, hi;
    int64_t nc;                     /* integer: the no-change code (NNF_NO_NC: none) */
    const char *must;               /* the error's tail after "NAME VALUE: " */
    const char *const *strings;     /* NNF_STRINGS (Get): size (i32), count (i32), the strings */
    int n_strings;
} nnc_field;
typedef struct nnc_props {
    pthread_mutex_t *mu;
    void *base;
    const nnc_field *fields;
    int n;
} nnc_props;
#define NNC_MAX_FIELDS 12
/* Rows of a field table: T the group's struct type. */
#define NNF_ROW(ty, T, nm, mem, chk, sto, lo_, hi_, nc_, must_)                                           \
    { .type = (ty), .name = (nm), .off = offsetof(T, mem), .check = (chk), .store = (sto), .lo = (lo_),   \
      .hi = (hi_), .nc = (nc_), .must = (must_) }
#define NNF_FLAG(T, nm, mem) /* a Set's flag: 0 no change, 1 on, 2 off (the member 1 or 0) */              \
    NNF_ROW(NNF_U16, T, nm, mem, NNF_RANGE, NNF_IS1, 1, 2, 0, "must be 0 (no change), 1 (on) or 2 (off)")
#define NNF_F32(T, nm, mem, chk, lo_, hi_, must_)                                                          \
    NNF_ROW(NNF_F32, T, nm, mem, chk, NNF_SAME, lo_, hi_, NNF_NO_NC, must_)
#define NNF_TIME(T, nm, mem) NNF_F32(T, nm, mem, NNF_RANGE, 0, 1000, "must be in [0, 1000] s")
#define NNF_STRS(list, count) { .type = NNF_STRINGS, .strings = (list), .n_strings = (count) }
int nnc_props_get(nnc_ctx *x); /* x->cmd->arg: the nnc_props */
int nnc_props_set(nnc_ctx *x);
int nnc_props_put(nnc_ctx *x, const nnc_props *p); /* the Get's body alone (no ping) */

/* ---- the signal table (nanonis_signals.c) -------------------------------------------------------------- */
enum nnc_src { SRC_STREAM = 0, SRC_BIAS = 1, SRC_CTRL = 2 };
enum nnc_kind { KIND_Z = 0, KIND_DEFL_V, KIND_DEFL_M, KIND_FORCE, KIND_OTHER };
/* SRC_CTRL rows' ranges (Signals.RangeGet) */
enum nnc_range { RNG_NONE = 0, RNG_PIEZO, RNG_MOTOR, RNG_XY, RNG_FORCE, RNG_VOLT, RNG_GAP };
typedef struct nnc_signal {
    const char *name; /* Nanonis style: "Name (unit)" */
    int src;
    int ch;           /* SRC_STREAM: the stream channel (nanonis.h NN_CH_*) */
    int kind;         /* SRC_CTRL: KIND_OTHER (not a Z spectroscopy channel, nor an auto-retract signal) */
    const char *key;  /* SRC_CTRL: the field of status.ctrl */
    double scale;     /* SRC_CTRL: the value is scale * status.ctrl[key] */
    int range;        /* SRC_CTRL: enum nnc_range */
} nnc_signal;
#define NNC_NSIG 18
extern const nnc_signal nnc_signals[NNC_NSIG];
extern const char *nnc_signal_names[NNC_NSIG];

/* ---- module state (all connections share it: the instrument's), under nnc_mu --------------------------- */
typedef struct nnc_state {
    float bias_V;
    /* Z spectroscopy */
    int chs[NNC_MAX_CHS], n_chs;
    int backward, points, sweeps, autosave, show_dialog, save_all;
    float t_fwd_bwd_s;
    int record_final_z, lockin_run, reset_z;
    float z_offset_m, z_distance_m;
    float t_zavg_s, t_init_settle_s, slew_V_per_s, t_settle_s, t_integr_s, t_end_settle_s, t_zctrl_s;
    float retract_delay_s;
    int ar_enable, ar_signal, ar_cmp;
    float ar_threshold;
    int ar2_cond, ar2_signal, ar2_cmp; /* ar2_cond as Get reports it: 0 -No-, 1 OR, 2 AND, 3 THEN */
    float ar2_threshold;
    int running, stop;
    unsigned long long curves; /* curves run: the next one's index (its random stream) */
} nnc_state;
extern pthread_mutex_t nnc_mu;
extern nnc_state nnc_m;

/* ---- the modules' tables ------------------------------------------------------------------------------- */
extern const nnc_cmd nnc_signals_cmds[];
extern const size_t nnc_signals_ncmds;
extern const nnc_cmd nnc_zspectr_cmds[];
extern const size_t nnc_zspectr_ncmds;
extern const nnc_cmd nnc_ctrl_cmds[];
extern const size_t nnc_ctrl_ncmds;
#endif
