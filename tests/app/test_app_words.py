"""Words for an audience on every page: no server paths, command-line flags or source strings."""

from __future__ import annotations

from pathlib import Path

import pytest
from streamlit.testing.v1 import AppTest

from gesturekit.app import HOME
from tests.conftest import shown
from tests.waits import APP_RUN_S

pytestmark = pytest.mark.slow  # builds the demo database (demo_home) and runs every page in AppTest

PAGES = [
    "Home.py",
    "views/1_Synthesize.py",
    "views/2_Retrieval_inspector.py",
    "views/3_Database.py",
    "views/4_Study_stimuli.py",
    "views/5_Live.py",
    "views/6_Study.py",
]


def _texts(at: AppTest) -> list[str]:
    """Every text an audience reads: markdown, notes, labels of buttons and downloads, choices offered."""
    texts = []
    for kind in ("markdown", "caption", "info", "success", "warning", "error", "title", "header", "subheader"):
        texts += [shown(str(e.value)) for e in at.get(kind)]
    texts += [str(d.proto.label) for d in at.get("download_button")]
    texts += [str(b.label) for b in at.button]
    for box in list(at.selectbox) + list(at.radio):
        texts += [str(box.label)] + [str(o) for o in box.options]
    return texts


@pytest.mark.parametrize("page", PAGES)
def test_no_page_shows_server_paths_flags_or_source_strings_after_a_run(app_env, page):
    from gesturekit.refine import default_refiner_path

    at = AppTest.from_file(str(HOME), default_timeout=APP_RUN_S).run()
    home_texts = _texts(at)  # the start page, as a user first sees it
    at.switch_page("views/1_Synthesize.py").run()
    at.radio(key="_w.synth.mode").set_value("Example speech").run()
    at.button(key="synth.go").click().run()  # a run on the demo database, then the page under test
    assert not at.exception, at.exception
    if page not in ("Home.py", "views/1_Synthesize.py"):
        at.switch_page(page).run()
        assert not at.exception, at.exception
    texts = home_texts if page == "Home.py" else _texts(at)
    assert texts
    paths = (str(app_env), str(default_refiner_path()), str(Path.cwd()), str(Path.home()))
    for text in texts:
        for path in paths:
            assert path not in text, (page, text)
        assert " --" not in text and not text.startswith("--"), (page, text)  # no command-line flags
        assert "gesturekit.datasets" not in text and "generator=" not in text, (page, text)
