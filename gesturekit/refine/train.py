"""Training the resynchronisation cGAN (WGAN-GP), with checkpoints, resume and a loss log.

One iteration (:meth:`Trainer.step`) draws a batch of training windows, updates
the critic on real windows against the generator's refinement of their k-NN
motion (Wasserstein loss plus a gradient penalty of weight 100), and every
5th iteration also updates the generator with the adversarial loss plus
0.1 x the L1 distance to its k-NN input. Everything is z-scored: audio with the
database's statistics of the 28 cGAN audio channels, motion with statistics of
the training windows. Adam (betas (0, 0.9)), Xavier initialisation; the
``paper`` preset has the authors' sizes, batch 100 and lr 1e-4
(``docs/METHOD.md``, "Resynchronisation cGAN"), the ``quick`` preset smaller networks,
batch 50 and lr 1e-3 so that it learns in minutes on a CPU.

:func:`train_refiner` does the whole job for a database: training pairs
(:mod:`gesturekit.refine.data`), training, a checkpoint folder written every
``checkpoint_every`` iterations (and when interrupted; each one whole or not at all), ``resume=True`` to go on
from the last checkpoint. Random draws come from one seeded ``torch.Generator``
whose state is checkpointed, so a resumed run ends with the same weights as an
uninterrupted one.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import shutil
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch

from .._arguments import checks_arguments
from .._io import atomic_write
from .._version import __version__
from ..database import MatchingDatabase
from ..errors import ConfigError, DatabaseError, InputFileError
from ..features import LAYOUT
from ..skeleton import JOINT_NAMES
from .config import TrainConfig
from .data import PairsConfig, TrainingPairs, make_training_pairs
from .infer import FORMAT, FORMAT_VERSION, file_sha256, load_state, read_refiner_config, read_stats
from .model import ModelConfig, build_models

__all__ = [
    "TrainConfig",
    "PRESETS",
    "preset",
    "Trainer",
    "gradient_penalty",
    "normalisation_stats",
    "train_refiner",
    "LOG_COLUMNS",
]

#: Motion channels whose spread is below this (metres) are not amplified by the z-scoring.
MOTION_STD_FLOOR = 0.01

LOG_COLUMNS = (
    "iteration",
    "elapsed_s",
    "critic_loss",
    "wasserstein",
    "gradient_penalty",
    "generator_loss",
    "generator_adversarial",
    "generator_l1",
)


@dataclass(frozen=True)
class Preset:
    """A named pair of model sizes and training schedule."""

    model: ModelConfig
    train: TrainConfig
    description: str = ""


PRESETS: dict[str, Preset] = {
    # a quarter of the paper's generator widths and an eighth of its critic's; batches of 50,
    # 1,200 iterations (240 generator updates) at a larger learning rate: minutes on a 2-core CPU
    "quick": Preset(
        model=ModelConfig(generator_channels=(32, 64, 64, 128), critic_channels=(64, 32, 16)),
        train=TrainConfig(iterations=1200, batch_size=50, lr=1e-3, checkpoint_every=200, log_every=10),
        description="small networks, 1,200 iterations of 50 windows: ~5 min on a free 2-core CPU",
    ),
    # the paper's sizes; 20,000 generator updates (the paper states no schedule length): for a GPU
    "paper": Preset(
        model=ModelConfig(),
        train=TrainConfig(iterations=100_000, checkpoint_every=2000, log_every=50),
        description="the paper's network sizes, 100,000 iterations: hours on a GPU",
    ),
}


@checks_arguments
def preset(name: str) -> Preset:
    """A training preset by name (``quick`` or ``paper``)."""
    if name not in PRESETS:
        raise ConfigError(f"unknown refiner preset {name!r}; choose one of {', '.join(PRESETS)}")
    return PRESETS[name]


@checks_arguments
def gradient_penalty(
    critic: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
    audio: torch.Tensor,
    real: torch.Tensor,
    fake: torch.Tensor,
    *,
    eps: torch.Tensor,
    weight: float = 100.0,
) -> torch.Tensor:
    """WGAN-GP penalty at points between real and generated motion (same audio).

    ``weight * mean_b (|| d critic(audio_b, x) / d x ||_2 - 1)^2`` at
    ``x_b = eps_b real_b + (1 - eps_b) fake_b``; the gradient is taken with
    respect to the motion channels (the audio is the shared condition), its
    norm over all frames and channels of a window.

    Parameters
    ----------
    critic : callable (audio, motion) -> (B,) scores
    audio : torch.Tensor, shape (B, T, A)
    real, fake : torch.Tensor, shape (B, T, D)
    eps : torch.Tensor, shape (B, 1, 1)
        Mixing weights in [0, 1].
    weight : float

    Returns
    -------
    torch.Tensor, scalar, differentiable in the critic's parameters.
    """
    x = (eps * real.detach() + (1.0 - eps) * fake.detach()).requires_grad_(True)
    score = critic(audio, x)
    (grad,) = torch.autograd.grad(score.sum(), x, create_graph=True)
    norm = torch.sqrt(grad.flatten(1).pow(2).sum(dim=1) + 1e-12)
    return weight * (norm - 1.0).pow(2).mean()


@checks_arguments
def normalisation_stats(db: MatchingDatabase, pairs: TrainingPairs) -> dict[str, np.ndarray]:
    """z-scoring statistics: the database's for the audio, the training windows' for the motion.

    Returns
    -------
    dict with ``audio_mean``, ``audio_std`` (28,) and ``motion_mean``, ``motion_std`` (165,), float32;
    motion spreads are floored at :data:`MOTION_STD_FLOOR` metres.
    """
    real = pairs.real.reshape(-1, pairs.real.shape[-1]).astype(np.float64)
    return {
        "audio_mean": np.asarray(db.stats["A_mean"], np.float32),
        "audio_std": np.asarray(db.stats["A_std"], np.float32),
        "motion_mean": real.mean(axis=0).astype(np.float32),
        "motion_std": np.maximum(real.std(axis=0), MOTION_STD_FLOOR).astype(np.float32),
    }


def resolve_device(device: str = "auto") -> torch.device:
    """``auto``: the GPU when torch sees one, else the CPU."""
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        dev = torch.device(device)
    except RuntimeError as exc:
        raise ConfigError(f"unknown device {device!r} ({exc})") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ConfigError("a CUDA device was asked for, but torch sees no GPU")
    return dev


class Trainer:
    """WGAN-GP training of a generator and a critic on z-scored training windows.

    Parameters
    ----------
    model : ModelConfig
    train : TrainConfig
    audio : np.ndarray, shape (W, 64, 28), z-scored
    knn : np.ndarray, shape (W, 64, 165), z-scored
        The generator's motion input.
    real : np.ndarray, shape (W, 64, 165), z-scored
        Ground-truth windows (the critic's "real" examples).
    device : str or torch.device
    """

    def __init__(
        self,
        *,
        model: ModelConfig,
        train: TrainConfig,
        audio: np.ndarray,
        knn: np.ndarray,
        real: np.ndarray,
        device: str | torch.device = "cpu",
    ):
        self.model_config = model
        self.config = train
        self.device = torch.device(device)
        self.generator, self.critic = build_models(model, seed=train.seed)
        self.generator.to(self.device).train()
        self.critic.to(self.device).train()
        self.opt_g = torch.optim.Adam(self.generator.parameters(), lr=train.lr, betas=train.betas)
        self.opt_c = torch.optim.Adam(self.critic.parameters(), lr=train.lr, betas=train.betas)
        # batches and penalty points are drawn on the CPU so a run is the same on any device
        self.rng = torch.Generator().manual_seed(int(train.seed) + 1)
        self.iteration = 0

        def tensor(x, name, channels):
            t = torch.as_tensor(np.ascontiguousarray(x, dtype=np.float32))
            if t.ndim != 3 or t.shape[1] != model.window or t.shape[2] != channels:
                raise ConfigError(f"{name} must have shape (windows, {model.window}, {channels}), got {tuple(t.shape)}")
            return t.to(self.device)

        self.audio = tensor(audio, "audio", model.audio_dim)
        self.knn = tensor(knn, "knn", model.motion_dim)
        self.real = tensor(real, "real", model.motion_dim)
        if not self.audio.shape[0] == self.knn.shape[0] == self.real.shape[0] >= 1:
            raise ConfigError("audio, knn and real must hold the same number (>= 1) of windows")

    @property
    def n_windows(self) -> int:
        return int(self.real.shape[0])

    def step(self) -> dict[str, float]:
        """One iteration: a critic update, and a generator update on every ``generator_every``-th.

        Returns
        -------
        dict
            ``critic_loss``, ``wasserstein`` (mean critic score of real minus generated),
            ``gradient_penalty``; on generator iterations also ``generator_loss``,
            ``generator_adversarial`` and ``generator_l1``.
        """
        cfg = self.config
        self.iteration += 1
        B = cfg.batch_size
        idx = torch.randint(self.n_windows, (B,), generator=self.rng)
        eps = torch.rand(B, 1, 1, generator=self.rng)
        idx, eps = idx.to(self.device), eps.to(self.device)
        a, k, r = self.audio[idx], self.knn[idx], self.real[idx]

        with torch.no_grad():
            fake = self.generator(a, k)
        d_real = self.critic(a, r).mean()
        d_fake = self.critic(a, fake).mean()
        gp = gradient_penalty(self.critic, a, r, fake, eps=eps, weight=cfg.gp_weight)
        c_loss = d_fake - d_real + gp
        self.opt_c.zero_grad(set_to_none=True)
        c_loss.backward()
        self.opt_c.step()
        out = {
            "critic_loss": float(c_loss.detach()),
            "wasserstein": float((d_real - d_fake).detach()),
            "gradient_penalty": float(gp.detach()),
        }

        if self.iteration % cfg.generator_every == 0:
            self.critic.requires_grad_(False)  # the critic is fixed while the generator learns
            try:
                fake = self.generator(a, k)
                adv = -self.critic(a, fake).mean()
                l1 = (fake - k).abs().mean()  # logged per value, whatever the reduction
                l1_term = l1 * (fake[0].numel() if cfg.l1_reduction == "window_sum" else 1)
                g_loss = adv + cfg.l1_weight * l1_term
                self.opt_g.zero_grad(set_to_none=True)
                g_loss.backward()
                self.opt_g.step()
            finally:
                self.critic.requires_grad_(True)
            out.update(
                generator_loss=float(g_loss.detach()),
                generator_adversarial=float(adv.detach()),
                generator_l1=float(l1.detach()),
            )
        return out

    def state_dict(self) -> dict:
        """Optimisers, random-generator state and iteration (the networks are saved apart)."""
        return {
            "iteration": self.iteration,
            "opt_g": self.opt_g.state_dict(),
            "opt_c": self.opt_c.state_dict(),
            "rng": self.rng.get_state(),
        }

    def load_state_dict(self, state: dict, *, generator: dict, critic: dict) -> None:
        """Restore networks, optimisers, random state and iteration from a checkpoint."""
        self.generator.load_state_dict(generator)
        self.critic.load_state_dict(critic)
        self.opt_g.load_state_dict(state["opt_g"])
        self.opt_c.load_state_dict(state["opt_c"])
        self.rng.set_state(state["rng"])
        self.iteration = int(state["iteration"])


# ---- checkpoint folder ---------------------------------------------------------------------------


def _save_torch(path: Path, obj: object) -> str:
    buf = io.BytesIO()
    torch.save(obj, buf)
    data = buf.getvalue()
    atomic_write(path, lambda f: f.write(data), overwrite=True)
    return file_sha256(path)


def _write_log(path: Path, rows: list[dict]) -> None:
    text = io.StringIO()
    w = csv.DictWriter(text, fieldnames=LOG_COLUMNS, lineterminator="\n")
    w.writeheader()
    for row in rows:
        w.writerow(
            {
                k: ("" if row.get(k) is None else (f"{row[k]:.6g}" if isinstance(row[k], float) else row[k]))
                for k in LOG_COLUMNS
            }
        )
    data = text.getvalue().encode("utf-8")
    atomic_write(path, lambda f: f.write(data), overwrite=True)


def _read_log(path: Path, upto: int) -> list[dict]:
    f = path / "loss_log.csv"
    if not f.is_file():
        return []
    rows = []
    with open(f, newline="", encoding="utf-8") as fh:
        for row in csv.DictReader(fh):
            try:
                it = int(row["iteration"])
            except (KeyError, ValueError):
                raise InputFileError("loss_log.csv has a row without an iteration number", path=path) from None
            if it <= upto:
                rows.append(
                    {
                        k: (int(v) if k == "iteration" else (float(v) if v != "" else None))
                        for k, v in row.items()
                        if k in LOG_COLUMNS
                    }
                )
    return rows


def _save_checkpoint(
    out: Path, trainer: Trainer, meta: dict, stats: dict, rows: list[dict], *, train_state: bool
) -> None:
    """Write a whole checkpoint folder beside ``out`` and swap it in: all of it or nothing.

    The files go into ``.NAME.tmp-PID`` (``config.json`` last, with the hashes of
    the state files), which then takes the place of ``out`` in one step
    (:func:`gesturekit.outputs.swap_folder`): a process killed at any moment
    leaves the previous checkpoint complete, and the next run removes the
    temporary folder. The caller holds the output lock of ``out``.
    """
    from ..outputs import beside_name, swap_folder, write_errors

    tmp = out.parent / beside_name(out, f".tmp-{os.getpid()}")
    try:
        with write_errors(out):
            if tmp.exists():
                shutil.rmtree(tmp)
            tmp.mkdir(parents=True)
            files = {
                "generator.pt": _save_torch(tmp / "generator.pt", trainer.generator.state_dict()),
                "critic.pt": _save_torch(tmp / "critic.pt", trainer.critic.state_dict()),
            }
            if train_state:
                files["train_state.pt"] = _save_torch(tmp / "train_state.pt", trainer.state_dict())

            def write_stats(f):
                np.savez(f, **stats)

            atomic_write(tmp / "stats.npz", write_stats)
            _write_log(tmp / "loss_log.csv", rows)
            cfg = dict(meta)
            cfg["iteration"] = trainer.iteration
            cfg["files"] = files
            cfg["resumable"] = train_state
            data = json.dumps(cfg, indent=1).encode("utf-8")
            atomic_write(tmp / "config.json", lambda f: f.write(data))
            swap_folder(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _database_summary(db: MatchingDatabase) -> dict:
    return {
        "path": None if db.path is None else str(db.path),
        "label": db.label,
        "source": db.meta["build"].get("source", ""),
        "takes": len(db.take_names),
        "clips": db.n_clips,
        "overlap_windows": 0 if db.overlap is None else int(db.overlap["clip_take"].shape[0]),
    }


@checks_arguments
def train_refiner(
    db: MatchingDatabase,
    out: str | os.PathLike,
    *,
    preset_name: str = "quick",
    iterations: int | None = None,
    model: ModelConfig | None = None,
    train: TrainConfig | None = None,
    data: PairsConfig | None = None,
    resume: bool = False,
    overwrite: bool = False,
    device: str = "auto",
    keep_train_state: bool = True,
    on_pairs: Callable[[int, int], None] | None = None,
    on_step: Callable[[int, int, dict], None] | None = None,
) -> Path:
    """Train a refiner on a database and write its folder.

    Parameters
    ----------
    db : MatchingDatabase
        Built with an overlapping cut (``--overlap-stride``).
    out : path
        The refiner folder (see :mod:`gesturekit.refine.infer` for its files).
    preset_name : {"quick", "paper"}
        Model sizes and schedule; ``model`` and ``train`` override them.
    iterations : int, optional
        Overrides the preset's number of iterations (with ``resume``: train on up to this many).
    data : PairsConfig, optional
        Seed of k, held-out takes and ranges (default ``PairsConfig()``; with ``resume``,
        the checkpoint's, and a different one given here is an error).
    resume : bool
        Go on from the checkpoint in ``out`` (same model, data and database layout).
    overwrite : bool
        Replace an existing refiner folder (without ``resume``).
    device : str
        ``auto`` (GPU when present), ``cpu``, ``cuda``.
    keep_train_state : bool
        Keep ``train_state.pt`` (optimiser state, needed by ``resume``) in the final folder.
    on_pairs : callable(done, total), optional
        Progress of the training-pair search, in windows.
    on_step : callable(iteration, total, losses), optional
        Called after every iteration.

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    ConfigError
        ``out`` exists (without ``resume`` or ``overwrite``), or ``resume`` with other options.
    OutputError
        ``out`` holds something other than a refiner folder (also with ``overwrite``), is, lies in
        or contains the database's folder, another process is writing it, or writing failed.
    DatabaseError
        The database has no overlapping cut, or another layout than the checkpoint.
    """
    from ..outputs import check_not_input, check_output, clean_stale, output_lock

    out = Path(out)
    # the refiner folder is never the database, inside it or around it (its stats.npz would be replaced)
    check_not_input(out, [db.path])
    if not resume and check_output(out, "refiner", overwrite=True) and not overwrite:
        raise ConfigError("exists already; add --resume to go on training or --force to start again", path=out)
    with output_lock(out):
        # a checkpoint swap cut short by a kill is undone, its temporary folder removed
        clean_stale(out, own=True)
        return _train_locked(
            db,
            out,
            preset_name=preset_name,
            iterations=iterations,
            model=model,
            train=train,
            data=data,
            resume=resume,
            device=device,
            keep_train_state=keep_train_state,
            on_pairs=on_pairs,
            on_step=on_step,
        )


def _train_locked(
    db, out: Path, *, preset_name, iterations, model, train, data, resume, device, keep_train_state, on_pairs, on_step
) -> Path:
    """:func:`train_refiner` once the output is checked and locked."""
    p = preset(preset_name)
    model = model or p.model
    train = train or p.train
    if iterations is not None:
        train = replace(train, iterations=int(iterations))
    dev = resolve_device(device)

    prev = None
    if resume:
        prev = read_refiner_config(out)
        if not prev.get("resumable") or not (out / "train_state.pt").is_file():
            raise InputFileError("this refiner folder holds no training state to resume from", path=out)
        if prev.get("layout") != db.meta.get("layout"):
            raise DatabaseError(
                "the database has another feature layout than the checkpoint was trained on", path=db.path
            )
        was = {k: prev.get("database", {}).get(k) for k in ("takes", "clips", "overlap_windows")}
        now = {k: _database_summary(db)[k] for k in was}
        if was != now:
            raise DatabaseError(
                f"the checkpoint was trained on another database ({was}; this one: {now})", path=db.path
            )
        model = ModelConfig.from_dict(prev["model"])
        old_train = TrainConfig.from_dict(prev["training"])
        train = replace(old_train, iterations=train.iterations if iterations is not None else old_train.iterations)
        old_data = PairsConfig.from_dict(prev["data"])
        data = old_data if data is None else data
        if old_data != data:
            raise ConfigError(
                "the checkpoint was trained with other held-out takes or data options; resume with the same ones",
                path=out,
            )
    else:
        data = PairsConfig() if data is None else data

    t0 = time.perf_counter()
    pairs = make_training_pairs(db, config=data, progress=on_pairs)
    pairs_s = time.perf_counter() - t0
    stats = read_stats(out) if prev is not None else normalisation_stats(db, pairs)

    def z(x, key):
        return (x - stats[f"{key}_mean"]) / stats[f"{key}_std"]

    trainer = Trainer(
        model=model,
        train=train,
        audio=z(pairs.audio, "audio"),
        knn=z(pairs.knn, "motion"),
        real=z(pairs.real, "motion"),
        device=dev,
    )
    rows: list[dict] = []
    elapsed0 = 0.0
    if prev is not None:
        state = load_state(out, "train_state.pt", prev)
        trainer.load_state_dict(
            state, generator=load_state(out, "generator.pt", prev), critic=load_state(out, "critic.pt", prev)
        )
        rows = _read_log(out, trainer.iteration)
        elapsed0 = float(prev.get("time", {}).get("train_s", 0.0))

    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "gesturekit_version": __version__,
        "preset": preset_name if prev is None else prev.get("preset"),
        "model": model.to_dict(),
        "training": train.to_dict(),
        "data": data.to_dict(),
        "layout": db.meta.get("layout", LAYOUT.signature()),
        "joint_names": list(db.meta.get("joint_names", JOINT_NAMES)),
        "database": _database_summary(db),
        "pairs": {"windows": len(pairs), "dropped": pairs.dropped, "search_s": round(pairs_s, 2)},
        "device": str(dev),
        "torch_version": torch.__version__,
    }

    acc: dict[str, list[float]] = {}
    t_start = time.perf_counter()

    def checkpoint(*, final: bool):
        m = dict(meta)
        m["complete"] = trainer.iteration >= train.iterations
        m["time"] = {"train_s": round(elapsed0 + time.perf_counter() - t_start, 2), "search_s": round(pairs_s, 2)}
        _save_checkpoint(out, trainer, m, stats, rows, train_state=keep_train_state or not (final and m["complete"]))

    if trainer.iteration >= train.iterations:
        checkpoint(final=True)
        return out
    with _deferred_interrupt() as interrupted:
        while trainer.iteration < train.iterations:
            losses = trainer.step()
            for key, v in losses.items():
                acc.setdefault(key, []).append(v)
            it = trainer.iteration
            if it % train.log_every == 0 or it == train.iterations:
                row = {"iteration": it, "elapsed_s": round(elapsed0 + time.perf_counter() - t_start, 3)}
                row.update({key: float(np.mean(v)) for key, v in acc.items()})
                rows.append(row)
                acc.clear()
            if on_step is not None:
                on_step(it, train.iterations, losses)
            if interrupted():
                # between two iterations: the checkpoint is exactly where a resumed run goes on
                checkpoint(final=False)
                raise KeyboardInterrupt
            if it % train.checkpoint_every == 0 and it < train.iterations:
                checkpoint(final=False)
    checkpoint(final=True)
    return out


@contextlib.contextmanager
def _deferred_interrupt():
    """Ctrl-C during training is noted and acted on between iterations (main thread only)."""
    flag = {"hit": False}
    if threading.current_thread() is not threading.main_thread():
        yield lambda: False
        return

    def handler(signum, frame):
        if flag["hit"]:  # a second Ctrl-C stops at once
            raise KeyboardInterrupt
        flag["hit"] = True

    old = signal.signal(signal.SIGINT, handler)
    try:
        yield lambda: flag["hit"]
    finally:
        signal.signal(signal.SIGINT, old)
