#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Benchmark of the live web panel (issue #28), a report, never a pass/fail on speed:
  - lag from a block's publication to its drawing in the page (p50, p99), at the default scene and at 1 MS/s:
    a Python subscriber stamps each block's arrival (time.time(), on this machine ≈ publication), the page
    stamps the animation frame that drew it (performance.timeOrigin + now(), the same wall clock);
  - the same for the always-on controller's `live` messages while idle (a subscriber to `live` by name
    stamps each message's arrival, the page its drawing);
  - the daemon's CPU (utime + stime from /proc) over the same paced campaign with no panel, the panel and
    1 browser, and 5 browsers: what the panel adds to the daemon.
usage: bench_web.py VAFMD OUT_DIR"""
import json
import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))
os.environ.setdefault("VAFMD", sys.argv[1] if len(sys.argv) > 1 else "")
import vafmd_harness  # noqa: E402
from test_web import BRIDGE, HEADER, browser, wait_for  # noqa: E402

CURVES = 6


def cpu_s(pid):
    with open(f"/proc/{pid}/stat") as fh:
        f = fh.read().rsplit(")", 1)[1].split()
    return (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")


def campaign(d, sub):
    """One paced campaign of CURVES curves; returns {seq: arrival time} and the daemon CPU seconds."""
    c0 = cpu_s(d.proc.pid)
    r = d.cmd({"cmd": "campaign", "n": CURVES})
    assert r["status"] == "ok", r
    arrive = {}
    for parts in vafmd_harness.messages_until(sub, time.monotonic() + 300):
        if parts[0] == b"data":
            arrive[HEADER.unpack(parts[1])[3]] = time.time()
        elif parts[0] == b"campaign.end":
            break
    return arrive, cpu_s(d.proc.pid) - c0


LIVE_S = 3.0


def live_arrivals(d):
    """{live seq: arrival time} over LIVE_S seconds of an idle daemon."""
    sub = d.sub(topics=(b"live", b"heartbeat"), greet=True)
    arrive = {}
    for parts in vafmd_harness.messages_until(sub, time.monotonic() + LIVE_S, poll_ms=100):
        if parts[0] == b"live":
            arrive[json.loads(parts[1])["seq"]] = time.time()
    sub.close(0)
    return arrive


def run_case(rate, viewers, measure_lag):
    d = vafmd_harness.Daemon()
    web, drivers = None, []
    try:
        if rate:
            assert d.cmd({"cmd": "set", "values": {"sample_rate_Hz": rate}})["status"] == "ok"
        if viewers:
            ready = os.path.join(d.dir, "ready")
            web = subprocess.Popen([sys.executable, BRIDGE, "--daemon", d.rep, "--listen", "127.0.0.1:0",
                                    "--ready-file", ready], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            wait_for("panel", lambda: os.path.exists(ready))
            url = open(ready).read().strip()
            drivers = [browser(url) for _ in range(viewers)]
        live_lags = []
        if measure_lag and drivers:
            larr = live_arrivals(d)
            last = max(larr)
            wait_for("the last live message drawn", lambda: any(s == last for s, _ in drivers[0].execute_script(
                "return window.vafmPanel.liveDrawLog.slice(-100)")), timeout=30)
            drawn = dict((int(s), t) for s, t in drivers[0].execute_script("return window.vafmPanel.liveDrawLog"))
            live_lags = [(drawn[s] - t) * 1e3 for s, t in larr.items() if s in drawn]
        sub = d.sub(greet=True)
        arrive, cpu = campaign(d, sub)
        lags = []
        if measure_lag and drivers:
            last = max(arrive)
            wait_for("the last block drawn", lambda: any(s == last for s, _ in drivers[0].execute_script(
                "return window.vafmPanel.drawLog.slice(-500)")), timeout=60)
            drawn = dict((int(s), t) for s, t in drivers[0].execute_script("return window.vafmPanel.drawLog"))
            lags = [(drawn[s] - t) * 1e3 for s, t in arrive.items() if s in drawn]
        sub.close(0)
        return {"rate": rate, "viewers": viewers, "blocks": len(arrive), "daemon_cpu_s": cpu, "lags_ms": lags,
                "live_lags_ms": live_lags}
    finally:
        for drv in drivers:
            drv.quit()
        if web:
            web.terminate()
            web.wait(10)
        d.stop()


def main():
    out = sys.argv[2] if len(sys.argv) > 2 else "."
    os.makedirs(out, exist_ok=True)
    rows = []
    for rate, label in ((None, "default scene"), (1e6, "1 MS/s")):
        r = run_case(rate, 1, True)
        lag = np.array(r["lags_ms"])
        rows.append(f"| lag, {label} | {len(lag)} of {r['blocks']} blocks | p50 {np.percentile(lag, 50):.1f} ms | "
                    f"p99 {np.percentile(lag, 99):.1f} ms | max {lag.max():.1f} ms |")
        ll = np.array(r["live_lags_ms"])
        rows.append(f"| live lag (idle), {label} | {len(ll)} live messages in {LIVE_S:g} s | p50 {np.percentile(ll, 50):.1f} ms | "
                    f"p99 {np.percentile(ll, 99):.1f} ms | max {ll.max():.1f} ms |")
    cpu = {}
    for v in ((0, 1, 5) if "--no-cpu" not in sys.argv else ()):
        cpu[v] = run_case(None, v, False)["daemon_cpu_s"]
    for v in (1, 5) if cpu else ():
        rows.append(f"| daemon CPU, {v} browser(s) | campaign of {CURVES} curves | {cpu[v]:.3f} s | "
                    f"without panel {cpu[0]:.3f} s | added {cpu[v] - cpu[0]:+.3f} s |")
    text = "| measure | over | | | |\n|---|---|---|---|---|\n" + "\n".join(rows) + "\n"
    print(text)
    with open(os.path.join(out, "web.md"), "w") as fh:
        fh.write(text)
    with open(os.path.join(out, "web.json"), "w") as fh:
        json.dump({"rows": rows, "cpu": cpu}, fh)


if __name__ == "__main__":
    main()
