"""The database's stored audio: raw int16, a lower rate or FLAC, read back as 16 kHz float32."""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.database.audio import AudioStorage, decode_take_audio, encode_take_audio, take_audio_fields, to_int16
from gesturekit.errors import ConfigError, DatabaseError
from tests.badinput import assert_refused, run_cli, snapshot
from tests.cli.test_cli import _positions_folder
from tests.conftest import make_take

SR = 16000
STORAGES = [AudioStorage(), AudioStorage("flac"), AudioStorage("pcm", 8000), AudioStorage("flac", 8000)]


@pytest.fixture(scope="module")
def takes():
    return [make_take(9.0, seed=1, name="a"), make_take(6.0, seed=2, name="b")]


@pytest.fixture(scope="module")
def saved(takes, tmp_path_factory):
    """The same takes saved with each storage: {(format, rate): loaded database}."""
    root = tmp_path_factory.mktemp("audio")
    out = {}
    for s in STORAGES:
        db = MatchingDatabase.build(takes, config=BuildConfig(audio_format=s.format, audio_rate=s.rate))
        out[s.format, s.rate] = MatchingDatabase.load(db.save(root / f"{s.format}{s.rate}"))
    return out


# ---- encoding and decoding ---------------------------------------------------------------------
@settings(max_examples=40, deadline=None)
@given(pcm=arrays(np.int16, st.integers(0, 3000)), fmt=st.sampled_from(["pcm", "flac"]))
def test_full_rate_round_trip_is_exact(pcm, fmt):
    storage = AudioStorage(fmt)
    enc = encode_take_audio(pcm, storage)
    assert enc.samples == pcm.size
    back = decode_take_audio(enc.data, enc.samples, storage)
    assert back.dtype == np.float32 and back.shape == pcm.shape
    np.testing.assert_array_equal(back, pcm.astype(np.float32) / np.float32(32767))


