"""Optional dependencies: every import of one goes through gesturekit._optional, and a missing one
is a message saying what to install (exit 2 on the command line), never a traceback.

A missing package is simulated as Python does for a module it must not import: ``sys.modules[name] = None``
makes every later ``import name`` fail with ``ModuleNotFoundError``, as on an install without the extra.
"""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
import textwrap
import types
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from packaging.requirements import Requirement

from gesturekit import _optional
from gesturekit._optional import EXTRAS, install_hint, installed, optional, require
from gesturekit.errors import GestureKitError, MissingDependencyError
from tests.badinput import assert_refused, run_cli, snapshot
from tests.project.test_layering import PACKAGE, ROOT, is_module, module_name
from tests.project.test_packaging import declared
from tests.waits import patience


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    """A 0.5-minute demo database and a 2 s speech file, made once for the module."""
    from gesturekit.demo import build_demo_database

    root = tmp_path_factory.mktemp("optional")
    build_demo_database(root / "db", minutes=0.5)
    t = np.arange(32000) / 16000
    sf.write(root / "speech.wav", (0.3 * np.sin(2 * np.pi * 220 * t)).astype(np.float32), 16000)
    return root


# ---- the helper ----------------------------------------------------------------------------------


def test_require_imports_an_installed_module_and_names_the_extra_of_a_missing_one(monkeypatch):
    assert require("torch", purpose="x") is importlib.import_module("torch")
    for name, (package, extra) in EXTRAS.items():
        monkeypatch.setitem(sys.modules, name, None)
        with pytest.raises(MissingDependencyError) as err:
            require(name, purpose="doing something")
        assert isinstance(err.value, GestureKitError)
        hint = f"pip install 'gesturekit[{extra}]'"
        assert str(err.value) == f"doing something needs {package}, which is not installed; install it with {hint}"
        assert optional(name) is None and not installed(name)
    monkeypatch.delitem(sys.modules, "torch.nn")  # as on an install without torch
    with pytest.raises(MissingDependencyError, match=r"a submodule needs torch, .*gesturekit\[refiner\]"):
        require("torch.nn", purpose="a submodule")


def test_only_declared_extras_are_optional():
    with pytest.raises(KeyError, match="not one of gesturekit's optional modules"):
        require("scipy", purpose="x")
    with pytest.raises(KeyError):
        optional("streamlit")  # the core never imports streamlit, not even optionally
    assert install_hint("pyvista") == "pip install 'gesturekit[render]'"
    assert install_hint("distributed") == "pip install 'gesturekit[scale]'"
    # each package is declared in pyproject.toml, in the extra the message names
    for package, extra in EXTRAS.values():
        assert Requirement(package).name in declared((extra,)), (package, extra)
        assert Requirement(package).name not in declared(), package  # and is not in the core


def test_a_dependency_of_the_optional_package_missing_names_its_own_extra(monkeypatch):
    """pyvista installed without vtk: the message names vtk; another failure inside an installed
    package is not dressed up as a missing extra."""

    def fake_import(name, package=None):
        if name == "pyvista":
            raise ModuleNotFoundError("No module named 'vtkmodules'", name="vtkmodules.vtkCommonCore")
        if name == "torch":
            raise ImportError("libtorch_cpu.so: cannot open shared object file", name="torch._C")
        if name == "plotly":
            raise ModuleNotFoundError("No module named 'tenacity'", name="tenacity")
        return types.ModuleType(name)

    monkeypatch.setattr(_optional.importlib, "import_module", fake_import)
    with pytest.raises(MissingDependencyError, match=r"needs vtk, .*gesturekit\[render\]"):
        require("pyvista", purpose="rendering")
    # torch._C failing is torch itself not importable: the refiner extra (re)installs it
    with pytest.raises(MissingDependencyError, match=r"gesturekit\[refiner\]"):
        require("torch", purpose="a refiner")
    with pytest.raises(ModuleNotFoundError, match="tenacity"):
        require("plotly", purpose="figures")
    with pytest.raises(ModuleNotFoundError, match="tenacity"):
        optional("plotly")


# ---- the command line without an extra ------------------------------------------------------------


def _video(b: Path, out: Path) -> list:
    return ["synthesize", b / "speech.wav", "--db", b / "db", "--refiner", "none", "--video", "--out", out]


CASES = [
    # (missing module, command, the extra the message names)
    (
        "torch",
        lambda b, out: ["synthesize", b / "speech.wav", "--db", b / "db", "--refiner", "demo", "--out", out],
        "refiner",
    ),
    ("pyvista", _video, "render"),
    ("imageio_ffmpeg", _video, "render"),
    ("torch", lambda b, out: ["train-refiner", "--db", b / "db", "--out", out], "refiner"),
    ("torch", lambda b, out: ["train-fgd", "--db", b / "db", "--out", out, "--steps", "2"], "refiner"),
    ("pyvista", lambda b, out: ["stimuli", "--db", b / "db", "--audio", b / "speech.wav", "--out", out], "render"),
    (
        "distributed",
        lambda b, out: [
            "stimuli",
            "--db",
            b / "db",
            "--audio",
            b / "speech.wav",
            "--out",
            out,
            "--scheduler",
            "tcp://127.0.0.1:9",
        ],
        "scale",
    ),
]


