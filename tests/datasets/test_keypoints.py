"""Tests of reading data of any shape: the keypoint layout (partial skeleton, Y down, noisy bones),
axes, units, derived joints, bone normalisation at build time."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from gesturekit.bones import bone_length_spread
from gesturekit.database import MatchingDatabase
from gesturekit.datasets.keypoint_example import (
    KEYPOINT_NAMES,
    keypoint_joint_map,
    keypoint_positions,
    write_keypoint_example,
)
from gesturekit.datasets.positions import read_positions_take
from gesturekit.datasets.takes import discover_takes
from gesturekit.errors import ConfigError, InputFileError, MotionFileError
from gesturekit.skeleton import DERIVABLE_JOINTS, DERIVED, JOINT_NAMES, RECORDED, joint_index
from gesturekit.workspace import build_database
from tests.badinput import assert_refused, run_cli, snapshot

SECONDS = 6.0  # 90 frames: one clip per take
DERIVED_HERE = tuple(n for n in DERIVABLE_JOINTS if n != "neck")


@pytest.fixture(scope="module")
def examples(tmp_path_factory) -> dict[str, Path]:
    """The keypoint layout written once in each format (two short takes)."""
    root = tmp_path_factory.mktemp("keypoints")
    out = {}
    for fmt in ("txt", "csv", "npy"):
        write_keypoint_example(root / fmt, fmt=fmt, takes=2, seconds=SECONDS, seed=4)
        out[fmt] = root / fmt
    return out


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def _rewrite(folder: Path, transform) -> None:
    """Apply ``transform`` to the (frames, 49, 3) positions of every .npy take in ``folder``."""
    for p in folder.glob("*.npy"):
        np.save(p, transform(np.load(p)))


def test_the_example_is_deterministic_and_has_the_layout(tmp_path, examples):
    write_keypoint_example(tmp_path / "again", fmt="npy", takes=2, seconds=SECONDS, seed=4)
    for name in ("take_00.npy", "take_01.wav", "joint_map.json"):
        assert (tmp_path / "again" / name).read_bytes() == (examples["npy"] / name).read_bytes()
    array = np.load(examples["npy"] / "take_00.npy")
    assert array.shape == (90, 49, 3) and len(KEYPOINT_NAMES) == 49
    np.testing.assert_array_equal(array[:, 0], 0.0)  # neck-relative
    lw, hand_root = KEYPOINT_NAMES.index("l_wrist"), KEYPOINT_NAMES.index("l_hand0")
    np.testing.assert_array_equal(array[:, lw], array[:, hand_root])  # the hand root repeats the wrist
    # image axes: the wrists hang below the neck, so their y is positive (y down)
    assert np.median(array[:, lw, 1]) > 0
    # noisy bones: the upper arm's length varies by a few per cent
    elbow, shoulder = KEYPOINT_NAMES.index("l_elbow"), KEYPOINT_NAMES.index("l_shoulder")
    upper = np.linalg.norm(array[:, elbow] - array[:, shoulder], axis=-1)
    assert 0.01 < upper.std() / upper.mean() < 0.06
    jmap = json.loads((examples["npy"] / "joint_map.json").read_text())
    assert jmap == json.loads(json.dumps(keypoint_joint_map())) and jmap["joints"]["head"] is None


def test_csv_takes_are_discovered(examples):
    sources = discover_takes(examples["csv"])
    assert [s.motion.name for s in sources] == ["take_00.csv", "take_01.csv"]
    assert all(s.kind == "positions" and s.audio is not None for s in sources)


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["txt", "csv", "npy"])
def test_database_builds_from_each_format_on_the_command_line(tmp_path, examples, fmt):
    folder = examples[fmt]
    out = tmp_path / "db"
    run = run_cli(
        "build-db", folder, "--joint-map", folder / "joint_map.json", "--fps", "15", "--up", "-y",
        "--normalize-bones", "--out", out,
    )  # fmt: skip
    assert run.code == 0, run.stderr
    assert "reading    up -y (given), forward -z (from the shoulders), units m (detected)" in run.stdout
    assert f"8 derived ({', '.join(DERIVED_HERE)})" in run.stdout
    assert "take_01: bone lengths normalised" in run.stdout
    db = MatchingDatabase.load(out)
    assert db.joint_presence.names(DERIVED) == DERIVED_HERE
    assert len(db.joint_presence.names(RECORDED)) == 47 and not db.joint_presence.names("absent")
    info = run_cli("info", out)
    assert info.code == 0 and "reading    up -y (given)" in info.stdout


def test_python_build_gives_an_upright_body_with_derived_torso_and_head(tmp_path, examples):
    folder = examples["npy"]
    db = build_database(
        folder, tmp_path / "db", joint_map=folder / "joint_map.json", fps=15, up="-y", normalize_bones=True
    )
    saved = MatchingDatabase.load(tmp_path / "db")
    assert saved.joint_presence == db.joint_presence
    assert saved.joint_presence.names(DERIVED) == DERIVED_HERE
    g = np.asarray(saved.arrays["G"]).reshape(-1, 55, 3)
    y = {n: g[:, joint_index(n), 1] for n in ("head_top", "head", "neck", "chest", "spine_mid", "left_wrist")}
    assert (y["head_top"] > y["head"]).all() and (y["head"] > y["neck"]).all()
    assert (y["neck"] > y["chest"]).all() and (y["chest"] > y["spine_mid"]).all()
    assert np.median(y["left_wrist"]) < np.median(y["neck"])  # hands hang below the neck: upright
    # the character faces +Z: its left shoulder is on +X
    assert np.median(g[:, joint_index("left_shoulder"), 0] - g[:, joint_index("right_shoulder"), 0]) > 0.2
    reading = saved.meta["takes"][0]["sources"]["reading"]
    assert "up -y (given)" in reading and "bone lengths normalised" in reading


def test_normalised_bones_are_constant_and_the_change_reported(examples):
    folder = examples["txt"]
    kwargs = {"joint_map": folder / "joint_map.json", "fps": 15, "up": "-y"}
    motion, reading = read_positions_take(folder / "take_00.txt", **kwargs)
    before = bone_length_spread(motion.positions, motion.presence)
    assert before.max() > 0.005  # the upper arms vary by about 3 %
    from gesturekit.datasets._reading import normalise_motion

    fixed, after_reading = normalise_motion(motion, reading)
    assert bone_length_spread(fixed.positions, fixed.presence).max() < 1e-5
    assert after_reading.bones and "normalised" in after_reading.bones
    assert "spread (standard deviation over the frames) before" in after_reading.bones
    assert fixed.presence == motion.presence


def test_unmapped_fingers_are_absent_and_sit_on_their_parent(examples):
    folder = examples["npy"]
    jmap = keypoint_joint_map()
    for finger in ("left_thumb3", "left_thumb4", "right_ring4"):
        del jmap["joints"][finger]
    motion, reading = read_positions_take(folder / "take_00.npy", joint_map=jmap, fps=15, up="-y")
    assert motion.presence.names("absent") == ("left_thumb3", "left_thumb4", "right_ring4")
    p = motion.positions
    np.testing.assert_array_equal(p[:, joint_index("left_thumb4")], p[:, joint_index("left_thumb2")])
    np.testing.assert_array_equal(p[:, joint_index("right_ring4")], p[:, joint_index("right_ring3")])
    assert "3 absent (left_thumb3, left_thumb4, right_ring4)" in reading.text()


def test_an_unmapped_neck_is_the_mid_shoulder_point(examples):
    jmap = keypoint_joint_map()
    jmap["joints"]["neck"] = None
    motion, _ = read_positions_take(examples["npy"] / "take_00.npy", joint_map=jmap, fps=15, up="-y")
    p = motion.positions
    mid = 0.5 * (p[:, joint_index("left_shoulder")] + p[:, joint_index("right_shoulder")])
    np.testing.assert_allclose(p[:, joint_index("neck")], mid, atol=1e-6)
    assert "neck" in motion.presence.names(DERIVED)


@pytest.mark.parametrize("scale, unit", [(1.0, "m"), (100.0, "cm"), (1000.0, "mm")])
def test_units_auto_detects_metres_centimetres_millimetres(tmp_path, examples, scale, unit):
    folder = _copy(examples["npy"], tmp_path / "t")
    _rewrite(folder, lambda a: a * scale)
    kwargs = {"joint_map": folder / "joint_map.json", "fps": 15, "up": "-y"}
    motion, reading = read_positions_take(folder / "take_00.npy", **kwargs)
    assert reading.units == unit and not reading.units_given
    metres, _ = read_positions_take(examples["npy"] / "take_00.npy", **kwargs, units="m")
    np.testing.assert_allclose(motion.positions, metres.positions, atol=1e-4)


@pytest.mark.parametrize("scale", [1e5, 0.01])
def test_units_auto_refuses_a_body_of_no_human_size(tmp_path, examples, scale):
    folder = _copy(examples["npy"], tmp_path / "t")
    _rewrite(folder, lambda a: a * scale)
    with pytest.raises(MotionFileError, match="--units") as info:
        read_positions_take(folder / "take_00.npy", joint_map=folder / "joint_map.json", fps=15, up="-y")
    assert "take_00.npy" in str(info.value)


@pytest.mark.slow
def test_units_mm_is_accepted_on_the_command_line(tmp_path, examples):
    folder = _copy(examples["npy"], tmp_path / "t")
    _rewrite(folder, lambda a: a * 1000.0)
    run = run_cli(
        "build-db", folder, "--joint-map", folder / "joint_map.json", "--fps", "15", "--up", "-y", "--units", "mm",
        "--out", tmp_path / "db",
    )  # fmt: skip
    assert run.code == 0, run.stderr
    assert "units mm (given)" in run.stdout


# ---- bad input: refused on the command line, naming the file or option and the problem -------------------


def _lying(a: np.ndarray) -> np.ndarray:
    """Image axes (y down, z away) turned so that z is up: lying data."""
    return a @ np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]).T  # y_new = z, z_new = -y: up (-y) -> z


def _map_without(folder: Path, *names: str) -> Path:
    jmap = keypoint_joint_map()
    for n in names:
        jmap["joints"].pop(n)
    path = folder / "joint_map.json"
    path.write_text(json.dumps(jmap))
    return path


@pytest.mark.parametrize(
    "change, extra, named, problem",
    [
        # the raw Y-down data without --up: refused, naming --up and suggesting -y
        (None, [], "take_00.npy", "pass --up -y"),
        # lying data (Z up) without --up: refused, suggesting z
        (_lying, [], "take_00.npy", "pass --up z"),
        # no plausible human size in any unit
        (lambda a: a * 1e5, ["--up", "-y"], "take_00.npy", "--units"),
        # a forward axis along the up axis
        (None, ["--up", "-y", "--forward", "y"], "--forward", "along the up axis"),
    ],
    ids=["y-down-without-up", "lying-z-up", "units-nonsense", "forward-along-up"],
)
def test_keypoint_data_refused(tmp_path, examples, change, extra, named, problem):
    folder = _copy(examples["npy"], tmp_path / "t")
    if change is not None:
        _rewrite(folder, change)
    out = tmp_path / "db"
    before = snapshot(folder, out)
    run = run_cli("build-db", folder, "--joint-map", folder / "joint_map.json", "--fps", "15", *extra, "--out", out)
    assert_refused(run, names=named if named.startswith("--") else folder / named, problem=problem, before=before)


@pytest.mark.parametrize(
    "lacks, needs",
    [
        (("left_wrist",), ("the hand controls needs left_wrist", "the pose feature of the matching needs left_wrist")),
        (("right_pinky1", "left_elbow"), ("the pose feature of the matching needs left_elbow, right_pinky1",)),
        (("right_shoulder",), ("placing the arms on the body (views, BVH, the derived torso) needs right_shoulder",)),
    ],
)
def test_a_map_without_required_joints_is_refused_listing_them_per_need(tmp_path, examples, lacks, needs):
    folder = _copy(examples["npy"], tmp_path / "t")
    jmap = _map_without(folder, *lacks)
    out = tmp_path / "db"
    before = snapshot(folder, out)
    run = run_cli("build-db", folder, "--joint-map", jmap, "--fps", "15", "--up", "-y", "--out", out)
    assert_refused(run, names=jmap, problem="joints gesturekit needs are not mapped", before=before)
    for need in needs:
        assert need in run.stderr


def test_required_joints_given_as_null_are_missing_too(examples):
    jmap = keypoint_joint_map()
    jmap["joints"]["left_wrist"] = None
    with pytest.raises(ConfigError, match="the hand controls needs left_wrist"):
        read_positions_take(examples["npy"] / "take_00.npy", joint_map=jmap, fps=15, up="-y")


def test_bad_axis_options_are_refused_before_reading(examples):
    path = examples["npy"] / "take_00.npy"
    for kwargs, word in [({"up": "x"}, "--up"), ({"forward": "w"}, "--forward"), ({"units": "ft"}, "--units")]:
        with pytest.raises(ConfigError, match=word):
            read_positions_take(path, joint_map=keypoint_joint_map(), fps=15, **kwargs)
    with pytest.raises(InputFileError, match="joint map file not found"):
        read_positions_take(path, joint_map=examples["npy"] / "none.json", fps=15)


def test_keypoint_positions_of_every_joint_name(examples):
    """The layout's columns are our joints in image axes (x = our x, y = -our y, z = -our z), neck-relative."""
    rng = np.random.default_rng(0)
    ours = rng.normal(size=(3, len(JOINT_NAMES), 3))
    out = keypoint_positions(ours, seed=0, noise=0.0)
    neck = ours[:, joint_index("neck")]
    for col, name in ((0, "neck"), (KEYPOINT_NAMES.index("r_elbow"), "right_elbow"), (48, "right_pinky4")):
        want = (ours[:, joint_index(name)] - neck) * np.array([1.0, -1.0, -1.0])
        np.testing.assert_allclose(out[:, col], want, atol=1e-12)


