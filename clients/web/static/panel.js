// SPDX-License-Identifier: MIT
// vafm live panel: the page of clients/web/vafm_web.py (docs/web.md). Charts are uPlot's; this file only
// keeps the points the bridge sends (already decimated, min/max per display column) and wires the buttons.
"use strict";

const FRAME_MAGIC = 0x56574641;
const SCOPE_S = 10;
const SEG = {0: "approach", 1: "retract", 2: "dwell", 3: "tune"};
const P = window.vafmPanel = {
  connected: false, hello: null, t0: null, status: null, runs: {}, order: [], curves: [], faults: [],
  replies: [], messages: [], drawLog: [], frames: 0, map: null, tune: null, droppedFrames: 0,
  // the controller's live points (decimated by the bridge; "seq": the live message each came in), the live
  // messages' draw times, the run the stream says is in progress, and every (state, run) the panel showed
  live: {cols: {}, n: 0}, liveDrawLog: [], streamRun: null, stateShown: [],
  // the points the page holds for run `rid`, as plain arrays (the test compares them with the stream)
  points(rid) { const r = this.runs[rid]; return r ? r.cols : null; },
};
const $ = (id) => document.getElementById(id);
let ws = null, reqId = 0, dirty = {scope: false, curve: false}, pendingSeqs = [], pendingLive = [];
const pending = {};

