# SPDX-License-Identifier: MIT
"""Thermal tune fit: the free cantilever's deflection PSD and the damped-oscillator fit of its spring constant.

Used by examples/thermal_tune.py and by the web panel (clients/web/vafm_web.py), installed with the package so
neither imports from the source tree. The model, with the sampling folded in:

    S(f) = 2 k_B T / (π k f0 Q) · f0⁴ / ((f0² − f²)² + (f f0 / Q)²)        (one-sided, m²/Hz; ∫S df = k_B T / k)

each output sample being the mean over its interval (antialias=mean: the PSD times sinc²(f/fs)) or a point
value (antialias=point), aliased about multiples of fs. numpy here; scipy (Debian's python3-scipy) only
when fit_tune is called.
"""
import math

import numpy as np

K_B = 1.380649e-23  # J/K (exact, SI 2019)


def sho_psd(f, k, f0, q, kT):
    """One-sided deflection PSD of the thermally driven damped oscillator, m²/Hz (integral kT/k)."""
    return 2 * kT / (math.pi * k * f0 * q) * f0 ** 4 / ((f0 ** 2 - f ** 2) ** 2 + (f * f0 / q) ** 2)


def sampled_psd(f, k, f0, q, kT, fs, mean, images=4):
    """The PSD of the output samples: box-car mean over each interval (mean) and aliasing about m·fs."""
    s = np.zeros_like(f)
    for m in range(-images, images + 1):
        g = np.abs(f + m * fs)
        h = np.sinc(g / fs) ** 2 if mean else 1.0
        s += sho_psd(g, k, f0, q, kT) * h
    return s


def fit_tune(x, fs, kT, mean, nperseg=None):
    """Fit (k, f0, Q) to the Welch PSD of deflection x (m). Returns dict with values, 1σ errors, PSD."""
    from scipy.optimize import curve_fit
    from scipy.signal import welch
    n = len(x)
    nperseg = nperseg or min(n, 1 << max(8, int(math.log2(n / 64))))  # ≈ 64–128 segments
    f, p = welch(x, fs=fs, nperseg=nperseg)  # Hann, 50 % overlap, mean removed per segment
    use = f >= 2 * f[1]  # the lowest bins carry the per-segment mean removal
    ff, pp = f[use], p[use]
    # starting values: equipartition for k; f0 from <f²> of the PSD (= f0² for the oscillator); Q = 1
    var = np.var(x)
    f0_0 = math.sqrt(np.trapz(ff ** 2 * pp, ff) / np.trapz(pp, ff))
    p0 = [kT / var, f0_0, 1.0]

    def model(fr, k, f0, q):
        return sampled_psd(fr, k, abs(f0), abs(q), kT, fs, mean)

    # weights: each Welch bin scatters by a fixed fraction of its expectation; weighting by the data
    # would bias low, so fit twice with the previous model as the scale
    sigma = pp
    for _ in range(3):
        popt, pcov = curve_fit(model, ff, pp, p0=p0, sigma=sigma, absolute_sigma=False, maxfev=20000)
        p0, sigma = popt, model(ff, *popt)
    err = np.sqrt(np.diag(pcov))
    return {"k": popt[0], "f0": abs(popt[1]), "Q": abs(popt[2]), "k_err": err[0], "f0_err": err[1], "Q_err": err[2],
            "f": f, "psd": p, "fit_f": ff, "nperseg": nperseg, "k_equipartition": kT / var}
