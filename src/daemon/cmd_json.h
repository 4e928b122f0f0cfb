/* SPDX-License-Identifier: MIT */
/*
 * The vafmd command decoder (protocol/wire.md, "Commands"): bytes → a checked command, or an error
 * with a stable code, a message and the offending field. No I/O and no global state, so it can be
 * fuzzed on its own (tests/fuzz_cmd.c). It never aborts on any input.
 */
#ifndef VAFMD_CMD_JSON_H
#define VAFMD_CMD_JSON_H
#include <jansson.h>
#include <stddef.h>
#include <stdint.h>
#include "daemon/daemon.h"

/* Command flags (src/daemon/commands.def says what each means). */
enum {
    VAFMD_CF_IDEMPOTENT = 1 << 0, /* safe to resend after a lost reply */
    VAFMD_CF_FAULTABLE = 1 << 1,  /* a fault plan may fault it */
    VAFMD_CF_STARTS_RUN = 1 << 2, /* starts a run or a campaign */
    VAFMD_CF_READ_ONLY = 1 << 3,  /* changes nothing */
};

/* VAFMD_CMD_HELLO, ... in the order of commands.def; VAFMD_CMD_N commands. */
enum vafmd_cmd_kind {
#define VAFMD_COMMAND(ID, NAME, KEYS, FLAGS, HANDLER, HELP) VAFMD_CMD_##ID,
#include "daemon/commands.def"
    VAFMD_CMD_N
};

/* Stable error codes (protocol/wire.md lists them). */
#define VAFMD_E_MALFORMED "malformed"
#define VAFMD_E_TOO_LARGE "too_large"
#define VAFMD_E_UNKNOWN_COMMAND "unknown_command"
#define VAFMD_E_UNKNOWN_FIELD "unknown_field"
#define VAFMD_E_MISSING_FIELD "missing_field"
#define VAFMD_E_WRONG_TYPE "wrong_type"
#define VAFMD_E_OUT_OF_RANGE "out_of_range"
#define VAFMD_E_NOT_FOUND "not_found"
#define VAFMD_E_INVALID_SCENE "invalid_scene"
#define VAFMD_E_READ_ONLY "read_only"
#define VAFMD_E_STATE "state"
#define VAFMD_E_BUSY "busy"
#define VAFMD_E_NOT_IMPLEMENTED "not_implemented"
#define VAFMD_E_INTERNAL "internal"
#define VAFMD_E_IO "io_error"
#define VAFMD_E_BAD_FILE "bad_file" /* replay: a damaged or non-conforming file (message names the rule) */

#define VAFMD_LOG_PATH_MAX 4000

typedef struct vafmd_err {
    const char *code;  /* one of VAFMD_E_* (static) */
    char field[64];    /* offending field or "" */
    char message[400];
} vafmd_err;

#define VAFMD_CLIENT_RUN_ID_MAX 64

