"""Objective measures of gesture motion, each computed the way the literature computes it.

Every function is pure: arrays in, numbers (or a small table) out. Motion is
given as joint positions of shape ``(frames, joints, 3)`` in metres (usually
the 55-joint skeleton, pelvis-relative) with its frame rate ``fps``; audio as
mono float samples with its sample rate ``sr``.

Measures
--------
- **Beat consistency** (:func:`beat_consistency`): motion beats are the local
  minima of the kinetic velocity (mean joint speed, lightly smoothed), as in
  AI Choreographer (Li et al. 2021) and BEAT (Liu et al. 2022); audio beats are
  the onsets of librosa's onset envelope. For every audio onset, the distance ``d`` to the
  nearest motion beat scores ``exp(-d^2 / (2 sigma^2))``; the measure is the
  mean over the onsets (the averaging of both papers' published code). Higher
  is better, in [0, 1].
- **Diversity** (:func:`diversity_l1`): BEAT's L1div, the mean L1 distance of
  each sample to the mean sample; our samples are non-overlapping windows of
  the motion (one frame per window gives BEAT's per-pose number).
- **Fréchet distance** (:func:`frechet_distance`) between Gaussians fitted to
  two feature sets; with the latent features of a motion autoencoder
  (:mod:`gesturekit.evaluate.fgd`) it is the FGD of Yoon et al. 2020.
- **Hellinger distance** between histograms of joint speeds (or acceleration
  magnitudes) of two motions (:func:`kinematic_hellinger`), as in the GENEA
  challenge's numerical evaluations. 0 for identical distributions, at most 1.
- **Mean acceleration and jerk** (:func:`mean_acceleration`, :func:`mean_jerk`)
  from finite differences, m/s^2 and m/s^3.
- **Boundary jumps** (:func:`boundary_jumps`): the joint displacement across
  the joins of concatenated segments, and its ratio to the displacement
  between any other two frames (about 1 for continuous motion).
- **Control adherence** (:func:`control_adherence`): per control segment, the
  fraction of frames whose attributes meet its constraint, with the
  statistics of left-wrist height, hand speed and asymmetry in it.

Kinematic measures use :data:`KINEMATIC_JOINTS` (the upper body and both
wrists, as the cited works use the upper body) unless told otherwise; finger
joints, dense and small, would otherwise dominate the averages.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .._arguments import checks_arguments
from ..control import ATTRIBUTE_NAMES, ControlTrack, constraint_mask, frame_attributes
from ..errors import ConfigError
from ..motion import AUDIO_SR
from ..skeleton import BODY_JOINTS, joint_index

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "KINEMATIC_JOINTS",
    "joint_speeds",
    "kinetic_velocity",
    "motion_beats",
    "pick_peaks",
    "audio_onsets",
    "beat_consistency",
    "beat_consistency_score",
    "diversity_l1",
    "gaussian_statistics",
    "frechet_distance",
    "kinematic_magnitudes",
    "hellinger_distance",
    "kinematic_hellinger",
    "mean_acceleration",
    "mean_jerk",
    "boundary_jumps",
    "control_adherence",
    "overall_adherence",
]

#: Joints of the kinematic measures: the 13 upper-body joints and both wrists (indices).
KINEMATIC_JOINTS: tuple[int, ...] = tuple(joint_index(n) for n, _ in BODY_JOINTS) + (
    joint_index("left_wrist"),
    joint_index("right_wrist"),
)


def _positions(positions: np.ndarray, *, name: str = "positions") -> np.ndarray:
    x = np.asarray(positions, dtype=np.float64)
    if x.ndim != 3 or x.shape[2] != 3:
        raise ConfigError(f"{name} must have shape (frames, joints, 3), got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ConfigError(f"{name} hold NaN or infinite values")
    return x


def _fps(fps) -> float:
    if not (isinstance(fps, (int, float, np.integer, np.floating)) and math.isfinite(fps) and fps > 0):
        raise ConfigError(f"fps must be a positive number, got {fps!r}")
    return float(fps)


def _select(x: np.ndarray, joints: Sequence[int] | None) -> np.ndarray:
    if joints is None:
        return x
    idx = np.asarray(joints, dtype=np.int64)
    if idx.ndim != 1 or idx.size == 0 or idx.min() < 0 or idx.max() >= x.shape[1]:
        raise ConfigError(f"joints must be indices into the {x.shape[1]} joints, got {list(idx)}")
    return x[:, idx]


# ---- beats -------------------------------------------------------------------------------------


@checks_arguments
def joint_speeds(positions: np.ndarray, *, fps: float, joints: Sequence[int] | None = None) -> np.ndarray:
    """Speed of every joint in every frame.

    Parameters
    ----------
    positions : array, shape (frames, joints, 3), metres
    fps : float
        Frames per second.
    joints : sequence of int, optional
        Joints to keep (all by default).

    Returns
    -------
    np.ndarray, shape (frames, len(joints)), float64, m/s
        Central differences inside, one-sided at the ends; zeros for a single frame.
    """
    x = _select(_positions(positions), joints)
    fps = _fps(fps)
    if x.shape[0] < 2:
        return np.zeros(x.shape[:2])
    return np.linalg.norm(np.gradient(x, axis=0), axis=2) * fps


@checks_arguments
def kinetic_velocity(
    positions: np.ndarray, *, fps: float, joints: Sequence[int] | None = KINEMATIC_JOINTS, smooth_s: float = 1 / 15
) -> np.ndarray:
    """Mean joint speed per frame, smoothed with a Gaussian (the "kinetic velocity" of AI Choreographer).

    Parameters
    ----------
    positions : array, shape (frames, joints, 3), metres
    fps : float
    joints : sequence of int or None
        Joints averaged (default :data:`KINEMATIC_JOINTS`; None: all).
    smooth_s : float
        Standard deviation of the Gaussian, seconds (0: no smoothing). The default, one frame at
        15 fps, is about AI Choreographer's 5 frames at 60 fps.

    Returns
    -------
    np.ndarray, shape (frames,), m/s
    """
    from scipy.ndimage import gaussian_filter1d

    fps = _fps(fps)
    v = joint_speeds(positions, fps=fps, joints=joints).mean(axis=1)
    if smooth_s < 0:
        raise ConfigError(f"smooth_s must be >= 0 seconds, got {smooth_s}")
    if smooth_s > 0 and v.size > 1:
        v = gaussian_filter1d(v, sigma=smooth_s * fps, mode="nearest")
    return v


@checks_arguments
def motion_beats(
    positions: np.ndarray,
    *,
    fps: float,
    joints: Sequence[int] | None = KINEMATIC_JOINTS,
    smooth_s: float = 1 / 15,
    order: int = 1,
    min_speed: float = 0.0,
) -> np.ndarray:
    """Times of the motion beats: strict local minima of the kinetic velocity.

    Parameters
    ----------
    positions : array, shape (frames, joints, 3), metres
    fps : float
    joints, smooth_s
        See :func:`kinetic_velocity`.
    order : int
        A minimum must be lower than ``order`` frames on each side (``scipy.signal.argrelextrema``).
    min_speed : float
        Minima slower than this (m/s) are rest, not beats (BEAT's velocity threshold); 0 keeps all.

    Returns
    -------
    np.ndarray, shape (beats,), seconds from the first frame
        Empty for a motion that never changes speed (e.g. a constant pose).
    """
    from scipy.signal import argrelextrema

    if not isinstance(order, (int, np.integer)) or order < 1:
        raise ConfigError(f"order must be a positive integer, got {order!r}")
    v = kinetic_velocity(positions, fps=fps, joints=joints, smooth_s=smooth_s)
    if v.size < 3:
        return np.zeros(0)
    idx = argrelextrema(v, np.less, order=int(order))[0]
    idx = idx[v[idx] >= min_speed]
    return idx / _fps(fps)


@checks_arguments
def pick_peaks(
    x: np.ndarray, *, pre_max: int, post_max: int, pre_avg: int, post_avg: int, delta: float, wait: int
) -> np.ndarray:
    """Greedy peak picking of an onset envelope (Boeck et al. 2012, the rule librosa uses).

    Frame ``n`` is a peak when ``x[n] == max(x[n - pre_max : n + post_max])``,
    ``x[n] >= mean(x[n - pre_avg : n + post_avg]) + delta`` (windows clipped
    to the signal) and no peak was taken in the ``wait`` frames before it. The
    first frame only looks ahead.

    Parameters
    ----------
    x : array, shape (frames,)
        Envelope.
    pre_max, post_max, pre_avg, post_avg, wait : int
        Window extents and the refractory gap, frames (``post_*`` >= 1).
    delta : float
        Margin above the local mean, in units of ``x``.

    Returns
    -------
    np.ndarray, shape (peaks,), int64
        Frame indices, increasing.
    """
    x = np.asarray(x).ravel()
    if not np.issubdtype(x.dtype, np.floating):
        x = x.astype(np.float64)
    n = x.size
    if min(pre_max, pre_avg, wait) < 0 or min(post_max, post_avg) < 1 or delta < 0:
        raise ConfigError("peak picking needs pre_* >= 0, post_* >= 1, wait >= 0 and delta >= 0")
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    idx = np.arange(n)
    # windows clipped to [0, n): running max by a sliding view over a -inf-padded signal,
    # running mean by cumulative sums (vectorised; only the greedy wait rule needs a loop)
    padded = np.concatenate([np.full(pre_max, -np.inf), x, np.full(post_max, -np.inf)])
    local_max = np.lib.stride_tricks.sliding_window_view(padded, pre_max + post_max)[:n].max(axis=1)
    csum = np.concatenate([[0.0], np.cumsum(x, dtype=np.float64)])
    lo = np.maximum(idx - pre_avg, 0)
    hi = np.minimum(idx + post_avg, n)
    local_mean = (csum[hi] - csum[lo]) / (hi - lo)
    ok = (x == local_max) & (x >= local_mean + delta)
    # the first frame compares with what lies ahead only (its max window starts at 0 anyway)
    peaks: list[int] = []
    next_allowed = 0
    for i in np.flatnonzero(ok):
        if i >= next_allowed:
            peaks.append(int(i))
            next_allowed = i + wait + 1
    return np.asarray(peaks, dtype=np.int64)


@checks_arguments
def audio_onsets(audio: np.ndarray, *, sr: int = AUDIO_SR, hop_length: int = 160) -> np.ndarray:
    """Onset times of speech: peaks of librosa's spectral-flux onset envelope.

    The envelope is ``librosa.onset.onset_strength``, scaled to [0, 1]; the
    peaks follow librosa's ``onset_detect`` rule and defaults (30 ms before
    for the maximum, 100 ms around for the mean, margin 0.07, 30 ms wait),
    picked by :func:`pick_peaks` rather than librosa's cached numba gufunc,
    whose on-disk cache can crash processes that share it.

    Parameters
    ----------
    audio : array, shape (samples,)
        Mono audio in [-1, 1].
    sr : int
        Sample rate, Hz.
    hop_length : int
        Hop of the onset envelope, samples (160 = 10 ms at 16 kHz).

    Returns
    -------
    np.ndarray, shape (onsets,), seconds
    """
    import librosa

    a = np.asarray(audio, dtype=np.float32)
    if a.ndim != 1:
        raise ConfigError(f"audio must be mono, shape (samples,), got {a.shape}")
    if a.size < 2 * hop_length or not np.any(a):
        return np.zeros(0)
    sr, hop = int(sr), int(hop_length)
    env = librosa.onset.onset_strength(y=a, sr=sr, hop_length=hop)
    env = env - env.min()
    env /= env.max() + np.finfo(env.dtype).tiny
    if not env.any() or not np.all(np.isfinite(env)):
        return np.zeros(0)
    # window lengths exactly as onset_detect derives them (floor, then ceil to int)
    frames = pick_peaks(
        env,
        pre_max=math.ceil(0.03 * sr // hop),
        post_max=math.ceil(0.00 * sr // hop + 1),
        pre_avg=math.ceil(0.10 * sr // hop),
        post_avg=math.ceil(0.10 * sr // hop + 1),
        wait=math.ceil(0.03 * sr // hop),
        delta=0.07,
    )
    return librosa.frames_to_time(frames, sr=sr, hop_length=hop).astype(np.float64)


@checks_arguments
def beat_consistency(motion_beat_times: np.ndarray, onset_times: np.ndarray, *, sigma: float = 0.1) -> float:
    """Gaussian beat-alignment score of motion beats against audio onsets.

    ``mean over onsets o of exp(-min_b (o - b)^2 / (2 sigma^2))`` with ``b`` the motion beats.

    Parameters
    ----------
    motion_beat_times : array, shape (beats,), seconds
    onset_times : array, shape (onsets,), seconds
    sigma : float
        Tolerance, seconds (> 0). AI Choreographer used 3 frames at 60 fps (0.05 s), BEAT 0.3 s;
        speech has an onset every 0.2-0.3 s, so we take 0.1 s.

    Returns
    -------
    float in [0, 1]
        1 when a motion beat falls on every onset; 0 without motion beats; NaN without onsets.
    """
    if not sigma > 0:
        raise ConfigError(f"sigma must be a positive number of seconds, got {sigma!r}")
    beats = np.asarray(motion_beat_times, dtype=np.float64).ravel()
    onsets = np.asarray(onset_times, dtype=np.float64).ravel()
    if onsets.size == 0:
        return float("nan")
    if beats.size == 0:
        return 0.0
    beats = np.sort(beats)
    # nearest beat of each onset by binary search, not by an onsets x beats matrix
    i = np.clip(np.searchsorted(beats, onsets), 1, max(beats.size - 1, 1))
    d = np.minimum(np.abs(onsets - beats[i - 1]), np.abs(onsets - beats[np.minimum(i, beats.size - 1)]))
    return float(np.mean(np.exp(-(d**2) / (2 * sigma**2))))


@checks_arguments
def beat_consistency_score(
    positions: np.ndarray,
    audio: np.ndarray,
    *,
    fps: float,
    sr: int = AUDIO_SR,
    sigma: float = 0.1,
    onsets: np.ndarray | None = None,
    **beat_options: Any,
) -> float:
    """:func:`beat_consistency` of a motion and the speech it goes with.

    Parameters
    ----------
    positions : array, shape (frames, joints, 3), metres
    audio : array, shape (samples,)
        The speech, starting with the first frame.
    fps, sr, sigma
        See :func:`motion_beats`, :func:`audio_onsets`, :func:`beat_consistency`.
    onsets : array, optional
        Onset times already detected (several motions for one speech); only those within the
        motion's duration count.
    **beat_options
        Passed to :func:`motion_beats`.
    """
    x = _positions(positions)
    if onsets is None:
        onsets = audio_onsets(audio, sr=sr)
    onsets = np.asarray(onsets, dtype=np.float64)
    onsets = onsets[onsets < x.shape[0] / _fps(fps)]
    return beat_consistency(motion_beats(x, fps=fps, **beat_options), onsets, sigma=sigma)


# ---- diversity ---------------------------------------------------------------------------------


@checks_arguments
def diversity_l1(positions: np.ndarray, *, window: int = 15, joints: Sequence[int] | None = None) -> float:
    """BEAT's L1 diversity over non-overlapping windows of the motion.

    The windows (``window`` frames each, flattened) are the samples; the
    measure is the mean over samples of their L1 distance to the mean sample,
    divided by ``window`` so that it reads per frame (metres, summed over the
    coordinates of the joints). ``window=1`` is BEAT's L1div over poses.

    Parameters
    ----------
    positions : array, shape (frames, joints, 3), metres
    window : int
        Frames per window (15 = one second at 15 fps).
    joints : sequence of int, optional
        Joints used (all by default).

    Returns
    -------
    float, metres; 0 for a constant pose; NaN with fewer than two windows.
    """
    x = _select(_positions(positions), joints)
    if not isinstance(window, (int, np.integer)) or window < 1:
        raise ConfigError(f"window must be a positive number of frames, got {window!r}")
    n = x.shape[0] // int(window)
    if n < 2:
        return float("nan")
    rows = x[: n * window].reshape(n, -1)
    # deviations from the first row first: equal rows give exactly 0, and less rounding
    dev = rows - rows[0]
    return float(np.abs(dev - dev.mean(axis=0)).sum(axis=1).mean() / window)


# ---- Fréchet distance --------------------------------------------------------------------------


@checks_arguments
def gaussian_statistics(features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of a feature set.

    Parameters
    ----------
    features : array, shape (samples, dims), at least two samples

    Returns
    -------
    mean : np.ndarray, shape (dims,), float64
    cov : np.ndarray, shape (dims, dims), float64 (unbiased)
    """
    f = np.asarray(features, dtype=np.float64)
    if f.ndim != 2 or f.shape[0] < 2:
        raise ConfigError(f"features must have shape (samples >= 2, dims), got {f.shape}")
    return f.mean(axis=0), np.atleast_2d(np.cov(f, rowvar=False))


