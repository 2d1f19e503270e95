"""A textured character in its own materials: the page and the MP4 against a plain three.js rendering of its GLB.

The character is generated (:class:`tests.character_rigs.RigSpec` ``textured``): three materials with PNG
textures embedded in the GLB (a gradient with a checker, linear and mipmapped; a checker, nearest; stripes
under alpha MASK, double-sided), ``TEXCOORD_0`` with the seam's vertices doubled as exporters write them.
Our motion is retargeted onto it and written with it (:func:`gesturekit.character.export_character_glb`);
the *reference* is that GLB opened by three.js's own ``GLTFLoader`` in headless Chromium, its clip played to
the time shown, drawn with nothing of ours: the same camera, the look's ambient and directional lights, the
loader's own materials. Against it, at three times of the motion:

- the page (:func:`gesturekit.viz.viewer.skeleton_viewer` with ``character=``), its canvas screenshotted;
- the MP4's renderer (:class:`gesturekit.viz.render.SkeletonScene`, the frames the MP4 encodes), the
  reference drawn through the MP4's camera.

Silhouettes are the pixels not of the background; the colour difference is the mean absolute difference
(0-255, over the three channels) inside both silhouettes, one pixel in from their edges (where a pixel is
partly the body and partly the background in one picture and not the other).

``python -m tests.browser.test_browser_materials [--size 1280x800] [--out docs/screenshots] [--every]`` prints
the figures, and those of the same character drawn in one colour per vertex (its materials left out) for
comparison; with ``--out`` it writes the page's and the MP4's pictures at the middle time
(``character-materials-page.png``, ``character-materials-mp4.png``), with ``--every`` each picture and its
reference at every time.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from gesturekit.character.look import BACKGROUND
from gesturekit.character.retarget import retarget
from gesturekit.character.user import read_character
from gesturekit.export._character_bvh import rotation_of
from gesturekit.export.character import ANIMATION, export_character_glb
from gesturekit.motion import Motion
from gesturekit.viz.web import build as web
from tests import app_browser
from tests.character_rigs import RigSpec, write_rig

pytestmark = [
    pytest.mark.skipif(app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"),
    pytest.mark.slow,
]

ORIGIN = "http://gesturekit.test"
#: The generated textured character.
TEXTURED = RigSpec(textured=True, rest="A", roll_seed=6)
#: Seconds into the motion of the three pictures.
TIMES = (0.5, 2.0, 3.4)
#: The bounds: silhouette IoU at least, mean colour difference inside the body at most (levels of 0-255).
MIN_IOU, MAX_DIFFERENCE = 0.95, 8.0
BG = np.array([int(BACKGROUND[i : i + 2], 16) for i in (1, 3, 5)])

#: ``window.reference(url, clip, t, camera, look, size)``: the GLB's clip at time t, drawn by three.js alone.
PROBE = """
import * as THREE from "three";
import { GLTFLoader } from "three/examples/jsm/loaders/GLTFLoader.js";

window.reference = async (url, name, t, camera, look, size) => {
  const gltf = await new GLTFLoader().loadAsync(url);
  const mixer = new THREE.AnimationMixer(gltf.scene);
  mixer.clipAction(gltf.animations.find((c) => c.name === name)).play();
  mixer.setTime(t);
  const canvas = document.getElementById("view");
  canvas.width = size[0]; canvas.height = size[1];
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
  renderer.setSize(size[0], size[1], false);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(look.background);
  scene.add(gltf.scene);
  scene.add(new THREE.AmbientLight(0xffffff, look.ambient * Math.PI));
  for (const [dir, strength] of look.lights) {
    const light = new THREE.DirectionalLight(0xffffff, strength * Math.PI);
    light.position.set(...dir);
    scene.add(light);
  }
  const cam = new THREE.PerspectiveCamera(camera.fov, size[0] / size[1], 0.01, 100);
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
    '<canvas id="view"></canvas><script type="module" src="probe.js"></script>'
)
_PAINTED = "() => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)))"


def motion() -> Motion:
    """Two clips of the demo database (15 fps, about 8.5 s)."""
    from gesturekit.demo import open_default_database

    db = open_default_database()
    return Motion(db.poses[:2].reshape(-1, 55, 3).astype(np.float32), db.fps, db.joint_presence)


