# SPDX-License-Identifier: MIT
"""A new output channel through the table alone (issue #25, docs/architecture.md "Recipe: a new output
channel"): $VAFMD is vafmd_channel_demo, a vafmd built with one extra row of src/core/channels.h
(VAFM_CHANNELS_EXTRA in src/daemon/meson.build): `test_time_s`, the sample times of the simulation under a
new name, streamed in every live run. No other source file knows it. It must appear in hello and run.start
after the table's other rows, in every data block, with the simulation's times (those of `vafm samples`, bit
for bit), and the other channels must stay what they were (bit for bit against `vafm samples`).

Needs $VAFMD (the demo build) and $VAFM_CLI (a missing one is a failure, not a skip)."""
import os
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "clients", "python"))
from vafm_client import Stream, spawn  # noqa: E402

VAFMD = os.environ.get("VAFMD")
VAFM_CLI = os.environ.get("VAFM_CLI")
for _var in ("VAFMD", "VAFM_CLI"):
    if not os.environ.get(_var):
        raise RuntimeError(f"{_var} is not set: run this module with meson test")

NAMES = ["height_m", "deflection_m", "force_N", "vDeflection_V", "tip_m", "test_time_s"]


def cli_samples(index):
    out = subprocess.run([VAFM_CLI, "samples", "--preset", "paper-fig4", "--index", str(index), "--csv", "-"],
                         check=True, capture_output=True, text=True).stdout
    lines = out.strip().split("\n")
    assert lines[0] == "time_s,height_m,deflection_m,force_N,tip_m,segment"
    return np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])  # %.17g reads back exactly


def test_dummy_channel_in_hello_run_start_and_blocks():
    d = spawn.Daemon(VAFMD, "--preset", "paper-fig4", "--free-run")
    try:
        c = d.client
        assert [ch["name"] for ch in c.hello()["channels"]] == NAMES
        assert c.hello()["channels"][-1] == {"name": "test_time_s", "unit": "s", "dtype": "<f8"}
        with Stream(d.pub) as s:
            r = c.curve(index=3)
            run = s.run(r["run_id"])
        assert run.complete and run.gaps == 0
        assert [ch["name"] for ch in run.start["channels"]] == NAMES
        assert all(h.n_channels == len(NAMES) for h in run.headers)
        ref = cli_samples(3)
        assert len(run["test_time_s"]) == ref.shape[0] == run.end["samples"]
        assert np.array_equal(run["test_time_s"], ref[:, 0])  # the simulation's clock, bit for bit
        for col, name in ((1, "height_m"), (2, "deflection_m"), (3, "force_N"), (4, "tip_m")):
            assert np.array_equal(run[name], ref[:, col]), name
    finally:
        assert d.stop() == 0
