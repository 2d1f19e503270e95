"""A user's character written with our motion, opened by three.js in a real browser: its GLTFLoader finds the
'gesturekit' animation beside the character's own, and its AnimationMixer places every bone within a millimetre
of the retargeted positions; and a picture of the animated character mid-clip.

Headless Chromium driven by Playwright (``tests/app_browser.py``), three.js from the viewer's npm lock bundled
at test time (:func:`gesturekit.viz.web.build.bundle_module`), as in ``tests/browser/test_browser_gltf.py``.

``python -m tests.browser.test_browser_character [--out docs/screenshots]`` remakes ``character-glb.png``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from gesturekit.character.look import AMBIENT, BACKGROUND, KEY, LIGHT_DIRECTION, camera_for
from gesturekit.character.retarget import Retargeted, retarget
from gesturekit.character.user import read_character
from gesturekit.export._character_bvh import rotation_of
from gesturekit.export.character import ANIMATION, export_character_glb
from gesturekit.motion import Motion
from gesturekit.viz.web import build as web
from tests import app_browser
from tests.character_rigs import CASES, write_rig

pytestmark = pytest.mark.skipif(
    app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"
)

REPO = Path(__file__).resolve().parents[2]
ORIGIN = "http://gesturekit.test"
TOLERANCE = 1e-3
#: The characters read back, and the one pictured.
SHOWN = ("vrm1_t", "mixamo_a_rolled", "vrm0_a")
PICTURED = "vrm1_t"
SIZE = (480, 640)

#: ``window.readBack(url, name, fps, nodes, frames)``: the clips' names and, playing the clip ``name``, the world
#: positions of the nodes ``nodes`` at each frame of ``frames``; ``window.show(url, name, t, camera, light)``
#: draws the character at time ``t`` of the clip on the page's canvas.
PROBE = """
import * as THREE from "three";
import { GLTFLoader } from "three/examples/jsm/loaders/GLTFLoader.js";

async function playing(url, name) {
  const gltf = await new GLTFLoader().loadAsync(url);
  const nodes = await gltf.parser.getDependencies("node");
  const clip = gltf.animations.find((c) => c.name === name);
  const mixer = new THREE.AnimationMixer(gltf.scene);
  const action = mixer.clipAction(clip).setLoop(THREE.LoopOnce, 1);
  action.clampWhenFinished = true;
  action.play();
  return { gltf, nodes, clip, mixer };
}

window.readBack = async (url, name, fps, wanted, frames) => {
  const { gltf, nodes, clip, mixer } = await playing(url, name);
  const v = new THREE.Vector3();
  const positions = [];
  for (const f of frames) {
    mixer.setTime(f / fps);
    gltf.scene.updateMatrixWorld(true);
    for (const i of wanted) {
      nodes[i].getWorldPosition(v);
      positions.push(v.x, v.y, v.z);
    }
  }
  return { clips: gltf.animations.map((c) => c.name), tracks: clip.tracks.length, duration: clip.duration, positions };
};

window.show = async (url, name, t, camera, light) => {
  const { gltf, mixer } = await playing(url, name);
  mixer.setTime(t);
  const canvas = document.getElementById("view");
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
  renderer.setSize(canvas.width, canvas.height, false);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(light.background);
  scene.add(gltf.scene);
  scene.add(new THREE.AmbientLight(0xffffff, light.ambient * Math.PI));
  const key = new THREE.DirectionalLight(0xffffff, light.key * Math.PI);
  key.position.set(...light.direction);
  scene.add(key);
  const cam = new THREE.PerspectiveCamera(camera.fov, canvas.width / canvas.height, 0.01, 100);
  cam.position.set(...camera.position);
  cam.up.set(...camera.up);
  cam.lookAt(...camera.target);
  gltf.scene.updateMatrixWorld(true);
  renderer.render(scene, cam);
  return true;
};
"""

PAGE = (
    '<!DOCTYPE html><html><head><meta charset="utf-8"><style>body{margin:0}</style></head><body>'
    f'<canvas id="view" width="{SIZE[0]}" height="{SIZE[1]}"></canvas><script type="module" src="probe.js"></script>'
)


def motion() -> Motion:
    """Two clips of the demo database (15 fps)."""
    from gesturekit.demo import open_default_database

    db = open_default_database()
    return Motion(db.poses[:2].reshape(-1, 55, 3).astype(np.float32), db.fps, db.joint_presence)


def to_file(r: Retargeted, points: np.ndarray) -> np.ndarray:
    """Points (..., 3) of our frame in the character file's frame and units."""
    m = r.character.to_file
    return points @ m[:3, :3].T + m[:3, 3]


class Page:
    """The probe page, its files served from a folder by Playwright's routing."""

    def __init__(self, folder: Path):
        self.folder = folder
        probe = folder / "probe.src.js"
        probe.write_text(PROBE, encoding="utf-8")
        web.bundle_module(probe, folder / "probe.js")
        (folder / "index.html").write_text(PAGE, encoding="utf-8")

    def serve(self, route) -> None:
        name = route.request.url.removeprefix(f"{ORIGIN}/")
        path = self.folder / name
        if "/" in name or not path.is_file():
            route.fulfill(status=404, body="not found")
            return
        kind = {".html": "text/html", ".js": "text/javascript"}.get(path.suffix, "model/gltf-binary")
        route.fulfill(status=200, body=path.read_bytes(), content_type=kind)

    def open(self, page) -> list[str]:
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.route(f"{ORIGIN}/**", self.serve)
        page.goto(f"{ORIGIN}/index.html")
        page.wait_for_function("() => typeof window.readBack === 'function'")
        return errors


