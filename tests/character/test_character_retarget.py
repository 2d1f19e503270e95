"""Our motion on a user's character (issue 26): read generated rigs of every kind, retarget, check against ours.

The rigs (tests/character_rigs.py) are Mixamo-, VRM 0.x-, VRM 1.0-, ZEGGS- and
custom-named, in T and A rest poses, with rolled bones, an FBX-style armature,
other proportions, twist bones, no fingers, a missing bone. For each: every
bone a matched bone points at stays within 5 degrees of ours over the whole
result, the wrists within 2 % of the arm's length of our reach scaled to theirs,
and a control's adherence measured on the retargeted motion within 2 points of
ours. The figures are printed (``pytest -s``).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.character.humanoid import MIXAMO, PELVIS, REQUIRED, VRM_BONES, match_names
from gesturekit.character.retarget import TORSO_RADIUS, WRIST_SLACK, kabsch, retarget, swing
from gesturekit.character.target import Character, facing_frame
from gesturekit.character.user import read_character
from gesturekit.control import parse_control
from gesturekit.errors import ConfigError, GestureKitError, InputFileError, MotionFileError
from gesturekit.evaluate.metrics import control_adherence, overall_adherence
from gesturekit.motion import Motion
from gesturekit.skeleton import FINGERS, JOINT_NAMES, N_JOINTS, joint_index
from tests.character_rigs import CASES, RigSpec, custom_map, truth, write_rig

#: Every bone a matched bone points at, against ours (degrees).
DIRECTION_DEGREES = 5.0
#: A wrist from our reach scaled to the character's arm, as a fraction of the arm's length.
WRIST_FRACTION = 0.02
#: Control adherence, retargeted against ours, percentage points.
ADHERENCE_POINTS = 2.0

GOOD = [name for name in CASES if name != "missing_elbow"]


@pytest.fixture(scope="module")
def db():
    from gesturekit.demo import open_default_database

    return open_default_database()


@pytest.fixture(scope="module")
def controlled(db):
    """A synthesis of the demo speech with both hands held high, then low, and its control."""
    from gesturekit.datasets.synthetic import generate_demo_take
    from gesturekit.synthesis import SynthesisConfig, synthesize

    take, _ = generate_demo_take(seconds=12.0, seed=3, name="speech")
    text = "0-6:left_hand=high+right_hand=high,6-12:both_hands=low"
    control = parse_control(text)
    result = synthesize(take.audio, db=db, config=SynthesisConfig(control=text, seed=0))
    return result.motion, control


def _read(tmp_path, name):
    spec = CASES[name]
    path = write_rig(tmp_path, spec, name)
    return read_character(path, bone_map=custom_map(spec) if spec.naming == "custom" else None), spec


@pytest.mark.parametrize("name", GOOD)
def test_every_rig_follows_our_directions_reach_and_controls(tmp_path, name, db, controlled):
    motion, control = controlled
    ch, spec = _read(tmp_path, name)
    out = retarget(motion, ch)
    rep = out.report
    print(f"\n{name} ({ch.matched_by}, {ch.n_bones} bones): {rep.summary()}")

    # every bone a matched bone points at, over every frame
    assert rep.max_direction_error < DIRECTION_DEGREES, rep.summary()
    expected_chain = 43 if spec.fingers else 11
    assert len(rep.segments) >= expected_chain - 2, rep.segments
    # wrists at our reach scaled to their arm
    assert rep.wrist_error < WRIST_FRACTION, rep.summary()
    assert rep.wrist_error <= WRIST_SLACK + 1e-6
    t = truth(spec)
    ours = _our_arm(motion)
    np.testing.assert_allclose(rep.reach_scale, np.array(t.arm_length) / ours, rtol=1e-3)
    # the control holds on the character as on ours
    thresholds = db.thresholds
    a_ours, a_theirs = (
        100 * overall_adherence(control_adherence(m.positions, control, thresholds=thresholds, fps=m.fps))
        for m in (motion, out.our_motion())
    )
    print(f"   control adherence: ours {a_ours:.1f} %, on the character {a_theirs:.1f} %")
    assert a_ours > 50  # the control did something to measure
    assert abs(a_theirs - a_ours) <= ADHERENCE_POINTS
    # bone lengths are theirs: every bone keeps its rest distance to its parent
    p = ch.rest_position
    for b in range(ch.n_bones):
        pa = ch.parents[b]
        if pa >= 0:
            d = np.linalg.norm(out.position[:, b] - out.position[:, pa], axis=1)
            np.testing.assert_allclose(d, np.linalg.norm(p[b] - p[pa]), atol=1e-9)
    # the rotations are rotations, and positions follow from them (forward kinematics)
    r = out.rotation
    np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), np.broadcast_to(np.eye(3), r.shape), atol=1e-9)
    fk = out.position[:, ch.parents[1:]] + np.einsum(
        "tmab,mb->tma", out.turns()[:, ch.parents[1:]], p[1:] - p[ch.parents[1:]]
    )
    has = ch.parents[1:] >= 0
    np.testing.assert_allclose(fk[:, has], out.position[:, 1:][:, has], atol=1e-9)


def _our_arm(motion: Motion) -> np.ndarray:
    from gesturekit.character.rig import rig_for

    rig = rig_for(motion)
    return np.array(
        [rig.lengths[joint_index(f"{s}_elbow")] + rig.lengths[joint_index(f"{s}_wrist")] for s in ("left", "right")]
    )


@pytest.mark.parametrize(
    ("name", "matched_by"),
    [
        ("mixamo_t", "mixamo names"),
        ("vrm0_a", "VRM 0.x humanoid"),
        ("vrm1_t", "VRM 1.0 humanoid"),
        ("bvh_zeggs_a", "zeggs names"),
        ("custom_names", "JSON map"),
    ],
)
def test_bones_are_matched_as_the_rig_says(tmp_path, name, matched_by):
    ch, spec = _read(tmp_path, name)
    assert ch.matched_by == matched_by
    t = truth(spec)
    assert ch.matched() == {k: v for k, v in t.joint_map.items()}
    # in our frame: the character faces +Z with its left at +X, whatever the file's frame
    left, right = ch.rest_position[ch.bone("left_shoulder")], ch.rest_position[ch.bone("right_shoulder")]
    assert left[0] - right[0] > 0.2
    assert ch.rest_position[ch.bone("head")][1] > ch.rest_position[ch.pelvis][1] + 0.3
    # the file's frame, back from ours
    back = (ch.to_file[:3, :3] @ ch.rest_position.T).T
    names = list(t.bone_names)
    ours = [i for i, n in enumerate(ch.names) if n in names]  # a BVH's End Sites are bones here, not in the truth
    assert len(ours) == len(names)
    order = [names.index(ch.names[i]) for i in ours]
    np.testing.assert_allclose(back[ours], t.rest_world[order] / ch.bvh_units, atol=1e-5)


def test_a_rig_without_fingers_keeps_its_hands_still(tmp_path, controlled):
    motion, _ = controlled
    ch, _ = _read(tmp_path, "no_fingers")
    out = retarget(motion, ch)
    fingers = [n for n in JOINT_NAMES if any(f in n for f in ("thumb", "index", "middle", "ring", "pinky"))]
    assert set(fingers) <= set(out.report.missing)
    assert all(ch.bone(n) < 0 for n in fingers)
    # the hands still turn with our wrists
    hand = ch.bone("left_wrist")
    assert np.ptp(out.rotation[:, hand].reshape(len(out.rotation), -1), axis=0).max() > 0.1


def test_a_rig_missing_a_required_bone_is_refused_by_name(tmp_path):
    path = write_rig(tmp_path, CASES["missing_elbow"], "missing_elbow")
    with pytest.raises(ConfigError) as e:
        read_character(path)
    msg = str(e.value)
    assert "left_elbow" in msg and "LeftForeArm" in msg and str(path) in msg
    assert "right_elbow" not in msg.split("a character needs")[0]


def test_a_json_map_naming_a_bone_the_file_lacks_is_refused(tmp_path):
    spec = CASES["custom_names"]
    path = write_rig(tmp_path, spec, "c")
    bad = custom_map(spec)
    bad["joints"] = dict(bad["joints"], left_elbow="no_such_bone")
    with pytest.raises(ConfigError, match="no_such_bone"):
        read_character(path, bone_map=bad)
    (tmp_path / "map.json").write_text(json.dumps({"pelvis": "bone_00", "joints": {"left_knee": "bone_01"}}))
    with pytest.raises(ConfigError, match="left_knee"):
        read_character(path, bone_map=tmp_path / "map.json")


def test_a_map_whose_joints_are_out_of_order_is_refused(tmp_path):
    spec = CASES["custom_names"]
    path = write_rig(tmp_path, spec, "c")
    m = custom_map(spec)
    j = dict(m["joints"])
    j["left_elbow"], j["left_wrist"] = j["left_wrist"], j["left_elbow"]
    with pytest.raises(ConfigError, match="is not below"):
        read_character(path, bone_map={"pelvis": m["pelvis"], "joints": j})


def test_files_that_are_not_characters_are_refused_naming_them(tmp_path):
    for name, data in [("a.glb", b"glTF" + b"\0" * 30), ("b.vrm", b"not a model"), ("c.bvh", b"HIERARCHY\n")]:
        p = tmp_path / name
        p.write_bytes(data)
        with pytest.raises((InputFileError, MotionFileError, ConfigError)) as e:
            read_character(p)
        assert name in str(e.value)
    with pytest.raises(InputFileError, match="character is a"):
        read_character(tmp_path / "x.obj")
    with pytest.raises(InputFileError, match="no such"):
        read_character(tmp_path / "missing.glb")


def test_a_gltf_may_not_read_files_outside_its_folder(tmp_path):
    (tmp_path / "sub").mkdir()
    doc = {"asset": {"version": "2.0"}, "buffers": [{"uri": "../secret.bin", "byteLength": 4}], "nodes": [{}]}
    p = tmp_path / "sub" / "x.gltf"
    p.write_text(json.dumps(doc))
    (tmp_path / "secret.bin").write_bytes(b"1234")
    with pytest.raises(GestureKitError, match="beside it"):
        read_character(p)


# ----------------------------------------------------------------------------- the parts, against plain references


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-1, 1), min_size=6, max_size=6))
def test_swing_is_the_smallest_rotation_onto_the_target(v):
    a, b = np.array(v[:3]), np.array(v[3:])
    if np.linalg.norm(a) < 1e-3 or np.linalg.norm(b) < 1e-3:
        return
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    r = swing(a, b)
    np.testing.assert_allclose(r @ a, b, atol=1e-9)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(r) == pytest.approx(1.0)
    # the smallest: its angle is the angle between the vectors. Both measured in well-conditioned
    # forms: near a half turn, arccos of the trace magnifies a rounding of 1e-16 to 1e-8 and more
    from scipy.spatial.transform import Rotation

    angle = Rotation.from_matrix(r).magnitude()
    assert angle == pytest.approx(np.arctan2(np.linalg.norm(np.cross(a, b)), a @ b), abs=1e-6)


def test_swing_of_opposite_vectors_is_a_half_turn():
    a = np.array([0.0, 1.0, 0.0])
    r = swing(a, -a)
    np.testing.assert_allclose(r @ a, -a, atol=1e-12)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.integers(2, 6))
def test_kabsch_recovers_a_rotation_and_matches_a_brute_force_fit(seed, k):
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    r = Rotation.random(random_state=seed).as_matrix()
    u = rng.normal(size=(k, 3))
    w = rng.uniform(0.1, 1.0, size=k)
    np.testing.assert_allclose(kabsch(u, u @ r.T, w), r, atol=1e-8)
    # with noise: no other rotation fits better (scipy's own least squares as the reference)
    v = u @ r.T + 0.1 * rng.normal(size=(k, 3))
    ours = kabsch(u, v, w)
    ref, _ = Rotation.align_vectors(v, u, weights=w)
    cost = lambda m: float(np.sum(w * np.sum((u @ m.T - v) ** 2, axis=1)))  # noqa: E731
    assert cost(ours) <= cost(ref.as_matrix()) + 1e-9


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000))
def test_facing_frame_turns_any_upright_pose_into_ours(seed):
    from scipy.spatial.transform import Rotation

    turn = Rotation.random(random_state=seed).as_matrix()
    pelvis, head = np.zeros(3), np.array([0.0, 0.7, 0.0])
    left, right = np.array([0.2, 0.5, 0.03]), np.array([-0.2, 0.5, 0.03])
    f = facing_frame(*(turn @ x for x in (pelvis, head, left, right)))
    np.testing.assert_allclose(f @ turn, np.eye(3), atol=1e-9)


def test_a_character_of_our_own_shape_follows_us_exactly(db):
    """Our own rig as a character (rolled bones, another size): every bone, branches too, exactly ours."""
    from scipy.spatial.transform import Rotation

    from gesturekit.character.rig import rig_for
    from gesturekit.skeleton import PARENTS

    motion = Motion(db.poses[:3].reshape(-1, N_JOINTS, 3), 15.0, db.joint_presence)
    rig = rig_for(motion)
    names = ("Hips",) + tuple(MIXAMO.get(n, n) for n in JOINT_NAMES)
    parents = np.array([-1] + [0 if p < 0 else p + 1 for p in PARENTS])
    bone_of = np.arange(1, N_JOINTS + 1)
    bone_of[[i for i, n in enumerate(JOINT_NAMES) if n not in MIXAMO]] = -1
    ch = Character(
        path=__import__("pathlib").Path("ours"),
        kind="bvh",
        names=names,
        parents=parents,
        rest_rotation=Rotation.random(len(names), random_state=1).as_matrix(),
        rest_position=np.vstack([[0, -0.15, 0], rig.rest]) * 1.2,
        bone_of=bone_of,
        pelvis=0,
        matched_by="test",
        to_file=np.eye(4),
    )
    out = retarget(motion, ch, wrist_slack=0.0)  # the exact end: hands at our reach
    assert out.report.max_direction_error < 1e-5
    assert out.report.side_error.max() < 1e-3
    assert out.report.wrist_error < 1e-9
    np.testing.assert_allclose(out.report.reach_scale, 1.2, rtol=1e-9)
    # scaled back to our size, the pose is ours (up to where the pelvis is)
    back = out.our_motion().positions
    have = bone_of >= 0
    np.testing.assert_allclose(
        back[:, have] - back[:, :1], motion.positions[:, have] - motion.positions[:, :1], atol=2e-4
    )


def test_a_hand_that_would_enter_the_torso_is_moved_out_and_counted(tmp_path, db):
    """A character with short arms: our hand just in front of our chest would sink into its chest."""
    from gesturekit.character.rig import rig_for

    ch = read_character(write_rig(tmp_path, RigSpec(arm=0.55, forearm=0.55), "short"))
    pos = db.poses[:2].reshape(-1, N_JOINTS, 3).copy()
    rig = rig_for(Motion(pos, 15.0, db.joint_presence))
    width = rig.rest[joint_index("left_shoulder")] - rig.rest[joint_index("right_shoulder")]
    lw = joint_index("left_wrist")
    # our left hand on the midline, 1 cm in front of our torso capsule, every frame
    shift = pos[:, joint_index("chest")] + [0.0, 0.0, TORSO_RADIUS * np.linalg.norm(width) + 0.01] - pos[:, lw]
    fingers = [joint_index(f"left_{f}{k}") for f in ("thumb", "index", "middle", "ring", "pinky") for k in range(1, 5)]
    pos[:, [lw, *fingers]] += shift[:, None]
    out = retarget(Motion(pos, 15.0, db.joint_presence), ch, wrist_slack=0.0)  # every target at our reach
    rep = out.report
    print(f"\nshort arms: {rep.summary()}")
    assert rep.ours_inside[0] == 0
    assert rep.moved_out[0] > rep.frames // 2
    assert rep.inside[0] == 0
    # the hand is on the capsule's surface, in front
    hand = out.position[:, ch.bone("left_wrist")]
    spine = [ch.pelvis] + [ch.bone(k) for k in ("spine_mid", "chest", "upper_chest")]
    from gesturekit.character._arms import distance_to_chain as _distance_to_chain

    d, _ = _distance_to_chain(hand, out.position[:, spine])
    assert (d >= rep.torso_radius * 0.999).all()
    assert (hand[:, 2] > out.position[:, ch.bone("chest"), 2]).all()
    # without the proxy it would have been inside: the same motion on a character whose torso is a line
    assert rep.torso_radius > 0


def test_required_joints_and_name_tables_are_consistent():
    assert PELVIS in REQUIRED
    for table in (MIXAMO, VRM_BONES[0], VRM_BONES[1]):
        assert set(REQUIRED) <= set(table)
        assert len(set(table.values())) == len(table)
    assert VRM_BONES[1]["left_thumb1"] == "leftThumbMetacarpal"
    assert VRM_BONES[0]["left_thumb1"] == "leftThumbProximal"
    scheme, found = match_names(["mixamorig5:" + MIXAMO[k] for k in REQUIRED])
    assert scheme == "mixamo" and set(found) == set(REQUIRED)


def _edited(tmp_path, name, edit):
    """A generated textured rig's GLB with its document (and binary) changed by ``edit(doc, binary) -> binary``."""
    from gesturekit.character.glb import glb_bytes, read_glb

    path = write_rig(tmp_path, CASES["zeggs_glb"], "base")
    doc, binary = read_glb(path.read_bytes())
    binary = edit(doc, bytes(binary))
    out = tmp_path / name
    out.write_bytes(glb_bytes(doc, binary))
    return out


