"""Limits on what one input may cost, checked from its header before decoding.

A file's header states how much work it asks for: a WAV that says 1 Hz turns
16 KB into hours of resampled speech, a BVH whose frame time is 100000 s asks
for billions of frames at 15 fps, an npy header may claim a terabyte. Readers
estimate the cost from the header with the checks below and refuse beyond these
limits, before anything large is decoded or allocated.

Each limit has a default and an environment variable that raises (or lowers)
it; the command line also takes ``--max-speech-minutes`` for speech.

=====================================  ===========  ================================
limit                                  default      environment variable
=====================================  ===========  ================================
speech to synthesise for, per file     60 min       ``GESTUREKIT_MAX_SPEECH_MINUTES``
one take (motion or its audio)         4 h          ``GESTUREKIT_MAX_TAKE_HOURS``
audio sample rate                      4-384 kHz    ``GESTUREKIT_MIN_SAMPLE_RATE``,
                                                    ``GESTUREKIT_MAX_SAMPLE_RATE`` (Hz)
motion frame rate (BVH, positions)     1-1000 fps   ``GESTUREKIT_MIN_FPS``, ``GESTUREKIT_MAX_FPS``
one input once decoded in memory       4 GB         ``GESTUREKIT_MAX_INPUT_GB``
one JSON file (database.json, a map)   64 MB        ``GESTUREKIT_MAX_JSON_MB``
=====================================  ===========  ================================

Every file is read only if it is a regular file (:func:`check_regular`): a FIFO
would block the reader forever and a device never ends. JSON is read by
:func:`read_json`, which refuses a file beyond its size limit before reading it
and one nested deeper than :data:`JSON_DEPTH` before parsing it.

The values are read from the environment at each check, so a test or a
long-running server sees a change at once; :func:`override` sets one for a
block of code (the command line's options), in this thread or task only.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import IO, TYPE_CHECKING

from ._arguments import checks_arguments
from .errors import ConfigError, GestureKitError, InputFileError, MotionFileError

if TYPE_CHECKING:
    import numpy as np

__all__ = [
    "Limit",
    "override",
    "SPEECH_MINUTES",
    "TAKE_HOURS",
    "MIN_SAMPLE_RATE",
    "MAX_SAMPLE_RATE",
    "MIN_FPS",
    "MAX_FPS",
    "INPUT_GB",
    "max_speech_seconds",
    "max_take_seconds",
    "max_input_bytes",
    "check_duration",
    "check_sample_rate",
    "check_fps",
    "check_bytes",
    "describe_seconds",
    "describe_bytes",
    "npy_header",
    "npz_headers",
    "array_bytes",
    "JSON_MB",
    "JSON_DEPTH",
    "file_kind",
    "check_regular",
    "read_json",
    "parse_json",
    "check_npz",
]


@dataclass(frozen=True)
class Limit:
    """One limit: its default and the environment variable that changes it.

    Parameters
    ----------
    env : str
        Name of the environment variable.
    default : float
        Value when the variable is unset or empty.
    unit : str
        Unit of the value, for messages (``"minutes"``, ``"Hz"``, ...).
    """

    env: str
    default: float
    unit: str

    def value(self) -> float:
        """The limit now: the environment variable if set, else the default.

        Raises
        ------
        ConfigError
            The variable is set to something other than a positive finite number.
        """
        given = _overrides.get().get(self.env)
        if given is not None:
            return given[0]
        text = os.environ.get(self.env, "").strip()
        if not text:
            return self.default
        try:
            v = float(text)
        except ValueError:
            v = math.nan
        if not (math.isfinite(v) and v > 0):
            raise ConfigError(f"the environment variable {self.env}={text!r} must be a positive number of {self.unit}")
        return v

    def how_to_raise(self) -> str:
        """How a user changes this limit, for messages."""
        given = _overrides.get().get(self.env)
        if given is not None and given[1]:
            return f"{given[1]} sets it"
        return f"set the environment variable {self.env} to change it"


# an immutable default: a mapping shared by every context must not be changed in place
_overrides: contextvars.ContextVar[Mapping[str, tuple[float, str | None]]] = contextvars.ContextVar(
    "gesturekit_limits", default=MappingProxyType({})
)


@contextlib.contextmanager
@checks_arguments
def override(limit: Limit, value: float | None, *, option: str | None = None) -> Iterator[None]:
    """Set ``limit`` to ``value`` inside the block (nothing changes when ``value`` is None).

    Parameters
    ----------
    limit : Limit
    value : float or None
        In the limit's unit.
    option : str, optional
        The command-line option that gave it, named in messages and errors.

    Raises
    ------
    ConfigError
        ``value`` is not a positive finite number.
    """
    if value is None:
        yield
        return
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise ConfigError(f"{option or limit.env} must be a positive number of {limit.unit}, got {value!r}")
    token = _overrides.set({**_overrides.get(), limit.env: (v, option)})
    try:
        yield
    finally:
        _overrides.reset(token)


SPEECH_MINUTES = Limit("GESTUREKIT_MAX_SPEECH_MINUTES", 60.0, "minutes")
TAKE_HOURS = Limit("GESTUREKIT_MAX_TAKE_HOURS", 4.0, "hours")
MIN_SAMPLE_RATE = Limit("GESTUREKIT_MIN_SAMPLE_RATE", 4000.0, "Hz")
MAX_SAMPLE_RATE = Limit("GESTUREKIT_MAX_SAMPLE_RATE", 384000.0, "Hz")
MIN_FPS = Limit("GESTUREKIT_MIN_FPS", 1.0, "frames per second")
MAX_FPS = Limit("GESTUREKIT_MAX_FPS", 1000.0, "frames per second")
INPUT_GB = Limit("GESTUREKIT_MAX_INPUT_GB", 4.0, "GB")
JSON_MB = Limit("GESTUREKIT_MAX_JSON_MB", 64.0, "MB")

#: How deeply the JSON files gesturekit reads may nest arrays and objects (they need 4 levels).
JSON_DEPTH = 32


@checks_arguments
def max_speech_seconds() -> float:
    """Longest speech accepted for synthesis, seconds (``GESTUREKIT_MAX_SPEECH_MINUTES`` x 60)."""
    return SPEECH_MINUTES.value() * 60.0


@checks_arguments
def max_take_seconds() -> float:
    """Longest take (motion or its audio) accepted for a database, seconds."""
    return TAKE_HOURS.value() * 3600.0


@checks_arguments
def max_input_bytes() -> float:
    """Most memory one input may take once decoded, bytes."""
    return INPUT_GB.value() * 1e9


@checks_arguments
def describe_seconds(seconds: float) -> str:
    """A duration in the unit that reads best: ``"8.0 s"``, ``"2.2 h"``, ``"3.2e+07 h"``."""
    if not math.isfinite(seconds):
        return f"{seconds} s"
    if seconds < 120:
        return f"{seconds:.1f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    hours = seconds / 3600
    return f"{hours:.1f} h" if hours < 1e5 else f"{hours:.2g} h"


@checks_arguments
def describe_bytes(n: float) -> str:
    """A size such as ``"16.0 KB"``, ``"2.7 GB"`` (powers of 1000)."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("KB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}" if n / scale < 1e4 else f"{n / scale:.2g} {unit}"
    return f"{int(n)} bytes"


