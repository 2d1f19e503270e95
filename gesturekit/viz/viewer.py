"""A light 3D skeleton viewer: one self-contained HTML page that draws on a 2D canvas.

:func:`skeleton_viewer` shows the same thing as
:func:`gesturekit.viz.figures.skeleton_figure` (the 54 bones of each motion as
joint paths, several motions side by side, play/pause and a time slider, the
camera in front of the character with Y up) without WebGL: the page projects
the joints itself and draws lines on a canvas. A browser without a GPU draws
it at once, where a WebGL scene costs it seconds to set up; the app shows its
skeletons this way. Drag to orbit, scroll to zoom, double-click to reset the
view; space toggles play.

The page loads nothing from the network. Its data are one JSON object in a
``<script type="application/json" id="gk-data">`` element (see
:func:`viewer_data`), the coordinates as base64 float32 typed arrays like a
plotly figure's (:func:`gesturekit.viz.figures.data_array` reads them).
"""
from __future__ import annotations

import html
import json
from typing import Sequence

from ..motion import Motion
from .figures import (
    DEFAULT_MAX_FRAMES,
    MOTION_COLORS,
    _motions_and_labels,
    _skeleton_paths,
    _typed,
    data_array,
)

__all__ = ["CONTROLS_HEIGHT", "skeleton_viewer", "viewer_data", "read_viewer_data"]

#: Pixels the controls (play button, slider, time) take below the drawing.
CONTROLS_HEIGHT = 48

_DATA_ID = "gk-data"


def viewer_data(
    motions: Motion | Sequence[Motion],
    *,
    labels: Sequence[str] | None = None,
    fps: float | None = None,
    title: str | None = None,
    max_frames: int = DEFAULT_MAX_FRAMES,
    spacing: float | None = None,
) -> dict:
    """What :func:`skeleton_viewer` draws, as a JSON-ready dict.

    Parameters
    ----------
    motions, labels, fps, title, max_frames, spacing
        As for :func:`gesturekit.viz.figures.skeleton_figure`.

    Returns
    -------
    dict
        ``title``; ``fps`` (of the time grid) and ``frame_step`` (every ``frame_step``-th
        grid time is shown); ``times`` (seconds, one per shown frame); ``lo``, ``hi``
        (the scene's bounds over all frames, metres); ``up`` and ``eye`` (the default
        camera: Y up, in front of the characters on +Z); ``motions``: one dict per
        motion with ``label``, ``color``, ``offset`` (metres along X) and ``body``,
        ``hands``: typed-array specs of shape (frames, points, 3) holding the joint
        paths (14 body bones up to the wrists, 40 finger bones), NaN points between paths.

    Raises
    ------
    ConfigError
        As :func:`gesturekit.viz.figures.skeleton_figure`.
    """
    motions, labels = _motions_and_labels(motions, labels, who="skeleton_viewer")
    grid_fps, step, times, offsets, paths, lo, hi = _skeleton_paths(motions, fps=fps, max_frames=max_frames,
                                                                    spacing=spacing)
    out = []
    for i, (label, (body, hands), dx) in enumerate(zip(labels, paths, offsets)):
        parts = {}
        for name, a in (("body", body), ("hands", hands)):
            spec = _typed(a.reshape(-1))
            spec["shape"] = f"{a.shape[0]},{a.shape[1]},3"
            parts[name] = spec
        out.append({"label": label or "", "color": MOTION_COLORS[i % len(MOTION_COLORS)], "offset": float(dx),
                    **parts})
    return {
        "title": title or "",
        "fps": grid_fps,
        "frame_step": step,
        "times": [round(float(t), 4) for t in times],
        "lo": [float(x) for x in lo],
        "hi": [float(x) for x in hi],
        "up": [0, 1, 0],
        "eye": [0.0, 0.15, 1.0],
        "motions": out,
    }


def read_viewer_data(page: str) -> dict:
    """The data of a :func:`skeleton_viewer` page, with the coordinates decoded.

    Parameters
    ----------
    page : str
        The HTML text.

    Returns
    -------
    dict
        :func:`viewer_data`'s dict, each motion's ``body`` and ``hands`` as float64
        arrays of shape (frames, points, 3); also ``key``, the page's key.
    """
    start = page.index(f'id="{_DATA_ID}">') + len(f'id="{_DATA_ID}">')
    data = json.loads(page[start: page.index("</script>", start)])
    for m in data["motions"]:
        for name in ("body", "hands"):
            m[name] = data_array(m[name])
    data["key"] = html.unescape(page[page.index('data-key="') + 10:].split('"', 1)[0])
    return data


