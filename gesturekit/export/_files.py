"""Writing an export's file, the speech WAV beside it, and its accuracy warning, in that order.

The GLB, character GLB and character BVH writers measure what they wrote before any file
is touched; this puts the result on disk the same way for each.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._io import Target, target_path, write_to
from ..datasets.audio import write_wav
from ..errors import warn

__all__ = ["write_export"]


def write_export(
    path: Target,
    data: bytes,
    *,
    overwrite: bool,
    wav_path: Path | None = None,
    samples: np.ndarray | None = None,
    sr: int = 0,
    warning: str | None = None,
    stacklevel: int = 1,
) -> None:
    """Write ``data`` to ``path`` atomically (or into a binary file object), after the speech WAV
    beside it, then warn.

    Parameters
    ----------
    path : Path or binary file object
        The export file, or where to write its bytes.
    data : bytes
        Its whole content.
    overwrite : bool
        Replace existing files (checked by the writer beforehand).
    wav_path : Path, optional
        Where the speech goes (a 16-bit WAV marked as gesturekit's); nothing without it or ``samples``.
    samples : np.ndarray, shape (samples,), optional
        The speech, float in [-1, 1].
    sr : int
        Its sample rate, Hz.
    warning : str, optional
        Said (as a :class:`~gesturekit.errors.GestureKitWarning` prefixed with ``path``) once written.
    stacklevel : int
        Of the warning, counted from the caller of this function.
    """
    if wav_path is not None and samples is not None:
        # the speech first: a GLB naming its audio never exists without it
        write_wav(wav_path, samples, sr=int(sr), mark=True, overwrite=overwrite)
    write_to(path, lambda f: f.write(data), overwrite=overwrite)
    if warning is not None:
        warn(f"{target_path(path, 'the file')}: {warning}", stacklevel=stacklevel + 1)
