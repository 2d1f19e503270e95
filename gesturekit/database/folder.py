"""A matching database's folder on disk: its format, writing it, and reading it back with every check.

A database is a folder::

    database.json        format version, feature layout, build config, takes, thresholds
    F.npy  (M,64,112)    z-scored audio features f_t          float32
    P.npy  (M,64,96)     z-scored pose features p_t           float32
    G.npy  (M,64,165)    output poses g_t, metres             float32
    A.npy  (M,64,28)     cGAN audio input (m_t, dm_t), raw    float32
    valid.npy (M,64)     frame may start a segment            bool
    attributes.npy (M,64,9)  control attributes               float32
    pose_track.npy (M,70,24) raw feature-joint positions of frames s..s+69
    clip_take.npy, clip_start.npy (M,)  take index and start frame of each clip
    stats.npz            z-scoring statistics (F, P, A)
    audio.npy            all takes' audio, int16 at 16 kHz, a lower rate or FLAC (optional;
                         :mod:`gesturekit.database.audio`)
    overlap/             the overlapping cut, same arrays per window (optional)

Every array is a plain ``.npy`` (memory-mapped on load, never pickled); the
folder is written under a temporary name and swapped into place, by the rules
of :mod:`gesturekit.outputs` (``database.json`` is the marker that lets
``--force`` recognise a database, so it is written last).

:meth:`~gesturekit.database.MatchingDatabase.save` writes a database held in
memory with :func:`write_database`; a build from staged takes writes the folder
array by array, front to back, through a :class:`FolderOut`
(:func:`gesturekit.database.build.assemble`). Reading
(:func:`read_database`) trusts nothing: ``database.json`` is checked against the
structure writing produces and the arrays against it (shapes, dtypes, every
clip inside its take), arrays are never unpickled, and a damaged folder is a
:class:`~gesturekit.errors.DatabaseError` naming the file.
"""

from __future__ import annotations

import json
import os
import shutil
import zipfile
from collections.abc import Iterable
from pathlib import Path
from typing import IO, Any, Literal

import numpy as np

from .. import limits
from .._arguments import checks_arguments
from ..bones import Skeleton
from ..control import ATTRIBUTE_NAMES
from ..errors import ConfigError, DatabaseError, GestureKitError
from ..features import LAYOUT
from ..folders import read_json_marker
from ..motion import AUDIO_SR
from ..skeleton import JOINT_NAMES, POSE_FEATURE_INDICES, JointPresence
from .audio import AudioStorage, encode_take_audio, read_take_audio, take_audio_fields

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "CLIP_ARRAYS",
    "INDEX_ARRAYS",
    "FOLDER_FILES",
    "write_database",
    "write_stats",
    "write_meta",
    "read_database",
    "NpyWriter",
    "FolderOut",
]

#: ``database.json``'s ``format`` and ``format_version``: a folder of another version is refused on load.
FORMAT = "gesturekit-matching-database"
FORMAT_VERSION = 1
#: The per-clip arrays of a cut (``NAME.npy``), each with M clips first.
CLIP_ARRAYS = ("F", "P", "G", "A", "valid", "attributes", "pose_track")
#: The arrays that index the clips: each clip's take and its first frame in the take.
INDEX_ARRAYS = ("clip_take", "clip_start")
#: Every name a database folder can hold, its marker included (what lets a folder whose
#: ``database.json`` was cut short be recognised and rebuilt in place).
FOLDER_FILES = frozenset(
    [f"{a}.npy" for a in (*CLIP_ARRAYS, *INDEX_ARRAYS, "audio")] + ["stats.npz", "overlap", "database.json"]
)
_CHUNK_BYTES = 64 << 20  # attribute columns are read in pieces of this size
_MESSAGES = {
    "no_folder": "no database folder here (build one with `gesturekit build-db`)",
    "no_file": "not a gesturekit database: database.json is missing",
    "other_format": "not a gesturekit matching database (unknown format)",
    "other_version": "database format version {found} is not supported by this gesturekit (format version "
    "{supported}); rebuild it with `gesturekit build-db --force`",
}


