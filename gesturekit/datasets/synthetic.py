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

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._arguments import checks_arguments
from ..errors import ConfigError
from ..motion import AUDIO_SR, Motion, Take, n_audio_frames
from ..skeleton import FPS
from ._demo_body import render_motion
from ._demo_gestures import plan_gestures
from ._demo_speech import plan_speech, render_audio

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


@checks_arguments
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


@checks_arguments
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
    speech = plan_speech(speech_rng, duration)
    audio = render_audio(speech, audio_rng, n_samples)
    plan = plan_gestures(speech, gesture_rng, duration)
    positions = render_motion(plan.arms, speech, motion_rng, n_frames)
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
