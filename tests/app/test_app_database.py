"""The app shell (Home, sidebar) and the Database page, run headless with Streamlit's AppTest."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from streamlit.testing.v1 import AppTest

from gesturekit.app import HOME
from gesturekit.database import MatchingDatabase
from gesturekit.datasets.synthetic import DEMO_LABEL
from gesturekit.demo import build_demo_database
from gesturekit.skeleton import bones
from gesturekit.workspace import DEMO_DATABASE_LABEL, database_words
from tests.conftest import chart_spec as _chart
from tests.conftest import shown, viewer
from tests.waits import APP_RUN_S

pytestmark = pytest.mark.slow  # each module builds its demo database (demo_home) and runs pages in AppTest

DATABASE_PAGE = "views/3_Database.py"
TIMEOUT = APP_RUN_S  # a script run's deadline, which ends a hang (tests/waits.py)


@pytest.fixture(scope="module")
def demo_home(tmp_path_factory) -> Path:
    """A gesturekit home holding a 3-minute demo database at the default path."""
    home = tmp_path_factory.mktemp("gkhome")
    build_demo_database(home / "db" / "demo", minutes=3)
    return home


def _run_database_page() -> AppTest:
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    assert not at.exception
    at.switch_page(DATABASE_PAGE).run()
    assert not at.exception, at.exception
    return at


def _first_pose_bones(data: dict) -> np.ndarray:
    """The segments of frame 0 of a skeleton viewer's data, in the order of bones(), shape (54, 6)."""
    segs = []
    for m in data["motions"]:
        pts = m["points"][0]  # the joints where the page poses them
        segs.append(np.concatenate([pts[bones()[:, 0]], pts[bones()[:, 1]]], axis=1))  # (child, parent)
    return np.concatenate(segs)


def _clip_bones(db: MatchingDatabase, clip: int) -> np.ndarray:
    pos = np.asarray(db.G[clip, 0], dtype=np.float64).reshape(-1, 3)
    b = bones()
    return np.concatenate([pos[b[:, 0]], pos[b[:, 1]]], axis=1)


def _error_texts(at: AppTest) -> list[str]:
    return [shown(e.value) for e in at.error]


def test_home_opens_the_demo_database_and_labels_it_generated(app_env):
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    assert not at.exception
    assert not _error_texts(at)
    assert any(DEMO_LABEL in shown(w.value) and "Generated data" in shown(w.value) for w in at.main.warning)
    assert any("Habibie" in shown(m.value) for m in at.markdown)
    # the open database is named in words, not by the server's folder
    said = " ".join(shown(m.value) for m in at.markdown)
    assert database_words(app_env / "db" / "demo").lower() in said.lower() and str(app_env / "db") not in said
    assert [link.proto.label for link in at.get("page_link")] == [
        "Synthesize",
        "Retrieval inspector",
        "Database",
        "Study stimuli",
        "Live",
        "Study",
    ]


