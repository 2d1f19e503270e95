"""The app's "build from a folder" form reads keypoint takes like build-db: units, axes, bone lengths."""

from __future__ import annotations

from pathlib import Path

import pytest
from streamlit.testing.v1 import AppTest

from gesturekit.app import HOME
from gesturekit.database import MatchingDatabase
from gesturekit.datasets.keypoint_example import write_keypoint_example
from gesturekit.skeleton import DERIVED
from tests.conftest import shown
from tests.waits import APP_RUN_S

pytestmark = pytest.mark.slow  # each module builds its demo database (demo_home) and runs pages in AppTest

TIMEOUT = APP_RUN_S  # a script run's deadline, which ends a hang (tests/waits.py)


def _fill(at: AppTest, folder: Path, out: Path, *, up: str) -> AppTest:
    at.sidebar.text_input(key="_gk.build_folder").input(str(folder))
    at.sidebar.radio(key="_gk.build_naming").set_value("JSON joint map").run()
    at.sidebar.text_input(key="_gk.build_map").input(str(folder / "joint_map.json"))
    at.sidebar.number_input(key="_gk.build_fps").set_value(15.0)
    at.sidebar.selectbox(key="_gk.build_up").set_value(up)
    at.sidebar.checkbox(key="_gk.build_bones").check()
    at.sidebar.text_input(key="_gk.build_out").input(str(out))
    return at.sidebar.button(key="_gk.build_go").click().run()


def test_the_build_form_reads_y_down_keypoints_with_up_and_refuses_them_without(app_env, tmp_path):
    folder = tmp_path / "kp"
    write_keypoint_example(folder, fmt="csv", takes=2, seconds=6.0, seed=1)
    out = tmp_path / "built"
    at = _fill(AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run(), folder, out, up="y (checked)")
    assert not at.exception
    errors = [shown(e.value) for e in at.error]
    assert any("pass --up -y" in e and "take_00.csv" in e for e in errors), errors
    assert not (out / "database.json").exists()

    at = _fill(at, folder, out, up="-y")
    assert not at.exception and not [shown(e.value) for e in at.error]
    db = MatchingDatabase.load(out)
    assert db.joint_presence.names(DERIVED)[:3] == ("spine_mid", "chest", "upper_chest")
    assert "bone lengths normalised" in db.meta["takes"][1]["sources"]["reading"]
    assert any("up -y (given)" in shown(i.value) for i in at.sidebar.info)
