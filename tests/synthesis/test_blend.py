"""The joins between search segments (gesturekit.blend) and the bones blended motion is given back."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.blend import BLEND_MODES, DEFAULT_BLEND, blend_segment, blend_segments
from gesturekit.bones import bones_like, group_frames
from gesturekit.errors import ConfigError
from gesturekit.skeleton import PARENTS

SMOOTH = ("inertialize", "dead")


def _literal(g: np.ndarray, cuts: list[int], mode: str, halflife: float) -> np.ndarray:
    """The modes written out frame by frame from their definitions (the plain reference)."""
    out = np.array(g, np.float64)
    ends = [*cuts[1:], len(out)]
    for b, e in zip(cuts, ends):
        if b < 2 or b >= len(out):
            continue
        p1, p0 = out[b - 1].copy(), out[b - 2].copy()
        v = p1 - p0
        v_seg = out[b + 1] - out[b] if e - b > 1 else np.zeros_like(v)
        x0, v0 = p1 + v - out[b], v - v_seg
        for f in range(b, e):
            k = f - b
            if mode == "inertialize":
                y = 1.6783469900166608 / halflife
                out[f] = out[f] + (x0 + (v0 + y * x0) * k) * np.exp(-y * k)
            else:
                t = k + 1
                lam = np.log(2.0) / halflife
                ext = p1 + v * (1 - np.exp(-lam * t)) / lam
                u = min(max(t / (2 * halflife), 0.0), 1.0)
                w = u * u * (3 - 2 * u)
                out[f] = (1 - w) * ext + w * out[f]
    return out


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    n=st.integers(3, 60),
    segment=st.integers(1, 12),
    mode=st.sampled_from(SMOOTH),
    halflife=st.floats(0.3, 6.0),
)
def test_blends_equal_their_literal_definitions(seed, n, segment, mode, halflife):
    g = np.random.default_rng(seed).normal(size=(n, 4)).cumsum(axis=0)
    cuts = list(range(segment, n, segment))
    got = blend_segments(g, np.array(cuts, dtype=np.int64), mode=mode, halflife=halflife)
    np.testing.assert_allclose(got, _literal(g, cuts, mode, halflife), rtol=1e-12, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(
    v=st.lists(st.floats(-2, 2), min_size=3, max_size=3),
    n=st.integers(3, 40),
    mode=st.sampled_from(BLEND_MODES),
    halflife=st.floats(0.3, 6.0),
)
def test_motion_without_a_jump_passes_unchanged(v, n, mode, halflife):
    # a straight line at a constant velocity has nothing to smooth at any join (dead blending lets the
    # velocity it extrapolates decay, so for it only a pose held still is such a line)
    speed = np.zeros(3) if mode == "dead" else np.asarray(v)
    g = np.arange(n, dtype=np.float64)[:, None] * speed[None, :] + np.asarray(v)[None, :]
    out = blend_segments(g, np.arange(4, n, 4), mode=mode, halflife=halflife)
    np.testing.assert_allclose(out, g, atol=1e-9)


def test_inertialization_carries_position_and_velocity_and_decays_by_its_half_life():
    # a still segment, then a still one 1 m away: the join holds, and half the offset is gone after the half-life
    g = np.concatenate([np.zeros((8, 1)), np.ones((40, 1))])
    out = blend_segments(g, np.array([8]), mode="inertialize", halflife=5.0)
    assert out[8, 0] == 0.0  # where the first segment was heading
    assert out[13, 0] == pytest.approx(0.5, abs=1e-12)  # 5 frames later: half the offset left
    assert np.all(np.diff(out[8:, 0]) >= 0) and out[-1, 0] == pytest.approx(1.0, abs=1e-4)
    # the velocity at the join is carried through: a moving first segment keeps moving into the join
    moving = np.concatenate([np.arange(8.0)[:, None] * 0.1, np.zeros((20, 1))])
    m = blend_segments(moving, np.array([8]), mode="inertialize", halflife=5.0)
    assert m[8, 0] == pytest.approx(0.8) and m[9, 0] > m[8, 0] > m[7, 0]


def test_dead_blending_is_half_way_at_its_half_life_and_done_at_twice_it():
    g = np.concatenate([np.zeros((8, 1)), np.ones((40, 1))])
    out = blend_segments(g, np.array([8]), mode="dead", halflife=4.0)
    assert out[7 + 4, 0] == pytest.approx(0.5)  # 4 frames after the last frame of the first segment
    np.testing.assert_array_equal(out[7 + 8 :, 0], 1.0)
    assert np.all(np.diff(out[:, 0]) >= 0)


def test_a_segment_blends_as_in_the_whole_motion():
    g = np.random.default_rng(4).normal(size=(30, 6)).cumsum(axis=0)
    for mode in SMOOTH:
        whole = blend_segments(g, np.array([10, 20]), mode=mode, halflife=2.5)
        again = blend_segment(whole[8:10], g[10:20], mode=mode, halflife=2.5)
        np.testing.assert_allclose(again, whole[10:20], atol=1e-12)


def test_bad_blend_options_are_config_errors():
    g = np.zeros((10, 3))
    with pytest.raises(ConfigError, match="blend must be one of"):
        blend_segments(g, np.array([4]), mode="smooth")
    with pytest.raises(ConfigError, match="half-life"):
        blend_segments(g, np.array([4]), mode="dead", halflife=0.0)
    assert DEFAULT_BLEND in BLEND_MODES


def _lengths(pos: np.ndarray) -> np.ndarray:
    return np.linalg.norm(pos[:, 1:] - pos[:, PARENTS[1:]], axis=-1)


def test_blended_motion_is_given_the_knn_bones_and_hand_shapes(tmp_path):
    from gesturekit.demo import build_demo_database

    db = build_demo_database(tmp_path / "demo", minutes=0.5)
    knn = np.asarray(db.G[:3, :40], np.float32).reshape(-1, 55, 3)  # three clips end to end: hard joins
    cuts = np.arange(8, len(knn), 8)
    blended = blend_segments(knn.reshape(len(knn), -1), cuts, mode="dead", halflife=2.0).reshape(knn.shape)
    assert np.abs(_lengths(blended) - _lengths(knn)).max() > 1e-3  # blending stretches bones
    kept = bones_like(blended, knn)
    np.testing.assert_allclose(_lengths(kept), _lengths(knn), atol=1e-6)
    for group in ("left_wrist", "right_wrist", "upper_chest"):  # each group keeps the k-NN frame's shape
        frames_kept, _ = group_frames(kept, group)
        frames_knn, _ = group_frames(knn, group)
        from gesturekit.bones import RIGID_GROUPS
        from gesturekit.skeleton import joint_index

        j = joint_index(group)
        for child in RIGID_GROUPS[group]:
            c = joint_index(child)
            local_kept = np.einsum("tba,tb->ta", frames_kept, kept[:, c] - kept[:, j])
            local_knn = np.einsum("tba,tb->ta", frames_knn, knn[:, c] - knn[:, j])
            np.testing.assert_allclose(local_kept, local_knn, atol=1e-5)
    # the directions of the bones are the blended ones
    d_kept = kept[:, 1:] - kept[:, PARENTS[1:]]
    d_blend = blended[:, 1:] - blended[:, PARENTS[1:]]
    cos = np.sum(d_kept * d_blend, -1) / (np.linalg.norm(d_kept, axis=-1) * np.linalg.norm(d_blend, axis=-1) + 1e-12)
    assert np.median(cos) > 0.999
    np.testing.assert_allclose(bones_like(knn, knn), knn, atol=1e-6)  # nothing to change
