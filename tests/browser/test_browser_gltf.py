"""The glTF export read back by three.js in a real browser: its GLTFLoader and AnimationMixer place every joint of
every frame within a millimetre of the motion.

Headless Debian Chromium driven by Playwright (``tests/app_browser.py``) loads
each ``.glb`` with three.js's own ``GLTFLoader``, from the npm ``three`` of the
viewer (``gesturekit/viz/web``'s lock), bundled for the page at test time by
:func:`gesturekit.viz.web.build.bundle_module`; the page and the files are
served to it by Playwright's routing, from a temporary folder. Skipped, with
the reason, where the browser or node is missing.

The round trip's error is printed, and named in every assertion's message.
"""

from __future__ import annotations

import numpy as np
import pytest

from gesturekit.character.mesh import build_mesh
from gesturekit.character.rig import rig_for, solve_pose
from gesturekit.character.skin import skin_vertices
from gesturekit.export.gltf import accessor_array, export_gltf, node_matrices, read_glb
from gesturekit.motion import Motion
from gesturekit.skeleton import DERIVABLE_JOINTS, JOINT_NAMES, N_JOINTS, PARENTS, JointPresence
from gesturekit.viz.web import build as web
from tests import app_browser

pytestmark = pytest.mark.skipif(
    app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"
)

#: Largest distance (metres) of a joint or vertex placed by three.js from where it belongs.
TOLERANCE = 1e-3

#: Frames at which the skinned body is compared with the reference skinning.
SKIN_FRAMES = (0, 17, -1)

ORIGIN = "http://gesturekit.test"

#: The page's module: three.js's GLTFLoader and AnimationMixer, and ``window.readBack(url, fps, joints, skinFrames)``
#: returning what three.js makes of the file: the nodes' names, the clip, the skinned meshes and their bones, every
#: joint's world position at every key (frame / fps) and the body's vertices at ``skinFrames``.
PROBE = """
import { AnimationMixer, LoopOnce, Vector3 } from "three";
import { GLTFLoader } from "three/examples/jsm/loaders/GLTFLoader.js";

window.readBack = async (url, fps, joints, skinFrames) => {
  const gltf = await new GLTFLoader().loadAsync(url);
  const nodes = await gltf.parser.getDependencies("node");
  const names = nodes.map((n) => n.name);
  const bones = joints.map((name) => nodes[names.indexOf(name)]);
  const meshes = [];
  let plainMeshes = 0;
  gltf.scene.traverse((o) => {
    if (o.isSkinnedMesh) meshes.push(o);
    else if (o.isMesh) plainMeshes += 1;
  });
  const clip = gltf.animations[0];
  const mixer = new AnimationMixer(gltf.scene);
  // played once and held at its end: a looping clip would wrap its last key round to its first
  const action = mixer.clipAction(clip).setLoop(LoopOnce, 1);
  action.clampWhenFinished = true;
  action.play();
  const frames = Math.round(clip.duration * fps) + 1;
  const positions = new Float64Array(frames * bones.length * 3);
  const vertices = [];
  const v = new Vector3();
  for (let f = 0; f < frames; f++) {
    mixer.setTime(f / fps);
    gltf.scene.updateMatrixWorld(true);
    bones.forEach((bone, k) => {
      bone.getWorldPosition(v);
      positions.set([v.x, v.y, v.z], (f * bones.length + k) * 3);
    });
    if (skinFrames.includes(f)) {
      const mesh = meshes[0], n = mesh.geometry.attributes.position.count, out = new Float64Array(n * 3);
      for (let i = 0; i < n; i++) {
        mesh.getVertexPosition(i, v).applyMatrix4(mesh.matrixWorld);
        out.set([v.x, v.y, v.z], i * 3);
      }
      vertices.push(Array.from(out));
    }
  }
  return {
    names,
    isBone: bones.map((b) => !!(b && b.isBone)),
    clips: gltf.animations.length,
    duration: clip.duration,
    tracks: clip.tracks.length,
    skinned: meshes.length,
    plainMeshes,
    boundToJoints: meshes.map((m) => m.skeleton.bones.length === bones.length
                                     && m.skeleton.bones.every((b, k) => b === bones[k])),
    frames,
    positions: Array.from(positions),
    vertices,
  };
};
"""

