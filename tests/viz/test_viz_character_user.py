"""The page viewer with a user's character: what the page skins is what the retargeting skins, colours, bodies."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.character.bone_body import bone_body
from gesturekit.character.look import part_colors, scheme_for
from gesturekit.character.retarget import retarget
from gesturekit.demo import open_default_database
from gesturekit.errors import ConfigError
from gesturekit.motion import Motion
from gesturekit.viz.character_page import MAX_COLORS, PALETTE_ERROR, ROOT_NAME, palette
from gesturekit.viz.viewer import _decoded, _quaternion_matrices, read_viewer_data, skeleton_viewer, viewer_data
from tests.character_rigs import CASES, write_rig


@pytest.fixture(scope="module")
def motion() -> Motion:
    db = open_default_database()
    return Motion(db.poses[:3].reshape(-1, 55, 3).astype(np.float32), 15.0, db.joint_presence)


@pytest.fixture(scope="module")
def rigs(tmp_path_factory):
    from gesturekit.character.user import read_character

    folder = tmp_path_factory.mktemp("rigs")
    return lambda name: read_character(write_rig(folder, CASES[name]))


def decoded(data: dict) -> dict:
    """The data as the page gets them: through JSON, the arrays decoded."""
    return _decoded(json.loads(json.dumps(data)))


def page_skinned(m: dict) -> np.ndarray:
    """The vertices three.js draws for one motion of the data, shape (frames, V, 3): the int16 quaternions
    normalised, each bone's world matrix as the product of its parents' (translation by its offset, then its
    rotation; the root at the data's root position), times the inverse bind (a translation by minus its rest
    position), blended by the skin weights."""
    rot = _quaternion_matrices(m["rotations"])
    parents, offsets = m["rig"]["parents"], m["rig"]["offsets"].astype(np.float64)
    world = np.empty_like(rot)
    pos = np.empty(rot.shape[:2] + (3,))
    for j, p in enumerate(parents):
        if p < 0:
            world[:, j], pos[:, j] = rot[:, j], m["root"]
        else:
            world[:, j] = world[:, p] @ rot[:, j]
            pos[:, j] = pos[:, p] + world[:, p] @ offsets[j]
    rest = m["rig"]["rest"].astype(np.float64)
    v = m["mesh"]["vertices"].astype(np.float64)
    joints, weights = m["mesh"]["joints"].astype(np.int64), m["mesh"]["weights"].astype(np.float64)
    out = np.zeros((rot.shape[0], len(v), 3))
    for k in range(4):
        j = joints[:, k]
        out += weights[None, :, k, None] * (np.einsum("tvab,vb->tva", world[:, j], v - rest[j]) + pos[:, j])
    return out


def retarget_skinned(retargeted, skin) -> np.ndarray:
    """The retargeting's own skinning of ``skin`` (rest-pose mesh), shape (frames, V, 3)."""
    s = retargeted.skinning()
    v = skin.vertices.astype(np.float64)
    out = np.zeros((s.shape[0], len(v), 3))
    for k in range(4):
        j = skin.joints[:, k]
        m = s[:, j]
        out += skin.weights[None, :, k, None] * (np.einsum("tvab,vb->tva", m[..., :3], v) + m[..., 3])
    return out


@pytest.mark.parametrize("case", ["mixamo_t", "vrm0_a", "vrm1_t", "twist", "mixamo_a_rolled"])
def test_the_page_skins_the_character_as_the_retargeting_does(motion, rigs, case):
    ch = rigs(case)
    raw = viewer_data([motion, motion], character=ch, labels=["a", "b"])
    assert raw["motions"][1]["mesh"] == {"shared": 0}  # one mesh sent for both
    data = decoded(raw)
    posed = retarget(motion, ch)
    want = retarget_skinned(posed, ch.skin)
    for m in data["motions"]:
        assert m["rig"]["names"] == list(ch.names)
        assert m["derived"] == []
        got = page_skinned(m)
        assert got.shape == want.shape
        assert np.abs(got - want).max() < 1e-4
        # the mesh's colours, through the palette
        assert np.abs(np.asarray(m["colors"])[m["mesh"]["parts"]] - ch.skin.colors).max() <= 0.5 / 255 + 1e-6
    # side by side along X, framed on their pelvis and matched bones (the page shifts each character)
    lo, hi = np.asarray(data["box"])
    offsets = [m["offset"] for m in data["motions"]]
    assert offsets[0] < 0 < offsets[1]
    for dx in offsets:
        matched = posed.position[:, ch.bone_of[ch.bone_of >= 0]] + [dx, 0, 0]
        assert (matched >= lo).all() and (matched <= hi).all()
    # a standing character of theirs: the frame is at its height, not at ours (our pelvis at the origin)
    assert lo[1] > 0.3


