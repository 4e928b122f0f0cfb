#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
#
# The Debian packages `make deb` built (not part of meson test): each package holds its files and no file is
# in two packages; then, with no installation, the packages are extracted into a temporary directory and
# used from there: the extracted vafm and vafmd run (LD_LIBRARY_PATH at the extracted libvafm0) and report
# the packaged version, vafm runs a curve and a quick study with its figure, a C program builds against the
# extracted libvafm-dev through pkg-config, and python3 imports the extracted client.
# Usage: test_deb.sh DEB_DIR (the directory of the .debs).
set -u

DEBDIR=$(cd "${1:?usage: test_deb.sh DEB_DIR}" && pwd)
HERE=$(cd "$(dirname "$0")" && pwd)
. "$HERE/harness.sh"
MA=$(dpkg-architecture -qDEB_HOST_MULTIARCH)

deb_of() { # the .deb of a package, or nothing
    local f
    for f in "$DEBDIR/$1"_*.deb; do [ -f "$f" ] && echo "$f" && return; done
}
declare -A DEBS
for p in vafm libvafm0 libvafm-dev python3-vafm-client; do
    DEBS[$p]=$(deb_of "$p")
    if [ -n "${DEBS[$p]}" ]; then
        dpkg-deb -c "${DEBS[$p]}" | awk '{ sub(/^\./, "", $6); print $6 }' >"$TMP/$p.list"
        ok "$p: $(basename "${DEBS[$p]}") ($(grep -vc '/$' "$TMP/$p.list") files and links)"
    else
        bad "$p: no ${p}_*.deb in $DEBDIR"
    fi
done
if [ $fail -ne 0 ]; then
    harness_done
    exit 1
fi

has() { # has PACKAGE PATH...: each path is in the package's file list
    local p=$1 f
    shift
    for f in "$@"; do
        grep -qxF "$f" "$TMP/$p.list" && ok "$p has $f" || bad "$p has $f" "not in dpkg-deb -c $(basename "${DEBS[$p]}")"
    done
}
hasnt() {
    local p=$1 f
    shift
    for f in "$@"; do
        grep -qxF "$f" "$TMP/$p.list" && bad "$p has no $f" "it is there" || ok "$p has no $f"
    done
}
has vafm /usr/bin/vafm /usr/bin/vafmd /usr/share/man/man1/vafm.1.gz /usr/share/man/man1/vafmd.1.gz \
    /lib/systemd/system/vafmd.service /etc/vafm/vafmd.json /usr/share/vafm/study_plot.py \
    /usr/share/vafm/web/vafm_web.py /usr/share/vafm/web/static/index.html /usr/share/vafm/web/static/panel.js \
    /usr/share/vafm/web/node_modules/uplot/dist/uPlot.iife.min.js /usr/share/vafm/web/node_modules/uplot/LICENSE
dpkg-deb -I "${DEBS[vafm]}" conffiles 2>/dev/null | grep -qx /etc/vafm/vafmd.json &&
    ok "vafm: /etc/vafm/vafmd.json is a conffile" || bad "vafm: /etc/vafm/vafmd.json is a conffile"
has libvafm0 "/usr/lib/$MA/libvafm.so.0" "/usr/lib/$MA/libvafm_client.so.0"
hasnt libvafm0 "/usr/lib/$MA/libvafm.so" "/usr/lib/$MA/libvafm_client.so"
dpkg-deb -I "${DEBS[libvafm0]}" shlibs 2>/dev/null >"$TMP/shlibs"
grep -q "^libvafm 0 libvafm0 (>= " "$TMP/shlibs" && grep -q "^libvafm_client 0 libvafm0 (>= " "$TMP/shlibs" &&
    ok "libvafm0: shlibs for libvafm.so.0 and libvafm_client.so.0: $(head -1 "$TMP/shlibs")" ||
    bad "libvafm0: shlibs" "$(cat "$TMP/shlibs")"
has libvafm-dev /usr/include/vafm/version.h /usr/include/vafm/common.h /usr/include/vafm/sim.h \
    /usr/include/vafm/client.h "/usr/lib/$MA/pkgconfig/vafm.pc" "/usr/lib/$MA/pkgconfig/vafm-client.pc" \
    "/usr/lib/$MA/libvafm.so" "/usr/lib/$MA/libvafm_client.so"
