"""Showing things on a page: user errors as messages (never tracebacks), warnings, motions in 3D.

:func:`run_page` (which ``Home.py`` wraps around every page) shows every
:class:`~gesturekit.errors.GestureKitError` (and ``OSError`` from a file the
user named) as ``st.error`` with its message, never as a traceback; anything
else as a generic message with a reference into the server log, where its
traceback goes (logger ``gesturekit.app``).

Folders. Every path a user types is checked with :func:`allowed` before it
is read or written: only folders inside :func:`gesturekit.paths.allowed_roots`
(gesturekit's home, ``./db``, ``$GESTUREKIT_APP_ROOTS``) may be used, so a
browser user of a served app cannot open, list or write the server's other
folders. A file named in a message that lies outside them is shown by its
name only.

Markup. Text that comes from a user or a file (a database's label, take
names, paths, control strings, and the messages that quote them) is passed
through :func:`escape_markdown` before any Streamlit call that renders
Markdown (``st.markdown``, ``st.caption``, ``st.error`` and its kin, progress
texts): a label ``![x](http://host/x.png)`` is shown as those characters,
never as an image the browser fetches or a link.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import re
import secrets
import string
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import streamlit as st

from gesturekit.errors import GestureKitError, collect_warnings
from gesturekit.paths import PathNotAllowedError, check_allowed, is_allowed

if TYPE_CHECKING:
    import numpy as np
    import pandas as pd
    from streamlit.delta_generator import DeltaGenerator

    from gesturekit.character.target import Character
    from gesturekit.export.bvh import BvhReport
    from gesturekit.export.gltf import GltfReport
    from gesturekit.motion import Motion

__all__ = [
    "LOG",
    "allowed",
    "error_text",
    "escape_markdown",
    "result_bvh",
    "DOWNLOADS_PER_ROW",
    "download_columns",
    "result_downloads",
    "result_glb",
    "run_page",
    "selected_row",
    "show_bvh_report",
    "show_glb_report",
    "show_skeletons",
    "viewer_component",
    "microphones_component",
    "skeleton_note",
    "user_errors",
    "warnings_shown",
    "WORD_JOINER",
]

#: The server log of the app: unexpected errors (with their tracebacks) and failed background work.
LOG = logging.getLogger("gesturekit.app")


_PUNCTUATION = frozenset(string.punctuation)
_LINE_BREAK = re.compile(r"\r\n|\r|\n")
#: Where GitHub's Markdown finds a bare link (``http://x``, ``www.x``, ``a@b.c``) in the text.
_AUTOLINK = re.compile(r"https?(?=:)|www(?=\.)|@", re.IGNORECASE)
#: U+2060 WORD JOINER: invisible, and it breaks no line.
WORD_JOINER = "\u2060"


def escape_markdown(text: object) -> str:
    r"""``text`` (``str(text)``) made literal for Streamlit's Markdown: shown as it is, never as markup.

    Every ASCII punctuation character gets a backslash, which CommonMark (and GitHub's
    Markdown, which Streamlit renders) defines as that character itself: no link, image,
    emphasis, code, HTML tag, heading, list, table, ``$`` formula or Streamlit ``:color[...]``
    directive can begin. Line breaks stay line breaks. Bare links (``http://...``, ``www.``,
    an e-mail address) are found by Streamlit's renderer in the text after the escapes are
    undone: an invisible :data:`WORD_JOINER` after ``http``, ``https``, ``www`` and ``@``
    keeps them text. That character is the only difference a reader could find (by copying).

    Examples
    --------
    >>> print(escape_markdown("![x](pwn.png)"))
    \!\[x\]\(pwn\.png\)
    >>> escape_markdown("http://x").replace(WORD_JOINER, "~")
    'http~\\:\\/\\/x'
    """
    joined = _AUTOLINK.sub(lambda m: m.group(0) + WORD_JOINER, str(text))
    escaped = "".join("\\" + c if c in _PUNCTUATION else c for c in joined)
    return _LINE_BREAK.sub("  \n", escaped)  # a hard break: a lone newline would join the lines


@contextlib.contextmanager
def user_errors() -> Iterator[None]:
    """Show errors a user can cause as ``st.error`` in the current container, not as a traceback.

    Catches :class:`GestureKitError` (bad paths, bad folders, existing
    outputs, invalid settings) and ``OSError`` (a file that cannot be read or
    written). A file the message is about that lies outside the allowed
    folders (a temporary copy of an upload, a file a library opened) is named
    by its name only, so that the server's layout stays private; a refused
    path is shown as the user typed it. Anything else is a bug and propagates.
    Code after the failing statement inside the block does not run; code
    after the block does.
    """
    try:
        yield
    except (GestureKitError, OSError) as exc:
        st.error(escape_markdown(error_text(exc)), icon=":material/error:")


def error_text(exc: GestureKitError | OSError) -> str:
    """The message of a user error as the page shows it (see :func:`user_errors`)."""
    if isinstance(exc, PathNotAllowedError) or (isinstance(exc, GestureKitError) and exc.path is None):
        return str(exc)
    if isinstance(exc, GestureKitError):
        return f"{_shown_path(exc.path)}: {exc.problem}"
    where = f"{_shown_path(exc.filename)}: " if exc.filename else ""
    # strerror alone: str(exc) repeats the file names, in full
    return f"{where}{exc.strerror or type(exc).__name__}"


def _shown_path(filename) -> str:
    """A file name for the page: in full inside the allowed folders, else its last part only."""
    try:
        name = os.fsdecode(filename)
        return name if is_allowed(name) else Path(name).name
    except (TypeError, ValueError, OSError):  # a descriptor number, an undecodable name
        return "a file"


def run_page(body: Callable[[], None]) -> None:
    """Run a page's body, showing user errors as ``st.error`` (see :func:`user_errors`).

    Any other exception is a bug: the page says so with a reference, and the
    traceback goes to the server log (:data:`LOG`) under that reference, so that
    no traceback and no server path reach the browser. Streamlit's own
    ``st.stop`` and ``st.rerun`` pass through (they are not ``Exception`` s).
    """
    try:
        with user_errors():
            body()
    except Exception:  # noqa: BLE001  (the browser gets a reference; the log gets the rest)
        reference = secrets.token_hex(4)
        LOG.exception("unexpected error in a page (reference %s)", reference)
        st.error(
            f"Something went wrong; the details are in the server log (reference {reference}).", icon=":material/error:"
        )


def allowed(path: str | os.PathLike, *, what: str, write: bool = False) -> Path:
    """Refuse a typed path outside the folders the app may use (:func:`gesturekit.paths.check_allowed`).

    Returns the path resolved. The message is the same whether or not the path
    exists, so it tells a user nothing about the server's folders.

    Raises
    ------
    ConfigError
        Empty.
    PathNotAllowedError
        Outside :func:`gesturekit.paths.allowed_roots` (the message says how to add a folder, not which they are).
    """
    return check_allowed(path, what=what, write=write)


@contextlib.contextmanager
def warnings_shown() -> Iterator[list[str]]:
    """Show the :class:`GestureKitWarning` s raised inside the block as ``st.warning``.

    Yields the list their messages are collected in (complete when the block ends).
    """
    with collect_warnings() as messages:  # this session's thread only: sessions run side by side
        try:
            yield messages
        finally:
            for message in messages:
                st.warning(escape_markdown(message))


def selected_row(table: pd.DataFrame, *, key: str, height: int, column_config: dict | None = None) -> int | None:
    """Show ``table`` with one row selectable (a selection reruns the page); the selected row's position, or None."""
    event = st.dataframe(
        table,
        hide_index=True,
        key=key,
        on_select="rerun",
        selection_mode="single-row",
        height=height,
        column_config=column_config,
    )
    rows = list(event.selection.rows) if event is not None else []
    return int(rows[0]) if rows and rows[0] < len(table) else None


