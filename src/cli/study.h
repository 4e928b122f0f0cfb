/* SPDX-License-Identifier: MIT */
/*
 * `vafm study` and `vafm theory` (issue #7): the paper's results reproduced as campaigns with fits,
 * theory beside every point, a report and figures. Entry points for the command table (vafm.c), and the scene
 * option parser both commands share (preset, scene file, --NAME=VALUE overrides, as `vafm run`).
 */
#ifndef VAFM_CLI_STUDY_H
#define VAFM_CLI_STUDY_H

#include "vafm/params.h"

int vafm_cmd_study(int argc, char **argv);
int vafm_cmd_theory(int argc, char **argv);

/* Try to consume a scene option at argv[*i] (--preset NAME, --scene FILE, --NAME=VALUE or --NAME VALUE
 * for a parameter of the table). Preset and scene file must come before overrides. Returns 1 when
 * consumed (advancing *i), 0 when argv[*i] is not a scene option, 2 on a usage error (printed). */
int vafm_study_scene_arg(int argc, char **argv, int *i, vafm_params *p, char *desc, size_t desc_len);
#endif
