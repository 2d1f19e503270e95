"""The search's float32 scan on a torch device (a GPU): the features kept there, each step reduced there.

:class:`DeviceRows` keeps the database's pose and audio features on a torch device. Each step's
estimates ``|p|^2 - 2 p.q`` of every start of every clip come from one matrix product there, and
are reduced there per clip as the float32 scan on the CPU reduces them
(:func:`gesturekit.search.exact.reduce_chunk`): the least estimate, its first start, and whether
another start lies within twice the error bound of it or the least could be an exact zero. The
audio dot product at each clip's least start is made there too. Only per clip values come back,
and the full row of estimates of the few clips left open, which the search settles exactly as
on the CPU. The bounds hold for any summation order of true float32 products (blocked, SIMD,
FMA, a GPU's), so the decisions, and the result, are those of
:func:`gesturekit.search.reference.search_reference`. Reduced-precision products (TF32,
bfloat16) would break the bound: a torch set to use them is refused.

Used with ``SearchIndex(P, F, valid, device="cuda")``; ``device="cpu"`` runs the same path on
torch's CPU (the tests hold it equal to the reference on every kind of database).
"""

from __future__ import annotations

import threading
import time
import warnings
import weakref
from typing import Any

import numpy as np

from .._arguments import checks_arguments
from .._optional import require
from ..errors import ConfigError

__all__ = ["DeviceRows", "open_device"]

_WARNINGS_LOCK = threading.Lock()
_BIASES_KEPT = 4  # distinct admissibility masks kept on the device (a track has a few)


