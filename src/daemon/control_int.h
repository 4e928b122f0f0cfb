/* SPDX-License-Identifier: MIT */
/*
 * The control loop's private interface, shared by control.c (the loop, the queries, the handler table) and
 * control_runs.c (starting runs and campaigns, with the client-run-id history that answers a retried start).
 * Split out of control.c (issue #25: no source file over 1000 lines); nothing outside these two includes it.
 */
#ifndef VAFMD_CONTROL_INT_H
#define VAFMD_CONTROL_INT_H
#include <jansson.h>
#include "daemon/cmd_json.h"
#include "daemon/daemon.h"

static inline json_t *s_ok(const vafmd_cmd *c)
{
    json_t *r = json_object();
    json_object_set_new(r, "status", json_string("ok"));
    json_object_set_new(r, "cmd", json_string(vafmd_cmd_name(c->kind)));
    if (c->id)
        json_object_set(r, "id", c->id);
    return r;
}

/* A job (curve, tune, campaign) is in progress: the simulation thread has not reported it done. */
static inline int s_busy(const vafmd *d)
{
    return d->jobs_started != atomic_load_explicit(&d->sh.jobs_done, memory_order_acquire);
}

/* curve, tune and replay: one start each (control_runs.c) */
json_t *vafmd_control_start(vafmd *d, const vafmd_cmd *c, vafmd_err *e);
/* campaign, and map: a campaign over the map's pixels (control_runs.c) */
json_t *vafmd_control_campaign(vafmd *d, const vafmd_cmd *c, vafmd_err *e);

#endif