@checks_arguments
def write_database(
    path: Path,
    *,
    meta: dict[str, Any],
    arrays: dict[str, np.ndarray],
    stats: dict[str, np.ndarray],
    audio: np.ndarray | None,
    overlap: dict[str, np.ndarray] | None,
    overwrite: bool,
    inputs: Iterable[str | os.PathLike | None],
    locked: bool,
) -> None:
    """Write a database's parts as the folder ``path`` by the rules of :func:`gesturekit.outputs.write_folder`.

    Parameters
    ----------
    path : Path
        The database folder.
    meta, arrays, stats, audio, overlap
        The database: ``database.json``'s content (its ``counts`` are written anew), the
        arrays of :data:`CLIP_ARRAYS` and :data:`INDEX_ARRAYS` (M clips first), the z-scoring
        vectors, ``audio.npy`` (or None) and the overlapping cut (or None).
    overwrite, inputs, locked
        See :func:`gesturekit.outputs.write_folder`.

    Raises
    ------
    OutputError
        See :func:`gesturekit.outputs.write_folder`.
    DatabaseError
        An array holds NaN or infinite values; nothing is written.
    """
    from ..outputs import write_folder

    _check_finite(arrays, overlap, stats, audio, path)

    def fill(tmp: Path) -> None:
        for k, v in arrays.items():
            np.save(tmp / f"{k}.npy", np.ascontiguousarray(v), allow_pickle=False)
        write_stats(tmp / "stats.npz", stats)
        held = dict(meta)
        if audio is not None:
            stored, held = _stored_audio(audio, meta)
            np.save(tmp / "audio.npy", stored, allow_pickle=False)
        if overlap is not None:
            (tmp / "overlap").mkdir()
            for k, v in overlap.items():
                np.save(tmp / "overlap" / f"{k}.npy", np.ascontiguousarray(v), allow_pickle=False)
        write_meta(tmp, held, n_clips=int(arrays["clip_take"].shape[0]))

    write_folder(path, "database", fill, overwrite=overwrite, inputs=inputs, locked=locked)


def _stored_audio(audio: np.ndarray, meta: dict[str, Any]) -> tuple[np.ndarray, dict]:
    """``audio.npy``'s array and ``database.json``'s content for the storage the build asked for.

    A database whose audio is held as int16 at 16 kHz while its build asked for another
    storage (``audio_format``, ``audio_rate``) has each take encoded here, and the takes'
    audio entries and the ``"audio"`` entry are written for it. A database that holds
    what its build asked for is written as it is.
    """
    meta = dict(meta)
    held = AudioStorage.from_meta(meta)
    build = meta.get("build", {})
    wanted = AudioStorage(format=build.get("audio_format", "pcm"), rate=build.get("audio_rate", AUDIO_SR))
    audio = np.asarray(audio)
    if wanted == held:
        return audio, meta
    parts, takes, offset = [], [], 0
    for t in meta["takes"]:
        # the default holds the int16 samples themselves: encoded from them, with no round trip through float
        a0 = t["audio_offset"]
        samples = audio[a0 : a0 + t["audio_samples"]] if held.is_default else read_take_audio(audio, t, held)
        encoded = encode_take_audio(samples, wanted)
        parts.append(encoded.data)
        entry = {k: v for k, v in t.items() if k != "audio_size"}
        takes.append({**entry, **take_audio_fields(encoded, offset, wanted)})
        offset += encoded.data.size
    meta["takes"] = takes
    meta.pop("audio", None)
    if wanted.to_meta() is not None:
        meta["audio"] = wanted.to_meta()
    return (np.concatenate(parts) if parts else np.zeros(0, wanted.dtype)), meta


