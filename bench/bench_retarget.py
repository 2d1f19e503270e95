"""Retargeting speed: our motion onto a user's character, against the rotation solve every view already does.

Reads a generated VRM 1.0 character (the test rigs of ``tests/character_rigs.py``: 65
bones with fingers, rolled bones) and a ZEGGS-named BVH skeleton, and poses each with
``--minutes`` of the demo database's clips (15 fps) in one run: the rotation solve of
our own character (:func:`gesturekit.character.rig.solve_pose`, which every 3D view
and export does) and :func:`gesturekit.character.retarget.retarget` (which includes
that solve). Prints the time of each, the frames per second of retargeting, and its
cost over the solve alone; then the largest direction error and the wrist error.

Usage: python bench/bench_retarget.py [--minutes 10]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _machine() -> str:
    mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    return f"{os.cpu_count()} cores, {mem:.0f} GiB, {platform.machine()}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    args = parser.parse_args()
    sys.path.insert(0, str(REPO))
    import numpy as np

    from gesturekit.character.retarget import retarget
    from gesturekit.character.rig import rig_for, solve_pose
    from gesturekit.character.user import read_character
    from gesturekit.demo import open_default_database
    from gesturekit.motion import Motion
    from tests.character_rigs import CASES, write_rig

    db = open_default_database()
    frames = int(args.minutes * 60 * 15)
    clips = db.poses.reshape(len(db.poses), -1, 55, 3)
    reps = -(-frames // (clips.shape[0] * clips.shape[1]))
    pos = np.concatenate([clips.reshape(-1, 55, 3)] * reps)[:frames]
    motion = Motion(pos, 15.0, db.joint_presence)
    print(f"machine: {_machine()}, load average {os.getloadavg()[0]:.2f}")
    print(f"motion: {frames} frames ({args.minutes:g} min at 15 fps) of the demo database")
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("vrm1_t", "bvh_zeggs_a"):
            t = time.perf_counter()
            character = read_character(write_rig(Path(tmp), CASES[name], name))
            read_s = time.perf_counter() - t
            t = time.perf_counter()
            solve_pose(motion, rig_for(motion))
            solve_s = time.perf_counter() - t
            t = time.perf_counter()
            posed = retarget(motion, character)
            retarget_s = time.perf_counter() - t
            rep = posed.report
            print(
                f"{name}: {character.n_bones} bones ({character.matched_by}); read {read_s * 1000:.0f} ms; "
                f"our solve {solve_s:.2f} s, retarget {retarget_s:.2f} s ({frames / retarget_s:.0f} frames/s, "
                f"{retarget_s / solve_s:.2f}x the solve alone); directions within {rep.max_direction_error:.3f} deg, "
                f"wrists within {100 * rep.wrist_error:.3f} % of the arm"
            )


if __name__ == "__main__":
    main()
