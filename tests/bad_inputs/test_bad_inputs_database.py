"""Bad-input suite: options that would silently corrupt a database. Appending with other reading
options, given units and axes that do not fit the data, a wrong frame rate, joint-map mistakes,
outlier frames, moved or edited take files, damaged statistics. Each case runs the command line
and expects a clean refusal: exit 2, the file or option named, the problem stated, no traceback,
nothing changed."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from gesturekit.datasets.keypoint_example import keypoint_joint_map, write_keypoint_example
from tests.badinput import assert_refused, run_cli, snapshot

pytestmark = pytest.mark.slow  # builds databases and runs the CLI end to end

SECONDS = 6.0  # 90 frames at 15 fps: one clip per take


@pytest.fixture(scope="module")
def kp_base(tmp_path_factory) -> Path:
    """Three keypoint takes (15 fps, metres, Y down, neck-rooted), their speech and joint map."""
    root = tmp_path_factory.mktemp("kp")
    write_keypoint_example(root, fmt="npy", takes=3, seconds=SECONDS, seed=4)
    return root


@pytest.fixture
def kp(kp_base, tmp_path) -> Path:
    """A per-test folder of two of the takes (take_02 kept aside in ``tmp_path / "more"``)."""
    folder = tmp_path / "takes"
    shutil.copytree(kp_base, folder)
    (tmp_path / "more").mkdir()
    for ext in (".npy", ".wav"):
        shutil.move(folder / f"take_02{ext}", tmp_path / "more" / f"take_02{ext}")
    return folder


def _kp_build(folder: Path, out: Path, *options: str, joint_map: Path | None = None):
    jmap = joint_map or folder / "joint_map.json"
    return run_cli("build-db", folder, "--joint-map", jmap, "--fps", "15", "--out", out, *options)


def _built(kp: Path, *options: str) -> Path:
    out = kp.parent / "db"
    run = _kp_build(kp, out, "--up", "-y", *options)
    assert run.code == 0, run.stderr
    for ext in (".npy", ".wav"):  # the third take joins the folder, to be appended
        shutil.copy2(kp.parent / "more" / f"take_02{ext}", kp / f"take_02{ext}")
    return out


def _rewrite(path: Path, transform) -> None:
    np.save(path, transform(np.load(path)))


# ---- 1. --append reads every take as the database did ------------------------------------------
@pytest.mark.parametrize(
    "option, value, recorded",
    [("--units", "m", "auto"), ("--units", "mm", "auto"), ("--forward", "x", "auto"), ("--up", "z", "-y")],
)
@pytest.mark.parametrize("keep", [False, True], ids=["recompute", "keep-stats"])
def test_append_with_other_reading_options_is_refused(kp, option, value, recorded, keep):
    out = _built(kp)
    before = snapshot(kp, out)
    run = run_cli("build-db", kp, "--out", out, "--append", f"{option}={value}", *(["--keep-stats"] if keep else []))
    assert_refused(run, names=option, problem=f"{option} is {value} here and {recorded} in the database", before=before)


def test_append_without_reading_options_reads_every_take_as_the_database_did(kp):
    out = _built(kp)
    run = run_cli("build-db", kp, "--out", out, "--append")  # no --up, --fps, --joint-map: the database's
    assert run.code == 0, run.stderr
    meta = json.loads((out / "database.json").read_text())
    assert [t["name"] for t in meta["takes"]] == ["take_00", "take_01", "take_02"]
    assert meta["build"]["reading"] == {
        "kind": "positions",
        "fps": 15.0,
        "units": "auto",
        "up": "-y",
        "forward": "auto",
        "normalize_bones": False,
    }
    assert all("up -y (given)" in t["sources"]["reading"] for t in meta["takes"])


# ---- 2. given units and axes are checked as detected ones are -----------------------------------
@pytest.mark.parametrize(
    "scale, options, problem",
    [
        (1.0, ["--up", "-y", "--units", "cm"], "pass --units m"),
        (1.0, ["--up", "-y", "--units", "mm"], "pass --units m"),
        (1000.0, ["--up", "-y", "--units", "m"], "pass --units mm"),
        (1.0, ["--up", "y"], "pass --up -y"),
        (1.0, ["--up", "z"], "pass --up -y"),
    ],
    ids=["cm-on-metres", "mm-on-metres", "m-on-mm", "up-y-on-y-down", "up-z-on-y-down"],
)
def test_given_units_and_up_that_do_not_fit_the_data_are_refused(kp, tmp_path, scale, options, problem):
    if scale != 1.0:
        for p in kp.glob("*.npy"):
            _rewrite(p, lambda a: a * scale)
    before = snapshot(kp, tmp_path / "db")
    run = _kp_build(kp, tmp_path / "db", *options)
    assert_refused(run, names=kp / "take_00.npy", problem=problem, before=before)
    assert "--no-plausibility-check" in run.stderr


def test_no_plausibility_check_reads_given_values_as_given(kp, tmp_path):
    for p in kp.glob("*.npy"):
        _rewrite(p, lambda a: a * 100)  # centimetres
    run = _kp_build(kp, tmp_path / "db", "--up", "-y", "--units", "mm", "--no-plausibility-check")
    assert run.code == 0, run.stderr
    assert "units mm (given)" in run.stdout


@pytest.fixture(scope="module")
def bvh_takes(tmp_path_factory) -> tuple[Path, Path]:
    """Two generated BVH takes (centimetres, Y up) with speech, and a joint map that reads them."""
    from gesturekit.skeleton import JOINT_NAMES
    from tests.database.test_database_build import write_takes

    root = tmp_path_factory.mktemp("bvh")
    jmap = root / "identity.json"
    jmap.write_text(json.dumps({"pelvis": JOINT_NAMES[0], "joints": {n: n for n in JOINT_NAMES}}))
    return write_takes(root / "takes", ["t000", "t001"], seconds=SECONDS), jmap


@pytest.mark.parametrize(
    "options, problem", [(["--units", "m"], "pass --units cm"), (["--up", "z"], "pass --up y")], ids=["m", "up-z"]
)
def test_given_units_and_up_that_do_not_fit_a_bvh_are_refused(bvh_takes, tmp_path, options, problem):
    folder, jmap = bvh_takes
    before = snapshot(folder, tmp_path / "db")
    run = run_cli("build-db", folder, "--joint-map", jmap, "--out", tmp_path / "db", *options)
    assert_refused(run, names=folder / "t000.bvh", problem=problem, before=before)


# ---- 3. motion and speech of different lengths --------------------------------------------------
def test_a_frame_rate_that_makes_motion_and_speech_disagree_is_refused(kp, tmp_path):
    before = snapshot(kp, tmp_path / "db")
    run = run_cli(
        "build-db", kp, "--joint-map", kp / "joint_map.json", "--fps", "30", "--up", "-y", "--out", tmp_path / "db"
    )
    assert_refused(run, names=kp / "take_00.npy", problem="at --fps 15 they would agree", before=before)
    assert "3.00 s and its speech 6." in run.stderr
    # accepted when asked (at 20 fps the motion, 4.5 s, still fills a clip)
    run = run_cli(
        "build-db", kp, "--joint-map", kp / "joint_map.json", "--fps", "20", "--up", "-y", "--out", tmp_path / "db",
        "--allow-duration-mismatch",
    )  # fmt: skip
    assert run.code == 0, run.stderr


# ---- 4. gesturekit info says what its numbers are ----------------------------------------------
def test_info_says_what_spread_is_and_where_hand_heights_are_measured_from(kp):
    out = kp.parent / "db"
    assert _kp_build(kp, out, "--up", "-y", "--normalize-bones").code == 0
    run = run_cli("info", out)
    assert run.code == 0, run.stderr
    assert "spread (standard deviation over the frames)" in run.stdout
    assert "hand heights are above the takes' root: the pelvis, or the neck on neck-rooted data" in run.stdout


# ---- 5. joint-map mistakes ---------------------------------------------------------------------
def _swap(jmap: dict, a: str, b: str) -> dict:
    jmap["joints"][a], jmap["joints"][b] = jmap["joints"][b], jmap["joints"][a]
    return jmap


@pytest.mark.parametrize(
    "change, problem",
    [
        (
            lambda m: {**m, "joints": {**m["joints"], "left_wrist": "r_wrist"}},
            "reads left_wrist and right_wrist from one source column",
        ),
        (lambda m: _swap(m, "left_elbow", "left_wrist"), "are they swapped?"),
        (lambda m: _swap(m, "right_elbow", "right_wrist"), "are they swapped?"),
        (lambda m: {**m, "pelvis": "l_wrist"}, "reads pelvis and left_wrist from one source column"),
    ],
    ids=["both-wrists-one-column", "left-elbow-wrist-swapped", "right-elbow-wrist-swapped", "pelvis-is-a-wrist"],
)
def test_joint_map_mistakes_are_refused(kp, tmp_path, change, problem):
    jmap = tmp_path / "map.json"
    jmap.write_text(json.dumps(change(keypoint_joint_map())))
    before = snapshot(kp, tmp_path / "db", jmap)
    run = _kp_build(kp, tmp_path / "db", "--up", "-y", joint_map=jmap)
    assert_refused(run, names=kp / "take_00.npy", problem=problem, before=before)
    assert "column" in run.stderr  # the source column is named


# ---- 6. outlier frames --------------------------------------------------------------------------
def _off(frames, joints=slice(None)):
    def move(a):
        a = a.copy()
        for f in frames:
            a[f, joints, 1] += 50.0
        return a

    return move


@pytest.mark.parametrize(
    "move, frames",
    [(_off([40]), "frame 40 "), (_off([40], 3), "frame 40 "), (_off([10, 11, 70], 6), "frame 10, 11, 70 ")],
    ids=["whole-frame", "one-joint", "three-frames"],
)
def test_frames_far_from_the_body_are_refused_by_number(kp, tmp_path, move, frames):
    _rewrite(kp / "take_01.npy", move)
    before = snapshot(kp, tmp_path / "db")
    run = _kp_build(kp, tmp_path / "db", "--up", "-y")
    assert_refused(run, names=kp / "take_01.npy", problem="far from the body", before=before)
    assert frames in run.stderr


# ---- 7. a label given with --append --keep-stats ------------------------------------------------
def test_append_keeping_statistics_takes_the_label_given(kp):
    out = _built(kp, "--label", "day 1")
    run = run_cli("build-db", kp, "--out", out, "--append", "--keep-stats", "--label", "days 1-2")
    assert run.code == 0, run.stderr
    assert json.loads((out / "database.json").read_text())["build"]["label"] == "days 1-2"


# ---- 8. take files recorded by absolute path, size and time --------------------------------------
def test_append_from_another_directory_reads_the_recorded_files(kp, monkeypatch):
    monkeypatch.chdir(kp.parent)
    run = run_cli(
        "build-db", "takes", "--joint-map", "takes/joint_map.json", "--fps", "15", "--up", "-y", "--out", "db"
    )
    assert run.code == 0, run.stderr
    meta = json.loads((kp.parent / "db" / "database.json").read_text())
    assert meta["takes"][0]["sources"]["motion"] == str(kp / "take_00.npy")
    elsewhere = kp.parent / "elsewhere"
    (elsewhere / "takes").mkdir(parents=True)  # a folder of the same name, holding other files
    shutil.copy2(kp.parent / "more" / "take_02.npy", elsewhere / "takes" / "take_00.npy")
    shutil.copy2(kp.parent / "more" / "take_02.wav", elsewhere / "takes" / "take_00.wav")
    monkeypatch.chdir(elsewhere)
    run = run_cli("build-db", kp.parent / "more", "--out", kp.parent / "db", "--append")
    assert run.code == 0, run.stderr
    assert "appended 1 takes to the database's 2" in run.stdout  # the recorded files, not ./takes/take_00.npy


def test_append_refuses_a_take_file_changed_since_the_build(kp):
    out = _built(kp)
    _rewrite(kp / "take_01.npy", lambda a: a * 1.01)
    before = snapshot(kp, out)
    run = run_cli("build-db", kp, "--out", out, "--append")
    assert_refused(run, names=kp / "take_01.npy", problem="has changed since", before=before)
    assert "'take_01'" in run.stderr


def test_append_reads_the_relative_paths_of_an_older_database_from_the_current_directory(kp, monkeypatch):
    out = _built(kp)
    meta = json.loads((out / "database.json").read_text())
    for t in meta["takes"]:  # as a build before absolute paths were recorded wrote them
        s = t["sources"]
        for key in ("motion", "audio"):
            s[key] = os.path.relpath(s[key], kp.parent)
            del s[f"{key}_stat"]
    (out / "database.json").write_text(json.dumps(meta))
    monkeypatch.chdir(kp.parent)
    run = run_cli("build-db", kp, "--out", out, "--append")
    assert run.code == 0, run.stderr
    meta = json.loads((out / "database.json").read_text())
    # every take read again, and now recorded by absolute path
    assert [t["sources"]["motion"] for t in meta["takes"]] == [str(kp / f"take_0{i}.npy") for i in range(3)]


# ---- 9. --keep-stats onto statistics that give non-finite features --------------------------------
def test_keep_stats_refuses_a_zero_standard_deviation(kp):
    out = _built(kp)
    with np.load(out / "stats.npz", allow_pickle=False) as npz:
        stats = {k: npz[k] for k in npz.files}
    stats["F_std"] = stats["F_std"].copy()
    stats["F_std"][3] = 0.0
    np.savez(out / "stats.npz", **stats)
    before = snapshot(kp, out)
    run = run_cli("build-db", kp, "--out", out, "--append", "--keep-stats")
    if "stats.npz" in run.stderr and "F_std" not in run.stderr:  # refused as the database is opened
        assert_refused(run, names="stats.npz", problem="", before=before)
    else:
        assert_refused(run, names="F_std", problem="non-finite features", before=before)
