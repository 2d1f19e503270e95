"""Streaming synthesis: speech in chunks of any size, motion as soon as it is determined.

:class:`LiveSynthesizer` takes mono speech at 16 kHz as it arrives (:meth:`~LiveSynthesizer.push`)
and returns the motion frames that the speech so far determines; :meth:`~LiveSynthesizer.finish`
ends the speech and returns the rest, and :meth:`~LiveSynthesizer.result` gives the whole
performance as the :class:`~gesturekit.synthesis.SynthesisResult` that
:func:`~gesturekit.synthesis.synthesize` returns (npz, BVH and MP4 export and the retrieval
inspector take it as they take any result).

Equal to the offline synthesis. The motion streamed equals ``synthesize`` on the whole
recording with the result's configuration, frame for frame:

- A frame's audio features ``m_t`` are computed once every sample of its window has arrived
  (:func:`gesturekit.features.audio_frame_features` computes each frame from its own samples
  only, so they equal those of the whole file bit for bit); frames whose window reaches past
  the end of the speech wait for :meth:`finish`, where the end is known (zeros past it, and
  the last ``m`` repeated past the last frame, as offline).
- A search step starting at frame ``t`` needs ``f_t = [m_t, ..., m_{t+14}]``: it is taken once
  ``m_{t+14}`` is known, i.e. about ``14 / 15 + 1024 / 16000 = 0.997`` s of speech after ``t``
  (:attr:`~LiveSynthesizer.algorithmic_delay_s`), one step at a time from the previous
  step's pose (:class:`gesturekit.search.stream.StepSearch`); the past is never searched again.
- Blending (``config.blend = "offset"``) is causal: a join is faded into the frames after it
  from the two frames before it, so a step's frames are final when the step is taken.
- Controls switched with :meth:`~LiveSynthesizer.set_control` hold from the next step not yet
  taken; the result's configuration records them as a control track (seconds), and
  ``synthesize(speech, db=db, config=result.config)`` gives the same motion.

A refiner, when given, runs on a bounded window: whenever steps are taken it refines the
last :attr:`REFINE_WINDOW` frames of the k-NN motion and returns its output up to
:attr:`REFINE_LOOKAHEAD` frames before their end, which adds ``REFINE_LOOKAHEAD / 15`` s to
the delay. Its output differs from the offline refiner's (which sees the whole motion) most
near each window's end; the k-NN motion (``result().knn_motion``) is unaffected and equals
the offline one.
"""

from __future__ import annotations

import threading

import numpy as np

from .blend import fade_weights
from .control import ControlTrack, Segment, constraint_mask, parse_control
from .database import MatchingDatabase
from .errors import ConfigError
from .features import LAYOUT, audio_frame_features, cgan_audio_features, n_audio_frames, stack_audio_features
from .motion import AUDIO_SR, Motion
from .search.plan import SearchPlan, exclusions, resolved_search_config
from .search.stream import StepSearch
from .synthesis import MotionRefiner, SynthesisConfig, SynthesisResult, search_request, synthesizer_for

__all__ = ["LiveSynthesizer"]

Constraints = tuple[tuple[str, str], ...]


def _boundary_s(frame: int, fps: float) -> float:
    """A time in seconds (microseconds, as control tracks keep them) at which a control segment
    starts or ends exactly at output frame ``frame`` (see :meth:`ControlTrack.frame_labels`)."""
    s = np.floor(frame / fps * 1e6) / 1e6
    while int(np.ceil(round(s, 6) * fps - 1e-9)) < frame:  # pragma: no cover - floor is at most 1 us early
        s += 1e-6
    return round(float(s), 6)


class _Growing:
    """A float32 array of rows that grows by doubling; ``view`` holds the rows written."""

    def __init__(self, row_shape: tuple[int, ...], capacity: int = 1024) -> None:
        self.data = np.zeros((capacity, *row_shape), np.float32)
        self.n = 0

    def append(self, rows: np.ndarray) -> None:
        need = self.n + len(rows)
        if need > len(self.data):
            bigger = np.zeros((max(need, 2 * len(self.data)), *self.data.shape[1:]), np.float32)
            bigger[: self.n] = self.data[: self.n]
            self.data = bigger
        self.data[self.n : need] = rows
        self.n = need

    @property
    def view(self) -> np.ndarray:
        return self.data[: self.n]


