"""WGAN-GP training of the refiner: penalty, schedule, determinism, learning, checkpoints, resume."""

import csv
import json

import numpy as np
import pytest
import torch
from torch import nn

from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.errors import ConfigError, InputFileError
from gesturekit.refine.infer import Refiner, read_loss_log
from gesturekit.refine.model import ModelConfig
from gesturekit.refine.train import LOG_COLUMNS, PRESETS, TrainConfig, Trainer, gradient_penalty, train_refiner
from tests.conftest import make_take
from tests.refine_helpers import TINY, _one_torch_thread  # noqa: F401 (an autouse fixture)


def tiny_data(n=6, seed=0):
    rng = np.random.default_rng(seed)
    return (
        rng.normal(size=(n, 64, 28)).astype(np.float32),
        rng.normal(size=(n, 64, 165)).astype(np.float32),
        rng.normal(size=(n, 64, 165)).astype(np.float32),
    )


def tiny_trainer(seed=0, **train):
    a, k, r = tiny_data()
    cfg = TrainConfig(batch_size=4, seed=seed, **train)
    return Trainer(model=TINY, train=cfg, audio=a, knn=k, real=r)


# ---- gradient penalty -------------------------------------------------------------------------


class LinearCritic(nn.Module):
    """score = sum(w * motion) + sum(v * audio): its gradient in the motion is w everywhere."""

    def __init__(self, w, v):
        super().__init__()
        self.w, self.v = nn.Parameter(w), nn.Parameter(v)

    def forward(self, audio, motion):
        return (motion * self.w).flatten(1).sum(1) + (audio * self.v).flatten(1).sum(1)


class SquareCritic(nn.Module):
    """score = c * sum(motion^2): its gradient is 2 c motion."""

    def __init__(self, c):
        super().__init__()
        self.c = nn.Parameter(torch.tensor(c))

    def forward(self, audio, motion):
        return self.c * motion.pow(2).flatten(1).sum(1)


def test_gradient_penalty_of_a_linear_critic_by_hand():
    # w has two non-zero entries 0.3 and 0.4: |grad| = 0.5 for every sample, penalty 100 (0.5 - 1)^2 = 25
    w = torch.zeros(1, 8, 3)
    w[0, 0, 0], w[0, 5, 2] = 0.3, 0.4
    critic = LinearCritic(w, torch.ones(1, 8, 2))
    real, fake = torch.randn(3, 8, 3), torch.randn(3, 8, 3)
    gp = gradient_penalty(critic, torch.randn(3, 8, 2), real, fake, eps=torch.rand(3, 1, 1), weight=100.0)
    assert gp.item() == pytest.approx(25.0, rel=1e-5)


def test_gradient_penalty_at_the_interpolated_points_by_hand():
    # one frame, one channel: real 1, fake 3, eps 0.25 -> x = 2.5; grad 2 c x = 2 * 0.5 * 2.5 = 2.5
    # second sample: real 0, fake 0.4, eps 0.5 -> x = 0.2; grad 0.2
    # penalty 10 * mean((2.5 - 1)^2, (0.2 - 1)^2) = 10 * (2.25 + 0.64) / 2 = 14.45
    critic = SquareCritic(0.5)
    real = torch.tensor([1.0, 0.0]).reshape(2, 1, 1)
    fake = torch.tensor([3.0, 0.4]).reshape(2, 1, 1)
    eps = torch.tensor([0.25, 0.5]).reshape(2, 1, 1)
    gp = gradient_penalty(critic, torch.zeros(2, 1, 1), real, fake, eps=eps, weight=10.0)
    assert gp.item() == pytest.approx(14.45, rel=1e-5)
    # differentiable in the critic's parameters: d/dc of 10 mean((2 c x - 1)^2) = 10 mean(2 (2cx - 1) 2x)
    gp.backward()
    want = 10 * ((2 * (2.5 - 1) * 2 * 2.5) + (2 * (0.2 - 1) * 2 * 0.2)) / 2
    assert critic.c.grad.item() == pytest.approx(want, rel=1e-5)


