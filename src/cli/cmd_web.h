/* SPDX-License-Identifier: MIT */
/* `vafm web`: runs the live web panel's bridge (cmd_web.c; a row in the command table of vafm.c). */
#ifndef VAFM_CLI_CMD_WEB_H
#define VAFM_CLI_CMD_WEB_H
int vafm_cli_web(int argc, char **argv);
#endif
