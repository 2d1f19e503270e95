"""Motion: joint positions with their frame rate, and a take (motion + speech)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ._arguments import checks_arguments
from .errors import ConfigError
from .skeleton import FPS, N_JOINTS, PARENTS, JointPresence

__all__ = ["Motion", "HoldsMotion", "Take", "AUDIO_SR", "resample_positions", "output_frame_count", "n_audio_frames"]

#: Sample rate of all audio inside gesturekit, Hz.
AUDIO_SR = 16000


@checks_arguments
def n_audio_frames(n_samples: int, *, sr: int = AUDIO_SR, fps: int = FPS) -> int:
    """Whole frames at ``fps`` in ``n_samples`` of audio at ``sr`` Hz: ``floor(n_samples * fps / sr)``.

    Declared here, beside the sample rate, so that the readers and the demo speaker below the
    features agree with them on a take's length (:mod:`gesturekit.features` re-exports it).
    """
    return (int(n_samples) * int(fps)) // int(sr)


@dataclass(frozen=True)
class Motion:
    """Joint positions over time.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3), float32
        Pelvis-relative joint positions in metres, Y up, in the order of
        :data:`gesturekit.skeleton.JOINT_NAMES`.
    fps : float
        Frames per second.
    joints : JointPresence or None
        Which joints the data holds (recorded, derived from others, or absent: sitting on
        their parent and not drawn); None means all 55 are recorded.
    """

    positions: np.ndarray
    fps: float
    joints: JointPresence | None = None

    def __post_init__(self):
        pos = np.asarray(self.positions, dtype=np.float32)
        if pos.ndim != 3 or pos.shape[1:] != (N_JOINTS, 3):
            raise ConfigError(f"Motion positions must have shape (frames, {N_JOINTS}, 3), got {pos.shape}")
        if not self.fps > 0:
            raise ConfigError(f"Motion fps must be positive, got {self.fps}")
        object.__setattr__(self, "positions", pos)

    @property
    def n_frames(self) -> int:
        return int(self.positions.shape[0])

    @property
    def presence(self) -> JointPresence:
        """Which joints the data holds (:attr:`joints`, or all recorded when it is None)."""
        return self.joints if self.joints is not None else JointPresence.full()

    @property
    def duration(self) -> float:
        """Duration in seconds (frames / fps)."""
        return self.n_frames / self.fps

    def flat(self) -> np.ndarray:
        """Positions as the paper's g vectors, shape (frames, 165)."""
        return self.positions.reshape(self.n_frames, N_JOINTS * 3)

    @classmethod
    def from_flat(cls, g: np.ndarray, fps: float, joints: JointPresence | None = None) -> Motion:
        """Motion from g vectors of shape (frames, 165)."""
        g = np.asarray(g)
        return cls(g.reshape(g.shape[0], N_JOINTS, 3), fps, joints)

    def bone_lengths(self) -> np.ndarray:
        """Length of every bone in every frame, shape (frames, 54), metres."""
        child = np.flatnonzero(PARENTS >= 0)
        d = self.positions[:, child] - self.positions[:, PARENTS[child]]
        return np.linalg.norm(d, axis=-1)

    def slice(self, start: int, stop: int) -> Motion:
        return Motion(self.positions[start:stop], self.fps, self.joints)


class HoldsMotion:
    """Base of the records built around a :class:`Motion` in ``motion``: its length in frames and seconds."""

    motion: Motion

    @property
    def n_frames(self) -> int:
        """Frames of ``motion``."""
        return self.motion.n_frames

    @property
    def duration(self) -> float:
        """Seconds of ``motion``."""
        return self.motion.duration


@dataclass(frozen=True)
class Take:
    """One recording: motion and the speech that goes with it, aligned at time 0.

    Parameters
    ----------
    name : str
        Identifier of the take (usually the file stem).
    motion : Motion
        The motion, at any frame rate.
    audio : np.ndarray, shape (samples,), float32
        Mono speech at :data:`AUDIO_SR` Hz, starting with the motion's first frame.
    sources : dict
        Where the take came from (file paths), kept in database metadata.
    """

    name: str
    motion: Motion
    audio: np.ndarray
    sources: dict = field(default_factory=dict)

    @property
    def duration(self) -> float:
        return min(self.motion.duration, len(self.audio) / AUDIO_SR)


@checks_arguments
def resample_positions(positions: np.ndarray, fps_in: float, fps_out: float) -> np.ndarray:
    """Resample positions to another frame rate by linear interpolation in time.

    Frame ``t`` of the output lies at ``t / fps_out`` seconds; the output has
    ``floor(n_in / fps_in * fps_out)`` frames (the duration of the input,
    ``n_in / fps_in``, in whole output frames). When ``fps_in`` is a whole
    multiple of ``fps_out`` this is exact subsampling. Linear interpolation of
    positions shortens bones slightly between samples; readers that have
    rotations (BVH) resample rotations instead.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, ...)
    fps_in, fps_out : float
        Frame rates in frames per second.
    """
    n_in = positions.shape[0]
    n_out = output_frame_count(n_in, fps_in, fps_out)
    src = np.arange(n_out) * (fps_in / fps_out)
    i0 = np.clip(np.floor(src + 1e-9).astype(np.int64), 0, n_in - 1)
    i1 = np.minimum(i0 + 1, n_in - 1)
    w = (src - i0).reshape((-1,) + (1,) * (positions.ndim - 1))
    w = np.where(np.abs(w) < 1e-9, 0.0, w)
    return (positions[i0] * (1 - w) + positions[i1] * w).astype(positions.dtype, copy=False)


@checks_arguments
def output_frame_count(n_in: int, fps_in: float, fps_out: float) -> int:
    """Whole frames at ``fps_out`` that fit in ``n_in`` frames at ``fps_in`` (duration ``n_in/fps_in``)."""
    # a small tolerance so 2065 frames at 30 fps give 1032 frames at 15 fps, not 1031 by rounding
    return int(np.floor(n_in * fps_out / fps_in + 1e-9))
