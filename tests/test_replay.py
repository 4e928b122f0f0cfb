# SPDX-License-Identifier: MIT
"""End-to-end tests of `replay` (issue #6; protocol/wire.md, `replay`): recorded HDF5 curves streamed
through vafmd's live stream over real ZeroMQ sockets.

Each test starts its own daemon on ipc:// endpoints in a private temporary directory. The daemon path
comes from $VAFMD, the vafm CLI from $VAFM_CLI. Logged runs use paper-fig4 (~0.1 s per curve).
"""
import json
import os
import subprocess
import time

import numpy as np
import pytest
import zmq

import h5py  # noqa: E402

VAFMD = os.environ.get("VAFMD")
VAFM_CLI = os.environ.get("VAFM_CLI")
LIVE = ["height_m", "deflection_m", "force_N", "vDeflection_V", "tip_m"]

# Required, as .ci/deps.sh installs them and meson test sets the variables: a missing one fails the
# module with the reason, never skips it.
for _var in ("VAFMD", "VAFM_CLI"):
    if not os.environ.get(_var):
        raise RuntimeError(f"{_var} is not set: run this module with meson test (it sets VAFMD, VAFM_CLI)")

from vafmd_harness import HEADER, TIMEOUT_MS, Daemon, error_ok, fig4, reap_daemons  # noqa: E402,F401
from vafmd_harness import collect_run_timed as collect_run  # noqa: E402 (this file also times the blocks)


def arrays(start, blocks):
    """{channel name: concatenated samples} in the channel order of run.start."""
    names = [c["name"] for c in start["channels"]]
    for h, frames in blocks:
        assert h[8] == len(names) == len(frames), (h, names)
    return {n: np.concatenate([np.frombuffer(f[k], "<f8") for _, f in blocks]) for k, n in enumerate(names)}


def bits(a):
    return np.ascontiguousarray(a, dtype="<f8").view(np.uint64)


def log_curves(d, s, path, indices):
    """Log curves of the given indices to path; returns their live runs."""
    assert d.cmd({"cmd": "log", "path": str(path)})["status"] == "ok"
    runs = []
    for index in indices:
        rr = d.cmd({"cmd": "curve", "index": index})
        runs.append(collect_run(s, rr["run_id"]))
        d.wait_idle()
    st = d.cmd({"cmd": "log", "stop": True})
    assert st["log"]["curves"] == len(indices), st
    return runs


# ---- a vafm log replays bit for bit -------------------------------------------------------------------

def test_logged_run_replays_bit_for_bit(fig4, tmp_path):
    path = tmp_path / "log.h5"
    s = fig4.sub(greet=True)
    live = log_curves(fig4, s, path, [0, 3])[0]
    rr = fig4.cmd({"cmd": "replay", "path": str(path), "curves": "0", "client_run_id": "rp1"})
    assert rr["status"] == "ok", rr
    start, blocks, events, end, _, _ = collect_run(s, rr["run_id"])
    fig4.wait_idle()
    assert end["status"] == "ok" and end["kind"] == "replay", end
    assert start["kind"] == "replay" and start["replay"]["selection"] == [0]
    # a vafm log records the sensitivity (InvOLS, since 0.4), so vDeflection is streamed too; its time column
    # is streamed as time_s
    assert [c["name"] for c in start["channels"]] == ["height_m", "deflection_m", "force_N", "vDeflection_V",
                                                       "tip_m", "time_s"]
    assert start["sensitivity_m_per_V"] == live[0]["sensitivity_m_per_V"]
    assert start["sample_rate_Hz"] == live[0]["sample_rate_Hz"]
    assert start["block_samples"] == live[0]["block_samples"]
    assert start["scene"] == live[0]["scene"]  # the file's provenance: the scene at log start
    rp = start["replay"]
    assert rp["vafm"]["format_version"] == "1.1" and rp["vafm"]["seed"] == live[0]["scene"]["seed"]
    assert rp["software"] == "vafm" and rp["curves_in_file"] == 2 and rp["passes"] == 1
    c0 = rp["curves"][0]
    assert c0["attributes"]["spring constant"] == live[0]["scene"]["k_N_per_m"]
    assert c0["attributes"]["curve id"].startswith(f"run {live[0]['run_id']} index 0")
    assert c0["ground_truth"]["k_N_per_m"] == live[0]["scene"]["k_N_per_m"]
    assert c0["ground_truth"]["pulloff_sampled_N"] == live[3]["result"]["pulloff_sampled_N"]
    assert "replay" in fig4.cmd({"cmd": "hello"})["capabilities"]
    got, ref = arrays(start, blocks), arrays(live[0], live[1])
    assert end["samples"] == len(ref["force_N"])
    # bit for bit: height, force and tip position (the logged doubles themselves)
    for name in ("height_m", "force_N", "tip_m"):
        assert np.array_equal(bits(got[name]), bits(ref[name])), name
    # deflection = force / k: the daemon computed force = k·deflection in reduced units, so the quotient
    # is the original deflection up to two roundings: |Δ| ≤ 4 ulp (measured: ≤ 1 ulp, most exact)
    d_ulp = np.abs(bits(got["deflection_m"]).astype(np.int64) - bits(ref["deflection_m"]).astype(np.int64))
    assert d_ulp.max() <= 4, d_ulp.max()
    # the same blocks: sizes, first samples, segments and the LAST flag
    # (the replay has one channel more: the file's time column)
    assert [(h[6], h[7], h[9]) for h, _ in blocks] == [(h[6], h[7], h[9]) for h, _ in live[1]]
    assert all(h[8] == 6 for h, _ in blocks) and all(h[8] == 5 for h, _ in live[1])
    assert (blocks[-1][0][12] & 4) and (live[1][-1][0][12] & 4)
    # segment events at the same samples, plus one curve event
    seg = [(e["sample"], e["from"], e["to"]) for e in events if e["kind"] == "segment"]
    assert seg == [(e["sample"], e["from"], e["to"]) for e in live[2] if e["kind"] == "segment"]
    assert [e for e in events if e["kind"] == "curve"] == [
        {"run_id": rr["run_id"], "kind": "curve", "sample": 0, "curve": 0, "selection_index": 0, "pass": 0,
         "samples": len(ref["force_N"])}]
    # idempotent: the same client_run_id gives the same run back
    again = fig4.cmd({"cmd": "replay", "path": str(path), "client_run_id": "rp1"})
    assert again["duplicate"] is True and again["run_id"] == rr["run_id"]


