"""Outputs: what --force may replace, overlap with inputs, locks, stale temporaries, all-or-nothing writes."""

import errno
import json
import os
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit import outputs
from gesturekit._io import atomic_write
from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.errors import DatabaseError, GestureKitError, OutputError
from gesturekit.export.bvh import write_bvh
from gesturekit.export.npz import save_npz
from gesturekit.export.result import save_result_bvh, save_result_npz, save_result_video
from gesturekit.motion import Motion
from gesturekit.outputs import check_not_input, check_output, clean_stale, output_lock, write_folder
from tests.conftest import make_take
from tests.waits import patience, wait_until

REPO = Path(__file__).resolve().parents[2]


def run_script(code: str, *args, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run a Python snippet in a fresh interpreter that imports this checkout of gesturekit."""
    env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code), *map(str, args)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=patience(timeout),
    )


def dead_pid() -> int:
    """The id of a process that has exited."""
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


@pytest.fixture(scope="module")
def small_db():
    return MatchingDatabase.build(
        [make_take(9.0, seed=1, name="a"), make_take(5.0, seed=2, name="b")],
        config=BuildConfig(overlap_stride=16, store_audio=False),
    )


def still(frames=3, seed=0):
    from gesturekit.skeleton import N_JOINTS

    rng = np.random.default_rng(seed)
    return Motion(rng.normal(0, 0.3, size=(frames, N_JOINTS, 3)).astype(np.float32), 30.0)


# ---- what --force may replace -----------------------------------------------------------------------


def test_missing_and_empty_outputs_are_free(tmp_path):
    assert check_output(tmp_path / "new", "database", overwrite=False) is False
    (tmp_path / "empty").mkdir()
    assert check_output(tmp_path / "empty", "database", overwrite=False) is False


def test_a_foreign_folder_is_refused_saying_what_is_there(tmp_path):
    thesis = tmp_path / "thesis"
    (thesis / "chapters").mkdir(parents=True)
    for i in range(11):
        (thesis / "chapters" / f"{i}.tex").write_text("text")
    with pytest.raises(
        OutputError, match=r"thesis: holds 11 files and 1 folder that gesturekit did not write; refusing"
    ):
        check_output(thesis, "database", overwrite=True)


def test_each_kind_replaces_only_its_own(small_db, tmp_path):
    small_db.save(tmp_path / "db")
    assert check_output(tmp_path / "db", "database", overwrite=True) is True
    with pytest.raises(OutputError, match="already exists"):
        check_output(tmp_path / "db", "database", overwrite=False)
    with pytest.raises(OutputError, match="holds a matching database, not a refiner folder"):
        check_output(tmp_path / "db", "refiner", overwrite=True)
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(OutputError, match="notes.txt: is a file, not a folder"):
        check_output(tmp_path / "notes.txt", "study", overwrite=True)
    with pytest.raises(OutputError, match="db: is a folder, not a file"):
        check_output(tmp_path / "db", "file", overwrite=True)
    # a marker of another format is not ours either
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "database.json").write_text(json.dumps({"format": "someone-else"}))
    with pytest.raises(OutputError, match="did not write"):
        check_output(tmp_path / "other", "database", overwrite=True)
    # a damaged marker counts when the folder holds only what that kind of folder holds
    (tmp_path / "db" / "database.json").write_text("{ cut sh")
    assert check_output(tmp_path / "db", "database", overwrite=True) is True
    (tmp_path / "db" / "thesis.tex").write_text("mine")
    with pytest.raises(OutputError, match="did not write"):
        check_output(tmp_path / "db", "database", overwrite=True)


def test_files_are_recognised_by_their_markers(tmp_path):
    ours_npz = save_npz(tmp_path / "a.npz", motion=still())
    np.savez(tmp_path / "b.npz", positions=np.zeros(3))
    ours_bvh = write_bvh(tmp_path / "a.bvh", still())
    (tmp_path / "b.bvh").write_text("HIERARCHY\nROOT Hips\n{\n}\nMOTION\n")
    (tmp_path / "c.mp4").write_bytes(b"\0\0\0\x20ftypisom" + b"\0" * 100)
    assert check_output(ours_npz, "file", overwrite=True) and check_output(ours_bvh, "file", overwrite=True)
    for name in ("b.npz", "b.bvh", "c.mp4"):
        with pytest.raises(OutputError, match=f"{name}: is a file that gesturekit did not write"):
            check_output(tmp_path / name, "file", overwrite=True)
    # the exporters apply it: a foreign file survives overwrite=True
    before = (tmp_path / "b.npz").read_bytes()
    with pytest.raises(OutputError, match="did not write"):
        save_npz(tmp_path / "b.npz", motion=still(), overwrite=True)
    assert (tmp_path / "b.npz").read_bytes() == before
    save_npz(ours_npz, motion=still(seed=1), overwrite=True)  # its own output is replaced


def test_outputs_overlapping_inputs_are_refused(tmp_path):
    takes = tmp_path / "corpus" / "takes"
    takes.mkdir(parents=True)
    with pytest.raises(OutputError, match="is an input"):
        check_not_input(takes, [takes])
    with pytest.raises(OutputError, match="lies inside the input"):
        check_not_input(takes / "db", [takes])
    with pytest.raises(OutputError, match="contains the input"):
        check_not_input(tmp_path / "corpus", [takes])
    # the same folder by another spelling is still the same
    with pytest.raises(OutputError, match="is an input"):
        check_not_input(tmp_path / "corpus" / "." / "takes", [takes])
    check_not_input(tmp_path / "corpus" / "takes-db", [takes])  # a sibling with a common prefix is fine
    check_not_input(tmp_path / "db", [None, takes])


@settings(max_examples=60, deadline=None)
@given(
    a=st.lists(st.sampled_from("xyz"), min_size=1, max_size=4),
    b=st.lists(st.sampled_from("xyz"), min_size=1, max_size=4),
)
def test_overlap_means_one_path_is_a_prefix_of_the_other(tmp_path_factory, a, b):
    root = tmp_path_factory.getbasetemp() / "overlap"
    out, inp = root.joinpath(*a), root.joinpath(*b)
    overlaps = a[: len(b)] == b or b[: len(a)] == a
    if overlaps:
        with pytest.raises(OutputError):
            check_not_input(out, [inp])
    else:
        check_not_input(out, [inp])


# ---- locks --------------------------------------------------------------------------------------------


def test_a_second_writer_fails_at_once_naming_the_first(tmp_path):
    target = tmp_path / "db"
    with output_lock(target):
        assert (tmp_path / ".db.lock").read_text() == str(os.getpid())
        errors = []

        def second():
            try:
                with output_lock(target):
                    pass
            except OutputError as exc:
                errors.append(str(exc))

        t = threading.Thread(target=second)
        t.start()
        t.join(10)
        assert errors and f"another gesturekit process (pid {os.getpid()}) is writing" in errors[0]
        assert str(target) in errors[0]
    assert os.listdir(tmp_path) == []  # the lock file goes with the lock
    # a lock file a killed writer left is no obstacle
    (tmp_path / ".db.lock").write_text("999999")
    with output_lock(target):
        pass


# ---- stale temporaries --------------------------------------------------------------------------------


def test_stale_temporaries_of_dead_processes_are_removed(tmp_path):
    dead, alive = dead_pid(), os.getppid()
    (tmp_path / "db").mkdir()
    for name in (f".db.tmp-{dead}", f".db.old-{dead}", f".db.tmp-{alive}"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "F.npy").write_bytes(b"x")
    (tmp_path / f".out.npz.{dead}-0123abcd.tmp").write_bytes(b"half")
    (tmp_path / f".db.{alive}-0123abcd.tmp").write_bytes(b"busy")
    (tmp_path / ".dbx.tmp-1").mkdir()  # another output's
    removed = clean_stale(tmp_path / "db")
    assert sorted(p.name for p in removed) == sorted([f".db.tmp-{dead}", f".db.old-{dead}"])
    assert sorted(os.listdir(tmp_path)) == sorted(
        ["db", f".db.tmp-{alive}", f".out.npz.{dead}-0123abcd.tmp", f".db.{alive}-0123abcd.tmp", ".dbx.tmp-1"]
    )
    # an atomic write of out.npz removes its own kind of leftover
    atomic_write(tmp_path / "out.npz", lambda f: f.write(b"new"))
    assert not (tmp_path / f".out.npz.{dead}-0123abcd.tmp").exists()


def test_a_swap_cut_short_is_undone(tmp_path):
    # a writer died after moving the old folder aside and before moving the new one in
    dead = dead_pid()
    old = tmp_path / f".db.old-{dead}"
    old.mkdir()
    (old / "database.json").write_text("{}")
    (tmp_path / f".db.tmp-{dead}").mkdir()
    clean_stale(tmp_path / "db")
    assert os.listdir(tmp_path) == ["db"] and (tmp_path / "db" / "database.json").read_text() == "{}"


# ---- write errors --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "code, words",
    [
        (errno.ENOSPC, "the disk is full"),
        (errno.EACCES, "permission denied"),
        (errno.EROFS, "the file system is read-only"),
    ],
)
def test_write_errors_name_the_path_and_the_cause(tmp_path, monkeypatch, code, words):
    def refuse(*a, **k):
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(os, "replace", refuse)
    monkeypatch.setattr(os, "link", refuse)
    with pytest.raises(OutputError, match=f"out.bvh: cannot write: {words}"):
        write_bvh(tmp_path / "out.bvh", still())
    with pytest.raises(OutputError, match=f"rewrite.npz: cannot write: {words}"):
        atomic_write(tmp_path / "rewrite.npz", lambda f: f.write(b"x"), overwrite=True)
    monkeypatch.undo()
    assert os.listdir(tmp_path) == []  # no temporary file left


def test_a_database_save_on_a_full_disk_keeps_the_old_one(small_db, tmp_path, monkeypatch):
    small_db.save(tmp_path / "db")
    real = np.save

    def full(file, *a, **k):
        if "G" in os.path.basename(str(file)):
            raise OSError(errno.ENOSPC, "No space left on device", str(file))
        return real(file, *a, **k)

    monkeypatch.setattr(np, "save", full)
    with pytest.raises(OutputError, match=r"db: cannot write: the disk is full \(.*G\.npy\)"):
        small_db.save(tmp_path / "db", overwrite=True)
    monkeypatch.undo()
    assert os.listdir(tmp_path) == ["db"] and MatchingDatabase.load(tmp_path / "db").n_clips == small_db.n_clips


def test_write_folder_fills_a_temporary_folder_and_swaps_it_in(tmp_path):
    seen = []

    def fill(tmp):
        seen.append(tmp.name)
        (tmp / "study.json").write_text(json.dumps({"format": "gesturekit-study"}))

    (tmp_path / "s").mkdir()  # an empty folder is used
    write_folder(tmp_path / "s", "study", fill)
    assert seen == [f".s.tmp-{os.getpid()}"] and os.listdir(tmp_path) == ["s"]
    with pytest.raises(OutputError, match="already exists"):
        write_folder(tmp_path / "s", "study", fill)
    write_folder(tmp_path / "s", "study", fill, overwrite=True)

    def broken(tmp):
        (tmp / "half").write_text("x")
        raise GestureKitError("stopped")

    with pytest.raises(GestureKitError, match="stopped"):
        write_folder(tmp_path / "s", "study", broken, overwrite=True)
    assert os.listdir(tmp_path) == ["s"] and os.listdir(tmp_path / "s") == ["study.json"]


# ---- finite results only -------------------------------------------------------------------------------


def test_a_database_with_nan_is_not_written(small_db, tmp_path):
    arrays = dict(small_db.arrays)
    arrays["G"] = np.array(arrays["G"])
    arrays["G"][2, 10, 5] = np.nan
    bad = MatchingDatabase(
        meta=small_db.meta, arrays=arrays, stats=small_db.stats, audio=None, overlap=small_db.overlap
    )
    with pytest.raises(DatabaseError, match=r"db: the database's array G holds NaN or infinite values \(clip 2\)"):
        bad.save(tmp_path / "db")
    assert os.listdir(tmp_path) == []


def test_a_nan_motion_is_not_exported(tmp_path):
    m = still(4)
    m.positions[2, 0, 0] = np.inf
    with pytest.raises(GestureKitError, match="positions holds NaN or infinite values .from frame 2"):
        save_npz(tmp_path / "x.npz", motion=m)
    with pytest.raises(GestureKitError, match="not finite"):
        write_bvh(tmp_path / "x.bvh", m)
    assert os.listdir(tmp_path) == []


def test_a_refiner_that_yields_nan_is_named(tmp_path):
    from gesturekit.synthesis import SynthesisConfig, SynthesisResult

    knn = still(6)
    refined = Motion(np.full_like(knn.positions, np.nan), knn.fps)
    # the check comes before anything else of the result is used, so no search record is needed
    res = SynthesisResult(
        motion=refined,
        knn_motion=knn,
        search=None,
        audio=np.zeros(3200, np.float32),
        config=SynthesisConfig(),
        database="test",
        source="x.wav",
        refined_motion=refined,
    )
    for save, name in ((save_result_npz, "r.npz"), (save_result_bvh, "r.bvh"), (save_result_video, "r.mp4")):
        with pytest.raises(
            GestureKitError, match=f"{name}: not written: the refiner produced NaN or infinite positions .from frame 0"
        ):
            save(res, tmp_path / name)
    res.refined_motion, res.knn_motion = None, refined
    with pytest.raises(GestureKitError, match="the k-NN motion .poses read from the database"):
        save_result_npz(res, tmp_path / "k.npz")
    assert os.listdir(tmp_path) == []


# ---- fault tests: kill -9 in the middle ----------------------------------------------------------------

_BUILD = """
    import os, signal, sys
    import numpy as np
    from gesturekit.database import BuildConfig, MatchingDatabase
    from tests.conftest import make_take

    def build(seed):
        return MatchingDatabase.build([make_take(6.0, seed=seed, name="t")], config=BuildConfig(store_audio=False))
"""


def test_kill_during_a_database_save_keeps_the_previous_one(tmp_path):
    out = tmp_path / "db"
    run = run_script(
        _BUILD
        + """
    build(1).save(sys.argv[1])
    second = build(2)  # built before np.save dies: building stages its takes with np.save too
    real, calls = np.save, []

    def dying(*a, **k):
        calls.append(1)
        if len(calls) == 3:  # two arrays of the new database written, the rest not
            os.kill(os.getpid(), signal.SIGKILL)
        return real(*a, **k)

    np.save = dying
    second.save(sys.argv[1], overwrite=True)
    """,
        out,
    )
    assert run.returncode == -9, run.stderr
    left = sorted(os.listdir(tmp_path))
    # the killed writer's lock file and temporary folder stay behind, until the next writer
    assert len(left) == 3 and left[0] == ".db.lock" and left[1].startswith(".db.tmp-") and left[2] == "db", left
    first = MatchingDatabase.build([make_take(6.0, seed=1, name="t")], config=BuildConfig(store_audio=False))
    kept = MatchingDatabase.load(out)
    np.testing.assert_array_equal(kept.G, first.G)  # the previous database, intact
    second = MatchingDatabase.build([make_take(6.0, seed=2, name="t")], config=BuildConfig(store_audio=False))
    second.save(out, overwrite=True)
    assert os.listdir(tmp_path) == ["db"]  # the killed writer's temporary folder is gone
    np.testing.assert_array_equal(MatchingDatabase.load(out).G, second.G)


@pytest.mark.slow
def test_two_builds_to_one_folder_one_wins_the_other_says_so(tmp_path):
    from tests.badinput import assert_refused, run_cli, snapshot

    out, ready, go = tmp_path / "db", tmp_path / "ready", tmp_path / "go"
    first = subprocess.Popen(
        [
            sys.executable,
            "-c",
            textwrap.dedent("""
        import sys, time
        from pathlib import Path
        import gesturekit.datasets.synthetic as synthetic
        from gesturekit.cli import main
        from tests.conftest import make_take

        def takes(**kw):  # holds the lock until the test says go; then two tiny takes
            Path(sys.argv[2]).touch()
            while not Path(sys.argv[3]).exists():
                time.sleep(0.02)
            return [make_take(6.0, seed=1, name="a"), make_take(5.0, seed=2, name="b")]

        synthetic.generate_demo_takes = takes
        sys.exit(main(["build-db", "--demo", "--out", sys.argv[1]]))
        """),
            str(out),
            str(ready),
            str(go),
        ],
        cwd=REPO,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        wait_until(
            lambda: ready.exists() or first.poll() is not None, what="the first build holds the lock", timeout_s=300
        )
        assert ready.exists(), first.communicate()[1]
        before = snapshot(out)
        second = run_cli("build-db", "--demo", "--minutes", "0.1", "--out", out, "--force")
        assert_refused(
            second, names=out, problem=f"another gesturekit process (pid {first.pid}) is writing", before=before
        )
    finally:
        go.touch()
        _, err = first.communicate(timeout=patience(300))
    assert first.returncode == 0, err
    assert MatchingDatabase.load(out).take_names == ["a", "b"]
    assert sorted(os.listdir(tmp_path)) == ["db", "go", "ready"]


_TRAIN = """
    import os, signal, sys
    import gesturekit.refine.train as train
    from gesturekit.database import MatchingDatabase
    from gesturekit.refine.train import TrainConfig, train_refiner
    from tests.refine_helpers import TINY

    real, calls = train._save_torch, []

    def dying(path, obj):
        calls.append(path.name)
        if len(calls) == 5:  # the second checkpoint: generator.pt written, critic.pt not yet
            os.kill(os.getpid(), signal.SIGKILL)
        return real(path, obj)

    train._save_torch = dying
    db = MatchingDatabase.load(sys.argv[1])
    train_refiner(db, sys.argv[2], model=TINY, device="cpu",
                  train=TrainConfig(iterations=10, batch_size=4, checkpoint_every=4, log_every=2))
"""


@pytest.mark.slow
def test_kill_during_a_checkpoint_keeps_the_last_complete_one(small_db, tmp_path, monkeypatch):
    import gesturekit.refine.train as train_module
    from gesturekit.refine.infer import Refiner
    from gesturekit.refine.train import TrainConfig, train_refiner
    from tests.refine_helpers import TINY

    small_db.save(tmp_path / "db")
    db = MatchingDatabase.load(tmp_path / "db")
    cut = tmp_path / "cut"
    run = run_script(_TRAIN, tmp_path / "db", cut)
    assert run.returncode == -9, run.stderr
    assert any(n.startswith(".cut.tmp-") for n in os.listdir(tmp_path))
    cfg = json.loads((cut / "config.json").read_text())
    assert cfg["iteration"] == 4 and not cfg["complete"]
    Refiner.load(cut)  # synthesis can use it as it is
    torch.set_num_threads(1)

    def full(path, obj):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    # a full disk at the next checkpoint is a message, and the last complete checkpoint stays
    with monkeypatch.context() as m:
        m.setattr(train_module, "_save_torch", full)
        with pytest.raises(OutputError, match=r"/cut: cannot write: the disk is full \(.*generator\.pt\)"):
            train_refiner(db, cut, resume=True, device="cpu")
    assert json.loads((cut / "config.json").read_text())["iteration"] == 4
    resumed = train_refiner(db, cut, resume=True, device="cpu")
    straight = train_refiner(
        db,
        tmp_path / "straight",
        model=TINY,
        device="cpu",
        train=TrainConfig(iterations=10, batch_size=4, checkpoint_every=4, log_every=2),
    )
    a = torch.load(straight / "generator.pt", weights_only=True)
    b = torch.load(resumed / "generator.pt", weights_only=True)
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    assert sorted(os.listdir(tmp_path)) == ["cut", "db", "straight"]  # the temporary folder is cleaned up


def test_without_an_atomic_exchange_the_swap_uses_two_renames(tmp_path, monkeypatch):
    monkeypatch.setattr(outputs, "_exchange", lambda a, b: False)
    for n in (1, 2):
        write_folder(
            tmp_path / "s",
            "study",
            lambda tmp, n=n: (tmp / "study.json").write_text(json.dumps({"format": "gesturekit-study", "n": n})),
            overwrite=True,
        )
        assert json.loads((tmp_path / "s" / "study.json").read_text())["n"] == n
    assert os.listdir(tmp_path) == ["s"]


def test_a_dataset_bvh_is_not_taken_for_gesturekit_output(zeggs_files, tmp_path):
    bvh, _ = zeggs_files
    with pytest.raises(OutputError, match="is a file that gesturekit did not write"):
        check_output(bvh, "file", overwrite=True)


def test_the_folder_markers_are_those_the_writers_write():
    """outputs recognises folders by the markers declared in _io: the writers' own formats and files."""
    from gesturekit.database import folder as database_folder
    from gesturekit.evaluate import fgd
    from gesturekit.folders import FOLDER_KINDS
    from gesturekit.refine import folder

    assert FOLDER_KINDS["database"][:2] == ("database.json", database_folder.FORMAT)
    assert FOLDER_KINDS["refiner"][:2] == ("config.json", folder.FORMAT)
    assert FOLDER_KINDS["fgd"][1] == fgd._FORMAT


def test_a_folder_of_every_database_file_with_a_damaged_marker_is_recognised(tmp_path):
    """The names outputs recognises a database folder by include every name the folder format writes."""
    from gesturekit.database.folder import FOLDER_FILES
    from gesturekit.folders import folder_kind

    for name in FOLDER_FILES:
        if name == "overlap":
            (tmp_path / name).mkdir()
        else:
            (tmp_path / name).write_bytes(b"")
    (tmp_path / "database.json").write_text("{cut short", encoding="utf-8")
    assert folder_kind(tmp_path) == "database"
    (tmp_path / "notes.txt").write_text("mine", encoding="utf-8")
    assert folder_kind(tmp_path) is None
