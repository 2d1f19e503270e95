"""Outputs gesturekit owns: what ``--force`` may replace, who may write, and what a crash leaves.

Every writer of a folder or file output goes through this module, so that the
same rules hold everywhere:

* **Replace only what gesturekit wrote.** ``overwrite=True`` (``--force``)
  replaces an output only when it is recognisably one gesturekit wrote, of the
  same kind (:data:`FOLDER_KINDS`, :data:`FILE_KINDS`): a database folder
  (``database.json`` of format ``gesturekit-matching-database``), a refiner
  folder (``config.json`` of format ``gesturekit-refiner``), a study folder
  (``study.json`` of format ``gesturekit-study``), an FGD model folder
  (``fgd.json``), an evaluation folder (``evaluation.json`` of format
  ``gesturekit-evaluation``), an ``.npz`` archive with
  gesturekit's ``config`` and ``format_version`` entries, a BVH file whose
  joints are gesturekit's 55 in its order, an MP4 carrying gesturekit's
  metadata tag, a glTF binary whose ``asset.generator`` is gesturekit, a WAV
  carrying gesturekit's tag (the speech beside a glTF file). Anything else
  (a folder of other files, a file where a folder goes, a folder where a file
  goes) is refused, saying what is there. An empty folder is used as it is.
* **Outputs never overlap inputs.** An output folder that is, lies inside or
  contains an input folder (the takes, the database trained on, the speech of
  a study) is refused.
* **One writer per output.** :func:`output_lock` takes an exclusive
  ``flock`` on ``.NAME.lock`` beside the output; a second writer fails at once
  naming the first one's process id.
* **Crashes leave nothing behind for long.** Folders are written as
  ``.NAME.tmp-PID`` and swapped into place (:func:`write_folder`); the next
  writer removes the temporaries (``.NAME.tmp-PID``, ``.NAME.old-PID``, the
  ``.NAME.PID-*.tmp`` files of :func:`gesturekit._io.atomic_write`)
  of processes that are no longer running (:func:`clean_stale`).
* **Write failures are messages.** An ``OSError`` while writing (disk full,
  permission denied) becomes an :class:`~gesturekit.errors.OutputError` naming
  the path (:func:`write_errors`).
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import re
import shutil
import stat
import threading
import zipfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from ._arguments import checks_arguments
from .errors import OutputError
from .folders import FOLDER_KINDS, folder_kind

__all__ = [
    "FOLDER_KINDS",
    "FILE_KINDS",
    "MP4_TAG",
    "check_output",
    "check_not_input",
    "output_lock",
    "beside_name",
    "clean_stale",
    "write_folder",
    "swap_folder",
    "write_errors",
    "pid_alive",
]

#: File kinds gesturekit can recognise as its own, by suffix.
FILE_KINDS = {
    ".npz": "an npz archive",
    ".bvh": "a BVH file",
    ".mp4": "an MP4 video",
    ".glb": "a glTF file",
    ".vrm": "a VRM file",
    ".wav": "a WAV file",
}

#: The MP4 metadata comment gesturekit's videos carry (``-metadata comment=...``).
MP4_TAG = "written by gesturekit"

# how far into a file the markers are looked for: BVH hierarchies and MP4 headers (faststart) are short
_HEAD_BYTES = 1 << 16


# ---- what is there --------------------------------------------------------------------------------


def _describe_contents(path: Path, limit: int = 10_000) -> str:
    """``"12 files"``, ``"3 files and 1 folder"``: what a folder holds, counted to ``limit`` entries."""
    files = folders = 0
    for _root, dirs, names in os.walk(path):
        files += len(names)
        folders += len(dirs)
        if files + folders >= limit:
            break
    more = "+" if files + folders >= limit else ""
    parts = [f"{files}{more} file{'' if files == 1 else 's'}"] if files or not folders else []
    if folders:
        parts.append(f"{folders} folder{'' if folders == 1 else 's'}")
    return " and ".join(parts)


def _file_is_owned(path: Path) -> bool:
    """True when ``path`` is a file gesturekit wrote, recognised by its suffix's marker."""
    suffix = path.suffix.lower()
    try:
        if suffix == ".npz":
            with zipfile.ZipFile(path) as zf:
                members = set(zf.namelist())
            return {"config.npy", "format_version.npy", "positions.npy"} <= members
        with open(path, "rb") as f:
            head = f.read(_HEAD_BYTES)
        if suffix == ".bvh":
            from .skeleton import JOINT_NAMES

            text = head.decode("ascii", "replace")
            if not text.startswith("HIERARCHY"):
                return False
            joints = re.findall(r"^\s*(?:ROOT|JOINT)\s+(\S+)", text.split("MOTION")[0], re.M)
            return sorted(joints) == sorted(JOINT_NAMES)
        if suffix in (".glb", ".vrm"):  # a VRM is a GLB
            return head[:4] == b"glTF" and b'"generator":"gesturekit ' in head
        if suffix == ".wav":
            return head[:4] == b"RIFF" and head[8:12] == b"WAVE" and MP4_TAG.encode() in head
        if suffix == ".mp4":
            if MP4_TAG.encode() in head:
                return True
            size = os.path.getsize(path)
            with open(path, "rb") as f:
                f.seek(max(0, size - _HEAD_BYTES))
                return MP4_TAG.encode() in f.read()
    except (OSError, zipfile.BadZipFile, ValueError):
        return False
    return False


