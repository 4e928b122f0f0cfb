# SPDX-License-Identifier: MIT
"""pytest plugin: an instrument in every test. A test that asks for `vafmd` gets a fresh vafmd on free
endpoints, a connected `Client`, a `Stream`, its HDF5 log in the test's tmp_path as the ground truth, and
the daemon is stopped and checked (exit status, no process left) afterwards, also when the test failed.

    def test_pulloff(vafmd, vafm_scene, vafm_faults):
        vafm_scene("contact-silica", setpoint="1nN")      # a preset plus overrides with units
        faults = vafm_faults(drop=0.01, seed=3)           # a fault plan (protocol/faults.md)
        saved = my_acquisition.take(vafmd.rep, vafmd.pub, n=5)
        vafmd.assert_curves_match_log(saved)              # what it saved is the daemon's log, bit for bit
        vafmd.assert_faults_noticed(my_reports)           # every injected fault was noticed

Loaded by its `pytest11` entry point (python3-vafm-client, `make install`) or with
`-p vafm_client.pytest_plugin`. Options: --vafmd PATH, --vafm-speed, --vafm-keep-logs, --vafm-transport,
--vafm-share; markers `vafm(...)`, `vafm_engage(...)` and `skip_without_vafmd` (see pytest_configure).

The always-on controller (docs/instrument.md): a test that asks for `vafm_engaged` gets the same daemon with
its controller engaged at the setpoint (the auto-approach done, feedback on) and a Stream that carries the
`live` topic:

    @pytest.mark.vafm_engage(setpoint="1nN")
    def test_grid(vafm_engaged):
        live = vafm_engaged.live(50)                      # the next 50 monitor points, every channel
        assert abs(live["force_N"].mean() - 1e-9) < 1e-10
        vafm_engaged.client.move(1e-6, 0)                 # the acquisition code under test goes on from here

A test that asks for `vafm_nanonis` gets the vafmd fixture's daemon serving the Nanonis TCP programming
interface (docs/nanonis.md) on a free loopback port too: the fixture is its (host, port).
"""
import json
import math
import os
import re
import shutil
import signal
import socket
import subprocess
import tempfile
import threading
import time

import numpy as np
import pytest
import zmq

from .client import Client, Stream, TransportError

# faults.md §2: what a shorthand rate means for each kind (vafm_faults(drop=0.01) = per block)
_RATE = {"late": "per_block", "jitter": "per_block", "drop": "per_block", "stall": "per_block",
         "restart": "per_block", "saturate": "per_block", "dropout": "per_block", "truncate": "per_run",
         "no_trigger": "per_run", "kill": "per_run", "reply_delay": "per_command", "no_reply": "per_command",
         "busy": "per_command"}
# faults a client can notice, and the report (Stream.reports "kind") that notices it (faults.md §5)
NOTICEABLE = {"drop": "gap", "truncate": "truncated", "restart": "restart", "stall": "stall",
              "saturate": "saturate", "dropout": "dropout"}
# faults that leave a run's streamed samples incomplete or altered: such a run must not be saved as good
DAMAGING = ("drop", "truncate", "restart", "saturate", "dropout", "kill")
_PREFIX = {"": 1.0, "f": 1e-15, "p": 1e-12, "n": 1e-9, "u": 1e-6, "\u00b5": 1e-6, "m": 1e-3, "k": 1e3,
           "M": 1e6, "G": 1e9}
_QTY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(\S*)\s*$")
_SUN_PATH_MAX = 107  # bytes of an AF_UNIX socket path (ipc://) on Linux, without the NUL
_LIVE = set()        # every Instrument not yet stopped: reaped at the end of the session whatever happened


