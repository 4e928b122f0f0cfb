#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
#
# The faults of issue #18, each reproduced in seconds: nothing lost, nothing crashes.
#   1. --overwrite of a file another process writes is refused and leaves it intact; a refused --resume
#      changes no byte; info/export/resume of a file in use say "in use", not "damaged".
#   3. a full disk (ulimit -f: EFBIG, the same path as ENOSPC) ends with exit 1 and the OS's reason, no
#      crash; the file holds every flushed curve and resumes.
#   4. a FIFO named *.h5 (or given as a scene file) is refused at once, never opened.
#   5. a curve, tune or campaign that would take gigabytes is refused before it starts, naming the field.
#   6. a small file that declares more samples than a curve may have is refused before its data are read.
#   7. curves are addressed by group name: a gapped file exports group 2 as --curve 2, and --curve 1 is
#      refused naming the groups.
#   9. the study's plotter never goes through a shell: a directory named x'$(touch pwned)' runs nothing,
#      one named O'Brien gets its figure.
#   and the smaller ones: vafm listen keeps an existing CSV without --overwrite; vafm info names at most 20
#   unreadable curves; vafmd binds tcp://localhost and names the endpoint it cannot bind.
# Usage: test_faults.sh path/to/vafm path/to/vafmd. Prints one line per check and "N passed, M failed".
set -u

VAFM=${1:?usage: test_faults.sh path/to/vafm path/to/vafmd}
VAFMD=${2:?usage: test_faults.sh path/to/vafm path/to/vafmd}
PY=/usr/bin/python3
. "$(dirname "$0")/harness.sh"

WRITER=
harness_cleanup() { [ -n "$WRITER" ] && kill -9 "$WRITER" 2>/dev/null; wait 2>/dev/null; }

# expect DESC STATUS NEEDLE -- ARGS...: vafm ARGS exits STATUS and stderr holds NEEDLE (within 60 s)
expect() {
    local desc=$1 want=$2 needle=$3
    shift 4
    timeout 60 "$VAFM" "$@" >"$TMP/out" 2>"$TMP/err"
    rc=$?
    if [ "$rc" -ne "$want" ]; then
        bad "$desc" "exit $rc, want $want: $(head -c 300 "$TMP/err")"
    elif ! grep -qF -- "$needle" "$TMP/err"; then
        bad "$desc" "message lacks '$needle': $(head -c 300 "$TMP/err")"
    else
        ok "$desc"
    fi
}
cd "$TMP" || exit 1
FAST=(--preset paper-fig4 --v 6.4e-4 --threads 1 -q)

# ---- 1: a file another process writes ------------------------------------------------------------
# A long campaign (thousands of curves, flushed every 0.2 s) is the other writer; it is killed at the end.
# The scalar kernel: its curves come one by one (the batch kernel's first burst of ~16 would take several seconds).
"$VAFM" campaign -n 100000 --preset paper-fig4 --threads 1 --flush-interval 0.2 --kernel scalar --out busy.h5 -q \
    >/dev/null 2>"$TMP/writer.err" &
WRITER=$!
for _ in $(seq 1 300); do
    [ -s busy.h5 ] && grep -q "in use" <("$VAFM" info busy.h5 2>&1) && break
    sleep 0.1
done
sleep 1 # some flushes
size_before=$(stat -c %s busy.h5)
expect "--overwrite of a file another process writes is refused, naming it" 1 "in use by another process" -- \
    campaign -n 2 "${FAST[@]}" --out busy.h5 --overwrite
size_after=$(stat -c %s busy.h5)
if [ "$size_after" -ge "$size_before" ]; then ok "the file was not truncated ($size_before -> $size_after bytes)"
else bad "the file was not truncated" "$size_before -> $size_after bytes"; fi
expect "vafm info of a file being written says 'in use', not 'damaged'" 1 "open for writing" -- info busy.h5
expect "vafm export of a file being written says 'in use'" 1 "in use by another process" -- export busy.h5 --curve 0
expect "--resume of a file being written is refused" 1 "in use by another process" -- \
    campaign -n 100000 --preset paper-fig4 --threads 1 --out busy.h5 --resume -q
