"""The sidebar of every page: which database is open, and building one from a folder of takes.

The chosen folder is kept in ``st.session_state`` under :data:`DATABASE_KEY`,
shared by all pages. The choices are the databases
:func:`gesturekit.workspace.database_folders` finds, or a folder the user
types (inside the folders the app may use, :func:`display.allowed`). The
default (demo) database is built on first use.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import streamlit as st

from gesturekit.app import characters, resources
from gesturekit.app.display import allowed, escape_markdown, user_errors, warnings_shown
from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.datasets.takes import FORWARD_CHOICES, UNIT_CHOICES, UP_CHOICES, reading_lines
from gesturekit.errors import ConfigError, DatabaseError
from gesturekit.options import widget_limits
from gesturekit.paths import default_database_path, home
from gesturekit.workspace import database_folders, is_generated

__all__ = ["DATABASE_KEY", "show_database_label", "sidebar_database"]

#: Session-state key of the user's chosen database folder (a string), shared by all pages.
DATABASE_KEY = "gk.database"
_PENDING_KEY = "gk.database_pending"  # a database to select on the next run (after a build)
_FLASH_KEY = "gk.flash"  # a message to show once on the next run
_CHOICE_WIDGET = "_gk.database_choice"
_TYPED_WIDGET = "_gk.database_typed"
_OTHER = "\0other"  # the "type a path" option of the selector (cannot be a path)


def _select_database() -> Path:
    """The database selector of the sidebar; returns the chosen folder (not yet opened)."""
    ss = st.session_state
    options = database_folders()
    keys = list(options) + [_OTHER]
    if _PENDING_KEY in ss:  # a build finished: select its output before the widgets exist
        ss[DATABASE_KEY] = ss.pop(_PENDING_KEY)
        ss.pop(_CHOICE_WIDGET, None)
        ss.pop(_TYPED_WIDGET, None)
    chosen = ss.get(DATABASE_KEY)
    if _CHOICE_WIDGET not in ss or ss[_CHOICE_WIDGET] not in keys:
        if chosen is None or chosen in options:
            ss[_CHOICE_WIDGET] = chosen or keys[0]
        else:
            ss[_CHOICE_WIDGET] = _OTHER
            ss[_TYPED_WIDGET] = chosen
    if _TYPED_WIDGET not in ss:
        ss[_TYPED_WIDGET] = ""
    # written on every run (as state.persistent_key does), so that every run sends the choice to the
    # browser: a page switch removes the widgets from the browser, and one re-created without its
    # value would show, and on the next run send back, the first option (the demo database)
    ss[_CHOICE_WIDGET] = ss[_CHOICE_WIDGET]
    ss[_TYPED_WIDGET] = ss[_TYPED_WIDGET]
    choice = st.sidebar.selectbox(
        "Database",
        keys,
        key=_CHOICE_WIDGET,
        format_func=lambda k: "another folder…" if k == _OTHER else options[k],
        help="The demo database, databases in ./db or in gesturekit's home db folder, or a folder you type "
        "(inside the folders this app may use).",
    )
    if choice == _OTHER:
        typed = st.sidebar.text_input("Database folder", key=_TYPED_WIDGET, placeholder="/path/to/database")
        if not typed.strip():
            ss.pop(DATABASE_KEY, None)
            st.info("Type the folder of a database in the sidebar, or pick one from the list.")
            st.stop()
        path = Path(typed.strip()).expanduser()
    else:
        path = Path(choice)
    ss[DATABASE_KEY] = str(path)
    return path


def show_database_label(db: MatchingDatabase, *, container: Any = st) -> None:
    """Say which database is open and what it holds; generated data is flagged as such."""
    # the folder's name and the label are the user's (or a file's): shown as typed, never as markup
    name = escape_markdown(db.path.name) if db.path is not None else "(in memory)"
    label = escape_markdown(db.label or "")
    if is_generated(db):
        container.warning(f"**Generated data** · {name}: {label or 'the demo speaker'}", icon=":material/science:")
    else:
        container.info(f"**{name}**" + (f": {label}" if label else ""), icon=":material/storage:")


def sidebar_database() -> MatchingDatabase:
    """The sidebar of every page; returns the user's database, opened.

    Shows the database selector, the "build from a folder" expander and the user's
    character (:func:`characters.sidebar_character`). If
    the choice is the default demo database and it does not exist yet, it is
    built first (with a progress bar in the page).

    Raises
    ------
    GestureKitError
        The chosen folder lies outside the allowed folders (:func:`allowed`) or is not a
        readable database (shown by :func:`run_page`).
    """
    ss = st.session_state
    path = _select_database()
    _build_expander()
    characters.sidebar_character()
    for kind, text in ss.pop(_FLASH_KEY, []):
        getattr(st.sidebar, kind)(text)
    allowed(path, what="database folder")  # before anything looks at the folder
    if path.expanduser().resolve() == default_database_path().expanduser().resolve():
        path = resources.ensure_demo_database()
        try:
            db = resources.load_database(path)
        except DatabaseError as exc:  # e.g. built by an older gesturekit: offer to rebuild it
            st.error(escape_markdown(exc), icon=":material/error:")
            if st.button("Rebuild the demo database", key="_gk.rebuild_demo"):
                resources.rebuild_demo(path)
                st.rerun()
            st.stop()
    else:
        db = resources.load_database(path)
    show_database_label(db, container=st.sidebar)
    counts = f"{_count(db.n_clips, 'clip')} · {_count(len(db.take_names), 'take')}"
    st.sidebar.caption(counts)  # the folder's name is in the label above; its path is the server's
    return db


def _build_from_folder(
    folder: str,
    *,
    joint_map: str,
    out: str,
    overwrite: bool = False,
    fps: float | None = None,
    label: str = "",
    units: str = "auto",
    up: str | None = None,
    forward: str = "auto",
    normalize_bones: bool = False,
    progress=None,
    workers: int = 1,
) -> MatchingDatabase:
    """Build and save a database from a folder of takes, as typed in the sidebar's form
    (:func:`gesturekit.workspace.build_database`, what ``gesturekit build-db FOLDER`` does).

    Parameters
    ----------
    folder, out : str
        Folder of takes, and the database folder to write (typed; neither may be empty).
    joint_map : str
        ``"zeggs"``, ``"beat"`` or the path of a JSON joint map.
    overwrite : bool
        Replace an earlier database at ``out`` (only a database gesturekit built; other folders are refused).
    fps : float, optional
        Frame rate of joint-position files (they do not carry one).
    label : str
        Description stored with the database.
    units, up, forward, normalize_bones
        How to read the motion files (:class:`gesturekit.datasets.takes.ReadOptions`).
    progress : callable(done, total, take_name), optional
        Called after each take is read.
    workers : int
        Processes that read takes at once (the database is the same for any number).

    Raises
    ------
    GestureKitError
        An empty field, a missing or empty folder, an existing output without ``overwrite``,
        an unreadable joint map or take; the message names the path.
    """
    from gesturekit.outputs import check_output
    from gesturekit.workspace import build_database

    if not str(folder).strip():
        raise ConfigError("type the folder of takes to build from")
    if not str(out).strip():
        raise ConfigError("type the database folder to write")
    folder, out = Path(folder).expanduser(), Path(out).expanduser()
    # 'overwrite' replaces only a database gesturekit wrote, never the takes or a folder of other files
    if check_output(out, "database", overwrite=True, inputs=[folder]) and not overwrite:
        raise DatabaseError("a database already exists here; tick 'overwrite' to replace it", path=out)
    return build_database(
        folder,
        out,
        config=BuildConfig(label=label),
        joint_map=joint_map,
        fps=fps,
        units=units,
        up=up,
        forward=forward,
        normalize_bones=normalize_bones,
        overwrite=overwrite,
        progress=progress,
        workers=workers,
    )


def _reading_inputs() -> tuple[str, str | None, str, bool]:
    """The form's units, up axis, forward axis and bone normalisation (``build-db``'s options of the same names)."""
    # one under another: two columns of the sidebar cut the choices' words
    left = right = st.container()
    units = left.selectbox(
        "Units", list(UNIT_CHOICES), key="_gk.build_units", help="auto: from the body's size (BVH: the skeleton's)"
    )
    up = right.selectbox(
        "Up axis",
        ["y (checked)", *UP_CHOICES],
        key="_gk.build_up",
        help="the files' up axis; 'y (checked)' refuses a take that does not stand upright with y up",
    )
    forward = left.selectbox(
        "Forward axis", list(FORWARD_CHOICES), key="_gk.build_forward", help="auto: from the shoulders"
    )
    normalize = right.checkbox(
        "normalise bone lengths",
        key="_gk.build_bones",
        help="one skeleton for the database: one length per bone over all takes and fixed finger roots, "
        "for keypoints whose bone lengths vary from frame to frame and take to take",
    )
    return str(units), None if str(up).startswith("y (") else str(up), str(forward), bool(normalize)


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _build_expander() -> None:
    """The sidebar's "build from a folder" form; a built database becomes the selection."""
    with st.sidebar.expander("Build a database from a folder"):
        folder = st.text_input(
            "Folder of takes",
            key="_gk.build_folder",
            help="BVH + speech files of the same name, joint-position files + speech, "
            "or npz files of the Habibie et al. 2021 layout",
        )
        naming = st.radio(
            "Skeleton",
            ["zeggs", "beat", "JSON joint map"],
            key="_gk.build_naming",
            horizontal=True,
            help="joint naming preset of the BVH files, or a JSON joint map",
        )
        map_path = ""
        if naming == "JSON joint map":
            map_path = st.text_input("Joint map (JSON file)", key="_gk.build_map")
        fps = st.number_input(
            "Frame rate of joint-position files (0: not needed)",
            min_value=0.0,
            value=0.0,
            step=1.0,
            key="_gk.build_fps",
        )
        units, up, forward, normalize = _reading_inputs()
        out = st.text_input(
            "Database folder to write", key="_gk.build_out", placeholder=str(home() / "db" / "<folder name>")
        )
        label_limits = widget_limits(BuildConfig, "label")
        label = st.text_input(
            "Label (optional)", value=label_limits["default"], key="_gk.build.label", help=label_limits["help"]
        )
        workers = st.number_input(
            "Worker processes",
            min_value=1,
            value=os.cpu_count() or 1,
            step=1,
            key="_gk.build_workers",
            help="takes read at once; the database is the same for any number",
        )
        overwrite = st.checkbox(
            "overwrite an existing database",
            key="_gk.build_overwrite",
            help="replaces only a database gesturekit built; any other folder is kept",
        )
        if not st.button("Build", key="_gk.build_go"):
            return
        with user_errors():
            if naming == "JSON joint map" and not map_path.strip():
                raise ConfigError("type the path of the JSON joint map")
            target = out.strip() or (str(home() / "db" / Path(folder.strip()).name) if folder.strip() else "")
            # every typed path is checked before any is looked at (_build_from_folder reports empty ones)
            for typed, what, write in (
                (folder, "folder of takes", False),
                (map_path, "joint map", False),
                (target, "database folder to write", True),
            ):
                if typed.strip():
                    allowed(typed.strip(), what=what, write=write)
            bar = st.progress(0.0, text="finding takes…")

            def progress(i: int, total: int, name: str) -> None:
                bar.progress(min(1.0, i / max(total, 1)), text=f"read {i}/{total} takes ({escape_markdown(name)})")

            with warnings_shown() as warned, resources.build_lock():
                db = _build_from_folder(
                    folder,
                    joint_map=map_path.strip() if naming == "JSON joint map" else naming,
                    out=target,
                    overwrite=overwrite,
                    fps=fps or None,
                    label=label.strip(),
                    units=units,
                    up=up,
                    forward=forward,
                    normalize_bones=normalize,
                    progress=progress,
                    workers=int(workers),
                )
            bar.progress(1.0, text="saved")
            st.session_state[_PENDING_KEY] = str(Path(db.path).resolve())
            # the page reruns to open the new database; the messages are shown on that run
            st.session_state[_FLASH_KEY] = [
                (
                    "success",
                    f"Built {_count(db.n_clips, 'clip')} from {_count(len(db.take_names), 'take')} into "
                    f"{escape_markdown(db.path)}",
                )
            ]
            st.session_state[_FLASH_KEY] += [
                ("info", escape_markdown(line)) for line in reading_lines(db.meta.get("takes", []))
            ]
            st.session_state[_FLASH_KEY] += [("warning", escape_markdown(w)) for w in warned]
            st.rerun()