def pytest_addoption(parser):
    g = parser.getgroup("vafm", "vafm: a virtual AFM daemon (vafmd) for acquisition tests")
    g.addoption("--vafmd", metavar="PATH", help="the vafmd to test against (default: $VAFMD, else vafmd on "
                "PATH); a path given here that is not an executable is an error, not a skip")
    g.addoption("--vafm-speed", metavar="X", default=None,
                help="pacing of every daemon: 'free' (the default: as fast as it computes) or a multiple of "
                "real time (1 = real time, as an instrument); a vafm(speed=...) marker wins")
    g.addoption("--vafm-keep-logs", action="store_true",
                help="keep each daemon's HDF5 log and stderr in the test's tmp_path also when the test passed "
                "(they are always kept when it failed)")
    g.addoption("--vafm-transport", choices=("ipc", "tcp"), default="ipc",
                help="ipc (private sockets in a temporary folder, the default) or tcp (free loopback ports)")
    g.addoption("--vafm-share", choices=("test", "module"), default="test",
                help="a fresh daemon per test (default) or one per module")


def pytest_configure(config):
    if config.getoption("vafmd"):
        find_vafmd(config)  # an explicit --vafmd that is not an executable: a usage error at once
    config.addinivalue_line("markers", "vafm(preset=None, speed=None, args=(), share=None, transport=None, "
                            "log=True, nanonis=False): how the vafmd fixture starts its daemon (a preset, 'free' or "
                            "a multiple of real time, extra vafmd arguments, 'test' or 'module', 'ipc' or 'tcp', "
                            "HDF5 logging on or off, the Nanonis port on a free loopback port: also when the test "
                            "asks for vafm_nanonis)")
    config.addinivalue_line("markers", "vafm_engage(setpoint=None, settings=None, approach_speed=1000, "
                            "timeout=60): how vafm_engaged engages (the setpoint with a unit, '2nN' or '0.1V', or "
                            "a number in N; other ctrl_* settings, units allowed; the pacing factor of the "
                            "approach, restored after it; the most seconds the approach may take)")
    config.addinivalue_line("markers", "skip_without_vafmd: skip, naming the reason, when no vafmd is found "
                            "(without it a missing vafmd fails the test)")


def find_vafmd(config):
    """(path, None) of the vafmd to use, or (None, why not). An explicit --vafmd must be executable."""
    given = config.getoption("vafmd")
    if given:
        if os.path.isfile(given) and os.access(given, os.X_OK):
            return os.path.abspath(given), None
        raise pytest.UsageError(f"--vafmd {given}: not an executable file")
    env = os.environ.get("VAFMD")
    if env:
        if os.path.isfile(env) and os.access(env, os.X_OK):
            return os.path.abspath(env), None
        return None, f"$VAFMD={env} is not an executable file"
    path = shutil.which("vafmd")
    if path:
        return path, None
    return None, "no vafmd found: give --vafmd PATH, set $VAFMD, or install the vafm package (vafmd on PATH)"


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def quantity(value, unit):
    """A value in SI for a parameter whose unit is `unit` (the daemon's `get` info): numbers as they are,
    strings such as "1nN", "0.2 N/m", "300K", "5 um/s" converted; ValueError names what does not fit."""
    if not isinstance(value, str):
        return value
    m = _QTY.match(value)
    if not m:
        raise ValueError(f"{value!r} is not a number with a unit (e.g. '1nN')")
    x, u = float(m.group(1)), m.group(2)
    if u == unit or (not u and not unit):
        return x
    if u and u[0] in _PREFIX and u[1:] == unit:
        return x * _PREFIX[u[0]]
    raise ValueError(f"{value!r}: the unit must be {unit or 'none'} (with an SI prefix f p n u m k M G)")


