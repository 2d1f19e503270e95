"""Input limits: the limits themselves, memory of refused inputs, truncated compressed audio, absurd BVH values."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit import limits
from gesturekit.datasets.audio import load_audio, load_audio_with_info
from gesturekit.datasets.bvh import load_bvh_motion
from gesturekit.errors import AudioFileError, ConfigError, InputFileError, MotionFileError
from gesturekit.skeleton import N_JOINTS
from tests import hostile as h
from tests.datasets.test_bvh import bvh_text, random_values, zeggs_like_skeleton
from tests.waits import patience

SHARED_SPEECH = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "speech"
LIMIT_VARS = [
    limits.SPEECH_MINUTES,
    limits.TAKE_HOURS,
    limits.MIN_SAMPLE_RATE,
    limits.MAX_SAMPLE_RATE,
    limits.MIN_FPS,
    limits.MAX_FPS,
    limits.INPUT_GB,
]

# random joint angles are no upright body: read them with the axes as they are
AS_IS = {"up": "y", "forward": "z", "check_plausible": False}


@pytest.fixture(autouse=True)
def _default_limits(monkeypatch):
    for limit in LIMIT_VARS:
        monkeypatch.delenv(limit.env, raising=False)


# ----------------------------------------------------------------------------- the limits


def test_documented_defaults():
    assert limits.max_speech_seconds() == 3600.0
    assert limits.max_take_seconds() == 4 * 3600.0
    assert (limits.MIN_SAMPLE_RATE.value(), limits.MAX_SAMPLE_RATE.value()) == (4000.0, 384000.0)
    assert (limits.MIN_FPS.value(), limits.MAX_FPS.value()) == (1.0, 1000.0)
    assert limits.max_input_bytes() == 4e9


@pytest.mark.parametrize("limit", LIMIT_VARS, ids=lambda lim: lim.env)
def test_each_limit_is_set_by_its_environment_variable(limit, monkeypatch):
    monkeypatch.setenv(limit.env, "2.5")
    assert limit.value() == 2.5
    monkeypatch.setenv(limit.env, "")
    assert limit.value() == limit.default


@pytest.mark.parametrize("text", ["nan", "-1", "0", "lots", "inf"])
def test_a_bad_environment_value_is_refused_naming_the_variable(text, monkeypatch):
    monkeypatch.setenv("GESTUREKIT_MAX_TAKE_HOURS", text)
    with pytest.raises(ConfigError, match="GESTUREKIT_MAX_TAKE_HOURS"):
        limits.max_take_seconds()


def test_override_holds_inside_its_block_only_and_outranks_the_environment(monkeypatch):
    monkeypatch.setenv("GESTUREKIT_MAX_SPEECH_MINUTES", "10")
    with limits.override(limits.SPEECH_MINUTES, 2, option="--max-speech-minutes"):
        assert limits.max_speech_seconds() == 120.0
        with pytest.raises(InputFileError, match=r"limit of 2\.0 min for speech \(--max-speech-minutes sets it\)"):
            limits.check_duration(121.0, what="the header says", path="a.wav", speech=True)
        with limits.override(limits.SPEECH_MINUTES, None):  # no option given: no change
            assert limits.max_speech_seconds() == 120.0
    assert limits.max_speech_seconds() == 600.0
    with pytest.raises(ConfigError, match="--max-speech-minutes must be a positive number"):
        with limits.override(limits.SPEECH_MINUTES, float("nan"), option="--max-speech-minutes"):
            pass


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(hours=st.floats(0.01, 100), seconds=st.floats(0, 1e6) | st.sampled_from([math.inf, math.nan]))
def test_duration_is_refused_exactly_beyond_the_limit(hours, seconds, monkeypatch):
    monkeypatch.setenv("GESTUREKIT_MAX_TAKE_HOURS", repr(hours))
    if math.isfinite(seconds) and seconds <= hours * 3600:
        limits.check_duration(seconds, what="the header says", path="take.bvh")
        return
    with pytest.raises(InputFileError) as info:
        limits.check_duration(seconds, what="the header says 9 frames", path="take.bvh")
    message = str(info.value)
    assert message.startswith("take.bvh: the header says 9 frames")
    assert "beyond the limit" in message and "GESTUREKIT_MAX_TAKE_HOURS" in message


@settings(max_examples=60, deadline=None)
@given(fps=st.floats(allow_nan=True, allow_infinity=True))
def test_frame_rate_range(fps):
    inside = math.isfinite(fps) and 1.0 <= fps <= 1000.0
    try:
        limits.check_fps(fps, what="the frame rate", path="x.bvh")
    except InputFileError as e:
        assert not inside and "x.bvh" in str(e) and "1-1000 fps" in str(e)
    else:
        assert inside
    if not inside:
        with pytest.raises(ConfigError, match="^--fps: "):
            limits.check_fps(fps, what="the frame rate", option="--fps")


@settings(max_examples=60, deadline=None)
@given(rate=st.integers(0, 2**32))
def test_sample_rate_range(rate):
    inside = 4000 <= rate <= 384000
    try:
        limits.check_sample_rate(rate, what="the WAV header", path="a.wav")
    except InputFileError as e:
        assert not inside and "GESTUREKIT_MIN_SAMPLE_RATE" in str(e)
    else:
        assert inside


def test_descriptions():
    assert limits.describe_seconds(8.04) == "8.0 s"
    assert limits.describe_seconds(8000) == "2.2 h"
    assert limits.describe_seconds(600) == "10.0 min"
    assert limits.describe_bytes(16_000) == "16 KB"
    assert limits.describe_bytes(2.7e9) == "2.7 GB"
    assert limits.array_bytes((10**12, 55, 3), 8) == 1.32e15  # no integer overflow


def test_npy_and_npz_headers_are_read_without_the_data(tmp_path):
    path = h.npy_claiming(tmp_path / "big.npy", (10**12, 55, 3))
    with open(path, "rb") as f:
        shape, dtype, offset = limits.npy_header(f, path=path)
    assert (shape, dtype, offset) == ((10**12, 55, 3), np.dtype("<f8"), 128)
    z = h.npz_claiming(tmp_path / "big.npz", {"body": (3, 10**9, 165), "wav": np.zeros((3, 5), np.float32)})
    headers = limits.npz_headers(z)
    assert headers["body"] == ((3, 10**9, 165), np.dtype("<f4"))
    assert headers["wav"] == ((3, 5), np.dtype("<f4"))
    (tmp_path / "bad.npy").write_bytes(b"\x93NUMPY\x09\x00garbage")
    with open(tmp_path / "bad.npy", "rb") as f, pytest.raises(MotionFileError, match="cannot read the npy header"):
        limits.npy_header(f, path=tmp_path / "bad.npy")


# ----------------------------------------------------------------------------- memory of refused inputs

#: The most a refused input may cost (peak resident memory above the process before it).
MEMORY_BOUND_MB = 200

_MEASURE = textwrap.dedent("""
    import json, sys
    from gesturekit.cli import main

    def status(key):
        for line in open("/proc/self/status"):
            if line.startswith(key):
                return int(line.split()[1]) / 1024  # MB

    results = {}
    # calibration: the measure must see memory that is used
    open("/proc/self/clear_refs", "w").write("5")
    before = status("VmRSS:")
    import numpy as np
    block = np.ones(100 * 2**20 // 8)
    results["calibration"] = {"code": None, "peak_mb": status("VmHWM:"), "above_mb": status("VmHWM:") - before}
    del block
    for name, argv in json.loads(sys.argv[1]).items():
        main(argv)  # once for the imports this command needs, which are not the input's cost
        open("/proc/self/clear_refs", "w").write("5")  # reset the peak (VmHWM) to now
        before = status("VmRSS:")
        code = main(argv)
        results[name] = {"code": code, "peak_mb": status("VmHWM:"), "above_mb": status("VmHWM:") - before}
    print(json.dumps(results))
""")


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/clear_refs").exists(), reason="needs Linux /proc to read peak memory")
def test_refusing_a_hostile_input_costs_less_than_200_mb(tmp_path):
    """Each hostile file asks for gigabytes (the 1 Hz WAV once took 2.7 GB); refusing it must not."""

    def bvh_folder(name, **kwargs):
        folder = tmp_path / name
        h.bvh_take(folder, **kwargs)
        return folder

    one_hz = bvh_folder("one_hz", audio=False)
    h.wav_with_header(one_hz / "take.wav", rate=1)
    huge_flac = bvh_folder("huge_flac", audio=False)
    h.flac_declaring(huge_flac / "take.flac", 2**36 - 1)
    positions = tmp_path / "positions"
    h.position_take(positions)
    jmap = h.identity_position_map(tmp_path / "map.json")
    big_npy = tmp_path / "big_npy"
    big_npy.mkdir()
    h.npy_claiming(big_npy / "take.npy", (10**12, N_JOINTS, 3))
    sf.write(big_npy / "take.wav", h.speech_like(2.0), h.SR)
    habibie = tmp_path / "habibie"
    habibie.mkdir()
    h.npz_claiming(habibie / "s.npz", {"wav": (2, 10**10), "body": (2, 10**8, N_JOINTS * 3)})

    out = str(tmp_path / "db")
    cases = {
        "wav header 1 Hz": ["build-db", str(one_hz), "--out", out],
        "flac declaring 2^36 samples": ["build-db", str(huge_flac), "--out", out],
        "bvh frame time 100000": ["build-db", str(bvh_folder("slow", frame_time="100000")), "--out", out],
        "bvh Frames: 10^12": ["build-db", str(bvh_folder("many", frames="1000000000000")), "--out", out],
        "positions --fps 1e-300": [
            "build-db",
            str(positions),
            "--kind",
            "positions",
            "--joint-map",
            str(jmap),
            "--fps",
            "1e-300",
            "--out",
            out,
        ],
        "npy header 10^12 frames": [
            "build-db",
            str(big_npy),
            "--kind",
            "positions",
            "--joint-map",
            str(jmap),
            "--fps",
            "30",
            "--out",
            out,
        ],
        "habibie npz 10^8 frames": ["build-db", str(habibie), "--kind", "habibie2021", "--out", out],
    }
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    proc = subprocess.run(
        [sys.executable, "-c", _MEASURE, json.dumps(cases)],
        capture_output=True,
        text=True,
        env=env,
        timeout=patience(300),
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    results = json.loads(proc.stdout.strip().splitlines()[-1])
    assert 95 < results.pop("calibration")["above_mb"] < 130  # a 100 MiB array is seen
    for name, r in results.items():
        assert r["code"] == 2, (name, proc.stderr[-2000:])
        assert r["above_mb"] < MEMORY_BOUND_MB, (name, r)
    print(
        "\n".join(
            f"{n}: {r['above_mb']:.1f} MB above the process, peak {r['peak_mb']:.0f} MB" for n, r in results.items()
        )
    )


# ----------------------------------------------------------------------------- truncated compressed audio


@pytest.fixture(scope="module")
def speech(tmp_path_factory) -> dict[str, Path]:
    return h.encoded(tmp_path_factory.mktemp("speech"), seconds=20.0)


@pytest.mark.parametrize(
    "kind, fmt",
    [("wav", "WAV"), ("flac", "FLAC"), ("ogg", "OGG"), ("opus", "OGG"), ("mp3", "MP3"), ("xing.mp3", "MP3")],
)
def test_whole_files_still_load(kind, fmt, speech):
    audio, info = load_audio_with_info(speech[kind])
    assert info.format == fmt
    assert abs(info.duration - 20.0) < 0.15  # MP3 without a Xing header decodes its encoder delay too
    assert audio.shape[0] == pytest.approx(20.0 * 16000, abs=0.15 * 16000)


@pytest.mark.parametrize("name", ["espeak_en_us.mp3", "espeak_en_us_44k_stereo.flac"])
def test_shared_recordings_still_load(name):
    path = SHARED_SPEECH / name
    if not path.exists():
        pytest.skip("shared test data not present")
    audio, info = load_audio_with_info(path)
    assert 16.5 < info.duration < 17.5 and audio.shape[0] > 16 * 16000


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(fraction=st.floats(0.05, 0.995), kind=st.sampled_from(["ogg", "opus"]))
def test_any_cut_of_an_ogg_stream_is_reported(fraction, kind, speech, tmp_path):
    path = h.cut(speech[kind], tmp_path / f"cut_{kind}.ogg", fraction)
    with pytest.raises(AudioFileError, match="truncated") as info:
        load_audio(path)
    assert str(path) in str(info.value) and "Ogg stream ends" in str(info.value)


def test_ogg_message_says_how_much_is_left(speech, tmp_path):
    path = h.cut(speech["ogg"], tmp_path / "cut.ogg", 0.4)
    with pytest.raises(AudioFileError) as info:
        load_audio(path)
    seconds = float(str(info.value).split("ends after ")[1].split(" s")[0])
    assert 5.0 < seconds < 11.0  # 40 % of the bytes of 20 s, within the encoder's rate changes


@pytest.mark.parametrize("fraction", [0.4, 0.71, 0.93])
def test_mp3_without_xing_cut_inside_a_frame(fraction, speech, tmp_path):
    path = h.cut(speech["mp3"], tmp_path / "cut.mp3", fraction)
    with pytest.raises(
        AudioFileError,
        match=r"the last MP3 frame is cut off \(\d+ of its bytes are missing\); "
        r"the audio ends after [\d.]+ s",
    ) as info:
        load_audio(path)
    seconds = float(str(info.value).split("ends after ")[1].split(" s")[0])
    assert seconds == pytest.approx(20.0 * fraction, abs=0.5)  # constant bitrate: bytes are time


def _id3_with_length(ms: int) -> bytes:
    """An ID3v2.3 tag holding one TLEN (length in milliseconds) frame."""
    text = b"\x00" + str(ms).encode()
    frame = b"TLEN" + len(text).to_bytes(4, "big") + b"\x00\x00" + text
    size = len(frame)
    synchsafe = bytes((size >> s) & 0x7F for s in (21, 14, 7, 0))
    return b"ID3\x03\x00\x00" + synchsafe + frame


def test_mp3_cut_between_frames_is_caught_by_its_id3_length(tmp_path):
    # 32 kbit/s at 16 kHz: every frame is exactly 144 bytes, so a cut can fall between two frames
    bare = tmp_path / "bare.mp3"
    sf.write(tmp_path / "s.wav", h.speech_like(10.0), h.SR)
    h.ffmpeg(
        "-i", tmp_path / "s.wav", "-c:a", "libmp3lame", "-b:a", "32k", "-write_xing", "0", "-id3v2_version", "0", bare
    )
    raw = bare.read_bytes()
    assert raw[:2] == b"\xff\xf3" and raw[144:146] == b"\xff\xf3"
    whole = tmp_path / "whole.mp3"
    whole.write_bytes(_id3_with_length(10_000) + raw)
    assert abs(load_audio_with_info(whole)[1].duration - 10.0) < 0.2
    cut = tmp_path / "cut.mp3"
    cut.write_bytes(_id3_with_length(10_000) + raw[: 144 * 150])  # 150 frames of 576 samples: 5.4 s
    with pytest.raises(
        AudioFileError,
        match=r"cut\.mp3: the file is truncated: it ends after 5\.4 s of the 10\.0 s "
        r"its ID3 tag declares",
    ):
        load_audio(cut)


def test_audio_longer_than_the_take_limit_is_refused_before_decoding(tmp_path, monkeypatch):
    path = tmp_path / "long.flac"
    sf.write(path, h.speech_like(3.0), h.SR, format="FLAC")
    monkeypatch.setenv("GESTUREKIT_MAX_TAKE_HOURS", str(2.0 / 3600))
    with pytest.raises(
        InputFileError,
        match=r"long\.flac: the FLAC header says 48000 samples at 16000 Hz: 3\.0 s, "
        r"beyond the limit of 2\.0 s for one take",
    ):
        load_audio(path, take=True)
    assert load_audio(path).shape == (48000,)  # speech has its own limit


def test_many_channels_beyond_the_memory_limit(tmp_path, monkeypatch):
    path = tmp_path / "wide.wav"
    h.wav_with_header(path, rate=16000, n_samples=16000, channels=64)
    monkeypatch.setenv("GESTUREKIT_MAX_INPUT_GB", "0.001")  # 1 MB; 64 channels of 1 s take 4 MB
    with pytest.raises(
        InputFileError,
        match=r"wide\.wav: the WAV header says 16000 samples of 64 channels: "
        r"4\.16 MB once decoded, beyond the limit of 1 MB",
    ):
        load_audio(path)


@pytest.fixture(scope="module")
def m4a(tmp_path_factory) -> Path:
    """12 s of speech in an M4A (AAC) container, which soundfile cannot read: ffmpeg decodes it."""
    folder = tmp_path_factory.mktemp("m4a")
    sf.write(folder / "s.wav", h.speech_like(12.0), h.SR)
    h.ffmpeg("-i", folder / "s.wav", "-c:a", "aac", folder / "speech.m4a")
    return folder / "speech.m4a"


def test_a_container_read_by_ffmpeg_is_checked_from_its_header(m4a, monkeypatch):
    monkeypatch.setenv("GESTUREKIT_MAX_SPEECH_MINUTES", "0.1")
    with pytest.raises(
        InputFileError,
        match=r"speech\.m4a: the AAC container header says 192000 samples at "
        r"16000 Hz: 12\.0 s, beyond the limit of 6\.0 s for speech",
    ):
        load_audio(m4a)
    monkeypatch.setenv("GESTUREKIT_MAX_SPEECH_MINUTES", "0.5")
    assert load_audio_with_info(m4a)[1].duration == pytest.approx(12.0, abs=0.1)


def test_a_stream_of_unstated_length_is_decoded_only_up_to_the_limit(m4a, monkeypatch):
    from gesturekit.datasets import audio as audio_module

    monkeypatch.setattr(audio_module, "_probe_ffmpeg", lambda exe, path, budget: None)  # a header that says nothing
    monkeypatch.setenv("GESTUREKIT_MAX_SPEECH_MINUTES", "0.1")
    with pytest.raises(
        InputFileError,
        match=r"speech\.m4a: decoding stopped past the limit, at: 7\.0 s, "
        r"beyond the limit of 6\.0 s for speech",
    ):
        load_audio(m4a)


def test_the_app_upload_meets_the_same_limits(tmp_path):
    from gesturekit.errors import GestureKitError
    from gesturekit.interactive import read_speech_upload

    raw = h.wav_with_header(tmp_path / "one_hz.wav", rate=1).read_bytes()
    with pytest.raises(GestureKitError, match=r"^my speech\.wav: the WAV header says a sample rate of 1 Hz"):
        read_speech_upload("my speech.wav", raw)


# ----------------------------------------------------------------------------- absurd BVH values


def _skeleton_with(tmp_path, *, offset_scale=1.0, root_shift=0.0, name="t.bvh"):
    joints = zeggs_like_skeleton()
    if offset_scale != 1.0:  # one finger bone absurdly long
        k = next(i for i, j in enumerate(joints) if j[0] == "LeftHandIndex2")
        n, p, off, ch, end = joints[k]
        joints[k] = (n, p, off * offset_scale, ch, end)
    values = random_values(joints, 30, np.random.default_rng(3))
    values[:, 0] += root_shift
    path = tmp_path / name
    path.write_text(bvh_text(joints, values))
    return path


def test_a_bone_kilometres_long_is_refused_after_forward_kinematics(tmp_path):
    path = _skeleton_with(tmp_path, offset_scale=1e6)  # 3.2 cm -> 32 km
    with pytest.raises(
        MotionFileError,
        match=r"absurd positions after forward kinematics: joint "
        r"'LeftHandIndex\d(_End)?' at frame 0 \(0\.00 s\) lies [\d.e+]+ m from "
        r"the pelvis 'Hips' along one axis \(more than 1 km\)",
    ) as info:
        load_bvh_motion(path, **AS_IS)
    assert str(path) in str(info.value)


def test_plausible_large_values_still_load(tmp_path):
    path = _skeleton_with(tmp_path, root_shift=50_000.0)  # walked 500 m away: unusual, not absurd
    motion = load_bvh_motion(path, **AS_IS)
    assert np.isfinite(motion.positions).all() and np.abs(motion.positions).max() < 2.0


@pytest.mark.parametrize(
    "value, problem", [("1e300", "absurd rotation"), ("-1e300", "absurd rotation"), ("2e6", "absurd rotation")]
)
def test_rotation_values_no_pose_can_have(value, problem, tmp_path):
    path = h.bvh_take(tmp_path, marks={(17, 8): value}, audio=False)
    with pytest.raises(MotionFileError, match=problem + r".*at frame 17 \(0\.57 s\); 1 frames affected"):
        load_bvh_motion(path, **AS_IS)


@pytest.mark.parametrize(
    "kwargs, problem",
    [
        (dict(frame_time="100000"), "outside the accepted range"),
        (dict(frames="1000000000"), "beyond the limit of 4.0 h"),
    ],
)
def test_bvh_header_beyond_the_limits_is_refused_before_the_file_is_read_whole(kwargs, problem, tmp_path, monkeypatch):
    from gesturekit.datasets.bvh import parse_bvh

    path = h.bvh_take(tmp_path, audio=False, **kwargs)

    def read_whole(self):
        raise AssertionError("the whole file was read")

    monkeypatch.setattr(Path, "read_bytes", read_whole)
    with pytest.raises(InputFileError, match=problem) as info:
        parse_bvh(path)
    assert str(info.value).startswith(f"{path}: line ")
