"""Configuration dataclasses: their options' metadata, and their JSON forms.

Every option a user sets is a field of a frozen configuration dataclass declared with
:func:`option`, whose metadata (help, bounds, choices, unit) is the one source the
command line's options (:mod:`gesturekit.cli._options`) and the app's widget limits
(:func:`widget_limits`) are made from::

    @dataclass(frozen=True)
    class Example:
        k: int = option(0, help="take the k-th best candidate", low=0)

    options_of(Example)["k"].low  # 0

Every configuration of gesturekit is a frozen dataclass saved as JSON with what
it made (a synthesis, a refiner, a study). :func:`config_to_dict` writes one from
its fields; :func:`config_from_dict` reads it back, refusing unknown keys and
turning JSON lists back into the tuples (and nested configurations) the fields
hold. The classes' own ``__post_init__`` does the rest of the checking.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Callable, Iterable, Mapping
from typing import Any, ClassVar, TypeVar

from ._arguments import checks_arguments
from .errors import ConfigError

__all__ = [
    "JsonConfig",
    "config_to_dict",
    "config_from_dict",
    "Option",
    "option",
    "options_of",
    "option_of",
    "default_of",
    "check_option",
    "widget_limits",
    "options_config",
]

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


_KEY = "gesturekit.option"


@dataclasses.dataclass(frozen=True)
class Option:
    """What a user is told about one option of a configuration, and what it may be.

    Parameters
    ----------
    help : str
        One line, as the command line's ``--help`` says it (without the default).
    low, high : float, optional
        Inclusive bounds of a number (None: unbounded on that side).
    choices : tuple, optional
        The values a choice may take.
    unit : str, optional
        The number's unit, e.g. ``"Hz"``, ``"s"``, ``"frames"``.
    kind : type, optional
        ``int``, ``float`` or ``str``: how the command line reads the value (default: the default's type).
    flag : str, optional
        The command-line flag (default ``--`` and the field's name with dashes).
    aliases : tuple of str
        Earlier names of the flag, still read.
    metavar : str or tuple of str, optional
        The value's name in ``--help`` (one name per value where ``nargs`` is a number).
    step : float, optional
        The app's widget step (default 1 for integers).
    limit : callable(context) -> float, optional
        A tighter upper bound that depends on the data (e.g. a database's clip length),
        applied by :func:`widget_limits` when it is given a context.
    low_open : bool
        ``low`` itself is refused (a positive number: ``low=0, low_open=True``).
    default_help : str, optional
        How ``--help`` says the default where its value does not (``"all cores"`` for None).
    nargs : str or int, optional
        The command line takes several values after the flag (``"+"``, or exactly 2).
    append : bool
        The command line's flag may be given again, each time adding a value.
    start : optional
        Where the app's widget starts, where that is not the default (the study page's systems:
        those that need no held-out part or refiner); :func:`widget_limits` says it as ``start``.
    switch_help : str, optional
        What the command line's flag of a switch says, where it gives the other value than the
        field's default (``--no-audio``: "do not keep ...", for ``store_audio``'s "keep ...").
    """

    help: str
    low: float | None = None
    high: float | None = None
    choices: tuple | None = None
    unit: str | None = None
    kind: type | None = None
    flag: str | None = None
    aliases: tuple[str, ...] = ()
    metavar: str | tuple[str, ...] | None = None
    step: float | None = None
    limit: Callable[[Any], float] | None = None
    low_open: bool = False
    default_help: str | None = None
    nargs: str | int | None = None
    append: bool = False
    start: Any = None
    switch_help: str | None = None

    def bounds_text(self, integer: bool) -> str:
        """``"an integer >= 0"``, ``"a number from 0 to 7.5"``: what a value must be, for messages."""
        what = "an integer" if integer else "a number"
        if self.low is not None and self.high is not None:
            return f"{what} from {self.low:g} to {self.high:g}"
        if self.low == 0 and self.low_open:
            return f"a positive {what.split()[-1]}"
        if self.low is not None:
            return f"{what} {'>' if self.low_open else '>='} {self.low:g}"
        if self.high is not None:
            return f"{what} <= {self.high:g}"
        return f"a finite {what.split()[-1]}"


@checks_arguments
def option(
    default: Any = dataclasses.MISSING,
    *,
    help: str,
    default_factory: Callable[[], Any] | Any = dataclasses.MISSING,
    compare: bool = True,
    hash: bool | None = None,
    **metadata: Any,
) -> Any:
    """A dataclass field that is a user's option, with its :class:`Option` metadata.

    Parameters
    ----------
    default, default_factory
        As :func:`dataclasses.field`'s.
    help : str
    compare, hash
        As :func:`dataclasses.field`'s.
    **metadata
        The other fields of :class:`Option` (``low``, ``high``, ``choices``, ``unit``, ...).

    Returns
    -------
    dataclasses.Field
    """
    meta = {_KEY: Option(help=help, **metadata)}
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory, compare=compare, hash=hash, metadata=meta)
    return dataclasses.field(default=default, compare=compare, hash=hash, metadata=meta)


@checks_arguments
def options_of(cls: type) -> dict[str, Option]:
    """The options of a configuration class, field name -> :class:`Option`, in field order.

    Parameters
    ----------
    cls : dataclass type

    Returns
    -------
    dict of str -> Option
        Fields declared without :func:`option` are left out.
    """
    return {f.name: f.metadata[_KEY] for f in dataclasses.fields(cls) if _KEY in f.metadata}


@checks_arguments
def option_of(cls: type, name: str) -> Option:
    """The :class:`Option` of the field ``name`` of ``cls``; KeyError if it is no option."""
    return options_of(cls)[name]


@checks_arguments
def default_of(cls: type, name: str) -> Any:
    """The default value of the field ``name`` of ``cls`` (its factory's value where it has one)."""
    for f in dataclasses.fields(cls):
        if f.name == name:
            if f.default_factory is not dataclasses.MISSING:
                return f.default_factory()
            if f.default is dataclasses.MISSING:
                raise KeyError(f"{cls.__name__}.{name} has no default")
            return f.default
    raise KeyError(f"{cls.__name__} has no field {name!r}")


def _integer(cls: type, name: str, opt: Option) -> bool:
    kind = opt.kind
    if kind is None:
        default = default_of(cls, name)
        kind = type(default) if default is not None else float
    return kind is int


@checks_arguments
def check_option(cls: type, name: str, value: Any, *, what: str | None = None) -> Any:
    """``value`` checked against the option's metadata: its choices, or its type and bounds.

    Parameters
    ----------
    cls : dataclass type
    name : str
        A field declared with :func:`option`.
    value
        None passes (an option not given).
    what : str, optional
        How the message names the option (default ``"Class.name"``; the command line: its flag).

    Returns
    -------
    The value, integers as ``int`` and numbers as ``float``.

    Raises
    ------
    ConfigError
        ``"--k must be an integer >= 0, got -1"``.
    """
    opt = option_of(cls, name)
    label = what or f"{cls.__name__}.{name}"
    if value is None:
        return value
    if opt.choices is not None:
        if value not in opt.choices:
            raise ConfigError(f"{label} must be one of {', '.join(map(str, opt.choices))}, got {value!r}")
        return value
    try:
        default = default_of(cls, name)
    except KeyError:  # a required option
        default = None
    if isinstance(default, bool):  # a switch
        if not isinstance(value, bool):
            raise ConfigError(f"{label} must be True or False, got {value!r}")
        return value
    if opt.kind is str or isinstance(default, str):
        return value  # text is checked by the class itself
    if isinstance(default, tuple):
        if opt.nargs is None or (opt.low is None and opt.high is None):
            return value  # text and tuples are checked by the class itself
        # numbers given one by one after the flag (--percentiles 15 85): each within the bounds
        return tuple(_checked_number(cls, name, opt, v, label) for v in value)
    return _checked_number(cls, name, opt, value, label)


def _checked_number(cls: type, name: str, opt: Option, value: Any, label: str) -> Any:
    """``value`` as an ``int`` or ``float`` within the option's bounds, else ConfigError naming ``label``."""
    integer = _integer(cls, name, opt)
    ok = not isinstance(value, bool) and isinstance(value, numbers.Integral if integer else numbers.Real)
    if ok:
        above = opt.low is None or value > opt.low or (value == opt.low and not opt.low_open)
        ok = math.isfinite(value) and above and (opt.high is None or value <= opt.high)
    if not ok:
        raise ConfigError(f"{label} must be {opt.bounds_text(integer)}, got {value!r}")
    return int(value) if integer else float(value)


@checks_arguments
def widget_limits(cls: type, name: str, *, context: Any = None) -> dict[str, Any]:
    """What an input widget for the option ``name`` of ``cls`` allows, as plain values.

    Parameters
    ----------
    cls : dataclass type
    name : str
    context : optional
        What the option's data-dependent ``limit`` reads (e.g. the database searched); without
        it that limit is not applied.

    Returns
    -------
    dict
        ``min``, ``max`` (None: unbounded), ``step`` (None for choices), ``default``, ``start``
        (where the widget starts: the option's ``start``, else ``default``), ``choices`` (a list, or
        None), ``help`` and ``unit``.

    Examples
    --------
    What the app's input of N allows, and the same for a database of 32-frame clips:

    >>> from gesturekit.options import widget_limits
    >>> from gesturekit.search import SearchConfig
    >>> limits = widget_limits(SearchConfig, "segment")
    >>> limits["min"], limits["max"], limits["default"], limits["help"]
    (1, None, 8, 'frames per search step, N')
    >>> from types import SimpleNamespace
    >>> widget_limits(SearchConfig, "segment", context=SimpleNamespace(clip_frames=32))["max"]
    32
    """
    opt = option_of(cls, name)
    high = opt.high
    if context is not None and opt.limit is not None:
        tighter = opt.limit(context)
        high = tighter if high is None else min(high, tighter)
    integer = opt.choices is None and _integer(cls, name, opt)
    step = None if opt.choices is not None else (opt.step if opt.step is not None else (1 if integer else 0.1))

    def number(x: float | None) -> float | int | None:
        if x is None:
            return None
        return int(x) if integer else float(x)

    return {
        "min": number(opt.low),
        "max": number(high),
        "step": step,
        "default": default_of(cls, name),
        "start": default_of(cls, name) if opt.start is None else opt.start,
        "choices": None if opt.choices is None else list(opt.choices),
        "help": opt.help,
        "unit": opt.unit,
    }


@checks_arguments
def options_config(cls: type[C], config: C | None, options: Mapping[str, Any]) -> C:
    """``config`` (or the defaults of ``cls``) with the fields ``options`` replaced.

    For functions that take a configuration and, for convenience, its fields as keywords.

    Parameters
    ----------
    cls : dataclass type
    config : cls instance, optional
    options : mapping of str -> value
        Fields of ``cls``.

    Returns
    -------
    cls instance

    Raises
    ------
    ConfigError
        An option that is no field of ``cls``, or a field without default that is not given.
    """
    names = {f.name for f in dataclasses.fields(cls) if f.init}  # type: ignore[arg-type]
    unknown = set(options) - names
    if unknown:
        raise ConfigError(f"unknown {cls.__name__} options: {', '.join(sorted(unknown))}")
    if config is not None:
        return dataclasses.replace(config, **options)  # type: ignore[type-var]
    try:
        return cls(**options)
    except TypeError as exc:  # a field without default, not given
        raise ConfigError(f"{cls.__name__}: {exc}") from None