# ---- pacing -------------------------------------------------------------------------------------------

def slow_bound(D):
    """The latest a paced run of duration D may end and still pass: never early is exact (the lower bound
    D); the late side only catches gross errors, whatever the machine's load (a run ignoring its speed of
    10, or paced at a tenth of it, fails)."""
    return 1.5 * D + 2.0


@pytest.mark.parametrize("speed,passes", [(1, 6), (10, 40)])
def test_pacing_follows_recorded_rate(tmp_path, speed, passes):
    """A logged curve replayed `passes` times: the last block is released at t_start + D/speed, where D
    is the recorded duration (n / sample rate per pass: a vafm file's time column is uniform). Pacing
    never releases a block early, so run.end's wall_s ≥ D/speed exactly. The late side depends on the
    machine's load (stalls of ~0.1-0.5 s seen on a loaded 2-core machine with the sanitizers), so it is
    bounded only against gross errors (SLOW_BOUND: a replay that ignored `speed` 10 fails it); how close to
    its deadlines a block leaves is measured by bench/bench_daemon.py, not asserted here (issue #18: a test
    must not depend on how busy the machine is)."""
    d = Daemon("--preset", "paper-fig4", "--free-run")
    try:
        s = d.sub(greet=True)
        path = tmp_path / "log.h5"
        log_curves(d, s, path, [1])
        with h5py.File(path, "r") as f:
            n, fs = len(f["0/force"]), f["0"].attrs["rate approach"]
        D = passes * n / fs / speed
        assert d.cmd({"cmd": "set", "values": {"free_run": False}})["status"] == "ok"
        t0 = time.monotonic()
        rr = d.cmd({"cmd": "replay", "path": str(path), "speed": speed, "loop": passes})
        t_reply = time.monotonic()
        start, blocks, events, end, t_first, t_last = collect_run(s, rr["run_id"])
        assert start["speed"] == speed and start["replay"]["passes"] == passes
        assert end["status"] == "ok" and end["samples"] == passes * n
        assert D <= end["wall_s"] <= slow_bound(D), (D, end["wall_s"])
        assert D - 0.05 <= t_last - t_reply <= slow_bound(D) + (t_reply - t0), (D, t_last - t_reply)
        assert not any(h[12] & 8 for h, _ in blocks)  # paced, not FREE_RUN
        # one curve event per pass, at the pass boundaries
        assert [(e["sample"], e["pass"]) for e in events if e["kind"] == "curve"] == [(p * n, p) for p in range(passes)]
    finally:
        assert d.stop() == 0


# ---- files of other programs ----------------------------------------------------------------------------

UNITS = {"force": "N", "height (measured)": "m", "height (piezo)": "m", "segment": "", "time": "s",
         "tip position": "m"}


def write_curve(f, i, chans, attrs):
    """One curve group of the layout (protocol/hdf5.md), written with h5py as another program would."""
    g = f.create_group(str(i))
    for name, data in chans.items():
        ds = g.create_dataset(name, data=data)
        ds.attrs["unit"] = UNITS[name]
    for k, v in attrs.items():
        g.attrs[k] = v
    return g


