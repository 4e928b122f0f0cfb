# SPDX-License-Identifier: MIT
# Sourced by the shell tests: a private $TMP (removed at exit, after the test's own harness_cleanup if it
# defines one), the check counters with ok/bad, and harness_done, which prints "N passed, M failed" and
# returns non-zero when a check failed; run and expect_fail call "$VAFM" (set by the test before sourcing).
TMP=$(mktemp -d)
harness_cleanup() { :; }
trap 'harness_cleanup; rm -rf "$TMP"' EXIT
pass=0
fail=0
ok() { echo "ok   - $1"; pass=$((pass + 1)); }
bad() { echo "FAIL - $1${2:+ ($2)}"; fail=$((fail + 1)); }
# run ARGS...: "$VAFM" ARGS with stdout in $TMP/out, stderr in $TMP/err, the exit status in $rc.
run() { "$VAFM" "$@" >"$TMP/out" 2>"$TMP/err"; rc=$?; }
# expect_fail DESC STATUS NEEDLE... -- ARGS...: vafm ARGS exits STATUS and stderr holds every NEEDLE.
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
harness_done() {
    echo "$pass passed, $fail failed"
    [ "$fail" -eq 0 ]
}
