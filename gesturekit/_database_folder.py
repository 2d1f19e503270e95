"""A matching database's folder on disk: writing it, and reading it back with every check; and the
staging folder an out-of-core build keeps beside it until the database is written.

The layout of the folder is described in :mod:`gesturekit.database`;
:meth:`~gesturekit.database.MatchingDatabase.save` and
:meth:`~gesturekit.database.MatchingDatabase.load` call :func:`write_database`
and :func:`read_database`. Reading trusts nothing: ``database.json`` is checked
against the structure writing produces and the arrays against it (shapes,
dtypes, every clip inside its take), arrays are never unpickled, and a
damaged folder is a :class:`~gesturekit.errors.DatabaseError` naming the file.
"""

from __future__ import annotations

import json
import os
import shutil
import uuid
import zipfile
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from . import limits
from ._database_audio import AudioStorage, encode_take_audio, read_take_audio, take_audio_fields
from ._io import DATABASE_CLIP_ARRAYS, read_json_marker
from ._version import __version__
from .bones import Skeleton
from .control import ATTRIBUTE_NAMES
from .errors import ConfigError, DatabaseError, GestureKitError, OutputError
from .features import LAYOUT
from .motion import AUDIO_SR
from .skeleton import JOINT_NAMES, POSE_FEATURE_INDICES, JointPresence

if TYPE_CHECKING:
    from .database import MatchingDatabase

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "CLIP_ARRAYS",
    "STAGING_VERSION",
    "write_database",
    "write_stats",
    "write_meta",
    "read_database",
    "staging_folder",
    "is_staging",
    "open_staging",
    "remove_staging",
]

FORMAT = "gesturekit-matching-database"
FORMAT_VERSION = 1
#: The staging folder of an out-of-core build (``.NAME.staging`` beside the database): its marker file
#: and format; a staged unit records the version, and one of another version is staged again.
STAGING_FORMAT = "gesturekit-database-staging"
STAGING_VERSION = 1
_MARKER = "staging.json"
# the per-clip arrays of a cut, each with M clips first (declared in _io); clip_take and clip_start index them
CLIP_ARRAYS = DATABASE_CLIP_ARRAYS
_INDEX_ARRAYS = ("clip_take", "clip_start")
_MESSAGES = {
    "no_folder": "no database folder here (build one with `gesturekit build-db`)",
    "no_file": "not a gesturekit database: database.json is missing",
    "other_format": "not a gesturekit matching database (unknown format)",
    "other_version": "database format version {found} is not supported by this gesturekit (format version "
    "{supported}); rebuild it with `gesturekit build-db --force`",
}


def write_database(
    db: MatchingDatabase, path: Path, *, overwrite: bool, inputs: Iterable[str | os.PathLike | None], locked: bool
) -> None:
    """Write ``db`` as the folder ``path`` by the rules of :func:`gesturekit.outputs.write_folder`.

    Raises
    ------
    OutputError
        See :func:`gesturekit.outputs.write_folder`.
    DatabaseError
        An array holds NaN or infinite values; nothing is written.
    """
    from .outputs import write_folder

    _check_finite(db, path)

    def fill(tmp: Path) -> None:
        for k, v in db.arrays.items():
            np.save(tmp / f"{k}.npy", np.ascontiguousarray(v), allow_pickle=False)
        write_stats(tmp / "stats.npz", db.stats)
        meta = dict(db.meta)
        if db.audio is not None:
            audio, meta = _stored_audio(db)
            np.save(tmp / "audio.npy", audio, allow_pickle=False)
        if db.overlap is not None:
            (tmp / "overlap").mkdir()
            for k, v in db.overlap.items():
                np.save(tmp / "overlap" / f"{k}.npy", np.ascontiguousarray(v), allow_pickle=False)
        write_meta(tmp, meta, n_clips=db.n_clips)

    write_folder(path, "database", fill, overwrite=overwrite, inputs=inputs, locked=locked)


