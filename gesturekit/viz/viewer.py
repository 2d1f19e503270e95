"""A 3D viewer of motions as people: one self-contained HTML page that draws on a 2D canvas.

:func:`skeleton_viewer` shows several motions side by side, each as a person in
the one appearance of :mod:`gesturekit.viz.appearance` (shaded capsules for the
limbs, fingers, neck and torso, a head sphere, a contact shadow on a floor),
without WebGL: the page projects the points itself and paints the shapes far to
near. A browser without a GPU draws it at once, where a WebGL scene costs it
seconds to set up; the app shows its motions this way. Drag to orbit, scroll to
zoom, double-click to reset the view; space toggles play.

Playback has one clock. Given the speech, the page embeds it (16-bit WAV, as a
data URI in an ``<audio>`` element) and the one play button plays it: the
shown frame is always ``floor(audio.currentTime * shown fps)``, so gesture and
speech stay in sync, and moving the slider seeks the speech. Side-by-side
motions share the clock. Without speech a plain clock runs. Every frame is
kept up to :data:`VIEWER_MAX_FRAMES` (ten minutes at 15 fps); a longer result
shows every n-th frame and the page says so.

The page loads nothing from the network. Its data are one JSON object in a
``<script type="application/json" id="gk-data">`` element (see
:func:`viewer_data`), the points as base64 float32 typed arrays like a plotly
figure's (:func:`gesturekit.viz.figures.data_array` reads them).
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
import re
import wave
from collections.abc import Sequence
from typing import TYPE_CHECKING, TypedDict

import numpy as np
import numpy.typing as npt

from ..errors import ConfigError
from ..motion import AUDIO_SR, Motion
from ..skeleton import DERIVED, N_JOINTS, joint_index
from ._plotly import _frames_at, _motions_and_labels, _time_grid, _typed, data_array
from .appearance import APPEARANCE, DERIVED_POINTS, Appearance

if TYPE_CHECKING:
    from typing_extensions import Unpack  # typing.Unpack is Python 3.11+; only the type checker reads it

__all__ = [
    "CONTROLS_HEIGHT",
    "VIEWER_MAX_FRAMES",
    "ViewOptions",
    "skeleton_viewer",
    "viewer_data",
    "read_viewer_data",
    "wav_data_uri",
]

#: Pixels the controls (play button, slider, time, note) take below the drawing.
CONTROLS_HEIGHT = 48

#: Frames a viewer keeps: every frame of ten minutes at 15 fps. A side-by-side pair of that
#: length embeds about 13 MB of points and 19 MB of speech (base64 adds a third).
VIEWER_MAX_FRAMES = 9000

_DATA_ID = "gk-data"
_AUDIO_PREFIX = "data:audio/wav;base64,"


def wav_data_uri(audio: npt.ArrayLike, *, sr: int = AUDIO_SR) -> str:
    """Mono audio as a ``data:audio/wav;base64,...`` URI: 16-bit PCM at ``sr``.

    Parameters
    ----------
    audio : array_like
        Shape (samples,), float in [-1, 1] (clipped beyond; NaN as 0).
    sr : int
        Sample rate, Hz.

    Returns
    -------
    str
        The URI; a sample ``x`` is stored as ``round(x * 32767)``.
    """
    a = np.clip(np.nan_to_num(np.asarray(audio, dtype=np.float64).ravel()), -1.0, 1.0)
    pcm = np.round(a * 32767.0).astype("<i2")
    buf = io.BytesIO()
    with wave.open(buf, "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(int(sr))
        w.writeframes(pcm.tobytes())
    return _AUDIO_PREFIX + base64.b64encode(buf.getvalue()).decode("ascii")


def _read_wav_uri(uri: str) -> tuple[np.ndarray, int]:
    with wave.open(io.BytesIO(base64.b64decode(uri[len(_AUDIO_PREFIX) :])), "rb") as w:
        sr, n = w.getframerate(), w.getnframes()
        pcm = np.frombuffer(w.readframes(n), dtype="<i2")
    return pcm.astype(np.float64) / 32767.0, sr


def _ordinal(n: int) -> str:
    return f"{n}{'th' if 10 <= n % 100 <= 20 else {1: 'st', 2: 'nd', 3: 'rd'}.get(n % 10, 'th')}"


class ViewOptions(TypedDict, total=False):
    """How :func:`viewer_data` lays the motions out: the keywords :func:`skeleton_viewer` passes on to it.

    Attributes
    ----------
    labels : sequence of str or None
    fps : float or None
    title : str or None
    max_frames : int
    spacing : float or None
    appearance : Appearance
        As for :func:`viewer_data` (which names them, with their defaults).
    """

    labels: Sequence[str] | None
    fps: float | None
    title: str | None
    max_frames: int
    spacing: float | None
    appearance: Appearance


def viewer_data(
    motions: Motion | Sequence[Motion],
    *,
    labels: Sequence[str] | None = None,
    fps: float | None = None,
    title: str | None = None,
    max_frames: int = VIEWER_MAX_FRAMES,
    spacing: float | None = None,
    appearance: Appearance = APPEARANCE,
) -> dict:
    """What :func:`skeleton_viewer` draws, as a JSON-ready dict.

    Parameters
    ----------
    motions : Motion or sequence of Motion
        Joint positions, shape (frames, 55, 3), metres, each at its own fps. Motions of
        different lengths are shown together; a shorter one holds its last pose.
    labels : sequence of str, optional
        One name per motion, shown above it.
    fps : float, optional
        The time grid's frame rate; default the highest of the motions'.
    title : str, optional
    max_frames : int
        Most frames kept; a longer grid shows every ``ceil(frames / max_frames)``-th frame.
    spacing : float, optional
        Metres between neighbouring motions along X; default the widest motion plus 0.25 m.
    appearance : Appearance
        The look (:mod:`gesturekit.viz.appearance`).

    Returns
    -------
    dict
        ``title``; ``fps`` (of the time grid) and ``frame_step`` (every ``frame_step``-th
        grid time is shown); ``n_grid`` (frames of the grid); ``times`` (seconds, one per
        shown frame); ``note`` (what the page says about dropped frames, or ``""``);
        ``lo``, ``hi`` (the framing box, metres); ``ground`` (the floor's Y, metres); ``up``
        and ``eye`` (the default camera: Y up, in front of the characters on +Z); ``look``
        (:meth:`Appearance.to_json`); ``capsules`` (``[a, b, radius, part]`` rows) and
        ``spheres`` (``[centre, radius, part]`` rows) indexing each motion's points; ``axis``
        (the points from pelvis to upper chest, along which merged parts are shaded);
        ``motions``: one dict per motion with ``label``, ``color``, ``colors`` (per part),
        ``capsules`` and ``spheres`` (its own, as above: only the joints that exist, those of
        derived joints with the part ``"derived"``), ``shadow`` (whether it has a pelvis to
        stand on), ``derived`` (names of its derived joints; the page says what grey means),
        ``offset`` (metres along X) and ``points``, a typed-array spec of shape
        (shown frames, 61, 3): :meth:`Appearance.body`'s points at the shown times
        (sample and hold), offset along X.

    Raises
    ------
    ConfigError
        No motion, a motion with no frame or with every joint absent, labels of another
        count, a non-positive fps or ``max_frames`` below 1.
    """
    motions, labels = _motions_and_labels(motions, labels, who="skeleton_viewer", drawn=True)
    grid_fps, n_grid, step, times = _time_grid(motions, fps=fps, max_frames=max_frames)
    bodies = [appearance.body(m.positions[_frames_at(m, times)], m.presence) for m in motions]
    if spacing is None:
        widest = max(float(np.ptp(b.drawn_points()[..., 0])) for b in bodies)
        spacing = max(0.8, widest + 0.25)
    offsets = (np.arange(len(motions)) - (len(motions) - 1) / 2) * float(spacing)
    points = [b.points + np.array([dx, 0, 0], dtype=np.float32) for b, dx in zip(bodies, offsets)]
    # framed on what is drawn: absent joints sit on their parents and have no shape
    every = np.concatenate([p[:, b.drawn].reshape(-1, 3) for p, b in zip(points, bodies)])
    ground = appearance.ground_height(every)
    lo, hi = appearance.bounds(every, margin=False)
    lo[1] = min(lo[1], ground)
    pad = appearance.frame_margin * (hi - lo)  # per axis: side by side, X must not shrink Y's margin
    lo, hi = lo - pad, hi + pad
    caps, spheres = bodies[0].capsules, bodies[0].spheres
    out = []
    for i, (label, p, dx, b) in enumerate(zip(labels, points, offsets, bodies)):
        spec = _typed(p.reshape(-1))
        spec["shape"] = f"{p.shape[0]},{p.shape[1]},3"
        parts = sorted({c.part for c in b.capsules} | {s.part for s in b.spheres})
        out.append(
            {
                "label": label or "",
                "color": appearance.color(i),
                "colors": {part: appearance.part_color(i, part) for part in parts},
                "offset": float(dx),
                "points": spec,
                # this motion's shapes: only its joints that exist, derived ones in their own part
                "capsules": [[c.a, c.b, c.radius, c.part] for c in b.capsules],
                "spheres": [[sp.centre, sp.radius, sp.part] for sp in b.spheres],
                "shadow": bool(b.drawn[N_JOINTS + DERIVED_POINTS.index("pelvis")]),
                "derived": list(motions[i].presence.names(DERIVED)),
            }
        )
    note = ""
    if step > 1:
        note = (
            f"every {_ordinal(step)} frame shown: {n_grid} frames are more than the viewer keeps "
            f"({max_frames}); the MP4 has them all"
        )
    return {
        "title": title or "",
        "fps": grid_fps,
        "frame_step": step,
        "n_grid": n_grid,
        "times": [round(float(t), 4) for t in times],
        "note": note,
        "lo": [float(x) for x in lo],
        "hi": [float(x) for x in hi],
        "ground": float(ground),
        "up": [0, 1, 0],
        "eye": [0.0, 0.18, 1.0],
        "look": appearance.to_json(),
        "capsules": [[c.a, c.b, c.radius, c.part] for c in caps],
        "axis": [N_JOINTS + DERIVED_POINTS.index("pelvis"), joint_index("upper_chest")],
        "spheres": [[s.centre, s.radius, s.part] for s in spheres],
        "motions": out,
    }


def read_viewer_data(page: str) -> dict:
    """The data of a :func:`skeleton_viewer` page, with the points and the speech decoded.

    Parameters
    ----------
    page : str
        The HTML text.

    Returns
    -------
    dict
        :func:`viewer_data`'s dict, each motion's ``points`` as a float64 array of shape
        (frames, 61, 3); ``key``, the page's key; ``audio``, the embedded speech (float64
        samples in [-1, 1], shape (samples,)) or None; ``audio_sr`` its rate (Hz) or None.
    """
    start = page.index(f'id="{_DATA_ID}">') + len(f'id="{_DATA_ID}">')
    data = json.loads(page[start : page.index("</script>", start)])
    for m in data["motions"]:
        m["points"] = data_array(m["points"])
    data["key"] = html.unescape(page[page.index('data-key="') + 10 :].split('"', 1)[0])
    data["audio"] = data["audio_sr"] = None
    at = page.find(f'src="{_AUDIO_PREFIX}')
    if at >= 0:
        uri = page[at + 5 : page.index('"', at + 5)]
        data["audio"], data["audio_sr"] = _read_wav_uri(uri)
    return data


def skeleton_viewer(
    motions: Motion | Sequence[Motion],
    *,
    audio: npt.ArrayLike | None = None,
    sr: int = AUDIO_SR,
    height: int = 520,
    key: str = "skeleton",
    **view: Unpack[ViewOptions],
) -> str:
    """A self-contained HTML page that plays one or several motions side by side, with their speech.

    Parameters
    ----------
    motions
        As for :func:`viewer_data`.
    audio : array_like, optional
        The speech, shape (samples,), float in [-1, 1], starting with the motions' first
        frame. When given, the page's play button plays it and its time decides the shown
        frame; when shorter than the motions it is padded with silence, so the last frames
        are reached.
    sr : int
        ``audio``'s sample rate, Hz.
    height : int
        Height of the drawing in pixels (the controls come below it: :data:`CONTROLS_HEIGHT`).
    key : str
        A name for the page (``data-key`` of its body), by which pages and tests find it.
    **view
        :class:`ViewOptions` (``labels``, ``fps``, ``title``, ``max_frames``, ``spacing``,
        ``appearance``), passed on to :func:`viewer_data`.

    Returns
    -------
    str
        The HTML. Once it has drawn its first frame, the page's body has
        ``data-drawn="1"`` and the canvas ``data-frame`` holds the shown frame's index;
        the script's global ``gk`` holds ``frame``, ``frames`` (how many the page holds), ``time`` (the clock, seconds),
        ``audioTime`` (the speech's ``currentTime``, or null), ``playing``, ``drawn``
        (frames drawn so far) and ``drawMs`` (the last draw's milliseconds).

    Raises
    ------
    ConfigError
        As :func:`viewer_data`; ``audio`` not one-dimensional or ``sr`` not positive.
    """
    data = viewer_data(motions, **view)
    audio_tag = ""
    if audio is not None:
        a = np.asarray(audio, dtype=np.float32)
        if a.ndim != 1:
            raise ConfigError(f"the viewer's speech must be mono samples (one dimension), got shape {a.shape}")
        if not (isinstance(sr, (int, np.integer)) and sr > 0):
            raise ConfigError(f"the speech's sample rate must be a positive integer, got {sr!r}")
        need = int(math.ceil(data["n_grid"] / data["fps"] * sr))
        if len(a) < need:  # silence after the speech, so its clock reaches the last frame
            a = np.concatenate([a, np.zeros(need - len(a), np.float32)])
        audio_tag = f'<audio id="gk-audio" preload="auto" src="{wav_data_uri(a, sr=int(sr))}"></audio>'
    # "</" cannot end the data element early: JSON escapes are valid inside a string
    payload = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    fill = {
        "HEIGHT": str(int(height)),
        "KEY": html.escape(key, quote=True),
        "BG": view.get("appearance", APPEARANCE).background,
        "AUDIO": audio_tag,
        "DATA": payload,
    }
    # one pass, so no inserted text is read as a placeholder
    return re.sub(r"__(HEIGHT|KEY|BG|AUDIO|DATA)__", lambda m: fill[m.group(1)], _PAGE)


_PAGE = """<!DOCTYPE html>
<html><head><meta charset="utf-8"><style>
body{margin:0;font-family:"Source Sans Pro",system-ui,sans-serif;font-size:14px;color:#31333f;background:#fff}
#bar{display:flex;align-items:center;gap:10px;height:40px;padding:2px 4px}
button{font:inherit;padding:3px 12px;border:1px solid #ccc;border-radius:6px;background:#fff;cursor:pointer}
input[type=range]{flex:1}
#t{min-width:120px;text-align:right;font-variant-numeric:tabular-nums}
#note{color:#9a6700;font-size:12px}
canvas{display:block;width:100%;cursor:grab;touch-action:none;background:__BG__}
</style></head>
<body data-key="__KEY__">
<canvas id="c" style="height:__HEIGHT__px" title="drag: orbit, scroll: zoom, double-click: reset"></canvas>
<div id="bar"><button id="play">&#9654; Play</button><input id="s" type="range" min="0" value="0" step="1"><span id="t"></span><span id="note"></span></div>
__AUDIO__
<script type="application/json" id="gk-data">__DATA__</script>
<script>
(function () {
  const D = JSON.parse(document.getElementById("gk-data").textContent);
  const dec = (spec) => {
    const b = atob(spec.bdata), n = b.length, u = new Uint8Array(n);
    for (let i = 0; i < n; i++) u[i] = b.charCodeAt(i);
    return {a: new Float32Array(u.buffer), n: Number(spec.shape.split(",")[1])};
  };
  const M = D.motions.map(m => ({label: m.label, color: m.color, colors: m.colors, offset: m.offset, pts: dec(m.points),
    caps: m.capsules, sph: m.spheres, shadow: m.shadow, derived: m.derived || []}));
  const N = D.times.length, shownFps = D.fps / D.frame_step, look = D.look, L = look.light;
  const canvas = document.getElementById("c"), ctx = canvas.getContext("2d");
  const slider = document.getElementById("s"), tlabel = document.getElementById("t"), play = document.getElementById("play");
  const audio = document.getElementById("gk-audio");
  document.getElementById("note").title = D.note;
  slider.max = String(N - 1);
  const lo = D.lo, hi = D.hi, centre = [0, 1, 2].map(i => (lo[i] + hi[i]) / 2);
  const extent = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 0.3);
  const home = {yaw: Math.atan2(D.eye[0], D.eye[2]), pitch: Math.atan2(D.eye[1], Math.hypot(D.eye[0], D.eye[2])), zoom: 1};
  let view = Object.assign({}, home), frame = 0, playing = false, t0 = 0, clock0 = 0;
  const gk = window.gk = {frame: 0, frames: N, time: 0, audioTime: audio ? 0 : null, playing: false, drawn: 0, drawMs: 0};
  const rgb = (hex) => [1, 3, 5].map(i => parseInt(hex.slice(i, i + 2), 16));
  const base = M.map(m => { const o = {}; for (const k in m.colors) o[k] = rgb(m.colors[k]); return o; });
  // the appearance's rule: colour * min(1, ambient + diffuse * max(0, normal . light)), light in the camera frame
  const lit = (c, nx, ny, nz) => {
    const k = Math.min(1, look.ambient + look.diffuse * Math.max(0, nx * L[0] + ny * L[1] + nz * L[2]));
    return "rgb(" + Math.round(c[0] * k) + "," + Math.round(c[1] * k) + "," + Math.round(c[2] * k) + ")";
  };
  const ACROSS = [-1, -0.7, -0.35, 0, 0.35, 0.7, 1];

  function size() {
    const r = window.devicePixelRatio || 1, w = canvas.clientWidth, h = canvas.clientHeight;
    canvas.width = Math.round(w * r); canvas.height = Math.round(h * r);
    ctx.setTransform(r, 0, 0, r, 0, 0);
  }
  function camera() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    const cy = Math.cos(view.yaw), sy = Math.sin(view.yaw), cp = Math.cos(view.pitch), sp = Math.sin(view.pitch);
    const dist = 2.5 * extent;  // the eye's distance from the framing box's centre
    // the framing box's X-Y extent fills the canvas, then the zoom
    const f = view.zoom * dist * Math.min(w / (hi[0] - lo[0]), h / (hi[1] - lo[1]));
    // to camera space (x right, y up, z towards the eye) and then the screen: [sx, sy, z, scale]
    return (x, y, z) => {
      x -= centre[0]; y -= centre[1]; z -= centre[2];
      const x1 = cy * x - sy * z, z1 = sy * x + cy * z;  // about Y
      const y2 = cp * y - sp * z1, z2 = sp * y + cp * z1;  // about X
      const s = f / (dist - z2);
      return [w / 2 + s * x1, h / 2 - s * y2, z2, s];
    };
  }
  function ground(P) {
    // the floor: a band from the framing box's front to its back; a soft shadow under each body
    const g = D.ground, x0 = lo[0] - extent, x1 = hi[0] + extent, z0 = lo[2] - extent, z1 = hi[2] + extent;
    const q = [P(x0, g, z0), P(x1, g, z0), P(x1, g, z1), P(x0, g, z1)];
    ctx.fillStyle = look.ground; ctx.beginPath(); ctx.moveTo(q[0][0], q[0][1]);
    for (let i = 1; i < 4; i++) ctx.lineTo(q[i][0], q[i][1]);
    ctx.closePath(); ctx.fill();
    for (const m of M) {
      if (m.shadow === false) continue;  // a body without a pelvis stands on nothing
      const a = m.pts.a, o = (frame * m.pts.n + 55) * 3;  // the pelvis, the first derived point
      const c = P(a[o], g, a[o + 2]), ex = P(a[o] + 0.28, g, a[o + 2]), ez = P(a[o], g, a[o + 2] + 0.2);
      const rx = Math.hypot(ex[0] - c[0], ex[1] - c[1]), ry = Math.max(2, Math.hypot(ez[0] - c[0], ez[1] - c[1]));
      ctx.save(); ctx.translate(c[0], c[1]); ctx.scale(1, ry / rx);
      const grad = ctx.createRadialGradient(0, 0, 0, 0, 0, rx);
      grad.addColorStop(0, "rgba(0,0,0," + look.shadow_alpha + ")"); grad.addColorStop(1, "rgba(0,0,0,0)");
      ctx.fillStyle = grad; ctx.beginPath(); ctx.arc(0, 0, rx, 0, 2 * Math.PI); ctx.fill(); ctx.restore();
    }
  }
  function shading(c, p, r, ux, uy, half) {
    // across a cylinder from p to r on screen, half its width wide: the normal at a fraction s of
    // the way across is s * across + sqrt(1 - s^2) * towards the eye (camera y points up, screen y down)
    const mx = (p[0] + r[0]) / 2, my = (p[1] + r[1]) / 2;
    const g = ctx.createLinearGradient(mx - ux * half, my - uy * half, mx + ux * half, my + uy * half);
    for (const s of ACROSS) g.addColorStop((s + 1) / 2, lit(c, s * ux, -s * uy, Math.sqrt(1 - s * s)));
    return g;
  }
  function group(it) {
    const p = it.p, r = it.r, dx = r[0] - p[0], dy = r[1] - p[1], len = Math.hypot(dx, dy);
    const ux = len > 1e-6 ? -dy / len : 1, uy = len > 1e-6 ? dx / len : 0;
    let half = 1;
    for (const c of it.group) for (const e of [c.p, c.r]) {
      half = Math.max(half, Math.abs((e[0] - (p[0] + r[0]) / 2) * ux + (e[1] - (p[1] + r[1]) / 2) * uy) + c.rad);
    }
    ctx.strokeStyle = shading(it.col, p, r, ux, uy, half);
    for (const c of it.group) {
      ctx.lineWidth = 2 * c.rad; ctx.beginPath(); ctx.moveTo(c.p[0], c.p[1]); ctx.lineTo(c.r[0] + 0.01, c.r[1]); ctx.stroke();
    }
  }
  function draw() {
    const started = performance.now();
    const w = canvas.clientWidth, h = canvas.clientHeight;
    ctx.clearRect(0, 0, w, h);
    const P = camera();
    ground(P);
    // every shape of every motion, painted far to near
    const items = [];
    M.forEach((m, mi) => {
      const a = m.pts.a, n = m.pts.n, o = frame * n * 3, q = new Array(n);
      for (let i = 0; i < n; i++) q[i] = P(a[o + 3 * i], a[o + 3 * i + 1], a[o + 3 * i + 2]);
      const merged = {};
      for (const c of (m.caps || D.capsules)) {
        const p = q[c[0]], r = q[c[1]];
        const it = {z: (p[2] + r[2]) / 2, cap: true, p: p, r: r, rad: c[2] * (p[3] + r[3]) / 2, col: base[mi][c[3]]};
        if (look.merged.indexOf(c[3]) < 0) { items.push(it); continue; }
        (merged[c[3]] = merged[c[3]] || []).push(it);
      }
      for (const part in merged) {
        // one surface: its capsules share one shading, a cylinder along the spine
        const caps = merged[part], a = q[D.axis[0]], b = q[D.axis[1]];
        items.push({z: caps.reduce((s, c) => s + c.z, 0) / caps.length, group: caps, p: a, r: b, col: base[mi][part]});
      }
      for (const s of (m.sph || D.spheres)) { const p = q[s[0]]; items.push({z: p[2], cap: false, p: p, rad: s[1] * p[3], col: base[mi][s[2]]}); }
    });
    items.sort((u, v) => u.z - v.z);
    ctx.lineCap = "round";
    for (const it of items) {
      const p = it.p, c = it.col;
      if (it.group) { group(it); continue; }
      if (!it.cap) {
        // a sphere: brightest where its normal meets the light
        const g = ctx.createRadialGradient(p[0] - L[0] * 0.45 * it.rad, p[1] + -L[1] * 0.45 * it.rad, 0.05 * it.rad, p[0], p[1], it.rad);
        g.addColorStop(0, lit(c, L[0], L[1], L[2])); g.addColorStop(0.6, lit(c, L[0] * 0.6, L[1] * 0.6, 0.8));
        g.addColorStop(1, lit(c, -L[0], -L[1], 0.15));
        ctx.fillStyle = g; ctx.beginPath(); ctx.arc(p[0], p[1], it.rad, 0, 2 * Math.PI); ctx.fill();
        continue;
      }
      const r = it.r, dx = r[0] - p[0], dy = r[1] - p[1], len = Math.hypot(dx, dy);
      // across the limb on screen; in camera space y points the other way
      const ux = len > 1e-6 ? -dy / len : 1, uy = len > 1e-6 ? dx / len : 0;
      ctx.lineWidth = 2 * it.rad;
      if (it.rad < 2.2) {
        ctx.strokeStyle = lit(c, 0, 0, 1);
      } else {
        ctx.strokeStyle = shading(c, p, r, ux, uy, it.rad);
      }
      ctx.beginPath(); ctx.moveTo(p[0], p[1]); ctx.lineTo(r[0] + (len < 0.01 ? 0.01 : 0), r[1]); ctx.stroke();
    }
    ctx.fillStyle = "#31333f"; ctx.textAlign = "center"; ctx.font = "13px sans-serif";
    if (M.length > 1) for (const m of M) {
      if (!m.label) continue;
      const q = P(centre[0] + m.offset, hi[1], centre[2]);
      ctx.fillText(m.label, q[0], Math.max(14, q[1]));
    }
    if (M.some(m => m.derived.length)) {
      // joints the data does not hold, placed from others, are grey: say so on the picture
      ctx.fillStyle = look.derived; ctx.font = "12px sans-serif"; ctx.textAlign = "right";
      ctx.fillText("grey: derived (placed from neck and shoulders)", w - 8, h - 8);
    }
    if (D.title) { ctx.font = "15px sans-serif"; ctx.textAlign = "left"; ctx.fillText(D.title, 8, 20); }
    if (D.note) { ctx.fillStyle = "#9a6700"; ctx.font = "12px sans-serif"; ctx.textAlign = "left"; ctx.fillText(D.note, 8, h - 8); }
    slider.value = String(frame);
    const total = D.n_grid / D.fps;
    tlabel.textContent = D.times[frame].toFixed(2) + " / " + total.toFixed(2) + " s";
    canvas.dataset.frame = String(frame);
    document.body.dataset.drawn = "1";
    gk.frame = frame; gk.drawn += 1; gk.drawMs = performance.now() - started;
  }
  const frameAt = (t) => Math.min(N - 1, Math.max(0, Math.floor(t * shownFps + 1e-6)));
  function now() {
    // the clock: the speech's time when there is speech, else a plain one
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
      if (audio) audio.pause(); else { clock0 = now(); }
      stopped(); show(now()); return;
    }
    const atEnd = frame >= N - 1;
    if (audio) {
      if (atEnd || audio.ended) audio.currentTime = 0;
      audio.play().then(start, (e) => { document.getElementById("note").textContent = "the speech cannot play: " + e.message; });
    } else {
      if (atEnd) clock0 = 0; else clock0 = D.times[frame];
      t0 = performance.now(); start();
    }
  }
  if (audio) {
    audio.addEventListener("ended", () => { stopped(); show(audio.currentTime); });
    audio.addEventListener("pause", () => { if (playing) { stopped(); show(audio.currentTime); } });
    audio.addEventListener("seeked", () => { if (!playing) show(audio.currentTime); });
  }
  play.addEventListener("click", toggle);
  document.addEventListener("keydown", (e) => { if (e.code === "Space") { e.preventDefault(); toggle(); } });
  slider.addEventListener("input", () => {
    const k = Number(slider.value), t = D.times[k] + 0.25 / D.fps;  // inside frame k's interval
    if (audio) audio.currentTime = t; else { clock0 = t; t0 = performance.now(); }
    frame = k; gk.time = t; draw();
  });
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