class _Monitor(threading.Thread):
    """The instrument's own subscriber to the small topics (run.start, run.end, faults, heartbeat): the
    runs the daemon streamed and every fault record, whatever the code under test does with its stream."""

    def __init__(self, pub, timeout=10.0):
        super().__init__(daemon=True, name="vafmd-monitor")
        self.ctx = zmq.Context()
        self.sock = self.ctx.socket(zmq.SUB)
        self.sock.setsockopt(zmq.LINGER, 0)
        for t in (b"run.start", b"run.end", b"faults", b"heartbeat"):
            self.sock.setsockopt(zmq.SUBSCRIBE, t)
        self.sock.connect(pub)
        self.starts, self.ends, self.faults = {}, {}, []
        self.lock = threading.Lock()
        self.stop_ev = threading.Event()
        if not self.sock.poll(int(timeout * 1000)):  # the greeting heartbeat: the subscription is in place
            self.close()
            raise TransportError(f"{pub}: no heartbeat within {timeout} s")
        self.sock.recv_multipart()
        self.start()

    def run(self):
        while not self.stop_ev.is_set():
            if not self.sock.poll(50):
                continue
            topic, *rest = self.sock.recv_multipart()
            if topic == b"heartbeat" or not rest:
                continue
            msg = json.loads(rest[0])
            with self.lock:
                if topic == b"run.start":
                    self.starts.setdefault(msg["run_id"], msg)
                elif topic == b"run.end":
                    self.ends[msg["run_id"]] = msg
                elif topic == b"faults":
                    self.faults.append(msg)

    def close(self):
        self.stop_ev.set()
        if self.is_alive():
            self.join(5)
        self.sock.close(0)
        self.ctx.term()


