"""The search's float32 scan on a torch device (a GPU): the pose features kept there, one product a step.

:class:`DeviceRows` keeps the database's pose features on a torch device and gives each step's
estimates ``-2 p.q`` for every start of every clip with one matrix product there, copied back
to the host. The search then reduces them with the same kernels and the same error bound as its
float32 matrix product on the CPU (:mod:`gesturekit.search.index`): the bound holds for any
summation order of true float32 products (blocked, SIMD, FMA, a GPU's), so the decisions, and
the result, are those of :func:`gesturekit.search.reference.search_reference`. Reduced-precision
products (TF32, bfloat16) would break the bound: a torch set to use them is refused.

Used with ``SearchIndex(P, F, valid, device="cuda")``; ``device="cpu"`` runs the same path on
torch's CPU product (the tests hold it equal to the reference on every kind of database).
"""

from __future__ import annotations

import threading
import warnings
from typing import Any

import numpy as np

from .._arguments import checks_arguments
from .._optional import require
from ..errors import ConfigError

__all__ = ["DeviceRows"]

_WARNINGS_LOCK = threading.Lock()


class DeviceRows:
    """A database's pose features on a torch device, for the scan's matrix product.

    Parameters
    ----------
    rows : np.ndarray, shape (M T, D), float32
        The pose features of every start, clip by clip.
    device : str
        A torch device: ``"cuda"``, ``"cuda:1"``, ``"cpu"``, ...

    Raises
    ------
    MissingDependencyError
        torch is not installed.
    ConfigError
        The device is unknown or absent, or torch is set to multiply float32 in reduced precision.
    """

    @checks_arguments
    def __init__(self, rows: np.ndarray, device: str) -> None:
        torch = require("torch", purpose="the search on a torch device")
        try:
            self.device = torch.device(device)
        except (RuntimeError, TypeError) as exc:
            raise ConfigError(f"search device {device!r} is not a torch device ({exc})") from None
        if self.device.type == "cuda" and not torch.cuda.is_available():
            raise ConfigError(f"search device {device!r}: torch sees no CUDA device here")
        _check_precision(torch, self.device)
        self._torch = torch
        with _WARNINGS_LOCK, warnings.catch_warnings():  # a read-only (memory-mapped) database is only read
            warnings.filterwarnings("ignore", message=".*not writable.*", category=UserWarning)
            host = torch.from_numpy(np.ascontiguousarray(rows, dtype=np.float32))
        self.rows = host.to(self.device)  # the same memory on the CPU, a copy on a GPU
        self.shape = tuple(rows.shape)

    def products(self, W: np.ndarray) -> np.ndarray:
        """``rows @ W.T`` on the device, on the host: shape (M T, B) float32.

        Parameters
        ----------
        W : np.ndarray, shape (B, D), float32
            The queries' pose features times -2 (exact), so that the product is ``-2 p.q``.
        """
        torch = self._torch
        _check_precision(torch, self.device)  # the setting may have changed since the rows were placed
        w = torch.from_numpy(np.ascontiguousarray(np.asarray(W, np.float32).T)).to(self.device)
        out = self.rows @ w
        return np.ascontiguousarray(out.cpu().numpy())


def _check_precision(torch: Any, device: Any) -> None:
    """Refuse a torch set to multiply float32 matrices in reduced precision (TF32, bfloat16)."""
    precision = torch.get_float32_matmul_precision()
    tf32 = device.type == "cuda" and bool(torch.backends.cuda.matmul.allow_tf32)
    if precision != "highest" or tf32:
        raise ConfigError(
            "the search's error bound needs true float32 products; torch is set to multiply float32 in "
            f"reduced precision (float32 matmul precision {precision!r}, TF32 {'on' if tf32 else 'off'}): "
            "set torch.set_float32_matmul_precision('highest') and torch.backends.cuda.matmul.allow_tf32 = False"
        )
