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


@pytest.mark.slow
def test_the_demo_database_holds_one_skeleton_so_its_files_are_exact(tmp_path):
    import warnings

    from gesturekit.bones import bone_length_spread
    from gesturekit.datasets.synthetic import generate_demo_take
    from gesturekit.errors import GestureKitWarning
    from gesturekit.export.result import export_result_bvh, export_result_glb
    from gesturekit.synthesis import SynthesisConfig, synthesize

    db = build_demo_database(tmp_path / "demo", minutes=2.0)
    assert db.skeleton is not None and MatchingDatabase.load(db.path).skeleton is not None
    frames = np.asarray(db.G, np.float32).reshape(-1, 55, 3)
    assert bone_length_spread(frames).max() < 1e-5  # one length per bone, metres
    speech = generate_demo_take(seconds=8.0, seed=5, name="q")[0].audio
    try:
        from gesturekit.refine import open_refiner

        refiners = [None, open_refiner("demo")]
    except ImportError:  # no torch: the k-NN results only
        refiners = [None]
    for refiner in refiners:
        for config in (SynthesisConfig(), SynthesisConfig(blend="none", control="1-6:both_hands=high")):
            res = synthesize(speech, db=db, config=config, refiner=refiner)
            assert res.one_skeleton
            with warnings.catch_warnings():
                warnings.simplefilter("error", GestureKitWarning)  # no "up to ... off the motion"
                bvh = export_result_bvh(res, tmp_path / "r.bvh", overwrite=True)
                glb = export_result_glb(res, tmp_path / "r.glb", overwrite=True)
            assert bvh.max_error < 1e-4 and glb.max_error < 1e-4, (bvh.summary(), glb.summary())
