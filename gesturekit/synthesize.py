"""The whole pipeline in one place: speech -> features -> search (controls) -> blend -> motion.

:func:`synthesize` takes speech (a file or samples) and a matching database and
returns a :class:`SynthesisResult`: the motion, the raw k-NN motion, the search
record (every step's chosen clip and top-K candidates) and the configuration
that made it; :mod:`gesturekit.export.result` writes it as npz, BVH and MP4.
:func:`synthesize_batch` searches several speeches together, scanning the
database once per step. A refiner is given as an object (:class:`MotionRefiner`);
the layers above open one from its folder (:func:`gesturekit.refine.open_refiner`).
"""

from __future__ import annotations

import numbers
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, TypeAlias, runtime_checkable

import numpy as np

from ._config import config_from_dict, config_to_dict
from ._version import __version__
from .blend import BLEND_MODES, KEEP_BELOW_HZ, blend_segments, keep_slow
from .control import ControlTrack, parse_control
from .database import MatchingDatabase, normalise_exclusions
from .errors import ConfigError, GestureKitError, warn
from .motion import AUDIO_SR, HoldsMotion, Motion
from .search import SearchConfig, SearchIndex, SearchResult
from .search.plan import SearchPlan, plan_search, rest_pose_frame
from .search.types import RENAMED_SEARCH_KEYS, renamed_search_keys, window_source

if TYPE_CHECKING:  # named in annotations only: the refiner sits above the synthesis
    import pandas as pd


#: Speech: a file in any format the readers take, or mono float32 samples at 16 kHz.
Speech: TypeAlias = "str | os.PathLike[str] | np.ndarray"

__all__ = [
    "PAPER_SETTINGS",
    "SynthesisConfig",
    "SynthesisResult",
    "MotionRefiner",
    "synthesize",
    "synthesize_batch",
    "prepare_search",
    "rest_pose_frame",
]

#: The settings of Habibie et al. 2022: option -> (the paper's value, how a value is written,
#: the paper's value as written after it). ``refiner_keep_hz`` counts only when a refiner is
#: applied (the paper uses the refiner's output as it is).
PAPER_SETTINGS = {
    "k": (0, "k = {}", "0"),
    "segment": (8, "N = {}", "8"),
    "init": ("random", "initial pose: {}", "random"),
    "blend": ("none", "blending: {}", "none"),
    "mask_rule": ("ends", "control held at: {}", "ends"),
    "refiner_keep_hz": (0.0, "k-NN motion kept below {:g} Hz", "0: the refiner's output as it is"),
}


#: The options of :class:`SynthesisConfig` that belong to its search (:class:`SearchConfig`);
#: the saved form lists them beside the others, as it always has.
SEARCH_OPTIONS = ("k", "segment", "record", "seed", "mask_rule", "pins")


