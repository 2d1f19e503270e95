"""The Live page's engine: microphone audio in, resampled and synthesised in a background thread.

The browser's microphone reaches the server through streamlit-webrtc, whose audio
sink hands every received frame (20 ms of 48 kHz stereo, decoded from the browser's
Opus stream), in order, to :meth:`LiveStage.on_frame` on the transport's event loop.
:meth:`LiveSession.on_frame` only turns the frame into mono samples and queues them
with the moment they arrived, so the transport never waits; a worker thread
resamples them to 16 kHz with a streaming soxr filter (the same filter as
:func:`gesturekit.datasets.audio.resample`, one chunk at a time) and pushes them
into a :class:`gesturekit.live.LiveSynthesizer`, keeping the frames of motion it
returns. Control switches travel through the same queue, so a switch takes effect
after the speech that arrived before it.

The page asks :meth:`LiveSession.view` several times a second what to draw: the
newest frame determined, and how long ago its speech was heard. A step's frames
arrive together, once the speech a step's feature looks ahead to has arrived; the
newest is the step's last, so it is drawn about a step sooner than its first would be.
"""

from __future__ import annotations

import json
import os
import queue
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gesturekit.database import MatchingDatabase
from gesturekit.errors import ConfigError, GestureKitError
from gesturekit.live import LiveSynthesizer
from gesturekit.motion import AUDIO_SR
from gesturekit.synthesis import SynthesisConfig, SynthesisResult

__all__ = [
    "CONTROLS",
    "FilePlayer",
    "ICE_SERVERS_ENV",
    "NO_ICE_SERVERS",
    "LiveSession",
    "LiveStage",
    "LiveView",
    "mono_samples",
    "rtc_configuration",
]

#: The page's control buttons: label -> the constraint held from the next step on (None: free).
CONTROLS: dict[str, str | None] = {
    "Free": None,
    "Left hand high": "left_hand=high",
    "Left hand low": "left_hand=low",
    "Right hand high": "right_hand=high",
    "Right hand low": "right_hand=low",
    "Both hands high": "both_hands=high",
    "Slow": "speed=slow",
    "Fast": "speed=fast",
    "Symmetric": "symmetry=symmetric",
    "Asymmetric": "symmetry=asymmetric",
    "Narrow": "width=narrow",
    "Wide": "width=wide",
}
#: WebRTC configuration with no STUN/TURN server: on one machine (127.0.0.1) the browser and the
#: server find each other through their local addresses, and nothing outside is contacted.
NO_ICE_SERVERS: dict[str, Any] = {"iceServers": []}
#: The environment variable naming STUN/TURN servers for serving the Live page to other machines:
#: a JSON list of RTCIceServer objects, e.g. ``[{"urls": ["stun:stun.example.org:3478"]}]``.
ICE_SERVERS_ENV = "GESTUREKIT_ICE_SERVERS"


def rtc_configuration(environ: Mapping[str, str] | None = None) -> dict[str, Any]:
    """The WebRTC configuration of the Live page: :data:`NO_ICE_SERVERS` unless
    ``$GESTUREKIT_ICE_SERVERS`` names STUN/TURN servers (a JSON list of ``{"urls": ..., "username":
    ..., "credential": ...}``), which browser and server then both use.

    Raises
    ------
    ConfigError
        The variable is not such a JSON list.
    """
    text = (os.environ if environ is None else environ).get(ICE_SERVERS_ENV, "").strip()
    if not text:
        return dict(NO_ICE_SERVERS)
    try:
        servers = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(f"${ICE_SERVERS_ENV} is not JSON ({exc.msg} at character {exc.pos})") from None
    if not isinstance(servers, list) or not all(isinstance(x, dict) and "urls" in x for x in servers):
        raise ConfigError(
            f"${ICE_SERVERS_ENV} must be a JSON list of servers, each with its urls, "
            'e.g. [{"urls": ["stun:stun.example.org:3478"]}]'
        )
    return {"iceServers": servers}


