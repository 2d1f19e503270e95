"""The canvas skeleton viewer: its page carries every bone of every shown frame, side by side, offline."""
from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

from gesturekit.errors import ConfigError
from gesturekit.motion import Motion
from gesturekit.skeleton import N_JOINTS, bones
from gesturekit.viz.figures import skeleton_figure
from gesturekit.viz.viewer import read_viewer_data, skeleton_viewer


def _motion(n_frames: int, *, seed: int = 0, fps: float = 15.0) -> Motion:
    rng = np.random.default_rng(seed)
    pos = rng.normal(0, 0.3, size=(1, N_JOINTS, 3)) + np.cumsum(rng.normal(0, 0.01, (n_frames, N_JOINTS, 3)), 0)
    return Motion(pos.astype(np.float32), fps)


def _bones_drawn(m: dict, k: int) -> set:
    """(child, parent) segments of frame k: consecutive finite points of each joint path."""
    out = set()
    for part in ("body", "hands"):
        pts = m[part][k]
        for i in range(len(pts) - 1):
            if np.isfinite(pts[i]).all() and np.isfinite(pts[i + 1]).all():
                out.add(tuple(np.round(np.concatenate([pts[i + 1], pts[i]]), 5)))
    return out


def _bones_of(positions: np.ndarray, dx: float = 0.0) -> set:
    # the viewer offsets float32 positions in float32
    p = (positions.astype(np.float32) + np.array([dx, 0, 0], dtype=np.float32)).astype(np.float64)
    b = bones()
    return {tuple(np.round(np.concatenate([p[c], p[q]]), 5)) for c, q in b}


@settings(max_examples=20, deadline=None)
@given(hst.integers(1, 120), hst.integers(1, 60), hst.integers(0, 10**6))
def test_every_bone_of_every_shown_frame_side_by_side(n, max_frames, seed):
    a, b = _motion(n, seed=seed), _motion(max(1, n // 2), seed=seed + 1)
    data = read_viewer_data(skeleton_viewer([a, b], labels=["A", "B"], max_frames=max_frames))
    fig = skeleton_figure([a, b], labels=["A", "B"], max_frames=max_frames)
    assert data["times"] == fig.layout.meta["times"]  # the same time grid as the plotly figure
    step = data["frame_step"]
    for k in {0, len(data["times"]) // 2, len(data["times"]) - 1}:
        for motion, m in zip((a, b), data["motions"]):
            src = min(k * step, motion.n_frames - 1)  # the shorter motion holds its last pose
            assert _bones_drawn(m, k) == _bones_of(motion.positions[src], m["offset"])
    assert data["motions"][1]["offset"] - data["motions"][0]["offset"] >= 0.8  # B on the viewer's right


def test_page_is_offline_and_names_survive_any_text():
    label = 'k-NN </script><b>"&'
    page = skeleton_viewer(_motion(10), labels=[label], title="t </script>", key='a"b<c')
    assert not re.search(r"(src|href)\s*=|https?://|@import", page)  # nothing fetched
    data = read_viewer_data(page)
    assert data["motions"][0]["label"] == label and data["title"] == "t </script>" and data["key"] == 'a"b<c'
    assert page.count("</script>") == 2  # only the page's own two script elements end


def test_default_camera_faces_the_character_with_y_up_and_bounds_hold_all_frames():
    m = _motion(40, seed=3)
    data = read_viewer_data(skeleton_viewer(m))
    assert data["up"] == [0, 1, 0] and data["eye"][2] > 0 and abs(data["eye"][0]) < 1e-9
    pts = m.positions.reshape(-1, 3)
    assert np.all(np.asarray(data["lo"]) <= pts.min(axis=0)) and np.all(np.asarray(data["hi"]) >= pts.max(axis=0))


def test_bad_input_is_refused():
    with pytest.raises(ConfigError):
        skeleton_viewer([])
    with pytest.raises(ConfigError):
        skeleton_viewer(_motion(5), max_frames=0)