@checks_arguments
def check_not_input(out: str | os.PathLike, inputs: Iterable[str | os.PathLike | None]) -> None:
    """Refuse an output that is, lies inside, or contains one of the ``inputs``.

    Parameters
    ----------
    out : path
        The output folder or file.
    inputs : iterable of path or None
        Input files or folders (None entries are skipped).

    Raises
    ------
    OutputError
        Naming the output and the input it would overwrite.
    """
    o = Path(os.path.realpath(out))
    for inp in inputs:
        if inp is None:
            continue
        i = Path(os.path.realpath(inp))
        if o == i:
            raise OutputError(f"is an input of this command ({inp}); choose another output", path=out)
        if i in o.parents:
            raise OutputError(f"lies inside the input {inp}; choose an output outside it", path=out)
        if o in i.parents:
            raise OutputError(f"contains the input {inp}; choose an output that does not", path=out)


@checks_arguments
def check_output(
    path: str | os.PathLike, kind: str, *, overwrite: bool, inputs: Iterable[str | os.PathLike | None] = ()
) -> bool:
    """Check that ``path`` may be written as an output of ``kind``.

    Parameters
    ----------
    path : path
        The output folder or file.
    kind : str
        A key of :data:`FOLDER_KINDS`, or ``"file"`` (recognised by the suffix, :data:`FILE_KINDS`).
    overwrite : bool
        Whether an earlier output of the same kind may be replaced.
    inputs : iterable of path, optional
        Inputs of the command (see :func:`check_not_input`).

    Returns
    -------
    bool
        True when an earlier output of this kind is there (and will be replaced).

    Raises
    ------
    OutputError
        The output overlaps an input; something other than an empty folder or
        an output of this kind is there; or an output is there and ``overwrite``
        is False.
    """
    path = Path(path)
    check_not_input(path, inputs)
    if path.is_symlink():
        raise OutputError("is a symbolic link; refusing to write through it", path=path)
    if not path.exists():
        return False
    if kind == "file":
        if path.is_dir():
            raise OutputError("is a folder, not a file; refusing to replace it", path=path)
        if not overwrite:
            raise OutputError(
                "already exists; pass overwrite=True (--force on the command line) to replace it", path=path
            )
        if not path.is_file() or not _file_is_owned(path):
            what = FILE_KINDS.get(path.suffix.lower())
            raise OutputError(
                f"is a file that gesturekit did not write{'' if what is None else f' (not {what} of gesturekit)'}; "
                "refusing to replace it",
                path=path,
            )
        return True
    _marker, _fmt, name = FOLDER_KINDS[kind]
    if not path.is_dir():
        raise OutputError(f"is a file, not a folder; refusing to replace it with {name}", path=path)
    try:
        empty = next(path.iterdir(), None) is None
    except OSError as exc:
        raise OutputError(f"cannot be read ({exc.strerror or exc})", path=path) from None
    if empty:
        return False
    found = folder_kind(path)
    if found == kind:
        if not overwrite:
            raise OutputError(
                f"{name} already exists here; pass overwrite=True (--force on the command line) to replace it",
                path=path,
            )
        return True
    if found is not None:
        raise OutputError(f"holds {FOLDER_KINDS[found][2]}, not {name}; refusing to replace it", path=path)
    raise OutputError(
        f"holds {_describe_contents(path)} that gesturekit did not write; refusing to replace it", path=path
    )


# ---- locks ------------------------------------------------------------------------------------------

_held = threading.local()


# the longest file name most file systems take (NAME_MAX), in bytes
_NAME_MAX = 255


@checks_arguments
def beside_name(path: str | os.PathLike, suffix: str) -> str:
    """The name of a hidden file beside ``path``: ``.NAME`` + ``suffix``, shortened to fit a file name.

    A name that would pass the file system's 255-byte limit keeps its start and
    ends with a hash of the whole name, so different long outputs get different names.

    Parameters
    ----------
    path : path
        The output.
    suffix : str
        What follows the name (``".lock"``, ``".tmp-PID"``).

    Returns
    -------
    str
    """
    name = Path(path).name
    full = f".{name}{suffix}"
    if len(os.fsencode(full)) <= _NAME_MAX:
        return full
    return _short_prefix(name) + suffix