# ---- schedule and determinism ------------------------------------------------------------------


def _params(module):
    return [p.detach().clone() for p in module.parameters()]


def _changed(before, module):
    return any(not torch.equal(a, b) for a, b in zip(before, module.parameters()))


def test_generator_is_updated_on_every_fifth_iteration_only():
    tr = tiny_trainer()
    gen_updates, critic_updates = [], []
    for _ in range(15):
        g0, c0 = _params(tr.generator), _params(tr.critic)
        out = tr.step()
        if _changed(g0, tr.generator):
            gen_updates.append(tr.iteration)
            assert "generator_loss" in out
        else:
            assert "generator_loss" not in out
        if _changed(c0, tr.critic):
            critic_updates.append(tr.iteration)
    assert gen_updates == [5, 10, 15]
    assert critic_updates == list(range(1, 16))


def test_a_training_step_is_deterministic_with_a_seed():
    a, b, c = tiny_trainer(seed=7), tiny_trainer(seed=7), tiny_trainer(seed=8)
    for tr in (a, b, c):
        for _ in range(5):  # includes a generator update
            tr.step()
    for x, y in zip(
        list(a.generator.state_dict().values()) + list(a.critic.state_dict().values()),
        list(b.generator.state_dict().values()) + list(b.critic.state_dict().values()),
    ):
        assert torch.equal(x, y)
    assert not torch.equal(a.generator.enc1[0].weight, c.generator.enc1[0].weight)


@pytest.mark.slow
def test_a_tiny_model_overfits_a_tiny_batch():
    # k-NN input = real motion, so the adversarial and the L1 term agree: output the input.
    # On 4 windows of 16 frames the generator's L1 to its input falls at least 2.5-fold
    # in 300 iterations (60 generator updates; about 3.3-fold in practice).
    rng = np.random.default_rng(0)
    t = np.linspace(0, 2 * np.pi, 16)[None, :, None]
    motion = np.sin(t * rng.uniform(0.5, 2, size=(4, 1, 165)) + rng.uniform(0, 6, size=(4, 1, 165))).astype(np.float32)
    audio = rng.normal(size=(4, 16, 28)).astype(np.float32)
    tr = Trainer(
        model=ModelConfig(window=16, generator_channels=(32, 32, 32, 32), critic_channels=(4, 4, 4)),
        train=TrainConfig(batch_size=4, lr=5e-3, seed=0),
        audio=audio,
        knn=motion,
        real=motion,
    )
    l1 = [tr.step().get("generator_l1") for _ in range(300)]
    l1 = [v for v in l1 if v is not None]
    assert len(l1) == 60
    assert np.mean(l1[-3:]) < np.mean(l1[:3]) / 2.5


def test_training_config_validation():
    with pytest.raises(ConfigError):
        TrainConfig(iterations=0)
    with pytest.raises(ConfigError):
        TrainConfig(betas=(0.0, 1.5))
    assert TrainConfig.from_dict(TrainConfig().to_dict()) == TrainConfig()
    paper = PRESETS["paper"]
    assert paper.model == ModelConfig()
    t = paper.train
    assert (t.batch_size, t.lr, t.betas, t.gp_weight, t.l1_weight, t.generator_every) == (
        100,
        1e-4,
        (0.0, 0.9),
        100.0,
        0.1,
        5,
    )


# ---- the whole job on a tiny database ----------------------------------------------------------


@pytest.fixture(scope="module")
def tiny_db(tmp_path_factory):
    takes = [make_take(14.0, seed=1, name="a"), make_take(12.0, seed=2, name="b")]
    path = tmp_path_factory.mktemp("db") / "tiny"
    MatchingDatabase.build(takes, config=BuildConfig(overlap_stride=16, store_audio=False)).save(path)
    return MatchingDatabase.load(path)


TINY_TRAIN = TrainConfig(iterations=10, batch_size=4, checkpoint_every=4, log_every=2)


