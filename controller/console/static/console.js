// dronectl console: the page. Plain JavaScript, served by the package; talks only to its own server.
// One WebSocket (relative to this page's address, which carries the run's token) brings JSON messages
// (telemetry, the loop's steps, the log) and binary video frames: 4-byte length, JSON header, JPEG.
"use strict";

const $ = (id) => document.getElementById(id);
const canvas = $("video");
const ctx = canvas.getContext("2d");
const STALE_FRAMES = 6;
const FRAME_DRAWN = '{"type":"frame_drawn"}';

const state = {
  socket: null, page: null, holder: null, hello: null, flying: false, activity: "idle",
  overlay: null,          // the newest step or detections message: what the loop (or the watcher) saw
  bitmap: null, header: null,
};

// What the page measured, for the tests and `dronectl bench console` (read with page.evaluate).
window.consoleStats = { frames: 0, firstFrameMs: null, lastFrameMs: null, latencyMs: [], lastFrame: null,
  steps: 0, messages: [] };

function nowMs() { return performance.timeOrigin + performance.now(); }

// ------------------------------------------------------------------ the connection
function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  const socket = new WebSocket(`${scheme}://${location.host}${location.pathname.replace(/[^/]*$/, "")}ws`);
  socket.binaryType = "arraybuffer";
  state.socket = socket;
  socket.onopen = () => setBadge("connection", "connected", "ok");
  socket.onclose = () => {
    setBadge("connection", "disconnected", "bad");
    state.page = null;
    updateSeat();
    setTimeout(connect, 1000);
  };
  socket.onmessage = (event) => {
    if (typeof event.data === "string") onMessage(JSON.parse(event.data));
    else onFrame(event.data);
  };
}

function send(message) {
  if (state.socket && state.socket.readyState === WebSocket.OPEN) {
    state.socket.send(JSON.stringify(message));
    return true;
  }
  say("not connected to the console", "error");
  return false;
}

function setBadge(id, text, kind) {
  const el = $(id);
  el.textContent = text;
  el.className = `badge ${kind || ""}`;
}

// ------------------------------------------------------------------ messages
function onMessage(m) {
  switch (m.type) {
    case "hello": state.hello = m; state.page = m.page; $("vehicle-name").textContent = m.vehicle;
      renderBars(null); break;
    case "seat": state.holder = m.holder; updateSeat(m.pages); break;
    case "telemetry": showTelemetry(m); break;
    case "state": showState(m); break;
    case "step": state.overlay = m; window.consoleStats.steps += 1; renderBars(m); showStep(m); break;
    case "detections": if (!state.overlay || state.overlay.type !== "step" || !state.busyCentring)
      state.overlay = m; break;
    case "log": showLog(m.entries); break;
    case "message": say(m.text, m.level || "info"); break;
    default: break;
  }
}

function commands() { return state.page !== null && state.holder === state.page; }

function updateSeat(pages) {
  const mine = commands();
  const free = state.holder === null;
  setBadge("seat", mine ? "you command" : free ? "no one commands" : "watching: another page commands",
    mine ? "ok" : "warn");
  if (pages !== undefined) $("seat").title = `${pages} page(s) open`;
  $("take-seat").hidden = mine || !free || state.page === null;
  for (const id of ["btn-takeoff", "btn-hold", "btn-land", "btn-kill", "instruction"]) $(id).disabled = !mine;
}

function fmt(value, unit, digits) {
  return value === null || value === undefined ? "–" : `${Number(value).toFixed(digits)} ${unit}`;
}

function showTelemetry(t) {
  const link = $("t-link");
  link.textContent = t.link;
  link.className = t.link === "ok" ? "ok" : "bad";
  if (t.link !== "ok" && t.mode === undefined) return;
  $("t-mode").textContent = t.mode;
  $("t-armed").textContent = t.armed ? "yes" : "no";
  $("t-in-air").textContent = t.in_air ? "yes" : "no";
  $("t-altitude").textContent = fmt(t.altitude_m, "m", 2);
  $("t-setpoint").textContent = t.setpoint_age_s === null || t.setpoint_age_s === undefined
    ? "no setpoint stream" : fmt(t.setpoint_age_s, "s", 2);
  $("t-battery").textContent = t.battery_percent === null || t.battery_percent === undefined
    ? "not reported" : fmt(t.battery_percent, "%", 0);
}

function showState(s) {
  state.flying = s.flying;
  state.activity = s.activity;
  state.busyCentring = s.activity === "centring";
  $("t-activity").textContent = s.instruction ? `${s.activity}: ${s.instruction}` : s.activity;
  $("video-lost").hidden = s.video !== "lost";
}

function say(text, level) {
  const box = $("messages");
  const line = document.createElement("div");
  line.className = level;
  line.textContent = text;
  box.prepend(line);
  while (box.children.length > 6) box.lastChild.remove();
  window.consoleStats.messages.push({ level, text });
}

