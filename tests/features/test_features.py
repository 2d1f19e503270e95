"""Tests of gesturekit.features: the 15 fps frame grid, per-frame audio features,
feature stacking and padding, the layout, and z-scoring."""

from __future__ import annotations

import dataclasses
import json
import math
from fractions import Fraction

import librosa
import numpy as np
import pytest
import scipy.fft
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.errors import ConfigError
from gesturekit.features import (
    LAYOUT,
    FeatureLayout,
    ZScore,
    _MelBands,
    audio_frame_features,
    cgan_audio_features,
    frame_centres,
    mel_filterbank,
    n_audio_frames,
    pose_features,
    stack_audio_features,
    valid_starts,
)
from gesturekit.skeleton import N_JOINTS, POSE_FEATURE_JOINTS, joint_index

SR, FPS = 16000, 15
ENERGY = LAYOUT.n_mfcc  # column of the log mean energy in m_t
SILENCE = math.log(1e-10)  # log energy of a window of zeros


def add_burst(x: np.ndarray, t_burst: float, *, sr: int = SR, half_width: float = 0.005) -> None:
    """Add, in place, a 10 ms Hann-shaped 1 kHz tone burst centred at ``t_burst`` seconds.

    The burst is evaluated in continuous time, so its centre need not fall on a sample.
    """
    first = math.ceil((t_burst - half_width) * sr)
    n = np.arange(first, math.floor((t_burst + half_width) * sr) + 1)
    tau = n / sr - t_burst
    x[n] += (np.cos(np.pi * tau / (2 * half_width)) ** 2 * np.cos(2 * np.pi * 1000 * tau)).astype(x.dtype)


# --- the frame grid --------------------------------------------------------------------


@pytest.mark.slow
def test_energy_peaks_land_on_the_15fps_grid_after_an_hour():
    """The acceptance pin of the frame grid: no drift over 60 minutes of audio.

    15 fps does not divide 16 kHz (1066.67 samples per frame); a grid built by
    adding a rounded hop of 1067 samples would be 1.1 s (17 frames) late after
    an hour. Bursts sit on frame centres and up to 0.3 frame off them, near the
    start and after 60 minutes; each must peak in frame round(t * 15), and the
    late bursts' energy profiles must match their early twins'.
    """
    offsets = (0.0, 0.3, -0.3, 0.15, -0.25)
    early = [20 + 15 * i for i in range(len(offsets))]
    late = [60 * 60 * FPS + k for k in early]
    x = np.zeros((60 * 60 + 12) * SR, dtype=np.float32)  # 231 MB; bursts touch only a few pages
    for k, delta in zip(early + late, offsets + offsets):
        add_burst(x, (k + delta) / FPS)

    m = audio_frame_features(x, chunk_frames=1024)  # smaller chunks bound the temporary memory
    del x

    assert m.shape == (n_audio_frames(60 * 60 * SR + 12 * SR), 14) == (54180, 14)
    energy = m[:, ENERGY]
    for k, delta in zip(early + late, offsets + offsets):
        expected = round((k + delta) / FPS * FPS)
        assert expected == k
        window = energy[k - 7 : k + 8]
        peak = k - 7 + int(np.argmax(window))
        assert peak == k, f"burst at {(k + delta) / FPS:.4f} s peaked in frame {peak}, not {k}"
        assert window[7] > SILENCE + 10
    # an hour is a whole number of samples, so twins see identical windows; a drift
    # of a single sample already moves the neighbouring frames' energies by ~0.005
    for k_early, k_late in zip(early, late):
        np.testing.assert_allclose(energy[k_late - 2 : k_late + 3], energy[k_early - 2 : k_early + 3], atol=1e-3)
    # between bursts the windows see only zeros
    np.testing.assert_allclose(energy[200:53900], SILENCE, rtol=1e-6)


SR_FPS = [(16000, 15), (16000, 30), (16000, 60), (8000, 15), (22050, 15), (44100, 24), (44100, 30), (48000, 25)]