@settings(max_examples=25, deadline=None)
@given(
    freqs=st.lists(st.floats(60.0, 3000.0), min_size=1, max_size=4),
    seconds=st.floats(0.3, 2.0),
    fmt=st.sampled_from(["pcm", "flac"]),
)
def test_lower_rate_keeps_what_lies_below_its_band_edge(freqs, seconds, fmt):
    # speech below 3 kHz survives 8 kHz storage: beyond the filter's edge effects, the error
    # is a fraction of a percent of the signal's amplitude (quantisation at 8 kHz included)
    t = np.arange(int(seconds * SR)) / SR
    x = sum(np.sin(2 * np.pi * f * t + i) for i, f in enumerate(freqs)) * (0.8 / len(freqs))
    storage = AudioStorage(fmt, 8000)
    enc = encode_take_audio(x.astype(np.float32), storage)
    assert enc.samples == t.size and enc.data.size <= (t.size // 2 + 1 if fmt == "pcm" else t.size)
    back = decode_take_audio(enc.data, enc.samples, storage)
    assert back.shape == (t.size,) and back.dtype == np.float32
    inner = slice(400, t.size - 400)  # 25 ms at each end, where the resampling filter runs off the signal
    ref = to_int16(x.astype(np.float32)).astype(np.float64) / 32767
    assert np.abs(back[inner] - ref[inner]).max() < 0.01


def test_flac_is_smaller_and_lower_rates_scale_the_size(takes):
    speech = np.concatenate([t.audio for t in takes])
    raw = encode_take_audio(speech, AudioStorage()).data.nbytes
    assert raw == 2 * speech.size
    half = encode_take_audio(speech, AudioStorage("pcm", 8000)).data.nbytes
    assert abs(half - raw / 2) <= 2
    flac = encode_take_audio(speech, AudioStorage("flac")).data.nbytes
    assert flac < 0.75 * raw  # a tone with noise; speech compresses to about half
    assert encode_take_audio(speech, AudioStorage("flac", 8000)).data.nbytes < flac


def test_encoding_is_deterministic(takes):
    # a streaming or parallel build must store the same bytes as a serial one
    for s in STORAGES:
        a, b = (encode_take_audio(takes[0].audio, s) for _ in range(2))
        assert a.data.dtype == s.dtype and np.array_equal(a.data, b.data)


def test_take_fields_name_the_size_only_for_other_storages(takes):
    for s in STORAGES:
        enc = encode_take_audio(takes[1].audio, s)
        fields = take_audio_fields(enc, 123, s)
        assert fields["audio_offset"] == 123 and fields["audio_samples"] == takes[1].audio.size
        assert ("audio_size" in fields) == (not s.is_default)
        assert s.to_meta() is None if s.is_default else AudioStorage.from_meta({"audio": s.to_meta()}) == s


@pytest.mark.parametrize(
    "kwargs, problem",
    [
        ({"format": "mp3"}, "format"),
        ({"rate": 3000}, "4000 to 16000"),
        ({"rate": 22050}, "4000 to 16000"),
        ({"rate": 8000.5}, "integer"),
    ],
)
def test_bad_storage_is_refused(kwargs, problem):
    with pytest.raises(ConfigError, match=problem):
        AudioStorage(**kwargs)


def test_build_config_refuses_audio_options_without_audio():
    with pytest.raises(ConfigError, match="store_audio=False"):
        BuildConfig(store_audio=False, audio_format="flac")
    with pytest.raises(ConfigError, match="4000 to 16000"):
        BuildConfig(audio_rate=44100)


# ---- databases ---------------------------------------------------------------------------------
def test_every_storage_reads_back_16k_float32_aligned_with_the_clips(saved, takes):
    exact = saved["pcm", SR]
    for (fmt, rate), db in saved.items():
        assert db.audio_storage == AudioStorage(fmt, rate)
        for i, t in enumerate(takes):
            a = db.take_audio(i)
            assert a.dtype == np.float32 and a.shape == t.audio.shape
            if rate == SR:
                np.testing.assert_array_equal(a, exact.take_audio(i))
            else:  # the test takes' tones lie far below 4 kHz; their noise above it is lost
                err = np.abs(a[400:-400] - exact.take_audio(i)[400:-400])
                assert np.sqrt(np.mean(err**2)) < 0.01
        seg = db.segment_audio(2, 8, 8)  # take b's first clip, frames 8..16
        s0 = round(8 * SR / 15)
        np.testing.assert_array_equal(seg, db.take_audio("b")[s0 : s0 + seg.size])
        assert seg.shape == exact.segment_audio(2, 8, 8).shape


def test_stored_sizes_on_disk(saved):
    size = {k: (db.path / "audio.npy").stat().st_size for k, db in saved.items()}
    raw = size["pcm", SR]
    assert size["pcm", 8000] < 0.51 * raw and size["flac", SR] < 0.75 * raw and size["flac", 8000] < size["flac", SR]


def test_default_storage_writes_databases_as_before(saved, takes):
    db = saved["pcm", SR]
    meta = json.loads((db.path / "database.json").read_text())
    assert "audio" not in meta and all("audio_size" not in t for t in meta["takes"])
    stored = np.load(db.path / "audio.npy", allow_pickle=False)
    assert stored.dtype == np.int16
    np.testing.assert_array_equal(stored, np.concatenate([to_int16(t.audio) for t in takes]))
    other = json.loads((saved["flac", 8000].path / "database.json").read_text())
    assert other["audio"] == {"format": "flac", "rate": 8000}
    assert [t["audio_samples"] for t in other["takes"]] == [t.audio.size for t in takes]


def test_a_database_from_before_the_option_reads_the_same(saved, tmp_path):
    import shutil

    old = tmp_path / "old"
    shutil.copytree(saved["pcm", SR].path, old)
    meta = json.loads((old / "database.json").read_text())
    del meta["build"]["audio_format"], meta["build"]["audio_rate"]
    (old / "database.json").write_text(json.dumps(meta))
    db = MatchingDatabase.load(old)
    assert db.audio_storage.is_default
    np.testing.assert_array_equal(db.take_audio("b"), saved["pcm", SR].take_audio("b"))
    # saved again, it stays as it was
    again = json.loads((db.save(tmp_path / "again") / "database.json").read_text())
    assert "audio" not in again


def test_saving_a_loaded_database_keeps_its_storage(saved, tmp_path):
    db = saved["flac", 8000]
    copy = MatchingDatabase.load(db.save(tmp_path / "copy"))
    assert (copy.path / "audio.npy").read_bytes() == (db.path / "audio.npy").read_bytes()
    np.testing.assert_array_equal(copy.take_audio("a"), db.take_audio("a"))


def _edit(path, edit):
    meta = json.loads((path / "database.json").read_text())
    edit(meta)
    (path / "database.json").write_text(json.dumps(meta))


@pytest.mark.parametrize(
    "edit, problem",
    [
        (lambda m: m.__setitem__("audio", {"format": "mp3", "rate": 16000}), "format"),
        (lambda m: m.__setitem__("audio", {"format": "flac"}), "format and rate"),
        (lambda m: m.__setitem__("audio", {"format": "pcm", "rate": 100}), "4000"),
        (lambda m: m["takes"][1].pop("audio_size"), "audio_size"),
        (lambda m: m["takes"][1].__setitem__("audio_size", 10**9), "at least"),
    ],
)
def test_damaged_audio_entries_are_refused_on_load(saved, tmp_path, edit, problem):
    import shutil

    path = tmp_path / "db"
    shutil.copytree(saved["flac", SR].path, path)
    _edit(path, edit)
    with pytest.raises(DatabaseError, match=problem) as info:
        MatchingDatabase.load(path)
    assert str(path) in str(info.value)


def test_a_damaged_flac_stream_is_a_database_error(saved, tmp_path):
    import shutil

    path = tmp_path / "db"
    shutil.copytree(saved["flac", SR].path, path)
    audio = np.load(path / "audio.npy", allow_pickle=False)
    audio[:64] = 7  # the first take's stream header
    np.save(path / "audio.npy", audio, allow_pickle=False)
    db = MatchingDatabase.load(path)
    with pytest.raises(DatabaseError, match="cannot be decoded") as info:
        db.take_audio("a")
    assert str(path) in str(info.value) and "'a'" in str(info.value)
    assert db.take_audio("b").size == 6 * SR  # the other take is intact


# ---- command line ------------------------------------------------------------------------------
@pytest.mark.slow
def test_build_db_stores_the_audio_as_asked(tmp_path):
    folder, jm = _positions_folder(tmp_path)
    out = tmp_path / "db"
    args = ["build-db", folder, "--joint-map", jm, "--fps", "30", "--up", "y", "--forward", "z", "--units", "m"]
    args += ["--no-plausibility-check"]  # random positions are no body
    args += ["--out", out]
    run = run_cli(*args, "--audio-format", "flac", "--audio-rate", "8000")
    assert run.code == 0, run.stderr
    db = MatchingDatabase.load(out)
    assert db.audio_storage == AudioStorage("flac", 8000) and db.take_audio("t0").size == 9 * SR


@pytest.mark.parametrize(
    "extra, names, problem",
    [
        (["--no-audio", "--audio-format", "flac"], "--audio-format", "--no-audio keeps none"),
        (["--no-audio", "--audio-rate", "8000"], "--audio-rate", "--no-audio keeps none"),
        (["--audio-rate", "3000"], "--audio-rate", "4000 to 16000"),
        (["--audio-rate", "48000"], "--audio-rate", "4000 to 16000"),
    ],
)
def test_build_db_refuses_bad_audio_options(tmp_path, extra, names, problem):
    folder, jm = _positions_folder(tmp_path)
    out = tmp_path / "db"
    before = snapshot(tmp_path)
    run = run_cli("build-db", folder, "--joint-map", jm, "--fps", "30", "--out", out, *extra)
    assert_refused(run, names=names, problem=problem, before=before)