@checks_arguments
def write_stats(path: Path, stats: dict[str, Any]) -> None:
    """Write the z-scoring statistics as ``stats.npz``, the same bytes for the same statistics.

    :func:`numpy.savez` stamps each member with the time of writing; here every
    member carries the zip format's earliest date, so that two builds of the
    same takes give identical folders.
    """
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_STORED) as zf:
        for k, v in stats.items():
            info = zipfile.ZipInfo(f"{k}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.external_attr = 0o644 << 16
            with zf.open(info, "w") as member:
                np.lib.format.write_array(member, np.asarray(v), allow_pickle=False)


@checks_arguments
def write_meta(folder: Path, meta: dict[str, Any], *, n_clips: int) -> None:
    """Write ``database.json`` (``meta`` with the counts of clips and takes) into ``folder``: the marker
    that lets a later ``--force`` recognise the folder, so written last."""
    meta = dict(meta)
    meta["counts"] = {"clips": int(n_clips), "takes": len(meta["takes"])}
    (folder / "database.json").write_text(json.dumps(meta, indent=1), encoding="utf-8")


def _check_finite(
    arrays: dict[str, np.ndarray],
    overlap: dict[str, np.ndarray] | None,
    stats: dict[str, np.ndarray],
    audio: np.ndarray | None,
    path: Path,
) -> None:
    """Refuse to save arrays with NaN or infinite values (they would poison every search)."""
    parts = [("", arrays), ("overlap ", overlap or {}), ("z-scoring ", stats)]
    for where, group in parts:
        for k, v in group.items():
            v = np.asarray(v) if where == "z-scoring " else v
            if not np.issubdtype(v.dtype, np.floating):
                continue
            # clip by clip, so that a memory-mapped array is never copied whole
            flat = v.reshape(v.shape[0], -1) if v.ndim > 1 else v.reshape(1, -1)
            for i in range(0, flat.shape[0], 256):
                ok = np.isfinite(flat[i : i + 256]).all(axis=1)
                if not ok.all():
                    row = i + int(np.argmin(ok))
                    at = f" (clip {row})" if v.ndim > 1 and not where else ""
                    raise DatabaseError(
                        f"the database's {where}array {k} holds NaN or infinite values{at}: a take's motion or "
                        "audio features are not finite; nothing was written",
                        path=path,
                    )
    if audio is not None and np.issubdtype(np.asarray(audio).dtype, np.floating):
        if not np.isfinite(audio).all():
            raise DatabaseError("the database's audio holds NaN or infinite values; nothing was written", path=path)


@checks_arguments
def read_database(path: Path, *, mmap: bool) -> dict:
    """Read and check a database folder.

    Returns
    -------
    dict
        ``meta``, ``arrays``, ``stats``, ``audio`` (or None), ``overlap`` (or
        None): the keyword arguments of :class:`~gesturekit.database.MatchingDatabase`.

    Raises
    ------
    DatabaseError
        Missing folder or files, another format or format version, another
        feature layout, or files that are damaged or disagree with each other.
    """
    meta = read_json_marker(
        path, "database.json", marker_format=FORMAT, version=FORMAT_VERSION, error=DatabaseError, messages=_MESSAGES
    )
    if meta.get("layout") != LAYOUT.signature():
        raise DatabaseError(
            "database was built with another feature layout; rebuild it with `gesturekit build-db --force`", path=path
        )
    _check_meta(meta, path)
    mode: Literal["r"] | None = "r" if mmap else None

    def read(p: Path):
        if os.path.lexists(p):
            limits.check_regular(p, what=f"{p.name} ", error=DatabaseError, owner=path)
        try:
            return np.load(p, mmap_mode=mode, allow_pickle=False)
        except FileNotFoundError:
            raise DatabaseError(f"{p.name} is missing; the database is incomplete", path=path) from None
        except (ValueError, EOFError) as exc:
            raise DatabaseError(f"{p.name} cannot be read ({exc})", path=path) from None
        except OSError as exc:
            raise DatabaseError(f"{p.name} cannot be read ({exc.strerror or exc})", path=path) from None

    arrays = {k: read(path / f"{k}.npy") for k in CLIP_ARRAYS + INDEX_ARRAYS}
    stats = _read_stats(path)
    audio = read(path / "audio.npy") if (path / "audio.npy").exists() else None
    overlap = None
    if (path / "overlap").is_dir():
        overlap = {k: read(path / "overlap" / f"{k}.npy") for k in CLIP_ARRAYS + INDEX_ARRAYS}
    _check_arrays(meta, arrays, stats, path, where="")
    _check_clip_order(meta, arrays["clip_take"], path)
    if overlap is not None:
        _check_arrays(meta, overlap, stats, path, where="overlap/")
    if audio is not None:
        storage = AudioStorage.from_meta(meta)
        size = "audio_samples" if storage.is_default else "audio_size"
        need = max((t["audio_offset"] + t[size] for t in meta["takes"]), default=0)
        what = "int16 samples" if storage.format == "pcm" else "uint8 bytes of FLAC streams"
        if audio.ndim != 1 or audio.dtype != storage.dtype or audio.shape[0] < need:
            raise DatabaseError(
                f"audio.npy must be {what}, at least {need} of them; found {audio.dtype} of shape {audio.shape}",
                path=path,
            )
    return {"meta": meta, "arrays": arrays, "stats": stats, "audio": audio, "overlap": overlap}


_STATS_KEYS = {"F": LAYOUT.audio_dim, "P": LAYOUT.pose_dim, "A": LAYOUT.cgan_audio_dim}


def _is_int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x)


