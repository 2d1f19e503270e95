"""Speech to gesture motion: the options of a synthesis and the functions that run it.

:func:`synthesize` takes speech (a file or samples) and a matching database and
returns a :class:`SynthesisResult`: the motion, the raw k-NN motion, the search
record (every step's chosen clip and top-K candidates) and the configuration
that made it (:class:`SynthesisConfig`); :mod:`gesturekit.export.result` writes it
as npz, BVH and MP4. :func:`synthesize_batch` searches several speeches together,
scanning the database once per step.

Both run the stages of a :class:`~gesturekit.synthesis.synthesizer.Synthesizer` (features, plan,
search, assemble, refine; :mod:`gesturekit.synthesis.synthesizer`) on the database's shared
search index (:func:`~gesturekit.synthesis.synthesizer.synthesizer_for`). A refiner is given as an
object (:class:`MotionRefiner`); the layers above open one from its folder
(:func:`gesturekit.refine.open_refiner`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from .._arguments import checks_arguments
from ..control import ControlTrack
from ..database import MatchingDatabase
from ..errors import ConfigError
from ..motion import AUDIO_SR
from ..search.plan import rest_pose_frame
from .config import PAPER_SETTINGS, SynthesisConfig
from .synthesizer import (
    SEARCH_DEVICE_ENV,
    Synthesizer,
    check_refiner,
    search_device_default,
    search_request,
    synthesizer_for,
)
from .types import MotionRefiner, QueryFeatures, Speech, SynthesisResult

__all__ = [
    "PAPER_SETTINGS",
    "SynthesisConfig",
    "SynthesisResult",
    "MotionRefiner",
    "QueryFeatures",
    "Speech",
    "Synthesizer",
    "synthesizer_for",
    "search_device_default",
    "SEARCH_DEVICE_ENV",
    "search_request",
    "check_refiner",
    "synthesize",
    "synthesize_batch",
    "prepare_search",
    "rest_pose_frame",
]


@checks_arguments
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
        The database whose index is built (the shared one, :func:`synthesizer_for`); any
        database compiles the same code, one opened from a folder (read-only arrays) the
        code for every folder.
    """
    syn = synthesizer_for(db)
    silence = np.zeros(2 * AUDIO_SR, np.float32)
    syn.run([silence], [SynthesisConfig(record=2, k=1)])
    syn.run([silence], [SynthesisConfig(control="0-2:left_hand=high")])
    syn.run([silence, silence], [SynthesisConfig()] * 2)


@checks_arguments
def synthesize(
    audio: Speech,
    *,
    db: MatchingDatabase,
    config: SynthesisConfig | None = None,
    control: ControlTrack | str | None = None,
    refiner: MotionRefiner | None = None,
    search_device: str | None = None,
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
    search_device : str, optional
        A torch device (``"cuda"``) for the search's scan: the same result, the scan there
        (:mod:`gesturekit.search.device`). Default: ``GESTUREKIT_SEARCH_DEVICE`` if set, else the CPU.

    Returns
    -------
    SynthesisResult
        The output has exactly ``floor(samples * 15 / 16000)`` frames.

    Examples
    --------
    >>> import tempfile
    >>> from gesturekit.demo import build_demo_database
    >>> from gesturekit.datasets.synthetic import generate_demo_take
    >>> from gesturekit.synthesis import SynthesisConfig, synthesize
    >>> db = build_demo_database(tempfile.mkdtemp() + "/demo", minutes=0.5)
    >>> speech = generate_demo_take(seconds=4.0, seed=1, name="speech")[0].audio  # 16 kHz mono
    >>> res = synthesize(speech, db=db, config=SynthesisConfig(seed=0, control="1-3:left_hand=high"))
    >>> res.motion.positions.shape  # 15 frames per second of speech, 55 joints, metres
    (60, 55, 3)
    >>> len(res.steps_table())  # one row per 8-frame search step
    8
    >>> again = synthesize(speech, db=db, config=res.config)  # the same inputs give the same motion
    >>> bool((again.motion.positions == res.motion.positions).all())
    True
    """
    return synthesize_batch(
        [audio], db=db, config=config, controls=[control], refiner=refiner, search_device=search_device
    )[0]


@checks_arguments
def synthesize_batch(
    audios: Iterable[Speech],
    *,
    db: MatchingDatabase,
    config: SynthesisConfig | Sequence[SynthesisConfig] | None = None,
    controls: Sequence[ControlTrack | str | None] | None = None,
    refiner: MotionRefiner | None = None,
    names: Sequence[str] | None = None,
    search_device: str | None = None,
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
    search_device : str, optional
        As in :func:`synthesize`.

    Returns
    -------
    list of SynthesisResult, identical to calling :func:`synthesize` on each.

    Examples
    --------
    >>> import tempfile
    >>> from gesturekit.demo import build_demo_database
    >>> from gesturekit.datasets.synthetic import generate_demo_take
    >>> from gesturekit.synthesis import synthesize, synthesize_batch
    >>> db = build_demo_database(tempfile.mkdtemp() + "/demo", minutes=0.5)
    >>> speeches = [generate_demo_take(seconds=s, seed=s, name="speech")[0].audio for s in (2, 3)]
    >>> results = synthesize_batch(speeches, db=db, controls=[None, "0-2:speed=slow"])
    >>> [r.motion.positions.shape for r in results]
    [(30, 55, 3), (45, 55, 3)]
    >>> one = synthesize(speeches[1], db=db, control="0-2:speed=slow")
    >>> bool((one.motion.positions == results[1].motion.positions).all())
    True
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
    if len({(c.exclude_takes, c.exclude_ranges) for c in configs}) > 1:
        raise ConfigError("all speeches of one batch must exclude the same database takes and ranges")
    syn = synthesizer_for(db, refiner=refiner, search_device=search_device)
    # a given control replaces the config's: the config a result records is the one searched
    configs = [c if ctl is None else c.with_control(ctl) for c, ctl in zip(configs, controls)]
    return syn.run(audios, configs, names=names)