def _short_prefix(name: str) -> str:
    # the start of the name, a hash of all of it, and room for any suffix we use (32 bytes)
    import hashlib

    digest = hashlib.sha1(os.fsencode(name)).hexdigest()[:16]
    stem = os.fsencode(name)[: _NAME_MAX - 32 - len(digest) - 2].decode("utf-8", "ignore")
    return f".{stem}~{digest}"


def _lock_fd(lock: Path) -> int:
    """Open (or create) a lock file without following links; refuse anything we did not make.

    A lock file gesturekit made is a regular file with one name that holds nothing
    but a process id. A symbolic link, a hard link to another file, a folder or a
    FIFO planted under the lock's name is refused before anything is written to it.
    """
    flags = os.O_RDWR | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    refuse = "is not a lock file gesturekit made ({}); remove it if no gesturekit process is writing this output"
    try:
        return os.open(lock, flags | os.O_CREAT | os.O_EXCL, 0o666)
    except FileExistsError:
        pass
    try:
        fd = os.open(lock, flags)
    except FileNotFoundError:
        return _lock_fd(lock)  # removed meanwhile by a holder that finished
    except OSError as exc:
        if exc.errno in (errno.ELOOP, errno.EMLINK, errno.EISDIR, errno.ENXIO):
            raise OutputError(refuse.format(_what_is(lock)), path=lock) from None
        raise
    st = os.fstat(fd)
    problem = None
    if not stat.S_ISREG(st.st_mode):
        problem = _what_is(lock)
    elif st.st_nlink != 1:
        problem = f"a file with {st.st_nlink} names"
    elif st.st_size > 32 or (st.st_size and not os.pread(fd, 33, 0).strip().isdigit()):
        problem = f"a file of {st.st_size} bytes that holds no process id"
    if problem is not None:
        os.close(fd)
        raise OutputError(refuse.format(problem), path=lock)
    return fd


def _what_is(path: Path) -> str:
    """``"a symbolic link"``, ``"a folder"``, ...: what is at ``path``, not followed."""
    from .limits import file_kind

    try:
        return file_kind(os.lstat(path).st_mode)
    except OSError:
        return "not readable"


@contextlib.contextmanager
@checks_arguments
def output_lock(path: str | os.PathLike) -> Iterator[None]:
    """Hold the exclusive lock of one output path for the block.

    The lock is an ``flock`` on ``.NAME.lock`` beside ``path`` (its folder is
    created; a long name is shortened by :func:`beside_name`). It is released,
    and the lock file removed, when the block ends or the process dies; a lock
    file left by a dead process is no obstacle. The lock file is opened without
    following links, and only a regular file holding a process id is taken for
    one: a link or anything else planted under its name is refused untouched.

    Raises
    ------
    OutputError
        Another process, or another thread of this one, holds the lock, or
        something other than a lock file is in its place.
    """
    import fcntl

    path = Path(path)
    with write_errors(path.parent):
        path.parent.mkdir(parents=True, exist_ok=True)
    lock = path.parent / beside_name(path, ".lock")
    while True:
        with write_errors(lock):
            fd = _lock_fd(lock)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno not in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
                os.close(fd)
                raise OutputError(f"cannot be locked for writing ({exc.strerror or exc})", path=path) from None
            try:
                holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
            except OSError:
                holder = ""
            os.close(fd)
            who = f"pid {holder}" if holder.isdigit() else "pid unknown"
            raise OutputError(
                f"another gesturekit process ({who}) is writing this output; try again when it has finished", path=path
            ) from None
        # the file may have been removed by a holder that finished between our open and flock
        try:
            same = os.fstat(fd).st_ino == os.lstat(lock).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode("ascii"), 0)
        yield
    finally:
        try:
            # only our own file: something put in its place meanwhile is left alone
            if os.fstat(fd).st_ino == os.lstat(lock).st_ino:
                os.unlink(lock)
        except OSError:
            pass
        os.close(fd)


# ---- stale temporaries ------------------------------------------------------------------------------


