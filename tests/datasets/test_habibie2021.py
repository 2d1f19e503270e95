"""Tests of gesturekit.datasets.habibie2021: the npz layout of Habibie et al. 2021."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from gesturekit.datasets.habibie2021 import load_habibie2021
from gesturekit.errors import ConfigError, GestureKitWarning, MotionFileError
from gesturekit.motion import AUDIO_SR, Take

FRAMES = 30  # 2 s at 15 fps
SAMPLES = 2 * AUDIO_SR


def make(n_seq=3, frames=FRAMES, samples=SAMPLES, seed=0):
    rng = np.random.default_rng(seed)
    wav = rng.uniform(-0.5, 0.5, (n_seq, samples)).astype(np.float32)
    body = rng.normal(0.0, 0.2, (n_seq, frames, 165)).astype(np.float32)
    mfcc = rng.normal(size=(n_seq, frames, 13)).astype(np.float32)
    return wav, body, mfcc


def test_reads_takes(tmp_path):
    wav, body, mfcc = make()
    path = tmp_path / "oliver.npz"
    np.savez(path, wav=wav, body=body, mfcc=mfcc)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # equal lengths: no warning
        takes = load_habibie2021(path)
    assert len(takes) == 3 and all(isinstance(t, Take) for t in takes)
    for i, take in enumerate(takes):
        assert take.name == f"oliver_{i:04d}"
        assert take.sources == {"file": str(path), "sequence": i}
        assert take.motion.fps == 15 and take.motion.positions.shape == (FRAMES, 55, 3)
        np.testing.assert_array_equal(take.motion.flat(), body[i])
        assert take.audio.dtype == np.float32
        np.testing.assert_array_equal(take.audio, wav[i])
        assert take.duration == pytest.approx(2.0)


def test_int16_audio_units_and_4d_body(tmp_path):
    wav, body, _ = make(n_seq=2)
    pcm = (wav * 32767).astype(np.int16)
    path = tmp_path / "pcm.npz"
    np.savez(path, wav=pcm[..., None], body=(body * 100).reshape(2, FRAMES, 55, 3))
    takes = load_habibie2021(path, units="cm")
    np.testing.assert_allclose(takes[1].audio, pcm[1] / 32768.0, atol=1e-7)
    np.testing.assert_allclose(takes[1].motion.flat(), body[1], atol=1e-5)
    with pytest.raises(ConfigError):
        load_habibie2021(path, units="inch")


def test_joint_order(tmp_path):
    wav, body, _ = make(n_seq=2)
    order = np.random.default_rng(1).permutation(55)
    path = tmp_path / "perm.npz"
    np.savez(path, wav=wav, body=body)
    takes = load_habibie2021(path, joint_order=order)
    np.testing.assert_array_equal(takes[0].motion.positions, body[0].reshape(FRAMES, 55, 3)[:, order])
    np.savez(path, wav=wav, body=body, joint_order=order)
    np.testing.assert_array_equal(load_habibie2021(path)[1].motion.positions, body[1].reshape(FRAMES, 55, 3)[:, order])
    # the argument wins over the stored order
    np.testing.assert_array_equal(load_habibie2021(path, joint_order=np.arange(55))[1].motion.flat(), body[1])
    with pytest.raises(ConfigError, match="permutation"):
        load_habibie2021(path, joint_order=np.zeros(55, dtype=int))
    np.savez(path, wav=wav, body=body, joint_order=np.arange(54))
    with pytest.raises(MotionFileError, match="perm.npz.*permutation"):
        load_habibie2021(path)


@pytest.mark.parametrize(
    "samples, frames_kept, samples_kept, gap",
    [
        (AUDIO_SR, 15, AUDIO_SR, "1.000 s"),  # audio 1 s shorter: motion trimmed
        (3 * AUDIO_SR, FRAMES, SAMPLES, "1.000 s"),  # audio 1 s longer: audio trimmed
        (SAMPLES - 4000, 26, 27733, "0.250 s"),  # a quarter second shorter
    ],
)
def test_length_mismatch_trims_with_a_warning(tmp_path, samples, frames_kept, samples_kept, gap):
    wav, body, _ = make(n_seq=2, samples=samples)
    path = tmp_path / "mismatch.npz"
    np.savez(path, wav=wav, body=body)
    with pytest.warns(GestureKitWarning, match=gap):
        takes = load_habibie2021(path)
    for i, take in enumerate(takes):
        assert take.motion.n_frames == frames_kept and len(take.audio) == samples_kept
        np.testing.assert_array_equal(take.motion.flat(), body[i, :frames_kept])
        np.testing.assert_array_equal(take.audio, wav[i, :samples_kept])
        assert abs(take.motion.duration - len(take.audio) / AUDIO_SR) <= 0.5 / 15


def test_small_mismatch_is_silent(tmp_path):
    wav, body, _ = make(n_seq=1, samples=SAMPLES + 300)  # 19 ms more audio than motion
    path = tmp_path / "close.npz"
    np.savez(path, wav=wav, body=body)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        (take,) = load_habibie2021(path)
    assert take.motion.n_frames == FRAMES and len(take.audio) == SAMPLES


def _bad_archives():
    wav, body, mfcc = make(n_seq=2)
    nan_body = body.copy()
    nan_body[1, 3, 7] = np.nan
    inf_wav = wav.copy()
    inf_wav[0, 10] = np.inf
    return {
        "no_wav": ({"body": body}, "missing key.*wav"),
        "no_body": ({"wav": wav}, "missing key.*body"),
        "body_shape": ({"wav": wav, "body": body[..., :164]}, "'body' must have shape"),
        "wav_shape": ({"wav": wav[0], "body": body}, "'wav' must have shape"),
        "count": ({"wav": wav[:1], "body": body}, "1 sequences but 'body' has 2"),
        "mfcc_shape": ({"wav": wav, "body": body, "mfcc": mfcc[0]}, "'mfcc' must have shape"),
        "nan_body": ({"wav": wav, "body": nan_body}, "'body' contains NaN.*sequence 1"),
        "inf_wav": ({"wav": inf_wav, "body": body}, "'wav' contains NaN.*sequence 0"),
        "string_body": ({"wav": wav, "body": np.array([["a"]])}, "shape|numbers"),
        "int_wav": ({"wav": (wav * 100).astype(np.int64), "body": body}, "int16"),
        "empty": ({"wav": wav[:, :0], "body": body}, "no data"),
        "tiny_audio": ({"wav": wav[:, :100], "body": body}, "shorter than one motion frame"),
    }


@pytest.mark.parametrize("case", sorted(_bad_archives()))
def test_bad_archives_raise_motion_file_error_naming_the_file(tmp_path, case):
    arrays, fragment = _bad_archives()[case]
    path = tmp_path / f"bad_{case}.npz"
    np.savez(path, **arrays)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GestureKitWarning)
        with pytest.raises(MotionFileError, match=fragment) as info:
            load_habibie2021(path)
    assert f"bad_{case}.npz" in str(info.value)


def test_not_an_archive(tmp_path):
    with pytest.raises(MotionFileError, match="absent.npz.*not found"):
        load_habibie2021(tmp_path / "absent.npz")
    text = tmp_path / "text.npz"
    text.write_text("hello")
    with pytest.raises(MotionFileError, match="text.npz.*npz"):
        load_habibie2021(text)
    single = tmp_path / "single.npy"
    np.save(single, np.zeros((2, 3)))
    with pytest.raises(MotionFileError, match="single.npy.*single array"):
        load_habibie2021(single)
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, wav=np.array([{"a": 1}], dtype=object), body=np.zeros((1, FRAMES, 165)))
    with pytest.raises(MotionFileError, match="pickled.npz"):
        load_habibie2021(pickled)


# ---- discovery reads headers only, and never unpickles ---------------------------------------
from gesturekit.datasets.habibie2021 import count_sequences, is_habibie2021_npz  # noqa: E402
from gesturekit.datasets.takes import count_takes, discover_takes  # noqa: E402


@pytest.mark.parametrize("body_shape, n", [((3, FRAMES, 165), 3), ((2, FRAMES, 55, 3), 2), ((FRAMES, 165), 1)])
def test_sequences_are_counted_from_the_header(tmp_path, body_shape, n):
    path = tmp_path / "s.npz"
    np.savez(path, wav=np.zeros((n, SAMPLES), np.float32), body=np.zeros(body_shape, np.float32))
    assert is_habibie2021_npz(path) and count_sequences(path) == n
    assert count_takes(discover_takes(tmp_path)) == n


def test_object_body_is_refused_without_unpickling(tmp_path, monkeypatch):
    import pickle

    path = tmp_path / "s.npz"
    np.savez(path, wav=np.zeros((1, SAMPLES), np.float32), body=np.array([{"a": 1}], dtype=object))

    def no_unpickling(*args, **kwargs):
        raise AssertionError("unpickled")

    monkeypatch.setattr(pickle, "load", no_unpickling)
    monkeypatch.setattr(pickle, "loads", no_unpickling)
    with pytest.raises(MotionFileError, match="dtype object.*never unpickles") as info:
        count_sequences(path)
    assert info.value.path == str(path)
    with pytest.raises(MotionFileError, match="Object arrays cannot be loaded"):
        load_habibie2021(path)


@pytest.mark.parametrize("keep", [0.2, 0.6, 0.95])
def test_truncated_archive_is_refused_in_discovery(tmp_path, keep):
    wav, body, mfcc = make()
    path = tmp_path / "s.npz"
    np.savez(path, wav=wav, body=body, mfcc=mfcc)
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(MotionFileError, match="not a readable npz archive.*truncated") as info:
        discover_takes(tmp_path, kind="habibie2021")
    assert info.value.path == str(path)
