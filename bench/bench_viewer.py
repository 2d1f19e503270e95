"""The 3D view's drawing speed without a GPU: frames per second of the page in headless Chromium's software WebGL.

Builds the viewer's page (:func:`gesturekit.viz.viewer.skeleton_viewer`) of demo-database clips, one
character and two side by side (the Synthesize page's k-NN and refined), opens it in headless Chromium
with the GPU disabled (WebGL drawn by SwiftShader on the CPU, as on a machine without a GPU), and steps
through the frames as fast as the browser paints them: each animation frame shows the next frame of
the motion (skinning, the legs, the stage, the lights). Prints, per view size, the frames per second
painted over ``--seconds`` and the mean time of the page's own drawing call; the page plays at 15 fps,
so at least 15 painted frames per second keep playback smooth. The load average is printed too: other
work on the machine slows the software renderer.

With ``--character FILE`` the motions are retargeted onto a user's character (a GLB, glTF or VRM is drawn
in its own materials and textures).

Usage: python bench/bench_viewer.py [--seconds 6] [--sizes 760x520,1280x720] [--character FILE]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

#: Steps through the frames, one per painted animation frame, for ``seconds``; returns frames painted and the
#: page's mean drawing time (milliseconds).
_STEP = """(seconds) => new Promise((done) => {
  const s = document.getElementById("s"), n = Number(s.max) + 1;
  let painted = 0, spent = 0; const t0 = performance.now();
  function next() {
    const now = performance.now();
    if (now - t0 >= seconds * 1000) {
      done({painted, seconds: (now - t0) / 1000, drawMs: spent / Math.max(1, painted)});
      return;
    }
    s.value = String((gk.frame + 1) % n); s.dispatchEvent(new Event("input"));
    spent += gk.drawMs; painted += 1;
    requestAnimationFrame(next);
  }
  requestAnimationFrame(next);
})"""


def _app_browser():
    """The browser driver shared with the browser tests (``tests/app_browser.py``), loaded by its path."""
    spec = importlib.util.spec_from_file_location("gesturekit_app_browser", REPO / "tests" / "app_browser.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--sizes", default="760x520,1280x720")
    parser.add_argument("--character", type=Path, default=None, help="a user's character file")
    args = parser.parse_args(argv)
    import numpy as np
    from machine import describe_machine  # bench/ is the script's folder

    from gesturekit.demo import open_default_database
    from gesturekit.motion import Motion
    from gesturekit.viz.viewer import skeleton_viewer

    browser = _app_browser()
    reason = browser.unavailable()
    if reason:
        print(f"cannot measure: {reason}")
        return 1
    print(f"machine: {describe_machine(accelerator='no GPU (Chromium --disable-gpu: WebGL in SwiftShader)')}")
    db = open_default_database()
    clips = np.asarray(db.poses).reshape(len(db.poses), -1, 55, 3)
    motions = [Motion(np.concatenate(clips[k : k + 4]), db.fps, db.joint_presence) for k in (0, 8)]
    character = None
    if args.character is not None:
        from gesturekit.character.user import read_character

        character = read_character(args.character)
        print(
            f"character: {args.character.name}"
            + (" in its own materials" if character.skin and character.skin.has_materials else "")
        )
    with tempfile.TemporaryDirectory(prefix="gesturekit-bench-") as tmp:
        for name, shown, labels in (
            ("one character", motions[:1], None),
            ("side by side", motions, ["k-NN", "refined"]),
        ):
            for size in args.sizes.split(","):
                w, h = (int(v) for v in size.split("x"))
                page_file = Path(tmp) / f"{len(shown)}_{w}.html"
                page_file.write_text(
                    skeleton_viewer(shown, labels=labels, height=h, character=character), encoding="utf-8"
                )
                with browser.browser(width=w, height=h + 60) as page:
                    page.goto(page_file.as_uri())
                    page.wait_for_selector('body[data-drawn="1"]', state="attached")
                    if character is not None:  # its textures are read before the stepping starts
                        page.wait_for_selector('body[data-materials="1"]', state="attached")
                    r = page.evaluate(_STEP, args.seconds)
                fps = r["painted"] / r["seconds"]
                verdict = "smooth at 15 fps" if fps >= 15 else "BELOW the 15 fps playback"
                print(
                    f"{name}, {w}x{h}: {fps:.1f} frames painted per second ({verdict}); "
                    f"drawing call {r['drawMs']:.1f} ms; load average {os.getloadavg()[0]:.2f}"
                )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