@dataclass(frozen=True, init=False)
class SynthesisConfig:
    """Every option of a synthesis; saved with every output.

    The search's options live in ``search`` (a :class:`SearchConfig`) and are read
    through it; ``k``, ``segment``, ``record``, ``seed``, ``mask_rule`` and ``pins`` are
    accepted as keywords (and by :func:`dataclasses.replace`) and read as attributes,
    both passing through to ``search``.

    Parameters
    ----------
    search : SearchConfig, optional
        k, N (``segment``), recorded candidates (``record``), seed, mask rule and pins.
        Its ``init_pose`` must be ``"random"``: the initial pose is chosen by ``init``.
    init : {"random", "rest"}
        ``random``: a random database frame that satisfies the first step's control
        (the authors' choice); ``rest``: the database's rest pose (see :func:`rest_pose_frame`).
    blend : {"none", "offset"}
        ``none`` is the paper (the refiner smooths); ``offset`` fades each join over ``blend_frames``.
    blend_frames : int
    control : str or ControlTrack
        The control track, e.g. ``"0-3:left_hand=low,3-6:speed=slow"`` (seconds); kept as its
        text, and parsed once (:attr:`control_track`).
    exclude_takes : tuple of str
        Database takes the search must not use (e.g. the query's own take).
    exclude_ranges : tuple of (str, float, float)
        (take, start_s, end_s) stretches the search must not use.
    refiner_keep_hz : float
        With a refiner: keep the k-NN motion's content slower than this (Hz) and take
        the faster content from the refiner (see :func:`gesturekit.blend.keep_slow`),
        so controls of hand height, width and symmetry survive refinement; 0: the
        refiner's output as it is (the paper).
    k, segment, record, seed, mask_rule, pins
        The options of ``search`` (see :class:`SearchConfig`); given, they replace its values.
    """

    search: SearchConfig = field(default_factory=SearchConfig)
    init: str = "random"
    blend: str = "none"
    blend_frames: int = 4
    control: str = ""
    exclude_takes: tuple = ()
    exclude_ranges: tuple = ()
    refiner_keep_hz: float = KEEP_BELOW_HZ
    if TYPE_CHECKING:  # set by __init__: the control parsed once (not an option of its own)
        _track: ControlTrack = field(init=False, repr=False, compare=False)

    def __init__(
        self,
        search: SearchConfig | None = None,
        *,
        init: str = "random",
        blend: str = "none",
        blend_frames: int = 4,
        control: str | ControlTrack = "",
        exclude_takes: Sequence[str] = (),
        exclude_ranges: Sequence[tuple[str, float, float]] = (),
        refiner_keep_hz: float = KEEP_BELOW_HZ,
        **search_options: Any,
    ) -> None:
        unknown = set(search_options) - set(SEARCH_OPTIONS)
        if unknown:
            raise ConfigError(f"unknown synthesis options: {', '.join(sorted(unknown))}")
        search = SearchConfig() if search is None else search
        if not isinstance(search, SearchConfig):
            raise ConfigError(f"search must be a SearchConfig, got {type(search).__name__}")
        if search_options:
            search = replace(search, **search_options)
        if search.init_pose != "random":
            raise ConfigError(
                "the initial pose of a synthesis is chosen by init ('random' or 'rest'), not by search.init_pose"
            )
        hz = refiner_keep_hz
        if isinstance(hz, bool) or not isinstance(hz, numbers.Real) or not (np.isfinite(hz) and hz >= 0):
            raise ConfigError(f"refiner_keep_hz must be a frequency >= 0 (0: off), got {hz!r}")
        if init not in ("random", "rest"):
            raise ConfigError(f"init must be 'random' or 'rest', got {init!r}")
        if blend not in BLEND_MODES:
            raise ConfigError(f"blend must be one of {', '.join(BLEND_MODES)}, got {blend!r}")
        if not isinstance(blend_frames, int) or blend_frames < 1:
            raise ConfigError(f"blend_frames must be a positive integer, got {blend_frames!r}")
        track = control if isinstance(control, ControlTrack) else parse_control(control)  # validates
        takes, ranges = normalise_exclusions(exclude_takes, exclude_ranges)
        for name, value in (
            ("search", search),
            ("init", init),
            ("blend", blend),
            ("blend_frames", blend_frames),
            ("control", track.to_text()),
            ("exclude_takes", takes),
            ("exclude_ranges", ranges),
            ("refiner_keep_hz", float(hz)),
            ("_track", track),
        ):
            object.__setattr__(self, name, value)

    # the search's options, read through ``search`` (one source of truth)
    k = property(lambda self: self.search.k, doc="Take the k-th best of the combined ranking (0 = best).")
    segment = property(lambda self: self.search.segment, doc="Frames per search step, N (8 in the paper).")
    record = property(lambda self: self.search.record, doc="Candidates per step recorded for inspection.")
    seed = property(lambda self: self.search.seed, doc="Seed of the random initial pose.")
    mask_rule = property(lambda self: self.search.mask_rule, doc="Where a control must hold in a window.")
    pins = property(lambda self: self.search.pins, doc="Step -> (clip, start): forced choices.")

    @property
    def control_track(self) -> ControlTrack:
        """The control track, parsed once when the configuration was made."""
        return self._track

    def to_dict(self) -> dict:
        """A JSON-able dict, the search's options beside the others (the layout of every
        version's saved form); :meth:`from_dict` reads it back."""
        search = self.search.to_dict()
        out = {name: search[name] for name in ("k", "segment", "record", "seed")}
        out["init"] = self.init
        out["mask_rule"] = search["mask_rule"]
        out.update(config_to_dict(self, exclude=("search", "init", "refiner_keep_hz")))
        out["pins"] = search["pins"]
        out["refiner_keep_hz"] = self.refiner_keep_hz
        return out

    @classmethod
    def from_dict(cls, d: Mapping) -> SynthesisConfig:
        """Inverse of :meth:`to_dict`; also reads a nested ``"search"`` object, and the names
        earlier versions saved N and the recorded candidates under (``step``, ``topk``).

        Raises
        ------
        ConfigError
            Unknown options.
        """
        if not isinstance(d, Mapping):
            raise ConfigError(f"synthesis options must be a JSON object, got {type(d).__name__}")
        d = dict(d)
        search = dict(d.pop("search", None) or {})
        # earlier versions' flat "step" and "topk" belong to the search too ("init" is ours)
        flat = [*SEARCH_OPTIONS, *(old for old in RENAMED_SEARCH_KEYS if old != "init")]
        search.update({name: d.pop(name) for name in flat if name in d})
        search = renamed_search_keys(search)
        d["search"] = SearchConfig.from_dict(search)
        return config_from_dict(cls, d, what="synthesis options")

    def paper_differences(self, *, refined: bool) -> list[str]:
        """The settings that differ from the paper's (:data:`PAPER_SETTINGS`), as text.

        Parameters
        ----------
        refined : bool
            Whether a refiner is applied (``refiner_keep_hz`` counts only then).

        Returns
        -------
        list of str
            E.g. ``["N = 6 (paper 8)"]``; empty when the search is the paper's.
        """
        out = []
        for name, (paper, form, paper_text) in PAPER_SETTINGS.items():
            value = getattr(self, name)
            if value != paper and (refined or name != "refiner_keep_hz"):
                out.append(f"{form.format(value)} (paper {paper_text})")
        return out

    def with_control(self, control: str | ControlTrack) -> SynthesisConfig:
        """A copy with another control track (its text, or the track itself)."""
        options: dict[str, Any] = {f.name: getattr(self, f.name) for f in fields(self)}
        options["control"] = control
        return SynthesisConfig(**options)

    def with_pin(self, step: int, clip: int, start: int) -> SynthesisConfig:
        """A copy with one more pinned choice (replacing any pin at that step)."""
        pins = dict(self.pins)
        pins[int(step)] = (int(clip), int(start))
        return replace(self, search=replace(self.search, pins=pins))

    def without_pin(self, step: int) -> SynthesisConfig:
        """A copy without the pinned choice at ``step`` (if any)."""
        pins = {i: v for i, v in self.pins.items() if i != int(step)}
        return replace(self, search=replace(self.search, pins=pins))


