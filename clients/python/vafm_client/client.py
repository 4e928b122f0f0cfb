# SPDX-License-Identifier: MIT
"""Client (commands) and Stream (sample stream) of vafmd; see the package docstring and protocol/wire.md."""
import json
import os
import struct
import time
from collections import namedtuple

import numpy as np
import zmq

DEFAULT_REP = "tcp://127.0.0.1:5555"
DEFAULT_PUB = "tcp://127.0.0.1:5556"
PROTOCOL_VERSION = 1
MAGIC = 0x4D464156  # the bytes V A F M
HEADER = struct.Struct("<IHHQQQQIHHdqII")  # wire.md §4: 72 bytes, little-endian, no padding
CHANNELS = ("height_m", "deflection_m", "force_N", "vDeflection_V", "tip_m")
SEGMENTS = {"approach": 0, "retract": 1, "dwell": 2, "tune": 3}
FLAG_LATE, FLAG_SEG_CHANGE, FLAG_LAST, FLAG_FREE_RUN, FLAG_CLIPPED = 1, 2, 4, 8, 16

Header = namedtuple("Header", "magic version header_size seq run_id block_index first_sample n_samples "
                              "n_channels segment sample_rate_Hz t0_ns flags reserved")


class DaemonError(Exception):
    """An error reply: `code` is the daemon's stable code (wire.md §2.2), `field` the offending key or None."""

    def __init__(self, reply):
        self.reply = reply
        self.code = reply.get("code", "internal")
        self.field = reply.get("field")
        self.message = reply.get("message", "")
        super().__init__(f"{self.code}: {self.message}" + (f" (field {self.field})" if self.field else ""))


class TransportError(Exception):
    """No reply within the timeout (after the retries), or a message that does not follow the protocol."""


class GapError(Exception):
    """Data blocks were lost (a jump in the header's seq): the run is incomplete."""


class TruncatedError(GapError):
    """The run never got its run.end (the stream stopped mid-run, or the publisher restarted during it):
    the run is incomplete."""


def decode_header(buf):
    """Decode a data header (bytes of at least 72). Raises TransportError on a bad magic or version."""
    if len(buf) < HEADER.size:
        raise TransportError(f"data header of {len(buf)} bytes, expected at least {HEADER.size}")
    h = Header(*HEADER.unpack_from(buf))
    if h.magic != MAGIC or h.version != PROTOCOL_VERSION or not HEADER.size <= h.header_size <= len(buf):
        raise TransportError(f"bad data header (magic {h.magic:#x}, version {h.version}, size {h.header_size})")
    return h


def _apply_curve(sock, curve):
    """curve = (server_public, client_public, client_secret), Z85 str/bytes (protocol/wire.md §1.1)."""
    if curve is None:
        return
    server_public, client_public, client_secret = (k.encode() if isinstance(k, str) else k for k in curve)
    sock.curve_serverkey = server_public
    sock.curve_publickey = client_public
    sock.curve_secretkey = client_secret


# Commands a resend cannot change anything with (a start is made idempotent by its client_run_id).
_IDEMPOTENT = {"hello", "get", "status", "presets"}