kill -9 "$WRITER" 2>/dev/null
wait "$WRITER" 2>/dev/null
WRITER=
run info busy.h5
n_busy=$(sed -n 's/.* \([0-9]*\) curve(s)$/\1/p' "$TMP/out" | head -1)
if [ "$rc" -eq 0 ] && [ "${n_busy:-0}" -ge 1 ]; then ok "the other writer's file survived ($n_busy flushed curves, kill -9 after)"
else bad "the other writer's file survived" "info exit $rc: $(head -c 300 "$TMP/err")"; fi

# a refused --resume (another grid) changes no byte
run campaign -n 3 "${FAST[@]}" --out grid.h5
cp grid.h5 grid0.h5
expect "--resume with another grid is refused, naming the field" 2 "curves_per_point" -- \
    campaign -n 4 "${FAST[@]}" --out grid.h5 --resume
expect "--resume with another scene is refused, naming the field" 2 "T_K" -- \
    campaign -n 3 "${FAST[@]}" --T 7 --out grid.h5 --resume
if cmp -s grid0.h5 grid.h5; then ok "a refused --resume changes no byte of the file"
else bad "a refused --resume changes no byte of the file" "$(cmp grid0.h5 grid.h5 | head -1)"; fi

# ---- 3: a full disk ------------------------------------------------------------------------------
# ulimit -f makes write() fail with EFBIG, as ENOSPC does on a full file system: vafm ignores SIGXFSZ itself
# (0.6.1 was killed by it: exit 153 and no message).
# paper-fig4 at its own speed: ~0.5 MB per curve, so the third curve does not fit in 1.5 MB. The scalar
# kernel delivers the curves one by one, each flushed before the next comes; the batch kernel delivers
# these 10 in one burst, and the flusher may not have made any durable when the disk fills (docs/files.md).
FULL=(--preset paper-fig4 --threads 1 -q --flush-interval 0 --kernel scalar)
(ulimit -f 1500; exec "$VAFM" campaign -n 10 "${FULL[@]}" --out full.h5) \
    >"$TMP/out" 2>"$TMP/err"
rc=$?
if [ "$rc" -eq 1 ] && grep -q "File too large" "$TMP/err"; then ok "a full disk: exit 1 with the OS's reason"
else bad "a full disk: exit 1 with the OS's reason" "exit $rc: $(head -c 300 "$TMP/err")"; fi
run info full.h5
n_full=$(sed -n 's/.* \([0-9]*\) curve(s)$/\1/p' "$TMP/out" | head -1)
if [ "$rc" -eq 0 ] && [ "${n_full:-0}" -ge 1 ]; then ok "the full disk's file holds its $n_full flushed curves"
else bad "the full disk's file holds its flushed curves" "info exit $rc: $(head -c 300 "$TMP/err")"; fi
run campaign -n 10 "${FULL[@]}" --out full.h5 --resume
run2=$rc
run info full.h5
if [ "$run2" -eq 0 ] && grep -q " 10 curve(s)" "$TMP/out"; then ok "with room again, --resume completes it (10 curves)"
else bad "with room again, --resume completes it" "exit $run2: $(head -c 300 "$TMP/err")"; fi

# ---- 4: FIFOs ------------------------------------------------------------------------------------
mkfifo fifo.h5 fifo.json
expect "vafm info of a FIFO is refused at once" 1 "not a regular file" -- info fifo.h5
expect "vafm export of a FIFO is refused at once" 1 "not a regular file" -- export fifo.h5 --curve 0
expect "--resume of a FIFO is refused at once" 1 "not a regular file" -- campaign -n 1 "${FAST[@]}" --out fifo.h5 --resume
expect "--overwrite of a FIFO is refused at once" 1 "not a regular file" -- campaign -n 1 "${FAST[@]}" --out fifo.h5 --overwrite
expect "a FIFO as scene file is refused at once" 2 "not a regular file" -- run --scene fifo.json

# ---- 5: curves and campaigns that would take gigabytes are refused before they start ----------------
expect "sample_rate_Hz 1e10 is refused before the curve runs" 2 "VAFM_SIM_MAX_SAMPLES" -- \
    campaign -n 1 --preset paper-fig4 --sample_rate_Hz=1e10 --out big.h5
expect "a 1e-12 m/s retract is refused, naming v_retract_m_per_s" 2 "v_retract_m_per_s" -- \
    run --preset paper-fig4 --v_retract_m_per_s=1e-12
