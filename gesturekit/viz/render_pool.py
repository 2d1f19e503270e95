"""Many frames of a scene on every core: the rendering processes behind the MP4 videos.

:func:`render_frames` gives a clip's frames in order, exactly those of
:meth:`gesturekit.viz.render.SkeletonScene.render_frame`. A short clip renders
in the calling process; a long one in several rendering processes
(:mod:`gesturekit.viz.render_worker`), each with its own offscreen window,
taking turns by chunks of :data:`CHUNK_FRAMES` frames. The scene reaches them
as a job file (:func:`_write_job`, read back by :func:`scene_from_job`), the
frames come back as raw RGB through pipes.
"""

from __future__ import annotations

import json
import os
import queue
import subprocess
import sys
import tempfile
import threading
from collections.abc import Generator, Sequence
from pathlib import Path
from typing import IO

import numpy as np

from .._arguments import checks_arguments
from ..character.target import Character
from ..errors import ConfigError, GestureKitError
from ..motion import Motion
from ..skeleton import JointPresence
from .character_user import character_arrays, character_from_arrays
from .render import RenderStyle, SkeletonScene, check_character, check_scene

__all__ = ["CHUNK_FRAMES", "PARALLEL_MIN_FRAMES", "default_workers", "render_frames"]

#: Frames one rendering process renders in a row before the next process's turn (2 s at 15 fps).
CHUNK_FRAMES = 30

#: With ``workers=None``, clips shorter than this render in the calling process: starting
#: the rendering processes (about a second) would cost more than it saves.
PARALLEL_MIN_FRAMES = 150

# the most frame bytes waiting in the parent for their turn, all processes together
_BUFFER_BYTES = 256 << 20


