"""Tests of gesturekit.datasets.audio: every format, rate and channel count gives the
features of the original signal; every bad file gives an AudioFileError naming it."""

from __future__ import annotations

import functools
import math
import subprocess
import warnings
from dataclasses import dataclass
from pathlib import Path

import audioread
import librosa
import numpy as np
import pytest
import soundfile as sf
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit.datasets.audio import SILENCE_PEAK, load_audio, load_audio_with_info
from gesturekit.errors import AudioFileError, ConfigError, GestureKitWarning
from gesturekit.features import audio_frame_features

SR = 16000
DURATION = 3.0
FULL_BAND = 7900.0  # Hz; below the 8 kHz Nyquist frequency of the 16 kHz output
NARROW_BAND = 3800.0  # Hz; what an 8 kHz file can hold
SHARED = Path(__file__).resolve().parents[2].parent / "shared" / "data"


@functools.cache
def speech_like(rate: int, band: float = FULL_BAND) -> np.ndarray:
    """A 3 s speech-like signal defined in continuous time, sampled at ``rate`` Hz.

    Voiced part: harmonics of a gliding pitch (110-245 Hz) shaped by three moving
    formants, under a 4 Hz syllable envelope that never falls below a quarter.
    Unvoiced part: 200 fixed partials spread evenly on the mel scale up to
    ``band`` Hz, so every mel band of the features holds energy (an empty band
    would compare numerical noise floors in dB). Being a sum of sinusoids, the
    same signal can be sampled exactly at any rate above ``2 * band``.

    Returns
    -------
    np.ndarray, shape (round(3 * rate),), float64, read-only; peak about 0.4.
    """
    rng = np.random.default_rng(0)
    t = np.arange(round(DURATION * rate)) / rate
    f0 = 110 + 25 * t + 30 * np.sin(np.pi * t)
    phase = 2 * np.pi * (110 * t + 12.5 * t**2 + 30 * (1 - np.cos(np.pi * t)) / np.pi)  # integral of f0
    syllables = np.sin(4 * np.pi * t) ** 2
    formants = (
        (550 + 250 * np.sin(2 * np.pi * 1.3 * t), 1.0),
        (1500 + 600 * np.sin(2 * np.pi * 0.9 * t + 1), 0.6),
        (2700 + 300 * np.sin(2 * np.pi * 1.7 * t + 2), 0.3),
    )
    voiced = np.zeros_like(t)
    for k in range(1, int(band // f0.max()) + 1):
        gain = 0.03 + sum(g * np.exp(-0.5 * ((k * f0 - fc) / 130) ** 2) for fc, g in formants)
        voiced += gain * np.sin(k * phase + rng.uniform(0, 2 * np.pi))
    n_partials = 200
    freqs = librosa.mel_to_hz(rng.uniform(librosa.hz_to_mel(20.0), librosa.hz_to_mel(band), n_partials))
    noise = np.zeros_like(t)
    for f, p in zip(freqs, rng.uniform(0, 2 * np.pi, n_partials)):
        noise += np.sin(2 * np.pi * f * t + p)
    noise /= np.sqrt(n_partials / 2)
    x = (0.25 + 0.75 * syllables) * voiced / voiced.std() * 0.12 + (1 - 0.6 * syllables) * noise * 0.04
    # 50 ms raised-cosine fades, so resamplers see no step at either end
    ramp = np.minimum(1.0, np.minimum(t, t[-1] - t) / 0.05)
    x *= 0.5 - 0.5 * np.cos(np.pi * ramp)
    x.setflags(write=False)
    return x


@functools.cache
def reference_features(band: float = FULL_BAND) -> np.ndarray:
    """Features of the original signal at 16 kHz, shape (45, 14)."""
    return audio_frame_features(speech_like(SR, band).astype(np.float32))


def stereo_difference(rate: int) -> np.ndarray:
    """A strong 1234 Hz tone added to one channel and subtracted from the other."""
    return 0.2 * np.sin(2 * np.pi * 1234 * np.arange(round(DURATION * rate)) / rate)


def write_audio(path: Path, x: np.ndarray, rate: int, *, format: str | None = None, subtype: str | None = None):
    """Write ``x`` (frames[, channels]) with soundfile; MP3 through ffmpeg when libsndfile lacks it."""
    if format == "MP3" and "MP3" not in sf.available_formats():
        ffmpeg = pytest.importorskip("imageio_ffmpeg").get_ffmpeg_exe()
        source = path.with_suffix(".source.wav")
        sf.write(source, x, rate, subtype="FLOAT")
        subprocess.run([ffmpeg, "-v", "error", "-y", "-i", str(source), "-c:a", "libmp3lame", str(path)], check=True)
        return
    sf.write(path, x, rate, format=format, subtype=subtype)


@dataclass(frozen=True)
class Tol:
    """How far loaded features may be from the original's.

    mfcc: max |difference| of any MFCC in any frame (MFCCs span about +-50 here);
    energy: max |difference| of the log mean energy (natural log; 0.1 is 0.43 dB);
    corr: min over the 14 columns of the correlation over time.
    """

    mfcc: float
    energy: float
    corr: float


EXACT = None
# Lossless: only quantisation noise, 6 dB quieter per bit, against a signal
# near -8 dBFS with every mel band within ~50 dB of the strongest.
PCM_32 = PCM_24 = Tol(mfcc=1e-3, energy=1e-4, corr=0.99999)
PCM_16 = Tol(mfcc=0.02, energy=1e-3, corr=0.99999)
PCM_U8 = Tol(mfcc=2.5, energy=0.06, corr=0.99)  # 8 bits: noise only ~40 dB below the signal
# Resampled (soxr_hq): the anti-alias filter trims the top mel band's last few hundred Hz.
RESAMPLED = Tol(mfcc=1.5, energy=0.02, corr=0.999)
# Lossy codecs reshape the fine spectrum frame by frame; the envelope over time and
# the energy must survive.
LOSSY = Tol(mfcc=8.0, energy=0.2, corr=0.95)


def assert_features_match(got: np.ndarray, ref: np.ndarray, tol: Tol | None) -> None:
    assert abs(len(got) - len(ref)) <= 1
    n = min(len(got), len(ref))
    got, ref = got[:n], ref[:n]
    if tol is EXACT:
        np.testing.assert_array_equal(got, ref)
        return
    mfcc_err = float(np.abs(got[:, :13] - ref[:, :13]).max())
    energy_err = float(np.abs(got[:, 13] - ref[:, 13]).max())
    corr = [float(np.corrcoef(got[:, k], ref[:, k])[0, 1]) for k in range(14)]
    assert mfcc_err <= tol.mfcc, f"MFCCs differ by up to {mfcc_err:.4g} (allowed {tol.mfcc})"
    assert energy_err <= tol.energy, f"log-energy differs by up to {energy_err:.4g} (allowed {tol.energy})"
    assert min(corr) >= tol.corr, f"per-column correlations {np.round(corr, 4)} (required >= {tol.corr})"


# (id, file suffix, soundfile format, subtype, source rate, channels, band of the signal, tolerance)
CASES = [
    ("wav-u8", ".wav", "WAV", "PCM_U8", SR, 1, FULL_BAND, PCM_U8),
    ("wav-16", ".wav", "WAV", "PCM_16", SR, 1, FULL_BAND, PCM_16),
    ("wav-24", ".wav", "WAV", "PCM_24", SR, 1, FULL_BAND, PCM_24),
    ("wav-32", ".wav", "WAV", "PCM_32", SR, 1, FULL_BAND, PCM_32),
    ("wav-float", ".wav", "WAV", "FLOAT", SR, 1, FULL_BAND, EXACT),
    ("wav-double", ".wav", "WAV", "DOUBLE", SR, 1, FULL_BAND, EXACT),
    ("flac-16", ".flac", "FLAC", "PCM_16", SR, 1, FULL_BAND, PCM_16),
    ("flac-24", ".flac", "FLAC", "PCM_24", SR, 1, FULL_BAND, PCM_24),
    ("ogg-vorbis", ".ogg", "OGG", "VORBIS", SR, 1, FULL_BAND, LOSSY),
    ("mp3", ".mp3", "MP3", "MPEG_LAYER_III", SR, 1, FULL_BAND, LOSSY),
    ("wav-float-stereo", ".wav", "WAV", "FLOAT", SR, 2, FULL_BAND, PCM_24),
    ("wav-16-8k", ".wav", "WAV", "PCM_16", 8000, 1, NARROW_BAND, RESAMPLED),
    ("wav-16-22k", ".wav", "WAV", "PCM_16", 22050, 1, FULL_BAND, RESAMPLED),
    ("wav-16-44k-stereo", ".wav", "WAV", "PCM_16", 44100, 2, FULL_BAND, RESAMPLED),
    ("flac-24-48k-3ch", ".flac", "FLAC", "PCM_24", 48000, 3, FULL_BAND, RESAMPLED),
]


@pytest.mark.slow
@pytest.mark.parametrize(
    "suffix, fmt, subtype, rate, channels, band, tol", [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_every_format_rate_and_layout_gives_the_original_features(
    tmp_path, suffix, fmt, subtype, rate, channels, band, tol
):
    x = speech_like(rate, band)
    if channels > 1:
        # channels that differ, but whose average is exactly the signal
        d = stereo_difference(rate)
        x = np.stack([x + d, x - d, x][:channels], axis=1)
    path = tmp_path / f"speech{suffix}"
    write_audio(path, x, rate, format=fmt, subtype=subtype)

    audio, info = load_audio_with_info(path)

    assert audio.dtype == np.float32 and audio.ndim == 1
    assert abs(len(audio) - DURATION * SR) <= 1
    assert (info.sample_rate, info.channels, info.format, info.reader) == (rate, channels, fmt, "soundfile")
    assert info.duration == pytest.approx(DURATION, abs=1e-3)
    assert_features_match(audio_frame_features(audio), reference_features(band), tol)


@pytest.mark.slow
def test_m4a_is_read_through_ffmpeg(tmp_path):
    ffmpeg = pytest.importorskip("imageio_ffmpeg").get_ffmpeg_exe()
    source, path = tmp_path / "source.wav", tmp_path / "speech.m4a"
    sf.write(source, speech_like(44100), 44100, subtype="FLOAT")
    encode = [ffmpeg, "-v", "error", "-y", "-i", str(source), "-c:a", "aac", "-b:a", "96k", str(path)]
    subprocess.run(encode, check=True)

    audio, info = load_audio_with_info(path)

    assert (info.reader, info.format, info.sample_rate, info.subtype) == ("ffmpeg", "MP4", 44100, None)
    assert abs(len(audio) - DURATION * SR) <= 0.01 * DURATION * SR
    assert_features_match(audio_frame_features(audio), reference_features(), LOSSY)


def test_audioread_then_ffmpeg_take_over_only_when_soundfile_cannot_read(tmp_path, monkeypatch):
    path = tmp_path / "speech.wav"
    sf.write(path, speech_like(SR), SR, subtype="PCM_16")
    real = sf.SoundFile

    def soundfile_without_wav(file, *args, **kwargs):
        if isinstance(file, (str, Path)):  # files on disk; ffmpeg's output arrives as bytes
            raise sf.LibsndfileError(1, "Error opening file: ")  # 1: format not recognised
        return real(file, *args, **kwargs)

    monkeypatch.setattr(sf, "SoundFile", soundfile_without_wav)
    audio, info = load_audio_with_info(path)
    assert (info.reader, info.format, info.subtype, info.channels) == ("audioread", "WAV", None, 1)
    assert_features_match(audio_frame_features(audio), reference_features(), PCM_16)

    def no_backend(*args, **kwargs):
        raise audioread.NoBackendError()

    monkeypatch.setattr(audioread, "audio_open", no_backend)
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    audio, info = load_audio_with_info(path)
    assert info.reader == "ffmpeg"
    assert_features_match(audio_frame_features(audio), reference_features(), PCM_16)

    def no_ffmpeg():
        raise RuntimeError("no ffmpeg")

    monkeypatch.setattr(imageio_ffmpeg, "get_ffmpeg_exe", no_ffmpeg)
    with pytest.raises(AudioFileError, match=r"speech\.wav: looks like WAV audio but cannot be decoded"):
        load_audio(path)


# --- errors ---------------------------------------------------------------------------


def _message(path: Path, **kwargs) -> str:
    with pytest.raises(AudioFileError) as info:
        load_audio(path, **kwargs)
    message = str(info.value)
    assert path.name in message
    return message


def test_missing_file(tmp_path):
    assert "not found" in _message(tmp_path / "absent.wav")


def test_folder_is_not_a_file(tmp_path):
    folder = tmp_path / "takes.wav"
    folder.mkdir()
    assert "folder" in _message(folder)


def test_empty_file(tmp_path):
    path = tmp_path / "empty.wav"
    path.write_bytes(b"")
    assert "empty (0 bytes)" in _message(path)


@pytest.mark.parametrize("suffix", [".wav", ".mp3", ".flac", ".ogg"])
def test_text_and_random_bytes_are_not_audio(tmp_path, suffix):
    text = tmp_path / f"notes{suffix}"
    text.write_text("This is a transcript, not a recording.\n" * 50)
    noise = tmp_path / f"noise{suffix}"
    noise.write_bytes(np.random.default_rng(3).bytes(20000))
    for path in (text, noise):
        assert "not an audio file" in _message(path)


def test_damaged_file_with_an_audio_signature(tmp_path):
    path = tmp_path / "broken.flac"
    path.write_bytes(b"fLaC" + np.random.default_rng(1).bytes(3000))
    message = _message(path)
    assert "FLAC" in message and ("cannot be decoded" in message or "damaged" in message)


def test_file_soundfile_finds_malformed_is_not_handed_to_other_decoders(tmp_path):
    whole = tmp_path / "whole.ogg"
    sf.write(whole, speech_like(SR), SR, format="OGG", subtype="VORBIS")
    path = tmp_path / "cut.ogg"
    path.write_bytes(whole.read_bytes()[:1500])  # inside the Vorbis setup header
    message = _message(path)
    assert "truncated" in message and "ffmpeg" not in message


def _pcm16_wav(path: Path, seconds: float = 2.0) -> bytes:
    sf.write(path, speech_like(SR)[: int(seconds * SR)], SR, subtype="PCM_16")
    return path.read_bytes()


@pytest.mark.parametrize("keep", [8, 30, 50, 40000])
def test_truncated_wav_is_detected_from_its_header(tmp_path, keep):
    whole = _pcm16_wav(tmp_path / "whole.wav")
    path = tmp_path / "cut.wav"
    path.write_bytes(whole[:keep])
    message = _message(path)
    assert "truncated" in message
    if keep > 44:
        assert f"declares {len(whole) - 44} bytes" in message and f"only {keep - 44} bytes" in message


@settings(
    deadline=None, max_examples=40, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(fraction=st.floats(0.0, 1.0, exclude_max=True))
def test_any_cut_of_a_wav_is_reported_as_truncated(tmp_path, fraction):
    whole = tmp_path / "whole.wav"
    if not whole.exists():
        _pcm16_wav(whole, seconds=1.2)
    data = whole.read_bytes()
    path = tmp_path / "cut.wav"
    path.write_bytes(data[: max(4, int(fraction * len(data)))])  # from the "RIFF" mark on
    assert "truncated" in _message(path, min_duration=0.0)


@pytest.mark.slow
@settings(
    deadline=None, max_examples=25, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(
    rate=st.sampled_from([8000, 11025, 16000, 22050, 32000, 44100, 48000, 96000]),
    channels=st.integers(1, 6),
    seed=st.integers(0, 2**32 - 1),
)
def test_loading_is_channel_average_then_soxr_resampling(tmp_path, rate, channels, seed):
    x = np.random.default_rng(seed).uniform(-0.5, 0.5, (rate + 17, channels)).astype(np.float32)
    path = tmp_path / "noise.wav"
    sf.write(path, x, rate, subtype="FLOAT")
    audio, info = load_audio_with_info(path)
    expected = librosa.resample(x.mean(axis=1), orig_sr=rate, target_sr=SR, res_type="soxr_hq")
    assert len(audio) == math.ceil((rate + 17) * SR / rate) == len(expected)
    np.testing.assert_array_equal(audio, expected)  # our soxr call is librosa's, without importing librosa
    assert (info.sample_rate, info.channels, info.n_samples) == (rate, channels, rate + 17)


def test_streamed_wav_without_sizes_is_not_called_truncated(tmp_path):
    whole = bytearray(_pcm16_wav(tmp_path / "whole.wav"))
    data = whole.find(b"data")
    whole[4:8] = whole[data + 4 : data + 8] = b"\xff\xff\xff\xff"  # what a writer that cannot seek leaves
    path = tmp_path / "streamed.wav"
    path.write_bytes(bytes(whole))
    np.testing.assert_array_equal(load_audio(path), load_audio(tmp_path / "whole.wav"))


def test_truncated_flac_and_mp3(tmp_path, capfd):
    for suffix, fmt in ((".flac", "FLAC"), (".mp3", "MP3")):
        if fmt not in sf.available_formats():
            continue
        whole = tmp_path / f"whole{suffix}"
        write_audio(whole, speech_like(SR), SR, format=fmt)
        path = tmp_path / f"cut{suffix}"
        path.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
        message = _message(path)
        assert "truncated" in message
    # detected before decoding, so the decoder has nothing to complain about on stderr
    assert capfd.readouterr() == ("", "")


def test_too_short(tmp_path):
    path = tmp_path / "short.wav"
    sf.write(path, speech_like(SR)[:8000], SR)
    message = _message(path)
    assert "0.50 s" in message and "1.00 s" in message
    assert len(load_audio(path, min_duration=0.5)) == 8000


def test_header_without_samples(tmp_path):
    path = tmp_path / "header_only.wav"
    sf.write(path, np.zeros(0, np.float32), SR)
    assert "no audio samples" in _message(path, min_duration=0.0)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_and_inf_samples(tmp_path, bad):
    x = speech_like(SR).astype(np.float32).copy()
    x[8000] = x[9000] = bad
    path = tmp_path / "invalid.wav"
    sf.write(path, x, SR, subtype="FLOAT")
    message = _message(path)
    assert "2 invalid samples (NaN or infinity)" in message and "0.500 s" in message


def test_bad_options_are_config_errors(tmp_path):
    path = tmp_path / "speech.wav"
    sf.write(path, speech_like(SR), SR)
    for kwargs in ({"sr": 0}, {"sr": 16000.5}, {"min_duration": -1.0}, {"min_duration": float("nan")}):
        with pytest.raises(ConfigError):
            load_audio(path, **kwargs)


# --- silence and quietness -------------------------------------------------------------


@pytest.mark.parametrize("peak, silent", [(0.0, True), (0.5 * SILENCE_PEAK, True), (1e-3, False)])
def test_silent_audio_warns_naming_the_file(tmp_path, peak, silent):
    x = peak * np.sin(2 * np.pi * 440 * np.arange(2 * SR) / SR)
    path = tmp_path / "quiet_room.wav"
    sf.write(path, x, SR, subtype="FLOAT")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        audio = load_audio(path)
    ours = [w for w in caught if issubclass(w.category, GestureKitWarning)]
    assert len(ours) == (1 if silent else 0)
    if silent:
        assert "quiet_room.wav" in str(ours[0].message) and "silent" in str(ours[0].message)
    np.testing.assert_allclose(audio, x.astype(np.float32), atol=1e-7)


def test_loading_is_quiet_and_leaves_warning_filters_alone(tmp_path, capfd):
    paths = []
    for name, rate, fmt, subtype in [
        ("a.wav", 44100, "WAV", "PCM_16"),
        ("b.ogg", 22050, "OGG", "VORBIS"),
        ("c.mp3", SR, "MP3", "MPEG_LAYER_III"),
    ]:
        paths.append(tmp_path / name)
        write_audio(paths[-1], np.stack([speech_like(rate)] * 2, axis=1), rate, format=fmt, subtype=subtype)
    capfd.readouterr()
    filters_before = list(warnings.filters)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for path in paths:
            load_audio(path)
    assert [str(w.message) for w in caught] == []
    assert capfd.readouterr() == ("", "")
    assert warnings.filters == filters_before


def test_info_summary(tmp_path):
    path = tmp_path / "speech.wav"
    sf.write(path, np.stack([speech_like(44100)] * 2, axis=1), 44100, subtype="PCM_24")
    _, info = load_audio_with_info(path)
    assert info.summary() == "WAV (PCM_24), 44100 Hz, 2 channels, 3.00 s"
    assert info.n_samples == 3 * 44100 and info.path == str(path)


# --- real recordings (read in place from the shared test data) --------------------------


def _shared(name: str) -> Path:
    path = SHARED / "speech" / name
    if not path.exists():
        pytest.skip(f"shared test data not available: {path}")
    return path


def test_real_speech_in_two_encodings_gives_the_same_features():
    # the same espeak-ng utterance as 22.05 kHz mono WAV and 44.1 kHz stereo FLAC
    wav, wav_info = load_audio_with_info(_shared("espeak_en_us.wav"))
    flac, flac_info = load_audio_with_info(_shared("espeak_en_us_44k_stereo.flac"))
    assert (wav_info.sample_rate, wav_info.channels) == (22050, 1)
    assert (flac_info.sample_rate, flac_info.channels) == (44100, 2)
    assert abs(len(wav) - len(flac)) <= 1
    a, b = audio_frame_features(wav), audio_frame_features(flac)
    voiced = a[:, 13] > a[:, 13].max() - 10  # frames within ~43 dB of the loudest: speech, not pauses
    assert voiced.mean() > 0.5
    np.testing.assert_allclose(b[voiced, 13], a[voiced, 13], atol=0.05)
    for k in range(13):
        assert np.corrcoef(a[voiced, k], b[voiced, k])[0, 1] > 0.99
