"""Tests of the BVH export's error report, its fitted bone lengths and partial skeletons.

The report's numbers are checked against the file read back by the small
scipy reader of ``test_export_bvh`` (which shares no code with the writer or
with gesturekit's reader), and partial files are read back with gesturekit's own reader.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit.bones import fit_bone_lengths, normalise_bone_lengths
from gesturekit.datasets.bvh import forward_kinematics
from gesturekit.datasets.bvh_file import parse_bvh
from gesturekit.datasets.synthetic import generate_demo_take
from gesturekit.errors import ConfigError, GestureKitWarning
from gesturekit.export.bvh import ROTATION_ORDERS, WARN_ABOVE, BvhReport, export_bvh, write_bvh
from gesturekit.motion import Motion
from gesturekit.skeleton import DERIVABLE_JOINTS, JOINT_NAMES, N_JOINTS, PARENTS, JointPresence, joint_index
from tests.export.test_export_bvh import fk, poses, scipy_fk, smooth_motion

THUMBS = tuple(f"{side}_thumb{k}" for side in ("left", "right") for k in range(1, 5))
TORSO = tuple(n for n in DERIVABLE_JOINTS if n != "neck")  # derived from the neck and the shoulders


@pytest.fixture(scope="module")
def demo_positions():
    take, _ = generate_demo_take(seconds=8, seed=3, name="demo")
    return take.motion.positions.astype(np.float64)


def scaled_bones(positions, amount, seed=0):
    """Every bone's length scaled by a factor in [1 - amount, 1 + amount], frame by frame, directions kept."""
    rng = np.random.default_rng(seed)
    factor = 1.0 + rng.uniform(-amount, amount, (len(positions), N_JOINTS, 1))
    out = positions.copy()
    for j in np.flatnonzero(PARENTS >= 0):
        out[:, j] = out[:, PARENTS[j]] + (positions[:, j] - positions[:, PARENTS[j]]) * factor[:, j]
    return out


def collapsed(positions, presence):
    """Absent joints on their parent, as every reader places them."""
    out = positions.copy()
    for j in np.flatnonzero(presence.absent & (PARENTS >= 0)):
        out[:, j] = out[:, PARENTS[j]]
    return out


def independent_errors(path, positions, drawn, scale=100.0):
    """(frames, drawn joints) distance of the file's joints from ``positions``, metres, by the scipy reader."""
    world = scipy_fk(path)
    names = [JOINT_NAMES[j] for j in np.flatnonzero(drawn)]
    back = np.stack([world[n] for n in names], axis=1) / scale
    return np.linalg.norm(back - positions[:, drawn], axis=-1), names


def assert_report_matches_file(report: BvhReport, positions, drawn, scale=100.0):
    err, names = independent_errors(report.path, positions, drawn, scale)
    assert report.max_error == pytest.approx(err.max(), abs=1e-7)
    assert report.mean_error == pytest.approx(err.mean(), abs=1e-7)
    frame, k = np.unravel_index(int(np.argmax(err)), err.shape)
    if err.max() > 1e-4:  # the worst place is well defined only where errors are not rounding
        assert (report.worst_joint, report.worst_frame) == (names[k], int(frame))


