"""The character viewer in Jupyter: the page's own viewer, shown in a notebook cell or saved as one HTML file.

:func:`character_view` wraps :func:`gesturekit.viz.viewer.skeleton_viewer`'s
self-contained page (three.js bundled in, the data and the speech embedded,
nothing fetched from the network) in an object a notebook displays: the cell
shows it in an ``<iframe srcdoc=...>``, so the page's script runs in its own
document, as in the app. The same object saves the page as a file that any
browser opens offline.
"""

from __future__ import annotations

import html
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy.typing as npt

from .._arguments import checks_arguments
from .._io import atomic_write
from ..errors import ConfigError
from ..motion import AUDIO_SR, Motion
from .viewer import CONTROLS_HEIGHT, ViewOptions, skeleton_viewer

if TYPE_CHECKING:
    from typing_extensions import Unpack

__all__ = ["CharacterView", "character_view"]


class CharacterView:
    """A viewer page that a notebook shows in a cell (``_repr_html_``) and that :meth:`save` writes.

    Parameters
    ----------
    page : str
        The page (:func:`gesturekit.viz.viewer.skeleton_viewer`'s HTML).
    height : int
        Height of its drawing, pixels (the controls add :data:`~gesturekit.viz.viewer.CONTROLS_HEIGHT`).
    """

    def __init__(self, page: str, *, height: int) -> None:
        self.page = page
        self.height = int(height)

    def _repr_html_(self) -> str:
        # srcdoc: the page runs in a document of its own, like the app's iframe; its own bundle needs no server
        return (
            f'<iframe srcdoc="{html.escape(self.page, quote=True)}" '
            f'style="width:100%;height:{self.height + CONTROLS_HEIGHT + 4}px;border:0" '
            'allow="autoplay" title="gesturekit character viewer"></iframe>'
        )

    def save(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
        """Write the page as one HTML file, atomically (it plays offline in any browser with WebGL).

        Parameters
        ----------
        path : str or os.PathLike
            The file; its folder must exist.
        overwrite : bool
            Replace an existing file.

        Returns
        -------
        Path
            The file written.

        Raises
        ------
        OutputError
            ``path`` exists and ``overwrite`` is False, or is a folder.
        """
        data = self.page.encode("utf-8")
        return atomic_write(path, lambda f: f.write(data), overwrite=overwrite)


@checks_arguments
def character_view(
    motions: Motion | Sequence[Motion],
    *,
    audio: npt.ArrayLike | None = None,
    sr: int = AUDIO_SR,
    height: int = 420,
    **view: Unpack[ViewOptions],
) -> CharacterView:
    """Motions as the app shows them, side by side in one clock with their speech, for a notebook.

    Parameters
    ----------
    motions : Motion or sequence of Motion
        Joint positions (frames, 55, 3), metres, each at its own fps.
    audio : array_like, optional
        The speech, shape (samples,), float in [-1, 1], from the motions' first frame; the play
        button plays it and the shown frame follows it.
    sr : int
        ``audio``'s sample rate, Hz.
    height : int
        Height of the drawing, pixels.
    **view
        ``labels``, ``fps``, ``title``, ``max_frames``, ``spacing``, ``neutral``, ``character``
        (a user's character, :func:`gesturekit.character.user.read_character`, that every motion is
        retargeted onto and drawn as): as for :func:`gesturekit.viz.viewer.viewer_data`.

    Returns
    -------
    CharacterView
        Shown by a notebook when it is a cell's value; ``.save(path)`` writes the page.

    Raises
    ------
    ConfigError
        As :func:`gesturekit.viz.viewer.skeleton_viewer`, or ``height`` not a positive integer.
    """
    if isinstance(height, bool) or not isinstance(height, int) or height <= 0:
        raise ConfigError(f"the viewer's height must be a positive number of pixels, got {height!r}")
    return CharacterView(
        skeleton_viewer(motions, audio=audio, sr=sr, height=height, key="notebook", **view), height=height
    )
