"""Makers of hostile and damaged input files for the limits and bad-input tests.

Each writes a small file whose header asks for far more than the file holds
(a 1 Hz WAV, a BVH frame time of 100000 s, an npy header claiming a terabyte),
or a valid recording cut short. Speech is generated here, never copied in.
"""

from __future__ import annotations

import json
import struct
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import soundfile as sf

from gesturekit.skeleton import JOINT_NAMES, N_JOINTS
from tests.datasets.test_bvh import bvh_text, random_values, zeggs_like_skeleton

SR = 16000


def speech_like(seconds: float, rate: int = SR, seed: int = 0) -> np.ndarray:
    """A voiced, syllable-rate modulated signal (mono float32, peak 0.5)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate)) / rate
    f0 = 120 + 30 * np.sin(2 * np.pi * 0.7 * t)
    voice = sum(np.sin(2 * np.pi * k * np.cumsum(f0) / rate) / k for k in range(1, 8))
    envelope = 0.5 + 0.5 * np.sin(2 * np.pi * 4 * t) ** 2
    x = voice * envelope + 0.05 * rng.standard_normal(t.size)
    return (0.5 * x / np.max(np.abs(x))).astype(np.float32)


def wav_with_header(
    path: Path, *, rate: int, n_samples: int = 8000, channels: int = 1, declared_bytes: int | None = None
) -> Path:
    """A 16-bit PCM WAV of ``n_samples`` noise samples whose header states ``rate`` (and a data size)."""
    data = (np.random.default_rng(1).standard_normal(n_samples * channels) * 3000).astype("<i2").tobytes()
    size = len(data) if declared_bytes is None else declared_bytes
    fmt = struct.pack("<IHHIIHH", 16, 1, channels, rate % 2**32, (rate * 2 * channels) % 2**32, 2 * channels, 16)
    path.write_bytes(
        b"RIFF"
        + struct.pack("<I", (36 + size) % 2**32)
        + b"WAVE"
        + b"fmt "
        + fmt
        + b"data"
        + struct.pack("<I", size)
        + data
    )
    return path


def flac_declaring(path: Path, total_samples: int, seconds: float = 2.0) -> Path:
    """A real FLAC file whose STREAMINFO states ``total_samples`` (36 bits) instead of the true count."""
    sf.write(path, speech_like(seconds), SR, format="FLAC")
    raw = bytearray(path.read_bytes())
    assert raw[:4] == b"fLaC" and raw[4] & 0x7F == 0  # the first metadata block is STREAMINFO
    # STREAMINFO bytes 10..17 (from its start at 8): 20 bits rate, 3 channels-1, 5 bps-1, 36 total samples
    field = int.from_bytes(raw[8 + 10 : 8 + 18], "big")
    field = (field & ~((1 << 36) - 1)) | (total_samples & ((1 << 36) - 1))
    raw[8 + 10 : 8 + 18] = field.to_bytes(8, "big")
    raw[8 + 18 : 8 + 34] = bytes(16)  # MD5 0: unknown, so decoders do not check it
    path.write_bytes(bytes(raw))
    return path


def ffmpeg(*args: str | Path) -> None:
    import imageio_ffmpeg

    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-nostdin", "-v", "error", "-y", *map(str, args)]
    subprocess.run(cmd, check=True, capture_output=True)


def encoded(folder: Path, seconds: float = 20.0) -> dict[str, Path]:
    """Generated speech as WAV, FLAC, Ogg Vorbis, Ogg Opus, MP3 without and with a Xing header."""
    src = folder / "speech.wav"
    sf.write(src, speech_like(seconds), SR, subtype="PCM_16")
    out = {"wav": src, "flac": folder / "speech.flac"}
    sf.write(out["flac"], speech_like(seconds), SR, format="FLAC")
    for name, args in (
        ("ogg", ("-c:a", "libvorbis")),
        ("opus", ("-c:a", "libopus")),
        ("mp3", ("-c:a", "libmp3lame", "-write_xing", "0")),
        ("xing.mp3", ("-c:a", "libmp3lame")),
    ):
        dst = folder / f"speech.{name}" if name != "opus" else folder / "speech.opus.ogg"
        ffmpeg("-i", src, *args, dst)
        out[name] = dst
    return out


def cut(src: Path, dst: Path, fraction: float) -> Path:
    """``dst`` holding the first ``fraction`` of ``src``'s bytes."""
    raw = src.read_bytes()
    dst.write_bytes(raw[: int(len(raw) * fraction)])
    return dst


