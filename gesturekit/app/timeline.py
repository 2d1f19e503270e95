"""The control timeline: a Streamlit component of ours (``gesturekit/viz/web/src/timeline.js``, built with the
viewer's bundle into ``static/timeline``) where controls are painted as ranges in one lane per control.

The page gives it the control table's ranges and gets back the user's edits
(:func:`control_timeline`); :mod:`gesturekit.control_lanes` turns ranges into the
track the search uses.
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gesturekit.control import ATTRIBUTE_UNITS
from gesturekit.control_lanes import LANE_LABELS, LANES, curve_attribute, lane_levels
from gesturekit.datasets.audio import wav_bytes
from gesturekit.motion import AUDIO_SR

__all__ = ["timeline_component", "lanes_args", "waveform_peaks", "control_timeline", "rows_of"]

#: Columns of the waveform's envelope the timeline draws (one value each, 0..1).
PEAKS = 1200


@functools.cache
def timeline_component() -> Any:
    """The control timeline as a Streamlit component, served from the build's ``static/timeline`` folder."""
    from streamlit.components.v1 import declare_component

    from gesturekit.viz.web.build import TIMELINE

    if not (TIMELINE / "timeline.js").is_file():  # said here, rather than shown as a blank frame
        raise FileNotFoundError(
            f"{TIMELINE / 'timeline.js'} is missing: build it with `python -m gesturekit.viz.web.build`"
        )
    return declare_component("control_timeline", path=str(TIMELINE))


def lanes_args(thresholds: Mapping[str, tuple[float, float]]) -> list[dict]:
    """One dict per lane, as the timeline draws it: name, label, levels (low, high), whether a curve can be
    drawn in it and, for that, the low and high thresholds of its attribute and the unit."""
    out = []
    for lane in LANES:
        attribute = curve_attribute(lane)
        low, high = thresholds.get(attribute, (0.0, 1.0)) if attribute else (0.0, 1.0)
        out.append(
            {
                "name": lane,
                "label": LANE_LABELS.get(lane, lane),
                "levels": list(lane_levels(lane)),
                "curve": attribute is not None and attribute in thresholds,
                "low": float(low),
                "high": float(high),
                "unit": ATTRIBUTE_UNITS.get(attribute or "", ""),
            }
        )
    return out


def waveform_peaks(audio: np.ndarray, *, columns: int = PEAKS) -> list[float]:
    """The speech's envelope: the largest magnitude in each of ``columns`` equal stretches, scaled to 0..1.

    Parameters
    ----------
    audio : np.ndarray, shape (samples,)
        Mono speech.
    columns : int
        Stretches (fewer when the speech has fewer samples).

    Returns
    -------
    list of float
        One value per stretch, rounded to 3 decimals.
    """
    a = np.abs(np.asarray(audio, dtype=np.float32).ravel())
    if a.size == 0:
        return []
    n = min(columns, a.size)
    edges = np.linspace(0, a.size, n + 1).astype(int)
    peaks = np.maximum.reduceat(a, edges[:-1])
    top = float(peaks.max())
    return [round(float(p), 3) for p in (peaks / top if top > 0 else peaks)]


@functools.lru_cache(maxsize=4)
def _speech(audio_bytes: bytes) -> tuple[bytes, str, tuple[float, ...]]:
    audio = np.frombuffer(audio_bytes, dtype=np.float32)
    wav = wav_bytes(audio)
    return wav, hashlib.sha256(wav).hexdigest()[:16], tuple(waveform_peaks(audio))


def control_timeline(
    audio: np.ndarray,
    ranges: Sequence[Mapping],
    *,
    thresholds: Mapping[str, tuple[float, float]],
    step_s: float,
    edit: str | None,
    key: str,
) -> dict | None:
    """Draw the control timeline; returns the user's last edit, or None before the first.

    Parameters
    ----------
    audio : np.ndarray, shape (samples,)
        The speech, mono float32 at 16 kHz: its waveform is drawn and its Play plays it.
    ranges : sequence of mappings
        The ranges to show: rows of the control table (``start_s``, ``end_s``, ``constraint``).
    thresholds : mapping
        The database's thresholds (attribute -> (low, high)), for the curves.
    step_s : float
        Seconds per search step: the timeline snaps to multiples of it.
    edit : str or None
        The id of the timeline's last edit that ``ranges`` already hold (so it keeps its selection).
    key : str
        The component's key.

    Returns
    -------
    dict or None
        ``edit`` (a new id per edit), ``ranges`` (``lane``, ``level``, ``start_s``, ``end_s``) and
        ``curve`` (``lane``, ``t``, ``y`` of a curve just drawn, else None).
    """
    a = np.ascontiguousarray(audio, dtype=np.float32)
    wav, digest, peaks = _speech(a.tobytes())
    shown = []
    for r in ranges:
        lane, _, level = str(r["constraint"]).partition("=")
        shown.append({"lane": lane, "level": level, "start_s": float(r["start_s"]), "end_s": float(r["end_s"])})
    value = timeline_component()(
        lanes=lanes_args(thresholds),
        ranges=shown,
        duration_s=len(a) / AUDIO_SR,
        step_s=float(step_s),
        peaks=list(peaks),
        audio=wav,
        audio_hash=digest,
        edit=edit,
        key=key,
        default=None,
    )
    return value if isinstance(value, dict) else None


def rows_of(value: Mapping) -> list[dict]:
    """The timeline's ranges (:func:`control_timeline`'s ``ranges``) as rows of the control table."""
    return [
        {"start_s": float(r["start_s"]), "end_s": float(r["end_s"]), "constraint": f"{r['lane']}={r['level']}"}
        for r in value.get("ranges", [])
    ]