def skeleton_viewer(
    motions: Motion | Sequence[Motion],
    *,
    labels: Sequence[str] | None = None,
    fps: float | None = None,
    title: str | None = None,
    max_frames: int = DEFAULT_MAX_FRAMES,
    spacing: float | None = None,
    height: int = 520,
    key: str = "skeleton",
) -> str:
    """A self-contained HTML page that animates one or several skeletons side by side.

    Parameters
    ----------
    motions, labels, fps, title, max_frames, spacing
        As for :func:`gesturekit.viz.figures.skeleton_figure`.
    height : int
        Height of the drawing in pixels (the controls come below it: :data:`CONTROLS_HEIGHT`).
    key : str
        A name for the page (``data-key`` of its body), by which pages and tests find it.

    Returns
    -------
    str
        The HTML. Once it has drawn its first frame, the page's body has
        ``data-drawn="1"`` and the canvas ``data-frame`` holds the shown frame's index.
    """
    data = viewer_data(motions, labels=labels, fps=fps, title=title, max_frames=max_frames, spacing=spacing)
    # "</" cannot end the data element early: JSON escapes are valid inside a string
    payload = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    return (_PAGE.replace("__HEIGHT__", str(int(height)))
            .replace("__KEY__", html.escape(key, quote=True))
            .replace("__DATA__", payload))


