/* SPDX-License-Identifier: MIT */
/*
 * The Nanonis command dispatcher and the helpers every module uses (nanonis_cmds.h says which file holds
 * which module; docs/nanonis.md): each command's argument and return layout as TCPProtocol_SPM gives them,
 * and what it does in vafm.
 *
 * Every request that names a known command reaches the control loop at least once as a JSON request (its
 * id "nanonis:CONN:SEQ:COMMAND"): the commands that need the daemon send theirs (get, set, curve, abort,
 * engage, move, ...); the others send `status`. So a fault plan acts on Nanonis requests as on any client's
 * (no_reply: no response; reply_delay; busy: an error status) and each shows in the daemon's records.
 *
 * On an error the response still carries the return arguments, zero (arrays empty), then the error status
 * 1 and its description: clients parse the return arguments before they look at the error.
 */
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "daemon/nanonis_cmds.h"

pthread_mutex_t nnc_mu = PTHREAD_MUTEX_INITIALIZER;
nnc_state nnc_m;

void nn_cmds_init(void)
{
    for (int i = 0; i < NNC_NSIG; i++)
        nnc_signal_names[i] = nnc_signals[i].name;
    pthread_mutex_lock(&nnc_mu);
    memset(&nnc_m, 0, sizeof nnc_m);
    nnc_m.chs[0] = 1; /* Deflection (V) */
    nnc_m.chs[1] = 3; /* Force (N) */
    nnc_m.n_chs = 2;
    nnc_m.backward = 1;
    nnc_m.points = 128;
    nnc_m.sweeps = 1;
    nnc_m.reset_z = 1;
    nnc_m.z_distance_m = 200e-9f;
    nnc_m.t_zavg_s = 0.1f;
    nnc_m.slew_V_per_s = 1000.f;
    nnc_m.t_integr_s = 1e-3f;
    nnc_m.ar_enable = 1;
    nnc_m.ar_threshold = 5e-9f;
    nnc_m.ar_signal = 3; /* Force (N) > 5 nN: vafm's default setpoint */
    nnc_m.ar_cmp = 0;
    pthread_mutex_unlock(&nnc_mu);
}

/* ---- helpers ---------------------------------------------------------------------------------------- */

int nnc_fail(nnc_ctx *x, const char *fmt, const char *a)
{
    snprintf(x->err, sizeof x->err, fmt, a);
    return NNC_FAIL;
}

/* One JSON request to the daemon: NNC_OK, NNC_FAIL (x->err) or NNC_SILENT (no reply). */
int nnc_call(nnc_ctx *x, json_t *req, json_t **reply)
{
    int rc = nn_call(x->c, req, reply, x->err, sizeof x->err);
    return rc == NN_OK ? NNC_OK : rc == NN_ENOREPLY ? NNC_SILENT : NNC_FAIL;
}

int nnc_ping(nnc_ctx *x) { return nnc_call(x, json_pack("{s:s}", "cmd", "status"), NULL); }

/* `get` of some scene values: an object {name: value} (the caller frees it), or NULL with rc set. */
json_t *nnc_get(nnc_ctx *x, const char *const *names, size_t n, int *rc)
{
    json_t *a = json_array();
    for (size_t i = 0; i < n; i++)
        json_array_append_new(a, json_string(names[i]));
    json_t *reply = NULL;
    *rc = nnc_call(x, json_pack("{s:s,s:o}", "cmd", "get", "names", a), &reply);
    if (*rc)
        return NULL;
    json_t *v = json_incref(json_object_get(reply, "values"));
    json_decref(reply);
    if (!v) {
        *rc = NNC_FAIL;
        snprintf(x->err, sizeof x->err, "the daemon's get reply has no values");
    }
    return v;
}

double nnc_num(json_t *o, const char *k)
{
    json_t *v = json_object_get(o, k);
    return json_is_number(v) ? json_number_value(v) : NAN;
}

