#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""What a real acquisition script does: engage, a grid of force curves with XY moves between them, withdraw.

    python3 clients/python/examples/acquire_grid.py --rep tcp://127.0.0.1:5555 --pub tcp://127.0.0.1:5556
    python3 clients/python/examples/acquire_grid.py --vafmd build/src/daemon/vafmd --faults   # self-test

It engages (the controller's auto-approach, docs/instrument.md), moves the tip to each point of an n x n
grid under feedback, takes one curve at each (curve index = grid point), withdraws, and recovers as an
acquisition script must from what the instrument and its network do (protocol/faults.md):
  - `busy` replies: retried (the Client does it);
  - a lost reply to `move` (not resendable: it is not idempotent): the state is queried, and the move
    waited for if it was executed, sent again if not;
  - a lost reply to `curve`: resent with its client_run_id (the daemon answers with the same run);
  - a lost data block (seq gap), a truncated run (no run.end), a saturated (CLIPPED) or NaN (dropout) run:
    not saved, the curve is taken again (a curve is the same bit for bit from its (seed, index));
  - a late block: nothing to do but wait (the stream's timeouts are longer).
With --faults it sets one fault of each of these kinds first (a scripted plan) and checks at the end that
the daemon injected each one and the script noticed it. What it recorded is compared with the ground truth
of each run: its pull-off (the streamed retract's most tensile sample) lies below the lever's true pull-off
(run.end's `pulloff_spring_N`, the most tensile spring force at any step) by no more than the sampling
allows (`pulloff_bounds`: the ramp k v / fs within a sample interval, the thermal peak, the detector's
noise), and equals run.end's `pulloff_sampled_N` bit for bit (the stream arrived intact); run.start's
controller position (`ctrl.x_m`, `y_m`) is the grid point. Exit status 0 when all holds, 1 otherwise (the
reason on stderr).

The sample (`ctrl_sample`, protocol/wire.md) is by default stripes along y of two JKR materials of clearly
different adhesion, one grid column per stripe: material a (gamma 0.05 J/m^2) under the even columns, b
(0.2 J/m^2) under the odd ones. Each curve is taken over the material under the tip, and run.start's
`sample` names it: the material the script infers from its own pull-off at each point (the nearer, on a log
scale, of the two materials' quasi-static JKR pull-offs 3 pi gamma R / 2) must be that one, and each
material's mean recorded pull-off must lie below the mean true one (`pulloff_spring_N`) by the sampling's
mean offset within its statistical error. `--sample ""` is the flat uniform sample of the scene (no material
checks).
"""
import argparse
import math
import os
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from vafm_client import Client, Stream  # noqa: E402
from vafm_client.client import DaemonError, GapError, TransportError  # noqa: E402

# one fault of each kind the script can meet; run ids count every run the daemon starts (re-takes included)
FAULT_PLAN = {"seed": 5, "script": [
    {"kind": "busy", "cmd": "engage", "nth": 1},
    {"kind": "no_reply", "cmd": "move", "nth": 2},
    {"kind": "no_reply", "cmd": "curve", "nth": 3},
    {"kind": "drop", "run": 2, "block": 1},
    {"kind": "truncate", "run": 4, "block": 2},
    {"kind": "saturate", "run": 6, "block": 1, "samples": 50},
    {"kind": "dropout", "run": 8, "block": 1, "samples": 20},
    {"kind": "late", "run": 9, "block": 1, "delay_s": 0.3},
]}
KB = 1.380649e-23  # J/K
# the report (or recovery) that shows each kind was noticed
NOTICED_BY = {"busy": "busy", "no_reply": "no_reply", "drop": "gap", "truncate": "truncated",
              "saturate": "saturate", "dropout": "dropout", "late": None}


class Acquisition:
    def __init__(self, rep, pub, say=print):
        self.c = Client(rep, timeout=3.0, retries=3)
        self.s = Stream(pub, timeout=20.0)
        self.say = say
        self.noticed = []   # what this script saw go wrong: kinds of NOTICED_BY's values
        self.saved = {}     # grid index -> (target, Run)

    def close(self):
        self.s.close()
        self.c.close()

    def _ctrl_event(self, kinds, timeout=60.0):
        deadline = time.monotonic() + timeout
        for topic, m in self.s.messages(deadline=deadline):
            if topic == "event" and m.get("source") == "ctrl" and m.get("kind") in kinds:
                return m
        raise TransportError(f"no controller event {kinds} within {timeout} s")

    def _busy_seen(self, before):
        if any("busy" in text for _, text in self.c.log[before:]):
            self.noticed.append("busy")

    def engage(self):
        n = len(self.c.log)
        self.c.engage()
        self._busy_seen(n)
        ev = self._ctrl_event(("engaged", "engage_failed", "crash"))
        if ev["kind"] != "engaged":
            raise RuntimeError(f"engage failed: {ev}")
        st = self.c.status()["ctrl"]
        self.say(f"engaged: motor at {st['motor_z_m'] * 1e6:.1f} um, piezo {st['piezo_z_m'] * 1e6:.3f} um, "
                 f"force {st['force_N'] * 1e9:.3f} nN (setpoint {st['setpoint_N'] * 1e9:.3f} nN)")

    def move(self, x, y):
        n = len(self.c.log)
        try:
            self.c.move(x, y)
        except TransportError:  # the reply was lost: was the move executed? ask, do not resend blindly
            self.noticed.append("no_reply")
            st = self.c.status()["ctrl"]
            if not st.get("moving") and (abs(st["x_m"] - x) > 1e-12 or abs(st["y_m"] - y) > 1e-12):
                self.say(f"move to ({x:g}, {y:g}): reply lost, not executed: sent again")
                self.c.move(x, y)
            else:
                self.say(f"move to ({x:g}, {y:g}): reply lost, executed: waiting for it")
        self._busy_seen(n)
        st = self.c.status()["ctrl"]
        if st.get("moving"):
            self._ctrl_event(("moved",))
        st = self.c.status()["ctrl"]
        if abs(st["x_m"] - x) > 1e-12 or abs(st["y_m"] - y) > 1e-12:
            raise RuntimeError(f"the tip is at ({st['x_m']}, {st['y_m']}), not at ({x}, {y})")

    def curve(self, index, tries=5):
        """Take curve `index` until it arrives whole and clean; returns the Run."""
        for attempt in range(tries):
            self.c.wait_idle()
            n = len(self.c.log)
            rid = self.c.curve(index=index)["run_id"]
            if any("no reply" in text for _, text in self.c.log[n:]):
                self.noticed.append("no_reply")  # resent with its client_run_id: the same run
            self._busy_seen(n)
            try:
                run = self.s.run(rid, strict=True)
            except GapError as e:  # a lost block (gap) or no run.end (truncated, TruncatedError)
                kind = "truncated" if "truncat" in type(e).__name__.lower() or "run.end" in str(e) else "gap"
                self.noticed.append(kind)
                self.say(f"curve {index}: run {rid} {kind}: {e}; taken again")
                continue
            if not run.clean:
                kinds = (["saturate"] if run.clipped_blocks else []) + (["dropout"] if run.nan_samples else [])
                self.noticed += kinds
                self.say(f"curve {index}: run {rid} not clean ({'; '.join(run.warnings)}): taken again")
                continue
            return run
        raise RuntimeError(f"curve {index}: no clean run in {tries} tries")

    def withdraw(self):
        self.c.withdraw(motor_steps=2)
        self._ctrl_event(("withdrawn",))


def stripes(n, pitch):
    """Stripes along y, one grid column each (x = (ix - (n-1)/2) pitch sits mid-stripe: material ix % 2)."""
    return (f"pattern=stripes,size_x_m={n * pitch!r},center_x_m=0,period_m={2 * pitch!r},"
            f"a_contact=jkr,a_E_star_Pa=1e9,a_gamma_J_per_m2=0.05,b_contact=jkr,b_E_star_Pa=1e9,"
            f"b_gamma_J_per_m2=0.2")


def infer_material(pulloff_N, run):
    """The material (0: a, 1: b) whose quasi-static JKR pull-off 3 pi gamma R / 2 is the nearer on a log
    scale (thermal escape only lowers a pull-off; the two differ fourfold); None without a two-material map."""
    m = (run.start.get("sample") or {}).get("map") or {}
    ga, gb = m.get("a_gamma_J_per_m2"), m.get("b_gamma_J_per_m2")
    if not (ga and gb and ga != gb):
        return None
    R = run.start["scene"]["R_m"]
    fa, fb = 1.5 * math.pi * ga * R, 1.5 * math.pi * gb * R
    lo = 0 if fa < fb else 1
    return lo if pulloff_N < math.sqrt(fa * fb) else 1 - lo


def recorded_pulloff(run):
    """The most tensile streamed force of the retract (segment 1), as a positive number (NaN without one)."""
    retract = run.segment == 1
    return float(-run["force_N"][retract].min()) if retract.any() else math.nan


def pulloff_bounds(scene):
    """How far below the true pull-off (run.end's `pulloff_spring_N`, the lever's most tensile spring force
    at any integration step) the recorded one (the most tensile output sample) may lie: (lo, hi, ramp,
    thermal, detector) in N.

    An output sample is the mean (antialias mean) or the last (point) of the spring forces of its interval,
    plus the detector's noise, so it exceeds the true pull-off by the noise alone (lo = -4 sigma_det,
    sigma_det = k InvOLS (noise_V_rms^2 + q^2/12)^1/2, q the ADC step). Below it, it lies by
    - the ramp: the spring force grows at k v until the rupture, which falls at a uniform phase phi of an
      interval 1/fs; the sample holding it is much less tensile (the lever snaps back and rings down at f0
      within it), so the most tensile sample is the interval before: (phi + 1/2) k v / fs, 0.5-1.5 k v / fs;
    - the thermal peak: the true value is the maximum over steps of a force that fluctuates, the sample a
      mean over the interval: at most a few sigma_th = (k kB T)^1/2, the free lever's thermal force (contact
      stiffens the lever: less); hi = 1.5 k v / fs + 3 sigma_th + 4 sigma_det.
    Default scene (k 0.1 N/m, v 1 um/s, fs 10 kHz, 298 K, no detector noise): k v / fs = 10 pN, sigma_th =
    20.3 pN, [lo, hi] = [0, 76] pN. Measured over a 6x6 grid (N = 18 points per material): 15.5 pN mean, sd
    4.8 pN, range 3.5-21.1 pN on a (2.33 nN); 17.2 pN, sd 5.3 pN, range 8.9-26.5 pN on b (9.41 nN)."""
    k, v, fs, T = scene["k_N_per_m"], scene["v_retract_m_per_s"], scene["sample_rate_Hz"], scene["T_K"]
    bits = scene.get("adc_bits") or 0
    q = scene.get("adc_range_V", 0.0) / 2 ** bits if bits else 0.0
    det = k * scene["sensitivity_m_per_V"] * math.sqrt((scene.get("noise_V_rms") or 0.0) ** 2 + q * q / 12)
    ramp, thermal = k * v / fs, math.sqrt(k * KB * T)
    return 0.0 - 4 * det, 1.5 * ramp + 3 * thermal + 4 * det, ramp, thermal, det


def check_materials(saved):
    """Per grid point the material inferred from the recorded pull-off against run.start's sample material;
    per material the mean recorded pull-off against the mean true pull-off (run.end's pulloff_spring_N) less
    the sampling's offset (pulloff_bounds)."""
    bad, rec, true, scenes = [], {}, {}, {}
    for idx, ((x, y), run) in sorted(saved.items()):
        sample = run.start.get("sample")
        if sample is None:
            continue
        f = recorded_pulloff(run)
        inferred = infer_material(f, run)
        if inferred is None:
            continue
        if inferred != sample["material"]:
            bad.append(f"curve {idx}: pull-off {f * 1e9:.3f} nN says material {inferred}, run.start's sample "
                       f"is material {sample['material']}")
        rec.setdefault(inferred, []).append(f)
        true.setdefault(sample["material"], []).append(run.end["result"]["pulloff_spring_N"])
        scenes.setdefault(sample["material"], run.start["scene"])
    # N = the material's grid points (3x3 grid: 6 of a, 3 of b); d = true - recorded pull-off per point, s
    # its sample standard deviation (measured ~5 pN, pulloff_bounds), at least the ramp's own spread
    # k v / fs / sqrt(12) (the uniform rupture phase: 2.9 pN). The mean of d must lie within the ramp's
    # mean offset k v / fs less 3 s / sqrt(N) and that plus the thermal peak's sigma_th plus 3 s / sqrt(N)
    # (default scene, 3x3 grid: [6.5, 33.8] pN for N = 6 of a, [5.0, 35.3] pN for N = 3 of b; measured
    # 16.7 and 17.0 pN). A single point has no mean to speak of: the per-curve check (check_truth) only.
    for mat in sorted(set(rec) | set(true)):
        r, t = rec.get(mat, []), true.get(mat, [])
        if len(r) != len(t):
            bad.append(f"material {mat}: {len(r)} points inferred, {len(t)} under the tip")
            continue
        n = len(r)
        d = [ti - ri for ri, ti in zip(r, t)]
        mean_r, mean_t, mean_d = sum(r) / n, sum(t) / n, sum(d) / n
        if n < 2:
            continue
        _, _, ramp, thermal, det = pulloff_bounds(scenes[mat])
        s = max(math.sqrt(sum((v - mean_d) ** 2 for v in d) / (n - 1)), ramp / math.sqrt(12))
        lo = ramp - 3 * s / math.sqrt(n) - 4 * det
        hi = ramp + thermal + 3 * s / math.sqrt(n) + 4 * det
        print(f"material {mat}: N = {n}, mean pull-off {mean_r * 1e9:.4f} nN, true {mean_t * 1e9:.4f} nN: "
              f"{mean_d * 1e12:.2f} pN below (sd {s * 1e12:.2f} pN; allowed [{lo * 1e12:.1f}, {hi * 1e12:.1f}] pN)")
        if not lo <= mean_d <= hi:
            bad.append(f"material {mat}: mean recorded pull-off {mean_r!r} N lies {mean_d!r} N below the true "
                       f"{mean_t!r} N, outside [{lo!r}, {hi!r}] N (N = {n}, s = {s!r} N)")
    return bad


def check_truth(saved):
    """What was recorded against each run's ground truth: a list of problems."""
    bad = []
    for idx, ((x, y), run) in sorted(saved.items()):
        ctrl = run.start.get("ctrl") or {}
        if ctrl.get("x_m") != x or ctrl.get("y_m") != y:
            bad.append(f"curve {idx}: run.start records the tip at ({ctrl.get('x_m')}, {ctrl.get('y_m')}), "
                       f"the grid point is ({x}, {y})")
        res = run.end["result"]
        f = recorded_pulloff(run)
        if res.get("pulloff_sampled_N") is None or f != res["pulloff_sampled_N"]:  # the stream is intact
            bad.append(f"curve {idx}: recorded pull-off {f!r} N, run.end's {res.get('pulloff_sampled_N')!r} N")
        # against the physics' truth: the true pull-off less the sampling's offset (pulloff_bounds)
        lo, hi = pulloff_bounds(run.start["scene"])[:2]
        true = res.get("pulloff_spring_N")
        if true is None or not lo <= true - f <= hi:
            bad.append(f"curve {idx}: recorded pull-off {f!r} N, the true one (pulloff_spring_N) {true!r} N: "
                       f"not within [{lo!r}, {hi!r}] N below it")
    return bad


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("--rep", default="tcp://127.0.0.1:5555", help="command endpoint")
    ap.add_argument("--pub", default="tcp://127.0.0.1:5556", help="stream endpoint")
    ap.add_argument("--vafmd", help="start this vafmd (free run, private ipc endpoints) and stop it after")
    ap.add_argument("-n", type=int, default=3, help="grid points per side (1-20)")
    ap.add_argument("--pitch", type=float, default=1e-6, help="grid pitch, m")
    ap.add_argument("--speed", type=float, default=1000.0,
                    help="the daemon's pacing factor while the script runs (engage and moves; restored after)")
    ap.add_argument("--sample", help="the controller's sample (ctrl_sample; \"\": flat uniform); default: "
                    "stripes of two materials, one grid column each")
    ap.add_argument("--faults", action="store_true", help="inject one fault of each kind first and check "
                    "that each was noticed")
    a = ap.parse_args(argv)
    if not 1 <= a.n <= 20:
        ap.error("-n must be in [1, 20]")
    proc = tmp = None
    if a.vafmd:
        tmp = tempfile.mkdtemp(prefix="vafm-grid-")
        a.rep, a.pub = f"ipc://{tmp}/rep", f"ipc://{tmp}/pub"
        proc = subprocess.Popen([a.vafmd, "--rep", a.rep, "--pub", a.pub, "--free-run"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(100):
            if os.path.exists(f"{tmp}/rep") and os.path.exists(f"{tmp}/pub"):
                break
            time.sleep(0.05)
    t0 = time.monotonic()
    acq = Acquisition(a.rep, a.pub)
    problems = []
    try:
        c = acq.c
        speed = c.get("speed")["speed"]
        c.set({"speed": a.speed})
        sample = c.get("ctrl_sample")["ctrl_sample"]
        c.set({"ctrl_sample": stripes(a.n, a.pitch) if a.sample is None else a.sample})  # before engaging:
        # a new sample rebuilds the controller
        if a.faults:
            c.faults(FAULT_PLAN)
        acq.engage()
        half = (a.n - 1) / 2
        for iy in range(a.n):
            for ix in range(a.n) if iy % 2 == 0 else reversed(range(a.n)):  # a serpentine, as scanners do
                x, y = (ix - half) * a.pitch, (iy - half) * a.pitch
                idx = iy * a.n + ix
                acq.move(x, y)
                run = acq.curve(idx)
                acq.saved[idx] = ((x, y), run)
                acq.say(f"curve {idx} at ({x * 1e6:+.2f}, {y * 1e6:+.2f}) um: run {run.run_id}, "
                        f"pull-off {run.end['result']['pulloff_sampled_N'] * 1e9:.3f} nN")
        acq.withdraw()
        c.set({"speed": speed, "ctrl_sample": sample})
        problems += check_truth(acq.saved)
        problems += check_materials(acq.saved)
        if len(acq.saved) != a.n * a.n:
            problems.append(f"{len(acq.saved)} of {a.n * a.n} grid points recorded")
        if a.faults:
            injected = [r["kind"] for r in c.faults()["last"]]
            for kind in injected:
                want = NOTICED_BY.get(kind)
                if want and want not in acq.noticed:
                    problems.append(f"fault {kind} was injected, the script did not notice it")
            missing = sorted({e["kind"] for e in FAULT_PLAN["script"]} - set(injected))
            if missing:
                problems.append(f"faults of the plan never injected: {missing}")
            print(f"faults injected: {injected}; noticed: {acq.noticed}")
    except (DaemonError, TransportError, RuntimeError) as e:
        problems.append(f"{type(e).__name__}: {e}")
    finally:
        acq.close()
        if proc:
            try:
                Client(a.rep, timeout=2, retries=0).shutdown()
            except TransportError:
                pass
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            for f in ("rep", "pub"):
                if os.path.exists(os.path.join(tmp, f)):
                    os.unlink(os.path.join(tmp, f))
            os.rmdir(tmp)
    print(f"{len(acq.saved)} curves on a {a.n}x{a.n} grid in {time.monotonic() - t0:.1f} s")
    for p in problems:
        print("error:", p, file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