def _psd_sqrt(c: np.ndarray) -> np.ndarray:
    w, v = np.linalg.eigh((c + c.T) / 2)
    return (v * np.sqrt(np.clip(w, 0, None))) @ v.T


@checks_arguments
def frechet_distance(mean1: np.ndarray, cov1: np.ndarray, mean2: np.ndarray, cov2: np.ndarray) -> float:
    """Fréchet (2-Wasserstein) distance between two Gaussians, squared as FID/FGD report it.

    ``|m1 - m2|^2 + tr(C1) + tr(C2) - 2 tr((C1^1/2 C2 C1^1/2)^1/2)``, computed with
    symmetric eigendecompositions (stable for singular covariances).

    Parameters
    ----------
    mean1, mean2 : array, shape (dims,)
    cov1, cov2 : array, shape (dims, dims), symmetric positive semi-definite

    Returns
    -------
    float >= 0; exactly 0 for identical statistics.
    """
    m1, m2 = np.asarray(mean1, np.float64), np.asarray(mean2, np.float64)
    c1, c2 = np.atleast_2d(np.asarray(cov1, np.float64)), np.atleast_2d(np.asarray(cov2, np.float64))
    d = m1.shape[0] if m1.ndim == 1 else -1
    if m1.shape != m2.shape or m1.ndim != 1 or c1.shape != (d, d) or c2.shape != (d, d):
        raise ConfigError(
            f"means (dims,) and covariances (dims, dims) must agree, got {m1.shape}, {c1.shape}, {m2.shape}, {c2.shape}"
        )
    if np.array_equal(m1, m2) and np.array_equal(c1, c2):
        return 0.0
    s1 = _psd_sqrt(c1)
    mid = s1 @ c2 @ s1
    cross = np.sqrt(np.clip(np.linalg.eigvalsh((mid + mid.T) / 2), 0, None)).sum()
    value = float(np.sum((m1 - m2) ** 2) + np.trace(c1) + np.trace(c2) - 2 * cross)
    return max(value, 0.0)


