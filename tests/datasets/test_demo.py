import numpy as np
import pytest

from gesturekit.cli import main
from gesturekit.database import MatchingDatabase
from gesturekit.datasets.synthetic import DEMO_LABEL
from gesturekit.demo import build_demo_database, open_default_database
from gesturekit.errors import DatabaseError, OutputError


@pytest.mark.slow
def test_demo_database_is_labelled_and_deterministic(tmp_path):
    seen = []
    a = build_demo_database(tmp_path / "a", minutes=2.0, progress=lambda d, t: seen.append((d, t)))
    b = build_demo_database(tmp_path / "b", minutes=2.0)
    assert a.label == DEMO_LABEL and "generated" in a.summary_text()
    for k in ("F", "P", "G", "attributes"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))
    assert a.overlap is not None  # the refiner's training cut comes with the demo
    assert seen and seen[-1][0] == pytest.approx(seen[-1][1])  # progress reaches the end
    assert all(x[0] <= y[0] for x, y in zip(seen, seen[1:]))  # and never goes back
    with pytest.raises(OutputError, match="already exists"):
        build_demo_database(tmp_path / "a", minutes=2.0)


def test_default_database_is_built_on_first_open(tmp_path, monkeypatch):
    monkeypatch.setenv("GESTUREKIT_HOME", str(tmp_path / "home"))
    db = open_default_database(minutes=2.0)
    assert db.path == tmp_path / "home" / "db" / "demo"
    assert db.n_clips == MatchingDatabase.load(db.path).n_clips > 0
    with pytest.raises(DatabaseError, match="not been built"):
        monkeypatch.setenv("GESTUREKIT_HOME", str(tmp_path / "other"))
        open_default_database(build_if_missing=False)


def test_cli_builds_demo_at_default_path(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("GESTUREKIT_HOME", str(tmp_path))
    assert main(["build-db", "--demo", "--minutes", "2"]) == 0
    out = capsys.readouterr().out
    assert "generated demo speaker" in out and "takes      1" in out
    assert main(["info"]) == 0
    assert "clips      28 x 64 frames" in capsys.readouterr().out  # 2 min = 1800 frames -> 28 clips