def picture(page, r: Retargeted, name: str, path: Path) -> Path:
    """Draw the character mid-clip, framed from the front as the app frames ours; save the canvas as a PNG."""
    mid = r.n_frames // 2
    pos = r.position[mid]
    lo, hi = pos.min(axis=0) - 0.15, pos.max(axis=0) + 0.15
    cam = camera_for(lo, hi, SIZE[0] / SIZE[1])
    r_f = rotation_of(r.character.to_file[:3, :3])
    camera = {
        "position": to_file(r, np.asarray(cam["position"])).tolist(),
        "target": to_file(r, np.asarray(cam["target"])).tolist(),
        "up": (r_f @ np.asarray(cam["up"])).tolist(),
        "fov": cam["fov"],
    }
    light = {
        "background": BACKGROUND,
        "ambient": AMBIENT,
        "key": KEY,
        "direction": (r_f @ np.asarray(LIGHT_DIRECTION)).tolist(),
    }
    page.evaluate(
        "([url, clip, t, camera, light]) => window.show(url, clip, t, camera, light)",
        [f"{ORIGIN}/{name}", ANIMATION, mid / r.fps, camera, light],
    )
    page.locator("#view").screenshot(path=str(path), type="png")
    return path


@pytest.fixture(scope="module")
def opened(tmp_path_factory):
    """``case -> (Retargeted, report, three.js's reading)``, and the picture of :data:`PICTURED`."""
    tmp = tmp_path_factory.mktemp("character_three")
    try:
        page_files = Page(tmp)
    except RuntimeError as exc:  # no node to bundle with
        pytest.skip(f"no browser test: {exc}")
    m = motion()
    made = {}
    for case in SHOWN:
        src = write_rig(tmp / "rigs", CASES[case], case)
        r = retarget(m, read_character(src))
        report = export_character_glb(tmp / f"{case}{src.suffix}", r)
        made[case] = (r, report)
    out = {}
    with app_browser.browser(width=SIZE[0], height=SIZE[1]) as page:
        errors = page_files.open(page)
        for case, (r, report) in made.items():
            frames = [0, r.n_frames // 3, r.n_frames // 2, r.n_frames - 1]
            nodes = [int(n) for n in r.character.gltf.nodes]
            got = page.evaluate(
                "([url, clip, fps, nodes, frames]) => window.readBack(url, clip, fps, nodes, frames)",
                [f"{ORIGIN}/{report.path.name}", ANIMATION, r.fps, nodes, frames],
            )
            got["positions"] = np.asarray(got["positions"]).reshape(len(frames), len(nodes), 3)
            got["frames"] = frames
            out[case] = (r, report, got)
        r, report = made[PICTURED]
        shot = picture(page, r, report.path.name, tmp / "character-glb.png")
        assert errors == [], errors
    return out, shot


@pytest.mark.parametrize("case", SHOWN)
def test_three_plays_the_gesturekit_clip_and_places_every_bone_within_a_millimetre(opened, case):
    r, report, got = opened[0][case]
    want = to_file(r, r.position[got["frames"]])
    scale = 1.0 / np.linalg.norm(r.character.to_file[:3, 0])  # metres per file unit
    err = np.linalg.norm(got["positions"] - want, axis=-1) * scale
    line = (
        f"three.js reading of {report.path.name} at frames {got['frames']}: {len(r.character.names)} bones, "
        f"max {err.max() * 1000:.4f} mm, mean {err.mean() * 1000:.4f} mm; the export's own: "
        f"max {report.max_error * 1000:.4f} mm"
    )
    print(line)
    assert ANIMATION in got["clips"], line
    assert got["tracks"] == len(report.animated), line
    assert got["duration"] == pytest.approx((r.n_frames - 1) / r.fps, abs=1e-6), line
    assert err.max() < TOLERANCE, line


def test_the_picture_shows_the_character_mid_clip(opened):
    from PIL import Image

    shot = opened[1]
    img = np.asarray(Image.open(shot).convert("RGB"), dtype=np.float64)
    background = np.array([int(BACKGROUND[i : i + 2], 16) for i in (1, 3, 5)], dtype=np.float64)
    drawn = np.abs(img - background).max(axis=-1) > 24
    print(f"{shot.name}: {img.shape[1]}x{img.shape[0]}, character on {drawn.mean():.1%} of the pixels")
    assert img.shape[:2] == (SIZE[1], SIZE[0])
    assert 0.03 < drawn.mean() < 0.6  # a figure, neither missing nor filling the frame
    rows, cols = np.flatnonzero(drawn.any(axis=1)), np.flatnonzero(drawn.any(axis=0))
    assert rows[0] > 0 and rows[-1] < SIZE[1] - 1 and cols[0] > 0 and cols[-1] < SIZE[0] - 1  # whole in the frame


def make_screenshot(out: Path) -> Path:
    """Write ``character-glb.png`` (the generated VRM 1.0 character mid-clip) into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="gesturekit-character-") as tmp:
        folder = Path(tmp)
        files = Page(folder)
        src = write_rig(folder / "rigs", CASES[PICTURED], PICTURED)
        r = retarget(motion(), read_character(src))
        report = export_character_glb(folder / f"{PICTURED}{src.suffix}", r)
        with app_browser.browser(width=SIZE[0], height=SIZE[1]) as page:
            errors = files.open(page)
            shot = picture(page, r, report.path.name, out / "character-glb.png")
            if errors:
                raise RuntimeError(f"the page failed: {errors[0]}")
    return shot


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="The picture of a user's character animated by our motion.")
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "screenshots")
    args = parser.parse_args(argv)
    reason = app_browser.unavailable()
    if reason:
        print(f"cannot make the picture: {reason}", file=sys.stderr)
        return 1
    print(make_screenshot(args.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
