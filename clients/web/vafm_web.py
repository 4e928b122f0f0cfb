#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""vafm web: the live web panel of a running vafmd (issue #28); docs/web.md says what it shows and why.

    /usr/bin/python3 clients/web/vafm_web.py --daemon tcp://127.0.0.1:5555 [--listen 127.0.0.1:8080]
    vafm web --daemon tcp://127.0.0.1:5555                # the same, through the CLI (execv, no shell)

A client of the daemon's public protocol (protocol/wire.md) and nothing more: it subscribes to the stream
(one SUB socket, whatever the number of browsers) and forwards the browser's commands over REQ. It serves
the page (static/) and one WebSocket per browser with aiohttp (Debian's python3-aiohttp).

Display decimation (the rule the page's points follow, tested against the raw stream): a data block of a run is
cut at every run sample that is a multiple of B (B = max(1, block_samples // columns_per_block), from the run's
`run.start`) and at a segment change; each piece gives the sample of its smallest and the sample of its largest
`force_N` (numpy's argmin/argmax: the first one), in sample order, once if they are the same sample. So the
pull-off and the trigger survive, and a 1 MS/s curve draws the same ~64 points per block as a 200 kS/s one.
The always-on controller's `live` topic (protocol/wire.md §3.7; the bridge subscribes to it by name) follows the
same rule on its points: a message is cut at every live point index (first_sample / decimation + j) that is a
multiple of L (L = max(1, ceil(monitor_rate_Hz / --live-columns-per-s))) and at a change of `state`; each piece
gives its min and max `force_N`. At the default 100 points/s and 100 columns/s every point is drawn.

Each browser has a bounded queue of frames (--queue); a browser that cannot keep up loses its oldest data
frames (counted, shown on its page), never the daemon's or other browsers' data: the bridge never waits for
a browser, and the daemon only ever sees this one subscriber.

Bound to loopback by default; on any other address a token is required (--token, or one is generated and
printed): the page and the WebSocket both need `?token=...`. It exposes only the daemon's commands (those
`hello` lists), minus `shutdown` (unless --allow-shutdown), and the daemon judges every argument.
"""
import argparse
import asyncio
import collections
import hmac
import ipaddress
import json
import math
import os
import secrets
import struct
import subprocess
import sys
import time

import numpy as np
import zmq
import zmq.asyncio
from aiohttp import WSMsgType, web

HERE = os.path.dirname(os.path.abspath(__file__))
# in the source tree, the client package beside it; installed (PREFIX/share/vafm/web), the installed package
if os.path.isdir(os.path.join(HERE, "..", "python", "vafm_client")):
    sys.path.insert(0, os.path.join(HERE, "..", "python"))
from vafm_client.client import FLAG_SEG_CHANGE, decode_header  # noqa: E402
from vafm_client.tune import K_B, fit_tune, sampled_psd  # noqa: E402  (the thermal_tune example's fit too)

SEGMENTS = {0: "approach", 1: "retract", 2: "dwell", 3: "tune"}
SEG_ID = {v: k for k, v in SEGMENTS.items()}
MAX_RUN_POINTS = 1 << 21     # decimated points of one run kept for late joiners and the overlay
MAX_TUNE_SAMPLES = 1 << 22   # raw deflection samples of a tune kept for its spectrum (32 MiB)
KEEP_CURVES = 8              # completed curves kept for the overlay (and for a browser that joins)
FLUSH_S = 0.05               # data frames go to the browsers every 50 ms
STREAM_QUEUE = 256           # stream messages waiting for the bridge (~1.3 s of a paced 5 ms-block stream):
                             # behind a free run the rest is dropped for the bridge alone (counted as gaps)
STATUS_S = 0.5               # the daemon's status is polled (once, for all browsers) every 0.5 s
LIVE_KEEP_S = 12.0           # live frames kept for a browser that joins (the scope shows 10 s)
NOT_FORWARDED = {"shutdown"}  # commands the panel never sends unless --allow-shutdown
FRAME_MAGIC = 0x56574641     # "AFWV": binary data frame of the panel's WebSocket (docs/web.md)


def decimate_indices(force, seg, first_sample, B):
    """Indices (into the block) of the samples the panel keeps of one data block: see the module docstring.
    force: the block's force_N; seg: per-sample segment ids; first_sample: run index of the block's first."""
    n = len(force)
    cuts = set(range((-first_sample) % B, n, B)) | {0, n}
    cuts |= set((np.flatnonzero(np.diff(seg)) + 1).tolist())
    cuts = sorted(c for c in cuts if 0 <= c <= n)
    keep = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        if b <= a:
            continue
        piece = force[a:b]
        i, j = a + int(np.argmin(piece)), a + int(np.argmax(piece))
        keep.extend(sorted({i, j}))
    return np.asarray(keep, dtype=np.int64)


def encode_frame(meta, arrays):
    """One binary WebSocket message: u32 magic, u32 JSON length, the JSON (meta, padded with spaces to a
    multiple of 8 bytes), then the float64 arrays named in meta["cols"], each meta["n"] values, little-endian."""
    j = json.dumps(meta, separators=(",", ":")).encode()
    j += b" " * ((-len(j) - 8) % 8)
    return struct.pack("<II", FRAME_MAGIC, len(j)) + j + b"".join(np.ascontiguousarray(a, "<f8").tobytes() for a in arrays)


def clean_json(x):
    """NaN and infinities as null (JSON has none)."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: clean_json(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [clean_json(v) for v in x]
    return x


class Viewer:
    """One browser: its WebSocket and a bounded queue; a full queue drops the oldest data frame."""

    def __init__(self, ws, limit):
        self.ws, self.limit = ws, limit
        self.q = collections.deque()
        self.wake = asyncio.Event()
        self.dropped = 0

    def put(self, msg, data=False, force=False):
        """force: a join's snapshot (the history a new browser needs), never dropped."""
        if len(self.q) >= self.limit and not force:
            idx = next((k for k, (d, _) in enumerate(self.q) if d), 0)
            del self.q[idx]
            self.dropped += 1
        self.q.append((data, msg))
        self.wake.set()

    async def pump(self):
        while not self.ws.closed:
            await self.wake.wait()
            self.wake.clear()
            while self.q:
                _, msg = self.q.popleft()
                if isinstance(msg, bytes):
                    await self.ws.send_bytes(msg)
                else:
                    await self.ws.send_str(msg)


class RunState:
    def __init__(self, start, cols_per_block):
        self.start = start
        self.run_id = start["run_id"]
        self.kind = start.get("kind")
        self.fs = start.get("sample_rate_Hz") or 1.0
        self.B = max(1, int(start.get("block_samples") or 1) // cols_per_block)
        self.names = [c["name"] for c in start.get("channels", [])]
        self.points = []          # decimated (cols) arrays per flushed frame, for late joiners and the overlay
        self.npoints = 0
        self.pending = None       # a SEG_CHANGE block waiting for its segment event
        self.tune = [] if self.kind == "tune" else None
        self.tune_n = 0


class Bridge:
    def __init__(self, a):
        self.a = a
        self.ctx = zmq.asyncio.Context()
        self.viewers = set()
        self.req_lock = asyncio.Lock()
        self.req = None
        self.hello = None
        self.status = None
        self.runs = {}                          # run_id -> RunState (runs in progress)
        self.curves = collections.deque(maxlen=KEEP_CURVES)  # (run.start, run.end, frames) of ended curves
        self.frame_buf = []                     # (run_id, cols, arrays, seqs, t_recv) waiting for the flush
        self.faults = collections.deque(maxlen=256)
        self.map = None
        self.tune_result = None
        self.last_json = {}
        self.commands = set()
        self.stats = {"blocks": 0, "frames": 0, "gaps": 0}
        self.last_seq = None
        self.live_frames = collections.deque()  # (t_recv, frame) of the last LIVE_KEEP_S seconds
        self.live_stats = {"messages": 0, "gaps": 0, "last_seq": None, "generation": None}
        self.t0 = time.time()  # the page's times are seconds since this (time.time(): the browser's clock too)

    # ---- the daemon --------------------------------------------------------------------------------------
    def secure(self, sock):
        """CURVE keys (--curve) on a socket to the daemon, as vafm ctl and the Python Client set them."""
        if self.a.curve_keys:
            sock.curve_serverkey, sock.curve_publickey, sock.curve_secretkey = self.a.curve_keys

    def _open_req(self):
        if self.req is not None:
            self.req.close(0)
        self.req = self.ctx.socket(zmq.REQ)
        self.req.setsockopt(zmq.LINGER, 0)
        self.secure(self.req)
        self.req.connect(self.a.daemon)

    async def request(self, obj, timeout=10.0):
        """The daemon's reply (ok or error) as a dict; a lost reply is an error of code "transport"."""
        async with self.req_lock:
            if self.req is None:
                self._open_req()
            await self.req.send(json.dumps(obj).encode())
            if await self.req.poll(int(timeout * 1000)):
                return json.loads(await self.req.recv())
            self._open_req()  # lazy pirate: a REQ socket that lost its reply cannot send again
            return {"status": "error", "code": "transport", "field": None,
                    "message": f"no reply from {self.a.daemon} within {timeout:g} s (the panel's own message: "
                               "the daemon did not answer)"}

    async def connect(self):
        deadline = time.monotonic() + self.a.connect_timeout
        while True:
            r = await self.request({"cmd": "hello"}, timeout=1.0)
            if r.get("status") == "ok":
                break
            if time.monotonic() > deadline:
                raise SystemExit(f"vafm web: no vafmd answers at {self.a.daemon}")
        self.hello = r
        self.commands = set(r.get("capabilities", [])) - (set() if self.a.allow_shutdown else NOT_FORWARDED)
        pub = self.a.pub or r.get("stream")
        self.sub = self.ctx.socket(zmq.SUB)
        self.sub.setsockopt(zmq.LINGER, 0)
        self.sub.setsockopt(zmq.RCVHWM, STREAM_QUEUE)
        self.sub.setsockopt(zmq.SUBSCRIBE, b"")
        self.sub.setsockopt(zmq.SUBSCRIBE, b"live")  # the daemon sends `live` only to a subscription by name
        self.secure(self.sub)
        self.sub.connect(pub)
        self.pub = pub

    async def stream_loop(self):
        while True:
            parts = await self.sub.recv_multipart()
            t_recv = time.time()
            topic = parts[0].decode("ascii", "replace")
            try:
                if topic == "data":
                    self.on_data(parts, t_recv)
                elif topic == "live":
                    self.on_live(parts, t_recv)
                elif topic in ("run.start", "run.end", "event", "heartbeat", "campaign.end", "faults"):
                    self.on_json(topic, json.loads(parts[1]), t_recv)
            except (ValueError, KeyError, IndexError) as e:  # a message off the protocol: say so, go on
                self.broadcast_json({"type": "panel_error", "message": f"stream message {topic}: {e}"})

    async def status_loop(self):
        while True:
            r = await self.request({"cmd": "status"}, timeout=5.0)
            if r.get("status") == "ok":
                self.status = r
                info = self.bridge_info()
                for v in list(self.viewers):  # each browser also learns the data frames it lost
                    v.put(json.dumps({"type": "status", "status": r, "bridge": info, "dropped_frames": v.dropped}))
            await asyncio.sleep(STATUS_S)

    async def flush_loop(self):
        while True:
            await asyncio.sleep(FLUSH_S)
            self.flush()

    def bridge_info(self):
        return {"viewers": len(self.viewers), "blocks": self.stats["blocks"], "gaps": self.stats["gaps"],
                "frames": self.stats["frames"], "pub": self.pub, "daemon": self.a.daemon,
                "live_messages": self.live_stats["messages"], "live_gaps": self.live_stats["gaps"]}

    # ---- stream messages ---------------------------------------------------------------------------------
    def on_data(self, parts, t_recv):
        h = decode_header(parts[1])
        self.stats["blocks"] += 1
        if self.last_seq is not None and h.seq > self.last_seq + 1:
            self.stats["gaps"] += h.seq - self.last_seq - 1
        self.last_seq = h.seq
        run = self.runs.get(h.run_id)
        if run is None:  # joined mid-run before its run.start: the daemon resends it; skip until then
            return
        chans = [np.frombuffer(p, "<f8") for p in parts[2:2 + h.n_channels]]
        if run.pending is not None:
            self.process_block(run, *run.pending)
            run.pending = None
        if h.flags & FLAG_SEG_CHANGE:
            run.pending = (h, chans, t_recv, None)  # its segment event follows at once
        else:
            self.process_block(run, h, chans, t_recv, None)

    def on_live(self, parts, t_recv):
        """A `live` message: decimated (the module docstring's rule) into one data frame of run_id 0, sent to
        every browser at once and kept LIVE_KEEP_S seconds for the ones that join."""
        h = json.loads(parts[1])
        names, n = list(h["channels"]), int(h["points"])
        if len(parts) != 2 + len(names) or any(len(p) != 8 * n for p in parts[2:]):
            raise ValueError(f"{len(parts) - 2} frames for {len(names)} channels of {n} points")
        if n == 0:
            return
        st = self.live_stats
        st["messages"] += 1
        if st["last_seq"] is not None and h["generation"] == st["generation"] and h["seq"] > st["last_seq"] + 1:
            st["gaps"] += h["seq"] - st["last_seq"] - 1
        st["last_seq"], st["generation"] = h["seq"], h["generation"]
        chans = [np.frombuffer(p, "<f8") for p in parts[2:]]
        m = max(1, int(h["decimation"]))
        p0 = int(h["first_sample"]) // m
        L = max(1, math.ceil(float(h["monitor_rate_Hz"]) / self.a.live_columns_per_s))
        state = chans[names.index("state")].astype(np.int64)
        idx = decimate_indices(chans[names.index("force_N")], state, p0, L)
        # on the page's clock: the last point is now; the others earlier by the controller's time / speed
        speed = float((self.status or {}).get("speed") or 1.0)
        ts = chans[names.index("time_s")]
        t = t_recv - (ts[-1] - ts[idx]) / speed - self.t0
        meta = {"type": "live", "run_id": 0, "cols": ["i", "t"] + names, "n": len(idx), "seqs": [h["seq"]],
                "generation": h["generation"], "state": h.get("state"), "L": L, "t_recv": [t_recv]}
        frame = encode_frame(meta, [(p0 + idx).astype(np.float64), t] + [c[idx] for c in chans])
        self.live_frames.append((t_recv, frame))
        while self.live_frames and self.live_frames[0][0] < t_recv - LIVE_KEEP_S:
            self.live_frames.popleft()
        for v in list(self.viewers):
            v.put(frame, data=True)

    def process_block(self, run, h, chans, t_recv, change):
        names = run.names
        n = h.n_samples
        seg = np.full(n, h.segment, dtype=np.int64)
        if change is not None and h.first_sample <= change[0] < h.first_sample + n:
            seg[change[0] - h.first_sample:] = change[1]
        if run.tune is not None and "deflection_m" in names and run.tune_n < MAX_TUNE_SAMPLES:
            x = chans[names.index("vDeflection_V")] if "vDeflection_V" in names else chans[names.index("deflection_m")]
            run.tune.append(x[:MAX_TUNE_SAMPLES - run.tune_n].copy())
            run.tune_n += len(run.tune[-1])
        force = chans[names.index("force_N")] if "force_N" in names else chans[0]
        idx = decimate_indices(force, seg, h.first_sample, run.B)
        speed = 1.0 if h.flags & 8 else (run.start.get("speed") or 1.0)
        t = t_recv - (n - 1 - idx) / run.fs / speed - self.t0
        cols = ["i", "t", "seg"] + names
        arrays = [(h.first_sample + idx).astype(np.float64), t, seg[idx].astype(np.float64)] + [c[idx] for c in chans]
        self.frame_buf.append((run.run_id, cols, arrays, h.seq, t_recv))

    def on_json(self, topic, p, t_recv):
        rid = p.get("run_id")
        if topic == "run.start":
            if rid in self.runs:
                return  # resent for a new subscriber
            self.flush()
            self.runs[rid] = RunState(p, self.a.columns_per_block)
            start = dict(p)
            if isinstance(start.get("replay"), dict):  # a replay's per-curve list may be long: not drawn
                start["replay"] = {k: v for k, v in start["replay"].items() if k != "curves"}
            self.last_json["run.start"] = start
            self.map_start(p)
            self.broadcast_json({"type": "run.start", "msg": start, "B": self.runs[rid].B, "t": t_recv - self.t0})
            return
        if topic == "event":
            run = self.runs.get(rid)
            if run is not None and run.pending is not None and p.get("kind") == "segment":
                h, chans, tr, _ = run.pending
                run.pending = None
                self.process_block(run, h, chans, tr, (p["sample"], SEG_ID.get(p.get("to"), h.segment)))
            self.flush()
            self.broadcast_json({"type": "event", "msg": p})
            return
        if topic == "run.end":
            run = self.runs.pop(rid, None)
            if run is not None and run.pending is not None:
                self.process_block(run, *run.pending)
            self.flush()
            if run is not None and run.kind == "curve":
                self.curves.append((run.start, p, run.points))
            self.map_end(p)
            self.last_json["run.end"] = p
            # t: when the run ended on the page's clock (its scope shading ends there)
            self.broadcast_json({"type": "run.end", "msg": clean_json(p), "t": t_recv - self.t0})
            if run is not None and run.tune is not None and run.tune:
                # the spectrum and its fit take a while (0.7 s for 0.2 s at 200 kS/s): in a thread, so that the
                # run.end, the live signal and the other browsers are not held up
                fut = asyncio.get_running_loop().run_in_executor(None, self.tune_fit, run)
                fut.add_done_callback(self.tune_done)
            return
        if topic == "faults":
            self.faults.append(p)
        elif topic == "heartbeat":
            self.last_json["heartbeat"] = p
        self.flush()
        self.broadcast_json({"type": topic, "msg": clean_json(p)})

    # ---- map and tune ------------------------------------------------------------------------------------
    def map_start(self, p):
        m = (p.get("campaign") or {}).get("map")
        if not m:
            return
        cid = p["campaign"]["campaign_id"]
        if self.map is None or self.map["campaign_id"] != cid:
            n = m["nx"] * m["ny"]
            self.map = {"campaign_id": cid, "nx": m["nx"], "ny": m["ny"], "runs": {},
                        "pixels": {k: [None] * n for k in ("pulloff_N", "contact_m", "E_star_Pa", "height_m")}}
        g = m["iy"] * m["nx"] + m["ix"]
        self.map["runs"][p["run_id"]] = g
        self.map["pixels"]["E_star_Pa"][g] = m.get("E_star_Pa")
        self.map["pixels"]["height_m"][g] = m.get("surface_height_m")

    def map_end(self, p):
        if self.map is None or p.get("run_id") not in self.map["runs"]:
            return
        g = self.map["runs"].pop(p["run_id"])
        res = p.get("result") or {}
        px = self.map["pixels"]
        px["pulloff_N"][g] = res.get("pulloff_sampled_N")
        th = res.get("touch_height_m")
        sh = res.get("surface_height_m")
        px["contact_m"][g] = (th + sh) if (th is not None and sh is not None) else None
        self.broadcast_json({"type": "map", "map": self.map_public(), "pixel": g})

    def map_public(self):
        return clean_json({k: v for k, v in self.map.items() if k != "runs"})

    def tune_fit(self, run):
        """The tune's spectrum and fit (in a worker thread: touches nothing of the bridge's)."""
        x = np.concatenate(run.tune)
        sens = run.start.get("sensitivity_m_per_V") or 1.0
        if "vDeflection_V" in run.names:
            x = x * sens
        scene = run.start.get("scene") or {}
        out = {"run_id": run.run_id, "samples": len(x), "fit": None, "fit_error": None}
        try:
            from scipy.signal import welch
            nper = min(len(x), 1 << max(8, int(math.log2(max(len(x), 256) / 64))))
            f, p = welch(x, fs=run.fs, nperseg=nper)
            keep = np.unique(np.geomspace(1, len(f) - 1, 600).astype(int))
            out["f_Hz"], out["psd_m2_per_Hz"] = f[keep].tolist(), p[keep].tolist()
            kT = K_B * scene.get("T_K", 300.0)
            mean = scene.get("antialias", "mean") == "mean"
            fit = fit_tune(x, run.fs, kT, mean)
            out["fit"] = {k: float(fit[k]) for k in ("k", "f0", "Q", "k_err", "f0_err", "Q_err", "k_equipartition")}
            out["fit_psd"] = sampled_psd(f[keep], fit["k"], fit["f0"], fit["Q"], kT, run.fs, mean).tolist()
        except Exception as e:  # noqa: BLE001 - a fit that does not converge is shown as such, not raised
            out["fit_error"] = f"{type(e).__name__}: {e}"
        return clean_json(out)

    def tune_done(self, fut):
        if fut.cancelled():
            return
        e = fut.exception()
        if e is not None:
            self.broadcast_json({"type": "panel_error", "message": f"tune spectrum: {type(e).__name__}: {e}"})
            return
        self.tune_result = fut.result()
        self.broadcast_json({"type": "tune", "tune": self.tune_result})

    # ---- to the browsers ---------------------------------------------------------------------------------
    def flush(self):
        if not self.frame_buf:
            return
        by_run = collections.OrderedDict()
        for rid, cols, arrays, seq, tr in self.frame_buf:
            by_run.setdefault(rid, []).append((cols, arrays, seq, tr))
        self.frame_buf = []
        for rid, items in by_run.items():
            cols = items[0][0]
            arrays = [np.concatenate([it[1][k] for it in items]) for k in range(len(cols))]
            meta = {"type": "data", "run_id": rid, "cols": cols, "n": len(arrays[0]),
                    "seqs": [it[2] for it in items], "t_recv": [it[3] for it in items]}
            frame = encode_frame(meta, arrays)
            run = self.runs.get(rid)
            if run is not None and run.npoints < MAX_RUN_POINTS:
                run.points.append(frame)
                run.npoints += meta["n"]
            self.stats["frames"] += 1
            for v in list(self.viewers):
                v.put(frame, data=True)

    def broadcast_json(self, obj):
        s = json.dumps(obj)
        for v in list(self.viewers):
            v.put(s)

    def snapshot(self, v):
        """What a browser that joins now needs: hello, the last curves, the run in progress, map, faults
        (queued whole: a snapshot is never dropped)."""
        def put(m):
            v.put(m, force=True)

        put(json.dumps({"type": "hello", "hello": self.hello, "commands": sorted(self.commands),
                          "t0_epoch": self.t0, "bridge": self.bridge_info()}))
        if self.status:
            put(json.dumps({"type": "status", "status": self.status, "bridge": self.bridge_info()}))
        for start, end, frames in self.curves:
            put(json.dumps({"type": "run.start", "msg": start, "history": True}))
            for f in frames:
                put(f)
            put(json.dumps({"type": "run.end", "msg": clean_json(end), "history": True}))
        for _, f in self.live_frames:
            put(f)
        for run in self.runs.values():
            put(json.dumps({"type": "run.start", "msg": run.start, "B": run.B}))
            for f in run.points:
                put(f)
        if self.map:
            put(json.dumps({"type": "map", "map": self.map_public(), "pixel": None}))
        if self.tune_result:
            put(json.dumps({"type": "tune", "tune": self.tune_result}))
        for f in self.faults:
            put(json.dumps({"type": "faults", "msg": clean_json(f), "history": True}))

    async def ctl_with_units(self, cmd, args):
        """A command typed as KEY=VALUE words with units ("x_m=2um", "speed_m_per_s=1um/s", "setpoint=1nN"):
        `vafm ctl CMD KEY=VALUE...` converts them (the CLI's units, one place) and sends it; its reply, ok or
        the daemon's error, comes back as it is. Only a command of hello's (less NOT_FORWARDED) is sent."""
        if not isinstance(cmd, str) or cmd not in self.commands:
            return {"status": "error", "code": "unknown_command", "field": "cmd",
                    "message": f"{cmd}: not a command this panel forwards (hello's capabilities)"}
        if not isinstance(args, list) or len(args) > 16 or not all(
                isinstance(w, str) and len(w) <= 200 and "=" in w and w[0].isalpha() for w in args):
            return {"status": "error", "code": "malformed", "field": None,
                    "message": "arguments are KEY=VALUE words, e.g. x_m=1um y_m=0 speed_m_per_s=2um/s"}
        return await self.run_ctl(cmd, args)

    async def run_ctl(self, cmd, words):
        """`vafm ctl CMD WORDS...` (an argv list: no shell), or without --vafm the words as JSON numbers."""
        if not self.a.vafm:
            req = {"cmd": cmd}
            vals = {}
            for w in words:
                k, _, v = w.partition("=")
                try:
                    vals[k] = json.loads(v)
                except ValueError:
                    vals[k] = v
            if cmd == "set":
                req["values"] = vals
            else:
                req.update(vals)
            return await self.request(req)
        proc = await asyncio.create_subprocess_exec(
            self.a.vafm, "ctl", "--rep", self.a.daemon, *(["--pub", self.pub] if self.pub else []),
            *(["--curve", self.a.curve] if self.a.curve else []), cmd, *words,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        out, err = await asyncio.wait_for(proc.communicate(), 30)
        for blob in (out, err):
            txt = blob.decode("utf-8", "replace")
            try:
                j = json.loads(txt[txt.index("{"):])
                if isinstance(j, dict) and "status" in j:
                    return j
            except ValueError:
                pass
        return {"status": "error", "code": "transport", "field": None,
                "message": (err or out).decode("utf-8", "replace").strip() or f"vafm ctl exited {proc.returncode}"}

    async def set_with_units(self, text):
        """`set` typed as NAME=VALUE... with units ("2um/s", "1nN"): the CLI's own parser converts them
        (`vafm ctl set`, one place for units), and its reply, ok or the daemon's error, comes back as it is."""
        words = text.split()
        if not words or not all("=" in w for w in words):
            return {"status": "error", "code": "malformed", "field": None,
                    "message": "type NAME=VALUE pairs separated by spaces, e.g. v_approach_m_per_s=2um/s setpoint_N=1nN"}
        return await self.run_ctl("set", words)

    # ---- HTTP and WebSocket ------------------------------------------------------------------------------
    def authorised(self, request):
        if self.a.token is None:
            return True
        got = request.query.get("token", "")
        return hmac.compare_digest(got.encode(), self.a.token.encode())

    async def page(self, request):
        if not self.authorised(request):
            raise web.HTTPForbidden(text="vafm web: this panel needs ?token=... (printed when it started)")
        return web.FileResponse(os.path.join(HERE, "static", "index.html"))

    async def ws(self, request):
        if not self.authorised(request):
            raise web.HTTPForbidden(text="vafm web: token required")
        ws = web.WebSocketResponse(heartbeat=20, max_msg_size=1 << 16)
        await ws.prepare(request)
        v = Viewer(ws, self.a.queue)
        self.snapshot(v)
        self.viewers.add(v)
        pump = asyncio.ensure_future(v.pump())
        try:
            async for msg in ws:
                if msg.type != WSMsgType.TEXT:
                    continue
                try:
                    m = json.loads(msg.data)
                    reply = await self.on_command(m)
                    v.put(json.dumps({"type": "reply", "id": m.get("id"), "reply": reply}))
                except (ValueError, AttributeError) as e:
                    v.put(json.dumps({"type": "panel_error", "message": f"bad message from the page: {e}"}))
        finally:
            self.viewers.discard(v)
            pump.cancel()
        return ws

    async def on_command(self, m):
        if m.get("type") == "set_text":
            return await self.set_with_units(str(m.get("text", "")))
        if m.get("type") == "ctl":
            return await self.ctl_with_units(m.get("cmd"), m.get("args"))
        req = m.get("request")
        if not isinstance(req, dict) or not isinstance(req.get("cmd"), str):
            return {"status": "error", "code": "malformed", "field": "cmd", "message": "a request needs \"cmd\""}
        if req["cmd"] not in self.commands:
            why = "not sent by the panel (start it with --allow-shutdown)" if req["cmd"] in NOT_FORWARDED else \
                "not a command of this daemon (hello's capabilities)"
            return {"status": "error", "code": "unknown_command", "field": "cmd", "message": f"{req['cmd']}: {why}"}
        return await self.request(req)

    async def vendor(self, request):
        name = request.match_info["name"]
        files = {"uPlot.iife.min.js": "uPlot.iife.min.js", "uPlot.min.css": "uPlot.min.css"}
        if name not in files:
            raise web.HTTPNotFound()
        path = os.path.join(self.a.uplot_dir, files[name])
        if not os.path.exists(path):
            raise web.HTTPNotFound(text=f"vafm web: {path} is missing: run `npm ci` in clients/web (make deps does)")
        return web.FileResponse(path)

    async def static(self, request):
        name = request.match_info["name"]
        if name not in ("panel.js", "panel.css"):
            raise web.HTTPNotFound()
        return web.FileResponse(os.path.join(HERE, "static", name))


def parse_listen(s):
    host, _, port = s.rpartition(":")
    host = host.strip("[]") or "127.0.0.1"
    if not port.isdigit() or int(port) > 65535:
        raise ValueError(s)
    return host, int(port)


def is_loopback(host):
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def load_curve(ap, path):
    """The three Z85 keys of a --curve file (the format of vafm ctl --curve), or a usage error naming it."""
    names = ("server_public_key", "public_key", "secret_key")
    try:
        with open(path) as fh:
            j = json.load(fh)
        keys = tuple(j[n].encode("ascii") for n in names)
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as e:
        ap.error(f"--curve {path}: needs JSON with {', '.join(names)} (Z85): {type(e).__name__}: {e}")
    if not all(len(k) == 40 for k in keys):
        ap.error(f"--curve {path}: {', '.join(names)} must be 40-character Z85 keys")
    return keys


def main(argv=None):
    ap = argparse.ArgumentParser(prog="vafm web", description="The live web panel of a running vafmd (docs/web.md).")
    ap.add_argument("--daemon", default="tcp://127.0.0.1:5555", help="the daemon's command endpoint (default %(default)s)")
    ap.add_argument("--pub", help="its stream endpoint (default: the one hello names)")
    ap.add_argument("--listen", default="127.0.0.1:8080", help="HOST:PORT of the panel (default %(default)s; port 0: any free)")
    ap.add_argument("--token", help="required on a non-loopback address (one is generated if not given)")
    ap.add_argument("--curve", metavar="FILE", help="CURVE keys for a daemon with curve_secret_key, as for vafm ctl: "
                    'JSON {"server_public_key": Z85, "public_key": Z85, "secret_key": Z85}')
    ap.add_argument("--vafm", help="the vafm CLI, to convert values typed with units (vafm web passes itself)")
    ap.add_argument("--uplot-dir", default=os.path.join(HERE, "node_modules", "uplot", "dist"),
                    help="uPlot's dist folder (default: npm ci's, in clients/web)")
    ap.add_argument("--columns-per-block", type=int, default=32, help="display columns per data block (default %(default)s)")
    ap.add_argument("--live-columns-per-s", type=float, default=100.0,
                    help="display columns per second of the live scope (default %(default)s: 10 s on 1000 columns)")
    ap.add_argument("--queue", type=int, default=64, help="frames queued per browser before the oldest data frame is dropped")
    ap.add_argument("--allow-shutdown", action="store_true", help="let the panel send `shutdown`")
    ap.add_argument("--connect-timeout", type=float, default=10.0, help="seconds to wait for the daemon's hello")
    ap.add_argument("--ready-file", help="write the panel's URL here once it listens (for scripts and tests)")
    a = ap.parse_args(argv)
    if not 1 <= a.columns_per_block <= 4096:
        ap.error("--columns-per-block: allowed range [1, 4096]")
    if not 1 <= a.live_columns_per_s <= 1e5:
        ap.error("--live-columns-per-s: allowed range [1, 1e5]")
    if not 2 <= a.queue <= 100000:
        ap.error("--queue: allowed range [2, 100000]")
    a.curve_keys = load_curve(ap, a.curve) if a.curve else None
    try:
        host, port = parse_listen(a.listen)
    except ValueError:
        ap.error(f"--listen {a.listen}: needs HOST:PORT, PORT in [0, 65535]")
    if not is_loopback(host) and not a.token:
        a.token = secrets.token_urlsafe(18)
    asyncio.run(serve(a, host, port))


async def serve(a, host, port):
    b = Bridge(a)
    await b.connect()
    app = web.Application()
    app.router.add_get("/", b.page)
    app.router.add_get("/ws", b.ws)
    app.router.add_get("/vendor/{name}", b.vendor)
    app.router.add_get("/static/{name}", b.static)
    runner = web.AppRunner(app, access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, host, port)
    await site.start()
    real_port = site._server.sockets[0].getsockname()[1]
    url = f"http://{'[' + host + ']' if ':' in host else host}:{real_port}/" + (f"?token={a.token}" if a.token else "")
    print(f"vafm web: panel of {a.daemon} at {url} (bridge {os.path.abspath(__file__)})", flush=True)
    if a.ready_file:
        tmp = a.ready_file + ".tmp"
        with open(tmp, "w") as fh:
            fh.write(url + "\n")
        os.replace(tmp, a.ready_file)
    tasks = [asyncio.ensure_future(t) for t in (b.stream_loop(), b.status_loop(), b.flush_loop())]
    try:
        await asyncio.gather(*tasks)
    finally:
        await runner.cleanup()


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:
        pass
