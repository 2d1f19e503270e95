"""Bad-input suite, readers: hostile and damaged audio, BVH and joint-position files on the command line.

Speech goes through ``gesturekit synthesize``, takes through ``gesturekit build-db``.
Every case must exit 2 with one message that names the file (or option) and the
problem, without a traceback, leaving the inputs and the output folder as they were.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from gesturekit.skeleton import N_JOINTS
from tests import hostile as h
from tests.badinput import assert_refused, run_cli, snapshot


@pytest.fixture(scope="module")
def tiny_db(tmp_path_factory) -> Path:
    from gesturekit.demo import build_demo_database

    path = tmp_path_factory.mktemp("readers") / "db"
    build_demo_database(path, minutes=1.0)
    return path


@pytest.fixture(scope="module")
def speech(tmp_path_factory) -> dict[str, Path]:
    return h.encoded(tmp_path_factory.mktemp("speech"), seconds=12.0)


def _earlier_output(tmp_path: Path) -> Path:
    """An output folder holding an earlier result, which a refused run must leave as it was."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "earlier.bvh").write_text("an earlier result\n")
    return out


# ----------------------------------------------------------------------------- speech (synthesize)


def _truncated(kind, fraction=0.4):
    def make(d, speech):
        src = speech[kind]
        return h.cut(src, d / ("cut_" + src.name), fraction)

    return make


SPEECH_CASES = {
    "wav_header_1_hz": (lambda d, s: h.wav_with_header(d / "one_hz.wav", rate=1), "sample rate of 1 Hz"),
    "wav_header_1e9_hz": (lambda d, s: h.wav_with_header(d / "giga.wav", rate=10**9), "outside the accepted range"),
    "wav_header_4_gb_of_data": (
        lambda d, s: h.wav_with_header(d / "huge.wav", rate=16000, declared_bytes=2**32 - 2),
        "truncated",
    ),
    "flac_declaring_2_pow_36_samples": (lambda d, s: h.flac_declaring(d / "huge.flac", 2**36 - 1), "beyond the limit"),
    "ogg_vorbis_cut_to_40_percent": (_truncated("ogg"), "truncated"),
    "ogg_opus_cut_to_60_percent": (_truncated("opus", 0.6), "truncated"),
    "mp3_without_xing_cut_to_40_percent": (_truncated("mp3"), "last MP3 frame is cut off"),
    "mp3_with_xing_cut_to_40_percent": (_truncated("xing.mp3"), "truncated"),
    "flac_cut_to_40_percent": (_truncated("flac"), "truncated"),
    "wav_cut_to_40_percent": (_truncated("wav"), "truncated"),
    "text_named_wav": (
        lambda d, s: (d / "notes.wav").write_text("hello, this is not audio\n" * 20) and d / "notes.wav",
        "not an audio file",
    ),
    "empty_mp3": (lambda d, s: (d / "empty.mp3").write_bytes(b"") or d / "empty.mp3", "empty"),
}


@pytest.mark.parametrize("case", list(SPEECH_CASES))
def test_hostile_speech_is_refused(case, tmp_path, tiny_db, speech):
    make, problem = SPEECH_CASES[case]
    path = make(tmp_path, speech)
    out = _earlier_output(tmp_path)
    before = snapshot(path, out, tiny_db)
    run = run_cli("synthesize", path, "--db", tiny_db, "--out", out)
    assert_refused(run, names=path, problem=problem, before=before)


def test_speech_beyond_the_environment_limit_is_refused(tmp_path, tiny_db, speech, monkeypatch):
    monkeypatch.setenv("GESTUREKIT_MAX_SPEECH_MINUTES", "0.1")  # 6 s; the speech is 12 s
    out = _earlier_output(tmp_path)
    before = snapshot(speech["ogg"], out)
    run = run_cli("synthesize", speech["ogg"], "--db", tiny_db, "--out", out)
    assert_refused(run, names=speech["ogg"], problem="GESTUREKIT_MAX_SPEECH_MINUTES", before=before)
    assert "12.0 s" in run.stderr and "6.0 s" in run.stderr


def test_speech_beyond_the_option_limit_is_refused(tmp_path, tiny_db, speech):
    out = _earlier_output(tmp_path)
    before = snapshot(speech["flac"], out)
    run = run_cli("synthesize", speech["flac"], "--db", tiny_db, "--out", out, "--max-speech-minutes", "0.05")
    assert_refused(run, names=speech["flac"], problem="--max-speech-minutes sets it", before=before)


@pytest.mark.parametrize("value", ["nan", "0", "-5"])
def test_bad_max_speech_minutes(value, tmp_path, tiny_db, speech):
    run = run_cli(
        "synthesize", speech["wav"], "--db", tiny_db, "--out", tmp_path / "out", "--max-speech-minutes", value
    )
    assert_refused(run, names="--max-speech-minutes", problem="positive number")


# ----------------------------------------------------------------------------- takes (build-db)

ROOT_X = 0  # the Hips' Xposition column
ROOT_ROT = 3  # the Hips' first rotation column

