"""What every page of the app shares: the database sidebar, cached loading, errors, per-user state.

A page is a short script::

    import streamlit as st

    import common


    def main():
        common.page_setup("My page")
        st.title("My page")
        db = common.sidebar_database()  # the user's database, opened (built first if it is the missing demo)
        ...


    common.run_page(main)

``run_page`` shows every :class:`~gesturekit.errors.GestureKitError` (and
``OSError`` from a file the user named) as ``st.error`` with its message,
never as a traceback; anything else as a generic message with a reference
into the server log, where its traceback goes (logger ``gesturekit.app``).

Folders. Every path a user types is checked with :func:`allowed` before it
is read or written: only folders inside :func:`gesturekit.paths.allowed_roots`
(gesturekit's home, ``./db``, ``$GESTUREKIT_APP_ROOTS``) may be used, so a
browser user of a served app cannot open, list or write the server's other
folders.

State. Databases are opened once per process with ``st.cache_resource``,
keyed by their folder and the modification time of their ``database.json``
(a rebuilt database is opened anew); the opened object is shared by all
sessions and must be treated as read-only. Everything a user chooses lives in
``st.session_state``, which Streamlit keeps per browser session, so two
users never see each other's choices. Streamlit forgets a widget's value when
it is not drawn in a run (its page is left, or the page stops early);
:func:`persistent_key` gives widgets a value that survives that, and
:func:`remount_key` does the same for a widget whose value a run cannot send
(the data editor).

Environment. ``GESTUREKIT_HOME`` moves gesturekit's own folder (see
:mod:`gesturekit.paths`); ``GESTUREKIT_DEMO_MINUTES`` sets the minutes of the
demo database the app builds on a machine that has none (default
:data:`gesturekit.demo.DEMO_MINUTES`; smaller is faster, for tests and
trials).
"""
from __future__ import annotations

import contextlib
import logging
import os
import secrets
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import streamlit as st

from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.demo import DEMO_MINUTES, build_demo_database
from gesturekit.errors import ConfigError, DatabaseError, GestureKitError, collect_warnings
from gesturekit.paths import PathNotAllowedError, check_allowed, default_database_path, home, is_allowed

__all__ = [
    "APP_DIR",
    "DATABASE_KEY",
    "DEMO_MINUTES_ENV",
    "LOG",
    "PAGES",
    "PINS_KEY",
    "Page",
    "SYNTHESIS_KEY",
    "allowed",
    "build_from_folder",
    "database_folders",
    "default_refiner",
    "error_text",
    "current_synthesis",
    "demo_minutes",
    "ensure_demo_database",
    "is_generated",
    "load_database",
    "load_refiner",
    "check_refiner",
    "page_setup",
    "persistent_key",
    "remount_key",
    "run_page",
    "run_synthesis",
    "server_lifespan",
    "show_database_label",
    "show_skeletons",
    "sidebar_database",
    "user_errors",
    "warm_up",
    "warm_up_search",
]

APP_DIR = Path(__file__).resolve().parent
#: The server log of the app: unexpected errors (with their tracebacks) and failed background work.
LOG = logging.getLogger("gesturekit.app")
DEMO_MINUTES_ENV = "GESTUREKIT_DEMO_MINUTES"

#: Session-state key of the user's chosen database folder (a string), shared by all pages.
DATABASE_KEY = "gk.database"
_PENDING_KEY = "gk.database_pending"  # a database to select on the next run (after a build)
_FLASH_KEY = "gk.flash"  # a message to show once on the next run
_CHOICE_WIDGET = "_gk.database_choice"
_TYPED_WIDGET = "_gk.database_typed"
_OTHER = "\0other"  # the "type a path" option of the selector (cannot be a path)


@dataclass(frozen=True)
class Page:
    """A page of the app: its script (relative to ``app/``), title, icon and one-line purpose."""

    script: str
    title: str
    icon: str
    purpose: str

    @property
    def exists(self) -> bool:
        return (APP_DIR / self.script).is_file()


