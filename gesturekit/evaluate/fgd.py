"""The motion autoencoder of the Fréchet Gesture Distance (FGD, Yoon et al. 2020).

FGD compares the distribution of generated motion with that of real motion in
the latent space of an autoencoder trained to reconstruct real motion. Ours is
a small 1-D convolutional autoencoder over windows of ``window`` frames (32 by
default, about 2 s at 15 fps) of the 165 pose values (55 joints x 3, metres,
z-scored with the database's per-value statistics). The encoder's latent
vector of every window is the feature; FGD is the Fréchet distance between the
Gaussians fitted to the features of the two motions
(:func:`gesturekit.evaluate.metrics.frechet_distance`).

The project trains it on a matching database (``gesturekit train-fgd --db DB
--out MODEL``), leaving any held-out part out. A model is a folder with
``fgd.json`` (format, configuration, layout) and ``weights.pt`` (the state
dict and the normalisation statistics, tensors only), read with
``torch.load(..., weights_only=True)``.
"""

from __future__ import annotations

import contextlib
import json
import os
import pickle
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._arguments import checks_arguments
from .._config import option, option_of
from .._optional import require
from ..errors import ConfigError, InputFileError
from ..features import LAYOUT
from ..limits import read_json
from .metrics import frechet_distance, gaussian_statistics

if TYPE_CHECKING:
    import torch

    from ..database import MatchingDatabase

__all__ = ["FGDConfig", "FGDModel", "train_fgd_model", "load_fgd_model", "fgd"]

_FORMAT = "gesturekit-fgd-autoencoder"
_PURPOSE = "the FGD metric"
_FORMAT_VERSION = 1