@runtime_checkable
class MotionRefiner(Protocol):
    """What synthesis needs of a refiner; :class:`gesturekit.refine.infer.Refiner` is one.

    A refiner may also have ``provenance(db) -> dict | None``: what the result records of it
    (:attr:`SynthesisResult.refiner`).
    """

    def check_database(self, db: MatchingDatabase, /) -> None:
        """Raise a :class:`~gesturekit.errors.GestureKitError` when ``db``'s features do not suit it."""

    def refine_motion(self, motion: Motion, audio_features: np.ndarray, /) -> Motion:
        """The refined ``motion`` (T, 55, 3), given the speech's cGAN audio features (T, 28)."""


@dataclass
class SynthesisResult(HoldsMotion):
    """A synthesised motion and everything that made it.

    Attributes
    ----------
    motion : Motion
        The output (k-NN segments, blended if asked), (T, 55, 3) metres at 15 fps.
    knn_motion : Motion
        The concatenated k-NN segments before any blending.
    search : SearchResult
        Per step: chosen clip and start, relaxations, and the top-K candidate table.
    audio : np.ndarray, shape (samples,), float32
        The speech at 16 kHz.
    config : SynthesisConfig
        The options it was made with, its control track included (:attr:`control`).
    database : str
        Path of the database (or its label when it was not saved).
    source : str
        Name of the speech (file name, or "audio").
    refined_motion : Motion or None
        The refiner's output, when a refiner was applied.
    refiner : dict or None
        Which refiner was applied (:func:`gesturekit.refine.provenance`: its folder, its
        training database, the sha256 of its weights); None without one, or for a refiner
        not loaded from a folder.
    plan : SearchPlan or None
        What the search was given (query features, control masks, exclusions, search
        options); the retrieval inspector reads it instead of recomputing it.
    one_skeleton : bool
        The database gives every take one skeleton (built with ``--normalize-bones``): its
        clips' bones have one length each, so only blending and refining change them.
    """

    motion: Motion
    knn_motion: Motion
    search: SearchResult
    audio: np.ndarray
    config: SynthesisConfig
    database: str
    source: str
    refined_motion: Motion | None = None
    refiner: dict | None = None
    plan: SearchPlan | None = None
    one_skeleton: bool = False

    @property
    def control(self) -> ControlTrack:
        """The control track the search used (``config.control``, parsed)."""
        return self.config.control_track

    @property
    def relaxed_steps(self) -> list[int]:
        """Steps whose control admitted no window and was dropped for that step."""
        return np.flatnonzero(self.search.relaxed).tolist()

    def steps_table(self) -> pd.DataFrame:
        """One row per step: frames, chosen clip and start, position in the ranking, relaxed, pinned."""
        import pandas as pd

        s = self.search
        n = s.n_steps
        N = self.config.segment
        return pd.DataFrame(
            {
                "step": np.arange(n),
                "first_frame": np.arange(n) * N,
                "start_s": np.arange(n) * N / self.motion.fps,
                "clip": s.clip,
                "start": s.start,
                "position": s.position,
                "candidates": s.n_candidates,
                "relaxed": s.relaxed,
                "pinned": s.pinned,
            }
        )

    def steps_overview(self, db: MatchingDatabase) -> pd.DataFrame:
        """:meth:`steps_table` with each chosen window's source take and time (``take``, ``source_s``).

        Parameters
        ----------
        db : MatchingDatabase
            The database the result was searched in.
        """
        table = self.steps_table()
        src = [window_source(db, c, s) for c, s in zip(self.search.clip, self.search.start)]
        table.insert(5, "take", [t for t, _ in src])
        table.insert(6, "source_s", [s for _, s in src])
        return table

    def metadata(self) -> dict:
        """The JSON saved with every export: how this result was made."""
        return {
            "gesturekit_version": __version__,
            "database": self.database,
            "source": self.source,
            "fps": self.motion.fps,
            "frames": self.n_frames,
            "duration_s": self.n_frames / self.motion.fps,
            "synthesis": self.config.to_dict(),
            "control_segments": self.control.to_records(),
            "relaxed_steps": self.relaxed_steps,
            "init_frame": list(self.search.init_frame),
            "refined": self.refined_motion is not None,
            "refiner": self.refiner,
        }

    def check_finite(self, path: str | os.PathLike[str] | None = None) -> None:
        """Refuse to write a result with NaN or infinite positions, naming where they came from.

        Raises
        ------
        GestureKitError
            The k-NN motion (read from the database) or the refiner's output is not finite.
        """
        parts = [("the k-NN motion (poses read from the database; the database may be damaged)", self.knn_motion)]
        if self.refined_motion is not None:
            parts.append(("the refiner", self.refined_motion))
        for who, motion in parts:
            bad = ~np.isfinite(motion.positions).all(axis=(1, 2))
            if bad.any():
                verb = "produced" if who == "the refiner" else "holds"
                raise GestureKitError(
                    f"not written: {who} {verb} NaN or infinite positions (from frame {int(np.argmax(bad))} on)",
                    path=path,
                )


