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



B="$TMP/bad.h5"
expect_fail "map: nx = 0 names nx and its range" 2 "nx" "[1, 1024]" -- map --nx 0 --out "$B"
expect_fail "map: 1024 x 1024 pixels names nx and the pixel limit" 2 "nx x ny" "262144" -- map --nx 1024 --ny 1024 --out "$B"
expect_fail "map: an unknown pattern names the known ones" 2 "pattern 'spiral'" "stripes" -- map --pattern spiral --out "$B"
expect_fail "map: a negative size names size_x_m and its range" 2 "size_x_m" "(0, 0.01]" -- map --size -1e-6 --out "$B"
expect_fail "map: an unknown pattern parameter lists the known ones" 2 "'bogus'" "period_m" -- map --pattern-param bogus=1 --out "$B"
expect_fail "map: a pattern parameter out of range names it" 2 "b_E_star_Pa" -- map --pattern-param b_E_star_Pa=-5 --out "$B"
expect_fail "map: domains of 1e-300 m name domain_m and its range (0.6.2: int64 overflow, a degenerate map)" 2 \
    "domain_m" "[1e-12, 0.01] m" -- map --preset cell-liquid --nx 2 --ny 2 --threads 1 --pattern domains \
    --pattern-param domain_m=1e-300 --out "$B"
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
    grep -q "^adhesion map" "$TMP/out" && grep -q "^conformance  ok: .*V1-V7" "$TMP/out"; then
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
    bad "python example force_map.py" "h5py or matplotlib missing for $PY (Debian: python3-h5py python3-matplotlib; .ci/deps.sh installs them)"
fi

# A measured map as the sample (--sample GRID.h5, pattern grid): the file's ground truth at every pixel is the
# grid's bilinear interpolation there (E*, height; clamped at the edges), to rounding; hostile grids are refused
# naming the dataset or attribute, before any curve runs.
if "$PY" -c 'import h5py, numpy' 2>/dev/null; then
    "$PY" - "$TMP" <<'EOF'
import sys, h5py, numpy as np
d = sys.argv[1]
y, x = np.mgrid[0:3, 0:4]
with h5py.File(d + "/grid.h5", "w") as f:
    f["E_star_Pa"] = 5e3 + 2e3 * x + 1e3 * y * x           # Pa, varies bilinearly and more
    f["height_m"] = 1e-7 * (x + y) ** 2 / 25                # m
    for k, v in (("x0_m", -3e-6), ("y0_m", -2e-6), ("dx_m", 2e-6), ("dy_m", 2e-6)):
        f.attrs[k] = v
with h5py.File(d + "/nan.h5", "w") as f:
    a = np.full((3, 3), 6e3); a[1, 1] = np.nan
    f["E_star_Pa"] = a
    for k, v in (("x0_m", 0.0), ("y0_m", 0.0), ("dx_m", 1e-6), ("dy_m", 1e-6)):
        f.attrs[k] = v
with h5py.File(d + "/noattr.h5", "w") as f:
    f["height_m"] = np.zeros((2, 2))
with h5py.File(d + "/shape.h5", "w") as f:
    f["E_star_Pa"] = np.full((3, 3), 6e3); f["height_m"] = np.zeros((2, 3))
    for k, v in (("x0_m", 0.0), ("y0_m", 0.0), ("dx_m", 1e-6), ("dy_m", 1e-6)):
        f.attrs[k] = v
# the data outside the file, in a FIFO: an external raw-data file, a virtual dataset's source
with h5py.File(d + "/external.h5", "w") as f:
    f.create_dataset("E_star_Pa", shape=(4, 4), dtype="f8", external=[(d + "/fifo", 0, 128)])
    for k, v in (("x0_m", -5e-6), ("y0_m", -5e-6), ("dx_m", 1e-6), ("dy_m", 1e-6)):
        f.attrs[k] = v
with h5py.File(d + "/virtual.h5", "w") as f:
    lay = h5py.VirtualLayout(shape=(4, 4), dtype="f8")
    lay[:] = h5py.VirtualSource(d + "/fifo", "E_star_Pa", shape=(4, 4))
    f.create_virtual_dataset("height_m", lay, fillvalue=0)
    for k, v in (("x0_m", -5e-6), ("y0_m", -5e-6), ("dx_m", 1e-6), ("dy_m", 1e-6)):
        f.attrs[k] = v
# links are not followed (issue #29): external to the FIFO or to a good grid file, soft to a dataset of the file
for name, link in (("extfifo", h5py.ExternalLink(d + "/fifo", "/E_star_Pa")),
                   ("extfile", h5py.ExternalLink(d + "/grid.h5", "/E_star_Pa")), ("soft", h5py.SoftLink("/data"))):
    with h5py.File(d + "/" + name + ".h5", "w") as f:
        f["data"] = np.full((3, 4), 6e3)
        f["E_star_Pa"] = link
        for k, v in (("x0_m", -3e-6), ("y0_m", -2e-6), ("dx_m", 2e-6), ("dy_m", 2e-6)):
            f.attrs[k] = v
