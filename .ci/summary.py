#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Sum meson test results of one or more build directories and print 'N passed, N failed'.

Reads each build's meson-logs/testlog.json (one JSON object per test). A test counts as passed when
its result is OK; SKIP is counted apart (", N skipped", each named on stderr) and is not a pass: only a
feature the build was told to leave out skips (README: `study` under -Dstudy=disabled); a missing dependency
fails. Anything else (FAIL, TIMEOUT, ERROR, UNEXPECTEDPASS) counts as failed. Exit status 1 when anything
failed or no test ran at all.
"""
import json
import os
import sys

passed = failed = skipped = 0
for build in sys.argv[1:]:
    path = os.path.join(build, "meson-logs", "testlog.json")
    if not os.path.exists(path):
        print(f"{build}: no test log (did the build fail?)", file=sys.stderr)
        failed += 1
        continue
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line:
                continue
            t = json.loads(line)
            r = t.get("result")
            if r == "OK" or r == "EXPECTEDFAIL":
                passed += 1
            elif r == "SKIP":
                skipped += 1
                print(f"SKIPPED: {build}: {t.get('name')}", file=sys.stderr)
            else:
                failed += 1
                print(f"FAILED: {build}: {t.get('name')} ({r})", file=sys.stderr)
print(f"{passed} passed, {failed} failed" + (f", {skipped} skipped" if skipped else ""))
sys.exit(1 if failed or passed == 0 else 0)