function showStep(m) {
  const where = m.offset_px ? `offset (${m.offset_px[0]}, ${m.offset_px[1]}) px` : "target not seen";
  const move = m.action_name ? `, chose ${m.action_name}` : "";
  $("step-info").textContent =
    `#${m.instruction_number} step ${m.index} (frame ${m.frame}): ${where}${move}${m.event ? ` [${m.event}]` : ""}`;
}

function renderBars(step) {
  const names = state.hello ? state.hello.actions : [];
  const bars = $("bars");
  bars.textContent = "";
  const d = step && step.distances ? step.distances : null;
  const finite = d ? d.filter((x) => x !== null) : [];
  const lo = finite.length ? Math.min(...finite) : 0;
  const hi = finite.length ? Math.max(...finite) : 1;
  names.forEach((name, i) => {
    const row = document.createElement("div");
    row.className = "bar" + (step && step.action === i ? " chosen" : "");
    row.dataset.action = name;
    const value = d ? d[i] : null;
    // Shorter distance = closer to the goal: the bar is longer the closer the move gets.
    const share = value === null || hi === lo ? (value === null ? 0 : 1) : 0.1 + 0.9 * (hi - value) / (hi - lo);
    row.innerHTML = `<span class="name"></span><span class="track"><span class="fill"></span></span>` +
      `<span class="value"></span>`;
    row.querySelector(".name").textContent = (step && step.action === i ? "▶ " : "") + name;
    row.querySelector(".fill").style.width = `${Math.round(share * 100)}%`;
    row.querySelector(".value").textContent = value === null ? "–" : value.toFixed(3);
    bars.appendChild(row);
  });
}

function showLog(entries) {
  const body = $("log").querySelector("tbody");
  body.textContent = "";
  for (const e of entries) {
    const row = document.createElement("tr");
    row.dataset.number = e.number;
    const cells = [e.number, e.instruction, e.outcome || "running", e.steps ?? "", e.message || ""];
    cells.forEach((text, i) => {
      const cell = document.createElement("td");
      cell.textContent = text;
      if (i === 2) cell.className = e.outcome === "centred" ? "outcome-centred"
        : e.outcome ? "outcome-other" : "outcome-running";
      row.appendChild(cell);
    });
    const link = document.createElement("td");
    if (e.report) {
      const a = document.createElement("a");
      a.href = e.report;
      a.target = "_blank";
      a.textContent = `report #${e.number}`;
      link.appendChild(a);
    }
    row.appendChild(link);
    body.appendChild(row);
  }
}

// ------------------------------------------------------------------ video
// Frames are decoded one at a time: one that arrives meanwhile waits, replaced by any newer one, so a
// slow page shows the newest frame rather than a queue of old ones. After drawing, the page says so:
// the server sends at most two frames ahead of what was drawn.
let decoding = false;
let waiting = null;

function frameDone() {
  if (state.socket && state.socket.readyState === WebSocket.OPEN) state.socket.send(FRAME_DRAWN);
}

function onFrame(buffer) {
  if (decoding) {
    if (waiting) frameDone();  // an older waiting frame is dropped: done with it too
    waiting = buffer;
    return;
  }
  decoding = true;
  showFrame(buffer).finally(() => {
    decoding = false;
    frameDone();
    if (waiting) { const next = waiting; waiting = null; onFrame(next); }
  });
}

async function showFrame(buffer) {
  const length = new DataView(buffer).getUint32(0);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, length)));
  const jpeg = new Blob([new Uint8Array(buffer, 4 + length)], { type: "image/jpeg" });
  let bitmap;
  try { bitmap = await createImageBitmap(jpeg); } catch (e) { return; }
  if (state.bitmap) state.bitmap.close();
  state.bitmap = bitmap;
  state.header = header;
  draw();
  const s = window.consoleStats;
  const t = nowMs();
  s.frames += 1;
  s.lastFrameMs = t;
  if (s.firstFrameMs === null) s.firstFrameMs = t;
  s.lastFrame = header.n;
  s.latencyMs.push(t - header.t_ms);
  if (s.latencyMs.length > 1000) s.latencyMs.shift();
}