def _check_meta(meta: dict, path: Path) -> None:
    """``database.json`` against the structure :func:`write_database` writes."""

    def bad(what: str):
        return DatabaseError(f"database.json: {what}; the file is damaged (rebuild the database)", path=path)

    for key, kind in (("build", dict), ("takes", list), ("thresholds", dict), ("attribute_names", list)):
        if key not in meta:
            raise bad(f"'{key}' is missing")
        if not isinstance(meta[key], kind):
            raise bad(f"'{key}' must be {'an object' if kind is dict else 'a list'}, found {type(meta[key]).__name__}")
    build = meta["build"]
    if not (_is_int(build.get("clip_frames")) and build["clip_frames"] > 0):
        raise bad(f"build.clip_frames must be a positive integer, found {build.get('clip_frames')!r}")
    for key in ("label", "source"):
        if not isinstance(build.get(key, ""), str):
            raise bad(f"build.{key} must be a string, found {type(build[key]).__name__}")
    stride = build.get("overlap_stride")
    if stride is not None and not (_is_int(stride) and stride > 0):
        raise bad(f"build.overlap_stride must be a positive integer or null, found {stride!r}")
    names = meta["attribute_names"]
    if names != list(ATTRIBUTE_NAMES):
        raise bad(f"attribute_names must be {', '.join(ATTRIBUTE_NAMES)}")
    thresholds = meta["thresholds"]
    for name in names:
        t = thresholds.get(name)
        if not (isinstance(t, list) and len(t) == 2 and all(_is_number(v) for v in t) and t[0] <= t[1]):
            raise bad(f"thresholds of {name} must be [low, high], two finite numbers, found {t!r}")
    takes = meta["takes"]
    if not takes:
        raise bad("'takes' is empty: the database has no takes")
    seen = set()
    for i, t in enumerate(takes):
        if not isinstance(t, dict):
            raise bad(f"takes[{i}] must be an object, found {type(t).__name__}")
        if not isinstance(t.get("name"), str) or not t["name"]:
            raise bad(f"takes[{i}].name must be a non-empty string")
        if t["name"] in seen:
            raise bad(f"take name {t['name']!r} appears twice")
        seen.add(t["name"])
        if not isinstance(t.get("sources"), dict):
            raise bad(f"takes[{i}].sources must be an object, found {type(t.get('sources')).__name__}")
        for key in ("n_frames", "first_clip", "n_clips", "audio_offset", "audio_samples"):
            if not (_is_int(t.get(key)) and t[key] >= 0):
                raise bad(f"takes[{i}].{key} must be an integer >= 0, found {t.get(key)!r}")
    try:
        storage = AudioStorage.from_meta(meta)
    except DatabaseError as exc:
        raise DatabaseError(exc.problem, path=path) from None
    if not storage.is_default:
        for i, t in enumerate(takes):
            if not (_is_int(t.get("audio_size")) and t["audio_size"] >= 0):
                raise bad(f"takes[{i}].audio_size must be an integer >= 0, found {t.get('audio_size')!r}")
    joints = meta.get("joints")
    if joints is not None:
        try:
            JointPresence(tuple(joints))
        except (TypeError, ValueError) as exc:
            raise bad(f"'joints' must list the status of each of the 55 joints ({exc})") from None
    skeleton = meta.get("skeleton")
    if skeleton is not None:
        try:
            Skeleton.from_json(skeleton)
        except ConfigError as exc:
            raise bad(f"'skeleton': {exc.problem}") from None
    counts = meta.get("counts")
    if counts is not None:
        if not (isinstance(counts, dict) and _is_int(counts.get("clips")) and _is_int(counts.get("takes"))):
            raise bad(f"'counts' must hold the integers clips and takes, found {counts!r}")
        if counts["takes"] != len(takes):
            raise bad(f"counts.takes is {counts['takes']} but {len(takes)} takes are listed")


