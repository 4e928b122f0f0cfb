#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
#
# `meson install` into a temporary root, then, from outside the source tree, what a user and a developer do
# with an installation: the installed vafm runs a curve and `vafm study hysteresis --quick` with its figure
# (the plotter found beside the binary, not in the source tree), a small C program builds against the
# installed client library through pkg-config and runs, Debian's python3 imports the installed client (and
# pytest its plugin, by entry point, on the installed vafmd), and the man pages, the service unit and its configuration are there. Usage: test_install.sh BUILD_DIR.
# Release build only (meson.build says why).
set -u

BUILD=$(cd "${1:?usage: test_install.sh BUILD_DIR}" && pwd)
HERE=$(cd "$(dirname "$0")" && pwd)
. "$HERE/harness.sh"
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
# the installed programs find their libraries themselves (a RUNPATH relative to the binary, unless the
# prefix is /usr): 0.6.2's did not, `make install PREFIX=/opt/vafm` gave a vafm that did not start
for b in vafm vafmd; do
    if [ "$PREFIX" = /usr ]; then
        ok "$b: prefix /usr, no RUNPATH wanted"
    elif env -u LD_LIBRARY_PATH "$ROOT/bin/$b" --version >"$TMP/v" 2>&1; then
        ok "the installed $b runs without LD_LIBRARY_PATH"
    else
        bad "the installed $b runs without LD_LIBRARY_PATH" "$(head -2 "$TMP/v")"
    fi
done
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

# a user's C program against the installed client library, through pkg-config: it calls every function
# client.h declares, those of the headers it includes too (0.6.2's vafm-client.pc left out libvafm, so a
# program calling vafm_strerror did not link: issue #29 item 11)
PCDIR=$(dirname "$(find "$ROOT" -name vafm-client.pc | head -1)")
cat >client_all.c <<'CEOF'
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "vafm/client.h"
int main(void)
{
    vafm_client *c = NULL;
    vafm_error err = {0};
    int r = vafm_client_new(&c, "ipc:///nonexistent/vafm-install-test", "ipc:///nonexistent/vafm-install-pub", &err);
    if (r) {
        printf("vafm_client_new: %s (%s)\n", err.message, vafm_strerror(r));
        return 1;
    }
    vafm_client_set_retries(c, 0);
    int rc = vafm_client_set_curve(c, "short", "short", "short", &err); /* refused: not Z85 keys */
    char *reply = NULL;
    int rq = vafm_client_request(c, "{\"cmd\":\"status\"}", 50, &reply, &err); /* no daemon: times out */
    const char *code = vafm_client_reply_code(c);
    int sb = vafm_client_subscribe(c, 50, &err);
    vafm_client_msg msg;
    memset(&msg, 0, sizeof msg);
    int rv = vafm_client_receive(c, &msg, 10, &err);
    vafm_client_msg_clear(&msg);
    unsigned long long gaps = (unsigned long long)vafm_client_gaps(c);
    vafm_client_destroy(&c);
    free(reply);
    unsigned char b[8];
    vafm_wire_put_f64(b, 1.5);
    printf("client %s api %06x: curve keys %s, request %s, code '%s', subscribe %d, receive %d, gaps %llu, f64 %g%s\n",
           vafm_version(), vafm_version_api(), rc ? "refused" : "taken", rq ? vafm_strerror(rq) : "answered",
           code ? code : "", sb, rv, gaps, vafm_wire_get_f64(b), c == NULL ? "" : " (destroy left c)");
    return rc != 0 && rq != 0 && c == NULL ? 0 : 1;
}
CEOF
missing=""
for f in $(sed -n 's/^VAFM_API[^(]*[ *]\(vafm_[a-z0-9_]*\)(.*/\1/p' "$ROOT/include/vafm/client.h" "$ROOT/include/vafm/common.h"); do
    grep -q "$f(" client_all.c || missing="$missing $f"
done
[ -z "$missing" ] && ok "the client test program calls every function of client.h and common.h" ||
    bad "the client test program calls every function of client.h and common.h" "missing:$missing"
flags=$(PKG_CONFIG_PATH=$PCDIR pkg-config --define-variable=prefix="$ROOT" --cflags --libs vafm-client 2>"$TMP/pc")
if [ $? -eq 0 ] && cc -std=c17 -Wall -Werror client_all.c $flags -o client_all 2>"$TMP/cc"; then
    ok "a C program builds against the installed client with pkg-config ($flags)"
    ./client_all >"$TMP/ch" 2>&1 && ok "... and runs: $(cat "$TMP/ch")" || bad "the C program runs" "$(cat "$TMP/ch")"
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
# the pytest plugin, by its pytest11 entry point (the installed dist-info), on the installed vafmd: the first
# test of docs/daemon.md "Testing your acquisition code"
cat >test_first.py <<'PY'
from vafm_client import Client, Stream

def take_curve(rep, pub, index):                 # your acquisition code
    with Client(rep) as c, Stream(pub) as s:
        return s.run(c.curve(index=index)["run_id"])

