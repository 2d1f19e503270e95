"""The package's layers: each module imports only from its own layer and those below it.

From the bottom up (the data's way through the package)::

    base        errors, _io, _jobs, _optional, _version, _config, options, limits, paths, outputs,
                skeleton, bones, motion, control
    datasets    the readers and the generated demo speaker (gesturekit/datasets/)
    features    audio and pose features, their layout
    character   the default body mesh, skinning, rotations from positions, retargeting
    database    MatchingDatabase, its folder on disk, the demo database, finding databases
    search      Algorithm 1 (gesturekit/search/), blending
    synthesize  speech -> motion (gesturekit/synthesis/): the options (config) and entry points
                (the package), the stages (synthesizer), what passes between them (types); the live
                synthesis; also the package's ``__init__``, which re-exports the database and the
                Synthesizer
    refine/export/viz/evaluate
                what is done with a synthesis (peers: they may import each other)
    study/interactive
                gesturekit/study/ (user-study stimuli, their options, running the study),
                interactive.py (the app's logic without streamlit)
    cli/app     gesturekit/cli/, __main__.py, and the Streamlit app (gesturekit/app/; the clone's
                app/Home.py, which serves it, is cli/app too)

Every module of gesturekit/ is listed by its full name in :data:`LAYERS`: a new module fails
:func:`test_every_module_has_a_layer` until it is placed, and a listed module that no longer
exists fails :func:`test_no_stale_entries`. For the layer order, every import counts, also those
inside functions and ``try`` blocks (a lazy import is still a dependency); only imports under
``if TYPE_CHECKING:`` do not, as they never run. For circles they count too
(:func:`test_no_import_circle`): a type named across a circle belongs in the module below.
No module imports another module's private (underscore) names or private modules
(:func:`test_no_module_reaches_into_anothers_private_names`), except a package's own private
modules imported inside that package (``gesturekit.character._body`` by ``gesturekit.character.*``).
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "gesturekit"
MAX_LINES = 700

# (layer, every module of gesturekit in it by its full dotted name); the clone's app/ is all cli/app.
LAYERS: list[tuple[str, tuple[str, ...]]] = [
    (
        "base",
        (
            "gesturekit._arguments",
            "gesturekit._config",
            "gesturekit._io",
            "gesturekit._jobs",
            "gesturekit._moved",
            "gesturekit._optional",
            "gesturekit._version",
            "gesturekit.bones",
            "gesturekit.control",
            "gesturekit.control_lanes",
            "gesturekit.errors",
            "gesturekit.folders",
            "gesturekit.limits",
            "gesturekit.motion",
            "gesturekit.options",
            "gesturekit.outputs",
            "gesturekit.paths",
            "gesturekit.skeleton",
        ),
    ),
    (
        "datasets",
        (
            "gesturekit.datasets",
            "gesturekit.datasets._axes",
            "gesturekit.datasets._demo_body",
            "gesturekit.datasets._demo_gestures",
            "gesturekit.datasets._demo_speech",
            "gesturekit.datasets._kinematics",
            "gesturekit.datasets._partial",
            "gesturekit.datasets._reading",
            "gesturekit.datasets.audio",
            "gesturekit.datasets.audio_headers",
            "gesturekit.datasets.bvh",
            "gesturekit.datasets.bvh_file",
            "gesturekit.datasets.habibie2021",
            "gesturekit.datasets.keypoint_example",
            "gesturekit.datasets.positions",
            "gesturekit.datasets.presets",
            "gesturekit.datasets.synthetic",
            "gesturekit.datasets.takes",
        ),
    ),
    ("features", ("gesturekit.features",)),
    (
        "character",
        (
            "gesturekit.character",
            "gesturekit.character._arms",
            "gesturekit.character._body",
            "gesturekit.character._loft",
            "gesturekit.character._user_bvh",
            "gesturekit.character._user_fbx",
            "gesturekit.character._fbx_read",
            "gesturekit.character._user_gltf",
            "gesturekit.character.bone_body",
            "gesturekit.character.contact",
            "gesturekit.character.glb",
            "gesturekit.character.humanoid",
            "gesturekit.character.look",
            "gesturekit.character.materials",
            "gesturekit.character.mesh",
            "gesturekit.character.mtoon",
            "gesturekit.character.paint",
            "gesturekit.character.retarget",
            "gesturekit.character.rig",
            "gesturekit.character.shape",
            "gesturekit.character.skin",
            "gesturekit.character.solve",
            "gesturekit.character.stand",
            "gesturekit.character.target",
            "gesturekit.character.user",
        ),
    ),
    (
        "database",
        (
            "gesturekit.database",
            "gesturekit.database.audio",
            "gesturekit.database.build",
            "gesturekit.database.clips",
            "gesturekit.database.config",
            "gesturekit.database.folder",
            "gesturekit.database.matching",
            "gesturekit.database.sources",
            "gesturekit.database.stage",
            "gesturekit.database.stage_check",
            "gesturekit.demo",
            "gesturekit.workspace",
        ),
    ),
    (
        "search",
        (
            "gesturekit.blend",
            "gesturekit.search",
            "gesturekit.search.admissible",
            "gesturekit.search.checks",
            "gesturekit.search.compile_cache",
            "gesturekit.search.decide",
            "gesturekit.search.device",
            "gesturekit.search.exact",
            "gesturekit.search.explain",
            "gesturekit.search.frames",
            "gesturekit.search.index",
            "gesturekit.search.kernels",
            "gesturekit.search.plan",
            "gesturekit.search.reduced",
            "gesturekit.search.reduced_kernels",
            "gesturekit.search.reference",
            "gesturekit.search.stream",
            "gesturekit.search.threads",
            "gesturekit.search.types",
        ),
    ),
    (
        "synthesize",
        (
            "gesturekit",
            "gesturekit.live",
            "gesturekit.synthesis",
            "gesturekit.synthesis.config",
            "gesturekit.synthesis.synthesizer",
            "gesturekit.synthesis.types",
        ),
    ),
    (
        "refine/export/viz/evaluate",
        (
            "gesturekit.evaluate",
            "gesturekit.evaluate.baselines",
            "gesturekit.evaluate.fgd",
            "gesturekit.evaluate.metrics",
            "gesturekit.evaluate.run",
            "gesturekit.export",
            "gesturekit.export._character_bvh",
            "gesturekit.export._files",
            "gesturekit.export.bvh",
            "gesturekit.export.character",
            "gesturekit.export.gltf",
            "gesturekit.export.loudness",
            "gesturekit.export.npz",
            "gesturekit.export.result",
            "gesturekit.export.video",
            "gesturekit.refine",
            "gesturekit.refine.config",
            "gesturekit.refine.data",
            "gesturekit.refine.folder",
            "gesturekit.refine.infer",
            "gesturekit.refine.model",
            "gesturekit.refine.train",
            "gesturekit.viz",
            "gesturekit.viz._plotly",
            "gesturekit.viz.analysis",
            "gesturekit.viz.appearance",
            "gesturekit.viz.body_meshes",
            "gesturekit.viz.character_page",
            "gesturekit.viz.character_mtoon",
            "gesturekit.viz.character_render",
            "gesturekit.viz.character_user",
            "gesturekit.viz.figures",
            "gesturekit.viz.notebook",
            "gesturekit.viz.paper",
            "gesturekit.viz.render",
            "gesturekit.viz.render_pool",
            "gesturekit.viz.render_worker",
            "gesturekit.viz.candidate_view",
            "gesturekit.viz.retrieval",
            "gesturekit.viz.skeleton_figure",
            "gesturekit.viz.viewer",
            "gesturekit.viz.walkthrough",
            "gesturekit.viz.web",
            "gesturekit.viz.web.build",
        ),
    ),
    (
        "study/interactive",
        (
            "gesturekit.interactive",
            "gesturekit.study",
            "gesturekit.study._fields",
            "gesturekit.study.analyse",
            "gesturekit.study.bradley_terry",
            "gesturekit.study.config",
            "gesturekit.study.design",
            "gesturekit.study.hemvip",
            "gesturekit.study.media",
            "gesturekit.study.report",
            "gesturekit.study.server",
            "gesturekit.study.simulate",
            "gesturekit.study.stimuli",
            "gesturekit.study.store",
        ),
    ),
    (
        "cli/app",
        (
            "gesturekit.__main__",
            "gesturekit.app",
            "gesturekit.app.Home",
            "gesturekit.app.characters",
            "gesturekit.app.display",
            "gesturekit.app.launch",
            "gesturekit.app.live_session",
            "gesturekit.app.nav",
            "gesturekit.app.resources",
            "gesturekit.app.sidebar",
            "gesturekit.app.state",
            "gesturekit.app.timeline",
            "gesturekit.app.views.1_Synthesize",
            "gesturekit.app.views.2_Retrieval_inspector",
            "gesturekit.app.views.3_Database",
            "gesturekit.app.views.4_Study_stimuli",
            "gesturekit.app.views.5_Live",
            "gesturekit.app.views.6_Study",
            "gesturekit.cli",
            "gesturekit.cli._app",
            "gesturekit.cli._character",
            "gesturekit.cli._options",
            "gesturekit.cli._parser",
            "gesturekit.cli._study",
        ),
    ),
]
MODULES: dict[str, str] = {m: layer for layer, names in LAYERS for m in names}
APP = "app"
RANK = {name: i for i, (name, _) in enumerate(LAYERS)}


def layer_of(module: str) -> str | None:
    """The layer of a module by its full name; None for a module that is not listed."""
    if module == APP or module.startswith(APP + "."):
        return "cli/app"
    return MODULES.get(module)


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


def _source(node: ast.ImportFrom, package: str) -> str:
    """The absolute module an ``ImportFrom`` reads from."""
    if node.level:
        base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
        return ".".join(base + ([node.module] if node.module else []))
    return node.module or ""


def _ours(name: str) -> bool:
    return name.split(".")[0] in ("gesturekit", APP)


def import_names(path: Path, *, type_checking: bool = False) -> list[tuple[str, str | None]]:
    """Every (module, name) a file imports from gesturekit or app: ``(module, None)`` for
    ``import module``, ``(module, name)`` for ``from module import name``; those under
    ``if TYPE_CHECKING:`` only when ``type_checking``."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    skip = set() if type_checking else _type_checking_only(tree)
    me = module_name(path)
    package = me if path.name == "__init__.py" else me.rpartition(".")[0]
    out: list[tuple[str, str | None]] = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out.extend((a.name, None) for a in node.names if a.name.split(".")[0] == "gesturekit")
        elif isinstance(node, ast.ImportFrom):
            source = _source(node, package)
            if source.split(".")[0] == "gesturekit" or (node.level and _ours(source)):
                out.extend((source, alias.name) for alias in node.names)
    return out