def instrument_curve(rng, n_app, n_ret, k, nan_at=None):
    """A JPK-like curve: piezo ramp down and up, a linear contact region, noise; no time column."""
    z = np.concatenate([np.linspace(1e-6, -2e-7, n_app), np.linspace(-2e-7, 1e-6, n_ret)])
    force = np.where(z < 0, -k * z, 0.0) + 2e-11 * rng.standard_normal(z.size)
    if nan_at is not None:
        force[nan_at] = np.nan  # a dropped ADC sample, as exported
    seg = np.concatenate([np.zeros(n_app, np.uint8), np.ones(n_ret, np.uint8)])
    hm = z + 1e-10 * rng.standard_normal(z.size)  # a real height sensor differs from the piezo command
    return {"force": force, "height (measured)": hm, "height (piezo)": z, "segment": seg}


def test_instrument_file_without_time_or_provenance(tmp_path):
    """Curves of different lengths, JPK-like metadata (sensitivity, different approach and retract
    rates, afmformats' `enum`/`path` keys), no time column, no tip position, no vafm provenance, a NaN."""
    path = tmp_path / "jpk.h5"
    rng = np.random.default_rng(7)
    k, sens, ra, rr = 0.062, 41.3e-9, 2000.0, 1000.0
    lengths = [(600, 400), (250, 150), (900, 700)]
    curves = []
    with h5py.File(path, "w") as f:
        f.attrs["software"] = "afmformats"
        f.attrs["software version"] = "0.18.0"
        for i, (na, nr) in enumerate(lengths):
            ch = instrument_curve(rng, na, nr, k, nan_at=123 if i == 1 else None)
            write_curve(f, i, ch, {
                "imaging mode": "force-distance", "spring constant": k, "sensitivity": sens,
                "rate approach": ra, "rate retract": rr, "speed approach": 1e-6, "speed retract": 1e-6,
                "point count": na + nr, "segment count": 2, "setpoint": 5e-9, "feedback mode": "contact",
                "instrument": "JPK NanoWizard 4", "software": "JPK", "software version": "6.1.163",
                "date": "2023-04-17", "time": "14:03:22.5", "position x": 1e-6 * i, "position y": 0.0,
                "enum": i, "path": "/data/cell1.jpk-force-map"})
            curves.append(ch)
    d = Daemon("--free-run")
    try:
        s = d.sub(greet=True)
        rr_ = d.cmd({"cmd": "replay", "path": str(path), "curves": "2,0-1"})
        assert rr_["status"] == "ok", rr_
        start, blocks, events, end, _, _ = collect_run(s, rr_["run_id"])
        assert end["status"] == "ok" and end["kind"] == "replay", end
        # channels the file lacks (tip position, time) are absent; deflection and vDeflection derived
        assert [c["name"] for c in start["channels"]] == ["height_m", "deflection_m", "force_N", "vDeflection_V"]
        rp = start["replay"]
        assert "scene" not in start and rp["vafm"] is None and rp["software"] == "afmformats"
        assert rp["selection"] == [2, 0, 1] and rp["curves_in_file"] == 3 and rp["time_column"] is False
        assert start["sample_rate_Hz"] == ra and start["sensitivity_m_per_V"] == sens
        c0 = rp["curves"][0]
        assert c0["curve"] == 2 and c0["samples"] == 1600 and "ground_truth" not in c0
        assert c0["attributes"]["instrument"] == "JPK NanoWizard 4" and c0["attributes"]["sensitivity"] == sens
        assert c0["attributes"]["rate retract"] == rr and "enum" not in c0["attributes"]
        got = arrays(start, blocks)
        order = [2, 0, 1]
        force = np.concatenate([curves[i]["force"] for i in order])
        height = np.concatenate([curves[i]["height (piezo)"] for i in order])
        assert np.array_equal(bits(got["force_N"]), bits(force))  # NaN included, bit for bit
        assert np.array_equal(bits(got["height_m"]), bits(height))  # the piezo height, not the sensor's
        # derived as documented, the same IEEE operations: bit for bit (NaN stays NaN)
        assert np.array_equal(bits(got["deflection_m"]), bits(force / k))
        assert np.array_equal(bits(got["vDeflection_V"]), bits(force / k / sens))
        nan_at = 1600 + 1000 + 123  # curve 1 comes third
        assert np.isnan(got["force_N"]).sum() == 1 and np.isnan(got["force_N"][nan_at])
        assert np.isnan(got["deflection_m"][nan_at]) and np.isnan(got["vDeflection_V"][nan_at])
        assert [(e["sample"], e["curve"], e["selection_index"]) for e in events if e["kind"] == "curve"] == [
            (0, 2, 0), (1600, 0, 1), (2600, 1, 2)]
        # segments: approach → retract inside each curve, retract → approach at the curve boundaries
        seg = [(e["sample"], e["to"]) for e in events if e["kind"] == "segment"]
        assert seg == [(900, "retract"), (1600, "approach"), (2200, "retract"), (2600, "approach"),
                       (2850, "retract")]

        # paced by the rate attributes (approach 2 kHz, retract 1 kHz): curve 1 alone lasts
        # 250/2000 + 150/1000 = 0.275 s; at speed 5 (and a 2-pass loop) 0.11 s
        assert d.cmd({"cmd": "set", "values": {"free_run": False}})["status"] == "ok"
        r2 = d.cmd({"cmd": "replay", "path": str(path), "curves": [1], "speed": 5, "loop": 2})
        start, blocks, events, end, _, _ = collect_run(s, r2["run_id"])
        D = 2 * (250 / ra + 150 / rr) / 5
        assert start["replay"]["duration_per_pass_s"] == pytest.approx(250 / ra + 150 / rr, rel=1e-12)  # at 1×
        assert end["samples"] == 800 and D <= end["wall_s"] <= slow_bound(D), (D, end["wall_s"])
    finally:
        assert d.stop() == 0


