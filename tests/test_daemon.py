# SPDX-License-Identifier: MIT
"""End-to-end tests of vafmd over real ZeroMQ sockets (protocol/wire.md).

Each test starts its own daemon on ipc:// endpoints in a private temporary directory (or on an
ephemeral loopback TCP port), so tests can run in parallel. The daemon path comes from $VAFMD, the
vafm CLI (the reference for the streamed samples) from $VAFM_CLI. Runs: paper-fig4 (~0.1 s per curve).
"""
import json
import os
import signal
import socket
import struct
import subprocess
import tempfile
import time

import numpy as np
import pytest
import zmq

VAFMD = os.environ.get("VAFMD")
VAFM_CLI = os.environ.get("VAFM_CLI")
HEADER = struct.Struct("<IHHQQQQIHHdqII")  # protocol/wire.md, 72 bytes
MAGIC = 0x4D464156
CHANNELS = ["height_m", "deflection_m", "force_N", "vDeflection_V", "tip_m"]
TIMEOUT_MS = 20000

pytestmark = pytest.mark.skipif(not VAFMD, reason="set VAFMD to the vafmd executable")


class Daemon:
    def __init__(self, *args, tcp=False, curve=None):
        self.curve = curve  # (server public key, client public key, client secret key), Z85 bytes
        self.dir = tempfile.mkdtemp(prefix="vafmd-")
        if tcp:
            self.rep, self.pub = (f"tcp://127.0.0.1:{free_port()}", f"tcp://127.0.0.1:{free_port()}")
        else:
            self.rep, self.pub = f"ipc://{self.dir}/rep", f"ipc://{self.dir}/pub"
        self.proc = subprocess.Popen([VAFMD, "--rep", self.rep, "--pub", self.pub, *args],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        self.ctx = zmq.Context()
        self.req = None
        self._connect()
        deadline = time.time() + 10
        while True:  # the first hello may race the bind: retry with fresh sockets
            try:
                assert self.cmd({"cmd": "hello"}, timeout=500)["status"] == "ok"
                break
            except zmq.Again:
                assert self.proc.poll() is None, self.proc.communicate()
                assert time.time() < deadline, "vafmd did not answer hello"
                self._connect()

    def _connect(self):
        if self.req is not None:
            self.req.close(0)
        self.req = self.ctx.socket(zmq.REQ)
        self.req.setsockopt(zmq.LINGER, 0)
        self.secure(self.req)
        self.req.connect(self.rep)

    def secure(self, sock, curve=None):
        curve = curve or self.curve
        if curve:
            sock.curve_serverkey, sock.curve_publickey, sock.curve_secretkey = curve

    def send_raw(self, data, timeout=TIMEOUT_MS):
        if isinstance(data, list):
            self.req.send_multipart(data)
        else:
            self.req.send(data)
        if not self.req.poll(timeout):
            raise zmq.Again("no reply")
        return json.loads(self.req.recv())

    def cmd(self, obj, timeout=TIMEOUT_MS):
        return self.send_raw(json.dumps(obj).encode(), timeout)

    def sub(self, rcvhwm=None, topics=(b"",), curve=None):
        s = self.ctx.socket(zmq.SUB)
        s.setsockopt(zmq.LINGER, 0)
        self.secure(s, curve)
        if rcvhwm is not None:
            s.setsockopt(zmq.RCVHWM, rcvhwm)
        for t in topics:
            s.setsockopt(zmq.SUBSCRIBE, t)
        s.connect(self.pub)
        return s

    def wait_idle(self, timeout=30):
        deadline = time.time() + timeout
        while time.time() < deadline:
            st = self.cmd({"cmd": "status"})
            if st["state"] == "idle":
                return st
            time.sleep(0.01)
        raise AssertionError("vafmd stayed busy")

    def stop(self):
        if self.proc.poll() is None:
            try:
                self.cmd({"cmd": "shutdown"}, timeout=5000)
            except zmq.Again:
                pass
        try:
            rc = self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            rc = self.proc.wait()
        self.ctx.destroy(0)
        return rc


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def fig4():
    d = Daemon("--preset", "paper-fig4", "--free-run")
    yield d
    assert d.stop() == 0


def settle(d, s):
    """Wait until the subscription is in place: the daemon greets each new subscription with a heartbeat."""
    assert s.poll(TIMEOUT_MS), "no heartbeat after subscribing"
    parts = s.recv_multipart()
    assert parts[0] == b"heartbeat", parts[0]
    hb = json.loads(parts[1])
    assert hb["state"] in ("idle", "running") and "last_seq" in hb and "dropped" in hb


def collect_run(s, run_id, timeout_ms=TIMEOUT_MS):
    """All messages of run `run_id` up to its run.end: (start, blocks, events, end)."""
    start, blocks, events = None, [], []
    while True:
        if not s.poll(timeout_ms):
            raise AssertionError("stream went silent")
        parts = s.recv_multipart()
        topic = parts[0]
        if topic == b"data":
            h = HEADER.unpack(parts[1])
            if h[4] == run_id:
                blocks.append((h, parts[2:]))
        elif topic in (b"run.start", b"run.end", b"event"):
            j = json.loads(parts[1])
            if j["run_id"] != run_id:
                continue
            if topic == b"run.start":
                start = start or j
            elif topic == b"event":
                events.append(j)
            else:
                return start, blocks, events, j


def error_ok(r, code, field=None):
    assert r["status"] == "error", r
    assert r["code"] == code, r
    assert isinstance(r["message"], str) and r["message"], r
    if field is not None:
        assert r["field"] == field, r


def test_hello(fig4):
    r = fig4.cmd({"cmd": "hello", "id": "h1"})
    assert r["status"] == "ok" and r["id"] == "h1"
    assert r["protocol_version"] == 1
    assert r["daemon"] == "vafmd" and r["daemon_version"]
    assert {"curve", "tune", "status", "get", "set"} <= set(r["capabilities"])
    assert [c["name"] for c in r["channels"]] == CHANNELS


def test_hello_over_loopback_tcp():
    d = Daemon("--preset", "paper-fig4", tcp=True)
    assert d.cmd({"cmd": "presets"})["presets"][0]["name"] == "paper-fig1"
    assert d.stop() == 0


def test_get_set_round_trip_and_range_error(fig4):
    r = fig4.cmd({"cmd": "set", "values": {"k_N_per_m": 0.2, "integrator": "baoab", "seed": "12345678901234567890",
                                           "free_exact": False, "sensitivity_m_per_V": 40e-9}})
    assert r["status"] == "ok", r
    g = fig4.cmd({"cmd": "get", "names": ["k_N_per_m", "integrator", "seed", "free_exact", "sensitivity_m_per_V"],
                  "info": True})
    assert g["values"] == {"k_N_per_m": 0.2, "integrator": "baoab", "seed": "12345678901234567890",
                           "free_exact": False, "sensitivity_m_per_V": 40e-9}
    assert g["info"]["k_N_per_m"]["unit"] == "N/m"
    lo, hi = g["info"]["k_N_per_m"]["min"], g["info"]["k_N_per_m"]["max"]
    r = fig4.cmd({"cmd": "set", "values": {"k_N_per_m": hi * 10}})
    error_ok(r, "out_of_range", "k_N_per_m")
    assert "%g" % lo in r["message"] and "%g" % hi in r["message"], r["message"]
    # all or nothing: a batch with one bad value changes nothing
    error_ok(fig4.cmd({"cmd": "set", "values": {"T_K": 10.0, "integrator": "nope"}}), "out_of_range", "integrator")
    assert fig4.cmd({"cmd": "get", "names": ["k_N_per_m"]})["values"]["k_N_per_m"] == 0.2
    error_ok(fig4.cmd({"cmd": "set", "values": {"no_such": 1}}), "unknown_field", "no_such")
    error_ok(fig4.cmd({"cmd": "set", "preset": "no-such"}), "not_found", "preset")
    error_ok(fig4.cmd({"cmd": "set", "values": {"hwm": 3}}), "read_only", "hwm")
    allv = fig4.cmd({"cmd": "get"})["values"]
    assert "E_star_Pa" in allv and "speed" in allv


def test_bad_inputs_get_errors_and_daemon_survives(fig4):
    error_ok(fig4.send_raw(b"{not json"), "malformed")
    error_ok(fig4.send_raw(b"\xff\xfe\x00"), "malformed")
    error_ok(fig4.send_raw(b"[1,2]"), "malformed")
    error_ok(fig4.send_raw([b"{\"cmd\":\"hello\"}", b"x"]), "malformed")
    error_ok(fig4.cmd({"cmd": "fly"}), "unknown_command", "cmd")
    error_ok(fig4.cmd({"nocmd": 1}), "missing_field", "cmd")
    error_ok(fig4.cmd({"cmd": 3}), "wrong_type", "cmd")
    error_ok(fig4.cmd({"cmd": "set", "values": {"k_N_per_m": "soft"}}), "wrong_type", "k_N_per_m")
    error_ok(fig4.cmd({"cmd": "curve", "index": "one"}), "wrong_type", "index")
    error_ok(fig4.cmd({"cmd": "curve", "bogus": 1}), "unknown_field", "bogus")
    error_ok(fig4.cmd({"cmd": "tune", "duration_s": -1}), "out_of_range", "duration_s")
    error_ok(fig4.send_raw(b'{"cmd":"hello","pad":"' + b"x" * 100000 + b'"}'), "too_large")
    error_ok(fig4.cmd({"cmd": "abort"}), "state")
    error_ok(fig4.cmd({"cmd": "campaign"}), "not_implemented")
    error_ok(fig4.cmd({"cmd": "log", "path": 5}), "wrong_type", "path")
    r = fig4.cmd({"cmd": "hello", "id": 7})
    assert r["status"] == "ok" and r["id"] == 7
    assert fig4.proc.poll() is None


def read_cli_samples(index):
    out = subprocess.run([VAFM_CLI, "samples", "--preset", "paper-fig4", "--index", str(index), "--csv", "-"],
                         check=True, capture_output=True, text=True).stdout
    lines = out.strip().split("\n")
    assert lines[0] == "time_s,height_m,deflection_m,force_N,tip_m,segment"
    # float() of the %.17g text recovers each double exactly
    return np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])


