/* SPDX-License-Identifier: MIT */
/* The table of `vafm` subcommands kept in their own files (see cli_ext.h). One row per command; a file
 * that is not built (an optional feature off) still gets its row through a "not built" stub in its file. */
#include <string.h>
#include "cli/cli_ext.h"
#include "cli/cmd_client.h"
#include "cli/study.h"

const vafm_cli_ext vafm_cli_ext_commands[] = {
    { "ctl", vafm_cli_ctl, "send any command to a running vafmd, print the reply" },
    { "status", vafm_cli_status, "the state of a running vafmd" },
    { "listen", vafm_cli_listen, "record the runs a vafmd streams to CSV or HDF5" },
    { "replay", vafm_cli_replay, "replay the curves of an HDF5 file through a running vafmd's stream" },
    { "study", vafm_cmd_study, "reproduce one of the paper's results: campaigns, fits, theory, report, figures" },
    { "theory", vafm_cmd_theory, "quasi-static, DHS and MFPT-rate references for a scene, without simulating" },
    { NULL, NULL, NULL },
};

const vafm_cli_ext *vafm_cli_ext_find(const char *name)
{
    for (const vafm_cli_ext *e = vafm_cli_ext_commands; e->name; e++)
        if (!strcmp(e->name, name))
            return e;
    return NULL;
}
