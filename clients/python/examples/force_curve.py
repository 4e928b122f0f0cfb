#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Live force curve: one curve from vafmd, logged to HDF5 by the daemon, plotted as force vs height.

    /usr/bin/python3 clients/python/examples/force_curve.py                       # a vafmd on the defaults
    /usr/bin/python3 clients/python/examples/force_curve.py --spawn build/src/daemon/vafmd --out-dir build/demo

Subscribes to the stream, turns on the daemon's HDF5 logging (`log`), starts one force curve (`curve`),
collects its samples as they are measured (paced in real time unless the daemon runs free), stops the
logging, and then: prints the pull-off force observables of the curve result (run.end: tensile
magnitudes, also in units of F_JKR = 3πγR/2), checks that the streamed pull-off equals the result's and
that the logged file holds the streamed samples bit for bit (vafm_client.load_h5), and writes a PNG of
force vs piezo height, approach and retract. Exit status 0, 1 on any failure.
"""
import argparse
import json
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from vafm_client import Stream, load_h5  # noqa: E402
from vafm_client.spawn import add_endpoint_args, connect, plt_agg, save_png  # noqa: E402

OBSERVABLES = (  # run.end result keys: what each means (physics notes, "what pull-off force means")
    ("pulloff_sampled_N", "N", "most tensile output sample of the retract (what an AFM user reads)"),
    ("pulloff_spring_N", "N", "most tensile spring force of any step of the retract (the paper's)"),
    ("detach_force_N", "N", "spring force when the tip detached (ground truth)"),
    ("detach_eq_force_N", "N", "noise-free equilibrium spring force at that height"),
    ("detach_height_m", "m", "piezo height at the detachment"),
    ("detach_time_s", "s", "time from the start of the retract to the detachment"),
)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    add_endpoint_args(ap)
    ap.add_argument("--out-dir", default=".", help="directory of the PNG and the HDF5 file (default: .)")
    ap.add_argument("--png", help="figure (default OUT_DIR/force_curve.png)")
    ap.add_argument("--h5", help="HDF5 file the daemon logs to (default OUT_DIR/force_curve.h5; replaced)")
    ap.add_argument("--index", type=int, default=0, help="curve index: its random stream (default 0)")
    ap.add_argument("--preset", help="apply this scene preset first (default: the daemon's current scene)")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="set a scene parameter or daemon setting first (repeat), e.g. --set free_run=true")
    ap.add_argument("--timeout", type=float, default=600, help="give up after this many seconds (default 600)")
    a = ap.parse_args(argv)
    os.makedirs(a.out_dir, exist_ok=True)
    png = os.path.abspath(a.png or os.path.join(a.out_dir, "force_curve.png"))
    h5 = os.path.abspath(a.h5 or os.path.join(a.out_dir, "force_curve.h5"))  # the daemon has its own cwd
    values = {}
    for kv in a.set:
        name, sep, v = kv.partition("=")
        if not sep:
            ap.error(f"--set {kv}: NAME=VALUE expected")
        try:
            values[name] = json.loads(v)
        except ValueError:
            values[name] = v

    with connect(a) as (c, rep, pub):
        if a.preset or values:
            c.set(values or None, preset=a.preset)
        c.wait_idle()
        with Stream(pub, curve=None) as s:
            c.request({"cmd": "log", "path": h5, "overwrite": True})
            try:
                r = c.curve(index=a.index, client_run_id=f"force_curve-{os.getpid()}-{a.index}")
                print(f"curve {a.index}: run {r['run_id']} started on {rep}; waiting for its samples ...", flush=True)
                run = s.run(r["run_id"], timeout=a.timeout)  # GapError if a block was lost
            finally:
                c.wait_idle(timeout=a.timeout)
                log = c.request({"cmd": "log", "stop": True})["log"]
    res, scene = dict(run.end["result"]), run.start["scene"]
    f = load_h5(h5)  # the daemon's file: its ground truth also has what run.end does not carry
    truth = f[0].truth if len(f) == 1 else {}
    failed = False
    for key, _, _ in OBSERVABLES:
        if res.get(key) is None and truth and math.isfinite(truth.get(key, math.nan)):
            res[key] = truth[key]
        elif res.get(key) is not None and truth and truth.get(key) != res[key]:
            print(f"error: {key}: run.end says {res[key]!r}, the file's ground truth {truth.get(key)!r}",
                  file=sys.stderr)
            failed = True
    f_jkr = 1.5 * math.pi * scene["gamma_J_per_m2"] * scene["R_m"]
    n_app, n_ret = int((run.segment == 0).sum()), int((run.segment == 1).sum())
    print(f"scene: k = {scene['k_N_per_m']:.6g} N/m, T = {scene['T_K']:.6g} K, v = {scene['v_retract_m_per_s']:.6g} m/s,"
          f" R = {scene['R_m']:.4g} m, F_JKR = 3πγR/2 = {f_jkr:.6g} N")
    print(f"samples: {len(run['force_N'])} ({n_app} approach, {n_ret} retract) at {run.start['sample_rate_Hz']:g} Hz,"
          f" {res['duration_s']:.4g} s simulated, {run.end['wall_s']:.3g} s wall, flags {res['flags']}")
    print("pull-off force observables (tensile magnitudes):")
    for key, unit, doc in OBSERVABLES:
        v = res.get(key)
        if v is None:
            print(f"  {key:18s} {'n/a':>14s}      {doc}")
        elif unit == "N":
            print(f"  {key:18s} {v * 1e9:12.6g} nN  {v / f_jkr:9.6f} F_JKR  {doc}")
        else:
            print(f"  {key:18s} {v:12.6g} {unit:2s}  {'':15s} {doc}")
    retract = run.segment == 1
    f_stream = float(-run["force_N"][retract].min()) if retract.any() else math.nan
    if res["pulloff_sampled_N"] is not None and f_stream != res["pulloff_sampled_N"]:
        print(f"error: streamed pull-off {f_stream!r} N differs from the result's {res['pulloff_sampled_N']!r} N",
              file=sys.stderr)
        failed = True
    # the daemon's file: one curve equal to the stream, bit for bit
    if log.get("curves") != 1 or len(f) != 1:
        print(f"error: {h5}: expected 1 logged curve, log says {log}", file=sys.stderr)
        return 1
    cv = f[0]
    same = (np.array_equal(cv["force"], run["force_N"]) and np.array_equal(cv["height (piezo)"], run["height_m"])
            and ("tip position" not in cv or np.array_equal(cv["tip position"], run["tip_m"]))
            and np.array_equal(cv.segment, run.segment))
    print(f"HDF5: {h5}: curve 0 ({cv.meta.get('curve id')}), {len(cv)} samples, "
          f"{'equal to the streamed samples bit for bit' if same else 'DIFFERS from the stream'}")
    failed |= not same

    plt = plt_agg()
    # left: force vs piezo height as analysis software shows it (approach drawn above the retract, offset
    # markers off); right: the same samples in time order, so that the approach's baseline noise, the snap-in
    # and the retract's adhesion well are each visible on their own
    fig, (ax, axt) = plt.subplots(1, 2, figsize=(11, 4.5), gridspec_kw={"width_ratios": [3, 2]})
    h_nm, f_nN, t_ms = run["height_m"] * 1e9, run["force_N"] * 1e9, (run.time_s - run.time_s[0]) * 1e3
    segs = ((1, "retract", "tab:red", 1.6, 1), (2, "dwell", "tab:gray", 1.0, 2), (0, "approach", "tab:blue", 1.0, 3))
    for seg, name, color, lw, z in segs:
        m = run.segment == seg
        if m.any():
            ax.plot(h_nm[m], f_nN[m], lw=lw, color=color, label=name, zorder=z, alpha=0.9)
            axt.plot(t_ms[m], f_nN[m], lw=0.8, color=color)
    if retract.any():
        i = np.flatnonzero(retract)[np.argmin(run["force_N"][retract])]
        ax.plot(h_nm[i], f_nN[i], "ko", ms=5, zorder=4,
                label=f"pull-off {f_stream * 1e9:.4g} nN" + (f" ({f_stream / f_jkr:.3f} F_JKR)" if f_jkr > 0 else ""))
        axt.plot(t_ms[i], f_nN[i], "ko", ms=4)
    if f_jkr > 0:
        ax.axhline(-f_jkr * 1e9, color="k", lw=0.6, ls="--", label="−F_JKR")
    ax.set_xlabel("piezo height above the contact point (nm)")
    ax.set_ylabel("force (nN, repulsive > 0)")
    ax.set_title(f"vafmd force curve {a.index}: k = {scene['k_N_per_m']:.3g} N/m, T = {scene['T_K']:.4g} K, "
                 f"v = {scene['v_approach_m_per_s'] * 1e6:.3g} µm/s", fontsize=9)
    ax.legend(fontsize=8)
    axt.set_xlabel("time (ms)")
    axt.set_title("the same samples in time: approach, then retract", fontsize=9)
    save_png(fig, png)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