def mono_samples(data: np.ndarray, *, fmt: str, planar: bool, channels: int) -> np.ndarray:
    """An audio frame's samples as mono float32 in [-1, 1].

    Parameters
    ----------
    data : np.ndarray
        ``av.AudioFrame.to_ndarray()``: shape (channels, n) when planar, (1, n * channels)
        interleaved when packed.
    fmt : str
        The sample format's name (``"s16"``, ``"s16p"``, ``"flt"``, ``"fltp"``, ``"s32"``...).
    planar : bool
    channels : int

    Returns
    -------
    np.ndarray, shape (n,), float32
    """
    a = np.asarray(data)
    x = a.reshape(channels, -1) if planar else a.reshape(-1, channels).T
    if fmt.startswith("s16"):
        x = x.astype(np.float32) / 32768.0
    elif fmt.startswith("s32"):
        x = x.astype(np.float32) / 2147483648.0
    elif fmt.startswith(("flt", "dbl")):
        x = x.astype(np.float32)
    else:
        raise ConfigError(f"the microphone sends samples as {fmt!r}, which the Live page does not read")
    return x.mean(axis=0).astype(np.float32)


@dataclass(frozen=True)
class LiveView:
    """What to draw now.

    Attributes
    ----------
    frame : int
        Index of the frame to draw: the newest determined.
    positions : np.ndarray, shape (55, 3)
        Its joint positions, metres.
    frames : int
        Frames of motion available.
    speech_s : float
        Seconds of speech received.
    latency_s : float
        From the moment the frame's speech was heard (its sample's arrival at the server,
        less the time later samples of its packet took to be spoken) to now.
    algorithmic_s : float
        Speech time the synthesis needs beyond a frame before it is determined.
    compute_s : float
        The latest push's compute time (resample, search), seconds.
    control : str or None
        The control held now.
    t0 : float
        Wall-clock time (``time.time()``) at which the first sample was heard.
    """

    frame: int
    positions: np.ndarray
    frames: int
    speech_s: float
    latency_s: float
    algorithmic_s: float
    compute_s: float
    control: str | None
    t0: float


