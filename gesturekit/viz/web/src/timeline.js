// The control timeline, a Streamlit component (app/timeline.py): the speech's waveform, then one lane per
// control where ranges are painted, moved and resized by dragging, snapped to the search's steps, with undo
// and the keyboard; a curve can be drawn in a lane of one attribute. It speaks Streamlit's component protocol
// itself (window messages to and from the app's page). Each "streamlit:render" message brings the args:
// lanes [{name, label, levels: [low, high], curve, low, high, unit}], ranges [{lane, level, start_s, end_s}],
// duration_s, step_s, peaks (the waveform's envelope, 0..1), audio (WAV bytes, a Uint8Array), audio_hash and
// edit (the last of our edits the page has applied). It returns {edit, ranges, curve}: every edit gets a new
// id; curve is {lane, t, y} when a curve was drawn (the page turns it into ranges), else null.

const LABEL_W = 236;  // pixels of the lane names' column
const LANE_H = 26, CURVE_H = 72, WAVE_H = 52, EDGE_PX = 7;
const COLORS = { low: "#4f7cac", high: "#d08c2c" };

function post(type, fields) {
  window.parent.postMessage({ isStreamlitMessage: true, type, ...fields }, "*");
}

const S = {
  lanes: [], ranges: [], sel: -1, undo: [], redo: [], paint: {}, drag: null, pending: null,
  curveLanes: new Set(), curves: {}, dur: 1, step: 1, sent: null, n: 0, mine: new Set(),
  session: Math.random().toString(36).slice(2, 10), audio: null, audioHash: null, audioUrl: null,
  cursor: 0, playing: false, following: null, shown: false, peaks: [], tracks: {}, lanesKey: null,
};
window.gkTimeline = S;  // for tests and tools that read what is shown

const round6 = (t) => Math.round(t * 1e6) / 1e6;
const clamp = (x, lo, hi) => Math.min(Math.max(x, lo), hi);
const copy = (rs) => rs.map((r) => ({ ...r }));
const key = (rs) => JSON.stringify(rs.map((r) => [r.lane, r.level, round6(r.start), round6(r.end)]).sort());
const el = (tag, cls, text) => {
  const e = document.createElement(tag);
  if (cls) e.className = cls;
  if (text !== undefined) e.textContent = text;
  return e;
};

/** The nearest step boundary to t (the speech's end counts as one), seconds. */
function snap(t) {
  let s = Math.round(t / S.step) * S.step;
  if (Math.abs(S.dur - t) < Math.abs(s - t)) s = S.dur;
  return round6(clamp(s, 0, S.dur));
}

function levelSide(lane, level) {
  const l = S.lanes.find((x) => x.name === lane);
  return l && l.levels[0] === level ? "low" : "high";
}

/** Room for a range of `lane` that is not `skip`: the free stretch [lo, hi] around time t. */
function room(lane, skip, t) {
  let lo = 0, hi = S.dur;
  S.ranges.forEach((r, i) => {
    if (i === skip || r.lane !== lane) return;
    if (r.end <= t + 1e-9) lo = Math.max(lo, r.end);
    else if (r.start >= t - 1e-9) hi = Math.min(hi, r.start);
  });
  return [lo, hi];
}

function pushUndo() {
  S.undo.push({ ranges: copy(S.ranges), sel: S.sel });
  if (S.undo.length > 200) S.undo.shift();
  S.redo = [];
}

function send(curve) {
  S.n += 1;
  S.sent = `${S.session}-${S.n}`;
  S.mine.add(S.sent);
  const ranges = S.ranges.map((r) => ({ lane: r.lane, level: r.level, start_s: round6(r.start), end_s: round6(r.end) }));
  post("streamlit:setComponentValue", { value: { edit: S.sent, ranges, curve: curve || null }, dataType: "json" });
}

function undo() {
  if (!S.undo.length) return;
  S.redo.push({ ranges: copy(S.ranges), sel: S.sel });
  const u = S.undo.pop();
  S.ranges = u.ranges;
  S.sel = u.sel < S.ranges.length ? u.sel : -1;
  draw();
  send();
}

