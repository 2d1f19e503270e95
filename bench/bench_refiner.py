"""Refiner inference speed: 60 s of motion on the CPU, as a multiple of real time (target >= 100x).

Prints, measured in one run (best of five after a warm-up), for the refiner shipped with
the demo database (quick preset) and for a generator of the paper's size (random
weights: speed does not depend on them):
- windowed inference (64-frame windows every 16 frames, cross-faded; the default);
- one fully convolutional pass (``mode="full"``);
- the torch thread count used, and the same with one thread.

Usage: python bench/bench_refiner.py [--seconds 60]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np


def _machine() -> str:
    mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    return f"{os.cpu_count()} cores, {mem:.0f} GiB, {platform.machine()}"


def _best_of(n, fn) -> float:
    fn()  # warm-up: oneDNN picks its kernels on the first call
    best = float("inf")
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _paper_sized():
    from gesturekit.features import LAYOUT
    from gesturekit.refine.infer import Refiner
    from gesturekit.refine.model import ModelConfig, build_models
    from gesturekit.skeleton import JOINT_NAMES

    gen, _ = build_models(ModelConfig(), seed=0)
    stats = {
        "audio_mean": np.zeros(28, np.float32),
        "audio_std": np.ones(28, np.float32),
        "motion_mean": np.zeros(165, np.float32),
        "motion_std": np.full(165, 0.1, np.float32),
    }
    return Refiner(gen, stats=stats, config={"layout": LAYOUT.signature(), "joint_names": list(JOINT_NAMES)})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60.0, help="seconds of motion to refine")
    args = ap.parse_args()

    import torch

    from gesturekit.refine import default_refiner_path, load_refiner

    print(f"machine: {_machine()}, torch {torch.__version__}, {torch.get_num_threads()} threads, device cpu")
    T = int(round(args.seconds * 15))
    rng = np.random.default_rng(0)
    t = np.arange(T)[:, None] / 15.0
    motion = (0.2 * np.sin(2 * np.pi * rng.uniform(0.1, 1.0, (1, 165)) * t)).astype(np.float32)
    audio = rng.normal(size=(T, 28)).astype(np.float32)

    refiners = []
    if (default_refiner_path() / "config.json").is_file():
        refiners.append(("demo refiner (quick preset)", load_refiner("demo")))
    else:
        print(f"(no demo refiner at {default_refiner_path()})")
    refiners.append(("paper-size generator", _paper_sized()))
    threads = torch.get_num_threads()
    for name, ref in refiners:
        for n_threads in sorted({threads, 1}, reverse=True):
            torch.set_num_threads(n_threads)
            for mode in ("windowed", "full"):
                dt = _best_of(5, lambda ref=ref, mode=mode: ref.refine(motion, audio, mode=mode))
                print(
                    f"{name}, {mode:8s}, {n_threads} thread(s): {args.seconds:.0f} s of motion in "
                    f"{dt * 1000:.1f} ms = {args.seconds / dt:.0f}x real time"
                )
    torch.set_num_threads(threads)


if __name__ == "__main__":
    main()