# the largest sample magnitude push() accepts (full scale is 1)
_MAX_PEAK = 16.0


class LiveSynthesizer:
    """Gesture motion for speech that arrives in chunks, equal to :func:`synthesize` on the whole.

    Parameters
    ----------
    db : MatchingDatabase
    config : SynthesisConfig, optional
        As for :func:`~gesturekit.synthesis.synthesize` (k, N, seed, initial pose, blending,
        exclusions, an initial control track); pins are refused (the speech's length is not known).
    refiner : MotionRefiner, optional
        Refines on a bounded window (see the module's notes); adds ``REFINE_LOOKAHEAD / 15`` s.
    name : str
        The result's source name.

    Notes
    -----
    The methods may be called from different threads (e.g. audio and user interface); each
    call runs alone.

    Examples
    --------
    >>> import tempfile
    >>> import numpy as np
    >>> from gesturekit.demo import build_demo_database
    >>> from gesturekit.datasets.synthetic import generate_demo_take
    >>> from gesturekit.live import LiveSynthesizer
    >>> from gesturekit.synthesis import synthesize
    >>> db = build_demo_database(tempfile.mkdtemp() + "/demo", minutes=0.5)
    >>> speech = generate_demo_take(seconds=3.0, seed=1, name="speech")[0].audio
    >>> live = LiveSynthesizer(db)
    >>> frames = [live.push(chunk) for chunk in np.array_split(speech, 30)]  # 0.1 s at a time
    >>> frames.append(live.finish())
    >>> np.concatenate(frames).shape
    (45, 55, 3)
    >>> res = live.result()
    >>> offline = synthesize(res.audio, db=db, config=res.config)
    >>> bool((offline.motion.positions == res.motion.positions).all())
    True
    """

    #: Frames of k-NN motion the live refiner refines at a time.
    REFINE_WINDOW = 64
    #: Frames the live refiner's output is held back from its window's end.
    REFINE_LOOKAHEAD = 8

    def __init__(
        self,
        db: MatchingDatabase,
        *,
        config: SynthesisConfig | None = None,
        refiner: MotionRefiner | None = None,
        name: str = "live",
    ) -> None:
        config = SynthesisConfig() if config is None else config
        if not isinstance(config, SynthesisConfig):
            raise ConfigError(f"config must be a SynthesisConfig, got {type(config).__name__}")
        if not isinstance(db, MatchingDatabase):
            raise ConfigError(f"db must be a MatchingDatabase, got {type(db).__name__}")
        # the stages of the offline synthesis, on the database's shared index; the search is
        # planned as it goes (a step at a time), the refiner applied to a window at a time
        self._stages = synthesizer_for(db, refiner=refiner)
        self._db, self._config, self._refiner, self._name = db, config, refiner, str(name)
        self._fps = float(db.fps)
        self._N = config.segment
        request = search_request(config)
        self._search = StepSearch(
            self._stages.index, resolved_search_config(db, request), exclude=exclusions(db, request)
        )
        self._zscore = self._stages.zscore
        self._G = db.G
        self._attributes = np.asarray(db.attributes)
        self._mask_of: dict[Constraints, int] = {}
        self._step_masks: list[int] = []
        self._switches: list[tuple[int, Constraints]] = []  # (first frame, constraints), in order
        self._audio = _Growing(())
        self._m = _Growing((LAYOUT.frame_dim,))
        self._knn = _Growing((LAYOUT.motion_dim,))  # the k-NN frames
        self._out = _Growing((LAYOUT.motion_dim,))  # blended
        self._fade = fade_weights(config.blend_frames)
        self._offsets: dict[int, np.ndarray] = {}  # join frame -> offset being faded in
        self._refined = _Growing((LAYOUT.motion_dim,))
        self._returned = 0
        self._n_final: int | None = None
        self._result: SynthesisResult | None = None
        self._lock = threading.RLock()

    # -- what the caller reads ---------------------------------------------------------------

    @property
    def samples_in(self) -> int:
        """Samples pushed so far."""
        return self._audio.n

    @property
    def frames_out(self) -> int:
        """Motion frames returned so far."""
        return self._returned

    @property
    def frames_determined(self) -> int:
        """k-NN motion frames the search has determined so far (with a refiner, the refined frames
        returned lag :attr:`REFINE_LOOKAHEAD` behind them)."""
        return self._search.n_frames

    @property
    def algorithmic_delay_s(self) -> float:
        """Seconds of speech needed beyond a frame's time before that frame is determined (at most):
        the audio feature's look-ahead (14 frames) and half an MFCC window (0.997 s), or a step's
        length when N exceeds the look-ahead, plus the live refiner's hold-back when a refiner is used."""
        # frame centres are rounded to whole samples: up to half a sample later than t / fps
        look = LAYOUT.audio_lookahead / self._fps + (LAYOUT.n_fft - LAYOUT.n_fft // 2 + 0.5) / AUDIO_SR
        delay = max(look, self._N / self._fps + 1 / AUDIO_SR)
        if self._refiner is not None:
            delay += self.REFINE_LOOKAHEAD / self._fps
        return delay

    @property
    def finished(self) -> bool:
        """Whether :meth:`finish` has been called."""
        return self._n_final is not None

    # -- input -------------------------------------------------------------------------------

    def push(self, samples: np.ndarray) -> np.ndarray:
        """Append speech; return the motion frames it determines.

        Parameters
        ----------
        samples : np.ndarray, shape (n,), float
            Mono speech at 16 kHz, nominally in [-1, 1] (float32; other float types are
            converted), any length >= 0.

        Returns
        -------
        np.ndarray, shape (frames, 55, 3), float32
            Metres; the frames that follow those returned before (``frames`` may be 0).

        Raises
        ------
        ConfigError
            Not a 1-D float array, values that are NaN, infinite or far outside [-1, 1]
            (the chunk is not used; the stream goes on), or the speech has finished.
        """
        with self._lock:
            self._check_open("push")
            x = self._checked(samples)
            known = (self._m.n, n_audio_frames(self._audio.n))
            self._audio.append(x)
            self._features(final=False)
            if (self._m.n, n_audio_frames(self._audio.n)) == known:  # no new feature frame: no new step
                return np.zeros((0, LAYOUT.n_joints, 3), np.float32)
            self._steps(final=False)
            return self._emit(final=False)

    def set_control(self, constraint: str | None) -> None:
        """Hold a control from the next step not yet taken on (``None`` or ``""``: free).

        Parameters
        ----------
        constraint : str or None
            E.g. ``"left_hand=high"`` or ``"left_hand=low+speed=slow"``. Frames already
            returned, and those of steps already taken, never change.

        Raises
        ------
        ConfigError
            An unknown control or value, or the speech has finished.
        """
        if constraint is not None and not isinstance(constraint, str):
            raise ConfigError(f"control must be text such as 'left_hand=high' or None, got {type(constraint).__name__}")
        parsed: Constraints = ()
        if constraint is not None and constraint.strip():
            if ":" in constraint or "," in constraint:
                raise ConfigError(f"control {constraint!r} must be name=value[+name=value], without times")
            parsed = parse_control(f"0-1:{constraint}").segments[0].constraints
        with self._lock:
            self._check_open("set_control")
            frame = self._search.n_frames
            while self._switches and self._switches[-1][0] >= frame:  # not yet in effect: replaced
                self._switches.pop()
            self._switches.append((frame, parsed))

    def finish(self) -> np.ndarray:
        """End the speech; return the remaining frames, shape (frames, 55, 3), float32 metres.

        Raises
        ------
        ConfigError
            Called twice, or the speech is shorter than one frame (1/15 s).
        """
        with self._lock:
            self._check_open("finish")
            n = n_audio_frames(self._audio.n)
            if n < 1:
                raise ConfigError("speech is shorter than one frame (1/15 s); push more before finish()")
            self._n_final = n
            self._features(final=True)
            self._steps(final=True)
            out = self._emit(final=True)
            self._result = self._make_result()
            self._search.close()
            return out

    def result(self) -> SynthesisResult:
        """The whole performance as a :class:`SynthesisResult` (after :meth:`finish`).

        ``config`` records the control track as it was switched (seconds); ``motion`` is what
        was returned (the live refiner's output when a refiner was given), ``knn_motion`` the
        k-NN motion, ``plan`` what the search was given.
        """
        with self._lock:
            if self._result is None:
                raise ConfigError("result() is available after finish()")
            return self._result

    # -- the pipeline ------------------------------------------------------------------------

    def _check_open(self, what: str) -> None:
        if self._n_final is not None:
            raise ConfigError(f"{what}(): the speech has finished (finish() was called); start a new LiveSynthesizer")

    @staticmethod
    def _checked(samples: np.ndarray) -> np.ndarray:
        if not isinstance(samples, np.ndarray):
            raise ConfigError(f"speech samples must be a numpy array, got {type(samples).__name__}")
        if samples.ndim != 1:
            raise ConfigError(f"speech samples must be mono, shape (samples,), got shape {samples.shape}")
        if samples.dtype.kind != "f":
            raise ConfigError(
                f"speech samples must be floats in [-1, 1] (float32), got {samples.dtype}"
                + (" (divide 16-bit samples by 32768)" if samples.dtype.kind in "iu" else "")
            )
        x = samples.astype(np.float32, copy=False)
        if not np.isfinite(x).all():
            raise ConfigError(
                f"speech samples contain NaN or infinite values (at sample {int(np.argmin(np.isfinite(x)))})"
            )
        # a little past full scale happens (resampling, mixing); far past it, every later feature
        # frame overflows, so the chunk is refused and the stream stays usable
        peak = float(np.max(np.abs(x), initial=0.0))
        if peak > _MAX_PEAK:
            at = int(np.argmax(np.abs(x)))
            hint = (
                "; these look like 16-bit samples: divide them by 32768"
                if peak <= 32768 * 1.01
                else "; the chunk was not used"
            )
            raise ConfigError(f"speech samples must lie in [-1, 1], found {x[at]:.6g} at sample {at}{hint}")
        return x

    def _features(self, *, final: bool) -> None:
        """Compute ``m_t`` of every frame whose window has arrived (all frames when ``final``)."""
        n_in = self._audio.n
        if final:
            ready = self._n_final or 0
        else:
            # frame t's window ends at centre(t) + n_fft - n_fft // 2 - 1 (centres: frame_centres)
            last = n_in - (LAYOUT.n_fft - LAYOUT.n_fft // 2)
            sr, fps = LAYOUT.sr, LAYOUT.fps
            ready = 0 if last < 0 else (2 * fps * (last + 1) - 1 - fps) // (2 * sr) + 1
            ready = min(ready, n_audio_frames(n_in))
        if ready > self._m.n:
            first = self._m.n
            self._m.append(audio_frame_features(self._audio.view, first_frame=first, n_frames=ready - first))

    def _label(self, frame: int) -> Constraints:
        """The constraints in force at output frame ``frame``."""
        for first, constraints in reversed(self._switches):
            if first <= frame:
                return constraints
        label: Constraints = ()
        for seg in self._config.control_track.segments:  # as ControlTrack.frame_labels
            if int(np.ceil(seg.start_s * self._fps - 1e-9)) <= frame < int(np.ceil(seg.end_s * self._fps - 1e-9)):
                label = seg.constraints
        return label

    def _steps(self, *, final: bool) -> None:
        """Take every search step whose audio feature (and length) is now known."""
        N, look = self._N, LAYOUT.audio_lookahead
        known = self._n_final if final else n_audio_frames(self._audio.n)
        assert known is not None
        while True:
            t = self._search.n_frames
            if final:
                if t >= known:
                    return
            elif t + look >= self._m.n or t + N > known:
                return
            end = min(t + N, known)
            m = self._m.view
            rows = np.minimum(t + np.asarray(LAYOUT.audio_offsets), len(m) - 1)  # clamped only at the end
            query = self._zscore.apply(m[rows].reshape(1, -1))[0]
            label = self._label((t + end - 1) // 2)  # a step's control is that of its middle frame
            j = -1
            if label:
                if label not in self._mask_of:
                    mask = constraint_mask(self._attributes, label, self._db.thresholds)
                    self._mask_of[label] = self._search.add_mask(mask)
                j = self._mask_of[label]
            self._step_masks.append(j)
            clip, start = self._search.step(query, j, end - t)
            g = np.asarray(self._G[clip, start : start + end - t], dtype=np.float32)
            self._append_motion(g, final=final)

    def _append_motion(self, g: np.ndarray, *, final: bool) -> None:
        """Append a step's k-NN frames and blend its join as :func:`blend_segments` does."""
        a = self._knn.n
        self._knn.append(g)
        self._out.append(g)
        if self._config.blend == "none":
            return
        out, b_end, F = self._out.data, self._out.n, len(self._fade)
        if a >= 2:  # blend_segments skips joins before frame 2
            self._offsets[a] = np.empty(0, np.float32)  # the offset is taken when its turn comes
        for b in sorted(self._offsets):  # joins in order: each sees the frames before it blended
            if b >= a and self._offsets[b].size == 0:
                expected = out[b - 1] + (out[b - 1] - out[b - 2])
                self._offsets[b] = expected - out[b]
            lo, hi = max(a, b), min(b + F, b_end)
            if lo < hi:
                out[lo:hi] += (self._fade[lo - b : hi - b, None] * self._offsets[b][None, :]).astype(np.float32)
        for b in [b for b in self._offsets if b + F <= b_end]:
            del self._offsets[b]

    def _emit(self, *, final: bool) -> np.ndarray:
        """The frames determined since the last call, (n, 55, 3) float32."""
        if final and self._n_final is not None and self._n_final < 3 and self._config.blend != "none":
            # blend_segments leaves motions shorter than 3 frames as they are
            self._out.data[: self._out.n] = self._knn.view
        if self._refiner is None:
            ready = self._out.n
            frames = self._out.view[self._returned : ready]
        else:
            ready = self._refine(final=final)
            frames = self._refined.view[self._returned : ready]
        self._returned = ready
        return frames.reshape(-1, LAYOUT.n_joints, 3).copy()

    def _refine(self, *, final: bool) -> int:
        """Refine the last window of k-NN frames; returns how many refined frames are final."""
        assert self._refiner is not None
        T = self._knn.n
        ready = T if final else max(T - self.REFINE_LOOKAHEAD, 0)
        if ready <= self._refined.n:
            return self._refined.n
        s = max(0, min(self._refined.n, T - self.REFINE_WINDOW))
        a = cgan_audio_features(self._m.view[s:T])
        knn = Motion.from_flat(self._knn.view[s:T], self._fps, self._db.joint_presence)
        refined = self._stages.refine_motion(knn, a, keep_hz=self._config.refiner_keep_hz).flat()
        self._refined.append(np.asarray(refined[self._refined.n - s : ready - s], dtype=np.float32))
        return ready

    def _track(self) -> ControlTrack:
        """The control track as it was switched: the config's until the first switch, then the switches."""
        n = self._n_final
        assert n is not None
        fps = self._fps
        if not self._switches:
            return self._config.control_track
        segs: list[Segment] = []
        first = self._switches[0][0]
        cut = _boundary_s(first, fps)
        for seg in self._config.control_track.segments:
            if seg.start_s < cut and int(np.ceil(seg.start_s * fps - 1e-9)) < first:
                segs.append(Segment(seg.start_s, min(seg.end_s, cut), seg.constraints))
        for k, (frame, constraints) in enumerate(self._switches):
            stop = self._switches[k + 1][0] if k + 1 < len(self._switches) else n
            if constraints and frame < min(stop, n):
                segs.append(Segment(_boundary_s(frame, fps), _boundary_s(min(stop, n), fps), constraints))
        return ControlTrack(tuple(segs))

    def _make_result(self) -> SynthesisResult:
        db, n = self._db, self._n_final
        assert n is not None
        search = self._search.result(fps=self._fps)
        track = self._track()
        config = self._config.with_control(track)
        masks = self._search.masks
        plan = SearchPlan(
            query=np.ascontiguousarray(self._zscore.apply(stack_audio_features(self._m.view[:n])), dtype=np.float32),
            config=self._search.config,
            control=track,
            masks=np.stack(masks) if masks else None,
            step_mask_index=np.asarray(self._step_masks, dtype=np.int64),
            exclude=self._search.exclude,
        )
        knn = Motion.from_flat(self._knn.view.copy(), db.fps, db.joint_presence)
        out = Motion.from_flat(self._out.view.copy(), db.fps, db.joint_presence)
        refined = None
        if self._refiner is not None:
            refined = Motion.from_flat(self._refined.view.copy(), db.fps, db.joint_presence)
        return SynthesisResult(
            motion=out if refined is None else refined,
            knn_motion=knn,
            search=search,
            audio=self._audio.view.copy(),
            config=config,
            database=self._stages.database_label,
            source=self._name,
            refined_motion=refined,
            refiner=self._stages.refiner_record,
            plan=plan,
            one_skeleton=self._stages.one_skeleton,
        )