def imports_of(path: Path, *, type_checking: bool = False) -> set[str]:
    """The gesturekit modules a file imports (``from .x import f`` -> ``gesturekit.x``;
    ``from . import x`` -> ``gesturekit.x`` when x is a module, else the package itself)."""
    me = module_name(path)
    out = set()
    for source, name in import_names(path, type_checking=type_checking):
        if source.split(".")[0] != "gesturekit":
            continue
        sub = f"{source}.{name}"
        out.add(sub if name is not None and is_module(sub) else source)
    out.discard(me)
    return out


def sources() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py")) + sorted((ROOT / "app").rglob("*.py"))


@functools.cache
def graph(*, type_checking: bool = False) -> dict[str, set[str]]:
    return {module_name(p): imports_of(p, type_checking=type_checking) for p in sources()}


def violations() -> set[tuple[str, str]]:
    bad = set()
    for importer, imported in graph().items():
        for target in imported:
            if RANK[layer_of(target)] > RANK[layer_of(importer)]:
                bad.add((importer, target))
    return bad


def circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The import circles of a graph: its strongly connected components of more than one
    module (or a module importing itself), each sorted, found by Tarjan's algorithm."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1 or v in edges.get(v, ()):
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return sorted(found)


def _private_part(module: str) -> int | None:
    """Index of the first private (underscore) component of a dotted module name, None if public."""
    for i, part in enumerate(module.split(".")):
        if part.startswith("_") and not (part.startswith("__") and part.endswith("__")):
            return i
    return None


