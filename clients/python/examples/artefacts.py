#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Instrument artefacts and the analysis that must survive them: a Hertz fit through offset, tilt and drift.

Runs `vafm samples` on the cell-liquid preset twice, ideal and with the artefacts of a real instrument at
typical levels (baseline offset, virtual deflection, baseline drift, a noise floor with 1/f noise, mains
pickup, a random contact point), then does what analysis software does with the approach: fit and subtract
the baseline (a line in height: it takes the offset, the tilt and, at constant speed, the drift), find the
contact point and fit the Hertz law F = 4/3 E* sqrt(R) d^(3/2) to the indentation d = (h_c - h) - F/k.
Prints the recovered E* against the scene's true one for both runs, draws the raw and corrected curves and
the fit (PNG), and exits 1 when the artefact run misses the truth by more than --tolerance.

Usage: artefacts.py --vafm build/src/cli/vafm [--png artefacts.png] [--index 0]
"""
import argparse
import csv
import io
import json
import math
import subprocess
import sys

import numpy as np

# Typical levels (cell-liquid: InvOLS 40 nm/V, k = 0.03 N/m, so 1 V is 1.2 nN): an offset of a tenth of a
# volt, a tilt of 0.1 V per um of travel, a drift of 50 mV/s, a 2 mV floor with 1/f noise below 20 Hz, 5 mV
# of 50 Hz pickup, a contact point anywhere within +-100 nm from curve to curve.
ARTEFACTS = {
    "baseline_offset_V": 0.1,
    "virtual_deflection_V_per_m": 1e5,
    "drift_V_per_s": 0.05,
    "noise_V_rms": 2e-3,
    "flicker_corner_Hz": 20.0,
    "mains_V": 5e-3,
    "contact_point_sd_m": 100e-9,
}


def run_vafm(vafm, preset, index, values):
    args = [vafm, "samples", "--preset", preset, "--index", str(index), "--csv", "-"]
    args += [f"--{k}={v!r}" for k, v in values.items()]
    out = subprocess.run(args, check=True, capture_output=True, text=True).stdout
    rows = list(csv.DictReader(io.StringIO(out)))
    cols = {k: np.array([float(r[k]) for r in rows]) for k in ("time_s", "height_m", "force_N", "segment")}
    scene = json.loads(subprocess.run([vafm, "params", "--json", "--preset", preset] +
                                      [f"--{k}={v!r}" for k, v in values.items()],
                                      check=True, capture_output=True, text=True).stdout)
    return cols, scene


def hertz_fit(h, F, k, R):
    """Baseline line on the upper half of the approach's travel, then the contact point and E* that
    minimise the Hertz residual (a scan of contact points, E* by linear least squares at each)."""
    top = h > h.min() + 0.6 * (h.max() - h.min())
    base = np.polyfit(h[top], F[top], 1)
    Fc = F - np.polyval(base, h)
    best = None
    for hc in np.linspace(h.min(), h.max(), 1500):
        d = (hc - h) - Fc / k
        m = d > 0
        if m.sum() < 20:
            continue
        x = d[m] ** 1.5
        a = float(np.dot(x, Fc[m]) / np.dot(x, x))
        # the residual over the whole approach: zero force above the contact point, Hertz below it
        model = np.where(d > 0, a * np.clip(d, 0, None) ** 1.5, 0.0)
        res = float(np.sum((Fc - model) ** 2))
        if best is None or res < best[0]:
            best = (res, hc, a)
    _, hc, a = best
    return {"E_star_Pa": a * 3.0 / (4.0 * math.sqrt(R)), "contact_m": hc, "baseline": base, "corrected": Fc}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("--vafm", default="vafm", help="the vafm program (default: vafm on PATH)")
    ap.add_argument("--preset", default="cell-liquid", help="scene preset (default cell-liquid)")
    ap.add_argument("--index", type=int, default=0, help="curve index (default 0)")
    ap.add_argument("--png", help="write the figure here (needs matplotlib)")
    ap.add_argument("--tolerance", type=float, default=0.05,
                    help="largest relative error of E* accepted with the artefacts on (default 0.05)")
    a = ap.parse_args(argv)
    fits = {}
    for name, values in (("ideal", {}), ("artefacts", ARTEFACTS)):
        cols, scene = run_vafm(a.vafm, a.preset, a.index, values)
        app = cols["segment"] == 0
        fit = hertz_fit(cols["height_m"][app], cols["force_N"][app], scene["k_N_per_m"], scene["R_m"])
        fits[name] = (cols, scene, fit)
        err = fit["E_star_Pa"] / scene["E_star_Pa"] - 1.0
        print(f"{name:9s}: E* = {fit['E_star_Pa']:.5g} Pa (true {scene['E_star_Pa']:.5g} Pa, {err:+.2%}), "
              f"contact point at {fit['contact_m'] * 1e9:.1f} nm, baseline slope {fit['baseline'][0]:.3g} N/m")
    cols, scene, fit = fits["artefacts"]
    err = fit["E_star_Pa"] / scene["E_star_Pa"] - 1.0
    if a.png:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 4.2))
        for name, color in (("ideal", "tab:gray"), ("artefacts", "tab:blue")):
            c, s, f = fits[name]
            app = c["segment"] == 0
            ax0.plot(c["height_m"] * 1e9, c["force_N"] * 1e9, lw=0.7, color=color, label=f"{name} (raw)")
            ax1.plot(c["height_m"][app] * 1e9, f["corrected"] * 1e9, lw=0.7, color=color,
                     label=f"{name}: E* = {f['E_star_Pa']:.4g} Pa")
        h = cols["height_m"][cols["segment"] == 0]
        d = np.clip(fit["contact_m"] - h - fit["corrected"] / scene["k_N_per_m"], 0, None)
        ax1.plot(h * 1e9, 4.0 / 3.0 * fit["E_star_Pa"] * math.sqrt(scene["R_m"]) * d ** 1.5 * 1e9, "k--", lw=0.8,
                 label="Hertz fit, d = h_c - h - F/k")
        ax0.set_xlabel("piezo height (nm)")
        ax0.set_ylabel("force (nN)")
        ax0.set_title("as recorded: offset, tilt, drift, noise, mains, moved contact point", fontsize=9)
        ax1.set_xlabel("piezo height (nm)")
        ax1.set_title(f"approach after baseline correction; true E* = {scene['E_star_Pa']:.4g} Pa", fontsize=9)
        ax0.legend(fontsize=8)
        ax1.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(a.png, dpi=110)
        print(f"PNG: {a.png}")
    if not abs(err) <= a.tolerance:
        print(f"error: with the artefacts on, E* is off by {err:+.2%} (tolerance {a.tolerance:.0%})", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
