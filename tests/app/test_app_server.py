"""The app's server start: ``gesturekit app`` and ``streamlit run app/Home.py`` serve Home's ``st.App``,
whose lifespan prepares the default database's search and refiner in the background."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import pytest

from gesturekit.app import HOME
from gesturekit.paths import default_database_path
from gesturekit.workspace import is_generated
from tests.waits import patience

CLONE_HOME = Path(__file__).resolve().parents[2] / "app" / "Home.py"


@pytest.fixture
def common(app_env):
    """The app's resources module (what the server's start prepares)."""
    from gesturekit.app import resources as module

    return module


def _start_and_stop(common) -> None:
    async def run():
        async with common.server_lifespan(None):
            pass

    asyncio.run(run())


def test_streamlit_run_finds_the_app_with_its_lifespan():
    from streamlit.web.server.app_discovery import discover_asgi_app

    for home in (HOME, CLONE_HOME):  # the packaged entrypoint, and the clone's script that serves it
        found = discover_asgi_app(home)
        assert found.is_asgi_app and found.app_name == "app", home


@pytest.mark.slow
def test_server_start_prepares_search_and_refiner_of_the_default_database(common, monkeypatch):
    import gesturekit.interactive as gs

    made = []
    real = gs.example_speech
    monkeypatch.setattr(gs, "example_speech", lambda label: made.append(label) or real(label))
    common.example_audio.clear()
    _start_and_stop(common)
    path = default_database_path().resolve()
    db = common.load_database(path)
    stamp = (path / "database.json").stat().st_mtime_ns
    search = common._warm_up(str(path), stamp)  # cached: the thread the start began
    assert search.name == "gesturekit-warm-up"
    refiner = Path(common.default_refiner(db))
    assert is_generated(db) and (refiner / "config.json").is_file()
    warm_refiner = common._warm_refiner(str(refiner), (refiner / "config.json").stat().st_mtime_ns)
    assert warm_refiner.name == "gesturekit-warm-refiner"
    for thread in (search, warm_refiner):
        thread.join(timeout=patience(300))
        assert not thread.is_alive()
    from gesturekit.search.exact import compiled

    assert compiled.cache_info().currsize == 1  # the compiled search is loaded
    # the example speech a first visit to Synthesize shows is made once, at the start
    first = next(iter(gs.SPEECH_EXAMPLES))
    assert made == [first]
    assert common.example_audio(first).shape == (int(gs.SPEECH_EXAMPLES[first][0] * 16000),) and made == [first]


@pytest.mark.slow
def test_server_start_without_a_database_builds_nothing(common, tmp_path, monkeypatch, caplog):
    monkeypatch.setenv("GESTUREKIT_HOME", str(tmp_path / "empty"))
    with caplog.at_level("DEBUG", logger="gesturekit.app"):
        _start_and_stop(common)
    assert not default_database_path().exists()  # the first page view builds it, with a progress bar
    assert not [r for r in caplog.records if r.name == "gesturekit.app"]


@pytest.mark.slow
def test_server_start_with_a_broken_database_still_starts(common, tmp_path, monkeypatch, caplog):
    home = tmp_path / "broken"
    monkeypatch.setenv("GESTUREKIT_HOME", str(home))
    folder = default_database_path()
    folder.mkdir(parents=True)
    (folder / "database.json").write_text(json.dumps({"format": "nonsense"}))
    with caplog.at_level("WARNING", logger="gesturekit.app"):
        _start_and_stop(common)
    (record,) = [r for r in caplog.records if r.name == "gesturekit.app"]  # the server log, not the page
    assert "warm-up at start skipped" in record.getMessage() and str(folder) in str(record.exc_info[1])
