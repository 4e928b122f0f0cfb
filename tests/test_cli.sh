#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
#
# End-to-end checks of the vafm command-line tool: help and parameter table, scene resolution
# (presets, JSON scene files, overrides), error messages and exit codes, a short athermal run against
# the quasi-static theory, CSV output and its independence of the thread count, and the HDF5 commands
# (campaign, info, export): files the standard HDF5 tools read and the conformance check passes,
# thread independence, kill -9 and resume equal to an uninterrupted run, refusals and damaged files.
# Usage: test_cli.sh path/to/vafm. Prints one line per check and "N passed, M failed".
#
# Only the paper-fig4 scene is run (~0.1 s per curve); paper-fig1 curves take tens of seconds. The HDF5
# checks use faster ramps: v = 6.4e-5 m/s (v~ = 1e-2, ~10 ms per curve) and 6.4e-4 m/s (v~ = 0.1).
set -u

VAFM=${1:?usage: test_cli.sh path/to/vafm}
. "$(dirname "$0")/harness.sh"



# The unit a field's name promises (the table's naming rule: SI unit as the suffix).
unit_of() {
    case $1 in
    *_V_per_sqrt_s) echo "V/s^0.5" ;; *_V_per_s) echo "V/s" ;; *_V_per_m) echo "V/m" ;;
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
    got=$(awk -v f="$f" 'index($0, "  " f " ") == 1 { print $2; exit }' "$TMP/help")
    if [ -z "$got" ]; then missing="$missing $f(absent)"; elif [ -n "$u" ] && [ "$got" != "$u" ]; then missing="$missing $f($got!=$u)"; fi
done
if [ "$rc" -eq 0 ] && [ "$nfields" -ge 20 ] && [ -z "$missing" ]; then ok "--help lists every field with its unit"; else bad "--help parameter list" "exit $rc:$missing"; fi
missing=""
for c in run curves samples params presets integrators campaign info export; do
    grep -q "^vafm $c" "$TMP/help" || missing="$missing $c"
done
if [ -z "$missing" ]; then ok "--help shows the usage of every command"; else bad "--help usage" "$missing"; fi

run help run
if [ "$rc" -eq 0 ] && grep -q "^vafm run" "$TMP/out" && grep -q "^  k_N_per_m " "$TMP/out"; then ok "help run"; else bad "help run" "exit $rc"; fi
run curves --help
if [ "$rc" -eq 0 ] && grep -q -- "--threads" "$TMP/out"; then ok "curves --help"; else bad "curves --help" "exit $rc"; fi
# an integer field shows its own range from the table (0.6.1 showed [0, 2^64-1], the seed's, for all)
run help params
if [ "$rc" -eq 0 ] && grep -qE '^  adc_bits +bits +integer \[0, 24\] ' "$TMP/out" &&
    grep -qE '^  segment_samples +samples +integer \[0, 16777216\] ' "$TMP/out" &&
    grep -qE '^  seed +- +integer \[0, 2\^64-1\] ' "$TMP/out"; then ok "help params: integer fields show their own range"
else bad "help params integer ranges" "exit $rc: $(grep -E '^  (adc_bits|segment_samples|seed) ' "$TMP/out")"; fi
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
# --T, --v and --k (a campaign's grid axes) set a single scene in command-line order too (0.6.1 applied them
# after every other override: the first value won)
run params --json --k 1 --k_N_per_m 2
kk=$rc; grep -q '"k_N_per_m": 2,' "$TMP/out"; kk=$((kk + $?))
run params --json --k_N_per_m 2 --k 1
grep -q '"k_N_per_m": 1,' "$TMP/out"; kk=$((kk + rc + $?))
run params --json --speed 2um/s --v 5um/s --v_retract_m_per_s 1um/s --T_K 5 --T 7
grep -q '"v_approach_m_per_s": 5e-06,' "$TMP/out" && grep -q '"v_retract_m_per_s": 1e-06,' "$TMP/out" &&
    grep -q '"T_K": 7,' "$TMP/out"; kk=$((kk + rc + $?))
run params --k 1 --T 5 --k_N_per_m 2
grep -q -- "overrides --k_N_per_m=1 --T_K=5 --k_N_per_m=2$" "$TMP/out"; kk=$((kk + rc + $?))
if [ "$kk" -eq 0 ]; then ok "--T, --v, --k apply in command-line order with the other overrides"
else bad "--T/--v/--k order" "$(grep -E '^scene' "$TMP/out")"; fi
run curves -n 1 --preset paper-fig4 --T 1,2 --k_N_per_m 0.3 --k 0.1,0.2 --quiet --csv -
if [ "$rc" -eq 0 ] && [ "$(grep -cE '^[0-9]+,[0-3],[12],[^,]*,0\.[12]0000' "$TMP/out")" -eq 4 ]; then
    ok "curves: --T and --k lists stay a grid (4 points)"
else bad "curves grid" "exit $rc: $(head -c 300 "$TMP/err")"; fi

# A file's "preset" key applies first wherever it stands; overrides come after the file.
printf '{"T_K": 5, "preset": "paper-fig4", "dwell_s": 0.25}\n' >"$TMP/pre.json"
run params --json --scene "$TMP/pre.json" --dwell_s 0.5
if [ "$rc" -eq 0 ] && grep -q '"T_K": 5,' "$TMP/out" && grep -q '"E_star_Pa": 1e+09,' "$TMP/out" &&
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

