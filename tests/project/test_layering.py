"""The package's layers: each module imports only from its own layer and those below it.

From the bottom up (the data's way through the package, issue 17's acceptance)::

    base        errors, _io, _jobs, _optional, _version, _config, limits, paths, outputs,
                skeleton, bones, motion, control
    datasets    the readers and the generated demo speaker (gesturekit/datasets/)
    features    audio and pose features, their layout
    database    MatchingDatabase, its folder on disk, the demo database, finding databases
                (also the package's ``__init__``, which re-exports the database)
    search      Algorithm 1 (gesturekit/search/ or search.py, its kernels and reference), blending
    synthesize  speech -> motion, the whole pipeline
    refine/export/viz/evaluate
                what is done with a synthesis (peers: they may import each other)
    study/interactive
                study.py (user-study stimuli), studies/ (running the study), interactive.py (the app's
                logic without streamlit)
    cli/app     cli.py (its options: _cli_parser.py; synthesize --character: _cli_character.py;
                study: _cli_study.py), __main__.py, and the Streamlit app (app/)

Every import counts, also those inside functions and ``try`` blocks (a lazy import is still a
dependency); only imports under ``if TYPE_CHECKING:`` do not, as they never run. The map is by
module name, so modules that do not exist yet (or any more) cost nothing; a module of
gesturekit/ that is in no layer fails the test until it is placed.

A refiner reaches synthesis as an object (``gesturekit.synthesize.MotionRefiner``), opened from
its folder above it; results are written by ``gesturekit.export.result``; output folders are
recognised by their markers (``gesturekit._io.folder_kind``); the demo speaker takes its frame
count from ``gesturekit.motion``.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "gesturekit"
MAX_LINES = 700

# (layer, module-name prefixes); a module belongs to the layer of its longest matching prefix.
LAYERS: list[tuple[str, tuple[str, ...]]] = [
    (
        "base",
        (
            "gesturekit.errors",
            "gesturekit._io",
            "gesturekit._jobs",
            "gesturekit._optional",
            "gesturekit._version",
            "gesturekit._config",
            "gesturekit.limits",
            "gesturekit.paths",
            "gesturekit.outputs",
            "gesturekit.skeleton",
            "gesturekit.bones",
            "gesturekit.motion",
            "gesturekit.control",
        ),
    ),
    ("datasets", ("gesturekit.datasets",)),
    ("features", ("gesturekit.features",)),
    ("character", ("gesturekit.character",)),
    ("database", ("gesturekit", "gesturekit.database", "gesturekit.demo", "gesturekit.workspace")),
    ("search", ("gesturekit.search", "gesturekit._search_kernels", "gesturekit.search_reference", "gesturekit.blend")),
    ("synthesize", ("gesturekit.synthesize", "gesturekit.live")),
    ("refine/export/viz/evaluate", ("gesturekit.refine", "gesturekit.export", "gesturekit.viz", "gesturekit.evaluate")),
    ("study/interactive", ("gesturekit.study", "gesturekit.studies", "gesturekit.interactive")),
    (
        "cli/app",
        (
            "gesturekit.cli",
            "gesturekit._cli_parser",
            "gesturekit._cli_character",
            "gesturekit._cli_study",
            "gesturekit.__main__",
            "app",
        ),
    ),
]
RANK = {name: i for i, (name, _) in enumerate(LAYERS)}


def layer_of(module: str) -> str | None:
    best = None
    for name, prefixes in LAYERS:
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and (best is None or len(prefix) > len(best[1])):
                best = (name, prefix)
    return None if best is None else best[0]


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def is_module(name: str) -> bool:
    """Whether a dotted gesturekit name is a module or package in the tree (not an attribute)."""
    path = ROOT.joinpath(*name.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def _type_checking_only(node: ast.AST) -> set[int]:
    """ids of the import nodes inside ``if TYPE_CHECKING:`` blocks."""
    skip = set()
    for n in ast.walk(node):
        if isinstance(n, ast.If):
            test = n.test
            name = test.id if isinstance(test, ast.Name) else test.attr if isinstance(test, ast.Attribute) else None
            if name == "TYPE_CHECKING":
                for child in n.body:
                    skip.update(id(x) for x in ast.walk(child))
    return skip


def imports_of(path: Path) -> set[str]:
    """The gesturekit modules a file imports (``from .x import f`` -> ``gesturekit.x``;
    ``from . import x`` -> ``gesturekit.x`` when x is a module, else the package itself)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    skip = _type_checking_only(tree)
    me = module_name(path)
    package = me if path.name == "__init__.py" else me.rpartition(".")[0]
    out = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.split(".")[0] == "gesturekit")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            if source.split(".")[0] != "gesturekit":
                continue
            for alias in node.names:
                sub = f"{source}.{alias.name}"
                out.add(sub if is_module(sub) else source)
    out.discard(me)
    return out


