#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
#
# `vafm map` end to end (issue #15): bad input names the field and leaves no file; a uniform map's curve i is
# `vafm samples --index i` (time, height, force, tip position, segment as written); the file does not depend on
# the thread count; vafm info shows the map (grid, regions, text maps) and the conformance check passes (V5);
# --resume keeps a finished map and refuses another pattern; the Python example draws a map and recovers the
# moduli of a Hertz dome (cell-liquid: ~2 ms a curve).
# Usage: test_map_cli.sh path/to/vafm [path/to/python3]. Prints one line per check and "N passed, M failed".
set -u

VAFM=${1:?usage: test_map_cli.sh path/to/vafm [python3]}
PY=${2:-/usr/bin/python3}
HERE=$(cd "$(dirname "$0")" && pwd)
. "$HERE/harness.sh"

run() { "$VAFM" "$@" >"$TMP/out" 2>"$TMP/err"; rc=$?; }

expect_fail() {
    local desc=$1 want=$2 needles=() n
    shift 2
    while [ $# -gt 0 ] && [ "$1" != "--" ]; do needles+=("$1"); shift; done
    shift
    run "$@"
    if [ "$rc" -ne "$want" ]; then
        bad "$desc" "exit $rc, want $want: $(head -c 300 "$TMP/err")"
        return
    fi
    for n in "${needles[@]}"; do
        if ! grep -qF -- "$n" "$TMP/err"; then
            bad "$desc" "message lacks '$n': $(head -c 300 "$TMP/err")"
            return
        fi
    done
    ok "$desc"
}

B="$TMP/bad.h5"
expect_fail "map: nx = 0 names nx and its range" 2 "nx" "[1, 1024]" -- map --nx 0 --out "$B"
expect_fail "map: 1024 x 1024 pixels names nx and the pixel limit" 2 "nx x ny" "262144" -- map --nx 1024 --ny 1024 --out "$B"
expect_fail "map: an unknown pattern names the known ones" 2 "pattern 'spiral'" "stripes" -- map --pattern spiral --out "$B"
expect_fail "map: a negative size names size_x_m and its range" 2 "size_x_m" "(0, 0.01]" -- map --size -1e-6 --out "$B"
expect_fail "map: an unknown pattern parameter lists the known ones" 2 "'bogus'" "period_m" -- map --pattern-param bogus=1 --out "$B"
expect_fail "map: a pattern parameter out of range names it" 2 "b_E_star_Pa" -- map --pattern-param b_E_star_Pa=-5 --out "$B"
expect_fail "map: a fixed start below the dome's top names start_height_m" 2 "start_height_m" "fixed" -- \
    map --preset cell-liquid --pattern dome --pattern-param start=fixed,height_m=1e-6 --out "$B"
expect_fail "map: --out is required" 2 "--out" -- map --nx 2
if [ ! -e "$B" ]; then ok "map: refused maps leave no file"; else bad "map: refused maps leave no file" "$B exists"; fi

# a uniform map = the single curves, pixel by pixel (contact-silica: JKR, ~15 ms a curve)
run map --preset contact-silica --nx 3 --ny 2 --out "$TMP/u.h5" --threads 2 -q
if [ "$rc" -eq 0 ] && grep -q "^force map    3 x 2 pixels, pattern uniform, start surface; 6 curve(s)" "$TMP/out"; then
    ok "map: a 3 x 2 uniform map with its summary"
else bad "map: uniform map" "exit $rc: $(head -c 300 "$TMP/err")"; fi
same=1
for i in 0 4 5; do
    run export "$TMP/u.h5" --curve $i
    cut -d, -f1,2,4,5,6 "$TMP/out" >"$TMP/e.csv"
    run samples --preset contact-silica --index $i
    cut -d, -f1,2,4,5,6 "$TMP/out" >"$TMP/s.csv"
    cmp -s "$TMP/e.csv" "$TMP/s.csv" && [ "$(wc -l <"$TMP/e.csv")" -gt 100 ] || same=0
done
if [ $same = 1 ]; then ok "map: uniform pixels 0, 4, 5 = vafm samples --index 0, 4, 5 (index iy*nx + ix) as written"
else bad "map: uniform pixels = samples" "curves differ"; fi

# stripes on 1 and 2 threads: the same file, curve for curve
for t in 1 2; do
    run map --preset contact-silica --nx 4 --ny 2 --pattern stripes --pattern-param period_m=10e-6,b_E_star_Pa=5e9,b_gamma_J_per_m2=0.02 \
        --out "$TMP/s$t.h5" --threads $t -q
done
same=1
for i in 0 2 7; do
    "$VAFM" export "$TMP/s1.h5" --curve $i >"$TMP/a.csv" 2>/dev/null && "$VAFM" export "$TMP/s2.h5" --curve $i >"$TMP/b.csv" 2>/dev/null &&
        cmp -s "$TMP/a.csv" "$TMP/b.csv" || same=0
done
if [ $same = 1 ]; then ok "map: 1 and 2 threads give the same curves"; else bad "map: threads" "exports differ"; fi

run info "$TMP/s1.h5"
if [ "$rc" -eq 0 ] && grep -q "^grid         a force map (vafm map), pattern stripes, start surface" "$TMP/out" &&
    grep -q "^map          4 x 2 pixels over 10 x 10 um centred at (0, 0) um" "$TMP/out" &&
    grep -qE "^  a  E\* = 5.3e\+10 +Pa +gamma = 0.05 .* 4 curves" "$TMP/out" &&
    grep -qE "^  b  E\* = 5e\+09 +Pa +gamma = 0.02 .* 4 curves" "$TMP/out" &&
    grep -A2 "^material map" "$TMP/out" | grep -qx "  aabb" &&
    grep -q "^adhesion map" "$TMP/out" && grep -q "^conformance  ok: .*V1-V5" "$TMP/out"; then
    ok "info: a map as a map (grid, per-material regions, material and adhesion maps), conformance ok"
else bad "info of a map" "exit $rc: $(head -c 1500 "$TMP/out")"; fi

# resume: a finished map is kept as it is; another pattern is refused naming it
cp "$TMP/s1.h5" "$TMP/r.h5"
run map --preset contact-silica --nx 4 --ny 2 --pattern stripes --pattern-param period_m=10e-6,b_E_star_Pa=5e9,b_gamma_J_per_m2=0.02 \
    --out "$TMP/r.h5" --resume
if [ "$rc" -eq 0 ] && grep -q "holds 8 of the map's 8 curves" "$TMP/err" && grep -q "8 curves (8 kept from before, 0 new)" "$TMP/out"; then
    ok "map --resume of a finished map keeps its 8 curves"
else bad "map --resume" "exit $rc: $(head -c 300 "$TMP/err")"; fi
expect_fail "map --resume with another pattern is refused naming it" 2 "pattern" "differs" -- \
    map --preset contact-silica --nx 4 --ny 2 --pattern disc --out "$TMP/r.h5" --resume
expect_fail "map: an existing file needs --resume or --overwrite" 2 "exists already" -- map --out "$TMP/r.h5"

# topography: a dome, fixed start; the contact point follows the surface in the file
run map --preset cell-liquid --nx 5 --ny 1 --size 10e-6,2e-6 --pattern dome \
    --pattern-param radius_m=3.5e-6,height_m=200e-9,start=fixed,b_E_star_Pa=nan --start_height_m 600e-9 --T_K 0 \
    --out "$TMP/d.h5" -q
run info "$TMP/d.h5"
if grep -q "^height map" "$TMP/out" && grep -q "start fixed" "$TMP/out" && grep -q "^conformance  ok" "$TMP/out"; then
    ok "map: a dome with a fixed start (height map, conformance ok)"
else bad "map: dome" "$(head -c 800 "$TMP/out")"; fi

# the Python example: a 12 x 12 Hertz dome, true vs recovered maps into a PNG, moduli within 2%
if "$PY" -c "import h5py, matplotlib" 2>/dev/null; then
    run map --preset cell-liquid --nx 12 --ny 12 --pattern dome --pattern-param b_E_star_Pa=30e3,height_m=300e-9 \
        --out "$TMP/py.h5" -q
    MPLBACKEND=Agg PYTHONDONTWRITEBYTECODE=1 "$PY" "$HERE/../clients/python/examples/force_map.py" "$TMP/py.h5" \
        --png "$TMP/py.png" --json "$TMP/py.json" >"$TMP/pyout" 2>&1
    prc=$?
    if [ $prc -eq 0 ] && [ "$(head -c 4 "$TMP/py.png" | od -An -c | tr -d ' ')" = "211PNG" ] &&
        [ "$(stat -c %s "$TMP/py.png")" -gt 10000 ] &&
        "$PY" - "$TMP/py.json" <<'EOF'
import json, sys
r = json.load(open(sys.argv[1]))
ms = r["materials"]
assert r["nx"] == 12 and len(ms) == 2, r
for m in ms:
    assert abs(m["E_recovered_Pa"] / m["E_true_Pa"] - 1) < 0.02, m
EOF
    then ok "python example force_map.py: PNG of true vs recovered maps; moduli within 2% ($(grep -c '^material' "$TMP/pyout") materials)"
    else bad "python example force_map.py" "exit $prc: $(head -c 600 "$TMP/pyout")"; fi
else
    echo "skip - python example force_map.py (h5py or matplotlib missing)"
fi

harness_done