@pytest.mark.parametrize("index", [0, 3])
def test_curve_stream_complete_and_equal_to_cli(fig4, index):
    s = fig4.sub()
    settle(fig4, s)
    r = fig4.cmd({"cmd": "curve", "index": index})
    assert r["status"] == "ok", r
    start, blocks, events, end = collect_run(s, r["run_id"])
    assert start is not None and start["kind"] == "curve" and start["index"] == index
    assert [c["name"] for c in start["channels"]] == CHANNELS
    assert start["scene"]["k_N_per_m"] is not None
    fs = start["sample_rate_Hz"]
    assert end["status"] == "ok" and end["error"] is None
    assert len(blocks) == end["blocks"] > 1
    seqs = [h[3] for h, _ in blocks]
    assert seqs == list(range(seqs[0], seqs[0] + len(blocks))), "sequence gap"
    assert (seqs[0], seqs[-1]) == (end["first_seq"], end["last_seq"])
    first = 0
    for i, (h, chans) in enumerate(blocks):
        magic, ver, hsize, seq, run_id, bidx, fsamp, n, nch, seg, rate, t0, flags, _ = h
        assert (magic, ver, hsize, run_id, bidx, fsamp, nch) == (MAGIC, 1, 72, r["run_id"], i, first, 5)
        assert rate == fs and t0 == round(fsamp / fs * 1e9)
        assert all(len(c) == 8 * n for c in chans)
        assert bool(flags & 4) == (i == len(blocks) - 1)  # LAST
        assert flags & 8  # free-run
        first += n
    assert first == end["samples"] == end["result"]["samples"]
    got = {name: np.concatenate([np.frombuffer(c[k], "<f8") for _, c in blocks]) for k, name in enumerate(CHANNELS)}
    if not VAFM_CLI:
        pytest.skip("VAFM_CLI not set: cannot compare with the CLI")
    ref = read_cli_samples(index)
    assert ref.shape[0] == first
    for col, name in ((1, "height_m"), (2, "deflection_m"), (3, "force_N"), (4, "tip_m")):
        assert np.array_equal(got[name], ref[:, col]), name  # bit for bit (no NaN in these runs)
    assert np.array_equal(got["vDeflection_V"], ref[:, 2] / start["sensitivity_m_per_V"])
    segs = ref[:, 5].astype(int)
    for h, _ in blocks:
        assert h[9] == segs[h[6]]
    changes = [j for j in range(1, first) if segs[j] != segs[j - 1]]
    assert [e["sample"] for e in events if e["kind"] == "segment"] == changes
    # the scene of run.start is a valid `set` and reproduces the scene exactly
    assert fig4.cmd({"cmd": "set", "values": start["scene"]})["status"] == "ok"
    assert fig4.cmd({"cmd": "get", "names": list(start["scene"])})["values"] == start["scene"]