# the instrument's words and values with units (issue #16)
run params --json --preset contact-silica --setpoint 2nN --speed 2um/s --T 25C --f0 15kHz --ramp-size 1um --invols 60nm/V
miss=""
for kv in '"setpoint_N": 2e-09' '"v_approach_m_per_s": 2e-06' '"v_retract_m_per_s": 2e-06' '"T_K": 298.15' \
          '"f0_Hz": 15000' '"ramp_size_m": 1e-06' '"sensitivity_m_per_V": 6e-08'; do
    grep -qF -- "$kv" "$TMP/out" || miss="$miss $kv"
done
if [ "$rc" -eq 0 ] && [ -z "$miss" ]; then ok "instrument words with units set their fields"; else bad "instrument words" "exit $rc, missing$miss"; fi
run params --json --preset contact-silica --ramp-size 1um --ramp-rate 1Hz --segment_samples 1000
if [ "$rc" -eq 0 ] && grep -qF '"v_approach_m_per_s": 2e-06' "$TMP/out" && grep -qF '"sample_rate_Hz": 2000' "$TMP/out"; then
    ok "ramp rate and samples per segment derive speed and sample rate"
else bad "ramp rate" "exit $rc: $(head -c 300 "$TMP/out")"; fi
# the paper's step by name (the default of every preset; docs/speed-and-accuracy.md, "The default step")
run params --json --preset contact-silica --omega_dt paper
paper=$(grep -o '"omega_dt": [^,]*' "$TMP/out")
run params --json --preset contact-silica
if [ "$rc" -eq 0 ] && [ -n "$paper" ] && grep -qF -- "$paper," "$TMP/out"; then
    ok "--omega_dt paper is the default step ($paper)"
else bad "--omega_dt paper" "exit $rc, '$paper' vs $(grep -o '"omega_dt": [^,]*' "$TMP/out")"; fi
# issue #29 item 9: a field given on the command line that an instrument setting would derive. Both on the
# command line: a usage error naming both options; the setting from a scene file: the command line wins,
# with a note on stderr (0.6.2 let the setting win without a word in every case)
expect_fail "--speed with --ramp-rate" 2 "--speed and --ramp-rate conflict" "2e-06 m/s" "3e-06 m/s" -- params --speed 3um/s --ramp-size 1um --ramp-rate 1Hz
expect_fail "--setpoint with --setpoint_V" 2 "--setpoint and --setpoint_V conflict" -- params --setpoint 1nN --setpoint_V 0.5
expect_fail "--rate with --segment_samples" 2 "--rate and --segment_samples conflict" -- params --rate 10kHz --ramp-size 1um --segment_samples 1000
expect_fail "--v with --extend_time_s" 2 "--v and --extend_time_s conflict" -- params --v 3um/s --ramp-size 1um --extend_time_s 1
run params --speed 2um/s --ramp-size 1um --ramp-rate 1Hz
[ "$rc" -eq 0 ] && ok "--speed equal to what --ramp-rate makes it is no conflict" || bad "--speed equal to the ramp rate's" "exit $rc: $(head -c 300 "$TMP/err")"
echo '{"ramp_size_m": 1e-6, "ramp_rate_Hz": 1}' >"$TMP/ramp.json"
run params --scene "$TMP/ramp.json" --speed 3um/s
if [ "$rc" -eq 0 ] && grep -qF "note: --speed (v_approach_m_per_s = 3e-06 m/s) wins over ramp_rate_Hz = 1 Hz of the scene file" "$TMP/err" &&
   grep -qE "^ *v_approach_m_per_s +3e-06 " "$TMP/out" && grep -qE "^ *v_retract_m_per_s +3e-06 " "$TMP/out" &&
   grep -qE "^ *ramp_rate_Hz +0 " "$TMP/out"; then
    ok "a scene file's ramp_rate_Hz gives way to --speed, with a note"
else
    bad "a scene file's ramp_rate_Hz gives way to --speed, with a note" "exit $rc: $(head -c 300 "$TMP/err") $(grep -E '^ *(v_a|v_r|ramp_rate)' "$TMP/out")"
fi
run params --scene "$TMP/ramp.json" --v_approach_m_per_s 3e-6
if [ "$rc" -eq 0 ] && grep -qE "^ *v_approach_m_per_s +3e-06 " "$TMP/out" && grep -qE "^ *v_retract_m_per_s +2e-06 " "$TMP/out"; then
    ok "the retract speed keeps what the scene file's ramp rate made it"
else
    bad "the retract speed keeps what the scene file's ramp rate made it" "exit $rc: $(grep -E '^ *(v_a|v_r|ramp_rate)' "$TMP/out")"
