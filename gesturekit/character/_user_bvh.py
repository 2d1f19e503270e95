"""A BVH file's skeleton as a character: its joints in the rest pose its offsets describe."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..datasets.bvh import unit_scale
from ..datasets.bvh_file import parse_bvh
from .target import FileSkeleton

__all__ = ["read_bvh_skeleton"]


def read_bvh_skeleton(path: Path) -> FileSkeleton:
    """The joints of a BVH file (End Sites included, as ``NAME_End``), at rest: every rotation zero.

    Raises
    ------
    MotionFileError
        The file is not a readable BVH (:func:`gesturekit.datasets.bvh_file.parse_bvh`).
    """
    data = parse_bvh(path)
    n = data.n_joints
    world = np.tile(np.eye(4), (n, 1, 1))
    for j in range(n):  # parents precede children in a BVH
        p = int(data.parents[j])
        world[j, :3, 3] = data.offsets[j] + (world[p, :3, 3] if p >= 0 else 0.0)
    return FileSkeleton(
        path=path,
        kind="bvh",
        names=tuple(data.names),
        parents=np.asarray(data.parents, dtype=np.int64),
        world=world,
        units=unit_scale(data, units="auto"),
    )