// ---- the WebSocket ---------------------------------------------------------------------------------------
function connect() {
  const tok = new URLSearchParams(location.search).get("token");
  ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws` + (tok ? `?token=${encodeURIComponent(tok)}` : ""));
  ws.binaryType = "arraybuffer";
  ws.onopen = () => { P.connected = true; $("conn").textContent = "connected"; $("conn").className = "ok"; };
  ws.onclose = () => { P.connected = false; $("conn").textContent = "disconnected: reload to retry"; $("conn").className = "bad"; };
  ws.onmessage = (ev) => {
    if (typeof ev.data === "string") onJson(JSON.parse(ev.data));
    else onFrame(ev.data);
  };
}

function send(request, label) {
  const id = ++reqId;
  pending[id] = label || request.cmd;
  ws.send(JSON.stringify({type: "cmd", id, request}));
  return id;
}

function sendSet(text) {
  const id = ++reqId;
  pending[id] = "set";
  ws.send(JSON.stringify({type: "set_text", id, text}));
}

function message(text, error) {
  P.messages.push({text, error: !!error});
  const li = document.createElement("li");
  li.textContent = text;
  if (error) li.className = "error";
  const ul = $("messages");
  ul.prepend(li);
  while (ul.children.length > 50) ul.lastChild.remove();
}

// ---- messages from the bridge ----------------------------------------------------------------------------
function runOf(rid) {
  if (!P.runs[rid]) {
    P.runs[rid] = {start: null, end: null, cols: {}, n: 0, t0: null, t1: null};
    P.order.push(rid);
    while (P.order.length > 64) delete P.runs[P.order.shift()];
  }
  return P.runs[rid];
}

function onJson(m) {
  switch (m.type) {
  case "hello":
    P.hello = m.hello; P.t0 = m.t0_epoch; P.commands = m.commands;
    $("daemon").textContent = `${m.hello.daemon} ${m.hello.daemon_version} at ${m.bridge.daemon}`;
    send({cmd: "presets"}, "presets");
    for (const [id, cmd] of [["btn-engage", "engage"], ["btn-withdraw", "withdraw"], ["btn-move", "move"], ["btn-z", "z"],
      ["btn-fb-on", "feedback"], ["btn-fb-off", "feedback"], ["btn-fb-setpoint", "feedback"]]) {
      $(id).disabled = !m.commands.includes(cmd);
      if ($(id).disabled) $(id).title = `${cmd}: not a command of this daemon`;
    }
    break;
  case "status":
    P.status = m.status; P.bridge = m.bridge; P.droppedFrames = m.dropped_frames || 0;
    drawState();
    break;
  case "reply": {
    const label = pending[m.id] || "?";
    delete pending[m.id];
    const r = m.reply;
    P.replies.push({label, reply: r});
    if (label === "presets" && r.status === "ok") {
      $("preset").innerHTML = "";
      for (const p of r.presets) { const o = document.createElement("option"); o.textContent = p.name; o.title = p.description; $("preset").append(o); }
      break;
    }
    if (r.status === "ok") message(`${label}: ok` + (r.run_id ? ` (run ${r.run_id})` : "") + (r.applies_to ? ` (${r.applies_to})` : ""));
    else message(`${label}: ${r.code}: ${r.message}` + (r.field ? ` (field ${r.field})` : ""), true);
    break;
  }
  case "run.start": {
    const s = m.msg, r = runOf(s.run_id);
    r.start = s; r.history = !!m.history;
    if (s.kind === "curve" || s.kind === "replay") P.current = s.run_id;
    if (!m.history && !r.end) { P.streamRun = s.run_id; drawState(); }  // shown at once, not at the next poll
    dirty.curve = true;
    break;
  }
  case "run.end": {
    const e = m.msg, r = runOf(e.run_id);
    r.end = e; r.t1 = r.t1 || (m.t != null ? m.t : nowT());  // the bridge's time of the run.end (history: none)
    if (P.streamRun === e.run_id) { P.streamRun = null; drawState(); }
    if (r.start && r.start.kind === "curve" && !P.curves.includes(e.run_id)) { P.curves.push(e.run_id); if (P.curves.length > 9) P.curves.shift(); }
    if (e.status !== "ok" && !m.history) message(`run ${e.run_id} ${e.status}` + (e.error ? `: ${e.error.message}` : ""), e.status === "error");
    dirty.curve = true;
    break;
  }
  case "faults": {
    const f = m.msg;
    if (P.faults.some((g) => g.n === f.n && g.session === f.session)) break;
    P.faults.push(f);
    const li = document.createElement("li");
    li.textContent = `#${f.n} ${f.kind}` + (f.run_id != null ? ` run ${f.run_id} block ${f.block}` : "") +
      (f.cmd ? ` cmd ${f.cmd}` : "") + ` at ${f.time_s.toFixed(2)} s (${f.source})`;
    $("fault-list").prepend(li);
    break;
  }
  case "map": P.map = m.map; drawMap(); break;
  case "tune": P.tune = m.tune; drawTune(); break;
  case "heartbeat": P.heartbeat = m.msg; break;
  case "event":
    if (m.msg && m.msg.source === "ctrl") {  // the controller's events (wire.md §3.4), as the daemon words them
      const e = m.msg, skip = new Set(["run_id", "source", "kind", "generation", "sample", "time_s"]);
      const detail = Object.keys(e).filter((k) => !skip.has(k)).map((k) => `${k} ${typeof e[k] === "number" ? e[k].toPrecision(4) : JSON.stringify(e[k])}`);
      const bad = ["crash", "engage_failed", "xy_range", "z_saturated", "lost_contact", "sim_error", "ctrl_refused", "events_dropped"].includes(e.kind);
      message(`controller: ${e.kind}` + (detail.length ? ` (${detail.join(", ")})` : "") + ` at ${(+e.time_s).toFixed(3)} s`, bad);
      P.ctrlEvents = (P.ctrlEvents || []).concat([e]).slice(-200);
    }
    break;
  case "panel_error": message(`panel: ${m.message}`, true); break;
  default: break;
  }
}

function nowT() { return Date.now() / 1000 - (P.t0 || Date.now() / 1000); }

function onFrame(buf) {
  const dv = new DataView(buf);
  if (dv.getUint32(0, true) !== FRAME_MAGIC) return;
  const jl = dv.getUint32(4, true);
  const meta = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 8, jl)));
  let off = 8 + jl;
  const a = {};
  for (const c of meta.cols) { a[c] = new Float64Array(buf, off, meta.n); off += 8 * meta.n; }
  if (meta.type === "live") { onLive(meta, a); return; }
  const r = runOf(meta.run_id);
  for (const c of meta.cols) { if (!r.cols[c]) r.cols[c] = []; const dst = r.cols[c]; for (let k = 0; k < meta.n; k++) dst.push(a[c][k]); }
  r.n += meta.n;
  if (r.t0 === null && meta.n) r.t0 = a.t[0];
  P.frames++;
  scopeAppend(a, meta.n, r);
  pendingSeqs.push(...meta.seqs);
  dirty.scope = dirty.curve = true;
}

