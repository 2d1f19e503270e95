"""Shared fixtures: the read-only test data beside the repository, tiny generated takes."""

from __future__ import annotations

import ast
import os
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

from gesturekit.motion import AUDIO_SR, Motion, Take
from gesturekit.skeleton import N_JOINTS

# CPython 3.11 builds an AST with state shared between threads (python/cpython#106905): an app test's
# script thread parsing (Streamlit's magic) while another thread parses (an import's assertion
# rewriting) can fail with "SystemError: AST constructor recursion depth mismatch". One parse at a time.
_AST_LOCK = threading.RLock()
_ast_parse = ast.parse


def _parse_one_at_a_time(*args, **kwargs):
    with _AST_LOCK:
        return _ast_parse(*args, **kwargs)


ast.parse = _parse_one_at_a_time

# No per-example deadline (hypothesis's default is 200 ms) and no health check on how long examples
# take to generate: on a busy machine an example that is quick alone can take seconds, and a
# deadline there fails tests for the machine's load, not for what they check. Every test file's own
# @settings starts from this profile (one that names its own health checks names too_slow too).
settings.register_profile("gesturekit", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("gesturekit")


SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
ZEGGS_BVH = SHARED_DATA / "zeggs" / "067_Speech_2_x_1_0.bvh"
ZEGGS_WAV = SHARED_DATA / "zeggs" / "067_Speech_2_x_1_0.wav"


BROWSER_TESTS = Path(__file__).resolve().parent / "browser"


@pytest.hookimpl(tryfirst=True)  # before ``-m`` deselects, so that ``-m "not browser"`` sees the marker
def pytest_collection_modifyitems(config, items):
    """Every test in ``tests/browser`` drives headless Chromium: it gets the ``browser`` marker here, on
    the folder, so a new browser test cannot be left out of ``-m "not browser"``.

    The ``load`` tests keep every core busy (``tests/load.py``): in a parallel run they would slow
    the tests of the other workers, some of which time things. They run alone: ``pytest -m load``
    (``.ci/run`` runs them after the others); a parallel run that does not ask for them skips them."""
    for item in items:
        if BROWSER_TESTS in Path(item.fspath).resolve().parents:
            item.add_marker(pytest.mark.browser)
    if not os.environ.get("PYTEST_XDIST_WORKER") or "load" in (config.getoption("markexpr") or ""):
        return
    skip = pytest.mark.skip(reason="keeps every core busy: runs alone, with `pytest -m load` (.ci/run does)")
    for item in items:
        if item.get_closest_marker("load") is not None:
            item.add_marker(skip)


@pytest.fixture(autouse=True)
def _restore_main_module():
    """Streamlit's AppTest runs pages as ``__main__`` and leaves them there; processes spawned
    later in the same test process would import that page. Each test gets the original back."""
    main = sys.modules.get("__main__")
    yield
    if main is not None:
        sys.modules["__main__"] = main


@pytest.fixture(params=["quiet", pytest.param("busy", marks=pytest.mark.load)])
def machine(request):
    """The test runs twice: on the machine as it is ("quiet"; None), and with every core kept busy
    throughout ("busy", a ``load`` test; the running :class:`tests.load.Busy`)."""
    if request.param == "quiet":
        yield None
        return
    from tests import load

    with load.busy_cores() as busy:
        yield busy


@pytest.fixture(scope="module")
def demo_home(tmp_path_factory) -> Path:
    """A gesturekit home holding a 2-minute demo database at the default path (one per test module)."""
    from gesturekit.demo import build_demo_database

    home = tmp_path_factory.mktemp("gkhome")
    build_demo_database(home / "db" / "demo", minutes=2)
    return home


@pytest.fixture
def app_env(demo_home, tmp_path, monkeypatch) -> Path:
    """The app's environment: ``demo_home`` as GESTUREKIT_HOME, and a fresh working directory
    (``./db`` of the working directory is one of the places the sidebar lists), which is also
    one of the folders the app may use (``GESTUREKIT_APP_ROOTS``), so a test's files can be typed in."""
    monkeypatch.setenv("GESTUREKIT_HOME", str(demo_home))
    monkeypatch.setenv("GESTUREKIT_APP_ROOTS", str(tmp_path))
    monkeypatch.delenv("GESTUREKIT_DEMO_MINUTES", raising=False)
    monkeypatch.chdir(tmp_path)
    return demo_home


def chart_spec(at, key: str) -> dict:
    """The plotly JSON spec of the chart with widget key ``key`` on an AppTest page."""
    import json

    for el in at.get("plotly_chart"):
        if el.proto.id.endswith(key):
            return json.loads(el.proto.spec)
    raise AssertionError(f"no plotly chart with key {key!r}")


def viewer(at, key: str) -> dict:
    """The data of the skeleton viewer with key ``key`` on an AppTest page (coordinates decoded, see
    :func:`gesturekit.viz.viewer.read_viewer_args`): the args of its component (app/display.viewer_component)."""
    import json

    from gesturekit.viz.viewer import read_viewer_args

    for el in at.get("component_instance"):
        args = json.loads(el.proto.json_args)
        if el.proto.component_name.endswith("skeleton_viewer") and args.get("key") == key:
            audio = next((a.bytes for a in el.proto.special_args if a.key == "audio"), None)
            return read_viewer_args(args["data"], audio, key)
    raise AssertionError(f"no skeleton viewer with key {key!r}")


def plotly_array(value) -> np.ndarray:
    """A data array of a plotly JSON spec (typed-array dict or list, None as NaN), float64."""
    import base64

    if isinstance(value, dict):
        return np.frombuffer(base64.b64decode(value["bdata"]), dtype=np.dtype(value["dtype"])).astype(np.float64)
    return np.array([np.nan if v is None else v for v in value], dtype=np.float64)


@pytest.fixture
def shared_data() -> Path:
    """The shared test data folder; the test is skipped when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared test data not found at {SHARED_DATA} (it lives beside the repository)")
    return SHARED_DATA


@pytest.fixture
def zeggs_files(shared_data) -> tuple[Path, Path]:
    if not (ZEGGS_BVH.is_file() and ZEGGS_WAV.is_file()):
        pytest.skip(f"ZEGGS take not found in {shared_data / 'zeggs'}")
    return ZEGGS_BVH, ZEGGS_WAV


def make_take(seconds: float, *, seed: int = 0, name: str = "take", fps: float = 15.0) -> Take:
    """A small random take: smooth joint wander and a noisy, amplitude-modulated tone.

    Not a plausible body (bone lengths vary); enough to exercise features and databases.
    """
    rng = np.random.default_rng(seed)
    n = int(round(seconds * fps))
    base = rng.normal(0, 0.3, size=(1, N_JOINTS, 3))
    walk = np.cumsum(rng.normal(0, 0.01, size=(n, N_JOINTS, 3)), axis=0)
    pos = (base + walk).astype(np.float32)
    t = np.arange(int(seconds * AUDIO_SR)) / AUDIO_SR
    env = 0.5 + 0.5 * np.sin(2 * np.pi * (1.5 + seed % 3) * t)
    audio = (0.3 * env * np.sin(2 * np.pi * (150 + 20 * seed) * t) + 0.01 * rng.normal(size=t.size)).astype(np.float32)
    return Take(name, Motion(pos, fps), audio, {"generator": "tests"})


def shown(markdown: str) -> str:
    """What a reader sees of an element's Markdown source (an AppTest element's ``value``): the text
    rendered, without markup, escapes or the invisible word joiners (app/display.escape_markdown)."""
    import html
    import re

    from markdown_it import MarkdownIt

    text = html.unescape(re.sub(r"<[^>]+>", "", MarkdownIt("commonmark").render(str(markdown))))
    return text.replace("\u2060", "").strip()