def export_quietly(path, motion, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        report = export_bvh(path, motion, **kwargs)
    return report, [w for w in caught if issubclass(w.category, GestureKitWarning)]


# ----------------------------------------------------------------------------- varying bone lengths


def test_noisy_bone_lengths_are_reported_and_warned(tmp_path, demo_positions):
    noisy = scaled_bones(demo_positions, 0.04)
    report, caught = export_quietly(tmp_path / "noisy.bvh", Motion(noisy, 15))
    assert report.max_error > WARN_ABOVE and report.exceeds
    assert_report_matches_file(report, noisy, np.ones(N_JOINTS, bool))
    assert len(caught) == 1
    message = str(caught[0].message)
    assert "noisy.bvh" in message and "npz keeps the exact positions" in message
    assert "--normalize-bones" in message and f"{report.max_error * 100:.1f} cm" in message
    # one length per bone: the median, as bones.fit_bone_lengths
    np.testing.assert_allclose(report.bone_lengths, fit_bone_lengths(Motion(noisy, 15).positions), atol=1e-12)
    joints = {j["name"]: j for j in _hierarchy(report.path)}
    for j in np.flatnonzero(PARENTS >= 0):
        assert np.linalg.norm(joints[JOINT_NAMES[j]]["offset"]) / 100 == pytest.approx(report.bone_lengths[j], abs=1e-7)


def test_normalised_bone_lengths_reproduce_the_positions(tmp_path, demo_positions):
    normalised, _ = normalise_bone_lengths(scaled_bones(demo_positions, 0.04))
    report, caught = export_quietly(tmp_path / "normalised.bvh", Motion(normalised, 15))
    assert report.max_error < 1e-6 and not report.exceeds and not caught
    assert_report_matches_file(report, normalised, np.ones(N_JOINTS, bool))
    assert report.summary().startswith("normalised.bvh: position error max 0.00 mm")


def test_each_joint_is_off_by_about_its_own_bone(tmp_path, demo_positions):
    # bones are aimed from the file's joint at the data's: a joint's error is bounded by its own bone's
    # length change (plus what one rotation carrying several bones cannot follow), not the chain's sum
    noisy = scaled_bones(demo_positions, 0.02, seed=1)
    report = export_bvh(tmp_path / "n.bvh", Motion(noisy, 15))
    err, _ = independent_errors(report.path, noisy, np.ones(N_JOINTS, bool))
    along_data, _ = normalise_bone_lengths(noisy)
    chain = np.linalg.norm(along_data - noisy, axis=-1)  # aiming along the data's directions instead
    assert err.mean() < 0.7 * chain.mean()


def test_write_bvh_still_returns_the_path(tmp_path):
    path = write_bvh(tmp_path / "a.bvh", Motion(smooth_motion(4, seed=0), 15))
    assert path == tmp_path / "a.bvh" and path.read_text().startswith("HIERARCHY")


# ----------------------------------------------------------------------------- partial skeletons


def _hierarchy(path):
    from tests.export.test_export_bvh import parse_bvh as parse_independently

    return parse_independently(path)[0]


def test_partial_skeleton_torso_derived_thumbs_absent(tmp_path):
    presence = JointPresence.from_names(recorded=set(JOINT_NAMES) - set(THUMBS) - set(TORSO), derived=TORSO)
    positions = collapsed(smooth_motion(20, seed=2), presence)
    report, caught = export_quietly(tmp_path / "partial.bvh", Motion(positions, 15, presence))
    assert not caught and report.max_error < 1e-6
    assert report.root == "spine_mid" and set(report.left_out) == set(THUMBS)
    assert set(report.derived) == set(TORSO)
    summary = report.summary()
    assert "root at the derived spine_mid" in summary and "8 finger joints left out: left_thumb1" in summary
    assert "derived joints written: chest" in summary
    assert_report_matches_file(report, positions, presence.drawn)
    # gesturekit's own reader reads it back: the drawn joints, where the motion has them
    data = parse_bvh(report.path)
    joints = [n for n in data.names if not n.endswith("_End")]
    assert sorted(joints) == sorted(presence.names("recorded") + presence.names("derived"))
    world = forward_kinematics(data) / 100.0
    for name in joints:
        np.testing.assert_allclose(world[:, data.index(name)], positions[:, joint_index(name)], atol=1e-6)
    # the wrists carry the four other fingers' roots
    assert data.names[data.parents[data.index("left_index1")]] == "left_wrist"


def test_joint_whose_children_are_absent_ends_in_an_end_site(tmp_path):
    absent = {f"left_index{k}" for k in (2, 3, 4)} | {"head", "head_top"}
    presence = JointPresence.from_names(recorded=set(JOINT_NAMES) - absent)
    positions = collapsed(smooth_motion(6, seed=3), presence)
    report = export_bvh(tmp_path / "ends.bvh", Motion(positions, 15, presence))
    data = parse_bvh(report.path)
    for leaf in ("left_index1", "neck_upper"):
        end = data.index(f"{leaf}_End")
        assert data.parents[end] == data.index(leaf) and np.linalg.norm(data.offsets[end]) > 0
    assert "left_index2" not in data.names and report.max_error < 1e-6
    assert report.summary().count("left out") == 1 and "5 joints left out" in report.summary()


def _neck_layout_positions(n_frames, seed):
    """Upper body of a keypoint layout: the neck and both shoulders rigid on the upper chest."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames)[:, None, None] / 15.0
    rv = 0.6 * np.sin(2 * np.pi * rng.uniform(0.1, 0.6, (1, N_JOINTS, 3)) * t + rng.uniform(0, 6, (1, N_JOINTS, 3)))
    for name in ("neck", "left_collar", "right_collar"):
        rv[:, joint_index(name)] = 0.0
    return fk(np.zeros((n_frames, 3)), rv)


def test_neck_rooted_skeleton_without_torso(tmp_path):
    # the lifted-keypoint layout: neck, arms and hands; nothing of the torso or head
    recorded = set(JOINT_NAMES) - set(DERIVABLE_JOINTS) | {"neck"}
    presence = JointPresence.from_names(recorded=recorded)
    positions = collapsed(_neck_layout_positions(15, seed=4), presence)
    report = export_bvh(tmp_path / "neck.bvh", Motion(positions, 15, presence))
    assert report.root == "neck" and "root at neck" in report.summary()
    assert set(report.left_out) == set(DERIVABLE_JOINTS) - {"neck"}
    assert report.max_error < 1e-6
    data = parse_bvh(report.path)
    assert data.names[0] == "neck" and data.parents[0] == -1
    assert data.names[data.parents[data.index("left_shoulder")]] == "neck"
    assert data.names[data.parents[data.index("right_shoulder")]] == "neck"
    assert_report_matches_file(report, positions, presence.drawn)


@pytest.mark.parametrize(
    "absent,names",
    [
        (("spine_mid",), ["chest", "not connected to the root neck"]),
        (("spine_mid", "neck"), ["spine_mid or the neck", "neither is drawn"]),
    ],
)
def test_disconnected_skeleton_is_refused(tmp_path, absent, names):
    presence = JointPresence.from_names(recorded=set(JOINT_NAMES) - set(absent))
    positions = collapsed(smooth_motion(3, seed=5), presence)
    target = tmp_path / "cut.bvh"
    with pytest.raises(ConfigError) as info:
        export_bvh(target, Motion(positions, 15, presence))
    assert str(target) in str(info.value) and all(n in str(info.value) for n in names)
    assert not target.exists()


# ----------------------------------------------------------------------------- property


@settings(
    max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(
    pos=poses(), order=st.sampled_from(ROTATION_ORDERS), units=st.sampled_from(["cm", "m"]), decimals=st.integers(4, 8)
)
def test_constant_bone_lengths_reproduce_to_the_written_precision(tmp_path, pos, order, units, decimals):
    report, caught = export_quietly(
        tmp_path / "c.bvh", Motion(pos, 15), rotation_order=order, units=units, decimals=decimals, overwrite=True
    )
    assert not caught
    # the offsets and root carry the printed precision, every angle 0.5e-decimals degrees on arms under 1 m;
    # a Motion holds float32, whose rounding makes bone lengths vary by a few 1e-8 m
    bound = 30 * report.precision + 20 * np.radians(0.5 * 10.0**-decimals) + 2e-7
    assert report.max_error <= bound
    assert_report_matches_file(report, pos, np.ones(N_JOINTS, bool), scale={"cm": 100.0, "m": 1.0}[units])


# ----------------------------------------------------------------------------- the command line


def _cli_world(root, presence=None, *, demo=False):
    """A small database (of demo takes, rigid bones, or of random walks, bones of any length) and a speech file."""
    import soundfile as sf

    from gesturekit.database import BuildConfig, MatchingDatabase
    from gesturekit.motion import Take
    from tests.conftest import make_take

    if demo:
        takes = [generate_demo_take(seconds=9.0, seed=s, name=f"t{s}")[0] for s in (1, 2)]
    else:
        takes = [make_take(9.0, seed=1, name="a"), make_take(6.0, seed=2, name="b")]
    if presence is not None:
        takes = [
            Take(t.name, Motion(collapsed(t.motion.positions, presence), t.motion.fps, presence), t.audio, t.sources)
            for t in takes
        ]
    MatchingDatabase.build(takes, config=BuildConfig(overlap_stride=16, store_audio=False)).save(root / "db")
    sf.write(root / "speech.wav", make_take(3.0, seed=4).audio, 16000, subtype="PCM_16")
    return root / "db", root / "speech.wav"


def _bvh_line(stdout):
    lines = [line.strip() for line in stdout.splitlines() if line.strip().startswith("BVH ")]
    assert len(lines) == 1, stdout
    return lines[0]


def test_cli_prints_the_report_and_warns(tmp_path):
    from tests.badinput import run_cli

    db, speech = _cli_world(tmp_path)
    out = tmp_path / "out"
    # (in this process the warning goes to pytest; run as a command it is a "warning: ..." line)
    with pytest.warns(GestureKitWarning, match="npz keeps the exact positions") as caught:
        run = run_cli("synthesize", speech, "--db", db, "--out", out, "--refiner", "none")
    assert run.code == 0, run.stderr
    line = _bvh_line(run.stdout)
    assert line.startswith("BVH speech.bvh: position error max ")
    # the numbers printed are those of the file against the npz's exact positions
    from gesturekit.export.npz import load_npz

    positions = load_npz(out / "speech.npz")[0].positions.astype(np.float64)
    err, _ = independent_errors(out / "speech.bvh", positions, np.ones(N_JOINTS, bool))
    assert f"max {err.max() * 1000:.2f} mm" in line and f"mean {err.mean() * 1000:.2f} mm" in line
    assert err.max() > WARN_ABOVE  # these takes' bones have any length: the warning is due
    message = str(caught[0].message)
    assert "speech.bvh" in message and "--normalize-bones" in message


def test_cli_partial_skeleton_says_what_it_wrote(tmp_path):
    from tests.badinput import run_cli

    presence = JointPresence.from_names(recorded=set(JOINT_NAMES) - set(THUMBS) - set(TORSO), derived=TORSO)
    db, speech = _cli_world(tmp_path, presence, demo=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error", GestureKitWarning)  # rigid bones: nothing to warn about
        run = run_cli("synthesize", speech, "--db", db, "--out", tmp_path / "out", "--refiner", "none")
    assert run.code == 0, run.stderr
    line = _bvh_line(run.stdout)
    assert "root at the derived spine_mid; 8 finger joints left out: left_thumb1" in line
    names = parse_bvh(tmp_path / "out" / "speech.bvh").names
    assert not set(THUMBS) & set(names) and "left_index4_End" in names


# ----------------------------------------------------------------------------- the app


@pytest.mark.slow
def test_app_shows_the_report_beside_the_download(app_env):
    from tests.app.test_app_synthesize import open_page, result, speech_file, upload
    from tests.conftest import shown

    at = upload(open_page(), speech_file(3.0))
    if at.toggle(key="_w.synth.refine").value:
        at.toggle(key="_w.synth.refine").set_value(False).run()
    at.button(key="synth.go").click().run()
    assert not at.exception and not at.error
    captions = [shown(c.value) for c in at.caption]
    data, report = gs_export(result(at))
    assert [c for c in captions if c.startswith("BVH ")] == [f"BVH {report.summary()}"]
    assert data.startswith(b"HIERARCHY") and any(d.proto.label == "Motion (BVH)" for d in at.get("download_button"))
    over = [w.value for w in at.warning if "BVH file is up to" in w.value]  # (the glTF file has its own)
    assert len(over) == int(report.exceeds)


def gs_export(res):
    from gesturekit import interactive as gs

    return gs.export_bvh_bytes(res, gs.export_filename(res, "bvh"))


@pytest.mark.parametrize(
    "absent,problem",
    [
        (("spine_mid", "neck"), "a BVH needs spine_mid or the neck as its root, and neither is drawn"),
        (("spine_mid",), "the drawn joints do not form one tree: chest"),
    ],
)
def test_cli_refuses_a_skeleton_no_bvh_can_hold_before_writing(tmp_path, absent, problem):
    from tests.badinput import assert_refused, run_cli, snapshot

    presence = JointPresence.from_names(recorded=set(JOINT_NAMES) - set(absent))
    db, speech = _cli_world(tmp_path, presence)
    out = tmp_path / "out"
    before = snapshot(tmp_path)
    run = run_cli("synthesize", speech, "--db", db, "--out", out, "--refiner", "none")
    assert_refused(run, names=db, problem=problem, before=before)
