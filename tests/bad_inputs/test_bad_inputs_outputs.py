"""Bad-input suite, outputs: --force never replaces what gesturekit did not write, outputs never overlap inputs.

Each case runs one command as a user would and asserts a clean refusal (exit 2,
the path named, the problem said, no traceback) that left every file as it was.
"""

import json
from pathlib import Path

import pytest
import soundfile as sf

from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.outputs import output_lock
from tests.badinput import assert_refused, run_cli, snapshot
from tests.conftest import make_take


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> Path:
    """A database, a folder of takes, a speech folder, someone's thesis, a note, a refiner and a study folder."""
    root = tmp_path_factory.mktemp("outputs")
    MatchingDatabase.build(
        [make_take(9.0, seed=1, name="a"), make_take(5.0, seed=2, name="b")],
        config=BuildConfig(overlap_stride=16, store_audio=False),
    ).save(root / "db")
    takes = root / "corpus" / "takes"
    takes.mkdir(parents=True)
    for name in ("a", "b"):
        take = make_take(3.0, seed=3, name=name)
        sf.write(takes / f"{name}.wav", take.audio, 16000, subtype="PCM_16")
        (takes / f"{name}.bvh").write_text("HIERARCHY\n")  # never read: the refusal comes first
    speech = root / "speech"
    speech.mkdir()
    sf.write(speech / "hello.wav", make_take(2.0, seed=4).audio, 16000, subtype="PCM_16")
    thesis = root / "thesis"
    (thesis / "figures").mkdir(parents=True)
    for name in ("main.tex", "refs.bib", "figures/plot.pdf"):
        (thesis / name).write_text("years of work")
    (root / "notes.txt").write_text("do not lose")
    (root / "refiner").mkdir()
    (root / "refiner" / "config.json").write_text(json.dumps({"format": "gesturekit-refiner", "format_version": 1}))
    (root / "study").mkdir()
    (root / "study" / "study.json").write_text(json.dumps({"format": "gesturekit-study"}))
    out = root / "results"
    out.mkdir()
    (out / "hello.npz").write_bytes(b"PK\x05\x06" + b"\0" * 18)  # an empty zip: not gesturekit's
    (out / "hello.bvh").mkdir()
    return root


