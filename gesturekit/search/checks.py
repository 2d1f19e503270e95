"""Input checks shared by the fast search and the reference: shapes, values, options.

Every check raises :class:`~gesturekit.errors.ConfigError` naming the input and
the problem; the normalised inputs come back as C-contiguous arrays.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, TypedDict

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError
from .exact import MAX_ABS, compiled
from .threads import in_parts
from .types import SearchConfig

if TYPE_CHECKING:  # typing.Unpack is Python 3.11+; only the type checker reads it
    from typing_extensions import Unpack

__all__ = [
    "CheckedCall",
    "SearchOptions",
    "validate",
    "validate_db",
    "validate_call",
    "check_segment",
    "checked_sqnorms",
]


@checks_arguments
def check_segment(n: int, clip_frames: int) -> None:
    """Refuse a segment length N (frames per step, already a positive integer) longer than a clip."""
    if n > clip_frames:
        raise ConfigError(f"segment N = {n} is longer than a database clip ({clip_frames} frames)")


@dataclass
class CheckedCall:
    """One search's inputs after :func:`validate_call`: C-contiguous arrays of the checked dtypes.

    Attributes
    ----------
    query : np.ndarray, shape (T_out, A), float32
    config : SearchConfig
    masks : np.ndarray, shape (n_masks, M, T), bool, or None
    step_mask_index : np.ndarray, shape (n_steps,), int64, or None
        Per step, the index into ``masks`` (-1: unconstrained).
    exclude : np.ndarray, shape (M, T), bool, or None
    n_steps : int
    P, F, valid : np.ndarray or None
        The database's features and valid frames, set by :func:`validate` (not by :func:`validate_call`).
    """

    query: np.ndarray
    config: SearchConfig
    masks: np.ndarray | None
    step_mask_index: np.ndarray | None
    exclude: np.ndarray | None
    n_steps: int
    P: np.ndarray | None = None
    F: np.ndarray | None = None
    valid: np.ndarray | None = None


class SearchOptions(TypedDict, total=False):
    """The keyword arguments of one search, shared by :func:`gesturekit.search.search`,
    :meth:`gesturekit.search.SearchIndex.search` and the reference; :func:`validate_call`
    is the one signature that names them (an unknown keyword is a ``TypeError`` there).

    Attributes
    ----------
    config : SearchConfig or None
    masks : np.ndarray, shape (n_masks, M, T), bool, or None
    step_mask_index : np.ndarray, shape (n_steps,), int, or None
    exclude : np.ndarray, shape (M, T), bool, or None
    """

    config: SearchConfig | None
    masks: np.ndarray | None
    step_mask_index: np.ndarray | None
    exclude: np.ndarray | None


@checks_arguments
def validate_db(P: np.ndarray, F: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The database's pose features (M, T, D), audio features (M, T, A) and valid frames (M, T) checked
    for shape and dtype, as C-contiguous float32, float32 and bool arrays."""
    P = np.ascontiguousarray(P, dtype=np.float32)
    F = np.ascontiguousarray(F, dtype=np.float32)
    valid = np.ascontiguousarray(valid)
    if P.ndim != 3 or P.shape[0] < 1 or P.shape[1] < 1 or P.shape[2] < 1:
        raise ConfigError(f"pose features must have shape (clips, frames, dims), got {P.shape}")
    M, T, _ = P.shape
    if F.ndim != 3 or F.shape[:2] != (M, T) or F.shape[2] < 1:
        raise ConfigError(f"audio features must have shape ({M}, {T}, dims) like the pose features, got {F.shape}")
    if valid.shape != (M, T) or valid.dtype != bool:
        raise ConfigError(f"valid must be a bool array of shape ({M}, {T}), got {valid.dtype} {valid.shape}")
    # finite values and magnitudes are checked by SearchIndex while it computes the norms
    return P, F, valid