class _Endpoint:
    """A socket of ours (`sock`) on a ZeroMQ context, the caller's or our own; a context manager. close()
    closes the socket and terminates the context if it is ours."""

    def __init__(self, context):
        self._own_ctx = context is None
        self.ctx = context or zmq.Context()
        self.sock = None

    def close(self):
        if self.sock is not None:
            self.sock.close(0)
            self.sock = None
        if self._own_ctx:
            self.ctx.term()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class Client(_Endpoint):
    """Commands over a REQ socket. Every method returns the reply dict or raises DaemonError/TransportError.

    Lazy pirate: a lost reply (no reply within `timeout`) closes and reopens the REQ socket and resends the
    request, at most `retries` times, but only when a resend is safe: read-only commands (hello, get, status,
    presets, a faults query) and starts that carry a client_run_id (the daemon answers a repeated one with
    the same run, "duplicate": true). `curve`, `tune` and `campaign` give every start a client_run_id of
    their own unless one is passed. A `busy` error reply (the daemon asks for a retry) is retried after a
    short pause, `busy_retries` times. `log` records what happened (timeouts, reopened sockets, retries)."""

    def __init__(self, endpoint=DEFAULT_REP, timeout=10.0, retries=2, context=None, curve=None, busy_retries=5):
        """curve: (server_public, client_public, client_secret) Z85 keys for a daemon with CURVE; a daemon
        that refuses them sends nothing, so requests time out (TransportError)."""
        self.endpoint, self.timeout, self.retries, self._curve_keys = endpoint, timeout, retries, curve
        self.busy_retries = busy_retries
        self.log = []  # (time.monotonic(), text) of every timeout, reopen and retry
        self._run_ids = 0
        super().__init__(context)
        self._open()

    def _open(self):
        if self.sock is not None:
            self.sock.close(0)
        self.sock = self.ctx.socket(zmq.REQ)
        self.sock.setsockopt(zmq.LINGER, 0)
        _apply_curve(self.sock, self._curve_keys)
        self.sock.connect(self.endpoint)

    @staticmethod
    def idempotent(obj):
        """May this request be sent again when its reply was lost?"""
        return obj.get("cmd") in _IDEMPOTENT or obj.get("client_run_id") is not None or \
            (obj.get("cmd") == "faults" and set(obj) <= {"cmd", "id"})

    def new_client_run_id(self):
        """A client_run_id unique to this client (a retried start with it is answered, not run again)."""
        self._run_ids += 1
        if not hasattr(self, "_token"):
            self._token = os.urandom(4).hex()
        return f"py-{self._token}-{self._run_ids}"

    def request(self, obj, timeout=None, retries=None):
        """Send one command (a dict with "cmd") and return its ok reply; raise DaemonError on an error reply,
        TransportError when no reply came (after the retries a non-idempotent request does not get)."""
        timeout = self.timeout if timeout is None else timeout
        retries = self.retries if retries is None else retries
        if not self.idempotent(obj):
            retries = 0
        data = json.dumps(obj).encode()
        attempt = busy = 0
        while True:
            self.sock.send(data)
            if self.sock.poll(int(timeout * 1000)):
                reply = json.loads(self.sock.recv())
                if not isinstance(reply, dict):
                    raise TransportError("reply is not a JSON object")
                if reply.get("status") == "error" and reply.get("code") == "busy" and busy < self.busy_retries:
                    busy += 1
                    self.log.append((time.monotonic(), f"{obj.get('cmd')}: busy, retry {busy}"))
                    time.sleep(0.02 * busy)
                    continue
                if reply.get("status") != "ok":
                    raise DaemonError(reply)
                return reply
            # lazy pirate: a REQ socket still waiting for its reply cannot send again: close, reopen
            self._open()
            self.log.append((time.monotonic(), f"{obj.get('cmd')}: no reply within {timeout} s, socket reopened"
                             + (", resending" if attempt < retries else "")))
            attempt += 1
            if attempt > retries:
                break
        raise TransportError(f"no reply from {self.endpoint} within {timeout} s ({attempt} attempt(s)"
                             + ("" if self.idempotent(obj) else "; not resent: not idempotent") + ")")

    def hello(self):
        return self.request({"cmd": "hello"})

    def status(self):
        return self.request({"cmd": "status"})

    def presets(self):
        return self.request({"cmd": "presets"})["presets"]

    def get(self, *names, info=False):
        """Values of the named parameters/settings (all without names) as a dict; with info, (values, info)."""
        req = {"cmd": "get"}
        if names:
            req["names"] = list(names)
        if info:
            req["info"] = True
        r = self.request(req)
        return (r["values"], r["info"]) if info else r["values"]

    def set(self, values=None, preset=None, **kw):
        """set(preset="paper-fig4", k_N_per_m=0.1) or set({"k_N_per_m": 0.1}); returns "now"/"next_run"."""
        vals = dict(values or {}, **kw)
        req = {"cmd": "set"}
        if preset is not None:
            req["preset"] = preset
        if vals:
            req["values"] = vals
        return self.request(req)["applies_to"]

    def curve(self, index=0, client_run_id=None, segments=None):
        """One force curve; `segments` (a list of segment dicts, wire.md "curve") runs a segment list instead."""
        req = {"cmd": "curve", "index": index, "client_run_id": client_run_id or self.new_client_run_id()}
        if segments is not None:
            req["segments"] = segments
        return self.request(req)

    def tune(self, duration_s=None, index=0, client_run_id=None):
        req = {"cmd": "tune", "index": index, "client_run_id": client_run_id or self.new_client_run_id()}
        if duration_s is not None:
            req["duration_s"] = duration_s
        return self.request(req)

    def faults(self, plan=None, clear=False, **kw):
        """Set (plan: a dict, protocol/faults.md), clear, or (neither) query the daemon's fault plan. Returns
        the reply: the plan in force, the count of faults injected and the last ones."""
        req = {"cmd": "faults"}
        if clear:
            req["clear"] = True
        if plan is not None or kw:
            req["plan"] = dict(plan or {}, **kw)
        return self.request(req)

    # ---- the always-on controller (protocol/wire.md: engage, withdraw, move, z, feedback; topic "live") ----
    @staticmethod
    def _at(req, at_s):
        if at_s is not None:
            req["at_s"] = at_s
        return req

    def engage(self, at_s=None):
        """Start the auto-approach; the event `engaged` (or `engage_failed`, `crash`) on the stream ends it.
        at_s: apply at that controller time (s) instead of now. Returns the reply (its "ctrl" is the status)."""
        return self.request(self._at({"cmd": "engage"}, at_s))

    def withdraw(self, motor_steps=0, at_s=None):
        """Feedback off, piezo retracted, then the motor up motor_steps steps (event `withdrawn`)."""
        return self.request(self._at({"cmd": "withdraw", "motor_steps": motor_steps}, at_s))

    def move(self, x_m, y_m, speed_m_per_s=None, at_s=None):
        """Move the tip to (x_m, y_m) (event `moved`); speed None: the controller's ctrl_xy_speed_m_per_s."""
        req = {"cmd": "move", "x_m": x_m, "y_m": y_m}
        if speed_m_per_s is not None:
            req["speed_m_per_s"] = speed_m_per_s
        return self.request(self._at(req, at_s))

    def z(self, z_m, at_s=None):
        """Feedback off, the piezo to extension z_m (event `z_reached`)."""
        return self.request(self._at({"cmd": "z", "z_m": z_m}, at_s))

    def feedback(self, on=None, setpoint=None, unit=None, relative=None, p_m_per_N=None, i_m_per_N_s=None,
                 tau_s=None, at_s=None):
        """Feedback on/off and/or its setpoint (unit "N" or "V", relative True/False) and gains."""
        req = {"cmd": "feedback"}
        for k, v in (("on", on), ("setpoint", setpoint), ("unit", unit), ("relative", relative),
                     ("p_m_per_N", p_m_per_N), ("i_m_per_N_s", i_m_per_N_s), ("tau_s", tau_s)):
            if v is not None:
                req[k] = v
        return self.request(self._at(req, at_s))

    def wait_idle(self, timeout=30.0, poll=0.005):
        """Wait until the daemon is idle and return its status. Needed between runs: run.end is published
        before the daemon's state returns to idle, so a start right after it may get a `state` error."""
        deadline = time.monotonic() + timeout
        while True:
            st = self.status()
            if st["state"] == "idle":
                return st
            if time.monotonic() > deadline:
                raise TransportError(f"daemon still {st['state']} after {timeout} s")
            time.sleep(poll)

    def abort(self):
        return self.request({"cmd": "abort"})

    def shutdown(self):
        return self.request({"cmd": "shutdown"})