# ---- kinematics --------------------------------------------------------------------------------


@checks_arguments
def kinematic_magnitudes(
    positions: np.ndarray, *, fps: float, order: int = 1, joints: Sequence[int] | None = KINEMATIC_JOINTS
) -> np.ndarray:
    """Magnitudes of the ``order``-th finite difference of every joint, in SI units.

    Parameters
    ----------
    positions : array, shape (frames, joints, 3), metres
    fps : float
    order : int
        1: speed (m/s), 2: acceleration (m/s^2), 3: jerk (m/s^3).
    joints : sequence of int or None
        Default :data:`KINEMATIC_JOINTS`; None: all joints.

    Returns
    -------
    np.ndarray, shape ((frames - order) * joints,), float64; empty when frames <= order.
    """
    if order not in (1, 2, 3):
        raise ConfigError(f"order must be 1, 2 or 3, got {order!r}")
    x = _select(_positions(positions), joints)
    fps = _fps(fps)
    if x.shape[0] <= order:
        return np.zeros(0)
    return (np.linalg.norm(np.diff(x, n=order, axis=0), axis=2) * fps**order).ravel()


@checks_arguments
def hellinger_distance(p: np.ndarray, q: np.ndarray) -> float:
    """Hellinger distance between two histograms (normalised here), ``sqrt(1 - sum sqrt(p q))``.

    Computed as ``sqrt(sum (sqrt p - sqrt q)^2 / 2)``, the same value, which is exactly 0 for
    equal histograms.

    Parameters
    ----------
    p, q : array, shape (bins,), non-negative counts or probabilities

    Returns
    -------
    float in [0, 1]; 0 for proportional histograms, 1 for disjoint ones.
    """
    p, q = np.asarray(p, np.float64).ravel(), np.asarray(q, np.float64).ravel()
    if p.shape != q.shape or np.any(p < 0) or np.any(q < 0) or p.sum() <= 0 or q.sum() <= 0:
        raise ConfigError("histograms must have the same number of bins, non-negative counts and some mass")
    d = np.sqrt(p / p.sum()) - np.sqrt(q / q.sum())
    return float(min(1.0, math.sqrt(0.5 * np.sum(d * d))))