@pytest.mark.slow
def test_a_bvh_character_gets_a_body_of_capsules(motion, rigs):
    ch = rigs("bvh_zeggs_a")
    assert ch.skin is None
    raw = viewer_data([motion, motion], character=ch)
    assert raw["motions"][1]["mesh"] == {"shared": 0}  # the schemes differ in colours only
    assert raw["motions"][0]["colors"] != raw["motions"][1]["colors"]
    data = decoded(raw)
    posed = retarget(motion, ch)
    for i, m in enumerate(data["motions"]):
        scheme = scheme_for(i)
        body = bone_body(ch, scheme=scheme)
        assert m["scheme"] == scheme and body.n_vertices > 1000
        np.testing.assert_allclose(m["mesh"]["vertices"], body.vertices)
        assert np.abs(page_skinned(m) - retarget_skinned(posed, body)).max() < 1e-4
        # in the scheme's skin and shirt colours
        shown = {tuple(np.round(c, 4)) for c in np.asarray(m["colors"])[m["mesh"]["parts"]]}
        allowed = {tuple(np.round(np.round(c * 255) / 255, 4)) for c in part_colors(scheme)[:2]}
        assert shown == allowed
    # every vertex follows one bone, and its normal points away from that bone's capsule axis
    body = bone_body(ch)
    assert (body.weights[:, 0] == 1).all() and (body.weights[:, 1:] == 0).all()
    assert body.joints[:, 0].max() < ch.n_bones
    v, f = body.vertices.astype(np.float64), body.faces
    volume = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6
    assert volume > 0  # closed surfaces, counter-clockwise seen from outside
    # the head's capsule: normals point away from the head bone
    head = ch.bone("head")
    on_head = body.joints[:, 0] == head
    assert on_head.any()
    away = np.einsum("ij,ij->i", body.normals[on_head], v[on_head] - ch.rest_position[head])
    assert (away > -1e-6).mean() > 0.95


def test_several_roots_and_many_bones_hang_from_one_added_root(motion, rigs):
    ch = rigs("mixamo_t")
    extra = 260  # props at the floor, roots of their own: more than a byte indexes
    props = np.column_stack([np.linspace(-1, 1, extra), np.zeros(extra), np.full(extra, -0.5)])
    many = dataclasses.replace(
        ch,
        names=(*ch.names, *(f"prop{i}" for i in range(extra))),
        parents=np.concatenate([ch.parents, np.full(extra, -1)]),
        rest_rotation=np.concatenate([ch.rest_rotation, np.broadcast_to(np.eye(3), (extra, 3, 3))]),
        rest_position=np.concatenate([ch.rest_position, props]),
    )
    raw = viewer_data(motion, character=many)
    m = raw["motions"][0]
    assert m["mesh"]["joints"]["dtype"] == "u2"
    m = decoded(raw)["motions"][0]
    parents = m["rig"]["parents"]
    assert m["rig"]["names"][0] == ROOT_NAME and parents[0] == -1 and sum(p < 0 for p in parents) == 1
    assert (m["root"] == 0).all()
    np.testing.assert_allclose(m["rig"]["rest"][1:], many.rest_position, atol=1e-6)
    want = retarget_skinned(retarget(motion, many), many.skin)
    assert np.abs(page_skinned(m) - want).max() < 1e-4


