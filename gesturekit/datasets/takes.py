"""Finding takes in a folder and reading them, whatever their kind.

A folder of takes is one of:

- ``bvh``: ``NAME.bvh`` with speech ``NAME.wav`` (or .flac/.ogg/.mp3) beside it (ZEGGS, BEAT,
  any BVH with a joint map);
- ``positions``: ``NAME.npy|.npz|.txt|.csv`` joint positions (frames x joints x 3) with ``NAME.wav``,
  read with a JSON joint map and a source frame rate;
- ``habibie2021``: ``*.npz`` files with keys ``wav`` and ``body`` (several sequences each).
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._arguments import checks_arguments
from ..bones import Skeleton
from ..errors import ConfigError, InputFileError
from ..motion import Motion, Take
from ._axes import FORWARD_CHOICES, UNIT_CHOICES, UP_CHOICES
from ._reading import reading_lines
from .positions import POSITION_EXTENSIONS, PositionJointMap, load_position_joint_map, read_positions_take

if TYPE_CHECKING:
    from .presets import JointMap

__all__ = [
    "AUDIO_EXTENSIONS",
    "POSITION_EXTENSIONS",
    "UNIT_CHOICES",
    "UP_CHOICES",
    "FORWARD_CHOICES",
    "reading_lines",
    "ReadOptions",
    "TakeSource",
    "discover_takes",
    "iter_takes",
    "fit_takes_skeleton",
    "count_takes",
    "MAX_DURATION_MISMATCH",
    "check_durations",
]

AUDIO_EXTENSIONS = (".wav", ".flac", ".ogg", ".mp3")
#: A take's motion and speech may differ by this fraction of the longer (and by
#: :data:`DURATION_SLACK_S`) before it is refused: a wrong ``--fps`` or file frame time.
MAX_DURATION_MISMATCH = 0.05
#: Seconds of difference always accepted (silence before or after the speech, a short take).
DURATION_SLACK_S = 1.0
KINDS = ("auto", "bvh", "positions", "habibie2021")


@dataclass(frozen=True)
class TakeSource:
    """Files of one take (or, for ``habibie2021``, one file of several takes)."""

    kind: str
    motion: Path
    audio: Path | None


def _audio_for(path: Path) -> Path | None:
    for ext in AUDIO_EXTENSIONS:
        for cand in (path.with_suffix(ext), path.with_suffix(ext.upper())):
            if cand.is_file():
                return cand
    return None


def _is_habibie_npz(path: Path) -> bool:
    from .habibie2021 import is_habibie2021_npz

    return is_habibie2021_npz(path)


@checks_arguments
def discover_takes(folder: str | os.PathLike, *, kind: str = "auto") -> list[TakeSource]:
    """List the takes in ``folder`` (not recursive), sorted by name.

    Parameters
    ----------
    folder : path
    kind : {"auto", "bvh", "positions", "habibie2021"}
        ``auto`` picks ``bvh`` if there is a BVH file, else ``habibie2021`` if an
        npz holds ``wav`` and ``body``, else ``positions``.

    Raises
    ------
    InputFileError
        The folder does not exist, holds no takes, or a motion file has no audio beside it.
    MotionFileError
        An ``.npz`` file looked at for the ``habibie2021`` kind is not a readable archive.
    """
    folder = Path(folder)
    if kind not in KINDS:
        raise ConfigError(f"unknown take kind {kind!r}; choose one of {', '.join(KINDS)}")
    if not folder.is_dir():
        raise InputFileError("no such folder", path=folder)
    files = sorted(p for p in folder.iterdir() if p.is_file())
    if kind == "auto":
        if any(p.suffix.lower() == ".bvh" for p in files):
            kind = "bvh"
        elif any(p.suffix.lower() == ".npz" and _is_habibie_npz(p) for p in files):
            kind = "habibie2021"
        else:
            kind = "positions"
    if kind == "habibie2021":
        out = [TakeSource(kind, p, None) for p in files if p.suffix.lower() == ".npz" and _is_habibie_npz(p)]
    else:
        exts = (".bvh",) if kind == "bvh" else POSITION_EXTENSIONS
        out = []
        missing = []
        for p in files:
            if p.suffix.lower() in exts:
                a = _audio_for(p)
                if a is None:
                    missing.append(p.name)
                else:
                    out.append(TakeSource(kind, p, a))
        if missing:
            raise InputFileError(
                f"no speech file ({'/'.join(AUDIO_EXTENSIONS)}) with the same name beside: {', '.join(missing)}",
                path=folder,
            )
    if not out:
        raise InputFileError(f"no {kind} takes found in this folder", path=folder)
    return out


@checks_arguments
def count_takes(sources: list[TakeSource]) -> int:
    """Number of takes the sources hold (an npz of the 2021 layout holds several)."""
    n = 0
    for s in sources:
        if s.kind == "habibie2021":
            from .habibie2021 import count_sequences

            n += count_sequences(s.motion)
        else:
            n += 1
    return n


def _speech_file(src: TakeSource) -> Path:
    """The speech file of a one-take source; a source made by hand may lack one."""
    if src.audio is None:
        raise InputFileError("this take has no speech file", path=src.motion)
    return src.audio


@dataclass(frozen=True)
class ReadOptions:
    """How to read the motion files of takes (the ``build-db`` options of the same names).

    Parameters
    ----------
    units : {"auto", "m", "cm", "mm"}
        Length unit of the motion files; ``auto`` detects it (BVH: from the
        skeleton's size; positions: from the shoulder width and upper arms).
    up : {"y", "-y", "z", "-z"} or None
        Up axis of the files; None: Y, and each take must look upright.
    forward : {"auto", "x", "-x", "y", "-y", "z", "-z"}
        The axis the body faces; ``auto`` finds it from the shoulders.
    normalize_bones : bool
        Give every take one skeleton (:func:`gesturekit.bones.normalise_bone_lengths` with a
        :class:`~gesturekit.bones.Skeleton`): one length per bone and one shape for the finger
        roots on each wrist and the neck and collars on the upper chest, for keypoints whose
        bone lengths vary from frame to frame and from take to take.
    skeleton : Skeleton, optional
        With ``normalize_bones``: the skeleton to give the takes (a database's, or one
        :func:`fit_takes_skeleton` fitted). Without one, :func:`iter_takes` fits it over all the
        takes it is given before it yields the first.
    check_plausible : bool
        Check what was given against the data, as ``auto`` values are checked: the body's size in
        the given ``units``, its uprightness with the given ``up``, the joint map's skeleton
        (:func:`gesturekit.datasets._axes.check_skeleton`) and, in joint-position files, frames far
        from the body. False (``--no-plausibility-check``) is for the rare data that fails them
        and is right.
    allow_duration_mismatch : bool
        Accept a take whose motion and speech durations differ by more than
        :data:`MAX_DURATION_MISMATCH` (``--allow-duration-mismatch``); else it is refused, naming
        the frame rate that would make them agree.
    """

    units: str = "auto"
    up: str | None = None
    forward: str = "auto"
    normalize_bones: bool = False
    skeleton: Skeleton | None = None
    check_plausible: bool = True
    allow_duration_mismatch: bool = False

    def __post_init__(self) -> None:
        from ._axes import check_axes_options

        check_axes_options(self.up, self.forward, self.units)
        if not isinstance(self.normalize_bones, bool):
            raise ConfigError(f"normalize_bones must be True or False, got {self.normalize_bones!r}")
        if self.skeleton is not None and not isinstance(self.skeleton, Skeleton):
            raise ConfigError(f"skeleton must be a gesturekit.bones.Skeleton, got {type(self.skeleton).__name__}")
        if self.skeleton is not None and not self.normalize_bones:
            raise ConfigError("a skeleton is given to the takes with normalize_bones=True")


@checks_arguments
def iter_takes(
    sources: list[TakeSource],
    *,
    joint_map: str | os.PathLike[str] | Mapping[str, Any] | JointMap | PositionJointMap | None = None,
    fps_in: float | None = None,
    units: str = "auto",
    options: ReadOptions | None = None,
) -> Iterator[Take]:
    """Read the takes one at a time.

    Each take's ``sources`` holds, under ``"reading"``, how it was read (axes,
    units, derived and absent joints, bone normalisation:
    :meth:`gesturekit.datasets._reading.Reading.text`).

    Parameters
    ----------
    sources : list of TakeSource
        From :func:`discover_takes`.
    joint_map : str, path, dict, JointMap or PositionJointMap
        Preset name (``"zeggs"``, ``"beat"``) or JSON joint map, or one already read for the
        kind of the takes; required for ``positions``.
    fps_in : float
        Frame rate of joint-position files (they do not carry one).
    units : {"auto", "m", "cm", "mm"}
        Units of the motion files, when ``options`` is not given.
    options : ReadOptions, optional
        Units, axes and bone normalisation (default: ``ReadOptions(units=units)``). With
        ``normalize_bones`` and no ``skeleton``, every take is read once first to fit one
        (:func:`fit_takes_skeleton`).
    """
    from ._reading import READING_KEY, normalise_motion
    from .audio import load_audio

    opts = options if options is not None else ReadOptions(units=units)
    if opts.normalize_bones and opts.skeleton is None:
        fitted = fit_takes_skeleton(sources, joint_map=joint_map, fps_in=fps_in, options=opts)
        opts = replace(opts, skeleton=fitted)
    maps: dict[str, Any] = {}  # per kind, the joint map read once (a file is not read again per take)
    for src in sources:
        if src.kind in ("bvh", "positions"):
            speech = _speech_file(src)  # a take without speech is refused before its motion is read
            if src.kind == "bvh":
                from .bvh import read_bvh_take
                from .presets import load_joint_map

                if isinstance(joint_map, PositionJointMap):
                    raise ConfigError("BVH takes need a BVH joint map, not a joint-position map")
                if "bvh" not in maps:
                    maps["bvh"] = load_joint_map(joint_map or "zeggs")
                motion, reading = read_bvh_take(
                    src.motion,
                    joint_map=maps["bvh"],
                    units=opts.units,
                    up=opts.up,
                    forward=opts.forward,
                    check_plausible=opts.check_plausible,
                )
            else:
                from .presets import JointMap

                if isinstance(joint_map, JointMap):
                    raise ConfigError("joint-position files need a joint-position map, not a BVH joint map")
                if joint_map is None or fps_in is None:
                    raise ConfigError(
                        "joint-position files need a JSON joint map (--joint-map) and their frame rate (--fps)"
                    )
                if "positions" not in maps:
                    maps["positions"] = load_position_joint_map(joint_map)
                motion, reading = read_positions_take(
                    src.motion,
                    joint_map=maps["positions"],
                    fps=fps_in,
                    units=opts.units,
                    up=opts.up,
                    forward=opts.forward,
                    check_plausible=opts.check_plausible,
                )
            if opts.normalize_bones:
                motion, reading = normalise_motion(motion, reading, skeleton=opts.skeleton)
            audio = load_audio(speech, take=True)
            if not opts.allow_duration_mismatch:
                fps_option = None if src.kind == "bvh" else ("--fps", float(fps_in or 0))
                check_durations(motion, len(audio), path=src.motion, fps_option=fps_option)
            info = {**_file_record("motion", src.motion), **_file_record("audio", speech), READING_KEY: reading.text()}
            yield Take(src.motion.stem, motion, audio, info)
        else:
            from .habibie2021 import load_habibie2021

            if opts.up is not None or opts.forward != "auto":
                raise ConfigError("--up and --forward are for BVH and joint-position files, not the habibie2021 kind")
            record = _file_record("file", src.motion)
            for take in load_habibie2021(src.motion, units="m" if opts.units == "auto" else opts.units):
                take = Take(take.name, take.motion, take.audio, {**take.sources, **record})
                if opts.normalize_bones:
                    positions, report = _normalise(take.motion, opts.skeleton)
                    take = Take(
                        take.name,
                        Motion(positions, take.motion.fps, take.motion.joints),
                        take.audio,
                        {**take.sources, READING_KEY: f"habibie2021 layout; bones: {report}"},
                    )
                yield take


def _file_record(key: str, path: Path) -> dict[str, str]:
    """A take's source file for ``database.json``: its absolute path, and its size and modification
    time (``KEY_stat``, ``"SIZE:MTIME_NS"``), so that ``--append`` finds it from anywhere and notices
    a file changed since."""
    path = Path(os.path.abspath(path))
    st = path.stat()
    return {key: str(path), f"{key}_stat": f"{st.st_size}:{st.st_mtime_ns}"}


@checks_arguments
def check_durations(
    motion: Motion, n_samples: int, *, path: str | os.PathLike[str], fps_option: tuple[str, float] | None
) -> None:
    """Refuse a take whose motion and speech last different times (beyond :data:`MAX_DURATION_MISMATCH`).

    Parameters
    ----------
    motion : Motion
        The take's motion as read.
    n_samples : int
        Samples of its speech at :data:`gesturekit.motion.AUDIO_SR`.
    path : path
        The motion file, named in the message.
    fps_option : (str, float) or None
        The option that set the motion's source frame rate and its value (``("--fps", 30.0)``),
        or None when the file states its own (BVH).

    Raises
    ------
    MotionFileError
        The message gives both durations and the frame rate that would make them agree.
    """
    from ..errors import MotionFileError
    from ..motion import AUDIO_SR

    motion_s = motion.n_frames / motion.fps
    speech_s = n_samples / AUDIO_SR
    longer = max(motion_s, speech_s)
    if speech_s <= 0 or abs(motion_s - speech_s) <= max(DURATION_SLACK_S, MAX_DURATION_MISMATCH * longer):
        return
    if fps_option is not None:
        option, fps = fps_option
        agree = fps * motion_s / speech_s
        hint = f"at {option} {agree:.4g} they would agree; give the files' frame rate"
    else:
        hint = "the file's frame time may be wrong, or the speech is of another take"
    raise MotionFileError(
        f"the motion lasts {motion_s:.2f} s and its speech {speech_s:.2f} s ({abs(motion_s - speech_s) / longer:.0%} "
        f"apart); {hint} (--allow-duration-mismatch keeps such a take, trimming the longer)",
        path=path,
    )


def _normalise(motion: Motion, skeleton: Skeleton | None) -> tuple[np.ndarray, str]:
    from ..bones import normalise_bone_lengths

    positions, report = normalise_bone_lengths(motion.positions, motion.presence, skeleton=skeleton)
    return positions.astype(np.float32), report.summary()


@checks_arguments
def fit_takes_skeleton(
    sources: list[TakeSource],
    *,
    joint_map: str | os.PathLike[str] | Mapping[str, Any] | JointMap | PositionJointMap | None = None,
    fps_in: float | None = None,
    options: ReadOptions | None = None,
) -> Skeleton:
    """One skeleton over every frame of every take of ``sources`` (:func:`gesturekit.bones.fit_skeleton`),
    each take read as :func:`iter_takes` reads it, before any normalisation.

    The takes' samples (:func:`gesturekit.bones.bone_samples`, 376 bytes a frame) are kept in
    memory; a database build from a folder keeps them on disk instead.

    Parameters
    ----------
    sources, joint_map, fps_in, options
        As for :func:`iter_takes` (``options``' ``normalize_bones`` and ``skeleton`` are not used).

    Raises
    ------
    ConfigError
        No takes; and what :func:`iter_takes` raises for a take that cannot be read.
    """
    from ..bones import bone_samples, fit_skeleton
    from ..errors import collect_warnings

    opts = replace(options or ReadOptions(), normalize_bones=False, skeleton=None)
    samples = []
    presence = None
    # the takes are read again after the fit: their warnings are given then, once
    with collect_warnings():
        for take in iter_takes(sources, joint_map=joint_map, fps_in=fps_in, options=opts):
            samples.append(bone_samples(take.motion.positions))
            presence = presence or take.motion.presence
    if not samples:
        raise ConfigError("no takes to fit a skeleton over")
    return fit_skeleton(samples, presence=presence)
