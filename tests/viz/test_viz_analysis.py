"""Analysis figures: loss curves, the speed profile around joins, beats against onsets, evaluation bars."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.errors import ConfigError
from gesturekit.evaluate.metrics import KINEMATIC_JOINTS, audio_onsets, motion_beats
from gesturekit.motion import AUDIO_SR, Motion
from gesturekit.skeleton import N_JOINTS
from gesturekit.viz.analysis import (
    adherence_figure,
    beats_figure,
    join_profile,
    join_profile_figure,
    loss_curves_figure,
    metrics_figure,
)


def _still(n: int = 60) -> np.ndarray:
    return np.zeros((n, N_JOINTS, 3), np.float32)


# ---- loss curves ---------------------------------------------------------------------------------


def test_loss_curves_draw_each_logged_loss_on_its_side():
    log = pd.DataFrame(
        {
            "iteration": [10, 20, 30, 40],
            "elapsed_s": [1, 2, 3, 4],
            "critic_loss": [4.0, 2.0, 1.0, 3.0],
            "wasserstein": [1, 2, 3, 4],
            "generator_l1": [0.9, 0.7, 0.6, 0.5],
        }
    )
    fig = loss_curves_figure(log)
    lines = {t.meta["column"]: t for t in fig.data}
    assert set(lines) == {"critic_loss", "wasserstein", "generator_l1"}  # elapsed_s is not a loss
    assert lines["critic_loss"].xaxis == "x" and lines["generator_l1"].xaxis == "x2"  # no generator_loss panel
    np.testing.assert_array_equal(lines["critic_loss"].x, [10, 20, 30, 40])
    np.testing.assert_allclose(lines["critic_loss"].y, [4, 2, 1, 3])
    full = {t.meta["column"]: t for t in loss_curves_figure(log.assign(generator_loss=800.0)).data}
    assert (full["generator_loss"].xaxis, full["generator_l1"].xaxis) == ("x2", "x3")  # the total apart from its terms
    smooth = {t.meta["column"]: t for t in loss_curves_figure(log, smooth=3).data}
    np.testing.assert_allclose(smooth["critic_loss"].y, [3.0, 7 / 3, 2.0, 2.0])  # centred means, ends shorter


def test_loss_curves_refuse_a_log_without_losses():
    with pytest.raises(ConfigError, match="iteration"):
        loss_curves_figure(pd.DataFrame({"critic_loss": [1.0]}))
    with pytest.raises(ConfigError, match="none of the loss columns"):
        loss_curves_figure(pd.DataFrame({"iteration": [1], "other": [2.0]}))
    with pytest.raises(ConfigError, match="smooth"):
        loss_curves_figure(pd.DataFrame({"iteration": [1], "critic_loss": [2.0]}), smooth=0)


# ---- joins ------------------------------------------------------------------------------------------


@settings(max_examples=30, deadline=None)
@given(
    jump=st.floats(0.01, 1.0),
    drift=st.floats(0.0, 0.05),
    radius=st.integers(0, 5),
    joins=st.lists(st.integers(8, 52), min_size=1, max_size=5, unique=True),
)
def test_join_profile_shows_a_jump_at_offset_zero_only(jump, drift, radius, joins):
    x = _still(60)
    x[:, :, 0] = np.arange(60)[:, None] * drift  # every joint moves `drift` metres per frame along x
    for b in joins:
        x[b:, :, 1] += jump  # and jumps by `jump` at each join
    off, v = join_profile(x, joins, fps=15, radius=radius)
    assert list(off) == list(range(-radius, radius + 1))
    counted = [b for b in joins if b - 1 - radius >= 0 and b - 1 + radius < 59]
    if not counted:
        assert np.isnan(v).all()
        return
    # at offset 0 every counted join adds the jump; elsewhere only joins that fall there do
    expected = np.zeros(off.size)
    for i, o in enumerate(off):
        steps = []
        for b in counted:
            y = jump * sum(1 for j in joins if j == b + o)
            steps.append(np.hypot(drift, y) * 15)
        expected[i] = np.mean(steps)
    np.testing.assert_allclose(v, expected, rtol=1e-4, atol=1e-5)
    assert v[radius] == pytest.approx(np.hypot(drift, jump) * 15, rel=1e-4)


def test_join_profile_uses_the_kinematic_joints_by_default():
    x = _still(20)
    finger = next(j for j in range(N_JOINTS) if j not in KINEMATIC_JOINTS)
    x[10:, finger, 1] = 1.0  # a finger jumps, the body does not
    assert np.allclose(join_profile(x, [10], fps=15, radius=2)[1], 0.0)
    assert join_profile(x, [10], fps=15, radius=2, joints=None)[1][2] > 0
    with pytest.raises(ConfigError):
        join_profile(np.zeros((5, 3)), [2], fps=15)


def test_join_profile_figure_overlays_one_line_per_motion():
    a, b = _still(40), _still(40)
    a[20:, :, 0] = 0.1
    fig = join_profile_figure([Motion(a, 15), Motion(b, 15)], [20], labels=["k-NN", "refined"], radius=3)
    lines = [t for t in fig.data if t.meta["part"] == "join"]
    assert [t.name for t in lines] == ["k-NN", "refined"]
    assert lines[0].y[3] == pytest.approx(1.5) and np.allclose(lines[1].y, 0)
    assert any(s.name == "join" for s in fig.layout.shapes)
    with pytest.raises(ConfigError, match="labels"):
        join_profile_figure([Motion(a, 15)], [20], labels=["a", "b"])


# ---- beats ------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_beats_figure_marks_motion_beats_and_speech_onsets_in_the_range():
    t = np.arange(90) / 15
    x = _still(90)
    x[:, :, 0] = (0.1 * np.sin(2 * np.pi * 1.0 * t))[:, None]  # two velocity minima per second
    m = Motion(x, 15)
    s = np.arange(int(6 * AUDIO_SR)) / AUDIO_SR
    audio = (np.sin(2 * np.pi * 200 * s) * ((s % 1.0) < 0.15)).astype(np.float32)  # a click every second
    fig = beats_figure([m], audio, labels=["a"], start_s=1.0, end_s=5.0)
    parts = {t.meta["part"]: t for t in fig.data}
    beats = motion_beats(x, fps=15)
    np.testing.assert_allclose(parts["beats"].x, beats[(beats >= 1.0) & (beats <= 5.0)])
    onsets = audio_onsets(audio)
    np.testing.assert_allclose(parts["onsets"].x, onsets[(onsets >= 1.0) & (onsets <= 5.0)])
    assert len(parts["onsets"].x) >= 3
    assert sum(s.name == "onset" for s in fig.layout.shapes) == len(parts["onsets"].x)
    assert min(parts["velocity"].x) >= 1.0 and max(parts["velocity"].x) <= 5.0
    with pytest.raises(ConfigError):
        beats_figure([m], audio, start_s=4.0, end_s=2.0)


# ---- evaluation tables ----------------------------------------------------------------------------


def test_metrics_figure_has_one_subplot_per_measure_and_skips_nan():
    table = pd.DataFrame(
        {
            "system": ["gt", "knn", "random"],
            "frames": [10, 10, 10],
            "fgd": [0.0, 2.0, np.nan],
            "mean_jerk": [1.0, 3.0, 9.0],
            "relaxed_steps": [0, 1, 0],
        }
    )
    fig = metrics_figure(table)
    bars = {t.meta["column"]: t for t in fig.data}
    assert set(bars) == {"fgd", "mean_jerk"}  # frames and relaxed_steps are not measures
    assert list(bars["fgd"].x) == ["gt", "knn"] and list(bars["mean_jerk"].x) == ["gt", "knn", "random"]
    np.testing.assert_allclose(bars["mean_jerk"].y, [1, 3, 9])
    assert {t.meta["column"] for t in metrics_figure(table, columns=["fgd"]).data} == {"fgd"}
    with pytest.raises(ConfigError, match="unknown"):
        metrics_figure(table, columns=["nope"])
    with pytest.raises(ConfigError, match="system"):
        metrics_figure(table.drop(columns="system"))


def test_adherence_figure_groups_bars_by_run_and_system():
    rows = []
    for system in ("knn", "random"):
        for run in ("controlled", "uncontrolled"):
            for i, c in enumerate(("left_hand=low", "speed=slow")):
                rows.append(
                    {
                        "system": system,
                        "run": run,
                        "start_s": 3.0 * i,
                        "end_s": 3.0 * i + 3,
                        "constraint": c,
                        "adherence": 0.9 if run == "controlled" else 0.1,
                    }
                )
    fig = adherence_figure(pd.DataFrame(rows))
    bars = [t for t in fig.data if t.meta["part"] == "adherence"]
    assert {(t.meta["system"], t.meta["run"]) for t in bars} == {
        (s, r) for s in ("knn", "random") for r in ("controlled", "uncontrolled")
    }
    knn = next(t for t in bars if t.meta == {"part": "adherence", "system": "knn", "run": "controlled"})
    assert list(knn.x) == ["0-3 s: left_hand=low", "3-6 s: speed=slow"] and list(knn.y) == [0.9, 0.9]
    assert knn.yaxis == "y" and next(t for t in bars if t.meta["run"] == "uncontrolled").yaxis == "y2"
    with pytest.raises(ConfigError, match="columns"):
        adherence_figure(pd.DataFrame({"system": ["a"]}))