def test_non_uniform_time_streamed_with_timestamps(tmp_path):
    """A time column with two sample intervals (approach every 1 ms, retract every 4 ms): samples are
    streamed as recorded with their times in the time_s channel, and blocks are paced by those times:
    the approach (first 500 samples) takes 0.5 s of the 2.5 s recording, not half of it."""
    path = tmp_path / "nonuniform.h5"
    na = nr = 500
    t = np.concatenate([0.5e-3 + 1e-3 * np.arange(na), 0.5e-3 + na * 1e-3 + 4e-3 * np.arange(nr)])
    ch = instrument_curve(np.random.default_rng(3), na, nr, 0.1)
    ch["time"] = t
    ch["tip position"] = ch["height (measured)"] + ch["force"] / 0.1
    with h5py.File(path, "w") as f:
        f.attrs["software"] = "labview-export"
        f.attrs["software version"] = "1"
        write_curve(f, 0, ch, {"imaging mode": "force-distance", "spring constant": 0.1})  # no rates, no sensitivity
    d = Daemon()
    try:
        s = d.sub(greet=True)
        speed = 10
        rr = d.cmd({"cmd": "replay", "path": str(path), "speed": speed})
        assert rr["status"] == "ok", rr
        start, blocks, events, end, t_first, t_last = collect_run(s, rr["run_id"])
        assert [c["name"] for c in start["channels"]] == ["height_m", "deflection_m", "force_N", "tip_m", "time_s"]
        assert start["replay"]["time_column"] is True
        got = arrays(start, blocks)
        assert np.array_equal(bits(got["time_s"]), bits(t))
        assert np.array_equal(bits(got["tip_m"]), bits(ch["tip position"]))
        # nominal rate from the mean interval: (n − 1) / (t_last − t_first)
        assert start["sample_rate_Hz"] == pytest.approx((na + nr - 1) / (t[-1] - t[0]), rel=1e-12)
        # recorded span + one mean interval, at speed 10
        mean_dt = (t[-1] - t[0]) / (na + nr - 1)
        D = (t[-1] - t[0] + mean_dt) / speed
        assert D <= end["wall_s"] <= slow_bound(D), (D, end["wall_s"])
        # the block holding sample 499 (the approach's last) is released 0.5 s / 10 = 50 ms after the
        # run start, never earlier (uniform pacing would give 125 ms): on the client's clock, from the
        # reply, in [45, 100) ms -- the upper bound only if the daemon did not flag the block LATE
        t_recv = {}
        # re-run, timing every block on arrival
        t_before = time.monotonic()  # the run cannot start earlier: a strict lower bound
        rr = d.cmd({"cmd": "replay", "path": str(path), "speed": speed})
        t_sent = time.monotonic()  # after the reply: the run started before it (the upper bound)
        while True:
            assert s.poll(TIMEOUT_MS)
            parts = s.recv_multipart()
            if parts[0] == b"data":
                h = HEADER.unpack(parts[1])
                t_recv[h[6]] = (time.monotonic(), h[7], h[12])
            if parts[0] == b"run.end":
                break
        approach_end, flags = next((tm, fl) for first, (tm, n, fl) in sorted(t_recv.items()) if first + n >= na)
        assert 0.045 <= approach_end - t_before, approach_end - t_before
        assert approach_end - t_sent < 0.1 or flags & 1, approach_end - t_sent
    finally:
        assert d.stop() == 0


# ---- damaged and non-conforming files, bad arguments -----------------------------------------------------

def minimal_file(path, mutate=None):
    """A valid one-curve file; mutate(group) breaks it."""
    ch = instrument_curve(np.random.default_rng(1), 30, 20, 0.1)
    with h5py.File(path, "w") as f:
        f.attrs["software"] = "test"
        f.attrs["software version"] = "0"
        g = write_curve(f, 0, ch, {"imaging mode": "force-distance", "spring constant": 0.1, "rate approach": 1e3,
                                   "rate retract": 1e3})
        if mutate:
            mutate(g)
    return path