@checks_arguments
def default_workers() -> int:
    """The cores this process may run on: the number of rendering processes used by default."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


@checks_arguments
def render_frames(
    motions: Sequence[Motion],
    *,
    labels: Sequence[str] | None = None,
    resolution: tuple[int, int] = (640, 480),
    style: RenderStyle | None = None,
    workers: int | None = None,
    character: Character | None = None,
) -> Generator[np.ndarray, None, None]:
    """Every frame of a scene's clip, in order, rendered on several cores.

    The frames are exactly those of :meth:`SkeletonScene.render_frame` for
    frames ``0 .. n_frames - 1``, whichever number of processes renders them.
    With more than one worker, each is a separate Python process
    (:mod:`gesturekit.viz.render_worker`) with its own offscreen window that
    renders every ``workers``-th chunk of :data:`CHUNK_FRAMES` frames; the
    frames come back through pipes and are handed out in order, at most about
    256 MB of them waiting at any time.

    Parameters
    ----------
    motions : sequence of Motion
        One or two motions of equal fps, as for :class:`SkeletonScene`.
    labels : sequence of str, optional
        One label per motion.
    resolution : (int, int)
        Width and height of the pictures, pixels.
    style : RenderStyle, optional
        Look of the scene.
    workers : int, optional
        Rendering processes; 1 renders in this process. By default one per
        core (:func:`default_workers`), or this process alone for clips
        shorter than :data:`PARALLEL_MIN_FRAMES` frames.
    character : Character, optional
        A user's character every motion is retargeted onto (see :class:`SkeletonScene`); the rendering
        processes receive it through the job file and retarget alike.

    Returns
    -------
    iterator of np.ndarray
        One picture per frame of the longest motion, each shape
        (height, width, 3), uint8 RGB, top row first. Close the iterator (or
        exhaust it) to stop the rendering processes early.

    Raises
    ------
    ConfigError
        Bad motions, labels, resolution or ``workers`` (raised by this call,
        before anything is rendered).
    GestureKitError
        A rendering process failed (raised while iterating; its message is included).
    """
    motions = list(motions)
    style = style or RenderStyle()
    check_scene(motions, labels, resolution)
    check_character(character, style)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1):
        raise ConfigError(f"workers must be a positive whole number, got {workers!r}")
    n_frames = max(m.n_frames for m in motions)
    chunks = -(-n_frames // CHUNK_FRAMES)
    if workers is None:
        workers = default_workers() if n_frames >= PARALLEL_MIN_FRAMES else 1
    workers = min(int(workers), chunks)
    resolution = (int(resolution[0]), int(resolution[1]))
    if workers == 1:
        return _serial_frames(motions, labels, resolution, style, character)
    return _parallel_frames(motions, labels, resolution, style, workers, character)


def _serial_frames(
    motions: list[Motion],
    labels: Sequence[str] | None,
    resolution: tuple[int, int],
    style: RenderStyle,
    character: Character | None,
) -> Generator[np.ndarray, None, None]:
    with SkeletonScene(motions, labels=labels, resolution=resolution, style=style, character=character) as scene:
        for frame in range(scene.n_frames):
            yield scene.render_frame(frame)


def _write_job(
    path: Path,
    motions: list[Motion],
    labels: Sequence[str] | None,
    resolution: tuple[int, int],
    style: RenderStyle,
    character: Character | None = None,
) -> None:
    spec = {
        "fps": float(motions[0].fps),
        "labels": None if labels is None else [str(x) for x in labels],
        "resolution": list(resolution),
        "style": style.to_json(),
        # which joints exist, per motion: the rendering processes draw what the parent would
        "joints": [None if m.joints is None else m.joints.to_list() for m in motions],
    }
    arrays = {f"motion{i}": np.asarray(m.positions) for i, m in enumerate(motions)}
    arrays["spec"] = np.array(json.dumps(spec))
    if character is not None:
        arrays.update(character_arrays(character))
    np.savez(path, allow_pickle=False, **arrays)


def scene_from_job(path: str) -> SkeletonScene:
    """The scene a job file written by :func:`_write_job` describes (in a rendering process)."""
    with np.load(path, allow_pickle=False) as data:
        spec = json.loads(str(data["spec"]))
        positions = [data[f"motion{i}"] for i in range(2) if f"motion{i}" in data.files]
        character = character_from_arrays(data)
    style = RenderStyle.from_json(spec["style"])
    joints = spec.get("joints") or [None] * len(positions)
    motions = [
        Motion(p, spec["fps"], None if j is None else JointPresence(tuple(j))) for p, j in zip(positions, joints)
    ]
    return SkeletonScene(
        motions, labels=spec["labels"], resolution=tuple(spec["resolution"]), style=style, character=character
    )


def _parallel_frames(
    motions: list[Motion],
    labels: Sequence[str] | None,
    resolution: tuple[int, int],
    style: RenderStyle,
    workers: int,
    character: Character | None = None,
) -> Generator[np.ndarray, None, None]:
    width, height = resolution
    size = width * height * 3
    n_frames = max(m.n_frames for m in motions)
    waiting = max(2, min(CHUNK_FRAMES, _BUFFER_BYTES // (size * workers)))
    stop = threading.Event()

    def read(stream: IO[bytes], out: queue.Queue[bytes | None]) -> None:
        """Move one process's frames from its pipe into its queue, then None (end or failure)."""

        def put(item: bytes | None) -> bool:
            while not stop.is_set():
                try:
                    out.put(item, timeout=0.1)
                    return True
                except queue.Full:
                    continue
            return False

        try:
            while True:
                data = stream.read(size)
                if len(data) < size or not put(data):
                    break
        finally:
            put(None)

    # the package this module belongs to, first on the path: the processes render with this same code
    root = str(Path(__file__).resolve().parents[2])
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([root] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    # one rasteriser thread per process (Mesa's llvmpipe): the processes are the parallelism
    env.setdefault("LP_NUM_THREADS", "1")
    with tempfile.TemporaryDirectory(prefix="gesturekit-render-") as tmp:
        job = Path(tmp) / "job.npz"
        _write_job(job, motions, labels, resolution, style, character)
        procs: list[subprocess.Popen[bytes]] = []
        streams: list[IO[bytes]] = []
        queues: list[queue.Queue[bytes | None]] = []
        threads: list[threading.Thread] = []
        logs: list[IO[bytes]] = []
        try:
            for k in range(workers):
                log = open(Path(tmp) / f"worker{k}.log", "w+b")
                logs.append(log)
                cmd = [
                    sys.executable,
                    "-m",
                    "gesturekit.viz.render_worker",
                    str(job),
                    str(k),
                    str(workers),
                    str(CHUNK_FRAMES),
                ]
                proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=log, env=env)
                procs.append(proc)
                assert proc.stdout is not None  # stdout=PIPE
                streams.append(proc.stdout)
                queues.append(queue.Queue(maxsize=waiting))
                threads.append(threading.Thread(target=read, args=(streams[k], queues[k]), daemon=True))
                threads[k].start()
            for frame in range(n_frames):
                k = (frame // CHUNK_FRAMES) % workers
                data = queues[k].get()
                if data is None:
                    code = procs[k].wait()
                    logs[k].seek(0)
                    message = logs[k].read().decode("utf-8", "replace").strip()[-2000:] or "no message"
                    raise GestureKitError(
                        f"a rendering process stopped at frame {frame} of {n_frames} (exit code {code}): {message}"
                    )
                yield np.frombuffer(data, dtype=np.uint8).reshape(height, width, 3)
        finally:
            stop.set()
            for proc in procs:
                if proc.poll() is None:
                    proc.kill()
                proc.wait()
            for thread in threads:
                thread.join()
            for stream in (*streams, *logs):
                stream.close()
