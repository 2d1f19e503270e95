"""The FGD autoencoder: training, determinism, saving and loading (tensors only), the distance."""

import json
from fractions import Fraction

import numpy as np
import pytest
import torch

from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.errors import ConfigError, InputFileError
from gesturekit.evaluate.fgd import FGDConfig, fgd, load_fgd_model, train_fgd_model
from tests.conftest import make_take

TINY = FGDConfig(steps=40, channels=8, latent=6, batch=8, window=16, stride=2)


@pytest.fixture(scope="module")
def db():
    takes = [make_take(20.0, seed=s, name=f"t{s}") for s in range(2)]
    return MatchingDatabase.build(takes, config=BuildConfig(store_audio=False))


@pytest.fixture(scope="module")
def model(db):
    return train_fgd_model(db, config=TINY)


@pytest.mark.slow
def test_identical_motion_has_zero_fgd_and_different_motion_more(db, model):
    a = np.asarray(db.G[:3]).reshape(-1, 55, 3)
    b = np.asarray(db.G[-3:]).reshape(-1, 55, 3)
    assert model.embed(a).shape == ((len(a) - 16) // 2 + 1, 6)
    assert fgd(model, a, a) == 0.0
    assert fgd(model, a, b) > 0.0
    assert fgd(model, a, b) == pytest.approx(fgd(model, b, a), rel=1e-6)
    assert fgd(model, a, a + 0.5) > fgd(model, a, a + 0.01)  # further from the data, further in the latent space


def test_training_is_deterministic_and_leaves_the_global_rng_alone(db, model):
    state = torch.random.get_rng_state()
    again = train_fgd_model(db, config=TINY)
    assert torch.equal(state, torch.random.get_rng_state())
    for (k1, v1), (k2, v2) in zip(model.net.state_dict().items(), again.net.state_dict().items()):
        assert k1 == k2 and torch.equal(v1, v2)
    other = train_fgd_model(db, config=FGDConfig(**{**TINY.__dict__, "seed": 1}))
    assert not torch.equal(model.net.state_dict()["encoder.out.weight"], other.net.state_dict()["encoder.out.weight"])


@pytest.mark.slow
def test_training_falls_and_held_out_clips_are_not_used(db):
    losses = []
    exclude = db.exclusion_mask(takes=["t1"])
    m = train_fgd_model(
        db,
        config=FGDConfig(**{**TINY.__dict__, "steps": 150}),
        exclude=exclude,
        progress=lambda i, n, loss: losses.append(loss),
    )
    assert m.info["clips_held_out"] == int((np.asarray(db.clip_take) == 1).sum())
    assert m.info["clips_used"] == int((np.asarray(db.clip_take) == 0).sum())
    assert losses[-1] < 0.7 * losses[0]
    with pytest.raises(ConfigError, match="held out"):
        train_fgd_model(db, config=TINY, exclude=np.ones_like(exclude))


def test_save_and_load_round_trip(db, model, tmp_path):
    model.save(tmp_path / "fgd")
    loaded = load_fgd_model(tmp_path / "fgd")
    a = np.asarray(db.G[:2]).reshape(-1, 55, 3)
    np.testing.assert_array_equal(loaded.embed(a), model.embed(a))
    assert loaded.config == TINY
    with pytest.raises(ConfigError, match="exists"):
        model.save(tmp_path / "fgd")
    # tensors only: the weights open with weights_only=True
    assert set(torch.load(tmp_path / "fgd" / "weights.pt", weights_only=True)) >= {"mean", "std"}


def test_bad_model_folders_are_input_errors(model, tmp_path):
    with pytest.raises(InputFileError, match="train-fgd"):
        load_fgd_model(tmp_path / "missing")
    model.save(tmp_path / "m")
    (tmp_path / "m" / "fgd.json").write_text("{not json")
    with pytest.raises(InputFileError, match="JSON"):
        load_fgd_model(tmp_path / "m")
    model.save(tmp_path / "p")
    torch.save({"mean": Fraction(1, 3)}, tmp_path / "p" / "weights.pt")  # not a tensor: refused unread
    with pytest.raises(InputFileError, match="weights"):
        load_fgd_model(tmp_path / "p")
    meta = json.loads((tmp_path / "p" / "fgd.json").read_text())
    meta["fps"] = 30
    (tmp_path / "p" / "fgd.json").write_text(json.dumps(meta))
    with pytest.raises(InputFileError, match="fps"):
        load_fgd_model(tmp_path / "p")


def test_bad_settings_and_short_motion(model):
    with pytest.raises(ConfigError, match="window"):
        FGDConfig(window=20)
    with pytest.raises(ConfigError, match="steps"):
        FGDConfig(steps=0)
    with pytest.raises(ConfigError, match="two windows"):
        fgd(model, np.zeros((10, 55, 3)), np.zeros((40, 55, 3)))
