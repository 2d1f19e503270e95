"""The embedded default: a matching database of the generated demo speaker."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ._arguments import checks_arguments
from .database import BuildConfig, MatchingDatabase
from .errors import DatabaseError
from .paths import default_database_path

if TYPE_CHECKING:
    from .bones import Skeleton

__all__ = ["DEMO_MINUTES", "DEMO_SEED", "build_demo_database", "open_default_database"]

DEMO_MINUTES = 20.0
DEMO_SEED = 0
DEMO_TAKE_SECONDS = 120.0


@checks_arguments
def build_demo_database(
    out: str | os.PathLike | None = None,
    *,
    minutes: float = DEMO_MINUTES,
    seed: int = DEMO_SEED,
    overwrite: bool = False,
    progress: Callable[[float, float], None] | None = None,
) -> MatchingDatabase:
    """Generate the demo speaker and build its database (deterministic, no download).

    Parameters
    ----------
    out : path, optional
        Folder to write; default :func:`gesturekit.paths.default_database_path`.
    minutes : float
        Minutes of generated speech and motion.
    progress : callable(done, total), optional
        Progress in seconds of generated material, then of processed takes.

    Examples
    --------
    >>> import tempfile
    >>> from gesturekit.demo import build_demo_database
    >>> db = build_demo_database(tempfile.mkdtemp() + "/demo", minutes=0.5)
    >>> db.poses.shape  # clips, frames per clip, 55 joints x 3
    (7, 64, 165)
    >>> db.path.name
    'demo'
    """
    from .outputs import check_output, output_lock

    out = Path(out) if out is not None else default_database_path()
    check_output(out, "database", overwrite=overwrite)  # before minutes of generating
    with output_lock(out):
        return _build_demo(out, minutes=minutes, seed=seed, overwrite=overwrite, progress=progress)


def _build_demo(
    out: Path, *, minutes: float, seed: int, overwrite: bool, progress: Callable[[float, float], None] | None
) -> MatchingDatabase:
    from .datasets.synthetic import DEMO_LABEL, generate_demo_takes

    total = minutes * 60.0

    def gen_progress(done, tot):
        if progress is not None:
            progress(0.5 * done / tot * total, total)

    takes = generate_demo_takes(minutes=minutes, take_seconds=DEMO_TAKE_SECONDS, seed=seed, progress=gen_progress)

    def build_progress(i, name):
        if progress is not None:
            progress(total * (0.5 + 0.5 * i / len(takes)), total)

    db = MatchingDatabase.build(
        [_on_skeleton(t, skeleton) for t in takes] if (skeleton := _demo_skeleton(takes)) else takes,
        config=BuildConfig(overlap_stride=8, label=DEMO_LABEL, source=f"demo (seed {seed}, {minutes:g} min)"),
        progress=build_progress,
        skeleton=skeleton,
    )
    db.save(out, overwrite=overwrite, locked=True)
    return db


def _demo_skeleton(takes: list) -> Skeleton | None:
    """The demo speaker's one skeleton (its bones are those of one rest skeleton in every frame), fitted
    over every take as ``build-db --normalize-bones`` fits one, so the database says it holds one skeleton
    and its BVH and glTF files are exact."""
    from .bones import bone_samples, fit_skeleton

    if not takes:
        return None
    return fit_skeleton([bone_samples(t.motion.positions) for t in takes], takes=len(takes))


def _on_skeleton(take, skeleton: Skeleton):
    """``take`` with its positions placed on ``skeleton`` (a change of float rounding for the demo speaker)."""
    from dataclasses import replace

    from .bones import normalise_bone_lengths
    from .motion import Motion

    pos, _ = normalise_bone_lengths(take.motion.positions, take.motion.joints, skeleton=skeleton)
    return replace(take, motion=Motion(pos.astype(np.float32), take.motion.fps, take.motion.joints))


@checks_arguments
def open_default_database(
    *,
    build_if_missing: bool = True,
    minutes: float = DEMO_MINUTES,
    progress: Callable[[float, float], None] | None = None,
) -> MatchingDatabase:
    """Open the demo database at the default path, building it first if it is not there.

    Parameters
    ----------
    minutes : float
        Minutes of demo speaker to generate if it has to be built.

    Examples
    --------
    The default path is under ``GESTUREKIT_HOME`` (``~/.cache/gesturekit`` unless set); here a
    temporary one, with a small database:

    >>> import os, tempfile
    >>> from gesturekit.demo import open_default_database
    >>> os.environ["GESTUREKIT_HOME"] = tempfile.mkdtemp()
    >>> db = open_default_database(minutes=0.5)  # built on the first call, opened on the next
    >>> open_default_database().poses.shape == db.poses.shape
    True
    """
    path = default_database_path()
    if not (path / "database.json").exists():
        if not build_if_missing:
            raise DatabaseError("the demo database has not been built yet (`gesturekit build-db --demo`)", path=path)
        build_demo_database(path, minutes=minutes, overwrite=path.exists(), progress=progress)
    return MatchingDatabase.load(path)
