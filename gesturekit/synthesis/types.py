"""What passes between the synthesis stages: the speech's features, the result, the refiner.

:class:`QueryFeatures` is what the first stage computes from the speech, once: the
k-NN search's query and the refiner's cGAN audio features. :class:`SynthesisResult`
is what the last stages assemble and refine. :class:`MotionRefiner` is what the
synthesis needs of a refiner (:class:`gesturekit.refine.infer.Refiner` is one).
The stages themselves are :class:`gesturekit.synthesis.synthesizer.Synthesizer`'s methods;
every name here is also importable from :mod:`gesturekit.synthesis`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, TypeAlias, runtime_checkable

import numpy as np

from .._arguments import checks_arguments
from .._version import __version__
from ..control import ControlTrack
from ..errors import ConfigError, GestureKitError
from ..motion import AUDIO_SR, HoldsMotion, Motion
from ..search import SearchResult
from ..search.plan import SearchPlan
from ..search.types import window_source

if TYPE_CHECKING:  # named in annotations only
    import pandas as pd

    from ..database import MatchingDatabase
    from .config import SynthesisConfig

__all__ = ["Speech", "QueryFeatures", "MotionRefiner", "SynthesisResult", "load_speech"]

#: Speech: a file in any format the readers take, or mono float32 samples at 16 kHz.
Speech: TypeAlias = "str | os.PathLike[str] | np.ndarray"


@dataclass(frozen=True, eq=False)
class QueryFeatures:
    """A speech and its features, computed once (:meth:`Synthesizer.features
    <gesturekit.synthesis.synthesizer.Synthesizer.features>`).

    Attributes
    ----------
    samples : np.ndarray, shape (samples,), float32
        The speech, mono at 16 kHz.
    query : np.ndarray, shape (T_out, 112), float32
        The k-NN search's query: the stacked audio features ``f_t``, z-scored with the
        database's statistics, one row per output frame (15 fps).
    audio : np.ndarray, shape (T_out, 28), float32
        The refiner's cGAN audio features (``m_t`` and its time derivative), not z-scored.
    source : str
        What the result calls the speech: its file name, or ``"audio"`` for samples.
    name : str or None
        What warnings call the speech (its file name, a given name, or None).
    """

    samples: np.ndarray
    query: np.ndarray
    audio: np.ndarray
    source: str
    name: str | None = None

    @property
    def n_frames(self) -> int:
        """Output frames, ``T_out = floor(samples * 15 / 16000)``."""
        return int(self.query.shape[0])

    @property
    def seconds(self) -> float:
        """The speech's length in seconds."""
        return len(self.samples) / AUDIO_SR


@checks_arguments
def load_speech(audio: Speech) -> tuple[np.ndarray, str]:
    """Speech as mono float32 samples at 16 kHz, and what a result calls it.

    Parameters
    ----------
    audio : path or np.ndarray, shape (samples,)
        A speech file in any format the readers take, or mono samples at 16 kHz.

    Returns
    -------
    samples : np.ndarray, shape (samples,), float32
    source : str
        The file's name, or ``"audio"`` for samples.

    Raises
    ------
    ConfigError
        Samples that are not mono, or speech shorter than one frame (1/15 s).
    """
    if isinstance(audio, (str, os.PathLike)):
        from ..datasets.audio import load_audio

        return load_audio(audio), Path(audio).name
    a = np.asarray(audio, dtype=np.float32)
    if a.ndim != 1:
        raise ConfigError(f"speech samples must be mono, shape (samples,), got {a.shape}")
    if len(a) < AUDIO_SR // 15:
        raise ConfigError("speech is shorter than one frame (1/15 s)")
    return a, "audio"


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