@functools.cache
def viewer_component() -> Any:
    """The viewer as a Streamlit component: its page and bundle are the package's static folder
    (:mod:`gesturekit.viz.web.build`), so the browser fetches the bundle once and caches it.

    Its args are :func:`gesturekit.viz.viewer.viewer_args` (the data as JSON text, the speech as
    WAV bytes, their hash), ``height`` (pixels of the drawing) and ``key``; it returns nothing.
    """
    from streamlit.components.v1 import declare_component

    from gesturekit.viz.web.build import STATIC, bundle

    bundle()  # a missing build says how to make it, here rather than as a blank frame
    return declare_component("skeleton_viewer", path=str(STATIC))


@functools.cache
def microphones_component() -> Any:
    """A component that says which microphones the browser offers (``components/microphones``):
    it returns ``{"api": bool, "microphones": int, "secure": bool}`` once the browser has looked,
    the ``default`` before; it shows nothing."""
    from streamlit.components.v1 import declare_component

    return declare_component("gk_microphones", path=str(Path(__file__).resolve().parent / "components" / "microphones"))


def show_skeletons(
    motions: Motion | Sequence[Motion],
    *,
    key: str,
    labels: Sequence[str] | None = None,
    title: str | None = None,
    height: int = 520,
    audio: np.ndarray | None = None,
    character: Character | None = None,
    schemes: Sequence[str] | None = None,
) -> None:
    """Show motions side by side in gesturekit's 3D viewer, a Streamlit component (:func:`viewer_component`).

    The viewer draws the skinned character with three.js (WebGL, in software where the
    browser has no GPU: no antialiasing, no shadows). ``height``: of the drawing, in
    pixels (its controls come below); ``key`` names the viewer (pages and tests find it by it).
    ``audio``: the speech of the motions (mono float32 at 16 kHz, from their first frame);
    the viewer's play button then plays it and the shown frame follows it, so no separate
    player is needed. A rerun that shows the same motions keeps the drawn view as it is.
    ``character``: the user's character (gesturekit/app/characters.py), drawn instead of the default body, with
    the retargeting's report of each motion under the view. ``schemes``: each motion's colour scheme by
    what it shows (:func:`gesturekit.character.look.role_scheme`, :func:`~gesturekit.character.look.rank_scheme`),
    so a colour means one thing on every page; default by place (k-NN blue, refined orange).
    """
    from gesturekit.viz.viewer import viewer_args

    args = viewer_args(motions, labels=labels, title=title, audio=audio, character=character, schemes=schemes)
    viewer_component()(**args, height=int(height), key=key, default=None)
    if character is not None:
        _retarget_summary(motions, labels, character)
        return
    note = skeleton_note(motions)
    if note:
        st.caption(note)