def test_idempotent_retry_and_state_errors():
    # paced at 0.1x: a 50 ms tune takes ~0.5 s of wall time, long enough to be "in progress"
    d = Daemon("--preset", "paper-fig4", "--speed", "0.1")
    s = d.sub()
    settle(d, s)
    r1 = d.cmd({"cmd": "tune", "duration_s": 0.05, "client_run_id": "job-42"})
    assert r1["status"] == "ok" and r1["duplicate"] is False
    r2 = d.cmd({"cmd": "tune", "duration_s": 0.05, "client_run_id": "job-42"})
    assert r2["status"] == "ok" and r2["duplicate"] is True and r2["run_id"] == r1["run_id"]
    error_ok(d.cmd({"cmd": "curve"}), "state", "cmd")
    error_ok(d.cmd({"cmd": "curve", "client_run_id": "job-42"}), "state", "client_run_id")
    st = d.cmd({"cmd": "status"})
    assert st["state"] in ("running", "starting") and st["run_id"] == r1["run_id"] and st["runs_started"] == 1
    start, blocks, _, end = collect_run(s, r1["run_id"])
    assert end["status"] == "ok" and end["client_run_id"] == "job-42"
    assert end["samples"] == sum(h[7] for h, _ in blocks) == round(0.05 * start["sample_rate_Hz"])
    assert 0.45 < end["wall_s"] < 5, end  # paced: 0.05 s / 0.1
    # a retry after the end still answers with the same run and starts nothing
    r3 = d.cmd({"cmd": "tune", "duration_s": 0.05, "client_run_id": "job-42"})
    assert r3["run_id"] == r1["run_id"] and r3["duplicate"] is True
    assert d.wait_idle()["runs_started"] == 1
    # abort mid-run
    r4 = d.cmd({"cmd": "tune", "duration_s": 0.05})
    assert d.cmd({"cmd": "abort"})["status"] == "ok"
    _, _, _, end = collect_run(s, r4["run_id"])
    assert end["status"] == "aborted"
    assert d.stop() == 0


