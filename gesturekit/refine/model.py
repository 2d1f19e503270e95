"""The resynchronisation cGAN's networks: a 1-D U-Net generator and a WGAN critic.

Both take time-first tensors, ``(batch, frames, channels)``, and transpose to
PyTorch's channel-first layout inside (once, at the module boundary).

Generator (``docs/METHOD.md``, "Resynchronisation cGAN")::

    [audio 28 | motion 165] (193) -> enc1 c1 --------------------------------------> dec1 c1 -> 1x1 -> 165
                                      | avgpool 2                                     ^ nearest x2
                                      enc2 c2 ----------------------------> dec2 c2 -'
                                        | avgpool 2                         ^ nearest x2
                                        enc3 c3 ---------------> dec3 c3 --'
                                          | avgpool 2            ^ nearest x2
                                          bottom c4 ------------'

with ``(c1, c2, c3, c4) = (128, 256, 256, 512)`` at the paper's size; every
block is two (Conv1d k=3, BatchNorm, LeakyReLU 0.2). The critic is three such
blocks with InstanceNorm (512, 256, 128 channels), each followed by an average
pool by 2, then a linear layer to one score (no sigmoid: WGAN).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from .._arguments import checks_arguments
from .._config import JsonConfig
from ..errors import ConfigError

__all__ = ["ModelConfig", "Generator", "Critic", "build_models", "xavier_init", "count_parameters"]

#: Frames per training window (the clip length T_match).
WINDOW = 64
#: Down-sampling factor of the generator (three poolings by 2); inputs must be a multiple of it.
GENERATOR_STRIDE = 8


@dataclass(frozen=True)
class ModelConfig(JsonConfig):
    """Sizes of the generator and the critic; saved in a refiner's ``config.json``.

    Parameters
    ----------
    audio_dim : int
        Audio channels per frame (28: 14 MFCC/energy values and their derivatives).
    motion_dim : int
        Motion channels per frame (165 = 55 joints x 3).
    window : int
        Frames per window seen by the critic (64); a multiple of 8.
    generator_channels : (int, int, int, int)
        Channels of the generator's blocks from the top down (paper: 128, 256, 256, 512).
    critic_channels : (int, int, int)
        Channels of the critic's blocks (paper: 512, 256, 128).
    """

    OPTIONS_NAME = "model options"

    audio_dim: int = 28
    motion_dim: int = 165
    window: int = WINDOW
    generator_channels: tuple = (128, 256, 256, 512)
    critic_channels: tuple = (512, 256, 128)

    def __post_init__(self):
        object.__setattr__(self, "generator_channels", tuple(int(c) for c in self.generator_channels))
        object.__setattr__(self, "critic_channels", tuple(int(c) for c in self.critic_channels))
        if len(self.generator_channels) != 4 or min(self.generator_channels) < 1:
            raise ConfigError(f"generator_channels must be 4 positive integers, got {self.generator_channels}")
        if len(self.critic_channels) != 3 or min(self.critic_channels) < 1:
            raise ConfigError(f"critic_channels must be 3 positive integers, got {self.critic_channels}")
        if self.window < GENERATOR_STRIDE or self.window % GENERATOR_STRIDE:
            raise ConfigError(f"window must be a positive multiple of {GENERATOR_STRIDE}, got {self.window}")
        if self.audio_dim < 1 or self.motion_dim < 1:
            raise ConfigError("audio_dim and motion_dim must be positive")


def _double_conv(cin: int, cout: int, norm: Callable[[int], nn.Module]) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv1d(cin, cout, kernel_size=3, padding=1),
        norm(cout),
        nn.LeakyReLU(0.2),
        nn.Conv1d(cout, cout, kernel_size=3, padding=1),
        norm(cout),
        nn.LeakyReLU(0.2),
    )


class Generator(nn.Module):
    """1-D U-Net: (audio, k-NN motion) -> refined motion, all z-scored.

    Fully convolutional: any length that is a multiple of 8 frames is accepted.
    """

    def __init__(self, config: ModelConfig = ModelConfig()):
        super().__init__()
        self.config = config
        c1, c2, c3, c4 = config.generator_channels
        bn = nn.BatchNorm1d
        self.enc1 = _double_conv(config.audio_dim + config.motion_dim, c1, bn)
        self.enc2 = _double_conv(c1, c2, bn)
        self.enc3 = _double_conv(c2, c3, bn)
        self.bottom = _double_conv(c3, c4, bn)
        self.dec3 = _double_conv(c4 + c3, c3, bn)
        self.dec2 = _double_conv(c3 + c2, c2, bn)
        self.dec1 = _double_conv(c2 + c1, c1, bn)
        self.out = nn.Conv1d(c1, config.motion_dim, kernel_size=1)

    def forward(self, audio: torch.Tensor, motion: torch.Tensor) -> torch.Tensor:
        """Refine a batch.

        Parameters
        ----------
        audio : torch.Tensor, shape (B, T, audio_dim)
        motion : torch.Tensor, shape (B, T, motion_dim)
            ``T`` must be a multiple of 8.

        Returns
        -------
        torch.Tensor, shape (B, T, motion_dim)
        """
        if audio.shape[:2] != motion.shape[:2]:
            raise ConfigError(f"audio {tuple(audio.shape)} and motion {tuple(motion.shape)} differ in batch or frames")
        if motion.shape[1] % GENERATOR_STRIDE:
            raise ConfigError(f"the generator takes a multiple of {GENERATOR_STRIDE} frames, got {motion.shape[1]}")
        x = torch.cat([audio, motion], dim=2).transpose(1, 2)
        e1 = self.enc1(x)
        e2 = self.enc2(F.avg_pool1d(e1, 2))
        e3 = self.enc3(F.avg_pool1d(e2, 2))
        b = self.bottom(F.avg_pool1d(e3, 2))
        d3 = self.dec3(torch.cat([F.interpolate(b, scale_factor=2, mode="nearest"), e3], dim=1))
        d2 = self.dec2(torch.cat([F.interpolate(d3, scale_factor=2, mode="nearest"), e2], dim=1))
        d1 = self.dec1(torch.cat([F.interpolate(d2, scale_factor=2, mode="nearest"), e1], dim=1))
        return self.out(d1).transpose(1, 2)


class Critic(nn.Module):
    """WGAN critic: a score per (audio, motion) window; higher means "more like real data"."""

    def __init__(self, config: ModelConfig = ModelConfig()):
        super().__init__()
        self.config = config
        c1, c2, c3 = config.critic_channels
        norm = nn.InstanceNorm1d
        self.blocks = nn.ModuleList(
            [
                _double_conv(config.audio_dim + config.motion_dim, c1, norm),
                _double_conv(c1, c2, norm),
                _double_conv(c2, c3, norm),
            ]
        )
        self.score = nn.Linear(c3 * (config.window // 8), 1)

    def forward(self, audio: torch.Tensor, motion: torch.Tensor) -> torch.Tensor:
        """Scores of a batch of windows.

        Parameters
        ----------
        audio : torch.Tensor, shape (B, window, audio_dim)
        motion : torch.Tensor, shape (B, window, motion_dim)

        Returns
        -------
        torch.Tensor, shape (B,)
        """
        if motion.shape[1] != self.config.window or audio.shape[:2] != motion.shape[:2]:
            raise ConfigError(
                f"the critic takes windows of {self.config.window} frames; got audio {tuple(audio.shape)}, "
                f"motion {tuple(motion.shape)}"
            )
        x = torch.cat([audio, motion], dim=2).transpose(1, 2)
        for block in self.blocks:
            x = F.avg_pool1d(block(x), 2)
        return self.score(x.flatten(1)).squeeze(1)


@checks_arguments
def xavier_init(module: nn.Module, *, generator: torch.Generator | None = None) -> None:
    """Xavier-uniform weights and zero biases for every convolution and linear layer (in place).

    Normalisation layers keep their defaults (scale 1, shift 0). ``generator``
    makes the draw reproducible without touching torch's global seed.
    """
    for m in module.modules():
        if isinstance(m, (nn.Conv1d, nn.Linear)):
            nn.init.xavier_uniform_(m.weight, generator=generator)
            if m.bias is not None:
                nn.init.zeros_(m.bias)


@checks_arguments
def build_models(config: ModelConfig, *, seed: int = 0) -> tuple[Generator, Critic]:
    """A generator and a critic with Xavier initialisation drawn from ``seed``."""
    g = torch.Generator().manual_seed(int(seed))
    gen, critic = Generator(config), Critic(config)
    xavier_init(gen, generator=g)
    xavier_init(critic, generator=g)
    return gen, critic


@checks_arguments
def count_parameters(module: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad)
