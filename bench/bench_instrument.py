# SPDX-License-Identifier: MIT
"""The always-on controller in vafmd (issue #26 §7): measured, not assumed. Reports, never fails on speed.

usage: bench_instrument.py VAFMD OUTDIR    (writes OUTDIR/bench_instrument.csv and .md)

- CPU of the whole daemon (utime + stime from /proc/PID/stat over 5 s, speed 1, default scene), idle with the
  monitor off, idle with it on (100 Hz, one `live` subscriber), engaged with it on;
- late blocks of a paced campaign (speed 1, 2 curves) with the monitor on vs off (run.end late_blocks);
- engage -> feedback: the force spread at full rate (decimation 1, point samples, 20000 points) against the
  free lever's thermal bound sqrt(k kT) and the detector floor k InvOLS noise_V_rms (contact stiffens the
  lever, so the in-contact thermal spread lies below the bound);
- moves under feedback across a dome (ctrl_sample) at 2, 5 and 20 um/s: the following error (the support's
  height above the known surface, and the force error) against the integral loop's lag slope v tau;
- a crash, a Z-range saturation and an engage timeout, each produced and its event and status reported.
"""
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "clients", "python"))
from vafm_client import Client, Stream  # noqa: E402

KB = 1.380649e-23
TICK = os.sysconf("SC_CLK_TCK")


def cpu_s(pid):
    with open(f"/proc/{pid}/stat") as f:
        st = f.read().rsplit(")", 1)[1].split()
    return (int(st[11]) + int(st[12])) / TICK  # utime, stime (fields 14, 15)


