#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""The default step chosen by evidence (issue #13): the analysis of bench_work_precision's group "presets".

    /usr/bin/python3 bench/default_step_fit.py default_step.csv [default_step_athermal.csv] > fit.md

The criterion: the default is the cheapest omega_dt whose bias on both pull-off observables (F2 =
pulloff_spring_N, F3 = detach_force_N) stays below a quarter of a 2000-curve campaign's standard error
(se2000 = sd / sqrt(2000)) in every case. A row of N = 2000 curves measures its bias against the reference
with a standard error sqrt(2) se2000 (more where N < 2000), so 0.25 se2000 cannot be seen row by row. The
method instead uses every row of a case at once: the case's means m_i at the steps x_i actually used
(omega_max dt) are fitted by

    m(x) = m0 + c x^p          (weighted least squares, weights 1/se_i^2; m0 = the converged value)

with p = 2, the order of gjf's (and brownian's) systematic error in the statistics of a smooth scene (where
the fit with p free excludes 2 at 2 sigma, the highest order it allows: a lower order extrapolates a larger
bias to the small steps); the
rows at large steps (1.0, 1.5), where a bias can be resolved, fix c, and the fit predicts the bias at every
candidate step with its standard error, c x^2 +- se(c) x^2. The upper bound is |c| x^2 + 2 se(c) x^2. The
order is checked twice: by a fit with p free (the profile chi^2 over p; its 2-sigma range), and by the
athermal rows (T = 0: one curve gives the step's bias exactly; its order from the two largest steps).
A candidate passes when, in every case and on both observables, the p = 2 upper bound is below 0.25 se2000,
its own measured row is not beyond 3 combined standard errors (about 26 cells per candidate: 2 se_c would
trip by chance), and the athermal bias is below
0.25 se2000 of the thermal case. numpy only.
"""
import csv
import math
import sys

import numpy as np

N_CAMPAIGN = 2000
LIMIT = 0.25
Z_MEASURED = 3.0  # a row's own bias is flagged beyond 3 se_c: ~26 cells per candidate, 2 would trip by chance
CANDIDATES = [2 * math.pi / 40, 0.3, 0.6, 1.0, 1.5]
OBS = [("obs2", "F2 pulloff_spring_N"), ("obs3", "F3 detach_force_N")]


def load(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        for k, v in r.items():
            try:
                r[k] = float(v)
            except (TypeError, ValueError):
                pass
    cases = {}
    for r in rows:
        cases.setdefault(r["case"], []).append(r)
    for name, rs in cases.items():  # a row at the reference's own step is the same curves (older runs had one)
        ref = [r for r in rs if r["is_ref"] == 1][0]
        cases[name] = [r for r in rs if r["is_ref"] == 1 or r["omega_dt"] != ref["omega_dt"]]
    return cases


def wls(x, m, se, p):
    """m = m0 + c x^p by weighted least squares: (m0, c, cov, chi2)."""
    A = np.column_stack([np.ones_like(x), x**p])
    w = 1.0 / se**2
    cov = np.linalg.inv(A.T @ (A * w[:, None]))
    beta = cov @ (A.T @ (w * m))
    chi2 = float(np.sum(w * (m - A @ beta) ** 2))
    return beta[0], beta[1], cov, chi2


def profile_p(x, m, se):
    """The order p from the data: the chi^2 minimum over p in [0.5, 8] and the range with chi^2 <= min + 4."""
    ps = np.arange(0.5, 8.0001, 0.05)
    chi = np.array([wls(x, m, se, p)[3] for p in ps])
    i = int(np.argmin(chi))
    ok = ps[chi <= chi[i] + 4.0]
    return ps[i], ok.min(), ok.max()


def nearest(rows, x0):
    return min(rows, key=lambda r: abs(r["omega_dt"] - x0))


def analyse(cases, athermal):
    verdict = {x: [] for x in CANDIDATES}  # per candidate: (case, obs, upper bound, reasons)
    out = []
    largest = []  # per case and observable: the step at which the upper bound reaches LIMIT se2000
    summary = {}  # case -> dict: n, cost, measured[x] = (F2, F3), upper[x] = worst, xmax, p, ath[x]
    out.append("## The default step: the fit (bench/default_step_fit.py)\n")
    out.append(
        "Per case and observable: se2000 = the scene's sd / sqrt(2000) (median over the case's rows); the fit "
        "m(x) = m0 + c x^p over all rows (x = omega_max dt actually used; p = 2, or the highest order the data allow "
        "where they exclude 2), chi2/dof; the order p fitted freely "
        "(best, and the 2-sigma range; 'flat' where no bias is resolved); then per candidate omega_dt the "
        "measured bias (/se2000, +- its own standard error), the predicted bias c x^2 +- se, and the upper "
        "bound (|c| + 2 se(c)) x^p, all in units of se2000; 'athermal' is the exact T = 0 bias in the same "
        "units. A cell is marked ** where the upper bound is >= 0.25, the measured row is beyond 3 combined "
        "standard errors, or the athermal bias is >= 0.25. 'largest step' = the omega_dt at which the upper "
        "bound reaches 0.25 se2000: (0.25 / (|c| + 2 se(c)))^(1/p).\n"
    )
    for name, rows in cases.items():
        rows = sorted(rows, key=lambda r: r["omega_dt"])
        ref = [r for r in rows if r["is_ref"] == 1][0]
        ath = athermal.get(name)
        out.append(f"\n**{name}** (N = {int(ref['n'])} per row, reference omega_dt = {ref['omega_dt']:.4g})\n")
        sm = summary.setdefault(name, {"n": int(ref["n"]), "ref": ref["omega_dt"], "meas": {}, "upper": {},
                                       "xmax": float("inf"), "p": [], "ath": {},
                                       "steps": {xc: nearest(rows, xc)["steps_per_curve"] for xc in CANDIDATES},
                                       "cpu": {xc: nearest(rows, xc)["cpu_s"] for xc in CANDIDATES}})
        out.append(
            "| observable | se2000 (F) | chi2/dof (p used) | p free [2-sigma] | largest step | omega_dt | measured | "
            "predicted | upper | athermal |\n|---|---|---|---|---|---|---|---|---|---|"
        )
        for key, label in OBS:
            good = [r for r in rows if math.isfinite(r[key + "_mean"]) and r[key + "_se"] > 0]
            x = np.array([r["omega_max_dt"] for r in good])
            m = np.array([r[key + "_mean"] for r in good])
            se = np.array([r[key + "_se"] for r in good])
            se2000 = float(np.median([r[key + "_sd"] for r in good])) / math.sqrt(N_CAMPAIGN)
            if len(set(np.round(x, 9))) < 3:
                out.append(f"| {label} | {se2000:.2g} | too few distinct steps | | | | | | | |")
                for xc in CANDIDATES:
                    verdict[xc].append((name, label, float("nan"), "too few distinct steps"))
                continue
            pbest, plo, phi = profile_p(x, m, se)
            # the integrator's order 2, unless the data exclude it: then the highest order they allow (a lower
            # order extrapolates a larger bias to the small steps)
            p_used = 2.0 if phi >= 2.0 else phi
            m0, c, cov, chi2 = wls(x, m, se, p_used)
            sc = math.sqrt(cov[1, 1])
            dof = len(x) - 2
            flat = abs(c) < 2 * sc
            ptxt = ("flat" if flat else f"{pbest:.1f} [{plo:.1f}, {phi:.1f}]") + (
                f", used {p_used:.2f}" if p_used != 2.0 else "")
            xmax = (LIMIT * se2000 / (abs(c) + 2 * sc)) ** (1.0 / p_used)
            largest.append((xmax, name, label))
            sm["xmax"] = min(sm["xmax"], xmax)
            sm["p"].append(ptxt)
            first = True
            for xc in CANDIDATES:
                r = nearest(rows, xc)
                xa = r["omega_max_dt"]
                pred, psd = c * xa**p_used, sc * xa**p_used
                upper = abs(pred) + 2 * psd
                meas = r[key + "_bias"] / se2000 if not r["is_ref"] else float("nan")
                meas_se = r[key + "_se_combined"] / se2000 if not r["is_ref"] else float("nan")
                reasons = []
                if upper / se2000 >= LIMIT:
                    reasons.append("upper bound")
                if math.isfinite(meas) and abs(r[key + "_bias_over_se"]) > Z_MEASURED:
                    reasons.append(f"measured beyond {Z_MEASURED:g} se_c")
                atxt = ""
                if ath:
                    ar = nearest(ath, xc)
                    aref = [a for a in ath if a["is_ref"] == 1][0]
                    ab = (ar[key + "_mean"] - aref[key + "_mean"]) / se2000
                    atxt = f"{ab:+.3f}"
                    if abs(ab) >= LIMIT:
                        reasons.append("athermal")
                        atxt += " **"
                verdict[xc].append((name, label, upper / se2000, ", ".join(reasons)))
                sm["meas"].setdefault(xc, []).append(meas)
                sm["upper"][xc] = max(sm["upper"].get(xc, 0.0), upper / se2000)
                if atxt:
                    sm["ath"][xc] = max(sm["ath"].get(xc, 0.0), abs(ab))
                mtxt = "ref" if r["is_ref"] else f"{meas:+.2f} ± {meas_se:.2f}"
                mark = " **" if reasons and reasons != ["athermal"] else ""
                head = (
                    f"| {label} | {se2000:.3g} | {chi2 / dof:.2f} | {ptxt} | {xmax:.3f} |" if first else "| | | | | |"
                )
                out.append(
                    f"{head} {xc:.3g} (used {xa:.3g}) | {mtxt} | {pred / se2000:+.3f} ± {psd / se2000:.3f} | "
                    f"{upper / se2000:.3f}{mark} | {atxt} |"
                )
                first = False
    out.append("\n### Summary per case\n")
    out.append(
        "Measured bias / se2000 (F2; F3; each ± about 1.4 at N = 2000, more at smaller N); the upper bound "
        "(worst of F2, F3); the athermal exact bias (worst of F2, F3); the largest step whose upper bound stays "
        "below 0.25 se2000; steps per curve at the paper's step and at 0.6.\n"
    )
    hx = [x for x in CANDIDATES]
    out.append(
        "| case | N | "
        + " | ".join(f"measured {x:.3g}" for x in hx)
        + " | upper 0.157 / 0.3 / 0.6 | athermal 0.157 / 0.3 / 0.6 | p free (F2; F3) | largest step | "
        "steps/curve 0.157 → 0.6 |\n|" + "---|" * (len(hx) + 7)
    )
    for name, sm in summary.items():
        cells = []
        for x in hx:
            v = sm["meas"].get(x, [])
            cells.append("; ".join("ref" if not math.isfinite(b) else f"{b:+.1f}" for b in v) if v else "–")
        up = " / ".join(f"{sm['upper'].get(x, float('nan')):.2f}" for x in hx[:3])
        at = " / ".join(f"{sm['ath'][x]:.2f}" for x in hx[:3]) if sm["ath"] else "–"
        out.append(
            f"| {name} | {sm['n']} | " + " | ".join(cells) + f" | {up} | {at} | {'; '.join(sm['p'])} | "
            f"{sm['xmax']:.3f} | {sm['steps'][hx[0]]:.3g} → {sm['steps'][hx[2]]:.3g} |"
        )
    out.append("\n### Verdict per candidate (worst case over every case and both observables)\n")
    out.append("| omega_dt | worst upper bound / se2000 | where | failing cells |\n|---|---|---|---|")
    passing = []
    for xc in CANDIDATES:
        cells = verdict[xc]
        finite = [c for c in cells if math.isfinite(c[2])]
        worst = max(finite, key=lambda c: c[2]) if finite else None
        fails = [f"{c[0]} {c[1].split()[0]} ({c[3]})" for c in cells if c[3] and c[3] != "too few distinct steps"]
        if not fails:
            passing.append(xc)
        out.append(
            f"| {xc:.3g} | {worst[2]:.3f} | {worst[0]} {worst[1].split()[0]} | "
            f"{'; '.join(fails) if fails else 'none'} |"
            if worst
            else f"| {xc:.3g} | – | – | – |"
        )
    largest.sort()
    out.append(
        "\nLargest step per case and observable (upper bound = 0.25 se2000), the five smallest: "
        + "; ".join(f"{n} {l.split()[0]} {x:.3f}" for x, n, l in largest[:5])
        + "."
    )
    best = max(passing) if passing else None
    out.append(
        "\nCheapest passing omega_dt (largest step with every case below "
        f"{LIMIT} se2000): {best:.3g}" if best else "\nNo candidate passes in every case."
    )
    return "\n".join(out) + "\n"


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    cases = load(sys.argv[1])
    athermal = load(sys.argv[2]) if len(sys.argv) > 2 else {}
    sys.stdout.write(analyse(cases, athermal))


if __name__ == "__main__":
    main()
