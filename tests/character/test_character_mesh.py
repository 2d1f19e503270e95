"""The character's body: a closed, consistently skinned mesh that follows every pose of the demo database.

Inversion: a triangle is *inverted* in a frame when its posed normal, taken back into the rest pose by
the world rotation of its dominant joint (the joint with the largest weight summed over its three
vertices), has a non-positive dot product with its rest normal. Stretch: a vertex's distance to its
dominant joint (largest weight) in the pose minus that distance in the rest pose.
A face whose three vertices are bound with weight 1 to one same joint moves rigidly with it, so it
can neither invert nor stretch: the checks over the whole database measure the other faces and
vertices, skinned by a grouped path proven equal to :func:`skin_vertices`.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from gesturekit.character._loft import signed_volume
from gesturekit.character.mesh import PARTS, CharacterMesh, build_mesh, vertex_normals
from gesturekit.character.rig import Pose, Rig, rig_for, solve_pose
from gesturekit.character.skin import skin_vertices
from gesturekit.datasets._partial import complete_skeleton
from gesturekit.demo import open_default_database
from gesturekit.errors import ConfigError
from gesturekit.motion import Motion
from gesturekit.skeleton import (
    ABSENT,
    DERIVED,
    FINGERS,
    JOINT_NAMES,
    N_JOINTS,
    PARENTS,
    RECORDED,
    JointPresence,
    joint_index,
)

#: The stretch allowed, as a share of the vertex's rest distance to its dominant joint plus metres:
#: blended vertices (the wrist, the finger joints, the spine, the neck) move a little towards the joint
#: they blend with (a twist between two spine joints draws the torso's blend in by a centimetre or two).
STRETCH_SHARE, STRETCH_SLACK = 0.1, 0.005


@functools.cache
def _db():  # noqa: ANN202
    return open_default_database()


@functools.cache
def _demo() -> tuple[Rig, CharacterMesh, Pose]:
    """One rig for the whole demo database, the mesh around it, and every clip's pose (clips in order)."""
    db = _db()
    clips = [Motion(c.reshape(-1, N_JOINTS, 3).astype(np.float32), 15.0, db.joint_presence) for c in db.poses]
    rig = rig_for(Motion(np.concatenate([c.positions for c in clips]), 15.0, db.joint_presence))
    poses = [solve_pose(c, rig) for c in clips]
    pose = Pose(np.concatenate([p.local for p in poses]), np.concatenate([p.root for p in poses]))
    return rig, build_mesh(rig), pose


def _clip_motion(clip: int) -> Motion:
    """One clip of the demo database as a motion (64 frames at 15 fps)."""
    db = _db()
    return Motion(np.asarray(db.poses[clip]).reshape(-1, N_JOINTS, 3).astype(np.float32), 15.0, db.joint_presence)