#: The pages, in menu order; Home links those whose script exists.
PAGES: tuple[Page, ...] = (
    Page("pages/1_Synthesize.py", "Synthesize", "🎙️",
         "speech in, gestures out: choose controls, run the search, refine, export"),
    Page("pages/2_Retrieval_inspector.py", "Retrieval inspector", "🔎",
         "step through the search: the candidates of every step, their distances and clips"),
    Page("pages/3_Database.py", "Database", "🗂️",
         "what the matching database holds: takes, clips, control attributes, any clip in 3D with its sound"),
    Page("pages/4_Study_stimuli.py", "Study stimuli", "🎬",
         "user-study videos: speeches x systems in one style, opaque ids, balanced order"),
)


# ---- errors -------------------------------------------------------------------------------------

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
        st.error(error_text(exc), icon="⚠️")


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
        st.error(f"Something went wrong; the details are in the server log (reference {reference}).", icon="⚠️")


def allowed(path: str | os.PathLike, *, what: str, write: bool = False) -> Path:
    """Refuse a typed path outside the folders the app may use (:func:`gesturekit.paths.check_allowed`).

    Returns the path resolved. The message is the same whether or not the path
    exists, so it tells a user nothing about the server's folders.

    Raises
    ------
    ConfigError
        Empty.
    PathNotAllowedError
        Outside :func:`gesturekit.paths.allowed_roots` (the message lists them).
    """
    return check_allowed(path, what=what, write=write)


@contextlib.contextmanager
def _warnings_shown() -> Iterator[list[str]]:
    """Show the :class:`GestureKitWarning` s raised inside the block as ``st.warning``.

    Yields the list their messages are collected in (complete when the block ends).
    """
    with collect_warnings() as messages:  # this session's thread only: sessions run side by side
        try:
            yield messages
        finally:
            for message in messages:
                st.warning(message)


# ---- state --------------------------------------------------------------------------------------

def persistent_key(name: str, default) -> str:
    """The widget key for a value that survives page switches and pages stopped early.

    Use the returned key as the widget's ``key`` and store the value it
    returns under ``name``::

        st.session_state["synth.seed"] = st.number_input("Seed", key=common.persistent_key("synth.seed", 0))

    Why the value is written to the widget on every run: a widget that is not
    drawn in a run (another page is shown, or the page stopped before it, as
    the sidebar does while a database folder is being typed) is removed from
    the browser, and when it is drawn again the browser shows the widget's
    default (a number input's minimum) unless the run sends the value; the
    next interaction would then send that default back as the user's choice.
    A value present under the key is the user's latest edit and is kept
    under ``name`` first.

    Parameters
    ----------
    name : str
        Session-state key of the value; prefix it with the page (``"db.clip"``).
    default
        The value before the user chose one.
    """
    ss = st.session_state
    key = f"_w.{name}"
    if key in ss:
        ss[name] = ss[key]
    ss[key] = ss.get(name, default)
    return key


_RUN_KEY = "_gk.page_run"  # runs of any page in this session (see page_setup)


def remount_key(key: str) -> str:
    """The key for a widget whose value a run cannot send to the browser (a data editor's edits).

    Such a widget, once not drawn in a run (another page, or a page stopped
    early), comes back in the browser without the user's edits while the
    session still holds them: the page would compute with edits the user no
    longer sees, and the next interaction would drop them. The key returned
    here changes whenever the widget was not drawn in the previous run of a
    page, so the widget starts anew, in the browser and here alike, from the
    page's own copy of its value (which the page must keep under another key).

    Parameters
    ----------
    key : str
        The widget's base key; the key returned is ``key`` until the first
        remount, then ``f"{key}.{n}"``.
    """
    ss = st.session_state
    run = ss.get(_RUN_KEY, 0)
    seen, n = ss.get(f"_gk.remount.{key}", (None, 0))
    if seen is not None and seen < run - 1:
        ss.pop(key if n == 0 else f"{key}.{n}", None)
        n += 1
    ss[f"_gk.remount.{key}"] = (run, n)
    return key if n == 0 else f"{key}.{n}"


