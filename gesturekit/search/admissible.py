"""Which windows a search step may use: rule 1 of Algorithm 1, vectorised, in one place.

A window of ``n`` frames starting at frame ``s`` of clip ``m`` is admissible iff
``s + n <= T``, ``valid[m, s]``, no frame of ``[s, s + n)`` is excluded, and the
step's control mask holds (rule ``"ends"``: at ``s`` and ``s + n - 1``; rule
``"all"``: on every frame of the window). :func:`admissible_starts` computes it
for every start of every clip at once; the fast search, the step explanations,
the baselines and the walkthrough tables all use it.
:func:`gesturekit.search.reference.window_admissible` states the same rule for
one window, loop for loop; the tests hold the two equal.
"""

from __future__ import annotations

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError

__all__ = ["MASK_RULES", "window_all", "base_starts", "control_starts", "admissible_starts", "draw_initial_frame"]

#: Where a control mask must hold in a window: its first and last frame, or every frame.
MASK_RULES = ("ends", "all")


@checks_arguments
def window_all(flags: np.ndarray, n: int) -> np.ndarray:
    """Whether a whole window holds a flag.

    Parameters
    ----------
    flags : np.ndarray, shape (M, T), bool
    n : int
        Window length, frames.

    Returns
    -------
    np.ndarray, shape (M, T), bool
        ``out[m, s]`` = all of ``flags[m, s : s + n]`` for ``s + n <= T``, False beyond.
    """
    M, T = flags.shape
    out = np.zeros((M, T), bool)
    if n <= T:
        bad = np.zeros((M, T + 1), np.int32)
        np.cumsum(~flags, axis=1, out=bad[:, 1:])  # failures before each frame
        out[:, : T - n + 1] = bad[:, n:] == bad[:, : T - n + 1]
    return out


@checks_arguments
def base_starts(valid: np.ndarray, n: int, exclude: np.ndarray | None = None) -> np.ndarray:
    """Admissible starts without a control: a valid start, the window inside its clip, nothing excluded.

    Parameters
    ----------
    valid : np.ndarray, shape (M, T), bool
        Frames whose features needed no padding.
    n : int
        Window length, frames.
    exclude : np.ndarray, shape (M, T), bool, optional
        Frames no window may contain.

    Returns
    -------
    np.ndarray, shape (M, T), bool
    """
    valid = np.asarray(valid, dtype=bool)
    T = valid.shape[1]
    adm = valid.copy()
    adm[:, max(0, T - n + 1) :] = False
    if exclude is not None:
        adm &= window_all(~np.asarray(exclude, dtype=bool), n)
    return adm


@checks_arguments
def control_starts(mask: np.ndarray, n: int, rule: str = "ends") -> np.ndarray:
    """Starts whose window a control mask admits under the mask rule.

    Parameters
    ----------
    mask : np.ndarray, shape (M, T), bool
        The frames a control admits.
    n : int
        Window length, frames.
    rule : {"ends", "all"}
        The mask must hold at the window's first and last frame, or on every frame.

    Returns
    -------
    np.ndarray, shape (M, T), bool
        False where the window leaves the clip.
    """
    mask = np.asarray(mask, dtype=bool)
    if rule == "all":
        return window_all(mask, n)
    if rule != "ends":
        raise ConfigError(f"mask_rule must be 'ends' or 'all', got {rule!r}")
    T = mask.shape[1]
    out = np.zeros_like(mask)
    if n <= T:
        out[:, : T - n + 1] = mask[:, : T - n + 1] & mask[:, n - 1 :]
    return out


@checks_arguments
def admissible_starts(
    valid: np.ndarray, n: int, *, exclude: np.ndarray | None = None, mask: np.ndarray | None = None, rule: str = "ends"
) -> np.ndarray:
    """Every admissible window start of a step (rule 1 of Algorithm 1).

    Parameters
    ----------
    valid : np.ndarray, shape (M, T), bool
        Frames whose features needed no padding (only these may start a window).
    n : int
        Window length N, frames.
    exclude : np.ndarray, shape (M, T), bool, optional
        Frames no window may contain (held-out takes).
    mask : np.ndarray, shape (M, T), bool, optional
        The step's control mask (None: no control).
    rule : {"ends", "all"}
        Where ``mask`` must hold in a window.

    Returns
    -------
    np.ndarray, shape (M, T), bool
        ``out[m, s]``: the window of ``n`` frames at frame ``s`` of clip ``m`` may be used.
    """
    if rule not in MASK_RULES:
        raise ConfigError(f"mask_rule must be 'ends' or 'all', got {rule!r}")
    adm = base_starts(valid, n, exclude)
    if mask is not None:
        adm &= control_starts(mask, n, rule)
    return adm


@checks_arguments
def draw_initial_frame(admissible: np.ndarray, seed: int) -> tuple[int, int]:
    """The random initial pose's database frame: the k-th admissible frame in clip order,
    ``k`` drawn with ``seed`` (found per clip, without an index of every frame).

    Parameters
    ----------
    admissible : np.ndarray, shape (M, T), bool
        Admissible window starts of the first step.
    seed : int

    Returns
    -------
    (clip, frame)

    Raises
    ------
    ConfigError
        No frame is admissible.
    """
    before = np.cumsum(admissible.sum(axis=1))
    if before[-1] == 0:
        raise ConfigError("no admissible database frame to draw the initial pose from")
    k = int(np.random.default_rng(seed).integers(int(before[-1])))
    clip = int(np.searchsorted(before, k, side="right"))
    return clip, int(np.flatnonzero(admissible[clip])[k - (int(before[clip - 1]) if clip else 0)])