# grid.h5's geometry with other values (a resume with it is another sample)
with h5py.File(d + "/grid_b.h5", "w") as f:
    f["E_star_Pa"] = 9e3 + 1e3 * x
    f["height_m"] = 1e-7 * (x + y) ** 2 / 25
    for k, v in (("x0_m", -3e-6), ("y0_m", -2e-6), ("dx_m", 2e-6), ("dy_m", 2e-6)):
        f.attrs[k] = v
EOF
    run map --preset cell-liquid --nx 5 --ny 4 --size 8e-6,6e-6 --sample "$TMP/grid.h5" --out "$TMP/grid_map.h5" -q
    if [ "$rc" -eq 0 ] && "$PY" - "$TMP/grid_map.h5" >"$TMP/gout" 2>&1 <<'EOF'
import sys, h5py, numpy as np
f = h5py.File(sys.argv[1], "r")
truth = np.concatenate([f.attrs[k] for k in sorted(a for a in f.attrs if a.startswith("vafm ground truth"))])
y, x = np.mgrid[0:3, 0:4]
E = 5e3 + 2e3 * x + 1e3 * y * x; H = 1e-7 * (x + y) ** 2 / 25
def bil(v, px, py):
    u = min(max((px + 3e-6) / 2e-6, 0), 3); w = min(max((py + 2e-6) / 2e-6, 0), 2)
    i = min(int(np.floor(u)), 2); j = min(int(np.floor(w)), 1); tu, tw = u - i, w - j
    lo = v[j, i] + (v[j, i + 1] - v[j, i]) * tu; hi = v[j + 1, i] + (v[j + 1, i + 1] - v[j + 1, i]) * tu
    return lo + (hi - lo) * tw
worst = 0
for row in truth:
    g = f[str(int(row["curve"]))]
    px, py = g.attrs["position x"], g.attrs["position y"]
    worst = max(worst, abs(row["E_star_Pa"] / bil(E, px, py) - 1), abs(row["surface_height_m"] - bil(H, px, py)) / 1e-7)
