"""Example takes in the layout of keypoints lifted from video, generated from the demo speaker.

The layout of the paper's own data (speakers filmed, their keypoints lifted to 3D):
49 source joints, neck-relative, image-like axes, 15 fps, bone lengths that vary
from frame to frame:

- column 0: ``neck``;
- columns 1-6: ``r_shoulder, r_elbow, r_wrist, l_shoulder, l_elbow, l_wrist``;
- columns 7-27: the left hand, ``l_hand0`` .. ``l_hand20``; 28-48 the right hand.
  A hand is its root (which repeats the wrist), then thumb, index, middle, ring
  and little finger, four joints each from the root to the tip;
- axes: x to the image's right (the speaker's left), y down, z away from the
  camera (the speaker faces the camera): up is ``-y``, forward is ``-z``;
- metres, relative to the neck; no pelvis, spine or head.

:func:`write_keypoint_example` writes such takes (``NAME.txt|.csv|.npy`` with the
speech ``NAME.wav`` beside each) and the JSON joint map for the layout
(``joint_map.json``, mapping the torso and head joints to ``null``). From the
command line::

    python -m gesturekit.datasets.keypoint_example OUT [--format txt|csv|npy] [--takes N] [--seconds S]
        [--scales S0 S1 ...] [--fan-jitter DEGREES]
"""

from __future__ import annotations

import argparse
import io
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np

from .._arguments import checks_arguments
from .._io import atomic_write
from ..errors import ConfigError, GestureKitError
from ..motion import AUDIO_SR
from ..skeleton import FINGERS, FPS, HAND_JOINT_SUFFIXES, N_JOINTS, PARENTS, joint_index
from .audio import wav_bytes
from .synthetic import generate_demo_take

__all__ = ["KEYPOINT_NAMES", "FORMATS", "keypoint_joint_map", "keypoint_positions", "write_keypoint_example", "main"]

_ARMS = ("shoulder", "elbow", "wrist")
#: The 49 source joints of the layout, in column order.
KEYPOINT_NAMES: tuple[str, ...] = (
    ("neck",)
    + tuple(f"{s}_{j}" for s in ("r", "l") for j in _ARMS)
    + tuple(f"{s}_hand{i}" for s in ("l", "r") for i in range(21))
)
FORMATS: tuple[str, ...] = ("txt", "csv", "npy")
#: Relative standard deviation of each bone's length per frame (a few per cent).
BONE_NOISE = 0.03
# ours (Y up, faces +Z, left +X) -> the layout's (x right = the speaker's left, y down, z away)
_TO_IMAGE = np.diag([1.0, -1.0, -1.0])
# the bones leaving the wrists: the hand's fan of finger roots
_FINGER_ROOTS = tuple(joint_index(f"{side}_{finger}1") for side in ("left", "right") for finger in FINGERS)


def _our_joint_of_column() -> dict[str, str | None]:
    """Source column name -> our joint (None for the hand roots, which repeat the wrists)."""
    out: dict[str, str | None] = {"neck": "neck"}
    for s, side in (("r", "right"), ("l", "left")):
        for j in _ARMS:
            out[f"{s}_{j}"] = f"{side}_{j}"
        for i, suffix in enumerate(HAND_JOINT_SUFFIXES):
            out[f"{s}_hand{i}"] = None if suffix == "wrist" else f"{side}_{suffix}"
    return out


@checks_arguments
def keypoint_joint_map() -> dict:
    """The position joint map of the layout: a dict for :func:`gesturekit.datasets.positions.load_position_joint_map`.

    The torso, head and collars, which the layout lacks, are mapped to ``null``
    (derived when read); the hand roots are not used (they repeat the wrists).
    """
    joints: dict[str, str | None] = {
        n: None
        for n in ("spine_mid", "chest", "upper_chest", "neck_upper", "head", "head_top", "left_collar", "right_collar")
    }
    joints.update({ours: col for col, ours in _our_joint_of_column().items() if ours is not None})
    return {"pelvis": None, "names": list(KEYPOINT_NAMES), "joints": joints}