class Run:
    """One run as received: `start`/`end` (the JSON messages), `events`, `headers`, the channels as numpy
    arrays (`run["force_N"]`, `run.channels`), `segment` (per sample), `time_s` and `gaps` (blocks lost)."""

    def __init__(self, run_id):
        self.run_id = run_id
        self.start = self.end = None
        self.events, self.headers, self._blocks = [], [], []
        self.gaps = 0
        self.channels = {}
        self.segment = self.time_s = None
        self.truncated = False   # no run.end came: the stream stopped mid-run (a later run or heartbeat says so)
        self.restarted = False   # the publisher restarted (new session) while the run was being received
        self.nan_samples = 0     # samples whose measured signals are NaN (detector dropout): kept as they are
        self.clipped_blocks = 0  # blocks flagged CLIPPED (ADC saturation): kept as they are
        self.warnings = []       # what is wrong with the run, in words

    @property
    def complete(self):
        """All of the run arrived, as it was sent (it may still carry NaN or clipped samples: `warnings`)."""
        return self.start is not None and self.end is not None and self.gaps == 0 and not self.truncated and \
            not self.restarted and sum(h.n_samples for h in self.headers) == self.end["samples"]

    @property
    def clean(self):
        """Complete, and no sample is NaN and no block clipped."""
        return self.complete and not self.nan_samples and not self.clipped_blocks

    def __getitem__(self, name):
        return self.channels[name]

    def _finish(self):
        names = [c["name"] for c in self.start["channels"]] if self.start else list(CHANNELS)
        for k, name in enumerate(names):
            parts = [b[k] for b in self._blocks if k < len(b)]
            self.channels[name] = np.concatenate(parts) if parts else np.empty(0)
        self._blocks = []
        n = sum(h.n_samples for h in self.headers)
        seg = np.empty(n, dtype=np.int64)
        pos = 0
        for h in self.headers:  # the header gives a block's first segment; events the changes inside it
            seg[pos:pos + h.n_samples] = h.segment
            pos += h.n_samples
        for e in self.events:
            if e.get("kind") == "segment" and e.get("sample") is not None and e["to"] in SEGMENTS:
                lim = next((h.first_sample + h.n_samples for h in self.headers
                            if h.first_sample <= e["sample"] < h.first_sample + h.n_samples), n)
                seg[e["sample"]:lim] = SEGMENTS[e["to"]]
        if "segment" in self.channels and len(self.channels["segment"]) == n:  # the per-sample channel (opt-in)
            seg = self.channels["segment"].astype(np.int64)
        self.segment = seg
        # measured signals are recorded as they came: a detector dropout stays NaN, a saturation clipped
        meas = [self.channels[k] for k in ("vDeflection_V", "deflection_m", "force_N") if k in self.channels]
        if meas and n:
            self.nan_samples = int(np.isnan(np.vstack(meas)).any(axis=0).sum())
        self.clipped_blocks = sum(1 for h in self.headers if h.flags & FLAG_CLIPPED)
        if self.gaps:
            self.warnings.append(f"{self.gaps} data block(s) lost (sequence gap)")
        if self.truncated:
            self.warnings.append("no run.end: the stream stopped mid-run (truncated)")
        if self.restarted:
            self.warnings.append("the publisher restarted (new session) during the run")
        if self.nan_samples:
            self.warnings.append(f"{self.nan_samples} sample(s) with NaN measured signals (detector dropout), "
                                 "kept as NaN")
        if self.clipped_blocks:
            self.warnings.append(f"{self.clipped_blocks} block(s) flagged CLIPPED (ADC saturation)")
        if self.start:
            fs = self.start["sample_rate_Hz"]
            # the time `vafm samples` prints: interval centre with antialias=mean, end with point (csv.md)
            off = 1.0 if self.start.get("scene", {}).get("antialias") == "point" else 0.5
            self.time_s = (np.arange(n) + off) / fs


