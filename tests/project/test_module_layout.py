"""The package's layout: each thing in its room, no import back up through __init__ (file lengths and the
layers: test_layering.py)."""

import ast
import importlib
from pathlib import Path

import pytest

import gesturekit
from gesturekit import _version

PACKAGE = Path(gesturekit.__file__).resolve().parent


def _modules():
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


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
        ("gesturekit.export.stimuli", "gesturekit.study.stimuli"),
        ("gesturekit.export.files", "gesturekit._io"),
    ],
)
def test_moved_modules_live_only_in_their_new_place(old, new):
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(old)
    assert importlib.import_module(new).__doc__