@checks_arguments
def keypoint_positions(
    positions: np.ndarray, *, seed: int, noise: float = BONE_NOISE, scale: float = 1.0, fan_jitter: float = 0.0
) -> np.ndarray:
    """Our 55-joint positions as the keypoint layout: 49 joints, neck-relative, image axes, noisy bones.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Metres, Y up, facing +Z (a :class:`~gesturekit.motion.Motion`'s positions).
    seed : int
        Seed of the bone-length noise (and of the fan's jitter).
    noise : float
        Relative standard deviation of each bone's length per frame.
    scale : float
        Every bone's length multiplied by this (a take lifted at another size), 0.2 to 5.
    fan_jitter : float
        Standard deviation, degrees, of a rotation of each finger root's bone about its wrist,
        drawn per frame about a random axis: the hand's fan of finger roots changes shape from
        frame to frame, as in keypoints lifted from video. 0 to 30.

    Returns
    -------
    np.ndarray, shape (frames, 49, 3), float64
        In the order of :data:`KEYPOINT_NAMES`, metres.
    """
    if not (isinstance(scale, (int, float)) and 0.2 <= scale <= 5.0):
        raise ConfigError(f"scale must be from 0.2 to 5, got {scale!r}")
    if not (isinstance(fan_jitter, (int, float)) and 0.0 <= fan_jitter <= 30.0):
        raise ConfigError(f"fan_jitter must be from 0 to 30 degrees, got {fan_jitter!r}")
    pos = np.asarray(positions, dtype=np.float64)
    rng = np.random.default_rng(seed)
    # every bone's length scaled per frame, rebuilt along the chains (parents precede children)
    lengths = scale * (1.0 + noise * rng.standard_normal((pos.shape[0], N_JOINTS)))
    bones = pos[:, 1:] - pos[:, PARENTS[1:]]
    bones = np.concatenate([np.zeros_like(pos[:, :1]), bones], axis=1)
    if fan_jitter > 0:
        # a generator of its own, so that the files without jitter stay as they were
        turn = np.random.default_rng([seed, 1])
        for j in _FINGER_ROOTS:
            bones[:, j] = _rotate(bones[:, j], turn, np.radians(fan_jitter))
    noisy = pos.copy()
    for j in range(N_JOINTS):
        p = PARENTS[j]
        if p >= 0:
            noisy[:, j] = noisy[:, p] + lengths[:, j, None] * bones[:, j]
    noisy = noisy - noisy[:, [joint_index("neck")]]
    ours = _our_joint_of_column()
    # a hand root repeats its wrist
    side = {"l": "left", "r": "right"}
    columns = [joint_index(ours[c] or f"{side[c[0]]}_wrist") for c in KEYPOINT_NAMES]
    return noisy[:, columns] @ _TO_IMAGE.T


def _rotate(v: np.ndarray, rng: np.random.Generator, sigma: float) -> np.ndarray:
    """Vectors ``v`` (frames, 3) each turned by an angle ~ N(0, ``sigma``) radians about a random axis."""
    axis = rng.standard_normal(v.shape)
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    angle = sigma * rng.standard_normal((v.shape[0], 1))
    # Rodrigues' formula
    cos, sin = np.cos(angle), np.sin(angle)
    dot = np.sum(axis * v, axis=-1, keepdims=True)
    return v * cos + np.cross(axis, v) * sin + axis * dot * (1.0 - cos)


def _array_bytes(array: np.ndarray, fmt: str) -> bytes:
    buf = io.BytesIO()
    flat = array.reshape(array.shape[0], -1)
    if fmt == "npy":
        np.save(buf, array.astype(np.float32), allow_pickle=False)
    else:
        np.savetxt(buf, flat, fmt="%.5f", delimiter="," if fmt == "csv" else " ")
    return buf.getvalue()


