"""The old import paths of moved modules and names, kept working for one release.

The command line, synthesis and the study became packages (``gesturekit.cli``,
``gesturekit.synthesis``, ``gesturekit.study``). An import by an old path gives the very module
object at the new path (imported once, so a class is the same class by either name) and warns
once, with a :class:`DeprecationWarning` naming the new path. Modules are aliased by an import
hook (:class:`ModuleAliases`, installed by ``gesturekit/__init__.py``); names a package took over
from the module it replaced are forwarded by that package's ``__getattr__`` (:func:`moved_names`).
The old paths go in the release after next.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from collections.abc import Callable, Collection, Sequence
from types import FrameType, ModuleType
from typing import Any

__all__ = ["MOVED_MODULES", "MOVED_PACKAGES", "ModuleAliases", "install", "moved_names", "new_name"]

# old module name -> new module name
MOVED_MODULES = {
    "gesturekit.synthesize": "gesturekit.synthesis",
    "gesturekit.synthesizer": "gesturekit.synthesis.synthesizer",
    "gesturekit.synthesis_config": "gesturekit.synthesis.config",
    "gesturekit.synthesis_types": "gesturekit.synthesis.types",
    "gesturekit.study_config": "gesturekit.study.config",
    "gesturekit._cli_character": "gesturekit.cli._character",
    "gesturekit._cli_options": "gesturekit.cli._options",
    "gesturekit._cli_parser": "gesturekit.cli._parser",
    "gesturekit._cli_study": "gesturekit.cli._study",
}
# old package -> new package: the package and every module under it
MOVED_PACKAGES = {"gesturekit.studies": "gesturekit.study"}


def new_name(old: str) -> str | None:
    """The new dotted name of a moved module, or None when ``old`` did not move."""
    if old in MOVED_MODULES:
        return MOVED_MODULES[old]
    for package, new in MOVED_PACKAGES.items():
        if old == package or old.startswith(package + "."):
            return new + old[len(package) :]
    return None


def _importer_level() -> int:
    """The ``stacklevel`` of the first frame outside this module and the import machinery."""
    level = 1
    frame: FrameType | None = sys._getframe(1)
    while frame is not None:
        name = frame.f_code.co_filename
        if not (name == __file__ or name == importlib.__file__ or _bootstrap(name)):
            break
        # warnings itself leaves out the import system's own frames when it counts
        level += 0 if _bootstrap(name) else 1
        frame = frame.f_back
    return level


def _bootstrap(filename: str) -> bool:
    return "importlib" in filename and "_bootstrap" in filename


def _warn(old: str, new: str) -> None:
    warnings.warn(
        f"{old} has moved to {new}; import it from there ({old} will be removed in the next release)",
        DeprecationWarning,
        stacklevel=_importer_level(),
    )


class ModuleAliases(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """An import hook: an old module name is the module at its new name (the same object)."""

    def find_spec(
        self, fullname: str, path: Sequence[str] | None = None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        return None if new_name(fullname) is None else importlib.machinery.ModuleSpec(fullname, self)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        new = new_name(spec.name)
        assert new is not None  # find_spec only answers for moved names
        _warn(spec.name, new)
        module = importlib.import_module(new)
        spec.loader_state = module.__spec__  # the import system sets the alias's spec on the module
        return module

    def exec_module(self, module: ModuleType) -> None:
        # already run under its new name: only give it back its own spec
        alias = module.__spec__
        if alias is not None and alias.loader is self:
            module.__spec__ = alias.loader_state


def install() -> None:
    """Put the aliases first on ``sys.meta_path`` (once): before the path finder, which would
    otherwise load an aliased package's modules a second time under the old name."""
    if not any(isinstance(finder, ModuleAliases) for finder in sys.meta_path):
        sys.meta_path.insert(0, ModuleAliases())


def moved_names(package: str, new: str, names: Collection[str]) -> Callable[[str], Any]:
    """A module ``__getattr__`` for ``package``: the ``names`` that moved to module ``new`` are
    read from there, with a warning the first time each is read."""
    namespace = sys.modules[package].__dict__

    def __getattr__(name: str) -> Any:
        if name not in names:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        _warn(f"{package}.{name}", f"{new}.{name}")
        value = getattr(importlib.import_module(new), name)
        namespace[name] = value  # read once: later reads find it without this function
        return value

    return __getattr__