@settings(deadline=None, max_examples=60)
@given(sr_fps=st.sampled_from(SR_FPS), data=st.data())
def test_frame_centres_are_exact_over_ten_hours(sr_fps, data):
    sr, fps = sr_fps
    t = data.draw(st.integers(0, 10 * 3600 * fps - 1), label="frame")
    c = frame_centres(t + 1, sr=sr, fps=fps)

    assert c.dtype == np.int64 and c.shape == (t + 1,)
    exact = Fraction(t * sr, fps)
    assert abs(c[t] - exact) <= Fraction(1, 2)
    assert c[t] == math.floor(exact + Fraction(1, 2))  # rounded half up, from t itself
    hop = Fraction(sr, fps)
    steps = np.diff(c)
    assert np.all((steps == math.floor(hop)) | (steps == math.ceil(hop)))  # monotonic, never a skipped frame
    # a frame's centre does not depend on how many frames were asked for
    k = data.draw(st.integers(0, t), label="prefix")
    np.testing.assert_array_equal(frame_centres(k + 1, sr=sr, fps=fps), c[: k + 1])


@settings(deadline=None)
@given(n_samples=st.integers(0, 10 * 3600 * 48000), sr_fps=st.sampled_from(SR_FPS))
def test_whole_frames_have_their_centre_inside_the_audio(n_samples, sr_fps):
    sr, fps = sr_fps
    n = n_audio_frames(n_samples, sr=sr, fps=fps)
    assert n == math.floor(Fraction(n_samples * fps, sr))
    if n:
        last_centre = math.floor(Fraction((n - 1) * sr, fps) + Fraction(1, 2))
        assert last_centre < n_samples


# --- per-frame audio features ------------------------------------------------------------


def literal_frame_features(audio: np.ndarray, t: int) -> np.ndarray:
    """m_t computed for one frame the long way, shape (14,)."""
    n_fft = LAYOUT.n_fft
    centre = round(Fraction(t * SR, FPS))  # exact, and no frame here is a half-sample tie
    segment = np.zeros(n_fft)
    for i in range(n_fft):
        j = centre - n_fft // 2 + i
        if 0 <= j < len(audio):
            segment[i] = audio[j]
    window = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(n_fft) / n_fft)  # periodic Hann
    power = np.abs(np.fft.rfft(segment * window)) ** 2
    mel = librosa.filters.mel(sr=SR, n_fft=n_fft, n_mels=LAYOUT.n_mels, fmin=0.0, fmax=SR / 2)
    mel_db = 10 * np.log10(np.maximum(mel @ power, 1e-10))
    mfcc = scipy.fft.dct(mel_db, type=2, norm="ortho")[: LAYOUT.n_mfcc]
    energy = np.log(np.sum(window * segment**2) / np.sum(window) + 1e-10)
    return np.concatenate([mfcc, [energy]])


@pytest.mark.parametrize(
    "sr, n_fft, n_mels",
    [(SR, LAYOUT.n_fft, LAYOUT.n_mels), (22050, 2048, 128), (16000, 512, 64), (8000, 256, 20), (44100, 1024, 80)],
)
def test_mel_filterbank_is_librosas_bit_for_bit(sr, n_fft, n_mels):
    ours = mel_filterbank(sr=sr, n_fft=n_fft, n_mels=n_mels)
    theirs = librosa.filters.mel(sr=sr, n_fft=n_fft, n_mels=n_mels, fmin=0.0, fmax=sr / 2)
    assert ours.dtype == theirs.dtype == np.float32
    np.testing.assert_array_equal(ours, theirs)


