#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
#
# An intact file that cannot be written is named "read-only" / "permission denied", never "damaged"
# (issue #29 item 3): vafm campaign --out/--resume/--overwrite and vafmd's log and log resume, on a
# tmpfs remounted read-only (which stops root too) and, for "permission denied", a mode-444 file written
# by an unprivileged user. The free-space check does not call a read-only file system "0 GB free".
# The script re-executes itself in a private mount namespace (unshare -m, or unshare -rm as non-root), so
# its mounts vanish with it. Usage: test_readonly.sh path/to/vafm path/to/vafmd.
set -u

VAFM=${1:?usage: test_readonly.sh path/to/vafm path/to/vafmd}
VAFMD=${2:?usage: test_readonly.sh path/to/vafm path/to/vafmd}
VAFM=$(realpath "$VAFM") VAFMD=$(realpath "$VAFMD")
if [ -z "${VAFM_RO_NS:-}" ]; then
    export VAFM_RO_NS=1
    for ns in -m -rm; do
        unshare $ns --propagation private true 2>/dev/null && exec unshare $ns --propagation private bash "$0" "$VAFM" "$VAFMD"
    done
    echo "FAIL - a private mount namespace (unshare -m) is needed to remount a tmpfs read-only"
    exit 1
fi
. "$(dirname "$0")/harness.sh"

DAEMON=
harness_cleanup() {
    [ -n "$DAEMON" ] && kill -9 "$DAEMON" 2>/dev/null
    wait 2>/dev/null
    umount "$TMP/ro" 2>/dev/null
    umount "$TMP/rw" 2>/dev/null
}
cd "$TMP" || exit 1
FAST=(--preset paper-fig4 --v 6.4e-4 --threads 1 -q)

# expect_ro DESC STATUS NEEDLE -- ARGS: exit STATUS, NEEDLE in stderr, and neither "damaged" nor "0 GB free"
expect_ro() {
    local desc=$1 want=$2 needle=$3
    shift 4
    run "$@"
    if [ "$rc" -ne "$want" ]; then
        bad "$desc" "exit $rc, want $want: $(head -c 300 "$TMP/err")"
    elif ! grep -qF -- "$needle" "$TMP/err"; then
        bad "$desc" "message lacks '$needle': $(head -c 300 "$TMP/err")"
    elif grep -qiE "damaged|0 GB free" "$TMP/err"; then
        bad "$desc" "calls it damaged or full: $(head -c 300 "$TMP/err")"
    else
        ok "$desc"
    fi
}

mkdir ro rw
if ! mount -t tmpfs -o size=64m tmpfs ro; then
    bad "mount a tmpfs" "mount failed"
    harness_done
    exit 1
fi
"$VAFM" campaign -n 2 "${FAST[@]}" --out ro/good.h5 >/dev/null 2>&1 || bad "write the file to protect" "campaign failed"
"$VAFMD" --preset paper-fig4 --rep "ipc://$TMP/rep" --pub "ipc://$TMP/stream" 2>"$TMP/d.err" &
DAEMON=$!
ctl() { "$VAFM" ctl --endpoint "ipc://$TMP/rep" "$@" >"$TMP/out" 2>"$TMP/err"; }
for _ in $(seq 1 100); do ctl --timeout 200 hello && break; sleep 0.1; done
ctl log path="$TMP/ro/log.h5" && ctl curve index=0 || bad "a daemon log" "$(cat "$TMP/err")"
for _ in $(seq 1 300); do ctl log stop=true && break; sleep 0.1; done # refused while the run is in progress
grep -q '"curves": 1' "$TMP/out" || bad "a daemon log of one curve" "$(head -c 300 "$TMP/out")"
sum_before=$(sha256sum ro/good.h5 ro/log.h5)
if ! mount -o remount,ro ro || touch ro/probe 2>/dev/null; then
    bad "remount the tmpfs read-only" "it is still writable"
    harness_done
    exit 1
fi

expect_ro "--resume of an intact file on a read-only file system says read-only" 1 "read-only" -- \
    campaign -n 2 "${FAST[@]}" --out ro/good.h5 --resume
expect_ro "--out on a read-only file system says read-only (not 0 GB free)" 1 "read-only" -- \
    campaign -n 2 "${FAST[@]}" --out ro/new.h5
expect_ro "--overwrite on a read-only file system says read-only" 1 "read-only" -- \
    campaign -n 2 "${FAST[@]}" --out ro/good.h5 --overwrite
run info ro/good.h5
if [ "$rc" -eq 0 ] && grep -q "conformance  ok" "$TMP/out"; then ok "the read-only file still reads: conformance ok"
else bad "info of the read-only file" "exit $rc: $(head -c 300 "$TMP/err")"; fi

# vafmd: log and log resume into the read-only file system
ctl_ro() {
    local desc=$1
    shift
    "$VAFM" ctl --endpoint "ipc://$TMP/rep" log "$@" >"$TMP/out" 2>"$TMP/err"
    if grep -q 'io_error' "$TMP/out" "$TMP/err" && grep -qF "read-only" "$TMP/out" "$TMP/err" &&
        ! grep -qi "damaged" "$TMP/out" "$TMP/err"; then
        ok "$desc"
    else
        bad "$desc" "$(head -c 400 "$TMP/out" "$TMP/err")"
    fi
}
ctl_ro "vafmd log resume of an intact read-only file says read-only" path="$TMP/ro/log.h5" resume=true
ctl_ro "vafmd log to a new file on a read-only file system says read-only" path="$TMP/ro/new.h5"
"$VAFM" ctl --endpoint "ipc://$TMP/rep" shutdown >/dev/null 2>&1
wait "$DAEMON"
DAEMON=
[ "$(sha256sum ro/good.h5 ro/log.h5)" = "$sum_before" ] && ok "the read-only files are unchanged" || bad "a read-only file changed"

# "permission denied": a mode-444 file and a mode-555 directory, for a user other than root (root passes modes)
if [ "$(id -u)" -eq 0 ] && mount -t tmpfs -o size=64m,mode=0777 tmpfs rw; then
    chmod 711 "$TMP"
    cp ro/good.h5 rw/mine.h5
    chmod 444 rw/mine.h5
    mkdir -m 555 rw/locked
    AS=(setpriv --reuid=65534 --regid=65534 --clear-groups)
    run() { "${AS[@]}" "$VAFM" "$@" >"$TMP/out" 2>"$TMP/err"; rc=$?; } # as nobody
    expect_ro "--resume of a mode-444 file says permission denied" 1 "permission denied" -- \
        campaign -n 2 "${FAST[@]}" --out "$TMP/rw/mine.h5" --resume
    expect_ro "--out into a mode-555 directory says permission denied" 1 "permission denied" -- \
        campaign -n 2 "${FAST[@]}" --out "$TMP/rw/locked/new.h5"
fi

harness_done