def _index(db: MatchingDatabase) -> SearchIndex:
    idx = db.__dict__.get("_search_index")
    if idx is None:
        idx = SearchIndex(db.P, db.F, db.valid)
        db.__dict__["_search_index"] = idx
    return idx


def prepare_search(db: MatchingDatabase) -> None:
    """Make the search of ``db`` ready: its index built, its compiled code loaded.

    The search's compiled loops come from the on-disk cache
    (:mod:`gesturekit.search.compile_cache`) or, on the first run after an install or an
    update, are compiled into it: tens of seconds, once. A server calls this before it
    answers, so that a user's first result comes as fast as the later ones. Two seconds
    of silence are searched as a single query with the inspector's candidates recorded,
    under a control, and as a batch of two: every path the search takes.

    Parameters
    ----------
    db : MatchingDatabase
        The database whose index is built; any database compiles the same code, one
        opened from a folder (read-only arrays) the code for every folder.
    """
    silence = np.zeros(2 * AUDIO_SR, np.float32)
    synthesize(silence, db=db, config=SynthesisConfig(record=2, k=1))
    synthesize(silence, db=db, config=SynthesisConfig(control="0-2:left_hand=high"))
    synthesize_batch([silence, silence], db=db)


def _load_speech(audio: Speech) -> tuple[np.ndarray, str]:
    if isinstance(audio, (str, os.PathLike)):
        from .datasets.audio import load_audio

        return load_audio(audio), Path(audio).name
    a = np.asarray(audio, dtype=np.float32)
    if a.ndim != 1:
        raise ConfigError(f"speech samples must be mono, shape (samples,), got {a.shape}")
    if len(a) < AUDIO_SR // 15:
        raise ConfigError("speech is shorter than one frame (1/15 s)")
    return a, "audio"