const LIVE_KEEP = 200000;
function onLive(meta, a) {
  const L = P.live, cols = meta.cols.concat(["seq"]);
  a.seq = new Float64Array(meta.n).fill(meta.seqs[0]);
  for (const c of cols) { if (!L.cols[c]) L.cols[c] = []; const dst = L.cols[c]; for (let k = 0; k < meta.n; k++) dst.push(a[c][k]); }
  L.n += meta.n;
  if (L.cols.i.length > LIVE_KEEP) for (const c of cols) L.cols[c].splice(0, L.cols[c].length - LIVE_KEEP);
  P.liveState = meta.state; L.L = meta.L;
  // the scope's channels, as the controller names them
  scopeAppend({t: a.t, vDeflection_V: a.signal_V, force_N: a.force_N, height_m: a.piezo_z_m, motor_z_m: a.motor_z_m}, meta.n, {start: {run_id: 0}});
  pendingLive.push(...meta.seqs);
  dirty.scope = true;
}

// ---- scope -----------------------------------------------------------------------------------------------
const scope = {t: [], y: {}, lastRun: null};
const SCOPE_CH = ["vDeflection_V", "force_N", "height_m", "height_measured_m", "motor_z_m"];
for (const c of SCOPE_CH) scope.y[c] = [];

function scopeAppend(a, n, r) {
  const rid = r.start ? r.start.run_id : null;
  if (scope.lastRun !== rid && scope.t.length) {  // a gap between runs: break the line
    scope.t.push(a.t[0] - 1e-6); for (const c of SCOPE_CH) scope.y[c].push(null);
  }
  scope.lastRun = rid;
  for (let k = 0; k < n; k++) {
    scope.t.push(a.t[k]);
    for (const c of SCOPE_CH) scope.y[c].push(a[c] ? a[c][k] : null);
  }
  const cut = nowT() - SCOPE_S - 2;
  let i = 0; while (i < scope.t.length && scope.t[i] < cut) i++;
  if (i) { scope.t.splice(0, i); for (const c of SCOPE_CH) scope.y[c].splice(0, i); }
}

function width(id) { return Math.max(300, $(id).parentElement.clientWidth - 16); }

const scopePlot = new uPlot({
  width: width("scope"), height: 220, scales: {x: {time: false}},
  axes: [{label: "time (s)"}, {size: 70}],
  series: [{}, {label: "signal", stroke: "#1f77b4", width: 1, points: {show: false}}],
  legend: {show: false},
  hooks: {drawClear: [(u) => {  // shade the runs (the one in progress to the right edge)
    const ctx = u.ctx; ctx.save(); ctx.fillStyle = "rgba(255, 170, 0, 0.15)";
    for (const rid of P.order) {
      const r = P.runs[rid]; if (r.t0 === null || r.history) continue;
      const x0 = u.valToPos(r.t0, "x", true), x1 = u.valToPos(r.end ? r.t1 : nowT(), "x", true);
      ctx.fillRect(x0, u.bbox.top, Math.max(1, x1 - x0), u.bbox.height);
    }
    ctx.restore();
  }]},
}, [[], []], $("scope"));

function drawScope() {
  const ch = $("scope-channel").value, now = nowT();
  scopePlot.batch(() => {
    scopePlot.setData([scope.t, scope.y[ch]], false);
    scopePlot.setScale("x", {min: now - SCOPE_S, max: now});
    const ys = scope.y[ch].filter((v) => v !== null && isFinite(v));
    if (ys.length) { let lo = Math.min(...ys.slice(-20000)), hi = Math.max(...ys.slice(-20000)); if (hi === lo) { hi += 1e-12; lo -= 1e-12; } const pad = (hi - lo) * 0.05; scopePlot.setScale("y", {min: lo - pad, max: hi + pad}); }
  });
}