function redo() {
  if (!S.redo.length) return;
  S.undo.push({ ranges: copy(S.ranges), sel: S.sel });
  const r = S.redo.pop();
  S.ranges = r.ranges;
  S.sel = r.sel < S.ranges.length ? r.sel : -1;
  draw();
  send();
}

/** The ranges of `lane` with [a, b) taken out (a range across it is cut in two). */
function cut(lane, a, b) {
  const out = [];
  for (const r of S.ranges) {
    if (r.lane !== lane || r.end <= a + 1e-9 || r.start >= b - 1e-9) {
      out.push(r);
      continue;
    }
    if (r.start < a - 1e-9) out.push({ ...r, end: a });
    if (r.end > b + 1e-9) out.push({ ...r, start: b });
  }
  return out;
}

function timeAt(track, clientX) {
  const box = track.getBoundingClientRect();
  return clamp(((clientX - box.left) / box.width) * S.dur, 0, S.dur);
}

function valueAt(lane, track, clientY) {
  const box = track.getBoundingClientRect();
  const [vmin, vmax] = curveScale(lane);
  return vmax - clamp((clientY - box.top) / box.height, 0, 1) * (vmax - vmin);
}

function curveScale(lane) {
  const span = Math.max(lane.high - lane.low, 1e-6);
  return [lane.low - 0.6 * span, lane.high + 0.6 * span];
}

// ---- drawing -----------------------------------------------------------------------------------

function build() {
  const root = document.getElementById("lanes");
  root.replaceChildren();
  S.tracks = {};
  const wave = el("div", "row wave");
  wave.append(el("div", "name", "speech"));
  const wtrack = el("div", "track");
  wtrack.id = "wavetrack";
  const canvas = el("canvas");
  canvas.id = "wavecanvas";
  wtrack.append(canvas);
  wtrack.addEventListener("pointerdown", (e) => seek(timeAt(wtrack, e.clientX)));
  wave.append(wtrack);
  root.append(wave);
  for (const lane of S.lanes) {
    const row = el("div", "row lane");
    row.dataset.lane = lane.name;
    const name = el("div", "name");
    name.append(el("span", "label", lane.label));
    const levels = el("span", "levels");
    lane.levels.forEach((level, i) => {
      const b = el("button", "level " + (i ? "high" : "low"), level);
      b.dataset.lane = lane.name;
      b.dataset.level = level;
      b.title = `paint ${level} in this lane; with a range of this lane selected, make it ${level}`;
      b.addEventListener("click", () => pickLevel(lane.name, level));
      levels.append(b);
    });
    if (lane.curve) {
      const c = el("button", "curve", "∿");
      c.dataset.lane = lane.name;
      c.title = "draw a curve in this lane: each step gets the level of the band that holds the curve's mean";
      c.addEventListener("click", () => {
        if (S.curveLanes.has(lane.name)) S.curveLanes.delete(lane.name);
        else S.curveLanes.add(lane.name);
        draw();
      });
      levels.append(c);
    }
    name.append(levels);
    const track = el("div", "track");
    track.dataset.lane = lane.name;
    track.addEventListener("pointerdown", (e) => down(e, lane, track));
    track.addEventListener("pointermove", (e) => move(e, lane, track));
    track.addEventListener("pointerup", (e) => up(e, lane, track));
    track.addEventListener("pointercancel", (e) => up(e, lane, track));
    row.append(name, track);
    root.append(row);
    S.tracks[lane.name] = track;
  }
  const cursor = el("div");
  cursor.id = "cursor";
  root.append(cursor);
  fitNames(root);
  new ResizeObserver(() => { drawWave(); placeCursor(); }).observe(wtrack);
}

// The names' column is as wide as the widest lane needs (a name and its level buttons), so no
// button reaches into the lanes; all rows share the width so the tracks stay aligned in time.
function fitNames(root) {
  let need = LABEL_W;
  for (const name of root.querySelectorAll(".row.lane .name")) {
    const css = getComputedStyle(name);
    const pad = parseFloat(css.paddingLeft) + parseFloat(css.paddingRight) + parseFloat(css.columnGap || "0");
    const label = name.querySelector(".label");
    const levels = name.querySelector(".levels");
    need = Math.max(need, Math.ceil(label.scrollWidth + levels.getBoundingClientRect().width + pad + 2));
  }
  document.documentElement.style.setProperty("--label-w", need + "px");
}