@checks_arguments
def pid_alive(pid: int) -> bool:
    """Whether a process with this id runs (on this machine)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:
        return True
    return True


@checks_arguments
def clean_stale(path: str | os.PathLike, *, own: bool = False) -> list[Path]:
    """Remove what interrupted writers of ``path`` left beside it.

    ``.NAME.tmp-PID`` and ``.NAME.old-PID`` folders and ``.NAME.PID-*.tmp``
    files whose process no longer runs are removed; with ``own`` (the caller
    holds :func:`output_lock`) also those of this process. If ``path`` itself
    is missing and a ``.NAME.old-PID`` folder is there (a writer died between
    the two renames of a swap), that folder is put back first.

    Returns
    -------
    list of Path
        What was removed.
    """
    path = Path(path)
    folder = path.parent
    if not folder.is_dir():
        return []
    name = rf"(?:\.{re.escape(path.name)}|{re.escape(_short_prefix(path.name))})"
    pattern = re.compile(rf"^(?:{name}\.(?:tmp|old)-(\d+)|\.{re.escape(path.name[:64])}\.(\d+)-[0-9a-f]+\.tmp)$")
    stale = []
    for entry in folder.iterdir():
        m = pattern.match(entry.name)
        if not m:
            continue
        pid = int(next(g for g in m.groups() if g is not None))
        if pid_alive(pid) and not (own and pid == os.getpid()):
            continue
        stale.append(entry)
    removed = []
    for entry in sorted(stale, key=lambda e: ".old-" not in e.name):
        if ".old-" in entry.name and not path.exists() and not path.is_symlink():
            os.replace(entry, path)
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            with contextlib.suppress(FileNotFoundError):
                entry.unlink()
        removed.append(entry)
    return removed


# ---- writing a folder -------------------------------------------------------------------------------

_RENAME_EXCHANGE = 2


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths in one step (Linux ``renameat2``); False where the system cannot."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    at_fdcwd = -100
    if fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), os.fspath(b))


@checks_arguments
def swap_folder(tmp: Path, path: Path) -> None:
    """Put the finished folder ``tmp`` in the place of ``path`` (which may exist) and delete the old one.

    Where the system can, the two folders are exchanged in one step, so that
    ``path`` is at every moment either the old folder or the new one. Elsewhere
    the old folder is first renamed to ``.NAME.old-PID``, which
    :func:`clean_stale` puts back if the process dies before the second rename.
    """
    if path.exists() and _exchange(tmp, path):
        shutil.rmtree(tmp, ignore_errors=True)
        return
    old = None
    if path.exists():
        old = path.parent / beside_name(path, f".old-{os.getpid()}")
        if old.exists():
            shutil.rmtree(old)
        os.replace(path, old)
    os.replace(tmp, path)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


@checks_arguments
def write_folder(
    path: str | os.PathLike,
    kind: str,
    fill: Callable[[Path], None],
    *,
    overwrite: bool = False,
    inputs: Iterable[str | os.PathLike | None] = (),
    locked: bool = False,
) -> Path:
    """Write an output folder all at once: checked, locked, filled under a temporary name, swapped in.

    Parameters
    ----------
    path : path
        The folder to write.
    kind : str
        A key of :data:`FOLDER_KINDS`; ``fill`` must write its marker file.
    fill : callable(Path)
        Writes every file into the (empty, existing) temporary folder it gets.
    overwrite : bool
        Replace an earlier output of the same kind.
    inputs : iterable of path
        Inputs that the output must not overlap.
    locked : bool
        The caller holds :func:`output_lock` of ``path`` already.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OutputError
        See :func:`check_output` and :func:`output_lock`; an ``OSError`` while writing.
    """
    path = Path(path)
    check_output(path, kind, overwrite=overwrite, inputs=inputs)
    lock = contextlib.nullcontext() if locked else output_lock(path)
    with lock:
        clean_stale(path, own=True)
        # checked again under the lock: another writer may have finished meanwhile
        check_output(path, kind, overwrite=overwrite, inputs=inputs)
        tmp = path.parent / beside_name(path, f".tmp-{os.getpid()}")
        try:
            with write_errors(path):
                tmp.mkdir()
                fill(tmp)
                if path.is_dir() and next(path.iterdir(), None) is None:
                    path.rmdir()  # an empty folder given as the output
                swap_folder(tmp, path)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
    return path


@contextlib.contextmanager
@checks_arguments
def write_errors(path: str | os.PathLike) -> Iterator[None]:
    """Turn an ``OSError`` raised in the block into an :class:`OutputError` naming ``path``."""
    try:
        yield
    except OutputError:
        raise
    except OSError as exc:
        reason = {
            errno.ENOSPC: "the disk is full",
            errno.EDQUOT: "the disk quota is exceeded",
            errno.EACCES: "permission denied",
            errno.EPERM: "permission denied",
            errno.EROFS: "the file system is read-only",
            errno.ENOTDIR: "a part of the path is a file, not a folder",
            errno.EEXIST: "something is in the way",
        }.get(exc.errno or 0, exc.strerror or str(exc))  # no errno: the message
        if exc.errno is None and re.fullmatch(r"\d+ requested and \d+ written", str(exc)):
            # numpy's short write (ndarray.tofile) carries no errno: the disk filled up under it
            reason = f"the disk is full (ENOSPC: {exc})"
        where = f" ({exc.filename})" if exc.filename and os.fspath(exc.filename) != os.fspath(path) else ""
        raise OutputError(f"cannot write: {reason}{where}", path=path) from None
