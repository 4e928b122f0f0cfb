# SPDX-License-Identifier: MIT
"""End-to-end tests of the clients (issue #5): the Python package clients/python/vafm_client (Client, Stream,
the HDF5 loader), `vafm ctl`/`vafm status`/`vafm listen`, the C client example and the Python examples, each
against a vafmd started here on ipc:// endpoints in a private temporary directory (tests can run in parallel).
The reference for the streamed samples is the vafm CLI (`vafm samples`), for the files `vafm info` (the C
conformance checker). Paths come from the environment (clients/c/meson.build): VAFMD, VAFM_CLI,
VAFM_EXAMPLE_SUBSCRIBE; VAFM_LONG_TESTS=0 (sanitizer build) cuts the examples' statistics.
Runs: paper-fig4 in free_run (~0.1 s per curve).
"""
import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import h5py
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
PYCLIENT = os.path.join(HERE, "..", "clients", "python")
sys.path.insert(0, PYCLIENT)
from vafm_client import (CHANNELS, Client, DaemonError, GapError, Stream,  # noqa: E402
                         TransportError, load_h5, spawn)

VAFMD = os.environ.get("VAFMD")
VAFM_CLI = os.environ.get("VAFM_CLI")
LONG = os.environ.get("VAFM_LONG_TESTS", "1") != "0"
EXAMPLES = os.path.join(PYCLIENT, "examples")
EXAMPLE = os.environ.get("VAFM_EXAMPLE_SUBSCRIBE")
CSV_HEADER = "time_s,height_m,deflection_m,force_N,tip_m,segment"

# Required, as .ci/deps.sh installs them and meson test sets the variables: a missing one fails the
# module with the reason, never skips it.
for _var in ("VAFMD", "VAFM_CLI", "VAFM_EXAMPLE_SUBSCRIBE"):
    if not os.environ.get(_var):
        raise RuntimeError(f"{_var} is not set: run this module with meson test (it sets VAFMD, VAFM_CLI, VAFM_EXAMPLE_SUBSCRIBE)")


class Daemon(spawn.Daemon):
    """The package's own spawned daemon (vafm_client.spawn), plus the vafm CLI pointed at it."""

    def __init__(self, *args, curve=None):
        super().__init__(VAFMD, *args, curve=curve)

    def ctl(self, *args, timeout=60, pre=()):
        return self.cli("ctl", *pre, *args, timeout=timeout)

    def cli(self, sub, *args, timeout=60):
        """vafm SUB --endpoint REP --pub PUB ARGS (SUB: ctl, status, listen)."""
        return subprocess.run([VAFM_CLI, sub, "--endpoint", self.rep, "--pub", self.pub, *args],
                              capture_output=True, text=True, timeout=timeout)


@pytest.fixture
def fig4():
    d = Daemon("--preset", "paper-fig4", "--free-run")
    yield d
    assert d.stop() == 0


def read_csv(text, header):
    lines = text.strip().split("\n")
    assert lines[0] == header
    return np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])  # %.17g reads back exactly


def cli_samples(index):
    out = subprocess.run([VAFM_CLI, "samples", "--preset", "paper-fig4", "--index", str(index), "--csv", "-"],
                         check=True, capture_output=True, text=True).stdout
    return read_csv(out, CSV_HEADER)


def test_python_client_commands(fig4):
    c = fig4.client
    h = c.hello()
    assert h["protocol_version"] == 1 and h["daemon"] == "vafmd"
    assert [ch["name"] for ch in h["channels"]] == list(CHANNELS)
    assert c.status()["state"] == "idle"
    assert c.presets()[0]["name"] and any(p["name"] == "paper-fig4" for p in c.presets())
    k0 = c.get("k_N_per_m")["k_N_per_m"]
    assert c.set(k_N_per_m=k0 * 2, speed=3.0) == "now"
    assert c.get("k_N_per_m", "speed") == {"k_N_per_m": k0 * 2, "speed": 3.0}
    values, info = c.get("k_N_per_m", info=True)
    assert info["k_N_per_m"]["unit"] == "N/m"
    with pytest.raises(DaemonError) as e:
        c.set(k_N_per_m=1e99)
    assert e.value.code == "out_of_range" and e.value.field == "k_N_per_m"
    assert c.get("k_N_per_m")["k_N_per_m"] == k0 * 2  # all or nothing
    with pytest.raises(DaemonError) as e:
        c.request({"cmd": "bogus"})
    assert e.value.code == "unknown_command"
    with pytest.raises(DaemonError) as e:
        c.get("no_such_parameter")
    assert e.value.code == "unknown_field"
    with pytest.raises(DaemonError) as e:
        c.abort()
    assert e.value.code == "state"


def test_python_client_timeout_reopens_socket(tmp_path):
    c = Client(f"ipc://{tmp_path}/nobody", timeout=0.2, retries=1)
    t0 = time.time()
    with pytest.raises(TransportError):
        c.hello()
    assert 0.35 < time.time() - t0 < 5  # two attempts of 0.2 s
    with pytest.raises(TransportError):  # the socket was reopened: a second request is possible
        c.hello()
    c.close()


