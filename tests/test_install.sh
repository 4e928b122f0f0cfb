#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
#
# `meson install` into a temporary root, then, from outside the source tree, what a user and a developer do
# with an installation: the installed vafm runs a curve and `vafm study hysteresis --quick` with its figure
# (the plotter found beside the binary, not in the source tree), a small C program builds against the
# installed client library through pkg-config and runs, Debian's python3 imports the installed client, and
# the man pages, the service unit and its configuration are there. Usage: test_install.sh BUILD_DIR.
# Release build only (meson.build says why).
set -u

BUILD=$(cd "${1:?usage: test_install.sh BUILD_DIR}" && pwd)
. "$(dirname "$0")/harness.sh"
STAGE=$TMP/stage
if ! DESTDIR=$STAGE meson install -C "$BUILD" --quiet --no-rebuild >"$TMP/install.log" 2>&1; then
    bad "meson install into a temporary root" "$(tail -5 "$TMP/install.log")"
    harness_done
    exit 1
fi
ok "meson install into a temporary root"
PREFIX=$(meson introspect --buildoptions "$BUILD" | /usr/bin/python3 -c 'import json,sys; print([o["value"] for o in json.load(sys.stdin) if o["name"] == "prefix"][0])')
ROOT=$STAGE$PREFIX
LIBDIR=$(dirname "$(find "$ROOT" -name 'libvafm.so*' | head -1)")
export LD_LIBRARY_PATH=$LIBDIR
mkdir -p "$TMP/away" && cd "$TMP/away" || exit 1 # nowhere near the source tree

"$ROOT/bin/vafm" --version >"$TMP/v" 2>&1 && grep -q "^vafm 0\." "$TMP/v" && ok "installed vafm --version: $(head -1 "$TMP/v")" ||
    bad "installed vafm --version" "$(cat "$TMP/v")"
"$ROOT/bin/vafmd" --version >"$TMP/v" 2>&1 && grep -q "^vafmd 0\." "$TMP/v" && ok "installed vafmd --version" ||
    bad "installed vafmd --version" "$(cat "$TMP/v")"
if "$ROOT/bin/vafm" run --preset paper-fig4 -q >"$TMP/run" 2>&1 && grep -q "pulloff_spring_N" "$TMP/run"; then
    ok "the installed vafm runs a curve"
else
    bad "the installed vafm runs a curve" "$(tail -3 "$TMP/run")"
fi
if "$ROOT/bin/vafm" study hysteresis --quick --out study >"$TMP/study" 2>&1; then
    if /usr/bin/python3 -c 'import matplotlib' 2>/dev/null; then
        [ -s study/hysteresis.png ] && ok "vafm study hysteresis --quick draws its figure with the installed plotter" ||
            bad "the installed plotter drew the figure" "$(grep -i figure study/report.md | head -3)"
    else
        bad "vafm study hysteresis --quick draws its figure" "matplotlib missing for /usr/bin/python3 (Debian: python3-matplotlib; .ci/deps.sh installs it)"
    fi
else
    bad "the installed vafm study" "$(tail -3 "$TMP/study")"
fi

# a user's C program against the installed client library, through pkg-config
PCDIR=$(dirname "$(find "$ROOT" -name vafm-client.pc | head -1)")
cat >client_hello.c <<'CEOF'
#include <stdio.h>
#include "vafm/client.h"
#include "vafm/common.h"
int main(void)
{
    vafm_client *c = NULL;
    vafm_error err = {0};
    int r = vafm_client_new(&c, "ipc:///nonexistent/vafm-install-test", NULL, &err);
    printf("client %s\n", r == 0 ? "created" : err.message);
    vafm_client_destroy(&c);
    return r == 0 ? 0 : 1;
}
CEOF
flags=$(PKG_CONFIG_PATH=$PCDIR pkg-config --define-variable=prefix="$ROOT" --cflags --libs vafm-client 2>"$TMP/pc")
if [ $? -eq 0 ] && cc -std=c17 client_hello.c $flags -o client_hello 2>"$TMP/cc"; then
    ok "a C program builds against the installed client with pkg-config ($flags)"
    ./client_hello >"$TMP/ch" 2>&1 && ok "... and runs: $(cat "$TMP/ch")" || bad "the C program runs" "$(cat "$TMP/ch")"
else
    bad "a C program builds against the installed client with pkg-config" "$(cat "$TMP/pc" "$TMP/cc" | head -5)"
fi
flags=$(PKG_CONFIG_PATH=$PCDIR pkg-config --define-variable=prefix="$ROOT" --cflags --libs vafm)
printf '#include "vafm/sim.h"\n#include <stdio.h>\nint main(void){vafm_params p; vafm_params_default(&p); printf("%%s\\n", vafm_version()); return vafm_params_validate(&p, NULL);}\n' >core.c
if cc -std=c17 core.c $flags -o core 2>"$TMP/cc" && ./core >"$TMP/core"; then ok "a C program builds against the installed core with pkg-config and runs"
else bad "a C program against the installed core" "$(head -5 "$TMP/cc")"; fi

PYDIR=$(dirname "$(find "$ROOT" -type d -name vafm_client | head -1)")
if PYTHONPATH=$PYDIR /usr/bin/python3 -c 'import vafm_client, sys; print(vafm_client.__version__, vafm_client.__file__)' >"$TMP/py" 2>&1 &&
   grep -q "$STAGE" "$TMP/py"; then
    ok "Debian's python3 imports the installed client ($(cat "$TMP/py"))"
else
    bad "Debian's python3 imports the installed client" "$(cat "$TMP/py")"
fi
for f in share/man/man1/vafm.1 share/man/man1/vafmd.1 lib/systemd/system/vafmd.service etc/vafm/vafmd.json share/vafm/study_plot.py; do
    [ -s "$ROOT/$f" ] && ok "installed: $f" || bad "installed: $f"
done
grep -q "ExecStart=$PREFIX/bin/vafmd --config $PREFIX/etc/vafm/vafmd.json" "$ROOT/lib/systemd/system/vafmd.service" &&
    ok "the unit starts the installed vafmd with the installed configuration" || bad "the unit's ExecStart"
grep -q '"tcp://127.0.0.1:5555"' "$ROOT/etc/vafm/vafmd.json" && ok "the default configuration is loopback" ||
    bad "the default configuration is loopback"
for h in h5.h record.h scene.h; do
    [ ! -e "$ROOT/include/vafm/$h" ] && ok "not installed: vafm/$h (a program-internal library's header)" ||
        bad "not installed: vafm/$h"
done

harness_done
