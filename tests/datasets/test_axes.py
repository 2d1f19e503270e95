"""Tests of gesturekit.datasets._axes: our frame from any up and forward axis, the upright check, units."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.datasets._axes import UP_CHOICES, auto_forward, axes_rotation, axis_vector, check_upright, detect_units
from gesturekit.datasets._reading import convert_and_complete
from gesturekit.datasets.bvh import read_bvh_take
from gesturekit.datasets.synthetic import generate_demo_take
from gesturekit.errors import ConfigError, MotionFileError
from gesturekit.skeleton import JOINT_NAMES
from tests.badinput import assert_refused, run_cli, snapshot

SIGNED = ("x", "-x", "y", "-y", "z", "-z")
ALL = np.ones(55, dtype=bool)
# keypoints lifted from video: no head (the upright check then goes by the upper arms)
HEADLESS = np.array([n not in ("neck_upper", "head", "head_top") for n in JOINT_NAMES])


# a demo take's positions (frames, 55, 3): upright, facing +Z
_DEMO = generate_demo_take(seconds=8.0, seed=11, name="t")[0].motion.positions.astype(np.float64)


def test_the_rotation_is_proper_and_left_is_up_cross_forward():
    for up in SIGNED:
        for fwd in SIGNED:
            if fwd.lstrip("-") == up.lstrip("-"):
                with pytest.raises(ConfigError, match="along the up axis"):
                    axes_rotation(up, fwd)
                continue
            r = axes_rotation(up, fwd)
            np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
            assert np.isclose(np.linalg.det(r), 1.0)
            np.testing.assert_allclose(r @ axis_vector(up), [0, 1, 0])
            np.testing.assert_allclose(r @ axis_vector(fwd), [0, 0, 1])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_demo_takes_pass_the_upright_check_and_face_plus_z(seed):
    take, _ = generate_demo_take(seconds=6.0, seed=seed, name="t")
    check_upright(take.motion.positions)
    assert auto_forward(take.motion.positions, "y") == "z"


def test_the_zeggs_take_passes_unchanged(zeggs_files):
    bvh, _ = zeggs_files
    motion, reading = read_bvh_take(bvh)
    assert reading.up == "y" and not reading.up_given and reading.forward == "z" and reading.units == "cm"
    plain, _ = read_bvh_take(bvh, up="y", forward="z", units="cm")
    np.testing.assert_array_equal(motion.positions, plain.positions)  # nothing turned


def _zeggs_turned_z_up(bvh, out, frames=40):
    """The ZEGGS take (first ``frames`` frames) with its whole body turned so that Z is up."""
    from scipy.spatial.transform import Rotation

    lines = bvh.read_text().splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.strip().startswith("Frame Time"))
    header = lines[: start - 1] + [f"Frames: {frames}", lines[start]]
    turn = Rotation.from_euler("X", 90, degrees=True)  # y -> z
    rows = []
    for ln in lines[start + 1 : start + 1 + frames]:
        v = np.array(ln.split(), dtype=np.float64)
        v[:3] = turn.apply(v[:3])  # Xposition Yposition Zposition
        rot = turn * Rotation.from_euler("ZYX", v[3:6], degrees=True)  # Zrotation Yrotation Xrotation
        v[3:6] = rot.as_euler("ZYX", degrees=True)
        rows.append(" ".join(f"{x:.6f}" for x in v))
    out.write_text("\n".join(header + rows) + "\n")
    return out


def test_a_z_up_bvh_is_refused_without_up_and_read_with_it(tmp_path, zeggs_files):
    bvh, wav = zeggs_files
    folder = tmp_path / "takes"
    folder.mkdir()
    turned = _zeggs_turned_z_up(bvh, folder / "take.bvh")
    (folder / "take.wav").symlink_to(wav)
    with pytest.raises(MotionFileError, match="pass --up z"):
        read_bvh_take(turned)
    motion, reading = read_bvh_take(turned, up="z")
    assert reading.up == "z" and reading.forward == "-y"  # the body faced +z, turned: -y
    plain, _ = read_bvh_take(bvh)
    np.testing.assert_allclose(motion.positions, plain.positions[: motion.n_frames], atol=1e-3)
    out = tmp_path / "db"
    before = snapshot(folder, out)
    assert_refused(run_cli("build-db", folder, "--out", out), names=turned, problem="pass --up z", before=before)


@settings(max_examples=40, deadline=None)
@given(up=st.sampled_from(SIGNED), fwd=st.sampled_from(SIGNED), give_forward=st.booleans(), head=st.booleans())
def test_an_axis_aligned_turn_is_refused_unless_up_is_y_and_read_back_with_the_matching_axes(
    up, fwd, give_forward, head
):
    """The body turned so that our up lies along ``up`` and our forward along ``fwd``, with or without a head."""
    if fwd.lstrip("-") == up.lstrip("-"):
        return
    turn = axes_rotation(up, fwd).T  # ours -> source
    source = _DEMO @ turn.T
    recorded = ALL if head else HEADLESS
    if up != "y":
        hint = f"pass --up {up}" if up in UP_CHOICES else "--up does not take"
        with pytest.raises(MotionFileError, match=hint):
            convert_and_complete(source, recorded, units="m", up=None, forward="auto")
    if up in UP_CHOICES:
        given_up = None if up == "y" else up
        back, reading = convert_and_complete(
            source, recorded, units="m", up=given_up, forward=fwd if give_forward else "auto"
        )
        assert reading.forward == fwd
        keep = recorded if not head else ALL  # the head is derived when the source has none
        np.testing.assert_allclose(back[:, keep], _DEMO[:, keep], atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(axis=st.tuples(*(st.floats(-1, 1),) * 3).filter(lambda v: np.linalg.norm(v) > 0.1), angle=st.floats(60, 180))
def test_a_body_with_a_head_tilted_by_60_degrees_or_more_is_refused(axis, angle):
    from scipy.spatial.transform import Rotation

    a = np.asarray(axis) / np.linalg.norm(axis)
    turn = Rotation.from_rotvec(np.deg2rad(angle) * a)
    # the tilt of the up axis itself, whatever the turn about it
    tilt = np.degrees(np.arccos(np.clip(turn.apply([0.0, 1.0, 0.0])[1], -1, 1)))
    if tilt < 60:
        return
    with pytest.raises(MotionFileError, match="does not stand upright"):
        check_upright(turn.apply(_DEMO.reshape(-1, 3)).reshape(_DEMO.shape))


@settings(max_examples=40, deadline=None)
@given(axis=st.tuples(*(st.floats(-1, 1),) * 3).filter(lambda v: np.linalg.norm(v) > 0.1), angle=st.floats(90, 180))
def test_a_headless_body_tilted_by_90_degrees_or_more_is_refused(axis, angle):
    """Without a head a lean is told from the upper arms, which often hang forward: lying and upside-down are
    refused, a lean of less than about 60 degrees may pass."""
    from scipy.spatial.transform import Rotation

    a = np.asarray(axis) / np.linalg.norm(axis)
    turn = Rotation.from_rotvec(np.deg2rad(angle) * a)
    if turn.apply([0.0, 1.0, 0.0])[1] > 0:  # the up axis itself tilted by less than 90 degrees
        return
    with pytest.raises(MotionFileError, match="does not stand upright"):
        check_upright(turn.apply(_DEMO.reshape(-1, 3)).reshape(_DEMO.shape), recorded=HEADLESS)


@settings(max_examples=20, deadline=None)
@given(yaw=st.floats(-180, 180), tilt=st.floats(0, 15))
def test_a_body_turned_about_up_or_slightly_tilted_passes(yaw, tilt):
    from scipy.spatial.transform import Rotation

    turn = Rotation.from_euler("YX", [yaw, tilt], degrees=True)
    check_upright(turn.apply(_DEMO.reshape(-1, 3)).reshape(_DEMO.shape))


@pytest.mark.parametrize("scale, unit", [(1.0, "m"), (100.0, "cm"), (1000.0, "mm")])
def test_detect_units(scale, unit):
    assert detect_units(_DEMO * scale) == unit


@pytest.mark.parametrize("scale", [0.001, 10.0, 1e4])
def test_detect_units_refuses_no_human_size(scale):
    with pytest.raises(MotionFileError, match="pass --units m, cm or mm"):
        detect_units(_DEMO * scale, path="body.npy")
