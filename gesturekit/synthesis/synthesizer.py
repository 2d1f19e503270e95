"""The synthesis in stages: :class:`Synthesizer`, one database's index, z-scoring and refiner.

Each stage is a public method, and :meth:`Synthesizer.run` runs them all:

1. :meth:`~Synthesizer.features`: the speech's k-NN query and the refiner's cGAN audio
   features, computed once (:class:`~gesturekit.synthesis.types.QueryFeatures`);
2. :meth:`~Synthesizer.plan`: what the search is given (:class:`~gesturekit.search.plan.SearchPlan`);
3. :meth:`~Synthesizer.search`: Algorithm 1 for several plans, one scan of the database per step
   (:meth:`SearchIndex.search_plans <gesturekit.search.index.SearchIndex.search_plans>`);
4. :meth:`~Synthesizer.assemble`: the k-NN motion, the blended motion, the result;
5. :meth:`~Synthesizer.refine`: the refiner applied to the k-NN motion.

:func:`gesturekit.synthesis.synthesize` and :func:`~gesturekit.synthesis.synthesize_batch`
run the stages on the database's shared index (:func:`synthesizer_for`);
:class:`gesturekit.live.LiveSynthesizer`, the baselines and the retrieval inspector drive the
same stages. Every public name here is also importable from :mod:`gesturekit.synthesis`.
"""

from __future__ import annotations

import os
import threading
import weakref
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._arguments import checks_arguments
from ..blend import blend_segments, keep_slow
from ..control import ControlTrack
from ..database import MatchingDatabase
from ..errors import ConfigError, warn
from ..features import audio_frame_features, cgan_audio_features, n_audio_frames, stack_audio_features
from ..motion import Motion
from ..search import SearchIndex, SearchResult
from ..search.plan import SearchPlan, SearchRequest, plan_search
from .types import MotionRefiner, QueryFeatures, Speech, SynthesisResult, load_speech

if TYPE_CHECKING:
    from ..features import ZScore
    from .config import SynthesisConfig

__all__ = [
    "Synthesizer",
    "synthesizer_for",
    "search_request",
    "check_refiner",
    "search_device_default",
    "SEARCH_DEVICE_ENV",
]


@checks_arguments
def search_request(config: SynthesisConfig) -> SearchRequest:
    """The search-level part of a synthesis configuration: what :func:`plan_search` is given.

    Parameters
    ----------
    config : SynthesisConfig

    Returns
    -------
    SearchRequest
        Its search options, initial pose, control track and exclusions.

    Raises
    ------
    ConfigError
        ``config`` is not a synthesis configuration.
    """
    if not all(hasattr(config, name) for name in ("search", "init", "control_track", "exclude_takes")):
        raise ConfigError(f"config must be a SynthesisConfig, got {type(config).__name__}")
    return SearchRequest(
        search=config.search,
        init=config.init,
        control=config.control_track,
        exclude_takes=config.exclude_takes,
        exclude_ranges=config.exclude_ranges,
    )


@checks_arguments
def check_refiner(refiner: object, db: MatchingDatabase) -> dict | None:
    """Refuse what is no refiner, or one of another feature layout than ``db``.

    Returns
    -------
    dict or None
        What a result records of the refiner (its ``provenance(db)``, when it has one).

    Raises
    ------
    ConfigError
        ``refiner`` is not a :class:`MotionRefiner`.
    GestureKitError
        Its features do not suit ``db`` (its ``check_database``).
    """
    if not isinstance(refiner, MotionRefiner):
        raise ConfigError(
            f"refiner must be a loaded refiner, got {type(refiner).__name__} (open a refiner folder with "
            "gesturekit.refine.open_refiner)"
        )
    refiner.check_database(db)
    describe = getattr(refiner, "provenance", None)
    return describe(db) if callable(describe) else None


class _IndexSlot:
    """A database's search index, built on first use; shared by the Synthesizers of one database
    that ask for it (:meth:`Synthesizer.with_refiner`, :func:`synthesizer_for`). It holds the
    index's arrays, never the database itself, so a cache of slots keeps no database alive."""

    def __init__(self, device: str | None = None) -> None:
        self.index: SearchIndex | None = None
        self.device = device
        self.lock = threading.Lock()


