"""Bad-input suite, files and processes: planted lock links, long names, FIFOs, devices, deep JSON, zip bombs.

Each case runs one command as a user would and asserts a clean refusal (exit 2,
the file named, the problem said, no traceback) that left every file as it was.
"""

from __future__ import annotations

import os
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.paths import assets
from tests import hostile as h
from tests.badinput import assert_refused, run_cli, snapshot
from tests.conftest import make_take

pytestmark = pytest.mark.slow  # builds databases and runs the CLI end to end


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


# ----------------------------------------------------------------------------- what a file is

DEMO_REFINER = assets() / "demo-refiner"
DEEP = "[" * 100_000 + "]" * 100_000


@pytest.fixture
def work(world, tmp_path) -> Path:
    """A per-test copy of the database, a refiner and the speech, free to break."""
    shutil.copytree(world / "db", tmp_path / "db")
    shutil.copytree(DEMO_REFINER, tmp_path / "refiner")
    shutil.copy(world / "speech.wav", tmp_path / "speech.wav")
    return tmp_path


def _synth(work: Path, *extra) -> list:
    return ["synthesize", work / "speech.wav", "--db", work / "db", "--out", work / "out", "--refiner", "none", *extra]


def _fifo(path: Path) -> Path:
    if path.exists():
        path.unlink()
    os.mkfifo(path)
    return path


def _deep(path: Path) -> Path:
    path.write_text(DEEP)
    return path


def _bomb(path: Path, megabytes: int = 64) -> Path:
    """An npz whose one member inflates to ``megabytes`` of zeros from a few kilobytes."""
    path.unlink(missing_ok=True)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as z:
        with z.open("F_mean.npy", "w", force_zip64=True) as f:
            n = megabytes * 2**20 // 4
            np.lib.format.write_array_header_1_0(f, {"descr": "<f4", "fortran_order": False, "shape": (n,)})
            zeros = bytes(2**20)
            for _ in range(megabytes):
                f.write(zeros)
    return path


# name: (make the case in the work folder -> (its arguments, what the message names), words of the problem)
FILE_CASES = {
    "deep database.json": (
        lambda w: (_synth(w), _deep(w / "db" / "database.json").parent),
        "database.json nests 100000 levels deep",
    ),
    "deep refiner config.json": (
        lambda w: (_synth(w)[:-2] + ["--refiner", w / "refiner"], _deep(w / "refiner" / "config.json").parent),
        "config.json nests 100000 levels deep",
    ),
    "deep control file": (
        lambda w: (_synth(w, "--control", _deep(w / "c.json")), w / "c.json"),
        "nests 100000 levels deep",
    ),
    "deep joint map": (
        lambda w: (
            ["build-db", h.position_take(w / "takes").parent, "--joint-map", _deep(w / "map.json"), "--out", f"{w}-db"],
            w / "map.json",
        ),
        "joint map nests 100000 levels deep",
    ),
    "deep config.json in --out": (
        lambda w: (
            ["train-refiner", "--db", w / "db", "--out", _deep(w / "refiner" / "config.json").parent],
            w / "refiner",
        ),
        "already",
    ),
    "FIFO speech": (lambda w: (_synth(w)[:1] + [_fifo(w / "s.wav")] + _synth(w)[2:], w / "s.wav"), "is a FIFO"),
    "/dev/zero speech": (
        lambda w: (_synth(w)[:1] + ["/dev/zero"] + _synth(w)[2:], "/dev/zero"),
        "is a character device, not a regular file",
    ),
    "FIFO database array": (lambda w: (_synth(w), _fifo(w / "db" / "F.npy").parent), "F.npy is a FIFO"),
    "FIFO database.json": (lambda w: (_synth(w), _fifo(w / "db" / "database.json").parent), "database.json is a FIFO"),
    "FIFO database.json in --out": (
        lambda w: (
            ["build-db", "--demo", "--minutes", "0.5", "--out", _fifo(w / "db" / "database.json").parent, "--force"],
            w / "db",
        ),
        "gesturekit did not write",
    ),
    "FIFO control file": (lambda w: (_synth(w, "--control", _fifo(w / "c.csv")), w / "c.csv"), "is a FIFO"),
    "zip bomb database stats.npz": (
        lambda w: (_synth(w), _bomb(w / "db" / "stats.npz").parent),
        "stats.npz declares 67.1 MB",
    ),
    "database stats.npz claiming a terabyte": (
        lambda w: (_synth(w), h.npz_claiming(w / "db" / "stats.npz", {"F_mean": (2**38,)}).parent),
        "stats.npz F_mean declares shape",
    ),
    "zip bomb refiner stats.npz": (
        lambda w: (_synth(w)[:-2] + ["--refiner", w / "refiner"], _bomb(w / "refiner" / "stats.npz").parent),
        "stats.npz declares 67.1 MB",
    ),
}