def _retarget_summary(motions: Motion | Sequence[Motion], labels: Sequence[str] | None, character: Character) -> None:
    """Under a view of the user's character: how closely it follows each motion (the retargeting's report)."""
    from gesturekit.character.retarget import retarget
    from gesturekit.motion import Motion

    shown = [motions] if isinstance(motions, Motion) else list(motions)
    names = list(labels) if labels is not None and len(labels) == len(shown) else [""] * len(shown)
    for name, m in zip(names, shown):
        report = retarget(m, character).report
        st.caption(escape_markdown(f"{name or 'Your character'}: {report.summary()}"))


def skeleton_note(motions: Motion | Sequence[Motion]) -> str:
    """What a view of a partial skeleton leaves out or derives, in one line ("" for complete skeletons)."""
    from gesturekit.motion import Motion
    from gesturekit.skeleton import ABSENT, DERIVED

    seen = []
    for m in [motions] if isinstance(motions, Motion) else list(motions):
        if not m.presence.is_full and m.presence not in seen:
            seen.append(m.presence)
    parts = []
    for presence in seen:
        derived, absent = presence.names(DERIVED), presence.names(ABSENT)
        line = []
        if derived:
            names = ", ".join(derived)
            line.append(f"grey: {len(derived)} derived joints, placed from the neck and shoulders ({names})")
        if absent:
            line.append(f"{len(absent)} joints absent from the data, not drawn")
        parts.append("; ".join(line))
    return " | ".join(parts)


def result_bvh(record: dict, *, key: str) -> tuple[bytes | None, BvhReport | str]:
    """A result's BVH download and its report, made once per result: reruns of the page reuse it,
    and a skeleton no BVH can hold is not tried again.

    Returns the file's bytes and its :class:`~gesturekit.export.bvh.BvhReport`, or None and why no
    BVH can be written. ``record`` is the page's result record (``"run"``, ``"result"``); ``key`` is
    the session-state key that keeps it.
    """
    from gesturekit import interactive as gs

    ss = st.session_state
    cached = ss.get(key)
    if cached is None or cached[0] != record["run"]:
        result = record["result"]
        try:
            with collect_warnings():  # the warning over 1 cm is shown from the report (show_bvh_report)
                data, report = gs.export_bvh_bytes(result, gs.export_filename(result, "bvh"))
            cached = (record["run"], data, report)
        except GestureKitError as exc:
            cached = (record["run"], None, exc.problem)
        ss[key] = cached
    return cached[1], cached[2]


def result_glb(record: dict, *, key: str) -> tuple[bytes | None, GltfReport | str]:
    """A result's glTF download (the character, skinned and animated) and its report, made once per
    result as :func:`result_bvh` makes the BVH.

    The file names its speech as the WAV download's name (``export_filename(result, "wav")``).
    Returns the file's bytes and its :class:`~gesturekit.export.gltf.GltfReport`, or None and why
    no glTF can be written.
    """
    import tempfile

    from gesturekit import interactive as gs
    from gesturekit.export.result import export_result_glb

    ss = st.session_state
    cached = ss.get(key)
    if cached is None or cached[0] != record["run"]:
        result = record["result"]
        try:
            with collect_warnings(), tempfile.TemporaryDirectory(prefix="gesturekit-glb-") as tmp:
                # the warning over 1 mm is shown from the report (show_glb_report)
                path = Path(tmp) / gs.export_filename(result, "glb")
                report = export_result_glb(result, path)
                cached = (record["run"], path.read_bytes(), report)
        except GestureKitError as exc:
            cached = (record["run"], None, exc.problem)
        ss[key] = cached
    return cached[1], cached[2]


