"""The old import paths of the modules that moved into gesturekit.cli, .synthesis and .study.

Each old path imports for one release, warns once naming the new path, and gives the very same
module (no second copy: a class is the same class by either name).
"""

from __future__ import annotations

import importlib.machinery
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import gesturekit
import gesturekit.study
from gesturekit import _moved

ROOT = Path(__file__).resolve().parents[2]

OLD_MODULES = [
    ("gesturekit.synthesize", "gesturekit.synthesis"),
    ("gesturekit.synthesizer", "gesturekit.synthesis.synthesizer"),
    ("gesturekit.synthesis_config", "gesturekit.synthesis.config"),
    ("gesturekit.synthesis_types", "gesturekit.synthesis.types"),
    ("gesturekit.study_config", "gesturekit.study.config"),
    ("gesturekit.studies", "gesturekit.study"),
    ("gesturekit.studies.analyse", "gesturekit.study.analyse"),
    ("gesturekit.studies.design", "gesturekit.study.design"),
    ("gesturekit.studies.hemvip", "gesturekit.study.hemvip"),
    ("gesturekit.studies.media", "gesturekit.study.media"),
    ("gesturekit.studies.report", "gesturekit.study.report"),
    ("gesturekit.studies.server", "gesturekit.study.server"),
    ("gesturekit.studies.simulate", "gesturekit.study.simulate"),
    ("gesturekit.studies.store", "gesturekit.study.store"),
    ("gesturekit._cli_options", "gesturekit.cli._options"),
]
# what gesturekit.study gave when it was one module (now gesturekit.study.stimuli)
OLD_STUDY_NAMES = [
    "StimulusSpeech",
    "StudyResult",
    "stimulus_id",
    "balanced_latin_square",
    "plan_stimuli",
    "measure_loudness",
    "normalise_loudness",
    "speech_sources",
    "stimulus_style",
    "StudyConfig",
    "make_stimuli",
]


def _forget(monkeypatch, old: str) -> None:
    """Import ``old`` as if for the first time: drop the alias (never the module it names)."""
    for name in [n for n in sys.modules if n == old or n.startswith(old + ".")]:
        if _moved.new_name(name) is not None:
            monkeypatch.delitem(sys.modules, name)
    parent, _, child = old.rpartition(".")
    if parent in sys.modules and _moved.new_name(parent) is None:
        monkeypatch.delattr(sys.modules[parent], child, raising=False)


def _deprecations(caught) -> list[str]:
    return [str(w.message) for w in caught if issubclass(w.category, DeprecationWarning)]


@pytest.mark.parametrize("old, new", OLD_MODULES)
def test_an_old_module_path_is_the_new_module_and_warns_once(old, new, monkeypatch):
    module = importlib.import_module(new)
    _forget(monkeypatch, old)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        first = importlib.import_module(old)
        again = importlib.import_module(old)
    assert first is module and again is module
    said = _deprecations(caught)
    assert len(said) == 1 and f"{old} has moved to {new}" in said[0], said
    # the module keeps its own name and spec: it was not run a second time under the old name
    assert module.__name__ == new and module.__spec__.name == new
    assert sys.modules[new] is module


def test_a_warning_points_at_the_importing_line(monkeypatch):
    _forget(monkeypatch, "gesturekit.synthesizer")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        import gesturekit.synthesizer  # noqa: F401
    assert [Path(w.filename).name for w in caught if issubclass(w.category, DeprecationWarning)] == [
        Path(__file__).name
    ]


def test_classes_are_the_same_by_either_path(monkeypatch):
    for old, _ in OLD_MODULES:
        _forget(monkeypatch, old)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from gesturekit.studies.design import StudyDesign as OldDesign
        from gesturekit.synthesis_config import SynthesisConfig as OldConfig
        from gesturekit.synthesis_types import SynthesisResult as OldResult
        from gesturekit.synthesize import SynthesisConfig, synthesize
        from gesturekit.synthesizer import Synthesizer as OldSynthesizer
    from gesturekit.study.design import StudyDesign
    from gesturekit.synthesis import SynthesisResult
    from gesturekit.synthesis.config import SynthesisConfig as NewConfig
    from gesturekit.synthesis.synthesizer import Synthesizer

    assert OldSynthesizer is Synthesizer is gesturekit.Synthesizer
    assert OldConfig is SynthesisConfig is NewConfig
    assert OldResult is SynthesisResult and OldDesign is StudyDesign
    # the package took the old module's name: its function keeps the function's
    assert callable(synthesize) and synthesize is gesturekit.synthesis.synthesize
    assert not isinstance(synthesize, type(gesturekit))


@pytest.mark.parametrize("name", OLD_STUDY_NAMES)
def test_a_name_of_the_old_study_module_is_read_from_stimuli_and_warns_once(name, monkeypatch):
    from gesturekit.study import stimuli

    monkeypatch.delitem(vars(gesturekit.study), name, raising=False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        first = getattr(gesturekit.study, name)
        again = getattr(gesturekit.study, name)
    assert first is getattr(stimuli, name) and again is first
    said = _deprecations(caught)
    assert said == [
        f"gesturekit.study.{name} has moved to gesturekit.study.stimuli.{name}; import it from there "
        f"(gesturekit.study.{name} will be removed in the next release)"
    ]


def test_a_name_the_study_never_had_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        gesturekit.study.no_such_name  # noqa: B018
    with pytest.raises(ImportError):
        from gesturekit.study import no_such_name  # noqa: F401


def test_no_file_is_left_at_an_old_path():
    """A file at an old path would be imported instead of the alias (and be a second copy)."""
    old = [o for o, _ in OLD_MODULES] + list(_moved.MOVED_MODULES) + list(_moved.MOVED_PACKAGES)
    for name in old:
        path = ROOT.joinpath(*name.split("."))
        assert not path.with_suffix(".py").exists() and not path.is_dir(), path
    assert not (ROOT / "gesturekit" / "cli.py").exists() and not (ROOT / "gesturekit" / "study.py").exists()


def test_the_alias_hook_is_first_and_installed_once():
    gesturekit._moved.install()
    aliases = [f for f in sys.meta_path if isinstance(f, _moved.ModuleAliases)]
    # other hooks (VTK's) may put themselves first later; what counts is being ahead of the path finder
    path_finder = next(i for i, f in enumerate(sys.meta_path) if f is importlib.machinery.PathFinder)
    assert len(aliases) == 1 and sys.meta_path.index(aliases[0]) < path_finder
    assert _moved.new_name("gesturekit.study") is None and _moved.new_name("gesturekit.studiesx") is None
    assert _moved.new_name("gesturekit.studies.server") == "gesturekit.study.server"


@pytest.mark.slow
def test_the_package_itself_uses_no_old_path():
    """Importing every package and the command line in a fresh interpreter warns of nothing moved."""
    code = (
        "import gesturekit, gesturekit.cli, gesturekit.synthesis, gesturekit.study.stimuli, "
        "gesturekit.study.server, gesturekit.study.report, gesturekit.cli._study, gesturekit.live, "
        "gesturekit.interactive\n"
        "import sys; sys.argv = ['gesturekit', '--help']\n"
        "import runpy; runpy.run_module('gesturekit', run_name='__main__')\n"
    )
    done = subprocess.run(
        [sys.executable, "-W", "error::DeprecationWarning:gesturekit", "-c", code],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    assert "usage: gesturekit" in done.stdout
    assert "has moved to" not in done.stderr
