# SPDX-License-Identifier: MIT
"""Fault injection (issue 14 part 2, protocol/faults.md): vafmd misbehaves on purpose, records what it
injected, and the project's clients (the Python Stream/Client, `vafm listen`) report every detectable fault
and never keep wrong data without saying so. One test per class of fault, then a "chaos" campaign with
several kinds at random rates. Runs: paper-fig4 in free_run (~0.1 s per curve).
"""
import json
import os
import signal
import subprocess
import sys
import threading
import time

import h5py
import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "clients", "python"))
from vafm_client import (Client, DaemonError, Stream, TransportError, TruncatedError,  # noqa: E402
                         load_h5, spawn)

VAFMD = os.environ.get("VAFMD")
VAFM_CLI = os.environ.get("VAFM_CLI")
# Required, as .ci/deps.sh installs them and meson test sets the variables: a missing one fails the
# module with the reason, never skips it.
for _var in ("VAFMD", "VAFM_CLI"):
    if not os.environ.get(_var):
        raise RuntimeError(f"{_var} is not set: run this module with meson test (it sets VAFMD, VAFM_CLI)")


class Daemon(spawn.Daemon):
    def __init__(self, *args):
        super().__init__(VAFMD, *args)

    def listen(self, *args):
        """A `vafm listen` process, returned once it is subscribed."""
        p = subprocess.Popen([VAFM_CLI, "listen", "--endpoint", self.rep, "--pub", self.pub, *args],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        lines = []
        while True:
            line = p.stderr.readline()
            assert line, "".join(lines)
            lines.append(line)
            if "subscribed" in line:
                break
        p.early = "".join(lines)
        return p


@pytest.fixture
def fig4():
    d = Daemon("--preset", "paper-fig4", "--free-run")
    yield d
    assert d.stop() == 0


def finish(p, timeout=60):
    err = p.early + p.stderr.read()
    return p.wait(timeout=timeout), err


def reference(d, index, stream):
    """The fault-free curve `index` of the daemon's scene (a plan-free run on the same daemon)."""
    c = d.client
    plan = c.faults()["plan"]
    c.faults(clear=True)
    run = stream.run(c.curve(index=index)["run_id"], timeout=20)
    c.wait_idle()
    if plan:
        c.faults(plan)
    return run


def test_plan_validation(fig4):
    c = fig4.client
    bad = [({"script": [{"kind": "late", "delay_s": 11}]}, "out_of_range", "script[0].delay_s", "(0, 10]"),
           ({"script": [{"kind": "drop", "blocks": 1.5}]}, "wrong_type", "script[0].blocks", "integer"),
           ({"script": [{"kind": "nope"}]}, "out_of_range", "script[0].kind", "late, jitter"),
           ({"script": [{"block": 1}]}, "missing_field", "script[0].kind", "kind"),
           ({"script": [{"kind": "drop", "run": 0}]}, "out_of_range", "script[0].run", "below 1"),
           ({"script": [{"kind": "drop", "block": 1, "time_s": 0.1}]}, "out_of_range", "script[0].time_s", "not both"),
           ({"script": [{"kind": "busy", "block": 1}]}, "unknown_field", "script[0].block", "cmd, nth"),
           ({"script": [{"kind": "no_reply", "cmd": "frobnicate"}]}, "out_of_range", "script[0].cmd", "no command"),
           # 0.6.1 took a fault of `faults` itself (never fired) and refused one of `map`
           ({"script": [{"kind": "busy", "cmd": "faults"}]}, "out_of_range", "script[0].cmd", "never faulted"),
           ({"random": {"busy": {"per_command": 0.5, "cmd": "faults"}}}, "out_of_range", "random.busy.cmd",
            "never faulted"),
           ({"random": {"drop": {"per_block": 2}}}, "out_of_range", "random.drop.per_block", "[0, 1]"),
           ({"random": {"drop": {}}}, "missing_field", "random.drop", "per_block or per_run"),
           ({"random": {"busy": {"per_block": 0.1}}}, "unknown_field", "random.busy.per_block", "per_command"),
           ({"random": {"dropout": {"per_run": 0.1, "value": "zero"}}}, "out_of_range", "random.dropout.value",
            "nan|stuck"),
           ({"seed": -1}, "out_of_range", "seed", "non-negative"),
           ({"sede": 1}, "unknown_field", "sede", "seed, script, random"),
           ({"script": [{"kind": "no_trigger", "delay_s": 1}]}, "unknown_field", "script[0].delay_s", "no_trigger")]
    for plan, code, field, text in bad:
        with pytest.raises(DaemonError) as e:
            c.faults(plan)
        assert (e.value.code, e.value.field) == (code, field), (plan, e.value.reply)
        assert text in e.value.message, e.value.message
    with pytest.raises(DaemonError) as e:
        c.request({"cmd": "faults", "clear": True, "plan": {}})
    assert e.value.field == "clear"
    assert c.faults()["plan"] is None  # nothing was installed by a bad plan
    plan = {"seed": "18446744073709551615", "script": [{"kind": "drop", "run": 7, "block": 1}],
            "random": {"late": {"per_block": 0.5, "delay_s": 0.01}}}
    r = c.faults(plan)
    assert r["plan"] == plan and r["count"] == 0 and r["last"] == []
    assert c.status()["faults"]["plan"] == plan and "faults" in c.hello()["capabilities"]
    assert c.faults(clear=True)["plan"] is None
    assert c.faults({"script": [{"kind": "busy", "cmd": "map"}]})["plan"]["script"][0]["cmd"] == "map"
    assert c.faults(clear=True)["plan"] is None


def test_config_plan(tmp_path):
    cfg = tmp_path / "d.json"
    cfg.write_text(json.dumps({"faults": {"script": [{"kind": "late", "delay_s": 20}]}}))
    p = subprocess.run([VAFMD, "--config", str(cfg), "--rep", f"ipc://{tmp_path}/r", "--pub", f"ipc://{tmp_path}/p"],
                       capture_output=True, text=True, timeout=20)
    assert p.returncode == 2 and "script[0].delay_s" in p.stderr and "(0, 10]" in p.stderr
    cfg.write_text(json.dumps({"preset": "paper-fig4", "values": {"free_run": True},
                               "faults": {"script": [{"kind": "drop", "run": 1, "block": 3}]}}))
    d = Daemon("--config", str(cfg))
    with Stream(d.pub) as s:
        run = s.run(d.client.curve(index=0)["run_id"], strict=False)
        assert run.gaps == 1 and [r["kind"] for r in s.reports] == ["gap"]
        last = d.client.status()["faults"]["last"]
        assert [(f["kind"], f["run_id"], f["block"]) for f in last] == [("drop", 1, 3)]
    assert d.stop() == 0


def test_drop_gap_reported(fig4, tmp_path):
    c = fig4.client
    c.faults({"script": [{"kind": "drop", "run": 1, "block": 2, "blocks": 2}]})
    out = tmp_path / "x.h5"
    li = fig4.listen("--out", str(out), "--runs", "2")
    with Stream(fig4.pub) as s:
        with pytest.raises(TruncatedError.__mro__[1]):  # GapError
            s.run(c.curve(index=0)["run_id"])
        c.wait_idle()
        ok = s.run(c.curve(index=0)["run_id"])  # the next run is complete and clean
        assert ok.clean
        assert s.reports == [{"kind": "gap", "run_id": 1, "blocks": 2, "seq": 2}]
    rc, err = finish(li)
    assert rc == 1 and "run 1: 2 data block(s) lost" in err, err
    f = load_h5(str(out))
    assert len(f.curves) == 1
    (fault,) = c.faults()["last"]
    assert (fault["kind"], fault["run_id"], fault["block"], fault["seq"], fault["params"]) == \
        ("drop", 1, 2, 2, {"blocks": 2})


def test_truncate_reported_and_not_written(fig4, tmp_path):
    c = fig4.client
    c.request({"cmd": "log", "path": str(tmp_path / "daemon.h5")})
    c.faults({"script": [{"kind": "truncate", "run": 1, "time_s": 0.02}]})
    out = tmp_path / "x.h5"
    li = fig4.listen("--out", str(out), "--runs", "2")
    with Stream(fig4.pub) as s:
        r1 = c.curve(index=0)["run_id"]
        c.wait_idle()  # the run is over for the daemon
        r2 = c.curve(index=1)["run_id"]
        got = []
        for r in s.runs(deadline=time.monotonic() + 20):  # the truncated run comes out when the next starts
            got.append(r)
            if r.run_id == r2:
                break
        assert [(r.run_id, r.truncated, r.complete) for r in got] == [(r1, True, False), (r2, False, True)]
    rc, err = finish(li)
    assert rc == 1 and "run 1: no run.end" in err and "truncated" in err, err
    assert len(load_h5(str(out)).curves) == 1  # only run 2
    st = c.status()
    assert st["state"] == "idle" and st["log"]["curves"] == 1 and st["log"]["curves_skipped"] == 1
    with Stream(fig4.pub) as s:
        c.faults({"script": [{"kind": "truncate", "run": 3, "block": 1}]})
        with pytest.raises(TruncatedError):
            s.run(c.curve(index=0)["run_id"])  # the heartbeat after it says the daemon is past the run
        assert [r["kind"] for r in s.reports] == ["truncated"]
    c.request({"cmd": "log", "stop": True})
    f = load_h5(str(tmp_path / "daemon.h5"))
    assert len(f.curves) == 1


def test_restart_and_stall_reported(fig4):
    c = fig4.client
    s0 = c.hello()["session"]
    c.faults({"script": [{"kind": "restart", "run": 1, "block": 3}, {"kind": "stall", "run": 2, "block": 1,
                                                                      "duration_s": 1.6}]})
    li = fig4.listen("--out", "-", "--runs", "2")
    with Stream(fig4.pub) as s:
        with pytest.raises(TruncatedError):
            s.run(c.curve(index=0)["run_id"])
        s1 = c.hello()["session"]
        assert s1 != s0 and s.session == s1
        c.wait_idle()
        run = s.run(c.curve(index=0)["run_id"])  # a stall loses nothing: complete and clean
        assert run.clean
        time.sleep(1.2)  # the heartbeat after the stall reveals it (the 1 s grid skipped beats)
        with pytest.raises(TransportError):
            list(s.runs(deadline=time.monotonic() + 1.5))
        kinds = [r["kind"] for r in s.reports]
        assert kinds == ["restart", "stall"], s.reports
        assert s.reports[0]["old_session"] == s0 and s.reports[1]["silent_s"] >= 1.6
    rc, err = finish(li)
    assert rc == 1 and "publisher restarted" in err and "run 1: the publisher restarted" in err, err
    assert "stalled" in err, err
    last = c.faults()["last"]
    assert [f["kind"] for f in last] == ["restart", "stall"] and last[0]["session"] == s1


@pytest.mark.parametrize("how", ["signal", "command"])
def test_shutdown_cuts_a_stall_short(how):
    """A stall holds the stream, not the daemon's end: SIGTERM or `shutdown` during a 30 s stall ends
    vafmd within seconds, status 0 (0.6.1 waited the stall out)."""
    d = Daemon("--preset", "paper-fig4", "--free-run")
    c = d.client
    c.faults({"script": [{"kind": "stall", "block": 1, "duration_s": 30}]})
    c.curve(index=0)
    time.sleep(0.5)  # the run has reached its block 1: the stream is silent now
    t0 = time.monotonic()
    if how == "signal":
        d.proc.send_signal(signal.SIGTERM)
    else:
        c.shutdown()
    rc = d.proc.wait(timeout=20)
    took = time.monotonic() - t0
    d.stop()
    assert rc == 0 and took < 5, (rc, took)


def test_late_and_jitter_no_false_alarm(fig4):
    c = fig4.client
    with Stream(fig4.pub) as s:
        ref = reference(fig4, 2, s)
        c.faults({"seed": 5, "script": [{"kind": "late", "block": 1, "delay_s": 0.3}],
                  "random": {"jitter": {"per_block": 0.3, "max_s": 0.01}}})
        t0 = time.monotonic()
        run = s.run(c.curve(index=2)["run_id"])
        assert time.monotonic() - t0 >= 0.3
        assert run.clean and s.reports == []
        for ch in ("force_N", "height_m", "tip_m", "vDeflection_V"):
            assert np.array_equal(run[ch], ref[ch])
    kinds = [f["kind"] for f in c.faults()["last"]]
    assert kinds[0] == "late" or "late" in kinds and "jitter" in kinds


def test_detector_faults_kept_as_is(fig4, tmp_path):
    c = fig4.client
    with Stream(fig4.pub) as s:
        ref = reference(fig4, 1, s)
        c.faults({"script": [{"kind": "dropout", "block": 1, "samples": 40},
                             {"kind": "dropout", "block": 4, "samples": 30, "value": "stuck"},
                             {"kind": "saturate", "block": 6, "samples": 20, "level_V": 7.5}]})
        csv = tmp_path / "x.csv"
        li = fig4.listen("--out", str(csv), "--runs", "1")
        run = s.run(c.curve(index=1)["run_id"])
        n = run.headers[0].n_samples
        assert run.complete and not run.clean and run.nan_samples == 40 and run.clipped_blocks == 1
        f = run["force_N"]
        assert np.isnan(f[n:n + 40]).all() and np.isfinite(f[:n]).all()
        assert (f[4 * n:4 * n + 30] == ref["force_N"][4 * n - 1]).all()  # stuck at the last good value
        assert (run["vDeflection_V"][6 * n:6 * n + 20] == 7.5).all()
        mask = np.ones(len(f), bool)
        mask[n:n + 40] = mask[4 * n:4 * n + 30] = mask[6 * n:6 * n + 20] = False
        assert np.array_equal(f[mask], ref["force_N"][mask])  # nothing else changed
        assert np.array_equal(run["tip_m"], ref["tip_m"])       # the ground truth is untouched
        assert [r["kind"] for r in s.reports] == ["dropout", "saturate"]
    rc, err = finish(li)
    assert rc == 0 and "40 sample(s) with NaN" in err and "1 block(s) flagged CLIPPED" in err, err
    rows = [line.split(",") for line in csv.read_text().splitlines()[1:]]
    assert sum(r[3] == "nan" for r in rows) == 40  # recorded as it came, never cleaned
    with Stream(fig4.pub) as s:  # to HDF5 (finite values only, L16) a NaN curve is refused, with a reason
        li = fig4.listen("--out", str(tmp_path / "y.h5"), "--runs", "1")
        s.run(c.curve(index=1)["run_id"], strict=False)
        rc, err = finish(li)
        assert rc == 1 and "detector dropout" in err and "L16" in err, err


def test_altered_force_written_without_tip(fig4, tmp_path):
    """A saturate or stuck-dropout fault alters the force and not the ground-truth tip, so the force is a
    measured one: vafmd's log and `vafm listen` write the curve without 'tip position' (hdf5.md V2, as with
    the detector on). 0.6.1 refused it (L14: log_failed in the log, exit 1 in listen)."""
    c = fig4.client
    log = tmp_path / "log.h5"
    assert c.request({"cmd": "log", "path": str(log)})["status"] == "ok"
    plans = [{"script": [{"kind": "saturate", "block": 2, "samples": 10}]},
             {"script": [{"kind": "dropout", "block": 2, "samples": 10, "value": "stuck"}]}]
    for i, plan in enumerate(plans):
        c.faults(plan)
        out = tmp_path / f"listen{i}.h5"
        li = fig4.listen("--out", str(out), "--runs", "1")
        c.curve(index=1)
        c.wait_idle()
        rc, err = finish(li)
        assert rc == 0, err
        with h5py.File(out, "r") as f:
            assert "tip position" not in f["0"] and "force" in f["0"]
    for _ in range(100):  # the writer appends after the run's end
        if c.status()["log"]["curves"] == 2:
            break
        time.sleep(0.05)
    st = c.status()["log"]
    assert st["curves"] == 2 and st["curves_dropped"] == 0, st
    assert c.request({"cmd": "log", "stop": True})["status"] == "ok"
    with h5py.File(log, "r") as f:
        assert len(f) == 2 and all("tip position" not in f[g] for g in f)
    if VAFM_CLI:
        for p in (log, tmp_path / "listen0.h5", tmp_path / "listen1.h5"):
            r = subprocess.run([VAFM_CLI, "info", str(p)], capture_output=True, text=True, timeout=60)
            assert r.returncode == 0 and "conformance  ok" in r.stdout, r.stdout + r.stderr


def test_no_trigger(fig4):
    """A trigger that never fires: the approach runs to its travel limit and the curve says so (flag 8,
    no_trigger), the record names the run and the block where the approach turned, and the next curve
    triggers again."""
    c = fig4.client
    with Stream(fig4.pub) as s:
        ref = s.run(c.curve(index=2)["run_id"])
        c.wait_idle()
        assert ref.end["result"]["flags"] & 8 == 0
        r1 = c.curve(index=2)["run_id"]
        c.faults({"script": [{"kind": "no_trigger", "run": r1 + 1}]})
        c.wait_idle()
        s.run(r1)
        run = s.run(c.curve(index=2)["run_id"])
        c.wait_idle()
        assert run.end["result"]["flags"] & 8, run.end["result"]
        app = run.segment == 0
        assert app.sum() > (ref.segment == 0).sum()  # the approach went on past the setpoint
        assert run["force_N"][app].max() > ref["force_N"][ref.segment == 0].max()
        last = c.status()["faults"]["last"][-1]
        assert last["kind"] == "no_trigger" and last["run_id"] == run.end["run_id"] and last["block"] >= 1, last
        again = s.run(c.curve(index=2)["run_id"])
        assert again.end["result"]["flags"] & 8 == 0
        assert np.array_equal(again["force_N"], ref["force_N"])


def test_command_faults(fig4):
    c = fig4.client
    c.faults({"script": [{"kind": "busy", "cmd": "status"}, {"kind": "no_reply", "cmd": "get"},
                         {"kind": "reply_delay", "cmd": "presets", "delay_s": 0.4},
                         {"kind": "no_reply", "cmd": "curve"}]})
    c.timeout = 1.0
    assert c.status()["state"] == "idle"  # busy: retried after a pause
    assert any("busy" in t for _, t in c.log)
    other = Client(fig4.rep, timeout=2)  # a request left unanswered does not block anyone else
    t0 = time.monotonic()
    assert c.get("k_N_per_m")  # lazy pirate: timeout, reopen, resend
    assert time.monotonic() - t0 >= 1.0 and any("reopened" in t for _, t in c.log)
    assert other.hello()["status"] == "ok"
    t0 = time.monotonic()
    c.presets()
    assert time.monotonic() - t0 >= 0.4
    with Stream(fig4.pub) as s:
        r = c.curve(index=0)  # its reply is lost, the resend (same client_run_id) gets the same run
        assert r["duplicate"] is True
        assert s.run(r["run_id"]).clean
    assert c.status()["runs_started"] == 1
    with pytest.raises(TransportError):  # a start without client_run_id is never resent
        c.faults({"script": [{"kind": "no_reply", "cmd": "abort"}]})
        c.request({"cmd": "abort"})
    assert [f["kind"] for f in c.faults()["last"]] == ["busy", "no_reply", "reply_delay", "no_reply", "no_reply"]
    other.close()


def test_kill_flushes_log(tmp_path):
    d = Daemon("--preset", "paper-fig4", "--free-run")
    c = d.client
    path = tmp_path / "log.h5"
    c.request({"cmd": "log", "path": str(path)})
    c.faults({"script": [{"kind": "kill", "run": 3, "block": 2, "status": 7}]})
    with Stream(d.pub) as s:
        for i in range(2):
            assert s.run(c.curve(index=i)["run_id"]).clean
            c.wait_idle()
        c.curve(index=2)
        assert d.proc.wait(timeout=20) == 7
    d.stop()
    f = load_h5(str(path))
    assert len(f.curves) == 2
    import h5py
    with h5py.File(path, "r") as h:
        faults = json.loads(h.attrs["vafm faults"])
    assert [(x["kind"], x["run_id"], x["block"], x["params"]) for x in faults] == [("kill", 3, 2, {"status": 7})]
    info = subprocess.run([VAFM_CLI, "info", str(path)], capture_output=True, text=True) if VAFM_CLI else None
    assert info is None or info.returncode == 0, info.stderr


def test_chaos_campaign(tmp_path):
    """Random drops, truncations, restarts, stalls, late blocks and dropouts over a campaign: every fault
    the daemon logged is reported by both clients, no false alarm, every curve kept clean equals the
    fault-free curve of the same index bit for bit, and the daemon's log holds every completed curve."""
    n = 200 if os.environ.get("VAFM_LONG_TESTS") == "1" else 60  # the 200 in the release build
    d = Daemon("--preset", "paper-fig4", "--free-run")
    c = d.client
    log = tmp_path / "daemon.h5"
    out = tmp_path / "listen.h5"
    c.request({"cmd": "log", "path": str(log)})
    c.faults({"seed": 14, "random": {"drop": {"per_block": 0.006}, "truncate": {"per_run": 0.05},
                                     "restart": {"per_run": 0.05}, "stall": {"per_run": 0.03, "duration_s": 1.6},
                                     "late": {"per_block": 0.01, "delay_s": 0.05},
                                     "dropout": {"per_run": 0.05, "samples": 25}}})
    li = d.listen("--out", str(out), "--runs", str(n))
    with Stream(d.pub, timeout=30) as s:
        cid = c.request({"cmd": "campaign", "n": n})["campaign_id"]
        runs, end = s.campaign(cid, timeout=90 * n / 60, strict=False)
        assert end["status"] == "ok"
        c.wait_idle()
        time.sleep(1.1)  # a stall at the very end shows in the next heartbeat
        with pytest.raises(TransportError):
            list(s.runs(deadline=time.monotonic() + 1.2))
        reports = list(s.reports)
        c.request({"cmd": "log", "stop": True})
        c.faults(clear=True)
        cid = c.request({"cmd": "campaign", "n": n})["campaign_id"]
        ref, _ = s.campaign(cid, timeout=90)
        ref = {r.start["index"]: r for r in ref}
    rc, err = finish(li)
    import h5py
    with h5py.File(log, "r") as h:
        faults = json.loads(h.attrs["vafm faults"])
    by_kind = {}
    for f in faults:
        by_kind.setdefault(f["kind"], []).append(f)
    assert set(by_kind) >= {"drop", "truncate", "restart", "late"}, by_kind.keys()
    run_of = {r.run_id: r for r in runs}
    rep = {}
    for r in reports:
        rep.setdefault(r["kind"], []).append(r)
    # Python: every fault reported, nothing else
    assert sorted({f["run_id"] for f in by_kind.get("drop", [])}) == \
        sorted({r["run_id"] for r in rep.get("gap", [])}), (by_kind.get("drop"), rep.get("gap"))
    assert sorted(f["run_id"] for f in by_kind.get("truncate", [])) == \
        sorted(r["run_id"] for r in rep.get("truncated", []))
    assert len(by_kind.get("restart", [])) == len(rep.get("restart", []))
    assert len(by_kind.get("stall", [])) == len(rep.get("stall", []))
    assert sorted(f["run_id"] for f in by_kind.get("dropout", [])) == \
        sorted(r["run_id"] for r in rep.get("dropout", []))
    assert not set(rep) - {"gap", "truncated", "restart", "stall", "dropout"}
    # listen: the same, in its words
    for f in by_kind.get("drop", []):
        assert f"run {f['run_id']}: " in err and "lost" in err
    for f in by_kind.get("truncate", []):
        assert f"run {f['run_id']}: no run.end" in err, err
    assert err.count("the publisher restarted: stream session") == len(by_kind.get("restart", []))
    assert err.count("the stream stalled") == len(by_kind.get("stall", [])), err
    for f in by_kind.get("dropout", []):
        assert f"run {f['run_id']}: 25 sample(s) have NaN" in err, err
    assert rc == (1 if set(by_kind) & {"drop", "truncate", "restart", "dropout"} else 0)
    # kept curves equal the fault-free ones
    kept = [r for r in runs if r.clean]
    hit = {f["run_id"] for f in faults if f["kind"] in ("drop", "truncate", "dropout")}
    restarted = {r.run_id for r in runs if r.restarted}
    assert {r.run_id for r in runs if not r.clean} == hit | restarted
    for r in kept:
        g = r.start["index"]
        for ch in ("force_N", "height_m", "tip_m"):
            assert np.array_equal(r[ch], ref[g][ch]), (g, ch)
    f = load_h5(str(out))
    written = {int(cv.meta["curve id"].split()[1]): cv for cv in f.curves}
    assert set(written) == {r.run_id for r in kept}
    for rid, cv in written.items():
        g = run_of[rid].start["index"]
        assert np.array_equal(cv["force"], ref[g]["force_N"])
    # the daemon's log: every curve it completed (not the truncated ones), with its samples
    lg = load_h5(str(log))
    truncated = {f["run_id"] for f in by_kind.get("truncate", [])}
    nan_runs = {f["run_id"] for f in by_kind.get("dropout", [])}  # NaN is not storable (L16): log_failed
    assert len(lg.curves) == n - len(truncated) - len(nan_runs - truncated)
    for cv in lg.curves:
        g = int(cv.meta["curve id"].split()[3])
        assert np.array_equal(cv["force"], ref[g]["force_N"])
    print(f"chaos: {n} curves, faults {sorted((k, len(v)) for k, v in by_kind.items())}, kept {len(kept)}")
    assert d.stop() == 0
