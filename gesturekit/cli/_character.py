"""``synthesize --character``: the user's character read before the search, its files written per result.

With a character, ``--format glb`` writes their GLB or VRM animated by the
motion (``NAME.glb``, the speech beside it) and ``--format bvh`` a BVH of their
skeleton (``NAME.bvh``); the npz keeps our joints. Each result prints the
retarget report, the files' read-back errors and, with a control track, how
well our motion and the character's meet it.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ..character.retarget import Retargeted
from ..character.target import Character
from ..errors import ConfigError
from ..outputs import check_output

if TYPE_CHECKING:
    from ..synthesis import SynthesisResult

__all__ = ["read_character_option", "check_target", "write_character_files"]


def read_character_option(args: argparse.Namespace, formats: Sequence[str]) -> Character | None:
    """The character of ``--character`` (matched by ``--character-map`` when given); None without it.

    Raises
    ------
    InputFileError, ConfigError
        An unreadable character, a bone needed that it lacks (named), a map without ``--character``, or
        ``--format glb`` for a BVH character (a skeleton without a body).
    """
    given = getattr(args, "character", None)
    bone_map = getattr(args, "character_map", None)
    slack = getattr(args, "wrist_slack", None)
    if given is None:
        if bone_map is not None:
            raise ConfigError("--character-map names the bones of a --character; give the character too")
        if slack is not None:
            raise ConfigError("--wrist-slack says how a --character's arms are posed; give the character too")
        return None
    from ..character.target import WRIST_SLACK, check_wrist_slack
    from ..character.user import read_character

    slack = WRIST_SLACK if slack is None else check_wrist_slack(slack, name="--wrist-slack")
    character = read_character(given, bone_map=bone_map, wrist_slack=slack)
    if character.gltf is None and "glb" in formats:
        raise ConfigError(
            f"{given} is a skeleton without a body, so no glTF of it can be written; "
            "use --format bvh (or npz,bvh) with it, or give a .glb, .gltf, .vrm or .fbx character"
        )
    return character


def check_target(
    path: Path, kind: str, character: Character | None, *, overwrite: bool, inputs: Sequence[Path | str]
) -> None:
    """Whether an output of ``synthesize`` may be written (a character's BVH replaces a BVH of its own skeleton)."""
    if character is None or kind != "bvh":
        check_output(path, "file", overwrite=overwrite, inputs=[*inputs, *([character.path] if character else [])])
        return
    from ..export.character import character_bvh_joints, check_character_bvh

    joints = character_bvh_joints(character)
    check_character_bvh(path, joints, overwrite=overwrite, inputs=[*inputs, character.path])


def write_character_files(
    result: SynthesisResult,
    character: Character | Retargeted,
    targets: Mapping[str, Path],
    *,
    overwrite: bool,
    thresholds: Mapping[str, tuple[float, float]],
    show: Callable[[str], None],
    their_clips: str = "keep",
) -> None:
    """Retarget a result's motion onto ``character`` and write its files; print what they hold.

    Parameters
    ----------
    result : SynthesisResult
    character : Character or Retargeted
        The character, or the result's motion already retargeted onto it (so that a character that cannot carry
        the motion is refused before any file of the result is written).
    targets : mapping
        ``"glb"`` and/or ``"bvh"`` -> the file to write.
    overwrite : bool
    thresholds : mapping
        The database's attribute thresholds, for control adherence.
    show : callable
        Prints one line.
    their_clips : {"keep", "drop"}
        The character's own animations in its GLB (``--character-clips``).
    """
    from ..evaluate.metrics import control_adherence, overall_adherence
    from ..export.result import export_result_character_bvh, export_result_character_glb, retarget_result

    retargeted = retarget_result(result, character)
    character = retargeted.character
    show(f"  on {character.path.name} ({character.matched_by}): {retargeted.report.summary()}")
    if "glb" in targets:
        glb = export_result_character_glb(
            result, retargeted, targets["glb"], overwrite=overwrite, their_clips=their_clips
        )
        show(f"  glTF {glb.summary()}")
    if "bvh" in targets:
        bvh = export_result_character_bvh(result, retargeted, targets["bvh"], overwrite=overwrite)
        show(f"  BVH {bvh.summary()}")
    if result.control.segments:
        ours, theirs = (
            overall_adherence(control_adherence(m.positions, result.control, thresholds=dict(thresholds), fps=m.fps))
            for m in (result.motion, retargeted.our_motion())
        )
        show(
            f"  control met on {ours:.0%} of the constrained frames by our motion, "
            f"{theirs:.0%} by {character.path.name}'s"
        )
