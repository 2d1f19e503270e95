"""The exact distances of the search, vectorised, and the error bounds of its float32 estimates.

:func:`exact_pose_sqdist` and :func:`exact_cosine_distance` are the definitions of
:mod:`gesturekit.search.reference` (float64, summed left to right) for many rows
at once, bit for bit. The fast search estimates distances in float32 and
re-checks every near-tie with these; the bounds below say how far an estimate
may be from the exact value (see :mod:`gesturekit.search.index`); :func:`reduce_chunk`
finds each clip's least estimate and whether it is decisive under those bounds.
"""

from __future__ import annotations

import functools
from types import ModuleType

import numpy as np

from .._arguments import checks_arguments

__all__ = [
    "exact_pose_sqdist",
    "exact_cosine_distance",
    "pose_err_factor",
    "audio_err",
    "compiled",
    "reduce_chunk",
    "initial_order",
    "MAX_ABS",
]

U32 = 2.0**-24
#: Absolute slack for float32 underflow in products.
TINY = 1e-30
#: Largest feature magnitude accepted: float32 products and sums of squares cannot overflow.
MAX_ABS = 1e15


@checks_arguments
def pose_err_factor(dims: int) -> float:
    """Multiple of ``max|p|^2 + |q|^2`` bounding the float32 pose estimate's error.

    The bound is ``(gamma_D + 3u)``; ``(D + 32) u`` adds room for the float64 rounding
    of the exact value and of ``|p|^2``, ``|q|^2`` (see :mod:`gesturekit.search.index`).
    """
    return (dims + 32) * U32


@checks_arguments
def audio_err(dims: int) -> float:
    """Bound on the error of the cosine distance estimated from a float32 dot product of
    A values (``gamma_A |a| |b|``, relative to ``|a| |b|``) and float64 norms."""
    return (dims + 16) * U32 + 1e-12


@checks_arguments
def exact_pose_sqdist(rows: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Exact squared pose distances of several rows to one query.

    Parameters
    ----------
    rows : np.ndarray, shape (n, D), float32
    q : np.ndarray, shape (D,), float32

    Returns
    -------
    np.ndarray, shape (n,), float64
        Bit-identical to :func:`gesturekit.search.reference.pose_sqdist` per row.
    """
    # (D, n), one column per row: float64(a_j) - float64(b_j), rows laid out for the loop below
    x = np.subtract(np.asarray(rows).T, np.asarray(q, dtype=np.float64)[:, None], dtype=np.float64, order="C")
    np.multiply(x, x, out=x)
    acc = np.zeros(x.shape[1])
    for j in range(x.shape[0]):  # left to right, as the definition says
        acc += x[j]
    return acc


@checks_arguments
def exact_cosine_distance(rows: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Exact cosine distances of several audio features ``rows`` (n, A) to one ``f`` (A,), all float32.

    Returns the (n,) float64 distances, each bit-identical to
    :func:`gesturekit.search.reference.cosine_distance` (1 where a norm is 0).
    """
    x = np.asarray(rows).T  # (A, n)
    y = np.asarray(f, dtype=np.float64)
    n = x.shape[1]
    terms = np.empty((x.shape[0], 2 * n))  # per dimension: the n products, then the n squares
    np.multiply(x, y[:, None], out=terms[:, :n], dtype=np.float64)
    np.multiply(x, x, out=terms[:, n:], dtype=np.float64)
    acc = np.zeros(2 * n)
    nb = 0.0
    for j, yj in enumerate(y.tolist()):  # left to right, as the definition says
        acc += terms[j]
        nb += yj * yj
    dot, na = acc[:n], acc[n:]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = 1.0 - dot / np.sqrt(na * nb)
    out[(na == 0.0) | (nb == 0.0)] = 1.0
    return out


@functools.cache
def compiled() -> ModuleType:
    """The compiled loops of the search (:mod:`gesturekit.search.kernels`), imported on first use."""
    from . import kernels  # numba is heavy: imported when a search first runs

    return kernels


@checks_arguments
def reduce_chunk(
    G3: np.ndarray, bias: np.ndarray, nq: np.ndarray, npmax: np.ndarray, c_err: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per clip and query of a chunk: the float32 argmin and minimum of the estimates
    ``A = G3 + bias`` over the clip's starts, and whether that minimum is not decisive:
    another start within twice the error bound of it, or a minimum that may be an exact zero
    (the scan of :class:`~gesturekit.search.index.SearchIndex`, chunk by chunk of clips).

    Parameters
    ----------
    G3 : (nc, T, b) float32
        ``-2 q.p`` per clip, start and query (a view; may be strided). With one query
        it is overwritten with ``A``.
    bias : (nc, T) float32
        ``|p|^2``, or +inf where the start is not admissible.
    nq : (b,) float64
        ``|q|^2`` per query.
    npmax : (nc,) float64
        Largest ``|p|^2`` per clip.
    c_err : float
        :func:`pose_err_factor` of the pose dimension.

    Returns
    -------
    s0 : (nc, b) int64, amin : (nc, b) float32, undecided : (nc, b) bool
    """
    nc, T, b = G3.shape
    if b > 1:  # several queries: numpy's reductions along the strided axis are slow
        s0 = np.empty((nc, b), np.int64)
        amin = np.empty((nc, b), np.float32)
        undecided = np.empty((nc, b), bool)
        compiled().reduce_many(G3, bias, nq, (npmax, c_err, TINY), (s0, amin, undecided))
        return s0, amin, undecided
    A = G3[:, :, 0]
    A += bias
    A = G3[:, :, 0]
    s0 = A.argmin(axis=1)
    amin = np.take_along_axis(A, s0[:, None], axis=1)[:, 0]
    err = c_err * (npmax + nq[0]) + TINY
    am64 = amin.astype(np.float64)
    finite = np.isfinite(amin)
    with np.errstate(invalid="ignore"):
        thr = np.where(finite, am64 + 2.0 * err, -np.inf).astype(np.float32)
    thr = np.nextafter(thr, np.float32(np.inf))  # round the float32 threshold up
    count = np.count_nonzero(A <= thr[:, None], axis=1)
    undecided = finite & ((count > 1) | (am64 + nq[0] <= err))
    return s0[:, None], amin[:, None], undecided[:, None]


@checks_arguments
def initial_order(v: np.ndarray, prefix: int) -> tuple[np.ndarray, int]:
    """The order the rank groups of :func:`~gesturekit.search.decide.decide_query` start from.

    Returns ``(order, L)``: the survivors with the ``L = min(prefix, n)`` smallest
    estimates first, sorted, the others after them in any order. Any order near the
    sorted one will do: the groups of near-equal estimates (equal exact values
    included) are proven whatever the order inside them (``prefix_groups`` of :mod:`~gesturekit.search.kernels`),
    and those that matter are re-sorted with exact values. Sorting float32 copies of
    the estimates is then enough (they misplace only values closer than float32
    rounding), and numpy sorts and partitions float32 keys faster than float64 ones.
    """
    n = v.size
    key = v.astype(np.float32)
    if prefix >= n:
        return np.argsort(key), n
    order = np.argpartition(key, prefix - 1)
    head = order[:prefix]
    order[:prefix] = head[np.argsort(key[head])]
    return order, prefix
