"""The Study stimuli page, run headless with Streamlit's AppTest."""

import pandas as pd
import pytest
import soundfile as sf
from streamlit.testing.v1 import AppTest

from gesturekit.app import HOME
from gesturekit.datasets.synthetic import generate_demo_take
from tests.conftest import shown
from tests.waits import APP_RUN_S

pytestmark = pytest.mark.slow  # each module builds its demo database (demo_home) and runs pages in AppTest

PAGE = "views/4_Study_stimuli.py"
TIMEOUT = APP_RUN_S  # a script run's deadline, which ends a hang (tests/waits.py)


def _page() -> AppTest:
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    assert not at.exception
    at.switch_page(PAGE).run()
    assert not at.exception, at.exception
    return at


def test_conditions_table_render_and_preview(app_env, tmp_path):
    speech = tmp_path / "speech"
    speech.mkdir()
    take, _ = generate_demo_take(seconds=2.0, seed=3, name="s")
    sf.write(speech / "hello.wav", take.audio[:19200], 16000)  # 1.2 s
    at = _page()
    assert any("Choose speech" in shown(i.value) for i in at.info)
    at.text_input(key="_w.study.folder").set_value(str(speech)).run()
    at.selectbox(key="_w.study.resolution").set_value("320x240")
    at.number_input(key="_w.study.workers").set_value(1)
    at.text_input(key="_w.study.out").set_value(str(tmp_path / "study")).run()
    assert not at.exception, at.exception
    table = next(d.value for d in at.dataframe if "system" in d.value.columns)
    assert sorted(table["system"]) == ["knn", "random"] and set(table["audio"]) == {"hello.wav"}
    at.button(key="study.go").click().run()
    assert not at.exception, at.exception
    assert not [shown(e.value) for e in at.error]
    manifest = pd.read_csv(tmp_path / "study" / "manifest.csv")
    assert sorted(manifest["id"]) == sorted(table["id"])
    assert len(at.get("video")) == 2  # the preview of participant 1's first stimuli
    assert any("stimuli written" in p.proto.text for p in at.get("progress"))


def test_a_missing_folder_is_an_error_message(app_env, tmp_path):
    at = _page()
    at.text_input(key="_w.study.folder").set_value(str(tmp_path / "nowhere")).run()
    assert not at.exception
    assert any("no such folder" in shown(e.value) for e in at.error)


def test_knn_cgan_uses_the_shipped_refiner_and_choices_are_checked_before_the_work(app_env, tmp_path):
    speech = tmp_path / "speech"
    speech.mkdir()
    take, _ = generate_demo_take(seconds=2.0, seed=3, name="s")
    sf.write(speech / "hello.wav", take.audio[:19200], 16000)
    at = _page()
    at.text_input(key="_w.study.folder").set_value(str(speech)).run()
    at.multiselect(key="_w.study.systems").set_value(["knn", "knn+cgan"]).run()
    assert not at.exception, at.exception
    # the demo database's refiner is offered, as on the Synthesize page
    refiner = at.text_input(key="_w.study.refiner").value
    assert refiner and "refiner" in refiner
    assert any(b.key == "study.go" for b in at.button)
    # no refiner: said on the page, in its words, and nothing to start
    at.text_input(key="_w.study.refiner").set_value("").run()
    errors = [shown(e.value) for e in at.error]
    assert any("knn+cgan needs a refiner" in e and "Refiner folder" in e for e in errors), errors
    assert not any("--refiner" in e for e in errors)
    assert not any(b.key == "study.go" for b in at.button)
    at.text_input(key="_w.study.refiner").set_value(str(tmp_path / "nowhere")).run()
    assert any("no refiner" in shown(e.value) for e in at.error)
    assert not any(b.key == "study.go" for b in at.button)