assert len(truth) == 20 and worst < 1e-12, worst
print(f"20 pixels, worst relative deviation {worst:.2g}")
EOF
    then ok "--sample grid: every pixel's E* and height are the grid's bilinear interpolation ($(cat "$TMP/gout"))"
    else bad "--sample grid" "exit $rc: $(head -c 400 "$TMP/err") $(head -c 400 "$TMP/gout")"; fi
    expect_fail "--sample: a NaN in the grid names the dataset and the point" 2 "E_star_Pa[1][1]" -- \
        map --preset cell-liquid --nx 2 --ny 2 --sample "$TMP/nan.h5" --out "$TMP/g1.h5"
    expect_fail "--sample: a missing origin names the attribute" 2 "x0_m" -- \
        map --preset cell-liquid --nx 2 --ny 2 --sample "$TMP/noattr.h5" --out "$TMP/g2.h5"
    expect_fail "--sample: datasets of different shapes are refused" 2 "height_m" "3 x 3" -- \
        map --preset cell-liquid --nx 2 --ny 2 --sample "$TMP/shape.h5" --out "$TMP/g3.h5"
    expect_fail "--sample: not a file" 2 "--sample" -- map --nx 2 --ny 2 --sample "$TMP/none.h5" --out "$TMP/g4.h5"
    expect_fail "--pattern grid without --sample says what it needs" 2 "grid" "measured map" -- \
        map --nx 2 --ny 2 --pattern grid --out "$TMP/g5.h5"
    # a FIFO blocks whoever opens it to read (0.6.2 hung here): a grid's data outside its file are never opened
    mkfifo "$TMP/fifo"
    for k in external:E_star_Pa:"stored in an external file" virtual:height_m:"a virtual dataset"; do
        IFS=: read -r kind dset why <<<"$k"
        timeout 20 "$VAFM" map --preset cell-liquid --nx 2 --ny 2 --threads 1 --sample "$TMP/$kind.h5" \
            --out "$TMP/g6.h5" >"$TMP/out" 2>"$TMP/err"
        rc=$?
        if [ "$rc" -eq 2 ] && grep -qF "'$dset' is $why" "$TMP/err" && [ ! -e "$TMP/g6.h5" ]; then
            ok "--sample: a dataset with $kind storage (a FIFO) is refused naming it, without opening it"
        else bad "--sample: a dataset with $kind storage" "exit $rc: $(head -c 300 "$TMP/err")"; fi
    done
    for k in extfifo:"an external link" extfile:"an external link" soft:"a soft link"; do
        IFS=: read -r kind why <<<"$k"
        timeout 20 "$VAFM" map --preset cell-liquid --nx 2 --ny 2 --threads 1 --sample "$TMP/$kind.h5" \
            --out "$TMP/g7.h5" >"$TMP/out" 2>"$TMP/err"
        rc=$?
        if [ "$rc" -eq 2 ] && grep -qF "'E_star_Pa' is $why" "$TMP/err" && [ ! -e "$TMP/g7.h5" ]; then
            ok "--sample: a dataset behind $why ($kind) is refused naming it, not followed"
        else bad "--sample: a dataset behind $why ($kind)" "exit $rc: $(head -c 300 "$TMP/err")"; fi
    done
    # a grid that the pixels do not overlap (grid x [-3, 3] um, y [-2, 2] um) is refused naming both extents
    expect_fail "--sample: a grid beside the map is refused naming both extents" 2 "do not overlap" \
        "x [9.6e-05, 0.000104] m" "x [-3e-06, 3e-06] m" -- map --preset cell-liquid --nx 2 --ny 2 --size 16e-6 \
        --pattern-param center_x_m=100e-6 --sample "$TMP/grid.h5" --out "$TMP/g8.h5"
    # a resume with the same file name and geometry but other values: refused (0.6.2 mixed the two samples)
    mkdir -p "$TMP/rs" && cp "$TMP/grid.h5" "$TMP/rs/s.h5"
    RS=(map --preset cell-liquid --nx 5 --ny 4 --size 8e-6,6e-6 --threads 1 --sample "$TMP/rs/s.h5" --out "$TMP/rs/m.h5" -q)
    run "${RS[@]}"
    cp "$TMP/grid_b.h5" "$TMP/rs/s.h5"
    expect_fail "--resume with another sample grid of the same geometry is refused naming it" 2 "sample grid" \
        "values_hash" -- "${RS[@]}" --resume
    cp "$TMP/grid.h5" "$TMP/rs/s.h5"
    run "${RS[@]}" --resume
    [ "$rc" -eq 0 ] && ok "--resume with the same sample grid goes on" || bad "--resume, same grid" "exit $rc: $(head -c 300 "$TMP/err")"
    # a grid of 12 stiffnesses, one per pixel: more materials than info's 8 regions, each one curve. A region
    # of one curve has no sem (0.6.2: "+- nan"); the pixels of the materials left out keep their pull-off in
    # the adhesion map (0.6.2: '?', "none") and are '?' in the material map, which says so.
    "$PY" - "$TMP" <<'EOF'
import sys, h5py, numpy as np
y, x = np.mgrid[0:3, 0:4]
with h5py.File(sys.argv[1] + "/many.h5", "w") as f:
    f["E_star_Pa"] = 1e10 * (1 + x + 4 * y)
    for k, v in (("x0_m", -3e-6), ("y0_m", -2e-6), ("dx_m", 2e-6), ("dy_m", 2e-6)):
        f.attrs[k] = v
EOF
    run map --preset contact-silica --nx 4 --ny 3 --size 8e-6,6e-6 --sample "$TMP/many.h5" --out "$TMP/many_map.h5" -q
    run info "$TMP/many_map.h5"
    if [ "$rc" -eq 0 ] && [ "$(grep -cE '^  [a-h]  E\* = .* pull-off [0-9.]+ nN \(n 1\)$' "$TMP/out")" -eq 8 ] &&
        ! grep -qi "nan" "$TMP/out" && grep -qF "(4 curve(s) of further materials left out)" "$TMP/out" &&
        grep -A3 "^material map (.*'?' a material left out" "$TMP/out" | grep -qxF "  ????" &&
        [ "$(grep -A3 "^adhesion map" "$TMP/out" | tail -3 | tr -d ' .:=+*#%@\n-' | wc -c)" -eq 0 ]; then
        ok "info of a map of 12 materials: 8 regions of one curve without '+- nan', every pixel in the adhesion map"
    else bad "info of a map of 12 materials" "exit $rc: $(sed -n '/^regions/,$p' "$TMP/out" | head -c 1500)"; fi
    if [ ! -e "$TMP/g1.h5" ] && [ ! -e "$TMP/g2.h5" ] && [ ! -e "$TMP/g3.h5" ] && [ ! -e "$TMP/g5.h5" ] &&
        [ ! -e "$TMP/g8.h5" ]; then
        ok "--sample: refused grids leave no file"
    else bad "--sample: refused grids leave no file"; fi
else
    bad "--sample grid" "h5py missing for $PY (Debian: python3-h5py; .ci/deps.sh installs it)"
fi

harness_done
