// gesturekit's 3D viewer: the skinned characters of the page's data drawn with three.js, on one clock: the speech's time when the page has speech (frame = floor(currentTime * shown fps)),
// else a plain one. Drag to orbit, scroll to zoom, double-click to reset the view; space toggles play.
// A standalone page holds its data in the "gk-data" JSON element and its speech in the "gk-audio" element;
// in the app the page is a Streamlit component and its data come with each render message (component.js).
import { AmbientLight, Color, DirectionalLight, PerspectiveCamera, Scene, Vector3, WebGLRenderer } from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";

import { buildCharacters, buildStage } from "./character.js";
import { component } from "./component.js";

/** The camera of gesturekit.character.look.camera_for: the box lo..hi whole, seen from the direction dir
 * (with top, a box narrower than the picture's height keeps its top at the picture's top). */
export function cameraFor(lo, hi, aspect, fov, dir, top, depthShare, floor) {
  const centre = [0, 1, 2].map((i) => (lo[i] + hi[i]) / 2);
  const half = [0, 1, 2].map((i) => Math.max((hi[i] - lo[i]) / 2, 1e-3));
  const norm = Math.hypot(dir[0], dir[1], dir[2]), tanV = Math.tan((fov * Math.PI) / 360);
  const dist = Math.max(half[1] / tanV, half[0] / (tanV * aspect)) + depthShare * half[2];
  if (top) {  // the height shown beyond the box's own: below the box, down to a little below the floor
    const extra = Math.max(0, (dist - depthShare * half[2]) * tanV - half[1]);
    const room = floor === null || floor === undefined ? extra : Math.max(0, lo[1] - extra - floor + 0.1);
    centre[1] -= Math.min(extra, room);
  }
  return { position: centre.map((c, i) => c + (dist * dir[i]) / norm), target: centre };
}

/** gesturekit.character.look.fitted_height: the drawing's height in pixels for a canvas `width` pixels wide, at
 * which the upper-body box of side-by-side characters fills it both ways (cameraFor fits the box's width there),
 * at most `most` (the height asked for) and at least `least` pixels (or `most`, if less). */
export function fittedHeight(box, width, most, least) {
  const wide = (box[1][0] - box[0][0]) / Math.max(box[1][1] - box[0][1], 1e-3);
  return Math.floor(Math.min(most, Math.max(Math.min(most, least), width / wide)) + 0.5);
}

/** Draw the data D with the speech element audio (or null); resized(), if given, is called when the drawing
 * changes its height. Returns a function that takes the view down. */
