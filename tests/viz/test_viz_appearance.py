"""The one appearance: every bone becomes a shape, derived points sit where the body is, one light rule."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

from gesturekit.errors import ConfigError
from gesturekit.skeleton import N_JOINTS, bones, joint_index
from gesturekit.viz.appearance import APPEARANCE, DERIVED_POINTS, Appearance, hex_to_rgb, rgb_to_hex


def _positions(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (rng.normal(0, 0.3, (1, N_JOINTS, 3)) + np.cumsum(rng.normal(0, 0.01, (n, N_JOINTS, 3)), 0)).astype(
        np.float32
    )


def test_every_bone_is_a_capsule_or_inside_a_sphere_and_nothing_else_points_nowhere():
    caps, spheres = APPEARANCE.shapes()
    drawn = {frozenset((c.a, c.b)) for c in caps} | {frozenset(b) for s in spheres for b in s.covers}
    for child, parent in bones():
        assert frozenset((int(child), int(parent))) in drawn
    n_points = N_JOINTS + len(DERIVED_POINTS)
    assert all(0 <= c.a < n_points and 0 <= c.b < n_points and c.radius > 0 for c in caps)
    assert {c.part for c in caps} == {"torso", "neck", "upper_arm", "forearm", "palm", "finger"}
    assert [s.part for s in spheres] == ["head"]


@settings(max_examples=25, deadline=None)
@given(hst.integers(1, 40), hst.integers(0, 10**6))
def test_body_keeps_the_joints_and_derives_pelvis_hips_and_head_centre(n, seed):
    p = _positions(n, seed)
    shapes = APPEARANCE.body(p)
    assert shapes.points.shape == (n, N_JOINTS + len(DERIVED_POINTS), 3) and shapes.points.dtype == np.float32
    np.testing.assert_array_equal(shapes.points[:, :N_JOINTS], p)
    pelvis, lhip, rhip, head_c, lchest, rchest = (shapes.points[:, N_JOINTS + i].astype(np.float64) for i in range(6))
    # the hips straddle the pelvis, hip_half_width either side
    np.testing.assert_allclose((lhip + rhip) / 2, pelvis, atol=1e-5)
    assert np.allclose(np.linalg.norm(lhip - pelvis, axis=1), APPEARANCE.hip_half_width, atol=1e-5)
    chest, upper = p[:, joint_index("chest")].astype(np.float64), p[:, joint_index("upper_chest")]
    mid = chest + (upper - chest) * APPEARANCE.chest_height
    np.testing.assert_allclose((lchest + rchest) / 2, mid, atol=1e-5)
    head, top = p[:, joint_index("head")], p[:, joint_index("head_top")]
    np.testing.assert_allclose(head_c, head + (top - head) * APPEARANCE.head_centre, atol=1e-5)
    lo, hi = APPEARANCE.bounds(shapes.points)
    assert np.all(shapes.points >= lo) and np.all(shapes.points <= hi)
    assert APPEARANCE.ground_height(shapes.points) < shapes.points[..., 1].min()


@settings(max_examples=30, deadline=None)
@given(hst.lists(hst.floats(-1, 1), min_size=3, max_size=3).filter(lambda v: np.linalg.norm(v) > 0.1))
def test_shading_is_lambert_with_ambient_and_brightest_facing_the_light(v):
    n = np.asarray(v) / np.linalg.norm(v)
    color = "#c0502d"
    got = APPEARANCE.shade(color, n)
    k = min(1.0, APPEARANCE.ambient + APPEARANCE.diffuse * max(0.0, float(n @ APPEARANCE.light())))
    np.testing.assert_allclose(got, hex_to_rgb(color) * k)
    assert np.all(got <= APPEARANCE.shade(color, APPEARANCE.light()) + 1e-12)


def test_colours_follow_the_app_and_tints_lighten():
    assert APPEARANCE.color(0) == "#2c5d8f" and APPEARANCE.color(1) == "#c0502d"
    assert APPEARANCE.color(len(APPEARANCE.motion_colors)) == APPEARANCE.color(0)
    assert hex_to_rgb(APPEARANCE.part_color(0, "head")).sum() > hex_to_rgb(APPEARANCE.color(0)).sum()
    assert APPEARANCE.part_color(1, "forearm") == APPEARANCE.color(1)
    assert rgb_to_hex(hex_to_rgb("#0a1b2c")) == "#0a1b2c"


@pytest.mark.parametrize("shape", [(10, 54, 3), (55, 3), (0, 55, 3), (4, 55, 2)])
def test_body_refuses_positions_of_another_shape(shape):
    with pytest.raises(ConfigError, match="positions must have shape"):
        Appearance().body(np.zeros(shape))
