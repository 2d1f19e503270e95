"""A humanoid found from its skeleton's shape and rest pose where names fail, and left and right checked by it.

:func:`match_by_shape` matches a rig whose names say nothing, or say no side (glTF nodes without names,
``bone_00``, ``arm_a``/``arm_b``): the pelvis carries two legs of one shape, the chest two arms of one shape.
:func:`sides_by_rest_pose` checks the sides of any match against the rest pose: left is the arm on the
character's left as it faces, up from the pelvis to the head and forward where its feet point
(:func:`facing_from_feet`).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence

import numpy as np

from .._arguments import checks_arguments
from .humanoid import PELVIS

__all__ = ["SHAPE", "match_by_shape", "facing_from_feet", "sides_by_rest_pose"]

#: The scheme name of :func:`match_by_shape` in messages and :attr:`Character.matched_by`.
SHAPE = "the hierarchy's shape, left and right from the rest pose"

#: Least forward reach of the feet, as a fraction of the character's height, that tells its facing.
_FEET_FORWARD = 0.02

#: Where the elbow is along the arm, from the shoulder, as a fraction of the arm's length (an extra bone in the
#: upper arm or forearm, a twist bone, sits further from it).
_ELBOW_AT = 0.53


def _tree(parents: Sequence[int], ends: Collection[int] = ()) -> tuple[list[list[int]], list[str], list[int]]:
    """Each bone's children (``ends``, a BVH's End Sites, left out), the shape of the subtree below it (a canonical
    text) and its size."""
    n = len(parents)
    children: list[list[int]] = [[] for _ in range(n)]
    for b, p in enumerate(parents):
        if p >= 0 and b not in ends:
            children[p].append(b)
    shape, size = [""] * n, [1] * n
    for b in reversed(_order(children, parents)):
        shape[b] = "(" + "".join(sorted(shape[c] for c in children[b])) + ")"
        size[b] = 1 + sum(size[c] for c in children[b])
    return children, shape, size


def _order(children: list[list[int]], parents: Sequence[int]) -> list[int]:
    """Parents before children."""
    out = [b for b, p in enumerate(parents) if p < 0]
    for b in out:
        out.extend(children[b])
    return out


def _pair(children: list[list[int]], shape: list[str], size: list[int], b: int) -> tuple[int, int] | None:
    """The largest two children of ``b`` whose subtrees have one shape, of three bones or more; None if none."""
    best: tuple[int, int] | None = None
    kids = children[b]
    for i, x in enumerate(kids):
        for y in kids[i + 1 :]:
            if shape[x] == shape[y] and size[x] >= 3 and (best is None or size[x] > size[best[0]]):
                best = (x, y)
    return best


def _arms_apart(children: list[list[int]], pos: np.ndarray, pelvis: int, chest: int, arms: tuple[int, int]) -> bool:
    """Whether the two chains from ``chest`` end further apart than half the way from the pelvis to the chest, as
    a body's hands do in any rest pose and two fingers of a hand do not."""
    ends = []
    for b in arms:
        while len(children[b]) == 1:
            b = children[b][0]
        ends.append(b)
    return bool(np.linalg.norm(pos[ends[0]] - pos[ends[1]]) > 0.5 * np.linalg.norm(pos[chest] - pos[pelvis]))


def _depths(parents: Sequence[int]) -> list[int]:
    depth = [0] * len(parents)
    for b, p in enumerate(parents):  # parents before children
        depth[b] = depth[p] + 1 if p >= 0 else 0
    return depth


def _ancestors_of(parents: Sequence[int], b: int) -> list[int]:
    out = []
    while b >= 0:
        out.append(b)
        b = int(parents[b])
    return out