def test_status_counters(fig4):
    s = fig4.sub()
    settle(fig4, s)
    before = fig4.cmd({"cmd": "status"})
    assert before["state"] == "idle" and before["samples"] == 0 and before["last_seq"] is None
    r = fig4.cmd({"cmd": "curve", "index": 1})
    _, blocks, _, end = collect_run(s, r["run_id"])
    st = fig4.wait_idle()
    assert st["samples"] == end["samples"] and st["blocks"] == len(blocks)
    assert st["last_seq"] == end["last_seq"] and st["runs_done"] == 1
    assert st["late_blocks"] == 0 and st["dropped"] == 0  # free run: no deadlines; a reading subscriber
    assert st["free_run"] is True


def test_late_joiner_gets_run_start():
    d = Daemon("--preset", "paper-fig4", "--speed", "0.1")
    early = d.sub()  # an earlier subscriber to the same topics must not hide the late one's subscription
    settle(d, early)
    r = d.cmd({"cmd": "tune", "duration_s": 0.1})
    time.sleep(0.2)
    s = d.sub()  # joins mid-run
    start, blocks, _, end = collect_run(s, r["run_id"])
    assert start is not None and start["run_id"] == r["run_id"] and start["kind"] == "tune"
    assert blocks and blocks[0][0][5] > 0  # really joined late
    start0, blocks0, _, _ = collect_run(early, r["run_id"])
    assert start0 == start and blocks0[0][0][5] == 0 and len(blocks0) > len(blocks)
    assert d.stop() == 0


