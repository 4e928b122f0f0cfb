# SPDX-License-Identifier: MIT
# Sourced by the shell tests: a private $TMP (removed at exit, after the test's own harness_cleanup if it
# defines one), the check counters with ok/bad, and harness_done, which prints "N passed, M failed" and
# returns non-zero when a check failed.
TMP=$(mktemp -d)
harness_cleanup() { :; }
trap 'harness_cleanup; rm -rf "$TMP"' EXIT
pass=0
fail=0
ok() { echo "ok   - $1"; pass=$((pass + 1)); }
bad() { echo "FAIL - $1${2:+ ($2)}"; fail=$((fail + 1)); }
harness_done() {
    echo "$pass passed, $fail failed"
    [ "$fail" -eq 0 ]
}
