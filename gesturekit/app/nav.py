"""The app's pages, declared once: the menu (``st.navigation``), the URLs and Home's list all come from here.

A page is a script in ``gesturekit/app/views/`` that draws itself when run; ``Home.py``
runs the one the user is on inside :func:`display.run_page`, after
:func:`state.page_setup`. Its URL is its title with ``_`` for spaces
(``/Retrieval_inspector``). The folder is not called ``pages/``: Streamlit
would take such a folder for the older, implicit way of declaring pages and
run its scripts without ``Home.py`` around them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import streamlit as st

from gesturekit.app import display, state

__all__ = ["APP_DIR", "HOME_TITLE", "PAGES", "Page", "link", "run"]

APP_DIR = Path(__file__).resolve().parent
HOME_TITLE = "Home"


@dataclass(frozen=True)
class Page:
    """A page of the app: its script (relative to ``gesturekit/app/``), title, icon and one-line purpose."""

    script: str
    title: str
    icon: str
    purpose: str

    @property
    def url_path(self) -> str:
        return self.title.replace(" ", "_")

    def streamlit_page(self) -> st.Page:
        return st.Page(APP_DIR / self.script, title=self.title, icon=self.icon, url_path=self.url_path)


#: The pages after Home, in menu order.
PAGES: tuple[Page, ...] = (
    Page(
        "views/1_Synthesize.py",
        "Synthesize",
        ":material/mic:",
        "speech in, gestures out: choose controls, run the search, refine, export",
    ),
    Page(
        "views/2_Retrieval_inspector.py",
        "Retrieval inspector",
        ":material/manage_search:",
        "step through the search: the candidates of every step, their distances and clips",
    ),
    Page(
        "views/3_Database.py",
        "Database",
        ":material/storage:",
        "what the matching database holds: takes, clips, control attributes, any clip in 3D with its sound",
    ),
    Page(
        "views/4_Study_stimuli.py",
        "Study stimuli",
        ":material/movie:",
        "user-study videos: speeches x systems in one style, opaque ids, balanced order",
    ),
    Page(
        "views/5_Live.py",
        "Live",
        ":material/record_voice_over:",
        "speak into the microphone and watch the body gesture as you talk; switch a control; keep the performance",
    ),
    Page(
        "views/6_Study.py",
        "Study",
        ":material/groups:",
        "a running study: who took part, ratings per stimulus and condition, the analysis, CSV downloads",
    ),
)


def link(title: str) -> None:
    """A link to the page titled ``title`` (its icon and title, as in the menu)."""
    page = next(p for p in PAGES if p.title == title)
    st.page_link(page.streamlit_page(), label=page.title, icon=page.icon)


def run(home: Callable[[], None]) -> None:
    """Declare the pages (``home`` first, at the app's root URL) and draw the one the user is on.

    Call once per run, from the entrypoint (``Home.py``).
    """
    page = st.navigation(
        [st.Page(home, title=HOME_TITLE, icon=state.APP_ICON, default=True)] + [p.streamlit_page() for p in PAGES]
    )
    state.page_setup(page.title)
    display.run_page(page.run)
