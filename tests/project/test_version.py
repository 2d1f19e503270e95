"""One version, written once (gesturekit/_version.py): the package metadata reads it, ``gesturekit --version``
prints it, and CHANGELOG.md's newest release is it."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import tomllib
from packaging.version import Version

from gesturekit._version import __version__

ROOT = Path(__file__).resolve().parents[2]
#: A release's heading in CHANGELOG.md: ``## 0.4.0 (2026-11-28)``.
HEADING = re.compile(r"^## (\S+) \((\d{4}-\d{2}-\d{2})\)$", re.M)


def releases() -> list[tuple[str, str]]:
    """(version, date) of every release in CHANGELOG.md, in the file's order."""
    return HEADING.findall((ROOT / "CHANGELOG.md").read_text(encoding="utf-8"))


def test_the_newest_release_in_the_changelog_is_the_packages_version():
    found = releases()
    assert found, "CHANGELOG.md has no release heading"
    assert found[0][0] == __version__
    assert str(Version(__version__)) == __version__  # a version pip reads as written


def test_the_changelog_goes_back_release_by_release():
    """Newest first, each version and date below the one before, each release with its changes."""
    found = releases()
    versions = [Version(v) for v, _ in found]
    assert versions == sorted(versions, reverse=True) and len(set(versions)) == len(versions)
    dates = [d for _, d in found]
    assert dates == sorted(dates, reverse=True)
    sections = HEADING.split((ROOT / "CHANGELOG.md").read_text(encoding="utf-8"))[1:]
    for version, _, body in zip(sections[::3], sections[1::3], sections[2::3]):
        assert re.search(r"^- \S", body, re.M), f"release {version} lists no change"


def test_the_metadata_takes_the_version_from_the_package():
    """pyproject.toml declares the version dynamic, read by setuptools from gesturekit/_version.py's one
    assignment (without importing the package); the built wheel's METADATA is checked in
    tests/project/test_wheel.py."""
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert "version" not in pyproject["project"] and "version" in pyproject["project"]["dynamic"]
    attr = pyproject["tool"]["setuptools"]["dynamic"]["version"]["attr"]
    module, name = attr.rsplit(".", 1)
    assert (module, name) == ("gesturekit._version", "__version__")
    tree = ast.parse((ROOT / (module.replace(".", "/") + ".py")).read_text(encoding="utf-8"))
    values = [
        ast.literal_eval(node.value)
        for node in tree.body
        if isinstance(node, ast.Assign) and [getattr(t, "id", None) for t in node.targets] == [name]
    ]
    assert values == [__version__]  # one literal assignment: what setuptools reads statically