@checks_arguments
def facing_from_feet(
    parents: Sequence[int], positions: np.ndarray, pelvis: int, spine: int, up: np.ndarray
) -> np.ndarray | None:
    """The character's forward direction from its rest pose: where its feet point (the ends of the two legs, off the
    line between the hips), or None where they do not point (no two legs, or feet shorter than a fiftieth of the
    height forward).

    Parameters
    ----------
    parents : sequence of int
    positions : np.ndarray, shape (M, 3)
        Rest positions, any unit and frame.
    pelvis, spine : int
        The hips bone and a bone of the spine above it (what is not a leg).
    up : np.ndarray, shape (3,)
        A unit vector from the pelvis towards the head.

    Returns
    -------
    np.ndarray, shape (3,), or None
        A unit vector at right angles to ``up``.
    """
    children, _, _ = _tree(parents)
    height = float(np.ptp(positions @ up)) if len(positions) else 0.0
    legs = []
    for first in children[pelvis]:
        below = [first]
        for b in below:
            below.extend(children[b])
        if spine in below:
            continue
        low = min(below, key=lambda b: float(positions[b] @ up))  # the leg's lowest point: its foot or toe
        if float((positions[pelvis] - positions[low]) @ up) > 0.25 * height:
            legs.append((first, below))
    if len(legs) != 2 or height <= 0:
        return None
    across = positions[legs[0][0]] - positions[legs[1][0]]
    across = across - up * float(across @ up)
    norm = float(np.linalg.norm(across))
    across = across / norm if norm > 1e-9 else across
    ahead = np.zeros(3)
    for first, below in legs:
        ends = [b for b in below if not children[b]]
        tip = max(ends, key=lambda b: float(np.linalg.norm(positions[b] - positions[first])))
        reach = positions[tip] - positions[first]
        ahead += reach - up * float(reach @ up) - across * float(reach @ across)
    length = float(np.linalg.norm(ahead)) / 2
    if length < _FEET_FORWARD * height:
        return None
    return ahead / (2 * length)


@checks_arguments
def match_by_shape(parents: Sequence[int], positions: np.ndarray, ends: Collection[int] = ()) -> dict[str, int]:
    """Our joints found from the hierarchy's shape and the rest pose alone, for a rig whose names say nothing.

    The pelvis is the highest bone with two children of one shape (the legs) and a third (the spine) that leads to
    a bone with two children of one shape (the arms, at the chest); the spine is the bones between them (the last
    three our spine_mid, chest and upper_chest), the neck and head the chain from the chest's other child (the head
    the last bone with children, its top its end). Each arm's chain down to its hand (the first bone with several
    children, or its end) is collar, upper arm, forearm (the bone nearest 53 % of the way along), hand. Left is
    the arm on the character's left as its rest pose faces: up from the pelvis to the head, forward where its feet
    point (:func:`facing_from_feet`; +Z, glTF's forward, where they do not say).

    Parameters
    ----------
    parents : sequence of int
        Parents before children.
    positions : np.ndarray, shape (M, 3)
        Rest positions, any unit and frame.
    ends : collection of int
        A BVH's End Sites (not bones: the ends of bones).

    Returns
    -------
    dict
        Our joint (or :data:`PELVIS`) -> bone; empty where the shape is not a humanoid's.
    """
    children, shape, size = _tree(parents, ends)
    depth = _depths(parents)
    pos = np.asarray(positions, dtype=np.float64)
    pairs = {b: pr for b in range(len(parents)) if (pr := _pair(children, shape, size, b)) is not None}
    best: tuple[int, int] | None = None
    for pelvis, legs in sorted(pairs.items(), key=lambda kv: depth[kv[0]]):
        for chest in sorted(pairs, key=lambda b: depth[b]):
            path = _ancestors_of(parents, chest)
            if pelvis not in path[1:] or any(leg in path for leg in legs):
                continue
            if any(b in pairs and b != chest and b != pelvis for b in path[1 : path.index(pelvis)]):
                continue  # another pair between: the chest is the first above the pelvis
            if len(children[chest]) >= 3 and _arms_apart(children, pos, pelvis, chest, pairs[chest]):
                best = (pelvis, chest)
                break
        if best is not None:
            break
    if best is None:
        return {}
    pelvis, chest = best
    arms = pairs[chest]
    found: dict[str, int] = {PELVIS: pelvis}
    spine = list(reversed(_ancestors_of(parents, chest)))
    spine = spine[spine.index(pelvis) + 1 :]
    keys = ("spine_mid", "chest", "upper_chest")[: min(3, len(spine))]
    for key, b in zip(keys, spine[len(spine) - len(keys) :]):
        found[key] = b
    others = [c for c in children[chest] if c not in arms]
    top = max(others, key=lambda c: (size[c], float(pos[c] @ (pos[chest] - pos[pelvis]))))
    chain = [top]
    while len(children[chain[-1]]) == 1:
        chain.append(children[chain[-1]][0])
    if children[chain[-1]]:  # the head has several children (eyes, jaw)
        head = len(chain) - 1
    else:
        head = max(0, len(chain) - 2) if len(chain) >= 3 else len(chain) - 1
        if head < len(chain) - 1:
            found["head_top"] = chain[-1]
    found["head"] = chain[head]
    if head >= 1:
        found["neck"] = chain[0]
    if head >= 2:
        found["neck_upper"] = chain[1]
    up = pos[chain[head]] - pos[pelvis]
    if np.linalg.norm(up) < 1e-12:
        return {}
    up = up / np.linalg.norm(up)
    forward = facing_from_feet(parents, pos, pelvis, spine[0] if spine else chest, up)
    if forward is None:
        forward = np.array([0.0, 0.0, 1.0]) - up * up[2]
        if np.linalg.norm(forward) < 1e-6:
            return {}
        forward /= np.linalg.norm(forward)
    left = np.cross(up, forward)
    sided = []
    for root in arms:
        chain = [root]
        while len(children[chain[-1]]) == 1:
            chain.append(children[chain[-1]][0])
        sided.append(chain)
    one, two = sided
    if float((pos[one[-1]] - pos[two[-1]]) @ left) < 0:
        one, two = two, one
    for side, chain in (("left", one), ("right", two)):
        arm, hand = chain[:-1], chain[-1]
        if len(arm) < 2:
            return {}
        if len(arm) >= 3:
            found[f"{side}_collar"], arm = arm[0], arm[1:]
        found[f"{side}_shoulder"], found[f"{side}_wrist"] = arm[0], hand
        along = np.cumsum([0.0] + [float(np.linalg.norm(pos[y] - pos[x])) for x, y in zip(arm, [*arm[1:], hand])])
        total = along[-1] if along[-1] > 0 else 1.0
        found[f"{side}_elbow"] = arm[1 + int(np.argmin(np.abs(along[1:-1] / total - _ELBOW_AT)))]
    return found


