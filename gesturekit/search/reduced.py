"""The reduced copy of the pose features that one query's scan reads first, and its error bound.

A search step reads every clip (``docs/METHOD.md``, "Exact arithmetic", says why no clip can
be left unread). It reads them from this copy: per frame 96 one-byte integers and two float32
values instead of 96 float32 values. Each clip ``m`` has a centre ``c_m`` (float32, the mean
of its frames); each frame's ``p' = p - c_m`` is rounded to ``p~ = s i`` with ``i`` in
-127..127 and a scale ``s`` of its own. Stored per frame: ``i``, ``-2 s`` and
``kappa = |p'|^2 + 2 p~.c_m`` (float32); per clip: the centre and the largest ``r = |p' - p~|``,
``|p~|``, ``|kappa|`` and ``|p'|^2`` over its frames (float64).

The query ``q`` is rounded once per step to ``q~ = s_q i_q`` (16-bit integers,
:func:`quantise_query`). Exactly, in real arithmetic,

``|p - q|^2 = kappa - 2 s s_q (i . i_q) + |q - c_m|^2 - 2 (p' - p~).(q - c_m) - 2 p~.(q - q~)``

and ``i . i_q`` is an exact integer, so the estimate
``fl(kappa + fl(-2 s * fl(s_q * fl(i . i_q)))) + |q - c_m|^2`` is within
:func:`clip_bounds` of the float64 definition (:mod:`gesturekit.search.reference`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from types import ModuleType

import numpy as np

from .._arguments import checks_arguments
from .exact import TINY, pose_err_factor
from .threads import in_parts

__all__ = [
    "ReducedPose",
    "QueryCodes",
    "reduce_pose",
    "quantise_query",
    "clip_bounds",
    "compiled_reduced",
    "QUERY_LEVELS",
]

#: Largest magnitude of a query code (fewer for D above 516, so that ``127 * levels * D < 2**31``).
QUERY_LEVELS = 32767


@dataclass(frozen=True)
class ReducedPose:
    """The reduced copy of pose features ``P`` (M, T, D).

    Attributes
    ----------
    codes : np.ndarray, shape (M, T, D), int8
        ``i``: each frame's centred feature over its scale, rounded.
    coef : np.ndarray, shape (M, T), float32
        ``-2 s`` per frame (exact).
    kappa : np.ndarray, shape (M, T), float32
        ``|p'|^2 + 2 p~.c_m`` per frame, rounded to float32.
    centre : np.ndarray, shape (M, D), float32
        ``c_m`` per clip.
    stats : np.ndarray, shape (M, 4), float64
        Per clip the largest ``|p' - p~|``, ``|p~|``, ``|kappa|`` and ``|p'|^2`` over its frames.
    """

    codes: np.ndarray
    coef: np.ndarray
    kappa: np.ndarray
    centre: np.ndarray
    stats: np.ndarray

    @property
    def nbytes(self) -> int:
        """Bytes held by the copy."""
        return sum(int(x.nbytes) for x in (self.codes, self.coef, self.kappa, self.centre, self.stats))


@dataclass(frozen=True)
class QueryCodes:
    """A query pose rounded for the reduced scan: ``q~ = scale * codes``.

    Attributes
    ----------
    codes : np.ndarray, shape (D,), int16
    scale : float
        ``s_q``, a float32 value.
    lost : float
        An upper bound on ``|q - q~|``.
    norm : float
        An upper bound on ``|q~|``.
    """

    codes: np.ndarray
    scale: float
    lost: float
    norm: float


@functools.cache
def compiled_reduced() -> ModuleType:
    """The compiled loops of the reduced scan (:mod:`gesturekit.search.reduced_kernels`), imported on first use."""
    from . import reduced_kernels  # numba is heavy: imported when a search first runs

    return reduced_kernels


@checks_arguments
def reduce_pose(P3: np.ndarray, workers: int = 1) -> ReducedPose:
    """The reduced copy of the pose features ``P3`` (M, T, D) float32, made by ``workers`` threads."""
    M, T, D = P3.shape
    out = ReducedPose(
        codes=np.empty((M, T, D), np.int8),
        coef=np.empty((M, T), np.float32),
        kappa=np.empty((M, T), np.float32),
        centre=np.empty((M, D), np.float32),
        stats=np.empty((M, 4)),
    )
    kernel = compiled_reduced().reduce_clips

    def part(a: int, b: int) -> None:
        kernel(P3[a:b], (out.codes[a:b], out.coef[a:b], out.kappa[a:b], out.centre[a:b], out.stats[a:b]))

    in_parts(M, workers, part)
    return out


@checks_arguments
def quantise_query(q: np.ndarray) -> QueryCodes:
    """Round a query pose ``q`` (D,) float32 to 16-bit codes with one float32 scale."""
    q64 = np.asarray(q, np.float64)
    levels = max(1, min(QUERY_LEVELS, (2**31 - 1) // (127 * max(1, q64.size))))  # the integer product cannot overflow
    top = float(np.abs(q64).max()) if q64.size else 0.0
    scale = float(np.float32(top / levels))
    if not scale > 0.0:  # an all-zero query (or one that underflows): nothing is rounded
        scale = 1.0
    codes = np.clip(np.rint(q64 / scale), -levels, levels).astype(np.int16)
    kept = scale * codes.astype(np.float64)  # exact: 24-bit scale times 16-bit code
    # float64 norms carry relative errors near 1e-16: the bound's float32 terms cover them
    lost = float(np.sqrt(np.sum((q64 - kept) ** 2)))
    norm = float(np.sqrt(np.sum(kept**2)))
    return QueryCodes(codes=codes, scale=scale, lost=lost, norm=norm)


@checks_arguments
def clip_bounds(stats: np.ndarray, centred_sqnorm: np.ndarray, query: QueryCodes, dims: int) -> np.ndarray:
    """The error bound of each clip's reduced estimates for one query (vectorised form).

    ``stats`` (M, 4) as in :class:`ReducedPose`, ``centred_sqnorm`` (M,) ``|q - c_m|^2``.
    The compiled scan computes the same bound clip by clip (:func:`~gesturekit.search.reduced_kernels.reduced_bound`).

    Returns
    -------
    np.ndarray, shape (M,), float64
        ``2 r |q - c_m| + 2 |p~| r_q + (D + 32) u (|kappa| + 2 |p~| |q~| + 3 |q - c_m|^2 + 2 |p'|^2) + tiny``.
    """
    lost, ptilde, kappa, centred = stats.T
    c = pose_err_factor(dims)
    return (
        2.0 * lost * np.sqrt(centred_sqnorm)
        + 2.0 * ptilde * query.lost
        + c * (kappa + 2.0 * ptilde * query.norm + 3.0 * centred_sqnorm + 2.0 * centred)
        + TINY
    )
