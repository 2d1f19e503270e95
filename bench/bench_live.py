"""Latency benchmark of streaming synthesis (gesturekit.live.LiveSynthesizer).

Streams a speech file in 20 ms chunks through the live synthesiser, each chunk pushed
when a real-time clock says it has been spoken (``--no-pace``: back to back, compute
only), and prints, measured in this one run on this machine:

* the algorithmic delay: how much speech past a motion frame's time had arrived when the
  frame was returned (median and max over the frames returned before the end), beside the
  stated bound (``LiveSynthesizer.algorithmic_delay_s``; target <= 1.0 s with N = 8);
* compute per pushed second of speech (wall time of ``push`` and ``finish``), as a multiple of
  real time (target >= 20x at the paper's scale), and the CPU time of all threads beside it
  (on a machine that others share, wall time counts their load too);
* the delay from a chunk's arrival to its frames being available (median, p95, max over
  the chunks that returned frames), i.e. the time ``push`` takes when it takes a step;

at the demo database and at the paper's scale: a random database of 9,624 clips x 64
frames (the "Oliver" database of the paper, features drawn as in ``bench_search.py``;
poses and attributes repeated from the demo database).

Usage: python bench/bench_live.py [SPEECH.wav] [--seconds 30] [--no-pace] [--scale demo|paper|both]
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_search import M_OLIVER, make_db  # noqa: E402
from machine import describe_machine  # noqa: E402

from gesturekit.database import MatchingDatabase  # noqa: E402
from gesturekit.live import LiveSynthesizer  # noqa: E402
from gesturekit.motion import AUDIO_SR  # noqa: E402
from gesturekit.synthesis import SynthesisConfig  # noqa: E402

CHUNK_MS = 20


def paper_scale(demo: MatchingDatabase, seed: int = 0) -> MatchingDatabase:
    """The demo database grown to 9,624 clips: random z-scored features (as bench_search.py draws
    them), the demo's poses and attributes repeated (the search's work does not depend on them)."""
    P, F, valid = make_db(M_OLIVER, np.random.default_rng(seed))
    rows = np.arange(M_OLIVER) % demo.n_clips
    arrays = dict(demo.arrays)
    arrays.update(P=P, F=F, valid=valid, G=np.asarray(demo.G)[rows], attributes=np.asarray(demo.attributes)[rows])
    meta = dict(demo.meta)
    meta["build"] = {**meta["build"], "label": "paper's scale (random)"}
    return MatchingDatabase(meta=meta, arrays=arrays, stats=demo.stats)


def run(db: MatchingDatabase, audio: np.ndarray, *, segment: int, pace: bool) -> dict:
    """Stream ``audio`` in 20 ms chunks; the figures of one run."""
    live = LiveSynthesizer(db, config=SynthesisConfig(segment=segment))
    chunk = AUDIO_SR * CHUNK_MS // 1000
    frame_delay: list[float] = []  # speech time past each returned frame when it was returned
    arrival: list[float] = []  # chunk arrival -> its frames available, chunks that returned frames
    compute = cpu = 0.0
    start = time.perf_counter()
    for pos in range(0, len(audio), chunk):
        piece = audio[pos : pos + chunk]
        spoken = start + (pos + len(piece)) / AUDIO_SR  # when the chunk's last sample was spoken
        if pace:
            wait = spoken - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
        c0, t0 = time.process_time(), time.perf_counter()
        first = live.frames_out
        frames = live.push(piece)
        t1 = time.perf_counter()
        compute += t1 - t0
        cpu += time.process_time() - c0
        if len(frames):
            arrival.append(t1 - (spoken if pace else t0))
            heard = live.samples_in / AUDIO_SR
            frame_delay.extend(heard - (first + np.arange(len(frames))) / db.fps)
    c0, t0 = time.process_time(), time.perf_counter()
    live.finish()
    compute += time.perf_counter() - t0
    cpu += time.process_time() - c0
    speech_s = len(audio) / AUDIO_SR
    return {
        "stated": live.algorithmic_delay_s,
        "delay": np.asarray(frame_delay),
        "rtf": speech_s / compute,
        "compute_per_s": compute / speech_s,
        "cpu_per_s": cpu / speech_s,
        "arrival": np.asarray(arrival),
        "frames": live.frames_out,
    }


def report(name: str, r: dict, pace: bool) -> None:
    d, a = r["delay"], r["arrival"] * 1e3
    print(f"\n{name}: {r['frames']} frames")
    print(
        f"  algorithmic delay (speech past a frame when returned): median {np.median(d):.3f} s, "
        f"max {d.max():.3f} s; stated bound {r['stated']:.4f} s (target <= 1.0 s), plus up to one "
        f"{CHUNK_MS} ms chunk: a frame is returned by the push whose chunk completes its speech"
    )
    print(
        f"  compute: {r['compute_per_s'] * 1e3:.1f} ms per second of speech = {r['rtf']:.0f}x faster than real time "
        f"(target >= 20x at the paper's scale); CPU time {r['cpu_per_s'] * 1e3:.1f} ms per second (all threads)"
    )
    what = "chunk arrival -> frames available" if pace else "push() taking a step (compute only)"
    print(
        f"  {what}: median {np.median(a):.1f} ms, p95 {np.percentile(a, 95):.1f} ms, max {a.max():.1f} ms "
        f"({len(a)} chunks of {CHUNK_MS} ms returned frames)"
    )


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("speech", nargs="?", help="a speech file (default: the demo speaker, generated)")
    ap.add_argument("--seconds", type=float, default=30.0, help="seconds of demo speech (default 30)")
    ap.add_argument("--segment", type=int, default=8, help="N, frames per search step (default 8, the paper)")
    ap.add_argument("--no-pace", action="store_true", help="push chunks back to back (compute only)")
    ap.add_argument("--scale", choices=("demo", "paper", "both"), default="both")
    args = ap.parse_args(argv)

    from gesturekit.demo import open_default_database

    if args.speech:
        from gesturekit.datasets.audio import load_audio

        audio, source = load_audio(args.speech), Path(args.speech).name
    else:
        from gesturekit.datasets.synthetic import generate_demo_take

        take, _ = generate_demo_take(seconds=args.seconds, seed=2022, name="bench")
        audio, source = take.audio, f"demo speaker, {args.seconds:g} s generated"
    pace = not args.no_pace
    where = describe_machine(accelerator="no GPU used (CPU only)")
    print(f"machine: {where}; numpy {np.__version__}, Python {platform.python_version()}")
    print(
        f"speech: {source} ({len(audio) / AUDIO_SR:.1f} s), {CHUNK_MS} ms chunks, N = {args.segment}, "
        + ("paced by a real-time clock" if pace else "not paced (compute only)")
    )
    demo = open_default_database()
    dbs = []
    if args.scale in ("demo", "both"):
        dbs.append((f"demo database ({demo.n_clips} clips)", demo))
    if args.scale in ("paper", "both"):
        dbs.append((f"paper's scale ({M_OLIVER} clips, random features)", paper_scale(demo)))
    for name, db in dbs:
        run(db, audio[: 3 * AUDIO_SR], segment=args.segment, pace=False)  # warm: compiled loops, caches
        report(name, run(db, audio, segment=args.segment, pace=pace), pace)


if __name__ == "__main__":
    main()
