/* SPDX-License-Identifier: MIT */
/*
 * The run.start JSON of a run (protocol/wire.md §3.2) and the stream's channel list. Pure functions of
 * their arguments, no shared state: both the control thread (single runs) and the simulation thread
 * (each curve of a campaign, built between curves) call them, so they live in a module of their own
 * rather than in the control module the simulation thread must not depend on.
 */
#ifndef VAFMD_RUN_JSON_H
#define VAFMD_RUN_JSON_H

#include <jansson.h>
#include "daemon/daemon.h"

/** The channels of a data block, the rows of core/channels.h whose bit is set in mask, in row order, as
 *  a JSON array [{"name", "unit", "dtype"}] (new reference). */
json_t *vafmd_channels_json(unsigned mask);

/** The channel bits a live run of scene p streams: the VAFM_CHF_LIVE rows, and the VAFM_CHF_OPTIONAL ones
 *  when the scene has a measured height of its own (a piezo model or a z sensor), the VAFM_CHF_OPTIN ones
 *  (segment) when set->segment_channel asks for them. */
unsigned vafmd_live_channels(const vafm_params *p, const vafmd_settings *set);

/** The "run.start" JSON text of a run (malloc'd; NULL on no memory). camp: the run's "campaign" object
 *  (stolen) or NULL; sample: a run from the live state's "sample" (borrowed) or NULL. */
char *vafmd_run_start_json(const vafm_params *p, const vafmd_settings *set, int kind, uint64_t run_id,
                           uint64_t index, const char *client_run_id, double dt_s, json_t *camp, json_t *sample);

#endif
