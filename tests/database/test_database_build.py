"""Building a database from a folder of takes: out of core, in parallel, resumed, appended to.

The takes are the generated speaker's, written as BVH (gesturekit's own 55 joints, read with an
identity joint map) and wav files, so every build reads and parses files as a real one does.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.database import MatchingDatabase
from tests.badinput import assert_refused, run_cli, snapshot
from tests.waits import patience

ROOT = Path(__file__).resolve().parents[2]
TAKE_SECONDS = 10.0


def write_takes(folder: Path, names: list[str], *, seconds: float = TAKE_SECONDS) -> Path:
    """Generated takes ``NAME.bvh`` + ``NAME.wav`` in ``folder`` (each name's seed from its position in ``names``)."""
    import soundfile as sf

    from gesturekit.datasets.synthetic import generate_demo_take
    from gesturekit.export.bvh import write_bvh

    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        take, _ = generate_demo_take(seconds=seconds, seed=int(name[1:]), name=name)
        write_bvh(folder / f"{name}.bvh", take.motion)
        sf.write(folder / f"{name}.wav", take.audio, 16000)
    return folder


@pytest.fixture(scope="module")
def joint_map(tmp_path_factory) -> Path:
    """A joint map that reads gesturekit's own BVH files (every joint by its own name)."""
    from gesturekit.skeleton import JOINT_NAMES

    path = tmp_path_factory.mktemp("map") / "identity.json"
    path.write_text(json.dumps({"pelvis": JOINT_NAMES[0], "joints": {n: n for n in JOINT_NAMES}}))
    return path


@pytest.fixture(scope="module")
def five(tmp_path_factory) -> Path:
    """A folder of five 10-second takes, t000 .. t004."""
    return write_takes(tmp_path_factory.mktemp("five"), [f"t{i:03d}" for i in range(5)])


def build(folder: Path, out: Path, joint_map: Path, *options: str) -> str:
    """``gesturekit build-db FOLDER --out OUT ...``; its standard output (the run must succeed)."""
    run = run_cli("build-db", folder, "--joint-map", joint_map, "--out", out, *options)
    assert run.code == 0, run.stderr
    return run.stdout


def files(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder``: relative path -> bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def assert_same_folder(a: Path, b: Path) -> None:
    fa, fb = files(a), files(b)
    assert sorted(fa) == sorted(fb)
    different = [k for k in fa if fa[k] != fb[k]]
    assert not different, f"files differ: {different}"


# ---- streaming and parallel builds -----------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("options", [("--overlap-stride", "8"), ("--no-audio",)], ids=["audio+overlap", "no-audio"])
def test_serial_and_parallel_builds_write_the_same_bytes(five, joint_map, tmp_path, options):
    build(five, tmp_path / "serial", joint_map, "--workers", "1", *options)
    build(five, tmp_path / "parallel", joint_map, "--workers", "2", *options)
    assert_same_folder(tmp_path / "serial", tmp_path / "parallel")
    db = MatchingDatabase.load(tmp_path / "serial")
    assert db.take_names == [f"t{i:03d}" for i in range(5)]
    assert (db.audio is None) == ("--no-audio" in options)
    assert (db.overlap is not None) == ("--overlap-stride" in options)
    assert not (tmp_path / ".serial.staging").exists() and not (tmp_path / ".parallel.staging").exists()


@pytest.mark.slow
def test_folder_build_matches_the_in_memory_build_of_the_same_takes(five, joint_map, tmp_path):
    """One builder: the folder build and MatchingDatabase.build (used by scripts and the demo) agree."""
    from gesturekit.database import BuildConfig
    from gesturekit.datasets.takes import discover_takes, iter_takes

    build(five, tmp_path / "folder", joint_map, "--workers", "1", "--overlap-stride", "16")
    on_disk = MatchingDatabase.load(tmp_path / "folder")
    takes = iter_takes(discover_takes(five), joint_map=str(joint_map))
    in_memory = MatchingDatabase.build(takes, config=BuildConfig(overlap_stride=16))
    for k in on_disk.arrays:
        np.testing.assert_array_equal(on_disk.arrays[k], in_memory.arrays[k], err_msg=k)
    for k in on_disk.overlap or {}:
        np.testing.assert_array_equal((on_disk.overlap or {})[k], (in_memory.overlap or {})[k], err_msg=k)
    for k in on_disk.stats:
        np.testing.assert_array_equal(on_disk.stats[k], in_memory.stats[k], err_msg=k)
    assert on_disk.thresholds == in_memory.thresholds
    np.testing.assert_array_equal(on_disk.audio, in_memory.audio)


def test_takes_are_listed_by_name_whatever_order_they_come_in():
    from tests.conftest import make_take

    db = MatchingDatabase.build([make_take(6.0, seed=2, name="b"), make_take(6.0, seed=1, name="a")])
    same = MatchingDatabase.build([make_take(6.0, seed=1, name="a"), make_take(6.0, seed=2, name="b")])
    assert db.take_names == ["a", "b"]
    for k in db.arrays:
        np.testing.assert_array_equal(db.arrays[k], same.arrays[k], err_msg=k)
    assert db.stats["F_mean"].tobytes() == same.stats["F_mean"].tobytes()


_PEAK = """
    import contextlib, io, resource, sys
    from gesturekit.cli import main
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(["build-db", sys.argv[1], "--joint-map", sys.argv[2], "--out", sys.argv[3], "--workers", "1"])
    print(code, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


@pytest.mark.slow
def test_peak_memory_does_not_grow_with_the_dataset(joint_map, tmp_path):
    """Ten times the takes (5 min of data against 30 s), each build in a fresh process: the peak resident
    memory grows by less than 20 % (the build that held every take grew by about 70 % here)."""
    small = write_takes(tmp_path / "small", [f"t{i:03d}" for i in range(3)])
    large = write_takes(tmp_path / "large", [f"t{i:03d}" for i in range(30)])
    peaks = {}
    for name, folder in (("small", small), ("large", large)):
        run = subprocess.run(
            [sys.executable, "-c", textwrap.dedent(_PEAK), folder, joint_map, tmp_path / f"db-{name}"],
            capture_output=True,
            text=True,
            cwd=ROOT,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
            timeout=patience(300),
        )
        assert run.returncode == 0, run.stderr
        code, peak_kib = run.stdout.split()
        assert code == "0", run.stderr
        peaks[name] = int(peak_kib)
    assert (
        MatchingDatabase.load(tmp_path / "db-large").n_clips
        == 10 * MatchingDatabase.load(tmp_path / "db-small").n_clips
    )
    assert peaks["large"] < 1.2 * peaks["small"], peaks


# ---- appending -------------------------------------------------------------------------------------


@pytest.mark.slow
def test_append_recomputing_statistics_equals_a_build_of_all_takes(five, joint_map, tmp_path):
    folder = tmp_path / "takes"
    folder.mkdir()
    for name in ("t000", "t002", "t004"):  # the appended takes sort between the old ones
        for ext in (".bvh", ".wav"):
            shutil.copy2(five / f"{name}{ext}", folder / f"{name}{ext}")
    build(folder, tmp_path / "db", joint_map, "--workers", "1", "--overlap-stride", "8")
    for name in ("t001", "t003"):
        for ext in (".bvh", ".wav"):
            shutil.copy2(five / f"{name}{ext}", folder / f"{name}{ext}")
    out = build(folder, tmp_path / "db", joint_map, "--append", "--workers", "1")
    assert "appended 2 takes to the database's 3; statistics and thresholds recomputed over all 5 takes" in out
    build(folder, tmp_path / "all", joint_map, "--workers", "1", "--overlap-stride", "8")
    assert_same_folder(tmp_path / "db", tmp_path / "all")
    again = build(folder, tmp_path / "db", joint_map, "--append", "--workers", "1")
    assert "nothing to append" in again
    assert_same_folder(tmp_path / "db", tmp_path / "all")


@pytest.mark.slow
def test_append_keeping_statistics_leaves_the_old_arrays_as_they_were(five, joint_map, tmp_path):
    folder = tmp_path / "takes"
    folder.mkdir()
    for name in ("t001", "t003"):
        for ext in (".bvh", ".wav"):
            shutil.copy2(five / f"{name}{ext}", folder / f"{name}{ext}")
    build(folder, tmp_path / "db", joint_map, "--workers", "1", "--overlap-stride", "8")
    before = files(tmp_path / "db")
    old = MatchingDatabase.load(tmp_path / "db")
    old_meta = json.loads(before["database.json"])
    for name in ("t000", "t004"):
        for ext in (".bvh", ".wav"):
            shutil.copy2(five / f"{name}{ext}", folder / f"{name}{ext}")
    out = build(folder, tmp_path / "db", joint_map, "--append", "--keep-stats", "--workers", "2")
    assert "appended 2 takes to the database's 2; statistics and thresholds kept from the database" in out
    after = files(tmp_path / "db")
    assert after["stats.npz"] == before["stats.npz"]
    for name, data in before.items():
        if name.endswith(".npy"):  # each old array is the front of the new one, byte for byte
            header = len(data) - np.load(io.BytesIO(data), allow_pickle=False).nbytes
            assert after[name][header:].startswith(data[header:]), name
    db = MatchingDatabase.load(tmp_path / "db")
    meta = json.loads(after["database.json"])
    assert meta["thresholds"] == old_meta["thresholds"]
    assert meta["takes"][:2] == old_meta["takes"]
    assert db.take_names == ["t001", "t003", "t000", "t004"]  # the new ones after the old, by name
    # the new takes are z-scored with the old statistics: the raw features of a full build, so scaled
    build(five, tmp_path / "all", joint_map, "--workers", "1", "--overlap-stride", "8")
    full = MatchingDatabase.load(tmp_path / "all")
    new_rows = np.asarray(db.clip_take) >= 2
    raw_new = db.zscore("F").invert(np.asarray(db.F)[new_rows])
    full_rows = np.isin(np.asarray(full.clip_take), [0, 4])
    raw_full = full.zscore("F").invert(np.asarray(full.F)[full_rows])
    np.testing.assert_allclose(raw_new, raw_full, rtol=1e-4, atol=1e-3)
    np.testing.assert_array_equal(np.asarray(db.G)[: old.n_clips], np.asarray(old.G))


# ---- resuming --------------------------------------------------------------------------------------


@pytest.mark.slow
def test_an_interrupted_build_resumes_with_the_takes_staged(five, joint_map, tmp_path):
    folder = tmp_path / "takes"
    shutil.copytree(five, folder)
    good = (folder / "t003.bvh").read_bytes()
    (folder / "t003.bvh").write_text("HIERARCHY\nROOT broken {\n")  # the fourth take fails
    run = run_cli("build-db", folder, "--joint-map", joint_map, "--out", tmp_path / "db", "--workers", "1")
    assert run.code == 2 and "t003.bvh" in run.stderr, run.stderr
    assert not (tmp_path / "db").exists()
    staging = tmp_path / ".db.staging"
    assert len([p for p in staging.iterdir() if p.is_dir()]) == 3  # t000, t001, t002 are staged
    (folder / "t003.bvh").write_bytes(good)
    out = build(folder, tmp_path / "db", joint_map, "--workers", "2")
    assert "reused 3 takes staged by an interrupted build" in out
    assert not staging.exists()
    build(five, tmp_path / "clean", joint_map, "--workers", "1")
    # the same folder of takes, other paths: every array and the statistics agree
    got, want = files(tmp_path / "db"), files(tmp_path / "clean")
    assert sorted(got) == sorted(want)
    assert all(got[k] == want[k] for k in got if k != "database.json")


@pytest.mark.slow
def test_a_killed_build_resumes(five, joint_map, tmp_path):
    """kill -9 after two takes are staged; the same command then reads only the other three."""
    script = textwrap.dedent("""
        import os, signal, sys
        import gesturekit.database.stage as stage
        from gesturekit.cli import main

        real, done = stage.stage_job, []

        def dying(job):
            result = real(job)
            done.append(job)
            if len(done) == 2:
                os.kill(os.getpid(), signal.SIGKILL)
            return result

        stage.stage_job = dying  # what the build calls for each take, in this process with --workers 1
        main(["build-db", sys.argv[1], "--joint-map", sys.argv[2], "--out", sys.argv[3], "--workers", "1"])
    """)
    run = subprocess.run(
        [sys.executable, "-c", script, five, joint_map, tmp_path / "db"],
        capture_output=True,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        timeout=patience(300),
    )
    assert run.returncode == -9, run.stderr
    assert not (tmp_path / "db" / "database.json").exists()
    out = build(five, tmp_path / "db", joint_map, "--workers", "1")
    assert "reused 2 takes staged by an interrupted build" in out
    build(five, tmp_path / "clean", joint_map, "--workers", "1")
    got, want = files(tmp_path / "db"), files(tmp_path / "clean")
    assert all(got[k] == want[k] for k in got if k != "database.json")


# ---- on a Dask cluster -----------------------------------------------------------------------------


@pytest.mark.slow
def test_a_dask_cluster_build_writes_the_same_bytes(five, joint_map, tmp_path):
    distributed = pytest.importorskip("distributed", reason="dask.distributed is not installed")
    from gesturekit.workspace import build_database

    build(five, tmp_path / "here", joint_map, "--workers", "1", "--overlap-stride", "16")
    with (
        distributed.LocalCluster(n_workers=2, processes=False, dashboard_address=None) as cluster,
        distributed.Client(cluster) as client,
    ):
        from gesturekit.database import BuildConfig

        build_database(
            five,
            tmp_path / "cluster",
            config=BuildConfig(overlap_stride=16),
            joint_map=str(joint_map),
            scheduler=client,
        )
    assert_same_folder(tmp_path / "here", tmp_path / "cluster")


# ---- the pieces ------------------------------------------------------------------------------------


@settings(max_examples=40, deadline=None)
@given(
    sizes=st.lists(st.integers(0, 30), min_size=1, max_size=6).filter(lambda s: sum(s) > 1),
    seed=st.integers(0, 2**31 - 1),
)
def test_moments_combined_take_by_take_match_those_of_all_frames(tmp_path_factory, sizes, seed):
    """Chan's update over takes of any sizes (empty ones too) gives the mean and std of all frames."""
    from gesturekit.database.build import combine_moments
    from gesturekit.database.clips import MOMENT_KEYS, moments
    from gesturekit.database.stage import StagedTake

    rng = np.random.default_rng(seed)
    folder = tmp_path_factory.mktemp("moments")
    dims = {"F": 3, "P": 2, "A": 4}
    parts = {k: [rng.normal(5.0, 3.0, size=(n, d)).astype(np.float32) for n in sizes] for k, d in dims.items()}
    staged = []
    for i, n in enumerate(sizes):
        for k in MOMENT_KEYS:
            np.save(folder / f"{i}.moments_{k}.npy", moments(parts[k][i]))
        staged.append(StagedTake(folder, {"index": i, "name": f"t{i}", "count": n}))
    stats = combine_moments(staged)
    for k in dims:
        x = np.concatenate(parts[k]).astype(np.float64)
        np.testing.assert_allclose(stats[f"{k}_mean"], x.mean(axis=0), rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(stats[f"{k}_std"], np.maximum(x.std(axis=0), 1e-6), rtol=1e-5, atol=1e-5)


@settings(max_examples=30, deadline=None)
@given(
    rows=st.lists(st.integers(0, 5), min_size=1, max_size=4),
    dtype=st.sampled_from([np.float32, np.int32, np.bool_, np.int16]),
    width=st.integers(1, 3),
)
def test_npy_written_row_by_row_is_what_numpy_saves(tmp_path_factory, rows, dtype, width):
    from gesturekit.database.folder import NpyWriter

    folder = tmp_path_factory.mktemp("npy")
    parts = [np.arange(n * width * 2).reshape(n, width, 2).astype(dtype) for n in rows]
    whole = np.concatenate(parts)
    np.save(folder / "saved.npy", whole)
    w = NpyWriter(folder / "written.npy", whole.dtype, whole.shape)
    for p in parts:
        w.write(p)
    w.close()
    assert (folder / "written.npy").read_bytes() == (folder / "saved.npy").read_bytes()
    w = NpyWriter(folder / "appended.npy", whole.dtype, (2 * whole.shape[0], *whole.shape[1:]))
    w.copy_from(folder / "saved.npy")
    w.write(whole)
    w.close()
    np.testing.assert_array_equal(np.load(folder / "appended.npy"), np.concatenate([whole, whole]))


@settings(max_examples=30, deadline=None)
@given(
    clips=st.integers(1, 9),
    frames=st.integers(1, 5),
    chunk_rows=st.integers(1, 7),
    seed=st.integers(0, 2**31 - 1),
    q=st.tuples(st.floats(0, 49), st.floats(51, 100)),
)
def test_thresholds_read_in_pieces_are_the_percentiles_of_every_frame(
    tmp_path_factory, clips, frames, chunk_rows, seed, q
):
    """Percentiles of each attribute column, read from attributes.npy a few rows at a time, are
    numpy's over the whole (clips * frames, 9) array."""
    from gesturekit.control import ATTRIBUTE_NAMES
    from gesturekit.database.folder import column_percentiles

    n = len(ATTRIBUTE_NAMES)
    attrs = np.random.default_rng(seed).normal(size=(clips, frames, n)).astype(np.float32)
    path = tmp_path_factory.mktemp("attrs") / "attributes.npy"
    np.save(path, attrs)
    # pieces of a few frames, crossing clip boundaries
    got = column_percentiles(path, q, chunk_bytes=chunk_rows * n * 4)
    flat = attrs.reshape(-1, n).astype(np.float64)
    for i, name in enumerate(ATTRIBUTE_NAMES):
        assert got[name] == [float(np.percentile(flat[:, i], q[0])), float(np.percentile(flat[:, i], q[1]))]


@pytest.mark.slow
def test_warnings_of_worker_processes_reach_the_command_line(joint_map, tmp_path):
    """A take whose speech is shorter than its motion is trimmed with a warning, also when a worker
    process reads it (the warning is issued again in the command's process, once)."""
    import soundfile as sf

    folder = write_takes(tmp_path / "takes", ["t000", "t001"])
    audio, sr = sf.read(folder / "t001.wav", dtype="float32")
    sf.write(folder / "t001.wav", audio[: len(audio) - sr], sr)  # one second short
    from gesturekit.errors import GestureKitWarning

    with pytest.warns(GestureKitWarning) as caught:
        run = run_cli("build-db", folder, "--joint-map", joint_map, "--out", tmp_path / "db", "--workers", "2")
    assert run.code == 0, run.stderr
    messages = [str(w.message) for w in caught if issubclass(w.category, GestureKitWarning)]
    assert messages == ["t001: motion has 10.00 s and audio 9.00 s; trimmed the motion by 1.00 s to 9.00 s"]


# ---- bad input -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("options", "names", "problem"),
    [
        (["--workers", "0"], "--workers", "positive"),
        (["--workers", "2", "--scheduler", "tcp://localhost:1"], "--scheduler", "not both"),
        (["--keep-stats"], "--keep-stats", "needs --append"),
        (["--append", "--force"], "--append", "not both"),
        (["--scheduler", " "], "--scheduler", "address"),
    ],
    ids=["workers-0", "workers-and-scheduler", "keep-stats-alone", "append-and-force", "empty-scheduler"],
)
def test_scale_options_that_do_not_fit_are_refused(five, joint_map, tmp_path, options, names, problem):
    before = snapshot(five, tmp_path)
    run = run_cli("build-db", five, "--joint-map", joint_map, "--out", tmp_path / "db", *options)
    assert_refused(run, names=names, problem=problem, before=before)


@pytest.mark.parametrize("option", ["--append", "--workers=2", "--scheduler=tcp://localhost:1"])
def test_scale_options_are_refused_with_demo(tmp_path, option):
    before = snapshot(tmp_path)
    run = run_cli("build-db", "--demo", "--out", tmp_path / "db", option)
    assert_refused(run, names=option.split("=")[0], problem="--demo generates", before=before)


@pytest.mark.slow
def test_a_scheduler_that_cannot_be_reached_is_refused(five, joint_map, tmp_path, monkeypatch):
    pytest.importorskip("distributed", reason="dask.distributed is not installed")
    import gesturekit._jobs as jobs_module

    monkeypatch.setattr(jobs_module, "SCHEDULER_TIMEOUT", "1s")
    before = snapshot(five, tmp_path)
    address = "tcp://127.0.0.1:1"
    run = run_cli("build-db", five, "--joint-map", joint_map, "--out", tmp_path / "db", "--scheduler", address)
    assert_refused(run, names=address, problem="cannot reach", before=before)


def test_append_keeps_the_label_or_replaces_it_when_one_is_given(five, joint_map, tmp_path):
    folder = tmp_path / "takes"
    folder.mkdir()
    write = lambda *names: [  # noqa: E731
        shutil.copy2(five / f"{n}{ext}", folder / f"{n}{ext}") for n in names for ext in (".bvh", ".wav")
    ]
    label = lambda: json.loads((tmp_path / "db" / "database.json").read_text())["build"]["label"]  # noqa: E731
    write("t000", "t001")
    build(folder, tmp_path / "db", joint_map, "--workers", "1", "--label", "speaker A, day 1")
    write("t002")
    build(folder, tmp_path / "db", joint_map, "--append", "--workers", "1")
    assert label() == "speaker A, day 1"
    write("t003")
    build(folder, tmp_path / "db", joint_map, "--append", "--workers", "1", "--label", "speaker A, days 1-2")
    assert label() == "speaker A, days 1-2" and len(MatchingDatabase.load(tmp_path / "db").take_names) == 4
    out = build(folder, tmp_path / "db", joint_map, "--append", "--workers", "1", "--label", "other")
    assert "nothing to append" in out and "its label is unchanged ('speaker A, days 1-2')" in out
    assert label() == "speaker A, days 1-2"


def test_append_without_a_database_is_refused(five, joint_map, tmp_path):
    before = snapshot(five, tmp_path)
    run = run_cli("build-db", five, "--joint-map", joint_map, "--out", tmp_path / "db", "--append")
    assert_refused(run, names=tmp_path / "db", problem="there is none", before=before)


def test_append_takes_the_databases_options_for_those_left_out_and_refuses_others_given(five, joint_map, tmp_path):
    folder, out = tmp_path / "takes", tmp_path / "db"
    folder.mkdir()
    write = lambda *names: [  # noqa: E731
        shutil.copy2(five / f"{n}{ext}", folder / f"{n}{ext}") for n in names for ext in (".bvh", ".wav")
    ]
    record = lambda: json.loads((out / "database.json").read_text())["build"]  # noqa: E731
    write("t000", "t001")
    build(folder, out, joint_map, "--workers", "1", "--percentiles", "10", "90", "--no-audio")
    write("t002")
    # --no-audio given (the database's), --percentiles left out: the database's 10 90, not the default 15 85
    build(folder, out, joint_map, "--append", "--workers", "1", "--no-audio")
    assert record()["percentiles"] == [10.0, 90.0] and record()["store_audio"] is False
    assert len(MatchingDatabase.load(out).take_names) == 3
    before = snapshot(folder, tmp_path)
    run = run_cli("build-db", folder, "--joint-map", joint_map, "--out", out, "--append", "--percentiles", "15", "85")
    assert_refused(run, names="--percentiles", problem="database's", before=before)


def test_append_with_other_build_options_is_refused(five, joint_map, tmp_path):
    build(five, tmp_path / "db", joint_map, "--workers", "1")
    before = snapshot(five, tmp_path)
    run = run_cli(
        "build-db", five, "--joint-map", joint_map, "--out", tmp_path / "db", "--append", "--overlap-stride", "8"
    )
    assert_refused(run, names="--overlap-stride", problem="database's", before=before)


def test_append_recomputing_refuses_when_an_old_take_file_is_gone(five, joint_map, tmp_path):
    folder = tmp_path / "takes"
    shutil.copytree(five, folder)
    build(folder, tmp_path / "db", joint_map, "--workers", "1")
    (folder / "t001.bvh").unlink()
    write_takes(folder, ["t007"])
    before = snapshot(folder, tmp_path / "db")
    run = run_cli("build-db", folder, "--joint-map", joint_map, "--out", tmp_path / "db", "--append")
    assert_refused(run, names=folder / "t001.bvh", problem="--keep-stats", before=before)


def test_a_staging_folder_that_is_not_ours_is_left_alone(five, joint_map, tmp_path):
    (tmp_path / ".db.staging").mkdir()
    (tmp_path / ".db.staging" / "mine.txt").write_text("keep me")
    before = snapshot(five, tmp_path)
    run = run_cli("build-db", five, "--joint-map", joint_map, "--out", tmp_path / "db", "--workers", "1")
    assert_refused(run, names=tmp_path / ".db.staging", problem="not one gesturekit made", before=before)


@pytest.mark.slow
def test_a_parallel_build_reports_the_error_a_serial_build_gives(tmp_path):
    """Every take refused (Y-down keypoints read without --up): two worker processes report the
    first take's error, whichever finishes first, as one process does."""
    from gesturekit.datasets.keypoint_example import write_keypoint_example
    from gesturekit.errors import MotionFileError
    from gesturekit.workspace import build_database

    folder = tmp_path / "kp"
    write_keypoint_example(folder, fmt="npy", takes=4, seconds=3, seed=2)
    for attempt in range(3):
        with pytest.raises(MotionFileError) as info:
            build_database(
                folder, tmp_path / f"db{attempt}", kind="positions", joint_map=folder / "joint_map.json", fps=15,
                workers=2,
            )  # fmt: skip
        assert "take_00.npy" in str(info.value) and "pass --up -y" in str(info.value)


def test_a_take_staged_with_other_audio_options_is_not_reused(tmp_path):
    """The staged audio is encoded as the build asks: a rerun with another --audio-rate or
    --audio-format stages the take again rather than reusing audio of another form."""
    from gesturekit.database import BuildConfig
    from gesturekit.database.stage import job_key
    from gesturekit.datasets.takes import TakeSource

    motion, audio = tmp_path / "t.npy", tmp_path / "t.wav"
    motion.write_bytes(b"x")
    audio.write_bytes(b"y")
    source = TakeSource("positions", motion, audio)
    forms = ({}, {"audio_rate": 8000}, {"audio_format": "flac"}, {"audio_format": "flac", "audio_rate": 8000})
    keys = {job_key(source, {"fps": 15}, BuildConfig(**options)) for options in forms}
    assert len(keys) == 4