PAGE = '<!DOCTYPE html><html><head><meta charset="utf-8"></head><body><script type="module" src="probe.js"></script>'


# ----------------------------------------------------------------------------- inputs


def demo_motion() -> Motion:
    """Four clips of the demo database, one after another (15 fps)."""
    from gesturekit.demo import open_default_database

    db = open_default_database()
    return Motion(db.poses[:4].reshape(-1, N_JOINTS, 3).astype(np.float32), db.fps, db.joint_presence)


def partial_motion() -> Motion:
    """A demo take without thumbs, its torso derived (the partial skeleton of tests/export/test_export_gltf.py)."""
    from gesturekit.datasets.synthetic import generate_demo_take

    thumbs = {f"{side}_thumb{k}" for side in ("left", "right") for k in range(1, 5)}
    torso = tuple(n for n in DERIVABLE_JOINTS if n != "neck")
    presence = JointPresence.from_names(recorded=set(JOINT_NAMES) - thumbs - set(torso), derived=torso)
    positions = generate_demo_take(seconds=4.0, seed=7, name="p")[0].motion.positions.copy()
    for j in np.flatnonzero(presence.absent & (PARENTS >= 0)):
        positions[:, j] = positions[:, PARENTS[j]]  # absent joints sit on their parent, as readers place them
    return Motion(positions, 15.0, presence)


def file_positions(path, joints) -> np.ndarray:
    """(keys, joints, 3) world positions of the named nodes, as the export's own report reads its file."""
    doc, binary = read_glb(path.read_bytes())
    animation = doc["animations"][0]
    tracks = {}
    for channel in animation["channels"]:
        sampler = animation["samplers"][channel["sampler"]]
        times = accessor_array(doc, binary, sampler["input"])
        tracks[(channel["target"]["node"], channel["target"]["path"])] = accessor_array(doc, binary, sampler["output"])
    by_name = {node["name"]: i for i, node in enumerate(doc["nodes"])}
    world = node_matrices(doc["nodes"], tracks, len(times))[..., :3, 3]
    return world[:, [by_name[n] for n in joints]]


# ----------------------------------------------------------------------------- the browser's reading


@pytest.fixture(scope="module")
def read_back(tmp_path_factory):
    """``name -> (motion, GltfReport, three.js's reading)`` for the demo and the partial motion."""
    tmp = tmp_path_factory.mktemp("gltf_three")
    probe = tmp / "probe.src.js"
    probe.write_text(PROBE, encoding="utf-8")
    try:
        web.bundle_module(probe, tmp / "probe.js")
    except RuntimeError as exc:  # no node to bundle with
        pytest.skip(f"no browser test: {exc}")
    files = {"index.html": (tmp / "index.html", "text/html"), "probe.js": (tmp / "probe.js", "text/javascript")}
    (tmp / "index.html").write_text(PAGE, encoding="utf-8")
    made = {}
    for name, motion in (("demo", demo_motion()), ("partial", partial_motion())):
        report = export_gltf(tmp / f"{name}.glb", motion)
        files[f"{name}.glb"] = (report.path, "model/gltf-binary")
        made[name] = (motion, report)

    def serve(route) -> None:
        found = files.get(route.request.url.removeprefix(f"{ORIGIN}/"))
        if found is None:
            route.fulfill(status=404, body="not found")
        else:
            route.fulfill(status=200, body=found[0].read_bytes(), content_type=found[1])

    out = {}
    with app_browser.browser(width=320, height=240) as page:
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.route(f"{ORIGIN}/**", serve)
        page.goto(f"{ORIGIN}/index.html")
        page.wait_for_function("() => typeof window.readBack === 'function'")
        for name, (motion, report) in made.items():
            frames = [f % motion.n_frames for f in SKIN_FRAMES]
            got = page.evaluate(
                "([url, fps, joints, frames]) => window.readBack(url, fps, joints, frames)",
                [f"{ORIGIN}/{name}.glb", motion.fps, list(report.joints), frames],
            )
            got["positions"] = np.asarray(got["positions"]).reshape(got["frames"], len(report.joints), 3)
            got["vertices"] = np.asarray(got["vertices"]).reshape(len(frames), -1, 3)
            got["skin_frames"] = frames
            out[name] = (motion, report, got)
        assert errors == [], errors
    return out