def test_damaged_files_refused_and_daemon_stays_up(fig4, tmp_path):
    s = fig4.sub(greet=True)
    logged = tmp_path / "log.h5"
    log_curves(fig4, s, logged, [2])
    size = logged.stat().st_size
    cases = []
    # truncated: the tail of a vafm log is cut off (a copy interrupted, a full disk)
    for frac in (0.5, 0.9):
        p = tmp_path / f"trunc{frac}.h5"
        p.write_bytes(logged.read_bytes()[:int(size * frac)])
        cases.append((p, "bad_file", None))
    # not HDF5 at all
    p = tmp_path / "text.h5"
    p.write_text("force,height\n1,2\n")
    cases.append((p, "bad_file", "not an HDF5 file"))
    # a required dataset is missing
    cases.append((minimal_file(tmp_path / "noforce.h5", lambda g: g.__delitem__("force")), "bad_file", "force"))
    cases.append((minimal_file(tmp_path / "noseg.h5", lambda g: g.__delitem__("segment")), "bad_file", "segment"))

    # wrong dtype: force stored as strings, segment labels as floats
    def strforce(g):
        del g["force"]
        g.create_dataset("force", data=np.array([b"1.0"] * 50)).attrs["unit"] = "N"

    def floatseg(g):
        del g["segment"]
        g.create_dataset("segment", data=np.zeros(50)).attrs["unit"] = ""
    cases.append((minimal_file(tmp_path / "strforce.h5", strforce), "bad_file", "float64"))
    cases.append((minimal_file(tmp_path / "floatseg.h5", floatseg), "bad_file", "uint8"))
    # channels of different lengths; a time column that goes backwards; no way to tell the sample rate
    def short(g):
        del g["height (piezo)"]
        g.create_dataset("height (piezo)", data=np.zeros(49)).attrs["unit"] = "m"
    cases.append((minimal_file(tmp_path / "short.h5", short), "bad_file", "samples"))
    cases.append((minimal_file(tmp_path / "backwards.h5", lambda g: g.create_dataset(
        "time", data=np.r_[np.arange(25), np.arange(25)] * 1e-3).attrs.__setitem__("unit", "s")), "bad_file", "time"))

    def norate(g):
        del g.attrs["rate approach"]
        del g.attrs["rate retract"]
    cases.append((minimal_file(tmp_path / "norate.h5", norate), "bad_file", "sample rate"))
    cases.append((minimal_file(tmp_path / "badk.h5", lambda g: g.attrs.__setitem__("spring constant", -1.0)),
                  "bad_file", "spring constant"))
    cases.append((tmp_path / "missing.h5", "io_error", "cannot open"))
    for p, code, words in cases:
        r = fig4.cmd({"cmd": "replay", "path": str(p)})
        error_ok(r, code, "path")
        assert str(p) in r["message"], r  # names the file
        if words:
            assert words in r["message"], r
    # bad arguments
    ok = minimal_file(tmp_path / "ok.h5")
    error_ok(fig4.cmd({"cmd": "replay"}), "missing_field", "path")
    error_ok(fig4.cmd({"cmd": "replay", "path": 3}), "wrong_type", "path")
    error_ok(fig4.cmd({"cmd": "replay", "path": str(ok), "curves": "1"}), "out_of_range", "curves")
    error_ok(fig4.cmd({"cmd": "replay", "path": str(ok), "curves": "0,x"}), "out_of_range", "curves")
    error_ok(fig4.cmd({"cmd": "replay", "path": str(ok), "curves": [0, -1]}), "out_of_range", "curves")  # a negative group number (wire.md §2.2)
    error_ok(fig4.cmd({"cmd": "replay", "path": str(ok), "speed": 0}), "out_of_range", "speed")
    error_ok(fig4.cmd({"cmd": "replay", "path": str(ok), "loop": 0}), "out_of_range", "loop")
    error_ok(fig4.cmd({"cmd": "replay", "path": str(ok), "loop": "always"}), "wrong_type", "loop")
    error_ok(fig4.cmd({"cmd": "replay", "path": str(ok), "index": 1}), "unknown_field", "index")
    # the daemon is up and replays a good file
    st = fig4.cmd({"cmd": "status"})
    assert st["status"] == "ok" and st["state"] == "idle"
    rr = fig4.cmd({"cmd": "replay", "path": str(ok), "curves": [0, 0]})
    start, blocks, events, end, _, _ = collect_run(s, rr["run_id"])
    assert end["status"] == "ok" and end["samples"] == 100