def test_hostile_gltf_characters_are_refused_naming_the_file(tmp_path):
    def cycle(doc, binary):
        top = next(i for i, n in enumerate(doc["nodes"]) if n.get("name") == "Hips")
        leaf = next(i for i, n in enumerate(doc["nodes"]) if n.get("name") == "HeadEnd")
        doc["nodes"][leaf]["children"] = [top]
        return binary

    def past_the_end(doc, binary):
        doc["accessors"][0]["count"] = 10**9
        return binary

    def bad_texture(doc, binary):
        view = doc["bufferViews"][doc["images"][0]["bufferView"]]
        start = view.get("byteOffset", 0)
        return (
            binary[:start]
            + b"\x89PNG garbage"
            + b"\0" * (view["byteLength"] - 12)
            + binary[start + view["byteLength"] :]
        )

    def skin_joint_out_of_range(doc, binary):
        doc["skins"][0]["joints"][0] = len(doc["nodes"]) + 5
        return binary

    for name, edit in [
        ("cycle.glb", cycle),
        ("past.glb", past_the_end),
        ("texture.glb", bad_texture),
        ("skin.glb", skin_joint_out_of_range),
    ]:
        path = _edited(tmp_path, name, edit)
        with pytest.raises(GestureKitError) as e:
            read_character(path)
        assert name in str(e.value), str(e.value)
        print(f"{name}: {e.value}")


