"""Per-user state: widget values that survive page switches, and the user's latest synthesis.

Everything a user chooses lives in ``st.session_state``, which Streamlit
keeps per browser session, so two users never see each other's choices.
Streamlit forgets a widget's value when it is not drawn in a run (its page
is left, or the page stops early): :func:`persistent_key` gives widgets a
value that survives that, and :func:`remount_key` does the same for a widget
whose value a run cannot send (the data editor). The Synthesize and Retrieval
inspector pages share the user's synthesis (:data:`SYNTHESIS_KEY`) and pinned
choices (:data:`PINS_KEY`).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import streamlit as st

from gesturekit.app.display import warnings_shown
from gesturekit.database import MatchingDatabase

if TYPE_CHECKING:
    import os

    import numpy as np

    from gesturekit.refine.infer import Refiner
    from gesturekit.synthesis import SynthesisConfig, SynthesisResult

__all__ = [
    "APP_ICON",
    "PINS_KEY",
    "SYNTHESIS_KEY",
    "current_synthesis",
    "keep_synthesis",
    "page_setup",
    "persistent_key",
    "picked_key",
    "remount_key",
    "run_synthesis",
]

#: The app's icon (the browser tab's and Home's): an emoji, which the browser draws itself. A Material
#: icon (``:material/...:``) as the page icon makes every browser fetch it from fonts.gstatic.com;
#: in the page itself, Material icons come from the font Streamlit serves.
APP_ICON = "👋"
_RUN_KEY = "_gk.page_run"  # runs of any page in this session (see page_setup)
#: Session-state key of the user's latest synthesis: a dict with ``result`` (SynthesisResult),
#: ``run`` (a number that changes with every new result), ``database`` (resolved folder),
#: ``speech`` (the speech's name) and ``refiner`` (what was passed to apply a refiner, or None).
SYNTHESIS_KEY = "gk.synthesis"
#: Session-state key of the user's pinned choices, step -> (clip, start) ("use this candidate instead"),
#: applied by every run until removed.
PINS_KEY = "gk.pins"
_RUN_COUNTER = "gk.run_counter"


def page_setup(title: str, *, icon: str = APP_ICON) -> None:
    """Page title and wide layout; called before every page is drawn (it also counts the
    session's runs, see :func:`remount_key`)."""
    st.set_page_config(page_title=f"{title} · gesturekit", page_icon=icon, layout="wide")
    st.session_state[_RUN_KEY] = st.session_state.get(_RUN_KEY, 0) + 1


def persistent_key(name: str, default: object) -> str:
    """The widget key for a value that survives page switches and pages stopped early.

    Use the returned key as the widget's ``key`` and store the value it
    returns under ``name``::

        st.session_state["synth.seed"] = st.number_input("Seed", key=state.persistent_key("synth.seed", 0))

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


def picked_key(name: str, selected: int | None, *, last: str, n: int) -> str:
    """The :func:`persistent_key` of a number input (0 to ``n - 1``) that a table row selection also sets.

    A row selected since the previous run (``selected``; ``last`` names where that run's
    selection is kept) wins over the number typed; the value is then clipped to the range,
    as another database or result may hold fewer rows.
    """
    ss = st.session_state
    key = persistent_key(name, 0)
    if selected is not None and selected != ss.get(last):
        ss[key] = selected
    ss[last] = selected
    ss[key] = int(min(max(int(ss[key]), 0), n - 1))
    return key


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


def run_synthesis(
    db: MatchingDatabase,
    audio: np.ndarray,
    *,
    config: SynthesisConfig,
    source: str,
    refiner: Refiner | str | os.PathLike[str] | None = None,
) -> dict:
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
        A refiner (folder or loaded, opened by :func:`gesturekit.refine.open_refiner`), applied by
        :func:`gesturekit.synthesis.synthesize`.

    Raises
    ------
    GestureKitError
        Impossible settings (shown by :func:`display.run_page` / :func:`display.user_errors`).
    """
    from gesturekit.refine import open_refiner
    from gesturekit.synthesis import synthesize

    with st.spinner("Searching the database…"), warnings_shown():
        result = synthesize(audio, db=db, config=config, refiner=open_refiner(refiner))
    return keep_synthesis(db, result, source=source, refiner=refiner)


def keep_synthesis(
    db: MatchingDatabase,
    result: SynthesisResult,
    *,
    source: str,
    refiner: Refiner | str | os.PathLike[str] | None = None,
) -> dict:
    """Store ``result`` (made with ``db``) as the user's synthesis (:data:`SYNTHESIS_KEY`) and return the record.

    The Synthesize page stores its runs here, the Live page its performances; the Retrieval
    inspector reads the latest. ``source``: the speech's name; ``refiner``: what was applied.
    """
    ss = st.session_state
    ss[_RUN_COUNTER] = ss.get(_RUN_COUNTER, 0) + 1
    record = {
        "result": replace(result, source=source),
        "run": ss[_RUN_COUNTER],
        "database": _folder(db) if db.path is not None else result.database,
        "speech": source,
        "refiner": refiner,
    }
    ss[SYNTHESIS_KEY] = record
    ss[PINS_KEY] = dict(result.config.pins)
    return record


def current_synthesis(db: MatchingDatabase) -> dict | None:
    """The user's latest synthesis (see :data:`SYNTHESIS_KEY`) if it was made with ``db``, else None."""
    record = st.session_state.get(SYNTHESIS_KEY)
    if record is None:
        return None
    return record if record["database"] == (_folder(db) if db.path is not None else None) else None


def _folder(db: MatchingDatabase) -> str:
    return str(Path(db.path).resolve())
