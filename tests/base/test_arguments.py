"""Every public function given ``None`` for a value it needs, or text for an array, raises our error naming the
argument, never a bare ``TypeError`` (issue 38).

The functions are found, not listed: every plain function in the ``__all__`` of gesturekit and of each public module
under it (the app and the command line aside: they are no Python API). So a new public function is checked as soon
as it is exported; one that does not check its arguments (:func:`gesturekit._arguments.checks_arguments`) fails here.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import numpy as np
import pytest

import gesturekit
from gesturekit._arguments import checks_arguments
from gesturekit.errors import ConfigError, GestureKitError

#: Modules whose functions do not check their arguments yet: the drawing of a user's character, being reworked for
#: its own materials and textures.
NOT_YET = frozenset(
    {
        "gesturekit.character.paint",
        "gesturekit.viz.character_page",
        "gesturekit.viz.character_render",
        "gesturekit.viz.character_user",
    }
)
#: Functions whose arguments are all optional or free (``warn`` takes any message), or of a module that runs as a
#: script by its path (``python gesturekit/viz/web/build.py``), outside the package's imports.
FREE = frozenset({"gesturekit.errors.warn"})
SCRIPTS = frozenset({"gesturekit.viz.web.build"})


def public_functions() -> dict[str, object]:
    """``module.name`` -> function, for every function exported by gesturekit and its public modules."""
    modules = [gesturekit]
    for info in pkgutil.walk_packages(gesturekit.__path__, "gesturekit."):
        parts = info.name.split(".")
        if any(p.startswith("_") for p in parts[1:]) or parts[1] in ("app", "cli"):
            continue
        modules.append(importlib.import_module(info.name))
    out = {}
    for module in modules:
        for name in getattr(module, "__all__", ()):
            f = getattr(module, name, None)
            if inspect.isfunction(f) and not name.startswith("_"):
                out.setdefault(f"{f.__module__}.{f.__name__}", f)
    return out


FUNCTIONS = public_functions()


def _required(f) -> list[inspect.Parameter]:
    return [
        p
        for p in inspect.signature(f).parameters.values()
        if p.default is p.empty and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD) and p.annotation is not p.empty
    ]


def _call(f, p: inspect.Parameter, value):
    return f(value) if p.kind == p.POSITIONAL_ONLY else f(**{p.name: value})


def _checked(name: str) -> bool:
    module = name.rsplit(".", 1)[0]
    return module not in NOT_YET and module not in SCRIPTS and name not in FREE


def test_the_public_api_is_found_whole():
    assert len(FUNCTIONS) > 400
    for name in ("gesturekit.control.parse_control", "gesturekit.character.user.read_character"):
        assert name in FUNCTIONS
    assert "gesturekit.export.result.export_result_character_glb" in FUNCTIONS


@pytest.mark.parametrize("name", sorted(n for n in FUNCTIONS if _checked(n)))
def test_none_where_a_value_is_needed_is_our_error_naming_the_argument(name):
    f = FUNCTIONS[name]
    sig = inspect.signature(f)
    for p in _required(f):
        if not checks_needs_value(sig, p):
            continue
        with pytest.raises(GestureKitError, match=rf"\b{p.name}\b"):
            _call(f, p, None)


@pytest.mark.parametrize("name", sorted(n for n in FUNCTIONS if _checked(n)))
def test_text_where_an_array_is_expected_is_our_error_naming_the_argument(name):
    from gesturekit._arguments import _ARRAY, _TEXT_OK, _text, _top

    f = FUNCTIONS[name]
    for p in inspect.signature(f).parameters.values():
        if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD) or p.annotation is p.empty:
            continue
        top = _top(_text(p.annotation))
        if _ARRAY.search(top) and not _TEXT_OK.search(top):
            with pytest.raises(GestureKitError, match=rf"\b{p.name}\b"):
                _call(f, p, "motion.npz")


def checks_needs_value(sig: inspect.Signature, p: inspect.Parameter) -> bool:
    """Whether ``p``'s annotation says it needs a value (``None`` not among its types)."""
    from gesturekit._arguments import _NONE_OK, _text, _top

    return not _NONE_OK.search(_top(_text(p.annotation)))


def test_the_checks_do_not_change_what_a_function_does_with_good_arguments():
    @checks_arguments
    def scaled(x: np.ndarray, *, by: float, name: str | None = None) -> np.ndarray:
        """Doubled."""
        return x * by

    assert scaled(np.ones(2), by=2.0).tolist() == [2.0, 2.0]
    assert scaled.__doc__ == "Doubled." and "by" in str(inspect.signature(scaled))
    with pytest.raises(ConfigError, match="scaled: the argument by is None"):
        scaled(np.ones(2), by=None)
    with pytest.raises(ConfigError, match="the argument x is the text 'a.npy'"):
        scaled("a.npy", by=1.0)
    assert scaled(np.ones(1), by=1.0, name=None).tolist() == [1.0]  # None where the annotation allows it


def test_a_checked_function_still_pickles_by_name():
    import pickle

    from gesturekit.skeleton import joint_index

    assert pickle.loads(pickle.dumps(joint_index)) is joint_index
