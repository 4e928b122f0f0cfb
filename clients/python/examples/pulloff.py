#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Record N force curves from a running vafmd and print pull-off force statistics.

    python3 clients/python/examples/pulloff.py --rep tcp://127.0.0.1:5555 --pub tcp://127.0.0.1:5556 -n 20 \
        --png pulloff.png

Each curve's pull-off is read twice: from the streamed samples (the most tensile force sample of the
retract, what an AFM user reads) and from run.end's curve result (`pulloff_sampled_N`, the same quantity,
and `pulloff_spring_N`, the paper's definition over every simulation step). Forces are tensile magnitudes.
With --png and python3-matplotlib, writes the last curve (force vs height) and the pull-off histogram.
"""
import argparse
import math
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from vafm_client import Client, Stream  # noqa: E402
from vafm_client.spawn import plt_agg, save_png  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("--rep", default="tcp://127.0.0.1:5555", help="command endpoint")
    ap.add_argument("--pub", default="tcp://127.0.0.1:5556", help="stream endpoint")
    ap.add_argument("-n", type=int, default=10, help="number of curves (indices first..first+n-1)")
    ap.add_argument("--first", type=int, default=0, help="first curve index")
    ap.add_argument("--preset", help="apply this preset first")
    ap.add_argument("--png", help="write a figure here (needs matplotlib)")
    a = ap.parse_args(argv)
    if a.n < 1:
        ap.error("-n must be at least 1")

    with Client(a.rep) as c, Stream(a.pub) as s:
        if a.preset:
            c.set(preset=a.preset)
        sampled, spring, last = [], [], None
        for i in range(a.first, a.first + a.n):
            c.wait_idle()  # the previous run's end reaches us before the daemon is idle again
            run = s.run(c.curve(index=i)["run_id"])  # raises GapError if a block was lost
            res = run.end["result"]
            retract = run.segment == 1
            f_stream = float(-run["force_N"][retract].min()) if retract.any() else math.nan
            if res["pulloff_sampled_N"] is not None and f_stream != res["pulloff_sampled_N"]:
                print(f"warning: curve {i}: streamed pull-off {f_stream!r} != result {res['pulloff_sampled_N']!r}",
                      file=sys.stderr)
            sampled.append(f_stream)
            spring.append(res["pulloff_spring_N"] if res["pulloff_spring_N"] is not None else math.nan)
            last = run
            print(f"curve {i}: pull-off {f_stream * 1e9:.4f} nN (sampled), {spring[-1] * 1e9:.4f} nN (spring), "
                  f"{len(run['force_N'])} samples")
    import numpy as np
    for name, v in (("sampled", np.array(sampled)), ("spring", np.array(spring))):
        v = v[np.isfinite(v)]
        if len(v) == 0:
            print(f"pull-off ({name}): no detachment")
            continue
        sd = v.std(ddof=1) if len(v) > 1 else math.nan
        print(f"pull-off ({name}): N = {len(v)}, mean = {v.mean() * 1e9:.4f} nN, sd = {sd * 1e9:.4f} nN, "
              f"sem = {sd / math.sqrt(len(v)) * 1e9:.4f} nN, min = {v.min() * 1e9:.4f} nN, "
              f"max = {v.max() * 1e9:.4f} nN")
    if a.png:
        try:
            plt = plt_agg()
        except ImportError:
            print("matplotlib not available (Debian: python3-matplotlib): no figure", file=sys.stderr)
            return 0
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
        for seg, name in ((0, "approach"), (1, "retract")):
            m = last.segment == seg
            ax1.plot(last["height_m"][m] * 1e9, last["force_N"][m] * 1e9, lw=0.6, label=name)
        ax1.set_xlabel("piezo height (nm)")
        ax1.set_ylabel("force (nN, repulsive > 0)")
        ax1.set_title(f"curve {last.start['index']}")
        ax1.legend()
        ax2.hist(np.array(spring) * 1e9, bins=max(5, int(math.sqrt(len(spring)))))
        ax2.set_xlabel("pull-off force (nN, spring)")
        ax2.set_ylabel("curves")
        save_png(fig, a.png, dpi=100, say="figure written to {}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
