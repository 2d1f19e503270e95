"""The options of a user study's stimuli: :class:`StudyConfig`, what :func:`.stimuli.make_stimuli` takes.

Each field that a user sets is declared with :func:`gesturekit._config.option`, the one
source of its help, bounds and default for ``gesturekit stimuli`` and the app's Study
stimuli page.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from .._config import check_option, option
from ..character.target import WRIST_SLACK, WRIST_SLACK_MAX

if TYPE_CHECKING:
    from distributed import Client

    from ..character.target import Character
    from ..synthesis import MotionRefiner, SynthesisConfig

__all__ = ["StudyConfig", "STUDY_SYSTEMS"]

#: The systems a study shows unless told otherwise.
STUDY_SYSTEMS: tuple[str, ...] = ("gt", "knn", "knn+cgan")


@dataclass(frozen=True)
class StudyConfig:
    """Every option of a study's stimuli (see :func:`gesturekit.study.stimuli.make_stimuli`).

    Parameters
    ----------
    audio : sequence of path
        Speech files or folders of them.
    holdouts : sequence of str
        Held-out parts of the database (``TAKE`` or ``TAKE:START-END``), the speeches with a
        recorded motion for ``gt``.
    systems : str or sequence of str
        Of :data:`gesturekit.evaluate.baselines.SYSTEMS`; ``gt`` needs held-out parts only,
        ``knn+cgan`` a refiner.
    seed : int
        Seed of the ids, the order and (unless ``synthesis`` says otherwise) the synthesis.
    participants : int, optional
        See :func:`gesturekit.study.stimuli.plan_stimuli` (default: the rows of the balanced Latin square).
    control : str
        Control track for every synthesised stimulus (``"0-3:left_hand=high"``), empty for none.
    synthesis : SynthesisConfig, optional
        k, N, seed, initial pose, blending of the synthesis.
    refiner : optional
        A trained refiner or its path, for ``knn+cgan``.
    resolution : (int, int)
        Width and height of every video, pixels (even).
    loudness_lufs : float
        Integrated loudness every soundtrack is scaled to, LUFS.
    workers : int, optional
        Processes rendering in parallel (default: all cores).
    scheduler : str or distributed.Client, optional
        Render on a Dask distributed cluster instead (e.g. ``"tcp://10.0.0.5:8786"``); its workers
        need gesturekit installed.
    character : path or Character, optional
        A user's humanoid (``.glb``, ``.gltf``, ``.vrm`` or ``.bvh``, or one read by
        :func:`gesturekit.character.user.read_character`) every stimulus shows instead of ours: its own
        colours kept, the background, light and fixed camera (one box for every stimulus) as ever.
        ``study.json`` records its file's name and SHA-256 (``character``).
    character_map : path or dict, optional
        Its JSON bone map (see :func:`~gesturekit.character.user.read_character`), with a character file.
    """

    audio: Sequence[str | os.PathLike[str]] = option((), help="speech files or folders of them", nargs="+")
    holdouts: Sequence[Any] = option(
        (),
        help="held-out parts of the database: speeches whose recorded motion is the ground truth (gt)",
        flag="--holdout",
        append=True,
        metavar="TAKE[:START-END]",
    )
    systems: str | Sequence[str] = option(
        STUDY_SYSTEMS,
        help="the systems every speech is shown by",
        kind=str,
        # the app starts with the systems that need neither a held-out part (gt) nor a refiner (knn+cgan)
        start=("knn", "random"),
    )
    seed: int = option(0, help="seed of the ids, the order and the synthesis", low=0)
    participants: int | None = option(
        None,
        help="participants to plan the order for",
        low=1,
        metavar="N",
        kind=int,
        default_help="the rows of the balanced Latin square",
    )
    control: str = option("", help="control track for every synthesised stimulus", kind=str)
    synthesis: SynthesisConfig | None = None
    refiner: MotionRefiner | str | os.PathLike[str] | None = option(
        None, help="trained refiner folder, for knn+cgan", kind=str
    )
    resolution: tuple[int, int] = option((640, 480), help="video size WIDTHxHEIGHT", unit="pixels", metavar="WxH")
    loudness_lufs: float = option(
        -23.0, help="loudness of every soundtrack, LUFS", unit="LUFS", flag="--loudness", metavar="LUFS"
    )
    workers: int | None = option(None, help="rendering processes", low=1, kind=int, default_help="all cores")
    scheduler: str | Client | None = option(
        None, help="render on a Dask distributed cluster (tcp://host:8786)", kind=str, metavar="ADDRESS"
    )
    character: str | os.PathLike[str] | Character | None = option(
        None,
        help="a humanoid (.glb, .gltf, .vrm or .bvh) every stimulus shows, in its own colours",
        kind=str,
        metavar="FILE",
        default_help="ours, grey",
    )
    character_map: str | os.PathLike[str] | dict | None = option(
        None, help="bone map of --character (our joint -> its bone)", kind=str, metavar="JSON"
    )
    wrist_slack: float = option(
        WRIST_SLACK,
        help="how far --character's wrists may stay from our reach, a fraction of its arm's length (0: exactly "
        "where ours reach; more keeps more of our arm directions where its arm's proportions differ)",
        low=0.0,
        high=WRIST_SLACK_MAX,
        unit="of the arm",
        metavar="FRACTION",
        step=0.01,
    )

    def __post_init__(self) -> None:
        for name in ("seed", "participants", "workers", "wrist_slack"):
            object.__setattr__(self, name, check_option(StudyConfig, name, getattr(self, name)))