def _stored_audio(db: MatchingDatabase) -> tuple[np.ndarray, dict]:
    """``audio.npy``'s array and ``database.json``'s content for the storage the build asked for.

    A database built in memory holds int16 at 16 kHz; when its build asked for another
    storage (``audio_format``, ``audio_rate``) each take is encoded here, and the takes'
    audio entries and the ``"audio"`` entry are written for it. A database that holds
    what its build asked for is written as it is.
    """
    meta = dict(db.meta)
    held = AudioStorage.from_meta(meta)
    build = meta.get("build", {})
    wanted = AudioStorage(format=build.get("audio_format", "pcm"), rate=build.get("audio_rate", AUDIO_SR))
    audio = np.asarray(db.audio)
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


def write_meta(folder: Path, meta: dict[str, Any], *, n_clips: int) -> None:
    """Write ``database.json`` (``meta`` with the counts of clips and takes) into ``folder``: the marker
    that lets a later ``--force`` recognise the folder, so written last."""
    meta = dict(meta)
    meta["counts"] = {"clips": int(n_clips), "takes": len(meta["takes"])}
    (folder / "database.json").write_text(json.dumps(meta, indent=1), encoding="utf-8")


def _check_finite(db: MatchingDatabase, path: Path) -> None:
    """Refuse to save arrays with NaN or infinite values (they would poison every search)."""
    parts = [("", db.arrays), ("overlap ", db.overlap or {}), ("z-scoring ", db.stats)]
    for where, arrays in parts:
        for k, v in arrays.items():
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
    if db.audio is not None and np.issubdtype(np.asarray(db.audio).dtype, np.floating):
        if not np.isfinite(db.audio).all():
            raise DatabaseError("the database's audio holds NaN or infinite values; nothing was written", path=path)


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

    arrays = {k: read(path / f"{k}.npy") for k in CLIP_ARRAYS + _INDEX_ARRAYS}
    stats = _read_stats(path)
    audio = read(path / "audio.npy") if (path / "audio.npy").exists() else None
    overlap = None
    if (path / "overlap").is_dir():
        overlap = {k: read(path / "overlap" / f"{k}.npy") for k in CLIP_ARRAYS + _INDEX_ARRAYS}
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


# ---- the staging folder -------------------------------------------------------------------------


def staging_folder(out: Path) -> Path:
    """The staging folder of a build of the database folder ``out``: ``.NAME.staging`` beside it."""
    from .outputs import beside_name

    return out.parent / beside_name(out, ".staging")


def is_staging(path: Path) -> bool:
    """Whether ``path`` is a staging folder gesturekit made (its ``staging.json`` says so)."""
    try:
        marker = limits.read_json(path / _MARKER)
    except GestureKitError:
        return False
    return isinstance(marker, dict) and marker.get("format") == STAGING_FORMAT


def open_staging(path: Path) -> None:
    """Make the staging folder ``path``, or reuse the one an interrupted build left (its unfinished
    units removed).

    Raises
    ------
    OutputError
        Something that is not a gesturekit staging folder is at ``path``.
    """
    from .outputs import write_errors

    with write_errors(path):
        if path.is_symlink() or (path.exists() and not is_staging(path)):
            raise OutputError(
                "is in the way of the build's staging folder and is not one gesturekit made; move it away", path=path
            )
        if not path.exists():
            tmp = path.parent / f"{path.name}.tmp-{uuid.uuid4().hex[:12]}"
            tmp.mkdir(parents=True)
            marker = {"format": STAGING_FORMAT, "version": STAGING_VERSION, "gesturekit": __version__}
            (tmp / _MARKER).write_text(json.dumps(marker), encoding="utf-8")
            os.replace(tmp, path)
            return
        for entry in path.iterdir():
            if ".tmp-" in entry.name:
                shutil.rmtree(entry, ignore_errors=True)


def remove_staging(path: Path) -> None:
    """Remove a staging folder gesturekit made (anything else is left alone)."""
    if is_staging(path) and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
