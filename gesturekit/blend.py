"""Transitions between search segments (not in the paper, which leaves smoothing to the cGAN),
and the step that keeps the k-NN motion's slow content in refined motion.

Modes (:data:`BLEND_MODES`) of :func:`blend_segments`:

- ``"none"``: the paper's hard joins;
- ``"offset"``: the new segment starts where the previous one was heading, and the
  difference fades out with a cosine over ``frames`` frames;
- ``"inertialize"`` (ours): inertialization as in game motion matching. At a join the output
  keeps its position and velocity; the difference between where it was heading and the new
  segment (an offset and its rate of change) decays like a critically damped spring,
  ``x(t) = (x0 + (v0 + y x0) t) exp(-y t)``, and the new segment's own motion is added on top,
  so the join is smooth in position and velocity. ``y`` is set by the half-life: the time an
  offset without velocity takes to fall to half.
- ``"dead"`` (the default, ours): dead blending, inertialization's extrapolate-and-fade form.
  The output is extrapolated from the join with its last velocity, which decays with the
  half-life, and cross-faded into the new segment with a smoothstep whose weight is one half
  at the half-life (it ends at twice that).

Every mode is causal: a join changes only the frames from it to the next join, computed
from the two output frames before it and the new segment, so live synthesis
(:mod:`gesturekit.live`) applies the same function a segment at a time
(:func:`blend_segment`).
"""

from __future__ import annotations

import numpy as np

from ._arguments import checks_arguments
from .errors import ConfigError

__all__ = [
    "BLEND_MODES",
    "DEFAULT_BLEND",
    "DEFAULT_HALFLIFE_S",
    "KEEP_BELOW_HZ",
    "blend_segment",
    "blend_segments",
    "fade_weights",
    "keep_slow",
]

BLEND_MODES = ("none", "offset", "inertialize", "dead")

#: The blend a synthesis uses by default (it shapes the output only without a refiner, which
#: is given the k-NN motion itself). Chosen by measurement (``bench/bench_blend.py``): on the
#: ZEGGS take and the keypoint example, dead blending at 0.12 s gives jerk and acceleration
#: within 10 % of the database's own and keeps the control adherence of the hard joins;
#: inertialization smooths as much but holds controls a little less (offsets decay after the
#: segment's own motion has already moved on).
DEFAULT_BLEND = "dead"

#: Default half-life of ``"inertialize"`` and ``"dead"``, seconds (``bench/bench_blend.py``).
DEFAULT_HALFLIFE_S = 0.12

#: ``u`` with ``(1 + u) exp(-u) = 1/2``: a critically damped offset without velocity is half
#: its start after ``u / y`` (``y`` the spring's decay rate).
_HALF_U = 1.6783469900166608

#: Default cut-off of :func:`keep_slow` in synthesis, Hz: about the segment rate (15 fps / 8 frames).
KEEP_BELOW_HZ = 2.0


@checks_arguments
def fade_weights(frames: int) -> np.ndarray:
    """The weights an ``"offset"`` blend fades a join's offset with, shape (frames,), float64:
    a cosine from 1 to 0, exclusive at both ends."""
    j = np.arange(frames)
    return 0.5 * (1 + np.cos(np.pi * (j + 1) / (frames + 1)))


def _spring(x0: np.ndarray, v0: np.ndarray, n: int, halflife: float) -> np.ndarray:
    """A critically damped offset from ``x0`` with rate ``v0`` (per frame) at frames 0..n-1,
    shape (n, D), decaying to half (without velocity) after ``halflife`` frames."""
    y = _HALF_U / halflife
    t = np.arange(n, dtype=np.float64)[:, None]
    return (x0[None, :] + (v0[None, :] + y * x0[None, :]) * t) * np.exp(-y * t)


def _dead(before: np.ndarray, seg: np.ndarray, halflife: float) -> np.ndarray:
    """Dead blending of ``seg`` (n, D) after the output frames ``before`` (2, D)."""
    n = len(seg)
    v = before[1] - before[0]
    lam = np.log(2.0) / halflife
    t = np.arange(1, n + 1, dtype=np.float64)[:, None]  # frames since the last output frame
    extrapolated = before[1][None, :] + v[None, :] * (1.0 - np.exp(-lam * t)) / lam
    u = np.clip(t / (2.0 * halflife), 0.0, 1.0)
    w = u * u * (3.0 - 2.0 * u)  # smoothstep: 1/2 at the half-life, 1 at twice it
    return (1.0 - w) * extrapolated + w * seg