expect "a 1e4 s dwell is refused, naming dwell_s" 2 "dwell_s" -- samples --preset paper-fig4 --dwell_s=1e4
expect "a thermal tune of 1e6 s is refused, naming tune_duration_s" 2 "tune_duration_s" -- \
    samples --tune --preset paper-fig4 --tune_duration_s=1e6
expect "-n 1e9 over three points: the file size is estimated and refused" 2 "more than the" -- \
    campaign -n 1000000000 --preset paper-fig4 --T 1,2,3 --out huge.h5
if [ ! -e big.h5 ] && [ ! -e huge.h5 ]; then ok "refused campaigns leave no file"; else bad "refused campaigns leave no file"; fi

# 0.6.2: a grid of 1e9 points is refused before its statistics are allocated; a grid too long for the file's
# 'vafm grid' attribute is refused before the file is created or overwritten (0.6.1 truncated it first);
# short curves count their metadata in the disk check (0.6.1: 4e-10 GB estimated for 3.8 MB)
L1000=$(printf '300,%.0s' $(seq 1000)); L1000=${L1000%,}
expect "a grid of 1000 x 1000 x 1000 points is refused, naming the limit" 2 "at most 65536" -- \
    curves -n 1 --threads 1 -q --preset cell-liquid --T "$L1000" --v "$L1000" --k "$L1000"
run campaign -n 2 "${FAST[@]}" --out keepgrid.h5
cp keepgrid.h5 keepgrid0.h5
L20000=$(printf '300,%.0s' $(seq 20000)); L20000=${L20000%,}
expect "a grid too long for the file is refused, naming T_K" 2 "T_K has the most" -- \
    campaign -n 1 "${FAST[@]}" --T "$L20000" --out keepgrid.h5 --overwrite
if cmp -s keepgrid0.h5 keepgrid.h5; then ok "... and the file it would have overwritten is unchanged"
else bad "... and the file it would have overwritten is unchanged" "$(ls -l keepgrid.h5)"; fi
expect "-n 1e9 curves of 2 samples are refused by the disk check" 2 "more than the" -- \
    campaign -n 1000000000 --v 300 --preset cell-liquid --threads 1 --out tiny.h5
if [ ! -e tiny.h5 ]; then ok "... and leave no file"; else bad "... and leave no file"; fi

# ---- 6: a decompression bomb -------------------------------------------------------------------
if "$PY" -c 'import h5py, numpy' 2>/dev/null; then
    "$PY" - <<'EOF'
import h5py, numpy as np
n = (1 << 25) + 1  # one more than VAFM_H5_MAX_SAMPLES: 268 MB of zeros, a few hundred kB deflated
with h5py.File("bomb.h5", "w") as f:
    f.attrs["software"] = "test"
    f.attrs["software version"] = "0"
    g = f.create_group("0")
    for name, unit, dt in (("force", "N", "<f8"), ("height (piezo)", "m", "<f8"), ("segment", "", "u1")):
        ds = g.create_dataset(name, shape=(n,), dtype=dt, chunks=(1 << 20,), compression="gzip")
        for i in range(0, n, 1 << 22):
            ds[i:i + (1 << 22)] = 0
        ds.attrs["unit"] = unit
    g.attrs["imaging mode"] = "force-distance"
EOF
    bytes=$(stat -c %s bomb.h5)
    expect "a ${bytes}-byte file declaring 2^25+1 samples is refused before reading (info)" 1 "declares 33554433 samples" -- \
        info bomb.h5
    expect "... and by export" 1 "declares 33554433 samples" -- export bomb.h5 --curve 0
else
    bad "decompression bomb" "h5py missing for $PY (Debian: python3-h5py; .ci/deps.sh installs it)"
fi

# ---- 7: group names ----------------------------------------------------------------------------
run campaign -n 3 "${FAST[@]}" --out gap.h5
if "$PY" -c 'import h5py' 2>/dev/null; then
    cp gap.h5 full3.h5
    "$PY" -c 'import h5py; f = h5py.File("gap.h5", "a"); del f["1"]; f.close()'
    expect "export --curve 1 of a file with groups 0 and 2 is refused, naming the groups" 2 "no curve group '1'" -- \
        export gap.h5 --curve 1
    run export gap.h5 --curve 2 --csv gap2.csv
    r1=$rc
    run export full3.h5 --curve 2 --csv full2.csv
    if [ "$r1" -eq 0 ] && cmp -s gap2.csv full2.csv; then ok "export --curve 2 of the gapped file is group 2"
    else bad "export --curve 2 of the gapped file is group 2" "exit $r1"; fi