# ---- the demo database --------------------------------------------------------------------------

def demo_minutes() -> float:
    """Minutes of the demo database the app builds: ``$GESTUREKIT_DEMO_MINUTES`` or the default.

    Raises
    ------
    ConfigError
        The variable is set but is not a positive number.
    """
    raw = os.environ.get(DEMO_MINUTES_ENV, "").strip()
    if not raw:
        return float(DEMO_MINUTES)
    try:
        minutes = float(raw)
    except ValueError:
        minutes = float("nan")
    if not minutes > 0 or minutes == float("inf"):
        raise ConfigError(f"{DEMO_MINUTES_ENV} must be a positive number of minutes, got {raw!r}")
    return minutes


@st.cache_resource(show_spinner=False)
def _build_lock() -> threading.Lock:
    # one build at a time in this server: sessions share the process (and the temporary folder name)
    return threading.Lock()


def ensure_demo_database() -> Path:
    """Build the demo database at the default path if it is not there, showing a progress bar.

    Nothing is downloaded: the demo speaker is generated (deterministically)
    and its database built, which takes about a second per minute of demo.

    Returns
    -------
    Path
        The default database folder (:func:`gesturekit.paths.default_database_path`).
    """
    path = default_database_path()
    if (path / "database.json").is_file():
        return path
    minutes = demo_minutes()
    with _build_lock():
        if (path / "database.json").is_file():  # another session built it meanwhile
            return path
        note = st.empty()
        note.info(
            f"No database yet at `{path}`: building the generated demo speaker's database "
            f"({minutes:g} minutes of synthetic speech and motion, no download)."
        )
        bar = st.progress(0.0, text="generating the demo speaker…")

        def progress(done: float, total: float) -> None:
            frac = min(1.0, done / total) if total > 0 else 1.0
            stage = "generating the demo speaker" if frac < 0.5 else "computing features and clips"
            bar.progress(frac, text=f"{stage}… {100 * frac:.0f}%")

        with _warnings_shown():
            build_demo_database(path, minutes=minutes, overwrite=path.exists(), progress=progress)
        bar.progress(1.0, text="demo database ready")
        note.success(f"Built the demo database at `{path}` ({minutes:g} minutes of generated speaker).")
    return path


def _rebuild_demo(path: Path) -> None:
    with _build_lock():
        bar = st.progress(0.0, text="rebuilding the demo database…")
        with _warnings_shown():
            build_demo_database(path, minutes=demo_minutes(), overwrite=True,
                                progress=lambda done, total: bar.progress(min(1.0, done / total)))


# ---- opening databases --------------------------------------------------------------------------

@st.cache_resource(max_entries=8, show_spinner="Opening the database…")
def _open(path: str, stamp: int) -> MatchingDatabase:
    # ``stamp`` (database.json's mtime) is only part of the cache key: a rebuilt database differs
    return MatchingDatabase.load(path)


def load_database(path: str | os.PathLike) -> MatchingDatabase:
    """Open a database folder, once per process and version (cached by path and mtime).

    The returned object is shared by every session: do not modify it.

    Raises
    ------
    DatabaseError
        No database there, or one that cannot be read (the message names the folder).
    """
    path = Path(path).expanduser().resolve()
    try:
        stamp = (path / "database.json").stat().st_mtime_ns
    except OSError:
        stamp = -1  # load() raises the precise error; failures are not cached
    return _open(str(path), stamp)


def is_generated(db: MatchingDatabase) -> bool:
    """Whether the database holds the generated demo speaker rather than recorded motion."""
    if str(db.meta.get("build", {}).get("source", "")).startswith("demo"):
        return True
    return any(
        str(t.get("sources", {}).get("generator", "")).startswith("gesturekit.datasets.synthetic")
        for t in db.meta.get("takes", [])
    )