@pytest.mark.parametrize(
    "missing, command, extra", CASES, ids=[f"{c[0]}-{c[1](Path('b'), Path('o'))[0]}-{i}" for i, c in enumerate(CASES)]
)
def test_a_command_needing_a_missing_extra_says_what_to_install(base, tmp_path, monkeypatch, missing, command, extra):
    out = tmp_path / "out"
    before = snapshot(base / "db", base / "speech.wav", out)
    monkeypatch.setitem(sys.modules, missing, None)
    run = run_cli(*command(base, out))
    assert_refused(run, names=None, problem=f"pip install 'gesturekit[{extra}]'", before=before)
    assert f"needs {EXTRAS[missing][0]}, which is not installed" in run.stderr


@pytest.mark.slow
def test_a_core_only_install_synthesizes_and_refuses_the_refiner_clearly(base, tmp_path):
    """In a fresh interpreter where no optional package can be found (as if not installed; scipy
    looks into sys.modules for torch, so they are absent rather than None): the core modules import,
    synthesize writes npz and BVH without a refiner, and asks for the extra for one. (The child
    shares the test process's numba cache: cold, as when this test runs alone, it compiles the
    search and the audio features, about 25 s on 2 cores; warm, about 3 s.)"""
    blocked = sorted(EXTRAS) + ["streamlit", "pyarrow"]
    # the app (gesturekit.app, the `app` extra) is Streamlit's: not part of a core install
    core = sorted(
        m
        for m in map(module_name, PACKAGE.rglob("*.py"))
        if m not in _heavy_modules() and not m.startswith("gesturekit.app.")
    )
    script = textwrap.dedent(
        f"""
        import importlib, sys

        class Absent:
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in {blocked!r}:
                    raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)

        sys.meta_path.insert(0, Absent())
        for name in {core!r}:
            if name != "gesturekit.__main__":
                importlib.import_module(name)
        from gesturekit.cli import main
        out = {str(tmp_path / "out")!r}
        speech, db = {str(base / "speech.wav")!r}, {str(base / "db")!r}
        code = main(["synthesize", speech, "--db", db, "--out", out])
        assert code == 0, code
        sys.exit(main(["synthesize", speech, "--db", db, "--out", out + "2", "--refiner", "demo"]))
        """
    )
    run = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=patience(300), cwd=ROOT
    )
    assert run.returncode == 2, run.stderr
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["speech.bvh", "speech.npz"]
    assert "Traceback" not in run.stderr
    assert "gesturekit: error: a refiner needs torch, which is not installed; install it with pip install " in (
        run.stderr
    )
    assert not (tmp_path / "out2").exists()


@pytest.mark.parametrize("missing", ["pyvista", "imageio_ffmpeg"])
def test_the_apps_video_without_the_render_extra_is_a_message(monkeypatch, missing):
    """The app's MP4 (gesturekit.interactive.render_mp4): a GestureKitError the page shows as a message."""
    from gesturekit.interactive import render_mp4
    from gesturekit.motion import Motion
    from gesturekit.synthesis import SynthesisConfig, SynthesisResult

    motion = Motion(np.zeros((15, 55, 3), np.float32), 15)
    result = SynthesisResult(
        motion=motion,
        knn_motion=motion,
        search=None,  # not read when rendering
        audio=np.zeros(16000, np.float32),
        config=SynthesisConfig(),
        database="test",
        source="x.wav",
    )
    monkeypatch.setitem(sys.modules, missing, None)
    with pytest.raises(MissingDependencyError, match=r"needs .*pip install 'gesturekit\[render\]'"):
        render_mp4(result)


# ---- the rule, read from the source ---------------------------------------------------------------


