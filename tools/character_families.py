"""The character guide's pictures: one character of each family, driven by a synthesis result, in the page and the MP4.

Each character is generated here with the properties of its family (no third-party asset): a Mixamo-like GLB
(``mixamorig:`` names, T-pose), a VRM 1.0-like file (its humanoid map, VRoid-like node names, A-pose, its materials
toon-shaded in MToon with outlines), a Blender export (``upper_arm.L``-style names, A-pose, rolled bones), each
with a generated texture of its own colours, and a mocap BVH laid out as the common CMU conversion writes it (CMU
names, zero-length ``Neck`` and shoulder bones, its own unit). The motion is a synthesis of the demo speaker's 8 s
example on the demo database. For each family, the viewer's page (as the app and ``character_view`` show it) is
screenshotted in headless Chromium and the MP4 (:func:`gesturekit.export.video.render_video`) decoded, both at one
frame, and written into docs/screenshots as ``character-mixamo-page.png`` and ``character-mixamo-mp4.png``, and so
on for each family.

Usage (from the repository's root, with the viewer's bundle built: ``python gesturekit/viz/web/build.py``)::

    python -m tools.character_families [--out docs/screenshots] [--families mixamo,vrm,blender,bvh]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

#: Family -> (file name, what it stands for).
FAMILIES = {
    "mixamo": ("mixamo-character.glb", "a Mixamo download: mixamorig: names, T-pose"),
    "vrm": ("avatar.vrm", "a VRM 1.0 avatar: its humanoid map, A-pose, toon-shaded (MToon)"),
    "blender": ("blender-export.glb", "a Blender export: .L/.R names, A-pose, rolled bones"),
    "bvh": ("cmu-mocap.bvh", "a mocap BVH: CMU names, zero-length Neck and shoulders"),
}

#: Picture size, pixels (the MP4's; the page is as large at a device pixel ratio of 1).
WIDTH, HEIGHT = 640, 480


def character_file(family: str, folder: Path) -> Path:
    """Write the stand-in character of ``family`` into ``folder``."""
    from tests.character_rigs import RigSpec, cmu_bvh, write_rig

    name = FAMILIES[family][0]
    if family == "bvh":
        path = folder / name
        path.write_bytes(cmu_bvh(unit=0.01))
        return path
    spec = {
        "mixamo": RigSpec(naming="mixamo", rest="T", texture=True, seed=3),
        "vrm": RigSpec(naming="vrm1", rest="A", texture=True, mtoon=True, seed=5),
        "blender": RigSpec(naming="blender", rest="A", roll_seed=2, texture=True, seed=11),
    }[family]
    return write_rig(folder, spec, Path(name).stem)


def synthesis_motion():
    """The final motion of a synthesis of the demo speaker's 8 s example on the demo database."""
    from gesturekit.demo import open_default_database
    from gesturekit.interactive import SPEECH_EXAMPLES, example_speech
    from gesturekit.synthesis import synthesize

    label = next(iter(SPEECH_EXAMPLES))
    result = synthesize(example_speech(label), db=open_default_database())
    return result.motion


def page_shot(page, html: Path, frame: int, out: Path) -> None:
    """Screenshot the viewer's drawing in ``html`` at ``frame``."""
    page.goto(html.as_uri())
    page.locator('body[data-drawn="1"]').wait_for(state="attached")
    shown = page.evaluate(
        """(k) => { const s = document.getElementById("s"); s.value = String(k);
        s.dispatchEvent(new Event("input")); return gk.frame; }""",
        frame,
    )
    if shown != frame:
        raise RuntimeError(f"the page shows frame {shown}, not {frame}")
    page.evaluate("() => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)))")
    page.locator("canvas#c").screenshot(path=str(out), type="png")


def mp4_frame(path: Path, index: int) -> np.ndarray:
    """Frame ``index`` of an MP4, RGB (height, width, 3)."""
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    w, h = meta["size"]
    try:
        for i, data in enumerate(reader):
            if i == index:
                return np.frombuffer(data, np.uint8).reshape(h, w, 3).copy()
    finally:
        reader.close()
    raise RuntimeError(f"{path.name} has no frame {index}")


def make(out: Path, families: list[str]) -> list[Path]:
    """Write the two pictures of each family into ``out``; return their paths."""
    from PIL import Image

    from gesturekit.character.user import read_character
    from gesturekit.export.video import render_video
    from gesturekit.viz.notebook import character_view
    from tests import app_browser

    out.mkdir(parents=True, exist_ok=True)
    motion = synthesis_motion()
    frame = int(round(4.2 * motion.fps))  # mid-sentence
    written = []
    with (
        tempfile.TemporaryDirectory(prefix="gesturekit-families-") as tmp,
        app_browser.browser(width=WIDTH, height=HEIGHT + 200) as page,
    ):
        folder = Path(tmp)
        for family in families:
            ch = read_character(character_file(family, folder))
            print(f"{family}: {ch.path.name}, {ch.n_bones} bones, matched by {ch.matched_by}", flush=True)
            html = character_view(motion, character=ch, height=HEIGHT, labels=[""]).save(folder / f"{family}.html")
            shot = out / f"character-{family}-page.png"
            page_shot(page, html, frame, shot)
            video = render_video(folder / f"{family}.mp4", motion, character=ch, resolution=(WIDTH, HEIGHT))
            still = out / f"character-{family}-mp4.png"
            Image.fromarray(mp4_frame(video, frame)).save(still)
            written += [shot, still]
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "screenshots")
    parser.add_argument("--families", default=",".join(FAMILIES), help="comma list of " + ", ".join(FAMILIES))
    args = parser.parse_args(argv)
    families = [f.strip() for f in args.families.split(",") if f.strip()]
    unknown = [f for f in families if f not in FAMILIES]
    if unknown:
        parser.error(f"unknown families: {', '.join(unknown)}")
    from tests import app_browser

    reason = app_browser.unavailable()
    if reason:
        print(f"cannot make the pictures: {reason}", file=sys.stderr)
        return 1
    for path in make(args.out, families):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
