"""Bad-input suite, a build's staging folder: damaged staged takes and a disk that fills up while staging.

A build that is interrupted leaves its staged takes for the next identical command to reuse. Each
case interrupts a build (a take that cannot be read), damages what it staged as a crash, a full
disk or a careless hand would, and resumes: the resumed build checks every staged unit, stages a
damaged one again and says so, and gives the database an uninterrupted build gives, byte for byte.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from gesturekit.datasets.keypoint_example import write_keypoint_example
from tests.badinput import assert_refused, run_cli

OPTIONS = ("--fps", "15", "--up", "-y", "--workers", "1", "--overlap-stride", "16")


@pytest.fixture(scope="module")
def kp_base(tmp_path_factory) -> Path:
    """Three six-second keypoint takes (one clip each), their speech and joint map."""
    root = tmp_path_factory.mktemp("kp")
    write_keypoint_example(root, fmt="npy", takes=3, seconds=6.0, seed=4)
    return root


@pytest.fixture
def kp(kp_base, tmp_path) -> Path:
    folder = tmp_path / "takes"
    shutil.copytree(kp_base, folder)  # modification times kept: the takes' records are the same
    return folder


def _build(folder: Path, out: Path, *options: str):
    return run_cli("build-db", folder, "--joint-map", folder / "joint_map.json", "--out", out, *OPTIONS, *options)


def _interrupt(folder: Path, out: Path, *options: str) -> Path:
    """A build that stops at the third take (unreadable), leaving the first two staged; the take
    restored, its file's time too. The staging folder."""
    take = folder / "take_02.npy"
    saved = take.read_bytes()
    st = take.stat()
    take.write_bytes(b"garbage")
    run = _build(folder, out, *options)
    assert run.code == 2 and "take_02.npy" in run.stderr, run.stderr
    take.write_bytes(saved)
    os.utime(take, ns=(st.st_atime_ns, st.st_mtime_ns))
    return out.parent / f".{out.name}.staging"


def _unit(staging: Path, take: str) -> Path:
    """The staged unit of ``take``."""
    for unit in staging.iterdir():
        if unit.is_dir() and take in (unit / "takes.json").read_text():
            return unit
    raise AssertionError(f"{take} is not staged in {staging}")


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _resave(path: Path, transform: Callable[[np.ndarray], np.ndarray]) -> None:
    np.save(path, transform(np.load(path)))


