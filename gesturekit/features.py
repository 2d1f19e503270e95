"""Audio and pose features of the matching, declared once.

The feature layout (:class:`FeatureLayout`) is the single place that says how
many values each feature has and where they sit; search, database, refiner,
app and tests all read it from here.

Audio (per frame, 14 values, ``m_t``): 13 MFCCs and the log mean energy of a
Hann window centred on frame ``t``, i.e. at ``t / 15`` s. The centre of every
frame is computed from ``t`` directly (rounded to the nearest sample), never by
adding up a rounded hop, so the grid does not drift over hours of audio.

Audio feature (``f_t``, 112): ``[m_t, m_{t+2}, ..., m_{t+14}]``, one second of look-ahead.
Pose feature (``p_t``, 96): positions of the 8 feature joints at ``t, t+2, t+4, t+6``.
cGAN audio (28): ``m_t`` and its first time derivative (per frame).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from ._arguments import checks_arguments
from .errors import ConfigError
from .motion import AUDIO_SR, n_audio_frames
from .skeleton import FPS, JOINT_NAMES, N_JOINTS, POSE_FEATURE_JOINTS

__all__ = [
    "FeatureLayout",
    "LAYOUT",
    "n_audio_frames",
    "frame_centres",
    "audio_frame_features",
    "stack_audio_features",
    "pose_features",
    "cgan_audio_features",
    "valid_starts",
    "ZScore",
]


@dataclass(frozen=True)
class FeatureLayout:
    """Sizes and positions of every feature block.

    The search feature of a frame is ``[audio (112) | pose (96)]``; its named
    slices are :attr:`slices`. Changing any field changes :meth:`signature`,
    which databases and refiners store and compare.
    """

    sr: int = AUDIO_SR
    fps: int = FPS
    n_mfcc: int = 13
    n_mels: int = 40
    n_fft: int = 2048
    audio_offsets: tuple[int, ...] = (0, 2, 4, 6, 8, 10, 12, 14)
    pose_offsets: tuple[int, ...] = (0, 2, 4, 6)
    pose_joints: tuple[str, ...] = POSE_FEATURE_JOINTS
    n_joints: int = N_JOINTS

    @property
    def frame_dim(self) -> int:
        """Values of ``m_t``: MFCCs + log mean energy (14)."""
        return self.n_mfcc + 1

    @property
    def audio_dim(self) -> int:
        """Values of ``f_t`` (112)."""
        return self.frame_dim * len(self.audio_offsets)

    @property
    def pose_dim(self) -> int:
        """Values of ``p_t`` (96)."""
        return len(self.pose_joints) * 3 * len(self.pose_offsets)

    @property
    def motion_dim(self) -> int:
        """Values of ``g_t`` (165)."""
        return self.n_joints * 3

    @property
    def cgan_audio_dim(self) -> int:
        """Values of the cGAN's audio input per frame (28)."""
        return 2 * self.frame_dim

    @property
    def audio_lookahead(self) -> int:
        """Frames after ``t`` that ``f_t`` reads (14)."""
        return max(self.audio_offsets)

    @property
    def pose_lookahead(self) -> int:
        """Frames after ``t`` that ``p_t`` reads (6)."""
        return max(self.pose_offsets)

    @property
    def slices(self) -> dict[str, slice]:
        """Named slices of the search feature ``[audio | pose]`` and of ``m_t``."""
        a, p = self.audio_dim, self.pose_dim
        return {
            "audio": slice(0, a),
            "pose": slice(a, a + p),
            "mfcc": slice(0, self.n_mfcc),
            "log_energy": slice(self.n_mfcc, self.n_mfcc + 1),
        }

    def signature(self) -> dict:
        """A JSON-able description; two layouts are compatible iff their signatures are equal."""
        d = asdict(self)
        d["audio_offsets"] = list(self.audio_offsets)
        d["pose_offsets"] = list(self.pose_offsets)
        d["pose_joints"] = list(self.pose_joints)
        return d


LAYOUT = FeatureLayout()
assert (LAYOUT.frame_dim, LAYOUT.audio_dim, LAYOUT.pose_dim, LAYOUT.motion_dim, LAYOUT.cgan_audio_dim) == (
    14,
    112,
    96,
    165,
    28,
)


