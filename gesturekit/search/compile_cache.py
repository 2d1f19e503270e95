"""numba's on-disk cache of compiled code, made safe between processes and versions.

numba keeps each compiled specialisation of a function in a data file ``<name>.<n>.nbc`` and
lists it in an index ``<name>.nbi``. A process that saves a new specialisation reads the
index, takes the first number it leaves free and writes the data and then the index. Two
processes that compile different specialisations at once take the same number: the index of
one then names the other's machine code, and the next process that loads it crashes. A
process still running an older source file writes into the same files as a newer one.

:func:`kernel` compiles like ``numba.njit(cache=True)`` with two changes:

- **one folder per version of the source**: ``<base>/<file>-<digest>``, where the digest is
  the SHA-256 of the source file as the process imported it, of numba's version and of
  Python's. Two versions never share a file. When a new version's folder is made, the
  folders of other versions of the same file that no process has opened for a week, and
  none holds now, are removed.
- **one lock per folder**: every load and save of an entry holds an exclusive lock
  (``fcntl.flock``) on the folder's ``.lock`` file, so the index and the data files it
  names are always read and written whole by one process at a time. The lock is opened
  without following links, and never truncated.

``<base>`` is numba's own ``$NUMBA_CACHE_DIR`` when it is set, else ``numba`` in
gesturekit's folder (:func:`gesturekit.paths.home`). Where no folder can be written, the
functions compile in memory only, each time a process first runs them.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import logging
import os
import shutil
import stat
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numba
from numba.core import caching

from .._arguments import checks_arguments

try:
    import fcntl
except ImportError:  # pragma: no cover  (not on Windows: no on-disk cache there)
    fcntl = None  # type: ignore[assignment]

from ..paths import home

__all__ = ["cache_folder", "kernel"]

LOG = logging.getLogger(__name__)

#: Name of the lock file in each cache folder.
LOCK_NAME = ".lock"

#: A folder of another version unused for this long (seconds) is removed.
STALE_S = 7 * 24 * 3600


def _base() -> Path:
    """The folder that holds the per-version folders (numba's ``$NUMBA_CACHE_DIR`` first)."""
    env: str = getattr(numba.config, "CACHE_DIR", "")  # numba reads $NUMBA_CACHE_DIR at import
    return Path(env).expanduser() if env else home() / "numba"


@functools.cache
def _digest(source: str) -> str:
    """The version key of ``source`` (a file path), computed once per process.

    Once per process, so that a process keeps the key of the source it imported: a file
    edited while it runs is another version, which that process never writes into.
    """
    h = hashlib.sha256()
    with open(source, "rb") as f:
        h.update(f.read())
    h.update(f"numba {numba.__version__} python {sys.version}".encode())
    return h.hexdigest()[:16]


@checks_arguments
def cache_folder(source: str | os.PathLike[str]) -> Path:
    """The folder that holds the compiled code of the functions defined in ``source``.

    Parameters
    ----------
    source : path
        The Python file that defines the functions (as imported by this process).

    Returns
    -------
    Path
        ``<base>/<file stem>-<digest>``: one folder per version of the file, of numba and of Python.
    """
    source = os.path.abspath(source)
    return _base() / f"{Path(source).stem}-{_digest(source)}"


class _FolderLock:
    """An exclusive lock on a cache folder, across processes (flock) and threads, re-entrant.

    numba loads and saves the entries of the functions a function calls while it compiles
    that function: the same thread takes the lock again, and only the outermost hold
    touches the file.
    """

    _guard = threading.RLock()
    _held: dict[str, tuple[int, int]] = {}  # folder -> (fd, depth), under _guard

    @classmethod
    @contextlib.contextmanager
    def hold(cls, folder: Path) -> Iterator[None]:
        key = str(folder)
        with cls._guard:
            fd, depth = cls._held.get(key, (-1, 0))
            if depth == 0:
                fd = _open_lock(folder)
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX)
                    os.utime(fd)  # "used now", for the pruning of other versions' folders
                except BaseException:
                    os.close(fd)
                    raise
            cls._held[key] = (fd, depth + 1)
            try:
                yield
            finally:
                fd, depth = cls._held.pop(key)
                if depth > 1:
                    cls._held[key] = (fd, depth - 1)
                else:
                    os.close(fd)  # closing the last descriptor releases the flock


