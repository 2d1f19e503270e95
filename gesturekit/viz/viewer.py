"""A 3D viewer of motions as people: one self-contained HTML page that draws the skinned character with three.js.

:func:`skeleton_viewer` shows several motions side by side, each as the
character of :mod:`gesturekit.character` (its mesh skinned to the motion's rig,
posed by the rig's joint rotations) in the shared look of
:mod:`gesturekit.character.look`: the same colours, Lambert light and camera as
the MP4. The page draws with WebGL (three.js, bundled from the npm registry by
:mod:`gesturekit.viz.web.build` and inlined), without antialiasing or shadows,
so that a browser without a GPU draws it in software at once; where WebGL is
missing the page says so and its controls still play the speech. Drag to
orbit, scroll to zoom, double-click to reset the view; space toggles play.

Playback has one clock. Given the speech, the page embeds it (16-bit WAV, as a
data URI in an ``<audio>`` element) and the one play button plays it: the
shown frame is always ``floor(audio.currentTime * shown fps)``, so gesture and
speech stay in sync, and moving the slider seeks the speech. Side-by-side
motions share the clock. Without speech a plain clock runs. Every frame is
kept up to :data:`VIEWER_MAX_FRAMES` (ten minutes at 15 fps); a longer result
shows every n-th frame and the page says so.

The page loads nothing from the network. Its data are one JSON object in a
``<script type="application/json" id="gk-data">`` element (see
:func:`viewer_data`), the arrays as base64 little-endian typed arrays like a
plotly figure's (:func:`gesturekit.viz.figures.data_array` reads them).

The same bundle also serves a page of its own, the build's ``static/index.html``,
which takes :func:`viewer_args` (the data as JSON text, the speech as WAV bytes)
from Streamlit's component protocol: the app shows the viewer as a component, so
the browser fetches the bundle once and caches it, and a rerun that sends the
same args keeps the drawn view.
"""

from __future__ import annotations

import base64
import hashlib
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

from .._arguments import checks_arguments
from ..character import look
from ..character.mesh import build_mesh
from ..character.paint import EMPTY_BODY, paint
from ..character.retarget import retarget
from ..character.rig import Rig, rig_for, rotation_to_quaternion, solve_pose
from ..character.stand import StandMesh, stand_mesh, standing_root
from ..character.target import Character
from ..datasets.audio import wav_bytes
from ..errors import ConfigError
from ..motion import AUDIO_SR, Motion
from ..skeleton import DERIVED, JOINT_NAMES, N_JOINTS
from ._plotly import _frames_at, _motions_and_labels, _time_grid
from .character_page import QUATERNION_SCALE, framed_points, page_character, typed_array
from .web.build import SHELL, bundle

if TYPE_CHECKING:
    from typing_extensions import Unpack  # typing.Unpack is Python 3.11+; only the type checker reads it

__all__ = [
    "CONTROLS_HEIGHT",
    "VIEWER_MAX_FRAMES",
    "QUATERNION_SCALE",
    "ViewOptions",
    "skeleton_viewer",
    "viewer_data",
    "read_viewer_data",
    "wav_data_uri",
    "ViewerArgs",
    "viewer_args",
    "read_viewer_args",
]

#: Pixels the controls (play button, slider, time, note) take below the drawing.
CONTROLS_HEIGHT = 48

#: Frames a viewer keeps: every frame of ten minutes at 15 fps. A side-by-side pair of that
#: length embeds about 8 MB of joint rotations and 19 MB of speech (base64 adds a third).
VIEWER_MAX_FRAMES = 9000

_DATA_ID = "gk-data"
_AUDIO_PREFIX = "data:audio/wav;base64,"


@checks_arguments
def wav_data_uri(audio: npt.ArrayLike, *, sr: int = AUDIO_SR) -> str:
    """Mono audio as a ``data:audio/wav;base64,...`` URI of :func:`wav_bytes` (same parameters)."""
    return _AUDIO_PREFIX + base64.b64encode(wav_bytes(audio, sr=sr)).decode("ascii")


def _read_wav(data: bytes) -> tuple[np.ndarray, int]:
    with wave.open(io.BytesIO(data), "rb") as w:
        sr, n = w.getframerate(), w.getnframes()
        pcm = np.frombuffer(w.readframes(n), dtype="<i2")
    return pcm.astype(np.float64) / 32767.0, sr


