/* SPDX-License-Identifier: MIT */
/* `vafm ctl`, `vafm status`, `vafm listen`: the CLI as a client of vafmd (cmd_ctl.c, cmd_status.c, cmd_listen.c over client_conn.h; rows in the command table of vafm.c). */
#ifndef VAFM_CLI_CMD_CLIENT_H
#define VAFM_CLI_CMD_CLIENT_H
int vafm_cli_ctl(int argc, char **argv);
int vafm_cli_status(int argc, char **argv);
int vafm_cli_listen(int argc, char **argv);
#endif
