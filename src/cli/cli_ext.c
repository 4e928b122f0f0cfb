/* SPDX-License-Identifier: MIT */
/* The table of `vafm` subcommands kept in their own files (see cli_ext.h). One row per command; a file
 * that is not built (an optional feature off) still gets its row through a "not built" stub in its file. */
#include <string.h>
#include "cli/cli_ext.h"

const vafm_cli_ext vafm_cli_ext_commands[] = {
    { NULL, NULL, NULL },
};

const vafm_cli_ext *vafm_cli_ext_find(const char *name)
{
    for (const vafm_cli_ext *e = vafm_cli_ext_commands; e->name; e++)
        if (!strcmp(e->name, name))
            return e;
    return NULL;
}