def _read_wav_uri(uri: str) -> tuple[np.ndarray, int]:
    return _read_wav(base64.b64decode(uri[len(_AUDIO_PREFIX) :]))


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
    neutral : bool
    character : Character or None
    schemes : sequence of str or None
    framing : str
        As for :func:`viewer_data` (which names them, with their defaults).
    """

    labels: Sequence[str] | None
    fps: float | None
    title: str | None
    max_frames: int
    spacing: float | None
    neutral: bool
    character: Character | None
    schemes: Sequence[str] | None
    framing: str


class ViewerArgs(TypedDict):
    """:func:`viewer_args`' result: the component's args.

    Attributes
    ----------
    data : str
        :func:`viewer_data`'s dict as JSON text.
    audio : bytes or None
        The speech as a WAV file.
    hash : str
        SHA-256 (hex) of both.
    """

    data: str
    audio: bytes | None
    hash: str


def _array(spec: dict) -> np.ndarray:
    """A typed-array spec's values, in its own dtype (native byte order) and shape."""
    out = np.frombuffer(base64.b64decode(spec["bdata"]), dtype=np.dtype(spec["dtype"]).newbyteorder("<"))
    return out.astype(out.dtype.newbyteorder("=")).reshape(tuple(int(n) for n in spec["shape"].split(",")))


def _page_parents(rig: Rig) -> list[int]:
    """Each joint's bone parent on the page: the rig's, and for a joint not in the rig its nearest ancestor in it
    (where it sits, unrotated), so every joint has a bone and none hangs loose."""
    from ..skeleton import PARENTS

    out = []
    for j in range(N_JOINTS):
        p = int(rig.parents[j])
        if p == -2:
            p = int(PARENTS[j])
            while p >= 0 and rig.parents[p] == -2:
                p = int(PARENTS[p])
            p = p if p >= 0 else rig.root
        out.append(p)
    return out


def _stand_spec(stand: StandMesh) -> dict:
    """The still legs' arrays (:func:`gesturekit.character.stand.stand_mesh`) as typed-array specs."""
    return {
        "vertices": typed_array(stand.vertices, "f4"),
        "normals": typed_array(stand.normals, "f4"),
        "faces": typed_array(stand.faces, "u2" if stand.n_vertices < 2**16 else "u4"),
        "parts": typed_array(stand.parts, "u1"),
    }


def _flat_spec(mesh: dict) -> dict:
    """An unlit stage mesh of :func:`gesturekit.character.look.stage_meshes` as typed-array specs."""
    return {
        "vertices": typed_array(mesh["vertices"], "f4"),
        "faces": typed_array(mesh["faces"], "u4"),
        "colors": typed_array(mesh["colors"], "u1"),
    }


def _character(motion: Motion, scheme: str) -> tuple[dict, StandMesh | None]:
    """One motion's rig, mesh and animation (over all its frames), as typed-array specs, and its still legs."""
    rig = rig_for(motion)
    pose = solve_pose(motion, rig)
    # a motion without a bone of any length (every joint at one point) has no body to build around
    has_body = bool((rig.lengths[rig.parents >= 0] > 1e-6).any())
    mesh = build_mesh(rig) if has_body else EMPTY_BODY
    stand = stand_mesh(rig, standing_root(pose.root)) if has_body else None
    quats = np.round(rotation_to_quaternion(pose.local) * QUATERNION_SCALE).astype(np.int16)
    mesh, colors = paint(mesh, motion.presence, scheme)
    return {
        "stand": _stand_spec(stand) if stand is not None else None,
        "scheme": scheme,
        "colors": [[round(float(c), 6) for c in row] for row in colors],
        "rig": {
            "names": list(JOINT_NAMES),
            "parents": _page_parents(rig),
            "in_rig": [bool(x) for x in rig.in_rig],
            "offsets": typed_array(rig.offsets, "f4"),
            "rest": typed_array(rig.rest, "f4"),
        },
        "mesh": {
            "vertices": typed_array(mesh.vertices, "f4"),
            "normals": typed_array(mesh.normals, "f4"),
            "faces": typed_array(mesh.faces, "u2" if mesh.n_vertices < 2**16 else "u4"),
            "joints": typed_array(mesh.joints, "u1"),
            "weights": typed_array(mesh.weights, "f4"),
            "parts": typed_array(mesh.parts, "u1"),
        },
        "rotations": typed_array(quats, "i2"),
        "root": typed_array(pose.root, "f4"),
    }, stand