@pytest.mark.parametrize("index", [0, 3])
def test_python_stream_equals_cli(fig4, index):
    c = fig4.client
    with Stream(fig4.pub) as s:
        r = c.curve(index=index)
        run = s.run(r["run_id"])
    assert run.complete and run.gaps == 0 and s.gaps == 0
    assert run.start["index"] == index and run.end["status"] == "ok"
    ref = cli_samples(index)
    assert ref.shape[0] == len(run["force_N"]) == run.end["samples"]
    for col, name in ((1, "height_m"), (2, "deflection_m"), (3, "force_N"), (4, "tip_m")):
        assert np.array_equal(run[name], ref[:, col]), name  # bit for bit
    assert np.array_equal(run["vDeflection_V"], ref[:, 2] / run.start["sensitivity_m_per_V"])
    assert np.array_equal(run.segment, ref[:, 5].astype(int))
    # time: reconstructed as (i + 1/2)/fs; the CLI's is the simulation clock (reduced-unit time scaled to
    # SI): not bit for bit. Measured: at most 1 ulp (2.2e-16 relative); 1e-14 leaves ~45 ulp of margin
    np.testing.assert_allclose(run.time_s, ref[:, 0], rtol=1e-14, atol=0)
    # the pull-off read from the stream equals the curve result's
    assert -run["force_N"][run.segment == 1].min() == run.end["result"]["pulloff_sampled_N"]


def test_python_stream_detects_gaps():
    # a subscriber that does not read while 500 blocks of 8 kB go out must lose blocks (queue of 50 messages
    # plus socket buffers of a few hundred kB), and must count exactly the blocks it did not receive
    d = Daemon("--preset", "paper-fig4", "--free-run", "--hwm", "50")
    try:
        c = d.client
        c.set(block_s=0.001)
        with Stream(d.pub, rcvhwm=1) as s:
            c.tune(duration_s=0.5)
            deadline = time.time() + 30
            while c.status()["state"] != "idle":
                assert time.time() < deadline
                time.sleep(0.01)
            r2 = c.curve(index=0)["run_id"]  # read everything up to the end of a second run
            seqs, end2 = [], None
            for topic, p in s.messages():
                if topic == "data":
                    seqs.append(p[0].seq)
                elif topic == "run.end" and p["run_id"] == r2:
                    end2 = p
                    break
            assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
            assert seqs[-1] == end2["last_seq"]
            lost = seqs[-1] - seqs[0] + 1 - len(seqs)
            assert lost > 0, "no block lost: the test did not overflow the queue"
            assert s.gaps == lost
            c.wait_idle()
            # a complete run after the loss: no new gap. Paced at 1x (a 63 ms curve, 1 ms blocks): free-running,
            # the core now outruns this Python reader with its 1-message receive queue
            c.set(free_run=False)
            c.curve(index=1)
            run = next(s.runs())
            assert run.complete and s.gaps == lost
        with Stream(d.pub, rcvhwm=1) as s:  # a strict run() of a run with lost blocks raises GapError
            r = c.tune(duration_s=0.5)["run_id"]
            time.sleep(1.0)
            with pytest.raises((GapError, TransportError)):
                s.run(r, timeout=3)
    finally:
        assert d.stop() == 0


def test_ctl_set_takes_units(fig4):
    """vafm ctl set sends a value typed with its unit in SI, as the CLI's options read it (0.6.2 sent "1nN" as a
    string: "expected a number"); a value it cannot read in the field's unit still goes to the daemon."""
    p = fig4.ctl("set", "setpoint_N=1nN", "v_approach_m_per_s=2\u03bcm/s", "T_K=25C")
    assert p.returncode == 0, p
    got = fig4.client.get("setpoint_N", "v_approach_m_per_s", "T_K")
    assert got == {"setpoint_N": 1e-9, "v_approach_m_per_s": 2e-6, "T_K": 25.0 + 273.15}, got
    p = fig4.ctl("set", "setpoint_N=1nm")  # a length for a force: not converted, refused by the daemon
    assert p.returncode == 1 and "wrong_type" in p.stderr and "setpoint_N" in p.stderr, p


