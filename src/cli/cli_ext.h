/* SPDX-License-Identifier: MIT */
/*
 * Subcommands of `vafm` that live in their own files (network clients, studies, MPI campaigns) and parse
 * their own arguments. vafm.c looks argv[1] up here before its own option parser; `vafm help` lists them.
 * Each entry: int fn(int argc, char **argv) with argv[0] = the command's name; returns the exit status
 * (0 ok, 1 runtime error, 2 usage error), prints its own --help.
 */
#ifndef VAFM_CLI_EXT_H
#define VAFM_CLI_EXT_H
#include <stdio.h>

typedef struct vafm_cli_ext {
    const char *name;
    int (*fn)(int argc, char **argv);
    const char *summary; /* one line for `vafm help` */
} vafm_cli_ext;

/* NULL-name-terminated table (cli_ext.c). */
extern const vafm_cli_ext vafm_cli_ext_commands[];
const vafm_cli_ext *vafm_cli_ext_find(const char *name);
int vafm_cli_replay(int argc, char **argv); /* cmd_replay.c */
#endif