# ----------------------------------------------------------------------------- motion


MARK = 4321.5  # a channel value replaced in the text by the hostile one


def bvh_take(
    folder: Path,
    name: str = "take",
    *,
    frame_time: str = "0.0333333333",
    frames: str | None = None,
    marks: dict[tuple[int, int], str] | None = None,
    n_frames: int = 30,
    audio: bool = True,
) -> Path:
    """A ZEGGS-named BVH take (and its speech) in ``folder``; returns the BVH path.

    ``marks`` puts text (``"1e300"``) in place of channel values at (frame, column).
    """
    folder.mkdir(parents=True, exist_ok=True)
    joints = zeggs_like_skeleton()
    values = random_values(joints, n_frames, np.random.default_rng(0))
    for f, c in marks or {}:
        values[f, c] = MARK
    text = bvh_text(joints, values, frame_time=1 / 30, frames_header=frames)
    text = text.replace("Frame Time: 0.0333333333", f"Frame Time: {frame_time}")
    lines = text.split("\n")
    motion_at = lines.index("MOTION")
    for (f, c), new in (marks or {}).items():
        row = lines[motion_at + 3 + f].split(" ")
        assert float(row[c]) == MARK
        row[c] = new
        lines[motion_at + 3 + f] = " ".join(row)
    path = folder / f"{name}.bvh"
    path.write_text("\n".join(lines))
    if audio:
        sf.write(folder / f"{name}.wav", speech_like(n_frames / 30 + 0.5), SR, subtype="PCM_16")
    return path


def npy_claiming(path: Path, shape: tuple[int, ...], dtype: str = "<f8", payload: bytes = b"\0" * 64) -> Path:
    """An ``.npy`` file whose header states ``shape`` but that holds only ``payload``."""
    with open(path, "wb") as f:
        np.lib.format.write_array_header_1_0(f, {"descr": dtype, "fortran_order": False, "shape": shape})
        f.write(payload)
    return path


def npz_claiming(path: Path, members: dict[str, tuple[int, ...] | np.ndarray]) -> Path:
    """An ``.npz`` archive: real arrays, or members whose npy header states a shape they do not hold."""
    with zipfile.ZipFile(path, "w") as z:
        for key, value in members.items():
            with z.open(f"{key}.npy", "w", force_zip64=True) as f:
                if isinstance(value, np.ndarray):
                    np.lib.format.write_array(f, value, allow_pickle=False)
                else:
                    np.lib.format.write_array_header_1_0(f, {"descr": "<f4", "fortran_order": False, "shape": value})
                    f.write(b"\0" * 64)
    return path


def identity_position_map(path: Path) -> Path:
    """A position joint map for files already in our joint order, pelvis first."""
    path.write_text(json.dumps({"pelvis": 0, "joints": {n: i for i, n in enumerate(JOINT_NAMES)}}))
    return path


def position_take(folder: Path, name: str = "take", *, frames: int = 60, fps: float = 30.0) -> Path:
    """A valid positions take (npy) with its speech; returns the npy path."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(2)
    path = folder / f"{name}.npy"
    np.save(path, rng.normal(0, 0.3, (frames, N_JOINTS, 3)))
    sf.write(folder / f"{name}.wav", speech_like(frames / fps + 0.5), SR, subtype="PCM_16")
    return path