@checks_arguments
def check_duration(
    seconds: float,
    *,
    what: str,
    path: str | os.PathLike[str] | None = None,
    speech: bool = False,
    max_seconds: float | None = None,
    option: str | None = None,
) -> None:
    """Refuse an input whose header asks for more than the duration limit.

    Parameters
    ----------
    seconds : float
        Duration the header states (or implies), seconds.
    what : str
        What the header says, in words (``"the WAV header says 8000 samples at 1 Hz"``).
    path : path, optional
        The file, named in the message.
    speech : bool
        Speech to synthesise for (limit :data:`SPEECH_MINUTES`) rather than a take
        (:data:`TAKE_HOURS`).
    max_seconds : float, optional
        A limit given explicitly (e.g. by a command-line option), seconds; default the
        environment's.
    option : str, optional
        The option that set ``max_seconds``, mentioned in the message.

    Raises
    ------
    InputFileError
        ``seconds`` is beyond the limit (or not a finite number).
    """
    limit = SPEECH_MINUTES if speech else TAKE_HOURS
    cap = max_seconds if max_seconds is not None else limit.value() * (60.0 if speech else 3600.0)
    if math.isfinite(seconds) and seconds <= cap:
        return
    kind = "speech" if speech else "one take"
    if option:
        how = f"{option} sets it"
    elif max_seconds is not None:
        how = "the maximum duration given"
    else:
        how = limit.how_to_raise()
    raise InputFileError(
        f"{what}: {describe_seconds(seconds)}, beyond the limit of {describe_seconds(cap)} for {kind} ({how})",
        path=path,
    )


