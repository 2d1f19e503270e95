"""The loudness of a soundtrack: EBU R 128 integrated loudness, measured by ffmpeg, and a gain to a target.

User-study stimuli (:mod:`gesturekit.study.stimuli`) bring every speech to one loudness, so that
nothing but the motion tells the stimuli apart.
"""

from __future__ import annotations

import math
import re
import subprocess

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError, GestureKitError
from ..motion import AUDIO_SR
from .video import ffmpeg_executable

__all__ = ["measure_loudness", "normalise_loudness"]

_LOUDNESS_RE = re.compile(r"Integrated loudness:\s*I:\s*(-?[0-9.]+|-inf)\s*LUFS", re.S)


@checks_arguments
def measure_loudness(audio: np.ndarray, *, sr: int = AUDIO_SR) -> float:
    """Integrated loudness (EBU R 128 / ITU-R BS.1770) of mono audio, LUFS, measured by ffmpeg.

    Returns
    -------
    float
        LUFS, 0.1 LU resolution; about -70 (the gate) for silence or audio under 0.4 s.
    """
    a = np.ascontiguousarray(audio, dtype="<f4")
    if a.ndim != 1 or a.size == 0:
        raise ConfigError(f"audio must be mono samples, shape (samples,), got {a.shape}")
    run = subprocess.run(
        [
            ffmpeg_executable(),
            "-hide_banner",
            "-nostdin",
            "-f",
            "f32le",
            "-ar",
            str(int(sr)),
            "-ac",
            "1",
            "-i",
            "pipe:0",
            "-af",
            "ebur128=framelog=quiet",
            "-f",
            "null",
            "-",
        ],
        input=a.tobytes(),
        capture_output=True,
    )
    m = _LOUDNESS_RE.search(run.stderr.decode("utf-8", "replace"))
    if run.returncode != 0 or m is None:
        raise GestureKitError(
            "ffmpeg could not measure the loudness of the speech: "
            + run.stderr.decode("utf-8", "replace").strip()[-300:]
        )
    return -70.0 if m.group(1) == "-inf" else float(m.group(1))


@checks_arguments
def normalise_loudness(
    audio: np.ndarray, *, sr: int = AUDIO_SR, target_lufs: float = -23.0, peak: float = 0.98
) -> tuple[np.ndarray, float]:
    """Scale speech to an integrated loudness, never past a sample peak.

    Parameters
    ----------
    audio : np.ndarray, shape (samples,)
    sr : int
    target_lufs : float
        Target loudness, LUFS (EBU R 128 broadcast: -23).
    peak : float
        Largest absolute sample allowed after scaling; when the target needs more, the gain
        stops there (the clip is then quieter than the target).

    Returns
    -------
    audio : np.ndarray, shape (samples,), float32
    gain_db : float
        The gain applied (0 for silence).
    """
    a = np.asarray(audio, dtype=np.float32)
    level = measure_loudness(a, sr=sr)
    if level <= -69.0:
        return a.copy(), 0.0
    gain = 10 ** ((target_lufs - level) / 20)
    top = float(np.max(np.abs(a)))
    if top > 0 and top * gain > peak:
        gain = peak / top
    return (a * np.float32(gain)).astype(np.float32), 20 * math.log10(gain)
