"""A tiny study folder shared by the study tests: 2 speeches x 3 systems, 160x120, 2 s each."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import soundfile as sf

from gesturekit.database import MatchingDatabase
from gesturekit.datasets.synthetic import generate_demo_take
from gesturekit.demo import build_demo_database
from gesturekit.study import make_stimuli

STUDY_SYSTEMS = ("knn", "random", "audio-only")


def make_tiny_study(root: Path, *, seed: int = 5) -> Path:
    """Write a stimuli folder under ``root`` (``root/study``) and return its path."""
    db_path, speech = root / "db", root / "speech"
    build_demo_database(db_path, minutes=1.0)
    speech.mkdir()
    for i in range(2):
        take, _ = generate_demo_take(seconds=2.0, seed=70 + i, name=f"s{i}")
        sf.write(speech / f"speech_{i}.wav", take.audio[:32000], 16000)
    make_stimuli(
        MatchingDatabase.load(db_path),
        out=root / "study",
        audio=[speech],
        systems=",".join(STUDY_SYSTEMS),
        resolution=(160, 120),
        seed=seed,
        workers=1,
    )
    return root / "study"


@pytest.fixture(scope="session")
def tiny_study(tmp_path_factory) -> Path:
    """A read-only stimuli folder (copy it before writing into it)."""
    return make_tiny_study(tmp_path_factory.mktemp("tiny-study"))


def copy_study(source: Path, target: Path) -> Path:
    """A copy of the study folder ``source`` at ``target`` (which must not exist); returns ``target``."""
    shutil.copytree(source, target)
    return target


@pytest.fixture
def study_folder(tiny_study, tmp_path) -> Path:
    """The test's own copy of :func:`tiny_study`, free to write into (import both fixtures)."""
    return copy_study(tiny_study, tmp_path / "study")
