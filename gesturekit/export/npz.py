"""Motion and its companions (search records, settings) in one ``.npz`` archive.

Layout of the archive (every entry a plain ``.npy`` array, nothing pickled):

=================  ==================  =======================================
key                shape, dtype        meaning
=================  ==================  =======================================
``positions``      (frames, 55, 3) f4  pelvis-relative joint positions, metres
``fps``            () f8               frames per second
``joint_names``    (55,) unicode       :data:`gesturekit.skeleton.JOINT_NAMES`
``parents``        (55,) i8            :data:`gesturekit.skeleton.PARENTS`
``joint_status``   (55,) unicode       per joint ``recorded``, ``derived`` (placed
                                       from others) or ``absent`` (not in the
                                       data; sits on its parent); an archive
                                       without it holds a complete skeleton
``config``         () unicode          the settings that made the motion, JSON
``format_version`` () i8               :data:`FORMAT_VERSION`
any other name     any                 extra arrays (``knn_positions``, ...)
=================  ==================  =======================================

The same inputs always give the same bytes: entries are written in a fixed
order with a fixed time stamp, extra arrays sorted by name and the settings
as JSON with sorted keys.
"""

from __future__ import annotations

import io
import json
import os
import re
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .._arguments import checks_arguments
from .._io import Target, target_path, write_to
from ..errors import ConfigError, MotionFileError
from ..motion import Motion
from ..skeleton import JOINT_NAMES, JOINT_STATES, N_JOINTS, PARENTS, JointPresence

__all__ = ["FORMAT_VERSION", "RESERVED_KEYS", "save_npz", "load_npz"]

#: Version of the archive layout above; readers refuse newer versions.
FORMAT_VERSION = 1

#: Keys of the archive that extra arrays may not use.
RESERVED_KEYS = ("positions", "fps", "joint_names", "parents", "joint_status", "config", "format_version")

# the earliest time a zip entry can carry; a fixed stamp makes the bytes reproducible
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)
_KEY_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


@checks_arguments
def save_npz(
    path: Target,
    *,
    motion: Motion,
    arrays: Mapping[str, np.ndarray] | None = None,
    config: Mapping[str, Any] | None = None,
    overwrite: bool = False,
    compress: bool = True,
) -> Path | None:
    """Save a motion, extra arrays and its settings to an ``.npz`` archive.

    A path is written atomically to exactly ``path`` (no suffix is added); a binary file
    object gets the same bytes at its position. Either reads with ``np.load(..., allow_pickle=False)``.

    Parameters
    ----------
    path : str, os.PathLike or binary file object
        The archive to create, or where to write it (``io.BytesIO``, an open file).
    motion : Motion
        Positions (frames, 55, 3) in metres (exactly as they are), the frame rate and
        which joints are real (:attr:`Motion.presence`, stored as ``joint_status``).
    arrays : mapping of str to np.ndarray, optional
        Extra arrays, e.g. ``"knn_positions"`` (frames, 55, 3) or the search
        record's candidate indices. Names are identifiers (letters, digits,
        ``_``) other than :data:`RESERVED_KEYS`; any shape; numeric, boolean
        or string dtypes (object arrays would need pickling and are refused).
    config : mapping, optional
        The settings that made the motion; stored as JSON. Numpy scalars and
        arrays become numbers and lists, paths become strings.
    overwrite : bool
        Replace an existing file.
    compress : bool
        Deflate the entries (smaller, slower); both are deterministic.

    Returns
    -------
    pathlib.Path or None
        ``path``, the archive written; None for a file object.

    Raises
    ------
    ConfigError
        An extra array has a reserved or invalid name or an object dtype, the
        config is not JSON-serialisable, or ``path`` exists and ``overwrite``
        is False.
    """
    where = target_path(path, "motion.npz")
    if not isinstance(motion, Motion):
        raise ConfigError(f"motion must be a gesturekit Motion, got {type(motion).__name__}", path=where)
    entries: list[tuple[str, np.ndarray]] = [
        ("positions", np.ascontiguousarray(motion.positions, dtype=np.float32)),
        ("fps", np.array(float(motion.fps), dtype=np.float64)),
        ("joint_names", np.array(JOINT_NAMES, dtype=np.str_)),
        ("parents", np.asarray(PARENTS, dtype=np.int64)),
        ("joint_status", np.array(motion.presence.status, dtype=np.str_)),
        ("config", np.array(_config_json(config, where), dtype=np.str_)),
        ("format_version", np.array(FORMAT_VERSION, dtype=np.int64)),
    ]
    extra = arrays or {}
    for name in sorted(extra):
        entries.append((name, _checked_extra(name, extra[name], where)))
    for name, arr in entries:
        if (name == "positions" or name.endswith("_positions")) and np.issubdtype(arr.dtype, np.floating):
            bad = np.atleast_1d(~np.isfinite(arr).all(axis=tuple(range(1, arr.ndim))))
            if bad.any():
                raise ConfigError(
                    f"not written: {name} holds NaN or infinite values (from frame {int(np.argmax(bad))} on)",
                    path=where,
                )
    if overwrite and isinstance(path, (str, os.PathLike)):
        from ..outputs import check_output

        check_output(path, "file", overwrite=True)  # only an npz gesturekit wrote is replaced
    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED

    def write(f) -> None:
        with zipfile.ZipFile(f, "w", compression=method, allowZip64=True) as zf:
            for name, arr in entries:
                buf = io.BytesIO()
                np.lib.format.write_array(buf, arr, allow_pickle=False)
                info = zipfile.ZipInfo(f"{name}.npy", date_time=_ZIP_TIME)
                info.compress_type = method
                info.external_attr = 0o644 << 16
                zf.writestr(info, buf.getvalue())

    return write_to(path, write, overwrite=overwrite)