@checks_arguments
def check_sample_rate(rate: float, *, what: str, path: str | os.PathLike[str] | None = None) -> None:
    """Refuse a sample rate outside :data:`MIN_SAMPLE_RATE` .. :data:`MAX_SAMPLE_RATE`.

    Parameters
    ----------
    rate : float
        Sample rate stated by the header, Hz.
    what : str
        Where the rate comes from (``"the WAV header"``).
    path : path, optional

    Raises
    ------
    InputFileError
    """
    lo, hi = MIN_SAMPLE_RATE.value(), MAX_SAMPLE_RATE.value()
    rate = float(rate)
    if math.isfinite(rate) and lo <= rate <= hi:
        return
    raise InputFileError(
        f"{what} says a sample rate of {rate:g} Hz, outside the accepted range of {lo:g}-{hi:g} Hz "
        f"(set {MIN_SAMPLE_RATE.env} or {MAX_SAMPLE_RATE.env} to change it)",
        path=path,
    )


@checks_arguments
def check_fps(fps: float, *, what: str, path: str | os.PathLike[str] | None = None, option: str | None = None) -> None:
    """Refuse a motion frame rate outside :data:`MIN_FPS` .. :data:`MAX_FPS`.

    Parameters
    ----------
    fps : float
        Frames per second.
    what : str
        Where the rate comes from (``"the frame time 100000 s"``, ``"--fps"``).
    path : path, optional
        The file the rate belongs to; with no path a :class:`ConfigError` is raised.
    option : str, optional
        The option that gave the rate, put in front of the message.

    Raises
    ------
    InputFileError, ConfigError
    """
    lo, hi = MIN_FPS.value(), MAX_FPS.value()
    try:
        fps = float(fps)
    except (TypeError, ValueError):
        fps = math.nan
    if math.isfinite(fps) and lo <= fps <= hi:
        return
    message = (
        f"{what} is {fps:g} fps, outside the accepted range of {lo:g}-{hi:g} fps "
        f"(set {MIN_FPS.env} or {MAX_FPS.env} to change it)"
    )
    if path is None:
        raise ConfigError(f"{option}: {message}" if option else message)
    raise InputFileError(message, path=path)


@checks_arguments
def check_bytes(n: float, *, what: str, path: str | os.PathLike[str] | None = None) -> None:
    """Refuse an input that would take more than :data:`INPUT_GB` once decoded.

    Parameters
    ----------
    n : float
        Bytes the decoded input would take.
    what : str
        What the header says (``"the npy header says shape (10, 10**9, 3) of float64"``).
    path : path, optional

    Raises
    ------
    InputFileError
    """
    cap = max_input_bytes()
    if math.isfinite(n) and n <= cap:
        return
    raise InputFileError(
        f"{what}: {describe_bytes(n)} once decoded, beyond the limit of {describe_bytes(cap)} for one input "
        f"({INPUT_GB.how_to_raise()})",
        path=path,
    )


@checks_arguments
def npy_header(
    f: IO[bytes], *, path: str | os.PathLike[str] | None = None, name: str = "npy"
) -> tuple[tuple[int, ...], np.dtype, int]:
    """Shape, dtype and header length of an ``.npy`` stream, read without loading the array.

    Parameters
    ----------
    f : binary file object
        Positioned at the start of the ``.npy`` data.
    path : path, optional
        The file, for messages.
    name : str
        What is read (``"npy"``, ``"'body' in the npz"``), for messages.

    Returns
    -------
    shape : tuple of int
    dtype : np.dtype
    offset : int
        Bytes of magic and header before the data.

    Raises
    ------
    MotionFileError
        Not an npy header, or an unsupported version.
    """
    import numpy as np

    fmt = np.lib.format
    try:
        version = fmt.read_magic(f)
        if version == (1, 0):
            shape, _, dtype = fmt.read_array_header_1_0(f)
        elif version in ((2, 0), (3, 0)):
            shape, _, dtype = fmt.read_array_header_2_0(f)
        else:
            raise ValueError(f"unsupported npy version {version}")
    except (ValueError, OSError, EOFError, SyntaxError) as exc:
        raise MotionFileError(f"cannot read the {name} header: {exc}", path=path) from None
    offset = f.tell() if hasattr(f, "tell") else 0
    return tuple(int(n) for n in shape), dtype, offset