def test_the_standalone_page_holds_the_character(motion, rigs):
    ch = rigs("mixamo_t")
    page = skeleton_viewer(motion, character=ch, key="mine")
    data = read_viewer_data(page)
    m = data["motions"][0]
    posed = retarget(Motion(motion.positions, motion.fps, motion.presence), ch)
    # the page's forward kinematics puts their bones where the retargeting does
    np.testing.assert_allclose(m["points"], posed.position, atol=1e-4)


@pytest.mark.slow
@pytest.mark.parametrize("case", ["vrm0_a", "bvh_zeggs_a"])
def test_the_page_frames_and_draws_the_character_as_the_mp4_does(motion, rigs, case):
    from gesturekit.viz.character_render import CharacterStage

    ch = rigs(case)
    other = Motion(motion.positions[::-1].copy(), motion.fps, motion.presence)
    data = decoded(viewer_data([motion, other], character=ch))
    stage = CharacterStage([motion, other], character=ch)
    np.testing.assert_allclose(np.asarray(data["box"]), stage.box, atol=1e-9)
    np.testing.assert_allclose([m["offset"] for m in data["motions"]], stage.offsets, atol=1e-9)
    for i, m in enumerate(data["motions"]):  # one body: the page's vertices are the MP4's (bar the offset)
        np.testing.assert_allclose(m["mesh"]["vertices"], stage.users[i].skin.vertices)
        np.testing.assert_allclose(page_skinned(m)[3] + [m["offset"], 0, 0], stage.vertices(i, 3), atol=1e-4)


def test_a_notebook_view_draws_the_character(motion, rigs):
    from gesturekit.viz.notebook import character_view

    ch = rigs("vrm1_t")
    view = character_view([motion, motion], character=ch, labels=["a", "b"], height=300)
    data = read_viewer_data(view.page)
    assert [m["rig"]["names"] for m in data["motions"]] == [list(ch.names)] * 2
    assert all(m["scheme"] == "character" for m in data["motions"])


def test_palette_of_few_colours_is_exact_and_of_many_is_bounded():
    rng = np.random.default_rng(0)
    few = rng.random((40, 3))[rng.integers(0, 40, 5000)]
    pal, parts = palette(few)
    assert len(pal) == 40 and np.abs(pal[parts] - few).max() <= 0.5 / 255 + 1e-12
    # a smooth texture: a gradient over the body, quantised by the median cut
    t = rng.random((20000, 2))
    smooth = np.column_stack([0.3 + 0.6 * t[:, 0], 0.2 + 0.5 * t[:, 1], 0.4 + 0.2 * t[:, 0] * t[:, 1]])
    pal, parts = palette(smooth)
    err = np.abs(pal[parts] - smooth).max()
    print(f"median cut of a smooth gradient: {len(pal)} colours, largest error {err:.4f}")
    assert len(pal) <= MAX_COLORS and err < 0.03
    assert np.array_equal(palette(smooth)[1], parts)  # deterministic
    with pytest.raises(ConfigError, match="216"):
        palette(smooth, max_colors=100)


@pytest.mark.slow
@settings(max_examples=30, deadline=None)
@given(
    st.integers(1, 3000),
    st.integers(0, 2**32 - 1),
    st.integers(216, 300),
    st.sampled_from(["uniform", "clustered", "grey"]),
)
def test_palette_error_is_bounded(n, seed, k, kind):
    """At most ``k`` colours; exact to 8 bits where the colours are that few, else within PALETTE_ERROR."""
    rng = np.random.default_rng(seed)
    colors = rng.random((n, 3))
    if kind == "clustered":
        colors = np.clip(rng.random((5, 3))[rng.integers(0, 5, n)] + rng.normal(0, 0.05, (n, 3)), 0, 1)
    elif kind == "grey":
        colors = np.repeat(colors[:, :1], 3, axis=1)
    pal, parts = palette(colors, max_colors=k)
    assert len(pal) <= k and parts.shape == (n,) and parts.min() >= 0 and parts.max() < len(pal)
    assert (pal >= 0).all() and (pal <= 1).all()
    err = np.abs(pal[parts] - colors).max()
    distinct = len(np.unique(np.round(colors * 255), axis=0))
    assert err <= (0.5 / 255 if distinct <= k else PALETTE_ERROR + 0.5 / 255) + 1e-9