def _open_lock(folder: Path) -> int:
    """Open (creating) ``folder/.lock`` for locking: never through a link, never truncated,
    and only a regular file; raises OSError otherwise."""
    folder.mkdir(parents=True, exist_ok=True)
    fd = os.open(folder / LOCK_NAME, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise OSError(f"{folder / LOCK_NAME} is not a regular file")
    return fd


def _last_used(folder: Path) -> float:
    """When a process last took ``folder``'s lock (its mtime), 0 if never."""
    try:
        return (folder / LOCK_NAME).lstat().st_mtime
    except OSError:
        return 0.0


def _prune(folder: Path, now: float) -> None:
    """Remove the folders of other versions of ``folder``'s source file unused since
    ``now - STALE_S`` that no process holds now."""
    stem = folder.name.rsplit("-", 1)[0]
    for other in folder.parent.glob(f"{stem}-*"):
        if other == folder or other.is_symlink() or not other.is_dir() or len(other.name) != len(folder.name):
            continue
        if now - _last_used(other) < STALE_S:
            continue
        try:
            fd = _open_lock(other)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # in use by a process of that version
            os.close(fd)
            continue
        try:
            shutil.rmtree(other, ignore_errors=True)
        finally:
            os.close(fd)


class _Locator(caching._CacheLocator):
    """Finds a function's entries in :func:`cache_folder` of its source file."""

    def __init__(self, py_func: Callable[..., Any], py_file: str) -> None:
        self._folder = cache_folder(py_file)
        self._lineno = py_func.__code__.co_firstlineno
        self._stamp = self._folder.name  # the folder is one version: the stamp never differs inside it

    def ensure_cache_path(self) -> None:
        new = not self._folder.is_dir()
        super().ensure_cache_path()
        if new:
            _prune(self._folder, time.time())

    def get_cache_path(self) -> str:
        return str(self._folder)

    def get_source_stamp(self) -> str:
        return self._stamp

    def get_disambiguator(self) -> str:
        return str(self._lineno)

    @classmethod
    def from_function(cls, py_func: Callable[..., Any], py_file: str) -> _Locator | None:
        if fcntl is None or not os.path.isfile(py_file):
            return None
        locator = cls(py_func, py_file)
        try:
            locator.ensure_cache_path()
        except OSError:
            return None
        return locator


class _Impl(caching.CompileResultCacheImpl):
    _locator_classes = [_Locator]


class _LockedCache(caching.FunctionCache):
    """numba's function cache in :func:`cache_folder`, each load and save under the folder's lock."""

    _impl_class = _Impl

    def load_overload(self, sig: Any, target_context: Any) -> Any:
        try:
            with _FolderLock.hold(Path(self._cache_path)):
                return super().load_overload(sig, target_context)
        except OSError:  # the folder went away or cannot be locked: compile instead
            LOG.debug("compiled-code cache not read (%s)", self._cache_path, exc_info=True)
            return None

    def save_overload(self, sig: Any, data: Any) -> None:
        try:
            with _FolderLock.hold(Path(self._cache_path)):
                super().save_overload(sig, data)
        except OSError:  # a full disk or a read-only folder costs a compile next time, nothing more
            LOG.debug("compiled-code cache not written (%s)", self._cache_path, exc_info=True)


@checks_arguments
def kernel(**options: Any) -> Callable[[Callable[..., Any]], Any]:
    """A decorator: ``numba.njit(nogil=True, **options)`` with the safe on-disk cache.

    Parameters
    ----------
    **options
        numba's compile options (``fastmath``, ...); ``cache`` is not one of them.

    Returns
    -------
    callable
        The decorator, giving numba's dispatcher.
    """
    if "cache" in options:
        raise TypeError("kernel() caches by itself; do not pass cache=")

    def decorate(func: Callable[..., Any]) -> Any:
        dispatcher = numba.njit(nogil=True, **options)(func)
        try:
            dispatcher._cache = _LockedCache(func)
        except RuntimeError:  # no folder can be written: numba found no locator
            LOG.info("compiling %s in memory only: no cache folder can be written", func.__qualname__)
        return dispatcher

    return decorate
