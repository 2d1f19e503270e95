"""Bad-input suite, files and processes: planted lock links, long names, FIFOs, devices, deep JSON, zip bombs.

Each case runs one command as a user would and asserts a clean refusal (exit 2,
the file named, the problem said, no traceback) that left every file as it was.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import soundfile as sf

from gesturekit.database import BuildConfig, MatchingDatabase

from .badinput import assert_refused, run_cli, snapshot
from .conftest import make_take


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> Path:
    """A small database, a folder of takes (never read), speech and someone's thesis."""
    root = tmp_path_factory.mktemp("files")
    MatchingDatabase.build(
        [make_take(9.0, seed=1, name="a"), make_take(5.0, seed=2, name="b")],
        config=BuildConfig(overlap_stride=16, store_audio=False),
    ).save(root / "db")
    takes = root / "takes"
    takes.mkdir()
    for name in ("a", "b"):
        sf.write(takes / f"{name}.wav", make_take(3.0, seed=3).audio, 16000, subtype="PCM_16")
        (takes / f"{name}.bvh").write_text("HIERARCHY\n")
    sf.write(root / "speech.wav", make_take(3.0, seed=4).audio, 16000, subtype="PCM_16")
    (root / "thesis.txt").write_text("years of work\n" * 60)
    return root


# ----------------------------------------------------------------------------- locks


def _lock_commands(w: Path, out: Path) -> dict[str, tuple[list, Path]]:
    """command -> (its arguments, the output whose lock it takes)."""
    return {
        "synthesize": (
            ["synthesize", w / "speech.wav", "--db", w / "db", "--out", out, "--refiner", "none"],
            out / "speech.npz",
        ),
        "build-db": (["build-db", w / "takes", "--preset", "zeggs", "--out", out / "db2"], out / "db2"),
        "train-refiner": (
            ["train-refiner", "--db", w / "db", "--preset", "quick", "--device", "cpu", "--out", out / "ref"],
            out / "ref",
        ),
    }


@pytest.mark.parametrize("command", ["synthesize", "build-db", "train-refiner"])
@pytest.mark.parametrize("plant", ["symlink", "hardlink"])
def test_a_planted_lock_link_never_touches_its_target(world, tmp_path, command, plant):
    out = tmp_path / "out"
    out.mkdir()
    args, target = _lock_commands(world, out)[command]
    lock = target.parent / f".{target.name}.lock"
    thesis = world / "thesis.txt"
    if plant == "symlink":
        lock.symlink_to(thesis)
    else:
        os.link(thesis, lock)
    before = snapshot(thesis, out)
    assert_refused(run_cli(*args), names=lock, problem="not a lock file gesturekit made", before=before)


def test_a_lock_that_is_a_folder_is_refused(world, tmp_path):
    out = tmp_path / "out"
    args, target = _lock_commands(world, out)["synthesize"]
    (out / f".{target.name}.lock").mkdir(parents=True)
    before = snapshot(out)
    assert_refused(run_cli(*args), names=out / ".speech.npz.lock", problem="not a lock file", before=before)


def test_a_stale_lock_of_a_dead_writer_is_no_obstacle(world, tmp_path):
    out = tmp_path / "out"
    args, target = _lock_commands(world, out)["synthesize"]
    out.mkdir()
    (out / ".speech.npz.lock").write_text("999999")
    run = run_cli(*args)
    assert run.code == 0, run.stderr
    assert {p.name for p in out.iterdir()} == {"speech.npz", "speech.bvh"}


@pytest.mark.parametrize("command", ["synthesize", "build-db", "train-refiner"])
def test_a_250_character_output_name_is_written(world, tmp_path, command):
    out = tmp_path / ("o" * 250)
    args, target = _lock_commands(world, out)[command]
    if command != "synthesize":  # the output folder itself has the long name
        args[args.index("--out") + 1] = target = out
    if command == "build-db":
        args = ["build-db", "--demo", "--minutes", "0.5", "--out", out]
    if command == "train-refiner":
        args += ["--iterations", "2"]
    run = run_cli(*args)
    assert run.code == 0, run.stderr
    assert target.exists()
    assert not [p.name for p in target.parent.iterdir() if p.name.startswith(".")]
