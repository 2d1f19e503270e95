"""A trained refiner: load a checkpoint folder and refine k-NN motion of any length.

A refiner folder (written by :func:`gesturekit.refine.train.train_refiner`)::

    config.json       format, model sizes, training options, feature layout, iteration, file hashes
    generator.pt      generator state dict (torch.save; read with weights_only=True)
    critic.pt         critic state dict
    train_state.pt    optimiser and random-generator states, for --resume (optional)
    stats.npz         z-scoring statistics: audio_mean/std (28), motion_mean/std (165)
    loss_log.csv      losses during training, one row per logging interval

Any length is refined without a seam every 64 frames, in one of two ways:
``mode="full"`` (the default) runs the fully convolutional generator over the
whole sequence at once (padded to a multiple of 8 frames), so there are no
windows at all; ``mode="windowed"`` refines 64-frame windows every ``hop``
frames, exactly the input size of training, and cross-fades their outputs with
Hann weights (every frame is a weighted mean of ``64 / hop`` windows, the
weights fading to almost 0 at each window's ends). Away from the ends both
agree closely; the full pass costs about ``64 / hop`` times less.

``keep_below_hz`` (ours; off by default here, 2 Hz by default in synthesis, see
:func:`gesturekit.blend.keep_slow`) keeps the k-NN motion's content slower than
that frequency and takes only the faster content from the generator.
"""

from __future__ import annotations

import hashlib
import os
import zipfile
import zlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from .. import limits
from .._arguments import checks_arguments
from ..blend import keep_slow
from ..errors import ConfigError, DatabaseError, InputFileError
from ..features import LAYOUT
from ..motion import Motion
from ..skeleton import FPS, JOINT_NAMES
from .folder import FORMAT, FORMAT_VERSION, check_layout, describe_training, provenance, read_refiner_config, trained_on
from .model import GENERATOR_STRIDE, Generator, ModelConfig

if TYPE_CHECKING:
    import pandas as pd

    from ..database import MatchingDatabase

__all__ = ["FORMAT", "FORMAT_VERSION", "Refiner", "read_refiner_config", "read_loss_log", "load_state", "file_sha256"]

STATE_FILES = ("generator.pt", "critic.pt", "train_state.pt")


