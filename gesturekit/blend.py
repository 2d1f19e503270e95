"""Optional transitions between search segments (not in the paper, which leaves smoothing to the
cGAN), and the step that keeps the k-NN motion's slow content in refined motion."""

from __future__ import annotations

import numpy as np

from .errors import ConfigError

__all__ = ["BLEND_MODES", "KEEP_BELOW_HZ", "blend_segments", "fade_weights", "keep_slow"]

BLEND_MODES = ("none", "offset")

#: Default cut-off of :func:`keep_slow` in synthesis, Hz: about the segment rate (15 fps / 8 frames).
KEEP_BELOW_HZ = 2.0


def fade_weights(frames: int) -> np.ndarray:
    """The weights an ``"offset"`` blend fades a join's offset with, shape (frames,), float64:
    a cosine from 1 to 0, exclusive at both ends."""
    j = np.arange(frames)
    return 0.5 * (1 + np.cos(np.pi * (j + 1) / (frames + 1)))


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
    weight = fade_weights(frames)
    for b in np.asarray(boundaries, dtype=np.int64):
        if b < 2 or b >= len(out):
            continue
        expected = out[b - 1] + (out[b - 1] - out[b - 2])
        offset = expected - out[b]
        n = min(frames, len(out) - b)
        out[b : b + n] += (weight[:n, None] * offset[None, :]).astype(out.dtype)
    return out


def keep_slow(refined: np.ndarray, knn: np.ndarray, hz: float, fps: float = 15.0) -> np.ndarray:
    """``refined`` with its content slower than ``hz`` replaced by ``knn``'s.

    ``refined + G * (knn - refined)``, ``G`` a Gaussian low-pass along time whose
    power falls to half at ``hz`` (sigma = sqrt(ln 2) / (2 pi hz) seconds), with
    the ends held (edge values repeated), so a constant offset between the two is
    removed entirely and changes much faster than ``hz`` are kept.

    Why: a refiner trained briefly (the quick preset) smooths the joins but also
    pulls slow features, such as hand height, towards its training data's average,
    which undoes the controls. The joins and the timing a refiner is for are
    faster than the segment rate (15 / 8 Hz); hand height, width and symmetry,
    which the controls set, are slower.

    Parameters
    ----------
    refined, knn : np.ndarray, shape (T, C)
        Refined and k-NN motion (e.g. flattened joint positions), metres.
    hz : float
        Cut-off frequency, > 0.
    fps : float
        Frame rate of both, frames per second.

    Returns
    -------
    np.ndarray, shape (T, C), float32
    """
    from scipy.ndimage import gaussian_filter1d

    if not (np.isfinite(hz) and hz > 0):
        raise ConfigError(f"keep_below_hz must be a positive frequency in Hz, got {hz}")
    refined = np.asarray(refined, np.float64)
    knn = np.asarray(knn, np.float64)
    if refined.shape != knn.shape:
        raise ConfigError(f"refined {refined.shape} and k-NN {knn.shape} motion differ in shape")
    sigma = np.sqrt(np.log(2.0)) / (2.0 * np.pi * float(hz)) * float(fps)  # frames
    slow = gaussian_filter1d(knn - refined, sigma, axis=0, mode="nearest", truncate=4.0)
    return (refined + slow).astype(np.float32)
