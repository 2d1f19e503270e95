"""The user's own character: uploaded in the sidebar, kept per session, shown in the 3D views, written as files.

A glTF/GLB, VRM or BVH humanoid (and, optionally, a JSON bone map) is read
with :func:`gesturekit.character.user.read_character_upload` from a temporary
copy under a sanitised name; the uploads are limited as every upload of the
app is (``server.maxUploadSize``). What was matched, or why the file cannot be
used, is shown in the sidebar; the character is kept in ``st.session_state``
under :data:`CHARACTER_KEY` until "Default character" is pressed. The
Synthesize page's viewer and the Retrieval inspector's side-by-side viewers
then draw it (:func:`display.show_skeletons`); the Synthesize page renders
its MP4 on it (:func:`render_mp4`) and offers it, posed by the result, as a GLB
(a glTF or VRM character) and a BVH. A slider sets how far its wrists may stay from
our reach (:attr:`~gesturekit.character.target.Character.wrist_slack`).
"""

from __future__ import annotations

import dataclasses
import secrets
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import streamlit as st

from gesturekit.app.display import LOG, error_text, escape_markdown
from gesturekit.character.target import WRIST_SLACK, WRIST_SLACK_MAX
from gesturekit.character.user import read_character_upload
from gesturekit.errors import GestureKitError, collect_warnings
from gesturekit.export.character import THEIR_CLIPS
from gesturekit.skeleton import FINGERS, JOINT_NAMES

if TYPE_CHECKING:
    from gesturekit.character.target import Character
    from gesturekit.synthesis import SynthesisResult

__all__ = [
    "CHARACTER_KEY",
    "CHARACTER_TYPES",
    "character_downloads",
    "character_token",
    "current_character",
    "render_mp4",
    "sidebar_character",
]

#: Session-state key of the user's character: ``{"character", "name", "token"}``.
CHARACTER_KEY = "gk.character"
#: File types the character uploader takes.
CHARACTER_TYPES = ["glb", "gltf", "vrm", "fbx", "bvh"]
_FAILED = "_gk.character_failed"  # (token, message) of an upload that could not be used
_RESETS = "_gk.character_resets"  # a new uploader after "Default character" (it then holds no file)
_CLIPS = "_gk.character_clips"  # the character's own animations in its GLB: "keep" or "drop"
_CLIP_LABELS = {"keep": "keep after ours", "drop": "leave out"}
_SLACK = "_gk.wrist_slack"  # the slider's value: percent of the arm's length
_MADE = "_gk.character_files"  # {(run, token, kind, clips): (bytes or None, summary or why not, warnings)}


def current_character() -> Character | None:
    """The user's character, or None for the default body."""
    kept = st.session_state.get(CHARACTER_KEY)
    return None if kept is None else kept["character"]


def character_token() -> tuple | None:
    """What tells the user's character apart from the one before (its upload's and bone map's ids and its wrist
    slack), or None."""
    kept = st.session_state.get(CHARACTER_KEY)
    return None if kept is None else (*kept["token"], kept["character"].wrist_slack)


def render_mp4(
    result: SynthesisResult, *, progress: Callable[[int, int], None] | None = None, framing: str = "upper body"
) -> bytes:
    """:func:`gesturekit.interactive.render_mp4` of the result, drawn on the user's character when there is one,
    framed on the upper body and every hand or on the whole body (``framing``)."""
    from gesturekit import interactive as gs
    from gesturekit.export.result import save_result_video

    ch = current_character()
    if ch is None:
        return gs.render_mp4(result, progress=progress, framing=framing)
    with tempfile.TemporaryDirectory(prefix="gesturekit-video-") as tmp:
        path = Path(tmp) / "result.mp4"
        side = result.refined_motion is not None
        save_result_video(result, path, progress=progress, side_by_side=side, character=ch, framing=framing)
        return path.read_bytes()


