"""What the plotly figures share: colours, motions on a common time grid, and compact typed arrays.

Numeric arrays are handed to plotly as float32 typed-array specs (little-endian,
base64), the form plotly itself serialises them to; :func:`data_array` reads
any form back. Used by :mod:`gesturekit.viz.skeleton_figure`,
:mod:`gesturekit.viz.figures` and :mod:`gesturekit.viz.viewer`.
"""

from __future__ import annotations

import base64
import html
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._arguments import checks_arguments
from ..character.look import ROLE_SCHEMES, SCHEMES, SIDE_BY_SIDE
from ..errors import ConfigError
from ..motion import Motion

#: Colours of the motions of a figure, in order (repeated past the end): the shirts of the 3D views'
#: side-by-side characters (:data:`gesturekit.character.look.SIDE_BY_SIDE`, k-NN blue, refined orange), so a
#: motion has one colour on the page's 3D view, in its plots and in the MP4.
MOTION_COLORS = tuple(SCHEMES[s]["shirt"] for s in SIDE_BY_SIDE)

#: The colour of what a plot shows by its role (:data:`gesturekit.character.look.ROLE_SCHEMES`: the k-NN result,
#: the refined motion, the candidate a search step chose): the shirt of a character in that role, so a role has
#: one colour in the 3D views, the 2D figures and the MP4s.
ROLE_COLORS = {role: SCHEMES[scheme]["shirt"] for role, scheme in ROLE_SCHEMES.items()}

_BAND_COLORS = ("#4c78a8", "#f58518", "#54a24b", "#e45756", "#b279a2", "#72b7b2", "#eeca3b", "#9d755d")


def _typed(values: np.ndarray) -> dict:
    """A float32 array as plotly's typed-array spec (little-endian, base64), as plotly itself writes it."""
    return {"dtype": "f4", "bdata": base64.b64encode(np.ascontiguousarray(values, "<f4").tobytes()).decode("ascii")}


def _xyz(points: np.ndarray) -> dict:
    """x, y, z of ``points`` (n, 3) as typed-array specs."""
    return {"x": _typed(points[:, 0]), "y": _typed(points[:, 1]), "z": _typed(points[:, 2])}


@checks_arguments
def data_array(value: dict | Sequence[Any] | np.ndarray) -> np.ndarray:
    """A plotly data array as numbers, whichever form it takes.

    Parameters
    ----------
    value : typed-array spec, sequence or np.ndarray
        A trace's ``x``/``y``/``z`` as a figure holds it (or as its JSON has it):
        plotly's typed-array dict ``{"dtype", "bdata"[, "shape"]}``, a list
        (``None`` for a gap) or an array.

    Returns
    -------
    np.ndarray, float64
        The values; gaps are NaN.
    """
    if isinstance(value, dict) and "bdata" in value:
        out = np.frombuffer(base64.b64decode(value["bdata"]), dtype=np.dtype(value["dtype"]).newbyteorder("<"))
        if value.get("shape"):
            out = out.reshape([int(d) for d in str(value["shape"]).split(",")])
        return out.astype(np.float64)
    cells = np.asarray(value, dtype=object)
    return np.array([np.nan if v is None else v for v in cells.ravel()], dtype=np.float64).reshape(cells.shape)


def plotly_safe(text: str) -> str:
    """``text`` as plotly shows it literally in a trace name, legend, annotation or hover label.

    plotly reads a subset of HTML there (``<a href>`` makes a link) and fills ``%{...}`` in
    hover templates: labels and take names come from users and files.
    """
    return html.escape(str(text), quote=False).replace("%{", "%\u2060{")


def _motions_and_labels(
    motions, labels, *, who: str, empty_ok: bool = False, label_one: bool = False, drawn: bool = False
) -> tuple[list[Motion], list[str]]:
    """One motion or a list of them, with one label each (checked; ``who`` names the caller in errors).

    A motion with no frame is refused unless ``empty_ok``; without ``labels``
    the motions are called "motion 1", "motion 2", ..., a lone motion only if
    ``label_one`` (else its label is empty). With ``drawn``, a motion whose joints are all
    absent (nothing to draw) is refused.
    """
    motions = [motions] if isinstance(motions, Motion) else list(motions)
    if not motions:
        raise ConfigError(f"{who} needs at least one motion")
    for m in motions:
        if not isinstance(m, Motion):
            raise ConfigError(f"{who} takes Motion objects, got {type(m).__name__}")
        if m.n_frames < 1 and not empty_ok:
            raise ConfigError(f"{who} got a motion with no frame")
        if drawn and not m.presence.drawn.any():
            raise ConfigError(f"{who} got a motion whose joints are all absent: nothing to draw")
    if labels is None:
        labels = [f"motion {i + 1}" for i in range(len(motions))] if len(motions) > 1 or label_one else [""]
    labels = [str(s) for s in labels]
    if len(labels) != len(motions):
        raise ConfigError(f"{who} got {len(labels)} labels for {len(motions)} motions")
    return motions, labels


def _time_grid(motions: list[Motion], *, fps, max_frames: int) -> tuple[float, int, int, np.ndarray]:
    """The time grid a skeleton view plays on: ``(grid_fps, n_grid, step, times)``.

    ``grid_fps`` is ``fps`` or the fastest motion's frame rate; ``n_grid`` frames of it
    cover the longest motion; every ``step``-th grid time is shown so that at most
    ``max_frames`` remain; ``times`` are the shown times in seconds, shape (shown,).

    Raises
    ------
    ConfigError
        ``max_frames`` below 1, or a frame rate that is not a positive finite number.
    """
    if max_frames < 1:
        raise ConfigError(f"max_frames must be at least 1, got {max_frames}")
    grid_fps = float(fps) if fps is not None else max(float(m.fps) for m in motions)
    if not (math.isfinite(grid_fps) and grid_fps > 0):
        raise ConfigError(f"fps must be positive, got {fps}")
    duration = max(m.duration for m in motions)
    n_grid = max(1, int(math.ceil(duration * grid_fps - 1e-9)))
    step = int(math.ceil(n_grid / max_frames))
    return grid_fps, n_grid, step, np.arange(0, n_grid, step) / grid_fps


def _frames_at(motion: Motion, times: np.ndarray) -> np.ndarray:
    """Indices of ``motion``'s frames shown at ``times`` (seconds): sample and hold, the last frame past its end."""
    return np.minimum(np.floor(times * motion.fps + 1e-6).astype(np.int64), motion.n_frames - 1)