def _weights(path):
    return torch.load(path / "generator.pt", weights_only=True)


def test_folder_contents_and_loss_log(tiny_db, tmp_path):
    out = train_refiner(tiny_db, tmp_path / "r", model=TINY, train=TINY_TRAIN, device="cpu")
    names = {p.name for p in out.iterdir()}
    assert {"config.json", "generator.pt", "critic.pt", "train_state.pt", "stats.npz", "loss_log.csv"} <= names
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["iteration"] == 10 and cfg["complete"] and cfg["model"] == TINY.to_dict()
    assert cfg["layout"] == tiny_db.meta["layout"]
    with open(out / "loss_log.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == LOG_COLUMNS
    assert [int(r["iteration"]) for r in rows] == [2, 4, 6, 8, 10]
    log = read_loss_log(out)
    # rows cover iterations 1-2, 3-4, 5-6, 7-8, 9-10: generator updates at 5 and 10 only
    assert list(log["generator_l1"].notna()) == [False, False, True, False, True]
    assert log["critic_loss"].notna().all()
    ref = Refiner.load(out)
    assert ref.refine(np.asarray(tiny_db.G[0]), np.asarray(tiny_db.A[0])).shape == (64, 165)
    # without --resume or --force an existing folder is kept
    with pytest.raises(ConfigError, match="--resume"):
        train_refiner(tiny_db, out, model=TINY, train=TINY_TRAIN, device="cpu")


@pytest.mark.slow
def test_resume_after_interruption_ends_with_the_same_weights(tiny_db, tmp_path):
    straight = train_refiner(tiny_db, tmp_path / "straight", model=TINY, train=TINY_TRAIN, device="cpu")

    def stop_at_7(i, n, losses):
        if i == 7:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train_refiner(tiny_db, tmp_path / "cut", model=TINY, train=TINY_TRAIN, device="cpu", on_step=stop_at_7)
    cfg = json.loads((tmp_path / "cut" / "config.json").read_text())
    assert cfg["iteration"] == 4 and not cfg["complete"]  # the last periodic checkpoint
    resumed = train_refiner(tiny_db, tmp_path / "cut", resume=True, device="cpu")
    a, b = _weights(straight), _weights(resumed)
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    la, lb = read_loss_log(straight).drop(columns="elapsed_s"), read_loss_log(resumed).drop(columns="elapsed_s")
    assert list(lb["iteration"]) == [2, 4, 6, 8, 10]
    assert la.equals(lb)


@pytest.mark.slow
def test_resume_extends_a_finished_run(tiny_db, tmp_path):
    short = train_refiner(tiny_db, tmp_path / "s", model=TINY, train=TINY_TRAIN, iterations=6, device="cpu")
    train_refiner(tiny_db, short, resume=True, iterations=10, device="cpu")
    straight = train_refiner(tiny_db, tmp_path / "t", model=TINY, train=TINY_TRAIN, device="cpu")
    a, b = _weights(short), _weights(straight)
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_a_damaged_checkpoint_is_refused(tiny_db, tmp_path):
    out = train_refiner(tiny_db, tmp_path / "r", model=TINY, train=TINY_TRAIN, device="cpu")
    with open(out / "generator.pt", "ab") as f:
        f.write(b"\0")
    with pytest.raises(InputFileError, match="generator.pt"):
        Refiner.load(out)
    with pytest.raises(InputFileError, match="generator.pt"):
        train_refiner(tiny_db, out, resume=True, iterations=12, device="cpu")


def test_without_train_state_the_folder_is_small_and_not_resumable(tiny_db, tmp_path):
    out = train_refiner(tiny_db, tmp_path / "r", model=TINY, train=TINY_TRAIN, device="cpu", keep_train_state=False)
    assert not (out / "train_state.pt").exists()
    Refiner.load(out)
    with pytest.raises(InputFileError, match="no training state"):
        train_refiner(tiny_db, out, resume=True, iterations=12, device="cpu")