def private_reach(importer: str, module: str, name: str | None) -> str | None:
    """What is private about ``importer`` importing ``name`` from ``module`` (None: nothing).

    A private module (``a.b._c``, or anything under it) is open to the modules of its package
    (``a.b`` and below); anywhere else it, and any underscore name of any module, is private.
    """
    target = module if name is None else f"{module}.{name}"
    if name is not None and not is_module(target):
        target = module  # a name, not a submodule: the module it comes from is what is reached into
        if name.startswith("_") and not (name.startswith("__") and name.endswith("__")):
            i = _private_part(module)
            inside = i is not None and (importer + ".").startswith(".".join(module.split(".")[:i]) + ".")
            if not inside:
                return f"{importer} imports the private name {name} of {module}"
    i = _private_part(target)
    if i is None:
        return None
    package = ".".join(target.split(".")[:i])
    if (importer + ".").startswith(package + "."):
        return None
    return f"{importer} imports the private module {'.'.join(target.split('.')[: i + 1])} from outside {package}"


def private_reaches() -> list[str]:
    found = set()
    for path in sources():
        me = module_name(path)
        for module, name in import_names(path, type_checking=True):
            problem = private_reach(me, module, name)
            if problem:
                found.add(problem)
    return sorted(found)


def test_every_module_has_a_layer():
    unplaced = sorted(m for m in graph() if layer_of(m) is None)
    assert not unplaced, (
        "place these modules in a layer of tests/project/test_layering.py's LAYERS (by their full names): "
        + ", ".join(unplaced)
    )