@dataclass(frozen=True)
class FGDConfig:
    """How the FGD autoencoder is built and trained; stored with the weights.

    Parameters
    ----------
    window : int
        Frames per window (a multiple of 8, at least 16).
    latent : int
        Size of the latent feature.
    channels : int
        Channels of the first convolution (the second and third use the same).
    steps : int
        Training steps (Adam, mean squared reconstruction error); ``gesturekit train-fgd``'s default.
    batch : int
        Windows per step.
    lr : float
        Learning rate.
    seed : int
        Seed of the initial weights and the window sampling.
    stride : int
        Hop between windows when a motion is embedded (frames).
    """

    window: int = option(32, help="frames per window, a multiple of 8", low=16, step=8, unit="frames")
    latent: int = option(32, help="size of the latent feature", low=1)
    channels: int = option(32, help="channels of the convolutions", low=1)
    steps: int = option(2000, help="training steps", low=1)
    batch: int = option(32, help="windows per step", low=1)
    lr: float = option(1e-3, help="learning rate", low=0.0, low_open=True)
    seed: int = option(0, help="seed", low=0)
    stride: int = option(1, help="hop between windows when a motion is embedded", low=1, unit="frames")

    def __post_init__(self):
        for name in ("window", "latent", "channels", "steps", "batch", "stride"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < option_of(FGDConfig, name).low:
                raise ConfigError(f"FGDConfig.{name} must be a positive integer, got {v!r}")
        if self.window < 16 or self.window % 8:
            raise ConfigError(f"FGDConfig.window must be a multiple of 8 of at least 16 frames, got {self.window}")
        if not self.lr > 0:
            raise ConfigError(f"FGDConfig.lr must be positive, got {self.lr}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise ConfigError(f"FGDConfig.seed must be a non-negative integer, got {self.seed!r}")


@contextlib.contextmanager
def _one_thread():
    """Run torch on one thread, then restore the setting.

    The network is small: a second thread gains little, and when cores are
    shared (tests in parallel, a busy machine) torch's spinning threads slow
    it down many times over.
    """
    torch = require("torch", purpose=_PURPOSE)

    old = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(old)


def _network(config: FGDConfig, dims: int):
    """Encoder and decoder: three stride-2 convolutions down, a linear latent, and back."""
    require("torch", purpose=_PURPOSE)
    import torch.nn as nn

    c, t = config.channels, config.window // 8

    class Encoder(nn.Module):
        def __init__(self):
            super().__init__()
            self.conv = nn.Sequential(
                nn.Conv1d(dims, c, 4, stride=2, padding=1),
                nn.LeakyReLU(0.2),
                nn.Conv1d(c, c, 4, stride=2, padding=1),
                nn.LeakyReLU(0.2),
                nn.Conv1d(c, c, 4, stride=2, padding=1),
                nn.LeakyReLU(0.2),
            )
            self.out = nn.Linear(c * t, config.latent)

        def forward(self, x):  # (batch, dims, window) -> (batch, latent)
            return self.out(self.conv(x).flatten(1))

    class Decoder(nn.Module):
        def __init__(self):
            super().__init__()
            self.inp = nn.Linear(config.latent, c * t)
            self.deconv = nn.Sequential(
                nn.LeakyReLU(0.2),
                nn.ConvTranspose1d(c, c, 4, stride=2, padding=1),
                nn.LeakyReLU(0.2),
                nn.ConvTranspose1d(c, c, 4, stride=2, padding=1),
                nn.LeakyReLU(0.2),
                nn.ConvTranspose1d(c, dims, 4, stride=2, padding=1),
            )

        def forward(self, z):
            return self.deconv(self.inp(z).view(z.shape[0], c, t))

    class Autoencoder(nn.Module):
        def __init__(self):
            super().__init__()
            self.encoder = Encoder()
            self.decoder = Decoder()

        def forward(self, x):
            return self.decoder(self.encoder(x))

    return Autoencoder()


class FGDModel:
    """A trained FGD autoencoder with its normalisation statistics.

    Parameters
    ----------
    config : FGDConfig
    net : torch.nn.Module
        The autoencoder (``encoder`` and ``decoder``).
    mean, std : np.ndarray, shape (165,), float32
        Per-value statistics of the training poses (metres).
    info : dict
        What it was trained on (database, excluded ranges, final loss).
    """

    def __init__(
        self, config: FGDConfig, net: torch.nn.Module, mean: np.ndarray, std: np.ndarray, info: dict | None = None
    ):
        self.config = config
        self.net = net.eval()
        self.mean = np.asarray(mean, np.float32)
        self.std = np.asarray(std, np.float32)
        self.info = dict(info or {})

    def windows(self, positions: np.ndarray) -> np.ndarray:
        """Normalised windows of a motion, shape (n, 165, window), float32 (n = 0 if it is too short)."""
        x = np.asarray(positions, dtype=np.float32)
        if x.ndim == 3:
            x = x.reshape(x.shape[0], -1)
        if x.ndim != 2 or x.shape[1] != self.mean.shape[0]:
            raise ConfigError(f"positions must have shape (frames, 55, 3) or (frames, 165), got {np.shape(positions)}")
        w, s = self.config.window, self.config.stride
        if x.shape[0] < w:
            return np.zeros((0, x.shape[1], w), np.float32)
        z = (x - self.mean) / self.std
        starts = np.arange(0, x.shape[0] - w + 1, s)
        return np.ascontiguousarray(z[starts[:, None] + np.arange(w)[None, :]].transpose(0, 2, 1))

    def embed(self, positions: np.ndarray) -> np.ndarray:
        """Latent features of every window of a motion.

        Parameters
        ----------
        positions : array, shape (frames, 55, 3), metres, at the database's frame rate

        Returns
        -------
        np.ndarray, shape (windows, latent), float64
            Windows every ``config.stride`` frames; none when the motion is shorter than a window.
        """
        torch = require("torch", purpose=_PURPOSE)

        win = self.windows(positions)
        if win.shape[0] == 0:
            return np.zeros((0, self.config.latent))
        encoder = self.net.get_submodule("encoder")
        with torch.no_grad(), _one_thread():
            out = [encoder(torch.from_numpy(win[i : i + 512])).double().numpy() for i in range(0, win.shape[0], 512)]
        return np.concatenate(out)

    def reconstruction_error(self, positions: np.ndarray) -> float:
        """Mean squared reconstruction error of a motion's windows (z-scored units)."""
        torch = require("torch", purpose=_PURPOSE)

        win = self.windows(positions)
        if win.shape[0] == 0:
            return float("nan")
        with torch.no_grad(), _one_thread():
            x = torch.from_numpy(win)
            return float(((self.net(x) - x) ** 2).mean())

    def save(self, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
        """Write the model folder (``fgd.json`` + ``weights.pt``) whole, swapped into place.

        ``overwrite`` replaces only an FGD model folder (see :mod:`gesturekit.outputs`).
        """
        import io

        torch = require("torch", purpose=_PURPOSE)

        from .._io import atomic_write
        from ..outputs import write_folder

        path = Path(path)
        state = {f"net.{k}": v.detach().clone() for k, v in self.net.state_dict().items()}
        state["mean"] = torch.from_numpy(self.mean.copy())
        state["std"] = torch.from_numpy(self.std.copy())
        buf = io.BytesIO()
        torch.save(state, buf)
        meta = {
            "format": _FORMAT,
            "format_version": _FORMAT_VERSION,
            "config": asdict(self.config),
            "motion_dim": int(self.mean.shape[0]),
            "fps": LAYOUT.fps,
            "info": self.info,
        }
        text = json.dumps(meta, indent=1).encode("utf-8")

        def fill(tmp: Path) -> None:
            atomic_write(tmp / "weights.pt", lambda f: f.write(buf.getvalue()))
            atomic_write(tmp / "fgd.json", lambda f: f.write(text))

        return write_folder(path, "fgd", fill, overwrite=overwrite)


@checks_arguments
def load_fgd_model(path: str | os.PathLike) -> FGDModel:
    """Open a model folder written by :meth:`FGDModel.save` (tensors only, ``weights_only=True``).

    Raises
    ------
    InputFileError
        Missing files, another format, or weights that do not fit the configuration.
    """
    torch = require("torch", purpose=_PURPOSE)

    path = Path(path)
    meta_file, weights = path / "fgd.json", path / "weights.pt"
    if not meta_file.is_file() or not weights.is_file():
        raise InputFileError(
            "not an FGD model folder (fgd.json and weights.pt expected; train one with `gesturekit train-fgd`)",
            path=path,
        )
    meta = read_json(meta_file, what="fgd.json ", owner=path)
    if not isinstance(meta, dict):
        raise InputFileError("fgd.json must hold an object", path=path)
    if meta.get("format") != _FORMAT or meta.get("format_version") != _FORMAT_VERSION:
        raise InputFileError("not a gesturekit FGD model of a supported version", path=path)
    if meta.get("fps") != LAYOUT.fps or meta.get("motion_dim") != LAYOUT.motion_dim:
        raise InputFileError(
            f"trained for {meta.get('motion_dim')} values at {meta.get('fps')} fps; "
            f"this gesturekit uses {LAYOUT.motion_dim} at {LAYOUT.fps} fps",
            path=path,
        )
    try:
        config = FGDConfig(**meta["config"])
        state = torch.load(weights, map_location="cpu", weights_only=True)
        net = _network(config, LAYOUT.motion_dim)
        net.load_state_dict({k[4:]: v for k, v in state.items() if k.startswith("net.")})
        mean, std = state["mean"].numpy(), state["std"].numpy()
    except (KeyError, TypeError, RuntimeError, ValueError, ConfigError, pickle.UnpicklingError, EOFError) as exc:
        raise InputFileError(f"the weights do not fit the stored configuration ({exc})", path=path) from None
    return FGDModel(config, net, mean, std, meta.get("info", {}))


def _training_windows(db: MatchingDatabase, exclude: np.ndarray | None, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Clips usable for training (no excluded frame) as (clips, 64, 165) float32, and their count."""
    G = np.asarray(db.G, dtype=np.float32)
    keep = np.ones(G.shape[0], bool) if exclude is None else ~np.asarray(exclude).any(axis=1)
    if not keep.any():
        raise ConfigError("every clip of the database is held out; nothing to train the FGD autoencoder on")
    if G.shape[1] < window:
        raise ConfigError(f"clips of {G.shape[1]} frames are shorter than the FGD window of {window} frames")
    return G[keep], np.flatnonzero(keep)


@checks_arguments
def train_fgd_model(
    db: MatchingDatabase,
    *,
    config: FGDConfig | None = None,
    exclude: np.ndarray | None = None,
    progress: Callable[[int, int, float], None] | None = None,
) -> FGDModel:
    """Train the FGD autoencoder on the poses of a matching database.

    Parameters
    ----------
    db : MatchingDatabase
    config : FGDConfig, optional
    exclude : np.ndarray, shape (M, 64), bool, optional
        Frames held out (``MatchingDatabase.exclusion_mask``); clips touching them are not used.
    progress : callable(step, steps, loss), optional
        Called every 50 steps and at the end.

    Returns
    -------
    FGDModel
        The same database, configuration and seed give the same weights (on one machine and
        torch version; the global random state is left as it was).
    """
    torch = require("torch", purpose=_PURPOSE)

    config = config or FGDConfig()
    clips, used = _training_windows(db, exclude, config.window)
    flat = clips.reshape(-1, clips.shape[-1]).astype(np.float64)
    mean = flat.mean(axis=0).astype(np.float32)
    std = np.maximum(flat.std(axis=0), 1e-3).astype(np.float32)  # floor: constant values map to 0
    data = ((clips - mean) / std).astype(np.float32)  # (clips, 64, 165)
    rng = np.random.default_rng(config.seed)
    span = clips.shape[1] - config.window + 1
    loss_value = float("nan")
    with torch.random.fork_rng(devices=[]), _one_thread():
        torch.manual_seed(config.seed)
        net = _network(config, clips.shape[-1])
        opt = torch.optim.Adam(net.parameters(), lr=config.lr)
        net.train()
        for step in range(1, config.steps + 1):
            ci = rng.integers(data.shape[0], size=config.batch)
            si = rng.integers(span, size=config.batch)
            frames = si[:, None] + np.arange(config.window)[None, :]
            batch = torch.from_numpy(np.ascontiguousarray(data[ci[:, None], frames].transpose(0, 2, 1)))
            loss = torch.mean((net(batch) - batch) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
            loss_value = float(loss.detach())
            if progress is not None and (step % 50 == 0 or step == config.steps):
                progress(step, config.steps, loss_value)
    info = {
        "database": str(db.path) if getattr(db, "path", None) is not None else "in-memory database",
        "clips_used": int(used.size),
        "clips_held_out": int(np.asarray(db.G).shape[0] - used.size),
        "final_loss": loss_value,
    }
    return FGDModel(config, net, mean, std, info)


@checks_arguments
def fgd(model: FGDModel, generated: np.ndarray, reference: np.ndarray) -> float:
    """Fréchet Gesture Distance between a generated and a reference motion.

    Parameters
    ----------
    model : FGDModel
    generated, reference : array, shape (frames, 55, 3), metres
        Each at least ``window + stride`` frames long (two windows).

    Returns
    -------
    float >= 0; 0 for identical motions.
    """
    a, b = model.embed(generated), model.embed(reference)
    if a.shape[0] < 2 or b.shape[0] < 2:
        raise ConfigError(
            f"FGD needs motions of at least {model.config.window + model.config.stride} frames "
            f"(two windows), got {len(np.asarray(generated))} and {len(np.asarray(reference))}"
        )
    return frechet_distance(*gaussian_statistics(a), *gaussian_statistics(b))