fi
# issue #29 item 10: a nonzero value that reads as 0 or a subnormal is an underflow, refused naming the range
expect_fail "--T 1e-400 underflows" 2 T_K "'1e-400' underflows" "[0, 1e+09] K" -- params --T 1e-400
expect_fail "--setpoint 1e-400 underflows" 2 setpoint_N underflows "[0, 1] N" -- params --setpoint 1e-400
expect_fail "--setpoint_N=1e-300fN underflows" 2 setpoint_N underflows -- params --setpoint_N=1e-300fN
expect_fail "--flush-interval 1e-400 underflows" 2 --flush-interval underflows 86400 -- campaign -n 1 --preset paper-fig4 --out "$TMP/uf.h5" --flush-interval 1e-400
# the same in a scene file (jansson reads 1e-400 as 0); zero spelled 0e-400 is zero
printf '{"T_K": 300,\n "setpoint_N": 1e-400}' >"$TMP/uf.json"
expect_fail "a scene file's 1e-400 underflows, named" 2 setpoint_N "line 2" "the number 1e-400 underflows" -- params --scene "$TMP/uf.json"
printf '{"setpoint_N": 0e-400}' >"$TMP/uf0.json"
run params --json --scene "$TMP/uf0.json"
if [ "$rc" -eq 0 ] && grep -q '"setpoint_N": 0' "$TMP/out"; then ok "a scene file's 0e-400 is zero"
else bad "a scene file's 0e-400 is zero" "exit $rc: $(head -c 300 "$TMP/err")"; fi
run params --setpoint 0e-400
if [ "$rc" -eq 0 ] && grep -qE "^ *setpoint_N +0 " "$TMP/out"; then ok "--setpoint 0e-400 is zero"; else bad "--setpoint 0e-400 is zero" "exit $rc: $(grep setpoint_N "$TMP/out" | head -c 200)"; fi
expect_fail "a value in the wrong unit names field and unit" 2 setpoint_N "'2nm'" "in N" -- params --setpoint 2nm
expect_fail "a ramp rate needs a ramp size" 2 ramp_rate_Hz ramp_size_m -- params --ramp-size 0 --ramp-rate 1Hz
expect_fail "a list element in the wrong unit" 2 "--T" "element 2" -- curves -n 1 --preset paper-fig4 --T 300K,5nN
printf '{"setpoint_N": "1nN"}\n' >"$TMP/unitjson.json"
expect_fail "JSON scene files keep plain SI numbers" 2 "$TMP/unitjson.json" setpoint_N -- params --scene "$TMP/unitjson.json"

printf '{"omega_dt": "paper"}\n' >"$TMP/paperjson.json"
run params --json --scene "$TMP/paperjson.json"
if [ "$rc" -eq 0 ] && [ -n "$paper" ] && grep -qF -- "$paper," "$TMP/out"; then ok "a JSON scene takes omega_dt \"paper\" ($paper)"
else bad "JSON omega_dt paper" "exit $rc $(head -c 200 "$TMP/err")"; fi
printf '{"omega_dt": "fast"}\n' >"$TMP/fastjson.json"
expect_fail "JSON omega_dt takes no other name" 2 "$TMP/fastjson.json" omega_dt -- params --scene "$TMP/fastjson.json"

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

# The kernels: every batch width gives the scalar kernel's CSV byte for byte (20 curves fill the lanes);
# the summary names the kernel; an unknown kernel is a usage error naming the option.
run curves -n 20 --preset paper-fig4 --csv - --threads 1 --kernel scalar
cp "$TMP/out" "$TMP/k_scalar.csv"
kern_ok=1
for k in batch batch4 batch8 auto; do
    run curves -n 20 --preset paper-fig4 --csv - --threads 2 --kernel $k
    cmp -s "$TMP/out" "$TMP/k_scalar.csv" && grep -q "^kernel       " "$TMP/err" || kern_ok=0
done
if [ "$kern_ok" -eq 1 ] && [ "$(wc -l <"$TMP/k_scalar.csv")" -eq 21 ]; then ok "curves --kernel scalar|batch|batch4|batch8|auto: the same CSV"
else bad "curves --kernel: the same CSV" "$(head -c 300 "$TMP/err")"; fi
expect_fail "curves --kernel fast" 2 -- --kernel fast -- curves -n 1 --preset paper-fig4 --kernel fast
# The kernel names are the backend table's (src/core/backend.h; the error lists them): each one is accepted
# and named in the help of every command that takes --kernel (printed from the table).
run curves -n 1 --preset paper-fig4 --kernel fast
knames=$(sed -n 's/.*is not a kernel (\(.*\)).*/\1/p' "$TMP/err" | tr -d ',')
kn_ok=1
for k in auto scalar batch; do case " $knames " in *" $k "*) ;; *) kn_ok=0 ;; esac; done
for k in $knames; do
    run curves -n 1 --preset paper-fig4 --kernel "$k" --csv "$TMP/kn.csv" --quiet
    [ "$rc" -eq 0 ] || { kn_ok=0; echo "  --kernel $k refused"; }
done
for c in curves campaign map; do
    run help $c
    for k in $knames; do grep -Eq -- "[ (,]$k[ ,):]" "$TMP/out" || { kn_ok=0; echo "  help $c does not name $k"; }; done
done
"$VAFM" study --help >"$TMP/out" 2>&1
for k in $knames; do grep -Eq -- "[ (,]$k[ ,):]" "$TMP/out" || { kn_ok=0; echo "  study --help does not name $k"; }; done
if [ "$kn_ok" -eq 1 ]; then ok "--kernel names ($knames): accepted, in the help of curves, campaign, map, study"
else bad "--kernel names in the help" "$knames"; fi

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
# A tune is bounded by its own length and rate, not by the force curve's (0.6.1 checked the curve at the tune's
# 100 kHz: a 400 s curve at 1 nm/s made the 0.5 s tune "4e+07 samples at sample_rate_Hz = 100000 Hz")
run samples --tune --v 1e-9 --csv "$TMP/tune1.csv"
t1=$rc; n1=$(wc -l <"$TMP/tune1.csv" 2>/dev/null)
run samples --tune --tune_rate_Hz 5e7 --tune_duration_s 1e-3 --v 1e-8 --csv "$TMP/tune2.csv"
if [ "$t1" -eq 0 ] && [ "$n1" -eq 50001 ] && [ "$rc" -eq 0 ] && [ "$(wc -l <"$TMP/tune2.csv")" -eq 50001 ]; then
    ok "samples --tune at slow speeds: the curve's length does not limit the tune"
