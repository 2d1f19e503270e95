"""JSON forms of the configuration dataclasses: one way to write them and to read them back.

Every configuration of gesturekit is a frozen dataclass saved as JSON with what
it made (a synthesis, a refiner, a study). :func:`config_to_dict` writes one from
its fields; :func:`config_from_dict` reads it back, refusing unknown keys and
turning JSON lists back into the tuples (and nested configurations) the fields
hold. The classes' own ``__post_init__`` does the rest of the checking.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping
from typing import Any, ClassVar, TypeVar

from .errors import ConfigError

__all__ = ["JsonConfig", "config_to_dict", "config_from_dict"]

C = TypeVar("C")
J = TypeVar("J", bound="JsonConfig")


def _jsonable(value: Any) -> Any:
    """``value`` with tuples as lists, mapping keys as strings and nested configurations as dicts."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        to_dict = getattr(value, "to_dict", None)
        return to_dict() if to_dict is not None else config_to_dict(value)
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (tuple, list)):
        return [_jsonable(v) for v in value]
    return value


def _tuples(value: Any) -> Any:
    """JSON lists back to tuples, at every depth."""
    if isinstance(value, (list, tuple)):
        return tuple(_tuples(v) for v in value)
    return value


def config_to_dict(config: Any, *, exclude: Iterable[str] = ()) -> dict:
    """A JSON-able dict of a configuration dataclass's fields, in field order.

    Parameters
    ----------
    config : dataclass instance
    exclude : iterable of str
        Fields left out (e.g. a name that the file's own name already says).

    Returns
    -------
    dict
        Tuples become lists, mapping keys strings, nested configurations dicts.
    """
    skip = set(exclude)
    return {f.name: _jsonable(getattr(config, f.name)) for f in dataclasses.fields(config) if f.name not in skip}


def config_from_dict(cls: type[C], data: Mapping, *, what: str) -> C:
    """A configuration read back from :func:`config_to_dict`'s form.

    Parameters
    ----------
    cls : dataclass type
    data : Mapping
        The JSON form. Fields whose default is a tuple get tuples back (lists at any
        depth become tuples); fields whose default is a configuration dataclass are
        read with that class's ``from_dict``.
    what : str
        What the options are, for the error message (e.g. ``"model options"``).

    Returns
    -------
    cls instance

    Raises
    ------
    ConfigError
        ``data`` is not a mapping, or holds keys that are not fields of ``cls``.
    """
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    if not isinstance(data, Mapping):
        raise ConfigError(f"{what} must be a JSON object, got {type(data).__name__}")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = set(data) - set(fields)
    if unknown:
        raise ConfigError(f"unknown {what}: {', '.join(sorted(map(str, unknown)))}")
    kwargs = {}
    for name, value in data.items():
        f = fields[name]
        default = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
        if dataclasses.is_dataclass(default) and not isinstance(default, type) and isinstance(value, Mapping):
            # the nested class's own reader where it has one, as _jsonable uses its own writer
            from_dict = getattr(type(default), "from_dict", None)
            value = from_dict(value) if from_dict is not None else config_from_dict(type(default), value, what=what)
        elif isinstance(default, tuple):
            value = _tuples(value)
        kwargs[name] = value
    return cls(**kwargs)


class JsonConfig:
    """``to_dict`` and ``from_dict`` for a configuration dataclass whose JSON form is its fields.

    A subclass names its options for error messages in ``OPTIONS_NAME`` (e.g. ``"model options"``).
    """

    OPTIONS_NAME: ClassVar[str] = "options"

    def to_dict(self) -> dict:
        """A JSON-able dict of the fields; :meth:`from_dict` reads it back."""
        return config_to_dict(self)

    @classmethod
    def from_dict(cls: type[J], d: Mapping) -> J:
        """Inverse of :meth:`to_dict`; unknown options raise :class:`~gesturekit.errors.ConfigError`."""
        return config_from_dict(cls, d, what=cls.OPTIONS_NAME)
