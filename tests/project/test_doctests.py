"""The Examples sections of the main public functions run as written (doctest), and every one
of those functions has one."""

from __future__ import annotations

import doctest
import importlib
import inspect
import re
import tempfile
from pathlib import Path

import pytest

#: The functions and classes whose docstrings must show an example, by the import path users write.
DOCUMENTED = (
    "gesturekit.demo.build_demo_database",
    "gesturekit.demo.open_default_database",
    "gesturekit.MatchingDatabase.build",
    "gesturekit.MatchingDatabase.load",
    "gesturekit.parse_control",
    "gesturekit.search.SearchConfig",
    "gesturekit.options.widget_limits",
    "gesturekit.synthesis.synthesize",
    "gesturekit.synthesis.synthesize_batch",
    "gesturekit.export.result.save_result_npz",
    "gesturekit.export.result.export_result_bvh",
    "gesturekit.refine.open_refiner",
    "gesturekit.live.LiveSynthesizer",
)

OPTIONS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


def resolve(dotted: str) -> object:
    """The object at ``dotted``: the longest importable module prefix, then attributes."""
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ModuleNotFoundError:
            continue
        for name in parts[cut:]:
            obj = getattr(obj, name)
        return obj
    raise ImportError(dotted)


def examples(obj: object) -> list[doctest.Example]:
    return doctest.DocTestParser().get_examples(inspect.getdoc(obj) or "")


def modules() -> list[str]:
    """The modules that define the documented objects: doctest runs over each of them whole."""
    return sorted({inspect.getmodule(resolve(name)).__name__ for name in DOCUMENTED})


@pytest.mark.parametrize("name", DOCUMENTED)
def test_every_listed_function_has_an_example(name):
    doc = inspect.getdoc(resolve(name)) or ""
    assert "\nExamples\n--------\n" in doc, f"{name}'s docstring has no Examples section"
    assert examples(resolve(name)), f"{name}'s Examples section has no doctest (>>> lines)"


def test_the_examples_page_shows_every_listed_function():
    """docs/examples.md names each function (a MkDocs hook, tools/mkdocs_examples.py, puts its
    Examples section there), and names no other."""
    page = (Path(__file__).resolve().parents[2] / "docs" / "examples.md").read_text(encoding="utf-8")
    shown = re.findall(r"^<!-- example: ([\w.]+) -->$", page, re.M)
    assert sorted(shown) == sorted(DOCUMENTED)
    assert len(modules()) >= 8


@pytest.fixture
def scratch(tmp_path, monkeypatch):
    """The examples' temporary folders and default database under pytest's temporary folder."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    monkeypatch.setenv("GESTUREKIT_HOME", str(tmp_path / "home"))  # restored after the examples change it
    return tmp_path


@pytest.mark.slow
@pytest.mark.parametrize("module", modules())
def test_the_examples_run(module, scratch):
    mod = importlib.import_module(module)
    tests = [t for t in doctest.DocTestFinder(recurse=True).find(mod, module) if t.examples]
    assert tests, f"{module} has no examples"
    runner = doctest.DocTestRunner(optionflags=OPTIONS)
    failures: list[str] = []
    for test in tests:
        runner.run(test, out=failures.append)
    results = runner.summarize(verbose=False)
    assert results.failed == 0, "".join(failures)