class Synthesizer:
    """The synthesis of speech on one database, stage by stage.

    Owns the database's search index (built on first use and kept), its z-scoring of the
    speech's audio features and an optional refiner. :meth:`run` runs every stage; each stage
    is also a method of its own: :meth:`features`, :meth:`plan`, :meth:`search`,
    :meth:`assemble`, :meth:`refine`.

    Parameters
    ----------
    db : MatchingDatabase
        The database searched; the Synthesizer keeps nothing in it.
    refiner : MotionRefiner, optional
        Applied by :meth:`refine` (and :meth:`run`); checked against ``db`` here.
    search_device : str, optional
        A torch device (``"cuda"``) for the search's scan (:mod:`gesturekit.search.device`): the
        same results, the scan there. Default: :func:`search_device_default`, the CPU unless the
        environment variable ``GESTUREKIT_SEARCH_DEVICE`` names one.

    Raises
    ------
    ConfigError
        ``db`` is no database, or ``refiner`` is no refiner; (on first use of the index) the
        search device is unknown or absent.
    GestureKitError
        The refiner's feature layout does not suit ``db``.

    Examples
    --------
    The stages one by one give what :func:`~gesturekit.synthesis.synthesize` gives::

        syn = Synthesizer(db)
        feats = syn.features(speech)
        plan = syn.plan(feats, config)
        (found,) = syn.search([plan])
        result = syn.assemble(feats, plan, found, config)
    """

    def __init__(
        self, db: MatchingDatabase, *, refiner: MotionRefiner | None = None, search_device: str | None = None
    ) -> None:
        self._setup(db, refiner, _IndexSlot(_chosen_device(search_device)))

    def _setup(self, db: MatchingDatabase, refiner: MotionRefiner | None, slot: _IndexSlot) -> None:
        if not isinstance(db, MatchingDatabase):
            raise ConfigError(f"db must be a MatchingDatabase, got {type(db).__name__}")
        self._record = None if refiner is None else check_refiner(refiner, db)
        self._db, self._refiner, self._slot = db, refiner, slot
        self._zscore = db.zscore("F")

    @classmethod
    def _sharing(cls, db: MatchingDatabase, refiner: MotionRefiner | None, slot: _IndexSlot) -> Synthesizer:
        out = cls.__new__(cls)
        out._setup(db, refiner, slot)
        return out

    def with_refiner(self, refiner: MotionRefiner | None) -> Synthesizer:
        """A Synthesizer of the same database with another refiner (None: none), sharing this one's index."""
        return Synthesizer._sharing(self._db, refiner, self._slot)

    # -- what it holds ----------------------------------------------------------------------

    @property
    def db(self) -> MatchingDatabase:
        """The database searched."""
        return self._db

    @property
    def refiner(self) -> MotionRefiner | None:
        """The refiner :meth:`refine` applies, or None."""
        return self._refiner

    @property
    def refiner_record(self) -> dict | None:
        """What a result records of the refiner (:attr:`SynthesisResult.refiner`); None without one."""
        return self._record

    @property
    def index(self) -> SearchIndex:
        """The database's search index, built on first use (seconds on a large database) and kept."""
        with self._slot.lock:
            if self._slot.index is None:
                db = self._db
                self._slot.index = SearchIndex(db.P, db.F, db.valid, device=self._slot.device)
            return self._slot.index

    @property
    def zscore(self) -> ZScore:
        """The z-scoring of the stacked audio features ``f_t`` (112 values) with the database's statistics."""
        return self._zscore

    @property
    def database_label(self) -> str:
        """What a result calls the database: its folder, else its label, else ``"in-memory database"``."""
        db = self._db
        return str(db.path) if db.path is not None else (db.label or "in-memory database")

    @property
    def one_skeleton(self) -> bool:
        """Whether the database gives every take one skeleton (:attr:`SynthesisResult.one_skeleton`)."""
        return self._db.meta.get("skeleton") is not None

    # -- the stages -------------------------------------------------------------------------

    def features(self, speech: Speech, *, name: str | None = None) -> QueryFeatures:
        """Stage 1: the speech's features, both the search's and the refiner's, computed once.

        Parameters
        ----------
        speech : path or np.ndarray, shape (samples,)
            A speech file in any format the readers take, or mono float32 samples at 16 kHz.
        name : str, optional
            What warnings call the speech (default: its file name; nothing for samples).

        Returns
        -------
        QueryFeatures
            ``query`` (T_out, 112) float32 z-scored and ``audio`` (T_out, 28) float32, with
            ``T_out = floor(samples * 15 / 16000)``.

        Raises
        ------
        ConfigError
            Samples that are not mono, or speech shorter than one frame (1/15 s).
        """
        samples, source = load_speech(speech)
        if name is None and isinstance(speech, (str, os.PathLike)):
            name = Path(speech).name
        m = audio_frame_features(samples, n_frames=n_audio_frames(len(samples)))
        query = np.ascontiguousarray(self._zscore.apply(stack_audio_features(m)), dtype=np.float32)
        return QueryFeatures(samples=samples, query=query, audio=cgan_audio_features(m), source=source, name=name)

    def plan(self, features: QueryFeatures, config: SynthesisConfig) -> SearchPlan:
        """Stage 2: what the search of one speech is given (:func:`~gesturekit.search.plan.plan_search`).

        Parameters
        ----------
        features : QueryFeatures
            From :meth:`features`.
        config : SynthesisConfig
            Its search options, initial pose, control track and exclusions are used.

        Returns
        -------
        SearchPlan
            The query, control masks, exclusions and search options (initial pose resolved).
        """
        return plan_search(self._db, features.query, search_request(config))

    def search(self, plans: Sequence[SearchPlan]) -> list[SearchResult]:
        """Stage 3: Algorithm 1 for each plan, one scan of the database per step serving all.

        Parameters
        ----------
        plans : sequence of SearchPlan
            From :meth:`plan`; all must exclude the same database frames.

        Returns
        -------
        list of SearchResult
            One per plan, identical to searching each alone.
        """
        return self.index.search_plans(plans, fps=self._db.fps)

    def assemble(
        self, features: QueryFeatures, plan: SearchPlan, found: SearchResult, config: SynthesisConfig
    ) -> SynthesisResult:
        """Stage 4: the chosen database frames as motion, blended as ``config`` asks, and the result.

        Parameters
        ----------
        features : QueryFeatures
            The speech searched (its samples and name are kept in the result).
        plan : SearchPlan
            What the search was given (kept in the result for the inspector).
        found : SearchResult
            The search's choices; ``found.frames`` (T_out, 2) are (clip, frame) indices.
        config : SynthesisConfig
            The configuration recorded; its ``blend`` and ``blend_frames`` are applied.

        Returns
        -------
        SynthesisResult
            ``knn_motion`` the concatenated windows and ``motion`` the blended one,
            (T_out, 55, 3) metres at the database's frame rate.
        """
        db = self._db
        g = np.asarray(db.G[found.frames[:, 0], found.frames[:, 1]], dtype=np.float32)  # (T, 165)
        boundaries = np.arange(1, found.n_steps) * config.segment
        blended = blend_segments(
            g, boundaries, mode=config.blend, frames=config.blend_frames, halflife=config.blend_halflife * db.fps
        )
        motion = Motion.from_flat(blended, db.fps, db.joint_presence)
        if config.blend != "none":
            motion = self.keep_bones(motion, Motion.from_flat(g, db.fps, db.joint_presence))
        return SynthesisResult(
            motion=motion,
            knn_motion=Motion.from_flat(g, db.fps, db.joint_presence),
            search=found,
            audio=features.samples,
            config=config,
            database=self.database_label,
            source=features.source,
            plan=plan,
            one_skeleton=self.one_skeleton,
        )

    @staticmethod
    def keep_bones(motion: Motion, knn: Motion) -> Motion:
        """Blended motion with the k-NN motion's bones again.

        Blending moves each joint by its own offset, which changes the bones' lengths a little;
        a BVH or glTF file (one length per bone) then no longer holds the motion exactly. This
        places every joint back at its parent plus the bone's length in the same frame of the
        k-NN motion along its blended direction, and each rigid group (finger roots on the wrist,
        neck and collars on the chest) in its k-NN shape (:func:`gesturekit.bones.bones_like`):
        clips a BVH file holds (a database with one skeleton, :attr:`one_skeleton`, or one take)
        give blended motion it holds too.

        Parameters
        ----------
        motion : Motion
            Blended motion, (T, 55, 3) metres.
        knn : Motion
            The k-NN motion it was blended from, (T, 55, 3) metres.

        Returns
        -------
        Motion
            The same frames with the bones' lengths and rigid shapes of the k-NN motion.
        """
        from ..bones import bones_like

        if motion.n_frames == 0:
            return motion
        return Motion(bones_like(motion.positions, knn.positions).astype(np.float32), motion.fps, motion.joints)

    def refine(self, result: SynthesisResult, features: QueryFeatures) -> SynthesisResult:
        """Stage 5: the refiner applied to the k-NN motion; it becomes the result's output.

        Parameters
        ----------
        result : SynthesisResult
            From :meth:`assemble`; changed in place (``refined_motion``, ``motion``, ``refiner``).
        features : QueryFeatures
            The same speech's features (their cGAN audio features are the refiner's input).

        Returns
        -------
        SynthesisResult
            ``result`` itself.

        Raises
        ------
        ConfigError
            This Synthesizer has no refiner, or the features are not of the result's length.
        """
        if features.n_frames != result.n_frames:
            raise ConfigError(f"features of {features.n_frames} frames do not fit a result of {result.n_frames}")
        result.refined_motion = self.refine_motion(
            result.knn_motion, features.audio, keep_hz=result.config.refiner_keep_hz
        )
        result.motion = result.refined_motion
        result.refiner = self._record
        return result

    def refine_motion(self, knn: Motion, audio_features: np.ndarray, *, keep_hz: float) -> Motion:
        """The refiner's output for k-NN motion, keeping the k-NN motion's content below ``keep_hz``.

        Parameters
        ----------
        knn : Motion
            k-NN motion, (T, 55, 3) metres.
        audio_features : np.ndarray, shape (T, 28), float32
            The speech's cGAN audio features over the same frames (:attr:`QueryFeatures.audio`).
        keep_hz : float
            Hz; the k-NN motion's content slower than this is kept (:func:`gesturekit.blend.keep_slow`)
            and so are its bones (:meth:`keep_bones`); 0: the refiner's output as it is.

        Returns
        -------
        Motion
            (T, 55, 3) metres.
        """
        if self._refiner is None:
            raise ConfigError("this Synthesizer has no refiner (give one: Synthesizer(db, refiner=...))")
        refined = self._refiner.refine_motion(knn, audio_features)
        if keep_hz <= 0:
            return refined  # the paper: the generator's output as it is
        kept = keep_slow(refined.flat(), knn.flat(), keep_hz, fps=knn.fps)
        refined = Motion.from_flat(kept, refined.fps, knn.joints)
        # the generator's positions stretch the bones (by centimetres at the fingers): the k-NN
        # motion's bones again, so that a BVH or glTF file holds the refined motion
        return self.keep_bones(refined, knn)

    # -- every stage ------------------------------------------------------------------------

    def run(
        self,
        speeches: Sequence[Speech],
        configs: Sequence[SynthesisConfig],
        *,
        names: Sequence[str | None] | None = None,
    ) -> list[SynthesisResult]:
        """Every stage for several speeches, searched together (one scan of the database per step).

        Parameters
        ----------
        speeches : sequence of path or np.ndarray, shape (samples,)
            Speech files, or mono float32 samples at 16 kHz.
        configs : sequence of SynthesisConfig
            One per speech, all with the same exclusions.
        names : sequence of str or None, optional
            What warnings call each speech (default: its file name; nothing for samples).

        Returns
        -------
        list of SynthesisResult
            One per speech, refined when this Synthesizer has a refiner; identical to running
            each speech alone.
        """
        speeches, configs = list(speeches), list(configs)
        named = list(names) if names is not None else [None] * len(speeches)
        if not len(speeches) == len(configs) == len(named):
            raise ConfigError("give one config (and one name, if any) per speech")
        feats = [self.features(s, name=n) for s, n in zip(speeches, named)]
        for f, c in zip(feats, configs):
            _warn_controls_past_the_end(c.control_track, f)
        plans = [self.plan(f, c) for f, c in zip(feats, configs)]
        found = self.search(plans)
        out = [self.assemble(f, p, r, c) for f, p, r, c in zip(feats, plans, found, configs)]
        if self._refiner is not None:
            for res, f in zip(out, feats):
                self.refine(res, f)
        return out