def run_tune(d, healthy, duration):
    r = d.cmd({"cmd": "tune", "duration_s": duration})
    assert r["status"] == "ok", r
    _, blocks, _, end = collect_run(healthy, r["run_id"])
    seqs = [h[3] for h, _ in blocks]
    assert seqs == list(range(seqs[0], seqs[0] + len(blocks))) and len(blocks) == end["blocks"]
    return end, d.wait_idle()


def test_stalled_subscriber_drops_without_slowdown():
    # 500 blocks of 8 kB; a queue of 200 messages gives the reading subscriber ~0.15 s of slack, while
    # the stalled one (queue + socket buffers, a few hundred kB) must overflow
    d = Daemon("--preset", "paper-fig4", "--free-run", "--hwm", "200")
    assert d.cmd({"cmd": "set", "values": {"block_s": 0.001}})["status"] == "ok"
    healthy = d.sub()
    settle(d, healthy)
    end0, st0 = run_tune(d, healthy, 0.5)
    assert end0["blocks"] == 500 and st0["dropped"] == 0
    stalled = d.sub(rcvhwm=1)  # connected and subscribed, never read after its greeting
    settle(d, stalled)
    end, st = run_tune(d, healthy, 0.5)  # the healthy subscriber still gets every block, no gap
    assert end["blocks"] == 500
    assert st["dropped"] > 0 and end["dropped"] > 0, st
    assert end["wall_s"] < 3 * end0["wall_s"] + 1.0, (end, end0)  # a publisher that blocked would never end
    stalled.close(0)
    assert d.stop() == 0


def test_shutdown_command_exits_zero():
    d = Daemon("--preset", "paper-fig4")
    assert d.cmd({"cmd": "shutdown"})["status"] == "ok"
    assert d.proc.wait(timeout=10) == 0
    d.ctx.destroy(0)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_mid_run_exits_zero(sig):
    d = Daemon("--preset", "paper-fig4", "--speed", "0.1")
    s = d.sub()
    settle(d, s)
    r = d.cmd({"cmd": "tune", "duration_s": 0.5})
    time.sleep(0.2)
    d.proc.send_signal(sig)
    assert d.proc.wait(timeout=10) == 0
    _, _, _, end = collect_run(s, r["run_id"], timeout_ms=5000)
    assert end["status"] == "aborted"
    d.ctx.destroy(0)


def test_refuses_non_loopback_and_bad_usage():
    p = subprocess.run([VAFMD, "--rep", "tcp://0.0.0.0:5555"], capture_output=True, text=True, timeout=10)
    assert p.returncode == 2 and "CURVE" in p.stderr
    p = subprocess.run([VAFMD, "--curve-required"], capture_output=True, text=True, timeout=10)
    assert p.returncode == 2 and "CURVE" in p.stderr
    p = subprocess.run([VAFMD, "--speed", "1e9"], capture_output=True, text=True, timeout=10)
    assert p.returncode == 2 and "speed" in p.stderr
    p = subprocess.run([VAFMD, "--bogus"], capture_output=True, text=True, timeout=10)
    assert p.returncode == 2
    p = subprocess.run([VAFMD, "--help"], capture_output=True, text=True, timeout=10)
    assert p.returncode == 0 and "--free-run" in p.stdout