else
    bad "gapped file" "h5py missing for $PY (Debian: python3-h5py; .ci/deps.sh installs it)"
fi

# ---- 0.6.2: a file's grid lists and map shape size nothing without bound ---------------------------
if "$PY" -c 'import h5py, numpy' 2>/dev/null; then
    cp full3.h5 biggrid.h5
    cp full3.h5 bigshape.h5
    "$PY" - <<'EOF'
import h5py, json, numpy as np
n = 3000  # 3000^3 points from a 0.5 MB attribute: 0.6.1's info allocated them (ASan: allocation too large)
with h5py.File("biggrid.h5", "r+") as f:
    f.attrs["vafm grid"] = json.dumps({"T_K": [300 + i * 1e-3 for i in range(n)],
                                       "v_m_per_s": [1e-6 + i * 1e-12 for i in range(n)],
                                       "k_N_per_m": [0.03 + i * 1e-6 for i in range(n)], "curves_per_point": 3})
with h5py.File("bigshape.h5", "r+") as f:  # 2^32 + 1 pixels wide: 0.6.1 printed it as a 1 x 1 map
    for g in f.values():
        g.attrs["grid shape x"], g.attrs["grid shape y"] = np.int64(2**32 + 1), np.int64(1)
        g.attrs["grid index x"], g.attrs["grid index y"] = np.int64(0), np.int64(0)
EOF
    run info biggrid.h5
    if [ "$rc" -eq 0 ] && grep -q "not summed up: the grid has 2.7e+10 points" "$TMP/out"; then
        ok "info of a file whose grid lists make 2.7e10 points does not sum them up"
    else bad "info of a file whose grid lists make 2.7e10 points does not sum them up" "exit $rc: $(head -c 300 "$TMP/err")"; fi
    run info bigshape.h5
    if [ "$rc" -eq 0 ] && ! grep -q "^map " "$TMP/out"; then ok "info prints no map for a grid shape of 2^32 + 1"
    else bad "info prints no map for a grid shape of 2^32 + 1" "exit $rc: $(grep "^map" "$TMP/out")"; fi
    cp full3.h5 unitarr.h5
    "$PY" -c '
import h5py, numpy as np
with h5py.File("unitarr.h5", "r+") as f:
    d = f["0"]["force"]; del d.attrs["unit"]
    d.attrs.create("unit", np.array(["N", "N"], dtype=h5py.string_dtype()))'
    expect "a unit attribute of two strings is named as such (0.6.1: \"is ''\")" 1 "holds 2 values" -- \
        export unitarr.h5 --curve 0
else
    bad "hostile grids" "h5py or numpy missing for $PY (Debian: python3-h5py python3-numpy; .ci/deps.sh installs them)"
fi

# ---- 9: the study's plotter and the shell ----------------------------------------------------------
mkdir -p plots
(cd plots && "$VAFM" study hysteresis --quick --out "x'\$(touch pwned)'" >/dev/null 2>&1)
if [ ! -e plots/pwned ] && [ -f "plots/x'\$(touch pwned)'/report.md" ]; then ok "an output directory x'\$(touch pwned)' runs nothing"
else bad "an output directory x'\$(touch pwned)' runs nothing" "$(ls plots)"; fi
(cd plots && "$VAFM" study hysteresis --quick --out "O'Brien" >/dev/null 2>&1)
if "$PY" -c 'import matplotlib' 2>/dev/null; then
    if [ -f "plots/O'Brien/hysteresis.png" ]; then ok "a directory named O'Brien gets its figure"
    else bad "a directory named O'Brien gets its figure" "$(ls "plots/O'Brien" 2>&1)"; fi
else
    bad "O'Brien figure" "matplotlib missing for $PY (Debian: python3-matplotlib; .ci/deps.sh installs it)"
fi

# ---- smaller ones --------------------------------------------------------------------------------
echo "keep me" >keep.csv
expect "vafm listen keeps an existing CSV without --overwrite" 2 "--overwrite replaces it" -- \
    listen --out keep.csv --endpoint ipc://"$TMP"/nobody --timeout 200