def _finish(
    db: MatchingDatabase, res: SearchResult, plan: SearchPlan, samples: np.ndarray, name: str, config: SynthesisConfig
) -> SynthesisResult:
    G = db.G
    g = np.asarray(G[res.frames[:, 0], res.frames[:, 1]], dtype=np.float32)  # (T, 165)
    knn = Motion.from_flat(g, db.fps, db.joint_presence)
    boundaries = np.arange(1, res.n_steps) * config.segment
    out = Motion.from_flat(
        blend_segments(g, boundaries, mode=config.blend, frames=config.blend_frames), db.fps, db.joint_presence
    )
    return SynthesisResult(
        motion=out,
        knn_motion=knn,
        search=res,
        audio=samples,
        config=config,
        database=str(db.path) if db.path is not None else (db.label or "in-memory database"),
        source=name,
        plan=plan,
        one_skeleton=db.meta.get("skeleton") is not None,
    )


def synthesize(
    audio: Speech,
    *,
    db: MatchingDatabase,
    config: SynthesisConfig | None = None,
    control: ControlTrack | str | None = None,
    refiner: MotionRefiner | None = None,
) -> SynthesisResult:
    """Synthesise gesture motion for speech.

    Parameters
    ----------
    audio : path or np.ndarray, shape (samples,)
        A speech file in any format the readers take, or mono float32 samples at 16 kHz.
    db : MatchingDatabase
    config : SynthesisConfig, optional
    control : ControlTrack or str, optional
        Replaces ``config.control``; the result's config records it.
    refiner : MotionRefiner, optional
        A trained refiner (:class:`gesturekit.refine.infer.Refiner`; open a folder, or
        ``"demo"`` for the one shipped with the demo database, with
        :func:`gesturekit.refine.open_refiner`). It refines the k-NN motion with the
        speech's cGAN audio features; the result is ``refined_motion`` and also ``motion``.

    Returns
    -------
    SynthesisResult
        The output has exactly ``floor(samples * 15 / 16000)`` frames.
    """
    return synthesize_batch([audio], db=db, config=config, controls=[control], refiner=refiner)[0]