def test_byte_flips_refused_or_replayed(fig4, tmp_path):
    """30 copies of a vafm log with one random bit flipped each (fixed seed): each replay either streams
    (a flip outside checksummed metadata and channels) or is refused with bad_file (with this seed: 1
    streams, 29 are refused); the daemon survives all of them."""
    s = fig4.sub(greet=True)
    logged = tmp_path / "log.h5"
    log_curves(fig4, s, logged, [5])
    data = bytearray(logged.read_bytes())
    rng = np.random.default_rng(2024)
    outcomes = {"ok": 0, "bad_file": 0}
    for i in range(30):
        b = bytearray(data)
        for pos in rng.integers(0, len(b), 1):
            b[pos] ^= 1 << int(rng.integers(0, 8))
        p = tmp_path / f"flip{i}.h5"
        p.write_bytes(bytes(b))
        r = fig4.cmd({"cmd": "replay", "path": str(p)})
        if r["status"] == "ok":
            *_, end, _, _ = collect_run(s, r["run_id"])
            assert end["status"] == "ok", end
            fig4.wait_idle()
            outcomes["ok"] += 1
        else:
            error_ok(r, "bad_file", "path")
            outcomes["bad_file"] += 1
    assert outcomes["bad_file"] > 0, outcomes
    assert fig4.cmd({"cmd": "status"})["state"] == "idle"


def test_selection_over_memory_bound_refused(fig4, tmp_path):
    """The whole selection is held in memory: more than 2^21 samples is refused before streaming."""
    path = tmp_path / "big.h5"
    n = 1_100_000
    with h5py.File(path, "w") as f:
        f.attrs["software"] = "test"
        f.attrs["software version"] = "0"
        g = f.create_group("0")
        for name, dt in (("force", "<f8"), ("height (measured)", "<f8"), ("height (piezo)", "<f8"), ("segment", "u1")):
            g.create_dataset(name, shape=(n,), dtype=dt, compression="gzip", fillvalue=0).attrs["unit"] = UNITS[name]
            g[name][:] = 0
        g.attrs["imaging mode"] = "force-distance"
        g.attrs["rate approach"] = 1e5
    r = fig4.cmd({"cmd": "replay", "path": str(path), "curves": [0, 0]})
    error_ok(r, "out_of_range", "curves")
    assert "2097152" in r["message"], r
    assert fig4.cmd({"cmd": "status"})["state"] == "idle"


def vm_hwm_kib(pid):
    """Peak resident memory of a process (VmHWM of /proc/pid/status), KiB."""
    with open(f"/proc/{pid}/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmHWM:"))


def attr_file(path, attrs, root_software="test"):
    """A one-curve file whose curve group carries these string attributes (libver latest: attributes over
    64 KiB are stored densely, as h5py does for them)."""
    ch = instrument_curve(np.random.default_rng(2), 30, 20, 0.1)
    with h5py.File(path, "w", libver="latest") as f:
        f.attrs["software"] = root_software
        f.attrs["software version"] = "0"
        write_curve(f, 0, ch, {"imaging mode": "force-distance", "spring constant": 0.1, "rate approach": 1e3,
                               "rate retract": 1e3, **attrs})
    return path


def test_hostile_attributes_bounded(fig4, tmp_path):
    """Issue #29 item 5: 0.6.2 copied each curve's attributes into run.start once per selection entry; a
    1 MiB 'software' attribute with "curves": [0]*512 took vafmd to 1.55 GB and held its control loop 35 s.
    An attribute over 64 KiB is refused, so is a selection whose attributes take more than 8 MiB in
    run.start (out_of_range, naming the field and the limit), each at once; a repetition is read once."""
    s = fig4.sub(greet=True)
    hwm0 = vm_hwm_kib(fig4.proc.pid)
    big = attr_file(tmp_path / "big.h5", {"software": "x" * (1 << 20)})
    t0 = time.monotonic()
    r = fig4.cmd({"cmd": "replay", "path": str(big), "curves": [0] * 512})
    dt = time.monotonic() - t0
    error_ok(r, "out_of_range", "path")
    assert "'software'" in r["message"] and "65536" in r["message"], r
    assert dt < 2.0, dt
    root = attr_file(tmp_path / "root.h5", {}, root_software="y" * 70000)
    r = fig4.cmd({"cmd": "replay", "path": str(root)})
    error_ok(r, "out_of_range", "path")
    assert "root attribute 'software'" in r["message"] and "70000" in r["message"], r
    # eight string attributes of 65 000 characters (imaging mode stays "force-distance"): 520 000 bytes and
    # some encoded an entry; 17 entries pass 8 MiB
    names = ["feedback mode", "instrument", "software", "software version", "date", "time", "session id",
             "curve id"]
    wide = attr_file(tmp_path / "wide.h5", {k: chr(97 + i) * 65000 for i, k in enumerate(names)})
    t0 = time.monotonic()
    r = fig4.cmd({"cmd": "replay", "path": str(wide), "curves": [0] * 512})
    dt = time.monotonic() - t0
    error_ok(r, "out_of_range", "curves")
    assert "8388608" in r["message"] and "entry 16," in r["message"], r
    assert dt < 2.0, dt
    # 16 entries (8.3 MB) are streamed; every entry carries the curve's attributes
    rr = fig4.cmd({"cmd": "replay", "path": str(wide), "curves": [0] * 16})
    assert rr["status"] == "ok", rr
    start, blocks, events, end, _, _ = collect_run(s, rr["run_id"])
    fig4.wait_idle()
    assert end["status"] == "ok", end
    cs = start["replay"]["curves"]
    assert len(cs) == 16 and all(c["attributes"] == cs[0]["attributes"] for c in cs), len(cs)
    assert cs[0]["attributes"]["instrument"] == "b" * 65000
    a = arrays(start, blocks)
    assert a["force_N"].size == 16 * 50 and np.array_equal(bits(a["force_N"][:50]), bits(a["force_N"][-50:]))
    grown_mib = (vm_hwm_kib(fig4.proc.pid) - hwm0) / 1024
    assert grown_mib < 300, grown_mib
    assert fig4.cmd({"cmd": "status"})["state"] == "idle"