// ---- force curve (uPlot's xy mode) -----------------------------------------------------------------------
const xy = (label, stroke, extra) => Object.assign({label, stroke, width: 1.2, points: {show: false},
  paths: uPlot.paths.linear(), facets: [{scale: "x", auto: true}, {scale: "y", auto: true}]}, extra || {});
const OVERLAYS = 8;
const curveSeries = [{}, xy("approach", "#1f77b4"), xy("retract", "#d62728"), xy("dwell", "#2ca02c"),
  xy("ground truth (force vs true tip height)", "#9467bd", {dash: [4, 3]}),
  xy("trigger", "#ff7f0e", {dash: [6, 4]}),
  xy("pull-off", "#000", {paths: uPlot.paths.points(), points: {show: true, size: 9, fill: "#ffd700", stroke: "#000"}})];
for (let k = 0; k < OVERLAYS; k++) curveSeries.push(xy(`curve -${k + 1}`, "rgba(120,120,120,0.45)", {width: 1}));
const curvePlot = new uPlot({
  mode: 2, width: width("curve"), height: 260, legend: {show: false},
  scales: {x: {time: false}, y: {}},
  axes: [{label: "piezo height (nm)"}, {label: "force (nN)", size: 60}],
  series: curveSeries,
}, [null, ...curveSeries.slice(1).map(() => [[], []])], $("curve"));

function segXY(r, seg, xcol) {
  const xs = [], ys = [], c = r.cols;
  if (!c.i) return [xs, ys];
  for (let k = 0; k < c.i.length; k++) if (seg === null || c.seg[k] === seg) { xs.push(c[xcol][k] * 1e9); ys.push(c.force_N[k] * 1e9); }
  return [xs, ys];
}

function drawCurve() {
  const rid = P.current, r = rid ? P.runs[rid] : null;
  const data = [null];
  const empty = [[], []];
  if (r) {
    data.push(segXY(r, 0, "height_m"), segXY(r, 1, "height_m"), segXY(r, 2, "height_m"));
    data.push($("truth").checked && r.cols.tip_m ? segXY(r, null, "tip_m") : empty);
    const sp = r.start && r.start.scene ? r.start.scene.setpoint_N : null;
    const hx = r.cols.height_m || [];
    if (sp != null && hx.length && (!r.start.scene.trigger || r.start.scene.trigger === "force")) {
      let lo = Infinity, hi = -Infinity; for (const h of hx) { if (h < lo) lo = h; if (h > hi) hi = h; }
      data.push([[lo * 1e9, hi * 1e9], [sp * 1e9, sp * 1e9]]);
    } else data.push(empty);
    const res = r.end && r.end.result;
    data.push(res && res.detach_height_m != null && res.pulloff_sampled_N != null ? [[res.detach_height_m * 1e9], [-res.pulloff_sampled_N * 1e9]] : empty);
  } else data.push(empty, empty, empty, empty, empty, empty);
  const n = Math.max(0, Math.min(OVERLAYS, +$("overlay-n").value || 0));
  const prev = P.curves.filter((x) => x !== rid).slice(-n).reverse();
  for (let k = 0; k < OVERLAYS; k++) data.push(k < prev.length && P.runs[prev[k]] ? segXY(P.runs[prev[k]], null, "height_m") : empty);
  curvePlot.setData(data);
  if (r && r.end && r.end.result) {
    const res = r.end.result;
    $("curve-info").textContent = `run ${rid}: pull-off ${res.pulloff_sampled_N != null ? (res.pulloff_sampled_N * 1e9).toFixed(3) + " nN" : "—"}, ` +
      `${r.n} points drawn of ${r.end.samples} samples`;
  } else if (r) $("curve-info").textContent = `run ${rid}: ${r.n} points so far`;
}

