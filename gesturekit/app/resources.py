"""What the app loads once per server and shares between sessions, and prepares in the background.

Databases are opened once per process with ``st.cache_resource``, keyed by
their folder and the modification time of their ``database.json`` (a rebuilt
database is opened anew); the opened object is shared by all sessions and
must be treated as read-only. Refiners are cached the same way (keyed by
their ``config.json``). The demo database is built on first use, with a
progress bar. Searches and refiners are warmed up in background threads so
that a user's first run does not wait for compiled code, torch or first-use
costs; a failure there only goes to the server log (logger ``gesturekit.app``).

Environment. ``GESTUREKIT_HOME`` moves gesturekit's own folder (see
:mod:`gesturekit.paths`); ``GESTUREKIT_DEMO_MINUTES`` sets the minutes of the
demo database the app builds on a machine that has none (default
:data:`gesturekit.demo.DEMO_MINUTES`; smaller is faster, for tests and
trials).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import threading
from collections.abc import AsyncIterator
from pathlib import Path
from typing import TYPE_CHECKING

import streamlit as st

from gesturekit.app.display import allowed, escape_markdown, warnings_shown
from gesturekit.database import MatchingDatabase
from gesturekit.demo import DEMO_MINUTES, build_demo_database
from gesturekit.errors import ConfigError, collect_warnings
from gesturekit.paths import default_database_path
from gesturekit.synthesis import prepare_search

if TYPE_CHECKING:
    import numpy as np

    from gesturekit.refine.infer import Refiner

__all__ = [
    "DEMO_MINUTES_ENV",
    "build_lock",
    "check_refiner",
    "default_refiner",
    "demo_minutes",
    "ensure_demo_database",
    "example_audio",
    "load_database",
    "load_refiner",
    "rebuild_demo",
    "server_lifespan",
    "warm_up",
    "warm_up_refiner",
    "warm_up_search",
]

LOG = logging.getLogger("gesturekit.app")
DEMO_MINUTES_ENV = "GESTUREKIT_DEMO_MINUTES"


def demo_minutes() -> float:
    """Minutes of the demo database the app builds: ``$GESTUREKIT_DEMO_MINUTES`` or the default.

    Raises
    ------
    ConfigError
        The variable is set but is not a positive number.
    """
    raw = os.environ.get(DEMO_MINUTES_ENV, "").strip()
    if not raw:
        return float(DEMO_MINUTES)
    try:
        minutes = float(raw)
    except ValueError:
        minutes = float("nan")
    if not minutes > 0 or minutes == float("inf"):
        raise ConfigError(f"{DEMO_MINUTES_ENV} must be a positive number of minutes, got {raw!r}")
    return minutes


@st.cache_resource(show_spinner=False)
def build_lock() -> threading.Lock:
    """The lock of database builds: one at a time in this server (sessions share the process,
    and a build's temporary folder name)."""
    return threading.Lock()


def ensure_demo_database() -> Path:
    """Build the demo database at the default path if it is not there, showing a progress bar.

    Nothing is downloaded: the demo speaker is generated (deterministically)
    and its database built, which takes about a second per minute of demo.

    Returns
    -------
    Path
        The default database folder (:func:`gesturekit.paths.default_database_path`).
    """
    path = default_database_path()
    if (path / "database.json").is_file():
        return path
    minutes = demo_minutes()
    with build_lock():
        if (path / "database.json").is_file():  # another session built it meanwhile
            return path
        note = st.empty()
        note.info(
            f"No database yet at {escape_markdown(path)}: building the generated demo speaker's database "
            f"({minutes:g} minutes of synthetic speech and motion, no download)."
        )
        bar = st.progress(0.0, text="generating the demo speaker…")

        def progress(done: float, total: float) -> None:
            frac = min(1.0, done / total) if total > 0 else 1.0
            stage = "generating the demo speaker" if frac < 0.5 else "computing features and clips"
            bar.progress(frac, text=f"{stage}… {100 * frac:.0f}%")

        with warnings_shown():
            db = build_demo_database(path, minutes=minutes, overwrite=path.exists(), progress=progress)
            # the first run after an install compiles the search: here, not on the user's first Run
            bar.progress(1.0, text="preparing the search (once after an install)…")
            prepare_search(db)
        bar.progress(1.0, text="demo database ready")
        note.success(f"Built the demo database at {escape_markdown(path)} ({minutes:g} minutes of generated speaker).")
    return path


def rebuild_demo(path: Path) -> None:
    """Build the demo database at ``path`` again (over an unreadable one), with a progress bar."""
    with build_lock():
        bar = st.progress(0.0, text="rebuilding the demo database…")
        with warnings_shown():
            build_demo_database(
                path,
                minutes=demo_minutes(),
                overwrite=True,
                progress=lambda done, total: bar.progress(min(1.0, done / total)),
            )


@st.cache_resource(max_entries=8, show_spinner="Opening the database…")
def _open(path: str, stamp: int) -> MatchingDatabase:
    # ``stamp`` (database.json's mtime) is only part of the cache key: a rebuilt database differs
    return MatchingDatabase.load(path)


def load_database(path: str | os.PathLike) -> MatchingDatabase:
    """Open a database folder, once per process and version (cached by path and mtime).

    The returned object is shared by every session: do not modify it.

    Raises
    ------
    DatabaseError
        No database there, or one that cannot be read (the message names the folder).
    """
    path = Path(path).expanduser().resolve()
    return _open(str(path), _stamp(path / "database.json"))  # none: load() raises the precise error


def _stamp(file: Path) -> int:
    """The modification time of ``file`` in ns (a cache key beside the folder), -1 if it cannot be read.

    A failed load is not cached, so -1 never stands for a version that was opened.
    """
    try:
        return file.stat().st_mtime_ns
    except OSError:
        return -1


def _in_background(name: str, *steps) -> threading.Thread:
    """Run ``steps`` (callables) one after the other in a daemon thread named ``name``; returns it started.

    A step that fails is logged to the server log (the user's own run reports it on the
    page) and the next one runs; warnings are kept off the pages.
    """

    def work() -> None:
        for step in steps:
            try:
                with collect_warnings():
                    step()
            except Exception:  # noqa: BLE001
                LOG.warning("a warm-up step failed (%s)", name, exc_info=True)

    thread = threading.Thread(target=work, name=name, daemon=True)
    thread.start()
    return thread


@st.cache_resource(show_spinner="Generating the example speech…", max_entries=4)
def example_audio(label: str) -> np.ndarray:
    """Example speech (a key of :data:`gesturekit.interactive.SPEECH_EXAMPLES`): mono float32 at
    16 kHz, read-only, made once per server and shared by every session."""
    from gesturekit.interactive import example_speech

    audio = example_speech(label)
    audio.setflags(write=False)
    return audio


def _first_use(noise) -> None:
    """Everything a first result needs once per process, run on small inputs: the example
    speech a first visit shows, the speech reader, the figures (plotly builds its validators
    on first use) and the WAV writer.

    ``noise``: a few seconds of mono float32 audio at 16 kHz.
    """

    import numpy as np
    import plotly.io as pio

    from gesturekit import interactive as gs
    from gesturekit.control import empty_segments, segments_frame, track_from_segments
    from gesturekit.datasets.audio import wav_bytes
    from gesturekit.motion import AUDIO_SR, N_JOINTS, Motion
    from gesturekit.viz.figures import waveform_figure, wrist_figure
    from gesturekit.viz.viewer import skeleton_viewer

    example_audio(next(iter(gs.SPEECH_EXAMPLES)))  # what a first visit to Synthesize shows
    audio, _ = gs.read_speech_upload("warm-up.wav", wav_bytes(noise))
    wav_bytes(audio)
    import pyarrow as pa  # what streamlit's tables are sent as: its first import takes most of a second

    pa.Table.from_pandas(segments_frame(track_from_segments(empty_segments())))
    motion = Motion(np.zeros((4, N_JOINTS, 3), np.float32), 15.0)
    skeleton_viewer([motion, motion], labels=["a", "b"])
    for fig in (waveform_figure(audio, AUDIO_SR), wrist_figure([motion, motion], labels=["a", "b"])):
        pio.to_json(fig.to_dict(), validate=False)


@st.cache_resource(show_spinner=False, max_entries=8)
def _warm_up(path: str, stamp: int) -> threading.Thread:
    import numpy as np

    from gesturekit.motion import AUDIO_SR
    from gesturekit.synthesis import SynthesisConfig, synthesize

    db = _open(path, stamp)
    noise = np.random.default_rng(0).normal(0.0, 0.1, 2 * AUDIO_SR).astype(np.float32)
    # what an upload needs first, then what Run needs
    return _in_background(
        "gesturekit-warm-up",
        lambda: _first_use(noise),
        lambda: synthesize(noise, db=db, config=SynthesisConfig(record=1)),
    )


def warm_up_search(db: MatchingDatabase) -> None:
    """Prepare the search of a database in the background, once per server and database.

    The first synthesis with a database builds its search index and loads
    the compiled search code (seconds for a large database); doing that
    while the user is still choosing speech makes their first run as fast
    as the later ones.
    """
    if db.path is None:
        return
    path = Path(db.path).expanduser().resolve()
    stamp = _stamp(path / "database.json")
    if stamp != -1:
        _warm_up(str(path), stamp)


def default_refiner(db: MatchingDatabase) -> str:
    """The refiner folder offered first for ``db``, with the refiner switched on: one trained on
    it (``<db>/refiner``, or the shipped demo refiner for the demo speaker; see
    :func:`gesturekit.refine.refiner_for`, which the command line uses too), else "" (off)."""
    try:
        from gesturekit.refine import refiner_for
    except ImportError:  # a gesturekit without the refiner
        return ""
    found = refiner_for(db)
    return "" if found is None else str(found)


def warm_up(db: MatchingDatabase) -> None:
    """Prepare, in the background and once per server, what a first run with ``db`` needs:
    its search (:func:`warm_up_search`) and its default refiner (:func:`warm_up_refiner`)."""
    warm_up_search(db)
    refiner = default_refiner(db)
    if refiner:
        warm_up_refiner(Path(refiner))


@contextlib.asynccontextmanager
async def server_lifespan(app: object) -> AsyncIterator[None]:
    """The server's start and stop (``st.App``'s lifespan, see ``Home.py``): at start,
    the default database's search and refiner are prepared in the background.

    The default database's search is made ready before the server answers
    (:func:`gesturekit.synthesis.prepare_search`: its compiled code loaded from the
    cache, or compiled on the first start after an install), so that the first result a
    user asks for comes as fast as the later ones. Nothing is built here: a missing demo
    database is built by the first page view, with a progress bar, and its search made
    ready there. A failure is left to the server log.
    """
    # the caches are filled outside any page run here, which streamlit's context lookup
    # would log as a warning for each cached call
    quiet = logging.getLogger("streamlit.runtime.scriptrunner_utils.script_run_context")
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        path = default_database_path()
        if (path / "database.json").is_file():
            db = load_database(path)
            await asyncio.to_thread(prepare_search, db)
            warm_up(db)
    except Exception:  # noqa: BLE001  (the server must start regardless)
        LOG.warning("warm-up at start skipped", exc_info=True)
    finally:
        quiet.setLevel(level)
    yield


@st.cache_resource(max_entries=4, show_spinner="Loading the refiner…")
def _open_refiner(path: str, stamp: int):
    # ``stamp`` (config.json's mtime) is only part of the cache key: a retrained refiner differs
    from gesturekit.refine import load_refiner as load

    return load(path)


def check_refiner(path: str | os.PathLike, db: MatchingDatabase) -> Path:
    """Check a refiner folder against ``db`` without loading it (no torch): its resolved path.

    Starts loading it in the background (see :func:`warm_up_refiner`), so that the
    run that uses it finds it ready.

    Raises
    ------
    GestureKitError
        A folder outside the allowed ones (:func:`allowed`), no refiner there, an unreadable
        ``config.json``, or another feature layout than ``db``'s.
    """
    from gesturekit.refine import check_refiner as check

    _allowed_refiner(path)
    folder = check(path, db)
    warm_up_refiner(folder)
    return folder


@st.cache_resource(show_spinner=False, max_entries=8)
def _warm_refiner(path: str, stamp: int) -> threading.Thread:
    def warm() -> None:
        # torch's import, the files read and a first forward pass (torch picks its kernels for
        # the shapes), into the cached object the runs use
        import numpy as np

        from gesturekit.blend import KEEP_BELOW_HZ, keep_slow

        n = 450  # frames of 30 s of speech
        knn = np.zeros((n, 165), np.float32)
        # as synthesis calls it: the generator, then the k-NN motion's slow content kept
        keep_slow(_open_refiner(path, stamp).refine(knn, np.zeros((n, 28), np.float32)), knn, KEEP_BELOW_HZ)

    return _in_background("gesturekit-warm-refiner", warm)


def warm_up_refiner(path: Path) -> None:
    """Load a refiner (torch, weights) in the background, once per server and version."""
    stamp = _stamp(Path(path) / "config.json")
    if stamp != -1:
        _warm_refiner(str(path), stamp)


def _allowed_refiner(path: str | os.PathLike) -> Path:
    """A typed refiner folder, refused when empty or outside the allowed folders (:func:`allowed`); resolved."""
    if not str(path).strip():
        raise ConfigError("type the folder of a trained refiner, or turn the refiner off")
    return allowed(path, what="refiner folder")


def load_refiner(path: str | os.PathLike, db: MatchingDatabase) -> Refiner:
    """Open a trained refiner folder once per process and version, checked against ``db``.

    The returned object is shared by every session: do not modify it.

    Raises
    ------
    GestureKitError
        A folder outside the allowed ones (:func:`allowed`), no refiner there, an unreadable
        one, or one trained on another feature layout than ``db``'s (the message names the folder).
    """
    path = _allowed_refiner(path)
    refiner = _open_refiner(str(path), _stamp(path / "config.json"))  # none: the loader raises the precise error
    refiner.check_database(db)
    return refiner
