/* SPDX-License-Identifier: MIT */
/* The JSON the stream announces a run with ("run.start", protocol/wire.md §3.2) and the channel list
 * that it and "hello" share (design: run_json.h). */
#include <stdlib.h>
#include "daemon/run_json.h"
#include "core/channels.h"
#include "vafm/detector.h"
#include "vafm/wire.h"

unsigned vafmd_live_channels(const vafm_params *p, const vafmd_settings *set)
{
    return vafm_channels_mask(VAFM_CHF_LIVE) |
           (vafm_detector_height_differs(p) ? vafm_channels_mask(VAFM_CHF_OPTIONAL) : 0u) |
           (set->segment_channel ? vafm_channels_mask(VAFM_CHF_OPTIN) : 0u);
}

json_t *vafmd_channels_json(unsigned mask)
{
    json_t *ch = json_array();
    for (int i = 0; i < VAFM_CH_COUNT; i++)
        if (mask & (1u << i))
            json_array_append_new(ch, json_pack("{s:s,s:s,s:s}", "name", vafm_channels[i].name, "unit",
                                                vafm_channels[i].unit, "dtype", VAFM_CH_DTYPE));
    return ch;
}

char *vafmd_run_start_json(const vafm_params *p, const vafmd_settings *set, int kind, uint64_t run_id,
                           uint64_t index, const char *client_run_id, double dt_s, json_t *camp, json_t *sample)
{
    size_t block_n = vafmd_block_samples(p->sample_rate_Hz, set->block_s);
    char *scene = malloc(65536);
    json_t *scene_json = NULL;
    if (scene && vafm_params_to_json(p, scene, 65536) > 0)
        scene_json = json_loads(scene, 0, NULL);
    free(scene);
    json_t *ch = vafmd_channels_json(vafmd_live_channels(p, set));
    json_t *start = json_object();
    json_object_set_new(start, "protocol_version", json_integer(VAFM_WIRE_PROTOCOL_VERSION));
    json_object_set_new(start, "run_id", json_integer((json_int_t)run_id));
    json_object_set_new(start, "client_run_id", client_run_id && client_run_id[0] ? json_string(client_run_id)
                                                                                : json_null());
    json_object_set_new(start, "kind", json_string(kind == VAFMD_RUN_TUNE ? "tune" : "curve"));
    json_object_set_new(start, "index", json_integer((json_int_t)index));
    json_object_set_new(start, "sample_rate_Hz", json_real(p->sample_rate_Hz));
    json_object_set_new(start, "block_samples", json_integer((json_int_t)block_n));
    json_object_set_new(start, "dt_s", json_real(dt_s));
    json_object_set_new(start, "sensitivity_m_per_V", json_real(p->sensitivity_m_per_V));
    json_object_set_new(start, "detector", json_pack("{s:b,s:f,s:i,s:f,s:f}", "on", vafm_detector_on(p),
                                                     "noise_V_rms", p->noise_V_rms, "adc_bits", p->adc_bits,
                                                     "adc_range_V", p->adc_range_V, "baseline_offset_V",
                                                     p->baseline_offset_V));
    json_object_set_new(start, "speed", json_real(set->speed));
    json_object_set_new(start, "free_run", json_boolean(set->free_run));
    json_object_set_new(start, "channels", ch);
    json_object_set_new(start, "segments", json_pack("{s:i,s:i,s:i,s:i}", "approach", VAFM_SEG_APPROACH, "retract",
                                                     VAFM_SEG_RETRACT, "dwell", VAFM_SEG_DWELL, "tune", VAFM_SEG_TUNE));
    json_object_set_new(start, "scene", scene_json ? scene_json : json_null());
    if (camp)
        json_object_set_new(start, "campaign", camp);
    if (sample && json_object_set(start, "sample", sample)) { /* the point under the tip: its scene re-runs it */
        json_decref(start);
        return NULL;
    }
    char *text = json_dumps(start, JSON_COMPACT);
    json_decref(start);
    return text;
}