# stats.npz holds six vectors of a few hundred numbers: far below this, and a zip bomb far above
_STATS_MAX_BYTES = 1 << 20


def _read_stats(path: Path) -> dict[str, np.ndarray]:
    """``stats.npz``: the six z-scoring vectors, finite, of the layout's sizes (never unpickled)."""
    f = path / "stats.npz"
    if os.path.lexists(f):
        limits.check_npz(f, max_bytes=_STATS_MAX_BYTES, what="stats.npz ", error=DatabaseError, owner=path)
    try:
        with np.load(f, allow_pickle=False) as z:
            stats = {k: np.asarray(z[k]) for k in z.files}
    except FileNotFoundError:
        raise DatabaseError("stats.npz is missing; the database is incomplete", path=path) from None
    except (ValueError, EOFError, zipfile.BadZipFile) as exc:
        # object arrays (pickles) land here too: allow_pickle=False refuses them
        raise DatabaseError(f"stats.npz cannot be read ({exc})", path=path) from None
    except OSError as exc:
        raise DatabaseError(f"stats.npz cannot be read ({exc.strerror or exc})", path=path) from None
    for key, dim in _STATS_KEYS.items():
        for part in ("mean", "std"):
            a = stats.get(f"{key}_{part}")
            if a is None:
                raise DatabaseError(f"stats.npz lacks {key}_{part}", path=path)
            if a.shape != (dim,) or not np.issubdtype(a.dtype, np.floating) or not np.isfinite(a).all():
                raise DatabaseError(
                    f"stats.npz: {key}_{part} must be {dim} finite numbers, found {a.dtype} of shape {a.shape}",
                    path=path,
                )
    return stats


