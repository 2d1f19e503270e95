"""The refiner on the command line and in synthesis: train-refiner, synthesize --refiner."""

import json

import numpy as np
import pytest
import soundfile as sf

from gesturekit.blend import keep_slow
from gesturekit.cli import main
from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.refine.infer import Refiner
from gesturekit.refine.train import TrainConfig, train_refiner
from gesturekit.synthesis import SynthesisConfig, synthesize
from tests.conftest import make_take
from tests.refine_helpers import TINY, _one_torch_thread  # noqa: F401 (an autouse fixture)


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    base = tmp_path_factory.mktemp("cli")
    takes = [make_take(12.0, seed=1, name="a"), make_take(10.0, seed=2, name="b")]
    MatchingDatabase.build(takes, config=BuildConfig(overlap_stride=16)).save(base / "db")
    db = MatchingDatabase.load(base / "db")
    refiner = train_refiner(db, base / "r", model=TINY, train=TrainConfig(iterations=5, batch_size=4), device="cpu")
    speech = make_take(6.0, seed=9).audio
    sf.write(base / "speech.wav", speech, 16000)
    return base, db, refiner, speech


@pytest.mark.slow
def test_synthesize_with_a_refiner_keeps_both_motions(setup):
    base, db, path, speech = setup
    res = synthesize(speech, db=db, refiner=Refiner.load(path))
    plain = synthesize(speech, db=db)
    np.testing.assert_array_equal(res.knn_motion.positions, plain.knn_motion.positions)
    assert res.refined_motion is not None and res.motion is res.refined_motion
    _, a = db.query_features(speech, n_frames=res.n_frames)
    # by default the k-NN motion's content below 2 Hz is kept (SynthesisConfig.refiner_keep_hz)
    generator = Refiner.load(path).refine(plain.knn_motion.flat(), a)
    want = keep_slow(generator, plain.knn_motion.flat(), 2.0)
    np.testing.assert_allclose(res.refined_motion.flat(), want, atol=1e-6)
    assert res.metadata()["refined"]
    # refiner_keep_hz = 0: the refiner's output as it is (the paper)
    raw = synthesize(speech, db=db, config=SynthesisConfig(refiner_keep_hz=0), refiner=Refiner.load(path))
    np.testing.assert_allclose(raw.refined_motion.flat(), generator, atol=1e-6)
    assert not np.allclose(raw.refined_motion.flat(), res.refined_motion.flat(), atol=1e-4)
    assert SynthesisConfig.from_dict(raw.config.to_dict()).refiner_keep_hz == 0.0
    with pytest.raises(Exception, match="refiner_keep_hz"):
        SynthesisConfig(refiner_keep_hz=-1)


def test_synthesize_refuses_a_refiner_of_another_layout(setup):
    base, db, path, speech = setup
    ref = Refiner.load(path)
    ref.config = dict(ref.config, layout=dict(ref.config["layout"], n_mels=64))
    with pytest.raises(Exception, match="another feature layout"):
        synthesize(speech, db=db, refiner=ref)


@pytest.mark.slow
def test_cli_train_refiner_and_synthesize(setup, tmp_path, capsys):
    base, db, _, _ = setup
    out = tmp_path / "ref"
    train = ["train-refiner", "--db", str(base / "db"), "--out", str(out), "--device", "cpu"]
    assert main([*train, "--iterations", "3", "--exclude-range", "a:2-5"]) == 0
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["preset"] == "quick" and cfg["iteration"] == 3
    assert cfg["data"]["exclude_ranges"] == [["a", 2.0, 5.0]]
    assert "training" in capsys.readouterr().out
    # an existing folder needs --resume or --force
    assert main(["train-refiner", "--db", str(base / "db"), "--out", str(out), "--iterations", "3"]) == 2
    assert "--resume" in capsys.readouterr().err
    assert main([*train, "--iterations", "4", "--resume"]) == 0
    assert json.loads((out / "config.json").read_text())["iteration"] == 4
    syn = tmp_path / "syn"
    assert (
        main(
            ["synthesize", str(base / "speech.wav"), "--db", str(base / "db"), "--refiner", str(out), "--out", str(syn)]
        )
        == 0
    )
    with np.load(syn / "speech.npz", allow_pickle=False) as z:
        assert z["refined_positions"].shape == z["knn_positions"].shape == z["positions"].shape
        np.testing.assert_array_equal(z["positions"], z["refined_positions"])
        assert not np.array_equal(z["positions"], z["knn_positions"])
        kept = z["refined_positions"]
        assert json.loads(str(z["config"]))["synthesis"]["refiner_keep_hz"] == 2.0
    # --refiner-keep-hz 0: the refiner's output as it is
    assert (
        main(
            [
                "synthesize",
                str(base / "speech.wav"),
                "--db",
                str(base / "db"),
                "--refiner",
                str(out),
                "--refiner-keep-hz",
                "0",
                "--out",
                str(tmp_path / "raw"),
            ]
        )
        == 0
    )
    with np.load(tmp_path / "raw" / "speech.npz", allow_pickle=False) as z:
        assert json.loads(str(z["config"]))["synthesis"]["refiner_keep_hz"] == 0.0
        np.testing.assert_array_equal(z["knn_positions"], np.load(syn / "speech.npz")["knn_positions"])
        assert np.abs(z["refined_positions"] - z["knn_positions"]).mean() > np.abs(kept - z["knn_positions"]).mean()


def test_cli_errors(setup, tmp_path, capsys):
    base, _, _, _ = setup
    assert main(["train-refiner", "--out", str(tmp_path / "x")]) == 2
    assert "--db" in capsys.readouterr().err
    assert (
        main(
            [
                "synthesize",
                str(base / "speech.wav"),
                "--db",
                str(base / "db"),
                "--refiner",
                str(tmp_path / "missing"),
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 2
    )
    assert "no refiner folder" in capsys.readouterr().err
    plain = tmp_path / "plain"
    MatchingDatabase.build([make_take(6.0, seed=3, name="p")], config=BuildConfig(store_audio=False)).save(plain)
    assert main(["train-refiner", "--db", str(plain), "--out", str(tmp_path / "y"), "--iterations", "1"]) == 2
    assert "overlap-stride" in capsys.readouterr().err


def test_exclusion_config_reaches_the_held_out_synthesis(setup):
    # the held-out evaluation recipe: train without a stretch, synthesise it with the same exclusion
    base, db, path, _ = setup
    audio = np.asarray(make_take(12.0, seed=1).audio)[2 * 16000 : 5 * 16000]
    res = synthesize(
        audio, db=db, config=SynthesisConfig(exclude_ranges=(("a", 2.0, 5.0),)), refiner=Refiner.load(path)
    )
    t = db.clip_start[res.search.frames[:, 0]] + res.search.frames[:, 1]
    held = (db.clip_take[res.search.frames[:, 0]] == 0) & (t >= 30) & (t < 75)
    assert not held.any() and res.refined_motion.n_frames == res.n_frames