class LiveSession:
    """One performance: the microphone's audio in, motion frames out, in a worker thread.

    Parameters
    ----------
    db : MatchingDatabase
    config : SynthesisConfig, optional
    name : str
        The speech's name in the result.
    control : str, optional
        The control held from the start (a constraint such as ``"left_hand=high"``).
    clock : callable
        Wall-clock seconds (``time.time``); tests give their own.
    """

    def __init__(
        self,
        db: MatchingDatabase,
        *,
        config: SynthesisConfig | None = None,
        name: str = "live",
        control: str | None = None,
        clock: Callable[[], float] = time.time,
    ) -> None:
        #: The database the performance is synthesised with (the sidebar may change meanwhile).
        self.db = db
        self._synth = LiveSynthesizer(db, config=config, name=name)
        if control is not None:
            self._synth.set_control(control)
        self._fps = float(db.fps)
        self._clock = clock
        self._queue: queue.Queue[tuple[str, Any]] = queue.Queue()
        self._lock = threading.Lock()
        self._frames: list[np.ndarray] = []
        self._ends: list[float] = []  # seconds of speech received at the end of each chunk
        self._arrived: list[float] = []  # ... and when that chunk arrived
        self._resampler: Any = None
        self._rate = 0
        self._control = control
        self._compute_s = 0.0
        self._error: str | None = None
        self._result: SynthesisResult | None = None
        self._closed = False
        self._worker = threading.Thread(target=self._work, name="gesturekit-live", daemon=True)
        self._worker.start()

    # --- fed by the transport's thread -------------------------------------------------------
    def on_frame(self, frame: Any) -> Any:
        """The audio callback: queue a PyAV ``AudioFrame``'s samples as mono; returns the frame."""
        fmt = frame.format
        try:
            samples = mono_samples(
                frame.to_ndarray(), fmt=fmt.name, planar=bool(fmt.is_planar), channels=len(frame.layout.channels)
            )
        except ConfigError as exc:  # said on the page (error); the transport goes on
            self._error = self._error or str(exc)
            return frame
        self.feed(samples, int(frame.sample_rate))
        return frame

    def feed(self, samples: np.ndarray, rate: int, *, arrived: float | None = None) -> None:
        """Queue mono samples at ``rate`` Hz that arrived at ``arrived`` (wall clock; default now)."""
        if not self._closed:
            when = arrived if arrived is not None else self._clock()
            self._queue.put(("audio", (np.asarray(samples, np.float32), int(rate), when)))

    # --- called by the page --------------------------------------------------------------------
    def set_control(self, constraint: str | None) -> None:
        """Hold ``constraint`` (None: free) from the speech received so far on."""
        if not self._closed:
            self._control = constraint
            self._queue.put(("control", constraint))

    @property
    def control(self) -> str | None:
        """The control asked for last."""
        return self._control

    @property
    def error(self) -> str | None:
        """Why the synthesis stopped, when it failed (a message for the page); else None."""
        return self._error

    def wait(self, timeout: float = 300.0) -> bool:
        """Block until everything queued so far has been synthesised; False if ``timeout`` (s) passed first."""
        done = threading.Event()
        self._queue.put(("mark", done))
        return done.wait(timeout)

    def view(self) -> LiveView | None:
        """The newest frame and its latency; None before the first frame."""
        with self._lock:
            if not self._frames:
                return None
            n, ends, arrived = len(self._frames), np.asarray(self._ends), np.asarray(self._arrived)
            now = self._clock()
            heard0 = arrived[0] - ends[0]
            delay = self._synth.algorithmic_delay_s
            frame = n - 1
            positions = self._frames[frame]
            speech_s = float(ends[-1])
        at = frame / self._fps  # the frame's speech time, seconds
        i = min(int(np.searchsorted(ends, at, side="right")), len(ends) - 1)
        heard = arrived[i] - (ends[i] - at)
        return LiveView(
            frame=frame,
            positions=positions,
            frames=n,
            speech_s=speech_s,
            latency_s=float(now - heard),
            algorithmic_s=float(delay),
            compute_s=self._compute_s,
            control=self._control,
            t0=float(heard0),
        )

    def stop(self, timeout: float = 300.0) -> SynthesisResult:
        """The end of the speech: synthesise what is queued, the rest, and return the whole performance.

        Raises
        ------
        GestureKitError
            The synthesis failed, or too little speech arrived (under one frame).
        """
        if self._result is not None:
            return self._result
        self._closed = True
        done = threading.Event()
        self._queue.put(("stop", done))
        if not done.wait(timeout):
            raise GestureKitError(f"the live synthesis did not finish within {timeout:g} s")
        if self._error is not None:
            raise GestureKitError(self._error)
        assert self._result is not None
        return self._result

    # --- the worker thread ---------------------------------------------------------------------
    def _work(self) -> None:
        while True:
            kind, item = self._queue.get()
            try:
                if kind == "audio":
                    if self._error is None:
                        self._push(*item)
                elif kind == "control":
                    if self._error is None:
                        self._synth.set_control(item)
                elif kind == "mark":
                    item.set()
                elif kind == "stop":
                    try:
                        if self._error is None:
                            self._finish()
                    except Exception as exc:  # noqa: BLE001  (recorded before stop() is woken, which reads it)
                        self._error = _failure(exc)
                    finally:
                        item.set()
                    return
            except Exception as exc:  # noqa: BLE001  (shown on the page; the thread must not die silently)
                self._error = _failure(exc)

    def _resample(self, samples: np.ndarray, rate: int, *, last: bool = False) -> np.ndarray:
        import soxr  # a dependency of librosa

        if rate == AUDIO_SR and self._resampler is None:
            return samples
        if self._resampler is None or rate != self._rate:
            tail = self._flush()
            self._resampler, self._rate = soxr.ResampleStream(rate, AUDIO_SR, 1, dtype="float32", quality="HQ"), rate
            return np.concatenate([tail, self._resampler.resample_chunk(samples, last=last)])
        return np.asarray(self._resampler.resample_chunk(samples, last=last), np.float32)

    def _flush(self) -> np.ndarray:
        if self._resampler is None:
            return np.zeros(0, np.float32)
        tail = np.asarray(self._resampler.resample_chunk(np.zeros(0, np.float32), last=True), np.float32)
        self._resampler = None
        return tail

    def _push(self, samples: np.ndarray, rate: int, arrived: float) -> None:
        t = time.perf_counter()
        x = self._resample(samples, rate)
        frames = self._synth.push(x)
        compute = time.perf_counter() - t
        with self._lock:
            # counted in the speech as it came (the resampler's output lags it by its filter)
            self._ends.append((self._ends[-1] if self._ends else 0.0) + len(samples) / rate)
            self._arrived.append(arrived)
            self._frames.extend(frames)
            if len(frames):
                self._compute_s = compute

    def _finish(self) -> None:
        tail = self._flush()
        if len(tail):
            self._synth.push(tail)
        with self._lock:
            self._frames.extend(self._synth.finish())
        self._result = self._synth.result()