@pytest.mark.slow
def test_mfccs_are_librosas_power_to_db_and_mfcc_bit_for_bit():
    """Our dB and DCT steps are librosa's, operation for operation (librosa is not imported at run time);
    the mel power is librosa's matrix product up to float32 rounding (we sum each band in a fixed order)."""
    rng = np.random.default_rng(9)
    audio = (0.2 * rng.standard_normal(3 * SR) * np.abs(np.sin(np.linspace(0, 9, 3 * SR)))).astype(np.float32)
    audio[SR : SR + 4000] = 0.0  # silence: the 1e-10 floor
    m = audio_frame_features(audio)
    n_fft, half = LAYOUT.n_fft, LAYOUT.n_fft // 2
    centres = frame_centres(m.shape[0], sr=SR, fps=FPS)
    idx = centres[:, None] + np.arange(-half, n_fft - half)[None, :]
    frames = np.where((idx >= 0) & (idx < audio.size), audio[np.clip(idx, 0, audio.size - 1)], 0.0).astype(np.float32)
    spec = scipy.fft.rfft(frames * np.hanning(n_fft + 1)[:-1].astype(np.float32), axis=1)
    power = spec.real**2 + spec.imag**2
    mel = librosa.filters.mel(sr=SR, n_fft=n_fft, n_mels=LAYOUT.n_mels, fmin=0.0, fmax=SR / 2)
    ours = _MelBands.of(LAYOUT).apply(power)
    np.testing.assert_allclose(ours, power @ mel.T, rtol=1e-5, atol=1e-12)
    mel_db = librosa.power_to_db(ours, ref=1.0, amin=1e-10, top_db=None)
    np.testing.assert_array_equal(m[:, : LAYOUT.n_mfcc], librosa.feature.mfcc(S=mel_db.T, n_mfcc=LAYOUT.n_mfcc).T)


def test_a_frames_features_depend_on_its_own_samples_only():
    """Frames computed in any pieces equal frames computed at once, bit for bit (what streaming relies on)."""
    audio = (0.1 * np.random.default_rng(4).standard_normal(4 * SR)).astype(np.float32)
    whole = audio_frame_features(audio)
    for size in (1, 7, 13, 60):
        pieces = [
            audio_frame_features(audio, first_frame=f, n_frames=min(size, len(whole) - f))
            for f in range(0, len(whole), size)
        ]
        np.testing.assert_array_equal(np.concatenate(pieces), whole)
        np.testing.assert_array_equal(audio_frame_features(audio, chunk_frames=size), whole)


def test_audio_frame_features_match_a_literal_computation():
    rng = np.random.default_rng(5)
    audio = (0.1 * rng.standard_normal(2 * SR) * np.linspace(0.2, 1.0, 2 * SR)).astype(np.float32)
    m = audio_frame_features(audio)
    assert m.shape == (30, 14) and m.dtype == np.float32
    for t in (0, 1, 7, 16, 29):  # 0 and 29 reach past the ends of the audio
        np.testing.assert_allclose(m[t], literal_frame_features(audio, t), rtol=1e-4, atol=2e-3)


def test_all_zero_audio_gives_finite_identical_frames():
    m = audio_frame_features(np.zeros(3 * SR, np.float32))
    assert m.shape == (45, 14) and np.all(np.isfinite(m))
    np.testing.assert_array_equal(m, np.broadcast_to(m[0], m.shape))
    np.testing.assert_allclose(m[:, ENERGY], SILENCE, rtol=1e-6)
    assert audio_frame_features(np.zeros(0, np.float32)).shape == (0, 14)


