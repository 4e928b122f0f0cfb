/* SPDX-License-Identifier: MIT */
/*
 * `vafm web`: the live web panel of a running vafmd (issue #28; docs/web.md). The panel is a Python bridge
 * (aiohttp, pyzmq: clients/web/vafm_web.py) that this command finds and runs: it execv()s /usr/bin/python3
 * with the bridge and the user's arguments as they are (argv, never a shell), plus `--vafm` naming this
 * binary (the bridge converts values typed with units through `vafm ctl set`).
 *
 * The bridge: $VAFM_WEB_BRIDGE if set; else installed beside this binary (BINDIR/VAFM_DATADIR_REL/web/,
 * meson install and the Debian package put it there with its page and uPlot); else the source tree's
 * (VAFM_WEB_BRIDGE_SRC, a build-tree binary). The options are checked here (a usage error names the
 * option, exit 2); their values are the bridge's to judge (it exits 2 naming the option too).
 */
#include "cli/cmd_web.h"
#include "cli/cli.h"

#ifndef VAFM_DATADIR_REL
#define VAFM_DATADIR_REL "../share/vafm"
#endif
#ifndef VAFM_WEB_BRIDGE_SRC
#define VAFM_WEB_BRIDGE_SRC "clients/web/vafm_web.py"
#endif
#define S_PYTHON "/usr/bin/python3"
#define S_MAX_ARGS 256 /* arguments passed through (the options below take at most 2 argv words each) */

/* The bridge's options (its argparse, which tests/test_web.py compares with this table). */
static const struct {
    const char *name;
    int takes_value;
} s_opts[] = {
    { "--daemon", 1 }, { "--pub", 1 }, { "--listen", 1 }, { "--token", 1 }, { "--curve", 1 },
    { "--vafm", 1 }, { "--uplot-dir", 1 }, { "--columns-per-block", 1 }, { "--queue", 1 },
    { "--live-columns-per-s", 1 },
    { "--allow-shutdown", 0 }, { "--connect-timeout", 1 }, { "--ready-file", 1 },
};
#define S_NOPTS ((int)(sizeof s_opts / sizeof s_opts[0]))

static const char s_help[] =
    "usage: vafm web [--daemon E] [--pub E] [--listen HOST:PORT] [--token T] [--curve FILE] [...]\n"
    "  The live web panel of a running vafmd: open the URL it prints in any browser (several at once).\n"
    "  A client of the daemon's public protocol (it may run on another host); docs/web.md.\n"
    "  --daemon E              the daemon's command endpoint (default tcp://127.0.0.1:5555)\n"
    "  --pub E                 its stream endpoint (default: the one its hello names)\n"
    "  --listen HOST:PORT      where the panel listens (default 127.0.0.1:8080; port 0: any free one)\n"
    "  --token T               required on any address but loopback (one is generated and printed if not\n"
    "                          given); the page and its WebSocket need ?token=T\n"
    "  --curve FILE            CURVE keys for a daemon with curve_secret_key, as for vafm ctl: JSON\n"
    "                          {\"server_public_key\": Z85, \"public_key\": Z85, \"secret_key\": Z85}\n"
    "  --allow-shutdown        let the panel send `shutdown` (never forwarded otherwise)\n"
    "  --columns-per-block N   display columns per data block (default 32; 1-4096): min/max per column\n"
    "  --live-columns-per-s N  display columns per second of the live scope (default 100; 1-1e5)\n"
    "  --queue N               frames queued per browser before its oldest data frame is dropped (default 64)\n"
    "  --connect-timeout S     seconds to wait for the daemon's hello (default 10)\n"
    "  --ready-file FILE       write the panel's URL here once it listens (scripts, tests)\n"
    "  --uplot-dir DIR         uPlot's dist folder (default: the one installed with the panel)\n"
    "  --vafm PATH             the vafm CLI for values typed with units (default: this vafm)\n"
    "Runs " S_PYTHON " (python3-aiohttp, python3-zmq, python3-numpy, python3-scipy for the tune fit)\n"
    "with the bridge, from $VAFM_WEB_BRIDGE, else installed (PREFIX/share/vafm/web/vafm_web.py), else the\n"
    "source tree's. Exit status: the bridge's (0 on Ctrl-C, 2 usage); 1 when it cannot be started.\n";

