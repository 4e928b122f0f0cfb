# SPDX-License-Identifier: MIT
"""A vafmd started by a test: private ipc:// endpoints (or ephemeral loopback TCP ports), a REQ socket
with retry on the first hello, subscriptions, shutdown. Shared by test_daemon.py and test_replay.py
(pytest puts this folder on sys.path). The daemon path comes from $VAFMD."""
import json
import os
import shutil
import socket
import struct
import subprocess
import tempfile
import time

import pytest
import zmq

VAFMD = os.environ.get("VAFMD")
VAFM_CLI = os.environ.get("VAFM_CLI")
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # the source tree


def read(*parts):
    """A file of the source tree (ROOT/parts...) as text: the tables the tests parse (commands.def,
    channels.h) and the documents they check against them."""
    with open(os.path.join(ROOT, *parts), encoding="utf-8") as f:
        return f.read()

TIMEOUT_MS = 20000
HEADER = struct.Struct("<IHHQQQQIHHdqII")  # the data header, protocol/wire.md §4 (72 bytes)

_STARTED = []  # (process, private folder) of every daemon a test started: reaped after the test, also
# when it failed, and its folder of ipc:// sockets removed (a test run leaves no vafmd-* folder behind)


@pytest.fixture(autouse=True)
def reap_daemons():
    yield
    while _STARTED:
        p, folder = _STARTED.pop()
        if p.poll() is None:
            p.kill()
            p.wait()
        shutil.rmtree(folder, ignore_errors=True)


class Daemon:
    def __init__(self, *args, tcp=False, curve=None, env=None, preexec_fn=None):
        self.curve = curve  # (server public key, client public key, client secret key), Z85 bytes
        self.dir = tempfile.mkdtemp(prefix="vafmd-")
        if tcp:
            self.rep, self.pub = (f"tcp://127.0.0.1:{free_port()}", f"tcp://127.0.0.1:{free_port()}")
        else:
            self.rep, self.pub = f"ipc://{self.dir}/rep", f"ipc://{self.dir}/pub"
        self.proc = subprocess.Popen([VAFMD, "--rep", self.rep, "--pub", self.pub, *args],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     env={**os.environ, **env} if env else None, preexec_fn=preexec_fn)
        _STARTED.append((self.proc, self.dir))
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

    def sub(self, rcvhwm=None, topics=(b"",), curve=None, greet=False):
        """A SUB socket on the stream. greet: wait for the heartbeat the daemon sends every new
        subscriber, so the subscription is known to be in place (needs topics to include heartbeat)."""
        s = self.ctx.socket(zmq.SUB)
        s.setsockopt(zmq.LINGER, 0)
        self.secure(s, curve)
        if rcvhwm is not None:
            s.setsockopt(zmq.RCVHWM, rcvhwm)
        for t in topics:
            s.setsockopt(zmq.SUBSCRIBE, t)
        s.connect(self.pub)
        if greet:
            assert s.poll(TIMEOUT_MS), "no heartbeat after subscribing"
            assert s.recv_multipart()[0] == b"heartbeat"
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
        shutil.rmtree(self.dir, ignore_errors=True)
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


def messages_until(s, deadline, poll_ms=1000):
    """The multipart messages socket s receives until time.monotonic() reaches deadline, one at a time,
    waiting at most poll_ms for each; ends quietly at the deadline (the caller says what was missing)."""
    while time.monotonic() < deadline:
        if s.poll(poll_ms):
            yield s.recv_multipart()


def receive_run(s, run_id, timeout_ms=TIMEOUT_MS):
    """All messages of run `run_id` up to its run.end: (start, blocks, events, end, t_ns), blocks as
    (header, channel frames) and t_ns their receive times (time.monotonic_ns: CLOCK_MONOTONIC, the
    daemon's pacing clock)."""
    start, blocks, events, t_ns = None, [], [], []
    deadline = time.monotonic() + 120  # heartbeats keep the stream alive: bound the wait for run.end
    while True:
        assert time.monotonic() < deadline, "no run.end"
        if not s.poll(timeout_ms):
            raise AssertionError("stream went silent")
        parts = s.recv_multipart()
        now = time.monotonic_ns()
        topic = parts[0]
        if topic == b"data":
            h = HEADER.unpack(parts[1])
            if h[4] == run_id:
                blocks.append((h, parts[2:]))
                t_ns.append(now)
        elif topic in (b"run.start", b"run.end", b"event"):
            j = json.loads(parts[1])
            if j["run_id"] != run_id:
                continue
            if topic == b"run.start":
                start = start or j
            elif topic == b"event":
                events.append(j)
            else:
                return start, blocks, events, j, t_ns


def collect_run(s, run_id, timeout_ms=TIMEOUT_MS):
    """(start, blocks, events, end) of run `run_id` (receive_run without the times)."""
    return receive_run(s, run_id, timeout_ms)[:4]


def collect_run_timed(s, run_id, timeout_ms=TIMEOUT_MS):
    """(start, blocks, events, end, t_first, t_last): with the time.monotonic() receive times of the first
    and the last data block (None without blocks)."""
    start, blocks, events, end, t_ns = receive_run(s, run_id, timeout_ms)
    return start, blocks, events, end, t_ns[0] / 1e9 if t_ns else None, t_ns[-1] / 1e9 if t_ns else None


def error_ok(r, code, field=None):
    """r is an error reply with this stable code (and offending field, if given) and a message."""
    assert r["status"] == "error", r
    assert r["code"] == code, r
    assert isinstance(r["message"], str) and r["message"], r
    if field is not None:
        assert r["field"] == field, r
