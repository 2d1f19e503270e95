"""Arguments of the public API checked before the work: ``None`` where a value is needed, text where an array is.

A public function given ``None`` for a path, an array or a character, or a ``str`` where it takes an array, would
otherwise fail deep inside with a bare ``TypeError`` or ``AttributeError``. :func:`checks_arguments` reads the
function's annotations once and, on each call, raises :class:`~gesturekit.errors.ConfigError` naming the function and
the argument: ``None`` where the annotation does not allow it (no ``None``, ``Optional``, ``Any`` or ``object`` in its
union), a ``str`` where it names an array (``np.ndarray``, ``ArrayLike``) and no text or path.
"""

from __future__ import annotations

import functools
import inspect
import re
from collections.abc import Callable
from typing import Any, TypeVar

from .errors import ConfigError

__all__ = ["checks_arguments"]

F = TypeVar("F", bound=Callable[..., Any])

_NONE_OK = re.compile(r"\b(None|Optional|Any|object)\b")
_ARRAY = re.compile(r"\b(ndarray|ArrayLike|NDArray)\b")
_PATH = re.compile(r"\b(PathLike|Path)\b")
_TEXT_OK = re.compile(r"\b(str|PathLike|Path|Any|object|Speech)\b")


def _text(annotation: object) -> str:
    return annotation if isinstance(annotation, str) else inspect.formatannotation(annotation)


def _top(text: str) -> str:
    """An annotation without what its brackets hold: ``Mapping[str, Any] | None`` -> ``Mapping | None``."""
    while True:
        inner = re.sub(r"\[[^\[\]]*\]", "", text)
        if inner == text:
            return text
        text = inner


def checks_arguments(func: F) -> F:
    """``func`` with its arguments checked on each call (see the module's text); its signature and docs kept.

    Raises
    ------
    ConfigError
        On a call with ``None`` for an argument whose annotation does not allow it, or a ``str`` for an array.
    """
    checks: list[tuple[int | None, str, bool, bool, str]] = []
    for i, p in enumerate(inspect.signature(func).parameters.values()):
        if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD) or p.annotation is p.empty:
            continue
        text = _text(p.annotation)
        top = _top(text)
        none_ok = bool(_NONE_OK.search(top)) or p.default is None
        array_only = bool(_ARRAY.search(top)) and not _TEXT_OK.search(top)
        if none_ok and not array_only:
            continue
        position = i if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) else None
        checks.append((position, p.name, none_ok, array_only, text))
    name = func.__qualname__

    @functools.wraps(func)
    def checked(*args: Any, **kwargs: Any) -> Any:
        for position, arg, none_ok, array_only, text in checks:
            if position is not None and position < len(args):
                value = args[position]
            elif arg in kwargs:
                value = kwargs[arg]
            else:
                continue
            if value is None and not none_ok:
                what = f"a file name or path ({text})" if _PATH.search(text) else text
                raise ConfigError(f"{name}: the argument {arg} is None; it takes {what}")
            if array_only and isinstance(value, str):
                raise ConfigError(f"{name}: the argument {arg} is the text {value[:40]!r}; it takes {text}")
        return func(*args, **kwargs)

    checked.__gesturekit_checked__ = True  # type: ignore[attr-defined]
    return checked  # type: ignore[return-value]
