"""Joins without a refiner: jerk, acceleration and control adherence of each blend, against the database's own.

Builds two databases, searches one speech on each with every blend mode (and the half-lives
given), and prints, measured in one run:
- ``jerk x`` and ``acc x``: the output's mean joint jerk and acceleration (the kinematic joints
  of :mod:`gesturekit.evaluate.metrics`) over the database's own, measured within its clips
  (64-frame windows, so no clip boundary counts);
- ``join x``: the mean joint displacement across joins over that between other frames;
- ``adherence``: the fraction of frames meeting a control track of hand height (``left_hand``
  high, then low, then high again), by the database's thresholds, as the search admits them.

Databases: the ZEGGS take (``../shared/data/zeggs``, preset ``zeggs``; skipped when absent),
searched with the BEAT speech (a speaker it never heard), and the keypoint example
(:mod:`gesturekit.datasets.keypoint_example`, six two-minute takes, bones normalised),
searched with a generated speech.

Usage: python bench/bench_blend.py [--halflives 0.05 0.1 0.15] [--work DIR]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from machine import describe_machine  # noqa: E402

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
CONTROL = "0-10:left_hand=high,10-20:left_hand=low,20-30:left_hand=high"


def _own(db) -> tuple[float, float]:
    """The database's own mean jerk and acceleration, within its clips (m/s^3, m/s^2)."""
    from gesturekit.evaluate.metrics import kinematic_magnitudes

    g = np.asarray(db.G, np.float32)
    clips = g.reshape(g.shape[0], g.shape[1], -1, 3)
    jerk, acc = [], []
    for clip in clips:  # every clip is one stretch of real motion
        jerk.append(kinematic_magnitudes(clip, fps=db.fps, order=3))
        acc.append(kinematic_magnitudes(clip, fps=db.fps, order=2))
    return float(np.concatenate(jerk).mean()), float(np.concatenate(acc).mean())


def _rows(db, speech, modes) -> list[tuple[str, float, float, float, float]]:
    from gesturekit.evaluate.metrics import (
        boundary_jumps,
        control_adherence,
        mean_acceleration,
        mean_jerk,
        overall_adherence,
    )
    from gesturekit.synthesis import SynthesisConfig, synthesize

    jerk0, acc0 = _own(db)
    rows = []
    for label, options in modes:
        free = synthesize(speech, db=db, config=SynthesisConfig(**options))
        ruled = synthesize(speech, db=db, config=SynthesisConfig(control=CONTROL, **options))
        pos = free.motion.positions
        joins = np.arange(1, free.search.n_steps) * free.config.segment
        table = control_adherence(ruled.motion.positions, ruled.control, thresholds=db.thresholds, fps=db.fps)
        rows.append(
            (
                label,
                mean_jerk(pos, fps=db.fps) / jerk0,
                mean_acceleration(pos, fps=db.fps) / acc0,
                boundary_jumps(pos, joins)["ratio"],
                overall_adherence(table),
            )
        )
    return rows


def _print(title: str, rows) -> None:
    print(f"\n{title}")
    print(f"  {'blend':<26}{'jerk x':>8}{'acc x':>8}{'join x':>8}{'adherence':>11}")
    for label, jerk, acc, join, adh in rows:
        print(f"  {label:<26}{jerk:8.2f}{acc:8.2f}{join:8.2f}{adh:11.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--halflives", type=float, nargs="+", default=[0.05, 0.1, 0.15, 0.2], help="seconds")
    ap.add_argument("--work", type=Path, default=None, help="folder for the databases (default: a temporary one)")
    args = ap.parse_args()

    from gesturekit.blend import DEFAULT_BLEND, DEFAULT_HALFLIFE_S
    from gesturekit.datasets.keypoint_example import write_keypoint_example
    from gesturekit.datasets.synthetic import generate_demo_take
    from gesturekit.workspace import build_database

    modes: list[tuple[str, dict]] = [("none (paper)", {"blend": "none"}), ("offset, 4 frames", {"blend": "offset"})]
    for mode in ("inertialize", "dead"):
        for h in args.halflives:
            modes.append((f"{mode}, {h:g} s", {"blend": mode, "blend_halflife": h}))
    print(describe_machine(accelerator="no GPU used (CPU only)"))
    print(f"default: {DEFAULT_BLEND}, half-life {DEFAULT_HALFLIFE_S:g} s; ratios are output / database's own")
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        take = SHARED / "zeggs" / "067_Speech_2_x_1_0.bvh"
        beat = SHARED / "speech" / "beat_lawrence_0_19_19.wav"
        if take.is_file() and beat.is_file():
            db = build_database(take.parent, work / "zeggs", joint_map="zeggs", overwrite=True)
            _print(f"ZEGGS take ({db.n_clips} clips), BEAT speech 82 s", _rows(db, beat, modes))
        else:
            print(f"\nZEGGS take: skipped ({take} or {beat} not found)")
        write_keypoint_example(work / "kp", fmt="npy", takes=6, seconds=120, seed=21)
        kp = build_database(
            work / "kp",
            work / "kpdb",
            kind="positions",
            joint_map=work / "kp" / "joint_map.json",
            fps=15,
            up="-y",
            normalize_bones=True,
            overwrite=True,
        )
        speech, _ = generate_demo_take(seconds=36, seed=9001, name="speech")
        _print(f"keypoint example ({kp.n_clips} clips), generated speech 36 s", _rows(kp, speech.audio, modes))


if __name__ == "__main__":
    main()
