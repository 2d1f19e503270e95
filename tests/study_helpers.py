"""A tiny study folder shared by the study tests: 2 speeches x 3 systems, 160x120, 2 s each."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import soundfile as sf

from gesturekit.database import MatchingDatabase
from gesturekit.datasets.synthetic import generate_demo_take
from gesturekit.demo import build_demo_database
from gesturekit.study.stimuli import make_stimuli

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


#: What an attentive participant gives each system of :data:`STUDY_SYSTEMS` (every prompt, 1..7).
QUALITY = {"knn": 6, "audio-only": 4, "random": 2}


def take_part(store, design, *, attentive: bool = True, pages: int | None = None, pid: str | None = None) -> str:
    """One participant answers the study through ``store`` as the server would keep it; returns the token.

    Ratings are :data:`QUALITY` of each stimulus's system, a pairwise choice clearly for the better one;
    an attentive participant passes every check, an inattentive one rates the check videos 7 (failing
    them; the beeps counted right). ``pages``: stop after that many pages (a participant still active).
    """
    import pandas as pd

    from gesturekit.study.design import check_answer, participant_pages

    systems = dict(pd.read_csv(design.folder / "manifest.csv", dtype=str)[["id", "system"]].values)
    person, _ = store.start(design.participants, prolific_pid=pid)
    todo = [p for p in participant_pages(design, person.row) if p.kind != "done"]
    for page in todo[:pages]:
        check = page.check or {}
        if page.kind == "audio_check":
            answers = {"count": check["expect"]["count"]["min"]}
        elif page.kind == "rating":
            answers = {}
            for m in page.media:
                if m.id != check.get("media"):
                    answers[m.id] = {p: QUALITY[systems[m.id]] for p, _ in design.prompts}
                else:
                    spans = check["expect"]
                    answers[m.id] = {p: (spans[p]["min"] if p in spans and attentive else 7) for p, _ in design.prompts}
        elif page.kind == "pairwise":
            left, right = (QUALITY[systems[m.id]] for m in page.media)
            answers = {"choice": -2 if left > right else 2}
        elif page.kind == "questionnaire":
            answers = {"age": 30}
        else:
            answers = {}
        ok = check_answer(page, answers)
        got = store.submit(
            person.token,
            page.id,
            page.index,
            page.kind,
            answers,
            [{"t": 1.0, "kind": "ended", "media": m.id, "at": 1.0} for m in page.media],
            2.0,
            failed_check=ok is False,
            max_failures=design.max_failures,
            last=page is todo[-1],
        )
        assert got.outcome == "stored", got
        if got.status != "active":
            break
    return person.token