@checks_arguments
def kinematic_hellinger(
    positions: np.ndarray,
    reference: np.ndarray,
    *,
    fps: float,
    order: int = 1,
    bins: int | Sequence[float] = 100,
    joints: Sequence[int] | None = KINEMATIC_JOINTS,
) -> float:
    """Hellinger distance between the speed (or acceleration) histograms of two motions.

    Parameters
    ----------
    positions, reference : array, shape (frames, joints, 3), metres, same fps
    fps : float
    order : int
        1: speed histograms, 2: acceleration histograms (see :func:`kinematic_magnitudes`).
    bins : int or sequence of float
        Number of equal bins from 0 to the largest magnitude of either motion, or explicit edges.
    joints : sequence of int or None

    Returns
    -------
    float in [0, 1]; 0 for identical motions. NaN when either motion is too short.
    """
    a = kinematic_magnitudes(positions, fps=fps, order=order, joints=joints)
    b = kinematic_magnitudes(reference, fps=fps, order=order, joints=joints)
    if a.size == 0 or b.size == 0:
        return float("nan")
    if isinstance(bins, (int, np.integer)):
        if bins < 1:
            raise ConfigError(f"bins must be a positive number, got {bins}")
        top = max(a.max(), b.max())
        edges = np.linspace(0.0, top if top > 0 else 1.0, int(bins) + 1)
    else:
        edges = np.asarray(bins, dtype=np.float64)
        if edges.ndim != 1 or edges.size < 2 or np.any(np.diff(edges) <= 0):
            raise ConfigError("bin edges must be an increasing sequence of at least two values")
        # values past the last edge count in the last bin, as a histogram of the tail
        a, b = np.minimum(a, edges[-1]), np.minimum(b, edges[-1])
    ha, _ = np.histogram(a, bins=edges)
    hb, _ = np.histogram(b, bins=edges)
    if ha.sum() == 0 or hb.sum() == 0:
        return float("nan")
    return hellinger_distance(ha, hb)