class Instrument:
    """A vafmd started for a test. `rep`, `pub` (endpoints), `client` (a connected Client), `stream()` (a new
    Stream, closed at teardown), `log()` (every curve it logged, with its ground truth; the HDF5 files are
    in `log_path`, the test's folder, None without logging), `stderr_path`, `proc`, `folder`. The assert_*
    methods check what acquisition code must get right."""

    def __init__(self, vafmd, folder, args=(), transport="ipc", log=True, start_timeout=10.0):
        self.folder = str(folder)
        self._sockdir = None
        if transport == "tcp":
            self.rep, self.pub = f"tcp://127.0.0.1:{_free_port()}", f"tcp://127.0.0.1:{_free_port()}"
        else:
            base = self.folder
            if len(os.fsencode(os.path.join(base, "rep"))) > _SUN_PATH_MAX - 8:  # a long tmp_path: a short one
                base = self._sockdir = tempfile.mkdtemp(prefix="vafm-", dir="/tmp")
            self.rep, self.pub = f"ipc://{base}/rep", f"ipc://{base}/pub"
        self.args = [vafmd, "--rep", self.rep, "--pub", self.pub, *args]
        self.stderr_path = os.path.join(self.folder, "vafmd.stderr")
        self.log_path = self.folder if log else None  # the folder of its log files (see log())
        self._log_parts = []
        self.expected_status = 0
        self.failed = False  # a test that used it failed: its logs are kept
        self.client = None
        self.monitor = None
        self._streams = []
        self.status = None
        self.nanonis_port = None  # the Nanonis port (vafm_nanonis), None without one
        self._err = open(self.stderr_path, "wb")
        self.proc = subprocess.Popen(self.args, stdin=subprocess.DEVNULL, stdout=self._err, stderr=self._err,
                                     cwd=self.folder)
        _LIVE.add(self)
        try:
            self._wait_hello(start_timeout)
            self.monitor = _Monitor(self.pub)
            if self.log_path:
                self._log_start()
        except BaseException:
            self.stop(check=False)
            raise

    def _wait_hello(self, timeout):
        deadline = time.monotonic() + timeout
        while True:  # the first hello may race the bind: the client reopens its socket after each timeout
            self.client = Client(self.rep, timeout=0.5, retries=0)
            try:
                self.hello = self.client.hello()
                self.client.timeout, self.client.retries = 20.0, 2
                return
            except TransportError:
                self.client.close()
                self.client = None
                if self.proc.poll() is not None:
                    raise RuntimeError(f"vafmd exited with status {self.proc.returncode} at start-up: "
                                       f"{self.stderr().strip()}") from None
                if time.monotonic() > deadline:
                    raise RuntimeError(f"vafmd did not answer hello within {timeout} s") from None

    def stderr(self, limit=16384):
        """What the daemon wrote to stdout/stderr so far (the last `limit` bytes)."""
        try:
            with open(self.stderr_path, "rb") as f:
                f.seek(max(0, os.path.getsize(self.stderr_path) - limit))
                return f.read().decode(errors="replace")
        except OSError:
            return ""

    def stream(self, **kw):
        """A Stream on this daemon (subscribed, its greeting received), closed at teardown."""
        s = Stream(self.pub, **kw)
        self._streams.append(s)
        return s

    def expect_exit(self, status):
        """The exit status teardown expects (a `kill` fault's status; default 0)."""
        self.expected_status = status

    # -- the ground truth ------------------------------------------------------------------------------
    def runs(self, timeout=10.0):
        """{run_id: (run.start, run.end or None)} of every run the daemon streamed, once it is idle."""
        self._settle(timeout)
        with self.monitor.lock:
            return {r: (s, self.monitor.ends.get(r)) for r, s in sorted(self.monitor.starts.items())}

    def fault_records(self, timeout=10.0):
        """Every fault the daemon injected (faults.md §3), complete: waits until the records received number
        the daemon's `count`."""
        deadline = time.monotonic() + timeout
        count = None
        while True:
            if self.proc.poll() is None:
                count = self.client.faults()["count"]
            with self.monitor.lock:
                got = list(self.monitor.faults)
            if count is None or len(got) >= count or time.monotonic() > deadline:
                if count is not None and len(got) < count:
                    raise AssertionError(f"the daemon injected {count} faults, {len(got)} records arrived")
                return got
            time.sleep(0.01)

    def _settle(self, timeout):
        """Idle, and every run.end it published received by the monitor."""
        if self.proc.poll() is not None:
            return
        self.client.wait_idle(timeout)
        want = self.client.status().get("last_run_id")
        # run.end goes out before the daemon is idle, on the stream: wait for the monitor to have it (a
        # truncated run has none: its run.start, and a short grace, do)
        deadline, grace = time.monotonic() + timeout, time.monotonic() + 1.0
        while want and time.monotonic() < deadline:
            with self.monitor.lock:
                if want in self.monitor.ends or (want in self.monitor.starts and time.monotonic() > grace):
                    return
            time.sleep(0.005)

    def _log_start(self):
        self._log_parts.append(os.path.join(self.folder, f"vafmd-{len(self._log_parts) + 1}.h5"))
        self.client.request({"cmd": "log", "path": self._log_parts[-1], "overwrite": True})

    def log(self):
        """Every curve the daemon logged so far, as a list of vafm_client.Curve (channels, metadata, the
        ground-truth row `truth`; needs h5py). Logging is stopped so the file is complete and closed, and
        goes on in a new file (the log files are vafmd-1.h5, vafmd-2.h5, ... in the test's folder)."""
        from .h5 import load_h5
        if not self.log_path:
            raise RuntimeError("this daemon logs nothing: vafm(log=False)")
        if self.proc.poll() is None:
            self._settle(30.0)
            self.client.request({"cmd": "log", "stop": True})
            self._log_start()
        curves = []
        for p in self._log_parts[:-1] if self.proc.poll() is None else self._log_parts:
            if os.path.exists(p):
                curves += load_h5(p).curves
        return curves

    # -- what acquisition code must get right ------------------------------------------------------------
    def assert_curves_match_log(self, curves, channels=(("force_N", "force"), ("height_m", "height (piezo)"))):
        """Each saved curve (a mapping or object with `index`, the curve index of `curve`, and the channel
        arrays force_N and height_m) equals the daemon's logged curve of that index bit for bit."""
        logged = {}
        for c in self.log():
            logged.setdefault(int(c.truth["curve"]) if c.truth is not None else None, c)
        assert curves, "no curve saved"
        for cur in curves:
            get = cur.__getitem__ if isinstance(cur, dict) else lambda k, cur=cur: getattr(cur, k)
            idx = int(get("index"))
            assert idx in logged, f"curve {idx}: saved, but the daemon logged no curve {idx} (logged: {sorted(logged)})"
            for mine, theirs in channels:
                a = np.ascontiguousarray(get(mine), dtype="<f8")
                b = np.ascontiguousarray(logged[idx][theirs], dtype="<f8")
                if a.shape != b.shape:
                    raise AssertionError(f"curve {idx}: {mine} has {a.size} samples, the daemon's log "
                                         f"{b.size} (samples lost or added)")
                if a.tobytes() != b.tobytes():
                    k = int(np.flatnonzero(a.view("<u8") != b.view("<u8"))[0])
                    raise AssertionError(f"curve {idx}: {mine}[{k}] = {a[k]!r}, the daemon's log {b[k]!r} "
                                         f"(not bit for bit)")

    def assert_pulloffs(self, measured, k=3.0, truth="pulloff_sampled_N"):
        """Each recorded pull-off is within k standard errors of the ground truth: `measured` maps a curve
        index to (pull-off in N, its standard error in N); the truth is the log's `truth` column."""
        rows = {int(c.truth["curve"]): c.truth for c in self.log() if c.truth is not None}
        assert measured, "no pull-off recorded"
        bad = []
        for idx, (value, se) in sorted(measured.items()):
            assert idx in rows, f"curve {idx}: no ground truth in the daemon's log (logged: {sorted(rows)})"
            t = float(rows[idx][truth])
            if not (math.isfinite(value) and se >= 0 and abs(value - t) <= k * se):
                bad.append(f"curve {idx}: {value!r} +- {se!r} N, truth {truth} {t!r} N "
                           f"({(value - t) / se if se else math.inf:+.2f} standard errors)")
        assert not bad, f"pull-off off by more than {k} standard errors: " + "; ".join(bad)

    def assert_faults_noticed(self, reports):
        """Every injected fault a client can notice (faults.md §5) was noticed: `reports` are dicts with
        "kind" (gap, truncated, restart, stall, saturate, dropout: as Stream.reports) and, for faults in a
        run, "run_id". Returns the records checked."""
        records = self.fault_records()
        seen = {(r.get("kind"), r.get("run_id")) for r in reports}
        kinds = {r.get("kind") for r in reports}
        missed = []
        for rec in records:
            want = NOTICEABLE.get(rec["kind"])
            if want is None or (rec["kind"] == "dropout" and rec["params"].get("value") == "stuck"):
                continue  # not detectable by a client (late, jitter, command faults, a stuck detector)
            if rec["kind"] in ("restart", "stall"):
                ok = want in kinds
            else:
                ok = (want, rec["run_id"]) in seen
            if not ok:
                missed.append(f"fault {rec['n']} {rec['kind']} (run {rec['run_id']}, block {rec['block']}): "
                              f"no {want!r} report")
        assert not missed, "injected faults not noticed: " + "; ".join(missed)
        return records

    def assert_nothing_dropped(self, saved, reported=()):
        """Every run the daemon streamed was saved or reported as lost (`saved`, `reported`: run ids), and no
        run that a fault damaged (a lost block, a truncation, a restart, altered samples) was saved."""
        runs = self.runs()
        saved, reported = set(saved), set(reported)
        damaged = {}
        for rec in self.fault_records():
            if rec["kind"] in DAMAGING and rec.get("run_id") is not None:
                damaged.setdefault(rec["run_id"], []).append(f"fault {rec['n']} {rec['kind']} at block {rec['block']}")
        silent = sorted(set(runs) - saved - reported)
        assert not silent, f"runs {silent} were streamed but neither saved nor reported (silently dropped)"
        bad = sorted(r for r in saved if r in damaged)
        assert not bad, "runs saved as good although a fault damaged them: " + "; ".join(
            f"run {r}: {', '.join(damaged[r])}" for r in bad)
        unknown = sorted(saved - set(runs))
        assert not unknown, f"runs {unknown} were saved but the daemon streamed no such run"

    # -- teardown ------------------------------------------------------------------------------------------
    def stop(self, check=True):
        """Stop the daemon (shutdown, then SIGKILL after 10 s) and return a list of what went wrong."""
        problems = []
        for s in self._streams:
            s.close()
        self._streams = []
        if self.proc.poll() is None:
            try:
                if self.client is not None:
                    self.client.request({"cmd": "shutdown"}, timeout=5.0, retries=0)
            except Exception:  # noqa: BLE001 (no reply: the wait and the kill below)
                pass
        try:
            self.status = self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.send_signal(signal.SIGKILL)
            self.status = self.proc.wait()
            problems.append(f"vafmd (pid {self.proc.pid}) did not exit within 10 s of shutdown: killed")
        if self.client is not None:
            self.client.close()
            self.client = None
        if self.monitor is not None:
            self.monitor.close()
            self.monitor = None
        self._err.close()
        if self._sockdir:
            shutil.rmtree(self._sockdir, ignore_errors=True)
        _LIVE.discard(self)
        if check and not problems and self.status != self.expected_status:
            problems.append(f"vafmd exited with status {self.status}, expected {self.expected_status}")
        return problems