function drawWave() {
  const canvas = document.getElementById("wavecanvas");
  if (!canvas) return;
  const w = canvas.clientWidth, h = canvas.clientHeight, dpr = window.devicePixelRatio || 1;
  canvas.width = Math.max(1, Math.round(w * dpr));
  canvas.height = Math.max(1, Math.round(h * dpr));
  const g = canvas.getContext("2d");
  g.scale(dpr, dpr);
  g.clearRect(0, 0, w, h);
  const mid = h / 2 + 6, amp = h / 2 - 8, n = S.peaks.length;
  g.fillStyle = "#8a94a6";
  for (let x = 0; x < w; x++) {
    const p = n ? S.peaks[Math.min(n - 1, Math.floor((x / w) * n))] : 0;
    const y = Math.max(0.5, p * amp);
    g.fillRect(x, mid - y, 1, 2 * y);
  }
  // seconds along the top, at a spacing that stays readable over a long speech
  const every = [0.5, 1, 2, 5, 10, 15, 30, 60, 120].find((s) => (s / S.dur) * w >= 48) || 300;
  g.fillStyle = "#6b7280";
  g.font = "11px system-ui, sans-serif";
  for (let t = 0; t <= S.dur + 1e-9; t += every) {
    const x = (t / S.dur) * w;
    g.fillRect(x, 0, 1, 4);
    if (x + 34 <= w) g.fillText(`${+t.toFixed(1)} s`, x + 2, 11);  // a label that would not fit is left out
  }
}

function draw() {
  for (const lane of S.lanes) {
    const track = S.tracks[lane.name];
    const curving = S.curveLanes.has(lane.name);
    track.parentElement.classList.toggle("curving", curving);
    track.style.height = (curving ? CURVE_H : LANE_H) + "px";
    const parts = [];
    if (curving) {
      const [vmin, vmax] = curveScale(lane);
      const y = (v) => ((vmax - v) / (vmax - vmin)) * 100;
      const hi = el("div", "band high");
      hi.style.top = "0";
      hi.style.height = y(lane.high) + "%";
      hi.textContent = `${lane.levels[1]} (above ${lane.high.toFixed(2)} ${lane.unit})`;
      const lo = el("div", "band low");
      lo.style.top = y(lane.low) + "%";
      lo.style.bottom = "0";
      lo.textContent = `${lane.levels[0]} (below ${lane.low.toFixed(2)} ${lane.unit})`;
      parts.push(hi, lo);
      const pts = (S.drag && S.drag.kind === "curve" && S.drag.lane === lane.name) ? S.drag.pts : S.curves[lane.name];
      if (pts && pts.length > 1) {
        const svg = document.createElementNS("http://www.w3.org/2000/svg", "svg");
        svg.setAttribute("viewBox", "0 0 1000 100");
        svg.setAttribute("preserveAspectRatio", "none");
        svg.classList.add("curveline");
        const line = document.createElementNS("http://www.w3.org/2000/svg", "polyline");
        line.setAttribute("points", pts.map(([t, v]) => `${(t / S.dur) * 1000},${y(v)}`).join(" "));
        line.setAttribute("vector-effect", "non-scaling-stroke");
        svg.append(line);
        parts.push(svg);
      }
    }
    S.ranges.forEach((r, i) => {
      if (r.lane !== lane.name) return;
      parts.push(rangeEl(r, i, curving));
    });
    const d = S.drag;
    if (d && d.kind === "paint" && d.lane === lane.name && d.moved) {
      const ghost = rangeEl({ lane: lane.name, level: d.level, start: d.a, end: d.b }, -1, curving);
      ghost.classList.add("draft");
      parts.push(ghost);
    }
    track.replaceChildren(...parts);
    const side = S.sel >= 0 && S.ranges[S.sel] && S.ranges[S.sel].lane === lane.name ? S.ranges[S.sel].level : paintLevel(lane.name);
    track.parentElement.querySelectorAll("button.level").forEach((b) => b.classList.toggle("on", b.dataset.level === side));
  }
  const undoB = document.getElementById("undo"), redoB = document.getElementById("redo");
  undoB.disabled = !S.undo.length;
  redoB.disabled = !S.redo.length;
  const sel = S.ranges[S.sel];
  document.getElementById("selinfo").textContent = sel
    ? `selected: ${sel.lane}=${sel.level}, ${sel.start.toFixed(2)}–${sel.end.toFixed(2)} s (Delete removes it, ← → move it a step)`
    : "drag in a lane to paint a range; drag a range to move it, its edges to resize it";
  post("streamlit:setFrameHeight", { height: document.body.scrollHeight });
}