// ---- map -------------------------------------------------------------------------------------------------
function colour(t) {  // dark blue -> teal -> yellow
  const s = [[33, 30, 90], [30, 150, 140], [250, 230, 40]];
  const x = Math.max(0, Math.min(1, t)) * 2, i = Math.min(1, Math.floor(x)), f = x - i;
  return s[i].map((v, k) => Math.round(v + (s[i + 1][k] - v) * f));
}

function drawMap() {
  const m = P.map; if (!m) return;
  const done = m.pixels.pulloff_N.filter((v) => v !== null).length;
  $("map-info").textContent = `campaign ${m.campaign_id}: ${m.nx} × ${m.ny}, ${done} pixels`;
  for (const [key, id] of [["pulloff_N", "map-pulloff"], ["contact_m", "map-contact"], ["E_star_Pa", "map-E"], ["height_m", "map-height"]]) {
    const cv = $(id), v = m.pixels[key];
    cv.width = m.nx; cv.height = m.ny;
    const ctx = cv.getContext("2d"), img = ctx.createImageData(m.nx, m.ny);
    const fin = v.filter((x) => x !== null); const lo = Math.min(...fin), hi = Math.max(...fin);
    for (let g = 0; g < v.length; g++) {
      const ix = g % m.nx, iy = Math.floor(g / m.nx), p = ((m.ny - 1 - iy) * m.nx + ix) * 4;
      const c = v[g] === null ? [220, 220, 220] : colour(hi > lo ? (v[g] - lo) / (hi - lo) : 0.5);
      img.data.set([...c, 255], p);
    }
    ctx.putImageData(img, 0, 0);
    cv.title = fin.length ? `${key}: ${lo.toPrecision(4)} … ${hi.toPrecision(4)}` : key;
  }
}

// ---- thermal tune ----------------------------------------------------------------------------------------
const tunePlot = new uPlot({
  width: width("tune"), height: 220, legend: {show: false},
  scales: {x: {time: false, distr: 3}, y: {distr: 3}},
  axes: [{label: "frequency (Hz)"}, {label: "PSD (pm²/Hz)", size: 70}],
  series: [{}, {label: "PSD", stroke: "#7f7f7f", width: 1, points: {show: false}}, {label: "fit", stroke: "#d62728", width: 1.5, points: {show: false}}],
}, [[1, 10], [null, null], [null, null]], $("tune"));

function drawTune() {
  const t = P.tune; if (!t || !t.f_Hz) { if (t) $("tune-info").textContent = `run ${t.run_id}: ${t.fit_error || "no spectrum"}`; return; }
  const keep = t.f_Hz.map((f, k) => k).filter((k) => t.f_Hz[k] > 0);
  // in pm²/Hz: uPlot's axes have no ticks below 1e-16, and a thermal PSD in m²/Hz is ~1e-26 (nothing was drawn)
  const PM2 = 1e24;
  tunePlot.setData([keep.map((k) => t.f_Hz[k]), keep.map((k) => t.psd_m2_per_Hz[k] * PM2),
    keep.map((k) => t.fit_psd && t.fit_psd[k] !== null ? t.fit_psd[k] * PM2 : null)]);
  $("tune-info").textContent = t.fit ? `run ${t.run_id}: k = ${t.fit.k.toPrecision(4)} ± ${t.fit.k_err.toPrecision(2)} N/m, ` +
    `f0 = ${(t.fit.f0 / 1e3).toPrecision(4)} kHz, Q = ${t.fit.Q.toPrecision(3)}` : `run ${t.run_id}: fit failed: ${t.fit_error}`;
}

// ---- state -----------------------------------------------------------------------------------------------
let lastRate = null;
const CTRL_WORDS = {idle: "out of contact", approaching: "approaching", engaged: "engaged (in contact)",
  withdrawing: "withdrawing", withdrawn: "withdrawn", crashed: "crashed"};