def _marker(request):
    m = request.node.get_closest_marker("vafm")
    return dict(m.kwargs) if m else {}


def _start(request, folder, opts):
    path, why = find_vafmd(request.config)
    if path is None:
        if request.node.get_closest_marker("skip_without_vafmd"):
            pytest.skip(why)
        pytest.fail(why + " (mark the test skip_without_vafmd to skip instead)", pytrace=False)
    args = []
    if opts.get("preset"):
        args += ["--preset", opts["preset"]]
    speed = opts.get("speed", request.config.getoption("vafm_speed"))
    if speed is None or str(speed) == "free":
        args.append("--free-run")
    else:
        args += ["--speed", str(float(speed))]
    nanonis = None
    if opts.get("nanonis") or "vafm_nanonis" in getattr(request, "fixturenames", ()):
        nanonis = _free_port()
        args += ["--nanonis", f"127.0.0.1:{nanonis}"]
    args += list(opts.get("args", ()))
    inst = Instrument(path, folder, args, transport=opts.get("transport") or request.config.getoption("vafm_transport"),
                      log=opts.get("log", True))
    inst.nanonis_port = nanonis
    return inst


def _finish(inst, keep):
    problems = inst.stop()
    if not (keep or inst.failed or problems):  # a passing test leaves no log behind (--vafm-keep-logs keeps it)
        for p in [*inst._log_parts, inst.stderr_path]:
            if os.path.exists(p):
                os.unlink(p)
    if problems:
        pytest.fail("; ".join(problems) + f"\n--- vafmd stderr ---\n{inst.stderr()}", pytrace=False)