# name: (args, the path the message must name, words of the problem, roots that must not change)
def _cases(w: Path) -> dict:
    db, takes, thesis, notes = w / "db", w / "corpus" / "takes", w / "thesis", w / "notes.txt"
    speech, res = w / "speech" / "hello.wav", w / "results"
    build = ["build-db", takes, "--preset", "zeggs"]
    train = ["train-refiner", "--db", db, "--preset", "quick", "--device", "cpu"]
    synth = ["synthesize", speech, "--db", db]
    stim = ["stimuli", "--db", db, "--audio", w / "speech", "--systems", "knn", "--workers", "1"]
    return {
        "build-db --force on a foreign folder": (
            build + ["--out", thesis, "--force"],
            thesis,
            "holds 3 files and 1 folder that gesturekit did not write",
            [thesis, takes],
        ),
        "build-db --force on a plain file": (
            build + ["--out", notes, "--force"],
            notes,
            "is a file, not a folder",
            [notes, takes],
        ),
        "build-db --out the takes folder --force": (
            build + ["--out", takes, "--force"],
            takes,
            "is an input of this command",
            [takes],
        ),
        "build-db --out a folder containing the takes": (
            build + ["--out", w / "corpus", "--force"],
            w / "corpus",
            "contains the input",
            [w / "corpus"],
        ),
        "build-db --out inside the takes folder": (
            build + ["--out", takes / "db"],
            takes / "db",
            "lies inside the input",
            [takes],
        ),
        "build-db onto a database without --force": (build + ["--out", db], db, "already exists", [db, takes]),
        "build-db --force onto a refiner folder": (
            build + ["--out", w / "refiner", "--force"],
            w / "refiner",
            "holds a refiner folder, not a matching database",
            [w / "refiner"],
        ),
        "build-db --demo --force on a foreign folder": (
            ["build-db", "--demo", "--minutes", "0.1", "--out", thesis, "--force"],
            thesis,
            "did not write",
            [thesis],
        ),
        "train-refiner --out the database --force": (
            train + ["--out", db, "--force"],
            db,
            "is an input of this command",
            [db],
        ),
        "train-refiner --out inside the database": (
            train + ["--out", db / "refiner", "--force"],
            db / "refiner",
            "lies inside the input",
            [db],
        ),
        "train-refiner --out a folder containing the database": (
            train + ["--out", w, "--force"],
            w,
            "contains the input",
            [db, thesis, notes],
        ),
        "train-refiner --force on a foreign folder": (
            train + ["--out", thesis, "--force"],
            thesis,
            "did not write",
            [thesis, db],
        ),
        "train-refiner --force on a plain file": (
            train + ["--out", notes, "--force"],
            notes,
            "is a file, not a folder",
            [notes, db],
        ),
        "train-refiner --resume onto the database": (
            train + ["--out", db, "--resume"],
            db,
            "is an input of this command",
            [db],
        ),
        "synthesize --out is a file": (synth + ["--out", notes], notes, "is a file, not a folder", [notes]),
        "synthesize output file exists without --force": (
            synth + ["--out", res],
            res / "hello.npz",
            "add --force",
            [res],
        ),
        "synthesize --force on an npz gesturekit did not write": (
            synth + ["--out", res, "--force"],
            res / "hello.npz",
            "is a file that gesturekit did not write",
            [res],
        ),
        "train-fgd --out the database --force": (
            ["train-fgd", "--db", db, "--out", db, "--force"],
            db,
            "is an input of this command",
            [db],
        ),
        "train-fgd --force on a foreign folder": (
            ["train-fgd", "--db", db, "--out", thesis, "--force"],
            thesis,
            "did not write",
            [thesis],
        ),
        "evaluate --force on a foreign folder": (
            ["evaluate", "--db", db, "--holdout", "a", "--out", thesis, "--force"],
            thesis,
            "did not write",
            [thesis],
        ),
        "evaluate --out inside the database": (
            ["evaluate", "--db", db, "--holdout", "a", "--out", db / "eval"],
            db / "eval",
            "lies inside the input",
            [db],
        ),
        "stimuli --force on a foreign folder": (stim + ["--out", thesis, "--force"], thesis, "did not write", [thesis]),
        "stimuli --out the speech folder": (
            stim + ["--out", w / "speech", "--force"],
            w / "speech",
            "is an input of this command",
            [w / "speech"],
        ),
        "stimuli --out the database": (stim + ["--out", db, "--force"], db, "is an input of this command", [db]),
        "stimuli --out is a file": (stim + ["--out", notes], notes, "is a file, not a folder", [notes]),
        "stimuli onto a study without --force": (
            stim + ["--out", w / "study"],
            w / "study",
            "already exists",
            [w / "study"],
        ),
        "stimuli --force onto a refiner folder": (
            stim + ["--out", w / "refiner", "--force"],
            w / "refiner",
            "holds a refiner folder, not a study folder",
            [w / "refiner"],
        ),
    }


CASES = sorted(_cases(Path("/")))


@pytest.mark.parametrize("case", CASES)
def test_outputs_refused(world, case):
    args, names, problem, roots = _cases(world)[case]
    before = snapshot(*roots)
    assert_refused(run_cli(*args), names=names, problem=problem, before=before)


def test_a_locked_output_is_refused_naming_the_writer(world):
    out = world / "locked-db"
    with output_lock(out):
        before = snapshot(out)
        run = run_cli("build-db", world / "corpus" / "takes", "--preset", "zeggs", "--out", out)
        assert_refused(run, names=out, problem="another gesturekit process (pid", before=before)


@pytest.mark.slow
def test_synthesize_refuses_files_another_run_is_writing(world, tmp_path):
    out = tmp_path / "out"
    args = ["synthesize", world / "speech" / "hello.wav", "--db", world / "db", "--out", out, "--refiner", "none"]
    with output_lock(out / "hello.npz"):  # another run is writing it
        before = snapshot(out)
        assert_refused(
            run_cli(*args), names=out / "hello.npz", problem="another gesturekit process (pid", before=before
        )
    # once the other run is done, the same command writes both files, and no lock file stays behind
    run = run_cli(*args)
    assert run.code == 0, run.stderr
    assert {p.name for p in out.iterdir()} == {"hello.npz", "hello.bvh"}
