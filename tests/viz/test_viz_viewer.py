"""The three.js viewer: its page carries every motion as a skinned character posed on every shown frame, side by
side, with the speech, offline; and its bundle is the build of the sources from the npm registry's packages."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

from gesturekit.character import look
from gesturekit.character.mesh import PARTS, CharacterMesh, build_mesh
from gesturekit.character.paint import split_at_part_seams
from gesturekit.character.rig import rig_for, rotation_to_quaternion, solve_pose
from gesturekit.errors import ConfigError
from gesturekit.motion import Motion
from gesturekit.skeleton import N_JOINTS
from gesturekit.viz.figures import skeleton_figure
from gesturekit.viz.viewer import (
    QUATERNION_SCALE,
    VIEWER_MAX_FRAMES,
    read_viewer_args,
    read_viewer_data,
    skeleton_viewer,
    viewer_args,
    viewer_data,
)
from gesturekit.viz.web import build as web


def _motion(n_frames: int, *, seed: int = 0, fps: float = 15.0) -> Motion:
    rng = np.random.default_rng(seed)
    pos = rng.normal(0, 0.3, size=(1, N_JOINTS, 3)) + np.cumsum(rng.normal(0, 0.01, (n_frames, N_JOINTS, 3)), 0)
    return Motion(pos.astype(np.float32), fps)


@pytest.mark.slow
@settings(max_examples=15, deadline=None)
@given(hst.integers(1, 60), hst.integers(1, 40), hst.integers(0, 10**6))
def test_every_shown_frame_poses_each_character_as_the_rig_solve_does_side_by_side(n, max_frames, seed):
    a, b = _motion(n, seed=seed), _motion(max(1, n // 2), seed=seed + 1)
    data = read_viewer_data(skeleton_viewer([a, b], labels=["A", "B"], max_frames=max_frames))
    fig = skeleton_figure([a, b], labels=["A", "B"], max_frames=max_frames)
    assert data["times"] == fig.layout.meta["times"]  # the same time grid as the plotly figure
    step = data["frame_step"]
    assert len(data["times"]) <= max_frames and (step == 1) == (n <= max_frames)
    assert (data["note"] != "") == (step > 1)
    for i, (motion, m) in enumerate(zip((a, b), data["motions"])):
        src = np.minimum(np.arange(len(data["times"])) * step, motion.n_frames - 1)  # shorter: holds its last pose
        shown = Motion(motion.positions[src], motion.fps)
        rig = rig_for(shown)
        pose = solve_pose(shown, rig)
        # the rotations are the solve's, rounded to int16 (sign of a quaternion: w >= 0 on both sides)
        np.testing.assert_allclose(m["rotations"], rotation_to_quaternion(pose.local), atol=0.51 / QUATERNION_SCALE)
        np.testing.assert_allclose(m["root"], pose.root, atol=1e-6)
        # forward kinematics of the page's bones lands where the rig's does
        expected = pose.world(rig)[1] + [m["offset"], 0.0, 0.0]
        np.testing.assert_allclose(m["points"], expected, atol=2e-3)
        # the mesh is the character's, bound to this rig, in the k-th scheme's colours
        mesh, page = build_mesh(rig), m["mesh"]
        for name in ("vertices", "normals", "joints", "weights"):  # every triangle's corners as the mesh has them
            np.testing.assert_array_equal(page[name][page["faces"]], getattr(mesh, name)[mesh.faces])
        np.testing.assert_array_equal(page["parts"][: mesh.n_vertices], mesh.parts)  # no derived joint here
        np.testing.assert_allclose(m["rig"]["offsets"], rig.offsets, atol=1e-6)
        assert m["scheme"] == look.scheme_for(i)
        np.testing.assert_allclose(np.asarray(m["colors"])[: len(PARTS)], look.part_colors(m["scheme"]), atol=1e-6)
    assert data["motions"][1]["offset"] - data["motions"][0]["offset"] >= 0.8  # B on the viewer's right


def test_neutral_draws_every_motion_grey():
    data = viewer_data([_motion(3), _motion(3, seed=1)], neutral=True)
    assert [m["scheme"] for m in data["motions"]] == [look.NEUTRAL, look.NEUTRAL]


@pytest.mark.slow
def test_every_frame_is_kept_up_to_ten_minutes_at_15_fps_and_beyond_the_page_says_so():
    assert VIEWER_MAX_FRAMES >= 10 * 60 * 15
    base = _motion(1).positions
    pos = np.repeat(base, VIEWER_MAX_FRAMES, axis=0)
    pos[:, :, 1] += np.arange(VIEWER_MAX_FRAMES)[:, None] * 1e-4  # each frame its own height
    data = viewer_data(Motion(pos, 15.0))
    assert data["frame_step"] == 1 and len(data["times"]) == VIEWER_MAX_FRAMES and data["note"] == ""
    assert data["motions"][0]["rotations"]["shape"] == f"{VIEWER_MAX_FRAMES},{N_JOINTS},4"
    longer = viewer_data(Motion(np.concatenate([pos, pos[:1]]), 15.0))
    assert longer["frame_step"] == 2 and len(longer["times"]) == (VIEWER_MAX_FRAMES + 2) // 2
    assert "every 2nd frame shown" in longer["note"] and str(VIEWER_MAX_FRAMES + 1) in longer["note"]


@settings(max_examples=15, deadline=None)
@given(hst.integers(1, 40), hst.integers(0, 10**6), hst.sampled_from([8000, 16000]))
def test_the_speech_is_embedded_and_decodes_to_its_samples(n, seed, sr):
    m = _motion(n, seed=seed)
    rng = np.random.default_rng(seed)
    audio = rng.uniform(-1, 1, int(sr * n / 15.0) + int(rng.integers(-200, 200))).astype(np.float32)
    audio = audio[: max(1, len(audio))]
    data = read_viewer_data(skeleton_viewer(m, audio=audio, sr=sr))
    assert data["audio_sr"] == sr
    got = data["audio"]
    np.testing.assert_allclose(got[: len(audio)], audio, atol=1 / 32767 + 1e-7)  # 16-bit PCM
    # silence after shorter speech, so the speech's clock reaches the last frame
    assert len(got) >= max(len(audio), int(np.ceil(n / 15.0 * sr)))
    assert np.all(got[len(audio) :] == 0)


def test_without_speech_there_is_no_audio_element():
    page = skeleton_viewer(_motion(5))
    assert "<audio" not in page and read_viewer_data(page)["audio"] is None
    assert "<audio" in skeleton_viewer(_motion(5), audio=np.zeros(100, np.float32))


def _bundle_script(page: str) -> tuple[str, str]:
    """The page's module script (the bundle) and the page without it."""
    start = page.index('<script type="module">') + len('<script type="module">')
    end = page.index("</script>", start)
    return page[start:end], page[:start] + page[end:]