function rangeEl(r, i, thin) {
  const e = el("div", "range " + levelSide(r.lane, r.level) + (i === S.sel ? " sel" : "") + (thin ? " thin" : ""));
  e.style.left = (r.start / S.dur) * 100 + "%";
  e.style.width = ((r.end - r.start) / S.dur) * 100 + "%";
  e.dataset.index = String(i);
  e.dataset.lane = r.lane;
  e.dataset.level = r.level;
  e.dataset.start = String(round6(r.start));
  e.dataset.end = String(round6(r.end));
  e.title = `${r.lane}=${r.level}, ${r.start.toFixed(2)}–${r.end.toFixed(2)} s`;
  e.append(el("span", "", r.level));
  return e;
}

function paintLevel(lane) {
  return S.paint[lane] || S.lanes.find((l) => l.name === lane).levels[1];
}

function pickLevel(lane, level) {
  S.paint[lane] = level;
  const sel = S.ranges[S.sel];
  if (sel && sel.lane === lane && sel.level !== level) {
    pushUndo();
    sel.level = level;
    draw();
    send();
    return;
  }
  draw();
}

// ---- the mouse -----------------------------------------------------------------------------------

function down(e, lane, track) {
  if (e.button !== 0) return;
  document.getElementById("tl").focus({ preventScroll: true });
  track.setPointerCapture(e.pointerId);
  const t = timeAt(track, e.clientX);
  if (S.curveLanes.has(lane.name)) {
    S.drag = { kind: "curve", lane: lane.name, pts: [[t, valueAt(lane, track, e.clientY)]] };
    draw();
    return;
  }
  const hit = e.target.closest(".range");
  if (hit && hit.dataset.index !== "-1") {
    const i = Number(hit.dataset.index), r = S.ranges[i];
    const box = hit.getBoundingClientRect();
    const edge = e.clientX - box.left <= EDGE_PX ? "left" : box.right - e.clientX <= EDGE_PX ? "right" : null;
    S.sel = i;
    S.drag = { kind: edge ? "resize" : "move", edge, i, t0: t, x0: e.clientX, orig: { ...r }, before: copy(S.ranges), changed: false };
    draw();
    return;
  }
  S.drag = { kind: "paint", lane: lane.name, level: paintLevel(lane.name), t0: t, x0: e.clientX, moved: false, a: 0, b: 0 };
}

function move(e, lane, track) {
  const d = S.drag;
  if (!d) {
    if (!S.curveLanes.has(lane.name)) {  // the cursor says what a press here would do
      const hit = e.target.closest(".range");
      let cur = "crosshair";
      if (hit) {
        const box = hit.getBoundingClientRect();
        cur = e.clientX - box.left <= EDGE_PX || box.right - e.clientX <= EDGE_PX ? "ew-resize" : "grab";
      }
      track.style.cursor = cur;
    }
    return;
  }
  const t = timeAt(track, e.clientX);
  if (d.kind === "curve") {
    d.pts.push([t, valueAt(lane, track, e.clientY)]);
    draw();
    return;
  }
  if (d.kind === "paint") {
    if (!d.moved && Math.abs(e.clientX - d.x0) < 4) return;
    d.moved = true;
    let a = snap(Math.min(d.t0, t)), b = snap(Math.max(d.t0, t));
    if (b - a < 1e-9) {
      b = round6(Math.min(a + S.step, S.dur));
      if (b - a < 1e-9) a = round6(Math.max(0, b - S.step));
    }
    d.a = a;
    d.b = b;
    draw();
    return;
  }
  const r = S.ranges[d.i], o = d.orig;
  const [lo, hi] = room(o.lane, d.i, (o.start + o.end) / 2);
  if (d.kind === "move") {
    const delta = Math.round((t - d.t0) / S.step) * S.step;
    const len = o.end - o.start;
    const start = round6(clamp(o.start + delta, lo, hi - len));
    r.start = start;
    r.end = round6(start + len);
  } else if (d.edge === "left") {
    const least = Math.min(S.step, o.end - o.start);
    r.start = round6(clamp(snap(t), lo, o.end - least));
  } else {
    const least = Math.min(S.step, o.end - o.start);
    r.end = round6(clamp(snap(t), o.start + least, hi));
  }
  d.changed = r.start !== o.start || r.end !== o.end;
  draw();
}