def test_axes_are_refused_for_habibie2021_takes(tmp_path):
    from tests.datasets.test_habibie2021 import make

    folder = tmp_path / "npz"
    folder.mkdir()
    wav, body, mfcc = make(n_seq=1)
    np.savez(folder / "a.npz", wav=wav, body=body, mfcc=mfcc)
    out = tmp_path / "db"
    before = snapshot(folder, out)
    run = run_cli("build-db", folder, "--kind", "habibie2021", "--up", "-z", "--out", out)
    assert_refused(run, names="--up", problem="not the habibie2021 kind", before=before)


def test_negative_axes_are_read_as_values_on_the_command_line():
    from gesturekit.cli._parser import build_parser, join_axis_values

    assert join_axis_values(["synthesize", "--out", "-y"]) == ["synthesize", "--out", "-y"]  # only --up, --forward
    argv = join_axis_values(["build-db", "f", "--up", "-z", "--forward", "-x", "--out", "db"])
    assert argv == ["build-db", "f", "--up=-z", "--forward=-x", "--out", "db"]
    args = build_parser().parse_args(argv)
    # --units not given: None (auto, or with --append the database's)
    assert (args.up, args.forward, args.units, args.normalize_bones) == ("-z", "-x", None, False)


@pytest.mark.slow
def test_the_guide_keypoint_example_runs_as_written(tmp_path, monkeypatch):
    import re
    import shlex

    from gesturekit.datasets import keypoint_example

    guide = (Path(__file__).resolve().parents[2] / "docs" / "guides" / "databases.md").read_text(encoding="utf-8")
    section = guide[guide.index("## Joint-position files") : guide.index("## Habibie et al. 2021")]
    block = re.search(r"```bash\n(python -m gesturekit\.datasets\.keypoint_example.*?)```", section, re.S)
    assert block, "the databases guide shows no keypoint example"
    monkeypatch.chdir(tmp_path)
    printed = []
    for line in block.group(1).splitlines():
        words = shlex.split(line.split("#")[0])
        if words[:3] == ["python", "-m", "gesturekit.datasets.keypoint_example"]:
            assert keypoint_example.main(words[3:]) == 0
        else:
            assert words[0] == "gesturekit", line
            run = run_cli(*words[1:])
            assert run.code == 0, run.stderr
            printed.append(run.stdout)
    assert "reading    up -y (given)" in printed[-1] and "bone lengths normalised" in printed[-1]
    assert MatchingDatabase.load(tmp_path / "db" / "kp").joint_presence.names(DERIVED) == DERIVED_HERE