@checks_arguments
def mean_acceleration(positions: np.ndarray, *, fps: float, joints: Sequence[int] | None = KINEMATIC_JOINTS) -> float:
    """Mean magnitude of joint acceleration (second differences), m/s^2; NaN under 3 frames."""
    v = kinematic_magnitudes(positions, fps=fps, order=2, joints=joints)
    return float(v.mean()) if v.size else float("nan")


@checks_arguments
def mean_jerk(positions: np.ndarray, *, fps: float, joints: Sequence[int] | None = KINEMATIC_JOINTS) -> float:
    """Mean magnitude of joint jerk (third differences), m/s^3; 0 for a constant pose, NaN under 4 frames."""
    v = kinematic_magnitudes(positions, fps=fps, order=3, joints=joints)
    return float(v.mean()) if v.size else float("nan")


@checks_arguments
def boundary_jumps(
    positions: np.ndarray, boundaries: np.ndarray | Sequence[int], *, joints: Sequence[int] | None = KINEMATIC_JOINTS
) -> dict:
    """How far the joints move across segment joins, against any other pair of frames.

    Parameters
    ----------
    positions : array, shape (frames, joints, 3), metres
    boundaries : sequence of int
        First frame of every segment after the first (a join lies between frames ``b - 1`` and ``b``).
        Values outside ``1 .. frames - 1`` are ignored.
    joints : sequence of int or None

    Returns
    -------
    dict
        ``jump``: mean joint displacement across the joins (metres per frame);
        ``elsewhere``: the same between all other consecutive frames;
        ``ratio``: ``jump / elsewhere`` (1 when joins look like any other frame, NaN if undefined);
        ``joins``: joins counted.
    """
    x = _select(_positions(positions), joints)
    disp = np.linalg.norm(np.diff(x, axis=0), axis=2).mean(axis=1) if x.shape[0] > 1 else np.zeros(0)
    b = np.unique(np.asarray(boundaries, dtype=np.int64).ravel())
    b = b[(b >= 1) & (b < x.shape[0])]
    at = np.zeros(disp.shape[0], bool)
    at[b - 1] = True
    jump = float(disp[at].mean()) if at.any() else float("nan")
    other = float(disp[~at].mean()) if (~at).any() else float("nan")
    ratio = jump / other if other > 0 and not math.isnan(jump) else float("nan")
    return {"jump": jump, "elsewhere": other, "ratio": ratio, "joins": int(at.sum())}