def _matched_lines(ch: Character) -> list[str]:
    """What the sidebar says of a character: how it was matched, and which of our joints it lacks."""
    matched = int((ch.bone_of >= 0).sum())
    body = "its mesh" if ch.skin is not None and ch.skin.n_vertices else "capsules around its bones (no mesh)"
    lines = [
        f"{ch.n_bones} bones, matched by {ch.matched_by}: pelvis and {matched} of our {len(JOINT_NAMES)} joints; "
        f"drawn as {body}"
    ]
    missing = [JOINT_NAMES[j] for j in range(len(JOINT_NAMES)) if ch.bone_of[j] < 0]
    if missing:
        fingers = [n for n in missing if any(f in n for f in FINGERS)]
        others = [n for n in missing if n not in fingers]
        parts = others[:12] + ([f"{len(fingers)} finger joints"] if fingers else [])
        lines.append("no bone for " + ", ".join(parts) + (" ..." if len(others) > 12 else "") + ": not shown")
    return lines


def sidebar_character() -> Character | None:
    """The sidebar's "Your character" expander: upload, what was matched or the error, "Default character".

    Returns the user's character (None: the default body).
    """
    ss = st.session_state
    kept = ss.get(CHARACTER_KEY)
    n = ss.get(_RESETS, 0)
    with st.sidebar.expander("Your character", expanded=kept is not None or _FAILED in ss):
        up = st.file_uploader(
            "Character: glb, gltf, vrm, fbx or bvh",
            type=CHARACTER_TYPES,
            key=f"_gk.character_file.{n}",
            help="a humanoid with a skinned mesh (glTF, GLB, VRM 0.x/1.0, FBX with its texture embedded) or a BVH "
            "skeleton: the 3D views of "
            "Synthesize and the Retrieval inspector draw it, posed by the motion",
        )
        bone_map = st.file_uploader(
            "Bone map (JSON, optional)",
            type=["json"],
            key=f"_gk.character_map.{n}",
            help='{"pelvis": "Hips", "joints": {"spine_mid": "Spine", ...}}: which of its bones is which of our '
            "joints, where its names are not Mixamo's, ZEGGS's or a VRM's",
        )
        if up is not None:
            token = (up.file_id, None if bone_map is None else bone_map.file_id)
            failed = ss.get(_FAILED)
            if (kept is None or kept["token"] != token) and (failed is None or failed[0] != token):
                try:
                    with st.spinner("Reading the character…"):
                        mapping = None if bone_map is None else (bone_map.name, bone_map.getvalue())
                        character = read_character_upload(up.name, up.getvalue(), bone_map=mapping)
                    kept = ss[CHARACTER_KEY] = {"character": character, "name": up.name, "token": token}
                    ss.pop(_FAILED, None)
                except (GestureKitError, OSError) as exc:
                    ss[_FAILED] = (token, error_text(exc), getattr(exc, "bone_tree", None))
                except Exception:  # noqa: BLE001  (a file no reader foresaw: said once, not read again)
                    reference = secrets.token_hex(4)
                    LOG.exception("a character upload could not be read (reference %s)", reference)
                    why = f"could not be read as a character (details in the server log, reference {reference})"
                    ss[_FAILED] = (token, f"{Path(up.name).name}: {why}", None)
        failed = ss.get(_FAILED)
        if failed is not None:
            st.error(escape_markdown(failed[1]), icon=":material/error:")
            if failed[2]:  # the bones it has, for a bone map (a nameless glTF node is node{index})
                st.caption("Its bones, with their rest positions (metres as read), for a bone map:")
                st.code(failed[2], language=None)
        if kept is None:
            st.caption("The default body is shown.")
            return None
        ch = kept["character"]
        st.success(f"**{escape_markdown(kept['name'])}** is shown", icon=":material/accessibility_new:")
        for line in _matched_lines(ch):
            st.caption(escape_markdown(line))
        for note in ch.notes:  # a unit found from its size
            st.warning(escape_markdown(note), icon=":material/straighten:")
        percent = st.slider(
            "Wrist slack, % of the arm",
            min_value=0.0,
            max_value=WRIST_SLACK_MAX * 100,
            value=WRIST_SLACK * 100,
            step=0.5,
            format="%.1f %%",
            key=_SLACK,
            help="how far its wrists may stay from where ours reach (scaled to its arm): where its upper arm and "
            "forearm have other proportions than ours, more slack keeps them closer to our directions; 0 puts "
            "the hands exactly where ours reach",
        )
        slack = round(float(percent) / 100, 6)
        if slack != ch.wrist_slack:  # the views, the MP4 and the files are then made again (character_token)
            ch = kept["character"] = dataclasses.replace(ch, wrist_slack=slack)
        if ch.gltf is not None and ch.gltf.document.get("animations"):
            st.radio(
                "Its own animations in the Character GLB",
                THEIR_CLIPS,
                format_func=_CLIP_LABELS.__getitem__,
                key=_CLIPS,
                horizontal=True,
                help="the file's own clips: kept after the motion's (viewers that play one play the first, the "
                "motion's), or left out",
            )
        if st.button("Default character", key="_gk.character_default", help="show the default body again"):
            ss.pop(CHARACTER_KEY, None)
            ss.pop(_FAILED, None)
            ss.pop(_SLACK, None)
            ss[_RESETS] = n + 1
            st.rerun()
    return ch