def silhouette(image: np.ndarray) -> np.ndarray:
    """Pixels clearly not of the background, (h, w) bool."""
    return np.abs(image[..., :3].astype(int) - BG).sum(axis=-1) > 24


def _inside(mask: np.ndarray) -> np.ndarray:
    """``mask`` one pixel in from its edges (each of the 4 neighbours in it too)."""
    m = mask.copy()
    m[1:] &= mask[:-1]
    m[:-1] &= mask[1:]
    m[:, 1:] &= mask[:, :-1]
    m[:, :-1] &= mask[:, 1:]
    return m


def compare(picture: np.ndarray, reference: np.ndarray) -> tuple[float, float, int]:
    """Silhouette IoU, mean absolute colour difference inside both bodies (0-255), and the pixels compared."""
    a, b = silhouette(picture), silhouette(reference)
    union = int((a | b).sum())
    both = _inside(a) & _inside(b)
    n = int(both.sum())
    if union == 0 or n == 0:
        return float("nan"), float("nan"), n
    diff = np.abs(picture[..., :3].astype(np.float64) - reference[..., :3].astype(np.float64))[both].mean()
    return float((a & b).sum() / union), float(diff), n


class Reference:
    """The probe page: three.js and its GLTFLoader bundled alone, the GLB served beside it."""

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

    def draw(self, page, glb: str, t: float, camera: dict, look: dict, size: tuple[int, int]) -> np.ndarray:
        from PIL import Image

        if page.url != f"{ORIGIN}/index.html":
            page.route(f"{ORIGIN}/**", self.serve)
            page.goto(f"{ORIGIN}/index.html")
            page.wait_for_function("() => typeof window.reference === 'function'")
        page.evaluate(
            "([u, c, t, cam, look, size]) => window.reference(u, c, t, cam, look, size)",
            [f"{ORIGIN}/{glb}", ANIMATION, t, camera, look, list(size)],
        )
        return np.asarray(Image.open(io.BytesIO(page.locator("#view").screenshot(type="png"))).convert("RGB"))


def _file_camera(ch, camera: dict) -> dict:
    """A camera of our frame (``position``, ``target``, ``up``, ``fov``) in the character file's frame."""
    m = ch.to_file
    r_f = rotation_of(m[:3, :3])
    return {
        "position": (np.asarray(camera["position"]) @ m[:3, :3].T + m[:3, 3]).tolist(),
        "target": (np.asarray(camera["target"]) @ m[:3, :3].T + m[:3, 3]).tolist(),
        "up": (r_f @ np.asarray(camera.get("up", (0.0, 1.0, 0.0)))).tolist(),
        "fov": float(camera["fov"]),
    }