def database_folders() -> dict[str, str]:
    """Databases the user can pick: folder (as a string) -> label, the default demo first.

    Looks for folders holding a ``database.json`` in ``./db`` (relative to the
    working directory) and in gesturekit's home ``db`` folder.
    """
    default = default_database_path().expanduser().resolve()
    out = {str(default): "demo database (generated speaker)"}
    for base in (Path.cwd() / "db", home() / "db"):
        try:
            subs = sorted(p for p in base.iterdir() if (p / "database.json").is_file())
        except OSError:
            continue
        for p in subs:
            key = str(p.resolve())
            out.setdefault(key, f"{p.name}  ({base})")
    return out


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
    choice = st.sidebar.selectbox(
        "Database", keys, key=_CHOICE_WIDGET,
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


def show_database_label(db: MatchingDatabase, *, container=st) -> None:
    """Say which database is open and what it holds; generated data is flagged as such."""
    name = db.path.name if db.path is not None else "(in memory)"
    if is_generated(db):
        container.warning(f"**Generated data** · {name}: {db.label or 'the demo speaker'}", icon="🧪")
    else:
        container.info(f"**{name}**" + (f": {db.label}" if db.label else ""), icon="🗂️")


def sidebar_database() -> MatchingDatabase:
    """The sidebar of every page; returns the user's database, opened.

    Shows the database selector and the "build from a folder" expander. If
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
    for kind, text in ss.pop(_FLASH_KEY, []):
        getattr(st.sidebar, kind)(text)
    allowed(path, what="database folder")  # before anything looks at the folder
    if path.expanduser().resolve() == default_database_path().expanduser().resolve():
        path = ensure_demo_database()
        try:
            db = load_database(path)
        except DatabaseError as exc:  # e.g. built by an older gesturekit: offer to rebuild it
            st.error(str(exc), icon="⚠️")
            if st.button("Rebuild the demo database", key="_gk.rebuild_demo"):
                _rebuild_demo(path)
                st.rerun()
            st.stop()
    else:
        db = load_database(path)
    show_database_label(db, container=st.sidebar)
    st.sidebar.caption(f"`{db.path}` · {_count(db.n_clips, 'clip')} · {_count(len(db.take_names), 'take')}")
    return db


# ---- building a database from a folder ---------------------------------------------------------

def build_from_folder(
    folder: str | os.PathLike,
    *,
    joint_map: str,
    out: str | os.PathLike,
    overwrite: bool = False,
    fps: float | None = None,
    label: str = "",
    progress: Callable[[int, int, str], None] | None = None,
) -> MatchingDatabase:
    """Build and save a database from a folder of takes (what ``gesturekit build-db FOLDER`` does).

    Parameters
    ----------
    folder : path
        Folder of takes (see :func:`gesturekit.datasets.takes.discover_takes`).
    joint_map : str
        ``"zeggs"``, ``"beat"`` or the path of a JSON joint map.
    out : path
        Database folder to write.
    overwrite : bool
        Replace an earlier database at ``out`` (only a database gesturekit built; other folders are refused).
    fps : float, optional
        Frame rate of joint-position files (they do not carry one).
    label : str
        Description stored with the database.
    progress : callable(done, total, take_name), optional
        Called after each take is read.

    Raises
    ------
    GestureKitError
        Empty or missing folder, an existing output without ``overwrite``, an
        unreadable joint map or take; the message names the path.
    """
    from gesturekit.datasets.presets import load_joint_map
    from gesturekit.datasets.takes import count_takes, discover_takes, iter_takes
    from gesturekit.outputs import check_output

    if not str(folder).strip():
        raise ConfigError("type the folder of takes to build from")
    if not str(out).strip():
        raise ConfigError("type the database folder to write")
    folder, out = Path(folder).expanduser(), Path(out).expanduser()
    # 'overwrite' replaces only a database gesturekit wrote, never the takes or a folder of other files
    if check_output(out, "database", overwrite=True, inputs=[folder]) and not overwrite:
        raise DatabaseError("a database already exists here; tick 'overwrite' to replace it", path=out)
    jmap = load_joint_map(joint_map)  # fail before reading any take
    sources = discover_takes(folder)
    total = count_takes(sources)
    config = BuildConfig(label=label, source=str(folder.resolve()), joint_map=str(joint_map))
    takes = iter_takes(sources, joint_map=jmap, fps_in=fps)

    def on_take(i: int, name: str) -> None:
        if progress is not None:
            progress(i, total, name)

    db = MatchingDatabase.build(takes, config=config, progress=on_take)
    db.save(out, overwrite=overwrite, inputs=[folder])
    return db


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _build_expander() -> None:
    """The sidebar's "build from a folder" form; a built database becomes the selection."""
    with st.sidebar.expander("Build a database from a folder"):
        folder = st.text_input("Folder of takes", key="_gk.build_folder",
                               help="BVH + speech files of the same name, joint-position files + speech, "
                                    "or npz files of the Habibie et al. 2021 layout")
        naming = st.radio("Skeleton", ["zeggs", "beat", "JSON joint map"], key="_gk.build_naming",
                          horizontal=True, help="joint naming preset of the BVH files, or a JSON joint map")
        map_path = ""
        if naming == "JSON joint map":
            map_path = st.text_input("Joint map (JSON file)", key="_gk.build_map")
        fps = st.number_input("Frame rate of joint-position files (0: not needed)", min_value=0.0,
                              value=0.0, step=1.0, key="_gk.build_fps")
        out = st.text_input("Database folder to write", key="_gk.build_out",
                            placeholder=str(home() / "db" / "<folder name>"))
        label = st.text_input("Label (optional)", key="_gk.build_label")
        overwrite = st.checkbox("overwrite an existing database", key="_gk.build_overwrite",
                                help="replaces only a database gesturekit built; any other folder is kept")
        if not st.button("Build", key="_gk.build_go"):
            return
        with user_errors():
            if naming == "JSON joint map" and not map_path.strip():
                raise ConfigError("type the path of the JSON joint map")
            target = out.strip() or (str(home() / "db" / Path(folder.strip()).name) if folder.strip() else "")
            # every typed path is checked before any is looked at (build_from_folder reports empty ones)
            for typed, what, write in ((folder, "folder of takes", False), (map_path, "joint map", False),
                                       (target, "database folder to write", True)):
                if typed.strip():
                    allowed(typed.strip(), what=what, write=write)
            bar = st.progress(0.0, text="finding takes…")

            def progress(i: int, total: int, name: str) -> None:
                bar.progress(min(1.0, i / max(total, 1)), text=f"read {i}/{total} takes ({name})")

            with _warnings_shown() as warned, _build_lock():
                db = build_from_folder(
                    folder, joint_map=map_path.strip() if naming == "JSON joint map" else naming, out=target,
                    overwrite=overwrite, fps=fps or None, label=label.strip(), progress=progress,
                )
            bar.progress(1.0, text="saved")
            st.session_state[_PENDING_KEY] = str(Path(db.path).resolve())
            # the page reruns to open the new database; the messages are shown on that run
            st.session_state[_FLASH_KEY] = [("success", f"Built {_count(db.n_clips, 'clip')} from "
                                                        f"{_count(len(db.take_names), 'take')} into {db.path}")]
            st.session_state[_FLASH_KEY] += [("warning", w) for w in warned]
            st.rerun()


# ---- page frame ---------------------------------------------------------------------------------

def page_setup(title: str, *, icon: str = "🖐️") -> None:
    """Page title and wide layout; call first on every page (it also counts the session's runs,
    see :func:`remount_key`)."""
    st.set_page_config(page_title=f"{title} · gesturekit", page_icon=icon, layout="wide")
    st.session_state[_RUN_KEY] = st.session_state.get(_RUN_KEY, 0) + 1


# ---- the user's synthesis, shared by the Synthesize and Retrieval inspector pages ---------------

#: Session-state key of the user's latest synthesis: a dict with ``result`` (SynthesisResult),
#: ``run`` (a number that changes with every new result), ``database`` (resolved folder),
#: ``speech`` (the speech's name) and ``refiner`` (what was passed to apply a refiner, or None).
SYNTHESIS_KEY = "gk.synthesis"
#: Session-state key of the user's pinned choices, step -> (clip, start) ("use this candidate instead"),
#: applied by every run until removed.
PINS_KEY = "gk.pins"
_RUN_COUNTER = "gk.run_counter"


def run_synthesis(db: MatchingDatabase, audio, *, config, source: str, refiner=None) -> dict:
    """Synthesise with a spinner, store the result as the user's synthesis and return that record.

    Parameters
    ----------
    db : MatchingDatabase
    audio : np.ndarray, shape (samples,)
        Mono float32 speech at 16 kHz.
    config : SynthesisConfig
    source : str
        Name of the speech, stored in the result (download names, metadata).
    refiner : optional
        A refiner (folder or loaded), applied by :func:`gesturekit.synthesize.synthesize`.

    Raises
    ------
    GestureKitError
        Impossible settings (shown by :func:`run_page` / :func:`user_errors`).
    """
    from dataclasses import replace

    from gesturekit.synthesize import synthesize

    ss = st.session_state
    with st.spinner("Searching the database…"), _warnings_shown():
        result = synthesize(audio, db=db, config=config, refiner=refiner)
    ss[_RUN_COUNTER] = ss.get(_RUN_COUNTER, 0) + 1
    record = {"result": replace(result, source=source), "run": ss[_RUN_COUNTER],
              "database": str(Path(db.path).resolve()) if db.path is not None else result.database,
              "speech": source, "refiner": refiner}
    ss[SYNTHESIS_KEY] = record
    ss[PINS_KEY] = dict(config.pins)
    return record


def current_synthesis(db: MatchingDatabase) -> dict | None:
    """The user's latest synthesis (see :data:`SYNTHESIS_KEY`) if it was made with ``db``, else None."""
    record = st.session_state.get(SYNTHESIS_KEY)
    if record is None:
        return None
    here = str(Path(db.path).resolve()) if db.path is not None else None
    return record if record["database"] == here else None


def show_skeletons(motions, *, key: str, labels=None, title: str | None = None, height: int = 520,
                   audio=None) -> None:
    """Show motions side by side in gesturekit's 3D viewer (:func:`gesturekit.viz.viewer.skeleton_viewer`).

    The viewer draws on a 2D canvas: a browser without a GPU shows it at once, where
    a WebGL scene would take it seconds to set up. ``height``: of the drawing, in
    pixels (its controls come below); ``key`` names the viewer (pages and tests find it by it).
    ``audio``: the speech of the motions (mono float32 at 16 kHz, from their first frame);
    the viewer's play button then plays it and the shown frame follows it, so no separate
    player is needed.
    """
    from gesturekit.viz.viewer import CONTROLS_HEIGHT, skeleton_viewer

    page = skeleton_viewer(motions, labels=labels, title=title, height=height, key=key, audio=audio)
    st.iframe(page, height=int(height) + CONTROLS_HEIGHT)


@st.cache_resource(show_spinner="Generating the example speech…", max_entries=4)
def example_audio(label: str):
    """Example speech (a key of :data:`gesturekit.viz.session.SPEECH_EXAMPLES`): mono float32 at
    16 kHz, read-only, made once per server and shared by every session."""
    from gesturekit.viz.session import example_speech

    audio = example_speech(label)
    audio.setflags(write=False)
    return audio


def _first_use(noise) -> None:
    """Everything a first result needs once per process, run on small inputs: the example
    speech a first visit shows, the speech reader, the figures (plotly builds its validators
    on first use) and the WAV writer.

    ``noise``: a few seconds of mono float32 audio at 16 kHz.
    """
    import io

    import numpy as np
    import plotly.io as pio
    import soundfile as sf

    from gesturekit.motion import AUDIO_SR, N_JOINTS, Motion
    from gesturekit.viz import session as gs
    from gesturekit.viz.figures import waveform_figure, wrist_figure
    from gesturekit.viz.viewer import skeleton_viewer

    example_audio(next(iter(gs.SPEECH_EXAMPLES)))  # what a first visit to Synthesize shows
    buf = io.BytesIO()
    sf.write(buf, noise, AUDIO_SR, format="WAV", subtype="PCM_16")
    audio, _ = gs.read_speech_upload("warm-up.wav", buf.getvalue())
    gs.wav_bytes(audio)
    import pyarrow as pa  # what streamlit's tables are sent as: its first import takes most of a second

    pa.Table.from_pandas(gs.segments_frame(gs.track_from_segments(gs.empty_segments())))
    motion = Motion(np.zeros((4, N_JOINTS, 3), np.float32), 15.0)
    skeleton_viewer([motion, motion], labels=["a", "b"])
    for fig in (waveform_figure(audio, AUDIO_SR), wrist_figure([motion, motion], labels=["a", "b"])):
        pio.to_json(fig.to_dict(), validate=False)


@st.cache_resource(show_spinner=False, max_entries=8)
def _warm_up(path: str, stamp: int) -> threading.Thread:
    import numpy as np

    from gesturekit.motion import AUDIO_SR
    from gesturekit.synthesize import SynthesisConfig, synthesize

    db = _open(path, stamp)
    noise = np.random.default_rng(0).normal(0.0, 0.1, 2 * AUDIO_SR).astype(np.float32)

    def warm() -> None:
        # what an upload needs first, then what Run needs; a failure is left to the server
        # log (the user's own run reports it on the page)
        for step in (lambda: _first_use(noise), lambda: synthesize(noise, db=db, config=SynthesisConfig(topk=1))):
            try:
                with collect_warnings():
                    step()
            except Exception:  # noqa: BLE001
                LOG.warning("a warm-up step failed", exc_info=True)

    thread = threading.Thread(target=warm, name="gesturekit-warm-up", daemon=True)
    thread.start()
    return thread


def warm_up_search(db: MatchingDatabase) -> None:
    """Prepare the search of a database in the background, once per server and database.

    The first synthesis with a database builds its search index and loads
    the compiled search code (seconds for a large database); doing that
    while the user is still choosing speech makes their first run as fast
    as the later ones.
    """
    if db.path is None:
        return
    path = Path(db.path).expanduser().resolve()
    try:
        stamp = (path / "database.json").stat().st_mtime_ns
    except OSError:
        return
    _warm_up(str(path), stamp)


def default_refiner(db: MatchingDatabase) -> str:
    """The refiner folder offered first for ``db``, with the refiner switched on: one trained on
    it (``<db>/refiner``, or the shipped demo refiner for the demo speaker; see
    :func:`gesturekit.refine.refiner_for`, which the command line uses too), else "" (off)."""
    try:
        from gesturekit.refine import refiner_for
    except ImportError:  # a gesturekit without the refiner
        return ""
    found = refiner_for(db)
    return "" if found is None else str(found)


def warm_up(db: MatchingDatabase) -> None:
    """Prepare, in the background and once per server, what a first run with ``db`` needs:
    its search (:func:`warm_up_search`) and its default refiner (:func:`warm_up_refiner`)."""
    warm_up_search(db)
    refiner = default_refiner(db)
    if refiner:
        warm_up_refiner(Path(refiner))


@contextlib.asynccontextmanager
async def server_lifespan(app):
    """The server's start and stop (``st.App``'s lifespan, see ``Home.py``): at start,
    the default database's search and refiner are prepared in the background.

    Nothing is built here: a missing demo database is built by the first page
    view, with a progress bar. A failure is left to the server log.
    """
    # the caches are filled outside any page run here, which streamlit's context lookup
    # would log as a warning for each cached call
    quiet = logging.getLogger("streamlit.runtime.scriptrunner_utils.script_run_context")
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        path = default_database_path()
        if (path / "database.json").is_file():
            warm_up(load_database(path))
    except Exception:  # noqa: BLE001  (the server must start regardless)
        LOG.warning("warm-up at start skipped", exc_info=True)
    finally:
        quiet.setLevel(level)
    yield


@st.cache_resource(max_entries=4, show_spinner="Loading the refiner…")
def _open_refiner(path: str, stamp: int):
    # ``stamp`` (config.json's mtime) is only part of the cache key: a retrained refiner differs
    from gesturekit.refine import load_refiner as load

    return load(path)


def check_refiner(path: str | os.PathLike, db: MatchingDatabase) -> Path:
    """Check a refiner folder against ``db`` without loading it (no torch): its resolved path.

    Starts loading it in the background (see :func:`warm_up_refiner`), so that the
    run that uses it finds it ready.

    Raises
    ------
    GestureKitError
        A folder outside the allowed ones (:func:`allowed`), no refiner there, an unreadable
        ``config.json``, or another feature layout than ``db``'s.
    """
    from gesturekit.refine import check_refiner as check

    if not str(path).strip():
        raise ConfigError("type the folder of a trained refiner, or turn the refiner off")
    allowed(path, what="refiner folder")
    folder = check(path, db)
    warm_up_refiner(folder)
    return folder


@st.cache_resource(show_spinner=False, max_entries=8)
def _warm_refiner(path: str, stamp: int) -> threading.Thread:
    def warm() -> None:
        # torch's import, the files read and a first forward pass (torch picks its kernels for
        # the shapes), into the cached object the runs use
        import numpy as np

        from gesturekit.blend import KEEP_BELOW_HZ, keep_slow

        n = 450  # frames of 30 s of speech
        try:
            knn = np.zeros((n, 165), np.float32)
            # as synthesis calls it: the generator, then the k-NN motion's slow content kept
            keep_slow(_open_refiner(path, stamp).refine(knn, np.zeros((n, 28), np.float32)), knn, KEEP_BELOW_HZ)
        except Exception:  # noqa: BLE001  (the run's own load reports it on the page)
            LOG.warning("the refiner's warm-up failed", exc_info=True)

    thread = threading.Thread(target=warm, name="gesturekit-warm-refiner", daemon=True)
    thread.start()
    return thread


def warm_up_refiner(path: Path) -> None:
    """Load a refiner (torch, weights) in the background, once per server and version."""
    try:
        stamp = (Path(path) / "config.json").stat().st_mtime_ns
    except OSError:
        return
    _warm_refiner(str(path), stamp)


def load_refiner(path: str | os.PathLike, db: MatchingDatabase):
    """Open a trained refiner folder once per process and version, checked against ``db``.

    The returned object is shared by every session: do not modify it.

    Raises
    ------
    GestureKitError
        A folder outside the allowed ones (:func:`allowed`), no refiner there, an unreadable
        one, or one trained on another feature layout than ``db``'s (the message names the folder).
    """
    if not str(path).strip():
        raise ConfigError("type the folder of a trained refiner, or turn the refiner off")
    path = allowed(path, what="refiner folder")
    try:
        stamp = (path / "config.json").stat().st_mtime_ns
    except OSError:
        stamp = -1  # the loader raises the precise error; failures are not cached
    refiner = _open_refiner(str(path), stamp)
    refiner.check_database(db)
    return refiner