def _check_arrays(meta: dict, arrays: dict, stats: dict, path: Path, *, where: str) -> None:
    """Shapes and dtypes of one cut's arrays, and every clip inside its take (index arrays only)."""
    L = meta["build"]["clip_frames"]
    ct, cs = arrays["clip_take"], arrays["clip_start"]
    for name, a in (("clip_take", ct), ("clip_start", cs)):
        if a.ndim != 1 or not np.issubdtype(a.dtype, np.integer):
            raise DatabaseError(
                f"{where}{name}.npy must be integers of shape (clips,), found {a.dtype} of shape {a.shape}", path=path
            )
    m = ct.shape[0]
    if m == 0:
        raise DatabaseError(f"{where}clip_take.npy: the database has no clips", path=path)
    if cs.shape[0] != m:
        raise DatabaseError(f"{where}clip_start.npy has {cs.shape[0]} clips, clip_take.npy {m}", path=path)
    if not where and meta.get("counts") is not None and meta["counts"]["clips"] != m:
        raise DatabaseError(f"database.json counts {meta['counts']['clips']} clips but the arrays hold {m}", path=path)
    expected = {
        "F": (m, L, stats["F_mean"].shape[0]),
        "P": (m, L, stats["P_mean"].shape[0]),
        "G": (m, L, len(JOINT_NAMES) * 3),
        "A": (m, L, stats["A_mean"].shape[0]),
        "valid": (m, L),
        "attributes": (m, L, len(ATTRIBUTE_NAMES)),
        "pose_track": (m, L + LAYOUT.pose_lookahead, 3 * len(POSE_FEATURE_INDICES)),
    }
    for k, shape in expected.items():
        if arrays[k].shape != shape:
            raise DatabaseError(
                f"{where}{k}.npy has shape {arrays[k].shape}, expected {shape} ({m} clips of {L} frames)", path=path
            )
    takes = meta["takes"]
    ti = np.asarray(ct, dtype=np.int64)
    if ti.min() < 0 or ti.max() >= len(takes):
        raise DatabaseError(
            f"{where}clip_take.npy holds take index {int(ti.min() if ti.min() < 0 else ti.max())}; "
            f"the database has takes 0..{len(takes) - 1}",
            path=path,
        )
    start = np.asarray(cs, dtype=np.int64)
    n_frames = np.array([t["n_frames"] for t in takes], dtype=np.int64)
    outside = (start < 0) | (start + L > n_frames[ti])
    if outside.any():
        c = int(np.flatnonzero(outside)[0])
        raise DatabaseError(
            f"{where}clip_start.npy: clip {c} starts at frame {int(start[c])}, outside take "
            f"{takes[ti[c]]['name']!r} of {int(n_frames[ti[c]])} frames (clips of {L} frames)",
            path=path,
        )


def _check_clip_order(meta: dict, clip_take: np.ndarray, path: Path) -> None:
    """Each take's clips are the ``n_clips`` consecutive clips from ``first_clip`` (what the tables and the
    search's take boundaries assume)."""
    takes = meta["takes"]
    first = np.array([t["first_clip"] for t in takes], dtype=np.int64)
    n = np.array([t["n_clips"] for t in takes], dtype=np.int64)
    m = clip_take.shape[0]
    if n.sum() != m or not np.array_equal(first, np.concatenate([[0], np.cumsum(n)[:-1]])):
        raise DatabaseError(
            f"database.json: the takes' first_clip/n_clips do not cover the {m} clips of clip_take.npy", path=path
        )
    if not np.array_equal(np.asarray(clip_take), np.repeat(np.arange(len(takes)), n)):
        raise DatabaseError("clip_take.npy does not match the takes' first_clip/n_clips in database.json", path=path)


# ---- writing a folder front to back -------------------------------------------------------------


class NpyWriter:
    """An ``.npy`` file written front to back: its header for the final shape, then rows in order.

    The bytes are those :func:`numpy.save` writes for the whole array. Rows are
    appended with plain writes, not through a memory map: pages of a mapped
    output count towards the process's resident memory until they are unmapped,
    which for a whole dataset is the dataset's size.

    Parameters
    ----------
    path : Path
        The file to write (created).
    dtype : np.dtype
    shape : tuple of int
        The whole array's shape, rows first.
    """

    def __init__(self, path: Path, dtype: np.dtype, shape: tuple[int, ...]) -> None:
        self.path, self.dtype, self.shape = path, np.dtype(dtype), shape
        self.rows = 0
        self.file: IO[bytes] = open(path, "wb")  # noqa: SIM115 (closed by close(), the writers outlive one block)
        header = {"descr": np.lib.format.dtype_to_descr(self.dtype), "fortran_order": False, "shape": shape}
        np.lib.format.write_array_header_1_0(self.file, header)

    def write(self, rows: np.ndarray) -> None:
        """Append ``rows`` (this dtype, this row shape)."""
        if rows.dtype != self.dtype or rows.shape[1:] != self.shape[1:]:
            raise GestureKitError(f"{self.path.name}: staged rows of {rows.dtype} {rows.shape} do not fit {self.shape}")
        self.file.write(np.ascontiguousarray(rows).tobytes())
        self.rows += rows.shape[0]

    def copy_from(self, path: Path) -> None:
        """Append the rows of the ``.npy`` file ``path`` (of this dtype and row shape) byte for byte."""
        with open(path, "rb") as src:
            version = np.lib.format.read_magic(src)
            read_header = (
                np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            )
            shape, fortran, dtype = read_header(src)
            if fortran or dtype != self.dtype or tuple(shape[1:]) != self.shape[1:]:
                raise GestureKitError(f"{path} holds {dtype} {shape}; cannot append it to {self.shape}")
            shutil.copyfileobj(src, self.file, 16 << 20)
        self.rows += int(shape[0])

    def close(self) -> None:
        """Close the file; every row of the shape must have been written."""
        self.file.close()
        if self.rows != self.shape[0]:
            raise GestureKitError(f"{self.path.name}: wrote {self.rows} rows of {self.shape[0]}")

    def __enter__(self) -> NpyWriter:
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is None:
            self.close()
        else:  # the error that stopped the writing is the one to report, not the rows missing after it
            self.file.close()