@checks_arguments
def file_sha256(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


@checks_arguments
def load_state(path: str | os.PathLike, name: str, cfg: dict) -> dict:
    """One ``.pt`` file of a refiner folder, checked against the hash in ``config.json``.

    Loaded with ``torch.load(..., weights_only=True)``: tensors and plain containers only.

    Raises
    ------
    InputFileError
        Missing, changed since ``config.json`` was written (an interrupted save), or unreadable.
    """
    path = Path(path)
    f = path / name
    if not f.is_file():
        raise InputFileError(f"{name} is missing; the refiner folder is incomplete", path=path)
    want = cfg.get("files", {}).get(name)
    if want is None or file_sha256(f) != want:
        raise InputFileError(
            f"{name} does not match config.json (a save was interrupted, or the file was changed); "
            "train again or restore the folder",
            path=path,
        )
    try:
        return torch.load(f, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises several types for corrupt or unsafe files
        raise InputFileError(f"{name} cannot be read as a weights-only checkpoint ({exc})", path=path) from None


def read_stats(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """The z-scoring statistics of a refiner folder (``stats.npz``, no pickles)."""
    path = Path(path)
    f = path / "stats.npz"
    if os.path.lexists(f):
        # four vectors of a few hundred numbers: a zip bomb is refused before it is inflated
        limits.check_npz(f, max_bytes=1 << 20, what="stats.npz ", owner=path)
    try:
        with np.load(f, allow_pickle=False) as z:
            stats = {k: np.asarray(z[k], dtype=np.float32) for k in z.files}
    except FileNotFoundError:
        raise InputFileError("stats.npz is missing; the refiner folder is incomplete", path=path) from None
    except (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        # a truncated archive, or object arrays (allow_pickle=False refuses them)
        raise InputFileError(f"stats.npz cannot be read ({exc})", path=path) from None
    for key in ("audio_mean", "audio_std", "motion_mean", "motion_std"):
        if key not in stats:
            raise InputFileError(f"stats.npz lacks {key}", path=path)
        if stats[key].ndim != 1 or not np.isfinite(stats[key]).all():
            raise InputFileError(
                f"stats.npz: {key} must be a vector of finite numbers, found shape {stats[key].shape}", path=path
            )
    return stats


@checks_arguments
def read_loss_log(path: str | os.PathLike) -> pd.DataFrame:
    """The loss log of a refiner folder as a pandas DataFrame (one row per logging interval).

    Columns: iteration, elapsed_s, critic_loss, wasserstein, gradient_penalty,
    generator_loss, generator_adversarial, generator_l1.
    """
    import pandas as pd

    f = Path(path) / "loss_log.csv"
    if not f.is_file():
        raise InputFileError("loss_log.csv is missing", path=path)
    return pd.read_csv(f)


def hann_weights(n: int) -> np.ndarray:
    """Cross-fade weights of one window, ``sin^2(pi (i + 0.5) / n)``, shape (n,), all > 0."""
    return (np.sin(np.pi * (np.arange(n) + 0.5) / n) ** 2).astype(np.float64)


class Refiner:
    """The generator of a trained resynchronisation cGAN, ready to refine motion.

    Parameters
    ----------
    generator : Generator
    stats : dict
        ``audio_mean``, ``audio_std`` (28,), ``motion_mean``, ``motion_std`` (165,).
    config : dict
        The refiner's ``config.json`` content (``layout`` and ``joint_names`` are checked).
    path : path, optional
    device : str or torch.device
    """

    def __init__(
        self,
        generator: Generator,
        *,
        stats: dict,
        config: dict,
        path: str | os.PathLike[str] | None = None,
        device: str | torch.device = "cpu",
    ):
        self.device = torch.device(device)
        self.generator = generator.to(self.device).eval()
        self.stats = {k: np.asarray(v, dtype=np.float32) for k, v in stats.items()}
        self.config = config
        self.path = None if path is None else Path(path)
        self.window = int(generator.config.window)

    # ---- loading ----------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | os.PathLike, *, device: str = "cpu") -> Refiner:
        """Open a refiner folder (weights read with ``torch.load(..., weights_only=True)``).

        Raises
        ------
        InputFileError
            Missing or damaged files.
        DatabaseError
            The refiner was trained on features of another layout than this gesturekit computes.
        """
        path = Path(path)
        cfg = read_refiner_config(path)
        if cfg.get("layout") != LAYOUT.signature() or cfg.get("joint_names") != list(JOINT_NAMES):
            raise DatabaseError(
                "this refiner was trained on another feature layout or skeleton than this gesturekit uses; "
                "train it again on a database built with this version",
                path=path,
            )
        try:
            mcfg = ModelConfig.from_dict(cfg["model"])
        except (KeyError, TypeError, ConfigError) as exc:
            raise InputFileError(f"config.json has no valid model section ({exc})", path=path) from None
        gen = Generator(mcfg)
        state = load_state(path, "generator.pt", cfg)
        try:
            gen.load_state_dict(state)
        except (RuntimeError, TypeError) as exc:
            raise InputFileError(f"generator.pt does not fit the model in config.json ({exc})", path=path) from None
        stats = read_stats(path)
        if any(
            stats[f"{k}_{part}"].shape != (dim,)
            for k, dim in (("audio", mcfg.audio_dim), ("motion", mcfg.motion_dim))
            for part in ("mean", "std")
        ):
            raise InputFileError("stats.npz does not fit the model's channel counts", path=path)
        return cls(gen, stats=stats, config=cfg, path=path, device=device)

    # ---- compatibility ----------------------------------------------------------------------
    def check_database(self, db: MatchingDatabase) -> None:
        """Refuse a database whose features have another layout than the refiner's training data.

        Raises
        ------
        DatabaseError
            Naming the database and the refiner.
        """

        check_layout(self.config, db, where=self.path if self.path is not None else "refiner")

    # ---- refining ---------------------------------------------------------------------------
    def refine(
        self,
        motion: np.ndarray,
        audio: np.ndarray,
        *,
        mode: str = "full",
        hop: int = 16,
        batch: int = 256,
        keep_below_hz: float | None = None,
    ) -> np.ndarray:
        """Refine k-NN motion with the audio of the same frames.

        Parameters
        ----------
        motion : np.ndarray, shape (T, 165) or (T, 55, 3), metres
            The k-NN motion (any T >= 1).
        audio : np.ndarray, shape (T, 28)
            Raw cGAN audio features of the same frames
            (:meth:`MatchingDatabase.query_features` returns them second).
        mode : {"full", "windowed"}
            ``full``: one fully convolutional pass over the whole sequence;
            ``windowed``: 64-frame windows every ``hop`` frames, cross-faded.
        hop : int
            Frames between windows of ``windowed`` (1..64; 16 = each frame seen by 4 windows).
        batch : int
            Windows per generator call (memory).
        keep_below_hz : float or None
            Keep the k-NN motion's content slower than this (Hz), see
            :func:`gesturekit.blend.keep_slow`; None (default): the generator's output
            as it is (the paper).

        Returns
        -------
        np.ndarray, shape (T, 165), float32, metres
        """
        if keep_below_hz is not None and not (np.isfinite(keep_below_hz) and keep_below_hz > 0):
            raise ConfigError(f"keep_below_hz must be a positive frequency in Hz or None, got {keep_below_hz}")
        g = np.asarray(motion, dtype=np.float32)
        if g.ndim == 3:
            g = g.reshape(g.shape[0], -1)
        a = np.asarray(audio, dtype=np.float32)
        D, A = self.generator.config.motion_dim, self.generator.config.audio_dim
        if g.ndim != 2 or g.shape[1] != D or g.shape[0] < 1:
            raise ConfigError(f"motion must have shape (frames >= 1, {D}), got {np.asarray(motion).shape}")
        if a.shape != (g.shape[0], A):
            raise ConfigError(f"audio features must have shape ({g.shape[0]}, {A}) like the motion, got {a.shape}")
        if not (np.isfinite(g).all() and np.isfinite(a).all()):
            raise ConfigError("motion or audio features contain NaN or infinite values")
        gz = (g - self.stats["motion_mean"]) / self.stats["motion_std"]
        az = (a - self.stats["audio_mean"]) / self.stats["audio_std"]
        if mode == "windowed":
            if not 1 <= hop <= self.window:
                raise ConfigError(f"hop must be in 1..{self.window}, got {hop}")
            out = self._windowed(gz, az, hop=int(hop), batch=max(1, int(batch)))
        elif mode == "full":
            out = self._full(gz, az)
        else:
            raise ConfigError(f"mode must be 'windowed' or 'full', got {mode!r}")
        out = (out * self.stats["motion_std"] + self.stats["motion_mean"]).astype(np.float32)
        return out if keep_below_hz is None else keep_slow(out, g, keep_below_hz)

    def refine_motion(self, motion: Motion, audio: np.ndarray, **options: Any) -> Motion:
        """:meth:`refine` for a :class:`~gesturekit.motion.Motion` at 15 fps; returns a Motion."""
        if motion.fps != FPS:
            raise ConfigError(f"the refiner works at {FPS} fps; the motion has {motion.fps} fps")
        return Motion.from_flat(self.refine(motion.flat(), audio, **options), motion.fps, motion.joints)

    def _run(self, az: np.ndarray, gz: np.ndarray) -> np.ndarray:
        with torch.inference_mode():
            y = self.generator(
                torch.from_numpy(np.ascontiguousarray(az)).to(self.device),
                torch.from_numpy(np.ascontiguousarray(gz)).to(self.device),
            )
        return y.float().cpu().numpy()

    def _windowed(self, gz, az, *, hop, batch):
        W = self.window
        T = gz.shape[0]
        # every frame of the input lies under the same number of windows (W / hop when hop divides W)
        front = W - hop
        back = W - hop + (-(T + front - hop)) % hop  # windows end exactly at the padded end
        n_win = (T + front + back - W) // hop + 1
        # edge padding: the ends are refined like the middle, with the motion held still outside
        gp = np.pad(gz, ((front, back), (0, 0)), mode="edge")
        ap = np.pad(az, ((front, back), (0, 0)), mode="edge")
        w = hann_weights(W)
        acc = np.zeros(gp.shape, np.float64)
        wsum = np.zeros(gp.shape[0], np.float64)
        starts = np.arange(n_win) * hop
        offs = np.arange(W)
        for b0 in range(0, n_win, batch):
            s = starts[b0 : b0 + batch]
            idx = s[:, None] + offs[None, :]
            y = self._run(ap[idx], gp[idx])
            for j, s0 in enumerate(s):
                acc[s0 : s0 + W] += w[:, None] * y[j]
                wsum[s0 : s0 + W] += w
        return (acc[front : front + T] / wsum[front : front + T, None]).astype(np.float32)

    def _full(self, gz, az):
        T = gz.shape[0]
        pad = -T % GENERATOR_STRIDE
        if T + pad < self.window:
            pad = self.window - T
        gp = np.pad(gz, ((0, pad), (0, 0)), mode="edge")
        ap = np.pad(az, ((0, pad), (0, 0)), mode="edge")
        return self._run(ap[None], gp[None])[0, :T]

    def provenance(self, db: MatchingDatabase) -> dict | None:
        """What reproduces a result refined for ``db`` (:func:`gesturekit.refine.provenance`); None
        for a refiner not loaded from a folder. Warns when it was trained on another database.
        """
        from ..errors import warn

        if self.path is None:
            return None
        if not trained_on(self.config, db):
            name = db.label or (db.path.name if db.path is not None else "this database")
            warn(
                f"refiner {self.path} was trained on {describe_training(self.config)}, not on {name}: "
                "its output may not suit this database (train one on it with `gesturekit train-refiner --db ...`)"
            )
        return provenance(self.path, self.config)

    # ---- description ------------------------------------------------------------------------
    def describe(self) -> dict:
        """Summary: path, preset, iterations, model sizes, training database."""
        c = self.config
        return {
            "path": None if self.path is None else str(self.path),
            "preset": c.get("preset"),
            "iteration": c.get("iteration"),
            "complete": c.get("complete"),
            "model": c.get("model"),
            "database": c.get("database", {}).get("label") or c.get("database", {}).get("path"),
            "windows": c.get("pairs", {}).get("windows"),
        }