def sources() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py")) + sorted((ROOT / "app").rglob("*.py"))


def graph() -> dict[str, set[str]]:
    return {module_name(p): imports_of(p) for p in sources()}


def violations() -> set[tuple[str, str]]:
    bad = set()
    for importer, imported in graph().items():
        for target in imported:
            if RANK[layer_of(target)] > RANK[layer_of(importer)]:
                bad.add((importer, target))
    return bad


def test_every_module_has_a_layer():
    unplaced = sorted(m for m in graph() if layer_of(m) is None)
    assert not unplaced, f"place these modules in a layer of tests/project/test_layering.py's LAYERS: {unplaced}"


def test_no_import_runs_back_up():
    bad = violations()
    lines = [f"{a} ({layer_of(a)}) imports {b} ({layer_of(b)})" for a, b in sorted(bad)]
    assert not bad, "imports running back up the layers:\n" + "\n".join(lines)


def test_the_core_never_imports_streamlit():
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else []
            )
            assert not any(n.split(".")[0] == "streamlit" for n in names), path


def test_no_file_over_700_lines():
    long = {
        str(p.relative_to(ROOT)): n
        for p in sorted(PACKAGE.rglob("*.py"))
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES
    }
    assert not long, f"over {MAX_LINES} lines: {long}"


# ---------------------------------------------------------------- the checker itself


def test_layer_map_places_the_planned_modules():
    """The modules issue 17 creates land where the layers say, whether they exist yet or not."""
    assert layer_of("gesturekit._io") == layer_of("gesturekit._version") == "base"
    assert layer_of("gesturekit.search.kernels") == layer_of("gesturekit.search") == "search"
    assert layer_of("gesturekit.search_reference") == "search"  # a prefix is a dotted name, not a string start
    assert layer_of("gesturekit.study") == layer_of("gesturekit.interactive") == "study/interactive"
    assert layer_of("gesturekit.datasets._demo_body") == "datasets"
    assert layer_of("gesturekit.viz.session") == "refine/export/viz/evaluate"
    assert layer_of("app.views.synthesize") == "cli/app"
    assert layer_of("gesturekit_other") is None and layer_of("apple") is None


def test_imports_are_resolved_to_modules(tmp_path, monkeypatch):
    """Relative, lazy and ``from package import module`` imports count; TYPE_CHECKING ones do not."""
    pkg = tmp_path / "gesturekit"
    (pkg / "sub").mkdir(parents=True)
    for name in ("__init__.py", "errors.py", "features.py", "sub/__init__.py", "sub/deep.py"):
        (pkg / name).write_text("")
    (pkg / "sub" / "deep.py").write_text(
        "from typing import TYPE_CHECKING\n"
        "from .. import errors, __version__\n"
        "from ..errors import GestureKitError\n"
        "if TYPE_CHECKING:\n"
        "    from ..database import MatchingDatabase\n"
        "def f():\n"
        "    import gesturekit.features\n"
        "    try:\n"
        "        from gesturekit.synthesize import synthesize\n"
        "    except ImportError:\n"
        "        pass\n"
    )
    monkeypatch.setitem(globals(), "ROOT", tmp_path)
    assert imports_of(pkg / "sub" / "deep.py") == {
        "gesturekit.errors",
        "gesturekit",
        "gesturekit.features",
        "gesturekit.synthesize",
    }
