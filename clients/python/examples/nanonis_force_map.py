#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""A force map the Nanonis way: FolMe moves over the sample, a Z spectroscopy at each point.

    vafmd --nanonis 6501 &
    python3 clients/python/examples/nanonis_force_map.py --nx 8 --ny 8 --size 2e-6 [--json map.json]

Speaks to vafmd's Nanonis port exactly as a script for a Nanonis controller would (plain sockets and
struct, from TCPProtocol_SPM: FolMe.XYPosSet, ZSpectr.ChsSet/PropsSet/RangeSet/TimingSet/RetractSet,
ZSpectr.Start with data), and listens on vafmd's stream for each curve's ground truth, found by the Run ID
the sweep returns (docs/nanonis.md): run.start's `scene` (the material the daemon simulated under the tip
for that curve) and run.end's `result` (wire.md §3.3: `pulloff_sampled_N`, the curve's own pull-off).

From each point's measured data alone it recovers the adhesion: the pull-off force of the backward sweep,
interpolated within the Z step where the tip snaps off (pulloff(): the sweep reads the force only every
dZ = distance/points, so its most tensile point falls short of the pull-off by up to k dZ, 0.2 nN at
k = 0.1 N/m and 2 nm; the tensile branch before the snap is a line of slope k, fitted on the points before
it, and the snapping point's mean is the branch's force over the part of the step before the snap plus the
free lever's after it, which gives where in the step the snap happened and the force there).
The truth is the same curve's `pulloff_sampled_N` (at a finite temperature the contact pulls off early,
thermally activated, so the athermal JKR pull-off 3/2 pi gamma R of the scene is not what the curve did;
it is printed as an extra line). That truth is itself sampled: the most tensile output sample, each sample
the mean over its sample period (the stream's `sample_rate_Hz`, run.start), so it falls short of the
snap's force by k dz (u + 1/2), dz = v_retract / sample_rate the Z travel of one sample, u uniform in
[0, 1): on average k dz (0.02 nN here), spread k dz/sqrt(12). The recovered value compared with it is the
interpolated pull-off less k dz (`adhesion_sampled_N`). Points are grouped by the material the ground truth
reports; the recovered contrast (the ratio of the two materials' mean adhesion) is printed beside the true
one of the same curves with sigma, the standard error of their difference: recovered and true are the same
curves, so only each curve's residual counts, k dz/sqrt(12) (the truth's sampling) and the residuals' own
spread, in quadrature, over sqrt(N) for each material's mean. The check (exit 4 when it fails) is agreement
within 3 sigma.

The sample: vafmd's `ctrl_sample` setting (wire.md §2.4) puts a map's sample under the controller, e.g.
    vafm ctl set ctrl_sample=pattern=stripes,period_m=2e-6,b_E_star_Pa=5e9,b_gamma_J_per_m2=0.2
(two materials in stripes); each ZSpectr curve then takes the material under the tip. Without it the sample
is the scene's one material: the example then reports one material, says so, and claims no contrast (exit
status 0; 3 with --require-contrast). It never labels points by where they are: the material of a point is
only what the daemon says it simulated there.
"""
import argparse
import json
import math
import socket
import struct
import sys
import time

import numpy as np
import zmq

HDR = struct.Struct(">32sih2x")  # request: command name, body size, send-response flag, 2 unused
RHDR = struct.Struct(">32si4x")  # response: command name, body size, 4 unused


class Body:
    """A response body read in order: take(fmt) unpacks the next values (big-endian struct formats)."""

    def __init__(self, b):
        self.b, self.off = b, 0

    def take(self, fmt):
        v = struct.unpack_from(fmt, self.b, self.off)
        self.off += struct.calcsize(fmt)
        return v

    def strings(self):
        """A 1D array of strings: its size in bytes (i32), its count (i32), then each as size + bytes."""
        _, count = self.take(">ii")
        return [self.take(f">{self.take('>i')[0]}s")[0].decode() for _ in range(count)]


def pulloff(bwd):
    """The pull-off force (N, tensile positive) from a backward sweep's force points (index: the forward
    point's, so the retract runs toward index 0), interpolated within the step where the tip snaps off.
    Returns (pull-off, the most tensile point's force): the first is NaN when the sweep has no tensile branch
    of three points to fit."""
    f = np.asarray(bwd, float)
    if not np.isfinite(f).any():
        return math.nan, math.nan
    i = int(np.nanargmin(f))
    naive = max(0.0, -float(f[i]))
    fit = np.arange(i + 1, i + 4)  # in contact: beyond the most tensile point
    if fit[-1] >= len(f) or not np.isfinite(f[fit]).all() or f[i] >= 0:
        return math.nan, naive
    slope, icpt = np.polyfit(fit, f[fit], 1)  # the tensile branch: f = icpt + slope * j
    if not slope > 0:
        return math.nan, naive
    # the snapping point j: the most tensile one if it is off the branch, else the next one out
    j = i if abs(f[i] - (icpt + slope * i)) > 0.05 * slope else i - 1
    if j < 0:
        return math.nan, naive
    free = f[max(0, j - 8):max(0, j - 2)]  # the free lever further out (its ring-down past)
    free = float(np.median(free)) if len(free) else 0.0
    f0, df = icpt + slope * (j + 0.5), -slope  # the branch at the step's start, its change over the step
    # the step's mean: q (f0 + q df / 2) + (1 - q) free, q the part of the step before the snap
    a, b, c = df / 2, f0 - free, free - f[j]
    disc = math.sqrt(max(b * b - 4 * a * c, 0.0))
    q = min([r for r in ((-b - disc) / (2 * a), (-b + disc) / (2 * a)) if -0.5 <= r <= 1.5] or [0.5],
            key=lambda r: abs(r - 0.5))
    q = min(max(q, 0.0), 1.0)
    return -(f0 + q * df), naive


class Nanonis:
    """A minimal Nanonis TCP client, from the specification alone."""

    def __init__(self, host, port, timeout=600.0):
        self.s = socket.create_connection((host, port), timeout=timeout)
        self.f = self.s.makefile("rb")

    def _recv(self, n):
        b = self.f.read(n)
        if len(b) < n:
            raise ConnectionError("the Nanonis server closed the connection")
        return b

    def call(self, name, body=b"", nret=None):
        """Send a request, return the body's return arguments (the error part checked and removed).
        nret: the return arguments' size when known (else the error part is found from the end)."""
        self.s.sendall(HDR.pack(name.encode(), len(body), 1) + body)
        _, size = RHDR.unpack(self._recv(40))
        b = self._recv(size)
        if nret is None:  # the error part: status (u32), description size (i32), the description
            for L in range(0, len(b) - 7):
                at = len(b) - 8 - L
                st, dl = struct.unpack_from(">Ii", b, at)
                if dl == L and st in (0, 1):
                    nret = at
                    break
        st, dl = struct.unpack_from(">Ii", b, nret)
        if st:
            raise RuntimeError(f"{name}: {b[nret + 8:nret + 8 + dl].decode(errors='replace')}")
        return b[:nret]

    def folme_xy(self, x, y):
        self.call("FolMe.XYPosSet", struct.pack(">ddI", x, y, 1), 0)

    def zspectr_start(self):
        r = Body(self.call("ZSpectr.Start", struct.pack(">Ii", 1, 0)))
        names = r.strings()
        rows, cols = r.take(">ii")
        data = np.array(r.take(f">{rows * cols}f"), dtype=float).reshape(rows, cols)
        params = r.take(f">{r.take('>i')[0]}f")
        return names, data, params


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("--nanonis", default="127.0.0.1:6501", help="vafmd's Nanonis port, HOST:PORT")
    ap.add_argument("--pub", default="tcp://127.0.0.1:5556", help="vafmd's stream (the ground truth)")
    ap.add_argument("--nx", type=int, default=8)
    ap.add_argument("--ny", type=int, default=8)
    ap.add_argument("--size", type=float, default=2e-6, help="the scan's side, m (centred on 0, 0)")
    ap.add_argument("--points", type=int, default=100, help="points of each sweep")
    ap.add_argument("--distance", type=float, default=200e-9, help="Z sweep distance, m")
    ap.add_argument("--trigger", type=float, default=5e-9, help="auto-retract at Force (N) > this")
    ap.add_argument("--json", help="write the points and the per-material summary here")
    ap.add_argument("--require-contrast", action="store_true",
                    help="exit 3 when the ground truth shows fewer than two materials")
    a = ap.parse_args(argv)
    if not (1 <= a.nx <= 256 and 1 <= a.ny <= 256):
        sys.exit("--nx and --ny must be in [1, 256]")
    host, _, port = a.nanonis.rpartition(":")
    n = Nanonis(host or "127.0.0.1", int(port))

    sub = zmq.Context.instance().socket(zmq.SUB)
    sub.setsockopt(zmq.SUBSCRIBE, b"run.start")
    sub.setsockopt(zmq.SUBSCRIBE, b"run.end")
    sub.connect(a.pub)
    # the subscription is in place once the daemon's welcome heartbeat (wire.md §3: one at once for every
    # new subscription) arrives: a run started before it would go unseen
    sub.setsockopt(zmq.SUBSCRIBE, b"heartbeat")
    if not sub.poll(10000):
        sys.exit(f"no heartbeat from {a.pub} within 10 s: is --pub vafmd's stream?")
    sub.setsockopt(zmq.UNSUBSCRIBE, b"heartbeat")

    # the signals by name (Signals.NamesGet), as a Nanonis script finds them
    names = Body(n.call("Signals.NamesGet")).strings()
    force = names.index("Force (N)")
    n.call("ZSpectr.Open", b"", 0)
    n.call("ZSpectr.ChsSet", struct.pack(">ii", 1, force), 0)
    n.call("ZSpectr.PropsSet", struct.pack(">HiHHHH", 1, a.points, 1, 2, 2, 2), 0)  # backward sweep on
    n.call("ZSpectr.RangeSet", struct.pack(">ff", 0.0, a.distance), 0)
    n.call("ZSpectr.TimingSet", struct.pack(">7f", 0.1, 0, 100, 0, 1e-3, 0, 0), 0)
    n.call("ZSpectr.RetractSet", struct.pack(">HfiH", 1, a.trigger, force, 0), 0)

    xs = (np.arange(a.nx) + 0.5) / a.nx * a.size - a.size / 2
    ys = (np.arange(a.ny) + 0.5) / a.ny * a.size - a.size / 2
    pts = []
    seen = {}  # run id -> {"run.start": header, "run.end": header}, from the stream

    def truth(run_id):
        deadline = time.time() + 10
        while len(seen.get(run_id, {})) < 2 and time.time() < deadline:  # this curve's run.start and run.end
            if sub.poll(500):
                frames = sub.recv_multipart()
                h = json.loads(frames[1])
                if frames[0] in (b"run.start", b"run.end") and "run_id" in h:
                    seen.setdefault(h["run_id"], {})[frames[0].decode()] = h
        got = seen.pop(run_id, {})
        for topic in ("run.start", "run.end"):
            if topic not in got:
                sys.exit(f"no {topic} for run {run_id} on {a.pub}: is --pub vafmd's stream?")
        return got["run.start"], got["run.end"]

    t0 = time.time()
    for iy, y in enumerate(ys):
        for ix, x in enumerate(xs):
            n.folme_xy(float(x), float(y))
            chans, data, params = n.zspectr_start()
            run_id = int(params[5])  # Run ID (docs/nanonis.md: after the fixed parameters)
            adhesion, most_tensile = pulloff(data[chans.index("Force [bwd] (N)")])
            start, end = truth(run_id)
            scene, res = start["scene"], end.get("result") or {}
            if end.get("status") != "ok" or res.get("pulloff_sampled_N") is None:
                sys.exit(f"run {run_id} ended {end.get('status')} without a pull-off: {end.get('error')}")
            R, gamma, E = scene["R_m"], scene["gamma_J_per_m2"], scene["E_star_Pa"]
            # one output sample's Z travel: the truth (the most tensile sample) is k dz short on average
            k_dz = scene["k_N_per_m"] * scene["v_retract_m_per_s"] / start["sample_rate_Hz"]
            pts.append({"ix": ix, "iy": iy, "x_m": float(x), "y_m": float(y), "run_id": run_id,
                        "adhesion_N": adhesion, "adhesion_sampled_N": adhesion - k_dz,
                        "adhesion_most_tensile_point_N": most_tensile, "sample_step_N": k_dz,
                        "E_star_Pa": E, "gamma_J_per_m2": gamma, "adhesion_true_N": res["pulloff_sampled_N"],
                        "adhesion_jkr_N": 1.5 * math.pi * gamma * R, "k_N_per_m": scene["k_N_per_m"]})
    dt = time.time() - t0

    mats = {}
    for p in pts:
        mats.setdefault((p["E_star_Pa"], p["gamma_J_per_m2"]), []).append(p)
    summary = []
    print(f"{len(pts)} points ({a.nx} x {a.ny} over {a.size * 1e6:g} um) in {dt:.1f} s")

    def sem(v):
        return float(v.std(ddof=1) / math.sqrt(len(v))) if len(v) > 1 else math.nan

    for (E, g), ps in sorted(mats.items()):
        rec = np.array([p["adhesion_sampled_N"] for p in ps])
        tru = np.array([p["adhesion_true_N"] for p in ps])
        jkr = ps[0]["adhesion_jkr_N"]
        # the standard error of the mean residual (recovered - true, the same curves): the truth's sampling
        # k dz/sqrt(12) and the residuals' own spread, in quadrature
        step = max(p["sample_step_N"] for p in ps)
        resid = rec - tru
        spread = float(np.nanstd(resid, ddof=1)) if np.isfinite(resid).sum() > 1 else 0.0
        m = {"E_star_Pa": E, "gamma_J_per_m2": g, "points": len(ps),
             "adhesion_true_N": float(tru.mean()), "adhesion_true_sem_N": sem(tru),
             "adhesion_recovered_N": float(np.nanmean(rec)), "adhesion_recovered_sem_N": sem(rec),
             "residual_sem_N": math.sqrt(step ** 2 / 12 + spread ** 2) / math.sqrt(np.isfinite(rec).sum()),
             "adhesion_jkr_N": jkr}
        summary.append(m)
        print(f"material E* = {E:.4g} Pa, gamma = {g:.4g} J/m^2: {len(ps)} points, adhesion recovered "
              f"{m['adhesion_recovered_N'] * 1e9:.3f} +- {m['adhesion_recovered_sem_N'] * 1e9:.3f} nN, "
              f"true (the same curves' pull-off) {m['adhesion_true_N'] * 1e9:.3f} "
              f"+- {m['adhesion_true_sem_N'] * 1e9:.3f} nN")
        print(f"  athermal JKR pull-off 3/2 pi gamma R {jkr * 1e9:.3f} nN (not the truth at a finite T)")
    result = {"points": pts, "materials": summary}
    status = 0
    if len(summary) >= 2:
        lo, hi = summary[0], summary[-1]
        c_true = hi["adhesion_true_N"] / lo["adhesion_true_N"]
        c_rec = hi["adhesion_recovered_N"] / lo["adhesion_recovered_N"]
        c_jkr = hi["adhesion_jkr_N"] / lo["adhesion_jkr_N"]
        # the standard error of c_rec - c_true: recovered and true are the same curves, so only their
        # residuals count (each material's residual_sem_N, relative to its mean), in quadrature
        res = max(p["sample_step_N"] for p in pts) / math.sqrt(12)
        sigma = c_true * math.sqrt(sum((m["residual_sem_N"] / m["adhesion_true_N"]) ** 2 for m in (lo, hi)))
        z = (c_rec - c_true) / sigma if sigma > 0 else math.inf if sigma == 0 else math.nan
        agree = bool(abs(z) <= 3) if math.isfinite(sigma) else None  # None: a material of one curve, no sem
        result["contrast"] = {"true": c_true, "recovered": c_rec, "sigma": sigma, "z": z, "resolution_N": res,
                              "points": [lo["points"], hi["points"]], "agree": agree, "jkr": c_jkr}
        print(f"adhesion contrast: recovered {c_rec:.4f}, true {c_true:.4f} (the same curves' pull-off; "
              f"N = {lo['points']} + {hi['points']} curves), sigma {sigma:.4f}: "
              f"{z:+.2f} sigma, " + ("no check (a material of one curve has no sem)" if agree is None else
                                     "agree within 3 sigma" if agree else "DISAGREE: not within 3 sigma"))
        print(f"athermal JKR contrast {c_jkr:.4f} (an extra line: the weaker contact pulls off early at a "
              f"finite T)")
        status = 4 if agree is False else 0
    else:
        result["contrast"] = None
        print("one material under every point (no two-material ctrl_sample set on vafmd, docs/nanonis.md): "
              "no contrast to recover; none is claimed")
        status = 3 if a.require_contrast else 0
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(result, fh, indent=1)
    return status


if __name__ == "__main__":
    sys.exit(main())
