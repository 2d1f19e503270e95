"""Optional transitions between search segments (not in the paper, which leaves smoothing to the cGAN)."""
from __future__ import annotations

import numpy as np

from .errors import ConfigError

__all__ = ["BLEND_MODES", "blend_segments"]

BLEND_MODES = ("none", "offset")


def blend_segments(g: np.ndarray, boundaries: np.ndarray, *, mode: str = "none", frames: int = 4) -> np.ndarray:
    """Smooth the jumps where one segment follows another.

    ``"offset"``: at each boundary ``b`` the new segment starts where the previous
    one was heading (its last frame plus its last velocity); the difference to the
    new segment's first frame is added to the new segment and faded out over
    ``frames`` frames with a smooth (cosine) weight, so the join is continuous
    and the segment's own motion is kept after the fade.

    Parameters
    ----------
    g : np.ndarray, shape (T, D)
        Concatenated segments (e.g. flattened joint positions, metres).
    boundaries : np.ndarray of int
        First frame of every segment after the first.
    mode : {"none", "offset"}
    frames : int
        Fade length in frames (>= 1).

    Returns
    -------
    np.ndarray, shape (T, D), same dtype; ``g`` itself is not modified.
    """
    if mode not in BLEND_MODES:
        raise ConfigError(f"blend must be one of {', '.join(BLEND_MODES)}, got {mode!r}")
    out = np.array(g, copy=True)
    if mode == "none" or len(out) < 3:
        return out
    if frames < 1:
        raise ConfigError(f"blend frames must be at least 1, got {frames}")
    j = np.arange(frames)
    weight = 0.5 * (1 + np.cos(np.pi * (j + 1) / (frames + 1)))  # 1 -> 0, exclusive at both ends
    for b in np.asarray(boundaries, dtype=np.int64):
        if b < 2 or b >= len(out):
            continue
        expected = out[b - 1] + (out[b - 1] - out[b - 2])
        offset = expected - out[b]
        n = min(frames, len(out) - b)
        out[b : b + n] += (weight[:n, None] * offset[None, :]).astype(out.dtype)
    return out
