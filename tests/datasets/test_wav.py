"""The package's one WAV encoder (gesturekit.datasets.audio.wav_bytes / write_wav)."""

from __future__ import annotations

import io
import wave

import numpy as np
import pytest
import soundfile as sf
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from gesturekit.datasets.audio import load_audio, wav_bytes, write_wav
from gesturekit.errors import ConfigError
from gesturekit.motion import AUDIO_SR
from gesturekit.outputs import check_output


def wave_module_pcm16(samples: np.ndarray, sr: int) -> bytes:
    """The plain reference: Python's wave module fed round(32767 * clip(x))."""
    pcm = np.round(np.clip(np.nan_to_num(np.asarray(samples, np.float64)), -1, 1) * 32767).astype("<i2")
    buf = io.BytesIO()
    with wave.open(buf, "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(sr)
        w.writeframes(pcm.tobytes())
    return buf.getvalue()


@settings(max_examples=60, deadline=None)
@given(
    arrays(np.float64, st.integers(0, 300), elements=st.floats(-4, 4) | st.just(float("nan"))),
    st.sampled_from([8000, 16000, 44100, 48000]),
)
def test_pcm16_is_byte_for_byte_the_wave_modules_file(samples, sr):
    assert wav_bytes(samples, sr=sr) == wave_module_pcm16(samples, sr)


def test_players_get_the_audio_at_its_own_level():
    quiet = (0.01 * np.sin(np.linspace(0, 200, AUDIO_SR))).astype(np.float32)
    quiet[10] = 3.0  # beyond full scale: clipped, not rescaled
    back, sr = sf.read(io.BytesIO(wav_bytes(quiet)), dtype="float32")
    assert sr == AUDIO_SR and back.shape == quiet.shape
    assert back[10] == pytest.approx(1.0, abs=1e-4)
    np.testing.assert_allclose(np.delete(back, 10), np.delete(quiet, 10), atol=1 / 32767)
    silent, _ = sf.read(io.BytesIO(wav_bytes(np.zeros(100, np.float32))))
    assert not silent.any()


def test_float32_keeps_every_sample_as_float32():
    x = np.sin(np.arange(999) / 3.0) * 0.7
    data = wav_bytes(x, sr=22050, encoding="float32")
    back, sr = sf.read(io.BytesIO(data), dtype="float64")
    info = sf.info(io.BytesIO(data))
    assert sr == 22050 and info.subtype == "FLOAT"
    np.testing.assert_array_equal(back, x.astype(np.float32).astype(np.float64))


def test_a_marked_file_is_recognised_as_gesturekits_and_still_reads(tmp_path):
    x = 0.3 * np.sin(np.arange(AUDIO_SR) / 5.0)
    marked, plain = tmp_path / "marked.wav", tmp_path / "plain.wav"
    write_wav(marked, x, mark=True)
    write_wav(plain, x)
    assert check_output(marked, "file", overwrite=True) is not None  # a file gesturekit wrote may be replaced
    with pytest.raises(ConfigError):
        check_output(plain, "file", overwrite=True)
    np.testing.assert_array_equal(load_audio(marked), load_audio(plain))


def test_write_wav_to_a_path_refuses_to_replace_and_to_a_file_object_writes_in_place(tmp_path):
    x = np.linspace(-1, 1, 50)
    path = tmp_path / "a.wav"
    write_wav(path, x, sr=8000)
    with pytest.raises(ConfigError, match="already exists"):
        write_wav(path, np.zeros(5), sr=8000)
    assert path.read_bytes() == wav_bytes(x, sr=8000)
    write_wav(path, np.zeros(5), sr=8000, overwrite=True)
    assert path.read_bytes() == wav_bytes(np.zeros(5), sr=8000)
    buf = io.BytesIO(b"head")
    buf.seek(4)
    write_wav(buf, x, sr=8000)
    assert buf.getvalue() == b"head" + wav_bytes(x, sr=8000) and not buf.closed


@pytest.mark.parametrize("kwargs", [{"sr": 0}, {"sr": 16000.5}, {"sr": True}, {"encoding": "mp3"}])
def test_bad_options_are_config_errors(kwargs):
    with pytest.raises(ConfigError):
        wav_bytes(np.zeros(4), **kwargs)
