"""A synthesis result written as files: npz (everything), BVH (the motion), glTF (the character, with its
speech as a WAV beside it), MP4 (the motion with its speech); and on a user's character (a glTF, VRM or BVH read
by :func:`gesturekit.character.user.read_character`): their GLB or VRM animated, and a BVH of their skeleton.

Each writer refuses a result whose motion is not finite
(:meth:`~gesturekit.synthesis.SynthesisResult.check_finite`), writes atomically and
replaces an existing file only with ``overwrite=True``.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .._arguments import checks_arguments
from .._io import Target, target_path
from ..character.retarget import Retargeted, retarget
from ..character.target import Character
from ..errors import ConfigError
from ..synthesis import SynthesisResult
from .bvh import BvhReport, export_bvh
from .character import CharacterBvhReport, CharacterGltfReport, export_character_bvh, export_character_glb
from .gltf import GltfReport, export_gltf
from .npz import save_npz
from .video import render_video

__all__ = [
    "save_result_npz",
    "save_result_bvh",
    "export_result_bvh",
    "export_result_glb",
    "retarget_result",
    "export_result_character_glb",
    "export_result_character_bvh",
    "save_result_video",
]


@checks_arguments
def save_result_npz(result: SynthesisResult, path: Target, *, overwrite: bool = False) -> Path | None:
    """An npz archive of a synthesis (read it back with :func:`gesturekit.export.npz.load_npz`).

    It holds ``positions`` (the final motion, (T, 55, 3) metres), ``fps``,
    ``knn_positions`` (the k-NN motion), ``refined_positions`` (with a refiner),
    the search record as ``search_*`` arrays and :meth:`SynthesisResult.metadata` as its config.

    ``path`` is a path (written atomically) or a binary file object (:func:`~gesturekit.export.npz.save_npz`).

    Returns
    -------
    Path or None
        ``path``, complete; None for a file object.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from gesturekit.demo import build_demo_database
    >>> from gesturekit.datasets.synthetic import generate_demo_take
    >>> from gesturekit.export.npz import load_npz
    >>> from gesturekit.export.result import save_result_npz
    >>> from gesturekit.synthesis import synthesize
    >>> out = Path(tempfile.mkdtemp())
    >>> db = build_demo_database(out / "demo", minutes=0.5)
    >>> res = synthesize(generate_demo_take(seconds=2.0, seed=1, name="speech")[0].audio, db=db)
    >>> path = save_result_npz(res, out / "speech.npz")
    >>> motion, arrays, config = load_npz(path)
    >>> motion.positions.shape, arrays["knn_positions"].shape, config["synthesis"]["k"]
    ((30, 55, 3), (30, 55, 3), 0)
    >>> save_result_npz(res, path)  # an existing output is kept unless overwrite=True
    Traceback (most recent call last):
    ...
    gesturekit.errors.ConfigError: ...speech.npz: already exists; pass overwrite=True ...
    >>> path == save_result_npz(res, path, overwrite=True)
    True
    """
    result.check_finite(target_path(path, "result.npz"))
    arrays = {"knn_positions": result.knn_motion.positions}
    if result.refined_motion is not None:
        arrays["refined_positions"] = result.refined_motion.positions
    arrays.update({f"search_{k}": np.asarray(v) for k, v in result.search.array_fields().items()})
    return save_npz(path, motion=result.motion, arrays=arrays, config=result.metadata(), overwrite=overwrite)


@checks_arguments
def save_result_bvh(
    result: SynthesisResult, path: str | os.PathLike[str], *, overwrite: bool = False, units: str = "cm"
) -> Path:
    """A BVH file of the final motion; :func:`export_result_bvh` without its report.

    Returns
    -------
    Path
        ``path``, complete.
    """
    return export_result_bvh(result, path, overwrite=overwrite, units=units).path


@checks_arguments
def export_result_bvh(
    result: SynthesisResult, path: Target, *, overwrite: bool = False, units: str = "cm"
) -> BvhReport:
    """A BVH file of the final motion, and how well it reproduces the motion's positions.

    The hierarchy is that of the motion's drawn joints, every bone with one length (the
    median); see :func:`gesturekit.export.bvh.export_bvh`, which also warns when the file
    is more than 1 cm off the positions. ``units`` (``"cm"`` or ``"m"``) are those of the
    file's offsets and root positions. The warning names what would help: for a database
    without one skeleton ``build-db --normalize-bones``; for one with it (whose clips the
    file holds exactly) what changed the bones afterwards: the refiner.

    Returns
    -------
    BvhReport
        The file, its largest and mean position error (metres), root and joints left out;
        ``report.summary()`` is one line.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from gesturekit.demo import build_demo_database
    >>> from gesturekit.datasets.synthetic import generate_demo_take
    >>> from gesturekit.export.result import export_result_bvh
    >>> from gesturekit.synthesis import synthesize
    >>> out = Path(tempfile.mkdtemp())
    >>> db = build_demo_database(out / "demo", minutes=0.5)
    >>> res = synthesize(generate_demo_take(seconds=2.0, seed=1, name="speech")[0].audio, db=db)
    >>> report = export_result_bvh(res, out / "speech.bvh")
    >>> report.root, report.max_error < 1e-4  # metres: the file holds the motion
    ('spine_mid', True)
    """
    result.check_finite(target_path(path, "result.bvh"))
    return export_bvh(path, result.motion, overwrite=overwrite, units=units, remedy=_bvh_remedy(result))


@checks_arguments
def export_result_glb(
    result: SynthesisResult, path: str | os.PathLike[str], *, overwrite: bool = False, scheme: str = "blue"
) -> GltfReport:
    """A binary glTF file of the final motion on the character, its speech as a WAV beside it, and how
    well the file reproduces the motion's positions.

    See :func:`gesturekit.export.gltf.export_gltf`, which writes the speech to
    :func:`gesturekit.export.gltf.audio_path_for` ``(path)`` (the same name with ``.wav``),
    names it in the file, and warns when the file is more than 1 mm off the positions (naming
    what would help, as for the BVH). ``scheme`` is the body's colour scheme.

    Returns
    -------
    GltfReport
        The files, the animation's frames and rate, its largest and mean position error
        (metres); ``report.summary()`` is one line.
    """
    result.check_finite(path)
    return export_gltf(
        path, result.motion, audio=result.audio, scheme=scheme, overwrite=overwrite, remedy=_bvh_remedy(result)
    )


@checks_arguments
def retarget_result(result: SynthesisResult, character: Character | Retargeted) -> Retargeted:
    """The final motion of ``result`` on a user's character (:func:`gesturekit.character.retarget.retarget`).

    Parameters
    ----------
    result : SynthesisResult
    character : Character or Retargeted
        The character (read with :func:`gesturekit.character.user.read_character`), or the result's motion already
        retargeted onto it (returned as it is, after checking that it is this result's motion).

    Raises
    ------
    ConfigError
        A ``Retargeted`` of another motion.
    """
    if isinstance(character, Retargeted):
        source = character.source
        if source.n_frames != result.motion.n_frames or not np.array_equal(source.positions, result.motion.positions):
            raise ConfigError(f"the motion retargeted onto {character.character.path.name} is not this result's")
        return character
    return retarget(result.motion, character)


@checks_arguments
def export_result_character_glb(
    result: SynthesisResult,
    character: Character | Retargeted,
    path: str | os.PathLike[str],
    *,
    overwrite: bool = False,
    their_clips: str = "keep",
) -> CharacterGltfReport:
    """The user's glTF or VRM character with the final motion as its animation ``"gesturekit"``, its speech as a
    WAV beside it (:func:`gesturekit.export.gltf.audio_path_for`), and how well the file reproduces the
    retargeted motion.

    See :func:`gesturekit.export.character.export_character_glb`; ``path`` ends in ``.glb`` or ``.vrm``.

    Parameters
    ----------
    result : SynthesisResult
    character : Character or Retargeted
        As for :func:`retarget_result` (pass the ``Retargeted`` to retarget once for several files).
    path : str or os.PathLike
    overwrite : bool
        Replace files gesturekit wrote.
    their_clips : {"keep", "drop"}
        The character's own animations: kept after ours (default) or left out.

    Returns
    -------
    CharacterGltfReport
        ``report.summary()`` is one line.
    """
    result.check_finite(path)
    posed = retarget_result(result, character)
    return export_character_glb(path, posed, audio=result.audio, overwrite=overwrite, their_clips=their_clips)


@checks_arguments
def export_result_character_bvh(
    result: SynthesisResult,
    character: Character | Retargeted,
    path: str | os.PathLike[str],
    *,
    overwrite: bool = False,
    units: str | None = None,
) -> CharacterBvhReport:
    """A BVH of the user's character's skeleton moved by the final motion, in its file's frame, and how well it
    reproduces the retargeted motion.

    See :func:`gesturekit.export.character.export_character_bvh`: a BVH character keeps its offsets, units and
    channel orders; ``units`` (``"cm"`` or ``"m"``) overrides its units (default centimetres for a glTF or VRM).

    Returns
    -------
    CharacterBvhReport
        ``report.summary()`` is one line.
    """
    result.check_finite(path)
    return export_character_bvh(path, retarget_result(result, character), units=units, overwrite=overwrite)


def _bvh_remedy(result: SynthesisResult) -> str | None:
    """What a BVH warning names as the way to a closer file; None: the default (``--normalize-bones``)."""
    if not result.one_skeleton:
        return None
    # the database's clips have one skeleton: only what is done to them afterwards changes their bones
    # (a blend gives the k-NN motion's bones back, see Synthesizer.keep_bones)
    causes = []
    if result.refined_motion is not None:
        causes.append("without the refiner (`--refiner none`)")
    if not causes:
        return "the database already gives every take one skeleton"
    return (
        "the database already gives every take one skeleton, and the k-NN motion keeps it "
        + " and ".join(causes)
        + ", which change the bones' lengths"
    )


@checks_arguments
def save_result_video(
    result: SynthesisResult,
    path: str | os.PathLike[str],
    *,
    overwrite: bool = False,
    progress: Callable[[int, int], None] | None = None,
    side_by_side: bool = False,
    resolution: tuple[int, int] = (640, 480),
    look: str = "character",
    character: Character | None = None,
    framing: str = "upper body",
) -> Path:
    """An MP4 of the character with the speech (H.264 + AAC); the k-NN and the refined motion side by
    side when ``side_by_side`` and the result was refined. ``resolution`` is (width, height) in pixels;
    ``look`` one of :data:`gesturekit.viz.render.LOOKS` (the page's character, or the capsule figure);
    ``framing`` the presenter's upper body and every hand (default) or the whole body down to the floor
    (:data:`gesturekit.character.look.FRAMINGS`);
    ``character`` a user's character the motion is retargeted onto (see
    :func:`gesturekit.export.video.render_video`).

    Raises
    ------
    MissingDependencyError
        The rendering libraries (the ``render`` extra) are not installed.
    """
    result.check_finite(path)
    from .._optional import require

    require("pyvista", purpose="rendering a video")  # the rendering libraries load only when rendering
    from ..viz.render import RenderStyle

    style = RenderStyle(look=look, framing=framing)
    if side_by_side and result.refined_motion is not None:
        return render_video(
            path,
            result.knn_motion,
            audio=result.audio,
            side_by_side=result.refined_motion,
            labels=("k-NN", "k-NN + refiner"),
            overwrite=overwrite,
            progress=progress,
            resolution=resolution,
            style=style,
            character=character,
        )
    return render_video(
        path,
        result.motion,
        audio=result.audio,
        overwrite=overwrite,
        progress=progress,
        resolution=resolution,
        style=style,
        character=character,
    )
