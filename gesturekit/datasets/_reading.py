"""How a take was read: axes, units, derived and absent joints, bone lengths.

Readers return a :class:`Reading` next to the motion; :func:`gesturekit.datasets.takes.iter_takes`
keeps its text in the take's sources (so the database stores it, and ``gesturekit info``
shows it), and :func:`reading_lines` groups the takes' readings for printing.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace

import numpy as np

from .._arguments import checks_arguments
from ..bones import Skeleton, normalise_bone_lengths
from ..motion import Motion
from ..skeleton import JointPresence
from ._axes import UNIT_SCALE, check_given_units, check_given_up, check_upright, detect_units, to_our_frame
from ._partial import complete_skeleton

__all__ = ["Reading", "convert_and_complete", "normalise_motion", "reading_lines", "READING_KEY"]

#: The key of a take's sources that holds its reading (:meth:`Reading.text`).
READING_KEY = "reading"
# between a reading and the bone normalisation's summary (which differs per take)
BONES_SEPARATOR = "; bones: "


@dataclass(frozen=True)
class Reading:
    """How one take was read.

    Attributes
    ----------
    up : str
        The source's up axis (``"y"`` when it was checked to be upright as it was).
    up_given : bool
        ``up`` was given (else it was Y, checked).
    forward : str
        The source axis the body faces.
    forward_given : bool
        ``forward`` was given (else it was found from the shoulders).
    units : str
        The length unit of the file.
    units_given : bool
        ``units`` was given (else detected).
    presence : JointPresence
        Which joints are recorded, derived and absent.
    bones : str
        The bone-length normalisation's summary, or ``""`` when not normalised.
    """

    up: str
    up_given: bool
    forward: str
    forward_given: bool
    units: str
    units_given: bool
    presence: JointPresence
    bones: str = ""

    def text(self) -> str:
        """One line, e.g. ``"up -y (given), forward -z (from the shoulders), units m (detected); joints: ..."``."""
        up = f"up {self.up} ({'given' if self.up_given else 'checked upright'})"
        fwd = f"forward {self.forward} ({'given' if self.forward_given else 'from the shoulders'})"
        units = f"units {self.units} ({'given' if self.units_given else 'detected'})"
        out = f"{up}, {fwd}, {units}; joints: {self.presence.describe()}"
        return out + (f"{BONES_SEPARATOR}{self.bones}" if self.bones else "")


def convert_and_complete(
    positions: np.ndarray,
    recorded: np.ndarray,
    *,
    units: str,
    up: str | None,
    forward: str,
    path: str | os.PathLike[str] | None = None,
    check_plausible: bool = True,
    check_units: bool = True,
) -> tuple[np.ndarray, Reading]:
    """Source positions in metres, our axes, with the joints the source lacks placed.

    Parameters
    ----------
    positions : np.ndarray, shape (frames, 55, 3)
        Positions in the file's units and axes; only ``recorded`` joints are read.
    recorded : np.ndarray, shape (55,) bool
        Joints the source holds (at least the required ones).
    units : {"auto", "m", "cm", "mm"}
    up : {"y", "-y", "z", "-z"} or None
        None: Y, checked upright (:func:`gesturekit.datasets._axes.check_upright`).
    forward : {"auto", "x", "-x", "y", "-y", "z", "-z"}
    path : path, optional
        The file, named in messages.
    check_plausible : bool
        Check given values as ``auto`` ones are: the body's size in the given ``units``
        (:func:`~gesturekit.datasets._axes.check_given_units`), its uprightness with the given
        ``up`` (:func:`~gesturekit.datasets._axes.check_given_up`).
    check_units : bool
        With ``check_plausible``: check the units too (False when the caller checked them).

    Returns
    -------
    positions : np.ndarray, shape (frames, 55, 3), float64, metres, our frame
    reading : Reading
    """
    pos = np.asarray(positions, dtype=np.float64)
    rec = np.asarray(recorded, dtype=bool)
    unit = detect_units(pos, path=path) if units == "auto" else units
    if units != "auto" and check_plausible and check_units:
        check_given_units(pos, unit, path=path)
    pos = pos * UNIT_SCALE[unit]
    if up is None:
        check_upright(pos, recorded=rec, path=path, what="the motion")
    elif check_plausible:
        check_given_up(pos, up, recorded=rec, path=path)
    turned, fwd = to_our_frame(pos, up=up or "y", forward=forward)
    placed, presence = complete_skeleton(turned, rec)
    reading = Reading(
        up=up or "y",
        up_given=up is not None,
        forward=fwd,
        forward_given=forward != "auto",
        units=unit,
        units_given=units != "auto",
        presence=presence,
    )
    return placed, reading


def normalise_motion(motion: Motion, reading: Reading, *, skeleton: Skeleton | None = None) -> tuple[Motion, Reading]:
    """``motion`` with one length per bone (:func:`gesturekit.bones.normalise_bone_lengths`: its own medians,
    or ``skeleton``'s lengths and rigid shapes), and its reading with the report's summary."""
    positions, report = normalise_bone_lengths(motion.positions, motion.presence, skeleton=skeleton)
    out = Motion(positions.astype(np.float32), motion.fps, motion.joints)
    return out, replace(reading, bones=report.summary())


@checks_arguments
def reading_lines(takes: Iterable[Mapping]) -> list[str]:
    """How a database's takes were read, for printing: one line per distinct reading.

    Parameters
    ----------
    takes : iterable of dict
        The database's ``meta["takes"]`` (each with ``name`` and ``sources``).

    Returns
    -------
    list of str
        ``"<reading>  (takes a, b, ...)"``; the bone normalisation's summary, which
        differs per take, on a line of its own per take. Empty when no take
        has a reading.
    """
    groups: dict[str, list[str]] = {}
    bones: list[str] = []
    for t in takes:
        text = str(t.get("sources", {}).get(READING_KEY, ""))
        if not text:
            continue
        head, _, tail = text.partition(BONES_SEPARATOR)
        groups.setdefault(head, []).append(str(t.get("name", "?")))
        if tail:
            bones.append(f"  {t.get('name', '?')}: {tail}")
    lines = []
    for head, names in groups.items():
        shown = ", ".join(names[:6]) + (f" and {len(names) - 6} more" if len(names) > 6 else "")
        lines.append(f"reading    {head}  (takes {shown})")
    return lines + bones
