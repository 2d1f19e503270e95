"""Tests of the generated demo speaker (gesturekit.datasets.synthetic).

The measures below are computed from the generated audio and positions with
plain signal processing, and cross-checked with the ground-truth events the
generator reports.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal
from scipy.ndimage import gaussian_filter1d, uniform_filter1d

from gesturekit.datasets.synthetic import DEMO_LABEL, GENERATOR, DemoEvents, generate_demo_take, generate_demo_takes
from gesturekit.errors import ConfigError
from gesturekit.features import audio_frame_features
from gesturekit.motion import AUDIO_SR, Take
from gesturekit.skeleton import FPS, N_JOINTS, joint_index

LW, RW = joint_index("left_wrist"), joint_index("right_wrist")


@pytest.fixture(scope="module")
def takes() -> list[tuple[Take, DemoEvents]]:
    """Four minutes of the demo speaker: four 60 s takes."""
    return [generate_demo_take(seconds=60.0, seed=s, name=f"t{s}") for s in range(4)]


# --- measures ---------------------------------------------------------------------------------


def _rms_100hz(audio: np.ndarray) -> np.ndarray:
    """RMS over 25 ms windows every 10 ms, shape (samples // 160,)."""
    power = uniform_filter1d(audio.astype(np.float64) ** 2, 400)
    return np.sqrt(power[80::160][: len(audio) // 160])


def _low_energy_runs(audio: np.ndarray, *, min_seconds: float = 0.2) -> np.ndarray:
    """Stretches at least 30 dB below the loud speech, shape (runs, 2), seconds."""
    env = _rms_100hz(audio)
    low = env < 10 ** (-30 / 20) * np.percentile(env, 90)
    edges = np.diff(np.concatenate([[0], low.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    keep = (stops - starts) / 100 > min_seconds
    return np.stack([starts[keep], stops[keep]], axis=1) / 100.0


def _syllable_peaks(audio: np.ndarray) -> np.ndarray:
    """Times (s) of energy peaks of the 250-2500 Hz band, where vowels are loud."""
    sos = signal.butter(2, [250, 2500], btype="bandpass", fs=AUDIO_SR, output="sos")
    env = gaussian_filter1d(_rms_100hz(signal.sosfiltfilt(sos, audio)), 2.0)
    loud = env[env > np.percentile(env, 60)]
    peaks, _ = signal.find_peaks(env, distance=8, prominence=0.25 * np.median(loud))
    return peaks / 100.0


def _energy_15fps(audio: np.ndarray, n_frames: int) -> np.ndarray:
    """RMS of the audio over one frame around each frame time, shape (n_frames,)."""
    hop = AUDIO_SR / FPS
    power = uniform_filter1d(audio.astype(np.float64) ** 2, int(hop))
    centres = np.minimum((np.arange(n_frames) * hop).astype(np.int64), len(audio) - 1)
    return np.sqrt(power[centres])


def _wrist_speeds(positions: np.ndarray) -> np.ndarray:
    """Speed of the left and right wrist, shape (frames, 2), m/s."""
    w = positions[:, [LW, RW]].astype(np.float64)
    return np.linalg.norm(np.gradient(w, axis=0), axis=2) * FPS


def _best_lag_correlation(x: np.ndarray, y: np.ndarray, *, max_lag: int) -> float:
    """Largest Pearson correlation of ``x`` and ``y`` shifted by up to ``max_lag`` frames."""
    best = -1.0
    for lag in range(-max_lag, max_lag + 1):
        a, b = (x[lag:], y[: len(y) - lag]) if lag >= 0 else (x[:lag], y[-lag:])
        n = min(len(a), len(b))
        best = max(best, float(np.corrcoef(a[:n], b[:n])[0, 1]))
    return best


def _inside(times: np.ndarray, intervals: np.ndarray) -> np.ndarray:
    """Whether each time lies in one of the (start, stop) intervals."""
    if len(intervals) == 0:
        return np.zeros(len(times), dtype=bool)
    i = np.searchsorted(intervals[:, 0], times, side="right") - 1
    return (i >= 0) & (times < intervals[np.maximum(i, 0), 1])


# --- determinism, shapes, skeleton -------------------------------------------------------------


def test_same_seed_gives_identical_take_and_another_seed_does_not():
    a, ea = generate_demo_take(seconds=20.0, seed=7, name="a")
    b, eb = generate_demo_take(seconds=20.0, seed=7, name="b")
    c, _ = generate_demo_take(seconds=20.0, seed=8, name="c")
    assert a.audio.tobytes() == b.audio.tobytes()
    assert a.motion.positions.tobytes() == b.motion.positions.tobytes()
    np.testing.assert_array_equal(ea.nucleus_onsets, eb.nucleus_onsets)
    assert a.audio.shape == c.audio.shape
    assert not np.array_equal(a.audio, c.audio)
    assert np.abs(a.motion.positions - c.motion.positions).max() > 0.05


@settings(max_examples=8, deadline=None)
@given(seconds=st.floats(min_value=2.0, max_value=9.0), seed=st.integers(min_value=0, max_value=2**32 - 1))
def test_shapes_rates_and_constant_bones(seconds, seed):
    take, events = generate_demo_take(seconds=seconds, seed=seed, name="h")
    n_samples = int(round(seconds * AUDIO_SR))
    assert take.audio.dtype == np.float32 and take.audio.shape == (n_samples,)
    assert take.motion.fps == FPS
    assert take.motion.positions.dtype == np.float32
    assert take.motion.positions.shape == (n_samples * FPS // AUDIO_SR, N_JOINTS, 3)
    assert np.isfinite(take.audio).all() and np.abs(take.audio).max() <= 1.0
    assert np.isfinite(take.motion.positions).all()
    lengths = take.motion.bone_lengths()
    assert np.abs(lengths - lengths[0]).max() < 1e-5
    assert events.duration == pytest.approx(n_samples / AUDIO_SR)
    assert take.sources == {"generator": GENERATOR, "seed": seed, "label": DEMO_LABEL, "seconds": seconds}


def test_skeleton_is_an_upright_adult_facing_plus_z(takes):
    take, _ = takes[0]
    pos = take.motion.positions.astype(np.float64)
    lengths = take.motion.bone_lengths()[0]
    child = {name: joint_index(name) for name in ("left_elbow", "left_wrist", "right_elbow", "right_wrist")}
    parents = {n: i - 1 for n, i in child.items()}  # bone index = child index - 1 (root has none)
    for name in ("left_elbow", "right_elbow"):
        assert 0.25 < lengths[parents[name]] < 0.35, "upper arm"
    for name in ("left_wrist", "right_wrist"):
        assert 0.2 < lengths[parents[name]] < 0.3, "forearm"
    head_top = pos[:, joint_index("head_top")]
    assert (head_top[:, 1] > 0.6).all() and (head_top[:, 1] < 0.95).all()  # Y up, pelvis-relative
    assert (pos[:, joint_index("left_shoulder"), 0] > 0.1).all()  # its left is +X
    assert (pos[:, joint_index("right_shoulder"), 0] < -0.1).all()
    raised = pos[:, LW, 1] > 0.2
    assert raised.mean() > 0.1
    assert np.median(pos[raised, LW, 2]) > 0.1  # gestures happen in front: it faces +Z


def test_wrists_move_smoothly(takes):
    for take, _ in takes:
        pos = take.motion.positions.astype(np.float64)
        for j in (LW, RW):
            assert pos[:, j].std(axis=0).max() > 0.05  # metres
            step = np.linalg.norm(np.diff(pos[:, j], axis=0), axis=1)
            assert step.max() < 0.17  # at most ~2.5 m/s between frames: no jumps
            accel = np.linalg.norm(np.diff(pos[:, j], 2, axis=0), axis=1)
            assert accel.max() < 0.16
        assert np.linalg.norm(np.diff(pos, axis=0), axis=2).max() < 0.4  # any joint, fingertips too


# --- the collection ----------------------------------------------------------------------------


def test_generate_demo_takes_cuts_the_total_into_labelled_takes():
    calls = []
    takes = generate_demo_takes(minutes=0.4, take_seconds=10.0, seed=3, progress=lambda d, t: calls.append((d, t)))
    # 24 s: a 10 s take and, the 4 s remainder being too short for a take of its own, a 14 s one
    assert [len(t.audio) for t in takes] == [10 * AUDIO_SR, 14 * AUDIO_SR]
    assert [t.motion.n_frames for t in takes] == [150, 210]
    assert calls == [(0.0, 24.0), (10.0, 24.0), (24.0, 24.0)]
    assert len({t.name for t in takes}) == 2
    for k, t in enumerate(takes):
        assert t.sources["generator"] == GENERATOR and t.sources["label"] == DEMO_LABEL
        assert t.sources["seed"] == 3 and t.sources["take_index"] == k
        again, _ = generate_demo_take(seconds=t.sources["seconds"], seed=t.sources["take_seed"], name="x")
        assert again.audio.tobytes() == t.audio.tobytes()  # each take is reproducible on its own
    assert takes[0].sources["take_seed"] != takes[1].sources["take_seed"]
    assert [len(t.audio) for t in generate_demo_takes(minutes=0.5, take_seconds=20.0)] == [20 * AUDIO_SR, 10 * AUDIO_SR]


@pytest.mark.parametrize(
    "kwargs",
    [
        {"minutes": 0.0},
        {"minutes": float("nan")},
        {"take_seconds": 5.0},
        {"seed": -1},
        {"seed": 1.5},
        {"seed": True},
        {"progress": "bar"},
    ],
)
def test_generate_demo_takes_rejects_bad_arguments(kwargs):
    with pytest.raises(ConfigError):
        generate_demo_takes(**{"minutes": 0.2, "take_seconds": 12.0, **kwargs})


@pytest.mark.parametrize("seconds", [0.0, 1.0, float("inf"), 7200.0])
def test_generate_demo_take_rejects_bad_durations(seconds):
    with pytest.raises(ConfigError, match="seconds"):
        generate_demo_take(seconds=seconds, seed=0, name="x")


# --- the speech --------------------------------------------------------------------------------


def test_events_are_consistent(takes):
    for _, ev in takes:
        assert np.all(np.diff(ev.syllable_onsets) > 0)
        assert np.all(ev.syllable_onsets <= ev.nucleus_onsets) and np.all(ev.nucleus_onsets < ev.syllable_ends)
        spans = np.sort(np.concatenate([ev.phrases, ev.pauses]), axis=0)
        assert spans[0, 0] == 0.0 and spans[-1, 1] == pytest.approx(ev.duration)
        np.testing.assert_allclose(spans[1:, 0], spans[:-1, 1])  # phrases and pauses tile the take
        inter = ev.pauses[(ev.pauses[:, 0] > 0) & (ev.pauses[:, 1] < ev.duration)]
        gaps = inter[:, 1] - inter[:, 0]
        assert gaps.min() >= 0.2 - 1e-9 and gaps.max() <= 1.2 + 1e-9
        speaking = (ev.phrases[:, 1] - ev.phrases[:, 0]).sum()
        assert 3.0 <= len(ev.syllable_onsets) / speaking <= 6.0
        assert 0.2 < ev.stressed.mean() < 0.5
        # every stroke ends on (within 20 ms of) the vowel onset of its stressed syllable
        assert np.abs(ev.stroke_times - ev.stroke_stress_onsets).max() <= 0.02 + 1e-9
        assert np.isin(ev.stroke_stress_onsets, ev.stress_onsets).all()
        assert set(ev.stroke_hands) <= {"left", "right", "both"}
    modes = {m for _, ev in takes for m in ev.gesture_modes}
    assert modes == {"symmetric", "asymmetric", "left", "right"}


def test_syllable_rate_measured_from_the_audio(takes):
    for take, ev in takes:
        peaks = _syllable_peaks(take.audio)
        runs = _low_energy_runs(take.audio)
        speaking = ev.duration - (runs[:, 1] - runs[:, 0]).sum()
        assert 3.0 <= len(peaks) / speaking <= 6.0
        # the peaks are the syllables the generator planned: about as many, each in a vowel
        assert 0.75 <= len(peaks) / len(ev.syllable_onsets) <= 1.05  # observed 0.84-0.89
        vowels = np.stack([ev.nucleus_onsets - 0.03, ev.syllable_ends + 0.03], axis=1)
        assert _inside(peaks, vowels).mean() > 0.95


def test_pauses_are_near_silent_stretches(takes):
    for take, ev in takes:
        runs = _low_energy_runs(take.audio)
        inter = ev.pauses[(ev.pauses[:, 0] > 0) & (ev.pauses[:, 1] < ev.duration)]
        assert len(runs) >= 0.9 * len(inter) and len(inter) >= 8
        assert _inside((inter[:, 0] + inter[:, 1]) / 2, runs).mean() > 0.9  # the silence is audible
        assert _inside((runs[:, 0] + runs[:, 1]) / 2, ev.pauses).mean() > 0.95  # and only there
        # a little room noise, about 50 dB below the speech
        quiet = np.concatenate([take.audio[int((a + 0.05) * AUDIO_SR) : int((b - 0.05) * AUDIO_SR)] for a, b in inter])
        loud = np.concatenate([take.audio[int(a * AUDIO_SR) : int(b * AUDIO_SR)] for a, b in ev.phrases])
        ratio_db = 20 * np.log10(np.sqrt(np.mean(quiet.astype(np.float64) ** 2)) / np.sqrt(np.mean(loud**2.0)))
        assert -70 < ratio_db < -35


def test_mfcc_and_energy_vary_like_speech(takes):
    take, ev = takes[0]
    seconds = 30
    m = audio_frame_features(take.audio[: seconds * AUDIO_SR])
    t = np.arange(len(m)) / FPS
    vowel = _inside(t, np.stack([ev.nucleus_onsets, ev.syllable_ends], axis=1))
    pause = _inside(t, ev.pauses - np.array([-0.1, 0.1]))
    assert vowel.sum() > 100 and pause.sum() > 20
    assert np.median(m[vowel, 13]) - np.median(m[pause, 13]) > 8.0  # log energy: speech vs silence
    mfcc_std = m[vowel, 1:13].std(axis=0)
    assert (mfcc_std[:4] > 3.0).all() and (mfcc_std > 1.0).all()  # vowel colour and loudness vary
    # stressed vowels are louder than unstressed ones
    stressed = _inside(t, np.stack([ev.nucleus_onsets, ev.syllable_ends], axis=1)[ev.stressed])
    assert np.median(m[stressed, 13]) > np.median(m[vowel & ~stressed, 13]) + 0.5


# --- audio and motion together -----------------------------------------------------------------

#: smoothing of the energy envelope and the wrist speed (frames, Gaussian sigma; 1/3 s)
SMOOTH = 5.0
#: the best lag is searched within +-0.5 s
MAX_LAG = 7


def test_audio_energy_and_hand_speed_correlate(takes):
    energy = [gaussian_filter1d(_energy_15fps(t.audio, t.motion.n_frames), SMOOTH) for t, _ in takes]
    speed = [gaussian_filter1d(_wrist_speeds(t.motion.positions).sum(axis=1), SMOOTH) for t, _ in takes]
    n = len(takes)
    r = np.array([[_best_lag_correlation(energy[i], speed[j], max_lag=MAX_LAG) for j in range(n)] for i in range(n)])
    matched = np.diag(r)
    mismatched = r[~np.eye(n, dtype=bool)]
    # a take's own motion follows its speech (observed: 0.21-0.52, mean 0.41; the hands move
    # in some pauses, where they retract) ...
    assert matched.mean() > 0.3 and matched.min() > 0.15
    # ... clearly more than another take's motion does (observed: mean 0.04)
    assert matched.mean() - mismatched.mean() > 0.2
    for i in range(n):
        assert matched[i] > np.delete(r[i], i).mean() + 0.1


def _speed_minima(speeds: np.ndarray) -> np.ndarray:
    """Times (s) of the local minima of the summed wrist speed, smoothed over about a frame."""
    return signal.argrelmin(gaussian_filter1d(speeds.sum(axis=1), 1.0))[0] / FPS


def test_strokes_end_on_stressed_syllables(takes):
    rng = np.random.default_rng(0)
    hits, chance = [], []
    for take, ev in takes:
        speeds = _wrist_speeds(take.motion.positions)
        minima = _speed_minima(speeds)

        def share_on(times, minima=minima):
            # share of the times with a velocity minimum (a motion beat) within about a frame
            return np.mean(np.abs(minima[:, None] - times[None, :]).min(axis=0) <= 0.07)

        hits.append(share_on(ev.stress_onsets))
        shifted = [np.sort((ev.stress_onsets + rng.uniform(1, ev.duration - 1)) % ev.duration) for _ in range(50)]
        chance.append(np.mean([share_on(s) for s in shifted]))
        # the hand stops where a stroke ends (observed 0.89-0.97 of the strokes) ...
        assert share_on(ev.stroke_times) > 0.75
        # ... having moved fast just before: the stroke precedes the stress
        hand = np.array([{"left": 0, "right": 1, "both": 0}[h] for h in ev.stroke_hands])
        end = np.round(ev.stroke_times * FPS).astype(int)
        before = np.max([speeds[end - k, hand] for k in (1, 2, 3)], axis=0)
        assert np.mean(before > np.percentile(speeds[:, 0], 75)) > 0.7  # observed 0.78-0.93
        assert np.mean(speeds[end, hand] < 0.5 * before) > 0.9  # observed 0.95-0.98
    hits, chance = np.mean(hits), np.mean(chance)
    # observed: 0.75 of the stressed vowel onsets fall on a motion beat, against 0.29 for
    # stresses shifted at random
    assert hits > 2.0 * chance and hits > chance + 0.3


def test_control_attributes_have_wide_ranges(takes):
    pos = np.concatenate([t.motion.positions for t, _ in takes]).astype(np.float64)
    lw, rw = pos[:, LW], pos[:, RW]
    axis = pos[:, joint_index("upper_chest")]
    height = lw[:, 1]
    assert np.percentile(height, 85) - np.percentile(height, 15) > 0.2  # left wrist height, m
    width = np.hypot(lw[:, 0] - axis[:, 0], lw[:, 2] - axis[:, 2])
    assert np.percentile(width, 85) - np.percentile(width, 15) > 0.1  # distance from the body axis, m
    speeds = np.concatenate([_wrist_speeds(t.motion.positions) for t, _ in takes])
    for h, wrist in enumerate((lw, rw)):  # both hands gesture: raised and fast often enough
        assert (wrist[:, 1] > 0.1).mean() > 0.2
        assert (speeds[:, h] > 0.5).mean() > 0.05
    mean_speed = speeds.mean(axis=1)
    assert np.percentile(mean_speed, 85) > 8 * np.percentile(mean_speed, 15)  # holds and strokes
    # symmetric stretches with both hands up, asymmetric ones with at least one hand up
    mirrored = rw.copy()
    mirrored[:, 0] = 2 * axis[:, 0] - rw[:, 0]  # the right wrist mirrored across the body's midplane
    asym = np.linalg.norm(lw - mirrored, axis=1)
    n = len(pos) // FPS * FPS  # one-second windows

    def windows(x):
        return x[:n].reshape(-1, FPS)

    both_up = windows((lw[:, 1] > 0.1) & (rw[:, 1] > 0.1)).all(axis=1)
    one_up = windows((lw[:, 1] > 0.1) | (rw[:, 1] > 0.1)).all(axis=1)
    a = windows(asym).mean(axis=1)
    assert (both_up & (a < 0.06)).sum() >= 10  # observed 57 of 240
    assert (one_up & (a > 0.25)).sum() >= 10  # observed 81


def test_the_demo_body_is_posed_by_the_bvh_readers_forward_kinematics():
    # one forward kinematics in the package: a fix to it reaches both the reader and the generator
    from gesturekit.datasets import _demo_body, _kinematics, bvh

    assert _demo_body.world_positions is _kinematics.world_positions is bvh.world_positions
    rng = np.random.default_rng(0)
    n = 5
    local = [np.linalg.qr(rng.normal(size=(n, 3, 3)))[0] for _ in range(N_JOINTS)]
    root = rng.normal(size=(n, 3))
    pos = _demo_body._forward_kinematics(root, local)
    # the same chain written out joint by joint: world rotation of the parent times the rest offset
    off = _demo_body._rest_offsets()
    from gesturekit.skeleton import PARENTS

    glob = [None] * N_JOINTS
    expect = np.empty_like(pos)
    for j, p in enumerate(PARENTS):
        if p < 0:
            glob[j], expect[:, j] = local[j], root
        else:
            glob[j] = glob[p] @ local[j]
            expect[:, j] = expect[:, p] + glob[p] @ off[j]
    np.testing.assert_allclose(pos, expect, atol=1e-12)