function up(e, lane, track) {
  const d = S.drag;
  if (!d) return;
  S.drag = null;
  if (track.hasPointerCapture(e.pointerId)) track.releasePointerCapture(e.pointerId);
  let committed = false;
  if (d.kind === "curve") {
    if (d.pts.length > 1) {
      S.curves[d.lane] = d.pts;
      pushUndo();
      send({ lane: d.lane, t: d.pts.map((p) => round6(p[0])), y: d.pts.map((p) => round6(p[1])) });
      committed = true;
    }
  } else if (d.kind === "paint") {
    if (d.moved) {
      pushUndo();
      S.ranges = cut(d.lane, d.a, d.b);
      S.ranges.push({ lane: d.lane, level: d.level, start: d.a, end: d.b });
      S.sel = S.ranges.length - 1;
      send();
      committed = true;
    } else {
      S.sel = -1;
    }
  } else if (d.changed) {
    S.undo.push({ ranges: d.before, sel: d.i });
    S.redo = [];
    send();
    committed = true;
  }
  if (S.pending && !committed) adopt(S.pending);
  S.pending = null;
  draw();
}

// ---- the keyboard --------------------------------------------------------------------------------

function nudge(by) {
  const r = S.ranges[S.sel];
  if (!r) return;
  const [lo, hi] = room(r.lane, S.sel, (r.start + r.end) / 2);
  const len = r.end - r.start;
  const start = round6(clamp(r.start + by, lo, hi - len));
  if (start === r.start) return;
  pushUndo();
  r.start = start;
  r.end = round6(start + len);
  draw();
  send();
}

function key_(e) {
  const mod = e.ctrlKey || e.metaKey;
  if (mod && (e.key === "z" || e.key === "Z")) {
    e.preventDefault();
    if (e.shiftKey) redo();
    else undo();
  } else if (mod && (e.key === "y" || e.key === "Y")) {
    e.preventDefault();
    redo();
  } else if ((e.key === "Delete" || e.key === "Backspace") && S.ranges[S.sel]) {
    e.preventDefault();
    pushUndo();
    S.ranges.splice(S.sel, 1);
    S.sel = -1;
    draw();
    send();
  } else if (e.key === "ArrowLeft" || e.key === "ArrowRight") {
    if (!S.ranges[S.sel]) return;
    e.preventDefault();
    nudge(e.key === "ArrowLeft" ? -S.step : S.step);
  } else if (e.key === "Escape") {
    S.sel = -1;
    draw();
  } else if (e.key === " ") {
    e.preventDefault();
    play();
  }
}

// ---- playback --------------------------------------------------------------------------------------

function placeCursor() {
  const c = document.getElementById("cursor"), w = document.getElementById("wavetrack");
  if (!c || !w) return;
  const root = document.getElementById("lanes").getBoundingClientRect(), box = w.getBoundingClientRect();
  c.style.left = box.left - root.left + (clamp(S.cursor, 0, S.dur) / S.dur) * box.width + "px";
  c.style.display = S.cursor > 0 || S.playing ? "block" : "none";
  document.getElementById("clock").textContent = `${S.cursor.toFixed(2)} / ${S.dur.toFixed(2)} s`;
}

