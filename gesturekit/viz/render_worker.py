"""A rendering process: some chunks of a scene's frames, as raw RGB on standard output.

:func:`gesturekit.viz.render_pool.render_frames` starts one of these per core
(``python -m gesturekit.viz.render_worker JOB WORKER WORKERS CHUNK``) so that
a long clip renders on every core while the frames still reach the encoder in
order. ``JOB`` is an ``.npz`` file written by the parent: ``motion0`` (and
``motion1``), positions (frames, 55, 3) in metres, and ``spec``, a JSON text
with the fps, labels, resolution and style. The worker renders chunks
``WORKER, WORKER + WORKERS, ...`` of ``CHUNK`` frames each and writes every
frame as ``height * width * 3`` bytes, top row first, in order. Running it as
its own program (not a ``multiprocessing`` child) means the caller's main
script is never imported again, whatever it is: the command line, a notebook,
the app's server or a user's unguarded script.
"""

from __future__ import annotations

import sys


def main(argv: list[str]) -> int:
    job, worker, workers, chunk = argv[0], int(argv[1]), int(argv[2]), int(argv[3])
    from .._optional import require

    require("pyvista", purpose="rendering")
    from .render_pool import scene_from_job

    scene = scene_from_job(job)
    out = sys.stdout.buffer
    try:
        for start in range(worker * chunk, scene.n_frames, workers * chunk):
            for frame in range(start, min(start + chunk, scene.n_frames)):
                out.write(scene.render_frame(frame).tobytes())
            out.flush()
    except BrokenPipeError:
        return 0  # the parent stopped reading: it has what it needs, or has failed itself
    finally:
        scene.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