@checks_arguments
def frame_centres(n_frames: int, *, sr: int = AUDIO_SR, fps: int = FPS, first: int = 0) -> np.ndarray:
    """Sample index of the centre of each frame, shape (n_frames,), int64.

    Frame ``t`` is centred at ``t / fps`` seconds, i.e. sample ``t * sr / fps``
    rounded half up, computed exactly in integers for every ``t``; the frames are
    ``first .. first + n_frames - 1``.
    """
    t = np.arange(first, first + n_frames, dtype=np.int64)
    return (2 * t * sr + fps) // (2 * fps)


# Slaney's mel scale: linear below 1 kHz, logarithmic above (constants as librosa writes them,
# so that the filters come out bit-identical)
_MEL_F_SP = 200.0 / 3
_MEL_MIN_LOG_HZ = 1000.0
_MEL_MIN_LOG_MEL = (_MEL_MIN_LOG_HZ - 0.0) / _MEL_F_SP
_MEL_LOGSTEP = np.log(6.4) / 27.0


def _hz_to_mel(hz: float | np.ndarray) -> np.ndarray:
    """Slaney mel of frequencies ``hz`` (array, Hz)."""
    hz = np.atleast_1d(np.asarray(hz, dtype=np.float64))
    mel = (hz - 0.0) / _MEL_F_SP
    log = hz >= _MEL_MIN_LOG_HZ
    mel[log] = _MEL_MIN_LOG_MEL + np.log(hz[log] / _MEL_MIN_LOG_HZ) / _MEL_LOGSTEP
    return mel


def _mel_to_hz(mel: float | np.ndarray) -> np.ndarray:
    """Inverse of :func:`_hz_to_mel`."""
    mel = np.atleast_1d(np.asarray(mel, dtype=np.float64))
    hz = 0.0 + _MEL_F_SP * mel
    log = mel >= _MEL_MIN_LOG_MEL
    hz[log] = _MEL_MIN_LOG_HZ * np.exp(_MEL_LOGSTEP * (mel[log] - _MEL_MIN_LOG_MEL))
    return hz


