"""The one exception family of gesturekit, and its warning category.

Every error a user can cause (a bad file, an impossible setting) is raised as a
subclass of :class:`GestureKitError` with a message that names the file (when
there is one) and the problem, so the command line and the app can show it as
a plain message instead of a traceback.
"""

from __future__ import annotations

import contextlib
import os
import threading
import warnings
from collections.abc import Iterator
from types import FrameType

__all__ = [
    "GestureKitError",
    "InputFileError",
    "AudioFileError",
    "MotionFileError",
    "DatabaseError",
    "ConfigError",
    "OutputError",
    "MissingDependencyError",
    "GestureKitWarning",
    "warn",
    "collect_warnings",
]


class GestureKitError(Exception):
    """Base class of every error gesturekit raises on purpose.

    Parameters
    ----------
    message : str
        What is wrong, in words a user can act on.
    path : str or os.PathLike, optional
        The file concerned; it is put in front of the message.
    """

    def __init__(self, message: str, *, path: str | os.PathLike | None = None):
        self.path = None if path is None else os.fspath(path)
        self.problem = message
        super().__init__(f"{self.path}: {message}" if self.path is not None else message)


class InputFileError(GestureKitError):
    """An input file cannot be read or holds data we cannot use."""


class AudioFileError(InputFileError):
    """An audio file is missing, empty, not audio, truncated or too short."""


class MotionFileError(InputFileError):
    """A motion file (BVH, joint positions, npz) is malformed or incomplete."""


class DatabaseError(GestureKitError):
    """A matching database is missing, of another format version, or would be overwritten."""


class ConfigError(GestureKitError):
    """A parameter or combination of parameters is invalid."""


class OutputError(ConfigError):
    """An output cannot be written where asked: something else is there, another writer, or the write failed."""


class MissingDependencyError(GestureKitError):
    """A feature needs an optional package that is not installed; the message says which extra installs it."""


class GestureKitWarning(UserWarning):
    """Something was adjusted (trimmed, relaxed, resampled) and the user should know."""


_collecting = threading.local()


def warn(message: str, *, stacklevel: int = 1) -> None:
    """Issue a :class:`GestureKitWarning`, or collect it inside :func:`collect_warnings`.

    Parameters
    ----------
    message : str
    stacklevel : int
        As :func:`warnings.warn`, counted from the caller of this function.
    """
    stack = getattr(_collecting, "stack", None)
    if stack:
        stack[-1].append(message)
    else:
        warnings.warn(GestureKitWarning(message), stacklevel=_past_checks(stacklevel + 1))


def _past_checks(stacklevel: int) -> int:
    """``stacklevel`` (counted from :func:`warn`'s caller's caller) with the frames of the argument checks
    (:mod:`gesturekit._arguments`) between skipped, so that a warning names the line that called gesturekit."""
    import sys

    frame: FrameType | None = sys._getframe(2)  # warn's caller: stack level 2
    level, at = stacklevel, 2
    while frame is not None and at < level:
        frame, at = frame.f_back, at + 1
        if frame is not None and frame.f_code.co_filename.endswith(f"{os.sep}_arguments.py"):
            level += 1
    return level


@contextlib.contextmanager
def collect_warnings() -> Iterator[list[str]]:
    """Collect the messages of the :class:`GestureKitWarning` s this thread issues in the block.

    Unlike :func:`warnings.catch_warnings`, which swaps process-wide state, this
    sees only the calling thread's warnings and leaves other threads alone: in the
    app, several sessions and background threads run at once. Blocks nest; the
    innermost collects.

    Yields
    ------
    list of str
        The messages, in order (complete when the block ends).
    """
    stack = getattr(_collecting, "stack", None)
    if stack is None:
        stack = _collecting.stack = []
    messages: list[str] = []
    stack.append(messages)
    try:
        yield messages
    finally:
        stack.pop()