def _top_level_targets(path: Path, body: list[ast.stmt]) -> set[str]:
    """The modules (gesturekit's, and optional ones by top-level name) the statements import."""
    me = module_name(path)
    package = me if path.name == "__init__.py" else me.rpartition(".")[0]
    out = set()
    for node in body:
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                source = ".".join(parts + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            for alias in node.names:
                sub = f"{source}.{alias.name}"
                out.add(sub if source.startswith("gesturekit") and is_module(sub) else source)
    return out


def _heavy_modules() -> dict[str, set[str]]:
    """gesturekit modules that import an optional package when imported (directly or through
    another such module): module -> the optional packages."""
    files = {module_name(p): p for p in PACKAGE.rglob("*.py")}
    targets = {m: _top_level_targets(p, ast.parse(p.read_text(encoding="utf-8")).body) for m, p in files.items()}
    heavy = {m: {t.split(".")[0] for t in ts} & set(EXTRAS) for m, ts in targets.items()}
    heavy = {m: h for m, h in heavy.items() if h}
    grew = True
    while grew:
        grew = False
        for m, ts in targets.items():
            found = set().union(*(heavy.get(t, set()) for t in ts))
            if not found <= heavy.get(m, set()):
                heavy[m] = heavy.get(m, set()) | found
                grew = True
    return heavy


def _required(func: ast.AST) -> set[str]:
    """Optional packages a function passes to require()."""
    names = set()
    for node in ast.walk(func):
        if (
            isinstance(node, ast.Call)
            and getattr(node.func, "id", getattr(node.func, "attr", None)) == "require"
            and node.args
            and isinstance(node.args[0], ast.Constant)
        ):
            names.add(str(node.args[0].value).split(".")[0])
    return names


@pytest.mark.slow
def test_optional_packages_are_imported_only_through_the_helper():
    """A function imports an optional package, or a module that imports one at its top, only after
    calling require() for that package; and only the leaves (refine's torch modules, viz) import
    one at their top, and the app's pages (the `app` extra, Streamlit's scripts)."""
    heavy = _heavy_modules()
    leaves = ("gesturekit.refine.", "gesturekit.viz.", "gesturekit.app.views.")
    assert set(heavy) <= {m for m in heavy if m.startswith(leaves)}, heavy
    assert "gesturekit.refine" not in heavy and "gesturekit.viz" not in heavy
    bad = []
    for path in sorted(PACKAGE.rglob("*.py")):
        me = module_name(path)
        if me.startswith("gesturekit.app."):  # the app's own modules: its extra is installed whole
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for func in ast.walk(tree):
            if not isinstance(func, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            inner = [n for n in ast.walk(func) if isinstance(n, (ast.Import, ast.ImportFrom))]
            targets = _top_level_targets(path, inner)
            needs = {t.split(".")[0] for t in targets} & set(EXTRAS)
            if me not in heavy:  # a leaf importing its peers needs nothing more
                needs |= set().union(*(heavy.get(t, set()) for t in targets))
            if needs - _required(func):
                bad.append(f"{me}.{func.name} imports {sorted(needs - _required(func))} without require()")
    assert not bad, "\n".join(bad)


def test_loaded_is_none_for_a_module_another_thread_is_still_importing(monkeypatch):
    half = types.ModuleType("half_imported")
    half.__spec__ = importlib.machinery.ModuleSpec("half_imported", None)
    half.__spec__._initializing = True  # as importlib marks a module while its body runs
    monkeypatch.setitem(sys.modules, "half_imported", half)
    assert _optional.loaded("half_imported") is None and _optional.loaded("not_imported_anywhere") is None
    half.__spec__._initializing = False
    assert _optional.loaded("half_imported") is half


# a thread imports torch (the app's refiner warm-up) while a search starts in another (the page's run)
_WHILE_TORCH_IMPORTS = """
import sys, threading
from gesturekit._optional import loaded, require
from gesturekit.search.threads import single_threaded_blas
assert "torch" not in sys.modules
warm = threading.Thread(target=require, args=("torch",), kwargs={"purpose": "a refiner"}, daemon=True)
warm.start()
seen = 0
while warm.is_alive():
    with single_threaded_blas():  # looked at torch half-imported: AttributeError (no get_num_threads yet)
        pass
    seen += "torch" in sys.modules and loaded("torch") is None
warm.join()
assert loaded("torch") is sys.modules["torch"] and loaded("torch").get_num_threads() >= 1
print("half-imported seen", seen)
"""


@pytest.mark.slow
def test_a_search_while_another_thread_imports_torch_leaves_the_half_imported_torch_alone():
    pytest.importorskip("torch")
    for _ in range(2):  # a fresh interpreter each time: torch is imported once per process
        run = subprocess.run(
            [sys.executable, "-c", _WHILE_TORCH_IMPORTS],
            capture_output=True,
            text=True,
            timeout=patience(300),
            cwd=ROOT,
        )
        assert run.returncode == 0, run.stderr[-3000:]
        assert int(run.stdout.split()[-1]) > 0  # the search did run while torch was half-imported


# the process ends while a daemon thread (the app's refiner warm-up) is importing torch: weakref's exit
# function unregisters torch's operators, which broke the import still running ("operator prims::... does
# not exist"); the import in flight must end first
_EXIT_DURING_TORCH_IMPORT = """
import sys, threading, time, weakref
from gesturekit._optional import require
def imported():
    torch = sys.modules.get("torch")
    return torch is not None and not torch.__spec__._initializing
class Marker:
    pass
marker = Marker()
# runs in weakref's exit function, where torch's own operator libraries are unregistered
weakref.finalize(marker, lambda: print("torch imported when finalizers ran:", imported(), flush=True))
threading.Thread(target=require, args=("torch",), kwargs={"purpose": "a refiner"}, daemon=True).start()
while "torch._prims" not in sys.modules:  # well inside torch's import
    time.sleep(0.001)
"""


@pytest.mark.slow
def test_the_process_ends_after_an_optional_import_in_flight():
    pytest.importorskip("torch")
    for _ in range(2):
        run = subprocess.run(
            [sys.executable, "-c", _EXIT_DURING_TORCH_IMPORT],
            capture_output=True,
            text=True,
            timeout=patience(300),
            cwd=ROOT,
        )
        assert run.returncode == 0, run.stderr[-3000:]
        assert run.stdout.strip() == "torch imported when finalizers ran: True", run.stdout + run.stderr[-3000:]
