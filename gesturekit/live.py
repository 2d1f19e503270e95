"""Streaming synthesis: push speech in chunks, get the motion frames that are now determined.

A plain implementation of the live API: it keeps the speech pushed so far and, whenever
another step of motion can be determined, runs :func:`gesturekit.synthesize.synthesize`
on all of it, returning the frames not yet returned.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .control import ControlTrack, Segment, _parse_constraints
from .database import MatchingDatabase
from .errors import ConfigError, GestureKitError
from .motion import AUDIO_SR
from .synthesize import MotionRefiner, SynthesisConfig, SynthesisResult, synthesize

__all__ = ["LiveSynthesizer"]

_LOOKAHEAD_FRAMES = 14  # frames of speech a step's audio feature reads past its first frame
_HALF_WINDOW_S = 0.064  # half an MFCC window


class LiveSynthesizer:
    """Synthesis of speech that arrives in chunks.

    Parameters
    ----------
    db : MatchingDatabase
    config : SynthesisConfig, optional
        The options of :func:`gesturekit.synthesize.synthesize`; its control is replaced
        by the controls set while running (:meth:`set_control`).
    refiner : MotionRefiner, optional
    name : str
        The speech's name in the result.
    """

    def __init__(
        self,
        db: MatchingDatabase,
        *,
        config: SynthesisConfig | None = None,
        refiner: MotionRefiner | None = None,
        name: str = "live",
    ) -> None:
        self._db = db
        self._config = config or SynthesisConfig()
        self._refiner = refiner
        self._name = name
        self._chunks: list[np.ndarray] = []
        self._n = 0
        self._out = 0
        self._switches: list[tuple[float, str | None]] = []
        self._result: SynthesisResult | None = None
        self._finished = False

    @property
    def samples_in(self) -> int:
        """Samples pushed so far."""
        return self._n

    @property
    def frames_out(self) -> int:
        """Frames returned so far."""
        return self._out

    @property
    def algorithmic_delay_s(self) -> float:
        """Speech time needed beyond a frame before it is determined, seconds."""
        return _LOOKAHEAD_FRAMES / self._db.fps + _HALF_WINDOW_S

    def _track(self, end_s: float) -> ControlTrack:
        segs = []
        for i, (start, constraint) in enumerate(self._switches):
            stop = self._switches[i + 1][0] if i + 1 < len(self._switches) else max(end_s, start + 1e-3)
            if constraint is not None and stop > start:
                segs.append(Segment(start, stop, _parse_constraints(constraint)))
        return ControlTrack(tuple(segs))

    def set_control(self, constraint: str | None) -> None:
        """Hold ``constraint`` (e.g. ``"left_hand=high"``; None: free) from the next undetermined step on."""
        if self._finished:
            raise GestureKitError("the speech has ended: no control can be set after finish()")
        if constraint is not None:
            _parse_constraints(constraint)  # validates
            if not constraint.strip():
                raise ConfigError("a control must look like name=value, e.g. left_hand=high")
        start = self._out / self._db.fps
        self._switches = [s for s in self._switches if s[0] < start] + [(start, constraint)]

    def _audio(self) -> np.ndarray:
        if len(self._chunks) > 1:
            self._chunks = [np.concatenate(self._chunks)]
        return self._chunks[0] if self._chunks else np.zeros(0, np.float32)

    def _run(self) -> SynthesisResult:
        audio = self._audio()
        config = self._config.with_control(self._track(len(audio) / AUDIO_SR))
        return synthesize(audio, db=self._db, config=config, refiner=self._refiner)

    def push(self, samples: np.ndarray) -> np.ndarray:
        """Append mono speech at 16 kHz (float32 in [-1, 1]); return the frames now determined, (n, 55, 3)."""
        if self._finished:
            raise GestureKitError("the speech has ended: push() after finish()")
        a = np.asarray(samples, dtype=np.float32)
        if a.ndim != 1:
            raise ConfigError(f"speech samples must be mono, shape (samples,), got {a.shape}")
        self._chunks.append(a)
        self._n += len(a)
        fps, n_seg = self._db.fps, self._config.segment
        # a step starting at t is determined once speech up to t + the delay has arrived
        known_s = self._n / AUDIO_SR - self.algorithmic_delay_s
        steps = math.floor(known_s * fps / n_seg) + 1 if known_s >= 0 else 0
        ready = min(steps * n_seg, self._n * 15 // AUDIO_SR)
        if ready <= self._out:
            return np.zeros((0, 55, 3), np.float32)
        frames = self._run().motion.positions[self._out : ready]
        self._out = ready
        return np.asarray(frames, dtype=np.float32)

    def finish(self) -> np.ndarray:
        """The end of the speech: the remaining frames, (n, 55, 3)."""
        self._finished = True
        if self._n < AUDIO_SR // 15:
            raise ConfigError("speech is shorter than one frame (1/15 s)")
        audio = self._audio()
        config = self._config.with_control(self._track(len(audio) / AUDIO_SR))
        res = synthesize(audio, db=self._db, config=config, refiner=self._refiner)
        self._result = replace(res, source=self._name)
        frames = res.motion.positions[self._out :]
        self._out = res.n_frames
        return np.asarray(frames, dtype=np.float32)

    def result(self) -> SynthesisResult:
        """After :meth:`finish`: the whole performance as a :class:`SynthesisResult`."""
        if self._result is None:
            raise GestureKitError("the performance has not ended: call finish() first")
        return self._result
