#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
#
# End-to-end checks of the vafm command-line tool: help and parameter table, scene resolution
# (presets, JSON scene files, overrides), error messages and exit codes, a short athermal run against
# the quasi-static theory, CSV output and its independence of the thread count.
# Usage: test_cli.sh path/to/vafm. Prints one line per check and "N passed, M failed".
#
# Only the paper-fig4 scene is run (~0.1 s per curve); paper-fig1 curves take tens of seconds.
set -u

VAFM=${1:?usage: test_cli.sh path/to/vafm}
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
pass=0
fail=0

ok() { echo "ok   - $1"; pass=$((pass + 1)); }
bad() { echo "FAIL - $1${2:+ ($2)}"; fail=$((fail + 1)); }

# Run vafm; stdout in $TMP/out, stderr in $TMP/err, exit status in $rc.
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

# The unit a field's name promises (the table's naming rule: SI unit as the suffix).
unit_of() {
    case $1 in
    *_m_per_s) echo "m/s" ;; *_N_per_m) echo "N/m" ;; *_J_per_m2) echo "J/m^2" ;; *_per_s) echo "1/s" ;;
    *_Pa) echo "Pa" ;; *_kg) echo "kg" ;; *_Hz) echo "Hz" ;; *_K) echo "K" ;; *_N) echo "N" ;;
    *_s) echo "s" ;; *_m) echo "m" ;; *) echo "" ;;
    esac
}

# ---- help and the parameter table ---------------------------------------------------------------

run params --json
fields=$(grep -o '"[A-Za-z0-9_]*":' "$TMP/out" | tr -d '":')
nfields=$(echo "$fields" | wc -w)
if [ "$rc" -eq 0 ] && [ "$nfields" -ge 20 ]; then ok "params --json lists $nfields fields"; else bad "params --json" "exit $rc, $nfields fields"; fi

run --help
cp "$TMP/out" "$TMP/help"
missing=""
for f in $fields; do
    u=$(unit_of "$f")
    got=$(awk -v f="$f" '$1 == f { print $2; exit }' "$TMP/help")
    if [ -z "$got" ]; then missing="$missing $f(absent)"; elif [ -n "$u" ] && [ "$got" != "$u" ]; then missing="$missing $f($got!=$u)"; fi
done
if [ "$rc" -eq 0 ] && [ "$nfields" -ge 20 ] && [ -z "$missing" ]; then ok "--help lists every field with its unit"; else bad "--help parameter list" "exit $rc:$missing"; fi
missing=""
for c in run curves samples params presets integrators; do
    grep -q "^vafm $c" "$TMP/help" || missing="$missing $c"
done
if [ -z "$missing" ]; then ok "--help shows the usage of every command"; else bad "--help usage" "$missing"; fi

run help run
if [ "$rc" -eq 0 ] && grep -q "^vafm run" "$TMP/out" && grep -q "^  k_N_per_m " "$TMP/out"; then ok "help run"; else bad "help run" "exit $rc"; fi
run curves --help
if [ "$rc" -eq 0 ] && grep -q -- "--threads" "$TMP/out"; then ok "curves --help"; else bad "curves --help" "exit $rc"; fi
run --version
if [ "$rc" -eq 0 ] && grep -q "^vafm [0-9]" "$TMP/out"; then ok "--version"; else bad "--version" "exit $rc"; fi

run presets
if [ "$rc" -eq 0 ] && grep -q "^paper-fig1 " "$TMP/out" && grep -q "^paper-fig4 " "$TMP/out" &&
    grep -q "^paper-fig4-bd " "$TMP/out"; then ok "presets lists paper-fig1, paper-fig4, paper-fig4-bd"; else bad "presets" "exit $rc"; fi
run integrators
if [ "$rc" -eq 0 ] && [ "$(grep -cE '^(gjf|baoab|paper-vv|brownian) ' "$TMP/out")" -eq 4 ]; then ok "integrators lists 4"; else bad "integrators" "exit $rc"; fi

# ---- scene resolution ----------------------------------------------------------------------------

run params --json
cp "$TMP/out" "$TMP/fig1.json"
run params --json --scene "$TMP/fig1.json"
if [ "$rc" -eq 0 ] && grep -q '"k_N_per_m": ' "$TMP/fig1.json" && cmp -s "$TMP/out" "$TMP/fig1.json"; then ok "params --json round trip (paper-fig1)"; else bad "round trip fig1" "exit $rc"; fi

# Every kind of field changed (real, choice, bool, seed), from a non-default preset.
set_args=(--preset paper-fig4 --T_K 123.456 --integrator=baoab --free_exact=false --seed 987654321 --noise uniform
    --start_height_m -1e-9 --trigger height --trigger_height_m -2e-8)