@pytest.fixture(scope="module")
def vafmd_module(request, tmp_path_factory):
    """One vafmd for the whole module (the vafm marker's preset/speed/args of the module apply)."""
    opts = _marker(request)
    inst = _start(request, tmp_path_factory.mktemp("vafmd"), opts)
    request.node.vafm_instruments = getattr(request.node, "vafm_instruments", []) + [inst]
    yield inst
    _finish(inst, request.config.getoption("vafm_keep_logs"))


@pytest.fixture
def vafmd(request, tmp_path):
    """A fresh vafmd for this test (one per module with vafm(share="module") or --vafm-share module)."""
    opts = _marker(request)
    share = opts.get("share") or request.config.getoption("vafm_share")
    if share == "module":
        inst = request.getfixturevalue("vafmd_module")
        request.node.vafm_instruments = [inst]
        yield inst
        return
    inst = _start(request, tmp_path, opts)
    request.node.vafm_instruments = [inst]
    yield inst
    _finish(inst, request.config.getoption("vafm_keep_logs"))


@pytest.fixture
def vafm_client(vafmd):
    """The vafmd fixture's connected Client."""
    return vafmd.client


@pytest.fixture
def vafm_stream(vafmd):
    """A Stream on the vafmd fixture's daemon (subscribed before the test starts a run)."""
    return vafmd.stream()


@pytest.fixture
def vafm_scene(vafmd):
    """scene(preset=None, **overrides): set the daemon's scene from a preset plus parameters, given in SI
    (`k_N_per_m=0.2`) or in the instrument's words with units (`setpoint="1nN"`, `T="300K"`: the parameter
    whose name is the word plus its unit). Returns the values set (SI names)."""
    info = vafmd.client.get(info=True)[1]

    def scene(preset=None, **overrides):
        values = {}
        for word, v in overrides.items():
            if word in info:
                values[word] = quantity(v, info[word].get("unit") or "")
                continue
            cands = sorted(n for n in info if n.startswith(word + "_"))
            if not cands:
                raise ValueError(f"{word}: no such parameter (see vafm params)")
            errs = []
            for n in cands:
                try:
                    values[n] = quantity(v, info[n].get("unit") or "")
                    break
                except ValueError:
                    errs.append(f"{n} [{info[n].get('unit')}]")
            else:
                raise ValueError(f"{word}={v!r}: give a unit of one of {', '.join(errs)}")
        vafmd.client.set(values or None, preset=preset)
        return values

    return scene