function main(D, audio, resized) {
  const begun = performance.now();
  const gone = new AbortController(), signal = gone.signal;
  const N = D.times.length, shownFps = D.fps / D.frame_step;
  const canvas = document.getElementById("c"), stage = document.getElementById("stage");
  const slider = document.getElementById("s"), tlabel = document.getElementById("t"), play = document.getElementById("play");
  const noteEl = document.getElementById("note");
  const gk = (window.gk = { frame: 0, frames: N, time: 0, audioTime: audio ? 0 : null, playing: false, drawn: 0, drawMs: 0 });
  noteEl.title = D.note;
  slider.max = String(N - 1);
  document.getElementById("title").textContent = D.title;
  document.getElementById("dropped").textContent = D.note;
  document.getElementById("derived").textContent = D.motions.some((m) => m.derived.length)
    ? "grey: derived (placed from neck and shoulders)" : "";
  const labels = D.motions.map((m) => {
    const el = document.createElement("div");
    el.className = "label";
    el.textContent = D.motions.length > 1 ? m.label : "";
    stage.appendChild(el);
    return el;
  });

  const decoded = performance.now();
  let renderer = null;
  try {
    // no antialiasing and no shadows: a browser without a GPU draws WebGL in software
    renderer = new WebGLRenderer({ canvas, antialias: false, powerPreference: "high-performance" });
  } catch (e) {
    const msg = document.getElementById("nogl");
    msg.textContent = "The 3D view needs WebGL, which this browser does not offer (" + e.message + "); the controls and the speech still work.";
    msg.style.display = "flex";
  }
  const scene = new Scene();
  scene.background = new Color(D.look.background);
  // three.js's Lambert surface sends albedo / pi of the light it gets: intensities of pi * strength give
  // colour = albedo * (ambient + key * max(0, n . l)), in linear light (the output is sRGB)
  scene.add(new AmbientLight(0xffffff, Math.PI * D.look.ambient));
  // key, fill and rim: the sum of their Lambert terms, as gesturekit.character.look.shade adds them
  for (const [dir, strength] of D.look.lights) {
    const light = new DirectionalLight(0xffffff, Math.PI * strength);
    light.position.set(dir[0], dir[1], dir[2]);
    scene.add(light);  // its target stays at the origin: the light comes from the direction of its position
  }
  const glReady = performance.now();
  for (const m of buildStage(D)) scene.add(m);
  const characters = buildCharacters(D);
  for (const c of characters) scene.add(c.group);
  const camera = new PerspectiveCamera(D.look.fov, 1, 0.01, 100);
  const controls = renderer ? new OrbitControls(camera, canvas) : null;
  // the wheel zooms towards the point under the cursor: side-by-side characters stay in view
  if (controls) controls.zoomToCursor = true;
  let framing = D.framing, lo = D.boxes[framing][0], hi = D.boxes[framing][1];
  const framingButton = document.getElementById("framing");
  let frame = 0, playing = false, t0 = 0, clock0 = 0, moved = false;

  function home() {
    const c = cameraFor(lo, hi, camera.aspect, D.look.fov, D.look.view, framing === "upper body", D.look.depth_share, D.ground);
    camera.position.set(c.position[0], c.position[1], c.position[2]);
    camera.up.set(0, 1, 0);
    gk.camera = { position: c.position, target: c.target, fov: camera.fov, aspect: camera.aspect, framing };
    if (framingButton) framingButton.textContent = framing === "upper body" ? "Full body" : "Upper body";
    if (controls) { controls.target.set(c.target[0], c.target[1], c.target[2]); controls.update(); }
    else camera.lookAt(c.target[0], c.target[1], c.target[2]);
  }
  // side by side, the drawing is no taller than the characters fill: its width frames them, the presenter rule
  // (the upper body fills most of the height) holds, and no empty floor is left under them
  const most = Number(stage.dataset.most) || stage.clientHeight;
  function size() {
    const fitted = fittedHeight(D.boxes["upper body"], Math.max(1, canvas.clientWidth), most, D.look.least_height);
    if (stage.style.height !== fitted + "px") {
      stage.style.height = fitted + "px";
      if (resized) resized();
    }
    const w = Math.max(1, canvas.clientWidth), h = Math.max(1, canvas.clientHeight);
    if (renderer) { renderer.setPixelRatio(window.devicePixelRatio || 1); renderer.setSize(w, h, false); }
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
  }
  const above = new Vector3();
  function place() {
    // each label above its character, at the framed box's top
    const w = canvas.clientWidth, h = canvas.clientHeight;
    D.motions.forEach((m, i) => {
      above.set((lo[0] + hi[0]) / 2 + m.offset, hi[1], (lo[2] + hi[2]) / 2).project(camera);
      labels[i].style.left = ((above.x + 1) / 2) * w + "px";
      labels[i].style.top = Math.max(D.title ? 24 : 2, ((1 - above.y) / 2) * h - 16) + "px";
    });
  }
  function draw() {
    const started = performance.now();
    for (const c of characters) c.pose(frame);
    if (renderer) renderer.render(scene, camera);
    place();
    slider.value = String(frame);
    tlabel.textContent = D.times[frame].toFixed(2) + " / " + (D.n_grid / D.fps).toFixed(2) + " s";
    canvas.dataset.frame = String(frame);
    document.body.dataset.drawn = "1";
    gk.frame = frame; gk.drawn += 1; gk.drawMs = performance.now() - started;
  }
  // a character in its file's own materials: drawn again once they are read (textures decode asynchronously)
  Promise.all(characters.map((c) => c.ready)).then(
    (own) => {
      if (signal.aborted) return;
      gk.materials = own.some(Boolean);
      if (renderer) draw();
      document.body.dataset.materials = "1";
    },
    (e) => {
      gk.materials = false;
      gk.materialsError = String(e && e.message ? e.message : e);
      document.body.dataset.materials = "failed";
      console.warn("the character's materials could not be read: " + gk.materialsError);
    },
  );
  const frameAt = (t) => Math.min(N - 1, Math.max(0, Math.floor(t * shownFps + 1e-6)));
  function now() {
    if (audio) return audio.currentTime;
    return playing ? clock0 + (performance.now() - t0) / 1000 : clock0;
  }
  function show(t) {
    gk.time = t; gk.audioTime = audio ? audio.currentTime : null;
    const k = frameAt(t);
    if (k !== frame || !document.body.dataset.drawn) { frame = k; draw(); }
  }
  function stopped() { playing = false; gk.playing = false; play.innerHTML = "&#9654; Play"; }
  function tick() {
    if (!playing) return;
    const t = now();
    show(t);
    if (!audio && frameAt(t) >= N - 1 && t * shownFps >= N) { stopped(); return; }
    requestAnimationFrame(tick);
  }
  function start() {
    playing = true; gk.playing = true; play.innerHTML = "&#10074;&#10074; Pause";
    requestAnimationFrame(tick);
  }
  function toggle() {
    if (N < 2) return;
    if (playing) {
      if (audio) audio.pause(); else clock0 = now();
      stopped(); show(now()); return;
    }
    const atEnd = frame >= N - 1;
    if (audio) {
      if (atEnd || audio.ended) audio.currentTime = 0;
      audio.play().then(start, (e) => { noteEl.textContent = "the speech cannot play: " + e.message; });
    } else {
      clock0 = atEnd ? 0 : D.times[frame];
      t0 = performance.now(); start();
    }
  }
  if (audio) {
    audio.addEventListener("ended", () => { stopped(); show(audio.currentTime); }, { signal });
    audio.addEventListener("pause", () => { if (playing) { stopped(); show(audio.currentTime); } }, { signal });
    audio.addEventListener("seeked", () => { if (!playing) show(audio.currentTime); }, { signal });
  }
  play.addEventListener("click", toggle, { signal });
  if (framingButton) {
    framingButton.style.display = D.ground === null || D.ground === undefined ? "none" : "";
    framingButton.addEventListener("click", () => {
      framing = framing === "upper body" ? "full body" : "upper body";
      lo = D.boxes[framing][0]; hi = D.boxes[framing][1];
      moved = false; home(); draw();
    }, { signal });
  }
  document.addEventListener("keydown", (e) => { if (e.code === "Space") { e.preventDefault(); toggle(); } }, { signal });
  slider.addEventListener("input", () => {
    const k = Number(slider.value), t = D.times[k] + 0.25 / D.fps;  // inside frame k's interval
    if (audio) audio.currentTime = t; else { clock0 = t; t0 = performance.now(); }
    frame = k; gk.time = t; draw();
  }, { signal });
  if (controls) {
    controls.addEventListener("change", draw);  // drawn on demand: orbit and zoom
    controls.addEventListener("start", () => { moved = true; });
    canvas.addEventListener("dblclick", () => { moved = false; home(); draw(); });
  }
  // a new size frames the box again at the new aspect ratio, unless the user has moved the view
  window.addEventListener("resize", () => { size(); if (!moved) home(); draw(); }, { signal });
  // the stage alone (the backdrop, the floor and the shadows) and back: what the characters stand in front of
  gk.showCharacters = (visible) => { for (const c of characters) c.group.visible = visible; draw(); };
  play.disabled = slider.disabled = N < 2;
  size(); home(); draw();
  // where the first frame's time went (milliseconds since the page began to load)
  gk.startup = { script: begun, data: decoded, webgl: glReady, drawn: performance.now() };
  return () => {
    stopped();
    gone.abort();
    if (audio) audio.pause();
    if (controls) controls.dispose();
    if (renderer) renderer.dispose();
    for (const el of labels) el.remove();
    // a fresh canvas for the next view: the old one keeps its context and listeners
    canvas.replaceWith(canvas.cloneNode(false));
    delete document.body.dataset.drawn;
  };
}

const standalone = document.getElementById("gk-data");
if (standalone) main(JSON.parse(standalone.textContent), document.getElementById("gk-audio"));
else component(main);
