# SPDX-License-Identifier: MIT
"""vafmd benchmarks (issue #4): pacing jitter, highest sustained sample rate at 1x, stream throughput to
1 and 4 subscribers, command round-trip latency; and the 1 MS/s target sustained over a 5-curve campaign
of the default scene. Reports, never fails on speed.

Pacing and the highest rate are measured with the default compute-ahead (`lookahead_s` 1 s) and, as the
baseline in the same run, with `lookahead_s` 0 (each block computed just before its deadline).

usage: bench_daemon.py VAFMD OUTDIR    (writes OUTDIR/bench_daemon.csv and OUTDIR/bench_daemon.md)

Pacing: the daemon releases block b at t_start + (end sample of b)/fs/speed on CLOCK_MONOTONIC. Its own
count of late blocks and worst lateness come from run.end (exact, measured at release), and so do its
release-lateness percentiles (send time minus deadline of every block, 1 us resolution below 1 ms). The subscriber
side measures delivery lateness: receive time (time.monotonic_ns, the same clock) minus the block's ideal
release time, with the unknown t_start estimated by the earliest block (so the best block counts as on
time): this includes ZeroMQ and Python receive delays, an upper bound of the release jitter.
"""
import json
import multiprocessing as mp
import os
import struct
import sys
import tempfile
import time
import subprocess

import numpy as np
import zmq

HEADER = struct.Struct("<IHHQQQQIHHdqII")


