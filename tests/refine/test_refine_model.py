"""The refiner's networks: shapes, the paper's structure, initialisation."""

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from torch import nn

from gesturekit.errors import ConfigError
from gesturekit.refine.model import Critic, Generator, ModelConfig, build_models, count_parameters
from tests.refine_helpers import TINY, _one_torch_thread  # noqa: F401 (an autouse fixture)


def test_paper_sizes_are_the_default():
    cfg = ModelConfig()
    assert (cfg.audio_dim, cfg.motion_dim, cfg.window) == (28, 165, 64)
    gen, critic = Generator(cfg), Critic(cfg)
    # generator: 193 channels in, 165 out; blocks 128, 256, 256, 512 from the top down
    assert gen.enc1[0].in_channels == 193 and gen.out.out_channels == 165 and gen.out.kernel_size == (1,)
    assert [b[0].out_channels for b in (gen.enc1, gen.enc2, gen.enc3, gen.bottom)] == [128, 256, 256, 512]
    assert all(isinstance(b[1], nn.BatchNorm1d) and b[0].kernel_size == (3,) for b in (gen.enc1, gen.dec1))
    assert all(isinstance(b[2], nn.LeakyReLU) and b[2].negative_slope == 0.2 for b in (gen.enc1, gen.bottom))
    # critic: InstanceNorm blocks 512, 256, 128 on 28 + 165 channels, a linear score, no sigmoid
    assert critic.blocks[0][0].in_channels == 193
    assert [b[0].out_channels for b in critic.blocks] == [512, 256, 128]
    assert all(isinstance(b[1], nn.InstanceNorm1d) for b in critic.blocks)
    assert critic.score.in_features == 128 * 8 and critic.score.out_features == 1
    assert not any(isinstance(m, nn.Sigmoid) for m in critic.modules())
    assert count_parameters(gen) > 3_000_000


@settings(max_examples=10, deadline=None)
@given(st.integers(1, 4), st.integers(1, 40).map(lambda n: 8 * n))
def test_generator_keeps_batch_and_frames(batch, frames):
    gen, _ = build_models(TINY)
    y = gen.eval()(torch.randn(batch, frames, 28), torch.randn(batch, frames, 165))
    assert y.shape == (batch, frames, 165)


def test_critic_scores_one_value_per_window():
    _, critic = build_models(TINY)
    assert critic(torch.randn(5, 64, 28), torch.randn(5, 64, 165)).shape == (5,)


def test_bad_shapes_are_refused():
    gen, critic = build_models(TINY)
    with pytest.raises(ConfigError, match="multiple of 8"):
        gen(torch.randn(1, 60, 28), torch.randn(1, 60, 165))
    with pytest.raises(ConfigError, match="64 frames"):
        critic(torch.randn(1, 32, 28), torch.randn(1, 32, 165))
    with pytest.raises(ConfigError):
        ModelConfig(window=60)
    with pytest.raises(ConfigError):
        ModelConfig(generator_channels=(4, 8, 8))


def test_xavier_init_is_seeded_and_biases_are_zero():
    g1, c1 = build_models(TINY, seed=3)
    g2, _ = build_models(TINY, seed=3)
    g3, _ = build_models(TINY, seed=4)
    for (n, a), (_, b), _ in zip(g1.state_dict().items(), g2.state_dict().items(), g3.state_dict().items()):
        assert torch.equal(a, b), n
    assert not torch.equal(g1.enc1[0].weight, g3.enc1[0].weight)
    convs = [m for m in list(g1.modules()) + list(c1.modules()) if isinstance(m, (nn.Conv1d, nn.Linear))]
    assert all(torch.count_nonzero(m.bias) == 0 for m in convs)
    # Xavier-uniform bound sqrt(6 / (fan_in + fan_out)) for the first conv (fan = channels x 3)
    w = g1.enc1[0].weight
    bound = (6.0 / (193 * 3 + 4 * 3)) ** 0.5
    assert w.abs().max() <= bound and w.abs().max() > 0.8 * bound


def test_config_round_trip():
    assert ModelConfig.from_dict(TINY.to_dict()) == TINY
    with pytest.raises(ConfigError, match="unknown"):
        ModelConfig.from_dict({"depth": 3})