hasnt libvafm-dev /usr/include/vafm/h5.h /usr/include/vafm/record.h /usr/include/vafm/scene.h
has python3-vafm-client /usr/lib/python3/dist-packages/vafm_client/__init__.py \
    /usr/lib/python3/dist-packages/vafm_client/client.py /usr/lib/python3/dist-packages/vafm_client/h5.py \
    /usr/lib/python3/dist-packages/vafm_client/spawn.py /usr/lib/python3/dist-packages/vafm_client/tune.py
cat "$TMP"/*.list | grep -v '/$' | sort | uniq -d >"$TMP/dup"
[ -s "$TMP/dup" ] && bad "no file is in two packages" "$(head -3 "$TMP/dup")" || ok "no file is in two packages"

has python3-vafm-client /usr/lib/python3/dist-packages/vafm_client/pytest_plugin.py \
    "/usr/lib/python3/dist-packages/vafm_client-$(dpkg-deb -f "${DEBS[python3-vafm-client]}" Version | sed 's/-[^-]*$//').dist-info/entry_points.txt" \
    /usr/share/doc/python3-vafm-client/examples/pytest_acquisition/test_acquire.py

# the packages extracted (no installation) and used from there
ROOT=$TMP/root
for p in vafm libvafm0 libvafm-dev python3-vafm-client; do dpkg-deb -x "${DEBS[$p]}" "$ROOT"; done
DOC=$ROOT/usr/share/doc/vafm
zcat -f "$DOC"/README.md* 2>/dev/null | head -1 | grep -q '^# vafm — a virtual AFM' &&
    ok "vafm's documentation: the README" || bad "vafm's documentation: the README" "$(ls "$DOC")"
zcat -f "$DOC"/protocol/wire.md* 2>/dev/null | grep -q . && ok "vafm's documentation: the protocol (protocol/wire.md)" ||
    bad "vafm's documentation: protocol/wire.md" "$(ls "$DOC")"
export LD_LIBRARY_PATH=$ROOT/usr/lib/$MA
VERSION=$(dpkg-deb -f "${DEBS[vafm]}" Version | sed 's/-[^-]*$//')
mkdir -p "$TMP/away" && cd "$TMP/away" || exit 1
for prog in vafm vafmd; do
    "$ROOT/usr/bin/$prog" --version >"$TMP/v" 2>&1 && grep -q "^$prog $VERSION\b" "$TMP/v" &&
        ok "extracted $prog --version: $(head -1 "$TMP/v")" || bad "extracted $prog --version says $VERSION" "$(head -3 "$TMP/v")"
done
ldd "$ROOT/usr/bin/vafm" >"$TMP/ldd" 2>&1
grep -q "libvafm.so.0 => $ROOT/" "$TMP/ldd" && grep -q "libvafm_client.so.0 => $ROOT/" "$TMP/ldd" &&
    ! grep -q "not found" "$TMP/ldd" && ok "vafm finds libvafm and libvafm_client in the extracted libvafm0" ||
    bad "vafm's libraries" "$(grep -E 'vafm|not found' "$TMP/ldd")"
for lib in libvafm libvafm_client; do
    so=$(objdump -p "$ROOT/usr/lib/$MA/$lib.so" | awk '$1 == "SONAME" { print $2 }')
    [ "$so" = "$lib.so.0" ] && ok "$lib SONAME $so" || bad "$lib SONAME is $lib.so.0" "$so"
done
if "$ROOT/usr/bin/vafm" run --preset paper-fig4 -q >"$TMP/run" 2>&1 && grep -q pulloff_spring_N "$TMP/run"; then
    ok "the extracted vafm runs a curve"
else
    bad "the extracted vafm runs a curve" "$(tail -3 "$TMP/run")"
fi
# the study's plotter is found beside the binary: /usr/bin/../share/vafm/study_plot.py
if "$ROOT/usr/bin/vafm" study hysteresis --quick --out study >"$TMP/study" 2>&1; then
    if /usr/bin/python3 -c 'import matplotlib' 2>/dev/null; then
        # (the report names the plotter: not the build tree's, whose path the binary keeps as a last resort)
        [ -s study/hysteresis.png ] && grep -qF "\`$ROOT/usr/bin/../share/vafm/study_plot.py\`" study/report.md &&
            ok "the extracted vafm study draws its figure with the packaged plotter" ||
            bad "the packaged plotter drew the figure" "$(grep -i figure study/report.md | head -3)"
    else
        bad "the extracted vafm study hysteresis --quick draws its figure" "matplotlib missing (Debian: python3-matplotlib; .ci/deps.sh installs it)"
    fi
else
    bad "the extracted vafm study hysteresis --quick" "$(tail -3 "$TMP/study")"
fi
printf '#include "vafm/sim.h"\n#include "vafm/client.h"\n#include <stdio.h>\nint main(void){vafm_params p; vafm_params_default(&p); printf("%%s\\n", vafm_version()); return vafm_params_validate(&p, NULL);}\n' >core.c
flags=$(PKG_CONFIG_PATH=$ROOT/usr/lib/$MA/pkgconfig pkg-config --define-variable=prefix="$ROOT/usr" --cflags --libs vafm vafm-client 2>&1)
if cc -std=c17 core.c $flags -o core >"$TMP/cc" 2>&1 && ./core >"$TMP/core" 2>&1; then
    ok "a C program builds against the extracted libvafm-dev with pkg-config and runs: $(cat "$TMP/core")"
else
    bad "a C program against the extracted libvafm-dev" "$flags; $(head -5 "$TMP/cc" "$TMP/core")"
fi
if PYTHONPATH=$ROOT/usr/lib/python3/dist-packages /usr/bin/python3 -c \
    'import vafm_client; print(vafm_client.__version__, vafm_client.__file__)' >"$TMP/py" 2>&1 &&
    grep -q "^$VERSION $ROOT/" "$TMP/py"; then
    ok "python3 imports the extracted vafm_client $(cut -d' ' -f1 "$TMP/py")"
else
    bad "python3 imports the extracted vafm_client $VERSION" "$(tail -3 "$TMP/py")"
fi
# the extracted `vafm web` serves the panel: the packaged bridge, page, uPlot and the packaged client's tune fit
if PYTHONPATH=$ROOT/usr/lib/python3/dist-packages PYTHONDONTWRITEBYTECODE=1 /usr/bin/python3 "$HERE/web_serves.py" \
    "$ROOT/usr/bin/vafm" "$ROOT/usr/bin/vafmd" "$ROOT/usr/share/vafm/web/vafm_web.py" >"$TMP/web" 2>&1; then
    ok "the extracted vafm web: $(cat "$TMP/web")"
else
    bad "the extracted vafm web serves the panel" "$(tail -3 "$TMP/web")"
fi

# the pytest plugin, found by its pytest11 entry point in the extracted dist-info (no -p), and vafmd on PATH:
# the packaged example acquisition module's tests, its expected failure (the careless module) included
EX=$TMP/pytest_acquisition
cp -r "$ROOT/usr/share/doc/python3-vafm-client/examples/pytest_acquisition" "$EX" 2>/dev/null &&
    find "$EX" -name '*.gz' -exec gunzip {} + 2>/dev/null
if [ -f "$EX/test_acquire.py" ] &&
    PATH=$ROOT/usr/bin:$PATH PYTHONPATH=$ROOT/usr/lib/python3/dist-packages PYTHONDONTWRITEBYTECODE=1 VAFMD= \
    /usr/bin/python3 -m pytest -p no:cacheprovider -rxs "$EX" >"$TMP/pytest" 2>&1 &&
    grep -Eq "^=+ 3 passed, 1 xfailed in" "$TMP/pytest"; then
    ok "the packaged example's tests pass through the extracted pytest plugin: $(tail -1 "$TMP/pytest" | tr -d =)"
else
    bad "the packaged example's tests through the extracted pytest plugin (entry point, vafmd on PATH)" \
        "$(tail -5 "$TMP/pytest" 2>/dev/null)"
fi
PYTHONPATH=$ROOT/usr/lib/python3/dist-packages /usr/bin/python3 -m pytest --trace-config --co -q "$EX" 2>&1 |
    grep -q "registered: <module 'vafm_client.pytest_plugin' from '$ROOT/" &&
    ok "pytest loads the plugin from the extracted package" ||
    bad "pytest loads the plugin from the extracted package" "$(grep -i vafm "$TMP/pytest" | head -3)"

harness_done