class Stream(_Endpoint):
    """The sample stream over a SUB socket. Subscribes at construction and waits for the daemon's greeting
    heartbeat, so a run started afterwards is seen from its first message. Counts lost data blocks (gaps in
    seq) in `gaps`."""

    def __init__(self, endpoint=DEFAULT_PUB, timeout=20.0, rcvhwm=None, context=None, curve=None, stall_s=1.5,
                 live=False):
        """stall_s: a wait of this long with no message at all (heartbeats come at 1 Hz) is reported as a
        stall of the publisher (`reports`), once it ends; `timeout` still bounds any wait. live: messages()
        also yields the controller's "live" topic as ("live", (header dict, {channel name: numpy array}))."""
        self.endpoint, self.timeout, self.stall_s, self.live = endpoint, timeout, stall_s, live
        self.session = None  # the publisher's session (heartbeats, data headers): a change is a restart
        self.reports = []    # detected faults: dicts with "kind" gap|truncated|restart|stall|dropout|saturate
        super().__init__(context)
        self.sock = self.ctx.socket(zmq.SUB)
        self.sock.setsockopt(zmq.LINGER, 0)
        if rcvhwm is not None:
            self.sock.setsockopt(zmq.RCVHWM, rcvhwm)
        self.sock.setsockopt(zmq.SUBSCRIBE, b"")
        if live:  # the daemon sends "live" only to a subscription to it by name (wire.md §3.7), not to ""
            self.sock.setsockopt(zmq.SUBSCRIBE, b"live")
        _apply_curve(self.sock, curve)
        self.sock.connect(endpoint)
        self.last_seq, self.gaps = None, 0
        self._pending = {}
        try:  # the daemon greets each new subscription with a heartbeat: then it is in place
            for topic, _ in self.messages(timeout):
                if topic == "heartbeat":
                    break
        except BaseException:
            self.close()
            raise

    def _session(self, new):
        """A session seen (heartbeat, data header): None, or the restart it reveals (also reported)."""
        if not new:
            return None  # a daemon without sessions
        old, self.session = self.session, new
        if old is None or old == new:
            return None
        rep = {"kind": "restart", "old_session": old, "new_session": new, "last_seq": self.last_seq}
        self.reports.append(rep)
        self.last_seq = None  # sequence numbers start again: no gap across a restart
        return rep

    def messages(self, timeout=None, deadline=None):
        """Yield (topic, payload): for "data" (Header, [numpy arrays], gap), else the decoded JSON; and the
        client's own findings as topics "restart" (the publisher's session changed: its sequence numbers
        started again) and "stall" (no message for stall_s or more, heartbeats included).
        Raises TransportError when nothing arrives within `timeout` seconds, or at the time.monotonic()
        `deadline` (heartbeats never let the stream fall silent, so a lost run.end needs a deadline)."""
        timeout = self.timeout if timeout is None else timeout
        while True:
            wait = timeout if deadline is None else min(timeout, deadline - time.monotonic())
            t0 = time.monotonic()
            if wait <= 0 or not self.sock.poll(int(wait * 1000)):
                silent = time.monotonic() - t0
                raise TransportError(f"stream {self.endpoint}: nothing expected within {timeout} s"
                                     + (f" (no message at all for {silent:.1f} s, heartbeats included: the "
                                        "publisher stalls or is gone)" if silent >= self.stall_s else ""))
            parts = self.sock.recv_multipart()
            topic = parts[0].decode("ascii", "replace")
            if topic == "data":
                h = decode_header(parts[1])
                chans = [np.frombuffer(p, "<f8") for p in parts[2:2 + h.n_channels]]
                if len(chans) != h.n_channels or any(len(c) != h.n_samples for c in chans):
                    raise TransportError(f"data block {h.seq}: frames do not match the header")
                restart = self._session(h.reserved)  # the header's last field carries the session
                if restart:
                    yield "restart", restart
                gap = 0
                if self.last_seq is not None and h.seq > self.last_seq + 1:
                    gap = h.seq - self.last_seq - 1
                    self.gaps += gap
                    self.reports.append({"kind": "gap", "run_id": h.run_id, "blocks": gap, "seq": self.last_seq + 1})
                if self.last_seq is None or h.seq > self.last_seq:
                    self.last_seq = h.seq
                yield topic, (h, chans, gap)
            elif topic in ("run.start", "run.end", "event", "heartbeat", "campaign.end", "faults"):
                p = json.loads(parts[1])
                if topic == "heartbeat":
                    restart = self._session(p.get("session"))
                    if restart:
                        yield "restart", restart
                    # heartbeats keep a 1 s grid of the daemon's clock and a stalled publisher skips the
                    # beats it missed: consecutive uptimes stall_s or more apart reveal a stall, also to a
                    # client that was not reading at the time (a restarted daemon's uptime starts again: no false alarm)
                    up = p.get("uptime_s")
                    if isinstance(up, (int, float)):
                        last, self._hb_uptime = getattr(self, "_hb_uptime", None), up
                        if last is not None and up - last >= self.stall_s:
                            rep = {"kind": "stall", "silent_s": up - last, "uptime_s": up}
                            self.reports.append(rep)
                            yield "stall", rep
                yield topic, p
            elif topic == "live" and self.live:  # the always-on controller's monitor (wire.md §3.7)
                h = json.loads(parts[1])
                yield topic, (h, {n: np.frombuffer(p, "<f8") for n, p in zip(h["channels"], parts[2:])})
            # other topics: ignored (wire.md §6)

    def runs(self, timeout=None, include_partial=False, deadline=None):
        """Yield each Run at its run.end. Runs joined mid-way (no run.start seen) are skipped unless
        include_partial. `timeout`, `deadline` as for messages()."""
        for kind, x in self._runs_and(timeout, include_partial, deadline):
            if kind == "run":
                yield x

    def campaign(self, campaign_id, timeout=None, strict=True):
        """Collect the runs of campaign `campaign_id` (run.start's "campaign" object names it) up to its
        campaign.end, waiting at most `timeout` seconds in all. Returns (runs in arrival order, campaign.end).
        With strict, raise GapError if a block of one of its runs was lost."""
        timeout = self.timeout if timeout is None else timeout
        runs = []
        for kind, x in self._runs_and(timeout, False, time.monotonic() + timeout):
            if kind == "run" and (x.start.get("campaign") or {}).get("campaign_id") == campaign_id:
                if strict and not x.complete:
                    raise GapError(f"campaign {campaign_id}: run {x.run_id}: {x.gaps} data block(s) lost")
                runs.append(x)
            elif kind == "campaign.end" and x.get("campaign_id") == campaign_id:
                return runs, x

    def _runs_and(self, timeout, include_partial, deadline):
        """("run", Run) at each run.end (or once a run is known to be truncated) and ("campaign.end", message)."""
        for topic, p in self.messages(timeout, deadline):
            if topic == "restart":  # every run being received lost its continuity
                for run in self._pending.values():
                    run.restarted = True
                continue
            if topic in ("run.start", "heartbeat", "campaign.end"):
                # a run that started and is not the daemon's current one any more, without a run.end: truncated
                # (campaign.end follows the last run.end of a campaign: no run of it is current then)
                cur = p.get("run_id") if topic != "campaign.end" else None
                for rid in [r for r, run in self._pending.items() if run.start is not None and r != cur]:
                    run = self._pending.pop(rid)
                    run.truncated = True
                    self.reports.append({"kind": "truncated", "run_id": rid, "samples": sum(h.n_samples for h in run.headers)})
                    run._finish()
                    yield "run", run
                if topic == "heartbeat":
                    continue
            if topic == "campaign.end":
                yield topic, p
            elif topic == "data":
                h, chans, gap = p
                run = self._pending.setdefault(h.run_id, Run(h.run_id))
                run.gaps += gap
                run.headers.append(h)
                run._blocks.append(chans)
            elif topic in ("run.start", "event", "run.end"):
                run = self._pending.setdefault(p["run_id"], Run(p["run_id"]))
                if topic == "run.start":
                    run.start = run.start or p
                elif topic == "event":
                    run.events.append(p)
                else:
                    run.end = p
                    del self._pending[p["run_id"]]
                    # blocks lost at the end of the run show only in run.end's last_seq
                    if p.get("last_seq") is not None and self.last_seq is not None and p["last_seq"] > self.last_seq:
                        lost = p["last_seq"] - self.last_seq
                        run.gaps += lost
                        self.gaps += lost
                        self.last_seq = p["last_seq"]
                    # run.end is authoritative: this also counts blocks lost before the first one seen
                    run.gaps = max(run.gaps, p.get("blocks", 0) - len(run.headers))
                    if run.gaps and not any(r.get("run_id") == run.run_id and r["kind"] == "gap" for r in self.reports):
                        self.reports.append({"kind": "gap", "run_id": run.run_id, "blocks": run.gaps, "seq": None})
                    if run.start is None and not include_partial:
                        continue
                    run._finish()
                    if run.nan_samples:
                        self.reports.append({"kind": "dropout", "run_id": run.run_id, "samples": run.nan_samples})
                    if run.clipped_blocks:
                        self.reports.append({"kind": "saturate", "run_id": run.run_id, "blocks": run.clipped_blocks})
                    yield "run", run

    def run(self, run_id, timeout=None, strict=True):
        """Collect run `run_id` up to its run.end, waiting at most `timeout` seconds (default the stream's)
        in all (TransportError then, e.g. when its run.end was lost); with strict, raise GapError if any
        block was lost."""
        timeout = self.timeout if timeout is None else timeout
        for run in self.runs(timeout, deadline=time.monotonic() + timeout):
            if run.run_id == run_id:
                if strict and (run.truncated or run.restarted):
                    raise TruncatedError(f"run {run_id}: " + "; ".join(run.warnings))
                if strict and not run.complete:
                    raise GapError(f"run {run_id}: {run.gaps} data block(s) lost")
                return run