def test_ctl_commands(fig4, tmp_path):
    p = fig4.ctl("hello")
    assert p.returncode == 0 and '"protocol_version": 1' in p.stdout, p
    p = fig4.ctl("set", "k_N_per_m=0.5", "free_run=true", "seed=7")
    assert p.returncode == 0, p
    p = fig4.ctl("get", "k_N_per_m", "seed")
    assert p.returncode == 0 and '"k_N_per_m": 0.5' in p.stdout and '"seed": "7"' in p.stdout, p
    p = fig4.ctl("set", "k_N_per_m=1e99")
    assert p.returncode == 1 and "out_of_range" in p.stderr and "k_N_per_m" in p.stderr, p
    p = fig4.ctl("set", "preset=paper-fig4")
    assert p.returncode == 0, p
    p = fig4.ctl("status")
    assert p.returncode == 0 and '"state": "idle"' in p.stdout, p
    p = fig4.ctl("curve", "--index", "1", "--wait")
    assert p.returncode == 0 and '"status": "ok"' in p.stdout and '"run_id"' in p.stdout, p
    fig4.client.wait_idle()  # run.end goes out before the daemon is idle again
    p = fig4.ctl("tune", "0.01", "--wait")
    assert p.returncode == 0 and '"kind": "tune"' in p.stdout, p
    fig4.client.wait_idle()
    p = fig4.ctl("abort")
    assert p.returncode == 1 and "state" in p.stderr, p
    # any command: KEY=VALUE arguments (JSON values) or a whole JSON request
    p = fig4.ctl("get", "names=[\"T_K\",\"speed\"]")
    assert p.returncode == 0 and '"T_K"' in p.stdout and '"speed"' in p.stdout, p
    p = fig4.ctl('{"cmd": "get", "names": ["m_kg"], "id": 42}')
    assert p.returncode == 0 and json.loads(p.stdout)["values"] == {"m_kg": 1e-12} and '"id": 42' in p.stdout, p
    h5 = tmp_path / "log.h5"
    p = fig4.ctl("log", f"path={h5}")
    assert p.returncode == 0 and '"curves_in_file": 0' in p.stdout, p
    p = fig4.ctl("log", "stop=true")
    assert p.returncode == 0 and '"curves": 0' in p.stdout, p
    p = fig4.ctl("bogus")
    assert p.returncode == 1 and "unknown_command" in p.stderr, p
    for bad in (["curve", "--x"], ["tune", "x"], ["set", "novalue"], ["set"], ["{not json"], []):
        p = fig4.ctl(*bad)
        assert p.returncode == 2 and "usage" in p.stderr, (bad, p)
    p = subprocess.run([VAFM_CLI, "ctl", "--endpoint", f"ipc://{tmp_path}/nobody", "--timeout", "200", "status"],
                       capture_output=True, text=True, timeout=10)
    assert p.returncode == 1 and "no reply" in p.stderr, p


def test_cli_refuses_non_finite_numbers(fig4, tmp_path):
    """A number for the daemon that is not finite or outside the range the CLI knows is a usage error naming
    the option, refused before anything is sent: jansson's json_real() is NULL for NaN and inf, and
    json_object_set_new then dropped the key (0.6.1: `ctl tune nan` ran the scene's tune, `replay --speed
    inf` ran at the daemon's speed, `listen --start tune --duration inf` recorded a 0.5 s tune, all "ok")."""
    out = tmp_path / "l.csv"
    cases = [(("ctl", "tune", v), "tune SECONDS") for v in ("nan", "inf", "-inf", "1e400", "-1", "2e5")]
    cases += [(("ctl", "set", "k_N_per_m=1e400"), "k_N_per_m=1e400"),
              (("ctl", "campaign", "n=1", "T_K=[300,1e400]"), "T_K=")]
    cases += [(("listen", "--start", "tune", "--duration", v, "-o", str(out)), "--duration")
              for v in ("inf", "nan", "1e400", "0", "2e5")]
    cases += [(("replay", str(tmp_path / "x.h5"), "--speed", v, "--curves", "0"), "--speed")
              for v in ("nan", "inf", "1e400", "0.001", "2000")]
    cases += [(("replay", str(tmp_path / "x.h5"), "--loop", v), "--loop") for v in ("0", "1000001", "99999999999999999999")]
    for args, needle in cases:
        p = fig4.cli(*args)
        assert p.returncode == 2 and needle in p.stderr and "usage" in p.stderr, (args, p)
    assert not out.exists()
    st = fig4.client.status()
    assert st["state"] == "idle" and st["runs_started"] == 0, st  # nothing reached the daemon
    # in range it goes through: 10 ms at paper-fig4's tune rate of 1 MHz (the scene's own tune: 50 ms)
    p = fig4.cli("listen", "--start", "tune", "--duration", "0.01", "-o", str(out))
    assert p.returncode == 0 and len(out.read_text().splitlines()) == 1 + 10000, p


def test_status(fig4, tmp_path):
    fig4.client.curve(index=0)
    fig4.client.wait_idle()
    p = fig4.cli("status")
    assert p.returncode == 0, p
    assert "state        idle, last run 1" in p.stdout and "runs         1 started, 1 done" in p.stdout, p.stdout
    assert "pacing       free run" in p.stdout and "log          off" in p.stdout, p.stdout
    assert "campaign" not in p.stdout, p.stdout
    p = fig4.cli("status", "--json")
    assert p.returncode == 0 and json.loads(p.stdout)["runs_done"] == 1, p
    fig4.client.request({"cmd": "campaign", "n": 2})
    deadline = time.time() + 20
    while fig4.client.status()["campaign"]["running"]:
        assert time.time() < deadline
        time.sleep(0.02)
    p = fig4.cli("status")
    assert p.returncode == 0 and "campaign     1: ended, 2 of 2 curves done" in p.stdout, p.stdout
    p = subprocess.run([VAFM_CLI, "status", "--endpoint", f"ipc://{tmp_path}/nobody", "--timeout", "200"],
                       capture_output=True, text=True, timeout=10)
    assert p.returncode == 1 and "no reply" in p.stderr, p
    p = fig4.cli("status", "--bogus")
    assert p.returncode == 2 and "usage" in p.stderr, p