typedef struct vafmd_cmd {
    int kind;              /* enum vafmd_cmd_kind */
    json_t *root;          /* owned: the whole request */
    json_t *id;            /* borrowed: the client's "id", echoed in the reply, or NULL */
    json_t *names;         /* get: borrowed array of names, or NULL (all) */
    int info;              /* get: 1 adds unit, range and doc per name */
    const char *preset;    /* set: borrowed preset name, or NULL */
    json_t *values;        /* set: borrowed object {name: value}, or NULL */
    int has_index;
    uint64_t index;        /* curve/tune: RNG stream index */
    char client_run_id[VAFMD_CLIENT_RUN_ID_MAX + 1]; /* "" if none */
    struct vafm_segment_spec *segs; /* curve: owned (vafmd_cmd_free), the "segments" list, or NULL */
    size_t nseg;
    int has_duration;
    double duration_s;     /* tune: overrides tune_duration_s */
    const char *log_path;  /* log: borrowed file name, or NULL */
    int log_overwrite, log_resume, log_stop; /* log: flags */
    const char *replay_path; /* replay: borrowed file name */
    json_t *replay_curves;   /* replay: borrowed selection (string or array of integers), or NULL (all) */
    int has_speed;
    double speed;            /* replay: pacing speed factor for this run */
    int replay_has_loop;
    int64_t replay_loop;     /* replay: passes over the selection, 0 = until abort */
    uint64_t camp_n;       /* campaign: curves per grid point (≥ 1) */
    json_t *camp_list[VAFM_CAMPAIGN_NAXES]; /* campaign: borrowed arrays of numbers per grid axis (T_K, v_m_per_s,
                                             k_N_per_m: vafm_campaign_axis_at), or NULL */
    uint64_t camp_first;   /* campaign, map: first_index (0 if absent) */
    vafm_map_spec map;     /* map: the spec (vafm_map_set of each key of "map") */
    double map_lateral_speed; /* map: lateral_speed_m_per_s */
    unsigned map_grid_given;  /* map: the grid's keys given (bit i: vafmd_map_grid_merge's i-th name) */
    int map_own_sample;       /* map: 1 if "map" names a field of the sample (pattern, its geometry, a material) */
    json_t *fault_plan;    /* faults: borrowed plan object (set/replace), or NULL */
    int fault_clear;       /* faults: 1 = "clear": true */
    vafmd_live_op ctrl;    /* engage, withdraw, move, z, feedback (live_json.c) */
} vafmd_cmd;

#define VAFMD_CAMPAIGN_LIST_MAX 1000      /* values per campaign list */
#define VAFMD_CAMPAIGN_POINTS_MAX 100000  /* grid points of a campaign */

/** A map from the live state (wire.md "map"): into dst (the controller's sample), the grid's fields the request
 *  gave (c->map_grid_given: nx, ny, size_x_m, size_y_m, center_x_m, center_y_m, start) from its spec req. */
void vafmd_map_grid_merge(vafm_map_spec *dst, const vafm_map_spec *req, unsigned given);

/** Decode one request. @return 0 (free c with vafmd_cmd_free) or -1 with e filled (c holds nothing). */
int vafmd_cmd_decode(const void *buf, size_t len, vafmd_cmd *c, vafmd_err *e);
/** Same from an already parsed object (takes a reference of its own). */
int vafmd_cmd_decode_json(json_t *root, vafmd_cmd *c, vafmd_err *e);
void vafmd_cmd_free(vafmd_cmd *c);

/** Apply a decoded `set` (preset first, then values) to p and s, all or nothing: the result must pass
 *  vafm_params_validate. @return 0 or -1 with e filled (p and s untouched). */
int vafmd_apply_set(vafm_params *p, vafmd_settings *s, const vafmd_cmd *c, vafmd_err *e);
/** The values (and with info, the descriptions) of the names asked for, or all. NULL with e filled if a
 *  name is unknown. */
json_t *vafmd_get_values(const vafm_params *p, const vafmd_settings *s, const vafmd_cmd *c, vafmd_err *e);
/** One scene or setting value as JSON (REAL: number, CHOICE: string, BOOL: bool, SEED: string). */
json_t *vafmd_param_value(const vafm_params *p, const vafm_param_info *f);
/** {"status":"error","code":..,"message":..,"field":..|null[,"id":..]} */
json_t *vafmd_error_reply(const vafmd_err *e, json_t *id);
void vafmd_err_set(vafmd_err *e, const char *code, const char *field, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
/** The command's name ("?" for a kind out of range), flags (VAFMD_CF_*, 0 out of range), argument keys
 *  (" a b ", each enclosed in spaces; NULL out of range) and one-line help (NULL out of range), from
 *  commands.def. */
const char *vafmd_cmd_name(int kind);
unsigned vafmd_cmd_flags(int kind);
const char *vafmd_cmd_keys(int kind);
const char *vafmd_cmd_help(int kind);
#endif