const um = (x) => x == null ? "—" : `${(x * 1e6).toFixed(3)} µm`;
const nm = (x) => x == null ? "—" : `${(x * 1e9).toFixed(2)} nm`;
const nN = (x) => x == null ? "—" : `${(x * 1e9).toFixed(3)} nN`;
function drawState() {
  const s = P.status; if (!s) return;
  // the run in progress: the stream's run.start/run.end (at once) over the 0.5 s poll (which may be older)
  let state = s.state, rid = s.run_id;
  if (P.streamRun !== null) { state = "running"; rid = P.streamRun; }
  else if (rid && P.runs[rid] && P.runs[rid].end) { state = "idle"; rid = null; }
  const cur = rid ? P.runs[rid] : null, kind = cur && cur.start ? cur.start.kind : null;
  const shown = P.stateShown.length ? P.stateShown[P.stateShown.length - 1] : null;
  if (!shown || shown[0] !== state || shown[1] !== rid) { P.stateShown.push([state, rid]); if (P.stateShown.length > 1000) P.stateShown.shift(); }
  let rtf = "—";
  if (lastRate && s.state === "running" && cur && cur.start) {
    const dt = (performance.now() - lastRate.t) / 1000, ds = s.samples - lastRate.samples;
    if (dt > 0 && ds >= 0) rtf = (ds / cur.start.sample_rate_Hz / dt).toFixed(2) + "×";
  }
  lastRate = {t: performance.now(), samples: s.samples};
  const z = cur && cur.cols.height_m && cur.cols.height_m.length ? (cur.cols.height_m[cur.cols.height_m.length - 1] * 1e9).toFixed(1) + " nm" : "—";
  const mp = cur && cur.start && cur.start.campaign && cur.start.campaign.map;
  const lg = s.log || {}, c = s.campaign, k = s.ctrl;
  const esc = (t) => String(t).replace(/[&<>]/g, (ch) => ({"&": "&amp;", "<": "&lt;", ">": "&gt;"})[ch]);
  let ctrlRows;
  if (!k) ctrlRows = [["controller", "none in this daemon (no status.ctrl)"]];
  else if (!k.available) ctrlRows = [["controller", `unavailable: ${esc(k.error || "")}`]];
  else {
    const held = state === "running" ? " — held: in a run" : "";
    ctrlRows = [
      ["controller", `<b id="state-ctrl">${k.state}</b> (${CTRL_WORDS[k.state] || k.state}${held})` +
        (k.last_fail ? `; last failure ${esc(k.last_fail)}` : "") + (k.moving ? "; moving" : "")],
      ["Z", `motor <span id="state-motor">${um(k.motor_z_m)}</span>, piezo <span id="state-piezo">${nm(k.piezo_z_m)}</span>` +
        (k.gap_m != null ? `, gap ${nm(k.gap_m)}` : "") + (k.saturated ? " (saturated)" : "")],
      ["XY", `<span id="state-xy">${um(k.x_m)}, ${um(k.y_m)}</span>` + (k.moving ? ` → ${um(k.target_x_m)}, ${um(k.target_y_m)}` : "") +
        (mp ? `; run: ${(mp.x_m * 1e6).toFixed(2)}, ${(mp.y_m * 1e6).toFixed(2)} µm (pixel ${mp.ix}, ${mp.iy})` : "")],
      ["feedback", `<span id="state-fb">${k.feedback ? "on" : "off"}</span>, setpoint ${nN(k.setpoint_N)}, error ${nN(k.error_N)}, force ${nN(k.force_N)}`],
    ];
  }
  const rows = [
    ["daemon", `<b id="state-daemon">${state}</b>` + (rid ? ` run <span id="state-run">${rid}</span> (${kind || "?"})` : "")],
    ...ctrlRows,
    ["run Z (piezo)", z],
    ["pacing", `speed ${s.speed}${s.free_run ? ", free run" : ""}; late blocks ${s.late_blocks} (worst ${(s.worst_late_ns / 1e6).toFixed(2)} ms); real-time factor ${rtf}`],
    ["campaign", c ? `#${c.campaign_id} ${c.running ? "running" : "ended"}: ${c.curves_done} / ${c.curves}` : "—"],
    ["logging", `${lg.state}${lg.path ? " " + esc(lg.path) : ""}; curves ${lg.curves || 0}, pending ${lg.queued || 0}` + (lg.error ? `; error ${esc(lg.error)}` : "")],
    ["faults", `${(s.faults && s.faults.count) || 0} injected` + (s.faults && s.faults.plan ? " (plan set)" : "")],
    ["stream", `${s.blocks} blocks, dropped ${s.dropped}; this page lost ${P.droppedFrames} frames` +
      (k && k.live ? `; live ${P.live.n} points (${(+k.live.monitor_rate_Hz).toPrecision(4)} /s, dropped ${k.live.dropped})` : "")],
  ];
  $("state").innerHTML = rows.map(([a, v]) => `<tr><td>${a}</td><td>${v}</td></tr>`).join("");
}