int nnc_args_done(nnc_ctx *x)
{
    if (x->r.bad) {
        snprintf(x->err, sizeof x->err, "%s", x->r.why);
        return NNC_FAIL;
    }
    return NNC_OK;
}

int nnc_signal_index(nnc_ctx *x, int32_t i, const char *arg)
{
    if (i < 0 || i >= NNC_NSIG) {
        snprintf(x->err, sizeof x->err, "%s %d: no such signal; vafm has signals 0 to %d (Signals.NamesGet)", arg,
                 (int)i, NNC_NSIG - 1);
        return NNC_FAIL;
    }
    return NNC_OK;
}

int nnc_ping_only(nnc_ctx *x) { return nnc_args_done(x) ? NNC_FAIL : nnc_ping(x); }

/* ---- table-driven Get and Set (nanonis_cmds.h) ------------------------------------------------------- */

static int s_field_check(nnc_ctx *x, const nnc_field *f, int64_t iv, float fv)
{
    if (f->type == NNF_F32) {
        float lo = (float)f->lo, hi = (float)f->hi, a = f->check == NNF_MAGNITUDE ? fabsf(fv) : fv;
        int bad = !isfinite(fv) || (f->check != NNF_ANY && (a < lo || a > hi || (f->lo_open && a <= lo)));
        if (bad)
            snprintf(x->err, sizeof x->err, "%s %g: %s", f->name, (double)fv, f->must);
        return bad ? NNC_FAIL : NNC_OK;
    }
    if (f->nc != NNF_NO_NC && iv == f->nc)
        return NNC_OK;
    if (f->check == NNF_SIGNAL)
        return nnc_signal_index(x, (int32_t)iv, f->name);
    if (f->check == NNF_RANGE && (iv < (int64_t)f->lo || iv > (int64_t)f->hi)) {
        snprintf(x->err, sizeof x->err, "%s %lld: %s", f->name, (long long)iv, f->must);
        return NNC_FAIL;
    }
    return NNC_OK;
}

int nnc_props_set(nnc_ctx *x)
{
    const nnc_props *p = x->cmd->arg;
    int64_t iv[NNC_MAX_FIELDS] = { 0 };
    float fv[NNC_MAX_FIELDS] = { 0 };
    for (int i = 0; i < p->n; i++) {
        const nnc_field *f = &p->fields[i];
        switch (f->type) {
        case NNF_U16: iv[i] = nn_get_u16(&x->r, f->name); break;
        case NNF_U32: iv[i] = nn_get_u32(&x->r, f->name); break;
        case NNF_I32: iv[i] = nn_get_i32(&x->r, f->name); break;
        case NNF_F32: fv[i] = nn_get_f32(&x->r, f->name); break;
        default: break; /* NNF_STRINGS: a Get's only */
        }
    }
    if (nnc_args_done(x))
        return NNC_FAIL;
    for (int i = 0; i < p->n; i++)
        if (p->fields[i].type != NNF_STRINGS && s_field_check(x, &p->fields[i], iv[i], fv[i]))
            return NNC_FAIL;
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    pthread_mutex_lock(p->mu);
    for (int i = 0; i < p->n; i++) {
        const nnc_field *f = &p->fields[i];
        char *dst = (char *)p->base + f->off;
        if (f->type == NNF_STRINGS || f->store == NNF_NONE)
            continue;
        if (f->type == NNF_F32) {
            memcpy(dst, &fv[i], sizeof fv[i]);
            continue;
        }
        if (f->nc != NNF_NO_NC && iv[i] == f->nc)
            continue;
        int v = f->store == NNF_IS1 ? iv[i] == 1 : f->store == NNF_IS2 ? iv[i] == 2
                : f->store == NNF_MINUS1 ? (int)(iv[i] - 1) : (int)iv[i];
        memcpy(dst, &v, sizeof v);
    }
    pthread_mutex_unlock(p->mu);
    return NNC_OK;
}