def test_page_is_offline_inlines_the_built_bundle_and_names_survive_any_text():
    label = 'k-NN </script><b>"&'
    page = skeleton_viewer(
        _motion(10),
        labels=[label],
        title="t </script> __AUDIO__ __BUNDLE__",
        key='a"b<c __DATA__',
        audio=np.zeros(1000, np.float32),
    )
    script, rest = _bundle_script(page)
    assert script == web.bundle().replace("</script", "<\\/script")  # the built bundle, whole
    # nothing fetched: the only source is the speech's data URI; the bundle imports nothing
    assert not re.search(r"(src|href)\s*=\s*\"(?!data:audio/wav;base64,)|https?://|@import", rest)
    assert not re.search(r"\bimport\s*\(|\bimport\s*[\w{*][^;]*\bfrom\s*[\"']|^import\s*[\"']", script)
    data = read_viewer_data(page)
    assert data["motions"][0]["label"] == label and data["title"] == "t </script> __AUDIO__ __BUNDLE__"
    assert data["key"] == 'a"b<c __DATA__'
    assert page.count("</script>") == 2  # only the page's own two script elements end


def test_the_framing_holds_every_joint_and_the_look_is_the_characters():
    m = _motion(40, seed=3)
    data = read_viewer_data(skeleton_viewer(m))
    assert data["up"] == [0, 1, 0] and data["look"]["view"] == list(look.VIEW_DIRECTION)
    pts = m.positions.reshape(-1, 3)
    lo, hi = np.asarray(data["box"])
    # the reach of most frames (each frame's extremes), and the lowest joint of every frame
    q = look.REACH_QUANTILE
    assert np.all(hi >= np.quantile(m.positions.max(axis=1), q, axis=0) + look.FRAME_MARGIN)
    assert np.all(lo[[0, 2]] <= np.quantile(m.positions.min(axis=1), 1 - q, axis=0)[[0, 2]] - look.FRAME_MARGIN)
    # the upper body's box reaches below the joints (the hips); the full body's down to the floor under the legs
    assert lo[1] < pts[:, 1].min() - look.FRAME_MARGIN - 0.1
    full = np.asarray(data["boxes"][look.FULL_BODY])
    assert data["ground"] is not None and full[0, 1] <= data["ground"] < lo[1]
    assert data["look"] == {
        "background": look.BACKGROUND,
        "ambient": look.AMBIENT,
        "key": look.KEY,
        "light": list(look.LIGHT_DIRECTION),
        "lights": [[list(d), k] for d, k in look.LIGHTS],
        "fov": look.FIELD_OF_VIEW,
        "view": list(look.VIEW_DIRECTION),
        "depth_share": look.DEPTH_SHARE,
        "least_height": look.LEAST_VIEW_HEIGHT,
    }


