"""The generated demo speaker's speech: a plan of phrases and syllables, and its audio at 16 kHz.

Phrases of 1.2-4 s separated by pauses; syllables of an optional onset
consonant, a vowel and an optional coda, about one in three stressed; a
glottal-like pulse train shaped by formant resonators for vowels, band-passed
noise for fricatives and bursts. Also the random draws the gesture plan and
the body share. Part of :mod:`gesturekit.datasets.synthetic`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy import signal
from scipy.ndimage import gaussian_filter1d

from ..motion import AUDIO_SR

# ---------------------------------------------------------------------------------------------
# speech plan
# ---------------------------------------------------------------------------------------------

# vowel formants (F1, F2, F3) in Hz of an adult male voice; the last class is a nasal murmur
_VOWEL_FORMANTS = np.array(
    [
        (730, 1090, 2440),  # a
        (270, 2290, 3010),  # i
        (300, 870, 2240),  # u
        (530, 1840, 2480),  # e
        (570, 840, 2410),  # o
        (500, 1500, 2500),  # schwa
        (260, 1100, 2300),  # nasal murmur (m, n)
    ],
    dtype=np.float64,
)
_FORMANT_BANDWIDTHS = np.array([80.0, 110.0, 160.0])
_NASAL = len(_VOWEL_FORMANTS) - 1
_N_VOWELS = _NASAL

# noise classes: band edges in Hz and level relative to the syllable's vowel
_NOISE_BANDS = np.array(
    [
        (3800, 7600),  # s
        (1800, 5000),  # sh
        (1000, 7600),  # f
        (500, 3500),  # h
        (400, 1600),  # p burst
        (3000, 6500),  # t burst
        (1400, 3200),  # k burst
    ],
    dtype=np.float64,
)
_FRICATIVES = (0, 1, 2, 3)
_FRICATIVE_LEVEL = np.array([0.22, 0.2, 0.08, 0.1])
_BURST_LEVEL = 0.35
# syllable onsets and codas: probabilities and duration ranges (s) of each kind
_ONSET_P = np.array([0.45, 0.25, 0.15, 0.15])  # fricative, plosive, nasal, none
_ONSET_SECONDS = ((0.05, 0.09), (0.04, 0.075), (0.04, 0.07), (0.0, 0.0))
_CODA_P = np.array([0.2, 0.12, 0.68])  # fricative, nasal, none
_CODA_SECONDS = ((0.045, 0.08), (0.035, 0.06), (0.0, 0.0))


@dataclass
class Speech:
    """Syllables, their acoustic segments and phrases of one take (times in seconds)."""

    phrases: np.ndarray  # (P, 2)
    arousal: np.ndarray  # (P,) in [0, 1]
    syl_start: np.ndarray  # (S,)
    syl_nucleus: np.ndarray  # (S,)
    syl_end: np.ndarray  # (S,)
    syl_stressed: np.ndarray  # (S,) bool
    syl_phrase: np.ndarray  # (S,) phrase index
    syl_emphasis: np.ndarray  # (S,) loudness of the syllable relative to its phrase and stress (about 1)
    voiced: np.ndarray  # (V, 6): start, stop, class, amp, attack, release
    noise: np.ndarray  # (N, 6): start, stop, class, amp, attack, release
    f0_base: float


def plan_speech(rng: np.random.Generator, duration: float) -> Speech:
    """Phrases, syllables and their segments; a plain loop over syllables (a few per second)."""
    phrases: list[tuple[float, float]] = []
    arousal: list[float] = []
    syl: list[tuple[float, float, float, bool, int, float]] = []  # (start, nucleus, end, stressed, phrase, emphasis)
    voiced: list[tuple[float, ...]] = []
    noise: list[tuple[float, ...]] = []
    t = rng.uniform(0.25, 0.6)
    while t < duration - 0.8:
        p = len(phrases)
        target = rng.uniform(1.2, 4.0)
        a = float(rng.beta(2.0, 2.0))
        tempo = 1.0 + 0.15 * (a - 0.5) + rng.normal(0.0, 0.05)  # aroused speech is a little faster
        level = 0.06 * 10 ** ((a - 0.5) * 16.0 / 20.0)  # +-8 dB with arousal
        stop_by = duration - 0.25
        durs: list[float] = []
        stress: list[bool] = []
        acc = 0.0
        while acc < target:
            prev_stressed = bool(stress) and stress[-1]
            s = rng.random() < (0.06 if prev_stressed else 0.42)
            d = math.exp(rng.normal(math.log(0.185), 0.22)) / tempo
            if s:
                d *= 1.25
            d = min(max(d, 0.11), 0.42)
            if t + acc + d > stop_by:
                break
            durs.append(d)
            stress.append(s)
            acc += d
        if len(durs) < 2:
            break
        if not any(stress):
            stress[-2 if len(stress) > 2 else 0] = True  # every phrase carries a nuclear accent
        durs[-1] = min(durs[-1] * 1.3, 0.42)  # phrase-final lengthening
        start = t
        for d, s in zip(durs, stress):
            nucleus, emphasis = _plan_syllable(rng, t, d, s, level, voiced, noise)
            syl.append((t, nucleus, t + d, s, p, emphasis))
            t += d
        phrases.append((start, t))
        arousal.append(a)
        t += rng.uniform(0.2, 1.2)
    syl_arr = np.array(syl, dtype=np.float64).reshape(-1, 6)
    return Speech(
        phrases=np.array(phrases, dtype=np.float64).reshape(-1, 2),
        arousal=np.array(arousal, dtype=np.float64),
        syl_start=syl_arr[:, 0].copy(),
        syl_nucleus=syl_arr[:, 1].copy(),
        syl_end=syl_arr[:, 2].copy(),
        syl_stressed=syl_arr[:, 3].astype(bool),
        syl_phrase=syl_arr[:, 4].astype(np.int64),
        syl_emphasis=syl_arr[:, 5].copy(),
        voiced=np.array(voiced, dtype=np.float64).reshape(-1, 6),
        noise=np.array(noise, dtype=np.float64).reshape(-1, 6),
        f0_base=115.0 * math.exp(rng.uniform(-0.08, 0.08)),
    )


def _plan_syllable(rng, t, d, stressed, level, voiced, noise) -> tuple[float, float]:
    """Append one syllable's segments; return the vowel onset time and the syllable's emphasis."""
    emphasis = math.exp(rng.normal(0.0, 0.15))
    amp = level * (1.8 if stressed else 1.0) * emphasis
    onset = draw(rng, _ONSET_P)  # fricative, plosive, nasal, none
    coda = draw(rng, _CODA_P)  # fricative, nasal, none
    c1 = rng.uniform(*_ONSET_SECONDS[onset])
    c2 = rng.uniform(*_CODA_SECONDS[coda])
    min_vowel = 0.07
    if d - c1 - c2 < min_vowel:
        c2, coda = 0.0, 2
    if d - c1 < min_vowel:
        c1 = max(0.0, d - min_vowel)
    v0, v1 = t + c1, t + d - c2
    if onset == 0:
        k = int(rng.integers(len(_FRICATIVES)))
        noise.append((t, v0 + 0.01, k, amp * _FRICATIVE_LEVEL[k], 0.015, 0.015))
    elif onset == 1 and c1 > 0.02:
        burst = min(0.018, 0.4 * c1)
        k = int(rng.integers(4, 7))
        noise.append((v0 - burst, v0 + 0.004, k, amp * _BURST_LEVEL, 0.002, 0.008))
    elif onset == 2 and c1 > 0.0:
        voiced.append((t, v0 + 0.012, _NASAL, amp * 0.3, 0.015, 0.015))
    vowel = int(rng.integers(_N_VOWELS))
    voiced.append((v0, v1, vowel, amp, rng.uniform(0.012, 0.025), rng.uniform(0.03, 0.05)))
    if coda == 0:
        k = int(rng.integers(len(_FRICATIVES)))
        noise.append((v1 - 0.01, t + d, k, amp * _FRICATIVE_LEVEL[k], 0.015, 0.02))
    elif coda == 1:
        voiced.append((v1 - 0.012, t + d, _NASAL, amp * 0.3, 0.015, 0.02))
    return v0, emphasis


# ---------------------------------------------------------------------------------------------
# audio
# ---------------------------------------------------------------------------------------------


def _resonator_sos(freqs: np.ndarray, sr: int) -> np.ndarray:
    """Cascade of two-pole resonators with unit gain at 0 Hz, as second-order sections."""
    sos = []
    for f, bw in zip(freqs, _FORMANT_BANDWIDTHS):
        r = math.exp(-math.pi * bw / sr)
        c = -2.0 * r * math.cos(2.0 * math.pi * f / sr)
        sos.append((1.0 + c + r * r, 0.0, 0.0, 1.0, c, r * r))
    return np.array(sos)


@functools.cache
def _filters(sr: int) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """Voiced and noise filters, each scaled to unit output RMS for its reference input."""
    n = sr // 4
    t = np.arange(n) / sr
    saw = 1.0 - 2.0 * ((120.0 * t) % 1.0)
    voiced = []
    for formants in _VOWEL_FORMANTS:
        sos = _resonator_sos(formants, sr)
        rms = np.sqrt(np.mean(signal.sosfilt(sos, saw)[n // 2 :] ** 2))
        sos = sos.copy()
        sos[0, :3] /= rms
        voiced.append(sos)
    impulse = np.zeros(4096)
    impulse[0] = 1.0
    noise = []
    for lo, hi in _NOISE_BANDS:
        sos = signal.butter(2, [lo, min(hi, 0.48 * sr)], btype="bandpass", fs=sr, output="sos")
        gain = np.sqrt(np.sum(signal.sosfilt(sos, impulse) ** 2))  # RMS gain for white noise
        sos = sos.copy()
        sos[0, :3] /= gain
        noise.append(sos)
    return tuple(voiced), tuple(noise)


def _smoothstep(u: np.ndarray) -> np.ndarray:
    """``3u^2 - 2u^3`` of ``u`` clipped to [0, 1]: a smooth 0-to-1 ramp."""
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def _render_segments(segs: np.ndarray, sos_by_class, n: int, sr: int, source):
    """Filter an enveloped source within each segment, class by class.

    Segments of one class are gathered into one buffer (each followed by 20 ms
    of zeros for the filter to ring out), filtered in one call, and returned as
    (sample indices, values) to be added into the output.

    Parameters
    ----------
    segs : np.ndarray, shape (segments, 6)
        start (s), stop (s), class, amplitude, attack (s), release (s).
    sos_by_class : sequence of np.ndarray, shape (sections, 6)
    n : int
        Samples of the output.
    source : callable(indices) -> np.ndarray
        The excitation at the given sample indices, float32.
    """
    pad = int(0.02 * sr)
    out_idx, out_val = [], []
    for k, sos in enumerate(sos_by_class):
        s = segs[segs[:, 2] == k]
        if len(s) == 0:
            continue
        start = np.round(s[:, 0] * sr).astype(np.int64)
        length = np.maximum(np.round(s[:, 1] * sr).astype(np.int64) - start, 1)
        total = length + pad
        seg = np.repeat(np.arange(len(s), dtype=np.int32), total)
        tau = np.arange(total.sum(), dtype=np.int64) - np.repeat(np.cumsum(total) - total, total)
        idx = start[seg] + tau
        keep = (idx >= 0) & (idx < n)
        if not keep.all():
            seg, tau, idx = seg[keep], tau[keep], idx[keep]
        # per-segment constants in float32, gathered once per sample
        amp = s[:, 3].astype(np.float32)[seg]
        inv_att = (1.0 / (s[:, 4] * sr)).astype(np.float32)[seg]
        inv_rel = (1.0 / (s[:, 5] * sr)).astype(np.float32)[seg]
        lin = length.astype(np.float32)[seg]
        tau_f = tau.astype(np.float32)
        env = (
            amp
            * _smoothstep(tau_f * inv_att)
            * _smoothstep((lin - tau_f) * inv_rel)  # 0 in the padding
            * (1.0 - 0.25 * np.minimum(tau_f / lin, 1.0))
        )
        x = source(idx) * env
        out_idx.append(idx)
        out_val.append(signal.sosfilt(sos.astype(np.float32), x))
    return out_idx, out_val


def render_audio(speech: Speech, rng: np.random.Generator, n_samples: int) -> np.ndarray:
    """Synthesise the take's audio, shape (n_samples,), float32 at 16 kHz."""
    sr = AUDIO_SR
    voiced_sos, noise_sos = _filters(sr)
    # pitch contour at a 5 ms control rate: declination over each phrase, accents on stresses
    hop = 80
    n_ctrl = n_samples // hop + 2
    tc = np.arange(n_ctrl) * (hop / sr)
    log_f0 = np.full(n_ctrl, math.log(speech.f0_base))
    if len(speech.phrases):
        p = np.clip(np.searchsorted(speech.phrases[:, 0], tc, side="right") - 1, 0, len(speech.phrases) - 1)
        ps, pe = speech.phrases[p, 0], speech.phrases[p, 1]
        pos = np.clip((tc - ps) / (pe - ps), 0.0, 1.0)
        log_f0 += (0.08 + 0.1 * speech.arousal[p]) - 0.22 * pos  # start high, decline by about 20 %
        stressed = speech.syl_stressed
        acc_t = speech.syl_nucleus[stressed] + 0.4 * (speech.syl_end[stressed] - speech.syl_nucleus[stressed])
        acc_h = (0.1 + 0.12 * speech.arousal[speech.syl_phrase[stressed]]) * np.exp(
            rng.normal(0.0, 0.2, size=len(acc_t))
        )
        if len(acc_t):
            j = np.searchsorted(acc_t, tc)
            for nb in (j - 1, j):  # accents are far apart: the two nearest suffice
                nb = np.clip(nb, 0, len(acc_t) - 1)
                log_f0 += acc_h[nb] * np.exp(-0.5 * ((tc - acc_t[nb]) / 0.07) ** 2)
    log_f0 += smooth_noise(rng, n_ctrl, 8.0)[:, 0] * 0.015  # slow pitch wobble
    # phase of the glottal cycle, accumulated at the control rate and interpolated: exact
    # integration of the piecewise-linear pitch, without a per-sample cumulative sum
    f0 = np.exp(log_f0)
    cycles = np.concatenate([[0.0], np.cumsum(0.5 * (f0[1:] + f0[:-1]) * (hop / sr))])
    ctrl_pos = np.arange(n_ctrl, dtype=np.float64)

    def glottal(idx: np.ndarray) -> np.ndarray:
        # a falling ramp per glottal period: a source falling at about -6 dB per octave
        phase = np.interp(idx / hop, ctrl_pos, cycles)
        return (1.0 - 2.0 * (phase % 1.0)).astype(np.float32)

    def noise(idx: np.ndarray) -> np.ndarray:
        return rng.standard_normal(len(idx), dtype=np.float32)

    vi, vv = _render_segments(speech.voiced, voiced_sos, n_samples, sr, glottal)
    ni, nv = _render_segments(speech.noise, noise_sos, n_samples, sr, noise)
    # room noise: faint, slightly low-passed noise everywhere, about 50 dB below a vowel
    room = rng.standard_normal(n_samples + 1, dtype=np.float32)
    out = (room[1:] + room[:-1]) * np.float32(1.2e-4)
    if vi or ni:
        out += np.bincount(np.concatenate(vi + ni), weights=np.concatenate(vv + nv), minlength=n_samples).astype(
            np.float32
        )
    return np.clip(out, -1.0, 1.0)


# ---------------------------------------------------------------------------------------------
# random draws shared by the speech, the gesture plan and the body
# ---------------------------------------------------------------------------------------------


def draw(rng: np.random.Generator, p: np.ndarray) -> int:
    """An index drawn with probabilities ``p`` (cheaper than ``Generator.choice`` for one draw)."""
    return int(min(np.searchsorted(np.cumsum(p), rng.random() * p.sum(), side="right"), len(p) - 1))


def smooth_noise(rng, n: int, sigma_frames: float, dims: int = 1) -> np.ndarray:
    """Gaussian-smoothed white noise with unit standard deviation, shape (n, dims)."""
    x = gaussian_filter1d(rng.standard_normal((n, dims)), sigma_frames, axis=0, mode="reflect")
    return x * math.sqrt(2.0 * math.sqrt(math.pi) * sigma_frames)
