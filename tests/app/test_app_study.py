"""The Study page (the researcher's view of a running study), run headless with Streamlit's AppTest.

The study is the 2-speech x 3-system one of ``tests/study_helpers.py`` with a design (rating and
pairwise pages, two attention checks); its participants answer through the response store as the
participant server keeps them (:func:`tests.study_helpers.take_part`).
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import pytest
from streamlit import config as st_config
from streamlit.testing.v1 import AppTest

from gesturekit.app import HOME
from gesturekit.study.design import init_study
from gesturekit.study.store import open_store
from tests.conftest import shown
from tests.study_helpers import STUDY_SYSTEMS, study_folder, take_part, tiny_study  # noqa: F401  (fixtures)
from tests.waits import APP_RUN_S

pytestmark = pytest.mark.slow  # each module builds its demo database (demo_home) and runs pages in AppTest

PAGE = "views/6_Study.py"
TIMEOUT = APP_RUN_S  # a script run's deadline, which ends a hang (tests/waits.py)
PASSWORD = "researcher-pw"


@contextlib.contextmanager
def listening_on(address: str | None):
    """Streamlit's ``server.address`` for the block (the page asks for the password unless it is local)."""
    before = st_config.get_option("server.address")
    st_config.set_option("server.address", address)
    try:
        yield
    finally:
        st_config.set_option("server.address", before)


def _page(folder: Path) -> AppTest:
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    assert not at.exception
    at.switch_page(PAGE).run()
    assert not at.exception, at.exception
    at.text_input(key="_w.studyrun.folder").set_value(str(folder)).run()
    assert not at.exception, at.exception
    return at


def _metrics(at: AppTest) -> dict[str, str]:
    return {m.label: m.value for m in at.metric}


#: A column that tells each of the page's tables apart (AppTest's tables carry no widget key).
TABLES = {
    "participants": "prolific_pid",
    "per_stimulus": "raters",
    "per_condition": "ratings",
    "per_pair": "system_left",
    "summary": "mean_lo",
    "bradley_terry": "elo",
}


def _table(at: AppTest, name: str):
    """The frame of the page's table ``name`` (of :data:`TABLES`)."""
    found = [d.value for d in at.dataframe if TABLES[name] in d.value.columns]
    assert len(found) == 1, f"{len(found)} tables {name!r} among {[list(d.value.columns) for d in at.dataframe]}"
    return found[0]


def _errors(at: AppTest) -> list[str]:
    return [shown(e.value) for e in at.error]


@pytest.fixture
def running(study_folder):  # noqa: F811
    """The study with 3 participants finished, 1 ended by the checks and 1 still at the audio check."""
    design = init_study(study_folder, pairwise=True, attention=2)
    store = open_store(None, study_folder)
    try:
        tokens = [take_part(store, design, pid=f"ok{i}") for i in range(3)]
        tokens.append(take_part(store, design, attentive=False, pid="careless"))
        tokens.append(take_part(store, design, pages=1, pid="slow"))
    finally:
        store.close()
    return study_folder, tokens


def test_the_page_shows_who_took_part_the_counts_the_analysis_and_csv_downloads(app_env, running):
    folder, tokens = running
    with listening_on("127.0.0.1"):
        at = _page(folder)
    assert not _errors(at)
    assert _metrics(at) == {"Started": "5", "Finished": "3", "Failed checks": "1", "Active": "1"}
    people = _table(at, "participants").set_index("prolific_pid")
    assert people.loc["careless", "status"] == "failed_checks" and people.loc["careless", "failed_checks"] == 2
    assert people.loc["slow", "status"] == "active"
    # every stimulus was rated by the three who finished; the careless one's ratings are left out
    per_stimulus = _table(at, "per_stimulus")
    assert len(per_stimulus) == 6 and (per_stimulus["raters"] == 3).all()
    per_condition = _table(at, "per_condition").set_index("system")["ratings"]
    assert per_condition.to_dict() == {s: 6 for s in STUDY_SYSTEMS}  # 3 raters x 2 speeches
    pairs = _table(at, "per_pair")
    assert pairs["answers"].sum() == 3 * 6  # each finisher: 3 pairs per speech
    summary = _table(at, "summary")
    overall = summary[summary["prompt"] == "all"]
    assert overall["system"].tolist() == ["knn", "audio-only", "random"]
    assert overall["mean"].tolist() == [6.0, 4.0, 2.0]
    assert set(_table(at, "bradley_terry")["system"]) == set(STUDY_SYSTEMS)
    # the flow: 5 started; the careless one excluded; the slow one has answered the instructions only
    flow = "\n".join(m.value for m in at.markdown)
    for line in ("Started: 5", "Excluded: 1", "No rating or pairwise answer: 1", "Analysed: 3 (finished: 3)"):
        assert line in flow, line
    assert "3 participants analysed" in "\n".join(c.value for c in at.caption)
    assert len(at.get("plotly_chart")) == 2  # the box plots and the significance matrix
    labels = {b.proto.label for b in at.get("download_button")}
    assert {f"{n}.csv" for n in ("participants", "responses", "ratings", "pairwise", "exclusions", "summary")} <= labels
    assert "token" not in people.columns  # a participant's key to their session stays in the CSV only