def test_frames_past_the_end_see_silence():
    audio = np.random.default_rng(2).uniform(-0.5, 0.5, SR).astype(np.float32)  # 15 frames
    m = audio_frame_features(audio, n_frames=25)
    np.testing.assert_allclose(m[:15], audio_frame_features(audio), rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(m[17:, ENERGY], SILENCE, rtol=1e-6)


def test_features_are_deterministic_and_independent_of_chunking():
    audio = np.random.default_rng(9).standard_normal(5 * SR).astype(np.float32) * 0.1
    a = audio_frame_features(audio)
    np.testing.assert_array_equal(a, audio_frame_features(audio.copy()))
    np.testing.assert_array_equal(audio_frame_features(audio, chunk_frames=7), a)


def test_shifting_audio_by_whole_frames_shifts_the_features():
    # 3 frames are exactly 3200 samples at 16 kHz, so every window moves with the audio
    audio = np.zeros(4 * SR, np.float32)
    add_burst(audio, 1.234)
    add_burst(audio, 2.5, half_width=0.02)
    shifted = np.concatenate([np.zeros(3200, np.float32), audio])
    np.testing.assert_allclose(audio_frame_features(shifted)[3:63], audio_frame_features(audio)[:60], atol=1e-4)


def test_audio_must_be_mono():
    with pytest.raises(ConfigError, match="mono"):
        audio_frame_features(np.zeros((SR, 2), np.float32))


# --- stacking, padding, valid starts -------------------------------------------------------


@settings(deadline=None)
@given(n=st.integers(1, 40), seed=st.integers(0, 2**32 - 1))
def test_stack_audio_features_matches_a_loop(n, seed):
    m = np.random.default_rng(seed).standard_normal((n, 14)).astype(np.float32)
    f = stack_audio_features(m)
    assert f.shape == (n, LAYOUT.audio_dim) and f.dtype == np.float32
    for t in range(n):
        expected = []
        for offset in (0, 2, 4, 6, 8, 10, 12, 14):
            expected.extend(m[min(t + offset, n - 1)])  # past the end the last frame repeats
        np.testing.assert_array_equal(f[t], expected)
    np.testing.assert_array_equal(f[:, LAYOUT.slices["mfcc"]], m[:, :13])
    np.testing.assert_array_equal(f[:, LAYOUT.slices["log_energy"]], m[:, 13:])


@settings(deadline=None)
@given(n=st.integers(1, 20), seed=st.integers(0, 2**32 - 1))
def test_pose_features_match_a_loop(n, seed):
    positions = np.random.default_rng(seed).standard_normal((n, N_JOINTS, 3)).astype(np.float32)
    p = pose_features(positions)
    assert p.shape == (n, LAYOUT.pose_dim) and p.dtype == np.float32
    for t in range(n):
        expected = []
        for offset in (0, 2, 4, 6):
            for name in POSE_FEATURE_JOINTS:
                expected.extend(positions[min(t + offset, n - 1), joint_index(name)])  # x, y, z
        np.testing.assert_array_equal(p[t], expected)


@settings(deadline=None)
@given(n=st.integers(0, 60), extra=st.integers(1, 20), seed=st.integers(0, 2**32 - 1))
def test_valid_starts_are_exactly_the_unpadded_frames(n, extra, seed):
    valid = valid_starts(n)
    assert valid.shape == (n,) and valid.dtype == bool
    np.testing.assert_array_equal(valid, np.arange(n) + 14 < n)
    if n == 0:
        return
    rng = np.random.default_rng(seed)
    m = rng.standard_normal((n + extra, 14)).astype(np.float32)
    positions = rng.standard_normal((n + extra, N_JOINTS, 3)).astype(np.float32)
    # appending frames changes a feature iff it was padded
    f_cut, f_long = stack_audio_features(m[:n]), stack_audio_features(m)[:n]
    p_cut, p_long = pose_features(positions[:n]), pose_features(positions)[:n]
    np.testing.assert_array_equal(f_cut[valid], f_long[valid])
    np.testing.assert_array_equal(p_cut[valid], p_long[valid])
    assert not np.any(np.all(f_cut[~valid] == f_long[~valid], axis=1))


def test_shape_errors():
    with pytest.raises(ConfigError):
        stack_audio_features(np.zeros((5, 13), np.float32))
    with pytest.raises(ConfigError):
        pose_features(np.zeros((5, 54, 3), np.float32))


def test_cgan_audio_features_append_the_time_derivative():
    t = np.arange(10, dtype=np.float32)[:, None]
    m = np.hstack([0.5 * t] * 7 + [-2.0 * t] * 7)
    c = cgan_audio_features(m)
    assert c.shape == (10, LAYOUT.cgan_audio_dim)
    np.testing.assert_array_equal(c[:, :14], m)
    np.testing.assert_allclose(c[:, 14:], np.array([0.5] * 7 + [-2.0] * 7)[None].repeat(10, 0))
    np.testing.assert_array_equal(cgan_audio_features(m[:1])[:, 14:], 0)


# --- layout ---------------------------------------------------------------------------------


def test_layout_sizes_and_slices():
    assert (LAYOUT.frame_dim, LAYOUT.audio_dim, LAYOUT.pose_dim, LAYOUT.motion_dim, LAYOUT.cgan_audio_dim) == (
        14,
        112,
        96,
        165,
        28,
    )
    assert (LAYOUT.audio_lookahead, LAYOUT.pose_lookahead) == (14, 6)
    s = LAYOUT.slices
    assert (s["audio"], s["pose"]) == (slice(0, 112), slice(112, 208))
    assert (s["mfcc"], s["log_energy"]) == (slice(0, 13), slice(13, 14))
    feature = np.arange(208)
    assert len(feature[s["audio"]]) + len(feature[s["pose"]]) == 208


def test_layout_signature_changes_with_every_field():
    changed = {
        "sr": 22050,
        "fps": 30,
        "n_mfcc": 20,
        "n_mels": 64,
        "n_fft": 1024,
        "audio_offsets": (0, 1, 2, 3),
        "pose_offsets": (0, 3),
        "pose_joints": POSE_FEATURE_JOINTS[:-1] + ("right_thumb1",),
        "n_joints": 56,
    }
    assert set(changed) == {f.name for f in dataclasses.fields(FeatureLayout)}, "give every field a new value here"
    base = LAYOUT.signature()
    assert json.loads(json.dumps(base)) == base == FeatureLayout().signature()
    for name, value in changed.items():
        other = dataclasses.replace(LAYOUT, **{name: value})
        assert other.signature() != base, name
        assert json.loads(json.dumps(other.signature())) == other.signature()


# --- z-scoring ------------------------------------------------------------------------------


@settings(deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    log_scale=st.floats(-2, 3),
    shift=st.floats(-100, 100),
    constant=st.floats(-1e3, 1e3, width=32),
)
def test_zscore_round_trip(seed, log_scale, shift, constant):
    rng = np.random.default_rng(seed)
    scale = 10.0**log_scale * np.array([1.0, 0.01, 30.0, 1e-3, 5.0])
    # offsets proportional to the spread, so float32 can still resolve the spread
    x = (shift * scale + rng.standard_normal((500, 5)) * scale).astype(np.float32)
    x = np.hstack([x, np.full((500, 1), constant, np.float32)])
    z = ZScore.fit(x)
    y = z.apply(x)
    assert y.dtype == np.float32 and y.shape == x.shape
    np.testing.assert_allclose(y[:, :5].mean(axis=0), 0.0, atol=1e-3)
    np.testing.assert_allclose(y[:, :5].std(axis=0), 1.0, atol=1e-3)
    np.testing.assert_array_equal(y[:, 5], 0.0)  # a constant dimension maps to 0, not to inf
    back = z.invert(y)
    tolerance = 1e-5 * (abs(shift) + 5) * np.append(scale, abs(constant) + 1)
    assert np.all(np.abs(back - x) <= tolerance)
    np.testing.assert_array_equal(back[:, 5], constant)


def test_zscore_fits_over_all_leading_axes():
    x = np.random.default_rng(0).standard_normal((4, 30, 5)).astype(np.float32) * 3 + 1
    a, b = ZScore.fit(x), ZScore.fit(x.reshape(-1, 5))
    np.testing.assert_array_equal(a.mean, b.mean)
    np.testing.assert_array_equal(a.std, b.std)
    assert a.apply(x).shape == x.shape
