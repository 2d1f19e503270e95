"""One retrieval candidate as the inspector shows it: plain data, without plotting libraries, so the
app's logic (:mod:`gesturekit.interactive`) can make it without the figures' packages."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from ..skeleton import N_JOINTS

__all__ = ["CandidateView"]


@dataclass(frozen=True)
class CandidateView:
    """What one candidate shows: its database clip and window, its ranks and distances.

    Attributes
    ----------
    position : int
        Its place in the combined ranking (0 = best).
    clip_positions : np.ndarray, shape (frames, 55, 3), float32
        The whole database clip (64 frames), pelvis-relative, metres.
    start : int
        The window's first frame in the clip.
    segment : int
        Frames per step, N (the window is ``start .. start + N``, fewer at the clip's end).
    pose_dist, audio_dist : float
        Its distances to the query pose (z-scored units) and to the step's speech (cosine).
    label : str
        A description (its take and time), shown in titles and on hover.
    chosen : bool
        The search took it (or it is the pin) at this step.
    """

    position: int
    clip_positions: np.ndarray
    start: int
    segment: int
    pose_dist: float
    audio_dist: float
    label: str = ""
    chosen: bool = False

    def __post_init__(self) -> None:
        p = np.asarray(self.clip_positions)
        if p.ndim != 3 or p.shape[1:] != (N_JOINTS, 3) or p.shape[0] < 1:
            raise ConfigError(f"a candidate's clip must have shape (frames, {N_JOINTS}, 3), got {p.shape}")
        if not 0 <= int(self.start) < p.shape[0] or int(self.segment) < 1:
            raise ConfigError(
                f"window from frame {self.start} ({self.segment} frames) lies outside a clip of {p.shape[0]}"
            )

    @property
    def window(self) -> np.ndarray:
        """The window's frames, shape (n <= segment, 55, 3)."""
        return np.asarray(self.clip_positions[self.start : self.start + self.segment], dtype=np.float32)