def _warn_controls_past_the_end(track: ControlTrack, features: QueryFeatures) -> None:
    """Warn of control segments that begin after the speech ends: the search never reaches them."""
    for seg in track.segments:
        if seg.start_s >= features.seconds:
            speech = f"{features.name}: " if features.name else ""
            warn(
                f"{speech}control segment {seg.start_s:g}-{seg.end_s:g} s starts after the speech ends "
                f"({features.seconds:.1f} s); it is ignored"
            )


#: Each database's search index, shared by :func:`~gesturekit.synthesis.synthesize`, its batch
#: and the live synthesis (:func:`synthesizer_for`): built on the first call, kept while the
#: database lives (a weak reference: the cache keeps no database alive, and it holds only
#: the index, never the database).
_SHARED_INDEX: weakref.WeakKeyDictionary[MatchingDatabase, dict[str | None, _IndexSlot]] = weakref.WeakKeyDictionary()
_SHARED_LOCK = threading.Lock()

#: The environment variable naming the torch device of every search whose device is not given.
SEARCH_DEVICE_ENV = "GESTUREKIT_SEARCH_DEVICE"


def search_device_default() -> str | None:
    """The search device of a synthesis that names none: ``GESTUREKIT_SEARCH_DEVICE`` if set
    (``cuda``, ``cuda:1``, ...; empty or ``cpu``: the CPU's own search), else None (the CPU's)."""
    return check_search_device(os.environ.get(SEARCH_DEVICE_ENV) or None)