@pytest.mark.parametrize(
    "kwargs, problem",
    [
        (dict(motions=[]), "at least one motion"),
        (dict(max_frames=0), "max_frames must be at least 1"),
        (dict(fps=0.0), "fps must be positive"),
        (dict(audio=np.zeros((10, 2), np.float32)), "mono samples"),
        (dict(audio=np.zeros(10, np.float32), sr=0), "sample rate"),
    ],
)
def test_bad_input_is_refused(kwargs, problem):
    kwargs = dict(kwargs)
    motions = kwargs.pop("motions", _motion(5))
    with pytest.raises(ConfigError, match=problem):
        skeleton_viewer(motions, **kwargs)


@pytest.mark.slow
@settings(max_examples=5, deadline=None)
@given(hst.integers(1, 20), hst.integers(0, 10**6), hst.booleans())
def test_the_component_args_carry_what_the_standalone_page_carries(n, seed, with_speech):
    """The app's component gets the page's data and speech as args; their hash tells viewers apart."""
    motions = [_motion(n, seed=seed), _motion(n + 3, seed=seed + 1)]
    rng = np.random.default_rng(seed)
    audio = rng.uniform(-1, 1, 1000 * n).astype(np.float32) if with_speech else None
    view = {"labels": ["a", "b"], "title": "t"}
    args = viewer_args(motions, audio=audio, **view)
    got = read_viewer_args(args["data"], args["audio"], "k")
    want = read_viewer_data(skeleton_viewer(motions, audio=audio, key="k", **view))
    assert json.loads(args["data"]) == viewer_data(motions, **view)
    assert got["key"] == want["key"] == "k" and got["audio_sr"] == want["audio_sr"]
    if with_speech:
        np.testing.assert_array_equal(got["audio"], want["audio"])
    else:
        assert got["audio"] is None and args["audio"] is None
    for g, w in zip(got["motions"], want["motions"]):
        np.testing.assert_array_equal(g["points"], w["points"])
    # the same viewer has the same hash (a rerun keeps the drawn view); other speech or motions another
    assert viewer_args(motions, audio=audio, **view)["hash"] == args["hash"]
    other_audio = np.zeros(10, np.float32) if audio is None else audio * 0.5
    assert viewer_args(motions, audio=other_audio, **view)["hash"] != args["hash"]
    assert viewer_args(motions[::-1], audio=audio, **view)["hash"] != args["hash"]


# ----------------------------------------------------------------------------- the web module and its build


def test_the_static_bundle_is_the_build_of_the_current_sources():
    """pip install builds it (setup.py); a change to src/, package.json or the lock without a build fails here."""
    assert web.is_current(), (
        "static/ is not the build of gesturekit/viz/web's sources: python -m gesturekit.viz.web.build"
    )
    assert (web.STATIC / "index.html").is_file() and len(web.bundle()) > 100_000  # three.js is in it