function tick() {
  const source = S.playing ? S.audio : S.following;
  if (source) S.cursor = source.currentTime;
  placeCursor();
  if (S.playing || S.following) requestAnimationFrame(tick);
}

function play() {
  const a = S.audio;
  if (!a) return;
  if (S.playing) {
    a.pause();
    return;
  }
  if (S.cursor >= S.dur - 0.01) a.currentTime = 0;
  a.play().catch(() => {});
}

function seek(t) {
  S.cursor = t;
  if (S.audio) S.audio.currentTime = t;
  placeCursor();
}

/** The page's own speech player (the app's audio element beside the timeline), followed while it plays. */
function followPage() {
  let playing = null;
  try {
    for (const a of window.parent.document.querySelectorAll("audio")) {
      if (!a.paused && Math.abs(a.duration - S.dur) < 0.2) playing = a;
    }
  } catch (err) {
    return;  // a page of another origin: only the timeline's own player moves the cursor
  }
  const was = S.following;
  S.following = S.playing ? null : playing;
  if (S.following && !was) requestAnimationFrame(tick);
}

function setAudio(bytes, hash) {
  if (hash === S.audioHash) return;
  S.audioHash = hash;
  if (S.audio) S.audio.pause();
  if (S.audioUrl) URL.revokeObjectURL(S.audioUrl);
  S.audio = null;
  S.audioUrl = null;
  if (!bytes) return;
  const a = new Audio();
  a.preload = "auto";
  S.audioUrl = URL.createObjectURL(new Blob([bytes], { type: "audio/wav" }));
  a.src = S.audioUrl;
  const button = document.getElementById("play");
  a.addEventListener("play", () => {
    S.playing = true;
    button.textContent = "❚❚ Pause";
    requestAnimationFrame(tick);
  });
  a.addEventListener("pause", () => { S.playing = false; button.textContent = "▶ Play"; });
  a.addEventListener("ended", () => { S.playing = false; button.textContent = "▶ Play"; });
  S.audio = a;
}

// ---- the page's args -----------------------------------------------------------------------------

function adopt(a) {
  const incoming = a.ranges.map((r) => ({ lane: r.lane, level: r.level, start: r.start_s, end: r.end_s }));
  if (!S.shown) {
    S.ranges = incoming;
    S.shown = true;
    return;
  }
  if (a.edit && a.edit !== S.sent && S.mine.has(a.edit)) {
    return;  // the page's answer to an edit of ours that a newer one has replaced: that one's answer follows
  }
  if (a.edit && a.edit === S.sent) {
    // the page's answer to our last edit (joined, sorted): the same ranges, kept selected
    const sel = S.ranges[S.sel];
    S.ranges = incoming;
    S.sel = sel ? incoming.findIndex((r) => r.lane === sel.lane && Math.abs(r.start - sel.start) < 1e-6) : -1;
    return;
  }
  if (key(incoming) !== key(S.ranges)) {
    pushUndo();  // an edit in the table is undone here too
    S.ranges = incoming;
    S.sel = -1;
  }
}

window.addEventListener("message", (event) => {
  const msg = event.data;
  if (!msg || msg.type !== "streamlit:render") return;
  const a = msg.args;
  document.body.dataset.key = a.key;
  S.dur = Math.max(a.duration_s, 1e-3);
  S.step = a.step_s;
  S.peaks = a.peaks || [];
  const lanesKey = JSON.stringify(a.lanes);
  if (lanesKey !== S.lanesKey) {
    S.lanesKey = lanesKey;
    S.lanes = a.lanes;
    build();
  }
  setAudio(a.audio, a.audio_hash);
  if (S.drag) S.pending = a;
  else adopt(a);
  drawWave();
  draw();
  placeCursor();
});

const tl = document.getElementById("tl");
tl.addEventListener("keydown", key_);
document.getElementById("play").addEventListener("click", play);
document.getElementById("undo").addEventListener("click", undo);
document.getElementById("redo").addEventListener("click", redo);
document.documentElement.style.setProperty("--label-w", LABEL_W + "px");
document.documentElement.style.setProperty("--wave-h", WAVE_H + "px");
setInterval(followPage, 250);
post("streamlit:componentReady", { apiVersion: 1 });