_PAGE = """<!DOCTYPE html>
<html><head><meta charset="utf-8"><style>
body{margin:0;font-family:"Source Sans Pro",system-ui,sans-serif;font-size:14px;color:#31333f;background:#fff}
#bar{display:flex;align-items:center;gap:10px;height:40px;padding:2px 4px}
button{font:inherit;padding:3px 12px;border:1px solid #ccc;border-radius:6px;background:#fff;cursor:pointer}
input[type=range]{flex:1}
#t{min-width:76px;text-align:right;font-variant-numeric:tabular-nums}
canvas{display:block;width:100%;cursor:grab;touch-action:none}
</style></head>
<body data-key="__KEY__">
<canvas id="c" style="height:__HEIGHT__px" title="drag: orbit, scroll: zoom, double-click: reset"></canvas>
<div id="bar"><button id="play">&#9654; Play</button><input id="s" type="range" min="0" value="0" step="1"><span id="t"></span></div>
<script type="application/json" id="gk-data">__DATA__</script>
<script>
(function () {
  const D = JSON.parse(document.getElementById("gk-data").textContent);
  const dec = (spec) => {
    const b = atob(spec.bdata), u = new Uint8Array(b.length);
    for (let i = 0; i < b.length; i++) u[i] = b.charCodeAt(i);
    const sh = spec.shape.split(",").map(Number);
    return {a: new Float32Array(u.buffer), n: sh[1]};
  };
  const M = D.motions.map(m => ({label: m.label, color: m.color, offset: m.offset, body: dec(m.body), hands: dec(m.hands)}));
  const N = D.times.length;
  const canvas = document.getElementById("c"), ctx = canvas.getContext("2d");
  const slider = document.getElementById("s"), tlabel = document.getElementById("t"), play = document.getElementById("play");
  slider.max = String(N - 1);
  const lo = D.lo, hi = D.hi, centre = [0, 1, 2].map(i => (lo[i] + hi[i]) / 2);
  const extent = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 0.3);
  const home = {yaw: Math.atan2(D.eye[0], D.eye[2]), pitch: Math.atan2(D.eye[1], Math.hypot(D.eye[0], D.eye[2])), zoom: 1};
  let view = Object.assign({}, home), frame = 0, playing = false, t0 = 0, f0 = 0;

  function size() {
    const r = window.devicePixelRatio || 1, w = canvas.clientWidth, h = canvas.clientHeight;
    canvas.width = Math.round(w * r); canvas.height = Math.round(h * r);
    ctx.setTransform(r, 0, 0, r, 0, 0);
  }
  function projector() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    const cy = Math.cos(view.yaw), sy = Math.sin(view.yaw), cp = Math.cos(view.pitch), sp = Math.sin(view.pitch);
    const dist = 2.2 * extent;  // the eye's distance from the scene centre
    // fit the scene's X-Y extent into the canvas, then zoom
    const f = view.zoom * 0.92 * dist * Math.min(w / (hi[0] - lo[0]), h / (hi[1] - lo[1]));
    return (x, y, z) => {
      x -= centre[0]; y -= centre[1]; z -= centre[2];
      const x1 = cy * x - sy * z, z1 = sy * x + cy * z;  // about Y
      const y2 = cp * y - sp * z1, z2 = sp * y + cp * z1;  // about X
      const depth = dist - z2;
      return [w / 2 + f * x1 / depth, h / 2 - f * y2 / depth];
    };
  }
  function path(P, part, k, width, dot) {
    const a = part.a, n = part.n, base = k * n * 3;
    ctx.lineWidth = width; ctx.beginPath();
    let open = false;
    const pts = [];
    for (let i = 0; i < n; i++) {
      const x = a[base + 3 * i];
      if (Number.isNaN(x)) { open = false; continue; }
      const q = P(x, a[base + 3 * i + 1], a[base + 3 * i + 2]);
      if (open) ctx.lineTo(q[0], q[1]); else ctx.moveTo(q[0], q[1]);
      open = true; pts.push(q);
    }
    ctx.stroke();
    for (const q of pts) { ctx.beginPath(); ctx.arc(q[0], q[1], dot, 0, 2 * Math.PI); ctx.fill(); }
  }
  function draw() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    ctx.clearRect(0, 0, w, h);
    const P = projector();
    ctx.lineCap = "round"; ctx.lineJoin = "round";
    if (D.title) { ctx.fillStyle = "#31333f"; ctx.font = "15px sans-serif"; ctx.textAlign = "left"; ctx.fillText(D.title, 8, 20); }
    for (const m of M) {
      ctx.strokeStyle = m.color; ctx.fillStyle = m.color;
      path(P, m.body, frame, 5, 2.6);
      path(P, m.hands, frame, 1.6, 1.1);
      if (m.label && M.length > 1) {
        const q = P(centre[0] + m.offset, hi[1], centre[2]);
        ctx.font = "13px sans-serif"; ctx.textAlign = "center"; ctx.fillText(m.label, q[0], Math.max(14, q[1]));
      }
    }
    slider.value = String(frame);
    tlabel.textContent = "t = " + D.times[frame].toFixed(2) + " s";
    canvas.dataset.frame = String(frame);
    document.body.dataset.drawn = "1";
  }
  function tick(now) {
    if (!playing) return;
    // a frame's time stamp may precede the click's: never step backwards
    const k = f0 + Math.floor(Math.max(0, now - t0) / 1000 * D.fps / D.frame_step);
    if (k >= N) { frame = N - 1; playing = false; play.innerHTML = "&#9654; Play"; draw(); return; }
    if (k !== frame) { frame = k; draw(); }
    requestAnimationFrame(tick);
  }
  function toggle() {
    if (N < 2) return;
    playing = !playing;
    play.innerHTML = playing ? "&#10074;&#10074; Pause" : "&#9654; Play";
    if (playing) { if (frame >= N - 1) frame = 0; f0 = frame; t0 = performance.now(); requestAnimationFrame(tick); }
  }
  play.addEventListener("click", toggle);
  document.addEventListener("keydown", (e) => { if (e.code === "Space") { e.preventDefault(); toggle(); } });
  slider.addEventListener("input", () => { frame = Number(slider.value); f0 = frame; t0 = performance.now(); draw(); });
  let drag = null;
  canvas.addEventListener("pointerdown", (e) => { drag = [e.clientX, e.clientY, view.yaw, view.pitch]; canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    view.yaw = drag[2] - (e.clientX - drag[0]) * 0.01;
    view.pitch = Math.max(-1.5, Math.min(1.5, drag[3] + (e.clientY - drag[1]) * 0.01));
    draw();
  });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("wheel", (e) => { e.preventDefault(); view.zoom = Math.max(0.2, Math.min(8, view.zoom * Math.exp(-e.deltaY * 0.001))); draw(); }, {passive: false});
  canvas.addEventListener("dblclick", () => { view = Object.assign({}, home); draw(); });
  window.addEventListener("resize", () => { size(); draw(); });
  if (N < 2) { play.disabled = true; slider.disabled = true; }
  size(); draw();
})();
</script></body></html>
"""
