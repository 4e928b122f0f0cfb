#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Pull-off force histogram of a campaign with a skew-normal fit (as in the paper's Fig. 3).

    /usr/bin/python3 clients/python/examples/pulloff_hist.py -n 200 --png fig3.png     # a vafmd on the defaults
    /usr/bin/python3 clients/python/examples/pulloff_hist.py --spawn build/src/daemon/vafmd \\
        --spawn-arg=--free-run --preset paper-fig4 -n 50 --T 100,300

Runs N curves per grid point (temperatures × speeds × spring constants; empty lists: the scene's value)
with the daemon's `campaign` command, collecting each curve's result from its run.end; a daemon without
`campaign` (reply not_implemented) gets the same curves as a sequence of `curve` commands with explicit
indices (said on stdout). For each point: the histogram of the pull-off force in units of
F_JKR = 3πγR/2 and the maximum-likelihood skew-normal fit (scipy.stats.skewnorm: location ξ, scale ω,
shape α) with 1σ errors from a bootstrap (--errors bootstrap, B resamples refitted) or from the inverse
of the observed Fisher information (--errors fisher; unreliable near α = 0, where the skew-normal
likelihood is flat in α). Writes the histograms with the fitted densities to a PNG.
"""
import argparse
import itertools
import json
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from vafm_client import DaemonError, Stream  # noqa: E402
from vafm_client.spawn import add_endpoint_args, connect, plt_agg, save_png  # noqa: E402


def floats(text):
    return [float(v) for v in text.split(",") if v.strip()]


SHAPE_MAX = 20.0  # |α| bound of the fit: a sample more skewed than a skew-normal allows (|g1| ≥ 0.995) has
                  # its likelihood maximum at α → ±∞; the fit then stops at the bound and says so


def _mle(x, x0=None):
    """Bounded maximum-likelihood skew-normal fit: (loc, scale, shape)."""
    from scipy import stats
    from scipy.optimize import minimize
    if x0 is None:  # method of moments, the skewness clipped into the skew-normal's range
        g1 = float(np.clip(stats.skew(x), -0.99, 0.99))
        r = np.sign(g1) * (2 * abs(g1) / (4 - math.pi)) ** (1 / 3)
        delta = r / math.sqrt(2 / math.pi * (1 + r * r)) if r else 0.0
        delta = float(np.clip(delta, -0.999, 0.999))
        scale = x.std() / math.sqrt(1 - 2 * delta * delta / math.pi)
        x0 = (x.mean() - scale * delta * math.sqrt(2 / math.pi), scale, delta / math.sqrt(1 - delta * delta))

    def nll(t):
        v = -np.sum(stats.skewnorm.logpdf(x, t[2], loc=t[0], scale=math.exp(t[1])))
        return v if np.isfinite(v) else 1e300  # a sample point outside the support of a very skewed fit

    t0 = np.array([x0[0], math.log(x0[1]), float(np.clip(x0[2], -SHAPE_MAX, SHAPE_MAX))])
    res = minimize(nll, t0, method="Nelder-Mead", bounds=[(None, None), (None, None), (-SHAPE_MAX, SHAPE_MAX)],
                   options={"xatol": 1e-7, "fatol": 1e-9, "maxiter": 4000})
    return res.x[0], math.exp(res.x[1]), res.x[2], nll


def skewnorm_fit(x, errors="bootstrap", b=200, seed=1):
    """ML fit of a skew-normal: dict loc, scale, shape, their 1σ errors (NaN if not available) and
    at_bound (the shape reached ±SHAPE_MAX)."""
    loc, scale, a, nll = _mle(x)
    out = {"loc": float(loc), "scale": float(scale), "shape": float(a), "at_bound": bool(abs(a) > 0.99 * SHAPE_MAX)}
    if errors == "bootstrap":
        rng = np.random.default_rng(seed)
        reps = np.array([_mle(rng.choice(x, size=len(x), replace=True), (loc, scale, a))[:3] for _ in range(b)])
        for k, col in zip(("loc", "scale", "shape"), reps.T):
            out[k + "_err"] = float(np.std(col, ddof=1)) if b > 1 else math.nan
    else:  # observed Fisher information: numerical Hessian of the negative log-likelihood at the optimum
        theta = np.array([loc, math.log(scale), a])
        h = np.array([1e-3 * scale, 1e-3, 1e-3 * max(1.0, abs(a))])
        hess = np.empty((3, 3))
        for i in range(3):
            for j in range(3):
                ei, ej = np.eye(3)[i] * h[i], np.eye(3)[j] * h[j]
                hess[i, j] = (nll(theta + ei + ej) - nll(theta + ei - ej) - nll(theta - ei + ej)
                              + nll(theta - ei - ej)) / (4 * h[i] * h[j])
        try:
            cov = np.linalg.inv(hess)
            d = np.sqrt(np.where(np.diag(cov) > 0, np.diag(cov), np.nan))
            out.update(loc_err=float(d[0]), scale_err=float(d[1] * scale), shape_err=float(d[2]))  # d(log ω) · ω = dω
        except np.linalg.LinAlgError:
            out.update(loc_err=math.nan, scale_err=math.nan, shape_err=math.nan)
    return out


def run_campaign(c, s, a, lists):
    """The daemon's campaign command; None if the daemon does not implement it."""
    req = {"cmd": "campaign", "n": a.n, "first_index": a.first_index, "client_run_id": f"hist-{os.getpid()}"}
    req.update({k: v for k, v in lists.items() if v})
    try:
        r = c.request(req)
    except DaemonError as e:
        if e.code in ("not_implemented", "unknown_command"):
            return None
        raise
    print(f"campaign {r['campaign_id']}: {r['curves']} curves", flush=True)
    runs, end = s.campaign(r["campaign_id"], timeout=a.timeout)
    if end.get("status") != "ok" or len(runs) != r["curves"]:
        raise SystemExit(f"campaign ended with status {end.get('status')}, {len(runs)} of {r['curves']} curves: {end}")
    return runs


def run_curves(c, s, a, lists):
    """The same curves as a sequence of `curve` commands: point p, curve j has index first + p·n + j."""
    print("the daemon has no campaign command: running the curves one `curve` command at a time", flush=True)
    names = [k for k in ("T_K", "v_m_per_s", "k_N_per_m")]
    keys = {"T_K": ["T_K"], "v_m_per_s": ["v_approach_m_per_s", "v_retract_m_per_s"], "k_N_per_m": ["k_N_per_m"]}
    saved = c.get(*[p for n in names for p in keys[n]])
    runs = []
    try:
        grid = [lists[n] or [None] for n in names]
        for p, point in enumerate(itertools.product(*grid)):
            vals = {par: v for n, v in zip(names, point) if v is not None for par in keys[n]}
            if vals:
                c.set(vals)
            for j in range(a.n):
                c.wait_idle()
                r = c.curve(index=a.first_index + p * a.n + j)
                runs.append(s.run(r["run_id"], timeout=a.timeout))
    finally:
        c.wait_idle()
        c.set(saved)
    return runs


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    add_endpoint_args(ap)
    ap.add_argument("-n", type=int, default=100, help="curves per grid point (default %(default)s)")
    ap.add_argument("--T", default="", help="temperatures, K (comma-separated; default the scene's)")
    ap.add_argument("--v", default="", help="piezo speeds, m/s (approach = retract)")
    ap.add_argument("--k", default="", help="spring constants, N/m")
    ap.add_argument("--first-index", type=int, default=0, help="random stream of the first curve")
    ap.add_argument("--preset", help="apply this scene preset first")
    ap.add_argument("--observable", default="pulloff_spring_N",
                    choices=("pulloff_spring_N", "pulloff_sampled_N", "detach_force_N"),
                    help="pull-off definition (default: the paper's, %(default)s)")
    ap.add_argument("--errors", choices=("bootstrap", "fisher"), default="bootstrap")
    ap.add_argument("--bootstrap", type=int, default=200, metavar="B", help="bootstrap resamples (default 200)")
    ap.add_argument("--no-campaign", action="store_true", help="use `curve` commands even if `campaign` exists")
    ap.add_argument("--png", default="pulloff_hist.png", help="figure (default %(default)s)")
    ap.add_argument("--json", help="also write the fit results here")
    ap.add_argument("--timeout", type=float, default=3600, help="give up after this many seconds")
    a = ap.parse_args(argv)
    if a.n < 3:
        ap.error("-n must be at least 3 (three parameters are fitted)")
    lists = {"T_K": floats(a.T), "v_m_per_s": floats(a.v), "k_N_per_m": floats(a.k)}

    with connect(a) as (c, rep, pub):
        if a.preset:
            c.set(preset=a.preset)
        c.wait_idle()
        with Stream(pub) as s:
            runs = None if a.no_campaign else run_campaign(c, s, a, lists)
            if runs is None:
                runs = run_curves(c, s, a, lists)
        c.wait_idle()
    points = {}
    for run in runs:
        sc = run.start["scene"]
        key = (sc["T_K"], sc["v_retract_m_per_s"], sc["k_N_per_m"])
        f_jkr = 1.5 * math.pi * sc["gamma_J_per_m2"] * sc["R_m"]
        v = run.end["result"][a.observable]
        points.setdefault(key, {"f_jkr": f_jkr, "x": [], "skipped": 0})
        if v is None or not math.isfinite(v):
            points[key]["skipped"] += 1
        else:
            points[key]["x"].append(v / f_jkr)
    results = []
    plt = plt_agg()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    from scipy import stats
    for (T, v, k), pt in sorted(points.items()):
        x = np.array(pt["x"])
        if len(x) < 3:
            print(f"T = {T:.6g} K, v = {v:.4g} m/s, k = {k:.4g} N/m: {len(x)} pull-offs, too few to fit")
            continue
        fit = skewnorm_fit(x, a.errors, a.bootstrap)
        mean, sd = x.mean(), x.std(ddof=1)
        fit.update(T_K=T, v_m_per_s=v, k_N_per_m=k, n=len(x), skipped=pt["skipped"], mean=float(mean), sd=float(sd),
                   skew=float(stats.skew(x)), F_JKR_N=pt["f_jkr"])
        results.append(fit)
        print(f"T = {T:.6g} K, v = {v:.4g} m/s, k = {k:.4g} N/m: N = {len(x)} ({pt['skipped']} without pull-off), "
              f"{a.observable}/F_JKR mean {mean:.5f} ± {sd / math.sqrt(len(x)):.5f}, sd {sd:.5f}, "
              f"skew {fit['skew']:+.3f}")
        print(f"  skew-normal ({a.errors}{' B = %d' % a.bootstrap if a.errors == 'bootstrap' else ''}): "
              f"location {fit['loc']:.5f} ± {fit['loc_err']:.5f}, scale {fit['scale']:.5f} ± {fit['scale_err']:.5f}, "
              f"shape {fit['shape']:+.3f} ± {fit['shape_err']:.3f}  (F_JKR = {pt['f_jkr'] * 1e9:.6g} nN)")
        if fit["at_bound"]:
            print(f"  note: the shape stopped at its bound ±{SHAPE_MAX:g}: the likelihood keeps growing toward |α| → ∞ "
                  "(usual for small samples, and for samples about as skewed as a skew-normal can be, |skewness| "
                  "< 0.995); the shape and its error are not meaningful then")
        bins = max(6, int(round(2 * len(x) ** (1 / 3))))
        h = ax.hist(x, bins=bins, density=True, alpha=0.45, label=f"T = {T:.4g} K, v = {v:.3g} m/s (N = {len(x)})")
        grid = np.linspace(x.min() - 2 * sd, x.max() + 2 * sd, 400)
        ax.plot(grid, stats.skewnorm.pdf(grid, fit["shape"], fit["loc"], fit["scale"]), color=h[2][0].get_facecolor(),
                alpha=1, lw=1.5, label=f"skew-normal ξ={fit['loc']:.4f}, ω={fit['scale']:.4f}, α={fit['shape']:.2f}")
    ax.set_xlabel(f"{a.observable.replace('_N', '')} / F_JKR")
    ax.set_ylabel("probability density")
    ax.set_title("pull-off force distribution (cf. the paper's Fig. 3)")
    ax.legend(fontsize=7)
    save_png(fig, os.path.abspath(a.png))
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(results, fh, indent=1)
    return 0 if results else 1


if __name__ == "__main__":
    sys.exit(main())