@checks_arguments
def npz_headers(path: str | os.PathLike[str]) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Shape and dtype of every array in an ``.npz`` archive, read without loading the arrays.

    Parameters
    ----------
    path : path

    Returns
    -------
    dict
        Array name (without ``.npy``) -> (shape, dtype).

    Raises
    ------
    MotionFileError
        Not a zip archive, or a member without an npy header.
    """
    import zipfile

    try:
        with zipfile.ZipFile(path) as z:
            out = {}
            for info in z.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                key = info.filename[:-4]
                with z.open(info) as member:
                    shape, dtype, _ = npy_header(member, path=path, name=f"{key!r} in the npz")
                out[key] = (shape, dtype)
            return out
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, NotImplementedError) as exc:
        raise MotionFileError(f"cannot read the npz archive: {exc}", path=path) from None


@checks_arguments
def array_bytes(shape: tuple[int, ...], itemsize: int) -> float:
    """Bytes of an array of ``shape`` with ``itemsize``-byte elements (float, never overflows)."""
    n = float(itemsize)
    for d in shape:
        n *= d
    return n


# ---- files: regular ones only, JSON bounded, npz archives checked -------------------------------------


@checks_arguments
def file_kind(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is, in words (``"a FIFO"``, ``"a character device"``, ...)."""
    import stat

    for test, what in (
        (stat.S_ISREG, "a regular file"),
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISLNK, "a symbolic link"),
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
    ):
        if test(mode):
            return what
    return "not a regular file"


@checks_arguments
def check_regular(
    path: str | os.PathLike[str],
    *,
    what: str = "",
    error: type[GestureKitError] = InputFileError,
    owner: str | os.PathLike[str] | None = None,
) -> int:
    """Refuse anything but a regular file before it is opened; a FIFO would block its reader for ever.

    Parameters
    ----------
    path : path
    what : str
        What the file is, in front of the problem (``"database.json "``); empty to name ``path`` alone.
    error : type
        The :class:`~gesturekit.errors.GestureKitError` subclass to raise.
    owner : path, optional
        What the message names instead of ``path`` (the folder holding it).

    Returns
    -------
    int
        The file's size in bytes.

    Raises
    ------
    GestureKitError
        Of type ``error``: missing, unreadable, or not a regular file (a folder, a FIFO, a device).
    """
    import stat

    where = path if owner is None else owner
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise error(f"{what}not found", path=where) from None
    except OSError as exc:
        raise error(f"{what}cannot be read ({exc.strerror or exc})", path=where) from None
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{what}is {file_kind(st.st_mode)}, not a regular file", path=where)
    return st.st_size


@checks_arguments
def read_json(
    path: str | os.PathLike[str],
    *,
    what: str = "",
    error: type[GestureKitError] = InputFileError,
    owner: str | os.PathLike[str] | None = None,
    encoding: str = "utf-8",
) -> object:
    """A JSON file, refused if it is not a regular file, beyond :data:`JSON_MB` or nested too deeply.

    The size is checked before anything is read (a 400 MB file would cost three
    times that once parsed), the nesting before parsing (Python's parser
    recurses, and raises ``RecursionError`` on deep input).

    Parameters
    ----------
    path : path
    what : str
        What the file is, in front of the problem (``"database.json "``, ``"joint map "``).
    error : type
        The :class:`~gesturekit.errors.GestureKitError` subclass to raise.
    owner : path, optional
        What the message names instead of ``path`` (the folder holding it).
    encoding : str
        ``"utf-8"``, or ``"utf-8-sig"`` to accept a byte-order mark.

    Returns
    -------
    object
        The parsed content.

    Raises
    ------
    GestureKitError
        Of type ``error``: not a regular file, too large, too deep, not UTF-8 or not JSON.
    """
    import json

    where = path if owner is None else owner
    size = check_regular(path, what=what, error=error, owner=owner)
    cap = JSON_MB.value() * 1e6
    if size > cap:
        raise error(
            f"{what}is {describe_bytes(size)}, beyond the limit of {describe_bytes(cap)} for a JSON file "
            f"({JSON_MB.how_to_raise()})",
            path=where,
        )
    try:
        with open(path, "rb") as f:
            raw = f.read(int(cap) + 1)
        text = raw.decode(encoding)
    except UnicodeDecodeError as exc:
        raise error(f"{what}is not UTF-8 text (byte {exc.start})", path=where) from None
    except OSError as exc:
        raise error(f"{what}cannot be read ({exc.strerror or exc})", path=where) from None
    depth = _json_depth(text)
    if depth > JSON_DEPTH:
        raise error(f"{what}nests {depth} levels deep, beyond the {JSON_DEPTH} a gesturekit file uses", path=where)
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise error(f"{what}{'is ' if what else ''}not valid JSON ({exc})", path=where) from None