class LiveStage:
    """A user's microphone across the page's runs: a :class:`LiveSession` begins with the first
    audio frame after Start and ends with Stop.

    The transport calls :meth:`on_frame` on its own thread; the page calls :meth:`configure`
    on every run (what the next performance uses), :meth:`set_control` for the control
    buttons (before or during a performance), :meth:`stop` for Stop, and :meth:`rearm`
    once the browser's stream is off, so that frames still arriving after a Stop (the
    microphone takes a moment to close) do not begin another performance.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.session: LiveSession | None = None
        self._armed = True
        self._make: Callable[[str | None], LiveSession] | None = None
        self.control: str | None = None

    def configure(self, make: Callable[[str | None], LiveSession]) -> None:
        """What begins the next performance: a callable that takes the control held from the
        start (see :meth:`set_control`) and returns a new :class:`LiveSession`."""
        self._make = make

    def set_control(self, constraint: str | None) -> None:
        """Hold ``constraint`` (None: free) in the current performance from now on, and from the
        start of the next."""
        with self._lock:
            self.control = constraint
            session = self.session
        if session is not None:
            session.set_control(constraint)

    def on_frame(self, frame: Any) -> Any:
        """The audio callback of the transport (see :meth:`LiveSession.on_frame`)."""
        with self._lock:
            if self.session is None:
                if not self._armed or self._make is None:
                    return frame
                self.session = self._make(self.control)
            session = self.session
        return session.on_frame(frame)

    def begin(self) -> LiveSession | None:
        """The current performance, begun now if there is none (None when a Stop awaits :meth:`rearm`)."""
        with self._lock:
            if self.session is None and self._armed and self._make is not None:
                self.session = self._make(self.control)
            return self.session

    def stop(self) -> tuple[SynthesisResult, MatchingDatabase] | None:
        """End the performance: its whole result and the database it was made with, or None when
        none was running."""
        with self._lock:
            session, self.session, self._armed = self.session, None, False
        return None if session is None else (session.stop(), session.db)

    def rearm(self) -> None:
        """The browser's stream is off: the next frames begin a new performance."""
        with self._lock:
            self._armed = True


class FilePlayer:
    """Speech from a file streamed into a :class:`LiveStage` in real time, as a microphone sends it.

    A thread hands the stage's performance one :data:`CHUNK_S` chunk of samples each time its
    moment comes (the file's time since :meth:`start`), through :meth:`LiveSession.feed`: the
    same path, queue, resampling and synthesis as the microphone's frames. For demos without a
    microphone, and for tests.

    Parameters
    ----------
    stage : LiveStage
        Where the performance runs (begun by the first chunk).
    samples : np.ndarray, shape (n,)
        Mono speech, float32 in [-1, 1].
    rate : int
        Its sample rate, Hz.
    """

    #: Seconds of speech handed over at a time (a microphone's WebRTC frame is 20 ms).
    CHUNK_S = 0.02

    def __init__(
        self,
        stage: LiveStage,
        samples: np.ndarray,
        rate: int,
        *,
        clock: Callable[[], float] = time.monotonic,
        wait: Callable[[float], bool] | None = None,
    ) -> None:
        x = np.asarray(samples, dtype=np.float32).ravel()
        if x.size == 0 or int(rate) <= 0:
            raise ConfigError("the speech file holds no sound to play")
        self._stage, self._x, self._rate, self._clock = stage, x, int(rate), clock
        self._stopped = threading.Event()
        self._wait = wait or self._stopped.wait
        self._sent = 0
        self._thread: threading.Thread | None = None

    @property
    def duration_s(self) -> float:
        """Seconds of speech in the file."""
        return self._x.size / self._rate

    @property
    def position_s(self) -> float:
        """Seconds of speech handed over so far."""
        return self._sent / self._rate

    @property
    def playing(self) -> bool:
        """Started, and not yet at the file's end nor stopped."""
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> None:
        """Begin streaming (once)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="gesturekit-live-file", daemon=True)
            self._thread.start()

    def stop(self) -> None:
        """Stop streaming; what was handed over stays in the performance."""
        self._stopped.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5)

    def _run(self) -> None:
        n = max(1, int(round(self.CHUNK_S * self._rate)))
        t0 = self._clock()
        for a in range(0, self._x.size, n):
            due = t0 + a / self._rate - self._clock()
            if due > 0 and self._wait(due):
                return  # stopped while waiting
            if self._stopped.is_set():
                return
            session = self._stage.begin()
            if session is None:
                return
            session.feed(self._x[a : a + n], self._rate)
            self._sent = min(a + n, self._x.size)


def _failure(exc: Exception) -> str:
    """What the page says of a failed push or Stop: a user error's own message, else what failed."""
    if isinstance(exc, GestureKitError):
        return str(exc)
    return f"the live synthesis failed: {type(exc).__name__}: {exc}"