@pytest.mark.parametrize("index", [0, 3])
def test_listen_csv_equals_cli(fig4, tmp_path, index):
    out = tmp_path / "run.csv"
    p = fig4.cli("listen", "--start", "curve", "--out", str(out), "--index", str(index))
    assert p.returncode == 0, p
    got = read_csv(out.read_text(), CSV_HEADER + ",vDeflection_V,run_id")
    ref = cli_samples(index)
    assert got.shape == (ref.shape[0], 8)
    assert np.array_equal(got[:, 1:6], ref[:, 1:6])  # height, deflection, force, tip, segment: bit for bit
    np.testing.assert_allclose(got[:, 0], ref[:, 0], rtol=1e-14, atol=0)  # see test_python_stream_equals_cli
    sens = fig4.client.get("sensitivity_m_per_V")["sensitivity_m_per_V"]
    assert np.array_equal(got[:, 6], ref[:, 2] / sens)
    assert np.all(got[:, 7] == 1)  # run_id


def test_listen_h5_equals_cli(fig4, tmp_path):
    """A curve streamed by vafmd and recorded by `vafm listen --out x.h5` equals `vafm samples` of the same
    scene and index bit for bit, passes `vafm info` (the conformance check of protocol/hdf5.md), and its
    ground truth is the run.end result."""
    out = tmp_path / "x.h5"
    p = fig4.cli("listen", "--start", "curve", "--index", "3", "--out", str(out))
    assert p.returncode == 0, p
    assert "1 written to" in p.stderr, p.stderr
    f = load_h5(str(out))
    assert f.is_vafm and len(f) == 1 and f.scene["k_N_per_m"] == fig4.client.get("k_N_per_m")["k_N_per_m"]
    c, ref = f[0], cli_samples(3)
    assert len(c) == ref.shape[0]
    for name, col in (("height (piezo)", 1), ("height (measured)", 1), ("force", 3), ("tip position", 4),
                      ("segment", 5)):
        assert np.array_equal(c[name], ref[:, col]), name  # bit for bit
    np.testing.assert_allclose(c.time, ref[:, 0], rtol=1e-14, atol=0)
    assert c.meta["curve id"] == "run 1 index 3" and c.meta["spring constant"] == f.scene["k_N_per_m"]
    assert c.truth["pulloff_sampled_N"] == -c.force[c.retract].min() and c.truth["samples"] == len(c)
    p = subprocess.run([VAFM_CLI, "info", str(out)], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0 and "conformance  ok" in p.stdout, p
    p = fig4.cli("listen", "--start", "curve", "--out", str(out))  # no silent replacement
    assert p.returncode == 1 and "exist" in p.stderr, p


def test_listen_skips_run_in_progress(tmp_path):
    """A run already going when listen subscribes (a paced tune) is skipped, not written with its beginning
    missing; the next run is recorded whole. No timing margin: the tune lasts 20 s (1 s paced at speed
    0.05: ~1 MB of the daemon's memory a second) and the test waits on conditions, so a loaded machine only
    makes it slower: listen is started once the tune has published a data block (a later subscriber joins
    it mid-run), and the tune is aborted once listen has said it skips it."""
    d = Daemon("--preset", "paper-fig4")
    lp = None
    try:
        d.client.set(speed=0.05)
        with Stream(d.pub) as s:  # in place (its greeting heartbeat) before the tune starts
            rid = d.client.tune(duration_s=1.0)["run_id"]
            deadline = time.monotonic() + 60
            for topic, p in s.messages(deadline=deadline):
                if topic == "data" and p[0].run_id == rid:
                    break  # blocks of the tune are out: a subscriber from now on has missed its start
        out = tmp_path / "mid.csv"
        lp = subprocess.Popen([VAFM_CLI, "listen", "--endpoint", d.rep, "--pub", d.pub, "--out", str(out)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        lines = queue.Queue()
        reader = threading.Thread(target=lambda: [lines.put(ln) for ln in lp.stderr] + [lines.put(None)],
                                  daemon=True)
        reader.start()
        err = []
        skipped = f"run {rid} was in progress when listen subscribed: skipped"
        while not err or skipped not in err[-1]:  # listen's stderr, until it has skipped the tune
            ln = lines.get(timeout=60)
            assert ln is not None, "listen exited before it skipped the tune: " + "".join(err)
            err.append(ln)
        assert "subscribed" in err[0], err
        st = d.client.status()
        assert st["state"] == "running" and st["run_id"] == rid, f"the tune ended before listen skipped it: {st}"
        d.client.abort()
        d.client.wait_idle()
        d.client.set(free_run=True, speed=1)
        d.client.curve(index=0)
        rc = lp.wait(timeout=60)
        while (ln := lines.get(timeout=10)) is not None:  # the rest of its stderr
            err.append(ln)
        err = "".join(err)
        assert rc == 0 and rid == 1 and "run 1 was in progress when listen subscribed: skipped" in err, err
        got = read_csv(out.read_text(), CSV_HEADER + ",vDeflection_V,run_id")
        assert np.all(got[:, 7] == 2) and np.array_equal(got[:, 3], cli_samples(0)[:, 3])
    finally:
        if lp is not None and lp.poll() is None:
            lp.kill()
            lp.wait()
        assert d.stop() == 0


def test_listen_several_runs_and_gaps(tmp_path):
    """listen without --start records the runs others start (a tune is not written to HDF5); a stalled
    listener (SIGSTOP) loses blocks of a 0.5 s tune of 1 ms blocks (500 blocks of 8 kB against a queue of
    50 messages and socket buffers of a few hundred kB) and must say so and exit 1."""
    d = Daemon("--preset", "paper-fig4", "--free-run", "--hwm", "50")
    try:
        out = tmp_path / "runs.h5"
        lp = subprocess.Popen([VAFM_CLI, "listen", "--endpoint", d.rep, "--pub", d.pub, "--runs", "3", "--out",
                               str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert "subscribed" in lp.stderr.readline()
        for kind, arg in (("curve", 1), ("tune", 0.01), ("curve", 2)):
            d.client.wait_idle()
            d.client.curve(index=arg) if kind == "curve" else d.client.tune(duration_s=arg)
        _, err = lp.communicate(timeout=60)
        assert lp.returncode == 0, err
        f = load_h5(str(out))
        # Client.curve gives each start a client_run_id of its own (retries are idempotent): " client ..."
        assert [c.meta["curve id"].split(" client ")[0] for c in f] == ["run 1 index 1", "run 3 index 2"], err
        assert "is a tune: not written" in err
        d.client.wait_idle()
        d.client.set(block_s=0.001)
        lp = subprocess.Popen([VAFM_CLI, "listen", "--endpoint", d.rep, "--pub", d.pub, "--runs", "1", "--out",
                               str(tmp_path / "gap.csv")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert "subscribed" in lp.stderr.readline()
        lp.send_signal(signal.SIGSTOP)
        d.client.tune(duration_s=0.5)
        d.client.wait_idle()
        lp.send_signal(signal.SIGCONT)
        time.sleep(1.0)  # let it drain its queues before a complete run (in case the tune's run.start was lost)
        d.client.curve(index=0)
        try:
            _, err = lp.communicate(timeout=30)
        finally:
            if lp.poll() is None:
                lp.kill()
                lp.communicate()
        # the loss shows as a seq gap, or (the tune's run.end lost too, a heartbeat seen first) as a run
        # that never got its run.end
        assert lp.returncode == 1 and ("lost (sequence gap)" in err or "no run.end" in err), err
    finally:
        assert d.stop() == 0


def test_c_example_prints_one_run(fig4):
    p = subprocess.run([EXAMPLE, fig4.rep, fig4.pub, "2"], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p
    lines = p.stdout.splitlines()
    assert any(ln.startswith("run.start run 1 kind curve index 2") for ln in lines), p.stdout
    blocks = [ln for ln in lines if ln.startswith("block ")]
    end = fig4.client.wait_idle()
    assert len(blocks) == end["blocks"] > 1 and not any("GAP" in b for b in blocks)
    assert lines[-1] == f"run.end status ok samples {end['samples']} gaps 0"


def test_pulloff_example(fig4, tmp_path):
    png = tmp_path / "pulloff.png"
    p = subprocess.run([sys.executable, os.path.join(PYCLIENT, "examples", "pulloff.py"), "--rep", fig4.rep,
                        "--pub", fig4.pub, "-n", "3", "--png", str(png)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p
    assert "pull-off (sampled): N = 3" in p.stdout and "pull-off (spring): N = 3" in p.stdout, p.stdout
    assert "warning" not in p.stderr, p.stderr
    import matplotlib  # noqa: F401  (required: .ci/deps.sh installs python3-matplotlib)
    assert png.stat().st_size > 1000


def test_curve_security(tmp_path):
    import zmq
    assert zmq.has("curve"), "libzmq without CURVE (Debian's libzmq5, which .ci/deps.sh installs, has it)"
    server_pub, server_sec = zmq.curve_keypair()
    client_pub, client_sec = zmq.curve_keypair()
    other_pub, other_sec = zmq.curve_keypair()
    cfg = tmp_path / "vafmd.json"
    cfg.write_text(json.dumps({"curve_secret_key": server_sec.decode(), "curve_clients": [client_pub.decode()]}))
    keys = (server_pub, client_pub, client_sec)
    d = Daemon("--config", str(cfg), "--preset", "paper-fig4", "--free-run", curve=keys)
    try:
        with Stream(d.pub, curve=keys) as s:  # the stream needs the keys as well
            run = s.run(d.client.curve(index=0)["run_id"])
            assert run.complete
        d.client.wait_idle()
        with Client(d.rep, timeout=0.3, curve=(server_pub, other_pub, other_sec)) as bad:
            with pytest.raises(TransportError):  # an unlisted key gets no reply at all
                bad.hello()
        kf = tmp_path / "keys.json"
        kf.write_text(json.dumps({"server_public_key": server_pub.decode(), "public_key": client_pub.decode(),
                                  "secret_key": client_sec.decode()}))
        p = d.cli("listen", "--curve", str(kf), "--start", "curve", "--out", str(tmp_path / "c.csv"))
        assert p.returncode == 0, p
        assert len((tmp_path / "c.csv").read_text().splitlines()) == run.end["samples"] + 1
        p = d.ctl("--timeout", "300", "status")  # without keys: no reply
        assert p.returncode == 1 and "no reply" in p.stderr, p
        kf.write_text("{}")
        p = d.ctl("status", pre=("--curve", str(kf)))
        assert p.returncode == 2 and "server_public_key" in p.stderr, p
    finally:
        assert d.stop() == 0


# ---- the HDF5 loader ------------------------------------------------------------------------------------

def test_loader_reads_foreign_file(tmp_path):
    """A file of the layout written by another program (h5py here, as afmformats' exporter writes: no
    `time`, no `tip position`, no vafm provenance) loads, and `vafm info` (the C reader and checker) agrees
    it is of the layout; a file breaking the layout is refused naming the rule."""
    path = tmp_path / "foreign.h5"
    n = 50
    rng = np.random.default_rng(5)
    force, height = rng.normal(size=n) * 1e-9, np.linspace(1e-7, 0, n)
    seg = np.r_[np.zeros(n // 2, np.uint8), np.ones(n - n // 2, np.uint8)]
    with h5py.File(path, "w") as f:
        f.attrs["software"] = "afmformats"
        f.attrs["software version"] = "0.18.0"
        for g in ("0", "1"):
            grp = f.create_group(g)
            for name, data, unit in (("force", force, "N"), ("height (measured)", height, "m"),
                                     ("height (piezo)", height, "m"), ("segment", seg, "")):
                grp.create_dataset(name, data=data).attrs["unit"] = unit
            grp.attrs["imaging mode"] = "force-distance"
            grp.attrs["spring constant"] = 0.05
            grp.attrs["point count"] = n
    lf = load_h5(str(path))
    assert not lf.is_vafm and lf.software == "afmformats" and lf.truth is None and lf.scene is None
    assert len(lf) == 2 and [c.group for c in lf] == [0, 1]
    c = lf[1]
    assert np.array_equal(c.force, force) and np.array_equal(c.height, height) and np.array_equal(c.segment, seg)
    assert c.time is None and "tip position" not in c and c.truth is None
    assert c.meta["spring constant"] == 0.05 and c.units["force"] == "N" and c.approach.sum() == n // 2
    if VAFM_CLI:
        p = subprocess.run([VAFM_CLI, "info", str(path)], capture_output=True, text=True, timeout=60)
        assert p.returncode == 0 and "2 curve(s)" in p.stdout, p
    with h5py.File(path, "a") as f:
        f.create_group("x")
    with pytest.raises(ValueError, match=r"\[L4\]"):
        load_h5(str(path))


def test_loader_refuses_data_outside_the_file(tmp_path):
    """A channel whose data lie outside the file (external raw-data storage, a virtual dataset) is refused
    naming the file and the dataset, never read: here they point at a FIFO, which blocks whoever opens it
    (0.6.2 hung in load_h5). In a child, so that a hang fails the test instead of stalling it."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    n = 8
    for kind in ("external", "virtual"):
        path = tmp_path / f"{kind}.h5"
        with h5py.File(path, "w") as f:
            f.attrs["software"], f.attrs["software version"] = "handmade", "1"
            grp = f.create_group("0")
            if kind == "external":
                d = grp.create_dataset("force", shape=(n,), dtype="<f8", external=[(str(fifo), 0, 8 * n)])
            else:
                lay = h5py.VirtualLayout(shape=(n,), dtype="<f8")
                lay[:] = h5py.VirtualSource(str(fifo), "force", shape=(n,))
                d = grp.create_virtual_dataset("force", lay, fillvalue=0)
            d.attrs["unit"] = "N"
            for name, unit in (("height (measured)", "m"), ("height (piezo)", "m")):
                grp.create_dataset(name, data=np.linspace(1e-7, 0, n)).attrs["unit"] = unit
            grp.create_dataset("segment", data=np.zeros(n, np.uint8)).attrs["unit"] = ""
            grp.attrs["imaging mode"] = "force-distance"
        p = subprocess.run([sys.executable, "-c", "import sys; sys.path.insert(0, sys.argv[1]); "
                            "from vafm_client import load_h5; load_h5(sys.argv[2])", PYCLIENT, str(path)],
                           capture_output=True, text=True, timeout=30)
        want = "stored in an external file (not read)" if kind == "external" else "a virtual dataset"
        assert p.returncode != 0 and f"[L2] {path}: /0/force: {want}" in p.stderr, p


def test_loader_refuses_huge_declared_length(tmp_path):
    """A channel declaring 10**12 samples (chunked, never written: a few kB on disk) is refused before it is
    read, naming VAFM_H5_MAX_SAMPLES (0.6.2: numpy was asked for 8 TB)."""
    path = tmp_path / "huge.h5"
    with h5py.File(path, "w") as f:
        f.attrs["software"], f.attrs["software version"] = "handmade", "1"
        grp = f.create_group("0")
        for name, unit in (("force", "N"), ("height (measured)", "m"), ("height (piezo)", "m"), ("segment", "")):
            grp.create_dataset(name, shape=(10**12,), dtype="u1" if name == "segment" else "<f8",
                               chunks=(1 << 20,)).attrs["unit"] = unit
        grp.attrs["imaging mode"] = "force-distance"
    with pytest.raises(ValueError, match=r"\[L7\] .*huge\.h5: /0: datasets declare 1000000000000 samples, more than a "
                                         r"curve may have \(33554432, VAFM_H5_MAX_SAMPLES\)"):
        load_h5(str(path))


def test_loader_refuses_hostile_map(tmp_path):
    """A map whose pixel indices would misplace a curve (a negative index, which numpy wraps; two curves on
    one pixel), whose shape would size the array from the file (10**6 pixels a side: 0.6.2 allocated it), or
    whose ground-truth tables are not such tables raises ValueError naming the file and what is wrong
    (0.6.2: a wrong map without a word, "invalid literal for int()", "no field of name curve")."""
    good = tmp_path / "hm.h5"
    subprocess.run([VAFM_CLI, "map", "--preset", "cell-liquid", "--nx", "2", "--ny", "2", "--threads", "1",
                    "--pattern", "dome", "--out", str(good), "-q"], check=True, capture_output=True, timeout=60)
    f = load_h5(str(good))
    assert f.is_map and f.map_shape == (2, 2)
    assert np.array_equal(f.map_array([c.group for c in f]), [[0, 1], [2, 3]])

    def hostile(name, edit):
        path = tmp_path / f"{name}.h5"
        path.write_bytes(good.read_bytes())
        with h5py.File(path, "a") as h:
            edit(h)
        return str(path)

    def set_attr(curves, **kv):
        def edit(h):
            for c in curves:
                for k, v in kv.items():
                    h[str(c)].attrs[k.replace("_", " ")] = v
        return edit

    p = hostile("negative", set_attr([3], grid_index_x=-2))
    with pytest.raises(ValueError, match=r"\[L17\] .*negative\.h5: /3: 'grid index x' is -2 \(afmformats wants a "
                                         r"non-negative integer\)"):
        load_h5(p).map_array(range(4))
    p = hostile("outside", set_attr([3], grid_index_y=2))
    with pytest.raises(ValueError, match=r"outside\.h5: /3: 'grid index y' is 2, above 1 \(outside 'grid shape y' 2\)"):
        load_h5(p).map_array(range(4))
    p = hostile("duplicate", set_attr([3], grid_index_x=0, grid_index_y=0))
    with pytest.raises(ValueError, match=r"duplicate\.h5: /3: pixel \(0, 0\) is curve 0's too"):
        load_h5(p).map_array(range(4))
    p = hostile("shape", set_attr(range(4), grid_shape_x=10**6))  # 16 MB if allocated: 0.6.2 returned it
    with pytest.raises(ValueError, match=r"shape\.h5: /0: 'grid shape x' is 1000000, above 1024 \(a map has at "
                                         r"most 1024 pixels a side"):
        load_h5(p).map_shape
    with pytest.raises(ValueError, match=r"'grid shape x' is 1000000"):
        load_h5(p).map_array(range(4))

    def rename_truth(h):
        t = h.attrs["vafm ground truth"]
        del h.attrs["vafm ground truth"]
        h.attrs["vafm ground truth from x"] = t
    with pytest.raises(ValueError, match=r"\[V4\] .*suffix\.h5: /: attribute 'vafm ground truth from x': a part of "
                                         r"the ground truth is named"):
        load_h5(hostile("suffix", rename_truth))

    def truth_without_curve(h):
        t = h.attrs["vafm ground truth"]
        del h.attrs["vafm ground truth"]
        h.attrs["vafm ground truth"] = np.zeros(len(t), dtype=[("point", "<u8"), ("E_star_Pa", "<f8")])
    with pytest.raises(ValueError, match=r"\[V4\] .*nocurve\.h5: /: attribute 'vafm ground truth' lacks the "
                                         r"integer field 'curve'"):
        load_h5(hostile("nocurve", truth_without_curve))

    def truth_twice(h):
        h.attrs["vafm ground truth from 3"] = h.attrs["vafm ground truth"][3:]
    with pytest.raises(ValueError, match=r"twice\.h5: /: two ground-truth rows for curve 3"):
        load_h5(hostile("twice", truth_twice))


# ---- the examples (each writes a PNG without a display) ---------------------------------------------------

def run_example(name, *args, timeout=180):
    p = subprocess.run([sys.executable, os.path.join(EXAMPLES, name), *args], capture_output=True, text=True,
                       timeout=timeout, env=dict(os.environ, MPLBACKEND="Agg", DISPLAY=""))
    assert p.returncode == 0, p
    return p


def assert_png(path):
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10000, path  # a real figure, not an empty canvas


def test_example_force_curve(fig4, tmp_path):
    p = run_example("force_curve.py", "--rep", fig4.rep, "--pub", fig4.pub, "--out-dir", str(tmp_path),
                    "--index", "2")
    png, h5 = tmp_path / "force_curve.png", tmp_path / "force_curve.h5"
    assert f"PNG: {png}" in p.stdout and f"HDF5: {h5}" in p.stdout, p.stdout
    assert "equal to the streamed samples bit for bit" in p.stdout, p.stdout
    assert_png(png)
    f = load_h5(str(h5))
    assert len(f) == 1 and f[0].meta["curve id"].startswith("run 1 index 2")
    ref = cli_samples(2)
    assert np.array_equal(f[0].force, ref[:, 3])  # the daemon's log equals `vafm samples` bit for bit
    # the printed observables are the file's ground truth
    line = next(ln for ln in p.stdout.splitlines() if ln.strip().startswith("pulloff_spring_N"))
    assert float(line.split()[1]) == pytest.approx(f[0].truth["pulloff_spring_N"] * 1e9, rel=1e-5)


def test_example_pulloff_hist_spawn(tmp_path):
    """--spawn starts and stops its own daemon; the skew-normal fit is compared with scipy's own fit of the
    same numbers (the example's bounded fit must agree where the shape is not at its bound)."""
    png, js = tmp_path / "hist.png", tmp_path / "hist.json"
    n = "8" if LONG else "5"
    p = run_example("pulloff_hist.py", "--spawn", VAFMD, "--spawn-arg=--free-run", "--preset", "paper-fig4",
                    "-n", n, "--bootstrap", "10", "--png", str(png), "--json", str(js))
    assert_png(png)
    (res,) = json.loads(js.read_text())
    assert res["n"] == int(n) and 0.5 < res["mean"] < 1.0  # thermal pull-off below F_JKR (paper-fig4: ~0.91)
    assert res["scale"] > 0 and res["loc_err"] > 0 and "skew-normal (bootstrap B = 10)" in p.stdout, p.stdout


def test_example_pulloff_hist_campaign_equals_curves(fig4, tmp_path):
    """The daemon's `campaign` and the fallback sequence of `curve` commands with explicit indices give the
    same curves (the campaign's numbering: point p, curve j has index p·n + j), so the same fits."""
    res = []
    for extra in ((), ("--no-campaign",)):
        js = tmp_path / f"h{len(res)}.json"
        p = run_example("pulloff_hist.py", "--rep", fig4.rep, "--pub", fig4.pub, "-n", "3", "--T", "1e6,3e6",
                        "--errors", "fisher", "--png", str(tmp_path / "h.png"), "--json", str(js), *extra)
        assert ("campaign 1: 6 curves" in p.stdout) == (not extra), p.stdout
        res.append(json.loads(js.read_text()))
    assert [r["T_K"] for r in res[0]] == [1e6, 3e6]
    for a, b in zip(*res):
        assert (a["n"], a["mean"], a["sd"], a["loc"]) == (b["n"], b["mean"], b["sd"], b["loc"])


def test_ctl_and_listen_campaign(fig4, tmp_path):
    out = tmp_path / "camp.h5"
    lp = subprocess.Popen([VAFM_CLI, "listen", "--endpoint", fig4.rep, "--pub", fig4.pub, "--runs", "4", "--out",
                           str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert "subscribed" in lp.stderr.readline()
    p = fig4.ctl("campaign", "n=2", "k_N_per_m=[1.6,3.2]", "--wait")
    assert p.returncode == 0 and '"campaign_id": 1' in p.stdout and '"curves_done": 4' in p.stdout, p
    _, err = lp.communicate(timeout=60)
    assert lp.returncode == 0, err
    f = load_h5(str(out))
    assert [c.meta["curve id"] for c in f] == [f"run {r} index {r - 1}" for r in (1, 2, 3, 4)]
    assert [c.meta["spring constant"] for c in f] == [1.6, 1.6, 3.2, 3.2]
    p = subprocess.run([VAFM_CLI, "info", str(out)], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0 and "conformance  ok" in p.stdout, p
    # the CLI's campaign file of the same grid: the same curves bit for bit, the same ground truth
    ref = tmp_path / "ref.h5"
    subprocess.run([VAFM_CLI, "campaign", "-n", "2", "--k", "1.6,3.2", "--preset", "paper-fig4", "--out", str(ref),
                    "--threads", "1", "--quiet"], check=True, capture_output=True, timeout=60)
    g = load_h5(str(ref))
    assert g.is_vafm and g.grid["k_N_per_m"] == [1.6, 3.2] and len(g) == 4
    for a, b in zip(f, g):
        for name in ("force", "height (piezo)", "tip position", "segment"):
            assert np.array_equal(a[name], b[name]), (a.group, name)
        for key in ("pulloff_sampled_N", "pulloff_spring_N", "detach_force_N", "detach_height_m", "k_N_per_m", "point"):
            assert a.truth[key] == b.truth[key], (a.group, key)


def test_example_thermal_tune(fig4, tmp_path):
    """The tune recovers the configured spring constant within 5% (the issue's requirement) and the
    resonance within 5%. Statistical expectation (paper-fig4: η = 4e5/s, f0 = 201 kHz, Q = 3.2): the mean
    square of T seconds of the oscillator has a relative standard error ≈ sqrt(2/(ηT)) = 0.5% at T = 0.2 s
    (0.7% at 0.1 s), so 5% is ≥ 7σ; the example's fit error is printed and checked to be of that order."""
    png, js = tmp_path / "tune.png", tmp_path / "tune.json"
    dur = "0.2" if LONG else "0.1"
    p = run_example("thermal_tune.py", "--rep", fig4.rep, "--pub", fig4.pub, "--duration", dur,
                    "--png", str(png), "--json", str(js))
    assert_png(png)
    r = json.loads(js.read_text())
    assert r["k_configured"] == 1.6
    assert abs(r["k_N_per_m"] / r["k_configured"] - 1) < 0.05, p.stdout
    assert abs(r["f0_Hz"] / r["f0_configured"] - 1) < 0.05, p.stdout
    assert 0.2 * r["expected_rel_sd"] < r["k_err"] / r["k_configured"] < 5 * r["expected_rel_sd"], p.stdout
    assert fig4.client.get("sample_rate_Hz")["sample_rate_Hz"] == pytest.approx(2e5)  # restored