def round_trip(name: str, motion: Motion, report, got) -> tuple[np.ndarray, str]:
    """(frames, joints) distance of three.js's joints from the motion's, metres, and the line that says it."""
    cols = [JOINT_NAMES.index(n) for n in report.joints]
    err = np.linalg.norm(got["positions"] - motion.positions[:, cols].astype(np.float64), axis=-1)
    frame, k = np.unravel_index(int(np.argmax(err)), err.shape)
    line = (
        f"three.js GLTFLoader round trip of {name}.glb ({motion.n_frames} frames, {len(cols)} joints): "
        f"max {err.max() * 1000:.4f} mm ({report.joints[k]}, frame {frame}), mean {err.mean() * 1000:.4f} mm; "
        f"the export's own reading: max {report.max_error * 1000:.4f} mm"
    )
    return err, line


# ----------------------------------------------------------------------------- tests


@pytest.mark.parametrize("name", ["demo", "partial"])
def test_three_places_every_joint_of_every_frame_within_a_millimetre(read_back, name):
    motion, report, got = read_back[name]
    err, line = round_trip(name, motion, report, got)
    print(line)
    assert got["positions"].shape == (motion.n_frames, len(report.joints), 3), line
    assert err.max() < TOLERANCE, line
    # and where the export's own reader (its report's figures) puts them
    ours = file_positions(report.path, report.joints)
    apart = np.linalg.norm(got["positions"] - ours, axis=-1).max()
    assert apart < TOLERANCE, f"{line}; three.js and the export's reader up to {apart * 1000:.4f} mm apart"
    assert abs(err.max() - report.max_error) < TOLERANCE, line


@pytest.mark.parametrize("name", ["demo", "partial"])
def test_three_reads_the_joint_names_the_clip_and_a_skin_bound_to_those_bones(read_back, name):
    motion, report, got = read_back[name]
    _, line = round_trip(name, motion, report, got)
    # one node per written joint, named by it, the body's node and the still legs' node
    assert got["names"] == [*report.joints, "character", "legs"], line
    drawn = [JOINT_NAMES[j] for j in range(N_JOINTS) if rig_for(motion).parents[j] >= -1]
    assert list(report.joints) == drawn and all(got["isBone"]), line
    # one clip of one key per frame: its last at (frames - 1) / fps; rotations of every joint and the root's position
    assert got["clips"] == 1 and got["frames"] == motion.n_frames, line
    assert got["duration"] == pytest.approx((motion.n_frames - 1) / motion.fps, abs=1e-6), line
    assert got["tracks"] == len(report.joints) + 1, line
    # every mesh of the body (one per part) is skinned, to the joints' nodes in the skin's order; the legs'
    # two (trousers, shoes) are not
    assert got["skinned"] == 3 and got["plainMeshes"] == 2 and all(got["boundToJoints"]), line


@pytest.mark.parametrize("name", ["demo", "partial"])
def test_three_skins_the_body_as_the_reference_skinning(read_back, name):
    motion, report, got = read_back[name]
    rig = rig_for(motion)
    reference = skin_vertices(build_mesh(rig), rig, solve_pose(motion, rig), np.asarray(got["skin_frames"]))
    off = np.linalg.norm(got["vertices"] - reference, axis=-1)
    assert off.shape == reference.shape[:2]
    assert off.max() < TOLERANCE, f"{name}.glb: body vertices up to {off.max() * 1000:.4f} mm off the reference"
