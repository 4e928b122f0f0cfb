#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Draw a force map: the true and the recovered modulus, adhesion and height, side by side.

    vafm map --preset cell-liquid --nx 32 --ny 32 --pattern dome --pattern-param b_E_star_Pa=30e3 --out map.h5
    python3 clients/python/examples/force_map.py map.h5 --png map.png [--json map.json]

Reads any force-map file of the layout (afmformats' map attributes place each curve; vafm's ground truth gives
the true E*, gamma and surface height of each pixel). From each curve's measured data alone it recovers:
  - the modulus: a Hertz fit of the approach, F = 4/3 E* sqrt(R) (z_c - z)^(3/2), over the samples above 10%
    of the approach's largest force, with z the tip position and z_c the contact point (both fitted; R from
    the file's scene);
  - the height: the fitted contact point z_c (the surface under the tip, from the substrate);
  - the adhesion: the pull-off force, the most tensile force of the retract (0 when none).
"True adhesion" is the JKR pull-off 3/2 pi gamma R of the pixel's true gamma (athermal, quasi-static).
Prints, per material, the true and the mean recovered modulus.
"""
import argparse
import json
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from vafm_client import load_h5  # noqa: E402
from vafm_client.spawn import plt_agg, save_png  # noqa: E402


def hertz_fit(tip, force, R):
    """(E*, z_c) of F = 4/3 E* sqrt(R) (z_c - tip)^1.5 by least squares: for each z_c the best E* is linear;
    z_c by a golden-section search around the first sample above the threshold."""
    sel = force > 0.1 * force.max()
    if sel.sum() < 5 or force.max() <= 0:
        return math.nan, math.nan
    z, f = tip[sel], force[sel]

    def cost(zc):
        g = 4.0 / 3.0 * math.sqrt(R) * np.clip(zc - z, 0, None) ** 1.5
        gg = float(g @ g)
        if gg <= 0:
            return math.inf, math.nan
        E = float(g @ f) / gg
        r = f - E * g
        return float(r @ r), E

    span = float(z.max() - z.min())
    lo, hi = float(z.max()), float(z.max()) + span  # the contact point lies above every indented sample
    phi = (math.sqrt(5) - 1) / 2
    a, b = hi - phi * (hi - lo), lo + phi * (hi - lo)
    ca, cb = cost(a)[0], cost(b)[0]
    for _ in range(80):
        if ca < cb:
            hi, b, cb = b, a, ca
            a = hi - phi * (hi - lo)
            ca = cost(a)[0]
        else:
            lo, a, ca = a, b, cb
            b = lo + phi * (hi - lo)
            cb = cost(b)[0]
    zc = 0.5 * (lo + hi)
    return cost(zc)[1], zc


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("file", help="a force-map HDF5 file (vafm map)")
    ap.add_argument("--png", default="force_map.png", help="the figure (default force_map.png)")
    ap.add_argument("--json", help="write the per-material true and recovered moduli here")
    a = ap.parse_args(argv)

    f = load_h5(a.file)
    if not f.is_map:
        sys.exit(f"{a.file}: not a force map (no 'grid shape x|y', 'grid index x|y' attributes)")
    R = float(f.scene["R_m"]) if f.scene else math.nan
    nx, ny = f.map_shape
    E_rec, z_rec, F_rec, E_true, h_true, F_true = [], [], [], [], [], []
    for c in f:
        tip = c["tip position"] if "tip position" in c else c["height (measured)"] + c.force / c.meta["spring constant"]
        appr, retr = c.approach, c.retract
        E, zc = hertz_fit(tip[appr], c.force[appr], R)
        E_rec.append(E)
        z_rec.append(zc)
        F_rec.append(max(0.0, -float(c.force[retr].min())) if retr.any() else math.nan)
        t = c.truth or {}
        E_true.append(t.get("E_star_Pa", math.nan))
        h_true.append(t.get("surface_height_m", math.nan))
        F_true.append(1.5 * math.pi * t.get("gamma_J_per_m2", math.nan) * R)

    # per material (distinct true E*, gamma): the mean recovered modulus
    mats = {}
    for c, E in zip(f, E_rec):
        t = c.truth or {}
        key = (t.get("E_star_Pa"), t.get("gamma_J_per_m2"))
        mats.setdefault(key, []).append(E)
    summary = []
    for (Et, gt), Es in sorted(mats.items(), key=lambda kv: kv[0][0] or 0):
        Es = np.array([e for e in Es if np.isfinite(e)])
        sem = float(Es.std(ddof=1) / math.sqrt(len(Es))) if len(Es) > 1 else math.nan
        rec = float(Es.mean()) if len(Es) else math.nan
        summary.append({"E_true_Pa": Et, "gamma_true_J_per_m2": gt, "pixels": len(Es), "E_recovered_Pa": rec,
                        "E_recovered_sem_Pa": sem})
        print(f"material E* = {Et:.6g} Pa, gamma = {gt:.4g} J/m^2: {len(Es)} pixels, Hertz fit of the approach "
              f"E* = {rec:.6g} +- {sem:.3g} Pa ({100 * (rec / Et - 1):+.2f}%)")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"nx": nx, "ny": ny, "materials": summary}, fh, indent=1)

    plt = plt_agg()
    ext = [v * 1e6 for v in f.map_extent]
    rows = [("modulus E*, kPa", E_true, E_rec, 1e-3), ("adhesion (pull-off), nN", F_true, F_rec, 1e9),
            ("surface height, nm", h_true, z_rec, 1e9)]
    fig, axes = plt.subplots(len(rows), 2, figsize=(9, 3.2 * len(rows)), squeeze=False)
    for r, (name, tv, rv, scale) in enumerate(rows):
        T, M = f.map_array(tv) * scale, f.map_array(rv) * scale
        finite = np.concatenate([T[np.isfinite(T)], M[np.isfinite(M)]])
        vmin, vmax = (float(finite.min()), float(finite.max())) if finite.size else (0, 1)
        for col, (data, what) in enumerate(((T, "true"), (M, "recovered"))):
            ax = axes[r][col]
            im = ax.imshow(data, origin="lower", extent=ext, vmin=vmin, vmax=vmax if vmax > vmin else vmin + 1,
                           cmap="viridis", interpolation="nearest")
            ax.set_title(f"{what} {name}", fontsize=9)
            ax.set_xlabel("x, um")
            ax.set_ylabel("y, um")
            fig.colorbar(im, ax=ax, shrink=0.8)
    spec = f.map_spec or {}
    fig.suptitle(f"{os.path.basename(a.file)}: {nx} x {ny} pixels, pattern {spec.get('pattern', '?')}", fontsize=10)
    save_png(fig, a.png, dpi=90)
    return 0


if __name__ == "__main__":
    sys.exit(main())