class FaultPlan:
    """A fault plan set on a daemon: `plan` (as sent), `records()` (the faults injected so far)."""

    def __init__(self, inst, plan):
        self.inst, self.plan = inst, plan
        inst.client.faults(plan)

    def records(self):
        return self.inst.fault_records()

    def clear(self):
        self.inst.client.faults(clear=True)


@pytest.fixture
def vafm_faults(vafmd):
    """faults(seed=0, script=None, **kinds): set a fault plan (protocol/faults.md). A kind given a number is
    a random rate (drop=0.01: per block; truncate, no_trigger, kill: per run; command kinds: per command), a
    dict is passed as it is (drop={"per_block": 0.1, "blocks": 2}). Returns a FaultPlan."""

    def faults(seed=0, script=None, **kinds):
        plan = {"seed": seed}
        if script:
            plan["script"] = list(script)
        rnd = {}
        for kind, v in kinds.items():
            if kind not in _RATE:
                raise ValueError(f"{kind}: not a fault kind ({', '.join(sorted(_RATE))})")
            rnd[kind] = dict(v) if isinstance(v, dict) else {_RATE[kind]: float(v)}
        if rnd:
            plan["random"] = rnd
        return FaultPlan(vafmd, plan)

    return faults


class Engaged:
    """An instrument whose controller is engaged (the vafm_engaged fixture): `vafmd` (the Instrument),
    `client`, `stream` (a Stream with the `live` topic), `event` (the `engaged` event), `generation` (the
    controller's, wire.md §2.4), `ctrl()` (status.ctrl now), `live(n)` (the next n monitor points)."""

    def __init__(self, inst, stream, event):
        self.vafmd, self.client, self.stream, self.event = inst, inst.client, stream, event
        self.generation = event.get("generation")

    def ctrl(self):
        return self.client.status()["ctrl"]

    def live(self, n, timeout=30.0):
        """{channel: numpy array} of the next n points of the `live` topic (wire.md §3.7), of this controller
        and of those that took its state over (a `set` rebuilds the controller and carries its state: a later
        generation, the same samples going on); raises TransportError if they do not come within `timeout` s
        (or a live message is lost: the points would not be consecutive)."""
        deadline = time.monotonic() + timeout
        since = self.event.get("sample")  # points that begin before the engaged event are not "engaged" points
        parts, got, last = [], 0, None
        for topic, x in self.stream.messages(deadline=deadline):
            if topic != "live" or (x[0].get("generation") or 0) < (self.generation or 0):
                continue
            h, ch = x
            if last is not None and h["seq"] != last + 1:
                raise TransportError(f"live message {last + 1} lost (next seen: {h['seq']})")
            last = h["seq"]
            skip = 0
            if since is not None and not parts:  # the stream may hold points from before the engage ended
                m = int(h.get("decimation") or 1)
                skip = min(h["points"], max(0, -(-(since - int(h["first_sample"])) // m)))
            if skip == h["points"]:
                continue
            parts.append({c: v[skip:] for c, v in ch.items()})
            got += h["points"] - skip
            if got >= n:
                break
        return {c: np.concatenate([p[c] for p in parts])[:n] for c in parts[0]}


def _ctrl_event(stream, kinds, generation, deadline):
    for topic, m in stream.messages(deadline=deadline):
        if topic == "event" and m.get("source") == "ctrl" and m.get("kind") in kinds and \
                (generation is None or m.get("generation") == generation):
            return m
    return None


def engage(inst, setpoint=None, settings=None, approach_speed=1000, timeout=60.0):
    """Engage the controller of `inst` (an Instrument): the ctrl_* settings and the setpoint (rebuilding the
    controller), the auto-approach at pacing factor approach_speed (the `speed` setting is restored after
    it), and wait for `engaged`. Returns an Engaged; raises RuntimeError naming the reason if the approach
    failed, crashed or took longer than `timeout` seconds of wall-clock time."""
    c = inst.client
    values = {}
    if settings:
        info = c.get(info=True)[1]
        for name, v in settings.items():
            name = name if name.startswith("ctrl_") else "ctrl_" + name
            if name not in info:
                raise ValueError(f"{name}: no such controller setting (see protocol/wire.md §2.4)")
            values[name] = quantity(v, info[name].get("unit") or "")
    if setpoint is not None:
        unit = "N"
        if isinstance(setpoint, str):
            unit = "V" if setpoint.strip().endswith("V") else "N"
            setpoint = quantity(setpoint, unit)
        values.update(ctrl_setpoint=float(setpoint), ctrl_setpoint_unit=unit)
    stream = inst.stream(live=True)
    st = c.status()["ctrl"]
    if not st.get("available"):
        raise RuntimeError(f"the daemon has no controller: {st.get('error')}")
    if values:
        c.set(values)  # the controller keeps its state (ctrl_motor_z0_m would start it again from far away)
    elif st["state"] == "engaged":  # a shared daemon already engaged as asked
        return Engaged(inst, stream, {"kind": "engaged", "generation": st["generation"], "reused": True})
    st = c.status()["ctrl"]
    if st["state"] in ("approaching", "engaged", "crashed"):
        c.withdraw()
        if _ctrl_event(stream, ("withdrawn",), st["generation"], time.monotonic() + timeout) is None:
            raise RuntimeError("the controller did not withdraw")
    speed = c.get("speed")["speed"]
    c.set({"speed": float(approach_speed)})
    try:
        r = c.engage()
        gen = r["ctrl"]["generation"]
        ev = _ctrl_event(stream, ("engaged", "engage_failed", "crash"), gen, time.monotonic() + timeout)
    except TransportError:
        ev = None
    finally:
        c.set({"speed": speed})
    if ev is None:
        raise RuntimeError(f"no engaged event within {timeout} s (status: {c.status()['ctrl']})")
    if ev["kind"] != "engaged":
        raise RuntimeError(f"engage failed: {ev}")
    return Engaged(inst, stream, ev)


@pytest.fixture
def vafm_engaged(vafmd, request):
    """The vafmd fixture's daemon with its controller engaged at the setpoint (the marker vafm_engage's, else
    the daemon's ctrl_setpoint), feedback on, and a Stream carrying the `live` topic. Returns an Engaged."""
    m = request.node.get_closest_marker("vafm_engage")
    opts = dict(m.kwargs) if m else {}
    try:
        return engage(vafmd, **opts)
    except RuntimeError as e:
        pytest.fail(f"vafm_engaged: {e}\n--- vafmd stderr ---\n{vafmd.stderr()}", pytrace=False)


@pytest.fixture
def vafm_nanonis(vafmd):
    """(host, port) of the vafmd fixture's Nanonis TCP programming interface (docs/nanonis.md), loopback."""
    if getattr(vafmd, "nanonis_port", None) is None:
        pytest.fail("vafm_nanonis: this daemon was started without --nanonis (a module-shared daemon: mark "
                    "the module vafm(nanonis=True))", pytrace=False)
    return ("127.0.0.1", vafmd.nanonis_port)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    rep = outcome.get_result()
    if rep.failed:
        for inst in getattr(item, "vafm_instruments", []):
            inst.failed = True
            rep.sections.append((f"vafmd stderr (pid {inst.proc.pid}, {inst.rep})", inst.stderr() or "(empty)"))
            if inst._log_parts:
                rep.sections.append(("vafmd log", "\n".join(inst._log_parts)))


def pytest_sessionfinish(session):
    for inst in list(_LIVE):  # a daemon whose fixture never finished (an interrupted run): no process left
        inst.stop(check=False)