def mel_filterbank(*, sr: int, n_fft: int, n_mels: int, fmin: float = 0.0, fmax: float | None = None) -> np.ndarray:
    """Triangular mel filters on Slaney's scale with Slaney's area normalisation.

    The same weights as ``librosa.filters.mel`` with its defaults (bit for bit,
    tested), computed here because importing librosa costs seconds.

    Parameters
    ----------
    sr : int
        Sample rate, Hz.
    n_fft : int
        FFT length, samples.
    n_mels : int
        Number of filters.
    fmin, fmax : float
        Lowest and highest filter edge, Hz (``fmax`` default ``sr / 2``).

    Returns
    -------
    np.ndarray, shape (n_mels, 1 + n_fft // 2), float32
    """
    fmax = sr / 2 if fmax is None else fmax
    fft_hz = np.fft.rfftfreq(n=n_fft, d=1.0 / sr)
    edges = _mel_to_hz(np.linspace(_hz_to_mel(fmin)[0], _hz_to_mel(fmax)[0], n_mels + 2))
    widths = np.diff(edges)
    ramps = np.subtract.outer(edges, fft_hz)
    weights = np.zeros((n_mels, 1 + n_fft // 2), dtype=np.float32)
    for i in range(n_mels):
        # rising and falling edge of filter i, clipped at zero (rounded to float32, then scaled,
        # in that order: the order of librosa's computation, so the weights are identical)
        weights[i] = np.maximum(0, np.minimum(-ramps[i] / widths[i], ramps[i + 2] / widths[i + 1]))
    weights *= (2.0 / (edges[2 : n_mels + 2] - edges[:n_mels]))[:, None]
    return weights


@dataclass(frozen=True, eq=False)
class _MelBands:
    """The mel filters as bands of consecutive FFT bins, applied frame by frame in a fixed order.

    A matrix product (BLAS) rounds a frame's sums differently depending on how many frames
    share the call and where the frame sits in it; summing each filter's band in one fixed
    order instead makes a frame's features depend on its own samples only, so features
    computed a few frames at a time (a growing signal, pieces of a long file) equal those
    computed at once, bit for bit.
    """

    index: np.ndarray  # (n_mels, width) int64: FFT bin of each band position
    weight: np.ndarray  # (n_mels, width) float64: the filter's weight there (0 past its band)

    @classmethod
    def of(cls, layout: FeatureLayout) -> _MelBands:
        key = (layout.sr, layout.n_fft, layout.n_mels)
        if key not in _BANDS:
            mel = mel_filterbank(sr=layout.sr, n_fft=layout.n_fft, n_mels=layout.n_mels, fmin=0.0, fmax=layout.sr / 2)
            nonzero = [np.flatnonzero(row) for row in mel]
            lo = np.array([nz[0] if nz.size else 0 for nz in nonzero], dtype=np.int64)
            width = max(int(nz[-1] - nz[0] + 1) if nz.size else 1 for nz in nonzero)
            index = np.minimum(lo[:, None] + np.arange(width)[None, :], mel.shape[1] - 1)
            weight = np.where(
                index - lo[:, None] == np.arange(width)[None, :], mel[np.arange(len(mel))[:, None], index], 0
            )
            _BANDS[key] = cls(index=index, weight=weight.astype(np.float64))
        return _BANDS[key]

    def apply(self, power: np.ndarray) -> np.ndarray:
        """Mel power of each frame, ``power @ mel.T``: (frames, 1 + n_fft // 2) -> (frames, n_mels), float32."""
        out = np.empty((power.shape[0], self.index.shape[0]), np.float32)
        for a in range(0, power.shape[0], 256):  # (frames, n_mels, width) float64 temporaries, 256 frames at a time
            # each filter's band summed on its own (numpy's pairwise sum of a contiguous row): the
            # same order for every frame, however many frames share the call
            out[a : a + 256] = (power[a : a + 256, self.index] * self.weight).sum(axis=2)
        return out


_BANDS: dict[tuple[int, int, int], _MelBands] = {}


@checks_arguments
def audio_frame_features(
    audio: np.ndarray,
    *,
    n_frames: int | None = None,
    first_frame: int = 0,
    layout: FeatureLayout = LAYOUT,
    chunk_frames: int = 4096,
) -> np.ndarray:
    """Per-frame audio features ``m_t``: 13 MFCCs and the log mean energy.

    Parameters
    ----------
    audio : np.ndarray, shape (samples,)
        Mono audio at ``layout.sr`` Hz (float, nominally in [-1, 1]).
    n_frames : int, optional
        Frames to compute; default :func:`n_audio_frames` of the audio.
        Windows reaching past either end of the audio see zeros.
    first_frame : int
        The first frame to compute (frames ``first_frame .. first_frame + n_frames - 1``);
        a frame's features depend on its own window only, so computing a signal's frames
        in pieces gives the features of computing them at once, bit for bit.
    layout : FeatureLayout
    chunk_frames : int
        Frames per chunk, bounding memory (a chunk holds ``chunk_frames * n_fft`` floats).

    Returns
    -------
    np.ndarray, shape (n_frames, 14), float32
        Columns 0..12 are MFCCs (DCT-II, orthonormal, of the log-power mel
        spectrum in dB), column 13 is ``log(mean(w * x**2) / mean(w) + 1e-10)``
        over the Hann window ``w`` of the frame.
    """
    import scipy.fft  # kept local: the layout is usable without it

    audio = np.asarray(audio, dtype=np.float32)
    if audio.ndim != 1:
        raise ConfigError(f"audio must be mono, shape (samples,), got {audio.shape}")
    if n_frames is None:
        n_frames = n_audio_frames(len(audio), sr=layout.sr, fps=layout.fps) - first_frame
    n_fft = layout.n_fft
    half = n_fft // 2
    centres = frame_centres(n_frames, sr=layout.sr, fps=layout.fps, first=first_frame)
    window = np.hanning(n_fft + 1)[:-1].astype(np.float32)  # periodic Hann
    bands = _MelBands.of(layout)
    out = np.empty((n_frames, layout.frame_dim), dtype=np.float32)
    offsets = np.arange(-half, n_fft - half, dtype=np.int64)
    n = len(audio)
    for a in range(0, n_frames, chunk_frames):
        b = min(n_frames, a + chunk_frames)
        # gather each window from the audio itself (zeros outside it): memory stays per chunk
        idx = centres[a:b, None] + offsets[None, :]
        inside = (idx >= 0) & (idx < n)
        frames = np.where(inside, audio[np.clip(idx, 0, max(n - 1, 0))] if n else 0.0, 0.0).astype(np.float32)
        spec = scipy.fft.rfft(frames * window, axis=1)  # complex64 for float32 input
        power = spec.real**2 + spec.imag**2
        # power in dB (floor 1e-10, reference 1) and its orthonormal DCT-II: librosa's
        # power_to_db and mfcc with their defaults, operation for operation
        mel_db = 10.0 * np.log10(np.maximum(1e-10, bands.apply(power)))
        out[a:b, : layout.n_mfcc] = scipy.fft.dct(mel_db, type=2, norm="ortho", axis=1)[:, : layout.n_mfcc]
        energy = (frames**2 * window).sum(axis=1, dtype=np.float64) / window.sum(dtype=np.float64)
        out[a:b, layout.n_mfcc] = np.log(energy + 1e-10)
    return out


def _stack(x: np.ndarray, offsets: tuple[int, ...]) -> np.ndarray:
    """``[x_{t+o} for o in offsets]`` per frame, with the last frame repeated past the end."""
    n = x.shape[0]
    idx = np.minimum(np.arange(n)[:, None] + np.asarray(offsets)[None, :], n - 1)
    return x[idx].reshape(n, -1)


@checks_arguments
def stack_audio_features(m: np.ndarray, *, layout: FeatureLayout = LAYOUT) -> np.ndarray:
    """Audio features ``f_t = [m_t, m_{t+2}, ..., m_{t+14}]``.

    Parameters
    ----------
    m : np.ndarray, shape (frames, 14)
        Per-frame audio features from :func:`audio_frame_features`.

    Returns
    -------
    np.ndarray, shape (frames, 112), float32
        Past the last frame the last ``m`` is repeated (padding); see :func:`valid_starts`.
    """
    if m.ndim != 2 or m.shape[1] != layout.frame_dim:
        raise ConfigError(f"per-frame audio features must have shape (frames, {layout.frame_dim}), got {m.shape}")
    return _stack(m, layout.audio_offsets).astype(np.float32, copy=False)


@checks_arguments
def pose_features(positions: np.ndarray, *, layout: FeatureLayout = LAYOUT) -> np.ndarray:
    """Pose features ``p_t``: the 8 feature joints at ``t, t+2, t+4, t+6``.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Pelvis-relative positions, metres, at 15 fps.

    Returns
    -------
    np.ndarray, shape (frames, 96), float32
        Ordered offset-major: ``[offset][joint][xyz]``. Past the end the last frame repeats.
    """
    if positions.ndim != 3 or positions.shape[1:] != (layout.n_joints, 3):
        raise ConfigError(f"positions must have shape (frames, {layout.n_joints}, 3), got {positions.shape}")
    idx = [JOINT_NAMES.index(j) for j in layout.pose_joints]
    joints = positions[:, idx].reshape(positions.shape[0], -1)
    return _stack(joints, layout.pose_offsets).astype(np.float32, copy=False)


@checks_arguments
def cgan_audio_features(m: np.ndarray) -> np.ndarray:
    """The cGAN's audio input: ``m_t`` and its time derivative (central differences, per frame).

    Parameters
    ----------
    m : np.ndarray, shape (frames, 14)

    Returns
    -------
    np.ndarray, shape (frames, 28), float32
    """
    if m.shape[0] < 2:
        d = np.zeros_like(m)
    else:
        d = np.gradient(m, axis=0)
    return np.concatenate([m, d], axis=1).astype(np.float32)


@checks_arguments
def valid_starts(n_frames: int, *, layout: FeatureLayout = LAYOUT) -> np.ndarray:
    """Frames whose audio and pose features need no padding, shape (n_frames,), bool.

    Frame ``t`` is valid iff ``t + max(lookahead) < n_frames``; only valid frames
    may start a segment.
    """
    look = max(layout.audio_lookahead, layout.pose_lookahead)
    return np.arange(n_frames) + look < n_frames


@dataclass
class ZScore:
    """Per-dimension z-scoring statistics.

    Parameters
    ----------
    mean, std : np.ndarray, shape (dims,), float32
        ``std`` is floored at ``1e-6`` so constant dimensions map to 0.
    """

    mean: np.ndarray
    std: np.ndarray = field()

    @classmethod
    def fit(cls, x: np.ndarray, *, floor: float = 1e-6) -> ZScore:
        """Statistics of ``x`` of shape (..., dims), accumulated in float64."""
        x2 = np.asarray(x).reshape(-1, np.asarray(x).shape[-1])
        mean = x2.mean(axis=0, dtype=np.float64)
        std = x2.std(axis=0, dtype=np.float64)
        return cls(mean.astype(np.float32), np.maximum(std, floor).astype(np.float32))

    def apply(self, x: np.ndarray) -> np.ndarray:
        """``(x - mean) / std``, float32, same shape as ``x``."""
        return ((np.asarray(x, dtype=np.float32) - self.mean) / self.std).astype(np.float32, copy=False)

    def invert(self, z: np.ndarray) -> np.ndarray:
        """``z * std + mean``, float32."""
        return (np.asarray(z, dtype=np.float32) * self.std + self.mean).astype(np.float32, copy=False)