def test_served_to_others_the_page_asks_for_the_password(app_env, study_folder):  # noqa: F811
    design = init_study(study_folder, pairwise=True, attention=2, password=PASSWORD)
    store = open_store(None, study_folder)
    try:
        take_part(store, design, pid="ok")
    finally:
        store.close()
    with listening_on("0.0.0.0"):
        at = _page(study_folder)
        assert not at.metric and not at.dataframe  # nothing of the study before the password
        assert any("researcher password" in shown(i.value) for i in at.info)
        at.text_input(key="studyrun.password").set_value("not-the-password").run()
        assert _errors(at) == ["Wrong password."] and not at.metric and not at.dataframe
        at.text_input(key="studyrun.password").set_value(PASSWORD).run()
        assert not at.exception and not _errors(at)
        assert _metrics(at)["Finished"] == "1"
    with listening_on("127.0.0.1"):  # on the researcher's own machine: no password asked
        at = _page(study_folder)
        assert _metrics(at)["Finished"] == "1"
        assert not [t for t in at.text_input if t.key == "studyrun.password"]


def test_served_a_study_without_a_password_is_not_shown(app_env, running):
    folder, _ = running
    with listening_on(None):  # Streamlit's default: every interface
        at = _page(folder)
    assert not at.exception
    assert any("no researcher password" in e for e in _errors(at))
    assert not at.metric and not at.dataframe


def test_errors_are_messages(app_env, study_folder, tmp_path):  # noqa: F811
    with listening_on("127.0.0.1"):
        at = _page(tmp_path.parent / "elsewhere")
        assert any("outside the allowed folders" in e for e in _errors(at))
        at = _page(study_folder)  # stimuli without a design yet: the page offers to make it
        assert not _errors(at) and any(b.label == "Write the design" for b in at.button)
        at = _page(study_folder.parent)  # not a stimuli folder
        assert any("manifest.csv" in e for e in _errors(at))
        at = _page(study_folder.parent / "not_made_yet")  # the first visit: no study yet is no error
        assert not _errors(at) and any("No study in this folder yet" in shown(i.value) for i in at.info)
        init_study(study_folder, attention=0)
        at = _page(study_folder)  # a design, no participant yet
        assert not _errors(at) and any("No participant has started" in shown(i.value) for i in at.info)
        design = json.loads((study_folder / "design.json").read_text(encoding="utf-8"))
        design["rating"]["scale"] = "likert12"
        (study_folder / "design.json").write_text(json.dumps(design), encoding="utf-8")
        at = _page(study_folder)
        assert not at.exception
        assert any(str(study_folder / "design.json") in e and "scale" in e for e in _errors(at))


def test_the_design_is_made_on_the_page(app_env, study_folder):  # noqa: F811
    """A stimuli folder without a design: the page's form writes it as ``gesturekit study init`` does."""
    from gesturekit.study.design import load_design, verify_password

    with listening_on("127.0.0.1"):
        at = _page(study_folder)
        at.radio[0].set_value("slider100")
        next(c for c in at.checkbox if c.label.startswith("Pairwise")).check()
        next(n for n in at.number_input if n.label.startswith("Attention")).set_value(1)
        next(t for t in at.text_input if t.label == "Researcher password").set_value("pw-12345678")
        next(b for b in at.button if b.label == "Write the design").click().run()
        assert not at.exception and not _errors(at), _errors(at)
    design = load_design(study_folder)
    assert design.scale == "slider100" and design.pairwise and design.rating
    assert len(design.checks) >= 1
    assert verify_password("pw-12345678", design.password_hash) and not verify_password("other", design.password_hash)
    assert any("No participant has started" in shown(i.value) for i in at.info)
