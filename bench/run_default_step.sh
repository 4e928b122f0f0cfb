#!/bin/bash
# SPDX-License-Identifier: MIT
# The default step chosen by evidence (issue #13): bench_work_precision's groups "presets" and "athermal",
# one case per process (a case's result survives a later one's failure), one thread, niced; then the fit.
#   bench/run_default_step.sh build/bench/bench_work_precision OUTDIR [N [CASES]]
# N caps every case's curves per row (the case table in bench_work_precision.c sets them: 2000, fewer where a
# curve is costly); CASES lists case numbers (default: all 13). Writes OUTDIR/case<i>/default_step.{csv,md},
# OUTDIR/default_step.csv (every case), OUTDIR/athermal/default_step_athermal.{csv,md} (T = 0, one curve per
# row) and OUTDIR/default_step_fit.md (bench/default_step_fit.py). 2026-11-26: ≈ 41 min of one core (0.6.0,
# paper-fig1 without its dt0/4 rows), ≈ 24 min (0.6.1, with them: `meson test -C build --benchmark default-step`).
set -eu
bench=$1 out=$2 n=${3:-2000} cases=${4:-"0 1 2 3 4 5 6 7 8 9 10 11 12"}
mkdir -p "$out"
for c in $cases; do
    mkdir -p "$out/case$c"
    echo "case $c: $(date -u +%H:%M:%S)" >&2
    nice -n 10 "$bench" "$out/case$c" "$n" 0 "presets,case$c," 1 >/dev/null 2>"$out/case$c/progress.log"
done
first=1
for c in $cases; do
    f="$out/case$c/default_step.csv"
    [ -f "$f" ] || continue
    if [ $first = 1 ]; then cat "$f"; first=0; else tail -n +2 "$f"; fi
done >"$out/default_step.csv"
mkdir -p "$out/athermal"
echo "athermal: $(date -u +%H:%M:%S)" >&2
nice -n 10 "$bench" "$out/athermal" 1 0 "athermal,$(printf 'case%s,' $cases)" 1 >/dev/null 2>"$out/athermal/progress.log"
/usr/bin/python3 "$(dirname "$0")/default_step_fit.py" "$out/default_step.csv" \
    "$out/athermal/default_step_athermal.csv" >"$out/default_step_fit.md"
