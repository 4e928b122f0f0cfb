# SPDX-License-Identifier: MIT
"""Figures of `vafm study` (issue #7): reads the CSV tables the study wrote into OUTDIR and writes PNGs.

Usage: study_plot.py STUDY OUTDIR. Prints one markdown list line per figure written (the study appends
them to its report). Exit 3 when matplotlib is missing (the study then notes that the PNG step was
skipped), 1 on any other failure. Only the standard library, numpy-free: the CSVs are small.
"""
import csv
import math
import os
import sys


def read(outdir, name):
    with open(os.path.join(outdir, name), newline="") as f:
        return list(csv.DictReader(f))


def save(fig, outdir, name, what):
    """Write the figure to OUTDIR/name and list it in the report: "- `name`: what"."""
    fig.tight_layout()
    fig.savefig(os.path.join(outdir, name), dpi=110)
    print("- `%s`: %s" % (name, what))


DYNAMICS = ("langevin", "brownian")


def values(rows, key):
    """The values of column `key`, as numbers, sorted."""
    return sorted({float(r[key]) for r in rows})


def points(rows, dyn, key, value):
    """The rows of dynamics `dyn` at `key` = value."""
    return [r for r in rows if r["dynamics"] == dyn and float(r[key]) == value]


def skewnorm_pdf(x, xi, om, al):
    z = (x - xi) / om
    return 2.0 / om * math.exp(-0.5 * z * z) / math.sqrt(2 * math.pi) * 0.5 * math.erfc(-al * z / math.sqrt(2))


def logspace(a, b, n):
    return [10 ** (a + (b - a) * i / (n - 1)) for i in range(n)]


