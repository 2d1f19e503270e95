"""MatchingDatabase: the clips the search matches against, with their features, poses and attributes.

Features are computed on each whole take (so look-ahead near a clip's end uses
the real following frames), then the take is cut into non-overlapping clips of
``clip_frames`` frames; the tail that does not fill a clip is dropped. On
request a second, overlapping cut (stride ``overlap_stride``) is stored for
training the refiner. The folder a database is saved as is described in
:mod:`gesturekit.database.folder`; building it, in :mod:`gesturekit.database.build`.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any, overload

import numpy as np

from ..bones import Skeleton
from ..control import ATTRIBUTE_UNITS
from ..errors import ConfigError, DatabaseError
from ..features import ZScore, audio_frame_features, cgan_audio_features, stack_audio_features
from ..motion import AUDIO_SR, Take
from ..skeleton import JointPresence
from .audio import AudioStorage, read_take_audio
from .build import build_in_memory
from .config import BuildConfig
from .folder import read_database, write_database

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["MatchingDatabase"]


class _Array(property):
    """A read-only property of :class:`MatchingDatabase` that is one of its clip arrays
    (``db.arrays[key]``), documented by ``doc``; type checkers and IDEs see an ``np.ndarray``."""

    def __init__(self, key: str, doc: str) -> None:
        super().__init__(lambda db: db.arrays[key])
        self.__doc__ = doc  # on the instance: the class's own docstring would shadow property's doc

    @overload
    def __get__(self, db: None, owner: type, /) -> _Array: ...
    @overload
    def __get__(self, db: Any, owner: type | None = None, /) -> np.ndarray: ...
    def __get__(self, db: Any, owner: type | None = None, /) -> Any:
        return super().__get__(db, owner)


class MatchingDatabase:
    """The matching database of the search: clips with their features, poses and attributes.

    Build one with :meth:`build` (from :class:`~gesturekit.motion.Take` objects)
    and :meth:`save`; open one with :meth:`load`. Array properties (shapes for
    M clips of 64 frames): :attr:`audio_features` (M,64,112), :attr:`pose_features`
    (M,64,96), :attr:`poses` (M,64,165), :attr:`cgan_audio_features` (M,64,28),
    :attr:`valid` (M,64), :attr:`attributes` (M,64,9), :attr:`pose_track` (M,70,24),
    :attr:`clip_take` (M,), :attr:`clip_start` (M,); the paper's letters ``F``, ``P``,
    ``G`` and ``A`` name the first four too.
    """

    def __init__(
        self,
        *,
        meta: dict,
        arrays: dict,
        stats: dict,
        audio: np.ndarray | None = None,
        overlap: dict[str, np.ndarray] | None = None,
        path: str | os.PathLike[str] | None = None,
    ):
        self.meta = meta
        self.arrays = arrays
        self.stats = stats
        self.audio = audio
        self.overlap = overlap
        self.path = None if path is None else Path(path)

    # ---- array access -------------------------------------------------------------------
    # readable names first; the paper's letters (Habibie et al. 2022, Sec. 3) are aliases below
    audio_features = _Array("F", "The z-scored audio features f_t of every clip frame, shape (M, 64, 112), float32.")
    pose_features = _Array("P", "The z-scored pose features p_t of every clip frame, shape (M, 64, 96), float32.")
    poses = _Array("G", "The output poses g_t: 55 joint positions per frame, flattened, shape (M, 64, 165), metres.")
    cgan_audio_features = _Array(
        "A", "The refiner's audio input (MFCCs m_t and their deltas), not z-scored, shape (M, 64, 28), float32."
    )
    valid = _Array(
        "valid", "Whether each clip frame may start a segment (its look-ahead lies in the take), shape (M, 64), bool."
    )
    attributes = _Array(
        "attributes",
        "The control attributes of every clip frame, shape (M, 64, 9), float32, in the order of "
        ":attr:`attribute_names` (units: :data:`gesturekit.control.ATTRIBUTE_UNITS`).",
    )
    pose_track = _Array(
        "pose_track", "Raw feature-joint positions of frames s..s+69 of each clip, shape (M, 70, 24), metres."
    )
    clip_take = _Array("clip_take", "The take index of each clip, shape (M,), int32.")
    clip_start = _Array("clip_start", "The first frame of each clip in its take, shape (M,), int32.")
    F = _Array("F", "The paper's name for :attr:`audio_features`.")
    P = _Array("P", "The paper's name for :attr:`pose_features`.")
    G = _Array("G", "The paper's name for :attr:`poses`.")
    A = _Array("A", "The paper's name for :attr:`cgan_audio_features`.")

    @property
    def n_clips(self) -> int:
        return int(self.arrays["clip_take"].shape[0])

    @property
    def clip_frames(self) -> int:
        return int(self.meta["build"]["clip_frames"])

    @property
    def fps(self) -> int:
        return int(self.meta["layout"]["fps"])

    @property
    def joint_presence(self) -> JointPresence:
        """Which of the 55 joints the takes hold (recorded, derived or absent); all recorded unless
        the database was built from a partial skeleton."""
        joints = self.meta.get("joints")
        return JointPresence.full() if joints is None else JointPresence(tuple(joints))

    @property
    def skeleton(self) -> Skeleton | None:
        """The one skeleton every take was normalised with (``build-db --normalize-bones``), or None
        when the takes keep their own bone lengths."""
        data = self.meta.get("skeleton")
        return None if data is None else Skeleton.from_json(data)

    @property
    def label(self) -> str:
        return self.meta["build"].get("label", "")

    @property
    def attribute_names(self) -> tuple[str, ...]:
        return tuple(self.meta["attribute_names"])

    @property
    def thresholds(self) -> dict[str, tuple[float, float]]:
        """Attribute -> (low, high) percentile thresholds over all database frames."""
        return {k: tuple(v) for k, v in self.meta["thresholds"].items()}

    @property
    def take_names(self) -> list[str]:
        return [t["name"] for t in self.meta["takes"]]

    def zscore(self, which: str) -> ZScore:
        """Z-scoring statistics of ``"F"``, ``"P"`` or ``"A"``."""
        return ZScore(self.stats[f"{which}_mean"], self.stats[f"{which}_std"])

    def attribute(self, name: str) -> np.ndarray:
        """One control attribute for all clip frames, shape (M, 64)."""
        if name not in self.attribute_names:
            raise ConfigError(f"unknown attribute {name!r}; known: {', '.join(self.attribute_names)}")
        return self.arrays["attributes"][..., self.attribute_names.index(name)]

    # ---- tables and descriptions --------------------------------------------------------
    def clips_table(self) -> pd.DataFrame:
        """Clip metadata as a pandas DataFrame: clip, take, take_index, start_frame, start_s, end_s."""
        import pandas as pd

        takes = self.take_names
        ti = np.asarray(self.arrays["clip_take"])
        st = np.asarray(self.arrays["clip_start"])
        return pd.DataFrame(
            {
                "clip": np.arange(self.n_clips),
                "take": [takes[i] for i in ti],
                "take_index": ti,
                "start_frame": st,
                "start_s": st / self.fps,
                "end_s": (st + self.clip_frames) / self.fps,
            }
        )

    def takes_table(self) -> pd.DataFrame:
        """Take metadata as a pandas DataFrame: name, frames, duration_s, clips, source."""
        import pandas as pd

        rows = [
            {
                "take": t["name"],
                "frames": t["n_frames"],
                "duration_s": t["n_frames"] / self.fps,
                "clips": t["n_clips"],
                "source": "; ".join(f"{k}={v}" for k, v in t["sources"].items()),
            }
            for t in self.meta["takes"]
        ]
        return pd.DataFrame(rows)

    def describe(self) -> dict:
        """A summary: counts, durations, fps, feature sizes, attribute ranges, label, sources."""
        attrs = np.asarray(self.arrays["attributes"]).reshape(-1, len(self.attribute_names))
        ranges = {}
        for i, name in enumerate(self.attribute_names):
            col = attrs[:, i]
            lo, hi = self.thresholds[name]
            ranges[name] = {"min": float(col.min()), "low": lo, "high": hi, "max": float(col.max())}
        frames_in_clips = self.n_clips * self.clip_frames
        return {
            "path": None if self.path is None else str(self.path),
            "label": self.label,
            "source": self.meta["build"].get("source", ""),
            "takes": len(self.meta["takes"]),
            "clips": self.n_clips,
            "clip_frames": self.clip_frames,
            "fps": self.fps,
            "minutes_in_clips": frames_in_clips / self.fps / 60,
            "minutes_of_takes": sum(t["n_frames"] for t in self.meta["takes"]) / self.fps / 60,
            "feature_sizes": {
                "audio f": int(self.arrays["F"].shape[-1]),
                "pose p": int(self.arrays["P"].shape[-1]),
                "motion g": int(self.arrays["G"].shape[-1]),
                "cgan audio": int(self.arrays["A"].shape[-1]),
            },
            "overlap_windows": 0 if self.overlap is None else int(self.overlap["clip_take"].shape[0]),
            "has_audio": self.audio is not None,
            "attributes": ranges,
        }

    def summary_text(self) -> str:
        """:meth:`describe` as readable lines (used by ``gesturekit info`` and ``build-db``)."""
        d = self.describe()
        lines = []
        if d["path"]:
            lines.append(f"database   {d['path']}")
        if d["label"]:
            lines.append(f"label      {d['label']}")
        lines += [
            f"source     {d['source']}",
            f"takes      {d['takes']}  ({d['minutes_of_takes']:.2f} min)",
            f"clips      {d['clips']} x {d['clip_frames']} frames  ({d['minutes_in_clips']:.2f} min at {d['fps']} fps)",
            "features   " + ", ".join(f"{k} {v}" for k, v in d["feature_sizes"].items()),
        ]
        if d["overlap_windows"]:
            lines.append(f"overlap    {d['overlap_windows']} windows for refiner training")
        skeleton = self.skeleton
        if skeleton is not None:
            lines.append(f"skeleton   {skeleton.describe()}")
        lines.append(
            "attributes (min / low threshold / high threshold / max; heights, widths and asymmetry in m, speeds in m/s)"
        )
        # control.frame_attributes measures heights along Y from the positions' origin: the pelvis
        # where the joint map names one, else the root the files are relative to
        lines.append(
            "           hand heights are above the takes' root: the pelvis, or the neck on neck-rooted data "
            "(keypoints read with no pelvis)"
        )
        for name, r in d["attributes"].items():
            unit = ATTRIBUTE_UNITS.get(name, "")
            values = f"{r['min']:8.3f} {r['low']:8.3f} {r['high']:8.3f} {r['max']:8.3f}"
            lines.append(f"  {name:<18} {values} {unit}".rstrip())
        return "\n".join(lines)

    # ---- audio of the database -------------------------------------------------------------
    @property
    def audio_storage(self) -> AudioStorage:
        """How :attr:`audio` holds the takes' audio (int16 at 16 kHz, a lower rate, or FLAC)."""
        return AudioStorage.from_meta(self.meta)

    def take_audio(self, take: int | str) -> np.ndarray:
        """A take's audio, float32 at 16 kHz, shape (samples,), whatever form it is stored in
        (requires a database built with ``store_audio``; see :mod:`gesturekit.database.audio`)."""
        if self.audio is None:
            raise DatabaseError("this database was built without audio (store_audio=False)")
        return read_take_audio(self.audio, self._take(take), self.audio_storage, path=self.path)

    def segment_audio(self, clip: int, start: int, n_frames: int) -> np.ndarray:
        """Audio of frames ``start .. start+n_frames`` of a clip, float32 at 16 kHz."""
        ti = int(self.arrays["clip_take"][clip])
        f0 = int(self.arrays["clip_start"][clip]) + int(start)
        a = self.take_audio(ti)
        s0 = int(round(f0 * AUDIO_SR / self.fps))
        s1 = int(round((f0 + n_frames) * AUDIO_SR / self.fps))
        return a[s0:s1]

    def _take(self, take: int | str) -> dict:
        if isinstance(take, str):
            names = self.take_names
            if take not in names:
                raise ConfigError(f"no take named {take!r} in the database; takes: {', '.join(names[:10])}")
            take = names.index(take)
        return self.meta["takes"][int(take)]

    # ---- held-out data ------------------------------------------------------------------------
    def exclusion_mask(
        self, *, takes: Iterable[str] = (), ranges: Iterable[tuple[str, float, float]] = ()
    ) -> np.ndarray:
        """Frames to keep out of the search, shape (M, 64), bool.

        Parameters
        ----------
        takes : names of takes to exclude entirely.
        ranges : (take, start_s, end_s) time ranges of takes to exclude.
        """
        mask = np.zeros((self.n_clips, self.clip_frames), dtype=bool)
        # a take's clips are consecutive (checked on load): only their rows are touched, so that
        # at a hundred hours no per-frame temporaries of the whole database are made
        for name in takes:
            t = self._take(name)
            mask[t["first_clip"] : t["first_clip"] + t["n_clips"]] = True
        for name, a, b in ranges:
            t = self._take(name)
            if not b > a:
                raise ConfigError(f"held-out range {a}-{b} s of {name!r}: end must be after start")
            rows = slice(t["first_clip"], t["first_clip"] + t["n_clips"])
            sec = (np.asarray(self.arrays["clip_start"][rows])[:, None] + np.arange(self.clip_frames)) / self.fps
            mask[rows] |= (sec >= a) & (sec < b)
        return mask

    # ---- queries ------------------------------------------------------------------------------
    def query_features(self, audio: np.ndarray, *, n_frames: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Features of speech to synthesise, normalised with this database's statistics.

        Returns
        -------
        F_q : np.ndarray, shape (T, 112), float32, z-scored
        A_q : np.ndarray, shape (T, 28), float32, raw (the refiner normalises it)
        """
        m = audio_frame_features(audio, n_frames=n_frames)
        return self.zscore("F").apply(stack_audio_features(m)), cgan_audio_features(m)

    # ---- build --------------------------------------------------------------------------------
    @classmethod
    def build(
        cls,
        takes: Iterable[Take],
        *,
        config: BuildConfig | None = None,
        progress: Callable[[int, str], None] | None = None,
        skeleton: Skeleton | None = None,
    ) -> MatchingDatabase:
        """Build a database in memory from takes.

        Each take is featurised and cut into clips as it is read, then the
        takes are assembled in order of name into the database's arrays
        (:mod:`gesturekit.database.build`): the arrays a build from files
        writes into its folder, the same numbers. The takes are listed in the
        database by name.

        Parameters
        ----------
        takes : iterable of Take
            Read lazily, one at a time (a generator keeps memory to one take's source).
        config : BuildConfig
        progress : callable(i, take_name), optional
            Called after each take is processed.
        skeleton : Skeleton, optional
            The skeleton the takes were normalised with
            (:func:`gesturekit.datasets.takes.fit_takes_skeleton`), stored with the database
            (:attr:`skeleton`).

        Examples
        --------
        >>> from gesturekit import BuildConfig, MatchingDatabase
        >>> from gesturekit.datasets.synthetic import generate_demo_takes
        >>> takes = generate_demo_takes(minutes=0.5, take_seconds=15.0, seed=0)
        >>> db = MatchingDatabase.build(takes, config=BuildConfig(label="two generated takes"))
        >>> len(db.takes_table()), db.F.shape, db.P.shape  # audio features 112, pose features 96
        (2, (6, 64, 112), (6, 64, 96))
        """
        kwargs = build_in_memory(takes, config=config or BuildConfig(), progress=progress, skeleton=skeleton)
        return cls(**kwargs)

    # ---- save / load --------------------------------------------------------------------------
    def save(
        self,
        path: str | os.PathLike,
        *,
        overwrite: bool = False,
        inputs: Iterable[str | os.PathLike | None] = (),
        locked: bool = False,
    ) -> Path:
        """Write the database folder atomically (a temporary folder swapped into place).

        ``path`` is the database folder: an empty folder is used, an earlier
        database is replaced only with ``overwrite``, anything else there is
        refused. ``inputs`` are the folders of the takes, which ``path`` must
        not be, lie in or contain; ``locked`` says that the caller holds
        :func:`gesturekit.outputs.output_lock` of ``path`` (the command line
        holds it for the whole build).

        Raises
        ------
        OutputError
            Something other than an earlier database is at ``path``, a database
            is there and ``overwrite`` is False, another process is writing it,
            ``path`` overlaps an input, or writing failed (disk full, permission).
        DatabaseError
            An array holds NaN or infinite values; nothing is written.
        """
        path = Path(path)
        write_database(
            path,
            meta=self.meta,
            arrays=self.arrays,
            stats=self.stats,
            audio=self.audio,
            overlap=self.overlap,
            overwrite=overwrite,
            inputs=inputs,
            locked=locked,
        )
        self.path = path
        return path

    @classmethod
    def load(cls, path: str | os.PathLike, *, mmap: bool = True) -> MatchingDatabase:
        """Open a database folder; big arrays are memory-mapped (opening costs milliseconds).

        ``database.json`` is checked against the structure :meth:`save` writes
        (types of the build options, takes, thresholds of every attribute,
        counts), and the arrays against it: shapes, dtypes, and that every clip
        lies inside its take (on the small index arrays only; the big arrays are
        not read).

        Raises
        ------
        DatabaseError
            Missing folder or files, another format or format version, another
            feature layout, or files that are damaged or disagree with each other.

        Examples
        --------
        >>> import tempfile
        >>> from gesturekit import MatchingDatabase
        >>> from gesturekit.demo import build_demo_database
        >>> folder = build_demo_database(tempfile.mkdtemp() + "/demo", minutes=0.5).path
        >>> db = MatchingDatabase.load(folder)
        >>> db.G.shape, db.fps  # the paper's G: joint positions of every clip frame, metres
        ((7, 64, 165), 15)
        >>> low, high = db.thresholds["left_hand_height"]  # the 15th and 85th percentiles, metres
        >>> bool(low < high)
        True
        """
        path = Path(path)
        return cls(**read_database(path, mmap=mmap), path=path)
