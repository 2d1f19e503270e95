"""The canvas viewer: its page carries every bone of every frame as a body, side by side, with the speech, offline."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

from gesturekit.errors import ConfigError
from gesturekit.motion import Motion
from gesturekit.skeleton import N_JOINTS, bones
from gesturekit.viz.appearance import APPEARANCE, DERIVED_POINTS
from gesturekit.viz.figures import skeleton_figure
from gesturekit.viz.viewer import VIEWER_MAX_FRAMES, read_viewer_data, skeleton_viewer, viewer_data


def _motion(n_frames: int, *, seed: int = 0, fps: float = 15.0) -> Motion:
    rng = np.random.default_rng(seed)
    pos = rng.normal(0, 0.3, size=(1, N_JOINTS, 3)) + np.cumsum(rng.normal(0, 0.01, (n_frames, N_JOINTS, 3)), 0)
    return Motion(pos.astype(np.float32), fps)


def _drawn_bones(data: dict) -> set:
    """The bones (child, parent) the page draws: its capsules' and the head sphere's, either way round."""
    out = {frozenset((a, b)) for a, b, _, _ in data["capsules"]}
    return out | {frozenset(bone) for s in APPEARANCE.shapes()[1] for bone in s.covers}


@settings(max_examples=20, deadline=None)
@given(hst.integers(1, 120), hst.integers(1, 60), hst.integers(0, 10**6))
def test_every_bone_of_every_shown_frame_is_drawn_side_by_side(n, max_frames, seed):
    a, b = _motion(n, seed=seed), _motion(max(1, n // 2), seed=seed + 1)
    data = read_viewer_data(skeleton_viewer([a, b], labels=["A", "B"], max_frames=max_frames))
    fig = skeleton_figure([a, b], labels=["A", "B"], max_frames=max_frames)
    assert data["times"] == fig.layout.meta["times"]  # the same time grid as the plotly figure
    step = data["frame_step"]
    assert len(data["times"]) <= max_frames and (step == 1) == (n <= max_frames)
    assert (data["note"] != "") == (step > 1)
    # every bone is drawn, between the points that hold the joints of every shown frame
    assert {frozenset((int(c), int(q))) for c, q in bones()} <= _drawn_bones(data)
    for motion, m in zip((a, b), data["motions"]):
        src = np.minimum(np.arange(len(data["times"])) * step, motion.n_frames - 1)  # shorter: holds its last pose
        assert m["points"].shape == (len(data["times"]), N_JOINTS + len(DERIVED_POINTS), 3)
        shifted = motion.positions[src] + np.array([m["offset"], 0, 0], dtype=np.float32)  # offset in float32
        np.testing.assert_array_equal(m["points"][:, :N_JOINTS], shifted)
    assert data["motions"][1]["offset"] - data["motions"][0]["offset"] >= 0.8  # B on the viewer's right
    assert [m["color"] for m in data["motions"]] == [APPEARANCE.color(0), APPEARANCE.color(1)]


def test_every_frame_is_kept_up_to_ten_minutes_at_15_fps_and_beyond_the_page_says_so():
    assert VIEWER_MAX_FRAMES >= 10 * 60 * 15
    pos = np.zeros((VIEWER_MAX_FRAMES, N_JOINTS, 3), np.float32)
    pos[:, :, 1] = np.arange(VIEWER_MAX_FRAMES)[:, None] * 1e-4  # each frame its own height
    data = viewer_data(Motion(pos, 15.0))
    assert data["frame_step"] == 1 and len(data["times"]) == VIEWER_MAX_FRAMES and data["note"] == ""
    longer = viewer_data(Motion(np.concatenate([pos, pos[:1]]), 15.0))
    assert longer["frame_step"] == 2 and len(longer["times"]) == (VIEWER_MAX_FRAMES + 2) // 2
    assert "every 2nd frame shown" in longer["note"] and str(VIEWER_MAX_FRAMES + 1) in longer["note"]


@settings(max_examples=15, deadline=None)
@given(hst.integers(1, 40), hst.integers(0, 10**6), hst.sampled_from([8000, 16000]))
def test_the_speech_is_embedded_and_decodes_to_its_samples(n, seed, sr):
    m = _motion(n, seed=seed)
    rng = np.random.default_rng(seed)
    audio = rng.uniform(-1, 1, int(sr * n / 15.0) + int(rng.integers(-200, 200))).astype(np.float32)
    audio = audio[: max(1, len(audio))]
    data = read_viewer_data(skeleton_viewer(m, audio=audio, sr=sr))
    assert data["audio_sr"] == sr
    got = data["audio"]
    np.testing.assert_allclose(got[: len(audio)], audio, atol=1 / 32767 + 1e-7)  # 16-bit PCM
    # silence after shorter speech, so the speech's clock reaches the last frame
    assert len(got) >= max(len(audio), int(np.ceil(n / 15.0 * sr)))
    assert np.all(got[len(audio) :] == 0)


def test_without_speech_there_is_no_audio_element():
    page = skeleton_viewer(_motion(5))
    assert "<audio" not in page and read_viewer_data(page)["audio"] is None
    assert "<audio" in skeleton_viewer(_motion(5), audio=np.zeros(100, np.float32))


def test_page_is_offline_and_names_survive_any_text():
    label = 'k-NN </script><b>"&'
    page = skeleton_viewer(
        _motion(10),
        labels=[label],
        title="t </script> __AUDIO__",
        key='a"b<c __DATA__',
        audio=np.zeros(1000, np.float32),
    )
    # nothing fetched: the only source is the speech's data URI
    assert not re.search(r"(src|href)\s*=\s*\"(?!data:audio/wav;base64,)|https?://|@import", page)
    data = read_viewer_data(page)
    assert data["motions"][0]["label"] == label and data["title"] == "t </script> __AUDIO__"
    assert data["key"] == 'a"b<c __DATA__'
    assert page.count("</script>") == 2  # only the page's own two script elements end


def test_default_camera_faces_the_character_and_the_framing_holds_every_surface_and_the_floor():
    m = _motion(40, seed=3)
    data = read_viewer_data(skeleton_viewer(m))
    assert data["up"] == [0, 1, 0] and data["eye"][2] > 0 and abs(data["eye"][0]) < 1e-9
    pts = data["motions"][0]["points"].reshape(-1, 3)
    lo, hi = np.asarray(data["lo"]), np.asarray(data["hi"])
    assert np.all(lo <= pts.min(axis=0) - APPEARANCE.head_radius) and np.all(
        hi >= pts.max(axis=0) + APPEARANCE.head_radius
    )
    assert data["ground"] < pts[:, 1].min() and lo[1] <= data["ground"]
    # framed to fill: the margin is a small fraction of the box on each axis
    inner_lo, inner_hi = pts.min(axis=0) - APPEARANCE.head_radius, pts.max(axis=0) + APPEARANCE.head_radius
    assert np.all((inner_lo - lo) <= 0.2 * (hi - lo)) and np.all((hi - inner_hi) <= 0.2 * (hi - lo))


@pytest.mark.parametrize(
    "kwargs, problem",
    [
        (dict(motions=[]), "at least one motion"),
        (dict(max_frames=0), "max_frames must be at least 1"),
        (dict(fps=0.0), "fps must be positive"),
        (dict(audio=np.zeros((10, 2), np.float32)), "mono samples"),
        (dict(audio=np.zeros(10, np.float32), sr=0), "sample rate"),
    ],
)
def test_bad_input_is_refused(kwargs, problem):
    kwargs = dict(kwargs)
    motions = kwargs.pop("motions", _motion(5))
    with pytest.raises(ConfigError, match=problem):
        skeleton_viewer(motions, **kwargs)