@checks_arguments
def validate_call(
    shape: tuple[int, int, int, int],
    query: np.ndarray,
    *,
    config: SearchConfig | None = None,
    masks: np.ndarray | None = None,
    step_mask_index: np.ndarray | None = None,
    exclude: np.ndarray | None = None,
) -> CheckedCall:
    """One search's inputs checked against a database of ``shape = (M, T, D, A)``.

    Raises
    ------
    ConfigError
        A wrong shape, dtype or value, naming the input.
    """
    M, T, D, A = shape
    config = SearchConfig() if config is None else config
    if not isinstance(config, SearchConfig):
        raise ConfigError(f"config must be a SearchConfig, got {type(config).__name__}")
    query = np.ascontiguousarray(query, dtype=np.float32)
    if query.ndim != 2 or query.shape[1] != A or query.shape[0] < 1:
        raise ConfigError(f"query audio features must have shape (frames >= 1, {A}), got {query.shape}")
    if not np.isfinite(query).all():
        raise ConfigError("query audio features contain NaN or infinite values")
    if np.abs(query).max() > MAX_ABS:
        raise ConfigError(f"query audio features exceed {MAX_ABS:g} in magnitude (are they z-scored?)")
    N = config.segment
    check_segment(N, T)
    if not isinstance(config.init_pose, str):
        if len(config.init_pose) != D:
            raise ConfigError(f"initial pose must have {D} values, got {len(config.init_pose)}")
        if max(abs(x) for x in config.init_pose) > MAX_ABS:
            raise ConfigError(f"initial pose exceeds {MAX_ABS:g} in magnitude (is it z-scored?)")
    n_steps = -(-query.shape[0] // N)
    if masks is not None:
        masks = np.ascontiguousarray(masks)
        if masks.ndim != 3 or masks.shape[1:] != (M, T) or masks.dtype != bool:
            raise ConfigError(
                f"masks must be a bool array of shape (n_masks, {M}, {T}), got {masks.dtype} {masks.shape}"
            )
    if step_mask_index is not None:
        index = np.asarray(step_mask_index)
        if index.shape != (n_steps,) or index.dtype.kind not in "iu":
            raise ConfigError(
                f"step_mask_index must be {n_steps} integers (one per step of {N} frames), got {index.shape}"
            )
        n_masks = 0 if masks is None else masks.shape[0]
        if index.size and (index.min() < -1 or index.max() >= n_masks):
            raise ConfigError(f"step_mask_index entries must be -1 or an index below {n_masks} (the number of masks)")
        step_mask_index = index.astype(np.int64)
    elif masks is not None:
        raise ConfigError("masks were given without step_mask_index (which mask each step uses)")
    if exclude is not None:
        exclude = np.ascontiguousarray(exclude)
        if exclude.shape != (M, T) or exclude.dtype != bool:
            raise ConfigError(f"exclude must be a bool array of shape ({M}, {T}), got {exclude.dtype} {exclude.shape}")
    for i, (m, s) in config.pins.items():
        if i >= n_steps:
            raise ConfigError(f"pin at step {i}, but the query has only {n_steps} steps")
        if m >= M or s + N > T:
            raise ConfigError(f"pin at step {i}: window (clip {m}, start {s}) of {N} frames is outside the database")
        if exclude is not None and exclude[m, s : s + N].any():
            raise ConfigError(f"pin at step {i}: window (clip {m}, start {s}) contains excluded frames")
    return CheckedCall(
        query=query, config=config, masks=masks, step_mask_index=step_mask_index, exclude=exclude, n_steps=n_steps
    )


@checks_arguments
def validate(
    P: np.ndarray, F: np.ndarray, valid: np.ndarray, query: np.ndarray, **options: Unpack[SearchOptions]
) -> CheckedCall:
    """Shared input checks of the fast and the reference search; returns the normalised inputs."""
    P, F, valid = validate_db(P, F, valid)
    M, T = valid.shape
    checked_sqnorms(P.reshape(M * T, -1), "pose")  # the values, as SearchIndex checks them
    checked_sqnorms(F.reshape(M * T, -1), "audio")
    call = validate_call((*P.shape, F.shape[2]), query, **options)
    call.P, call.F, call.valid = P, F, valid
    return call


@checks_arguments
def checked_sqnorms(x2: np.ndarray, name: str, workers: int = 1) -> np.ndarray:
    """Squared norms (float64) of the rows of a float32 (rows, dims) matrix, read once.

    Raises
    ------
    ConfigError
        NaN or infinite values, or magnitudes above ``MAX_ABS``.
    """
    out = np.empty(x2.shape[0])
    kernel = compiled().row_stats
    stats = in_parts(x2.shape[0], workers, lambda a, b: kernel(x2[a:b], out[a:b]))
    if not all(ok for ok, _ in stats):
        raise ConfigError(f"{name} features contain NaN or infinite values")
    if max(top for _, top in stats) > MAX_ABS:
        raise ConfigError(f"{name} features exceed {MAX_ABS:g} in magnitude (are they z-scored?)")
    return out