def skin_grouped(mesh: CharacterMesh, matrices: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Linear blend skinning of some vertices, joint by joint: shape (frames, 3, n), float64.

    ``matrices`` (frames, 55, 3, 4) from :meth:`Pose.skinning`; ``vertices`` (n,) indices.
    """
    v = np.concatenate([mesh.vertices[vertices], np.ones((len(vertices), 1))], axis=1).astype(np.float64)
    j, w = mesh.joints[vertices].astype(np.int64), mesh.weights[vertices].astype(np.float64)
    out = np.zeros((len(matrices), 3, len(vertices)))
    for joint in np.unique(j[w > 0]):
        rows, slots = np.nonzero((j == joint) & (w > 0))  # a vertex holds a joint at most once
        out[:, :, rows] += matrices[:, joint] @ (v[rows] * w[rows, slots, None]).T
    return out


def matrices(rot: np.ndarray, pos: np.ndarray, rig: Rig) -> np.ndarray:
    """The skinning matrices of :meth:`Pose.skinning` from world rotations and positions already computed."""
    return np.concatenate([rot, (pos - np.einsum("tjab,jb->tja", rot, rig.rest))[..., None]], axis=-1)


def dense_weights(mesh: CharacterMesh) -> np.ndarray:
    """Each vertex's weight on each joint, shape (V, 55)."""
    out = np.zeros((mesh.n_vertices, N_JOINTS))
    np.add.at(out, (np.arange(mesh.n_vertices)[:, None], mesh.joints.astype(np.int64)), mesh.weights)
    return out


def dominant(mesh: CharacterMesh) -> tuple[np.ndarray, np.ndarray]:
    """Each vertex's heaviest joint (V,) and each face's (F,) (largest weight summed over its vertices)."""
    per_joint = dense_weights(mesh)
    return per_joint.argmax(axis=1), per_joint[mesh.faces].sum(axis=1).argmax(axis=1)


def _face_normals(v: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit normals (3, ..., F) of vertices (3, ..., V), one coordinate per row (fast on many frames)."""
    (x0, y0, z0), (x1, y1, z1), (x2, y2, z2) = (v[..., faces[:, k]] for k in range(3))
    ax, ay, az, bx, by, bz = x1 - x0, y1 - y0, z1 - z0, x2 - x0, y2 - y0, z2 - z0
    n = np.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx])
    return n / np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])


def deformation(mesh: CharacterMesh, rig: Rig, pose: Pose, chunk: int = 256) -> dict:
    """The worst inversion (smallest dot product), stretch (metres) and stretch beyond the allowance
    (metres; within it when negative) over every frame of ``pose``."""
    vdom, fdom = dominant(mesh)
    rigid_v = (mesh.weights[:, 0] >= 1.0 - 1e-6) | (mesh.weights[:, 1:] == 0).all(axis=1)
    rigid_f = rigid_v[mesh.faces].all(axis=1) & (vdom[mesh.faces] == fdom[:, None]).all(axis=1)
    faces = np.flatnonzero(~rigid_f)
    faces = faces[np.argsort(fdom[faces], kind="stable")]  # each dominant joint's faces side by side
    verts = np.unique(np.concatenate([mesh.faces[faces].ravel(), np.flatnonzero(~rigid_v)]))
    tri = np.searchsorted(verts, mesh.faces[faces])  # the faces' corners among ``verts``
    rest_n = _face_normals(mesh.vertices.astype(np.float64)[verts].T, tri)  # (3, F)
    rest_d = np.linalg.norm(mesh.vertices[verts] - rig.rest[vdom[verts]], axis=-1)
    bounds = np.searchsorted(fdom[faces], np.arange(N_JOINTS + 1))
    groups = [(j, slice(bounds[j], bounds[j + 1])) for j in range(N_JOINTS) if bounds[j + 1] > bounds[j]]
    worst = {"dot": 1.0, "dot_at": None, "stretch": 0.0, "stretch_at": None, "excess": -1.0}
    allowed = STRETCH_SHARE * rest_d + STRETCH_SLACK
    for a in range(0, pose.n_frames, chunk):
        rot, pos = Pose(pose.local[a : a + chunk], pose.root[a : a + chunk]).world(rig)
        posed = skin_grouped(mesh, matrices(rot, pos, rig), verts).astype(np.float32)  # (t, 3, n)
        n = _face_normals(posed.transpose(1, 0, 2), tri)  # (3, t, F)
        dots = np.empty((len(posed), len(faces)), np.float32)
        for j, sel in groups:
            back = np.einsum("tab,bf->atf", rot[:, j].astype(np.float32), rest_n[:, sel].astype(np.float32))
            dots[:, sel] = np.einsum("atf,atf->tf", n[:, :, sel], back)
        if dots.size and dots.min() < worst["dot"]:
            t, f = np.unravel_index(dots.argmin(), dots.shape)
            worst.update(dot=float(dots.min()), dot_at=(a + int(t), int(faces[f]), JOINT_NAMES[fdom[faces[f]]]))
        d = np.sqrt(np.sum((posed - pos[:, vdom[verts]].transpose(0, 2, 1)) ** 2, axis=1))
        s = np.abs(d - rest_d)
        if s.size:
            worst["excess"] = max(worst["excess"], float((s - allowed).max()))
        if s.size and s.max() > worst["stretch"]:
            t, v = np.unravel_index(s.argmax(), s.shape)
            worst.update(stretch=float(s.max()), stretch_at=(a + int(t), int(verts[v]), JOINT_NAMES[vdom[verts[v]]]))
    return worst


# ---- the whole demo database ---------------------------------------------------------------------


@pytest.mark.slow
def test_the_grouped_skinning_equals_skin_vertices():
    rig, mesh, pose = _demo()
    frames = np.array([0, 1, 63, 64, 1000, 4371, pose.n_frames - 1])
    plain = skin_vertices(mesh, rig, pose, frames=frames)
    sub = Pose(pose.local[frames], pose.root[frames])
    m = matrices(*sub.world(rig), rig)
    np.testing.assert_allclose(m, sub.skinning(rig), atol=1e-12)
    grouped = skin_grouped(mesh, m, np.arange(mesh.n_vertices)).transpose(0, 2, 1)
    np.testing.assert_allclose(grouped, plain, atol=2e-6)


@pytest.mark.slow
def test_no_triangle_inverts_and_no_vertex_stretches_over_the_whole_demo_database():
    rig, mesh, pose = _demo()
    assert pose.n_frames == _db().poses.shape[0] * _db().poses.shape[1]
    worst = deformation(mesh, rig, pose)
    print(
        f"\nworst inversion dot {worst['dot']:.3f} at {worst['dot_at']}, stretch {worst['stretch'] * 1000:.1f} mm "
        f"at {worst['stretch_at']}, {-worst['excess'] * 1000:.1f} mm within the allowance"
    )
    assert worst["dot"] > 0.0, f"a triangle inverts: {worst}"
    assert worst["excess"] <= 0.0, (
        f"a vertex stretches beyond {STRETCH_SHARE} x its distance + {STRETCH_SLACK} m: {worst}"
    )


@pytest.mark.slow
def test_the_deformation_check_finds_the_fold_of_a_blended_elbow():
    """The check above can fail: blend the forearm's end into the upper arm (instead of the two capsules
    that turn about the elbow) and the frames where the elbow bends most fold it."""
    rig, mesh, pose = _demo()
    elbow, shoulder = joint_index("left_elbow"), joint_index("left_shoulder")
    x = mesh.vertices[:, 0] - rig.rest[elbow, 0]
    near = (mesh.joints[:, 0] == elbow) & (mesh.weights[:, 0] == 1.0) & (x < 0.06)
    joints, weights = mesh.joints.copy(), mesh.weights.copy()
    w = np.clip(x[near] / 0.06, 0.0, 1.0)
    joints[near, 1], weights[near, 0], weights[near, 1] = shoulder, w, 1.0 - w
    blended = CharacterMesh(mesh.vertices, mesh.normals, mesh.faces, joints, weights, mesh.parts)
    rot, pos = pose.world(rig)
    upper, fore = pos[:, shoulder] - pos[:, elbow], pos[:, joint_index("left_wrist")] - pos[:, elbow]
    cos = np.einsum("ta,ta->t", upper, fore) / np.linalg.norm(upper, axis=1) / np.linalg.norm(fore, axis=1)
    bent = np.flatnonzero(cos > np.cos(np.radians(35.0)))  # bent by more than 145 degrees
    assert len(bent)
    worst = deformation(blended, rig, Pose(pose.local[bent], pose.root[bent]))
    assert worst["dot"] <= 0.0, worst


# ---- structure -------------------------------------------------------------------------------------


def closed_parts(mesh: CharacterMesh) -> list[np.ndarray]:
    """The faces of each connected piece of the mesh (connected through shared vertices)."""
    f = mesh.faces.astype(np.int64)
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]]])
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(mesh.n_vertices,) * 2)
    _, label = connected_components(graph, directed=False)
    return [np.flatnonzero(label[f[:, 0]] == c) for c in np.unique(label[f[:, 0]])]


def assert_well_formed(mesh: CharacterMesh, rig: Rig) -> None:
    v, f = mesh.vertices, mesh.faces
    assert v.dtype == np.float32 and mesh.normals.dtype == np.float32 and f.dtype == np.int32
    assert mesh.joints.dtype == np.uint8 and mesh.weights.dtype == np.float32 and mesh.parts.dtype == np.uint8
    assert mesh.joints.shape == mesh.weights.shape == (len(v), 4) and mesh.parts.shape == (len(v),)
    assert np.isfinite(v).all() and (f >= 0).all() and (f < len(v)).all()
    assert (mesh.weights >= 0).all() and np.allclose(mesh.weights.sum(axis=1), 1.0, atol=1e-6)
    used = mesh.joints[mesh.weights > 0]
    assert (used < N_JOINTS).all() and (rig.parents[used] >= -1).all(), "a vertex is bound to a joint not in the rig"
    held = np.sort(np.where(mesh.weights > 0, mesh.joints.astype(np.int64), N_JOINTS + np.arange(4)), axis=1)
    assert (np.diff(held, axis=1) > 0).all(), "a joint twice in one vertex's slots"
    assert set(np.unique(mesh.parts).tolist()) <= set(range(len(PARTS)))
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    assert area.min() > 1e-9, f"degenerate face: area {area.min():.2e} m^2"
    np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-5)
    np.testing.assert_allclose(mesh.normals, vertex_normals(v, f), atol=1e-3)
    for piece in closed_parts(mesh):
        faces = f[piece]
        edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        key = edges[:, 0].astype(np.int64) * len(v) + edges[:, 1]
        back = edges[:, 1].astype(np.int64) * len(v) + edges[:, 0]
        assert len(np.unique(key)) == len(key), "an edge is used twice in one direction (inconsistent winding)"
        assert np.isin(back, key).all(), "a piece is not closed (an edge without its opposite)"
        assert signed_volume(v.astype(np.float64), faces) > 0, "a piece's faces wind inward"


@pytest.mark.slow
def test_the_demo_mesh_is_well_formed_within_budget_and_deterministic():
    rig, mesh, _ = _demo()
    assert_well_formed(mesh, rig)
    print(f"\n{mesh.n_vertices} vertices, {len(mesh.faces)} faces, {len(closed_parts(mesh))} closed pieces")
    assert 5000 <= mesh.n_vertices <= 6000
    again = build_mesh(rig)
    for name in ("vertices", "normals", "faces", "joints", "weights", "parts"):
        assert np.array_equal(getattr(again, name), getattr(mesh, name)), name
    # the moving body: skin, shirt and face (the trousers and shoes are the still legs')
    assert {PARTS[p] for p in np.unique(mesh.parts)} == {"skin", "shirt", "face"}


def test_the_body_is_a_half_body_presenter_facing_forward():
    rig, mesh, _ = _demo()
    v, head = mesh.vertices, rig.rest[joint_index("head")]
    spine = rig.rest[joint_index("spine_mid")]
    # cut at the waist: nothing far below spine_mid, the torso closed there
    torso = rig.rest[joint_index("neck"), 1] - spine[1]
    assert v[:, 1].min() > spine[1] - 0.3 * torso
    # the face (eyes, brows, mouth) is on the front of the head (+Z), the nose the frontmost point of it
    face = v[mesh.parts == PARTS.index("face")]
    assert len(face) and (face[:, 2] > head[2]).all()
    near_head = v[np.linalg.norm(v - head, axis=1) < 0.2]
    assert near_head[:, 2].max() > face[:, 2].max()
    # both hands' five fingers reach their tips
    for side in ("left", "right"):
        for finger in FINGERS:
            tip = rig.rest[joint_index(f"{side}_{finger}4")]
            assert np.linalg.norm(v - tip, axis=1).min() < 0.012, (side, finger)


def plain_vertex_normals(v: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals of one frame, face by face."""
    acc = np.zeros_like(v, dtype=np.float64)
    for f in faces:
        a, b, c = v[f].astype(np.float64)
        acc[f] += np.cross(b - a, c - a)
    return acc / np.linalg.norm(acc, axis=1, keepdims=True)


@pytest.mark.slow
def test_vertex_normals_of_many_frames_equal_the_plain_sum_frame_by_frame():
    rig, mesh, pose = _demo()
    posed = skin_vertices(mesh, rig, pose, frames=np.array([0, 500, 9000]))
    fast = vertex_normals(posed, mesh.faces)
    assert fast.shape == posed.shape
    for k in range(len(posed)):
        np.testing.assert_allclose(fast[k], plain_vertex_normals(posed[k], mesh.faces), atol=1e-9)
    np.testing.assert_allclose(vertex_normals(posed[1], mesh.faces), fast[1], atol=1e-12)


def test_detail_sets_the_vertex_count_and_keeps_the_mesh_well_formed():
    rig, mesh, _ = _demo()
    meshes = [build_mesh(rig, detail=d) for d in (0.5, 1.5)]
    for m in meshes:
        assert_well_formed(m, rig)
    assert meshes[0].n_vertices < mesh.n_vertices < meshes[1].n_vertices


def test_detail_must_be_positive():
    rig, _, _ = _demo()
    with pytest.raises(ConfigError, match="detail"):
        build_mesh(rig, detail=0.0)


# ---- scaling -----------------------------------------------------------------------------------------


def scaled_rig(rig: Rig, factors: np.ndarray) -> Rig:
    """``rig`` with each bone's length multiplied by ``factors`` (55,): offsets scaled, rest rebuilt."""
    offsets = rig.offsets * factors[:, None]
    rest = np.zeros_like(rig.rest)
    for j in range(N_JOINTS):
        p = int(rig.parents[j])
        if p >= 0:
            rest[j] = rest[p] + offsets[j]
        elif p == -2:
            rest[j] = rest[PARENTS[j]] if PARENTS[j] >= 0 else rest[j]
    return Rig(parents=rig.parents, offsets=offsets, rest=rest, lengths=rig.lengths * factors)


@settings(max_examples=10, deadline=None)
@given(st.floats(0.5, 2.0))
def test_the_mesh_scales_with_a_uniformly_scaled_rig(s):
    rig, mesh, _ = _demo()
    big = build_mesh(scaled_rig(rig, np.full(N_JOINTS, s)))
    np.testing.assert_allclose(big.vertices, s * mesh.vertices, rtol=1e-5, atol=1e-6)
    for name in ("faces", "parts"):
        assert np.array_equal(getattr(big, name), getattr(mesh, name))
    np.testing.assert_allclose(dense_weights(big), dense_weights(mesh), atol=1e-5)


@settings(max_examples=8, deadline=None)
@given(st.lists(st.floats(0.7, 1.4), min_size=N_JOINTS, max_size=N_JOINTS))
def test_the_mesh_follows_each_bones_length(factors):
    rig0, _, _ = _demo()
    rig = scaled_rig(rig0, np.array(factors))
    mesh = build_mesh(rig)
    assert_well_formed(mesh, rig)
    v = mesh.vertices.astype(np.float64)
    vdom, _ = dominant(mesh)
    width = np.linalg.norm(rig.rest[joint_index("left_shoulder")] - rig.rest[joint_index("right_shoulder")])
    # every limb's vertices stay within the limb's girth of their own bone (joint to child, or the joint)
    for j in np.unique(vdom):
        kids = np.flatnonzero(rig.parents == j)
        a = rig.rest[j]
        b = rig.rest[kids].mean(axis=0) if len(kids) else a
        ab = b - a
        t = np.clip((v[vdom == j] - a) @ ab / max(ab @ ab, 1e-12), 0.0, 1.0)
        dist = np.linalg.norm(v[vdom == j] - (a + t[:, None] * ab), axis=1)
        side = "left" if JOINT_NAMES[j].startswith("left") else "right"
        hand = np.linalg.norm(rig.rest[joint_index(f"{side}_index1")] - rig.rest[joint_index(f"{side}_pinky1")])
        # the torso is as wide as the shoulders; forearms go with the shoulders, palms with the hand's width
        limit = 0.55 * width if j < 13 else 0.2 * width + 0.6 * hand
        if j == joint_index("head"):
            limit = 1.2 * rig.lengths[joint_index("head_top")]
        assert dist.max() <= limit, (JOINT_NAMES[j], dist.max(), limit)
    # and the fingertips are covered wherever the fingers end
    for side in ("left", "right"):
        tip = rig.rest[joint_index(f"{side}_middle4")]
        assert np.linalg.norm(v - tip, axis=1).min() < 0.015


# ---- partial skeletons -------------------------------------------------------------------------------


def _names(*groups: tuple[str, ...]) -> list[str]:
    return [n for g in groups for n in g]


_TORSO = ("spine_mid", "chest", "upper_chest")
_HEAD = ("neck_upper", "head", "head_top")
_COLLARS = ("left_collar", "right_collar")
_ARMS = tuple(f"{s}_{j}" for s in ("left", "right") for j in ("shoulder", "elbow"))
_WRISTS = ("left_wrist", "right_wrist")
_FINGER_JOINTS = tuple(n for n in JOINT_NAMES if any(f in n for f in FINGERS))
_THUMBS = tuple(n for n in _FINGER_JOINTS if "thumb" in n)

#: name -> (recorded, derived by complete_skeleton?) ; derived: the torso and head from neck and shoulders
LAYOUTS = {
    "keypoints": (_names(("neck",), _ARMS, _WRISTS, _FINGER_JOINTS), True),
    "upper body, no thumbs": (_names(("neck",), _HEAD, _COLLARS, _ARMS, _WRISTS, _FINGER_JOINTS), True),
    "no hands": (_names(_TORSO, ("neck",), _HEAD, _COLLARS, _ARMS), False),
    "no fingers": (_names(_TORSO, ("neck",), _HEAD, _COLLARS, _ARMS, _WRISTS), False),
    "neck root": (_names(("neck",), _HEAD, _COLLARS, _ARMS, _WRISTS, _FINGER_JOINTS), False),
    "arms only from the neck": (_names(("neck",), _ARMS, _WRISTS, _FINGER_JOINTS), False),
    "no elbows": (_names(_TORSO, ("neck",), _HEAD, _COLLARS, _ARMS[::2], _WRISTS, _FINGER_JOINTS), False),
}


@functools.cache
def layout(name: str) -> tuple[Motion, Rig, CharacterMesh]:
    recorded, derive = LAYOUTS[name]
    if name == "upper body, no thumbs":
        recorded = [n for n in recorded if n not in _THUMBS]
    positions = _db().poses[:3].reshape(-1, N_JOINTS, 3).astype(np.float64)
    mask = np.array([n in recorded for n in JOINT_NAMES])
    if derive:
        positions, presence = complete_skeleton(positions, mask)
    else:
        presence = JointPresence.from_names(recorded=recorded)
        for j in np.flatnonzero(presence.absent):  # an absent joint sits on its parent
            positions[:, j] = positions[:, PARENTS[j]]
    motion = Motion(positions.astype(np.float32), 15.0, presence)
    rig = rig_for(motion)
    return motion, rig, build_mesh(rig)


@pytest.mark.parametrize("name", sorted(LAYOUTS))
def test_a_partial_skeleton_gets_a_well_formed_body_that_follows_its_motion(name):
    motion, rig, mesh = layout(name)
    assert_well_formed(mesh, rig)
    bound = np.zeros(N_JOINTS, bool)
    bound[mesh.joints[mesh.weights > 0]] = True
    assert not (bound & (rig.parents == -2)).any(), "a vertex is bound to an absent joint"
    worst = deformation(mesh, rig, solve_pose(motion, rig))
    assert worst["dot"] > 0.0 and worst["excess"] <= 0.0, (name, worst)


@pytest.mark.slow
@settings(max_examples=25, deadline=None)
@given(st.lists(st.booleans(), min_size=N_JOINTS, max_size=N_JOINTS))
def test_any_layout_with_both_shoulders_gets_a_body_that_neither_folds_nor_stretches(present):
    """Both shoulders are what every view needs (REQUIRED_JOINTS); any other joint may be absent."""
    status = [RECORDED if keep else ABSENT for keep in present]
    for name in ("left_shoulder", "right_shoulder"):
        status[joint_index(name)] = RECORDED
    presence = JointPresence(tuple(status))
    positions = _db().poses[1].reshape(-1, N_JOINTS, 3).astype(np.float32)
    for j in np.flatnonzero(presence.absent):
        if PARENTS[j] >= 0:
            positions[:, j] = positions[:, PARENTS[j]]
    motion = Motion(positions, 15.0, presence)
    try:
        rig = rig_for(motion)
    except ConfigError:  # no spine_mid and no neck: no hierarchy to build a body on
        assume(False)
    have = {n for n in JOINT_NAMES if rig.parents[joint_index(n)] >= -1}
    placeable = (
        {"spine_mid", "neck"} <= have
        or "head" in have
        or {"neck", "neck_upper"} <= have
        or any(f"{s}_elbow" in have or f"{s}_wrist" in have for s in ("left", "right"))
    )
    if not placeable:
        with pytest.raises(ConfigError, match="no piece"):
            build_mesh(rig)
        return
    mesh = build_mesh(rig)
    assert_well_formed(mesh, rig)
    assert not (rig.parents[mesh.joints[mesh.weights > 0]] == -2).any()
    worst = deformation(mesh, rig, solve_pose(motion, rig))
    assert worst["dot"] > 0.0 and worst["excess"] <= 0.0, (presence.describe(), worst)


def _reach(mesh: CharacterMesh) -> float:
    """How far the mesh reaches out to the side, metres."""
    return float(np.abs(mesh.vertices[:, 0]).max())


def test_hidden_parts_are_absent():
    full_rig, full, _ = _demo()
    wrist = full_rig.rest[joint_index("left_wrist"), 0]
    assert _reach(full) > wrist + 0.18, "the full hand reaches its fingertips"
    _, rig, no_hands = layout("no hands")
    assert _reach(no_hands) < rig.rest[joint_index("left_elbow"), 0] + 0.06, "a hand or forearm without wrists"
    _, rig, no_fingers = layout("no fingers")
    assert _reach(no_fingers) < rig.rest[joint_index("left_wrist"), 0] + 0.12, "fingers without finger joints"
    assert no_fingers.n_vertices < full.n_vertices - 1500
    for name in ("neck root", "arms only from the neck"):
        _, rig, mesh = layout(name)
        held = set(mesh.joints[mesh.weights > 0].tolist())
        assert not held & {joint_index(n) for n in _TORSO}, "a torso without spine joints"
        assert (mesh.vertices[:, 1] > rig.rest[joint_index("neck"), 1] - 0.12).all()
    _, rig, mesh = layout("arms only from the neck")
    assert PARTS.index("face") not in mesh.parts, "a face without a head"
    _, rig, mesh = layout("upper body, no thumbs")
    assert not set(mesh.joints[mesh.weights > 0].tolist()) & {joint_index(n) for n in _THUMBS}


@pytest.mark.parametrize("joint", ["chest", "upper_chest", "head", "left_collar"])
def test_derived_joints_move_their_parts(joint):
    motion, rig, mesh = layout("keypoints")
    j = joint_index(joint)
    assert motion.presence.status[j] == DERIVED and rig.parents[j] >= 0
    local = np.broadcast_to(np.eye(3), (1, N_JOINTS, 3, 3)).copy()
    c, s = np.cos(0.5), np.sin(0.5)
    local[0, j] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    posed = skin_vertices(mesh, rig, Pose(local, np.zeros((1, 3))))[0]
    moved = np.linalg.norm(posed - mesh.vertices, axis=1) > 1e-6
    sub = np.zeros(N_JOINTS, bool)  # the joint and every joint below it in the rig
    sub[j] = True
    for k in range(N_JOINTS):
        if rig.parents[k] >= 0 and sub[rig.parents[k]]:
            sub[k] = True
    touched = (sub[mesh.joints] & (mesh.weights > 0)).any(axis=1)
    assert moved.any() and np.array_equal(moved, touched)


def test_a_layout_without_any_body_is_refused():
    status = [ABSENT] * N_JOINTS
    for n in ("neck", "left_wrist"):
        status[joint_index(n)] = RECORDED
    positions = _db().poses[0, :2].reshape(-1, N_JOINTS, 3).astype(np.float32)
    rig = rig_for(Motion(positions, 15.0, JointPresence(tuple(status))))
    with pytest.raises(ConfigError, match="no piece"):
        build_mesh(rig)


def test_skinned_normals_are_the_rest_normals_turned_as_the_skinned_surface_turns():
    """skin_normals (the page's and the MP4's shading normals) against the normals of the skinned surface itself."""
    from gesturekit.character.mesh import vertex_normals
    from gesturekit.character.skin import skin_normals

    motion = _clip_motion(5)
    rig = rig_for(motion)
    mesh = build_mesh(rig)
    pose = solve_pose(motion, rig)
    frames = np.array([0, 31, 63])
    n = skin_normals(mesh, rig, pose, frames)
    assert n.shape == (3, mesh.n_vertices, 3)
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-5)
    # a vertex bound to one joint: exactly its rest normal turned by that joint's world rotation
    rot, _ = pose.world(rig)
    rigid = np.flatnonzero(mesh.weights[:, 0] == 1.0)
    want = np.einsum("tvab,vb->tva", rot[frames][:, mesh.joints[rigid, 0]], mesh.normals[rigid])
    np.testing.assert_allclose(n[:, rigid], want, atol=1e-5)
    # everywhere, close to the normal of the skinned surface (which a blend bends a little at joints)
    surface = vertex_normals(skin_vertices(mesh, rig, pose, frames), mesh.faces)
    cos = np.sum(n * surface, axis=-1)
    assert np.median(cos) > 0.999 and np.percentile(cos, 99) > 0.9, (np.median(cos), np.percentile(cos, 99))