def test_no_stale_entries():
    present = {m for m in graph() if m.startswith("gesturekit")}
    stale = sorted(set(MODULES) - present)
    assert not stale, f"tests/project/test_layering.py's LAYERS lists modules that no longer exist: {', '.join(stale)}"
    listed = [m for _, names in LAYERS for m in names]
    twice = sorted({m for m in listed if listed.count(m) > 1})
    assert not twice, f"listed in more than one layer: {', '.join(twice)}"


def test_no_import_circle():
    """No circle in the import graph, imports under ``if TYPE_CHECKING:`` included."""
    found = circles(graph(type_checking=True))
    assert not found, "import circles (TYPE_CHECKING imports included):\n" + "\n".join(" <-> ".join(c) for c in found)


def test_no_module_reaches_into_anothers_private_names():
    found = private_reaches()
    assert not found, "private names imported across modules:\n" + "\n".join(found)


def test_the_core_never_imports_streamlit():
    """Only the app (gesturekit/app/) imports streamlit; the command line and everything below it do not."""
    app = PACKAGE / "app"
    assert (app / "Home.py").is_file()
    for path in sorted(PACKAGE.rglob("*.py")):
        if app in path.parents:
            continue
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


def test_layer_map_is_by_full_name():
    """A module is placed by its own name only: an unlisted one (new, or a misspelling) has no layer."""
    assert layer_of("gesturekit._io") == layer_of("gesturekit._version") == "base"
    assert layer_of("gesturekit.search.kernels") == layer_of("gesturekit.search") == "search"
    assert layer_of("gesturekit.search.not_yet_written") is None  # a package does not place its new modules
    assert layer_of("gesturekit.study") == layer_of("gesturekit.interactive") == "study/interactive"
    assert layer_of("app.views.synthesize") == layer_of("app") == "cli/app"
    assert layer_of("gesturekit_other") is None and layer_of("apple") is None


def test_circles_are_the_strongly_connected_parts():
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"e"}, "f": {"d"}}
    assert circles(edges) == [["a", "b", "c"], ["e"]]
    assert circles({"a": {"b"}, "b": set()}) == []


def test_private_reach_rules(tmp_path, monkeypatch):
    pkg = tmp_path / "gesturekit"
    for name in ("__init__.py", "errors.py", "_io.py", "sub/__init__.py", "sub/_helper.py", "sub/deep.py"):
        (pkg / name).parent.mkdir(parents=True, exist_ok=True)
        (pkg / name).write_text("")
    monkeypatch.setitem(globals(), "ROOT", tmp_path)
    assert private_reach("gesturekit.sub.deep", "gesturekit.sub._helper", "f") is None  # its package's own
    assert private_reach("gesturekit.sub.deep", "gesturekit.sub", "_helper") is None
    assert private_reach("gesturekit.sub.deep", "gesturekit._io", "atomic_write") is None  # gesturekit's own
    assert private_reach("gesturekit.sub.deep", "gesturekit", "__version__") is None  # a dunder is not private
    assert "private module gesturekit.sub._helper" in private_reach("gesturekit.other", "gesturekit.sub._helper", "f")
    assert "private module gesturekit._io" in private_reach("app.page", "gesturekit._io", "atomic_write")
    assert "private name _f of gesturekit.errors" in private_reach("gesturekit.sub.deep", "gesturekit.errors", "_f")
    assert private_reach("gesturekit.sub.deep", "gesturekit.sub._helper", "_g") is None


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