BVH_CASES = {
    "frame_time_100000": (dict(frame_time="100000"), "1e-05 fps"),
    "frame_time_1e-9": (dict(frame_time="1e-9"), "outside the accepted range"),
    "frame_time_0": (dict(frame_time="0"), "positive"),
    "frame_time_minus_1": (dict(frame_time="-1"), "positive"),
    "frame_time_nan": (dict(frame_time="nan"), "positive"),
    "frames_10_pow_12_in_a_tiny_file": (dict(frames="1000000000000"), "1000000000000 frames"),
    "rotations_1e300": (dict(marks={(f, ROOT_ROT + 5): "1e300" for f in range(3, 30)}), "absurd rotation"),
    "root_translation_1e200": (dict(marks={(f, ROOT_X): "1e200" for f in range(30)}), "absurd position"),
    "every_value_1e300": (dict(marks={(f, c): "1e300" for f in range(30) for c in range(6)}), "absurd"),
    "root_10_000_km_away_in_a_frame_resampling_skips": (dict(marks={(9, ROOT_X): "-1e9"}), "absurd position"),
}


@pytest.mark.parametrize("case", list(BVH_CASES))
def test_hostile_bvh_take_is_refused(case, tmp_path):
    kwargs, problem = BVH_CASES[case]
    folder = tmp_path / "takes"
    path = h.bvh_take(folder, **kwargs)
    out = tmp_path / "db"
    before = snapshot(folder, out)
    run = run_cli("build-db", folder, "--out", out)
    assert_refused(run, names=path, problem=problem, before=before)


def test_take_beyond_the_environment_limit_is_refused(tmp_path, monkeypatch):
    monkeypatch.setenv("GESTUREKIT_MAX_TAKE_HOURS", "0.0001")  # 0.36 s; the take is 1 s
    folder = tmp_path / "takes"
    path = h.bvh_take(folder)
    before = snapshot(folder, tmp_path / "db")
    run = run_cli("build-db", folder, "--out", tmp_path / "db")
    assert_refused(run, names=path, problem="GESTUREKIT_MAX_TAKE_HOURS", before=before)


def test_take_audio_with_a_1_hz_header_is_refused(tmp_path):
    folder = tmp_path / "takes"
    h.bvh_take(folder, audio=False)
    wav = h.wav_with_header(folder / "take.wav", rate=1)
    before = snapshot(folder, tmp_path / "db")
    run = run_cli(
        "build-db", folder, "--up", "y", "--forward", "z", "--no-plausibility-check", "--out", tmp_path / "db"
    )
    assert_refused(run, names=wav, problem="sample rate of 1 Hz", before=before)


def _positions_folder(tmp_path: Path, make) -> tuple[Path, Path, Path]:
    folder = tmp_path / "takes"
    folder.mkdir()
    motion = make(folder)
    wav = folder / f"{motion.stem}.wav"
    if not wav.exists():
        sf.write(wav, h.speech_like(2.0), h.SR, subtype="PCM_16")
    return folder, motion, h.identity_position_map(tmp_path / "map.json")


POSITION_CASES = {
    "npy_header_claiming_10_pow_12_frames": (
        lambda d: h.npy_claiming(d / "take.npy", (10**12, N_JOINTS, 3)),
        "beyond the limit",
    ),
    "npy_header_claiming_a_billion_joints": (
        lambda d: h.npy_claiming(d / "take.npy", (100, 10**9, 3)),
        "beyond the limit",
    ),
    "npy_header_larger_than_the_file": (lambda d: h.npy_claiming(d / "take.npy", (600, N_JOINTS, 3)), "truncated"),
    "npy_of_wrong_dimensions": (lambda d: np.save(d / "take.npy", np.zeros((5, 7, 2, 2))) or d / "take.npy", "shape"),
    "npz_member_claiming_10_pow_12_frames": (
        lambda d: h.npz_claiming(d / "take.npz", {"positions": (10**12, N_JOINTS * 3)}),
        "beyond the limit",
    ),
}


@pytest.mark.parametrize("case", list(POSITION_CASES))
def test_hostile_position_take_is_refused(case, tmp_path):
    make, problem = POSITION_CASES[case]
    folder, motion, jmap = _positions_folder(tmp_path, make)
    out = tmp_path / "db"
    before = snapshot(folder, jmap, out)
    run = run_cli("build-db", folder, "--kind", "positions", "--joint-map", jmap, "--fps", "30", "--out", out)
    assert_refused(run, names=motion, problem=problem, before=before)


@pytest.mark.parametrize("fps", ["1e-300", "1e6", "0.5"])
def test_position_fps_outside_the_range_is_refused(fps, tmp_path):
    folder, _, jmap = _positions_folder(tmp_path, lambda d: h.position_take(d))
    before = snapshot(folder, tmp_path / "db")
    run = run_cli(
        "build-db", folder, "--kind", "positions", "--joint-map", jmap, "--fps", fps, "--out", tmp_path / "db"
    )
    assert_refused(run, names="--fps", problem="outside the accepted range", before=before)


def test_habibie_npz_claiming_hours_per_sequence_is_refused(tmp_path):
    folder = tmp_path / "takes"
    folder.mkdir()
    path = h.npz_claiming(folder / "speaker.npz", {"wav": (2, 10**9), "body": (2, 10**7, N_JOINTS * 3)})
    before = snapshot(folder, tmp_path / "db")
    run = run_cli("build-db", folder, "--kind", "habibie2021", "--out", tmp_path / "db")
    assert_refused(run, names=path, problem="beyond the limit", before=before)
