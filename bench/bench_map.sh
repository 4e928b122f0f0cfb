#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
#
# bench_map: what `vafm map` delivers for a 32 x 32 map (1024 curves) into one HDF5 file, on 1 and 2 threads:
# curves/s, MB written and the writer's share of the wall time, parsed from its summary; the median of 3
# repetitions. Two scenes: cell-liquid (Hertz, a 30 kPa dome on a 6.7 kPa substrate, ~2 ms a curve) and
# contact-silica (JKR stripes, ~15 ms a curve). It reports; it never fails on speed.
# Usage: bench_map.sh path/to/vafm OUTDIR   writes OUTDIR/bench_map.csv and .md (also printed).
set -u
VAFM=${1:?usage: bench_map.sh path/to/vafm OUTDIR}
OUT=${2:?usage: bench_map.sh path/to/vafm OUTDIR}
H5="$OUT/bench_map.h5"
CSV="$OUT/bench_map.csv"
MD="$OUT/bench_map.md"
echo "scene,pattern,threads,curves,wall_s,curves_per_s,mb,writer_pct" >"$CSV"
median() { sort -g | awk '{ v[NR] = $1 } END { print v[int((NR + 1) / 2)] }'; }
run_case() { # scene pattern params threads
    local rates=() walls=() mbs=() wp=() i line
    for i in 1 2 3; do
        line=$("$VAFM" map --preset "$1" --nx 32 --ny 32 --pattern "$2" --pattern-param "$3" --threads "$4" \
            --out "$H5" --overwrite -q 2>/dev/null) || { echo "vafm map failed: $1 $2" >&2; return; }
        rates+=("$(sed -n 's/^force map .* run in \([0-9.e+-]*\) s (\([0-9.e+-]*\) curves\/s)$/\2/p' <<<"$line")")
        walls+=("$(sed -n 's/^force map .* run in \([0-9.e+-]*\) s .*/\1/p' <<<"$line")")
        mbs+=("$(sed -n 's/^file .* \([0-9.e+-]*\) MB written.*/\1/p' <<<"$line")")
        wp+=("$(sed -n 's/^writer .* = \([0-9.]*\)% of the wall time.*/\1/p' <<<"$line")")
    done
    printf '%s,%s,%s,1024,%s,%s,%s,%s\n' "$1" "$2" "$4" "$(printf '%s\n' "${walls[@]}" | median)" \
        "$(printf '%s\n' "${rates[@]}" | median)" "$(printf '%s\n' "${mbs[@]}" | median)" \
        "$(printf '%s\n' "${wp[@]}" | median)" >>"$CSV"
}
for t in 1 2; do
    run_case cell-liquid dome "b_E_star_Pa=30e3,height_m=300e-9" $t
    run_case contact-silica stripes "b_E_star_Pa=5e9,b_gamma_J_per_m2=0.02" $t
done
rm -f "$H5"
{
    echo "# vafm map: a 32 x 32 force map (1024 curves) into one HDF5 file, median of 3"
    echo
    echo "| scene | pattern | threads | wall, s | curves/s | MB written | writer, % of wall |"
    echo "|---|---|---|---|---|---|---|"
    tail -n +2 "$CSV" | awk -F, '{ printf "| %s | %s | %s | %s | %s | %s | %s |\n", $1, $2, $3, $5, $6, $7, $8 }'
} >"$MD"
cat "$MD"
