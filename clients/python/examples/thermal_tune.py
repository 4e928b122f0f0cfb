#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Thermal tune: the free cantilever's deflection PSD, the damped-oscillator fit and the spring constant.

    /usr/bin/python3 clients/python/examples/thermal_tune.py --png tune.png      # a vafmd on the defaults
    /usr/bin/python3 clients/python/examples/thermal_tune.py --spawn build/src/daemon/vafmd --spawn-arg=--free-run

Records a `tune` (the free cantilever at the start height, no ramp) and calibrates the spring constant as
on an AFM: deflection from the detector signal (vDeflection_V × the sensitivity of run.start), Welch PSD,
least-squares fit of the thermally driven damped harmonic oscillator

    S(f) = 2 k_B T / (π k f0 Q) · f0⁴ / ((f0² − f²)² + (f f0 / Q)²)        (one-sided, m²/Hz; ∫S df = k_B T / k)

with the sampling folded in: each output sample is the mean over its interval (antialias=mean: the PSD
times sinc²(f/fs)) or a point value (antialias=point), aliased about multiples of fs. The free parameters are
k, f0 and Q; T is the scene's. Prints k with its 1σ fit error and its relative error against the configured
k, plus the equipartition estimate k_B T / <x²> as a cross-check, and writes the PSD and the fit to a PNG.

The tune's sample rate is set to --rate-factor (25) times the nominal resonance sqrt(k/m)/2π of the scene
(a tune's bandwidth is chosen from the nominal cantilever, as on an instrument) and restored afterwards.
Statistical expectation: the mean square of an oscillator with damping rate η recorded for a time T has a
relative standard error of about sqrt(2/(ηT)); the fitted k has an error of that order (printed).
"""
import argparse
import math
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from vafm_client import Stream  # noqa: E402
from vafm_client.spawn import add_endpoint_args, connect, plt_agg, save_png  # noqa: E402
from vafm_client.tune import K_B, fit_tune, sampled_psd, sho_psd  # noqa: E402  (the fit, shared with vafm web)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    add_endpoint_args(ap)
    ap.add_argument("--png", default="thermal_tune.png", help="figure (default %(default)s)")
    ap.add_argument("--duration", type=float, default=0.5, help="tune duration, s (default %(default)s)")
    ap.add_argument("--rate-factor", type=float, default=25.0,
                    help="sample rate / nominal resonance frequency (default %(default)s)")
    ap.add_argument("--preset", help="apply this scene preset first")
    ap.add_argument("--index", type=int, default=0, help="random stream of the tune (default 0)")
    ap.add_argument("--json", help="also write the results here (k, f0, Q with errors, configured values)")
    a = ap.parse_args(argv)

    with connect(a) as (c, rep, pub):
        if a.preset:
            c.set(preset=a.preset)
        c.wait_idle()
        sc = c.get("k_N_per_m", "m_kg", "sample_rate_Hz")
        f_nom = math.sqrt(sc["k_N_per_m"] / sc["m_kg"]) / (2 * math.pi)
        c.set(sample_rate_Hz=round(a.rate_factor * f_nom))
        try:
            with Stream(pub) as s:
                r = c.tune(duration_s=a.duration, index=a.index)
                run = s.run(r["run_id"], timeout=max(60.0, 20 * a.duration))
        finally:
            c.wait_idle()
            c.set(sample_rate_Hz=sc["sample_rate_Hz"])
    scene, fs = run.start["scene"], run.start["sample_rate_Hz"]
    x = run["vDeflection_V"] * run.start["sensitivity_m_per_V"]  # as an instrument: volts × InvOLS
    kT = K_B * scene["T_K"]
    mean = scene.get("antialias", "mean") == "mean"
    fit = fit_tune(x, fs, kT, mean)
    k_cfg, eta = scene["k_N_per_m"], scene["eta_per_s"]
    f0_cfg = math.sqrt(k_cfg / scene["m_kg"]) / (2 * math.pi)
    q_cfg = 2 * math.pi * f0_cfg / eta
    expect = math.sqrt(2 / (eta * a.duration))
    print(f"tune: {len(x)} samples at {fs:g} Hz ({a.duration:g} s, antialias {scene.get('antialias')}), "
          f"T = {scene['T_K']:.6g} K; Welch {fit['nperseg']} points per segment")
    print(f"fit:  k = {fit['k']:.6g} ± {fit['k_err']:.2g} N/m, f0 = {fit['f0']:.6g} ± {fit['f0_err']:.2g} Hz, "
          f"Q = {fit['Q']:.4g} ± {fit['Q_err']:.2g}")
    print(f"configured: k = {k_cfg:.6g} N/m, f0 = sqrt(k/m)/2π = {f0_cfg:.6g} Hz, Q = 2πf0/η = {q_cfg:.4g}")
    print(f"spring constant: relative error {fit['k'] / k_cfg - 1:+.4%} (fit 1σ {fit['k_err'] / k_cfg:.2%}; "
          f"statistical expectation sqrt(2/(ηT)) = {expect:.2%}); equipartition k_B T/<x²> = "
          f"{fit['k_equipartition']:.6g} N/m ({fit['k_equipartition'] / k_cfg - 1:+.3%})")

    if a.json:
        import json
        with open(a.json, "w") as fh:
            json.dump({"k_N_per_m": fit["k"], "k_err": fit["k_err"], "f0_Hz": fit["f0"], "f0_err": fit["f0_err"],
                       "Q": fit["Q"], "Q_err": fit["Q_err"], "k_equipartition": fit["k_equipartition"],
                       "k_configured": k_cfg, "f0_configured": f0_cfg, "Q_configured": q_cfg,
                       "expected_rel_sd": expect, "samples": len(x), "sample_rate_Hz": fs}, fh, indent=1)
    plt = plt_agg()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    f, p = fit["f"][1:], fit["psd"][1:]
    ax.loglog(f, p, lw=0.7, color="tab:gray", label="Welch PSD of the deflection")
    ax.loglog(f, sampled_psd(f, fit["k"], fit["f0"], fit["Q"], kT, fs, mean), color="tab:red", lw=1.2,
              label=f"fit: k = {fit['k']:.4g} N/m, f0 = {fit['f0'] / 1e3:.4g} kHz, Q = {fit['Q']:.3g}")
    ax.loglog(f, sho_psd(f, k_cfg, f0_cfg, q_cfg, kT), color="k", lw=0.8, ls="--",
              label=f"configured: k = {k_cfg:.4g} N/m")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("PSD (m²/Hz)")
    ax.set_title(f"thermal tune: k relative error {fit['k'] / k_cfg - 1:+.2%}")
    ax.legend(fontsize=8)
    save_png(fig, os.path.abspath(a.png))
    return 0


if __name__ == "__main__":
    sys.exit(main())