def test_first_curve(vafmd, vafm_scene):
    vafm_scene("contact-silica", setpoint="1nN")   # a preset plus overrides with units
    run = take_curve(vafmd.rep, vafmd.pub, 0)
    vafmd.assert_curves_match_log([{"index": 0, "force_N": run["force_N"], "height_m": run["height_m"]}])
PY
if PYTHONPATH=$PYDIR PYTHONDONTWRITEBYTECODE=1 VAFMD= /usr/bin/python3 -m pytest -p no:cacheprovider \
    --vafmd "$ROOT/bin/vafmd" test_first.py >"$TMP/pytest" 2>&1 && grep -Eq "^=+ 1 passed in" "$TMP/pytest"; then
    ok "pytest finds the installed plugin by its entry point; the first test passes on the installed vafmd"
else
    bad "the installed pytest plugin (entry point) runs the first test" "$(tail -5 "$TMP/pytest")"
fi
# the installed `vafm web` serves the panel: the installed bridge, its page, uPlot (npm) and the tune fit of the
# installed vafm_client (0.6.2's panel ran from the source tree only)
if PYTHONPATH=$PYDIR PYTHONDONTWRITEBYTECODE=1 /usr/bin/python3 "$HERE/web_serves.py" "$ROOT/bin/vafm" "$ROOT/bin/vafmd" \
    "$ROOT/share/vafm/web/vafm_web.py" >"$TMP/web" 2>&1; then
    ok "the installed vafm web: $(cat "$TMP/web")"
else
    bad "the installed vafm web serves the panel" "$(tail -3 "$TMP/web")"
fi
for f in share/man/man1/vafm.1 share/man/man1/vafmd.1 lib/systemd/system/vafmd.service etc/vafm/vafmd.json share/vafm/study_plot.py \
    share/vafm/web/static/index.html share/vafm/web/node_modules/uplot/LICENSE; do
    [ -s "$ROOT/$f" ] && ok "installed: $f" || bad "installed: $f"
done
grep -q "ExecStart=$PREFIX/bin/vafmd --config $PREFIX/etc/vafm/vafmd.json" "$ROOT/lib/systemd/system/vafmd.service" &&
    ok "the unit starts the installed vafmd with the installed configuration" || bad "the unit's ExecStart"
grep -q '"tcp://127.0.0.1:5555"' "$ROOT/etc/vafm/vafmd.json" && ok "the default configuration is loopback" ||
    bad "the default configuration is loopback"
# the installed configuration starts the documented default scene (contact-silica, docs/daemon.md and
# `vafmd --help`): the scene `get` reports with it equals the one without a configuration (0.6.2's file
# named paper-fig1, 7 °C and Q 0.63: issue #29 item 12). Private ipc endpoints, not the file's tcp ones.
scene_with() { # CONFIG|"" -> the `get` reply's values, on stdout
    local dir=$TMP/d$RANDOM cfg=() pid
    mkdir -p "$dir"
    if [ -n "$1" ]; then
        /usr/bin/python3 -c 'import json,sys; c=json.load(open(sys.argv[1])); c.update(rep=sys.argv[2], pub=sys.argv[3]); json.dump(c, open(sys.argv[4], "w"))' \
            "$1" "ipc://$dir/r" "ipc://$dir/p" "$dir/cfg.json" && cfg=(--config "$dir/cfg.json")
    else
        cfg=(--rep "ipc://$dir/r" --pub "ipc://$dir/p")
    fi
    "$ROOT/bin/vafmd" "${cfg[@]}" >"$dir/log" 2>&1 &
    pid=$!
    "$ROOT/bin/vafm" ctl --endpoint "ipc://$dir/r" --timeout 5000 get | /usr/bin/python3 -c 'import json,sys; print(json.dumps(json.load(sys.stdin)["values"], sort_keys=True))'
    kill "$pid" 2>/dev/null
    wait "$pid" 2>/dev/null
}
grep -q "default $(sed -n 's/.*"preset": *"\([^"]*\)".*/\1/p' "$ROOT/etc/vafm/vafmd.json"))" <("$ROOT/bin/vafmd" --help) &&
    ok "the installed vafmd.json names the default preset of vafmd --help" ||
    bad "the installed vafmd.json names the default preset of vafmd --help" "$(grep preset "$ROOT/etc/vafm/vafmd.json")"
with=$(scene_with "$ROOT/etc/vafm/vafmd.json")
without=$(scene_with "")
if [ -n "$with" ] && [ "$with" = "$without" ]; then
    ok "the installed vafmd.json starts the default scene"
else
    bad "the installed vafmd.json starts the default scene" "$(printf '%s\n%s' "$with" "$without" | head -c 600)"
fi
for h in h5.h record.h scene.h; do
    [ ! -e "$ROOT/include/vafm/$h" ] && ok "not installed: vafm/$h (a program-internal library's header)" ||
        bad "not installed: vafm/$h"
done

harness_done
