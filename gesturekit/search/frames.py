"""The frame copy of the pose features: one frame's joints, in 16 bits, instead of a start's trajectory.

A pose feature holds the same joints at several frames ahead (``docs/METHOD.md``, "Features":
the 8 feature joints at ``t, t+2, t+4, t+6``), z-scored per dimension. So the block of offset
``o_k`` of start ``s`` is, up to float32 rounding, an affine map of the first block of frame
``s + o_k`` of the same clip: ``p[s]_k ~ a_k * y[s + o_k] + b_k`` with ``y[f] = p[f]_0``
(K = D / n values), ``a_k = sigma_0 / sigma_k`` and ``b_k = (mu_0 - mu_k) / sigma_k``. A scan
then reads K values a frame instead of D, and every start's squared distance follows from n
dot products per frame. The copy keeps each value as a 16-bit code times a step of its clip
(``y ~ step_i * code``, the step the clip's largest ``|y_i|`` over 32767): 2 K bytes a frame.

The map is fitted on the database itself (:func:`fit_frame_map`); nothing rests on the fit
being right. Per clip the copy stores the largest ``|p[s] - y^(s)|`` over its valid starts,
measured, where ``y^(s)`` stacks ``a_k y'[s + o_k] + b_k`` of the decoded values
``y' = step * code`` (so the residual holds the rounding to codes as well); the estimate's bound
(:func:`frame_bounds`) carries it. A database whose features are not built this way gives a
large residual on the fit's sample, and the search keeps the 8-bit copy
(:mod:`gesturekit.search.reduced`) instead.

Exactly, in real arithmetic, ``|y^ - q|^2 = |y^|^2 - 2 sum_k y'[s + o_k] . (a_k q_k) + |q|^2 - 2 b.q``;
the scan computes ``kappa - 2 sum_k fl(code[s + o_k] . fl(g_k step))`` in float32 with
``kappa = fl(|y^|^2)`` stored per start and ``g_k = fl(a_k q_k)`` per query, and adds
``|q|^2 - 2 b.q`` in float64.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._arguments import checks_arguments
from .exact import TINY, pose_err_factor
from .reduced import compiled_reduced
from .threads import in_parts

__all__ = [
    "FramePose",
    "FrameQuery",
    "fit_frame_map",
    "frame_pose",
    "frame_query",
    "frame_bias",
    "frame_bounds",
    "FIT_CLIPS",
]

#: Clips (evenly spaced) the affine map is fitted and first checked on.
FIT_CLIPS = 64
#: The fit is used when nine starts in ten of its sample lie this close to the map (relative
#: to the typical feature norm): float32 rounding gives about 1e-7.
FIT_TOLERANCE = 1e-4


@dataclass(frozen=True)
class FramePose:
    """The frame copy of pose features ``P`` (M, T, D = n K).

    Attributes
    ----------
    codes : np.ndarray, shape (M, K, T), int16
        Each frame's first block of K values over its step, rounded, stored value-major per
        clip (a scan's products then run along frames).
    steps : np.ndarray, shape (M, K), float32
        Per clip and value, the step of its codes.
    kappa : np.ndarray, shape (M, T), float32
        ``|y^(s)|^2`` per start, rounded to float32; +inf at starts ``s >= T - max(o)``, which
        the copy does not cover.
    stats : np.ndarray, shape (M, 2), float64
        Per clip the largest ``|p[s] - y^(s)|`` and the largest ``|y^(s)|`` over its valid
        covered starts.
    offsets : np.ndarray, shape (n,), int64
        ``o_k``, frames ahead of each block.
    scale, shift : np.ndarray, shape (n, K), float64
        ``a_k`` and ``b_k``.
    """

    codes: np.ndarray
    steps: np.ndarray
    kappa: np.ndarray
    stats: np.ndarray
    offsets: np.ndarray
    scale: np.ndarray
    shift: np.ndarray

    @property
    def covered(self) -> int:
        """Starts ``0 .. covered - 1`` of each clip are covered: their frames lie in the clip."""
        return int(self.kappa.shape[1] - self.offsets.max())

    @property
    def shift_norm(self) -> float:
        """``|b|``, an upper bound (float64 rounding is far inside the bound's float32 terms)."""
        return float(np.sqrt(np.sum(self.shift**2)))

    @property
    def nbytes(self) -> int:
        """Bytes held by the copy."""
        return sum(int(x.nbytes) for x in (self.codes, self.steps, self.kappa, self.stats, self.scale, self.shift))


@dataclass(frozen=True)
class FrameQuery:
    """A query pose as the frame scan uses it.

    Attributes
    ----------
    weights : np.ndarray, shape (n, K), float32
        ``g_k = fl(a_k q_k)``.
    offset : float
        ``|q|^2 - 2 b.q`` (float64).
    norm : float
        ``|q|``.
    """

    weights: np.ndarray
    offset: float
    norm: float


def _blocks(D: int, offsets: np.ndarray) -> int:
    """K, the values per block, or 0 where D is not n blocks."""
    n = offsets.size
    return D // n if n >= 2 and D % n == 0 else 0


@checks_arguments
def fit_frame_map(P3: np.ndarray, valid: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The affine map of each block from the first block of a later frame, fitted by least squares.

    Parameters
    ----------
    P3 : np.ndarray, shape (M, T, D), float32
    valid : np.ndarray, shape (M, T), bool
    offsets : np.ndarray, shape (n,), int

    Returns
    -------
    (scale, shift) : two np.ndarray, shape (n, K), float64, or None
        None where the features are not n blocks of frames ``offsets`` ahead: D is not a
        multiple of n, no clip has a covered valid start, or the sample's residual is large.
    """
    M, T, D = P3.shape
    offsets = np.asarray(offsets, np.int64)
    K = _blocks(D, offsets)
    if K == 0 or offsets.min() < 0 or offsets.max() >= T:
        return None
    covered = T - int(offsets.max())
    clips = np.unique(np.linspace(0, M - 1, min(M, FIT_CLIPS)).astype(np.int64))
    sample = np.asarray(P3[clips], np.float64)  # (m, T, D), a few MB at most
    keep = np.asarray(valid)[clips, :covered]
    if not keep.any():
        return None
    scale = np.ones((offsets.size, K))
    shift = np.zeros((offsets.size, K))
    residual = np.zeros(int(keep.sum()))
    for k, o in enumerate(offsets):
        x = sample[:, o : o + covered, :K][keep]  # (starts, K): the first block, o frames on
        y = sample[:, :covered, k * K : (k + 1) * K][keep]
        xm, ym = x.mean(axis=0), y.mean(axis=0)
        var = ((x - xm) ** 2).mean(axis=0)
        cov = ((x - xm) * (y - ym)).mean(axis=0)
        scale[k] = np.where(var > 0, cov / np.where(var > 0, var, 1.0), 0.0)
        shift[k] = ym - scale[k] * xm
        residual += ((y - (scale[k] * x + shift[k])) ** 2).sum(axis=1)
    residual = np.sqrt(residual)
    typical = float(np.median(np.sqrt((sample[:, :covered][keep] ** 2).sum(axis=1))))
    if not (np.isfinite(residual).all() and np.quantile(residual, 0.9) <= FIT_TOLERANCE * max(typical, TINY)):
        return None
    return scale, shift


@checks_arguments
def frame_pose(P3: np.ndarray, valid: np.ndarray, offsets: np.ndarray, workers: int = 1) -> FramePose | None:
    """The frame copy of ``P3`` (M, T, D) float32 made by ``workers`` threads, or None where
    the features are not built of frames ``offsets`` ahead (see :func:`fit_frame_map`)."""
    offsets = np.asarray(offsets, np.int64)
    fit = fit_frame_map(P3, valid, offsets)
    if fit is None:
        return None
    scale, shift = fit
    M, T, D = P3.shape
    K = D // offsets.size
    out = FramePose(
        codes=np.empty((M, K, T), np.int16),
        steps=np.empty((M, K), np.float32),
        kappa=np.empty((M, T), np.float32),
        stats=np.empty((M, 2)),
        offsets=offsets,
        scale=scale,
        shift=shift,
    )
    kernel = compiled_reduced().frame_clips
    valid = np.ascontiguousarray(valid, dtype=bool)

    def part(a: int, b: int) -> None:
        kernel(
            P3[a:b],
            valid[a:b],
            offsets,
            (scale, shift),
            (out.codes[a:b], out.steps[a:b], out.kappa[a:b], out.stats[a:b]),
        )

    in_parts(M, workers, part)
    covered = valid[:, : out.covered]
    if not (np.isfinite(out.stats).all() and np.isfinite(out.kappa[:, : out.covered][covered]).all()):
        return None  # values so large that float32 squares overflow: the 8-bit copy is used
    return out


@checks_arguments
def frame_query(q: np.ndarray, frames: FramePose) -> FrameQuery:
    """The query pose ``q`` (D,) float32 as the frame scan uses it."""
    q64 = np.asarray(q, np.float64).reshape(frames.scale.shape)
    weights = (frames.scale * q64).astype(np.float32)
    offset = float(np.sum(q64 * q64) - 2.0 * np.sum(frames.shift * q64))
    return FrameQuery(weights=weights, offset=offset, norm=float(np.sqrt(np.sum(q64 * q64))))


@checks_arguments
def frame_bias(frames: FramePose, bias: np.ndarray) -> np.ndarray:
    """What the frame scan reads of the admissible starts: ``kappa`` where a start is admissible
    and covered, -inf where it is admissible and not covered, +inf where it is not admissible.

    Parameters
    ----------
    frames : FramePose
    bias : np.ndarray, shape (M T,) or (M, T), float32
        +inf where a start is not admissible (the scan's ``bias``).

    Returns
    -------
    np.ndarray, shape (M, T), float32
        One array in place of ``kappa`` and the admissible starts: the scan reads 4 bytes a
        start fewer, and needs no masking (+inf minus a finite product stays +inf).
    """
    M, T = frames.kappa.shape
    admissible = np.asarray(bias).reshape(M, T) < np.inf
    # kappa is +inf exactly at the starts not covered, or where a start is not valid (never admissible)
    marked = np.where(np.isinf(frames.kappa), np.float32(-np.inf), frames.kappa)
    return np.where(admissible, marked, np.float32(np.inf)).astype(np.float32, copy=False)


@checks_arguments
def frame_bounds(stats: np.ndarray, query: FrameQuery, shift_norm: float, dims: int) -> np.ndarray:
    """The error bound of each clip's frame estimates for one query (vectorised form).

    The compiled scan computes the same bound clip by clip (``frame_bound``).

    Returns
    -------
    np.ndarray, shape (M,), float64
        ``(D + 32) u (|y^|^2 + (|y^| + |b|)^2 + |q|^2) + r (2 (|y^| + |q|) + r) + tiny`` with
        ``r`` the clip's residual and ``|y^|`` its largest norm.
    """
    lost, top = stats.T
    c = pose_err_factor(dims)
    return c * (top**2 + (top + shift_norm) ** 2 + query.norm**2) + lost * (2.0 * (top + query.norm) + lost) + TINY