@checks_arguments
def viewer_data(
    motions: Motion | Sequence[Motion],
    *,
    labels: Sequence[str] | None = None,
    fps: float | None = None,
    title: str | None = None,
    max_frames: int = VIEWER_MAX_FRAMES,
    spacing: float | None = None,
    neutral: bool = False,
    character: Character | None = None,
    schemes: Sequence[str] | None = None,
    framing: str = look.UPPER_BODY,
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
        Metres between neighbouring motions along X; default :func:`gesturekit.character.look.stage_layout`'s.
    neutral : bool
        Every motion in :data:`gesturekit.character.look.NEUTRAL`'s colours (else the k-th takes
        :func:`~gesturekit.character.look.scheme_for` ``(k)``).
    character : Character, optional
        A user's character (:func:`gesturekit.character.user.read_character`): every motion is
        retargeted onto it (:func:`gesturekit.character.retarget.retarget`) and drawn as that
        character, its mesh and colours (a character without a mesh as
        :func:`gesturekit.character.bone_body.bone_body` in the motion's scheme), framed on its
        pelvis, matched bones and head (see :mod:`gesturekit.viz.character_page`).
    schemes : sequence of str, optional
        Each motion's colour scheme (keys of :data:`gesturekit.character.look.SCHEMES`), by what it shows
        (:func:`~gesturekit.character.look.role_scheme`, :func:`~gesturekit.character.look.rank_scheme`);
        default by place (:func:`~gesturekit.character.look.scheme_for`).
    framing : str
        The view's first framing (:data:`gesturekit.character.look.FRAMINGS`); the page's button switches
        between the two boxes (``box`` and ``boxes``).

    Returns
    -------
    dict
        ``title``; ``fps`` (of the time grid) and ``frame_step`` (every ``frame_step``-th
        grid time is shown); ``n_grid`` (frames of the grid); ``times`` (seconds, one per
        shown frame); ``note`` (what the page says about dropped frames, or ``""``);
        ``box`` (the framed box's lower and upper corners, metres, from
        :func:`~gesturekit.character.look.stage_layout` in ``framing``), ``boxes`` (the box of each of
        :data:`~gesturekit.character.look.FRAMINGS`), ``framing``, ``ground`` (the floor's height, metres, or
        None without legs), ``stage`` (the floor and each character's contact shadow,
        :func:`~gesturekit.character.look.stage_meshes`: ``vertices``, ``faces``, sRGB ``colors`` (u1)),
        ``up`` (Y) and ``look`` (``background``, ``ambient``, ``key``, ``light``, ``lights`` (each
        ``[direction, strength]``), ``fov``, ``view``, ``depth_share``: the page's camera is
        :func:`~gesturekit.character.look.camera_for` of ``box`` at its own aspect ratio, its top kept at the
        top in the upper-body framing; ``least_height``: the drawing is
        :func:`~gesturekit.character.look.fitted_height` of the upper-body box high, at most as high as asked);
        ``motions``: one dict per motion with ``label``, ``offset`` (metres along X),
        ``derived`` (names of its derived joints; the page says what grey means), ``scheme``,
        ``colors`` (sRGB in [0, 1] of each of :data:`~gesturekit.character.mesh.PARTS`, then of
        derived parts), ``rig`` (``names``, ``parents`` (a joint not in the rig hangs from its
        nearest ancestor in it), ``in_rig``, ``offsets`` and ``rest``, shape (55, 3), metres),
        ``mesh`` (:class:`~gesturekit.character.mesh.CharacterMesh`'s arrays, ``parts``
        indexing ``colors``), ``stand`` (the still legs, :func:`gesturekit.character.stand.stand_mesh`:
        ``vertices``, ``normals``, ``faces``, ``parts`` indexing ``colors``, in the motion's frame; None
        without a body or on a user's character), ``rotations`` (each joint's rotation relative to its parent per
        shown frame, shape (shown frames, 55, 4), xyzw quaternions times
        :data:`QUATERNION_SCALE` as int16) and ``root`` (the root's position per shown frame,
        shape (shown frames, 3), metres). Arrays are typed-array specs (``dtype``, ``bdata``,
        ``shape``). With ``character``, ``rig`` holds its bones instead of our 55 joints
        (:func:`gesturekit.viz.character_page.page_character`), ``colors`` its palette and ``derived`` is empty;
        a motion whose mesh is the first motion's has ``mesh`` ``{"shared": 0}`` (the page, and
        :func:`read_viewer_data`, take the first's).

    Raises
    ------
    ConfigError
        No motion, a motion with no frame or with every joint absent, labels of another
        count, a non-positive fps or ``max_frames`` below 1.
    """
    motions, labels = _motions_and_labels(motions, labels, who="skeleton_viewer", drawn=True)
    if schemes is not None and len(schemes) != len(motions):
        raise ConfigError(f"{len(motions)} motions need as many colour schemes, got {len(schemes)}")
    if schemes is not None:
        unknown = [s for s in schemes if s not in look.SCHEMES]
        if unknown:
            raise ConfigError(f"unknown colour scheme {unknown[0]!r}; choose one of {', '.join(look.SCHEMES)}")
    if framing not in look.FRAMINGS:
        raise ConfigError(f"unknown framing {framing!r}; choose one of {', '.join(look.FRAMINGS)}")
    grid_fps, n_grid, step, times = _time_grid(motions, fps=fps, max_frames=max_frames)
    shown = [Motion(m.positions[_frames_at(m, times)], m.fps, m.presence) for m in motions]
    if character is not None:
        posed = [retarget(s, character) for s in shown]
        drawn = [framed_points(r) for r in posed]
    else:
        # framed on what is drawn: joints not in the data have no body
        drawn = [s.positions[:, np.array([st != "absent" for st in s.presence.status])] for s in shown]
    offsets, _ = look.stage_layout(drawn, spacing=spacing)
    out: list[dict] = []
    stands: list[StandMesh | None] = []
    for i, (label, m, dx) in enumerate(zip(labels, shown, offsets)):
        scheme = look.scheme_for(i, neutral=neutral) if schemes is None else schemes[i]
        if character is not None:
            spec = {"label": label or "", "offset": float(dx), "derived": []}
            spec.update(page_character(posed[i], scheme=scheme))
            if i and spec["mesh"] == out[0]["mesh"]:  # one character side by side: its mesh sent once
                spec["mesh"] = {"shared": 0}
        else:
            spec = {"label": label or "", "offset": float(dx), "derived": list(m.presence.names(DERIVED))}
            body, stand = _character(m, scheme)
            spec.update(body)
            stands.append(stand)
        out.append(spec)
    floors = [st.floor for st in stands if st is not None]
    ground = min(floors) if floors else None
    waist = min(st.pelvis for st in stands if st is not None) if floors else None
    boxes = {
        f: look.stage_layout(drawn, spacing=spacing, framing=f, ground=ground, waist=waist)[1] for f in look.FRAMINGS
    }
    box = boxes[framing]
    stage: list[dict] = []
    if ground is not None:
        feet = [
            np.array([dx, 0.0, 0.0]) + st.vertices.mean(axis=0) for st, dx in zip(stands, offsets) if st is not None
        ]
        stage = [_flat_spec(s) for s in look.stage_meshes(boxes[look.FULL_BODY], ground, feet)]
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
        "box": [[float(x) for x in corner] for corner in box],
        "boxes": {f: [[float(x) for x in corner] for corner in b] for f, b in boxes.items()},
        "framing": framing,
        "ground": ground,
        "stage": stage,
        "up": [0, 1, 0],
        "look": {
            "background": look.BACKGROUND,
            "ambient": look.AMBIENT,
            "key": look.KEY,
            "light": list(look.LIGHT_DIRECTION),
            "lights": [[list(d), k] for d, k in look.LIGHTS],
            "fov": look.FIELD_OF_VIEW,
            "view": list(look.VIEW_DIRECTION),
            "depth_share": look.DEPTH_SHARE,
            "least_height": look.LEAST_VIEW_HEIGHT,
        },
        "motions": out,
    }


def _quaternion_matrices(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) xyzw, normalised first."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def _joint_positions(m: dict) -> np.ndarray:
    """Forward kinematics of a decoded motion, as the page poses its bones: shape (frames, 55, 3), metres,
    shifted by the motion's offset along X."""
    rot = _quaternion_matrices(m["rotations"])
    parents, offsets = m["rig"]["parents"], m["rig"]["offsets"].astype(np.float64)
    world = np.empty_like(rot)
    pos = np.empty(rot.shape[:2] + (3,))
    for j, p in enumerate(parents):  # parents precede children
        if p < 0:
            world[:, j], pos[:, j] = rot[:, j], m["root"]
        else:
            world[:, j] = world[:, p] @ rot[:, j]
            pos[:, j] = pos[:, p] + world[:, p] @ (offsets[j] if m["rig"]["in_rig"][j] else np.zeros(3))
    return pos + np.array([m["offset"], 0.0, 0.0])


@checks_arguments
def read_viewer_data(page: str) -> dict:
    """The data of a :func:`skeleton_viewer` page, with its arrays and the speech decoded.

    Parameters
    ----------
    page : str
        The HTML text.

    Returns
    -------
    dict
        :func:`viewer_data`'s dict, its arrays decoded (the rotations as float quaternions,
        shape (frames, 55, 4), the int16 divided by :data:`QUATERNION_SCALE`), each motion
        with ``points``: its joints where the page puts them (forward kinematics of the rig
        with the rotations and root positions, shifted by the offset), float64, shape
        (frames, 55, 3), metres (a user's character: (frames, B, 3), its bones); a mesh shared with
        the first motion is that motion's mesh; ``key``, the page's key; ``audio``, the embedded speech
        (float64 samples in [-1, 1], shape (samples,)) or None; ``audio_sr`` its rate (Hz) or None.
    """
    start = page.index(f'id="{_DATA_ID}">') + len(f'id="{_DATA_ID}">')
    data = _decoded(json.loads(page[start : page.index("</script>", start)]))
    data["key"] = html.unescape(page[page.index('data-key="') + 10 :].split('"', 1)[0])
    data["audio"] = data["audio_sr"] = None
    at = page.find(f'src="{_AUDIO_PREFIX}')
    if at >= 0:
        uri = page[at + 5 : page.index('"', at + 5)]
        data["audio"], data["audio_sr"] = _read_wav_uri(uri)
    return data


def _decoded(data: dict) -> dict:
    """:func:`viewer_data`'s dict with its arrays decoded and each motion's ``points`` (see :func:`read_viewer_data`)."""
    data["stage"] = [{name: _array(value) for name, value in mesh.items()} for mesh in data.get("stage", [])]
    for m in data["motions"]:
        if "shared" in m["mesh"]:
            m["mesh"] = data["motions"][m["mesh"]["shared"]]["mesh"]
        for group in ("rig", "mesh"):
            for name, value in m[group].items():
                if isinstance(value, dict):
                    m[group][name] = _array(value)
        if m.get("stand"):
            m["stand"] = {name: _array(value) for name, value in m["stand"].items()}
        m["rotations"] = _array(m["rotations"]).astype(np.float64) / QUATERNION_SCALE
        m["root"] = _array(m["root"]).astype(np.float64)
        m["points"] = _joint_positions(m)
    return data


def _speech(audio: npt.ArrayLike, sr: int, data: dict) -> np.ndarray:
    """``audio`` checked and padded with silence up to the last frame of ``data`` (:func:`viewer_data`'s)."""
    a = np.asarray(audio, dtype=np.float32)
    if a.ndim != 1:
        raise ConfigError(f"the viewer's speech must be mono samples (one dimension), got shape {a.shape}")
    if not (isinstance(sr, (int, np.integer)) and sr > 0):
        raise ConfigError(f"the speech's sample rate must be a positive integer, got {sr!r}")
    need = int(math.ceil(data["n_grid"] / data["fps"] * sr))
    if len(a) < need:  # silence after the speech, so its clock reaches the last frame
        a = np.concatenate([a, np.zeros(need - len(a), np.float32)])
    return a


@checks_arguments
def viewer_args(
    motions: Motion | Sequence[Motion],
    *,
    audio: npt.ArrayLike | None = None,
    sr: int = AUDIO_SR,
    **view: Unpack[ViewOptions],
) -> ViewerArgs:
    """What the viewer's bundle draws when it is served as a component: :func:`skeleton_viewer`'s page without the page.

    Parameters
    ----------
    motions, audio, sr, **view
        As for :func:`skeleton_viewer`.

    Returns
    -------
    ViewerArgs
        ``data``: :func:`viewer_data`'s dict as JSON text; ``audio``: the speech (padded as
        :func:`skeleton_viewer` pads it) as a 16-bit WAV file's bytes, or None; ``hash``: SHA-256
        (hex) of both, by which the page knows a viewer it already shows.

    Raises
    ------
    ConfigError
        As :func:`skeleton_viewer`.
    """
    data = viewer_data(motions, **view)
    wav = None if audio is None else wav_bytes(_speech(audio, sr, data), sr=int(sr))
    text = json.dumps(data, separators=(",", ":"))
    digest = hashlib.sha256(text.encode())
    digest.update(b"\0" + (wav if wav is not None else b"no speech"))
    return {"data": text, "audio": wav, "hash": digest.hexdigest()}


@checks_arguments
def read_viewer_args(data: str, audio: bytes | None, key: str) -> dict:
    """:func:`viewer_args`' data and speech decoded, as :func:`read_viewer_data` decodes a page.

    Parameters
    ----------
    data : str
        The JSON text (``viewer_args(...)["data"]``).
    audio : bytes or None
        The WAV bytes.
    key : str
        The viewer's key.

    Returns
    -------
    dict
        As :func:`read_viewer_data`.
    """
    out = _decoded(json.loads(data))
    out["key"] = key
    out["audio"] = out["audio_sr"] = None
    if audio is not None:
        out["audio"], out["audio_sr"] = _read_wav(bytes(audio))
    return out


@checks_arguments
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
        ``neutral``, ``character``), passed on to :func:`viewer_data`.

    Returns
    -------
    str
        The HTML, with the viewer's bundle (three.js included) inlined as a module script. Once
        it has drawn its first frame, the page's body has ``data-drawn="1"`` and the canvas
        ``data-frame`` holds the shown frame's index; the script's global ``gk`` holds
        ``frame``, ``frames`` (how many the page holds), ``time`` (the clock, seconds),
        ``audioTime`` (the speech's ``currentTime``, or null), ``playing``, ``drawn`` (frames
        drawn so far) and ``drawMs`` (the last draw's milliseconds).

    Raises
    ------
    ConfigError
        As :func:`viewer_data`; ``audio`` not one-dimensional or ``sr`` not positive.
    FileNotFoundError
        The viewer's bundle is not built (``python -m gesturekit.viz.web.build``).
    """
    data = viewer_data(motions, **view)
    audio_tag = ""
    if audio is not None:
        a = _speech(audio, sr, data)
        audio_tag = f'<audio id="gk-audio" preload="auto" src="{wav_data_uri(a, sr=int(sr))}"></audio>'
    # "</" cannot end the data element early: JSON escapes are valid inside a string
    payload = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    fill = {
        "HEIGHT": str(int(height)),
        "KEY": html.escape(key, quote=True),
        "BG": look.BACKGROUND,
        "AUDIO": audio_tag,
        "DATA": payload,
        "BUNDLE": _inline_bundle(),
    }
    # one pass, so no inserted text is read as a placeholder
    return re.sub(r"__(HEIGHT|KEY|BG|AUDIO|DATA|BUNDLE)__", lambda m: fill[m.group(1)], _PAGE)


def _inline_bundle() -> str:
    """The bundle as a module script's text: nothing in it may end the script element."""
    text = bundle()
    # "</script" only occurs inside the bundle's strings, where "<\/" reads the same
    return text.replace("</script", "<\\/script")


_PAGE = (
    SHELL
    + """__AUDIO__
<script type="application/json" id="gk-data">__DATA__</script>
<script type="module">__BUNDLE__</script></body></html>
"""
)