def test_loop_forever_until_abort_and_busy(fig4, tmp_path):
    path = minimal_file(tmp_path / "ok.h5")
    assert fig4.cmd({"cmd": "set", "values": {"free_run": False}})["status"] == "ok"
    s = fig4.sub(greet=True)
    assert fig4.cmd({"cmd": "log", "path": str(tmp_path / "log.h5")})["status"] == "ok"  # replays are not logged
    rr = fig4.cmd({"cmd": "replay", "path": str(path), "loop": "forever", "speed": 10})  # 50 ms a pass at 1000 Hz
    assert rr["status"] == "ok", rr
    error_ok(fig4.cmd({"cmd": "curve"}), "state", "cmd")  # one run at a time
    error_ok(fig4.cmd({"cmd": "replay", "path": str(path)}), "state", "cmd")
    passes = set()
    while len(passes) < 4:
        assert s.poll(TIMEOUT_MS)
        parts = s.recv_multipart()
        if parts[0] == b"event":
            e = json.loads(parts[1])
            if e["kind"] == "curve":
                passes.add(e["pass"])
    assert fig4.cmd({"cmd": "status"})["state"] == "running"
    assert fig4.cmd({"cmd": "abort"})["status"] == "ok"
    *_, end, _, _ = collect_run(s, rr["run_id"])
    assert end["status"] == "aborted" and end["kind"] == "replay" and end["samples"] >= 4 * 50 - 50
    fig4.wait_idle()
    log = fig4.cmd({"cmd": "log", "stop": True})["log"]
    assert (log["curves"], log["curves_skipped"], log["curves_dropped"]) == (0, 0, 0), log


# ---- the CLI ----------------------------------------------------------------------------------------------

