/* SPDX-License-Identifier: MIT */
/* `vafm study` in a build without GSL (meson feature `study` off or libgsl-dev missing): the command's
 * row stays in the table and says how to get it. */
#include <stdio.h>
#include "cli/study.h"

int vafm_cmd_study(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    fprintf(stderr, "vafm study: not built: this vafm was built without GSL (install libgsl-dev and rebuild, "
                    "or configure with -Dstudy=enabled)\n");
    return 1;
}
