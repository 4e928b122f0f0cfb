#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The files vafm writes open in the standard HDF5 tools (h5dump, h5ls) and pass
# a check that follows afmformats' HDF5 reader step by step (afmformats itself is not packaged for
# Debian): detection, metadata keys and their Python types, known columns, segment cast to bool, tip
# position convention. The reference file (written with raw HDF5 calls, no "time") is checked alike.
# Usage: test_h5_tools.sh PATH/TO/test_h5
set -u
T=$1
D=$(mktemp -d)
trap 'rm -rf "$D"' EXIT
pass=0
fail=0
ok() { pass=$((pass + 1)); }
bad() { echo "FAILED: $*" >&2; fail=$((fail + 1)); }
check() { if "$@" >/dev/null 2>&1; then ok; else bad "$*"; fi; }
has() { if grep -q -- "$2" "$1"; then ok; else bad "$1 lacks '$2'"; fi; }
hasnt() { if grep -q -- "$2" "$1"; then bad "$1 has '$2'"; else ok; fi; }

if ! "$T" --make-files "$D"; then
    echo "FAILED: test_h5 --make-files" >&2
    echo "0 passed, 1 failed"
    exit 1
fi

for f in vafm.h5 reference.h5; do
    check h5dump -H "$D/$f"
    h5dump -H "$D/$f" >"$D/$f.hdr" 2>&1
    h5ls -r "$D/$f" >"$D/$f.ls" 2>&1 && ok || bad "h5ls -r $f"
    has "$D/$f.ls" '^/0/force'
    has "$D/$f.ls" '^/0/segment'
    has "$D/$f.ls" '^/2/height\\ (piezo)'
    # every string is variable-length (fixed-length strings make afmformats miss the file)
    has "$D/$f.hdr" 'STRSIZE H5T_VARIABLE'
    hasnt "$D/$f.hdr" 'STRSIZE [0-9]'
    check h5dump -d "/1/force" "$D/$f"
done
has "$D/vafm.h5.hdr" 'ATTRIBUTE "vafm ground truth"'
has "$D/vafm.h5.hdr" 'ATTRIBUTE "vafm scene"'
has "$D/vafm.h5.hdr" 'DATASET "tip position"'
has "$D/vafm.h5.ls" '^/3/time'
hasnt "$D/reference.h5.ls" '/time'
h5dump -d /0/segment "$D/vafm.h5" >"$D/seg.txt" 2>&1 && ok || bad "h5dump segment"
has "$D/seg.txt" 'H5T_STD_U8LE'
h5dump -a "/vafm scene" "$D/vafm.h5" >"$D/scene.txt" 2>&1 && ok || bad "h5dump scene"
has "$D/scene.txt" 'k_N_per_m'
h5dump -A -d "/0/force" "$D/vafm.h5" >"$D/unit.txt" 2>&1 && ok || bad "h5dump unit"
has "$D/unit.txt" '"N"'

PY=""
for p in python3 /usr/bin/python3; do
    if command -v "$p" >/dev/null 2>&1 && "$p" -c 'import h5py, numpy' >/dev/null 2>&1; then
        PY=$p
        break
    fi
done
if [ -z "$PY" ]; then
    bad "afmformats-style check" "h5py or numpy missing (Debian: python3-h5py python3-numpy; .ci/deps.sh installs them)"
else
    for f in vafm.h5 reference.h5; do
        if "$PY" - "$D/$f" <<'EOF'; then ok; else bad "afmformats-style check of $f"; fi
import sys
import h5py
import numpy as np

# afmformats' metadata keys (meta.py META_FIELDS, force-distance) and their parsers' types
STR = {"feedback mode", "imaging mode", "instrument", "software", "software version", "curve id", "date",
       "format", "path", "session id", "time"}
FLOAT = {"sensitivity", "spring constant", "duration", "duration approach", "duration retract",
         "rate approach", "rate retract", "setpoint", "speed approach", "speed retract", "z range",
         "grid center x", "grid center y", "grid size x", "grid size y", "position x", "position y"}
INT = {"enum", "point count", "segment count", "grid index x", "grid index y", "grid shape x", "grid shape y"}
COLUMNS = {"force", "height (measured)", "height (piezo)", "index", "segment", "time", "tip position"}
UNITS = {"force": "N", "height (measured)": "m", "height (piezo)": "m", "segment": "", "time": "s",
         "tip position": "m"}

path = sys.argv[1]
with h5py.File(path, "r") as h5:
    # detect_hdf5
    assert "software" in h5.attrs and "software version" in h5.attrs, "root software attributes"
    assert isinstance(h5.attrs["software"], str), "root software is not str"
    assert "0" in h5, "no group 0"
    assert h5["0"].attrs["imaging mode"] == "force-distance", "imaging mode of group 0"
    # load_hdf5: every root key is an enum, every group attribute a known key of the right type
    for key in h5.keys():
        grp = h5[key]
        assert isinstance(grp, h5py.Group), key
        int(key)
        for k, v in grp.attrs.items():
            if k in STR:
                assert isinstance(v, str), f"{key}: {k} is {type(v)}"
            elif k in FLOAT:
                float(v)
                assert not isinstance(v, (str, bytes)), f"{key}: {k} is a string"
            elif k in INT:
                assert int(v) == v, f"{key}: {k} is not integral"
            else:
                raise AssertionError(f"{key}: unknown metadata key {k}")
        n = None
        for col, ds in grp.items():
            assert col in COLUMNS, f"{key}: unknown column {col}"
            assert ds.attrs["unit"] == UNITS[col], f"{key}/{col}: unit"
            data = ds[:]
            assert data.ndim == 1
            n = len(data) if n is None else n
            assert len(data) == n, f"{key}/{col}: length"
        if "point count" in grp.attrs:
            assert grp.attrs["point count"] == n, f"{key}: point count"
        seg = np.asarray(grp["segment"][:], dtype=bool)  # afmformats' cast
        assert seg.any() and (~seg).any(), f"{key}: no approach or no retract"
        if "tip position" in grp:
            k = grp.attrs["spring constant"]
            tip = grp["tip position"][:]
            want = grp["height (measured)"][:] + grp["force"][:] / k
            assert np.allclose(tip, want, rtol=1e-9, atol=0), f"{key}: tip position convention"
        if "time" in grp:
            t = grp["time"][:]
            assert t[0] >= 0 and np.all(np.diff(t) > 0), f"{key}: time"
print("afmformats-style check passed:", path)
EOF
    done
fi

echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