def test_a_motion_without_fingers_or_torso_leaves_those_bones_at_rest(tmp_path, db):
    """A partial skeleton (no fingers recorded, the torso derived): the character's finger bones keep their rest
    rotation relative to the hand, and the derived torso still drives its spine."""
    from gesturekit.skeleton import DERIVABLE_JOINTS, JointPresence

    ch, _ = _read(tmp_path, "mixamo_t")
    body = [n for n in JOINT_NAMES if not any(f in n for f in FINGERS) and n not in DERIVABLE_JOINTS]
    presence = JointPresence.from_names(recorded=body, derived=DERIVABLE_JOINTS)
    motion = Motion(db.poses[:2].reshape(-1, N_JOINTS, 3), 15.0, presence)
    out = retarget(motion, ch)
    finger_bones = [ch.bone(f"left_{f}{k}") for f in FINGERS for k in range(1, 4)]
    hand = ch.bone("left_wrist")
    q = ch.rest_rotation
    for b in finger_bones:
        pa = ch.parents[b]
        local = np.swapaxes(out.rotation[:, pa], 1, 2) @ out.rotation[:, b]
        np.testing.assert_allclose(local, np.broadcast_to(q[pa].T @ q[b], local.shape), atol=1e-9)
    assert hand in ch.parents[finger_bones]
    assert not any(any(f in n for f in FINGERS) for n in out.report.missing)
    assert out.report.max_direction_error < DIRECTION_DEGREES
