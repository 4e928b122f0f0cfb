# SPDX-License-Identifier: MIT
"""End-to-end tests of the clients (issue #5): the Python package clients/python/vafm_client, vafm-ctl and
the C client example, each against a vafmd started here on ipc:// endpoints in a private temporary directory
(tests can run in parallel). The reference for the streamed samples is the vafm CLI (`vafm samples`).
Paths come from the environment (clients/c/meson.build): VAFMD, VAFM_CLI, VAFM_CTL, VAFM_EXAMPLE_SUBSCRIBE.
Runs: paper-fig4 in free_run (~0.1 s per curve).
"""
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
PYCLIENT = os.path.join(HERE, "..", "clients", "python")
sys.path.insert(0, PYCLIENT)
from vafm_client import (CHANNELS, Client, DaemonError, GapError, Stream,  # noqa: E402
                         TransportError)

VAFMD = os.environ.get("VAFMD")
VAFM_CLI = os.environ.get("VAFM_CLI")
VAFM_CTL = os.environ.get("VAFM_CTL")
EXAMPLE = os.environ.get("VAFM_EXAMPLE_SUBSCRIBE")
CSV_HEADER = "time_s,height_m,deflection_m,force_N,tip_m,segment"

pytestmark = pytest.mark.skipif(not VAFMD, reason="set VAFMD to the vafmd executable")


class Daemon:
    def __init__(self, *args, curve=None):
        self.dir = tempfile.mkdtemp(prefix="vafmd-clients-")
        self.rep, self.pub = f"ipc://{self.dir}/rep", f"ipc://{self.dir}/pub"
        self.proc = subprocess.Popen([VAFMD, "--rep", self.rep, "--pub", self.pub, *args],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        deadline = time.time() + 10
        while True:  # the first hello may race the bind; the client reopens its socket after a timeout
            self.client = Client(self.rep, timeout=0.5, curve=curve)
            try:
                self.client.hello()
                break
            except TransportError:
                self.client.close()
                assert self.proc.poll() is None, self.proc.communicate()
                assert time.time() < deadline, "vafmd did not answer hello"
        self.client.timeout = 20.0

    def ctl(self, *args, timeout=60, pre=()):
        return subprocess.run([VAFM_CTL, "--endpoint", self.rep, "--pub", self.pub, *pre, *args],
                              capture_output=True, text=True, timeout=timeout)

    def stop(self):
        if self.proc.poll() is None:
            try:
                self.client.shutdown()
            except TransportError:
                pass
        self.client.close()
        try:
            rc = self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            rc = self.proc.wait()
        self.proc.communicate()
        shutil.rmtree(self.dir, ignore_errors=True)
        return rc


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
    if not VAFM_CLI:
        pytest.skip("VAFM_CLI not set: cannot compare with the CLI")
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
            c.curve(index=1)  # a complete run after the loss: no new gap
            run = next(s.runs())
            assert run.complete and s.gaps == lost
        with Stream(d.pub, rcvhwm=1) as s:  # a strict run() of a run with lost blocks raises GapError
            r = c.tune(duration_s=0.5)["run_id"]
            time.sleep(1.0)
            with pytest.raises((GapError, TransportError)):
                s.run(r, timeout=3)
    finally:
        assert d.stop() == 0


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
    for bad in (["bogus"], ["curve", "--x"], ["tune"], ["record"], ["set", "novalue"], []):
        p = fig4.ctl(*bad)
        assert p.returncode == 2 and "usage" in p.stderr, (bad, p)
    p = subprocess.run([VAFM_CTL, "--endpoint", f"ipc://{tmp_path}/nobody", "--timeout", "200", "status"],
                       capture_output=True, text=True, timeout=10)
    assert p.returncode == 1 and "no reply" in p.stderr, p


@pytest.mark.parametrize("index", [0, 3])
def test_ctl_record_equals_cli(fig4, tmp_path, index):
    out = tmp_path / "run.csv"
    p = fig4.ctl("record", "--out", str(out), "--index", str(index))
    assert p.returncode == 0, p
    got = read_csv(out.read_text(), CSV_HEADER + ",vDeflection_V")
    ref = cli_samples(index)
    assert got.shape == (ref.shape[0], 7)
    assert np.array_equal(got[:, 1:6], ref[:, 1:6])  # height, deflection, force, tip, segment: bit for bit
    np.testing.assert_allclose(got[:, 0], ref[:, 0], rtol=1e-14, atol=0)  # see test_python_stream_equals_cli
    sens = fig4.client.get("sensitivity_m_per_V")["sensitivity_m_per_V"]
    assert np.array_equal(got[:, 6], ref[:, 2] / sens)


def test_c_example_prints_one_run(fig4):
    if not EXAMPLE:
        pytest.skip("VAFM_EXAMPLE_SUBSCRIBE not set")
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
    try:
        import matplotlib  # noqa: F401
        assert png.stat().st_size > 1000
    except ImportError:
        assert "matplotlib not available" in p.stderr


def test_curve_security(tmp_path):
    zmq = pytest.importorskip("zmq")
    if not zmq.has("curve"):
        pytest.skip("libzmq without CURVE")
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
        p = d.ctl("record", "--out", str(tmp_path / "c.csv"), pre=("--curve", str(kf)))
        assert p.returncode == 0, p
        assert len((tmp_path / "c.csv").read_text().splitlines()) == run.end["samples"] + 1
        p = d.ctl("--timeout", "300", "status")  # without keys: no reply
        assert p.returncode == 1 and "no reply" in p.stderr, p
        kf.write_text("{}")
        p = d.ctl("status", pre=("--curve", str(kf)))
        assert p.returncode == 2 and "server_public_key" in p.stderr, p
    finally:
        assert d.stop() == 0