def check_search_device(device: str | None) -> str | None:
    """``device`` as a search keeps it: None (the CPU's own 8-bit search) for None, ``""`` or ``"cpu"``.

    Raises
    ------
    ConfigError
        ``device`` is not a string.
    """
    if device is None:
        return None
    if not isinstance(device, str):
        raise ConfigError(f"search device must be a torch device name such as 'cuda', got {device!r}")
    name = device.strip()
    return None if name in ("", "cpu") else name


def _chosen_device(given: str | None) -> str | None:
    """The device a search given ``given`` runs on: the default where None is given."""
    return search_device_default() if given is None else check_search_device(given)


def open_search_device(given: str | None) -> str | None:
    """The device a synthesis given ``given`` scans on (None: the CPU's own search), checked now:
    a command says an absent device before any work.

    Raises
    ------
    ConfigError
        The device is unknown or absent (see :func:`gesturekit.search.device.open_device`).
    MissingDependencyError
        A device is named and torch is not installed.
    """
    device = _chosen_device(given)
    if device is not None:
        from ..search.device import open_device  # torch loads only then

        open_device(device)
    return device


@checks_arguments
def synthesizer_for(
    db: MatchingDatabase, *, refiner: MotionRefiner | None = None, search_device: str | None = None
) -> Synthesizer:
    """A Synthesizer of ``db`` that shares the database's cached search index.

    Parameters
    ----------
    db : MatchingDatabase
    refiner : MotionRefiner, optional
    search_device : str, optional
        A torch device (``"cuda"``) for the search's scan; default :func:`search_device_default`.
        Each device has an index of its own.

    Returns
    -------
    Synthesizer
        A new object each call; the index it builds on first use serves every later call with
        the same database and device (:func:`~gesturekit.synthesis.synthesize` uses it), until the
        database is dropped.
    """
    if not isinstance(db, MatchingDatabase):
        raise ConfigError(f"db must be a MatchingDatabase, got {type(db).__name__}")
    device = _chosen_device(search_device)
    with _SHARED_LOCK:
        slots = _SHARED_INDEX.get(db)
        if slots is None:
            slots = _SHARED_INDEX[db] = {}
        slot = slots.get(device)
        if slot is None:
            slot = slots[device] = _IndexSlot(device)
    return Synthesizer._sharing(db, refiner, slot)