def distribution(plt, outdir):
    rows = read(outdir, "distribution_curves.csv")
    fits = [r for r in read(outdir, "distribution_fits.csv") if r["observable"] == "pulloff_spring_N"]
    temps = sorted({float(r["T_K"]) for r in rows})
    fjkr = float(rows[0]["F_JKR_nN"])
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    for T in temps:
        x = [float(r["pulloff_spring_nN"]) for r in rows if float(r["T_K"]) == T]
        fit = next((f for f in fits if float(f["T_K"]) == T), None)
        red = [v / fjkr for v in x]
        h = ax[1].hist(red, bins=max(8, int(math.sqrt(len(x)))), density=True, histtype="step",
                       label="T = %.0f K (n = %d)" % (T, len(x)))
        if fit and fit["converged"] == "1":
            xi, om, al = (float(fit[k]) / (fjkr if k != "alpha" else 1) for k in ("xi_nN", "omega_nN", "alpha"))
            lo, hi = min(red), max(red)
            xs = [lo + (hi - lo) * (i / 199.0) * 1.2 - 0.1 * (hi - lo) for i in range(200)]
            ax[1].plot(xs, [skewnorm_pdf(v, xi, om, al) for v in xs], "--", color=h[2][0].get_edgecolor())
        if T == temps[len(temps) // 2] or len(temps) == 1 or abs(T - temps[0]) < 1e-9 and len(temps) == 2:
            ax[0].hist(x, bins=max(8, int(math.sqrt(len(x)))), density=True, color="tab:red", alpha=0.6,
                       label="vafm, T = %.0f K" % T)
            if fit and fit["converged"] == "1":
                xi, om, al = float(fit["xi_nN"]), float(fit["omega_nN"]), float(fit["alpha"])
                lo, hi = min(x), max(x)
                xs = [lo + (hi - lo) * i / 199.0 for i in range(200)]
                ax[0].plot(xs, [skewnorm_pdf(v, xi, om, al) for v in xs], "k--", label="skew-normal ML fit")
    ax[0].set_xlabel("pull-off force (pulloff_spring_N), nN")
    ax[0].set_ylabel("probability density, 1/nN")
    ax[0].set_title("Fig. 2 scene (paper-fig1)")
    ax[0].legend(fontsize=8)
    ax[1].set_xlabel("pull-off force / F_JKR")
    ax[1].set_ylabel("probability density")
    ax[1].set_title("temperature dependence (Fig. 3); dashed: skew-normal fits")
    ax[1].legend(fontsize=8)
    save(fig, outdir, "distribution.png",
         "histograms of `pulloff_spring_N` (nN; and / F_JKR per temperature) with the "
         "skew-normal maximum-likelihood fits")


def velocity_athermal(plt, outdir):
    rows = read(outdir, "athermal.csv")
    fits = read(outdir, "athermal_fits.csv")
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    for i, dyn in enumerate(DYNAMICS):
        for k in values(rows, "k"):
            pts = points(rows, dyn, "k", k)
            v = [float(r["v"]) for r in pts]
            f = [float(r["F0_spring_over_FJKR"]) for r in pts]
            line = ax[i].semilogx(v, f, "o", mfc="none", label="k = %g" % k)[0]
            fit = next(iter(points(fits, dyn, "k", k)), None)
            if fit and fit["converged"] == "1":
                vs = logspace(math.log10(min(v)), math.log10(max(v)), 200)
                a0 = float(fit["alpha0"])
                if fit["onset_only"] == "1":  # exp(c v^a0): v0 and beta0 not separately determined
                    c = float(fit["c"])
                    ys = [math.exp(c * x ** a0) for x in vs]
                else:
                    v0, b0 = float(fit["v0"]), float(fit["beta0"])
                    ys = [(1 + (x / v0) ** a0) ** b0 for x in vs]
                ax[i].semilogx(vs, ys, "--", color=line.get_color())
        ax[i].set_xlabel("reduced speed v")
        ax[i].set_title("%s dynamics, T = 0 (dashed: Eq. 14 fits)" % dyn.capitalize())
        ax[i].legend(fontsize=8)
    ax[0].set_ylabel("F0 / F_JKR (pulloff_spring_N)")
    save(fig, outdir, "velocity_athermal.png",
         "F̃₀/F_JKR (`pulloff_spring_N`, T = 0) against ṽ for each k̃, both dynamics, "
         "with the Eq. 14 fits")


def velocity_thermal(plt, outdir):
    rows = read(outdir, "thermal.csv")
    fits = read(outdir, "thermal_fits.csv")
    fig, ax = plt.subplots(2, 2, figsize=(11, 8), sharex=True)
    for i, dyn in enumerate(DYNAMICS):
        for j, ob in enumerate(("spring", "detach")):
            a = ax[j][i]
            for kT in values(rows, "kT"):
                pts = points(rows, dyn, "kT", kT)
                v = [float(r["v"]) for r in pts]
                ft = [float(r["Ft_" + ob]) for r in pts]
                se = [float(r["se_Fp_" + ob]) for r in pts]
                line = a.errorbar(v, ft, yerr=se, fmt="o", mfc="none", label="kT = %g" % kT)[0]
                fit = next((x for x in points(fits, dyn, "kT", kT) if x["observable"] == ob), None)
                if fit and fit["converged"] == "1":
                    vs = logspace(math.log10(min(v)), math.log10(max(v)), 200)
                    if fit["log_only"] == "1":  # Eq. 15 not determined: a + b ln v
                        la, lb = float(fit["log_a"]), float(fit["log_b"])
                        ys = [la + lb * math.log(x) for x in vs]
                    else:
                        p = [float(fit[n]) for n in ("xi", "alpha_t", "v_t", "beta_t")]
                        ys = [p[0] * (1 + p[1] * math.exp(-(x / p[2]) ** p[3])) for x in vs]
                    a.plot(vs, ys, "--", color=line.get_color())
                if ob == "detach":
                    th = [float(r["F0_detach"]) - float(r["mfpt_F_detach"]) for r in pts]
                    a.plot(v, th, ":", color=line.get_color(), label="MFPT theory, kT = %g" % kT)
            a.set_xscale("log")
            a.set_title("%s, k = 0.1: F_t from %s" % (dyn.capitalize(),
                        "pulloff_spring_N (paper)" if ob == "spring" else "detach_force_N (ground truth)"))
            a.set_ylabel("F_t / F_JKR")
            a.legend(fontsize=7)
    for a in ax[1]:
        a.set_xlabel("reduced speed v")
    save(fig, outdir, "velocity_thermal.png",
         "F̃_t = F̃₀ − F̃_p against ṽ (top: `pulloff_spring_N`, the paper's observable; "
         "bottom: `detach_force_N` with the MFPT theory, dotted), both dynamics, Eq. 15 fits dashed")


def hysteresis(plt, outdir):
    rows = read(outdir, "hysteresis.csv")
    th = read(outdir, "hysteresis_theory.csv")
    meta = read(outdir, "hysteresis_meta.csv")[0]
    u0_m, fjkr_nN = float(meta["u0_m"]), float(meta["F_JKR_N"]) * 1e9
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for seg, name, col in ((0, "approach", "tab:blue"), (1, "retract", "tab:red"), (2, "dwell", "tab:gray")):
        pts = [r for r in rows if int(r["segment"]) == seg]
        if pts:
            ax.plot([float(r["height_m"]) / u0_m for r in pts],
                    [float(r["force_N"]) * 1e9 / fjkr_nN for r in pts], lw=0.8, color=col, label=name)
    ax.plot([float(r["u_spr_over_u0"]) for r in th], [-float(r["F_over_FJKR"]) for r in th], "k--", lw=1,
            label="quasi-static equilibrium")
    ax.set_xlabel("piezo height / u0")
    ax.set_ylabel("force / F_JKR (positive repulsive)")
    ax.set_title("one loading-unloading curve (paper Fig. 1 scene)")
    ax.legend(fontsize=8)
    save(fig, outdir, "hysteresis.png",
         "output force samples (`force`, the user's observable) / F_JKR against the piezo "
         "height / ũ₀, with the quasi-static equilibrium branch")


def main():
    if len(sys.argv) != 3:
        print("usage: study_plot.py STUDY OUTDIR", file=sys.stderr)
        return 2
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return 3
    fn = {"distribution": distribution, "velocity-athermal": velocity_athermal,
          "velocity-thermal": velocity_thermal, "hysteresis": hysteresis}.get(sys.argv[1])
    if not fn:
        print("unknown study " + sys.argv[1], file=sys.stderr)
        return 2
    fn(plt, sys.argv[2])
    return 0


if __name__ == "__main__":
    sys.exit(main())
