"""The objective measures on constructed motions and sounds with known answers."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.control import ATTRIBUTE_NAMES, parse_control
from gesturekit.errors import ConfigError
from gesturekit.evaluate import metrics as M
from gesturekit.motion import AUDIO_SR
from gesturekit.skeleton import N_JOINTS, joint_index
from tests.waits import patience

FPS = 15
LW = joint_index("left_wrist")


def _rest(frames: int) -> np.ndarray:
    """A fixed pose (random but constant over time), (frames, 55, 3)."""
    pose = np.random.default_rng(0).normal(0, 0.3, size=(1, N_JOINTS, 3))
    return np.repeat(pose, frames, axis=0)


def _strokes(beat_times, seconds: float) -> np.ndarray:
    """Arm joints move between keyposes with minimum-jerk strokes; speed is 0 exactly at ``beat_times``."""
    n = int(round(seconds * FPS))
    t = np.arange(n) / FPS
    x = _rest(n)
    knots = np.concatenate([[0.0], np.sort(beat_times), [seconds]])
    offset = np.zeros(n)
    for k in range(len(knots) - 1):
        a, b = knots[k], knots[k + 1]
        inside = (t >= a) & (t < b)
        u = (t[inside] - a) / (b - a)
        s = 10 * u**3 - 15 * u**4 + 6 * u**5  # minimum jerk: zero speed at both ends
        offset[inside] = (k % 2) + (1 if k % 2 == 0 else -1) * s
    arm = [joint_index(j) for j in ("left_elbow", "left_wrist", "right_elbow", "right_wrist")]
    x[:, arm, 0] += 0.3 * offset[:, None]
    return x


def _clicks(times, seconds: float) -> np.ndarray:
    """Silence with a short noise burst at each time."""
    rng = np.random.default_rng(1)
    audio = (1e-4 * rng.normal(size=int(seconds * AUDIO_SR))).astype(np.float32)
    for t in times:
        s = int(round(t * AUDIO_SR))
        burst = rng.normal(size=800) * np.exp(-np.arange(800) / 200)
        audio[s : s + 800] += (0.5 * burst[: len(audio[s : s + 800])]).astype(np.float32)
    return audio


BEATS = np.array([1.0, 2.6, 3.8, 5.4, 6.6, 8.2])  # on the 15 fps grid, at least 1.2 s apart


@pytest.mark.slow
def test_audio_onsets_find_clicks():
    onsets = M.audio_onsets(_clicks(BEATS, 10.0))
    assert len(onsets) == len(BEATS)
    np.testing.assert_allclose(onsets, BEATS, atol=0.03)


def _pick_peaks_literal(x, pre_max, post_max, pre_avg, post_avg, delta, wait):
    """The peak-picking rule as written: a frame-by-frame walk, windows clipped to the signal."""
    n, peaks, i = len(x), [], 0
    while i < n:
        lo_m, hi_m = max(0, i - pre_max), min(n, i + post_max)
        lo_a, hi_a = max(0, i - pre_avg), min(n, i + post_avg)
        if x[i] == max(x[lo_m:hi_m]) and x[i] >= sum(float(v) for v in x[lo_a:hi_a]) / (hi_a - lo_a) + delta:
            peaks.append(i)
            i += wait + 1
        else:
            i += 1
    return peaks


@settings(max_examples=200, deadline=None)
@given(
    x=st.lists(st.integers(0, 6), min_size=0, max_size=60),
    pre_max=st.integers(0, 4),
    post_max=st.integers(1, 4),
    pre_avg=st.integers(0, 6),
    post_avg=st.integers(1, 6),
    delta=st.sampled_from([0.0, 0.25, 0.5, 1.0]),
    wait=st.integers(0, 5),
)
def test_pick_peaks_equals_the_literal_rule(x, pre_max, post_max, pre_avg, post_avg, delta, wait):
    # small integers in float: many ties and plateaus, and exact means
    xs = np.asarray(x, dtype=np.float64) / 2
    got = M.pick_peaks(
        xs, pre_max=pre_max, post_max=post_max, pre_avg=pre_avg, post_avg=post_avg, delta=delta, wait=wait
    )
    assert got.tolist() == _pick_peaks_literal(xs, pre_max, post_max, pre_avg, post_avg, delta, wait)


def test_pick_peaks_rejects_bad_windows():
    with pytest.raises(ConfigError):
        M.pick_peaks(np.ones(5), pre_max=1, post_max=0, pre_avg=1, post_avg=1, delta=0.0, wait=0)


@pytest.mark.slow
def test_audio_onsets_equal_librosa_onset_detect_on_real_speech(shared_data, tmp_path):
    # librosa's own picker is a cached numba gufunc: run it in a child process with a private cache
    import os
    import subprocess
    import sys

    from gesturekit.datasets.audio import load_audio

    files = sorted(shared_data.rglob("*.wav"))
    assert files, f"no speech in {shared_data}"
    ours = {f.name: M.audio_onsets(load_audio(f)) for f in files}
    code = (
        "import sys, pathlib, numpy as np, librosa\n"
        "from gesturekit.datasets.audio import load_audio\n"
        "out = pathlib.Path(sys.argv[1])\n"
        "for f in map(pathlib.Path, sys.argv[2:]):\n"
        "    t = librosa.onset.onset_detect(y=load_audio(f), sr=16000, hop_length=160, units='time')\n"
        "    np.save(out / (f.name + '.npy'), t)\n"
    )
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    subprocess.run(
        [sys.executable, "-c", code, str(tmp_path), *map(str, files)], check=True, env=env, timeout=patience(300)
    )
    for f in files:
        ref = np.load(tmp_path / (f.name + ".npy"), allow_pickle=False)
        assert len(ours[f.name]) > 20, f.name
        np.testing.assert_array_equal(ours[f.name], ref, err_msg=f.name)


def test_motion_beats_are_the_speed_minima_of_the_strokes():
    beats = M.motion_beats(_strokes(BEATS, 10.0), fps=FPS)
    inner = beats[(beats > 0.5) & (beats < 9.0)]
    np.testing.assert_allclose(inner, BEATS, atol=1.01 / FPS)


@pytest.mark.slow
def test_beats_on_onsets_score_higher_than_beats_shifted_by_half_a_second():
    audio = _clicks(BEATS, 10.0)
    on = M.beat_consistency_score(_strokes(BEATS, 10.0), audio, fps=FPS)
    off = M.beat_consistency_score(_strokes(BEATS + 0.5, 10.0), audio, fps=FPS)
    assert on > 0.8, on
    assert off < 0.2, off
    assert on - off > 0.6


def test_beat_consistency_known_values():
    b = np.array([1.0, 3.0, 5.0])
    assert M.beat_consistency(b, b, sigma=0.1) == 1.0
    assert M.beat_consistency(b + 0.5, b, sigma=0.1) == pytest.approx(math.exp(-0.25 / 0.02))
    assert M.beat_consistency(np.array([1.0]), np.array([1.0, 1.2]), sigma=0.1) == pytest.approx((1 + math.exp(-2)) / 2)
    assert M.beat_consistency([], b) == 0.0
    assert math.isnan(M.beat_consistency(b, []))
    with pytest.raises(ConfigError):
        M.beat_consistency(b, b, sigma=0)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(0, 20), min_size=1, max_size=12), st.lists(st.floats(0, 20), min_size=1, max_size=12))
def test_beat_consistency_is_the_definition(beats, onsets):
    want = np.mean([math.exp(-min((o - b) ** 2 for b in beats) / (2 * 0.1**2)) for o in onsets])
    assert M.beat_consistency(beats, onsets, sigma=0.1) == pytest.approx(want, abs=1e-12)


@pytest.mark.slow
def test_constant_pose_has_zero_diversity_jerk_acceleration_and_no_beats():
    x = _rest(90)
    assert M.diversity_l1(x) == 0.0
    assert M.mean_jerk(x, fps=FPS) == 0.0
    assert M.mean_acceleration(x, fps=FPS) == 0.0
    assert M.motion_beats(x, fps=FPS).size == 0
    assert M.beat_consistency_score(x, _clicks(BEATS[:3], 6.0), fps=FPS) == 0.0


def test_diversity_known_value():
    x = np.zeros((4, 1, 3))
    x[2:] = 1.0  # two windows of two frames: all zeros, all ones
    # each window is 0.5 per value from the mean window: 6 values -> 3, per frame of the window -> 1.5
    assert M.diversity_l1(x, window=2) == pytest.approx(1.5)
    assert math.isnan(M.diversity_l1(x, window=3))  # one window only


def test_acceleration_and_jerk_of_polynomials():
    t = np.arange(30) / FPS
    x = np.zeros((30, 1, 3))
    x[:, 0, 1] = 0.5 * 2.0 * t**2  # constant acceleration 2 m/s^2
    assert M.mean_acceleration(x, fps=FPS, joints=None) == pytest.approx(2.0)
    assert M.mean_jerk(x, fps=FPS, joints=None) == pytest.approx(0.0, abs=1e-9)
    x[:, 0, 1] = t**3  # jerk 6 m/s^3
    assert M.mean_jerk(x, fps=FPS, joints=None) == pytest.approx(6.0)


def test_hellinger_identical_is_zero_and_disjoint_is_one():
    x = _strokes(BEATS, 10.0)
    assert M.kinematic_hellinger(x, x, fps=FPS, order=1) == 0.0
    assert M.kinematic_hellinger(x, x, fps=FPS, order=2) == 0.0
    assert M.hellinger_distance([1, 0, 0], [0, 0, 3]) == 1.0
    gliding = _rest(150) + (np.arange(150) * 0.01)[:, None, None]  # every joint at one constant speed
    assert M.kinematic_hellinger(gliding, _rest(150), fps=FPS) == 1.0  # versus still: disjoint histograms
    assert 0.0 < M.kinematic_hellinger(x, _rest(150), fps=FPS) < 1.0


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(0, 50), min_size=4, max_size=4), st.lists(st.integers(0, 50), min_size=4, max_size=4))
def test_hellinger_is_a_bounded_symmetric_distance(p, q):
    if sum(p) == 0 or sum(q) == 0:
        with pytest.raises(ConfigError):
            M.hellinger_distance(p, q)
        return
    h = M.hellinger_distance(p, q)
    assert 0.0 <= h <= 1.0
    assert h == pytest.approx(M.hellinger_distance(q, p), abs=1e-12)
    assert M.hellinger_distance(p, [2 * v for v in p]) == pytest.approx(0.0, abs=1e-7)


def test_frechet_distance_closed_forms():
    # one dimension: (m1 - m2)^2 + (s1 - s2)^2
    assert M.frechet_distance([0.0], [[4.0]], [1.0], [[1.0]]) == pytest.approx(2.0)
    rng = np.random.default_rng(0)
    f = rng.normal(size=(200, 5))
    mu, cov = M.gaussian_statistics(f)
    assert M.frechet_distance(mu, cov, mu, cov) == 0.0
    # a shift of the mean adds its squared length
    assert M.frechet_distance(mu + 2.0, cov, mu, cov) == pytest.approx(4 * 5, rel=1e-9)
    with pytest.raises(ConfigError):
        M.frechet_distance(mu, cov, mu[:3], cov)


def test_boundary_jumps_find_the_inserted_jump():
    x = np.zeros((40, 1, 3))
    x[:, 0, 0] = np.arange(40) * 0.01  # 1 cm per frame
    x[20:, 0, 0] += 0.09  # a 9 cm jump between frames 19 and 20
    r = M.boundary_jumps(x, [20], joints=None)
    assert r["jump"] == pytest.approx(0.10)
    assert r["elsewhere"] == pytest.approx(0.01)
    assert r["ratio"] == pytest.approx(10.0)
    assert r["joins"] == 1
    smooth = M.boundary_jumps(x[:20], [8, 16, 99], joints=None)
    assert smooth["ratio"] == pytest.approx(1.0) and smooth["joins"] == 2


def test_control_adherence_counts_frames_meeting_the_constraint():
    n = 60
    x = _rest(n)
    x[:30, LW, 1] = 0.6  # left wrist high for the first two seconds
    x[30:, LW, 1] = -0.3
    thresholds = {name: (0.0, 0.4) for name in ATTRIBUTE_NAMES}
    table = M.control_adherence(
        x, parse_control("0-2:left_hand=high,2-4:left_hand=low"), thresholds=thresholds, fps=FPS
    )
    assert list(table["adherence"]) == [1.0, 1.0]
    assert list(table["frames"]) == [30, 30]
    assert table["left_hand_height_mean"].tolist() == pytest.approx([0.6, -0.3])
    swapped = M.control_adherence(
        x, parse_control("0-2:left_hand=low,2-3:left_hand=high"), thresholds=thresholds, fps=FPS
    )
    assert list(swapped["adherence"]) == [0.0, 0.0]
    assert M.overall_adherence(swapped) == 0.0
    # half the frames of a segment
    half = M.control_adherence(x, parse_control("1-3:left_hand=high"), thresholds=thresholds, fps=FPS)
    assert half["adherence"].iloc[0] == pytest.approx(0.5)


def test_bad_inputs_are_config_errors():
    with pytest.raises(ConfigError, match="shape"):
        M.mean_jerk(np.zeros((10, 3)), fps=FPS)
    with pytest.raises(ConfigError, match="fps"):
        M.mean_jerk(_rest(10), fps=0)
    with pytest.raises(ConfigError, match="NaN"):
        M.diversity_l1(np.full((10, 2, 3), np.nan))
    with pytest.raises(ConfigError, match="joints"):
        M.mean_jerk(_rest(10), fps=FPS, joints=[99])