def test_config_file(tmp_path):
    cfg = tmp_path / "vafmd.json"
    cfg.write_text(json.dumps({"preset": "paper-fig4", "values": {"k_N_per_m": 0.3, "speed": 2.0}}))
    d = Daemon("--config", str(cfg))
    g = d.cmd({"cmd": "get", "names": ["k_N_per_m", "speed", "R_m"]})["values"]
    assert g["k_N_per_m"] == 0.3 and g["speed"] == 2.0
    assert d.stop() == 0


def test_overrun_counted_when_pacing_is_too_fast():
    # paper-fig4 computes ~1 simulated second per wall second; at 1000x every block misses its deadline
    d = Daemon("--preset", "paper-fig4", "--speed", "1000")
    s = d.sub()
    settle(d, s)
    r = d.cmd({"cmd": "tune", "duration_s": 0.02})
    _, blocks, events, end = collect_run(s, r["run_id"])
    late = [h for h, _ in blocks if h[12] & 1]
    assert end["late_blocks"] == len(late) > 0 and end["worst_late_ns"] > 0
    assert not any(h[12] & 8 for h, _ in blocks)  # paced, not free-run
    assert [e["kind"] for e in events].count("overrun") == 1
    st = d.wait_idle()
    assert st["late_blocks"] == end["late_blocks"] and st["worst_late_ns"] == end["worst_late_ns"]
    assert d.stop() == 0


def test_heartbeat_is_periodic():
    d = Daemon("--preset", "paper-fig4")
    s = d.sub(topics=(b"heartbeat",))
    settle(d, s)
    # 1 Hz: a 2.5 s window holds 2 or 3 periodic beats (plus at most one late greeting of the subscription)
    t = time.time()
    beats = 0
    while time.time() - t < 2.5:
        if s.poll(50):
            assert json.loads(s.recv_multipart()[1])["state"] == "idle"
            beats += 1
    assert 2 <= beats <= 4, beats
    assert d.stop() == 0


# ---- HDF5 logging ------------------------------------------------------------------------------------

def h5_curve(f, i):
    g = f[str(i)]
    return {k: g[k][:] for k in ("force", "height (piezo)", "height (measured)", "tip position", "segment", "time")}