def _file_name(record: dict, ch: Character, kind: str) -> str:
    from gesturekit import interactive as gs

    suffix = ".vrm" if kind == "glb" and ch.kind.startswith("vrm") else f".{kind}"
    return Path(gs.export_filename(record["result"], "bvh")).stem + "_character" + suffix


def _character_file(record: dict, kind: str) -> dict:
    """The result's final motion on the user's character as a GLB or BVH, made once per result and character:
    ``data`` (the file's bytes, or None), ``summary`` (its report's, or why there is none), ``warned`` (the
    warnings of writing it) and ``speech`` (a GLB's WAV beside it, which it names, or None)."""
    from gesturekit.character.retarget import retarget
    from gesturekit.export.result import export_result_character_bvh, export_result_character_glb

    ss = st.session_state
    kept = ss[CHARACTER_KEY]
    clips = ss.get(_CLIPS, THEIR_CLIPS[0])
    key = (record["run"], character_token(), kind, clips)
    made = ss.get(_MADE, {})
    if key not in made:
        result = record["result"]
        ch = kept["character"]
        out: dict = {"data": None, "summary": "", "warned": [], "speech": None}
        try:
            with collect_warnings() as warned, tempfile.TemporaryDirectory(prefix="gesturekit-character-") as tmp:
                posed = retarget(result.motion, ch)
                path = Path(tmp) / _file_name(record, ch, kind)
                if kind == "glb":  # its speech beside it, as the WAV it names
                    glb = export_result_character_glb(result, posed, path, their_clips=clips)
                    out["speech"] = None if glb.audio is None else glb.audio.read_bytes()
                    out["summary"] = glb.summary()
                else:
                    out["summary"] = export_result_character_bvh(result, posed, path).summary()
                out["data"] = path.read_bytes()
            out["warned"] = list(warned)
        except GestureKitError as exc:
            out["summary"] = exc.problem
        made = {k: v for k, v in made.items() if k[:2] == key[:2]}  # only the current result's are kept
        made[key] = out
        ss[_MADE] = made
    return made[key]


def character_downloads(record: dict, *, prefix: str) -> None:
    """The result on the user's character: "Character GLB" (a glTF or VRM character, with the WAV it names)
    and "Character BVH" downloads, with their reports; nothing without a character."""
    kept = st.session_state.get(CHARACTER_KEY)
    if kept is None:
        return
    ch = kept["character"]
    kinds = (["glb"] if ch.gltf is not None else []) + ["bvh"]
    st.markdown(f"**On your character** ({escape_markdown(kept['name'])})")
    cols = st.columns(3)
    for col, kind in zip(cols, kinds):
        made = _character_file(record, kind)
        label = "Character GLB" if kind == "glb" else "Character BVH"
        if made["data"] is None:
            col.error(f"No {label}: {escape_markdown(made['summary'])}", icon=":material/error:")
            continue
        name = _file_name(record, ch, kind)
        col.download_button(
            label,
            data=made["data"],
            file_name=name,
            mime="model/gltf-binary" if kind == "glb" else "application/octet-stream",
            key=f"{prefix}.download_character_{kind}",
            on_click="ignore",
        )
        if made["speech"] is not None:
            col.download_button(
                "Its speech (WAV)",
                data=made["speech"],
                file_name=Path(name).with_suffix(".wav").name,
                mime="audio/wav",
                key=f"{prefix}.download_character_wav",
                on_click="ignore",
                help="the speech the GLB names: keep it beside the GLB",
            )
        col.caption(escape_markdown(made["summary"]))
        for message in made["warned"]:
            col.warning(escape_markdown(message), icon=":material/warning:")
