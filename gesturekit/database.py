"""MatchingDatabase: takes -> features -> 64-frame clips, saved as plain arrays + JSON.

Features are computed on each whole take (so look-ahead near a clip's end uses
the real following frames), then the take is cut into non-overlapping clips of
``clip_frames`` frames; the tail that does not fill a clip is dropped. On
request a second, overlapping cut (stride ``overlap_stride``) is stored for
training the refiner.

On disk a database is a folder::

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
    audio.npy            all takes' audio, int16 at 16 kHz, a lower rate or FLAC (optional; _database_audio)
    overlap/             the overlapping cut, same arrays per window (optional)

Every array is a plain ``.npy`` (memory-mapped on load, never pickled); the
folder is written under a temporary name and swapped into place, by the rules
of :mod:`gesturekit.outputs` (``database.json`` is the marker that lets
``--force`` recognise a database). Writing, reading and checking the folder
is :mod:`gesturekit._database_folder`'s part; building is this module's.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, overload

import numpy as np

from ._database_audio import AudioStorage, read_take_audio
from ._database_folder import CLIP_ARRAYS, FORMAT, FORMAT_VERSION, read_database, write_database
from ._version import __version__
from .control import ATTRIBUTE_NAMES, ATTRIBUTE_UNITS, frame_attributes
from .errors import ConfigError, DatabaseError, warn
from .features import (
    LAYOUT,
    FeatureLayout,
    ZScore,
    audio_frame_features,
    cgan_audio_features,
    n_audio_frames,
    pose_features,
    stack_audio_features,
    valid_starts,
)
from .motion import AUDIO_SR, Take, resample_positions
from .skeleton import FPS, JOINT_NAMES, POSE_FEATURE_INDICES, JointPresence

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["FORMAT_VERSION", "BuildConfig", "TakeFeatures", "take_features", "MatchingDatabase", "normalise_exclusions"]


@dataclass
class BuildConfig:
    """How a database is built; stored in ``database.json``.

    Parameters
    ----------
    clip_frames : int
        Frames per clip (the paper's T_match = 64).
    overlap_stride : int or None
        If set, also store the overlapping cut with this stride (frames), for the refiner.
    percentiles : (float, float)
        Percentiles of each control attribute that define "low" and "high".
    store_audio : bool
        Keep the takes' audio (int16) so clips can be listened to.
    audio_format : {"pcm", "flac"}
        How the kept audio is stored: raw int16 samples, or FLAC (lossless, smaller).
    audio_rate : int
        Sample rate of the kept audio, Hz (4000 to 16000; below 16000 the audio is for
        browsing only: it is resampled back to 16 kHz when read). See :mod:`gesturekit._database_audio`.
    label : str
        A description shown to users (e.g. that the data is generated).
    source : str
        Where the takes came from (a folder, ``"demo"``).
    joint_map : str or None
        The joint map or preset used to read the takes.
    """

    clip_frames: int = 64
    overlap_stride: int | None = None
    percentiles: tuple[float, float] = (15.0, 85.0)
    store_audio: bool = True
    label: str = ""
    source: str = ""
    joint_map: str | None = None
    audio_format: str = "pcm"
    audio_rate: int = AUDIO_SR

    def __post_init__(self) -> None:
        if self.clip_frames < 16:
            raise ConfigError(f"clip_frames must be at least 16, got {self.clip_frames}")
        if self.overlap_stride is not None and not 1 <= self.overlap_stride <= self.clip_frames:
            raise ConfigError(f"overlap_stride must be in 1..{self.clip_frames}, got {self.overlap_stride}")
        lo, hi = self.percentiles
        if not 0 <= lo < hi <= 100:
            raise ConfigError(f"percentiles must satisfy 0 <= low < high <= 100, got {self.percentiles}")
        self.percentiles = (float(lo), float(hi))
        storage = AudioStorage(format=self.audio_format, rate=self.audio_rate)  # checks both
        if not self.store_audio and not storage.is_default:
            raise ConfigError("an audio format or rate was given, but the database keeps no audio (store_audio=False)")


@dataclass
class TakeFeatures:
    """Per-frame arrays of one take at 15 fps (features not yet z-scored).

    Attributes
    ----------
    positions : (T,55,3) metres; m : (T,14); f : (T,112); p : (T,96); a : (T,28);
    valid : (T,) bool; attributes : (T,9); track : (T,24) feature-joint positions.
    """

    name: str
    positions: np.ndarray
    m: np.ndarray
    f: np.ndarray
    p: np.ndarray
    a: np.ndarray
    valid: np.ndarray
    attributes: np.ndarray
    track: np.ndarray
    audio: np.ndarray
    sources: dict = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return int(self.positions.shape[0])


def take_features(take: Take, *, layout: FeatureLayout = LAYOUT) -> TakeFeatures:
    """Compute every per-frame array of a take, trimming motion and audio to the shorter.

    Motion at another frame rate is resampled to 15 fps (linear in positions;
    readers with rotations resample before this). A length mismatch is trimmed
    with a :class:`GestureKitWarning` that says by how much.
    """
    pos = take.motion.positions
    if take.motion.fps != layout.fps:
        pos = resample_positions(pos, take.motion.fps, layout.fps)
    n_motion = pos.shape[0]
    n_audio = n_audio_frames(len(take.audio), sr=layout.sr, fps=layout.fps)
    n = min(n_motion, n_audio)
    if n_motion != n_audio:
        longer = "motion" if n_motion > n_audio else "audio"
        warn(
            f"{take.name}: motion has {n_motion / layout.fps:.2f} s and audio {n_audio / layout.fps:.2f} s; "
            f"trimmed the {longer} by {abs(n_motion - n_audio) / layout.fps:.2f} s to {n / layout.fps:.2f} s",
            stacklevel=2,
        )
    if n < 1:
        raise ConfigError(f"take {take.name!r} has no frame after aligning motion and audio")
    pos = np.ascontiguousarray(pos[:n], dtype=np.float32)
    audio = np.asarray(take.audio, dtype=np.float32)[: int(np.ceil(n * layout.sr / layout.fps))]
    m = audio_frame_features(audio, n_frames=n, layout=layout)
    return TakeFeatures(
        name=take.name,
        positions=pos,
        m=m,
        f=stack_audio_features(m, layout=layout),
        p=pose_features(pos, layout=layout),
        a=cgan_audio_features(m),
        valid=valid_starts(n, layout=layout),
        attributes=frame_attributes(pos, fps=layout.fps),
        track=pos[:, POSE_FEATURE_INDICES].reshape(n, -1),
        audio=audio,
        sources=dict(take.sources),
    )


def normalise_exclusions(
    takes: Iterable[object], ranges: Iterable[Any]
) -> tuple[tuple[str, ...], tuple[tuple[str, float, float], ...]]:
    """Held-out takes and (take, start_s, end_s) ranges as plain tuples, for configs.

    Raises
    ------
    ConfigError
        A range entry is not a (take, start, end) triple of a name and two finite numbers
        with ``0 <= start < end``.
    """
    out = []
    for r in ranges:
        try:
            take, a, b = r
            take, a, b = str(take), float(a), float(b)
        except (TypeError, ValueError):
            raise ConfigError(f"exclude_ranges entries must be (take, start_s, end_s), got {r!r}") from None
        if not (np.isfinite(a) and np.isfinite(b) and 0 <= a < b):
            raise ConfigError(f"exclude range {take}:{a:g}-{b:g} s: need finite times with 0 <= start < end")
        out.append((take, a, b))
    return tuple(str(t) for t in takes), tuple(out)


def _windows(n_frames: int, length: int, stride: int) -> np.ndarray:
    """Start frames of windows of ``length`` frames every ``stride`` frames inside ``n_frames``."""
    if n_frames < length:
        return np.zeros(0, dtype=np.int64)
    return np.arange(0, n_frames - length + 1, stride, dtype=np.int64)


def _cut(tf: TakeFeatures, starts: np.ndarray, length: int, track_len: int) -> dict[str, np.ndarray]:
    idx = starts[:, None] + np.arange(length)[None, :]
    tidx = np.minimum(starts[:, None] + np.arange(track_len)[None, :], tf.n_frames - 1)
    return {
        "F": tf.f[idx],
        "P": tf.p[idx],
        "G": tf.positions.reshape(tf.n_frames, -1)[idx],
        "A": tf.a[idx],
        "valid": tf.valid[idx],
        "attributes": tf.attributes[idx],
        "pose_track": tf.track[tidx],
    }


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
        lines.append(
            "attributes (min / low threshold / high threshold / max; heights, widths and asymmetry in m, speeds in m/s)"
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
        (requires a database built with ``store_audio``; see :mod:`gesturekit._database_audio`)."""
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
    ) -> MatchingDatabase:
        """Build a database in memory from takes.

        Parameters
        ----------
        takes : iterable of Take
            Read lazily, one at a time (a generator keeps memory to one take's source).
        config : BuildConfig
        progress : callable(i, take_name), optional
            Called after each take is processed.
        """
        config = config or BuildConfig()
        L = config.clip_frames
        track_len = L + LAYOUT.pose_lookahead
        per_take: list[TakeFeatures] = []
        presence: JointPresence | None = None
        for i, take in enumerate(takes):
            # every take of a database holds the same joints: what a clip shows must not depend on its take
            this = take.motion.presence
            if presence is None:
                presence = this
            elif this != presence:
                raise ConfigError(
                    f"take {take.name!r} holds other joints than the takes before it "
                    f"({this.describe()} against {presence.describe()}); read every take with the same joint map"
                )
            tf = take_features(take)
            if np.isnan(tf.positions).any():
                raise ConfigError(f"take {take.name!r} has NaN positions")
            per_take.append(tf)
            if progress is not None:
                progress(i + 1, take.name)
        if not per_take:
            raise ConfigError("no takes to build a database from")
        names = [t.name for t in per_take]
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise ConfigError(f"take names must be unique; repeated: {', '.join(dup)}")

        # z-scoring statistics over the frames that can start a segment (no padding inside)
        allv = np.concatenate([t.valid for t in per_take])
        if not allv.any():
            raise ConfigError(f"every take is shorter than {LAYOUT.audio_lookahead + 1} frames; nothing can be matched")
        stats = {}
        for key, attr in (("F", "f"), ("P", "p"), ("A", "a")):
            z = ZScore.fit(np.concatenate([getattr(t, attr) for t in per_take])[allv])
            stats[f"{key}_mean"], stats[f"{key}_std"] = z.mean, z.std

        clip_parts: dict[str, list] = {k: [] for k in CLIP_ARRAYS}
        overlap_parts: dict[str, list] | None = (
            {k: [] for k in CLIP_ARRAYS + ("clip_take", "clip_start")} if config.overlap_stride else None
        )
        clip_take: list[int] = []
        clip_start: list[int] = []
        take_meta: list[dict] = []
        audio_parts: list[np.ndarray] = []
        audio_offset = 0
        for ti, tf in enumerate(per_take):
            starts = _windows(tf.n_frames, L, L)
            cut = _cut(tf, starts, L, track_len)
            for k in CLIP_ARRAYS:
                clip_parts[k].append(cut[k])
            first_clip = len(clip_take)
            clip_take += [ti] * len(starts)
            clip_start += starts.tolist()
            if overlap_parts is not None and config.overlap_stride is not None:
                ostarts = _windows(tf.n_frames, L, config.overlap_stride)
                ocut = _cut(tf, ostarts, L, track_len)
                for k in CLIP_ARRAYS:
                    overlap_parts[k].append(ocut[k])
                overlap_parts["clip_take"].append(np.full(len(ostarts), ti, np.int32))
                overlap_parts["clip_start"].append(ostarts.astype(np.int32))
            n_samples = len(tf.audio) if config.store_audio else 0
            take_meta.append(
                {
                    "name": tf.name,
                    "sources": {k: str(v) for k, v in tf.sources.items()},
                    "n_frames": tf.n_frames,
                    "first_clip": first_clip,
                    "n_clips": int(len(starts)),
                    "audio_offset": audio_offset,
                    "audio_samples": n_samples,
                }
            )
            if config.store_audio:
                audio_parts.append(np.clip(np.round(tf.audio * 32767), -32768, 32767).astype(np.int16))
                audio_offset += n_samples
        if not clip_take:
            raise ConfigError(f"every take is shorter than one clip ({L} frames = {L / FPS:.1f} s)")

        def finish(parts):
            out = {k: np.concatenate(parts[k]) for k in CLIP_ARRAYS}
            out["F"] = ZScore(stats["F_mean"], stats["F_std"]).apply(out["F"])
            out["P"] = ZScore(stats["P_mean"], stats["P_std"]).apply(out["P"])
            return out

        arrays = finish(clip_parts)
        arrays["clip_take"] = np.asarray(clip_take, dtype=np.int32)
        arrays["clip_start"] = np.asarray(clip_start, dtype=np.int32)
        overlap = None
        if overlap_parts is not None:
            overlap = finish(overlap_parts)
            overlap["clip_take"] = np.concatenate(overlap_parts["clip_take"])
            overlap["clip_start"] = np.concatenate(overlap_parts["clip_start"])

        # thresholds over every frame of the clips (the frames the search may use)
        flat_attrs = arrays["attributes"].reshape(-1, len(ATTRIBUTE_NAMES)).astype(np.float64)
        lo_q, hi_q = config.percentiles
        thresholds = {
            name: [float(np.percentile(flat_attrs[:, i], lo_q)), float(np.percentile(flat_attrs[:, i], hi_q))]
            for i, name in enumerate(ATTRIBUTE_NAMES)
        }
        meta = {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "gesturekit_version": __version__,
            "layout": LAYOUT.signature(),
            "joint_names": list(JOINT_NAMES),
            "build": asdict(config),
            "attribute_names": list(ATTRIBUTE_NAMES),
            "thresholds": thresholds,
            "takes": take_meta,
        }
        if presence is not None and not presence.is_full:
            meta["joints"] = presence.to_list()
        audio = np.concatenate(audio_parts) if config.store_audio else None
        return cls(meta=meta, arrays=arrays, stats=stats, audio=audio, overlap=overlap)

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
        write_database(self, path, overwrite=overwrite, inputs=inputs, locked=locked)
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
        """
        path = Path(path)
        return cls(**read_database(path, mmap=mmap), path=path)