def _config_json(config: Mapping[str, Any] | None, path) -> str:
    if config is None:
        config = {}
    if not isinstance(config, Mapping):
        raise ConfigError(f"config must be a mapping, got {type(config).__name__}", path=path)
    try:
        return json.dumps(dict(config), sort_keys=True, default=_json_default, ensure_ascii=False)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"config cannot be stored as JSON: {e}", path=path) from None


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray) and obj.dtype != object:
        return obj.tolist()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if isinstance(obj, (set, frozenset)):
        return sorted(obj)
    raise TypeError(f"{type(obj).__name__} object is not JSON-serialisable")


def _checked_extra(name: str, value: Any, path) -> np.ndarray:
    if not isinstance(name, str) or not _KEY_RE.match(name):
        raise ConfigError(f"extra array name {name!r} must be letters, digits and _ (not first a digit)", path=path)
    if name in RESERVED_KEYS:
        raise ConfigError(f"extra array name {name!r} is reserved; reserved: {', '.join(RESERVED_KEYS)}", path=path)
    arr = np.asarray(value)
    if arr.dtype.hasobject or arr.dtype.kind not in "biufcSUmM":
        raise ConfigError(
            f"extra array {name!r} has dtype {arr.dtype}, which cannot be saved without pickling", path=path
        )
    # (np.ascontiguousarray would turn a 0-d array into shape (1,))
    return np.asarray(arr, order="C")