def _truncate(unit: Path) -> None:
    data = (unit / "0.F.npy").read_bytes()
    (unit / "0.F.npy").write_bytes(data[: len(data) // 2])


def _rows_of_another_count(unit: Path) -> None:
    record = json.loads((unit / "takes.json").read_text())
    record["takes"][0]["n_clips"] = 5  # "wrote 5 rows of ..." when the database was written
    (unit / "takes.json").write_text(json.dumps(record))


DAMAGE: dict[str, tuple[Callable[[Path], None], str]] = {
    "truncated array": (_truncate, "0.F.npy: has"),
    "wrong shape": (lambda u: _resave(u / "0.G.npy", lambda a: a[:, :32]), "0.G.npy: holds float32 (1, 32, 165)"),
    "wrong dtype": (lambda u: _resave(u / "0.P.npy", lambda a: a.astype(np.float64)), "0.P.npy: holds float64"),
    "NaN-filled G": (lambda u: _resave(u / "0.G.npy", lambda a: np.full_like(a, np.nan)), "0.G.npy: holds NaN"),
    "NaN moments_F": (
        lambda u: _resave(u / "0.moments_F.npy", lambda a: np.full_like(a, np.nan)),
        "0.moments_F.npy: holds NaN",
    ),
    "deleted array": (lambda u: (u / "0.overlap.A.npy").unlink(), "0.overlap.A.npy: not found"),
    "garbage JSON": (lambda u: (u / "takes.json").write_text("{\x00not json"), "takes.json:"),
    "JSON of another shape": (lambda u: (u / "takes.json").write_text('{"takes": 5}'), "takes.json: not a staged"),
    "clip count of another take": (_rows_of_another_count, "takes.json: take 0 has 5 clips"),
}


@pytest.mark.parametrize("case", list(DAMAGE))
def test_a_damaged_staged_take_is_staged_again(kp, tmp_path, case):
    damage, reason = DAMAGE[case]
    staging = _interrupt(kp, tmp_path / "db")
    damage(_unit(staging, "take_00"))
    run = _build(kp, tmp_path / "db")
    assert run.code == 0 and "Traceback" not in run.stderr, run.stderr
    assert f"staged copy damaged ({reason}" in run.stdout, run.stdout
    assert "), staged again" in run.stdout
    if "JSON" not in case:  # the take is named when its record can be read
        assert "take take_00: staged copy damaged" in run.stdout, run.stdout
    assert "reused 1 takes staged by an interrupted build" in run.stdout  # take_01's was whole
    assert not staging.exists()
    clean = _build(kp, tmp_path / "clean")
    assert clean.code == 0, clean.stderr
    assert _files(tmp_path / "db") == _files(tmp_path / "clean")


def test_damaged_bone_samples_are_read_again(kp, tmp_path):
    staging = _interrupt(kp, tmp_path / "db", "--normalize-bones")
    bones = _unit(staging, "take_00") / "0.bones.npy"
    bones.write_bytes(bones.read_bytes()[:200])
    run = _build(kp, tmp_path / "db", "--normalize-bones")
    assert run.code == 0 and "Traceback" not in run.stderr, run.stderr
    assert "take take_00: staged copy damaged (0.bones.npy:" in run.stdout, run.stdout
    clean = _build(kp, tmp_path / "clean", "--normalize-bones")
    assert clean.code == 0, clean.stderr
    assert _files(tmp_path / "db") == _files(tmp_path / "clean")


def test_nothing_non_finite_is_written_from_a_staged_take(kp, tmp_path):
    """The last guard, when a staged array turns non-finite after it was checked: the file is named."""
    from gesturekit.database import BuildConfig
    from gesturekit.database.build import assemble
    from gesturekit.database.folder import FolderOut
    from gesturekit.database.stage import StagedTake
    from gesturekit.database.stage_check import check_staged_unit
    from gesturekit.errors import DatabaseError

    config = BuildConfig(overlap_stride=16)
    staging = _interrupt(kp, tmp_path / "db")
    units = [_unit(staging, "take_00"), _unit(staging, "take_01")]
    for unit in units:
        check_staged_unit(unit, config)
    staged = [StagedTake(u, json.loads((u / "takes.json").read_text())["takes"][0]) for u in units]
    _resave(units[1] / "0.overlap.G.npy", lambda a: np.full_like(a, np.inf))
    (tmp_path / "out").mkdir()
    with pytest.raises(DatabaseError, match=r"0\.overlap\.G\.npy: .*take 'take_01' .*non-finite.*overlap/G\.npy"):
        assemble(FolderOut(tmp_path / "out"), staged, config)
    _resave(units[0] / "0.moments_F.npy", lambda a: np.full_like(a, np.nan))
    with pytest.raises(DatabaseError, match=r"0\.moments_F\.npy: .*take 'take_00'.*non-finite"):
        assemble(FolderOut(tmp_path / "out"), staged, config)


# ---- a full disk while staging ---------------------------------------------------------------------


def _full_disk(monkeypatch, how: str) -> list[str]:
    """np.save fails on the second staged take's F.npy, having written part of it, as a full disk
    does: numpy's short write (no errno) or ENOSPC. The names it failed on."""
    real = np.save
    failed: list[str] = []

    def save(file, arr, *args, **kwargs):
        name = os.fspath(file)
        if ".staging" in name and name.endswith("0.F.npy") and "take_01" in failed_take[0]:
            with open(name, "wb") as f:
                f.write(b"\x93NUMPY partial")
            failed.append(name)
            if how == "short write":
                raise OSError("168960 requested and 166880 written")
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(file, arr, *args, **kwargs)

    # which take is being staged: the staging of each take starts with its features
    import gesturekit.database.clips as clips

    failed_take = [""]
    real_features = clips.take_features

    def features(take, **kwargs):
        failed_take[0] = take.name
        return real_features(take, **kwargs)

    monkeypatch.setattr(clips, "take_features", features)
    monkeypatch.setattr(np, "save", save)
    return failed


@pytest.mark.parametrize("how", ["short write", "ENOSPC"])
def test_a_full_disk_while_staging_names_the_file_and_the_build_resumes(kp, tmp_path, monkeypatch, how):
    failed = _full_disk(monkeypatch, how)
    run = _build(kp, tmp_path / "db")
    monkeypatch.undo()
    assert len(failed) == 1
    assert_refused(run, names="0.F.npy", problem="cannot write: the disk is full")
    assert ".db.staging" in run.stderr and "requested and" not in run.stderr.split("(ENOSPC")[0]
    staging = tmp_path / ".db.staging"
    # the partial file went with its unit's temporary folder: only take_00's unit is left
    assert not os.path.exists(failed[0]) and not any(".tmp-" in p.name for p in staging.iterdir())
    assert not (tmp_path / "db").exists()
    run = _build(kp, tmp_path / "db")  # space again
    assert run.code == 0, run.stderr
    assert "reused 1 takes staged by an interrupted build" in run.stdout and "damaged" not in run.stdout
    clean = _build(kp, tmp_path / "clean")
    assert clean.code == 0, clean.stderr
    assert _files(tmp_path / "db") == _files(tmp_path / "clean")


def test_synthesis_output_on_a_full_disk_names_the_file_and_leaves_nothing(kp, tmp_path, monkeypatch):
    assert _build(kp, tmp_path / "db").code == 0
    real = os.fsync

    def fsync(fd):  # a full disk shows when the written data reaches it; the output is speech.*
        if "speech" in os.path.basename(os.readlink(f"/proc/self/fd/{fd}")):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    speech = shutil.copy2(kp / "take_00.wav", tmp_path / "speech.wav")
    out = tmp_path / "out"
    out.mkdir()
    run = run_cli("synthesize", speech, "--db", tmp_path / "db", "--out", out, "--refiner", "none")
    monkeypatch.undo()
    assert_refused(run, names=out / "speech", problem="cannot write: the disk is full")
    assert [p.name for p in out.iterdir()] == []  # no partial output, no temporary file
