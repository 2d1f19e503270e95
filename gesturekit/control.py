"""Control attributes of database frames, their thresholds, and time-varying control tracks.

A *control* restricts which database frames the search may use while it is
active. Each frame of the database has a few scalar *attributes* computed from
its pose (wrist heights, hand speeds, hand distances from the body axis,
left/right asymmetry). A *constraint* compares one attribute with a percentile
threshold of the database (the authors used the 15th and 85th percentiles: "low"
is below the 15th, "high" above the 85th). A :class:`ControlTrack` says which
constraints hold over which stretches of the output, e.g.
``"0-3:left_hand=low,3-6:speed=slow+symmetry=symmetric"``.

The *control table* (:func:`segments_frame`, :func:`track_from_segments`,
:func:`add_segment`) is a track as the app's editor and the inspector show it:
one row per constraint with its start and end in seconds.
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from . import limits
from ._arguments import checks_arguments
from .errors import ConfigError, InputFileError
from .skeleton import FPS, joint_index

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "ATTRIBUTE_NAMES",
    "ATTRIBUTE_UNITS",
    "CONSTRAINTS",
    "frame_attributes",
    "Segment",
    "ControlTrack",
    "parse_time_range",
    "parse_control",
    "load_control_file",
    "constraint_mask",
    "step_masks",
    "SEGMENT_COLUMNS",
    "CONSTRAINT_CHOICES",
    "empty_segments",
    "segments_frame",
    "track_from_segments",
    "add_segment",
]

#: Per-frame attributes, in the order of the database's ``attributes`` array (units in brackets).
ATTRIBUTE_NAMES: tuple[str, ...] = (
    "left_hand_height",  # left wrist height above the root: the pelvis, or the neck on neck-rooted data [m]
    "right_hand_height",  # right wrist height above the root [m]
    "left_hand_speed",  # left wrist speed [m/s]
    "right_hand_speed",  # right wrist speed [m/s]
    "hand_speed",  # mean of both wrist speeds [m/s]
    "left_hand_width",  # horizontal distance of the left wrist from the body's vertical axis [m]
    "right_hand_width",  # same, right wrist [m]
    "hand_width",  # mean of both widths [m]
    "asymmetry",  # distance between the left wrist and the mirrored right wrist [m]
)

#: The unit of each attribute: metres for heights, widths and asymmetry, metres per second for speeds.
ATTRIBUTE_UNITS: dict[str, str] = {name: "m/s" if "speed" in name else "m" for name in ATTRIBUTE_NAMES}

#: Constraint name -> (attribute(s) it tests, {value: "low"|"high"}). "low" means below the low
#: percentile of the attribute, "high" above the high percentile; several attributes must all hold.
CONSTRAINTS: dict[str, tuple[tuple[str, ...], dict[str, str]]] = {
    "left_hand": (("left_hand_height",), {"low": "low", "high": "high"}),
    "right_hand": (("right_hand_height",), {"low": "low", "high": "high"}),
    "both_hands": (("left_hand_height", "right_hand_height"), {"low": "low", "high": "high"}),
    "speed": (("hand_speed",), {"slow": "low", "fast": "high"}),
    "left_speed": (("left_hand_speed",), {"slow": "low", "fast": "high"}),
    "right_speed": (("right_hand_speed",), {"slow": "low", "fast": "high"}),
    "symmetry": (("asymmetry",), {"symmetric": "low", "asymmetric": "high"}),
    "width": (("hand_width",), {"narrow": "low", "wide": "high"}),
}


@checks_arguments
def frame_attributes(positions: np.ndarray, *, fps: float = FPS) -> np.ndarray:
    """Control attributes of every frame of one take.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Pelvis-relative positions in metres, Y up, character facing +Z, at ``fps``.
    fps : float
        Frame rate, frames per second (speeds are in m/s).

    Returns
    -------
    np.ndarray, shape (frames, len(ATTRIBUTE_NAMES)), float32
        Columns in the order of :data:`ATTRIBUTE_NAMES`. Speeds use central
        differences inside the take (one-sided at its ends).
    """
    pos = np.asarray(positions, dtype=np.float64)
    lw, rw = pos[:, joint_index("left_wrist")], pos[:, joint_index("right_wrist")]
    axis = pos[:, joint_index("upper_chest")]
    n = pos.shape[0]
    if n >= 2:
        lv = np.linalg.norm(np.gradient(lw, axis=0), axis=1) * fps
        rv = np.linalg.norm(np.gradient(rw, axis=0), axis=1) * fps
    else:
        lv = rv = np.zeros(n)
    lwid = np.hypot(lw[:, 0] - axis[:, 0], lw[:, 2] - axis[:, 2])
    rwid = np.hypot(rw[:, 0] - axis[:, 0], rw[:, 2] - axis[:, 2])
    # mirror the right wrist across the body's sagittal plane (x -> 2*axis_x - x)
    mirrored = rw.copy()
    mirrored[:, 0] = 2 * axis[:, 0] - rw[:, 0]
    asym = np.linalg.norm(lw - mirrored, axis=1)
    cols = [lw[:, 1], rw[:, 1], lv, rv, (lv + rv) / 2, lwid, rwid, (lwid + rwid) / 2, asym]
    return np.stack(cols, axis=1).astype(np.float32)


@dataclass(frozen=True)
class Segment:
    """One stretch of a control track.

    Parameters
    ----------
    start_s, end_s : float
        Time range in seconds of the output, ``start_s < end_s``.
    constraints : tuple of (name, value)
        E.g. ``(("left_hand", "low"), ("speed", "slow"))``; all must hold.
    """

    start_s: float
    end_s: float
    constraints: tuple[tuple[str, str], ...]

    def __post_init__(self):
        if not (np.isfinite(self.start_s) and np.isfinite(self.end_s)) or self.start_s < 0:
            raise ConfigError(f"control segment times must be finite and >= 0, got {self.start_s}-{self.end_s}")
        if not self.end_s > self.start_s:
            raise ConfigError(f"control segment {self.start_s}-{self.end_s}: end must be after start")
        if not self.constraints:
            raise ConfigError(f"control segment {self.start_s}-{self.end_s} has no constraint")
        # microsecond resolution, so text, CSV and JSON forms round-trip exactly
        object.__setattr__(self, "start_s", round(float(self.start_s), 6))
        object.__setattr__(self, "end_s", round(float(self.end_s), 6))
        seen = set()
        for name, value in self.constraints:
            _check_constraint(name, value)
            if name in seen:
                raise ConfigError(f"control segment {self.start_s}-{self.end_s} sets {name!r} twice")
            seen.add(name)

    def label(self) -> str:
        """Constraints as text, e.g. ``"left_hand=low+speed=slow"``."""
        return "+".join(f"{n}={v}" for n, v in self.constraints)


def _check_constraint(name: str, value: str) -> None:
    if name not in CONSTRAINTS:
        raise ConfigError(f"unknown control {name!r}; known controls: {', '.join(CONSTRAINTS)}")
    values = CONSTRAINTS[name][1]
    if value not in values:
        raise ConfigError(f"control {name!r} takes {' or '.join(values)}, got {value!r}")


@dataclass(frozen=True)
class ControlTrack:
    """Time-varying control: segments of the output with their constraints.

    Frames outside every segment are unconstrained. Segments must not overlap
    (a segment may set several constraints instead).
    """

    segments: tuple[Segment, ...] = field(default_factory=tuple)

    def __post_init__(self):
        segs = tuple(sorted(self.segments, key=lambda s: (s.start_s, s.end_s)))
        for a, b in zip(segs, segs[1:]):
            if b.start_s < a.end_s - 1e-9:
                raise ConfigError(
                    f"control segments {a.start_s:g}-{a.end_s:g} and {b.start_s:g}-{b.end_s:g} overlap; "
                    "combine their constraints in one segment instead"
                )
        object.__setattr__(self, "segments", segs)

    def __bool__(self) -> bool:
        return bool(self.segments)

    def frame_labels(self, n_frames: int, *, fps: float = FPS) -> list[tuple[tuple[str, str], ...]]:
        """The constraints active at each output frame (frame t at time t/fps)."""
        out: list[tuple[tuple[str, str], ...]] = [()] * n_frames
        for seg in self.segments:
            # times are kept to the microsecond: a step boundary such as 16/15 s is stored as 1.066667 s, a
            # hair after frame 16, which must still start there (1e-4 frames is far above that rounding)
            a = int(np.ceil(seg.start_s * fps - 1e-4))
            b = int(np.ceil(seg.end_s * fps - 1e-4))
            for t in range(max(a, 0), min(b, n_frames)):
                out[t] = seg.constraints
        return out

    def to_text(self, *, decimals: int | None = None) -> str:
        """The command-line form, e.g. ``"0-3:left_hand=low,3-6:speed=slow"``.

        ``decimals``: times rounded to that many decimals, for a person to read (``"3.73-6.4"`` for a range
        snapped to 56/15 to 96/15 s); by default every digit kept, so that the text reads back to this track.
        """
        if decimals is None:
            return ",".join(f"{s.start_s:.15g}-{s.end_s:.15g}:{s.label()}" for s in self.segments)
        d = int(decimals)
        return ",".join(f"{round(s.start_s, d):g}-{round(s.end_s, d):g}:{s.label()}" for s in self.segments)

    def to_records(self) -> list[dict]:
        """One dict per segment: start_s, end_s, constraint (text)."""
        return [{"start_s": s.start_s, "end_s": s.end_s, "constraint": s.label()} for s in self.segments]

    def to_csv(self) -> str:
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=["start_s", "end_s", "constraint"], lineterminator="\n")
        w.writeheader()
        for r in self.to_records():
            w.writerow(r)
        return buf.getvalue()

    @classmethod
    def from_records(cls, records: Iterable[Mapping[str, Any]], *, source: str = "control") -> ControlTrack:
        """From dicts/rows with start_s, end_s and constraint (``"a=b+c=d"``)."""
        segs = []
        for i, r in enumerate(records):
            try:
                start, end, text = float(r["start_s"]), float(r["end_s"]), str(r["constraint"])
            except (KeyError, TypeError, ValueError) as exc:
                raise ConfigError(f"{source}: row {i + 1} needs start_s, end_s and constraint ({exc})") from None
            try:
                segs.append(Segment(start, end, _parse_constraints(text)))
            except ConfigError as exc:
                raise ConfigError(f"{source}: row {i + 1}: {exc.problem}") from None
        return cls(tuple(segs))


# a time in seconds: plain decimal digits (no sign, exponent, nan or inf), e.g. 3, 2.5, .5
_SECONDS = r"(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)"
_TIME_RANGE_RE = re.compile(rf"^\s*({_SECONDS})\s*-\s*({_SECONDS})\s*$")


@checks_arguments
def parse_time_range(text: str, *, what: str = "time range", form: str = "START-END") -> tuple[float, float]:
    """``"START-END"`` in seconds -> ``(start, end)``, with ``0 <= start < end`` and both finite.

    The one grammar of every time range a user types (control segments,
    ``--exclude-range``, ``--holdout``): two plain decimal numbers joined by
    ``-``. Signs, exponents, ``nan`` and ``inf`` are refused here rather than
    being half-accepted by a pattern and failing later in ``float()``.

    Parameters
    ----------
    text : str
        The range alone, e.g. ``"0-2.5"``.
    what : str
        How the message names what was given (e.g. ``"--exclude-range 'T:1-2'"``).
    form : str
        The form the message asks for (e.g. ``"TAKE:START-END"``).

    Returns
    -------
    (float, float)
        Start and end, seconds.

    Raises
    ------
    ConfigError
        Not of that form, not finite, or the end not after the start.
    """
    m = _TIME_RANGE_RE.match(text)
    if not m:
        raise ConfigError(f"{what} must look like {form} in seconds (plain numbers >= 0, e.g. 0-2.5)")
    start, end = float(m.group(1)), float(m.group(2))
    if not (np.isfinite(start) and np.isfinite(end)):
        raise ConfigError(f"{what}: a time is too large to be seconds")
    if not end > start:
        raise ConfigError(f"{what}: end must be after start (need 0 <= start < end)")
    return start, end


def _parse_constraints(text: str) -> tuple[tuple[str, str], ...]:
    out = []
    for part in re.split(r"[+&]", text):
        part = part.strip()
        if not part:
            continue
        if "=" not in part:
            raise ConfigError(f"control {part!r} must look like name=value, e.g. left_hand=high")
        name, value = (s.strip() for s in part.split("=", 1))
        _check_constraint(name, value)
        out.append((name, value))
    return tuple(out)


@checks_arguments
def parse_control(text: str) -> ControlTrack:
    """Parse ``"0-3:left_hand=low,3-6:speed=slow+symmetry=symmetric"`` (seconds).

    An empty string gives an empty (unconstrained) track. Times follow
    :func:`parse_time_range`.

    Raises
    ------
    ConfigError
        A segment that is not ``START-END:name=value[+name=value...]``, an unknown
        control or value, or overlapping segments.

    Examples
    --------
    >>> from gesturekit import parse_control
    >>> track = parse_control("0-3:left_hand=low,6-9:speed=fast+symmetry=symmetric")
    >>> [(s.start_s, s.end_s, s.constraints) for s in track.segments]
    [(0.0, 3.0, (('left_hand', 'low'),)), (6.0, 9.0, (('speed', 'fast'), ('symmetry', 'symmetric')))]
    >>> parse_control("").segments  # no control: every database frame may be used
    ()
    """
    if text is None or not text.strip():
        return ControlTrack(())
    segs = []
    for chunk in text.split(","):
        if not chunk.strip():
            continue
        times, colon, constraints = chunk.partition(":")
        if not colon or not constraints.strip():
            raise ConfigError(f"control segment {chunk.strip()!r} must look like START-END:name=value (seconds)")
        start, end = parse_time_range(times, what=f"control segment {chunk.strip()!r}", form="START-END:name=value")
        segs.append(Segment(start, end, _parse_constraints(constraints)))
    return ControlTrack(tuple(segs))


_CONTROL_COLUMNS = ("start_s", "end_s", "constraint")


@checks_arguments
def load_control_file(path: str | os.PathLike) -> ControlTrack:
    """Read a control track from CSV (columns start_s, end_s, constraint) or JSON (a list of such objects).

    JSON may also be an object whose ``segments`` is that list.

    Raises
    ------
    InputFileError
        Unreadable, not UTF-8, not valid JSON, JSON of another structure, CSV
        without the three columns, or a row that is not a valid segment.
    """
    p = os.fspath(path)
    is_json = p.lower().endswith(".json")
    try:
        if is_json:
            text = ""
        elif limits.check_regular(p, what="control file ") > limits.JSON_MB.value() * 1e6:
            raise InputFileError(f"larger than a control file can be ({limits.JSON_MB.how_to_raise()})", path=p)
        else:
            with open(p, encoding="utf-8") as fh:
                text = fh.read()
    except UnicodeDecodeError as exc:
        raise InputFileError(f"not UTF-8 text (byte {exc.start}); save the control file as UTF-8", path=p) from None
    except OSError as exc:
        raise InputFileError(f"cannot read control file ({exc.strerror})", path=p) from None
    try:
        if is_json:
            data = limits.read_json(p)
            if isinstance(data, dict):
                data = data.get("segments", [])
            if not isinstance(data, list):
                raise InputFileError(
                    f"a JSON control file must hold a list of segments (objects with {', '.join(_CONTROL_COLUMNS)}), "
                    f"found {type(data).__name__}",
                    path=p,
                )
            for i, r in enumerate(data):
                if not isinstance(r, dict):
                    raise InputFileError(
                        f"row {i + 1} must be an object with {', '.join(_CONTROL_COLUMNS)}, found {type(r).__name__}",
                        path=p,
                    )
            return ControlTrack.from_records(data, source=p)
        reader = csv.DictReader(io.StringIO(text))
        columns = reader.fieldnames or []
        missing = [c for c in _CONTROL_COLUMNS if c not in columns]
        if missing:
            raise InputFileError(
                f"a CSV control file needs the columns {', '.join(_CONTROL_COLUMNS)}; missing {', '.join(missing)} "
                f"(found {', '.join(columns) or 'no header'})",
                path=p,
            )
        return ControlTrack.from_records(list(reader), source=p)
    except json.JSONDecodeError as exc:
        raise InputFileError(f"not valid JSON ({exc.msg} at line {exc.lineno})", path=p) from None
    except ConfigError as exc:
        problem = exc.problem
        if problem.startswith(p + ": "):
            problem = problem[len(p) + 2 :]
        raise InputFileError(problem, path=p) from None


@checks_arguments
def constraint_mask(
    attributes: np.ndarray, constraints: tuple[tuple[str, str], ...], thresholds: dict[str, tuple[float, float]]
) -> np.ndarray:
    """Frames of the database that satisfy all ``constraints``.

    Parameters
    ----------
    attributes : np.ndarray, shape (..., len(ATTRIBUTE_NAMES))
    constraints : tuple of (name, value)
    thresholds : dict
        Attribute name -> (low, high) threshold values (the database's percentiles).

    Returns
    -------
    np.ndarray, shape (...), bool
    """
    mask = np.ones(attributes.shape[:-1], dtype=bool)
    for name, value in constraints:
        _check_constraint(name, value)
        attrs, values = CONSTRAINTS[name]
        side = values[value]
        for a in attrs:
            col = attributes[..., ATTRIBUTE_NAMES.index(a)]
            low, high = thresholds[a]
            mask &= (col < low) if side == "low" else (col > high)
    return mask


@checks_arguments
def step_masks(
    track: ControlTrack,
    attributes: np.ndarray,
    thresholds: dict[str, tuple[float, float]],
    *,
    n_frames: int,
    segment: int,
    fps: float = FPS,
) -> tuple[np.ndarray | None, np.ndarray]:
    """Frame masks for the search, one per distinct constraint set, and each step's index into them.

    Each search step uses the constraints active at its middle output frame.

    Parameters
    ----------
    attributes : np.ndarray, shape (M, 64, n_attributes)
    n_frames : int
        Output frames; steps cover ``[i*segment, min((i+1)*segment, n_frames))``.
    segment : int
        Frames per search step, N.

    Returns
    -------
    masks : np.ndarray, shape (n_masks, M, 64), bool, or None when nothing is constrained
    step_mask_index : np.ndarray, shape (n_steps,), int64
        Index into ``masks`` per step, ``-1`` for an unconstrained step.
    """
    n_steps = -(-n_frames // segment)
    labels = track.frame_labels(n_frames, fps=fps)
    keys: list[tuple] = []
    idx = np.full(n_steps, -1, dtype=np.int64)
    for i in range(n_steps):
        a, b = i * segment, min((i + 1) * segment, n_frames)
        c = labels[(a + b - 1) // 2]
        if c:
            if c not in keys:
                keys.append(c)
            idx[i] = keys.index(c)
    if not keys:
        return None, idx
    masks = np.stack([constraint_mask(attributes, k, thresholds) for k in keys])
    return masks, idx


# ---- the control table: a track as the app's editor and the inspector show it ----------------------

#: Columns of the control segment table, in order.
SEGMENT_COLUMNS: tuple[str, ...] = ("start_s", "end_s", "constraint")

#: Every single constraint a table row can hold, as ``"name=value"`` (see :data:`CONSTRAINTS`).
CONSTRAINT_CHOICES: tuple[str, ...] = tuple(
    f"{name}={value}" for name, (_, values) in CONSTRAINTS.items() for value in values
)


@checks_arguments
def empty_segments() -> pd.DataFrame:
    """A control table without rows, with the column types the editor needs."""
    import pandas as pd  # kept local: only the table needs pandas

    return pd.DataFrame(
        {
            "start_s": pd.Series([], dtype="float64"),
            "end_s": pd.Series([], dtype="float64"),
            "constraint": pd.Series([], dtype="object"),
        }
    )


@checks_arguments
def segments_frame(track: ControlTrack) -> pd.DataFrame:
    """A control track as a table: one row per constraint, sorted by time.

    A segment with several constraints gives several rows with the same
    times; :func:`track_from_segments` joins them again.

    Returns
    -------
    pandas.DataFrame
        Columns :data:`SEGMENT_COLUMNS`; ``start_s`` and ``end_s`` in seconds.
    """
    import pandas as pd  # kept local: only the table needs pandas

    rows = [
        {"start_s": float(s.start_s), "end_s": float(s.end_s), "constraint": f"{n}={v}"}
        for s in track.segments
        for n, v in s.constraints
    ]
    return (
        pd.DataFrame(rows, columns=list(SEGMENT_COLUMNS)).astype({"start_s": "float64", "end_s": "float64"})
        if rows
        else empty_segments()
    )


def _is_blank(value: object) -> bool:
    import pandas as pd  # kept local: only the table needs pandas

    if value is None:
        return True
    if isinstance(value, str):
        return not value.strip()
    try:
        return bool(pd.isna(value))
    except (TypeError, ValueError):
        return False


@checks_arguments
def track_from_segments(table: pd.DataFrame | Sequence[Mapping]) -> ControlTrack:
    """The control track a segment table describes.

    Rows whose cells are all empty (a row just added in the editor) are
    ignored. Rows with the same start and end form one segment whose
    constraints must all hold.

    Parameters
    ----------
    table : pandas.DataFrame or sequence of mappings
        Columns ``start_s``, ``end_s`` (seconds) and ``constraint``
        (``"name=value"``, one of :data:`CONSTRAINT_CHOICES`).

    Returns
    -------
    ControlTrack

    Raises
    ------
    ConfigError
        A row with a missing or invalid value, end not after start, one
        control set twice for the same time range, or segments that overlap;
        the message names the row (counted from 1).
    """
    import pandas as pd  # kept local: only the table needs pandas

    records = table.to_dict("records") if isinstance(table, pd.DataFrame) else [dict(r) for r in table]
    groups: dict[tuple[float, float], list[tuple[str, str]]] = {}
    first_row: dict[tuple[float, float], int] = {}
    for i, seg in filled_rows(records):
        key = (seg.start_s, seg.end_s)
        name, value = seg.constraints[0]
        if any(n == name for n, _ in groups.get(key, [])):
            raise ConfigError(
                f"control row {i}: {name} is set twice for {seg.start_s:g}-{seg.end_s:g} s "
                f"(also in row {first_row[key]})"
            )
        groups.setdefault(key, []).append((name, value))
        first_row.setdefault(key, i)
    return ControlTrack(tuple(Segment(a, b, tuple(c)) for (a, b), c in groups.items()))


@checks_arguments
def filled_rows(records: Iterable[Mapping]) -> Iterator[tuple[int, Segment]]:
    """Each filled row of a control table, checked: (its number counted from 1, a segment of its one
    constraint); rows left blank (just added in an editor) are skipped.

    Raises
    ------
    ConfigError
        A row with a missing or invalid value, or end not after start; the message names the row.
    """
    for i, r in enumerate(records, start=1):
        cells = [r.get(c) for c in SEGMENT_COLUMNS]
        if all(_is_blank(v) for v in cells):
            continue
        missing = [c for c, v in zip(SEGMENT_COLUMNS, cells) if _is_blank(v)]
        if missing:
            raise ConfigError(f"control row {i}: fill in {', '.join(missing)}")
        try:
            start, end = float(r["start_s"]), float(r["end_s"])
        except (TypeError, ValueError):
            raise ConfigError(f"control row {i}: start_s and end_s must be numbers of seconds") from None
        text = str(r["constraint"]).strip()
        if text not in CONSTRAINT_CHOICES:
            raise ConfigError(
                f"control row {i}: unknown constraint {text!r}; choose one of {', '.join(CONSTRAINT_CHOICES)}"
            )
        try:
            yield i, Segment(start, end, (_constraint_pair(text),))
        except ConfigError as exc:
            raise ConfigError(f"control row {i}: {exc.problem}") from None


def _constraint_pair(text: str) -> tuple[str, str]:
    """``"name=value"`` (one of :data:`CONSTRAINT_CHOICES`) -> ``(name, value)``."""
    name, _, value = text.partition("=")
    return name, value


@checks_arguments
def add_segment(table: pd.DataFrame, start_s: float, end_s: float, constraint: str) -> pd.DataFrame:
    """The table with a new constraint over a time range, replacing what it overlaps.

    Rows overlapping ``[start_s, end_s)`` are cut back to the parts outside
    it (a row covering the whole range is split in two), so the table stays
    free of overlaps; blank rows are dropped.

    Parameters
    ----------
    table : pandas.DataFrame
        Columns :data:`SEGMENT_COLUMNS`.
    start_s, end_s : float
        The range, seconds, ``0 <= start_s < end_s``.
    constraint : str
        One of :data:`CONSTRAINT_CHOICES`.

    Returns
    -------
    pandas.DataFrame
        A new table sorted by start time with a fresh 0..n-1 index.

    Raises
    ------
    ConfigError
        An invalid range or constraint.
    """
    import pandas as pd  # kept local: only the table needs pandas

    if constraint not in CONSTRAINT_CHOICES:
        raise ConfigError(f"unknown constraint {constraint!r}; choose one of {', '.join(CONSTRAINT_CHOICES)}")
    new = Segment(float(start_s), float(end_s), (_constraint_pair(constraint),))
    rows = []
    for r in table.to_dict("records"):
        if all(_is_blank(r.get(c)) for c in SEGMENT_COLUMNS):
            continue
        try:
            a, b = float(r["start_s"]), float(r["end_s"])
        except (TypeError, ValueError):
            rows.append(r)  # an unfinished row: the user's to fix, not ours to drop
            continue
        if not (a < new.end_s and b > new.start_s):
            rows.append(r)
            continue
        for lo, hi in ((a, min(b, new.start_s)), (max(a, new.end_s), b)):
            if hi - lo > 1e-6:
                rows.append({**r, "start_s": lo, "end_s": hi})
    rows.append({"start_s": new.start_s, "end_s": new.end_s, "constraint": constraint})
    out = pd.DataFrame(rows, columns=list(SEGMENT_COLUMNS)).astype({"start_s": "float64", "end_s": "float64"})
    return out.sort_values(["start_s", "end_s"], kind="stable").reset_index(drop=True)
