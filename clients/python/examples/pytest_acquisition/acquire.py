# SPDX-License-Identifier: MIT
"""A small acquisition module, written as a user of an AFM would: take N force curves from the instrument,
save each to disk, and compute the pull-off force and the contact point. Its tests (test_acquire.py) run it
against a vafmd that the pytest plugin of vafm_client starts for each test.

    saved, reports = take_curves(rep, pub, n=5, out_dir="curves")
    for c in load_curves("curves"):
        print(c["index"], pulloff(c), contact_point(c))

`careless=True` is the bug the plugin must catch: a run with lost blocks (a sequence gap) is saved as if
it were whole.
"""
import os

import numpy as np

from vafm_client import Client, GapError, Stream

APPROACH, RETRACT = 0, 1


def take_curves(rep, pub, n, out_dir, first_index=0, careless=False, timeout=60.0):
    """Take curves first_index .. first_index+n-1 and save each complete one as out_dir/curve_INDEX.npz.
    Returns (saved run ids, reports): the stream's reports of what went wrong (Stream.reports), and one
    {"kind": "lost", "run_id"} per run not saved."""
    os.makedirs(out_dir, exist_ok=True)
    saved, lost = [], []
    with Client(rep) as c, Stream(pub) as s:
        for i in range(first_index, first_index + n):
            run_id = c.curve(index=i)["run_id"]
            try:
                run = s.run(run_id, timeout=timeout, strict=not careless)
            except GapError:  # blocks lost, truncated, or the publisher restarted: not saved, reported
                lost.append({"kind": "lost", "run_id": run_id})
                c.wait_idle()
                continue
            c.wait_idle()
            if not careless and not run.clean:  # NaN or clipped samples: the data are not the force
                lost.append({"kind": "lost", "run_id": run_id})
                continue
            np.savez(os.path.join(out_dir, f"curve_{i}.npz"), index=i, run_id=run_id, force_N=run["force_N"],
                     height_m=run["height_m"], segment=run.segment)
            saved.append(run_id)
        return saved, list(s.reports) + lost


def load_curves(out_dir):
    """The saved curves, by index: dicts of index, run_id, force_N, height_m, segment."""
    names = sorted((f for f in os.listdir(out_dir) if f.startswith("curve_") and f.endswith(".npz")),
                   key=lambda f: int(f[6:-4]))
    out = []
    for f in names:
        with np.load(os.path.join(out_dir, f)) as z:
            out.append({k: (int(z[k]) if z[k].ndim == 0 else z[k]) for k in z.files})
    return out


def baseline_sd(c, fraction=0.3):
    """The force noise (N): the standard deviation of the first `fraction` of the approach (tip far away)."""
    f = c["force_N"][c["segment"] == APPROACH]
    return float(np.std(f[: max(2, int(len(f) * fraction))], ddof=1))


def pulloff(c):
    """(pull-off force, its standard error), N: the deepest adhesive force of the retract, with the
    baseline's force noise as its error."""
    f = c["force_N"][c["segment"] == RETRACT]
    return float(-f.min()), baseline_sd(c)


def contact_point(c):
    """Height (m) of the contact on approach: the last approach sample whose force is above zero (the lever
    is pushed back) seen from the end of the approach backwards, i.e. where the repulsive branch starts."""
    seg = c["segment"] == APPROACH
    f, z = c["force_N"][seg], c["height_m"][seg]
    k = len(f) - 1
    while k > 0 and f[k - 1] > 0:
        k -= 1
    return float(z[k])
