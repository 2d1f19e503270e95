"""MP4 render speed: 82 s of speech, k-NN and refined side by side, as the app renders it.

Synthesizes the speech on a small generated demo database (not timed), then renders the
MP4 the Synthesize page renders (640x480, both motions side by side, the speech as
soundtrack) twice in one run: in the earlier capsule look (``RenderStyle(look="capsules")``)
and as the page's character (the default look), both on every core
(:func:`gesturekit.viz.render_pool.render_frames`; ``--workers 1`` for one process).
Prints the wall time and frames per second of each, the character's speed over the
capsules', the CPU seconds the rendering processes and the encoder spent together, and
the load average (other work on the machine slows both).

The speech is the shared BEAT recording ``../shared/data/speech/beat_lawrence_0_19_19.wav``
(82 s) when present, else 82 s of the generated speaker.

With ``--character FILE`` a third MP4 is rendered with the motions retargeted onto a user's character (a
VRM is drawn toon-shaded, in its MToon), and its speed is printed against our character's.

Usage: python bench/bench_video.py [--seconds 82] [--resolution 640x480] [--workers N] [--character FILE]
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BEAT = REPO.parent / "shared" / "data" / "speech" / "beat_lawrence_0_19_19.wav"


def _machine() -> str:
    mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    return f"{os.cpu_count()} cores, {mem:.0f} GiB, {platform.machine()}"


def _cpu_seconds() -> float:
    """CPU time of this process and its finished children (rendering processes, ffmpeg)."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=82.0, help="speech length when BEAT is absent")
    parser.add_argument("--resolution", default="640x480", help="video size, WIDTHxHEIGHT")
    parser.add_argument("--workers", type=int, default=None, help="rendering processes (default: every core)")
    parser.add_argument("--character", type=Path, default=None, help="also render on a user's character file")
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.resolution.lower().split("x"))

    from gesturekit.datasets.audio import load_audio
    from gesturekit.datasets.synthetic import generate_demo_take
    from gesturekit.demo import build_demo_database
    from gesturekit.export.video import render_video
    from gesturekit.refine import open_refiner
    from gesturekit.synthesis import synthesize
    from gesturekit.viz.render import RenderStyle
    from gesturekit.viz.render_pool import default_workers

    print(f"machine: {_machine()}")
    with tempfile.TemporaryDirectory(prefix="gesturekit-bench-video-") as tmp:
        tmp = Path(tmp)
        db = build_demo_database(tmp / "db", minutes=4)
        if BEAT.is_file():
            audio, name = load_audio(BEAT), BEAT.name
        else:
            take, _ = generate_demo_take(seconds=args.seconds, seed=7, name="speech")
            audio, name = take.audio, f"{args.seconds:g} s of the generated speaker"
        result = synthesize(audio, db=db, refiner=open_refiner("demo"))
        left, right = result.knn_motion, result.refined_motion  # what the page shows side by side
        print(
            f"speech: {name}, {len(result.audio) / 16000:.1f} s; {result.n_frames} frames side by side, "
            f"{width}x{height}"
        )
        workers = args.workers or default_workers()
        runs = {}
        character = None
        if args.character is not None:
            from gesturekit.character.user import read_character

            character = read_character(args.character)
        looks = ("capsules", "character") + (() if character is None else (args.character.name,))
        for look in looks:
            out = tmp / "user.mp4" if look == getattr(args.character, "name", None) else tmp / f"{look}.mp4"
            load = os.getloadavg()[0]
            cpu, t0 = _cpu_seconds(), time.perf_counter()
            render_video(
                out,
                left,
                side_by_side=right,
                audio=result.audio,
                labels=("k-NN", "k-NN + refiner"),
                resolution=(width, height),
                workers=workers,
                style=RenderStyle(look="capsules" if look == "capsules" else "character"),
                character=character if look not in ("capsules", "character") else None,
            )
            wall, cpu = time.perf_counter() - t0, _cpu_seconds() - cpu
            frames = round(len(result.audio) / 16000 * left.fps)
            runs[look] = frames / wall
            print(
                f"{look}: {wall:.1f} s, {frames / wall:.1f} frames/s, {cpu:.1f} CPU s, {workers} workers "
                f"(load average before: {load:.1f})"
            )
        print(f"character vs capsules: {runs['character'] / runs['capsules']:.2f}x the frames per second")
        if character is not None:
            mine = runs[args.character.name] / runs["character"]
            print(f"{args.character.name} vs our character: {mine:.2f}x the frames per second")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