def test_cli_replay_end_to_end(fig4, tmp_path):
    s = fig4.sub(greet=True)
    path = tmp_path / "log.h5"
    runs = log_curves(fig4, s, path, [4, 6])
    # a relative path from the CLI's working directory: the CLI makes it absolute for the daemon
    p = subprocess.run([VAFM_CLI, "replay", "log.h5", "--curves", "1-", "--speed", "2", "--loop", "2",
                        "--client-run-id", "cli-1", "--endpoint", fig4.rep, "--wait", "--pub", fig4.pub],
                       capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert p.returncode == 0, p.stdout + p.stderr
    reply, cli_end = map(json.loads, p.stdout.splitlines())  # --wait: the reply, then the run's run.end
    assert reply["status"] == "ok" and reply["client_run_id"] == "cli-1", reply
    assert cli_end["run_id"] == reply["run_id"] and cli_end["status"] == "ok" and cli_end["kind"] == "replay"
    start, blocks, events, end, _, _ = collect_run(s, reply["run_id"])
    assert start["replay"]["path"] == str(path) and start["replay"]["selection"] == [1]
    assert start["speed"] == 2 and start["replay"]["passes"] == 2
    ref = arrays(runs[1][0], runs[1][1])["force_N"]
    assert np.array_equal(bits(arrays(start, blocks)["force_N"]), bits(np.r_[ref, ref]))
    assert end["status"] == "ok"
    fig4.wait_idle()
    # a daemon error: exit 1, the reply on stdout, the message on stderr
    p = subprocess.run([VAFM_CLI, "replay", str(tmp_path / "nope.h5"), "--endpoint", fig4.rep],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 1 and json.loads(p.stdout)["code"] == "io_error" and "nope.h5" in p.stderr, p
    # usage errors: exit 2
    for args in ([], ["a.h5", "--speed", "fast"], ["a.h5", "--bogus"], ["a.h5", "b.h5"]):
        p = subprocess.run([VAFM_CLI, "replay", *args], capture_output=True, text=True, timeout=60)
        assert p.returncode == 2 and "usage" in p.stderr, (args, p)


def test_cli_listen_records_a_replay_to_csv(tmp_path):
    """`vafm listen` records a replay of an instrument file: the channels the file lacks (tip position)
    are empty cells, the others equal the file's values bit for bit (%.17g round-trips a double), and the
    time column is the file's own (non-uniform here)."""
    path = tmp_path / "inst.h5"
    rng = np.random.default_rng(11)
    k, sens = 0.05, 40e-9
    ch = instrument_curve(rng, 300, 200, k)
    t = np.cumsum(rng.uniform(0.5e-4, 1.5e-4, 500))
    t -= t[0]  # hdf5.md L13: starts at 0, strictly increasing
    ch["time"] = t
    with h5py.File(path, "w") as f:
        f.attrs["software"], f.attrs["software version"] = "an instrument", "1.0"
        write_curve(f, 0, ch, {"imaging mode": "force-distance", "spring constant": k, "sensitivity": sens})
    d = Daemon("--free-run")
    out = tmp_path / "rec.csv"
    listen = subprocess.Popen([VAFM_CLI, "listen", "--endpoint", d.rep, "--pub", d.pub, "--out", str(out)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        t_end = time.monotonic() + 20
        line = ""
        while "subscribed" not in line:  # the subscription is in place once listen says so
            assert time.monotonic() < t_end and listen.poll() is None, listen.communicate()
            line = listen.stderr.readline()
        time.sleep(0.2)  # its XPUB subscription reaches the daemon
        r = d.cmd({"cmd": "replay", "path": str(path)})
        assert r["status"] == "ok", r
        _, err = listen.communicate(timeout=30)
        assert listen.returncode == 0, err
    finally:
        if listen.poll() is None:
            listen.kill()
        assert d.stop() == 0
    rows = out.read_text().splitlines()
    assert rows[0] == "time_s,height_m,deflection_m,force_N,tip_m,segment,vDeflection_V,run_id"
    cells = [row.split(",") for row in rows[1:]]
    assert len(cells) == 500
    col = {name: i for i, name in enumerate(rows[0].split(","))}
    num = lambda name: np.array([float(c[col[name]]) for c in cells])  # noqa: E731
    assert all(c[col["tip_m"]] == "" for c in cells)  # absent from the file, so from the stream
    assert np.array_equal(bits(num("time_s")), bits(t))
    assert np.array_equal(bits(num("force_N")), bits(ch["force"]))
    assert np.array_equal(bits(num("height_m")), bits(ch["height (piezo)"]))
    assert np.array_equal(bits(num("deflection_m")), bits(ch["force"] / k))
    assert np.array_equal(bits(num("vDeflection_V")), bits(ch["force"] / k / sens))
    assert [int(c[col["segment"]]) for c in cells] == list(ch["segment"])


def test_selection_by_group_name_gapped_float32(fig4, tmp_path):
    """Curves are named by their group number everywhere (issue #18): an afmformats export whose groups are
    "1" and "5" (float32 data, widened exactly) replays as [5, 1]; run.start's selection and the curve events
    say the same numbers; a group the file lacks is refused naming the file's groups."""
    path = tmp_path / "gapped.h5"
    rng = np.random.default_rng(3)
    chans = {}
    with h5py.File(path, "w") as f:
        f.attrs["software"] = "afmformats"
        f.attrs["software version"] = "0.18.0"
        for g, n in ((1, 40), (5, 60)):
            ch = instrument_curve(rng, n, n // 2, 0.05)
            ch = {k: (v.astype(np.float32) if v.dtype == np.float64 else v) for k, v in ch.items()}
            chans[g] = ch
            write_curve(f, g, ch, {"imaging mode": "force-distance", "spring constant": 0.05, "rate approach": 1e3,
                                   "rate retract": 1e3})
    s = fig4.sub(greet=True)
    r = fig4.cmd({"cmd": "replay", "path": str(path), "curves": [5, 1]})
    assert r["status"] == "ok", r
    start, blocks, events, end, _, _ = collect_run(s, r["run_id"])
    assert end["status"] == "ok" and start["replay"]["selection"] == [5, 1]
    assert [c["curve"] for c in start["replay"]["curves"]] == [5, 1]
    assert [e["curve"] for e in events if e["kind"] == "curve"] == [5, 1]
    force = arrays(start, blocks)["force_N"]
    want = np.r_[chans[5]["force"].astype(np.float64), chans[1]["force"].astype(np.float64)]
    assert np.array_equal(bits(force), bits(want))  # float32 widened exactly
    fig4.wait_idle()
    r = fig4.cmd({"cmd": "replay", "path": str(path), "curves": "1-"})
    assert r["status"] == "ok", r
    start, _, _, end, _, _ = collect_run(s, r["run_id"])
    assert start["replay"]["selection"] == [1, 5] and end["status"] == "ok"
    fig4.wait_idle()
    for bad in ([0], [2], "2-4"):
        r = fig4.cmd({"cmd": "replay", "path": str(path), "curves": bad})
        error_ok(r, "out_of_range", "curves")
        assert "1 to 5" in r["message"], r
    assert fig4.cmd({"cmd": "status"})["state"] == "idle"