@checks_arguments
def blend_segment(before: np.ndarray, seg: np.ndarray, *, mode: str, halflife: float, frames: int = 4) -> np.ndarray:
    """One segment after a join, as :func:`blend_segments` makes it (``"inertialize"``, ``"dead"``).

    Parameters
    ----------
    before : np.ndarray, shape (2, D)
        The two output frames before the join (already blended).
    seg : np.ndarray, shape (n, D)
        The new segment's frames, up to the next join (n >= 1).
    mode : {"inertialize", "dead"}
    halflife : float
        Half-life in frames (> 0).

    Returns
    -------
    np.ndarray, shape (n, D), float64
    """
    before = np.asarray(before, np.float64)
    seg = np.asarray(seg, np.float64)
    if mode == "dead":
        return _dead(before, seg, halflife)
    v_out = before[1] - before[0]
    x0 = before[1] + v_out - seg[0]  # where the output was heading, less where the segment is
    v_seg = seg[1] - seg[0] if len(seg) > 1 else np.zeros_like(v_out)
    return seg + _spring(x0, v_out - v_seg, len(seg), halflife)


@checks_arguments
def blend_segments(
    g: np.ndarray,
    boundaries: np.ndarray,
    *,
    mode: str = "none",
    frames: int = 4,
    halflife: float = DEFAULT_HALFLIFE_S * 15.0,
) -> np.ndarray:
    """Smooth the jumps where one segment follows another.

    ``"offset"``: at each boundary ``b`` the new segment starts where the previous
    one was heading (its last frame plus its last velocity); the difference to the
    new segment's first frame is added to the new segment and faded out over
    ``frames`` frames with a smooth (cosine) weight, so the join is continuous
    and the segment's own motion is kept after the fade.
    ``"inertialize"`` and ``"dead"``: see the module's description; each join's
    transition lasts until the next join, which starts its own from the output.

    Parameters
    ----------
    g : np.ndarray, shape (T, D)
        Concatenated segments (e.g. flattened joint positions, metres).
    boundaries : np.ndarray of int
        First frame of every segment after the first.
    mode : {"none", "offset", "inertialize", "dead"}
    frames : int
        Fade length of ``"offset"`` in frames (>= 1).
    halflife : float
        Half-life of ``"inertialize"`` and ``"dead"`` in frames (> 0).

    Returns
    -------
    np.ndarray, shape (T, D), same dtype; ``g`` itself is not modified.
    Joins before frame 2 (no velocity to carry) and motions under 3 frames are left as they are.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.concatenate([np.arange(4.0), np.arange(10.0, 14.0)])[:, None]  # a jump of 7 at frame 4
    >>> out = blend_segments(g, np.array([4]), mode="inertialize", halflife=2.0)
    >>> float(out[4, 0])  # the join continues the first segment's motion
    4.0
    >>> bool(abs(out[-1, 0] - 13.0) < abs(4.0 - 10.0))  # and the offset decays towards the new segment
    True
    """
    if mode not in BLEND_MODES:
        raise ConfigError(f"blend must be one of {', '.join(BLEND_MODES)}, got {mode!r}")
    out = np.array(g, copy=True)
    if mode == "none" or len(out) < 3:
        return out
    if frames < 1:
        raise ConfigError(f"blend frames must be at least 1, got {frames}")
    if not (np.isfinite(halflife) and halflife > 0):
        raise ConfigError(f"blend half-life must be a positive number of frames, got {halflife}")
    cuts = np.asarray(boundaries, dtype=np.int64)
    if mode in ("inertialize", "dead"):
        ends = [*cuts[1:].tolist(), len(out)]
        for b, e in zip(cuts.tolist(), ends):
            if b < 2 or b >= len(out):
                continue
            out[b:e] = blend_segment(out[b - 2 : b], out[b:e], mode=mode, halflife=halflife).astype(out.dtype)
        return out
    weight = fade_weights(frames)
    for b in cuts:
        if b < 2 or b >= len(out):
            continue
        expected = out[b - 1] + (out[b - 1] - out[b - 2])
        offset = expected - out[b]
        n = min(frames, len(out) - b)
        out[b : b + n] += (weight[:n, None] * offset[None, :]).astype(out.dtype)
    return out


@checks_arguments
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