@checks_arguments
def sides_by_rest_pose(
    found: Mapping[str, int], parents: Sequence[int], positions: np.ndarray, names: Sequence[str]
) -> tuple[dict[str, int], str]:
    """Left and right as the rest pose has them: where the bones matched as the left arm are on the character's right
    (its forward from its feet, :func:`facing_from_feet`), every left and right joint is swapped, and said.

    Returns
    -------
    found : dict
        The match, its sides swapped where the rest pose says so.
    note : str
        What was swapped and why, or ``""``.
    """
    out = dict(found)
    need = (PELVIS, "head", "spine_mid", "left_shoulder", "left_wrist", "right_wrist")
    if any(k not in found for k in need):
        return out, ""
    pos = np.asarray(positions, dtype=np.float64)
    up = pos[found["head"]] - pos[found[PELVIS]]
    if np.linalg.norm(up) < 1e-12:
        return out, ""
    up = up / np.linalg.norm(up)
    forward = facing_from_feet(parents, pos, found[PELVIS], found["spine_mid"], up)
    if forward is None:
        return out, ""
    left = np.cross(up, forward)
    if float((pos[found["left_wrist"]] - pos[found["right_wrist"]]) @ left) >= 0:
        return out, ""
    swapped = {}
    for k, b in found.items():
        if k.startswith("left_"):
            swapped["right_" + k[5:]] = b
        elif k.startswith("right_"):
            swapped["left_" + k[6:]] = b
        else:
            swapped[k] = b
    note = (
        f"the bones matched as the left arm ({names[found['left_shoulder']]!r} ...) are on the character's right "
        "as its rest pose faces (where its feet point): its names have left and right the other way round, so "
        "they are taken as its right arm, and the other as its left"
    )
    return swapped, note