run params --json "${set_args[@]}"
cp "$TMP/out" "$TMP/mod.json"
run params --json --scene "$TMP/mod.json"
if [ "$rc" -eq 0 ] && grep -q '"k_N_per_m": ' "$TMP/mod.json" && cmp -s "$TMP/out" "$TMP/mod.json"; then ok "params --json round trip (every kind of field)"; else bad "round trip mod" "exit $rc $(cat "$TMP/err")"; fi
if grep -q '"T_K": 123.456,' "$TMP/mod.json" && grep -q '"integrator": "baoab"' "$TMP/mod.json" &&
    grep -q '"free_exact": false' "$TMP/mod.json" && grep -q '"seed": "987654321"' "$TMP/mod.json" &&
    grep -qE '"start_height_m": -1(\.0+1?)?e-09,' "$TMP/mod.json"; then ok "overrides (--NAME VALUE and --NAME=VALUE) reach the scene"; else bad "overrides" "$(cat "$TMP/mod.json")"; fi

run params --json --k_N_per_m 1 --k_N_per_m=2
if [ "$rc" -eq 0 ] && grep -q '"k_N_per_m": 2,' "$TMP/out"; then ok "overrides apply in order"; else bad "override order" "exit $rc"; fi

# A file's "preset" key applies first wherever it stands; overrides come after the file.
printf '{"T_K": 5, "preset": "paper-fig4", "dwell_s": 0.25}\n' >"$TMP/pre.json"
run params --json --scene "$TMP/pre.json" --dwell_s 0.5
if [ "$rc" -eq 0 ] && grep -q '"T_K": 5,' "$TMP/out" && grep -q '"E_star_Pa": 1000000000,' "$TMP/out" &&
    grep -q '"dwell_s": 0.5,' "$TMP/out"; then ok "scene file: preset first, then keys, then overrides"; else bad "scene preset order" "exit $rc"; fi

# ---- errors ------------------------------------------------------------------------------------

expect_fail "--k_N_per_m=-1 is out of range" 2 k_N_per_m -1 1e-06 10000 -- params --k_N_per_m=-1
expect_fail "--k_N_per_m=abc is not a number" 2 k_N_per_m abc 1e-06 10000 -- params --k_N_per_m=abc
expect_fail "--integrator=foo names the choices" 2 integrator foo "gjf|baoab|paper-vv|brownian" -- params --integrator=foo
expect_fail "--free_exact=maybe names the choices" 2 free_exact maybe "true|false" -- params --free_exact=maybe
expect_fail "--seed=-3 names the range" 2 seed -3 "2^64" -- params --seed=-3
expect_fail "unknown --bogus=1" 2 bogus -- params --bogus=1
expect_fail "unknown preset" 2 nope paper-fig4 -- params --preset nope
expect_fail "parameter without a value" 2 k_N_per_m -- params --k_N_per_m
expect_fail "run: unstable dt names dt_s" 2 dt_s stability -- run --preset paper-fig4 --dt_s=1e-3

printf '{"k_N_per_m": 0.1,\n' >"$TMP/trunc.json"
expect_fail "malformed JSON: file, line, column" 2 "$TMP/trunc.json" "line 2" column -- params --scene "$TMP/trunc.json"
printf '{"k_N_per_m": "abc"}\n' >"$TMP/type1.json"
expect_fail "JSON string for a number: key, range, file" 2 "$TMP/type1.json" k_N_per_m 1e-06 10000 -- params --scene "$TMP/type1.json"
printf '{"integrator": true}\n' >"$TMP/type2.json"
expect_fail "JSON boolean for a choice: key, choices" 2 "$TMP/type2.json" integrator "gjf|baoab" -- params --scene "$TMP/type2.json"
printf '{"T_K": -4}\n' >"$TMP/range.json"
expect_fail "JSON value out of range" 2 "$TMP/range.json" T_K -4 1e+09 -- params --scene "$TMP/range.json"
printf '{"bogus": 1}\n' >"$TMP/unknown.json"
expect_fail "JSON unknown key" 2 "$TMP/unknown.json" bogus -- params --scene "$TMP/unknown.json"
printf '[1, 2]\n' >"$TMP/array.json"
expect_fail "JSON array instead of an object" 2 "$TMP/array.json" object -- params --scene "$TMP/array.json"
expect_fail "missing scene file" 2 "$TMP/none.json" -- params --scene "$TMP/none.json"

expect_fail "unknown command" 2 frobnicate -- frobnicate
expect_fail "option of another command" 2 -- --threads -- run --threads 2
expect_fail "curves without -n" 2 -- -n -- curves --preset paper-fig4
expect_fail "curves -n 0" 2 -- -n -- curves -n 0 --preset paper-fig4
expect_fail "curves: bad list element" 2 -- --T 1,x -- curves -n 1 --preset paper-fig4 --T 1,x
expect_fail "curves: grid value out of range names the field" 2 T_K -5 -- curves -n 1 --preset paper-fig4 --T 0,-5
expect_fail "run --index -1" 2 -- --index -- run --preset paper-fig4 --index -1
expect_fail "campaign: not yet" 2 "not yet" "vafm curves --csv" -- campaign
expect_fail "info: not yet" 2 "not yet" -- info some.h5
expect_fail "export: not yet" 2 "not yet" -- export some.h5
expect_fail "unwritable CSV is a runtime error" 1 "cannot open" -- samples --preset paper-fig4 --csv "$TMP/no/such/dir.csv"