def test_database_page_shows_tables_histograms_skeleton_and_audio(app_env):
    at = _run_database_page()
    db = MatchingDatabase.load(app_env / "db" / "demo")
    tables = [d.value for d in at.dataframe]
    takes = next(t for t in tables if "duration_s" in t.columns)
    clips = next(t for t in tables if "start_frame" in t.columns)
    assert list(takes["take"]) == db.take_names
    assert len(clips) == db.n_clips
    assert [shown(m.value) for m in at.metric][:2] == [str(db.n_clips), str(len(db.take_names))]

    hist = _chart(at, "db.histograms")
    assert [t["meta"]["attribute"] for t in hist["data"]] == list(db.attribute_names)
    lo, hi = db.thresholds["hand_speed"]
    lines = sorted(s["x0"] for s in hist["layout"]["shapes"] if s["name"].startswith("hand_speed"))
    assert lines == pytest.approx([lo, hi])

    skel = viewer(at, "db.skeleton")
    assert len(skel["times"]) == db.clip_frames
    assert skel["up"] == [0, 1, 0]
    # posed by the rig's rotations, sent as int16 quaternions: their rounding moves a fingertip by under 2 mm
    np.testing.assert_allclose(_first_pose_bones(skel), _clip_bones(db, 0), atol=2e-3)
    # the clip's speech plays in the viewer, on its clock: no separate player
    np.testing.assert_allclose(
        skel["audio"][: db.clip_frames * 16000 // 15],
        db.segment_audio(0, 0, db.clip_frames)[: db.clip_frames * 16000 // 15],
        atol=1e-4,
    )
    assert len(at.get("audio")) == 0
    # the clip's attributes, each with its unit
    (attrs,) = [d for d in at.dataframe if "clip mean" in d.value.columns]
    units = dict(zip(attrs.value["attribute"], attrs.value["unit"]))
    assert units == {n: ("m/s" if "speed" in n else "m") for n in db.attribute_names}


def test_choosing_another_clip_changes_the_viewer(app_env):
    at = _run_database_page()
    db = MatchingDatabase.load(app_env / "db" / "demo")
    clip_input = next(n for n in at.number_input if n.label == "Clip to view")
    clip_input.set_value(3).run()
    assert not at.exception
    skel = viewer(at, "db.skeleton")
    assert skel["title"].startswith("clip 3:")
    np.testing.assert_allclose(_first_pose_bones(skel), _clip_bones(db, 3), atol=2e-3)

    # selecting a row of the clips table picks that clip too
    at.session_state["db.clips_table"] = {"selection": {"rows": [7], "columns": []}}
    at.run()
    assert not at.exception
    assert viewer(at, "db.skeleton")["title"].startswith("clip 7:")
    assert next(n for n in at.number_input if n.label == "Clip to view").value == 7

    # the choice is per user: a second session still shows clip 0
    other = _run_database_page()
    assert viewer(other, "db.skeleton")["title"].startswith("clip 0:")


@pytest.mark.parametrize("kind", ["missing", "not_a_database"])
def test_a_bad_database_path_shows_an_error_not_a_traceback(app_env, tmp_path, kind):
    target = tmp_path / "nowhere" if kind == "missing" else tmp_path
    at = _run_database_page()
    at.sidebar.selectbox[0].select_index(-1).run()  # "another folder…"
    assert not at.exception and not _error_texts(at)
    at.sidebar.text_input(key="_gk.database_typed").input(str(target)).run()
    assert not at.exception
    errors = _error_texts(at)
    assert len(errors) == 1 and str(target) in errors[0]
    assert ("no database folder" if kind == "missing" else "database.json is missing") in errors[0]
    assert not at.get("plotly_chart") and not at.get("component_instance")


def test_databases_in_the_working_directory_are_offered(app_env, tmp_path):
    shutil.copytree(app_env / "db" / "demo", tmp_path / "db" / "copy")
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    options = at.sidebar.selectbox[0].options
    assert options[0] == DEMO_DATABASE_LABEL and options[1] == "a database you built: copy"
    at.sidebar.selectbox[0].select_index(1).run()
    assert not at.exception
    # the folder's name in the sidebar's label, its path on the server not in the caption under it
    assert any("copy" in shown(w.value) for w in [*at.sidebar.warning, *at.sidebar.info])
    assert not any(str(tmp_path) in shown(c.value) for c in at.sidebar.caption)


def test_building_into_an_existing_database_or_from_a_missing_folder_is_an_error(app_env, tmp_path):
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    at.sidebar.text_input(key="_gk.build_folder").input(str(tmp_path / "no_takes"))
    at.sidebar.button(key="_gk.build_go").click().run()
    assert not at.exception
    assert [shown(e.value) for e in at.sidebar.error] == [f"{tmp_path / 'no_takes'}: no such folder"]

    at.sidebar.text_input(key="_gk.build_out").input(str(app_env / "db" / "demo"))
    at.sidebar.button(key="_gk.build_go").click().run()
    assert not at.exception
    (err,) = [shown(e.value) for e in at.sidebar.error]
    assert str(app_env / "db" / "demo") in err and "already exists" in err


def test_building_from_a_folder_of_takes_selects_the_new_database(app_env, tmp_path, zeggs_files):
    takes = tmp_path / "takes"
    takes.mkdir()
    for f in zeggs_files:
        (takes / f.name).symlink_to(f)
    out = tmp_path / "built"
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    at.sidebar.text_input(key="_gk.build_folder").input(str(takes))
    at.sidebar.text_input(key="_gk.build_out").input(str(out))
    at.sidebar.button(key="_gk.build_go").click().run()
    assert not at.exception and not _error_texts(at)
    assert (out / "database.json").is_file()
    assert any(str(out) in shown(s.value) for s in at.sidebar.success)
    assert at.session_state["gk.database"] == str(out.resolve())
    assert not any(DEMO_LABEL in shown(w.value) for w in at.main.warning)  # recorded motion: no "generated" flag
    assert any(c.value.endswith("· 1 take") for c in at.sidebar.caption)


def test_fresh_machine_builds_the_demo_database(tmp_path, monkeypatch):
    home = tmp_path / "empty_home"
    monkeypatch.setenv("GESTUREKIT_HOME", str(home))
    monkeypatch.setenv("GESTUREKIT_DEMO_MINUTES", "0.5")
    monkeypatch.chdir(tmp_path)
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    assert not at.exception and not _error_texts(at)
    assert (home / "db" / "demo" / "database.json").is_file()
    (bar,) = at.get("progress")
    assert bar.proto.value == 100
    db = MatchingDatabase.load(home / "db" / "demo")
    assert db.meta["build"]["source"] == "demo (seed 0, 0.5 min)"
    assert any(DEMO_LABEL in shown(w.value) for w in at.main.warning)


def test_an_invalid_demo_size_is_reported(tmp_path, monkeypatch):
    monkeypatch.setenv("GESTUREKIT_HOME", str(tmp_path / "empty_home"))
    monkeypatch.setenv("GESTUREKIT_DEMO_MINUTES", "lots")
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    assert not at.exception
    (err,) = _error_texts(at)
    assert "GESTUREKIT_DEMO_MINUTES" in err and "'lots'" in err
    assert not (tmp_path / "empty_home" / "db" / "demo").exists()


def test_an_unreadable_demo_database_can_be_rebuilt(tmp_path, monkeypatch):
    home = tmp_path / "home"
    (home / "db" / "demo").mkdir(parents=True)
    (home / "db" / "demo" / "database.json").write_text("{ not json", encoding="utf-8")
    monkeypatch.setenv("GESTUREKIT_HOME", str(home))
    monkeypatch.setenv("GESTUREKIT_DEMO_MINUTES", "0.5")
    monkeypatch.chdir(tmp_path)
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    assert not at.exception
    (err,) = _error_texts(at)
    assert str(home / "db" / "demo") in err and "not valid JSON" in err
    at.button(key="_gk.rebuild_demo").click().run()
    assert not at.exception and not _error_texts(at)
    assert MatchingDatabase.load(home / "db" / "demo").n_clips > 0
    assert any(DEMO_LABEL in shown(w.value) for w in at.main.warning)


def test_building_with_worker_processes_gives_the_database_of_one(app_env, tmp_path, zeggs_files):
    """The sidebar's worker processes read the takes; the database is the one a single process builds
    (also while the app's own threads run searches, which hold BLAS to one thread)."""
    takes = tmp_path / "takes"
    takes.mkdir()
    for stem in ("a", "b"):
        for f in zeggs_files:
            (takes / f"{stem}{f.suffix}").symlink_to(f)
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    for workers, out in ((2, tmp_path / "two"), (1, tmp_path / "one")):
        at.sidebar.text_input(key="_gk.build_folder").input(str(takes))
        at.sidebar.text_input(key="_gk.build_out").input(str(out))
        at.sidebar.number_input(key="_gk.build_workers").set_value(workers)
        at.sidebar.button(key="_gk.build_go").click().run()
        assert not at.exception and not _error_texts(at)
    for name in ("F.npy", "P.npy", "G.npy", "A.npy", "stats.npz", "audio.npy"):
        assert (tmp_path / "two" / name).read_bytes() == (tmp_path / "one" / name).read_bytes(), name