_DOWNLOAD_LABELS = {
    "wav": "Speech (WAV)",
    "npz": "Motion + search (npz)",
    "bvh": "Motion (BVH)",
    "glb": "Character (glTF)",
    "csv": "Control track (CSV)",
    "json": "Config (JSON)",
}


#: Download buttons side by side at most: on a laptop's window (1280 pixels wide) a row of more cuts their labels.
DOWNLOADS_PER_ROW = 4


def download_columns(n: int, *, per_row: int = DOWNLOADS_PER_ROW) -> list[DeltaGenerator]:
    """``n`` columns for download buttons, in rows of ``per_row`` (the last row's columns as wide as the others)."""
    cols: list[DeltaGenerator] = []
    while len(cols) < n:
        cols.extend(st.columns(per_row)[: n - len(cols)])
    return cols


def result_downloads(
    record: dict,
    kinds: Sequence[str],
    *,
    prefix: str,
    keys: tuple[str, str],
    before_video: Callable[[DeltaGenerator], None],
    glb_key: str | None = None,
) -> None:
    """A result's downloads in rows of :data:`DOWNLOADS_PER_ROW`, the MP4 last, and the BVH's (and glTF's) report
    under them.

    ``record`` is the page's result record (``"run"``, ``"result"``); ``kinds`` the files
    before the MP4, of ``"wav"``, ``"npz"``, ``"bvh"``, ``"glb"``, ``"csv"``, ``"json"``; ``prefix``
    names the buttons' keys (``PREFIX.download_KIND``). ``keys`` are the session-state
    keys of the BVH made once per result (:func:`result_bvh`) and of the rendered video
    (``{"run", "bytes"}``); ``glb_key`` that of the glTF (:func:`result_glb`), needed with
    ``"glb"``; ``before_video(column)`` fills the MP4's column until there is one.
    """
    from gesturekit import interactive as gs

    result = record["result"]
    cols = download_columns(len(kinds) + 1)
    bvh, report = result_bvh(record, key=keys[0])  # made once per result, for the report under the buttons
    made: dict[str, bytes | None] = {"bvh": bvh}
    glb_report: GltfReport | str | None = None
    if "glb" in kinds:
        if glb_key is None:
            raise ValueError("a glTF download needs glb_key, the session-state key that keeps it")
        made["glb"], glb_report = result_glb(record, key=glb_key)
    for col, kind in zip(cols, kinds):
        ready = made.get(kind)
        if kind in made and ready is None:
            col.caption(f"{'BVH' if kind == 'bvh' else 'glTF'}: see below")
            continue
        col.download_button(
            _DOWNLOAD_LABELS[kind],
            # the others are made when clicked: most results are never downloaded
            data=ready if ready is not None else functools.partial(gs.export_bytes, result, kind),
            file_name=gs.export_filename(result, kind),
            mime=gs.EXPORT_KINDS[kind][1],
            key=f"{prefix}.download_{kind}",
            on_click="ignore",
        )
    done = st.session_state.get(keys[1])
    if done is not None and done["run"] == record["run"]:
        cols[-1].download_button(
            "Video (MP4)",
            data=done["bytes"],
            file_name=gs.export_filename(result, "mp4"),
            mime="video/mp4",
            key=f"{prefix}.download_mp4",
            on_click="ignore",
        )
    else:
        before_video(cols[-1])
    show_bvh_report(bvh, report)
    if glb_report is not None:
        show_glb_report(made["glb"], glb_report)


def show_bvh_report(data: bytes | None, report: BvhReport | str) -> None:
    """Under a result's downloads: the BVH's error against the motion, its warning over 1 cm, or why
    there is no BVH (from :func:`result_bvh`)."""
    _show_file_report("BVH", "BVH", data, report)


def show_glb_report(data: bytes | None, report: GltfReport | str) -> None:
    """Under a result's downloads: the glTF file's error against the motion, its warning over 1 cm, or
    why there is no glTF file (from :func:`result_glb`)."""
    _show_file_report("glTF", "glTF file", data, report)


def _show_file_report(kind: str, name: str, data: bytes | None, report: BvhReport | GltfReport | str) -> None:
    if data is None or isinstance(report, str):
        st.error(f"No {name}: {escape_markdown(report)}", icon=":material/error:")
        return
    st.caption(f"{kind} {escape_markdown(report.summary())}")
    message = report.warning()
    if message is not None:
        st.warning(escape_markdown(message[0].upper() + message[1:]), icon=":material/warning:")