int nnc_props_put(nnc_ctx *x, const nnc_props *p)
{
    pthread_mutex_lock(p->mu);
    for (int i = 0; i < p->n; i++) {
        const nnc_field *f = &p->fields[i];
        const char *src = (const char *)p->base + f->off;
        int v = 0;
        float fl = 0;
        if (f->type == NNF_F32)
            memcpy(&fl, src, sizeof fl);
        else if (f->type != NNF_STRINGS)
            memcpy(&v, src, sizeof v);
        switch (f->type) {
        case NNF_U16: nn_put_u16(x->o, (uint16_t)v); break;
        case NNF_U32: nn_put_u32(x->o, (uint32_t)v); break;
        case NNF_I32: nn_put_i32(x->o, v); break;
        case NNF_F32: nn_put_f32(x->o, fl); break;
        default:
            nn_put_i32(x->o, (int32_t)nn_strings_bytes(f->strings, (size_t)f->n_strings));
            nn_put_i32(x->o, f->n_strings);
            nn_put_strings(x->o, f->strings, (size_t)f->n_strings);
            break;
        }
    }
    pthread_mutex_unlock(p->mu);
    return NNC_OK;
}

int nnc_props_get(nnc_ctx *x)
{
    int rc = nnc_ping(x);
    return rc ? rc : nnc_props_put(x, x->cmd->arg);
}

/* ---- the dispatcher ------------------------------------------------------------------------------------ */

static const struct {
    const nnc_cmd *rows;
    const size_t *n;
} s_tables[] = { { nnc_signals_cmds, &nnc_signals_ncmds },
                 { nnc_zspectr_cmds, &nnc_zspectr_ncmds },
                 { nnc_ctrl_cmds, &nnc_ctrl_ncmds } };

static void s_zero(nn_buf *o, const char *ret)
{
    for (const char *c = ret; *c; c++)
        switch (*c) {
        case 'H': nn_put_u16(o, 0); break;
        case 'd': nn_put_f64(o, 0); break;
        default: nn_put_u32(o, 0); break; /* i, I, f: four zero bytes */
        }
}

int nn_dispatch(nn_conn *c, const char *name, const unsigned char *body, size_t n, nn_buf *out)
{
    nnc_ctx x;
    memset(&x, 0, sizeof x);
    x.c = c;
    x.o = out;
    x.r.p = body;
    x.r.n = n;
    const nnc_cmd *cmd = NULL;
    size_t total = 0;
    for (size_t t = 0; t < sizeof s_tables / sizeof s_tables[0]; t++) {
        for (size_t i = 0; i < *s_tables[t].n && !cmd; i++)
            if (!strcmp(s_tables[t].rows[i].name, name))
                cmd = &s_tables[t].rows[i];
        total += *s_tables[t].n;
    }
    int rc;
    if (!cmd) {
        char safe[4 * 32 + 1];
        size_t k = 0;
        for (const unsigned char *p = (const unsigned char *)name; *p && k + 4 < sizeof safe; p++)
            k += (size_t)snprintf(safe + k, sizeof safe - k, *p >= 32 && *p < 127 ? "%c" : "\\x%02x", *p);
        safe[k] = 0;
        snprintf(x.err, sizeof x.err, "unknown command '%s': vafmd serves %zu Nanonis commands (docs/nanonis.md)",
                 safe, total);
        rc = NNC_FAIL;
    } else {
        x.cmd = cmd;
        rc = cmd->fn(&x);
    }
    if (rc == NNC_SILENT)
        return 1;
    if (rc == NNC_FAIL) {
        out->n = 0;
        out->oom = 0;
        if (cmd)
            s_zero(out, cmd->ret);
    }
    nn_put_u32(out, rc == NNC_FAIL);
    size_t l = rc == NNC_FAIL ? strlen(x.err) : 0;
    nn_put_i32(out, (int32_t)l);
    nn_put_bytes(out, x.err, l);
    return 0;
}