function draw() {
  const h = state.header;
  if (!state.bitmap || !h) return;
  const scale = canvas.width / h.w;
  canvas.height = Math.round(h.h * scale);
  ctx.imageSmoothingEnabled = true;
  ctx.drawImage(state.bitmap, 0, 0, canvas.width, canvas.height);
  const cx = (h.w / 2) * scale, cy = (h.h / 2) * scale;
  const o = state.overlay;
  const eps = o && o.epsilon_px ? o.epsilon_px : state.hello ? state.hello.epsilon_px : null;
  if (eps) {
    ctx.strokeStyle = "#7cfc00"; ctx.lineWidth = 2; ctx.setLineDash([]);
    ctx.strokeRect(cx - eps * scale, cy - eps * scale, 2 * eps * scale, 2 * eps * scale);
    if (o && o.stop_threshold_px) {
      const s = o.stop_threshold_px * scale;
      ctx.setLineDash([4, 4]); ctx.strokeRect(cx - s, cy - s, 2 * s, 2 * s); ctx.setLineDash([]);
    }
  }
  ctx.fillStyle = "#ffffff";
  ctx.beginPath(); ctx.arc(cx, cy, 4, 0, 2 * Math.PI); ctx.fill();
  if (o && o.detections) {
    ctx.font = "14px system-ui, sans-serif";
    // Detections of an older frame (the loop flies between its looks): drawn fainter and dashed.
    const stale = h.n - o.frame > STALE_FRAMES;
    ctx.globalAlpha = stale ? 0.55 : 1.0;
    if (stale) ctx.setLineDash([6, 4]);
    for (const d of o.detections) {
      const [u0, v0, u1, v1] = d.bbox_px.map((x) => x * scale);
      ctx.strokeStyle = d.named ? "#ffd23f" : "#4fc3f7";
      ctx.lineWidth = d.named ? 3 : 2;
      ctx.strokeRect(u0, v0, u1 - u0, v1 - v0);
      const [u, v] = d.centre_px.map((x) => x * scale);
      ctx.beginPath(); ctx.arc(u, v, 3, 0, 2 * Math.PI); ctx.fillStyle = ctx.strokeStyle; ctx.fill();
      const label = `${d.named ? "TARGET " : ""}${d.kind || "?"}${d.colour ? " · " + d.colour : ""} ${d.score.toFixed(2)}`;
      const w = ctx.measureText(label).width + 8;
      ctx.fillStyle = "rgba(0,0,0,0.65)";
      ctx.fillRect(u0, Math.max(0, v0 - 20), w, 20);
      ctx.fillStyle = d.named ? "#ffd23f" : "#4fc3f7";
      ctx.fillText(label, u0 + 4, Math.max(14, v0 - 5));
      if (d.named) {
        ctx.strokeStyle = "#ffd23f"; ctx.lineWidth = 1;
        ctx.beginPath(); ctx.moveTo(cx, cy); ctx.lineTo(u, v); ctx.stroke();
      }
    }
    ctx.globalAlpha = 1.0;
    ctx.setLineDash([]);
    const age = h.n - o.frame;
    ctx.fillStyle = "rgba(0,0,0,0.6)"; ctx.fillRect(0, canvas.height - 22, canvas.width, 22);
    ctx.fillStyle = "#e6e9ee";
    const what = o.type === "step" ? `step ${o.index} of #${o.instruction_number}` : "watching";
    ctx.fillText(`${what}: detections of frame ${o.frame}` + (age > 0 ? ` (${age} frames ago)` : ""),
      6, canvas.height - 6);
  }
}

setInterval(() => {
  const s = window.consoleStats;
  const lostMs = state.hello ? state.hello.video_lost_s * 1000 : 2000;  // the server's threshold
  const stale = s.lastFrameMs === null || nowMs() - s.lastFrameMs > lostMs;
  if (stale && state.header) $("video-lost").hidden = false;
  const recent = s.latencyMs.slice(-30);
  const mean = recent.length ? recent.reduce((a, b) => a + b, 0) / recent.length : null;
  const span = s.firstFrameMs !== null ? (s.lastFrameMs - s.firstFrameMs) / 1000 : 0;
  const fps = span > 0 ? (s.frames - 1) / span : 0;
  $("video-stats").textContent = s.frames
    ? `frame ${s.lastFrame} · ${fps.toFixed(1)} fps · camera to page ${mean === null ? "–" : mean.toFixed(0)} ms`
    : "no frame yet";
}, 500);

// ------------------------------------------------------------------ the operator's input
$("instruction-form").addEventListener("submit", (event) => {
  event.preventDefault();
  const input = $("instruction");
  if (send({ type: "instruction", text: input.value })) input.select();
});
$("btn-takeoff").onclick = () => send({ type: "command", name: "takeoff", sent_ms: nowMs() });
$("btn-hold").onclick = () => send({ type: "command", name: "hold", sent_ms: nowMs() });
$("btn-land").onclick = () => send({ type: "command", name: "land", sent_ms: nowMs() });
$("btn-kill").onclick = () => { $("kill-confirm").hidden = false; };
$("btn-kill-cancel").onclick = () => { $("kill-confirm").hidden = true; };
$("btn-kill-confirm").onclick = () => {
  $("kill-confirm").hidden = true;
  send({ type: "command", name: "kill", confirm: true, sent_ms: nowMs() });
};
$("take-seat").onclick = () => send({ type: "take_command" });

updateSeat();
connect();
