# SPDX-License-Identifier: MIT
"""One list of output channels (issue #25): src/core/channels.h declares them; everything that lists them
again must say the same. Checked against the table: the Python client's CHANNELS (the rows every live run
streams), hello's and run.start's channel lists (names, units, dtype, in the table's order), the CSV header of
`vafm samples` and `vafm export`, `vafm listen`'s CSV header, and protocol/wire.md's channel table.

Needs $VAFMD and $VAFM_CLI (a missing one is a failure, not a skip)."""
import json
import os
import re
import subprocess
import sys

from vafmd_harness import ROOT, VAFM_CLI, VAFMD, Daemon, read, reap_daemons  # noqa: F401

sys.path.insert(0, os.path.join(ROOT, "clients", "python"))


def table():
    """[dict(id, name, unit, file, kind, flags, csv, field)] of core/channels.h, in row order."""
    text = read("src", "core", "channels.h")
    body = text[text.index("#define VAFM_CHANNELS(X)"):text.index("VAFM_CHANNELS_EXTRA(X)\n/* clang-format on */")]
    rows = re.findall(r'X\((\w+),\s*"(\w+)",\s*"(\w*)",\s*(NULL|"[^"]*"),\s*VAFM_CHK_(\w+),\s*VAFM_CHF_(\w+),'
                      r'\s*(\d+),\s*(\w+)\)', body)
    assert len(rows) == body.count("X(") and len(rows) >= 7, "a row of channels.h does not parse"
    out = [dict(id=r[0], name=r[1], unit=r[2], file=None if r[3] == "NULL" else r[3].strip('"'), kind=r[4],
                flags=r[5], csv=int(r[6]), field=r[7]) for r in rows]
    assert len({r["name"] for r in out}) == len(out)
    return out


ROWS = table()
LIVE = [r for r in ROWS if r["flags"] == "LIVE"]


def test_environment():
    assert VAFMD and os.access(VAFMD, os.X_OK), "set VAFMD to the vafmd executable"
    assert VAFM_CLI and os.access(VAFM_CLI, os.X_OK), "set VAFM_CLI to the vafm executable"


def test_python_client_channels():
    from vafm_client import client
    assert list(client.CHANNELS) == [r["name"] for r in LIVE]


def test_hello_and_run_start_lists():
    d = Daemon()
    try:
        got = d.cmd({"cmd": "hello"})["channels"]
        assert got == [{"name": r["name"], "unit": r["unit"], "dtype": "<f8"} for r in LIVE], got
    finally:
        d.stop()


def csv_head(last):
    cells = {r["csv"]: r["name"] for r in ROWS if r["csv"]}
    cells[6] = "segment"
    return ",".join(cells[c] for c in range(1, last + 1))


def test_samples_csv_header(tmp_path):
    out = subprocess.run([VAFM_CLI, "samples", "--csv", "-", "--z_range_m=2e-8"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines()[0] == csv_head(6)
    out = subprocess.run([VAFM_CLI, "samples", "--csv", "-", "--piezo_hysteresis=0.1"], capture_output=True,
                         text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines()[0] == csv_head(7)


def test_wire_md_channel_table():
    wire = read("protocol", "wire.md")
    for r in ROWS:
        if r["flags"] in ("LIVE", "OPTIONAL", "REPLAY", "OPTIN"):
            assert "`" + r["name"] + "`" in wire, r["name"]


def test_wire_md_units():
    """wire.md §3.1's channel table gives each channel the table's unit."""
    wire = read("protocol", "wire.md")
    sec = wire[wire.index("### 3.1 Data blocks"):wire.index("#### 3.1.1")]
    units = {r["name"]: r["unit"] for r in ROWS}
    rows = re.findall(r"^\| \d+ \| `(\w+)` \| (\w+) \|", sec, flags=re.M)
    assert len(rows) >= 7
    for name, unit in rows:
        assert units.get(name) == unit, (name, unit)


def test_file_datasets():
    """Each channel's file dataset is one of the HDF5 layer's (src/h5/h5_common.c), in the same unit."""
    text = read("src", "h5", "h5_common.c")
    body = text[text.index("vafm_h5i_chans[VAFM_H5I_NCHAN] = {"):]
    h5 = dict(re.findall(r'\{ "([^"]+)", "(\w*)", \d, offsetof', body[:body.index("};")]))
    assert "segment" in h5 and len(h5) >= 6, h5
    for r in ROWS:
        if r["file"] is not None:
            assert h5.get(r["file"]) == r["unit"], (r["name"], r["file"], h5)
