"""The generated demo speaker: speech-like audio with gestures that follow it.

A deterministic stand-in for a motion-capture dataset, so that gesturekit can
build its default matching database without downloading anything. Nothing here
is recorded: every take says so in its ``sources``
(``{"generator": "gesturekit.datasets.synthetic", "seed": ..., "label": DEMO_LABEL}``).

How a take is made
------------------
1. **Speech plan.** Phrases of 1.2-4 s separated by pauses of 0.2-1.2 s. A
   phrase is a run of syllables (about 4-5 per second of speech, 0.11-0.42 s
   each); a syllable is an optional onset consonant (fricative, plosive or
   nasal), a vowel and an optional coda. About one syllable in three is
   stressed: longer, louder and carrying a pitch accent. Each phrase has an
   *arousal* in [0, 1] that makes it louder, higher in pitch and its gestures
   larger and faster.
2. **Audio** (16 kHz). A glottal-like pulse train whose pitch declines over a
   phrase and rises on stressed syllables, shaped by three formant resonators
   per vowel; band-passed noise for fricatives and plosive bursts; silence
   with faint room noise in pauses and plosive closures.
3. **Gesture plan.** Most phrases (all aroused ones) carry a gesture phrase:
   a preparation, then strokes (louder syllable, larger stroke) that *end*
   on the vowel onset of a stressed syllable, where the hand stops and turns
   (a minimum of its velocity: the motion beat that AI Choreographer and
   BEAT measure), so that the stroke's fast part precedes the stress. The
   gesture phases keep to the syllables: a stroke starts on the vowel onset
   of a syllable before the stress, and the hand rebounds about as briskly
   to where the next stroke starts, arriving on a later vowel onset, and
   holds there until that stroke (a stroke too soon for a rebound goes
   straight back instead); the beats of a gesture phrase go much the same
   way. After the last stroke the hand rebounds and holds until the phrase
   ends; in a pause of 0.6 s or more comes an unhurried retraction to the
   rest pose (hands low beside the hips); through shorter pauses the hands
   stay up. A gesture phrase uses both hands
   symmetrically, both hands differently, or one hand, at a low, middle or
   high height, narrow or wide, slow or fast, with a hand shape (open,
   relaxed, pointing, fist, pinch). Wrist moves peak at 2.3 m/s at most.
4. **Motion** (15 fps). Keyposes (wrist target, elbow swivel, forearm roll,
   wrist angles, finger curls and spread) are joined by minimum-jerk
   interpolation, given a little drift, turned into joint rotations by
   two-bone inverse kinematics, and posed by forward kinematics on a fixed
   rest skeleton, so bone lengths are exactly constant. The torso sways
   slowly, leans slightly and the head nods on stressed syllables.

All randomness comes from :class:`numpy.random.Generator` streams spawned from
the seed, so a seed gives byte-identical audio and motion.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import signal
from scipy.ndimage import gaussian_filter1d

from ..errors import ConfigError
from ..features import n_audio_frames
from ..motion import AUDIO_SR, Motion, Take
from ..skeleton import FINGERS, FPS, N_JOINTS, PARENTS, joint_index

__all__ = ["DEMO_LABEL", "GENERATOR", "DemoEvents", "generate_demo_take", "generate_demo_takes"]

#: How every generated take describes itself in ``Take.sources["label"]``.
DEMO_LABEL = "generated demo speaker (synthetic, not motion capture)"

#: ``Take.sources["generator"]`` of every generated take.
GENERATOR = "gesturekit.datasets.synthetic"

# a remainder shorter than this is added to the last take rather than becoming a take of its own
_MIN_TAKE_SECONDS = 10.0
_MAX_TAKE_SECONDS = 3600.0


@dataclass(frozen=True)
class DemoEvents:
    """Ground truth of one generated take: what was said and gestured, and when.

    All times are in seconds from the start of the take.

    Attributes
    ----------
    duration : float
        Length of the take, seconds.
    syllable_onsets, nucleus_onsets, syllable_ends : np.ndarray, shape (syllables,), float64
        Start of each syllable (its onset consonant, if any), start of its
        vowel (where its energy rises), and its end.
    stressed : np.ndarray, shape (syllables,), bool
        Whether the syllable carries stress (louder, longer, pitch accent).
    phrases : np.ndarray, shape (phrases, 2), float64
        Start and end of each spoken phrase.
    pauses : np.ndarray, shape (pauses, 2), float64
        Silent stretches: before the first phrase, between phrases, after the last.
    stroke_times : np.ndarray, shape (strokes,), float64
        End of each gesture stroke: the hand stops and turns (its velocity is
        at a minimum), after the stroke's fast part.
    stroke_stress_onsets : np.ndarray, shape (strokes,), float64
        Vowel onset of the stressed syllable each stroke goes with; the stroke
        ends on it, ``|stroke_times - stroke_stress_onsets| <= 0.02`` s.
    stroke_hands : tuple of str
        ``"left"``, ``"right"`` or ``"both"`` per stroke.
    gesture_phrases : np.ndarray, shape (gesture phrases, 2), float64
        Start of the preparation and end of the last stroke (before rebound,
        hold and retraction) of each gesture phrase.
    gesture_modes : tuple of str
        ``"symmetric"``, ``"asymmetric"``, ``"left"`` or ``"right"`` per gesture phrase.
    """

    duration: float
    syllable_onsets: np.ndarray
    nucleus_onsets: np.ndarray
    syllable_ends: np.ndarray
    stressed: np.ndarray
    phrases: np.ndarray
    pauses: np.ndarray
    stroke_times: np.ndarray
    stroke_stress_onsets: np.ndarray
    stroke_hands: tuple[str, ...]
    gesture_phrases: np.ndarray
    gesture_modes: tuple[str, ...]

    @property
    def stress_onsets(self) -> np.ndarray:
        """Vowel onsets of the stressed syllables, shape (stressed syllables,), seconds."""
        return self.nucleus_onsets[self.stressed]


# ---------------------------------------------------------------------------------------------
# public API
# ---------------------------------------------------------------------------------------------


def generate_demo_takes(
    *,
    minutes: float = 20.0,
    take_seconds: float = 120.0,
    seed: int = 0,
    progress: Callable[[float, float], None] | None = None,
) -> list[Take]:
    """Generate the demo speaker: ``minutes`` of speech and gesture, cut into takes.

    Parameters
    ----------
    minutes : float
        Total duration, minutes (> 0).
    take_seconds : float
        Duration of each take, seconds (10-3600). The last take holds the
        remainder; a remainder under 10 s is added to the take before it.
    seed : int
        Non-negative seed; take ``k`` is :func:`generate_demo_take` with a seed
        derived from ``(seed, k)``.
    progress : callable(done_seconds, total_seconds), optional
        Called before the first take and after each take.

    Returns
    -------
    list of Take
        Motion at 15 fps, shape (frames, 55, 3), float32 metres; audio float32
        mono at 16 kHz with ``frames = floor(samples * 15 / 16000)``. Names are
        ``demo{seed}_{k:03d}``; ``sources`` holds ``generator``, ``seed`` (this
        call's seed), ``label`` (:data:`DEMO_LABEL`), ``take_index``,
        ``take_seed`` and ``seconds``.
    """
    seed = _check_seed(seed)
    if not (isinstance(minutes, (int, float)) and math.isfinite(minutes) and minutes > 0):
        raise ConfigError(f"minutes must be a positive number, got {minutes!r}")
    if not (
        isinstance(take_seconds, (int, float))
        and math.isfinite(take_seconds)
        and _MIN_TAKE_SECONDS <= take_seconds <= _MAX_TAKE_SECONDS
    ):
        raise ConfigError(
            f"take_seconds must be between {_MIN_TAKE_SECONDS:g} and {_MAX_TAKE_SECONDS:g}, got {take_seconds!r}"
        )
    if progress is not None and not callable(progress):
        raise ConfigError("progress must be a callable(done_seconds, total_seconds) or None")
    total = float(minutes) * 60.0
    n_full = int(math.floor(total / take_seconds + 1e-9))
    lengths = [float(take_seconds)] * n_full
    rest = total - n_full * take_seconds
    if rest > 1e-6:
        if rest < _MIN_TAKE_SECONDS and lengths:
            lengths[-1] += rest
        else:
            lengths.append(rest)
    take_seeds = np.random.SeedSequence(seed).generate_state(len(lengths), dtype=np.uint32)
    takes: list[Take] = []
    done = 0.0
    if progress is not None:
        progress(0.0, total)
    for k, (secs, tseed) in enumerate(zip(lengths, take_seeds)):
        take, _ = generate_demo_take(seconds=secs, seed=int(tseed), name=f"demo{seed}_{k:03d}")
        sources = {
            "generator": GENERATOR,
            "seed": seed,
            "label": DEMO_LABEL,
            "take_index": k,
            "take_seed": int(tseed),
            "seconds": secs,
        }
        takes.append(Take(take.name, take.motion, take.audio, sources))
        done += secs
        if progress is not None:
            progress(min(done, total), total)
    return takes


def generate_demo_take(*, seconds: float, seed: int, name: str) -> tuple[Take, DemoEvents]:
    """Generate one take of the demo speaker and its ground-truth events.

    Parameters
    ----------
    seconds : float
        Duration, seconds (2-3600). The audio has ``round(seconds * 16000)``
        samples and the motion ``floor(samples * 15 / 16000)`` frames.
    seed : int
        Non-negative seed; the same seed gives byte-identical audio and positions.
    name : str
        Name of the take.

    Returns
    -------
    take : Take
        Motion at 15 fps (positions (frames, 55, 3) float32, metres,
        pelvis-relative, Y up, facing +Z, left is +X) and audio (samples,)
        float32 mono at 16 kHz in [-1, 1]. ``sources`` is
        ``{"generator", "seed", "label", "seconds"}``.
    events : DemoEvents
        Syllables, stress, phrases, pauses and gesture strokes of the take.
    """
    seed = _check_seed(seed)
    if not (isinstance(seconds, (int, float)) and math.isfinite(seconds) and 2.0 <= seconds <= _MAX_TAKE_SECONDS):
        raise ConfigError(f"seconds must be between 2 and {_MAX_TAKE_SECONDS:g}, got {seconds!r}")
    n_samples = int(round(float(seconds) * AUDIO_SR))
    n_frames = n_audio_frames(n_samples, sr=AUDIO_SR, fps=FPS)
    duration = n_samples / AUDIO_SR
    speech_rng, audio_rng, gesture_rng, motion_rng = (
        np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4)
    )
    speech = _plan_speech(speech_rng, duration)
    audio = _render_audio(speech, audio_rng, n_samples)
    plan = _plan_gestures(speech, gesture_rng, duration)
    positions = _render_motion(plan, speech, motion_rng, n_frames)
    events = DemoEvents(
        duration=duration,
        syllable_onsets=speech.syl_start,
        nucleus_onsets=speech.syl_nucleus,
        syllable_ends=speech.syl_end,
        stressed=speech.syl_stressed,
        phrases=speech.phrases,
        pauses=_pauses(speech.phrases, duration),
        stroke_times=plan.stroke_times,
        stroke_stress_onsets=plan.stroke_stress,
        stroke_hands=plan.stroke_hands,
        gesture_phrases=plan.gesture_phrases,
        gesture_modes=plan.gesture_modes,
    )
    sources = {"generator": GENERATOR, "seed": seed, "label": DEMO_LABEL, "seconds": float(seconds)}
    return Take(name, Motion(positions, float(FPS)), audio, sources), events


def _check_seed(seed) -> int:
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def _pauses(phrases: np.ndarray, duration: float) -> np.ndarray:
    """Gaps before, between and after phrases, shape (pauses, 2)."""
    if len(phrases) == 0:
        return np.array([[0.0, duration]])
    starts = np.concatenate([[0.0], phrases[:, 1]])
    stops = np.concatenate([phrases[:, 0], [duration]])
    keep = stops - starts > 1e-6
    return np.stack([starts[keep], stops[keep]], axis=1)


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
class _Speech:
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


def _plan_speech(rng: np.random.Generator, duration: float) -> _Speech:
    """Phrases, syllables and their segments; a plain loop over syllables (a few per second)."""
    phrases, arousal = [], []
    syl = []  # (start, nucleus, end, stressed, phrase, emphasis)
    voiced, noise = [], []
    t = rng.uniform(0.25, 0.6)
    while t < duration - 0.8:
        p = len(phrases)
        target = rng.uniform(1.2, 4.0)
        a = float(rng.beta(2.0, 2.0))
        tempo = 1.0 + 0.15 * (a - 0.5) + rng.normal(0.0, 0.05)  # aroused speech is a little faster
        level = 0.06 * 10 ** ((a - 0.5) * 16.0 / 20.0)  # +-8 dB with arousal
        stop_by = duration - 0.25
        durs, stress = [], []
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
    return _Speech(
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
    onset = _draw(rng, _ONSET_P)  # fricative, plosive, nasal, none
    coda = _draw(rng, _CODA_P)  # fricative, nasal, none
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


@functools.lru_cache(maxsize=None)
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


def _render_audio(speech: _Speech, rng: np.random.Generator, n_samples: int) -> np.ndarray:
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
    log_f0 += _smooth_noise(rng, n_ctrl, 8.0)[:, 0] * 0.015  # slow pitch wobble
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
# skeleton: rest offsets and forward kinematics
# ---------------------------------------------------------------------------------------------

_UPPER_ARM = 0.30  # shoulder to elbow, m
_FOREARM = 0.26  # elbow to wrist, m
_REACH = 0.985 * (_UPPER_ARM + _FOREARM)  # the elbow never quite straightens
# body offsets from the parent joint in the rest pose, metres (T-pose: arms along +-X, palms down)
_BODY_OFFSETS = {
    "spine_mid": (0.0, 0.11, -0.02),  # from the pelvis (implicit root)
    "chest": (0.0, 0.12, 0.0),
    "upper_chest": (0.0, 0.12, 0.0),
    "neck": (0.0, 0.14, -0.01),
    "neck_upper": (0.0, 0.05, 0.01),
    "head": (0.0, 0.05, 0.01),
    "head_top": (0.0, 0.14, 0.02),
    "left_collar": (0.03, 0.10, -0.01),
    "left_shoulder": (0.15, 0.0, 0.0),
    "left_elbow": (_UPPER_ARM, 0.0, 0.0),
}
# keyposes keep the wrist within this fraction of the reach; beyond it inverse kinematics
# pulls the wrist in smoothly
_COMFORT = 0.97
# upper_chest and the left shoulder in the upright rest pose, pelvis frame, m
_UPPER_CHEST = np.sum([_BODY_OFFSETS[n] for n in ("spine_mid", "chest", "upper_chest")], axis=0)
_SHOULDER = _UPPER_CHEST + np.sum([_BODY_OFFSETS[n] for n in ("left_collar", "left_shoulder")], axis=0)
# hand of the left side, wrist frame = world frame in the rest pose: fingers +X, thumb +Z, palm -Y
_FINGER_ROOTS = {
    "thumb": (0.028, -0.015, 0.024),
    "index": (0.095, 0.0, 0.026),
    "middle": (0.096, 0.0, 0.004),
    "ring": (0.089, -0.002, -0.016),
    "pinky": (0.081, -0.005, -0.034),
}
_FINGER_DIRS = {
    "thumb": (0.72, -0.2, 0.66),
    "index": (1.0, 0.0, 0.06),
    "middle": (1.0, 0.0, 0.0),
    "ring": (1.0, 0.0, -0.06),
    "pinky": (1.0, 0.0, -0.13),
}
_PHALANGES = {  # root->2, 2->3, 3->tip, metres
    "thumb": (0.040, 0.033, 0.028),
    "index": (0.041, 0.031, 0.025),
    "middle": (0.046, 0.034, 0.026),
    "ring": (0.042, 0.033, 0.025),
    "pinky": (0.034, 0.026, 0.022),
}
# flexion per unit curl of joints 1..3 (radians) and spread angles (per unit spread)
_CURL_ANGLES = {"thumb": (0.5, 0.7, 0.9), "other": (1.3, 1.65, 1.1)}
_SPREAD_ANGLES = {"thumb": 0.3, "index": 0.17, "middle": 0.03, "ring": -0.1, "pinky": -0.24}
_MIRROR = np.diag([-1.0, 1.0, 1.0])


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@functools.lru_cache(maxsize=1)
def _rest_offsets() -> np.ndarray:
    """Offset of every joint from its parent in the rest pose, shape (55, 3), metres."""
    off = np.zeros((N_JOINTS, 3))
    for name, o in _BODY_OFFSETS.items():
        off[joint_index(name)] = o
        if name.startswith("left_"):
            off[joint_index("right_" + name[5:])] = _MIRROR @ np.asarray(o)
    off[joint_index("left_wrist")] = (_FOREARM, 0.0, 0.0)
    off[joint_index("right_wrist")] = (-_FOREARM, 0.0, 0.0)
    for finger in FINGERS:
        d = _unit(_FINGER_DIRS[finger])
        chain = [np.asarray(_FINGER_ROOTS[finger])] + [length * d for length in _PHALANGES[finger]]
        for i, o in enumerate(chain, start=1):
            off[joint_index(f"left_{finger}{i}")] = o
            off[joint_index(f"right_{finger}{i}")] = _MIRROR @ o
    off.setflags(write=False)
    return off


def _axis_angle(axis, angle: np.ndarray) -> np.ndarray:
    """Rotations about fixed unit ``axis`` (3,) by ``angle`` (T,) radians, shape (T, 3, 3)."""
    x, y, z = _unit(axis)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    a = np.asarray(angle, dtype=np.float64)[:, None, None]
    return np.eye(3) + np.sin(a) * k + (1.0 - np.cos(a)) * (k @ k)


def _forward_kinematics(root_pos: np.ndarray, local: list[np.ndarray]) -> np.ndarray:
    """Joint positions from local rotations.

    Parameters
    ----------
    root_pos : np.ndarray, shape (T, 3)
        Position of the root joint (``spine_mid``), metres.
    local : list of 55 np.ndarray, each shape (T, 3, 3)
        Rotation of each joint relative to its parent (the root's is global).

    Returns
    -------
    np.ndarray, shape (T, 55, 3), float64
    """
    off = _rest_offsets()
    glob: list[np.ndarray] = []
    pos = np.empty((len(root_pos), N_JOINTS, 3))
    for j in range(N_JOINTS):
        p = PARENTS[j]
        if p < 0:
            glob.append(local[j])
            pos[:, j] = root_pos
        else:
            glob.append(glob[p] @ local[j])
            pos[:, j] = pos[:, p] + glob[p] @ off[j]
    return pos


# ---------------------------------------------------------------------------------------------
# gesture plan: keyposes per arm
# ---------------------------------------------------------------------------------------------

# keypose of one arm, in the left arm's convention (x is outward from the body axis):
# wrist target x, y, z (m, pelvis frame of an upright torso), elbow swivel, forearm roll
# (+ turns the palm down, - up), wrist flexion, wrist deviation (rad), 5 finger curls (0 open .. 1
# fist, thumb first), finger spread (0..1)
_WRIST = slice(0, 3)
_SWIVEL, _ROLL, _FLEX, _DEV = 3, 4, 5, 6
_CURL = slice(7, 12)
_SPREAD = 12
_POSE_DIM = 13

_HANDSHAPES = np.array(
    [  # curls (thumb, index, middle, ring, pinky), spread
        (0.1, 0.05, 0.05, 0.08, 0.1, 0.9),  # open
        (0.35, 0.3, 0.38, 0.45, 0.5, 0.4),  # relaxed
        (0.6, 0.02, 0.85, 0.9, 0.92, 0.2),  # pointing
        (0.75, 0.9, 0.92, 0.92, 0.9, 0.1),  # fist
        (0.6, 0.55, 0.4, 0.5, 0.55, 0.3),  # pinch
    ]
)
_HANDSHAPE_P = np.array([0.3, 0.3, 0.15, 0.1, 0.15])

_HEIGHTS = ((0.06, 0.2), (0.22, 0.34), (0.38, 0.58))  # low, middle, high wrist height (m)
_HEIGHT_P = np.array([0.38, 0.24, 0.38])
_WIDTHS = ((0.04, 0.13), (0.17, 0.27), (0.33, 0.46))  # narrow, middle, wide (m from the midline)
_WIDTH_P = np.array([0.35, 0.3, 0.35])
_MODES = ("symmetric", "asymmetric", "left", "right")
_MODE_P = np.array([0.4, 0.2, 0.2, 0.2])
_STROKE_KIND_P = np.array([0.5, 0.2, 0.2, 0.1])  # down, out, forward, across
_PALM_ROLLS = (-1.1, -0.5, 0.0, 0.6)  # forearm roll of a gesture: palm up, up-in, in, down (rad)


def _rest_pose(rng: np.random.Generator) -> np.ndarray:
    """Hands low beside the hips, palms inward, fingers relaxed (with a little variation)."""
    p = np.zeros(_POSE_DIM)
    p[_WRIST] = (0.21, -0.08, 0.05) + rng.normal(0.0, 0.012, 3)
    p[_SWIVEL] = 0.1
    p[_ROLL] = rng.normal(-0.1, 0.1)
    p[_FLEX] = 0.1
    p[_CURL] = (0.3, 0.3, 0.38, 0.45, 0.5)
    p[_SPREAD] = 0.3
    return p


def _reachable(pose: np.ndarray) -> np.ndarray:
    """A copy of ``pose`` with the wrist target pulled within comfortable reach of the shoulder."""
    pose = pose.copy()
    rel = pose[_WRIST] - _SHOULDER
    dist = float(np.linalg.norm(rel))
    if dist > _COMFORT * _REACH:
        pose[_WRIST] = _SHOULDER + rel * (_COMFORT * _REACH / dist)
    return pose


_MAX_SPEED = 2.3  # fastest wrist movement of a keypose move, m/s (peak)
_MIN_JERK_PEAK = 1.875  # peak speed of a minimum-jerk move over its mean speed


class _ArmTrack:
    """Keyposes of one arm; consecutive keyposes are joined by minimum-jerk moves."""

    def __init__(self, rest: np.ndarray):
        self.times = [0.0]
        self.poses = [_reachable(rest)]
        self.pending_retraction: float | None = None  # earliest start of an owed retraction

    @property
    def last_time(self) -> float:
        return self.times[-1]

    @property
    def last_pose(self) -> np.ndarray:
        return self.poses[-1]

    def move(self, t0: float, t1: float, pose: np.ndarray) -> None:
        """Hold the current pose until ``t0``, then move to ``pose``, arriving at ``t1``.

        A wrist target beyond comfortable reach is pulled towards the shoulder, so that the
        straight-line moves between keyposes stay inside the arm's reach, and a move that
        would be faster than :data:`_MAX_SPEED` at its peak stops short.
        """
        t0 = max(t0, self.times[-1])
        t1 = max(t1, t0 + 0.05)
        pose = _reachable(pose)
        step = pose[_WRIST] - self.poses[-1][_WRIST]
        longest = _MAX_SPEED * (t1 - t0) / _MIN_JERK_PEAK
        if np.linalg.norm(step) > longest:
            pose[_WRIST] = self.poses[-1][_WRIST] + step * (longest / np.linalg.norm(step))
        if t0 > self.times[-1] + 1e-6:
            self.times.append(t0)
            self.poses.append(self.poses[-1])
        self.times.append(t1)
        self.poses.append(pose)


@dataclass
class _GesturePlan:
    arms: tuple[_ArmTrack, _ArmTrack]  # left, right (both in the left arm's convention)
    stroke_times: np.ndarray
    stroke_stress: np.ndarray
    stroke_hands: tuple[str, ...]
    gesture_phrases: np.ndarray
    gesture_modes: tuple[str, ...]


def _home_pose(rng, height_class: int, width_class: int, shape: int, rest: np.ndarray) -> np.ndarray:
    """The centre of a gesture phrase's movements for one arm."""
    p = rest.copy()
    y = rng.uniform(*_HEIGHTS[height_class])
    x = rng.uniform(*_WIDTHS[width_class])
    z = rng.uniform(0.2, 0.36) - 0.12 * (width_class == 2) - 0.05 * (height_class == 0)
    p[_WRIST] = (x, y, z)
    p[_SWIVEL] = rng.uniform(-0.2, 0.5) + 0.3 * (width_class == 2)
    p[_ROLL] = _PALM_ROLLS[rng.integers(len(_PALM_ROLLS))] + rng.normal(0.0, 0.15)
    p[_FLEX] = rng.uniform(-0.3, 0.3)
    p[_DEV] = rng.uniform(-0.15, 0.15)
    hs = _HANDSHAPES[shape]
    p[_CURL] = np.clip(hs[:5] + rng.normal(0.0, 0.06, 5), 0.0, 1.0)
    p[_SPREAD] = np.clip(hs[5] + rng.normal(0.0, 0.1), 0.0, 1.0)
    return p


def _stroke_direction(rng) -> np.ndarray:
    """Unit direction of a stroke (left-arm convention): mostly down, also out, forward, across."""
    kind = _draw(rng, _STROKE_KIND_P)
    base = np.array([(0.0, -1.0, 0.35), (1.0, -0.3, 0.2), (0.1, -0.3, 1.0), (-1.0, -0.2, 0.3)][kind])
    return _unit(base + rng.normal(0.0, 0.25, 3))


def _plan_gestures(speech: _Speech, rng: np.random.Generator, duration: float) -> _GesturePlan:
    """Gesture phrases over the speech phrases: preparation, strokes on stresses, retraction."""
    rests = (_rest_pose(rng), _rest_pose(rng))
    arms = (_ArmTrack(rests[0]), _ArmTrack(rests[1]))
    stroke_times, stroke_stress, stroke_hands = [], [], []
    g_phrases, g_modes = [], []

    def settle(i: int, until: float) -> None:
        """Retract arm ``i`` after its last stroke, as far as the time before ``until`` allows."""
        arm = arms[i]
        if arm.pending_retraction is None:
            return
        t0 = max(arm.pending_retraction, arm.last_time)
        arm.pending_retraction = None
        avail = until - t0
        if avail >= 0.8:  # all the way down to the rest pose, unhurried
            arm.move(t0, t0 + min(rng.uniform(0.7, 1.0), avail - 0.1), _rest_pose(rng))
        # else: too short a pause to go down and come back up; the hands hold

    for p in range(len(speech.phrases)):
        a = speech.arousal[p]
        in_phrase = (speech.syl_phrase == p) & speech.syl_stressed
        stresses = speech.syl_nucleus[in_phrase]
        emphasis = speech.syl_emphasis[in_phrase]
        if rng.random() > 0.55 + a or len(stresses) == 0:  # calm phrases sometimes go ungestured
            settle(0, np.inf)
            settle(1, np.inf)
            continue
        mode = _MODES[_draw(rng, _MODE_P)]
        used = {"symmetric": (0, 1), "asymmetric": (0, 1), "left": (0,), "right": (1,)}[mode]
        for i in (0, 1):
            if i not in used:
                settle(i, np.inf)
        fast = rng.random() < 0.1 + 0.8 * a
        # Gesture phases keep to the syllables. A stroke ends on the stressed vowel onset: the hand
        # stops and turns there (a velocity minimum), so the stroke's fast part precedes the
        # stress. It starts on the vowel onset of a syllable before, and the hand rebounds, about
        # as briskly, to where the next stroke starts (or this one started), arriving on a later
        # vowel onset; where the syllables give no fitting length, a phase takes its own.
        g = np.flatnonzero(in_phrase)
        nuc, syl_p = speech.syl_nucleus, speech.syl_phrase
        shortest, longest = (0.18, 0.34) if fast else (0.24, 0.48)
        ends = stresses + rng.uniform(-0.02, 0.02, len(g))
        durs = rng.uniform(shortest, longest, len(g))
        jitter = rng.uniform(-0.02, 0.02, (2, len(g)))
        starts, rebounds = ends - durs, ends + durs
        for k, j in enumerate(g):
            for back in (1, 2):
                if j - back >= 0 and syl_p[j - back] == p and shortest <= ends[k] - nuc[j - back] <= longest:
                    starts[k] = nuc[j - back] + jitter[0, k]
                    break
            for ahead in (1, 2):
                if j + ahead < len(nuc) and syl_p[j + ahead] == p and shortest <= nuc[j + ahead] - ends[k] <= longest:
                    rebounds[k] = nuc[j + ahead] + jitter[1, k]
                    break
        chosen, last_end = [], -np.inf
        for k in range(len(g)):
            # a stroke too soon after the last one to leave room for a rebound starts straight from
            # its end, back the way the hand came (a beat back)
            if ends[k] - last_end >= shortest and ends[k] < duration - 0.1:
                chosen.append(k)
                last_end = ends[k]
        height, width = _draw(rng, _HEIGHT_P), _draw(rng, _WIDTH_P)
        home = {used[0]: _home_pose(rng, height, width, _draw(rng, _HANDSHAPE_P), rests[used[0]])}
        if mode == "symmetric":
            home[1] = home[0].copy()
            home[1][_WRIST] += rng.normal(0.0, 0.01, 3)
        elif mode == "asymmetric":
            # the other hand at another height and width, doing less
            h2, w2 = (height + rng.integers(1, 3)) % 3, (width + rng.integers(1, 3)) % 3
            home[1] = _home_pose(rng, h2, w2, _draw(rng, _HANDSHAPE_P), rests[1])
        # hands start moving at the earliest a little before the speech does, and after what
        # they did before; drop strokes until a preparation fits
        earliest = max([arms[i].last_time + 0.05 for i in used] + [speech.phrases[p, 0] - 0.3, 0.0])
        while chosen and starts[chosen[0]] - earliest < 0.3:
            chosen.pop(0)
        if not chosen:
            for i in used:
                settle(i, np.inf)
            continue
        first_start = starts[chosen[0]]
        # through a short pause the hands stay up; in a longer one they go down to rest if that
        # leaves time for an unhurried preparation
        silence = speech.phrases[p, 0] - (speech.phrases[p - 1, 1] if p > 0 else 0.0)
        for i in used:
            if silence >= 0.6:
                settle(i, first_start - 0.8)
            arms[i].pending_retraction = None
        # the preparation takes longer the further the hand travels
        travel = max(float(np.linalg.norm(home[i][_WRIST] - arms[i].last_pose[_WRIST])) for i in used)
        prep_dur = float(np.clip(travel / (rng.uniform(0.7, 1.0) * (1.3 if fast else 1.0)), 0.3, 0.8))
        earliest = max([earliest] + [arms[i].last_time + 0.05 for i in used])
        prep_start = max(earliest, first_start - prep_dur)
        dominant = int(rng.integers(2)) if mode == "asymmetric" else used[0]
        scale = (0.12 + 0.26 * a) if fast else (0.08 + 0.12 * a)
        # repeated beats of a gesture phrase go much the same way (the hands of a symmetric phrase
        # mirror each other; the secondary hand of an asymmetric one goes its own way)
        phrase_dir = {i: _stroke_direction(rng) for i in used}
        prev_dir: dict[int, np.ndarray | None] = {i: None for i in used}
        prev_start: dict[int, np.ndarray | None] = {i: None for i in used}
        rebound_at = {i: 0.0 for i in used}  # when the hand's rebound from its last stroke is due to end
        at_stroke_end = {i: False for i in used}  # the hand has just ended a stroke and not yet rebounded
        for n, k in enumerate(chosen):
            s1 = ends[k]
            direction = _unit(phrase_dir[dominant] + rng.normal(0.0, 0.25, 3))
            amp = scale * emphasis[k] ** 2 * rng.uniform(0.85, 1.15)  # louder syllable, bigger stroke
            hands = []
            for i in used:
                arm = arms[i]
                s0 = starts[k]
                if i != dominant and mode == "asymmetric":
                    if rng.random() > 0.4:
                        if n == 0:  # the secondary hand still takes its position
                            arm.move(prep_start, s1, home[i])
                        continue
                    d_i, amp_i = _unit(phrase_dir[i] + rng.normal(0.0, 0.25, 3)), 0.5 * amp
                else:
                    d_i, amp_i = direction, amp
                beat_back = at_stroke_end[i] and s0 - arm.last_time < shortest
                if beat_back:
                    d_i = _unit(-prev_dir[i] + rng.normal(0.0, 0.2, 3))
                start_pose = home[i].copy()
                start_pose[_WRIST] -= 0.5 * amp_i * d_i
                start_pose[_FLEX] -= 0.15
                end_pose = home[i].copy()
                end_pose[_WRIST] += 0.5 * amp_i * d_i
                end_pose[_FLEX] += 0.2  # the hand flicks with the beat
                end_pose[_CURL] = np.clip(end_pose[_CURL] - 0.08, 0.0, 1.0)
                if arm.last_time <= prep_start:  # preparation from wherever the hand rests
                    arm.move(prep_start, s0, start_pose)
                elif beat_back:  # no room for a rebound: straight back from the last stroke's end
                    s0 = arm.last_time
                elif at_stroke_end[i]:
                    # rebound to this stroke's start, then hold there until the stroke
                    arm.move(arm.last_time, min(rebound_at[i], s0), start_pose)
                    at_stroke_end[i] = False
                if s1 - s0 < 0.1 or s0 < arm.last_time:  # this hand is still busy; it sits this stroke out
                    continue
                arm.move(s0, s1, end_pose)
                prev_dir[i], prev_start[i], rebound_at[i] = d_i, start_pose, rebounds[k]
                at_stroke_end[i] = True
                hands.append(i)
            if hands:
                stroke_times.append(ends[k])
                stroke_stress.append(stresses[k])
                stroke_hands.append("both" if len(hands) == 2 else ("left", "right")[hands[0]])
        g_phrases.append((prep_start, max(arms[i].last_time for i in used)))
        g_modes.append(mode)
        phrase_end = speech.phrases[p, 1]
        for i in used:
            arm = arms[i]
            if at_stroke_end[i]:
                # after the last stroke the hand rebounds to where the stroke began and holds until
                # the speech pauses; the retraction comes in the pause
                arm.move(arm.last_time, rebound_at[i], prev_start[i])
            arm.pending_retraction = max(arm.last_time + rng.uniform(0.1, 0.3), phrase_end + rng.uniform(0.05, 0.2))
    settle(0, np.inf)
    settle(1, np.inf)
    return _GesturePlan(
        arms=arms,
        stroke_times=np.array(stroke_times, dtype=np.float64),
        stroke_stress=np.array(stroke_stress, dtype=np.float64),
        stroke_hands=tuple(stroke_hands),
        gesture_phrases=np.array(g_phrases, dtype=np.float64).reshape(-1, 2),
        gesture_modes=tuple(g_modes),
    )


def _draw(rng: np.random.Generator, p: np.ndarray) -> int:
    """An index drawn with probabilities ``p`` (cheaper than ``Generator.choice`` for one draw)."""
    return int(min(np.searchsorted(np.cumsum(p), rng.random() * p.sum(), side="right"), len(p) - 1))


def _min_jerk_track(times: np.ndarray, poses: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Keyposes joined by minimum-jerk moves, sampled at ``t``.

    Parameters
    ----------
    times : np.ndarray, shape (K,), increasing
    poses : np.ndarray, shape (K, D)
    t : np.ndarray, shape (T,)

    Returns
    -------
    np.ndarray, shape (T, D); velocity and acceleration are zero at every keypose.
    """
    if len(times) == 1:
        return np.repeat(poses[:1], len(t), axis=0)
    i = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
    s = np.clip((t - times[i]) / (times[i + 1] - times[i]), 0.0, 1.0)
    w = s**3 * (10.0 - 15.0 * s + 6.0 * s**2)
    return poses[i] + w[:, None] * (poses[i + 1] - poses[i])


# ---------------------------------------------------------------------------------------------
# motion
# ---------------------------------------------------------------------------------------------


def _smooth_noise(rng, n: int, sigma_frames: float, dims: int = 1) -> np.ndarray:
    """Gaussian-smoothed white noise with unit standard deviation, shape (n, dims)."""
    x = gaussian_filter1d(rng.standard_normal((n, dims)), sigma_frames, axis=0, mode="reflect")
    return x * math.sqrt(2.0 * math.sqrt(math.pi) * sigma_frames)


def _bumps(times: np.ndarray, heights: np.ndarray, n: int, sigma_frames: float) -> np.ndarray:
    """Sum of Gaussian bumps at ``times`` (in frames), sampled on frames 0..n-1, shape (n,)."""
    impulses = np.zeros(n + 2)
    f = np.clip(times, 0.0, n)
    i0 = np.floor(f).astype(np.int64)
    w = f - i0
    np.add.at(impulses, i0, heights * (1.0 - w))
    np.add.at(impulses, i0 + 1, heights * w)
    return gaussian_filter1d(impulses, sigma_frames, mode="constant")[:n] * (math.sqrt(2 * math.pi) * sigma_frames)


def _arm_rotations(pose: np.ndarray) -> dict[str, np.ndarray]:
    """Local rotations of one arm (left-arm convention) from its keypose track.

    Two-bone inverse kinematics in the frame of ``upper_chest``: the wrist
    reaches its target (pulled smoothly inside the arm's reach), the elbow lies
    in the plane set by the swivel angle.

    Parameters
    ----------
    pose : np.ndarray, shape (T, 13)
        Keyposes sampled per frame; the wrist target is in the pelvis frame of an
        upright torso and moves with the torso's sway.

    Returns
    -------
    dict of joint suffix -> np.ndarray, shape (T, 3, 3)
    """
    off = _rest_offsets()
    wrist_y = pose[:, 1]
    shrug = 0.03 + 0.2 * np.clip((wrist_y - 0.15) / 0.45, 0.0, 1.0) ** 2
    protract = 0.12 * np.clip(pose[:, 2] / 0.4, -0.5, 1.0)
    collar = _axis_angle((0, 0, 1), shrug) @ _axis_angle((0, -1, 0), protract)
    shoulder = off[joint_index("left_collar")] + collar @ off[joint_index("left_shoulder")]
    target = pose[:, _WRIST] - _UPPER_CHEST
    d_vec = target - shoulder
    dist = np.linalg.norm(d_vec, axis=1)
    n = d_vec / dist[:, None]
    l1, l2 = _UPPER_ARM, _FOREARM
    d_max = _REACH
    d0 = _COMFORT * d_max
    d = np.where(dist > d0, d0 + (d_max - d0) * np.tanh((dist - d0) / (d_max - d0)), dist)
    d = np.maximum(d, 0.12)
    a = (l1**2 - l2**2 + d**2) / (2.0 * d)
    r = np.sqrt(np.maximum(l1**2 - a**2, 0.0))
    pole = _unit([0.45, -0.8, -0.35])  # elbow down, out and a little back
    u0 = pole - (n @ pole)[:, None] * n
    u0 = u0 / np.linalg.norm(u0, axis=1, keepdims=True)
    sw = pose[:, _SWIVEL][:, None]
    u = u0 * np.cos(sw) + np.cross(n, u0) * np.sin(sw)
    elbow = shoulder + a[:, None] * n + r[:, None] * u
    wrist = shoulder + d[:, None] * n
    x_u = _unit(elbow - shoulder)
    x_f = _unit(wrist - elbow)
    y_u = -_unit(np.cross(x_u, x_f))  # elbow hinge axis
    upper = np.stack([x_u, y_u, np.cross(x_u, y_u)], axis=2)
    fore = np.stack([x_f, y_u, np.cross(x_f, y_u)], axis=2) @ _axis_angle((1, 0, 0), pose[:, _ROLL])
    hand = _axis_angle((0, 0, -1), pose[:, _FLEX]) @ _axis_angle((0, -1, 0), pose[:, _DEV])
    rots = {
        "collar": collar,
        "shoulder": np.swapaxes(collar, 1, 2) @ upper,
        "elbow": np.swapaxes(upper, 1, 2) @ fore,
        "wrist": hand,
    }
    palm = np.array([0.0, -1.0, 0.0])
    for fi, finger in enumerate(FINGERS):
        curl = pose[:, _CURL][:, fi]
        direction = _unit(_FINGER_DIRS[finger])
        toward = _unit([0.0, -0.6, -0.8]) if finger == "thumb" else palm
        axis = _unit(np.cross(direction, toward))
        angles = _CURL_ANGLES["thumb" if finger == "thumb" else "other"]
        spread = _axis_angle((0, -1, 0), _SPREAD_ANGLES[finger] * (pose[:, _SPREAD] - 0.3))
        rots[f"{finger}1"] = spread @ _axis_angle(axis, angles[0] * curl)
        rots[f"{finger}2"] = _axis_angle(axis, angles[1] * curl)
        rots[f"{finger}3"] = _axis_angle(axis, angles[2] * curl)
    return rots


def _render_motion(plan: _GesturePlan, speech: _Speech, rng: np.random.Generator, n_frames: int) -> np.ndarray:
    """Positions of the take, shape (n_frames, 55, 3), float32."""
    t = np.arange(n_frames) / FPS
    identity = np.broadcast_to(np.eye(3), (n_frames, 3, 3))
    local = [identity] * N_JOINTS
    # torso: slow sway, a slight forward lean and a head nod on every stressed syllable
    stress_frames = speech.syl_nucleus[speech.syl_stressed] * FPS
    lean = _bumps(stress_frames, rng.uniform(0.01, 0.025, len(stress_frames)), n_frames, 2.5)
    nod = _bumps(stress_frames + 0.03 * FPS, rng.uniform(0.04, 0.09, len(stress_frames)), n_frames, 1.8)
    sway = _smooth_noise(rng, n_frames, 12.0, 3) * np.array([0.025, 0.03, 0.02])  # lean, side, twist
    head = _smooth_noise(rng, n_frames, 10.0, 3) * np.array([0.04, 0.07, 0.025])  # pitch, yaw, roll
    shares = {"spine_mid": 0.4, "chest": 0.3, "upper_chest": 0.3}
    for name, share in shares.items():
        local[joint_index(name)] = (
            _axis_angle((1, 0, 0), share * (sway[:, 0] + lean))
            @ _axis_angle((0, 0, 1), share * sway[:, 1])
            @ _axis_angle((0, 1, 0), share * sway[:, 2])
        )
    local[joint_index("neck")] = _axis_angle((1, 0, 0), 0.3 * (head[:, 0] + nod))
    local[joint_index("head")] = (
        _axis_angle((1, 0, 0), 0.7 * (head[:, 0] + nod))
        @ _axis_angle((0, 1, 0), head[:, 1])
        @ _axis_angle((0, 0, 1), head[:, 2])
    )
    root = local[joint_index("spine_mid")] @ np.asarray(_BODY_OFFSETS["spine_mid"])
    for side, arm in zip(("left", "right"), plan.arms):
        pose = _min_jerk_track(np.asarray(arm.times), np.stack(arm.poses), t)
        # a living hold: the wrist and hand drift a little, never quite still
        pose[:, _WRIST] += _smooth_noise(rng, n_frames, 6.0, 3) * 0.008
        pose[:, _ROLL] += _smooth_noise(rng, n_frames, 8.0, 1)[:, 0] * 0.05
        pose[:, _CURL] = np.clip(pose[:, _CURL] + _smooth_noise(rng, n_frames, 8.0, 5) * 0.03, 0.0, 1.0)
        for suffix, rot in _arm_rotations(pose).items():
            # the right arm is the mirror image of a left arm with the same keyposes
            local[joint_index(f"{side}_{suffix}")] = rot if side == "left" else _MIRROR @ rot @ _MIRROR
    return _forward_kinematics(root, local).astype(np.float32)