def start(exe):
    import subprocess
    import tempfile
    d = tempfile.mkdtemp(prefix="vafm-benchi-")
    rep, pub = f"ipc://{d}/rep", f"ipc://{d}/pub"
    p = subprocess.Popen([exe, "--rep", rep, "--pub", pub], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for _ in range(100):
        if os.path.exists(f"{d}/rep") and os.path.exists(f"{d}/pub"):
            break
        time.sleep(0.05)
    c = Client(rep, timeout=20)
    c.hello()
    return p, c, pub


def stop(p, c):
    c.shutdown()
    c.close()
    p.wait(10)


def event(s, kinds, timeout=120):
    deadline = time.monotonic() + timeout
    for t, m in s.messages(deadline=deadline):
        if t == "event" and m.get("source") == "ctrl" and m["kind"] in kinds:
            return m
    raise RuntimeError(f"no {kinds}")


def drain(s, secs):
    """Read the stream for secs (a live subscriber that keeps up); returns the live messages."""
    out, end = [], time.monotonic() + secs
    try:
        for t, m in s.messages(deadline=end):
            if t == "live":
                out.append(m)
    except Exception:  # noqa: BLE001 (the deadline)
        pass
    return out


def engage(c, s):
    sp = c.get("speed")["speed"]
    c.set({"speed": 1000})
    c.engage()
    ev = event(s, ("engaged", "engage_failed", "crash"))
    c.set({"speed": sp})
    return ev


def dome(exe, passes=3):
    """Moves under feedback across a dome (ctrl_sample), as tests/test_ctrl.c's test_move_dome does in the
    core: the dome at x = 10 um (5 um base radius, 0.5 um high: a spherical cap of radius (a^2 + h^2) / 2h =
    25.25 um, slope a / sqrt(R_s^2 - a^2) = 0.2020 at its foot), the tip engaged at x = 0, then `passes`
    crossings from x = 3 to 17 um and back at each speed, every controller sample on `live` (monitor_rate_Hz
    = fs: decimation 1). The following error is the change of the support's height above the known surface
    (H - surface_m, H = motor_z_m - piezo_z_m) since the crossing began; an integral loop of time constant
    tau lags a surface rising at slope v by slope v tau. Also the feedback's force error (error_N), which is
    k times that lag when the contact is much stiffer than the lever. Medians over the passes."""
    p, c, pub = start(exe)
    s = Stream(pub, live=True)
    try:
        a, h, xc = 5e-6, 0.5e-6, 10e-6
        c.set({"ctrl_sample": f"pattern=dome,center_x_m={xc!r},radius_m={a!r},height_m={h!r}"})
        engage(c, s)
        v = c.get("k_N_per_m", "sample_rate_Hz", "ctrl_fb_tau_s", "ctrl_fb_i_m_per_N_s")
        k, fs = v["k_N_per_m"], v["sample_rate_Hz"]
        # the loop's time constant: the setting's, else from the integral gain (I = 1 / (k tau)), else the
        # default of 10 samples (docs/instrument.md)
        tau = v["ctrl_fb_tau_s"] or (1 / (k * v["ctrl_fb_i_m_per_N_s"]) if v["ctrl_fb_i_m_per_N_s"] else 10 / fs)
        Rs = (a * a + h * h) / (2 * h)
        slope = a / np.sqrt(Rs * Rs - a * a)
        c.set({"monitor_rate_Hz": fs, "speed": 1})

        def move(x, v_xy):
            c.move(x, 0, speed_m_per_s=v_xy)
            ch = {n: [] for n in ("motor_z_m", "piezo_z_m", "surface_m", "error_N", "state")}
            for t, m in s.messages(deadline=time.monotonic() + 120):
                if t == "live":
                    for n in ch:
                        ch[n].extend(m[1][n])
                if t == "event" and m.get("source") == "ctrl" and m["kind"] == "moved":
                    break
            return {n: np.array(x) for n, x in ch.items()}

        move(3e-6, 20e-6)
        drain(s, 0.3)
        rows, x = [], 3e-6
        for v_xy in (2e-6, 5e-6, 20e-6):
            err_h, err_f, top, npts, engaged = [], [], [], 0, True
            for i in range(passes):
                x = 20e-6 - x  # across the dome: 3 -> 17 um, 17 -> 3 um
                ch = move(x, v_xy)
                g = ch["motor_z_m"] - ch["piezo_z_m"] - ch["surface_m"]
                err_h.append(np.abs(g - g[0]).max())
                err_f.append(np.abs(ch["error_N"]).max())
                top.append(ch["surface_m"].max())
                npts += len(g)
                engaged &= bool(np.all(ch["state"] == 2))
                drain(s, 0.3)
            pred = slope * v_xy * tau
            dropped = c.status()["ctrl"]["live"].get("dropped")
            rows.append(("move over a dome",
                         f"under feedback, {v_xy * 1e6:g} um/s, slope {slope:.4f}, tau {tau * 1e3:g} ms",
                         f"max following error {np.median(err_h) * 1e9:.3f} nm (slope v tau {pred * 1e9:.3f} nm), "
                         f"max force error {np.median(err_f) * 1e12:.1f} pN (k slope v tau {k * pred * 1e12:.1f} pN)",
                         f"medians of {passes} crossings, {npts} live points at {fs:g} Hz, "
                         f"top {np.median(top) * 1e9:.1f} nm, engaged throughout {engaged}, dropped {dropped}"))
    finally:  # also on an error: no daemon left behind
        stop(p, c)
        s.close()
    return rows


def main(exe, out):
    rows = []
    p, c, pub = start(exe)
    s = Stream(pub, live=True)
    # CPU
    for label, rate, eng in (("idle, monitor off", 0, False), ("idle, monitor 100 Hz", 100, False),
                             ("engaged, monitor 100 Hz", 100, True)):
        c.set({"monitor_rate_Hz": rate})
        if eng:
            engage(c, s)
        drain(s, 1)
        t0, c0 = time.monotonic(), cpu_s(p.pid)
        msgs = drain(s, 5)
        frac = (cpu_s(p.pid) - c0) / (time.monotonic() - t0)
        dropped = c.status()["ctrl"]["live"].get("dropped")
        rows.append(("cpu", label, f"{100 * frac:.2f} % of one core", f"{len(msgs)} live messages, dropped {dropped}"))
    c.withdraw()
    event(s, ("withdrawn",))
    # late blocks of a paced campaign, monitor on vs off
    for rate in (100, 0):
        c.set({"monitor_rate_Hz": rate})
        c.wait_idle()
        cid = c.request({"cmd": "campaign", "n": 2, "client_run_id": c.new_client_run_id()})
        runs, end = s.campaign(cid.get("campaign_id", cid.get("run_id")), timeout=120, strict=False)
        late = sum(r.end["late_blocks"] for r in runs if r.end)
        rows.append(("late blocks", f"paced campaign of 2 curves, monitor {rate} Hz", f"{late} late blocks",
                     f"{sum(len(r.headers) for r in runs)} blocks"))
    stop(p, c)
    s.close()

    # engage -> feedback force spread at full rate, with detector noise
    p, c, pub = start(exe)
    s = Stream(pub, live=True)
    c.set({"noise_V_rms": 0.002, "antialias": "point"})
    v = c.get("k_N_per_m", "T_K", "sample_rate_Hz", "noise_V_rms")
    ev = engage(c, s)
    c.set({"monitor_rate_Hz": v["sample_rate_Hz"], "speed": 1})
    f, err = [], []
    drain(s, 0.5)
    while len(f) < 20000:
        for m in drain(s, 1):
            h, ch = m
            k = ch["state"] == 2
            f.extend(ch["force_N"][k])
            err.extend(ch["error_N"][k])
    f = np.array(f[:20000])
    st = c.status()["ctrl"]
    k, T = v["k_N_per_m"], v["T_K"]
    thermal = k * np.sqrt(KB * T / k)
    det = k * st["invols_m_per_V"] * v["noise_V_rms"]
    rows.append(("feedback spread", f"engaged ({ev['kind']}), setpoint {st['setpoint_N'] * 1e9:.3f} nN, N = {len(f)}",
                 f"mean {f.mean() * 1e9:.4f} nN, sd {f.std() * 1e12:.2f} pN",
                 f"free-lever thermal bound {thermal * 1e12:.2f} pN, detector floor {det * 1e12:.2f} pN, "
                 f"both {np.hypot(thermal, det) * 1e12:.2f} pN"))
    # failures: a Z-range saturation (setpoint beyond the pull-off: the loop retracts to 0), a crash, a timeout
    c.set({"speed": 50, "monitor_rate_Hz": 100})
    sp = c.get("ctrl_setpoint", "ctrl_setpoint_unit", "ctrl_setpoint_relative")
    c.feedback(setpoint=-50e-9, unit="N", relative=False)
    ev = event(s, ("z_saturated",), 30)
    st = c.status()["ctrl"]
    rows.append(("failure", "Z-range saturation (setpoint -50 nN)", f"event {ev['kind']}",
                 f"status saturated={st['saturated']}, piezo {st['piezo_z_m']:.3g} m"))
    c.withdraw()
    event(s, ("withdrawn",))
    c.feedback(setpoint=sp["ctrl_setpoint"], unit=sp["ctrl_setpoint_unit"], relative=sp["ctrl_setpoint_relative"])
    engage(c, s)
    pz = c.status()["ctrl"]["piezo_z_m"]
    c.z(min(pz + 5e-6, 10e-6))
    ev = event(s, ("crash",), 30)
    st = c.status()["ctrl"]
    rows.append(("failure", "crash (piezo +5 um, feedback off)", f"event crash, force {ev['force_N'] * 1e9:.2f} nN",
                 f"status state={st['state']}, crash_force_N={st['crash_force_N'] * 1e9:.2f} nN"))
    c.withdraw(motor_steps=1)
    event(s, ("withdrawn",))
    c.set({"ctrl_engage_timeout_s": 2})
    c.engage()
    ev = event(s, ("engage_failed", "engaged"), 60)
    rows.append(("failure", "engage timeout (ctrl_engage_timeout_s 2)", f"event {ev['kind']} {ev.get('reason')}",
                 f"status last_fail={c.status()['ctrl']['last_fail']}"))
    stop(p, c)
    s.close()

    rows += dome(exe)

    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "bench_instrument.csv"), "w") as fh:
        fh.write("what,case,figure,detail\n")
        for r in rows:
            fh.write(",".join('"' + x.replace('"', "'") + '"' for x in r) + "\n")
    with open(os.path.join(out, "bench_instrument.md"), "w") as fh:
        fh.write("| what | case | figure | detail |\n|---|---|---|---|\n")
        for r in rows:
            fh.write("| " + " | ".join(r) + " |\n")
    for r in rows:
        print(" | ".join(r))


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
