"""The app's pages are declared once (gesturekit/app/nav.py): every page script, at the URLs users and tests open."""

from __future__ import annotations

import pytest

from gesturekit.app import APP_DIR


@pytest.fixture
def nav():
    from gesturekit.app import nav as module

    return module


def test_every_page_script_is_declared_once_in_menu_order(nav):
    scripts = sorted(str(p.relative_to(APP_DIR)) for p in (APP_DIR / "views").glob("*.py"))
    assert [p.script for p in nav.PAGES] == scripts  # the file names' numbers give the order
    assert not (APP_DIR / "pages").exists()  # Streamlit would run a pages/ folder's scripts without Home.py


def test_the_pages_keep_their_titles_and_urls(nav):
    assert [(p.title, p.url_path) for p in nav.PAGES] == [
        ("Synthesize", "Synthesize"),
        ("Retrieval inspector", "Retrieval_inspector"),
        ("Database", "Database"),
        ("Study stimuli", "Study_stimuli"),
        ("Live", "Live"),
        ("Study", "Study"),
    ]
    assert all(p.purpose and p.icon for p in nav.PAGES)
