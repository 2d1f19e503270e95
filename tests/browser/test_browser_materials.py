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

#: ``window.reference(url, clip, t, camera, look, size, vrm)``: the GLB's clip at time t, drawn by three.js alone
#: (with ``vrm``, by three.js and three-vrm's loader plugin, as a VRM viewer draws it); ``window.mtoon(url)``: the
#: MToon parameters three-vrm gives each material of the GLB.
PROBE = """
import * as THREE from "three";
import { GLTFLoader } from "three/examples/jsm/loaders/GLTFLoader.js";
import { VRMLoaderPlugin } from "@pixiv/three-vrm";

function loader(vrm) {
  const loader = new GLTFLoader();
  if (vrm) loader.register((parser) => new VRMLoaderPlugin(parser));
  return loader;
}

window.mtoon = async (url) => {
  const gltf = await loader(true).loadAsync(url), seen = new Map();
  gltf.scene.traverse((o) => {
    for (const m of o.isMesh ? [o.material].flat() : []) {
      if (!m.isMToonMaterial || seen.has(m.name)) continue;
      seen.set(m.name, {
        outline: Boolean(m.isOutline), lit: m.color.toArray(), opacity: m.opacity, shade: m.shadeColorFactor.toArray(),
        shift: m.shadingShiftFactor, toony: m.shadingToonyFactor, rim: m.parametricRimColorFactor.toArray(),
        rimPower: m.parametricRimFresnelPowerFactor, rimLift: m.parametricRimLiftFactor,
        rimMix: m.rimLightingMixFactor, emissive: m.emissive.toArray(), outlineMode: m.outlineWidthMode,
        outlineWidth: m.outlineWidthFactor, outlineColor: m.outlineColorFactor.toArray(),
        outlineMix: m.outlineLightingMixFactor, map: Boolean(m.map), shadeMap: Boolean(m.shadeMultiplyTexture),
        alphaTest: m.alphaTest, doubleSided: m.side === THREE.DoubleSide,
      });
    }
  });
  return Object.fromEntries(seen);
};

window.reference = async (url, name, t, camera, look, size, vrm) => {
  const gltf = await loader(vrm).loadAsync(url);
  // a VRM viewer's update, before the clip poses the bones: its materials' uniforms (the alpha cutoff)
  if (vrm && gltf.userData.vrm) gltf.userData.vrm.update(0);
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

    def open(self, page) -> None:
        """Open the probe page in ``page`` (once)."""
        if page.url != f"{ORIGIN}/index.html":
            page.route(f"{ORIGIN}/**", self.serve)
            page.goto(f"{ORIGIN}/index.html")
            page.wait_for_function("() => typeof window.reference === 'function'")

    def draw(
        self, page, glb: str, t: float, camera: dict, look: dict, size: tuple[int, int], *, vrm: bool = False
    ) -> np.ndarray:
        """The GLB ``glb`` (a file of the folder) at ``t`` seconds, drawn by three.js (``vrm``: and three-vrm)."""
        from PIL import Image

        self.open(page)
        page.evaluate(
            "([u, c, t, cam, look, size, vrm]) => window.reference(u, c, t, cam, look, size, vrm)",
            [f"{ORIGIN}/{glb}", ANIMATION, t, camera, look, list(size), vrm],
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


def without_mtoon(ch):
    """The character ``ch`` with its materials' MToon left out (VRM 1.0's extension and VRM 0.x's material
    properties): its glTF materials alone, as a renderer that ignores MToon draws them."""
    from gesturekit.character.glb import glb_bytes, read_glb

    doc, binary = read_glb(ch.skin.materials)
    for m in doc.get("materials", []):
        (m.get("extensions") or {}).pop("VRMC_materials_mtoon", None)
    doc.pop("extensions", None)
    return dataclasses.replace(ch, skin=dataclasses.replace(ch.skin, materials=glb_bytes(doc, binary)))


#: What :func:`measure` draws: the character in its own materials, in one colour per vertex (its materials left
#: out), or in its glTF materials with their MToon left out.
DRAWN = ("own", "vertex", "no mtoon")


def measure(
    folder: Path,
    size: tuple[int, int],
    *,
    spec: RigSpec = TEXTURED,
    vrm: bool = False,
    times=TIMES,
    drawn: str = "own",
    plain: bool = False,
    out: Path | None = None,
    every: bool = False,
    name: str = "materials",
) -> list[dict]:
    """The page and the MP4 against the reference at ``times``; one dict of figures per (time, picture).

    ``spec``: the character; ``vrm``: the reference is drawn with three-vrm's loader plugin. ``drawn`` (one of
    :data:`DRAWN`): how the page and the MP4 draw the character, for comparison. ``plain``: also the GLB drawn by
    three.js alone against the reference, through the page's camera (picture ``"plain"``: what a renderer that
    ignores MToon draws). ``out``: a folder for ``character-{name}-page.png`` and ``character-{name}-mp4.png``
    (in its own materials, at the middle time); with ``every``, each picture and its reference at every time
    instead.
    """
    from PIL import Image

    from gesturekit.viz.render import SkeletonScene
    from gesturekit.viz.viewer import read_viewer_data, skeleton_viewer

    ch = read_character(write_rig(folder / "rigs", spec, name))
    m = motion()
    report = export_character_glb(folder / f"{name}_animated.glb", retarget(m, ch))
    shown = {
        "own": ch,
        "vertex": dataclasses.replace(ch, skin=dataclasses.replace(ch.skin, materials=b"")),
        "no mtoon": without_mtoon(ch),
    }[drawn]
    ref = Reference(folder)
    w, h = size
    html = skeleton_viewer([m], character=shown, labels=[""], height=h, key="materials")
    page_file = folder / f"{name}.html"
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
        scene = stack.enter_context(SkeletonScene([m], resolution=size, character=shown))
        assert scene._character is not None
        mp4_camera = _file_camera(ch, scene._character.stage.camera(w / h))
        page.goto(page_file.as_uri())
        page.locator('body[data-materials="1"]').wait_for(state="attached")
        assert page.evaluate("() => window.devicePixelRatio") == 1
        assert page.evaluate("() => gk.materials") is (drawn != "vertex")
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
            page_size, mp4_size = (shot.shape[1], shot.shape[0]), (mp4.shape[1], mp4.shape[0])
            want = ref.draw(other, report.path.name, at, page_camera, look, page_size, vrm=vrm)
            want_mp4 = ref.draw(other, report.path.name, at, mp4_camera, look, mp4_size, vrm=vrm)
            pictures = [("page", shot, want), ("mp4", mp4, want_mp4)]
            if plain:
                pictures.append(("plain", ref.draw(other, report.path.name, at, page_camera, look, page_size), want))
            for picture, got, reference in pictures:
                iou, diff, n = compare(got, reference)
                rows.append({"t": at, "picture": picture, "iou": iou, "difference": diff, "pixels": n})
                if out is not None and every:
                    tag = f"{drawn.replace(' ', '-')}-{picture}-{at:.2f}s"
                    Image.fromarray(got).save(out / f"{name}-{tag}.png")
                    Image.fromarray(reference).save(out / f"{name}-reference-{picture}-{at:.2f}s.png")
                elif out is not None and drawn == "own" and picture != "plain" and t == times[len(times) // 2]:
                    Image.fromarray(got).save(out / f"character-{name}-{picture}.png")
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


def assert_within_bounds(figures: list[dict], picture: str) -> None:
    """Every time's row of ``picture`` printed, and each a body (not a speck) within the IoU and colour bounds."""
    rows = [r for r in figures if r["picture"] == picture]
    for r in rows:
        print(_line(r))
    assert len(rows) == len(TIMES)
    for r in rows:
        assert r["pixels"] > 2000, _line(r)  # a body was compared, not a speck
        assert np.isfinite(r["iou"]) and r["iou"] >= MIN_IOU, _line(r)
        assert np.isfinite(r["difference"]) and r["difference"] <= MAX_DIFFERENCE, _line(r)