# ---- a short athermal run against the quasi-static theory -----------------------------------------

# physics.md: gamma~ = 0.229, k~ = 0.1 gives F_det = 0.97226725 F_JKR; a slow athermal run detaches at it
# (the spring keeps moving during the snap: slightly above, at v~ = 1e-3 well inside 1%).
run run --preset paper-fig4 --T_K 0
det=$(awk '$1 == "detach_force_N" && $5 == "F_JKR" { print $4; exit }' "$TMP/out")
if [ "$rc" -eq 0 ] && [ -n "$det" ] && awk -v d="$det" 'BEGIN { r = d / 0.97226725; exit !(r > 0.99 && r < 1.01) }'; then
    ok "run paper-fig4 T=0: detach force $det F_JKR within 1% of F_det 0.97226725"
else
    bad "run paper-fig4 T=0 detach force" "exit $rc, got '$det' $(head -c 300 "$TMP/err")"
fi
if grep -q "k~ = 0.1," "$TMP/out" && grep -q "gamma~ = 0.229," "$TMP/out" && grep -q "m~ = 0.01," "$TMP/out" &&
    grep -q "kT~ = 0," "$TMP/out"; then ok "run prints the reduced scene (m~ 0.01, k~ 0.1, gamma~ 0.229, kT~ 0)"; else bad "run reduced values"; fi
if grep -q "^time step" "$TMP/out" && grep -q "real-time factor" "$TMP/out" && grep -q "flags: none" "$TMP/out" &&
    grep -q "0.97226725 F_JKR" "$TMP/out"; then ok "run prints time step, flags, quasi-static F_det, real-time factor"; else bad "run summary"; fi

# ---- curves: CSV and thread independence ----------------------------------------------------------

run curves -n 4 --preset paper-fig4 --csv -
cp "$TMP/out" "$TMP/c0.csv"
rows=$(($(wc -l <"$TMP/c0.csv") - 1))
if [ "$rc" -eq 0 ] && [ "$rows" -eq 4 ] && head -1 "$TMP/c0.csv" | grep -q "^index,point,T_K,v_m_per_s,k_N_per_m,flags,"; then
    ok "curves -n 4 --csv -: header and 4 rows"
else bad "curves -n 4 csv" "exit $rc, $rows rows $(head -c 300 "$TMP/err")"; fi
if [ "$(cut -d, -f1 "$TMP/c0.csv" | tail -n +2 | tr '\n' ' ')" = "0 1 2 3 " ]; then ok "curves: indices 0..3 in order"; else bad "curves indices"; fi
if grep -q "detach_force_N" "$TMP/err" && grep -q "F_JKR" "$TMP/err"; then ok "curves: summary on stderr when the CSV is stdout"; else bad "curves summary"; fi
run curves -n 4 --preset paper-fig4 --csv - --threads 1
cp "$TMP/out" "$TMP/c1.csv"
run curves -n 4 --preset paper-fig4 --csv - --threads 2
cp "$TMP/out" "$TMP/c2.csv"
if [ "$(wc -l <"$TMP/c2.csv")" -eq 5 ] && cmp -s "$TMP/c0.csv" "$TMP/c1.csv" && cmp -s "$TMP/c1.csv" "$TMP/c2.csv"; then ok "curves: --threads 1 and 2 byte-identical"; else bad "curves thread independence"; fi

# Grid: T slowest; the point column and the T column follow the list.
run curves -n 2 --preset paper-fig4 --T 0,1e6 --csv "$TMP/grid.csv" --quiet
if [ "$rc" -eq 0 ] && [ "$(tail -n +2 "$TMP/grid.csv" 2>/dev/null | cut -d, -f2,3 | tr '\n' ' ')" = "0,0 0,0 1,1000000 1,1000000 " ] &&
    grep -q "^point 1: T = 1e+06 K" "$TMP/out"; then ok "curves grid --T 0,1e6: points and rows"; else bad "curves grid" "exit $rc"; fi

# ---- samples -----------------------------------------------------------------------------------

run samples --preset paper-fig4 --csv -
segs=$(tail -n +2 "$TMP/out" | cut -d, -f6 | sort -u | tr '\n' ' ')
badrows=$(tail -n +2 "$TMP/out" | awk -F, 'NF != 6' | wc -l)
if [ "$rc" -eq 0 ] && [ "$(head -1 "$TMP/out")" = "time_s,height_m,deflection_m,force_N,tip_m,segment" ] &&
    [ "$segs" = "0 1 " ] && [ "$badrows" -eq 0 ] && [ "$(wc -l <"$TMP/out")" -gt 100 ]; then
    ok "samples: header, 6 columns, segments 0 and 1"
else bad "samples" "exit $rc, segments '$segs', $badrows bad rows"; fi
run samples --preset paper-fig4 --tune
segs=$(tail -n +2 "$TMP/out" | cut -d, -f6 | sort -u | tr '\n' ' ')
if [ "$rc" -eq 0 ] && [ "$segs" = "3 " ]; then ok "samples --tune: segment 3 only"; else bad "samples --tune" "exit $rc, '$segs'"; fi

echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
