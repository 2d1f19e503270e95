"""A BVH file's skeleton as a character: its joints in the rest pose its offsets describe."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..datasets.bvh import unit_scale
from ..datasets.bvh_file import parse_bvh
from ..errors import MotionFileError
from .target import FileSkeleton

__all__ = ["read_bvh_skeleton", "MAX_OFFSET"]

#: Largest offset of a joint from its parent, in the file's units (a kilometre in millimetres).
MAX_OFFSET = 1e6


def read_bvh_skeleton(path: Path) -> FileSkeleton:
    """The joints of a BVH file (End Sites included, as ``NAME_End``), at rest: every rotation zero.

    Raises
    ------
    MotionFileError
        The file is not a readable BVH (:func:`gesturekit.datasets.bvh_file.parse_bvh`).
    """
    data = parse_bvh(path)
    n = data.n_joints
    offsets = np.asarray(data.offsets, dtype=np.float64)
    for j in range(n):  # before any sum: 1e308 offsets overflow to inf, and inf - inf to NaN
        size = float(np.abs(offsets[j]).max(initial=0.0)) if np.isfinite(offsets[j]).all() else np.inf
        if not size <= MAX_OFFSET:
            raise MotionFileError(
                f"joint {data.names[j]!r} has the offset {offsets[j].tolist()}, not a finite length below "
                f"{MAX_OFFSET:.0e} units",
                path=path,
            )
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
