"""Command-line options made from the configurations' field metadata, and configurations made from them.

An option declared with :func:`gesturekit._config.option` becomes ``--flag`` with the
field's default, type, choices and help (:func:`add_options`); after parsing,
:func:`options_given` checks each value against the field's bounds and returns the
keyword arguments of the configuration, so that the command line says no default,
range or choice list of its own.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from collections.abc import Iterable, Mapping
from typing import Any

from .._config import check_option, default_of, option_of

__all__ = ["add_options", "options_given", "flag_of", "FIELD_OF", "OPTIONS_DEST", "GIVEN_DEST"]

#: Set by :func:`add_options` on every action it adds: the (class, field) the option sets.
FIELD_OF = "gesturekit_field"
#: The parsed namespace's list of the (class, field) pairs its command's options set.
OPTIONS_DEST = "option_fields"
#: The parsed namespace's list of the (class, field) pairs whose options the user gave.
GIVEN_DEST = "option_fields_given"


class _FieldAction(argparse.Action):
    """Stores an option's value as argparse's own actions do, and notes that the user gave it.

    A switch (``nargs=0``) stores its ``const``; an appending option adds each value to a new list.
    The note is what lets a command tell an option left at the field's default from one given
    (``build-db --append``: left out means the database's).
    """

    def __init__(self, option_strings: list[str], dest: str, *, appends: bool = False, **kwargs: Any) -> None:
        self.appends = appends
        super().__init__(option_strings, dest, **kwargs)

    def __call__(
        self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any, option_string: Any = None
    ) -> None:
        if self.nargs == 0:
            value = self.const
        elif self.appends:
            value = [*(getattr(namespace, self.dest, None) or []), values]
        else:
            value = values
        setattr(namespace, self.dest, value)
        # a new list each time: the parser's defaults are shared between parses
        setattr(namespace, GIVEN_DEST, [*(getattr(namespace, GIVEN_DEST, None) or []), getattr(self, FIELD_OF)])


def flag_of(cls: type, name: str) -> str:
    """The command-line flag of the option ``name`` of ``cls`` (``--init-pose``, ``--k``)."""
    return option_of(cls, name).flag or "--" + name.replace("_", "-")


def _has_default(cls: type, name: str) -> bool:
    try:
        default_of(cls, name)
    except KeyError:
        return False
    return True


def _shown(value: Any) -> str:
    """A default as ``--help`` says it: ``8``, ``2``, ``640x480``, ``gt,knn``."""
    if isinstance(value, tuple) and all(isinstance(v, int) for v in value):
        return "x".join(map(str, value))
    if isinstance(value, tuple):
        return ",".join(map(str, value))
    return f"{value:g}" if isinstance(value, float) else str(value)


def _shown_values(value: tuple) -> str:
    """The default of an option that takes several values after its flag, as they are written: ``15 85``."""
    return " ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in value)


def add_options(
    parser: argparse.ArgumentParser, cls: type, names: Iterable[str], *, helps: Mapping[str, str] | None = None
) -> None:
    """Add the options ``names`` of the configuration class ``cls`` to ``parser``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
    cls : dataclass type
        Its fields ``names`` are declared with :func:`~gesturekit._config.option`.
    names : iterable of str
    helps : mapping of str -> str, optional
        A command's own wording of an option's help (e.g. what its seed seeds).
    """
    for name in names:
        opt = option_of(cls, name)
        required = not _has_default(cls, name)
        default = None if required else default_of(cls, name)
        text = (helps or {}).get(name, opt.help)
        shown = None if default in (None, "", ()) else _shown(default)
        if opt.choices is not None:
            kwargs: dict[str, Any] = {"choices": list(opt.choices)}
        elif isinstance(default, bool):  # a switch: its flag (--no-audio) gives the other value
            kwargs = {"nargs": 0, "const": not default}
            text = (helps or {}).get(name, opt.switch_help or opt.help)
            shown = None  # the flag's name says what it does
        elif opt.nargs or opt.append:  # a list of values: None when not given
            kwargs = {"nargs": opt.nargs} if opt.nargs else {"appends": True}
            kwargs["type"] = opt.kind or str
            if isinstance(default, tuple) and default:
                shown = _shown_values(default)
            default = None
        elif isinstance(default, tuple):  # written as text (640x480, a,b,c); the command reads it
            kwargs = {"type": str}
            default = _shown(default)
        else:
            kwargs = {"type": opt.kind or (type(default) if default is not None else str)}
        if opt.metavar:
            kwargs["metavar"] = opt.metavar
        if required:
            kwargs["required"] = True
        elif opt.default_help or shown is not None:
            text = f"{text} (default{':' if opt.default_help else ''} {opt.default_help or shown})"
        action = parser.add_argument(
            flag_of(cls, name), *opt.aliases, action=_FieldAction, dest=name, default=default, help=text, **kwargs
        )
        setattr(action, FIELD_OF, (cls, name))
        parser.set_defaults(**{OPTIONS_DEST: [*(parser.get_default(OPTIONS_DEST) or []), (cls, name)]})


def options_given(args: argparse.Namespace, *, only_given: bool = False) -> dict[type, dict[str, Any]]:
    """The values of the command's configuration options in ``args``, checked against their bounds.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed by a parser whose options were added with :func:`add_options`.
    only_given : bool
        Only the options the user gave (not those left at the field's default).

    Returns
    -------
    dict of class -> dict
        Per configuration class, field name -> value, for ``cls(**...)`` (or a configuration
        that passes them on); a class with no options in the command maps to ``{}``.

    Raises
    ------
    ConfigError
        A value out of its bounds, named by its flag (``--k must be an integer >= 0, got -1``).
    """
    out: dict[type, dict[str, Any]] = defaultdict(dict)
    given = getattr(args, GIVEN_DEST, None) or []
    for cls, name in getattr(args, OPTIONS_DEST, None) or ():
        if only_given and (cls, name) not in given:
            continue
        out[cls][name] = check_option(cls, name, getattr(args, name), what=flag_of(cls, name))
    return out
