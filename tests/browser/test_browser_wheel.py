"""The package as a user installs it from a wheel: no repository, no node, the app and its 3D view included.

The sdist is built from a clean copy of the sources and the wheel from that sdist (``python -m build``,
so a file missing from the sdist is missing from the wheel too). The wheel goes into a fresh virtual
environment that sees this interpreter's packages (``--system-site-packages``: the heavy dependencies
are not installed again) but whose own gesturekit is the wheel's, and everything runs from a folder
away from the repository with no ``node`` on the ``PATH``: ``gesturekit --version``, ``gesturekit
synthesize`` on speech, and ``gesturekit app``, whose Database page and 3D view draw in Chromium.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from gesturekit._version import __version__
from tests import app_browser
from tests.waits import patience

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"),
]

ROOT = Path(__file__).resolve().parents[2]
SHARED_SPEECH = ROOT.parent / "shared" / "data" / "speech" / "espeak_en_us.wav"


def _missing_tools() -> str | None:
    if importlib.util.find_spec("build") is None:
        return "the build package is not installed (requirements-test.txt)"
    if importlib.util.find_spec("ensurepip") is None:
        return "this Python cannot make virtual environments with pip (no ensurepip)"
    return None


def _source(dest: Path) -> Path:
    """What a clean clone holds of the package, without the viewer's npm packages and bundle (the build makes
    them), nor caches."""
    for name in ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md"):
        shutil.copy2(ROOT / name, dest / name)
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", "*.pyc", "node_modules", "static")
    shutil.copytree(ROOT / "gesturekit", dest / "gesturekit", ignore=ignore)
    return dest


def _clean_env(venv: Path) -> dict[str, str]:
    """The environment of a user of the venv: its bin first, no PYTHONPATH, no folder holding node."""
    dirs = [d for d in os.environ.get("PATH", "").split(os.pathsep) if d and not (Path(d) / "node").exists()]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = os.pathsep.join([str(venv / "bin"), *dirs])
    assert shutil.which("node", path=env["PATH"]) is None and shutil.which("npm", path=env["PATH"]) is None
    return env


def _run(cmd: list[str], *, cwd: Path, env: dict[str, str] | None = None, timeout: float) -> str:
    run = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=patience(timeout))
    assert run.returncode == 0, f"{' '.join(cmd)} (exit {run.returncode}):\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}"
    return run.stdout


def test_the_wheel_runs_the_cli_and_the_app_without_the_repository(demo_home, tmp_path):
    if (reason := _missing_tools()) is not None:
        pytest.skip(reason)
    src, dist, away = (tmp_path / name for name in ("src", "dist", "away"))
    for folder in (src, dist, away):
        folder.mkdir()
    _source(src)

    # the sdist, and the wheel built from it (no isolation: this environment has the build requirements)
    _run([sys.executable, "-m", "build", "--no-isolation", "--outdir", str(dist), str(src)], cwd=tmp_path, timeout=600)
    (wheel,) = dist.glob(f"gesturekit-{__version__}-*.whl")
    (sdist,) = dist.glob(f"gesturekit-{__version__}.tar.gz")
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        metadata = z.read(f"gesturekit-{__version__}.dist-info/METADATA").decode()
    for shipped in (
        "gesturekit/app/Home.py",
        "gesturekit/app/views/1_Synthesize.py",
        "gesturekit/app/views/6_Study.py",
        "gesturekit/viz/web/static/viewer.js",
        "gesturekit/assets/demo-refiner/config.json",
    ):
        assert shipped in names, f"the wheel lacks {shipped}"
    assert f"\nVersion: {__version__}\n" in metadata
    assert not [n for n in names if n.startswith(("app/", "tests/"))]  # the package only

    # a venv that reuses the installed dependencies, with the wheel's gesturekit as its own
    venv = tmp_path / "venv"
    # (without a pip and setuptools of its own, which would hide newer ones torch requires: this pip installs)
    _run(
        [sys.executable, "-m", "venv", "--system-site-packages", "--without-pip", str(venv)], cwd=tmp_path, timeout=300
    )
    env = _clean_env(venv)
    pip = [sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "install", "--no-index", "-q"]
    _run([*pip, "--disable-pip-version-check", f"gesturekit[app] @ {wheel.as_uri()}"], cwd=away, env=env, timeout=300)

    gk = venv / "bin" / "gesturekit"
    assert _run([str(gk), "--version"], cwd=away, env=env, timeout=120) == f"gesturekit {__version__}\n"
    probe = "import gesturekit, importlib.metadata as m; print(gesturekit.__file__); print(m.version('gesturekit'))"
    where, version = _run([str(venv / "bin" / "python"), "-c", probe], cwd=away, env=env, timeout=120).split()
    assert Path(where).resolve().is_relative_to(venv.resolve()), f"gesturekit imported from {where}, not the wheel"
    assert version == __version__

    # synthesis on speech, with the demo database of GESTUREKIT_HOME
    if SHARED_SPEECH.is_file():
        speech = SHARED_SPEECH
    else:  # ../shared is missing: speech the test makes
        speech = app_browser.write_speech(away / "speech.wav", seconds=8.0)
    env["GESTUREKIT_HOME"] = str(demo_home)
    _run([str(gk), "synthesize", str(speech), "--out", str(away / "out")], cwd=away, env=env, timeout=600)
    for suffix in (".npz", ".bvh"):
        made = away / "out" / (speech.stem + suffix)
        assert made.stat().st_size > 1000, made

    # the app, served by the installed command, drawn in Chromium: the Database page and its clip in 3D
    with app_browser.app_server(demo_home, gesturekit=gk, env=env, log=tmp_path / "app.log") as url:
        with app_browser.browser() as page:
            app_browser.open_app(page, url, "Database", heading="Database")
            canvas = app_browser.skeleton_canvas(page, "db.skeleton")
            box = canvas.bounding_box()
            assert box["width"] > 200 and box["height"] > 200
            assert app_browser.problems(page) == []
            app_browser.screenshot(page, tmp_path / "wheel_database.png")
    assert (tmp_path / "wheel_database.png").stat().st_size > 10_000
    (installed,) = venv.glob("lib/python*/site-packages/gesturekit/app/Home.py")
    with zipfile.ZipFile(wheel) as z:  # the app the server ran is the wheel's, in the venv
        assert z.read("gesturekit/app/Home.py") == installed.read_bytes()
    assert sdist.stat().st_size > 10_000