// ---- drawing loop: redraw what changed, log when each block was drawn ------------------------------------
function frame() {
  const drawn = pendingSeqs, drawnLive = pendingLive; pendingSeqs = []; pendingLive = [];
  if (dirty.curve) { dirty.curve = false; drawCurve(); }
  drawScope();
  if (drawn.length) {
    const t = (performance.timeOrigin + performance.now()) / 1000;
    for (const s of drawn) P.drawLog.push([s, t]);
    if (P.drawLog.length > 200000) P.drawLog.splice(0, 100000);
  }
  if (drawnLive.length) {
    const t = (performance.timeOrigin + performance.now()) / 1000;
    for (const s of drawnLive) P.liveDrawLog.push([s, t]);
    if (P.liveDrawLog.length > 200000) P.liveDrawLog.splice(0, 100000);
  }
  requestAnimationFrame(frame);
}

// ---- controls --------------------------------------------------------------------------------------------
$("btn-curve").onclick = () => send({cmd: "curve", index: +$("curve-index").value});
$("btn-abort").onclick = () => send({cmd: "abort"});
$("btn-tune").onclick = () => send({cmd: "tune", duration_s: +$("tune-duration").value});
$("btn-campaign").onclick = () => send({cmd: "campaign", n: +$("campaign-n").value});
$("btn-map").onclick = () => send({cmd: "map", map: {nx: +$("map-nx").value, ny: +$("map-ny").value, pattern: $("map-pattern").value}});
$("btn-log-on").onclick = () => send({cmd: "log", path: $("log-path").value}, "log on");
$("btn-log-off").onclick = () => send({cmd: "log", stop: true}, "log off");
$("btn-set").onclick = () => sendSet($("set-text").value);
$("btn-preset").onclick = () => send({cmd: "set", preset: $("preset").value}, "preset");
$("btn-faults").onclick = () => {
  let plan;
  try { plan = JSON.parse($("fault-plan").value); } catch (e) { message(`fault plan: not JSON: ${e.message}`, true); return; }
  send({cmd: "faults", plan}, "faults");
};
$("btn-faults-clear").onclick = () => send({cmd: "faults", clear: true}, "faults clear");
// the controller (wire.md §2.4): values with units go through the bridge's `vafm ctl` (one parser of units)
function ctl(cmd, args) {
  const id = ++reqId;
  pending[id] = cmd;
  ws.send(JSON.stringify({type: "ctl", id, cmd, args}));
}
$("btn-engage").onclick = () => send({cmd: "engage"});
$("btn-withdraw").onclick = () => send({cmd: "withdraw", motor_steps: +$("withdraw-steps").value});
$("btn-move").onclick = () => ctl("move", [`x_m=${$("move-x").value.trim()}`, `y_m=${$("move-y").value.trim()}`, `speed_m_per_s=${$("move-speed").value.trim()}`]);
$("btn-z").onclick = () => ctl("z", [`z_m=${$("z-z").value.trim()}`]);
$("btn-fb-on").onclick = () => send({cmd: "feedback", on: true}, "feedback");
$("btn-fb-off").onclick = () => send({cmd: "feedback", on: false}, "feedback");
$("btn-fb-setpoint").onclick = () => ctl("feedback", [`setpoint=${$("fb-setpoint").value.trim()}`]);
$("truth").onchange = $("overlay-n").onchange = () => { dirty.curve = true; };

connect();
requestAnimationFrame(frame);
