"""Optional dependencies: every import of one goes through here.

gesturekit's core (database, search, synthesis, npz and BVH export) needs only
the packages of ``pip install gesturekit``; the refiner, video rendering,
evaluation on a cluster and the app need the extras of ``pyproject.toml``.
:func:`require` imports an optional module or raises a
:class:`~gesturekit.errors.MissingDependencyError` that names the feature, the
package and the command that installs it, so the command line and the app show
a message instead of a traceback. :func:`optional` is for the few places that
work without the module (faster or with more formats with it).

A gesturekit module that imports an optional package at its top (``refine.model``,
``viz.render``, ...) is itself imported by the rest of the package only after
:func:`require` of that package.
"""

from __future__ import annotations

import atexit
import importlib
import importlib.util
import sys
import threading
import weakref
from types import ModuleType

from .errors import MissingDependencyError

__all__ = ["EXTRAS", "require", "optional", "loaded", "installed", "install_hint"]

#: Optional top-level module -> (the package that provides it, the extra of gesturekit that installs it).
EXTRAS: dict[str, tuple[str, str]] = {
    "torch": ("torch", "refiner"),
    "pyvista": ("pyvista", "render"),
    "vtk": ("vtk", "render"),
    "imageio_ffmpeg": ("imageio-ffmpeg", "render"),
    "distributed": ("dask[distributed]", "scale"),
    "dask": ("dask[distributed]", "scale"),
    "plotly": ("plotly", "app"),
    "choix": ("choix", "study"),
}


#: Held while an optional module is imported: the app imports torch in a background thread, and
#: other threads must not see it half-imported (see :func:`loaded`) nor the process end under it.
_IMPORTING = threading.RLock()


def _finish_imports() -> None:
    # at exit, weakref's finalizers unregister torch's operator libraries; a torch import still
    # running in a daemon thread then fails ("operator prims::... does not exist") or aborts the process
    _IMPORTING.acquire(timeout=120)


# atexit runs its functions last registered first: weakref's own exit function (registered by its
# first finalizer) must come before ours, so that ours waits before the finalizers run
weakref.finalize(_finish_imports, lambda: None)
atexit.register(_finish_imports)


def _import(name: str) -> ModuleType:
    with _IMPORTING:
        return importlib.import_module(name)


def loaded(name: str) -> ModuleType | None:
    """The module ``name`` if it is imported completely, else None (not imported, or being imported
    by another thread: its attributes are not all there yet). Imports nothing."""
    module = sys.modules.get(name)
    if module is None or getattr(getattr(module, "__spec__", None), "_initializing", False):
        return None
    return module


def install_hint(name: str) -> str:
    """``"pip install 'gesturekit[refiner]'"``: what installs the optional module ``name``."""
    top = name.split(".")[0]
    if top not in EXTRAS:
        raise KeyError(f"{name!r} is not one of gesturekit's optional modules ({', '.join(EXTRAS)})")
    return f"pip install 'gesturekit[{EXTRAS[top][1]}]'"


def _missing(name: str, exc: ImportError) -> str | None:
    """The optional module (a key of :data:`EXTRAS`) that ``exc`` says is not installed, when
    importing ``name`` failed for that reason (``pyvista`` without ``vtk`` names ``vtk``); None
    when an installed module failed in another way."""
    top = (exc.name or "").split(".")[0]
    if top == name.split(".")[0] or top in EXTRAS:
        return top
    if top == "vtkmodules":  # vtk's compiled modules
        return "vtk"
    return None


def installed(name: str) -> bool:
    """Whether the optional module ``name`` (a key of :data:`EXTRAS`) can be imported, without importing it."""
    install_hint(name)
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):
        return False


def require(name: str, *, purpose: str) -> ModuleType:
    """Import the optional module ``name`` (a key of :data:`EXTRAS`, or a submodule of one).

    Parameters
    ----------
    name : str
        E.g. ``"torch"`` or ``"torch.nn"``.
    purpose : str
        What needs it, as the message says it: ``"the refiner"``, ``"rendering a video"``.

    Returns
    -------
    module
        The imported module.

    Raises
    ------
    MissingDependencyError
        The module is not installed; the message names ``purpose``, the package and
        ``pip install 'gesturekit[EXTRA]'``.
    """
    install_hint(name)
    try:
        return _import(name)
    except ImportError as exc:
        missing = _missing(name, exc)
        if missing is None:
            raise
        package = EXTRAS[missing][0]
        raise MissingDependencyError(
            f"{purpose} needs {package}, which is not installed; install it with {install_hint(missing)}"
        ) from None


def optional(name: str) -> ModuleType | None:
    """The optional module ``name`` (a key of :data:`EXTRAS`), or None when it is not installed."""
    install_hint(name)  # only the modules of the table: each one stays declared in an extra
    try:
        return _import(name)
    except ImportError as exc:
        if _missing(name, exc) is None:
            raise
        return None