class Daemon:
    def __init__(self, exe, *args):
        self.dir = tempfile.mkdtemp(prefix="vafmd-bench-")
        self.rep, self.pub = f"ipc://{self.dir}/rep", f"ipc://{self.dir}/pub"
        self.proc = subprocess.Popen([exe, "--rep", self.rep, "--pub", self.pub, *args],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        self.ctx = zmq.Context()
        self.req = None
        deadline = time.time() + 10
        while True:
            self._connect()
            try:
                self.cmd({"cmd": "hello"}, 300)
                break
            except zmq.Again:
                if time.time() > deadline:
                    raise

    def _connect(self):
        if self.req is not None:
            self.req.close(0)
        self.req = self.ctx.socket(zmq.REQ)
        self.req.setsockopt(zmq.LINGER, 0)
        self.req.connect(self.rep)

    def cmd(self, obj, timeout=30000):
        self.req.send(json.dumps(obj).encode())
        if not self.req.poll(timeout):
            raise zmq.Again("no reply")
        r = json.loads(self.req.recv())
        assert r["status"] == "ok", r
        return r

    def sub(self):
        s = self.ctx.socket(zmq.SUB)
        s.setsockopt(zmq.LINGER, 0)
        s.setsockopt(zmq.RCVHWM, 0)
        s.setsockopt(zmq.SUBSCRIBE, b"")
        s.connect(self.pub)
        assert s.poll(10000) and s.recv_multipart()[0] == b"heartbeat"  # greeting: subscription in place
        return s

    def wait_idle(self):
        while self.cmd({"cmd": "status"})["state"] != "idle":
            time.sleep(0.01)

    def stop(self):
        try:
            self.cmd({"cmd": "shutdown"}, 5000)
        except zmq.Again:
            pass
        self.proc.wait(timeout=20)
        self.ctx.destroy(0)


def collect(s, run_id, timeout_ms=120000):
    """Receive run `run_id` to its end: (data headers with receive times, run.end, samples received)."""
    blocks, got = [], 0
    while True:
        if not s.poll(timeout_ms):
            raise RuntimeError("stream went silent")
        parts = s.recv_multipart()
        t = time.monotonic_ns()
        if parts[0] == b"data":
            h = HEADER.unpack(parts[1])
            if h[4] == run_id:
                blocks.append((h, t))
                got += h[7]
        elif parts[0] == b"run.end":
            j = json.loads(parts[1])
            if j["run_id"] == run_id:
                return blocks, j, got


def lateness_ms(blocks, speed=1.0):
    ends = np.array([(h[6] + h[7]) / h[10] / speed * 1e9 for h, _ in blocks])
    recv = np.array([t for _, t in blocks], dtype=float)
    off = recv - ends
    late = (off - off.min()) / 1e6
    return np.percentile(late, 50), np.percentile(late, 99), late.max()


def rel(end):
    """The daemon's own release lateness (run.end release_lateness_ns), ms."""
    rl = end.get("release_lateness_ns")
    if not rl:
        return "release lateness n/a (free run)"
    return f"release lateness p50 {rl['p50'] / 1e6:.3f} ms, p99 {rl['p99'] / 1e6:.3f} ms, max {rl['max'] / 1e6:.3f} ms"


def run(d, s, req):
    r = d.cmd(req)
    blocks, end, got = collect(s, r["run_id"])
    d.wait_idle()
    return blocks, end, got


LOOKAHEADS = (1.0, 0.0)  # the default, then the baseline without compute-ahead


def bench_pacing(exe, rows):
    for name, preset, values, req in (
        ("paper-fig4 tune 3 s", "paper-fig4", {}, {"cmd": "tune", "duration_s": 3.0}),
        ("paper-fig1 curve (the paper's scene)", "paper-fig1", {}, {"cmd": "curve", "index": 0}),
        ("paper-fig1 omega_dt=0.6 curve", "paper-fig1", {"omega_dt": 0.6}, {"cmd": "curve", "index": 0}),
    ):
        for la in LOOKAHEADS:
            d = Daemon(exe, "--preset", preset)
            d.cmd({"cmd": "set", "values": {**values, "lookahead_s": la}})
            s = d.sub()
            blocks, end, got = run(d, s, req)
            p50, p99, mx = lateness_ms(blocks)
            fs = blocks[0][0][10]
            rows.append(("pacing 1x", f"{name}, lookahead_s {la:g}",
                         f"{fs:.4g} S/s, {len(blocks)} blocks, {end['samples']} samples",
                         f"daemon: late blocks {end['late_blocks']}, worst {end['worst_late_ns'] / 1e6:.3f} ms, "
                         f"{rel(end)}; subscriber delivery lateness p50 {p50:.3f} ms, p99 {p99:.3f} ms, "
                         f"max {mx:.3f} ms"))
            d.stop()


def bench_max_rate(exe, rows, values=None, label="paper-fig1", lookahead_s=1.0):
    """Highest output sample rate of a scene (paper-fig1 force curve) at 1x with no late block."""
    d = Daemon(exe, "--preset", "paper-fig1")  # the measured scene, not the tools' default
    d.cmd({"cmd": "set", "values": {**(values or {}), "lookahead_s": lookahead_s}})
    label = f"{label}, lookahead_s {lookahead_s:g}"
    s = d.sub()
    best = None
    for fs in (2e3, 5e3, 10e3, 25e3, 50e3, 100e3, 200e3, 400e3, 1e6, 2e6, 3e6, 4e6, 6e6, 8e6):
        d.cmd({"cmd": "set", "values": {"sample_rate_Hz": fs}})
        blocks, end, got = run(d, s, {"cmd": "curve", "index": 0})
        ok = end["late_blocks"] == 0 and end["status"] == "ok"
        p50, p99, mx = lateness_ms(blocks)
        rows.append(("max rate 1x", f"{label}: curve at {fs / 1e6:g} MS/s",
                     f"{end['samples']} samples in {end['wall_s']:.2f} s",
                     f"late blocks {end['late_blocks']}, worst {end['worst_late_ns'] / 1e6:.3f} ms, {rel(end)}, "
                     f"subscriber got {got} ({'ok' if ok else 'LATE'}); delivery lateness p50 {p50:.3f} ms, "
                     f"p99 {p99:.3f} ms"))
        if not ok:
            break
        best = fs
    rows.append(("max rate 1x", f"{label}: highest rate tried with zero late blocks",
                 f"{best / 1e6:g} MS/s" if best else "none",
                 "target >= 1 MS/s" + ("" if values or lookahead_s else "; late blocks come from the contact "
                                         "phase, where the core's stepping is slower than real time (also in "
                                         "the CLI): compute-ahead (lookahead_s) absorbs it")))
    d.stop()


def bench_sustained(exe, rows, fs=1e6, n=5):
    """The target rate sustained: a daemon campaign of n default-scene curves back to back at fs, 1x."""
    d = Daemon(exe, "--preset", "paper-fig1")  # the measured scene, not the tools' default
    d.cmd({"cmd": "set", "values": {"sample_rate_Hz": fs}})
    s = d.sub()
    r = d.cmd({"cmd": "campaign", "n": n})
    first = r["run_id"]
    blocks, ends, got, t0 = [], [], 0, time.monotonic()
    while True:
        if not s.poll(120000):
            raise RuntimeError("stream went silent")
        parts = s.recv_multipart()
        t = time.monotonic_ns()
        if parts[0] == b"data":
            h = HEADER.unpack(parts[1])
            if first <= h[4] < first + n:
                blocks.append((h, t))
                got += h[7]
        elif parts[0] == b"run.end":
            ends.append(json.loads(parts[1]))
        elif parts[0] == b"campaign.end":
            break
    wall = time.monotonic() - t0
    d.wait_idle()
    late = sum(e["late_blocks"] for e in ends)
    worst = max(e["worst_late_ns"] for e in ends) / 1e6
    samples = sum(e["samples"] for e in ends)
    # delivery lateness per run (each run has its own t_start)
    p99s = [lateness_ms([b for b in blocks if b[0][4] == e["run_id"]])[1] for e in ends]
    rp99 = [e["release_lateness_ns"]["p99"] / 1e6 for e in ends]
    rmax = max(e["release_lateness_ns"]["max"] for e in ends) / 1e6
    ok = late == 0 and all(e["status"] == "ok" for e in ends) and got == samples
    rows.append(("sustained 1x", f"paper-fig1 (the paper's scene, default step): campaign of {n} curves at "
                 f"{fs / 1e6:g} MS/s", f"{samples} samples in {wall:.1f} s, late blocks {late}",
                 f"{'ok' if ok else 'LATE or LOST'}: worst {worst:.3f} ms; release lateness p99 per curve "
                 f"{min(rp99):.3f}-{max(rp99):.3f} ms, max {rmax:.3f} ms; subscriber got {got}, delivery "
                 f"lateness p99 per curve {min(p99s):.2f}-{max(p99s):.2f} ms"))
    d.stop()


def _subscriber(pub, run_q, out_q):
    ctx = zmq.Context()
    s = ctx.socket(zmq.SUB)
    s.setsockopt(zmq.RCVHWM, 0)
    s.setsockopt(zmq.SUBSCRIBE, b"")
    s.connect(pub)
    s.poll(10000)
    s.recv_multipart()
    out_q.put("ready")
    run_id = run_q.get()
    blocks, end, got = collect(s, run_id)
    seqs = [h[3] for h, _ in blocks]
    t = (blocks[-1][1] - blocks[0][1]) / 1e9 if len(blocks) > 1 else float("nan")
    out_q.put((got, t, len(blocks), (seqs[-1] - seqs[0] + 1) - len(seqs)))
    ctx.destroy(0)


def bench_throughput(exe, rows):
    """Free-run tune of the default scene at 4 MS/s, 1 and 4 subscriber processes."""
    for nsub in (1, 4):
        d = Daemon(exe, "--free-run")
        d.cmd({"cmd": "set", "values": {"sample_rate_Hz": 4e6}})
        run_qs, out_q = [mp.Queue() for _ in range(nsub)], mp.Queue()
        procs = [mp.Process(target=_subscriber, args=(d.pub, q, out_q)) for q in run_qs]
        for p in procs:
            p.start()
        for _ in procs:
            out_q.get(timeout=30)
        r = d.cmd({"cmd": "tune", "duration_s": 2.0})
        for q in run_qs:
            q.put(r["run_id"])
        res = [out_q.get(timeout=300) for _ in procs]
        for p in procs:
            p.join()
        d.wait_idle()
        st = d.cmd({"cmd": "status"})
        tot = sum(g for g, _, _, _ in res)
        wall = max(t for _, t, _, _ in res)
        rows.append(("stream throughput", f"{nsub} subscriber(s), free-run tune 2 s at 4 MS/s",
                     f"{tot / wall / 1e6:.2f} MS/s received in total ({tot / wall * 40 / 1e6:.0f} MB/s of "
                     f"5 x f64 channels)",
                     f"per subscriber {min(g for g, _, _, _ in res) / wall / 1e6:.2f} MS/s min; "
                     f"seq gaps {sum(gp for _, _, _, gp in res)}; daemon overflows {st['dropped']}"))
        d.stop()


def bench_rtt(exe, rows):
    d = Daemon(exe)
    lat = []
    for _ in range(3000):
        t = time.perf_counter_ns()
        d.cmd({"cmd": "hello"})
        lat.append((time.perf_counter_ns() - t) / 1e3)
    lat = np.array(lat[100:])
    rows.append(("command RTT", "hello over ipc://, 2900 requests", f"median {np.median(lat):.1f} us",
                 f"p99 {np.percentile(lat, 99):.1f} us, max {lat.max():.1f} us"))
    d.stop()


def main():
    exe, out = sys.argv[1], sys.argv[2]
    rows = []
    for f in (bench_rtt, bench_pacing, bench_sustained,
              *(lambda e, r, la=la: bench_max_rate(e, r, lookahead_s=la) for la in LOOKAHEADS),
              *(lambda e, r, la=la: bench_max_rate(e, r, {"omega_dt": 0.6}, "paper-fig1 omega_dt=0.6", la)
                for la in LOOKAHEADS), bench_throughput):
        f(exe, rows)
        print("done", flush=True)
    with open(os.path.join(out, "bench_daemon.csv"), "w") as fcsv:
        fcsv.write("benchmark,case,result,detail\n")
        for r in rows:
            fcsv.write(",".join('"' + c.replace('"', "'") + '"' for c in r) + "\n")
    md = ["| benchmark | case | result | detail |", "|---|---|---|---|"]
    md += ["| " + " | ".join(r) + " |" for r in rows]
    with open(os.path.join(out, "bench_daemon.md"), "w") as fmd:
        fmd.write("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