if [ "$(cat keep.csv)" = "keep me" ]; then ok "... and the CSV is unchanged"; else bad "... and the CSV is unchanged"; fi
if "$PY" -c 'import h5py' 2>/dev/null; then
    "$PY" -c '
import h5py
with h5py.File("empty.h5", "w") as f:
    f.attrs["software"] = "test"; f.attrs["software version"] = "0"
    for i in range(3000):
        f.create_group(str(i))'
    run info empty.h5
    lines=$(grep -c "" "$TMP/err")
    if [ "$rc" -ne 0 ] && [ "$lines" -le 25 ] && grep -q "2980 more curve(s)" "$TMP/err"; then
        ok "vafm info of 3000 empty groups names 20 and sums up the rest ($lines lines)"
    else bad "vafm info of 3000 empty groups names 20 and sums up the rest" "exit $rc, $lines lines"; fi
    # a root 'software' of 100 kB with an escape sequence: one line of at most ~150 bytes, no ESC byte
    # (0.6.2 printed it all, escape included)
    "$PY" -c '
import h5py
with h5py.File("software.h5", "w") as f:
    f.attrs["software"] = "x" * 100000 + "\x1b[31m"; f.attrs["software version"] = "0\n1\u009b2"
    f.create_group("0")'
    run info software.h5
    line=$(grep "^software " "$TMP/out")
    if [ "${#line}" -le 160 ] && grep -qF "... (100005 bytes) 0?1?2" "$TMP/out" && ! grep -q $'\x1b' "$TMP/out"; then
        ok "vafm info clips a 100 kB 'software' to one line of ${#line} bytes, control bytes as '?'"
    else bad "vafm info clips a huge 'software'" "exit $rc, line of ${#line} bytes"; fi
fi
port=$("$PY" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1]); s.close()')
"$VAFMD" --preset paper-fig4 --rep "tcp://localhost:$port" --pub "tcp://localhost:$((port + 1))" 2>"$TMP/d1.err" &
DAEMON=$!
for _ in $(seq 1 100); do "$VAFM" ctl --endpoint "tcp://localhost:$port" --timeout 200 hello >/dev/null 2>&1 && break; sleep 0.1; done
run ctl --endpoint "tcp://localhost:$port" hello
if [ "$rc" -eq 0 ] && grep -q '"protocol_version"' "$TMP/out"; then ok "vafmd binds tcp://localhost (as 127.0.0.1) and answers there"
else bad "vafmd binds tcp://localhost (as 127.0.0.1) and answers there" "exit $rc: $(cat "$TMP/d1.err")"; fi
"$VAFMD" --preset paper-fig4 --rep "tcp://127.0.0.1:$port" --pub "tcp://127.0.0.1:$((port + 2))" 2>"$TMP/d2.err"
if [ $? -eq 1 ] && grep -q "cannot bind tcp://127.0.0.1:$port" "$TMP/d2.err"; then ok "a second vafmd names the endpoint it cannot bind"
else bad "a second vafmd names the endpoint it cannot bind" "$(cat "$TMP/d2.err")"; fi
"$VAFM" ctl --endpoint "tcp://localhost:$port" shutdown >/dev/null 2>&1
wait "$DAEMON"

# vafm listen given only an ipc:// command endpoint follows the stream endpoint the daemon names in hello
"$VAFMD" --preset paper-fig4 --free-run --rep "ipc://$TMP/rep" --pub "ipc://$TMP/stream" 2>/dev/null &
DAEMON=$!
for _ in $(seq 1 100); do "$VAFM" ctl --endpoint "ipc://$TMP/rep" --timeout 200 hello >/dev/null 2>&1 && break; sleep 0.1; done
run listen --endpoint "ipc://$TMP/rep" --start curve --index 1 --out "$TMP/derived.csv" --timeout 20000
if [ "$rc" -eq 0 ] && [ "$(grep -c "" "$TMP/derived.csv")" -gt 1000 ]; then ok "vafm listen follows hello's stream endpoint (ipc://, no --pub)"
else bad "vafm listen follows hello's stream endpoint" "exit $rc: $(head -c 300 "$TMP/err")"; fi
"$VAFM" ctl --endpoint "ipc://$TMP/rep" shutdown >/dev/null 2>&1
wait "$DAEMON"

harness_done