@pytest.mark.parametrize("picture", ["page", "mp4"])
def test_the_textured_character_matches_a_plain_gltf_rendering(figures, picture):
    assert_within_bounds(figures, picture)


def comparison_parser(description: str) -> argparse.ArgumentParser:
    """The options of a comparison's command line: ``--size``, ``--out``, ``--every``."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--size", default="1280x800", help="WIDTHxHEIGHT, pixels")
    parser.add_argument("--out", type=Path, default=None, help="a folder for the page's and the MP4's pictures")
    parser.add_argument("--every", action="store_true", help="every picture and its reference, at every time")
    return parser


def comparison_size(args: argparse.Namespace) -> tuple[int, int] | None:
    """The picture size of a comparison's command line, its ``--out`` folder made; None (said on
    stderr) where no browser can measure."""
    reason = app_browser.unavailable()
    if reason:
        print(f"cannot measure: {reason}", file=sys.stderr)
        return None
    w, h = (int(x) for x in args.size.split("x"))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
    return w, h


def main(argv: list[str] | None = None) -> int:
    args = comparison_parser("A textured character: the page and the MP4 against GLTFLoader.").parse_args(argv)
    size = comparison_size(args)
    if size is None:
        return 1
    for drawn in ("own", "vertex"):
        print("in its own materials:" if drawn == "own" else "in one colour per vertex (as before):")
        with tempfile.TemporaryDirectory(prefix="gesturekit-materials-") as tmp:
            for row in measure(Path(tmp), size, drawn=drawn, out=args.out, every=args.every):
                print("  " + _line(row))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