@checks_arguments
def write_keypoint_example(
    out: str | os.PathLike[str],
    *,
    fmt: str = "txt",
    takes: int = 2,
    seconds: float = 30.0,
    seed: int = 0,
    noise: float = BONE_NOISE,
    scales: Sequence[float] | None = None,
    fan_jitter: float = 0.0,
) -> list[Path]:
    """Write takes of the keypoint layout, their speech, and the layout's joint map into ``out``.

    Parameters
    ----------
    out : path
        Folder to write into (created if missing); existing files are not replaced.
    fmt : {"txt", "csv", "npy"}
        Format of the position files: whitespace- or comma-separated text, one frame
        of 49 x 3 numbers per row, or an npy array of shape (frames, 49, 3).
    takes : int
        Number of takes (``take_00`` ...), each a demo-speaker take of its own seed.
    seconds : float
        Duration of each take, seconds (2-3600).
    seed : int
        Non-negative seed: the same seed gives the same files.
    noise : float
        Relative standard deviation of each bone's length per frame.
    scales : sequence of float, optional
        One per take: every bone of the take is this many times its length (takes lifted at
        different sizes, as lifting from video gives them); default 1 for every take.
    fan_jitter : float
        Degrees: the finger roots' fan changes shape from frame to frame (see
        :func:`keypoint_positions`).

    Returns
    -------
    list of Path
        The files written: ``joint_map.json``, then per take its positions and ``.wav``.

    Raises
    ------
    ConfigError
        A bad option, or a file that already exists.
    """
    if fmt not in FORMATS:
        raise ConfigError(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if not (isinstance(takes, int) and 1 <= takes <= 1000):
        raise ConfigError(f"--takes must be a whole number from 1 to 1000, got {takes!r}")
    if not (isinstance(noise, (int, float)) and 0 <= noise < 0.5):
        raise ConfigError(f"noise must be in [0, 0.5), got {noise!r}")
    sizes = [1.0] * takes if scales is None else [float(x) for x in scales]
    if len(sizes) != takes:
        raise ConfigError(f"--scales must give one scale per take ({takes}), got {len(sizes)}")
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    written = [_write(folder / "joint_map.json", _map_bytes())]
    seeds = np.random.SeedSequence(seed).generate_state(takes)
    for k in range(takes):
        name = f"take_{k:02d}"
        take, _ = generate_demo_take(seconds=seconds, seed=int(seeds[k]), name=name)
        array = keypoint_positions(
            take.motion.positions, seed=int(seeds[k]) + 1, noise=float(noise), scale=sizes[k], fan_jitter=fan_jitter
        )
        data, sound = _array_bytes(array, fmt), wav_bytes(take.audio, sr=AUDIO_SR)
        written.append(_write(folder / f"{name}.{fmt}", data))
        written.append(_write(folder / f"{name}.wav", sound))
    return written


def _write(path: Path, data: bytes) -> Path:
    def put(f: BinaryIO) -> None:
        f.write(data)

    return atomic_write(path, put)


def _map_bytes() -> bytes:
    return (json.dumps(keypoint_joint_map(), indent=1) + "\n").encode()


@checks_arguments
def main(argv: Sequence[str] | None = None) -> int:
    """The command line: ``python -m gesturekit.datasets.keypoint_example OUT [options]``."""
    p = argparse.ArgumentParser(
        prog="python -m gesturekit.datasets.keypoint_example",
        description="Write example takes in the layout of keypoints lifted from video (49 joints, Y down).",
    )
    p.add_argument("out", help="folder to write into")
    p.add_argument("--format", default="txt", choices=FORMATS, help="position file format (default txt)")
    p.add_argument("--takes", type=int, default=2, help="number of takes (default 2)")
    p.add_argument("--seconds", type=float, default=30.0, help="seconds per take (default 30)")
    p.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    p.add_argument("--scales", type=float, nargs="+", help="one size per take: every bone scaled (default 1)")
    p.add_argument(
        "--fan-jitter", type=float, default=0.0, help="degrees the finger roots turn about the wrist per frame"
    )
    args = p.parse_args(argv)
    try:
        files = write_keypoint_example(
            args.out,
            fmt=args.format,
            takes=args.takes,
            seconds=args.seconds,
            seed=args.seed,
            scales=args.scales,
            fan_jitter=args.fan_jitter,
        )
    except GestureKitError as exc:
        print(f"keypoint_example: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {len(files)} files to {args.out} ({FPS} fps; joint map: {files[0]})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