else bad "samples --tune at slow speeds" "exit $t1 ($n1 rows), $rc: $(head -c 300 "$TMP/err")"; fi
expect_fail "a tune too long for its rate names tune_duration_s and tune_rate_Hz" 2 tune_duration_s tune_rate_Hz \
    "VAFM_SIM_MAX_SAMPLES" -- samples --tune --tune_duration_s 1000 --csv "$TMP/tune3.csv"
if ! grep -q "sample_rate_Hz = " "$TMP/err" && [ ! -e "$TMP/tune3.csv" ]; then ok "... before any output, not naming the curve's rate"
else bad "tune refusal" "$(head -c 300 "$TMP/err")"; fi

# ---- HDF5 files: campaign, info, export -----------------------------------------------------------

# paper-fig4 (R = 16 nm, eta = 4e5 /s): v = v~ R eta
VA=6.4e-5 # v~ = 1e-2, ~1300 samples and ~10 ms per curve
VB=6.4e-4 # v~ = 0.1
GRID=(--preset paper-fig4 --v "$VA,$VB")

# ncurves: the curve count `vafm info` reports (from $TMP/out)
ncurves() { awk '$1 == "file" { for (i = 2; i <= NF; i++) if ($i == "curve(s)") { print $(i - 1); exit } }' "$TMP/out"; }
# export_all A.h5 B.h5 N: the number of curves 0..N-1 whose exports differ (or fail)
export_diff() {
    local i d=0
    for ((i = 0; i < $3; i++)); do
        "$VAFM" export "$1" --curve "$i" >"$TMP/ea.csv" 2>/dev/null || { d=$((d + 1)); continue; }
        "$VAFM" export "$2" --curve "$i" --csv "$TMP/eb.csv" 2>/dev/null || { d=$((d + 1)); continue; }
        [ "$(wc -l <"$TMP/ea.csv")" -gt 100 ] && cmp -s "$TMP/ea.csv" "$TMP/eb.csv" || d=$((d + 1))
    done
    echo "$d"
}
# stats FILE: the statistics block of a summary (up to the conformance line of vafm info)
stats() { sed -n '/^statistics/,$p' "$1" | grep -v '^conformance'; }

expect_fail "campaign without --out" 2 --out -- campaign -n 1 --preset paper-fig4
expect_fail "campaign: file name without .h5" 2 ".h5" "$TMP/x.hdf" -- campaign -n 1 --preset paper-fig4 --out "$TMP/x.hdf"
expect_fail "campaign --flush-interval -1 names the range" 2 --flush-interval -1 86400 -- campaign -n 1 --preset paper-fig4 --out "$TMP/x.h5" --flush-interval -1
expect_fail "campaign --gzip 12 names the range" 2 --gzip 12 "[0, 9]" -- campaign -n 1 --preset paper-fig4 --out "$TMP/x.h5" --gzip 12
expect_fail "campaign: grid value out of range names the field" 2 T_K -5 -- campaign -n 1 --preset paper-fig4 --T 0,-5 --out "$TMP/x.h5"
if [ ! -e "$TMP/x.h5" ] && [ ! -e "$TMP/x.hdf" ]; then ok "refused campaigns leave no file"; else bad "refused campaign left a file"; fi
expect_fail "campaign --resume of a missing file" 2 "$TMP/none.h5" -- campaign -n 1 --preset paper-fig4 --out "$TMP/none.h5" --resume
expect_fail "info without FILE" 2 FILE -- info
expect_fail "info of a missing file" 1 "$TMP/none.h5" -- info "$TMP/none.h5"

# 1 vs 2 threads (and gzip): the same curves, byte for byte, as vafm export writes them
run campaign -n 4 "${GRID[@]}" --threads 1 --out "$TMP/t1.h5" -q
cp "$TMP/out" "$TMP/t1.sum"
if [ "$rc" -eq 0 ] && grep -q "^file .*: 8 curves (0 kept from before, 8 new), .* MB written" "$TMP/t1.sum" &&
    grep -q "^campaign     2 grid point(s) x 4 curves, 8 run in .* curves/s" "$TMP/t1.sum" &&
    grep -q "^writer .*% of the wall time" "$TMP/t1.sum" && grep -q "^point 1: " "$TMP/t1.sum"; then
    ok "campaign summary: curves, grid, wall, curves/s, MB written, writer share, statistics"
else bad "campaign -n 4 --threads 1" "exit $rc $(head -c 300 "$TMP/err")"; fi
run campaign -n 4 "${GRID[@]}" --threads 2 --out "$TMP/t2.h5" -q
run campaign -n 4 "${GRID[@]}" --threads 2 --gzip 4 --out "$TMP/t2z.h5" -q
d2=$(export_diff "$TMP/t1.h5" "$TMP/t2.h5" 8)
dz=$(export_diff "$TMP/t1.h5" "$TMP/t2z.h5" 8)
if [ "$rc" -eq 0 ] && [ "$d2" -eq 0 ] && [ "$dz" -eq 0 ]; then ok "campaign: 1 and 2 threads (and gzip) give byte-identical exports of all 8 curves"; else bad "campaign thread independence" "$d2 and $dz curves differ"; fi

