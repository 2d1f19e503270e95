"""Interactive plotly figures of motions, databases and speech, for the app and notebooks.

Every function returns a :class:`plotly.graph_objects.Figure` and imports
nothing from streamlit, so the same figure can be shown with
``st.plotly_chart`` or ``fig.show()`` in a notebook. Coordinates follow
:mod:`gesturekit.skeleton`: metres, Y up, the character faces +Z and its
left is +X. Numeric arrays are handed to plotly as float32 numpy arrays, which
plotly serialises as compact typed arrays; the skeleton figure's many small
per-frame arrays are handed over already encoded that way (see
:func:`data_array` to read them back), since plotly's own per-array checks and
conversions took most of a second for a 30 s motion.

Traces carry a ``meta`` dict that says what they show (``{"motion": i,
"part": "body" | "hands" | "joints"}`` for skeletons, ``{"part": ...}``
elsewhere), so pages and tests can find them without relying on their order.

The figures are made in :mod:`gesturekit.viz.skeleton_figure` (the 3D
skeleton) and :mod:`gesturekit.viz.charts` (histograms, waveforms, wrist
tracks, candidates); this module is the one place to import them from.
"""

from __future__ import annotations

from ._plotly import MOTION_COLORS, data_array
from .charts import WRIST_ROWS, attribute_histograms, candidates_figure, waveform_figure, wrist_figure
from .skeleton_figure import DEFAULT_MAX_FRAMES, skeleton_figure

__all__ = [
    "DEFAULT_MAX_FRAMES",
    "MOTION_COLORS",
    "skeleton_figure",
    "attribute_histograms",
    "waveform_figure",
    "WRIST_ROWS",
    "wrist_figure",
    "candidates_figure",
    "data_array",
]