@checks_arguments
def parse_json(
    text: str | bytes,
    *,
    what: str = "",
    error: type[GestureKitError] = InputFileError,
    path: str | os.PathLike[str] | None = None,
) -> object:
    """JSON text (a cell, a request body) parsed, refused when nested deeper than :data:`JSON_DEPTH`.

    Raises
    ------
    GestureKitError
        Of type ``error``: not UTF-8, too deep, or not JSON; the message starts with ``what``.
    """
    import json

    try:
        text = text.decode("utf-8") if isinstance(text, bytes) else text
    except UnicodeDecodeError as exc:
        raise error(f"{what}is not UTF-8 text (byte {exc.start})", path=path) from None
    depth = _json_depth(text)
    if depth > JSON_DEPTH:
        raise error(f"{what}nests {depth} levels deep, beyond the {JSON_DEPTH} allowed", path=path)
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise error(f"{what}{'is ' if what else ''}not valid JSON ({exc})", path=path) from None


def _json_depth(text: str) -> int:
    """How deeply arrays and objects nest in JSON text (brackets inside strings do not count)."""
    import re

    import numpy as np

    bare = re.sub(r'"(?:[^"\\]|\\.)*"', "", text).encode("utf-8", "replace")
    b = np.frombuffer(bare, dtype=np.uint8)
    steps = np.isin(b, (ord("["), ord("{"))).astype(np.int64) - np.isin(b, (ord("]"), ord("}")))
    return int(np.cumsum(steps).max(initial=0))


@checks_arguments
def check_npz(
    path: str | os.PathLike[str],
    *,
    max_bytes: float,
    what: str = "",
    error: type[GestureKitError] = InputFileError,
    owner: str | os.PathLike[str] | None = None,
) -> None:
    """Refuse an ``.npz`` whose members would decompress (or declare arrays) beyond ``max_bytes`` in all.

    Only the archive's directory and each member's npy header are read: a zip
    bomb is refused before it is inflated.

    Parameters
    ----------
    path : path
    max_bytes : float
        The most the arrays may take together.
    what, error, owner
        As :func:`read_json`.

    Raises
    ------
    GestureKitError
        Of type ``error``: not a regular file, not an npz archive, or larger than ``max_bytes``.
    """
    import zipfile

    where = path if owner is None else owner
    check_regular(path, what=what, error=error, owner=owner)
    try:
        with zipfile.ZipFile(path) as z:
            declared = sum(float(i.file_size) for i in z.infolist())
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, NotImplementedError) as exc:
        raise error(f"{what}cannot be read ({exc})", path=where) from None
    if declared > max_bytes:
        raise error(
            f"{what}declares {describe_bytes(declared)} of arrays, beyond the {describe_bytes(max_bytes)} it can hold",
            path=where,
        )
    try:
        headers = npz_headers(path)
    except MotionFileError as exc:
        raise error(f"{what}cannot be read ({exc.problem})", path=where) from None
    for key, (shape, dtype) in headers.items():
        n = array_bytes(shape, dtype.itemsize)
        if n > max_bytes:
            raise error(
                f"{what}{key} declares shape {shape}: {describe_bytes(n)}, beyond the {describe_bytes(max_bytes)} "
                "it can hold",
                path=where,
            )