def test_the_source_hash_changes_with_any_source(tmp_path):
    for name in (*web.SOURCES, "src/a.js"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("x")
    before = web.source_hash(tmp_path)
    for name in (*web.SOURCES, "src/a.js"):
        (tmp_path / name).write_text("y")
        assert web.source_hash(tmp_path) != before
        (tmp_path / name).write_text("x")
    (tmp_path / "src" / "b.js").write_text("")
    assert web.source_hash(tmp_path) != before
    assert not web.is_current(tmp_path)  # nothing built there


def test_no_library_is_copied_into_the_web_module():
    """Outside node_modules/ and static/ (both made by the build, ignored by git) are only the project's own
    files: the npm manifest and lock, the build, and small ES modules that import three (and three-vrm) by their
    package names."""
    own = {"package.json", "package-lock.json", "build.mjs", "build.py", "__init__.py"}
    for path in web.HERE.rglob("*"):
        rel = path.relative_to(web.HERE)
        if path.is_dir() or rel.parts[0] in ("node_modules", "static", "__pycache__"):
            continue
        if rel.parts[0] == "src":
            text = path.read_text(encoding="utf-8")
            assert path.suffix == ".js" and len(text) < 24_000, rel  # the control timeline is the largest
            assert not re.search(r"@license|Copyright|three\.module", text), rel
            for spec in re.findall(r"from\s+\"([^\"]+)\"", text):
                assert spec.startswith(("three", "@pixiv/three-vrm", "./")), (rel, spec)
        else:
            assert str(rel) in own, rel


def test_a_module_outside_the_folder_is_bundled_with_the_locked_three(tmp_path):
    """bundle_module: a module anywhere (a test's page) imports three and its examples' loaders by package name,
    and gets the version of the lock (three.js's REVISION is in the bundle)."""
    try:
        web._node()
    except RuntimeError as exc:
        pytest.skip(str(exc))
    entry = tmp_path / "page.js"
    entry.write_text(
        'import { REVISION } from "three";\n'
        'import { GLTFLoader } from "three/examples/jsm/loaders/GLTFLoader.js";\n'
        "window.made = [REVISION, new GLTFLoader()];\n",
        encoding="utf-8",
    )
    out = web.bundle_module(entry, tmp_path / "page.bundle.js")
    text = out.read_text(encoding="utf-8")
    version = json.loads((web.HERE / "package.json").read_text())["dependencies"]["three"]
    assert f'"{version.split(".")[1]}"' in text  # REVISION, the minor version, as a string
    assert "KHR_materials_emissive_strength" in text and "glTF" in text  # the loader and its extensions
    assert 'from"three"' not in text.replace(" ", "") and "import " not in text  # nothing left to resolve


def test_the_npm_packages_are_pinned_and_locked():
    package = json.loads((web.HERE / "package.json").read_text())
    lock = json.loads((web.HERE / "package-lock.json").read_text())
    assert set(package["dependencies"]) == {"three", "@pixiv/three-vrm"}
    assert set(package["devDependencies"]) == {"esbuild"}
    for name, version in {**package["dependencies"], **package["devDependencies"]}.items():
        assert re.fullmatch(r"\d+\.\d+\.\d+", version), (name, version)  # exact: no range
        assert lock["packages"][f"node_modules/{name}"]["version"] == version
        assert lock["packages"][f"node_modules/{name}"]["integrity"].startswith("sha512-")  # npm ci checks it
    # what they bring (three-vrm's own packages) is locked as exactly
    for key, entry in lock["packages"].items():
        if key:
            assert re.fullmatch(r"\d+\.\d+\.\d+", entry["version"]), key
            assert entry["integrity"].startswith("sha512-"), key
    vrm = [k for k in lock["packages"] if k.startswith("node_modules/@pixiv/")]
    assert {lock["packages"][k]["version"] for k in vrm} == {package["dependencies"]["@pixiv/three-vrm"]}


def test_a_motion_with_every_joint_at_one_point_has_no_body_but_still_plays():
    still = Motion(np.zeros((4, N_JOINTS, 3), np.float32), 15.0)
    data = read_viewer_data(skeleton_viewer([still, _motion(4)]))
    nobody, body = data["motions"]
    assert nobody["mesh"]["vertices"].shape == (0, 3) and nobody["mesh"]["faces"].shape == (0, 3)
    assert body["mesh"]["vertices"].shape[0] > 0 and len(data["times"]) == 4
    assert np.isfinite(nobody["rotations"]).all() and np.isfinite(nobody["points"]).all()


@settings(max_examples=60, deadline=None)
@given(hst.integers(3, 30), hst.integers(1, 40), hst.integers(1, 4), hst.integers(0, 10**6))
def test_splitting_at_part_seams_keeps_every_corner_and_gives_each_triangle_one_part(
    n_vertices, n_faces, n_parts, seed
):
    rng = np.random.default_rng(seed)
    mesh = CharacterMesh(
        vertices=rng.normal(size=(n_vertices, 3)).astype(np.float32),
        normals=rng.normal(size=(n_vertices, 3)).astype(np.float32),
        faces=rng.integers(0, n_vertices, (n_faces, 3)).astype(np.int32),
        joints=rng.integers(0, N_JOINTS, (n_vertices, 4)).astype(np.uint8),
        weights=rng.dirichlet(np.ones(4), n_vertices).astype(np.float32),
        parts=np.zeros(n_vertices, np.uint8),
    )
    parts = rng.integers(0, n_parts, n_vertices).astype(np.uint8)
    out = split_at_part_seams(mesh, parts)
    for name in ("vertices", "normals", "joints", "weights"):
        np.testing.assert_array_equal(getattr(out, name)[out.faces], getattr(mesh, name)[mesh.faces])
    corner = out.parts[out.faces]
    assert (corner == corner[:, :1]).all()  # one part per triangle
    np.testing.assert_array_equal(out.parts[:n_vertices], parts)  # the original vertices keep theirs
    # a triangle takes the lowest part among its corners (so a seam between two rings runs along a ring)
    np.testing.assert_array_equal(corner[:, 0], parts[mesh.faces].min(axis=1))
    assert out.n_vertices <= n_vertices + 2 * n_faces  # copies only where a seam needs them
