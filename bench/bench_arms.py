"""Arm accuracy against reach on arms of other proportions: the trade-off behind the default wrist slack.

Generated rigs (``tests/character_rigs.py``) whose upper-arm-to-forearm ratio is ours -24 % to +20 % (the range
of real rigs), posed with ``--clips`` clips of the demo database for each wrist slack: prints, per ratio and
slack, the largest over both arms of each bone's median and 95th-percentile angle to ours (degrees) and how far
the hands are from our reach scaled to their arm (% of the arm's length).

Usage: python bench/bench_arms.py [--clips 20]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clips", type=int, default=20)
    args = parser.parse_args()
    sys.path.insert(0, str(REPO))
    import numpy as np

    from gesturekit.character.retarget import WRIST_SLACK
    from gesturekit.demo import open_default_database
    from gesturekit.motion import Motion
    from tests.character.test_character_arms import _rig, arm_errors

    db = open_default_database()
    motion = Motion(db.poses[: args.clips].reshape(-1, 55, 3).astype(np.float32), 15.0, db.joint_presence)
    print(f"{motion.n_frames} frames; default wrist slack {WRIST_SLACK:.0%}")
    with tempfile.TemporaryDirectory() as tmp:
        for change in (-0.24, -0.2, -0.12, 0.1, 0.2):
            ch = _rig(Path(tmp), change)
            for slack in (0.0, 0.02, 0.05, 0.055, 0.08, 0.1):
                med, p95, wrist = arm_errors(motion, ch, slack)
                print(
                    f"ratio {change:+.0%} slack {slack:5.1%}: bones median {med:4.1f} p95 {p95:4.1f} deg, "
                    f"hands {100 * wrist:4.1f} % of the arm"
                )


if __name__ == "__main__":
    main()