def vafm_info_ok(path):
    """The CLI's reader and conformance check accept the file (when the CLI is built)."""
    if not VAFM_CLI:
        return
    p = subprocess.run([VAFM_CLI, "info", str(path)], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stdout + p.stderr


def test_log_file_equals_stream(fig4, tmp_path):
    h5py = pytest.importorskip("h5py")
    path = tmp_path / "log.h5"
    r = fig4.cmd({"cmd": "log", "path": str(path)})
    assert r["status"] == "ok" and r["curves_in_file"] == 0, r
    assert fig4.cmd({"cmd": "status"})["log"]["state"] == "on"
    s = fig4.sub()
    settle(fig4, s)
    runs = []
    for index in (0, 5):
        rr = fig4.cmd({"cmd": "curve", "index": index, "client_run_id": f"c{index}"})
        runs.append(collect_run(s, rr["run_id"]))
        fig4.wait_idle()
    # a tune is streamed but not logged (the afmformats layout holds force curves only)
    rt = fig4.cmd({"cmd": "tune", "duration_s": 0.01})
    collect_run(s, rt["run_id"])
    fig4.wait_idle()
    error_ok(fig4.cmd({"cmd": "log", "path": str(path)}), "state", "path")  # already on
    st = fig4.cmd({"cmd": "log", "stop": True})
    assert st["status"] == "ok", st
    log = st["log"]
    assert (log["state"], log["curves"], log["overflows"], log["curves_dropped"], log["error"]) == ("off", 2, 0, 0, None)
    with h5py.File(path, "r") as f:
        assert sorted(f.keys()) == ["0", "1"]
        for i, (start, blocks, _, end) in enumerate(runs):
            got = {name: np.concatenate([np.frombuffer(c[k], "<f8") for _, c in blocks])
                   for k, name in enumerate(CHANNELS)}
            c = h5_curve(f, i)
            assert len(c["force"]) == end["samples"] == f[str(i)].attrs["point count"]
            # bit for bit: compare the 64-bit patterns, not the values
            assert np.array_equal(c["force"].view(np.uint64), got["force_N"].view(np.uint64))
            assert np.array_equal(c["height (piezo)"].view(np.uint64), got["height_m"].view(np.uint64))
            assert np.array_equal(c["height (measured)"].view(np.uint64), got["height_m"].view(np.uint64))
            assert np.array_equal(c["tip position"].view(np.uint64), got["tip_m"].view(np.uint64))
            # the block headers' segments are the segments of the blocks' first samples
            assert all(c["segment"][h[6]] == h[9] for h, _ in blocks)
            assert c["time"][0] >= 0 and np.all(np.diff(c["time"]) > 0)
            assert f[str(i)].attrs["curve id"] == f"run {start['run_id']} index {start['index']} client c{start['index']}"
            assert f[str(i)].attrs["spring constant"] == start["scene"]["k_N_per_m"]
    vafm_info_ok(path)
    # stop when off, resume appends to the same file, overwrite and resume exclude each other
    error_ok(fig4.cmd({"cmd": "log", "stop": True}), "state", "stop")
    error_ok(fig4.cmd({"cmd": "log", "path": str(path)}), "io_error", "path")  # exists, no overwrite
    error_ok(fig4.cmd({"cmd": "log", "path": str(path), "overwrite": True, "resume": True}), "out_of_range", "resume")
    r = fig4.cmd({"cmd": "log", "path": str(path), "resume": True})
    assert r["status"] == "ok" and r["curves_in_file"] == 2, r
    rr = fig4.cmd({"cmd": "curve", "index": 9})
    collect_run(s, rr["run_id"])
    fig4.wait_idle()
    assert fig4.cmd({"cmd": "log", "stop": True})["log"]["curves"] == 1
    with h5py.File(path, "r") as f:
        assert sorted(f.keys()) == ["0", "1", "2"]
    vafm_info_ok(path)


def test_log_bad_path_names_path(fig4, tmp_path):
    error_ok(fig4.cmd({"cmd": "log", "path": str(tmp_path / "no" / "such" / "dir.h5")}), "io_error", "path")
    error_ok(fig4.cmd({"cmd": "log", "path": str(tmp_path / "x.txt")}), "out_of_range", "path")  # not .h5
    error_ok(fig4.cmd({"cmd": "log", "path": ""}), "out_of_range", "path")
    error_ok(fig4.cmd({"cmd": "log"}), "missing_field", "path")
    error_ok(fig4.cmd({"cmd": "log", "path": str(tmp_path / "a.h5"), "overwrite": 1}), "wrong_type", "overwrite")
    error_ok(fig4.cmd({"cmd": "log", "stop": True, "path": "a.h5"}), "unknown_field", "path")
    assert fig4.cmd({"cmd": "status"})["log"]["state"] == "off"
    assert fig4.proc.poll() is None


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_log_signal_mid_run_leaves_valid_file(tmp_path, sig):
    h5py = pytest.importorskip("h5py")
    path = tmp_path / "sig.h5"
    d = Daemon("--preset", "paper-fig4", "--free-run")
    assert d.cmd({"cmd": "log", "path": str(path)})["status"] == "ok"
    s = d.sub()
    settle(d, s)
    ends = []
    for index in (0, 1):
        rr = d.cmd({"cmd": "curve", "index": index})
        ends.append(collect_run(s, rr["run_id"])[3])
        d.wait_idle()
    # the third curve paced at 0.05x (~0.06 s of curve → ~1.2 s of wall time): interrupted mid-run
    assert d.cmd({"cmd": "set", "values": {"free_run": False, "speed": 0.05}})["status"] == "ok"
    rr = d.cmd({"cmd": "curve", "index": 2})
    time.sleep(0.3)
    assert d.cmd({"cmd": "status"})["state"] == "running"
    d.proc.send_signal(sig)
    assert d.proc.wait(timeout=20) == 0
    assert collect_run(s, rr["run_id"], timeout_ms=5000)[3]["status"] == "aborted"
    d.ctx.destroy(0)
    with h5py.File(path, "r") as f:  # the completed curves, not the interrupted one
        assert sorted(f.keys()) == ["0", "1"]
        assert [len(f[str(i)]["force"]) for i in range(2)] == [e["samples"] for e in ends]
        assert "vafm ground truth" in f.attrs
    vafm_info_ok(path)


# ---- CURVE security (loopback only: --curve-required forces it on 127.0.0.1) -------------------------

def curve_config(tmp_path, server_secret, clients, **extra):
    cfg = tmp_path / "curve.json"
    cfg.write_text(json.dumps({"preset": "paper-fig4", "curve_secret_key": server_secret.decode(),
                               "curve_clients": [c.decode() for c in clients], **extra}))
    return str(cfg)


def test_curve_listed_client_served_unlisted_refused(tmp_path):
    server_pub, server_sec = zmq.curve_keypair()
    good_pub, good_sec = zmq.curve_keypair()
    bad_pub, bad_sec = zmq.curve_keypair()
    cfg = curve_config(tmp_path, server_sec, [good_pub], curve_public_key=server_pub.decode())
    d = Daemon("--config", cfg, "--curve-required", "--free-run", tcp=True, curve=(server_pub, good_pub, good_sec))
    h = d.cmd({"cmd": "hello"})
    assert h["security"] == "curve" and "log" in h["capabilities"]
    # the listed client's subscription is served
    s = d.sub()
    settle(d, s)
    r = d.cmd({"cmd": "curve", "index": 1})
    _, blocks, _, end = collect_run(s, r["run_id"])
    assert end["status"] == "ok" and len(blocks) == end["blocks"]
    # an unlisted key, and a client without CURVE, get no reply and no stream
    for curve in ((server_pub, bad_pub, bad_sec), None):
        req = d.ctx.socket(zmq.REQ)
        req.setsockopt(zmq.LINGER, 0)
        if curve:
            d.secure(req, curve)
        req.connect(d.rep)
        req.send(json.dumps({"cmd": "hello"}).encode())
        assert not req.poll(1500), "an unlisted client was answered"
        req.close(0)
    bad_sub = d.sub(curve=(server_pub, bad_pub, bad_sec))
    assert not bad_sub.poll(1500), "an unlisted subscriber received a message"
    st = d.cmd({"cmd": "status"})
    assert st["auth"]["mechanism"] == "curve" and st["auth"]["clients"] == 1
    assert st["auth"]["refused"] >= 2 and st["auth"]["accepted"] >= 2
    assert d.stop() == 0


def test_curve_config_errors(tmp_path):
    server_pub, server_sec = zmq.curve_keypair()
    other_pub, _ = zmq.curve_keypair()
    bad = [
        curve_config(tmp_path, server_sec, []),                                # empty allow-list
        curve_config(tmp_path, b"short", [other_pub]),                         # not a Z85 key
        curve_config(tmp_path, server_sec, [other_pub], curve_public_key=other_pub.decode()),  # wrong pair
    ]
    for cfg in bad:
        p = subprocess.run([VAFMD, "--config", cfg], capture_output=True, text=True, timeout=10)
        assert p.returncode == 2 and "curve_" in p.stderr, p.stderr
