"""The systems an evaluation or a user study compares, all on one matching database.

=============  ==================================================================================
``gt``         the recorded motion of the held-out speech (ground truth)
``random``     random database windows of N frames, concatenated (seeded)
``audio-only`` per step, the window whose audio feature is nearest the speech's (cosine
               distance, as Algorithm 1 measures audio), whatever the pose
``pose-only``  per step, the window whose pose feature is nearest the last output pose
               (Euclidean), whatever the audio: the paper's "simple k-NN"
``knn``        Algorithm 1 (:func:`gesturekit.synthesis.synthesize`), the paper's k-NN
``knn+cgan``   the k-NN motion refined by a trained refiner (the paper's full system)
=============  ==================================================================================

The three baselines search exactly as the k-NN does where they overlap: the
same windows are admissible (a valid start, the whole window inside its clip
and outside the held-out frames, a control holding at the window's first and
last frame, or at every frame), a step's control is dropped when it admits no
window (the step counts as relaxed), the random initial pose is drawn by the
same rule from the same seed, and a pose candidate at distance exactly 0 (the
query's own frame) is skipped. Distances are computed in float64 and ties go
to the lowest (clip, start), so the results are reproducible.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np

from .._arguments import checks_arguments
from ..control import ControlTrack
from ..errors import ConfigError
from ..motion import Motion
from ..search.admissible import admissible_starts
from ..search.checks import check_segment
from ..search.types import SearchConfig

if TYPE_CHECKING:
    from typing_extensions import Unpack  # typing.Unpack is Python 3.11+; only the type checker reads it

    from ..database import MatchingDatabase
    from ..synthesis import MotionRefiner, SynthesisConfig

__all__ = [
    "SYSTEMS",
    "SYSTEM_DESCRIPTIONS",
    "SystemUnavailable",
    "SystemOutput",
    "parse_systems",
    "admissible_windows",
    "random_segments",
    "audio_nearest_segments",
    "pose_nearest_segments",
    "WindowRules",
    "refiner_unavailable_reason",
    "run_system",
]

SYSTEMS: tuple[str, ...] = ("gt", "random", "audio-only", "pose-only", "knn", "knn+cgan")

SYSTEM_DESCRIPTIONS: dict[str, str] = {
    "gt": "recorded motion of the speech (ground truth)",
    "random": "random database segments",
    "audio-only": "audio-only nearest neighbour per step",
    "pose-only": "pose-only nearest neighbour per step (the paper's simple k-NN)",
    "knn": "k-NN motion matching (Algorithm 1)",
    "knn+cgan": "k-NN refined by the resynchronisation cGAN",
}


class SystemUnavailable(ConfigError):
    """A system cannot run here (e.g. ``knn+cgan`` without a trained refiner)."""


@dataclass
class SystemOutput:
    """The motion one system made for one speech.

    Attributes
    ----------
    system : str
    motion : Motion
        (frames, 55, 3) metres at the database's frame rate.
    boundaries : np.ndarray, shape (joins,), int64
        First frame of every segment after the first (for ``gt``: where the others join).
    relaxed_steps : int
        Steps whose control was dropped because it admitted no window.
    """

    system: str
    motion: Motion
    boundaries: np.ndarray
    relaxed_steps: int = 0


@checks_arguments
def parse_systems(systems: str | Sequence[str]) -> tuple[str, ...]:
    """``"gt,knn"`` or a sequence -> a tuple of known system names (order kept, duplicates dropped)."""
    if isinstance(systems, str):
        systems = [s.strip() for s in systems.split(",")]
    out: list[str] = []
    for s in systems:
        if not s:
            continue
        if s not in SYSTEMS:
            raise ConfigError(f"unknown system {s!r}; known systems: {', '.join(SYSTEMS)}")
        if s not in out:
            out.append(s)
    if not out:
        raise ConfigError(f"name at least one system of {', '.join(SYSTEMS)}")
    return tuple(out)


# ---- admissible windows -------------------------------------------------------------------------


@checks_arguments
def admissible_windows(
    valid: np.ndarray,
    *,
    segment: int,
    exclude: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    mask_rule: str = "ends",
) -> np.ndarray:
    """Start frames of windows of ``segment`` frames the search may use
    (:func:`gesturekit.search.admissible.admissible_starts`, the search's own rule).

    Parameters
    ----------
    valid : array, shape (M, T), bool
        Frames that may start a segment.
    segment : int
        Window length N, frames (1..T).
    exclude : array, shape (M, T), bool, optional
        Held-out frames: no window may contain one.
    mask : array, shape (M, T), bool, optional
        A control's admissible frames.
    mask_rule : {"ends", "all"}
        The control must hold at the window's first and last frame, or at every frame.

    Returns
    -------
    np.ndarray, shape (M, T), bool
    """
    valid = np.asarray(valid, dtype=bool)
    options = SearchConfig(segment=segment, mask_rule=mask_rule)  # checked as the search checks them
    check_segment(options.segment, valid.shape[1])
    return admissible_starts(valid, options.segment, exclude=exclude, mask=mask, rule=options.mask_rule)


class WindowRules(TypedDict, total=False):
    """Which windows a baseline's step may use, as the search decides it: the keywords shared by
    :func:`random_segments`, :func:`audio_nearest_segments` and :func:`pose_nearest_segments`.

    Attributes
    ----------
    segment : int
        Frames per window (default 8).
    exclude : np.ndarray, shape (M, T), bool, or None
        Held-out frames.
    masks : np.ndarray, shape (n_masks, M, T), bool, or None
        Control masks.
    step_mask_index : np.ndarray, shape (n_steps,), int, or None
        Each step's index into ``masks`` (-1: none).
    mask_rule : {"ends", "all"}
        Where a mask must hold (default "ends").
    """

    segment: int
    exclude: np.ndarray | None
    masks: np.ndarray | None
    step_mask_index: np.ndarray | None
    mask_rule: str


class _Steps:
    """Admissible windows per step, with the search's relaxation rule, cached per mask.

    Its signature is the one place that names :class:`WindowRules` (an unknown keyword is a
    ``TypeError`` here); ``n_frames`` output frames make ``n_steps`` steps of ``segment``.
    """

    def __init__(
        self,
        valid: np.ndarray,
        n_frames: int,
        *,
        segment: int = 8,
        exclude: np.ndarray | None = None,
        masks: np.ndarray | None = None,
        step_mask_index: np.ndarray | None = None,
        mask_rule: str = "ends",
    ):
        self.n_steps = n_steps = _check_n(n_frames, segment)
        valid = np.asarray(valid, bool)
        self.valid, self.segment, self.exclude, self.masks, self.rule = valid, segment, exclude, masks, mask_rule
        self.step_mask_index = (
            np.full(n_steps, -1, np.int64) if step_mask_index is None else np.asarray(step_mask_index, np.int64)
        )
        if self.step_mask_index.shape != (n_steps,):
            raise ConfigError(
                f"step_mask_index must have one entry per step ({n_steps}), got {self.step_mask_index.shape}"
            )
        if masks is None and np.any(self.step_mask_index >= 0):
            raise ConfigError("step_mask_index refers to control masks, but none were given")
        self._cache: dict[int, np.ndarray] = {}

    def _adm(self, j: int) -> np.ndarray:
        if j not in self._cache:
            self._cache[j] = admissible_starts(
                self.valid,
                self.segment,
                exclude=self.exclude,
                # no masks means every step's index is -1 (checked in __init__)
                mask=None if j < 0 or self.masks is None else self.masks[j],
                rule=self.rule,
            )
        return self._cache[j]

    def __call__(self, i: int) -> tuple[np.ndarray, bool]:
        adm = self._adm(int(self.step_mask_index[i]))
        if adm.any():
            return adm, False
        adm = self._adm(-1)
        if not adm.any():
            raise ConfigError("no admissible database window (every window is held out or invalid)")
        return adm, True


def _frames(choices: list[tuple[int, int]], n_frames: int, segment: int) -> np.ndarray:
    out = np.empty((n_frames, 2), np.int64)
    for i, (c, s) in enumerate(choices):
        a, b = i * segment, min((i + 1) * segment, n_frames)
        out[a:b, 0] = c
        out[a:b, 1] = s + np.arange(b - a)
    return out


def _check_n(n_frames: int, segment: int) -> int:
    """Steps of ``segment`` frames that cover ``n_frames`` (checked to be a positive integer)."""
    if not isinstance(n_frames, (int, np.integer)) or n_frames < 1:
        raise ConfigError(f"n_frames must be a positive integer, got {n_frames!r}")
    return -(-int(n_frames) // int(segment))


@checks_arguments
def random_segments(
    valid: np.ndarray, *, n_frames: int, seed: int = 0, **rules: Unpack[WindowRules]
) -> tuple[np.ndarray, np.ndarray]:
    """Random admissible windows, one per step.

    Parameters
    ----------
    valid : array, shape (M, T), bool
    n_frames : int
        Output frames.
    segment : int
        Frames per window.
    seed : int
    **rules
        The :class:`WindowRules` (``exclude``, ``masks``, ``step_mask_index``, ``mask_rule``)
        as for the search: held-out frames (M, T); control masks (n_masks, M, T) and each
        step's index into them (-1: none).

    Returns
    -------
    frames : np.ndarray, shape (n_frames, 2), int64
        (clip, frame) of every output frame.
    relaxed : np.ndarray, shape (n_steps,), bool
    """
    steps = _Steps(valid, n_frames, **rules)
    n_steps, segment = steps.n_steps, steps.segment
    rng = np.random.default_rng(seed)
    T = np.asarray(valid).shape[1]
    choices, relaxed = [], np.zeros(n_steps, bool)
    for i in range(n_steps):
        adm, relaxed[i] = steps(i)
        flat = np.flatnonzero(adm)
        choices.append(divmod(int(flat[rng.integers(flat.size)]), T))
    return _frames(choices, int(n_frames), segment), relaxed


@checks_arguments
def audio_nearest_segments(
    F: np.ndarray, valid: np.ndarray, query: np.ndarray, **rules: Unpack[WindowRules]
) -> tuple[np.ndarray, np.ndarray]:
    """Per step, the admissible window whose audio feature is nearest the query's (cosine distance).

    Parameters
    ----------
    F : array, shape (M, T, A)
        z-scored audio features of the database.
    valid : array, shape (M, T), bool
    query : array, shape (n_frames, A)
        z-scored audio features of the speech (step ``i`` matches ``query[i * segment]``).
    **rules
        The :class:`WindowRules`; see :func:`random_segments`.

    Returns
    -------
    (frames, relaxed)
        As :func:`random_segments` returns them.
    """
    F = np.asarray(F)
    M, T, A = F.shape
    q = np.asarray(query, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != A:
        raise ConfigError(f"query must have shape (frames, {A}), got {q.shape}")
    steps = _Steps(valid, q.shape[0], **rules)
    n_steps, segment = steps.n_steps, steps.segment
    rows = F.reshape(M * T, A)
    Q = q[np.arange(n_steps) * segment]
    qn = np.linalg.norm(Q, axis=1)
    # cosine distances of every database frame to every step's query, chunk by chunk of rows
    dist = np.empty((n_steps, M * T))
    for a in range(0, M * T, 65536):
        r = np.asarray(rows[a : a + 65536], dtype=np.float64)
        rn = np.linalg.norm(r, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            d = 1.0 - (Q @ r.T) / (qn[:, None] * rn[None, :])
        d[(qn[:, None] == 0) | (rn[None, :] == 0)] = 1.0
        dist[:, a : a + r.shape[0]] = d
    choices, relaxed = [], np.zeros(n_steps, bool)
    for i in range(n_steps):
        adm, relaxed[i] = steps(i)
        best = int(np.argmin(np.where(adm.ravel(), dist[i], np.inf)))  # first of equals: lowest index
        choices.append(divmod(best, T))
    return _frames(choices, q.shape[0], segment), relaxed


def _initial_pose(P: np.ndarray, adm: np.ndarray, seed: int) -> np.ndarray:
    """The search's rule: a random admissible frame of step 0, drawn with ``default_rng(seed)``."""
    flat = np.flatnonzero(adm)
    pick = int(flat[int(np.random.default_rng(seed).integers(flat.size))])
    return np.asarray(P.reshape(-1, P.shape[-1])[pick], dtype=np.float32)


@checks_arguments
def pose_nearest_segments(
    P: np.ndarray,
    valid: np.ndarray,
    *,
    n_frames: int,
    seed: int = 0,
    init_pose: np.ndarray | None = None,
    **rules: Unpack[WindowRules],
) -> tuple[np.ndarray, np.ndarray]:
    """Per step, the admissible window whose pose feature is nearest the last output pose feature.

    Candidates at distance exactly 0 (the query's own frame) are skipped, as in Algorithm 1.

    Parameters
    ----------
    P : array, shape (M, T, D)
        z-scored pose features of the database.
    valid : array, shape (M, T), bool
    n_frames : int
    seed : int
        Seed of the random initial pose (when ``init_pose`` is None).
    init_pose : array, shape (D,), optional
        The initial pose feature instead of a random one.
    **rules
        The :class:`WindowRules` (``segment`` ...); see :func:`random_segments`.

    Returns
    -------
    frames : np.ndarray, shape (n_frames, 2), int64
    relaxed : np.ndarray, shape (n_steps,), bool
    """
    P = np.asarray(P)
    M, T, D = P.shape
    steps = _Steps(valid, n_frames, **rules)
    n_steps, segment = steps.n_steps, steps.segment
    rows = P.reshape(M * T, D)
    if init_pose is None:
        init_adm, _ = steps(0)
        p = _initial_pose(P, init_adm, seed)
    else:
        p = np.asarray(init_pose, dtype=np.float32)
        if p.shape != (D,):
            raise ConfigError(f"init_pose must have shape ({D},), got {p.shape}")
    choices, relaxed = [], np.zeros(n_steps, bool)
    for i in range(n_steps):
        adm, relaxed[i] = steps(i)
        flat = np.flatnonzero(adm)
        d2 = np.sum((np.asarray(rows[flat], dtype=np.float64) - p.astype(np.float64)) ** 2, axis=1)
        d2[d2 == 0.0] = np.inf
        if not np.isfinite(d2).any():
            raise ConfigError(f"step {i}: no admissible window other than the query's own frame")
        c, s = divmod(int(flat[int(np.argmin(d2))]), T)
        choices.append((c, s))
        p = np.asarray(P[c, s + segment - 1], dtype=np.float32)
    return _frames(choices, int(n_frames), segment), relaxed


# ---- running a system ---------------------------------------------------------------------------


@checks_arguments
def refiner_unavailable_reason(refiner: MotionRefiner | str | os.PathLike[str] | None) -> str | None:
    """Why ``knn+cgan`` cannot run with this refiner (None: it can), said before any work starts."""
    if refiner is None:
        return (
            "knn+cgan is unavailable: it needs a trained refiner (give --refiner MODEL; train one with "
            "`gesturekit train-refiner`)"
        )
    return None


@checks_arguments
def run_system(
    system: str,
    *,
    db: MatchingDatabase,
    audio: np.ndarray,
    config: SynthesisConfig | None = None,
    control: ControlTrack | str | None = None,
    gt: Motion | None = None,
    refiner: MotionRefiner | str | os.PathLike[str] | None = None,
) -> SystemOutput:
    """Make the motion of one system for one speech.

    Parameters
    ----------
    system : str
        One of :data:`SYSTEMS`.
    db : MatchingDatabase
    audio : np.ndarray, shape (samples,), float32
        The speech at 16 kHz.
    config : SynthesisConfig, optional
        k, N (``segment``), seed, initial pose, mask rule, blending, exclusions (all systems but ``gt``
        use its N, seed, mask rule and exclusions; ``knn`` uses all of it).
    control : ControlTrack or str, optional
        Replaces ``config.control`` (``gt`` ignores controls).
    gt : Motion, optional
        The recorded motion (needed for ``gt``).
    refiner : optional
        A trained refiner or its path (needed for ``knn+cgan``).

    Returns
    -------
    SystemOutput
        Its motion has ``floor(samples * 15 / 16000)`` frames (``gt``: as recorded).

    Raises
    ------
    SystemUnavailable
        ``gt`` without a recording, ``knn+cgan`` without a usable refiner.
    """
    from ..synthesis import SynthesisConfig, synthesize, synthesizer_for

    if system not in SYSTEMS:
        raise ConfigError(f"unknown system {system!r}; known systems: {', '.join(SYSTEMS)}")
    config = config or SynthesisConfig()
    if control is not None:  # the config records the control every system uses
        # SynthesisConfig takes a ControlTrack as it is (its field holds the text); passed as a
        # keyword mapping because the dataclass field's type says str
        change: dict[str, Any] = {"control": control}
        config = replace(config, **change)
    audio = np.asarray(audio, dtype=np.float32)
    N = config.segment
    if system == "gt":
        if gt is None:
            raise SystemUnavailable("gt needs the recorded motion of the speech (a held-out part of the database)")
        return SystemOutput("gt", gt, np.arange(N, gt.n_frames, N, dtype=np.int64))
    if system in ("knn", "knn+cgan"):
        if system == "knn+cgan":
            reason = refiner_unavailable_reason(refiner)
            if reason:
                raise SystemUnavailable(reason)
        from ..refine import open_refiner

        opened = open_refiner(refiner) if system == "knn+cgan" else None
        res = synthesize(audio, db=db, config=config, refiner=opened)
        motion = res.motion
        return SystemOutput(system, motion, np.arange(N, motion.n_frames, N, dtype=np.int64), len(res.relaxed_steps))
    stages = synthesizer_for(db)  # the synthesis's own stages: the search the k-NN is given
    plan = stages.plan(stages.features(audio), config)
    n, options = plan.n_frames, plan.config
    valid = np.asarray(db.valid)
    common = WindowRules(
        segment=N,
        exclude=plan.exclude,
        masks=plan.masks,
        step_mask_index=plan.step_mask_index,
        mask_rule=options.mask_rule,
    )
    if system == "random":
        frames, relaxed = random_segments(valid, n_frames=n, seed=options.seed, **common)
    elif system == "audio-only":
        frames, relaxed = audio_nearest_segments(db.F, valid, plan.query, **common)
    else:  # pose-only, from the rest pose when the plan resolved one
        init = None if options.init_pose == "random" else np.asarray(options.init_pose, dtype=np.float32)
        frames, relaxed = pose_nearest_segments(db.P, valid, n_frames=n, seed=options.seed, init_pose=init, **common)
    g = np.asarray(db.G[frames[:, 0], frames[:, 1]], dtype=np.float32)
    motion = Motion.from_flat(g, db.fps, db.joint_presence)
    return SystemOutput(system, motion, np.arange(N, n, N, dtype=np.int64), int(relaxed.sum()))
