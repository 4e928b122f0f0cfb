#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
#
# Scaling of `vafm campaign` from one process to MPI ranks on this machine: curves/s of the same
# campaign run plainly (1 and all threads), under mpirun -np 1 (1 and all threads) and -np 2 (the
# default: each rank takes its share of the node's cores, here 1 thread each). The runs are
# interleaved (one of each per round), so a machine shared with other jobs slows them alike; the table
# gives medians over the rounds. curves/s is the summary's (from after MPI start-up to the file's
# close); CPU is user + sys of every process (mpirun and the ranks included), start-up included.
# Reports, never fails on speed. Writes bench_mpi.md to OUTDIR.
# Usage: bench_mpi.sh path/to/vafm [mpirun] [OUTDIR] [ROUNDS] [N: curves per point, default 40]
set -u
VAFM=${1:?usage: bench_mpi.sh path/to/vafm [mpirun] [OUTDIR] [ROUNDS] [N]}
MPIRUN=${2:-mpirun}
OUTDIR=${3:-.}
REP=${4:-3}
N=${5:-40}
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# OpenMPI's defaults (shared-memory single copy through CMA where the kernel allows it); in a container
# that forbids it, run with OMPI_MCA_btl_vader_single_copy_mechanism=none (the test suite does).
# Uneven costs: v = 1e-5 m/s curves take ~3x those at 3e-5 m/s.
ARGS=(--preset paper-fig4 --v 1e-5,3e-5 -n "$N" -q)
CORES=$(nproc)
MPI=("$MPIRUN" --oversubscribe --bind-to none)
NAMES=("plain, --threads 1" "plain, all $CORES threads" "mpirun -np 1 --threads 1" "mpirun -np 1 (all threads)"
       "mpirun -np 2 (cores/2 threads each)")

run_config() {
    case $1 in
        0) "$VAFM" campaign "${ARGS[@]}" --threads 1 -o "$TMP/b.h5" ;;
        1) "$VAFM" campaign "${ARGS[@]}" -o "$TMP/b.h5" ;;
        2) "${MPI[@]}" -np 1 "$VAFM" campaign "${ARGS[@]}" --threads 1 -o "$TMP/b.h5" ;;
        3) "${MPI[@]}" -np 1 "$VAFM" campaign "${ARGS[@]}" -o "$TMP/b.h5" ;;
        4) "${MPI[@]}" -np 2 "$VAFM" campaign "${ARGS[@]}" -o "$TMP/b.h5" ;;
    esac
}

median() { sort -g | sed -n "$(((REP + 1) / 2))p"; }

load0=$(cut -d' ' -f1-3 /proc/loadavg)
TIMEFORMAT='%U %S'
for round in $(seq 1 "$REP"); do
    for c in 0 1 2 3 4; do
        rm -f "$TMP/b.h5"
        { time run_config $c >"$TMP/b.out" 2>/dev/null; } 2>"$TMP/b.time"
        sed -n 's/^campaign .*(\([0-9.e+]*\) curves\/s).*/\1/p' "$TMP/b.out" >>"$TMP/rate.$c"
        awk -v n="$N" '{ printf "%.1f\n", ($1 + $2) * 1000 / (2 * n) }' "$TMP/b.time" >>"$TMP/cpu.$c"
    done
done
{
    echo "# vafm campaign: 1 process vs MPI ranks ($CORES cores, $(date -u +%Y-%m-%dT%H:%MZ))"
    echo
    echo "Campaign: \`vafm campaign ${ARGS[*]}\` ($((2 * N)) curves); medians of $REP interleaved rounds."
    echo "Load average before: $load0, after: $(cut -d' ' -f1-3 /proc/loadavg) (the machine may be shared)."
    echo
    echo "| run | curves/s | CPU ms per curve |"
    echo "|---|---|---|"
    for c in 0 1 2 3 4; do
        echo "| ${NAMES[$c]} | $(median <"$TMP/rate.$c") | $(median <"$TMP/cpu.$c") |"
    done
} | tee "$OUTDIR/bench_mpi.md"