/* 1 + the number of argv words option `a` takes (--x=value counts as one), 0 if it is not an option. */
static int s_opt_words(const char *a)
{
    for (int k = 0; k < S_NOPTS; k++) {
        size_t n = strlen(s_opts[k].name);
        if (strncmp(a, s_opts[k].name, n))
            continue;
        if (a[n] == '\0')
            return 1 + s_opts[k].takes_value;
        if (a[n] == '=' && s_opts[k].takes_value)
            return 1;
    }
    return 0;
}

/* The bridge: $VAFM_WEB_BRIDGE, else BINDIR/VAFM_DATADIR_REL/web/vafm_web.py, else the source tree's. */
static const char *s_bridge(char *buf, size_t len, const char *exe)
{
    const char *env = getenv("VAFM_WEB_BRIDGE");
    if (env && *env)
        return env;
    struct stat st;
    if (exe[0]) {
        char dir[4096];
        snprintf(dir, sizeof dir, "%s", exe);
        char *slash = strrchr(dir, '/');
        if (slash) {
            *slash = '\0';
            int w = VAFM_DATADIR_REL[0] == '/' ? snprintf(buf, len, "%s/web/vafm_web.py", VAFM_DATADIR_REL)
                                               : snprintf(buf, len, "%s/%s/web/vafm_web.py", dir, VAFM_DATADIR_REL);
            if (w > 0 && w < (int)len && stat(buf, &st) == 0)
                return buf;
        }
    }
    return VAFM_WEB_BRIDGE_SRC;
}

int vafm_cli_web(int argc, char **argv)
{
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
            fputs(s_help, stdout);
            return VAFM_CLI_EXIT_OK;
        }
    }
    if (argc - 1 > S_MAX_ARGS) {
        fprintf(stderr, "vafm web: too many arguments (%d; at most %d)\n", argc - 1, S_MAX_ARGS);
        return VAFM_CLI_EXIT_USAGE;
    }
    int user_vafm = 0;
    for (int i = 1; i < argc; i++) {
        int w = s_opt_words(argv[i]);
        if (!w) {
            fprintf(stderr, "vafm web: %s '%s' (vafm web --help lists the options)\n",
                    argv[i][0] == '-' ? "unknown option" : "unexpected argument", argv[i]);
            return VAFM_CLI_EXIT_USAGE;
        }
        if (w == 2 && i + 1 >= argc) {
            fprintf(stderr, "vafm web: %s needs a value (vafm web --help)\n", argv[i]);
            return VAFM_CLI_EXIT_USAGE;
        }
        if (!strncmp(argv[i], "--vafm", 6) && (argv[i][6] == '\0' || argv[i][6] == '='))
            user_vafm = 1;
        i += w - 1;
    }
    char exe[4096] = "";
    ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
    exe[n > 0 ? n : 0] = '\0';
    char found[4096];
    const char *bridge = s_bridge(found, sizeof found, exe);
    struct stat st;
    if (stat(bridge, &st)) {
        fprintf(stderr, "vafm web: the panel's bridge %s: %s (install vafm with meson install or the Debian package, "
                        "or set VAFM_WEB_BRIDGE)\n", bridge, strerror(errno));
        return VAFM_CLI_EXIT_RUNTIME;
    }
    /* python3, the bridge, [--vafm EXE], the user's arguments (a later --vafm of theirs wins), NULL */
    char *args[S_MAX_ARGS + 6];
    int k = 0;
    args[k++] = (char *)S_PYTHON;
    args[k++] = (char *)bridge;
    if (!user_vafm && exe[0]) {
        args[k++] = (char *)"--vafm";
        args[k++] = exe;
    }
    for (int i = 1; i < argc; i++)
        args[k++] = argv[i];
    args[k] = NULL;
    fflush(stdout);
    execv(S_PYTHON, args);
    fprintf(stderr, "vafm web: cannot run %s: %s (Debian: python3; .ci/deps.sh installs the panel's packages)\n",
            S_PYTHON, strerror(errno));
    return VAFM_CLI_EXIT_RUNTIME;
}
