"""The package's layout: each thing in its room, files a reader can hold, no import back up through __init__."""

import ast
import importlib
from pathlib import Path

import pytest

import gesturekit
from gesturekit import _version

PACKAGE = Path(gesturekit.__file__).resolve().parent
MAX_LINES = 700
# the search and what consumes it are being reorganised around one search plan; they are held to the
# limit once that lands
NOT_YET = {
    "search.py",
    "_search_kernels.py",
    "search_reference.py",
    "synthesize.py",
    "evaluate/baselines.py",
    "viz/walkthrough.py",
    "cli.py",
}


def _modules():
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def test_no_module_is_longer_than_a_reader_can_hold():
    long = {
        str(p.relative_to(PACKAGE)): n
        for p in _modules()
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES
    }
    assert set(long) <= NOT_YET, f"over {MAX_LINES} lines: {long}"


def test_no_module_imports_the_version_back_through_the_package():
    offenders = []
    for path in _modules():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if not isinstance(node, ast.ImportFrom) or not any(a.name == "__version__" for a in node.names):
                continue
            # `from . import __version__`, `from .. import __version__`, `from gesturekit import __version__`
            if node.module is None or node.module == "gesturekit":
                offenders.append(f"{path.relative_to(PACKAGE)}:{node.lineno}")
    assert offenders == []
    assert gesturekit.__version__ == _version.__version__


@pytest.mark.parametrize(
    "old, new",
    [
        ("gesturekit.viz.session", "gesturekit.interactive"),
        ("gesturekit.export.stimuli", "gesturekit.study"),
        ("gesturekit.export.files", "gesturekit._io"),
    ],
)
def test_moved_modules_live_only_in_their_new_place(old, new):
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(old)
    assert importlib.import_module(new).__doc__