def synthesize_batch(
    audios: Iterable[Speech],
    *,
    db: MatchingDatabase,
    config: SynthesisConfig | Sequence[SynthesisConfig] | None = None,
    controls: Sequence[ControlTrack | str | None] | None = None,
    refiner: MotionRefiner | None = None,
    names: Sequence[str] | None = None,
) -> list[SynthesisResult]:
    """Synthesise several speeches together: one scan of the database per step serves all.

    Parameters
    ----------
    audios : sequence of path or np.ndarray
    config : SynthesisConfig or one per speech
        Exclusions must be the same for all speeches in one batch.
    controls : sequence of ControlTrack, str or None, optional
        Per speech, replaces its config's ``control``; the result's config records it.
    refiner : MotionRefiner, optional
        As in :func:`synthesize`, applied to every speech.
    names : sequence of str, optional
        What warnings call each speech (default: its file name; nothing for an array).

    Returns
    -------
    list of SynthesisResult, identical to calling :func:`synthesize` on each.
    """
    audios = list(audios)
    if not audios:
        return []
    configs: list[SynthesisConfig]
    if config is None or isinstance(config, SynthesisConfig):
        configs = [config or SynthesisConfig()] * len(audios)
    else:
        configs = list(config)
    controls = list(controls) if controls is not None else [None] * len(audios)
    if len(configs) != len(audios) or len(controls) != len(audios):
        raise ConfigError("give one config and one control per speech (or one config for all)")
    excl = {(c.exclude_takes, c.exclude_ranges) for c in configs}
    if len(excl) > 1:
        raise ConfigError("all speeches of one batch must exclude the same database takes and ranges")
    made_by = None if refiner is None else _check_refiner(refiner, db)
    # a given control replaces the config's: the config a result records is the one searched
    configs = [c if ctl is None else c.with_control(ctl) for c, ctl in zip(configs, controls)]
    speeches = [_load_speech(a) for a in audios]
    shown = (
        list(names)
        if names is not None
        else [Path(a).name if isinstance(a, (str, os.PathLike)) else None for a in audios]
    )
    for (samples, _), c, name in zip(speeches, configs, shown):
        _warn_controls_past_the_end(c.control_track, len(samples) / AUDIO_SR, name)
    plans = [plan_search(db, samples, c) for (samples, _), c in zip(speeches, configs)]
    # masks differ per speech; the search shares one mask stack, so stack them with offsets
    stack: list[np.ndarray] = []
    step_idx: list[np.ndarray] = []
    for plan in plans:
        index = plan.step_mask_index.copy()
        if plan.masks is not None:
            index[index >= 0] += len(stack)
            stack.extend(list(plan.masks))
        step_idx.append(index)
    results = _index(db).search_batch(
        [plan.query for plan in plans],
        configs=[plan.config for plan in plans],
        masks=np.stack(stack) if stack else None,
        step_mask_indices=step_idx,
        exclude=plans[0].exclude,
        fps=db.fps,
    )
    out = [
        _finish(db, r, plan, samples, name, c) for r, plan, (samples, name), c in zip(results, plans, speeches, configs)
    ]
    if refiner is not None:
        for res in out:
            _refine(db, res, refiner)
            res.refiner = made_by
    return out


def _warn_controls_past_the_end(track: ControlTrack, seconds: float, name: str | None) -> None:
    """Warn of control segments that begin after the speech ends: the search never reaches them."""
    for seg in track.segments:
        if seg.start_s >= seconds:
            speech = f"{name}: " if name else ""
            warn(
                f"{speech}control segment {seg.start_s:g}-{seg.end_s:g} s starts after the speech ends "
                f"({seconds:.1f} s); it is ignored"
            )


def _check_refiner(refiner: object, db: MatchingDatabase) -> dict | None:
    """Refuse what is no refiner or one of another feature layout than ``db``; what the result
    records of it (its ``provenance(db)``, when it has one)."""
    if not isinstance(refiner, MotionRefiner):
        raise ConfigError(
            f"refiner must be a loaded refiner, got {type(refiner).__name__} (open a refiner folder with "
            "gesturekit.refine.open_refiner)"
        )
    refiner.check_database(db)
    describe = getattr(refiner, "provenance", None)
    return describe(db) if callable(describe) else None


def _refine(db: MatchingDatabase, res: SynthesisResult, refiner: MotionRefiner) -> None:
    """Refine the k-NN motion with the speech's cGAN audio features (keeping its content below
    ``refiner_keep_hz``); it becomes the output."""
    _, a = db.query_features(res.audio, n_frames=res.n_frames)
    refined = refiner.refine_motion(res.knn_motion, a)
    hz = res.config.refiner_keep_hz
    if hz > 0:
        kept = keep_slow(refined.flat(), res.knn_motion.flat(), hz, fps=res.knn_motion.fps)
        refined = Motion.from_flat(kept, refined.fps, res.knn_motion.joints)
    res.refined_motion = refined
    res.motion = res.refined_motion
