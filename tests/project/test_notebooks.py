"""The notebooks: stored without outputs, importing only gesturekit, and each runs top to bottom.

Each notebook is executed in a fresh Jupyter kernel (nbclient) on a small demo
database built once per test process in a temporary ``GESTUREKIT_HOME``; a
notebook's own cells assert what it shows (03 checks the control figures).
"""

from __future__ import annotations

import ast
import html
import time
from pathlib import Path

import pytest

from gesturekit.demo import open_default_database
from gesturekit.viz.viewer import read_viewer_data
from tests.waits import patience

NOTEBOOKS = Path(__file__).resolve().parents[2] / "notebooks"
NAMES = (
    "01_database.ipynb",
    "02_retrieval_walkthrough.ipynb",
    "03_control_figures.ipynb",
    "04_refiner.ipynb",
    "05_evaluation.ipynb",
)
#: Minutes of the demo speaker the notebooks run on here (the default demo has 20).
DEMO_MINUTES = 3.0
#: Notebooks that show motions on the app's character (gesturekit.viz.notebook.character_view): how many
#: motions side by side, and whether with their speech.
CHARACTER_VIEWS = {
    "01_database.ipynb": (1, True),
    "02_retrieval_walkthrough.ipynb": (3, False),
    "04_refiner.ipynb": (2, True),
}
#: Modules a notebook may import besides gesturekit (standard library only).
ALLOWED_IMPORTS = {"os", "pathlib"}


def _read(name: str):
    nbformat = pytest.importorskip("nbformat", reason="nbformat is in requirements-test.txt")
    return nbformat, nbformat.read(NOTEBOOKS / name, as_version=4)


def test_the_notebooks_folder_holds_the_five_notebooks():
    assert sorted(p.name for p in NOTEBOOKS.glob("*.ipynb")) == list(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_stored_without_outputs_and_importing_only_gesturekit(name):
    nbformat, nb = _read(name)
    nbformat.validate(nb)
    cells = [c for c in nb.cells if c.cell_type == "code"]
    assert cells and nb.cells[0].cell_type == "markdown"
    for c in cells:
        assert c.outputs == [] and c.execution_count is None, f"{name}: a cell was stored with its outputs"
        for node in ast.walk(ast.parse(c.source)):
            if isinstance(node, ast.Import):
                modules = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                modules = [node.module or ""]
            else:
                continue
            for m in modules:
                top = m.split(".")[0]
                assert top == "gesturekit" or top in ALLOWED_IMPORTS, f"{name} imports {m}"
    # one variable at the top points the notebook to another database
    first = ast.parse(cells[0].source)
    assigned = {
        t.id: n.value for n in first.body if isinstance(n, ast.Assign) for t in n.targets if isinstance(t, ast.Name)
    }
    assert isinstance(assigned.get("DATABASE"), ast.Constant) and assigned["DATABASE"].value is None


@pytest.fixture(scope="module")
def demo_home(tmp_path_factory):
    """A GESTUREKIT_HOME holding a small demo database (one per test process)."""
    home = tmp_path_factory.mktemp("gesturekit-home")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("GESTUREKIT_HOME", str(home))
        open_default_database(minutes=DEMO_MINUTES)
    return home


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_notebook_runs_top_to_bottom(name, demo_home, monkeypatch, capsys, tmp_path):
    pytest.importorskip("ipykernel", reason="ipykernel is in requirements-test.txt")
    nbclient = pytest.importorskip("nbclient", reason="nbclient is in requirements-test.txt")
    _, nb = _read(name)
    # the kernel inherits the environment: the notebooks open the demo database of this home
    monkeypatch.setenv("GESTUREKIT_HOME", str(demo_home))
    monkeypatch.setenv("GESTUREKIT_DEMO_MINUTES", str(DEMO_MINUTES))
    # and a numba cache of its own: compiled code cached by one process can crash another
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    client = nbclient.NotebookClient(
        nb, timeout=patience(600), kernel_name="python3", resources={"metadata": {"path": str(NOTEBOOKS)}}
    )
    t0 = time.perf_counter()
    client.execute()  # raises CellExecutionError, with the failing cell and its traceback
    seconds = time.perf_counter() - t0
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"]
    assert not errors
    text = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.outputs)
    assert f"demo (seed 0, {DEMO_MINUTES:g} min)" in text  # it ran on this home's database
    # the character viewer's page, whole, in each cell that shows one: three.js inlined, the motions and speech in it
    views = [
        html.unescape(o["data"]["text/html"].split('srcdoc="', 1)[1].split('" style=', 1)[0])
        for c in nb.cells
        if c.cell_type == "code"
        for o in c.outputs
        if "gesturekit character viewer" in o.get("data", {}).get("text/html", "")
    ]
    assert len(views) == (name in CHARACTER_VIEWS)
    for page in views:
        data = read_viewer_data(page)
        motions, speech = CHARACTER_VIEWS[name]
        assert len(data["motions"]) == motions and (data["audio"] is not None) == speech
        assert '<script type="module">' in page and 'src="http' not in page  # nothing fetched: the bundle is inlined
    with capsys.disabled():
        print(f"\n{name}: {seconds:.1f} s")