class DeviceRows:
    """A database's pose and audio features on a torch device, for the scan of each step.

    Parameters
    ----------
    rows : np.ndarray, shape (M T, D), float32
        The pose features of every start, clip by clip.
    audio : np.ndarray, shape (M T, A), float32
        The audio features of every start, in the same order.
    clips : int
        ``M``.
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
    def __init__(self, rows: np.ndarray, audio: np.ndarray, clips: int, device: str) -> None:
        torch, self.device = open_device(device)
        self._torch = torch
        self.rows = self._place(rows)  # the same memory on the CPU, a copy on a GPU
        self.audio = self._place(audio)
        M = int(clips)
        self.shape = (M, rows.shape[0] // M, rows.shape[1], audio.shape[1])
        self._biases: list[tuple[weakref.ref[np.ndarray], Any]] = []
        self._lock = threading.Lock()
        #: Seconds spent in :meth:`scan` so far (the device's work and the copies back included).
        self.scan_seconds = 0.0

    def _place(self, host: np.ndarray) -> Any:
        with _WARNINGS_LOCK, warnings.catch_warnings():  # a read-only (memory-mapped) database is only read
            warnings.filterwarnings("ignore", message=".*not writable.*", category=UserWarning)
            t = self._torch.from_numpy(np.ascontiguousarray(host, dtype=np.float32))
        return t.to(self.device)

    def _bias(self, bias: np.ndarray) -> Any:
        """``bias`` (M T,) on the device, kept for the next steps that use the same array."""
        with self._lock:
            for host, there in self._biases:
                if host() is bias:
                    return there
            there = self._place(bias).reshape(self.shape[0], self.shape[1])
            # a weak reference: the search's own cache decides how long the host array lives
            self._biases = [(weakref.ref(bias), there), *self._biases[: _BIASES_KEPT - 1]]
            return there

    def _products(self, W: np.ndarray) -> Any:
        torch = self._torch
        _check_precision(torch, self.device)  # the setting may have changed since the rows were placed
        w = torch.from_numpy(np.ascontiguousarray(np.asarray(W, np.float32).T)).to(self.device)
        return self.rows @ w

    def scan(
        self,
        Q: np.ndarray,
        biases: list[np.ndarray],
        fq: np.ndarray,
        pose_bound: tuple[np.ndarray, float, float],
        audio_sqnorms: np.ndarray,
    ) -> tuple:
        """One step's scan for B queries, reduced per clip on the device: what
        :meth:`SearchIndex._scan <gesturekit.search.index.SearchIndex>` returns.

        Parameters
        ----------
        Q : np.ndarray, shape (B, D), float32
            The queries' pose features.
        biases : list of B arrays, shape (M T,), float32
            ``|p|^2`` where the start is admissible for that query, +inf elsewhere.
        fq : np.ndarray, shape (B, A), float32
            The queries' audio features.
        pose_bound : (clip_max_sqnorm, err_factor, tiny)
            ``clip_max_sqnorm`` (M,) float64 and the two floats of the float32 error bound
            ``err_factor (clip_max_sqnorm + |q|^2) + tiny`` (as :func:`~gesturekit.search.exact.reduce_chunk`).
        audio_sqnorms : np.ndarray, shape (M, T), float64
            ``|a|^2`` of every start's audio feature.

        Returns
        -------
        tuple
            What :meth:`SearchIndex._scan <gesturekit.search.index.SearchIndex>` returns: per query
            and clip the first start of least estimate ``s0`` (B, M), its squared pose distance
            estimate ``d2`` and float32 bound ``err`` (B, M), ``|q|^2`` (B,), the open clips
            with their rows of estimates, and the audio estimates at ``s0`` with their exactness.
        """
        torch = self._torch
        t_start = time.perf_counter()
        M, T = self.shape[:2]
        Q = np.asarray(Q, np.float32)
        B = Q.shape[0]
        q64 = Q.astype(np.float64)
        nq = np.einsum("ij,ij->i", q64, q64)
        f32 = np.ascontiguousarray(fq, dtype=np.float32)
        f64 = f32.astype(np.float64)
        nb = np.einsum("ij,ij->i", f64, f64)
        G = self._products(np.float32(-2.0) * Q).reshape(M, T, B)  # -2 p.q (an exact scaling)
        clip_max, err_factor, tiny = pose_bound
        npmax = np.asarray(clip_max, np.float64)
        npmax_there = torch.from_numpy(npmax).to(self.device)
        f = torch.from_numpy(f32).to(self.device)
        inf32 = torch.tensor(np.inf, dtype=torch.float32, device=self.device)
        every = torch.arange(M, device=self.device)
        audio = self.audio.reshape(M, T, -1)
        there = []
        for j in range(B):
            A = G[:, :, j] + self._bias(biases[j])  # float32, as the bound assumes; +inf where not admissible
            best = torch.amin(A, dim=1)
            s0 = torch.argmin(A, dim=1)  # the first start of least estimate
            err = err_factor * (npmax_there + float(nq[j])) + tiny
            t64 = best.double() + 2.0 * err
            t32 = t64.float()
            t32 = torch.where(t32.double() < t64, torch.nextafter(t32, inf32), t32)  # rounded up
            count = (A <= t32[:, None]).sum(dim=1)
            und = torch.isfinite(best) & ((count > 1) | (best.double() + float(nq[j]) <= err))
            open_ = torch.nonzero(und).flatten()
            dot = (audio[every, s0] * f[j]).sum(dim=1)
            there.append((s0, best, open_, A[open_], dot))
        s0 = np.empty((B, M), np.int64)
        d2 = np.empty((B, M))
        av = np.full((B, M), np.nan)
        inexact = np.zeros((B, M), bool)
        undecided = []
        rows_m = np.arange(M)
        for j, parts in enumerate(there):
            s, best, open_, rows, dot = (x.cpu().numpy() for x in parts)
            s0[j] = s
            d2[j] = best.astype(np.float64) + nq[j]  # +inf stays +inf
            undecided.append((open_.astype(np.int64), np.ascontiguousarray(rows, np.float32)))
            # the audio estimate as the CPU's scan makes it from its float32 product
            hit = np.isfinite(best)
            d = audio_sqnorms[rows_m, s] * nb[j]
            with np.errstate(divide="ignore", invalid="ignore"):
                est = np.where(d == 0.0, 1.0, 1.0 - dot.astype(np.float64) / np.sqrt(d))
            av[j] = np.where(hit, est, np.nan)
            inexact[j] = hit & (d != 0.0)
        err = err_factor * (npmax[None, :] + nq[:, None]) + tiny
        self.scan_seconds += time.perf_counter() - t_start
        return s0, d2, err, nq, undecided, (av, inexact)


@checks_arguments
def open_device(device: str) -> tuple[Any, Any]:
    """torch and the torch device named ``device``, checked as the search needs it.

    Raises
    ------
    MissingDependencyError
        torch is not installed.
    ConfigError
        The name is no torch device, the device is absent (no CUDA device), or torch is set to
        multiply float32 in reduced precision.
    """
    torch = require("torch", purpose="the search on a torch device")
    try:
        there = torch.device(device)
    except (RuntimeError, TypeError) as exc:
        raise ConfigError(f"search device {device!r} is not a torch device ({exc})") from None
    if there.type == "cuda" and not torch.cuda.is_available():
        raise ConfigError(f"search device {device!r}: torch sees no CUDA device here")
    if there.type == "cuda" and there.index is not None and there.index >= torch.cuda.device_count():
        raise ConfigError(f"search device {device!r}: torch sees {torch.cuda.device_count()} CUDA device(s) here")
    _check_precision(torch, there)
    return torch, there


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