def column_percentiles(
    path: Path, percentiles: tuple[float, float], *, chunk_bytes: int = _CHUNK_BYTES
) -> dict[str, list[float]]:
    """Low and high percentiles of each attribute over every frame of the ``attributes.npy`` at ``path``.

    Read a column at a time in pieces of about ``chunk_bytes`` (float64, as the thresholds have
    always been computed): the same numbers as :func:`numpy.percentile` over the whole column.

    Returns
    -------
    dict
        Attribute name -> [low, high].
    """
    n_attr = len(ATTRIBUTE_NAMES)
    out: dict[str, list[float]] = {}
    with open(path, "rb") as f:
        np.lib.format.read_magic(f)
        shape, _fortran, dtype = np.lib.format.read_array_header_1_0(f)
        start = f.tell()
        frames = int(np.prod(shape[:-1]))
        step = max(1, chunk_bytes // (n_attr * dtype.itemsize))
        for i, name in enumerate(ATTRIBUTE_NAMES):
            col = np.empty(frames, dtype=np.float64)
            f.seek(start)
            for lo in range(0, frames, step):
                rows = np.fromfile(f, dtype=dtype, count=min(step, frames - lo) * n_attr)
                col[lo : lo + rows.shape[0] // n_attr] = rows.reshape(-1, n_attr)[:, i]
            out[name] = [float(v) for v in np.percentile(col, list(percentiles))]
    return out


class FolderOut:
    """A database folder as :func:`gesturekit.database.build.assemble` writes it: each array an
    ``.npy`` file written front to back (:class:`NpyWriter`), so that only a few takes are in
    memory at once.

    Parameters
    ----------
    folder : Path
        An empty folder (the output's temporary folder).
    """

    def __init__(self, folder: Path) -> None:
        self.folder = folder

    def array(self, cut: str, name: str, dtype: np.dtype, shape: tuple[int, ...]) -> NpyWriter:
        """The writer of array ``name`` of the cut ``cut`` (``""``, or ``"overlap"``: its sub-folder)."""
        sub = self.folder / cut if cut else self.folder
        sub.mkdir(exist_ok=True)
        return NpyWriter(sub / f"{name}.npy", dtype, shape)

    def thresholds(self, percentiles: tuple[float, float]) -> dict[str, list[float]]:
        """The attributes' thresholds over every frame of the ``attributes.npy`` written."""
        return column_percentiles(self.folder / "attributes.npy", percentiles)

    def finish(self, meta: dict[str, Any], stats: dict[str, np.ndarray], *, n_clips: int) -> None:
        """Write ``stats.npz``, then ``database.json`` (the marker, last)."""
        write_stats(self.folder / "stats.npz", stats)
        write_meta(self.folder, meta, n_clips=n_clips)