def measure(
    folder: Path, size: tuple[int, int], *, times=TIMES, own: bool = True, out: Path | None = None, every: bool = False
) -> list[dict]:
    """The page and the MP4 against the reference at ``times``; one dict of figures per (time, picture).

    ``own=False`` draws the character in one colour per vertex (its materials left out), for comparison.
    ``out``: a folder for ``character-materials-page.png`` and ``character-materials-mp4.png`` (in its own
    materials, at the middle time); with ``every``, each picture and its reference at every time instead.
    """
    from PIL import Image

    from gesturekit.viz.render import SkeletonScene
    from gesturekit.viz.viewer import read_viewer_data, skeleton_viewer

    ch = read_character(write_rig(folder / "rigs", TEXTURED, "textured"))
    m = motion()
    report = export_character_glb(folder / "textured_animated.glb", retarget(m, ch))
    drawn = ch if own else dataclasses.replace(ch, skin=dataclasses.replace(ch.skin, materials=b""))
    ref = Reference(folder)
    w, h = size
    html = skeleton_viewer([m], character=drawn, labels=[""], height=h, key="materials")
    page_file = folder / "materials.html"
    page_file.write_text(html, encoding="utf-8")
    data = read_viewer_data(html)
    r_f = rotation_of(ch.to_file[:3, :3])
    look = {
        "background": BACKGROUND,
        "ambient": data["look"]["ambient"],
        "lights": [[(r_f @ np.asarray(d)).tolist(), s] for d, s in data["look"]["lights"]],
    }
    step = int(data["frame_step"])
    rows = []
    with contextlib.ExitStack() as stack:
        page = stack.enter_context(app_browser.browser(width=w, height=h + 200))
        other = page.context.browser.new_page(viewport={"width": w, "height": h})  # the reference's own page
        scene = stack.enter_context(SkeletonScene([m], resolution=size, character=drawn))
        assert scene._character is not None
        mp4_camera = _file_camera(ch, scene._character.stage.camera(w / h))
        page.goto(page_file.as_uri())
        page.locator('body[data-materials="1"]').wait_for(state="attached")
        assert page.evaluate("() => window.devicePixelRatio") == 1
        assert page.evaluate("() => gk.materials") is own
        for t in times:
            k = int(np.floor(t * m.fps / step + 1e-6))
            frame = k * step
            page.evaluate(
                """(k) => { const s = document.getElementById("s"); s.value = String(k);
                s.dispatchEvent(new Event("input")); return gk.frame; }""",
                k,
            )
            page.evaluate(_PAINTED)
            shot = np.asarray(Image.open(io.BytesIO(page.locator("canvas#c").screenshot(type="png"))).convert("RGB"))
            page_camera = _file_camera(ch, page.evaluate("() => gk.camera"))
            mp4 = scene.render_frame(frame)
            at = frame / m.fps
            want = ref.draw(other, report.path.name, at, page_camera, look, (shot.shape[1], shot.shape[0]))
            want_mp4 = ref.draw(other, report.path.name, at, mp4_camera, look, (mp4.shape[1], mp4.shape[0]))
            for name, got, reference in (("page", shot, want), ("mp4", mp4, want_mp4)):
                iou, diff, n = compare(got, reference)
                rows.append({"t": at, "picture": name, "iou": iou, "difference": diff, "pixels": n})
                if out is not None and every:
                    tag = f"{'own' if own else 'vertex'}-{name}-{at:.2f}s"
                    Image.fromarray(got).save(out / f"materials-{tag}.png")
                    Image.fromarray(reference).save(out / f"materials-reference-{name}-{at:.2f}s.png")
                elif out is not None and own and t == times[len(times) // 2]:
                    Image.fromarray(got).save(out / f"character-materials-{name}.png")
    return rows


def _line(row: dict) -> str:
    return (
        f"t={row['t']:.2f} s {row['picture']:>4}: silhouette IoU {row['iou']:.4f}, "
        f"mean colour difference inside the body {row['difference']:.2f} levels over {row['pixels']} pixels"
    )


@pytest.fixture(scope="module")
def figures(tmp_path_factory):
    folder = tmp_path_factory.mktemp("materials")
    try:
        return measure(folder, (640, 400))
    except RuntimeError as exc:  # no node to bundle the reference with
        pytest.skip(f"no browser test: {exc}")


@pytest.mark.parametrize("picture", ["page", "mp4"])
def test_the_textured_character_matches_a_plain_gltf_rendering(figures, picture):
    rows = [r for r in figures if r["picture"] == picture]
    for r in rows:
        print(_line(r))
    assert len(rows) == len(TIMES)
    for r in rows:
        assert r["pixels"] > 2000, _line(r)  # a body was compared, not a speck
        assert np.isfinite(r["iou"]) and r["iou"] >= MIN_IOU, _line(r)
        assert np.isfinite(r["difference"]) and r["difference"] <= MAX_DIFFERENCE, _line(r)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="A textured character: the page and the MP4 against GLTFLoader.")
    parser.add_argument("--size", default="1280x800", help="WIDTHxHEIGHT, pixels")
    parser.add_argument("--out", type=Path, default=None, help="a folder for the page's and the MP4's pictures")
    parser.add_argument("--every", action="store_true", help="every picture and its reference, at every time")
    args = parser.parse_args(argv)
    reason = app_browser.unavailable()
    if reason:
        print(f"cannot measure: {reason}", file=sys.stderr)
        return 1
    w, h = (int(x) for x in args.size.split("x"))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
    for own in (True, False):
        print("in its own materials:" if own else "in one colour per vertex (as before):")
        with tempfile.TemporaryDirectory(prefix="gesturekit-materials-") as tmp:
            for row in measure(Path(tmp), (w, h), own=own, out=args.out, every=args.every):
                print("  " + _line(row))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
