"""A tiny study folder for the tests of ``gesturekit.studies``: 2 speeches x 3 systems.

``study_stimuli`` (session scope) is what ``gesturekit stimuli`` writes (videos, manifest.csv,
order.csv, study.json) for two short speeches (1.2 and 1.6 s) rendered at 160x120 by the systems
knn, random and audio-only on a 2-minute demo database; a test that writes into a study (``study
init``, responses) takes its own copy with :func:`copy_study` (or the ``study_folder`` fixture).
Import the fixtures into a test module: ``from tests.study_helpers import study_folder, study_stimuli``.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import soundfile as sf

#: The systems of the test study (none needs held-out parts or a refiner).
SYSTEMS = ("knn", "random", "audio-only")
#: The speeches' lengths in seconds (whole frames at 15 fps): short videos, quick to watch to the end.
SPEECH_S = (1.2, 1.6)
RESOLUTION = (160, 120)
SEED = 7


def make_study(folder: Path, home: Path) -> Path:
    """Write the test study into ``folder`` (a demo database is built in ``home`` first); returns ``folder``."""
    from gesturekit.database import MatchingDatabase
    from gesturekit.datasets.synthetic import generate_demo_take
    from gesturekit.demo import build_demo_database
    from gesturekit.study import make_stimuli

    db_path = home / "db"
    build_demo_database(db_path, minutes=2.0)
    speech = home / "speech"
    speech.mkdir(parents=True, exist_ok=True)
    for i, seconds in enumerate(SPEECH_S):
        take, _ = generate_demo_take(seconds=2.0, seed=60 + i, name=f"s{i}")
        sf.write(speech / f"speech_{i}.wav", take.audio[: int(seconds * 16000)], 16000)
    make_stimuli(
        MatchingDatabase.load(db_path),
        out=folder,
        audio=[speech],
        systems=list(SYSTEMS),
        seed=SEED,
        resolution=RESOLUTION,
        workers=1,
    )
    return folder


def copy_study(source: Path, target: Path) -> Path:
    """A copy of the study folder ``source`` at ``target`` (which must not exist); returns ``target``."""
    shutil.copytree(source, target)
    return target


@pytest.fixture(scope="session")
def study_stimuli(tmp_path_factory) -> Path:
    """The test study as ``gesturekit stimuli`` left it (shared by the session's tests: do not write into it)."""
    root = tmp_path_factory.mktemp("study-stimuli")
    return make_study(root / "study", root / "home")


@pytest.fixture
def study_folder(study_stimuli, tmp_path) -> Path:
    """The test's own copy of :func:`study_stimuli`, free to write into."""
    return copy_study(study_stimuli, tmp_path / "study")
