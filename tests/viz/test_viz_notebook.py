"""The character viewer in a notebook: the cell's iframe holds the page whole, and the page saves as one file."""

from __future__ import annotations

import html

import numpy as np
import pytest

from gesturekit.errors import ConfigError, GestureKitError
from gesturekit.motion import Motion
from gesturekit.skeleton import N_JOINTS
from gesturekit.viz.notebook import character_view
from gesturekit.viz.viewer import read_viewer_data


def _motion(frames: int = 6, shift: float = 0.0) -> Motion:
    from gesturekit.demo import open_default_database

    db = open_default_database()
    pos = np.asarray(db.poses[2]).reshape(-1, N_JOINTS, 3)[:frames].copy()
    pos[..., 0] += shift
    return Motion(pos, 15.0, db.joint_presence)


def test_the_cell_shows_the_page_whole_in_its_own_document():
    view = character_view([_motion(), _motion(4)], labels=["a", "<b>"], audio=np.zeros(1600, np.float32), height=300)
    cell = view._repr_html_()
    assert cell.startswith("<iframe srcdoc=") and "height:352px" in cell
    page = html.unescape(cell.split('srcdoc="', 1)[1].split('" style=', 1)[0])
    assert page == view.page  # escaping for the attribute loses nothing
    data = read_viewer_data(page)
    assert [m["label"] for m in data["motions"]] == ["a", "<b>"] and data["audio"] is not None
    assert data["audio_sr"] == 16000


def test_save_writes_the_page_once_and_replaces_it_only_when_asked(tmp_path):
    view = character_view(_motion())
    path = view.save(tmp_path / "clip.html")
    assert path.read_text(encoding="utf-8") == view.page
    other = character_view(_motion(3, shift=0.1))
    with pytest.raises(GestureKitError, match="clip.html"):
        other.save(path)
    assert path.read_text(encoding="utf-8") == view.page  # untouched
    other.save(path, overwrite=True)
    assert path.read_text(encoding="utf-8") == other.page
    assert not [p for p in tmp_path.iterdir() if p.name != "clip.html"]  # no temporary file left


@pytest.mark.parametrize("height", [0, -5, 2.5, True, "400"])
def test_a_height_that_is_not_a_positive_whole_number_is_refused(height):
    with pytest.raises(ConfigError, match="height"):
        character_view(_motion(), height=height)