# a grid with all three axes (2 T x 2 v x 3 k, one curve each): point p is (T[p / 6], v[p / 3 % 2], k[p % 3]),
# k fastest, then v, then T (protocol/hdf5.md), in the file's 'vafm grid' and in every ground-truth row
run campaign -n 1 --preset paper-fig4 --T 0,1 --v "$VA,$VB" --k 0.05,0.1,0.2 --out "$TMP/grid3.h5" -q
if [ "$rc" -eq 0 ] && /usr/bin/python3 - "$TMP/grid3.h5" "$VA" "$VB" >"$TMP/g3" 2>&1 <<'EOF'; then ok "campaign T x v x k grid: k fastest, then v, then T, in 'vafm grid' and the ground truth"; else bad "campaign T x v x k grid order" "exit $rc $(tail -c 400 "$TMP/g3") $(head -c 200 "$TMP/err")"; fi
import json, sys
import h5py
T, v, k = [0.0, 1.0], [float(sys.argv[2]), float(sys.argv[3])], [0.05, 0.1, 0.2]
with h5py.File(sys.argv[1], "r") as f:
    g = json.loads(f.attrs["vafm grid"])
    gt = f.attrs["vafm ground truth"]
assert (g["T_K"], g["v_m_per_s"], g["k_N_per_m"], g["points"], g["curves"]) == (T, v, k, 12, 12), g
assert len(gt) == 12, len(gt)
for row in gt:
    p = int(row["point"])
    want = (T[p // 6], v[p // 3 % 2], k[p % 3])
    got = (float(row["T_K"]), float(row["v_m_per_s"]), float(row["k_N_per_m"]))
    assert int(row["curve"]) == p and got == want, (p, got, want)
EOF

# the standard HDF5 tools read the file
if command -v h5ls >/dev/null 2>&1 && command -v h5dump >/dev/null 2>&1; then
    if h5ls -r "$TMP/t1.h5" >"$TMP/ls" 2>&1 && grep -q '^/0/force ' "$TMP/ls" && grep -q '^/7/tip\\ position ' "$TMP/ls" &&
        h5dump -H "$TMP/t2z.h5" >"$TMP/dump" 2>&1 && grep -q 'ATTRIBUTE "vafm ground truth"' "$TMP/dump" &&
        h5dump -d /3/segment "$TMP/t2.h5" >/dev/null 2>&1; then ok "h5ls and h5dump read campaign files"; else bad "h5ls/h5dump" "$(head -c 300 "$TMP/ls")"; fi
else
    bad "h5ls and h5dump read campaign files" "h5ls/h5dump missing (Debian: hdf5-tools; .ci/deps.sh installs it)"
fi

run info "$TMP/t1.h5"
cp "$TMP/out" "$TMP/t1.info"
lines=$(grep -cE '^ +[0-9]+ +[0-9]+ +[0-9]+ +[0-9]+ +[0-9]+ .* \| +[01] +0 ' "$TMP/t1.info")
if [ "$rc" -eq 0 ] && [ "$(ncurves)" = 8 ] && [ "$lines" -eq 8 ] && grep -q "^conformance  ok" "$TMP/t1.info" &&
    grep -q "^vafm format  1.1, created .*, seed 1, ground truth for 8 curve(s)" "$TMP/t1.info" &&
    grep -q "^grid         2 point(s) x 4 curves = 8 curves; .* v 6.4e-05,0.00064 m/s;" "$TMP/t1.info" &&
    grep -q "^software     vafm " "$TMP/t1.info"; then
    ok "info: 8 curve lines with ground truth, provenance, grid, conformance ok"
else bad "info t1.h5" "exit $rc, $lines curve lines $(head -c 300 "$TMP/err")"; fi
run info "$TMP/t1.h5" --json
cp "$TMP/out" "$TMP/stored.json"
run params --json --preset paper-fig4
if cmp -s "$TMP/out" "$TMP/stored.json"; then ok "info --json prints the stored scene (= params --json of the run)"; else bad "info --json"; fi

# the statistics from the file's ground truth equal those of vafm curves (same observables, same order)
run curves -n 4 "${GRID[@]}" -q
stats "$TMP/out" >"$TMP/s.curves"
stats "$TMP/t1.sum" >"$TMP/s.camp"
stats "$TMP/t1.info" >"$TMP/s.info"
if [ "$(wc -l <"$TMP/s.curves")" -ge 15 ] && cmp -s "$TMP/s.curves" "$TMP/s.camp" && cmp -s "$TMP/s.curves" "$TMP/s.info"; then
    ok "campaign and info statistics (from the ground truth) equal vafm curves'"
else bad "statistics differ" "$(diff "$TMP/s.curves" "$TMP/s.info" | head -5)"; fi

# export = samples of the same curve: time, height, force, tip, segment as written; deflection = force/k
run campaign -n 2 --preset paper-fig4 --v_approach_m_per_s "$VA" --v_retract_m_per_s "$VA" --out "$TMP/s.h5" -q
run export "$TMP/s.h5" --curve 1
cp "$TMP/out" "$TMP/exp.csv"
run samples --preset paper-fig4 --v_approach_m_per_s "$VA" --v_retract_m_per_s "$VA" --index 1
cp "$TMP/out" "$TMP/smp.csv"
worst=$(paste -d, "$TMP/exp.csv" "$TMP/smp.csv" | tail -n +2 |
    awk -F, '{ d = $3 - $9; s = ($9 < 0 ? -$9 : $9); r = (d < 0 ? -d : d) / (s > 0 ? s : 1); if (r > w) w = r } END { printf "%.3g", w + 0 }')
if [ "$rc" -eq 0 ] && [ "$(head -1 "$TMP/exp.csv")" = "time_s,height_m,deflection_m,force_N,tip_m,segment" ] &&
    [ "$(wc -l <"$TMP/exp.csv")" -gt 1000 ] && cmp -s <(cut -d, -f1,2,4,5,6 "$TMP/exp.csv") <(cut -d, -f1,2,4,5,6 "$TMP/smp.csv") &&
    awk -v w="$worst" 'BEGIN { exit !(w <= 1e-12) }'; then
    ok "export --curve 1 = samples --index 1 (deflection = force/k to $worst relative)"
else bad "export vs samples" "exit $rc, deflection rel. diff $worst"; fi

# refusals: overwrite, resume of another campaign
cp "$TMP/t1.h5" "$TMP/t1.bak"
expect_fail "campaign refuses an existing file" 2 "$TMP/t1.h5" exists --overwrite --resume -- campaign -n 4 "${GRID[@]}" --out "$TMP/t1.h5"
expect_fail "campaign: --resume and --overwrite together" 2 --resume --overwrite -- campaign -n 4 "${GRID[@]}" --out "$TMP/t1.h5" --resume --overwrite
if cmp -s "$TMP/t1.h5" "$TMP/t1.bak"; then ok "a refused campaign leaves the file untouched"; else bad "refused campaign changed the file"; fi
expect_fail "resume with another scene names the field" 2 "$TMP/t1.h5" T_K resume -- campaign -n 4 "${GRID[@]}" --out "$TMP/t1.h5" --resume --T_K 1000
expect_fail "resume with another N names the field" 2 curves_per_point -- campaign -n 5 "${GRID[@]}" --out "$TMP/t1.h5" --resume
expect_fail "resume with another speed list names the field" 2 v_m_per_s -- campaign -n 4 --preset paper-fig4 --v "$VA" --out "$TMP/t1.h5" --resume
run campaign -n 4 "${GRID[@]}" --out "$TMP/t1.h5" --resume -q
if [ "$rc" -eq 0 ] && grep -q ": 8 curves (8 kept from before, 0 new)" "$TMP/out" && [ "$(export_diff "$TMP/t1.h5" "$TMP/t2.h5" 8)" -eq 0 ]; then
    ok "resume of a complete file runs nothing and keeps every curve"
else bad "resume of a complete file" "exit $rc $(head -c 300 "$TMP/err")"; fi
run campaign -n 4 "${GRID[@]}" --out "$TMP/t1.h5" --overwrite -q
if [ "$rc" -eq 0 ] && grep -q ": 8 curves (0 kept from before, 8 new)" "$TMP/out"; then ok "campaign --overwrite replaces the file"; else bad "--overwrite" "exit $rc"; fi

# a scene with piezo hysteresis: the file's measured height is the actual piezo's (before 0.6 the campaign
# refused it: its tip position did not match the commanded height)
run campaign -n 2 --preset contact-silica --piezo_hysteresis 0.05 --out "$TMP/pz.h5" -q
if [ "$rc" -eq 0 ]; then run info "$TMP/pz.h5"; fi
if [ "$rc" -eq 0 ] && grep -q "^conformance  ok" "$TMP/out"; then ok "campaign of a scene with piezo hysteresis: written, conforming"
else bad "campaign with piezo hysteresis" "exit $rc $(head -c 300 "$TMP/err")"; fi

# kill -9 in the middle, then --resume: the result equals an uninterrupted run, curve for curve
run campaign -n 50 "${GRID[@]}" --out "$TMP/ref.h5" -q
full=$(stat -c %s "$TMP/ref.h5" 2>/dev/null || echo 0)
# (the scalar kernel: it finishes curves one by one, so the file grows as they are written; the batch
# kernel appends ~16 at once and the size would say little about what the flusher made durable. A curve's
# raw data reaches the file before the flush that commits it, and the whole campaign takes ~0.15 s on an idle
# machine: with a 0.05 s interval the first flush could still be under way at 40% of the file, and a kill
# there rightly leaves 0 curves. A flush every 2 ms makes curves durable as they come.)
"$VAFM" campaign -n 50 "${GRID[@]}" --out "$TMP/k.h5" -q --threads 1 --flush-interval 0.002 --kernel scalar >/dev/null 2>&1 &
pid=$!
size=0
while kill -0 "$pid" 2>/dev/null; do
    size=$(stat -c %s "$TMP/k.h5" 2>/dev/null || echo 0)
    # at 40% of the final size: the first point's curves (the larger ones) are half done
    if [ $((size * 10)) -ge $((full * 4)) ]; then kill -9 "$pid"; break; fi
    sleep 0.01
done
wait "$pid" 2>/dev/null # (bash would report the kill)
krc=$?
run info "$TMP/k.h5"
kept=$(ncurves)
if [ "$krc" -eq 137 ] && [ "$rc" -eq 0 ] && [ -n "$kept" ] && [ "$kept" -gt 0 ] && [ "$kept" -lt 100 ] &&
    grep -q "^conformance  ok" "$TMP/out"; then
    ok "kill -9 at $((size * 100 / (full + 1)))% of the file: it opens, conforms and holds $kept complete curves"
else bad "kill -9 mid-campaign" "exit of the killed run $krc (137 = killed), info exit $rc, $kept curves, $size of $full bytes"; fi
run campaign -n 50 "${GRID[@]}" --out "$TMP/k.h5" --resume -q
if [ "$rc" -eq 0 ] && grep -q ": 100 curves ($kept kept from before, $((100 - kept)) new)" "$TMP/out"; then ok "resume runs the $((100 - kept)) missing curves"; else bad "resume after kill" "exit $rc $(head -c 300 "$TMP/err")"; fi
dk=$(export_diff "$TMP/ref.h5" "$TMP/k.h5" 100)
run info "$TMP/k.h5"
stats "$TMP/out" >"$TMP/s.k"
run info "$TMP/ref.h5"
stats "$TMP/out" >"$TMP/s.ref"
if [ "$dk" -eq 0 ] && [ "$(ncurves)" = 100 ] && [ -s "$TMP/s.ref" ] && cmp -s "$TMP/s.k" "$TMP/s.ref"; then
    ok "killed + resumed = uninterrupted: all 100 exports byte-identical, same ground-truth statistics"
else bad "killed + resumed differs" "$dk curves differ"; fi

# export errors
expect_fail "export: a curve group the file lacks is refused, naming its groups" 2 --curve "no curve group '100'" "numbered 0 to 99" -- export "$TMP/ref.h5" --curve 100
expect_fail "export without --curve" 2 --curve -- export "$TMP/ref.h5"
expect_fail "export of a missing file" 1 "$TMP/none.h5" -- export "$TMP/none.h5" --curve 0

# damaged files: a clear message naming the file, exit 1, no crash
fsz=$(stat -c %s "$TMP/t2.h5")
for cut in 100 4096 $((fsz / 2)) $((fsz - 512)); do
    head -c "$cut" "$TMP/t2.h5" >"$TMP/trunc.h5"
    expect_fail "info on a file truncated to $cut bytes" 1 "$TMP/trunc.h5" -- info "$TMP/trunc.h5"
done
expect_fail "export from a truncated file" 1 "$TMP/trunc.h5" -- export "$TMP/trunc.h5" --curve 0
printf 'not HDF5\n' >"$TMP/text.h5"
expect_fail "info on a text file" 1 "$TMP/text.h5" "not an HDF5 file" -- info "$TMP/text.h5"

# a file written by other software (test_h5's reference: instrument-like metadata, no time column)
TH5="$(dirname "$VAFM")/../h5/test_h5"
if [ -x "$TH5" ] && "$TH5" --make-files "$TMP" >/dev/null 2>&1 && [ -f "$TMP/reference.h5" ]; then
    run info "$TMP/reference.h5"
    if [ "$rc" -eq 0 ] && [ "$(ncurves)" = 3 ] && grep -q "^software     afmformats 0.18.0" "$TMP/out" &&
        grep -q "^provenance   none" "$TMP/out" && grep -q "^conformance  ok" "$TMP/out" &&
        grep -qE '^ +0 +300 +150 +150 +0 +0.0471 +5e-06 +5e-06 +0.4$' "$TMP/out"; then
        ok "info of another program's file: 3 curves, its metadata, no provenance, conformance ok"
    else bad "info reference.h5" "exit $rc $(head -c 300 "$TMP/err")"; fi
    run export "$TMP/reference.h5" --curve 2
    # no time: empty column; deflection = force / k; tip = height (measured) + force / k (k = 0.0471 N/m),
    # where the reference's height (measured) = height (piezo) + 3 nm cos(j): tip - height_m - deflection
    # stays within 3 nm and is not 0 (the tip is not taken from the piezo height)
    badrows=$(tail -n +2 "$TMP/out" | awk -F, -v k=0.0471 'NF != 6 || $1 != "" || $3 == "" || $5 == "" ||
        ($3 - $4 / k) ^ 2 > (1e-12 * ($3 < 0 ? -$3 : $3) + 1e-300) ^ 2 ||
        ($5 - $2 - $3) ^ 2 > (3.000001e-9) ^ 2 { n++ } ($5 - $2 - $3) ^ 2 > 1e-18 { off++ } END { print (off > 100 ? n + 0 : -1) }')
    if [ "$rc" -eq 0 ] && [ "$(($(wc -l <"$TMP/out") - 1))" -eq 400 ] && [ "$badrows" -eq 0 ]; then
        ok "export of a file without time: empty time column, deflection = force/k, tip computed"
    else bad "export reference.h5" "exit $rc, $badrows bad rows"; fi
else
    bad "foreign-file checks" "$TH5 not built (it is built with the tests: meson setup -Dtests=true)"
fi

# --segments: a 4-segment list (baseline pause, extend to 3 nN, a force pause at a quarter of the rate, retract
# to the detachment): every sample labelled with its segment in order, the pause's 100 samples as 25; refusals
# name the segment and the field, or the unknown key
cat >"$TMP/seg4.json" <<'JSON'
{"segments": [
  {"kind": "pause", "duration_s": 0.005},
  {"kind": "extend", "speed_m_per_s": 1e-6, "trigger": {"channel": "force", "op": ">", "value": 3e-9}},
  {"kind": "pause", "mode": "force", "duration_s": 0.01, "sample_rate_Hz": 2500},
  {"kind": "retract", "speed_m_per_s": 1e-6, "end": "detach"}
]}
JSON
run samples --segments "$TMP/seg4.json"
segs=$(tail -n +2 "$TMP/out" | awk -F, 'BEGIN { ok = 1 } $6 < last { ok = 0 } { last = $6; n[$6]++ }
    END { print ok, n[0] + 0, (n[1] > 0), n[2] + 0, (n[3] > 0) }')
if [ "$rc" -eq 0 ] && [ "$segs" = "1 50 1 25 1" ]; then ok "samples --segments: 4 segments in order, labelled"
else bad "samples --segments" "exit $rc, '$segs'"; fi
# --out: the list run as a format 1.2 file ('vafm segments', segment = position, 'segment count' 4) that info
# lists, the checker passes and export writes back with the same samples as `vafm samples`
run run --segments "$TMP/seg4.json" --out "$TMP/seg4.h5" -q
run info "$TMP/seg4.h5"
if [ "$rc" -eq 0 ] && grep -q "^vafm format  1.2," "$TMP/out" && grep -q "^segments     4, every curve" "$TMP/out" &&
   grep -q "^   2 pause    0.01 s at constant force, 2500 Hz" "$TMP/out" &&
   grep -q "^conformance  ok" "$TMP/out"; then ok "run --segments --out: format 1.2, info lists the 4 segments, conformance ok"
else bad "run --segments --out" "exit $rc: $(grep -E 'format|segments|conformance' "$TMP/out" | head -5)"; fi
run samples --segments "$TMP/seg4.json" --csv "$TMP/seg4.csv"
run export "$TMP/seg4.h5" --curve 0 --csv "$TMP/seg4x.csv"
if [ "$rc" -eq 0 ] && cmp -s <(cut -d, -f1-2,6 "$TMP/seg4.csv") <(cut -d, -f1-2,6 "$TMP/seg4x.csv"); then
    ok "export of the list file: time, height and segment as vafm samples wrote them"
else bad "export of the list file" "exit $rc; $(diff <(cut -d, -f1-2,6 "$TMP/seg4.csv") <(cut -d, -f1-2,6 "$TMP/seg4x.csv") | head -3)"; fi
run run --out "$TMP/fd.h5" -q
run info "$TMP/fd.h5"
if [ "$rc" -eq 0 ] && grep -q "^vafm format  1.1," "$TMP/out" && ! grep -q "^segments" "$TMP/out"; then
    ok "run --out without a list: a format 1.1 file"
else bad "run --out" "exit $rc"; fi
# a tune runs no force curve: a segment list with it is a usage error (vafm run takes no --tune)
expect_fail "samples --tune --segments: excluded" 2 "--segments and --tune exclude each other" -- \
    samples --tune --segments "$TMP/seg4.json" --csv "$TMP/tuneseg.csv"
expect_fail "run --tune: not an option of vafm run" 2 "--tune does not apply" -- run --tune
printf '{"segments": [{"kind": "retract", "speed_m_per_s": 0, "distance_m": 1e-7}]}' >"$TMP/segbad.json"
expect_fail "--segments: a bad speed names the segment and field" 2 "segment 0" speed_m_per_s -- run --segments "$TMP/segbad.json"
printf '[{"kind": "extend", "sped": 1}]' >"$TMP/segbad.json"
expect_fail "--segments: an unknown key is named" 2 "segments[0].sped" -- run --segments "$TMP/segbad.json"
# a nonzero number that underflows reads as 0 (an extend's distance 0 is the approach limit): refused, as in
# scenes and vafmd; zero spelled 0e-400 is zero
printf '[{"kind": "extend", "speed_m_per_s": 1e-6, "distance_m": 1e-400,\n "trigger": {"channel": "force", "op": ">", "value": 1e-9}}]' >"$TMP/segbad.json"
expect_fail "--segments: 1e-400 underflows, named" 2 "segments.distance_m" "line 1: the number 1e-400 underflows" -- run --segments "$TMP/segbad.json"
printf '[{"kind": "extend", "speed_m_per_s": 1e-6, "distance_m": 0e-400,\n "trigger": {"channel": "force", "op": ">", "value": 1e-9, "relative": false}}]' >"$TMP/segok.json"
run run --segments "$TMP/segok.json"
if [ "$rc" -eq 0 ]; then ok "--segments: 0e-400 is zero"; else bad "--segments: 0e-400 is zero" "exit $rc: $(head -c 300 "$TMP/err")"; fi
# a list is costed as a scene's curve: a 1e4 s modulation at 10 kHz is refused before it runs
printf '[{"kind": "modulate", "duration_s": 1e4, "amplitude_m": 1e-9, "frequency_Hz": 100}]' >"$TMP/segbad.json"
expect_fail "--segments: a list beyond VAFM_SIM_MAX_SAMPLES is refused" 2 "segments[0].duration_s" VAFM_SIM_MAX_SAMPLES -- run --segments "$TMP/segbad.json"

harness_done