@checks_arguments
def load_npz(path: str | os.PathLike) -> tuple[Motion, dict[str, np.ndarray], dict[str, Any]]:
    """Load an archive written by :func:`save_npz`.

    Nothing is unpickled: archives holding object arrays are refused.

    Parameters
    ----------
    path : str or os.PathLike
        The archive.

    Returns
    -------
    motion : Motion
        Positions (frames, 55, 3) float32 metres, fps and ``joints`` (from ``joint_status``;
        None, a complete skeleton, when the archive has none or every joint is recorded).
    arrays : dict of str to np.ndarray
        The extra arrays, by name.
    config : dict
        The stored settings (``{}`` when the archive has none).

    Raises
    ------
    MotionFileError
        The file is missing, not an npz archive, holds pickled data, lacks one
        of the keys, describes another skeleton or holds invalid values.
    """
    path = Path(path)
    if not path.is_file():
        raise MotionFileError("file not found", path=path)
    if not zipfile.is_zipfile(path):
        raise MotionFileError("not an npz archive (not a zip file)", path=path)
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {key: z[key] for key in z.files}
    except ValueError as e:
        # np.load raises ValueError for object arrays when pickles are not allowed
        if "pickle" in str(e):
            raise MotionFileError("holds object arrays that only unpickling could read; refused", path=path) from None
        raise MotionFileError(f"cannot read the archive: {e}", path=path) from None
    except (OSError, zipfile.BadZipFile, EOFError, KeyError) as e:
        raise MotionFileError(f"cannot read the archive: {e}", path=path) from None

    missing = [k for k in ("positions", "fps", "joint_names", "parents") if k not in data]
    if missing:
        raise MotionFileError(
            f"missing key{'s' if len(missing) > 1 else ''} {', '.join(missing)}; "
            f"found {', '.join(sorted(data)) or 'nothing'}",
            path=path,
        )
    if "format_version" in data:
        version = data["format_version"]
        if version.shape != () or version.dtype.kind not in "iu":
            raise MotionFileError("format_version must be an integer scalar", path=path)
        if int(version) > FORMAT_VERSION:
            raise MotionFileError(
                f"format version {int(version)} is newer than this gesturekit reads ({FORMAT_VERSION})", path=path
            )

    names = data["joint_names"]
    parents = data["parents"]
    if names.dtype.kind != "U" or tuple(names.tolist()) != JOINT_NAMES:
        raise MotionFileError(f"joint_names are not those of the {N_JOINTS}-joint skeleton", path=path)
    if parents.shape != PARENTS.shape or parents.dtype.kind not in "iu" or not np.array_equal(parents, PARENTS):
        raise MotionFileError(f"parents are not those of the {N_JOINTS}-joint skeleton", path=path)

    positions = data["positions"]
    if positions.ndim != 3 or positions.shape[1:] != (N_JOINTS, 3) or positions.dtype.kind not in "fiu":
        raise MotionFileError(
            f"positions must be numbers of shape (frames, {N_JOINTS}, 3), got {positions.dtype} {positions.shape}",
            path=path,
        )
    fps = data["fps"]
    if fps.shape != () or fps.dtype.kind not in "fiu" or not np.isfinite(fps) or not fps > 0:
        raise MotionFileError(f"fps must be one positive number, got {fps!r}", path=path)

    joints = _joint_status(data.get("joint_status"), path)

    config: dict[str, Any] = {}
    if "config" in data:
        text = data["config"]
        if text.shape != () or text.dtype.kind != "U":
            raise MotionFileError("config must be a JSON string", path=path)
        try:
            config = json.loads(str(text))
        except json.JSONDecodeError as e:
            raise MotionFileError(f"config is not valid JSON: {e}", path=path) from None
        if not isinstance(config, dict):
            raise MotionFileError("config must be a JSON object", path=path)

    extras = {k: v for k, v in data.items() if k not in RESERVED_KEYS}
    return Motion(positions.astype(np.float32, copy=False), float(fps), joints), extras, config


def _joint_status(status: np.ndarray | None, path: Path) -> JointPresence | None:
    """The archive's ``joint_status`` as a presence; None (every joint recorded) when absent or full."""
    if status is None:
        return None  # written before archives listed which joints are real: a complete skeleton
    if status.shape != (N_JOINTS,) or status.dtype.kind != "U":
        raise MotionFileError(f"joint_status must be {N_JOINTS} strings, got {status.dtype} {status.shape}", path=path)
    bad = sorted(set(status.tolist()) - set(JOINT_STATES))
    if bad:
        raise MotionFileError(f"joint_status holds {bad}; expected {', '.join(JOINT_STATES)}", path=path)
    presence = JointPresence(tuple(status.tolist()))
    return None if presence.is_full else presence
