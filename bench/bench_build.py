"""Feature extraction speed and demo-database build time.

Prints, measured in one run:
- audio features (13 MFCC + log energy on the exact 15 fps grid) as a multiple of real time,
  on 10 minutes of generated speech (and on the ZEGGS take when ../shared/data is present);
- pose features, attributes and clip cutting as a multiple of real time;
- the time to generate and build the demo speaker's database (20 minutes by default).

Usage: python bench/bench_build.py [--minutes 20]
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np


def _machine() -> str:
    mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    return f"{os.cpu_count()} cores, {mem:.0f} GiB, {platform.machine()}, no GPU"


def _best_of(n, fn) -> float:
    best = float("inf")
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=20.0, help="minutes of demo speaker to build")
    args = ap.parse_args()

    from gesturekit.database import take_features
    from gesturekit.datasets.synthetic import generate_demo_takes
    from gesturekit.demo import build_demo_database
    from gesturekit.features import audio_frame_features

    print(f"machine: {_machine()}")
    # the first calls load librosa's filters and plan the FFTs
    audio_frame_features(np.random.default_rng(0).normal(0, 0.1, 16000 * 300).astype(np.float32))

    takes = generate_demo_takes(minutes=10.0, take_seconds=120.0, seed=1)
    audio = np.concatenate([t.audio for t in takes])
    seconds = len(audio) / 16000
    dt = _best_of(3, lambda: audio_frame_features(audio))
    print(f"audio features, {seconds / 60:.0f} min of speech: {dt:.2f} s = {seconds / dt:.0f}x real time")

    zeggs = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "zeggs" / "067_Speech_2_x_1_0.wav"
    if zeggs.is_file():
        from gesturekit.datasets.audio import load_audio

        a = load_audio(zeggs)
        dt = _best_of(3, lambda: audio_frame_features(a))
        print(f"audio features, ZEGGS take ({len(a) / 16000:.1f} s): {dt:.3f} s = {len(a) / 16000 / dt:.0f}x real time")

    t0 = time.perf_counter()
    for t in takes:
        take_features(t)
    dt = time.perf_counter() - t0
    print(
        f"all per-take features (audio, pose, attributes), {seconds / 60:.0f} min: {dt:.2f} s = "
        f"{seconds / dt:.0f}x real time"
    )

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        db = build_demo_database(Path(tmp) / "demo", minutes=args.minutes)
        dt = time.perf_counter() - t0
        t1 = time.perf_counter()
        from gesturekit.database import MatchingDatabase

        MatchingDatabase.load(Path(tmp) / "demo")
        dl = time.perf_counter() - t1
    print(
        f"demo database, {args.minutes:g} min of generated speaker -> {db.n_clips} clips: built and saved in "
        f"{dt:.1f} s ({args.minutes * 60 / dt:.0f}x real time); opened in {dl * 1000:.1f} ms"
    )


if __name__ == "__main__":
    main()