@pytest.mark.parametrize("case", list(FILE_CASES))
def test_hostile_file_refused(work, case):
    make, problem = FILE_CASES[case]
    args, names = make(work)
    before = snapshot(work)
    assert_refused(run_cli(*args), names=names, problem=problem, before=before)


def test_database_json_beyond_the_json_limit_is_refused_before_reading(work, monkeypatch):
    monkeypatch.setenv("GESTUREKIT_MAX_JSON_MB", "0.001")
    before = snapshot(work)
    run = run_cli(*_synth(work))
    assert_refused(run, names=work / "db", problem="beyond the limit of 1 KB for a JSON file", before=before)
    assert "GESTUREKIT_MAX_JSON_MB" in run.stderr


# ----------------------------------------------------------------------------- live speech


@pytest.mark.parametrize(
    "scale, problem",
    [
        (1e30, r"must lie in \[-1, 1\], found .*e\+29 at sample .*the chunk was not used"),
        (32767.0, "divide them by 32768"),
    ],
)
def test_live_push_of_absurd_samples_is_refused_and_the_stream_goes_on(world, scale, problem):
    from gesturekit.errors import ConfigError
    from gesturekit.live import LiveSynthesizer

    speech = make_take(3.0, seed=5).audio
    live = LiveSynthesizer(MatchingDatabase.load(world / "db"))
    live.push(speech[:16000])
    with pytest.raises(ConfigError, match=problem):
        live.push(speech[16000:24000] / np.abs(speech).max() * scale)
    assert live.samples_in == 16000
    live.push(speech[16000:])
    assert live.finish().shape[1:] == (55, 3) and np.isfinite(live.result().motion.positions).all()


# ----------------------------------------------------------------------------- controls past the speech


def test_a_control_past_the_end_of_the_speech_is_named_in_a_warning(work):
    from gesturekit.errors import GestureKitWarning

    with pytest.warns(GestureKitWarning) as record:
        run = run_cli(*_synth(work, "--control", "1-2:left_hand=high,100-200:left_hand=low"))
    assert run.code == 0, run.stderr
    said = [str(w.message) for w in record if "control segment" in str(w.message)]
    assert said == [
        f"{work / 'speech.wav'}: control segment 100-200 s starts after the speech ends (3.0 s); it is ignored"
    ]


# ----------------------------------------------------------------------------- names that drive a terminal

ESC = "\x1b[2J\x1b]0;owned\x07"


def test_names_with_escape_sequences_are_printed_escaped(world, tmp_path):
    speech = tmp_path / f"talk{ESC}.wav"
    shutil.copy(world / "speech.wav", speech)
    synth = run_cli("synthesize", speech, "--db", world / "db", "--out", tmp_path / "out", "--refiner", "none")
    assert synth.code == 0, synth.stderr
    db = tmp_path / "db"
    MatchingDatabase.build([make_take(5.0, seed=1, name=f"take{ESC}")], config=BuildConfig(store_audio=False)).save(db)
    info = run_cli("info", db, "--takes")
    takes = tmp_path / f"takes{ESC}"
    takes.mkdir()
    (takes / f"a{ESC}.bvh").write_text("HIERARCHY\n")
    sf.write(takes / f"a{ESC}.wav", make_take(3.0, seed=3).audio, 16000, subtype="PCM_16")
    build = run_cli("build-db", takes, "--preset", "zeggs", "--out", tmp_path / "db2")
    assert build.code == 2
    for run in (synth, info, build):
        assert "\x1b" not in run.stdout + run.stderr and "\x07" not in run.stdout + run.stderr
    assert "talk\\x1b[2J\\x1b]0;owned\\x07" in synth.stdout
    assert "take\\x1b[2J" in info.stdout
    assert "a\\x1b[2J\\x1b]0;owned\\x07.bvh: no MOTION section" in build.stderr


# ----------------------------------------------------------------------------- worker processes


def test_workers_beyond_the_cores_are_capped_with_a_warning(monkeypatch):
    from gesturekit import _jobs
    from gesturekit.errors import GestureKitWarning

    monkeypatch.setattr(_jobs, "usable_cores", lambda: 2)
    monkeypatch.delenv(_jobs.OVER_CORES_ENV, raising=False)
    with pytest.warns(GestureKitWarning, match=r"--workers 64: .* 2 cores, so 2 worker processes run"):
        assert _jobs.worker_count(64) == 2
    assert _jobs.worker_count(2) == 2 and _jobs.worker_count(None) == 2
    monkeypatch.setenv(_jobs.OVER_CORES_ENV, "1")
    assert _jobs.worker_count(64) == 64