# ---- controls ----------------------------------------------------------------------------------

_STAT_ATTRIBUTES = ("left_hand_height", "left_hand_speed", "hand_speed", "asymmetry")


@checks_arguments
def control_adherence(positions: np.ndarray, track: ControlTrack, *, thresholds: dict, fps: float) -> pd.DataFrame:
    """Per control segment: the fraction of frames meeting its constraint, and attribute statistics.

    The attributes of the motion are computed as for database frames
    (:func:`gesturekit.control.frame_attributes`) and compared with the
    database's thresholds, so "meets ``left_hand=high``" means exactly what the
    search admits.

    Parameters
    ----------
    positions : array, shape (frames, 55, 3), metres
    track : ControlTrack
    thresholds : dict
        Attribute -> (low, high), e.g. ``MatchingDatabase.thresholds``.
    fps : float

    Returns
    -------
    pandas.DataFrame
        One row per segment that covers at least one frame: ``start_s``, ``end_s``,
        ``constraint``, ``frames``, ``adherence`` (fraction in [0, 1]), and the mean and standard
        deviation of ``left_hand_height`` [m], ``left_hand_speed`` and ``hand_speed`` [m/s] and
        ``asymmetry`` [m] over the segment's frames.
    """
    import pandas as pd

    x = _positions(positions)
    fps = _fps(fps)
    missing = [a for a in ATTRIBUTE_NAMES if a not in thresholds]
    if missing:
        raise ConfigError(f"thresholds lack the attributes {', '.join(missing)}")
    attrs = frame_attributes(x, fps=fps)
    n = x.shape[0]
    rows = []
    for seg in track.segments:
        # the frames of a segment, counted as ControlTrack.frame_labels counts them
        a = max(int(np.ceil(seg.start_s * fps - 1e-9)), 0)
        b = min(int(np.ceil(seg.end_s * fps - 1e-9)), n)
        if b <= a:
            continue
        seg_attrs = attrs[a:b]
        ok = constraint_mask(seg_attrs, seg.constraints, thresholds)
        row = {
            "start_s": seg.start_s,
            "end_s": seg.end_s,
            "constraint": seg.label(),
            "frames": b - a,
            "adherence": float(ok.mean()),
        }
        for name in _STAT_ATTRIBUTES:
            col = seg_attrs[:, ATTRIBUTE_NAMES.index(name)].astype(np.float64)
            row[f"{name}_mean"] = float(col.mean())
            row[f"{name}_std"] = float(col.std())
        rows.append(row)
    columns = ["start_s", "end_s", "constraint", "frames", "adherence"] + [
        f"{n}_{s}" for n in _STAT_ATTRIBUTES for s in ("mean", "std")
    ]
    return pd.DataFrame(rows, columns=columns)


@checks_arguments
def overall_adherence(table: pd.DataFrame) -> float:
    """Frame-weighted mean adherence of a :func:`control_adherence` table (NaN if it has no frame)."""
    frames = np.asarray(table["frames"], dtype=np.float64)
    if frames.sum() <= 0:
        return float("nan")
    return float(np.sum(np.asarray(table["adherence"], dtype=np.float64) * frames) / frames.sum())
