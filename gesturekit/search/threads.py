"""Thread and BLAS control of the fast search.

The search runs its own few threads; numpy's BLAS and torch are held to one
thread each while it runs (:func:`single_threaded_blas`), and a batch's matrix
product goes to the routine that handles its tall, thin shape best
(:func:`matrix_product`).
"""

from __future__ import annotations

import contextlib
import functools
import os
import threading
import warnings
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

import numpy as np

from .._arguments import checks_arguments
from .._optional import loaded, optional

__all__ = ["in_parts", "matrix_product", "single_threaded_blas", "worker_count"]

R = TypeVar("R")


@checks_arguments
def worker_count() -> int:
    """Threads a search runs: one per core this process may use, at most 8."""
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    return min(cpus, 8)


@checks_arguments
def in_parts(n: int, workers: int, fn: Callable[[int, int], R]) -> list[R]:
    """``fn(a, b)`` for ``min(workers, n)`` (at least one) contiguous ranges ``a .. b - 1`` that
    cover ``0 .. n - 1``, each on a thread of its own when there are several.

    Returns
    -------
    list
        The results, in the ranges' order.
    """
    cuts = np.linspace(0, n, max(1, min(workers, n)) + 1).astype(int)
    parts = [(int(a), int(b)) for a, b in zip(cuts[:-1], cuts[1:])]
    if len(parts) == 1:
        return [fn(*parts[0])]
    with ThreadPoolExecutor(len(parts)) as pool:
        return list(pool.map(lambda ab: fn(*ab), parts))


_WARNINGS_LOCK = threading.Lock()


#: ``product(rows, W, out)``: writes ``rows @ W.T`` into ``out`` (see :func:`matrix_product`).
MatrixProduct = Callable[[np.ndarray, np.ndarray, np.ndarray], None]


def _numpy_product(rows: np.ndarray, W: np.ndarray, out: np.ndarray) -> None:
    np.matmul(rows, W.T, out=out)


@checks_arguments
def matrix_product(n_queries: int) -> MatrixProduct:
    """``out[:] = rows @ W.T`` for float32 arrays; the fastest routine for the shape on a CPU.

    ``rows`` (c, L, D) may be a strided view (the first ``L`` starts of ``c`` clips);
    ``W`` is (B, D), ``out`` a C-contiguous (c, L, B).

    One query (or no torch): numpy's BLAS, single-threaded while a search runs (see
    :func:`single_threaded_blas`; the search shares the rows out to its own threads).
    Several queries: torch's matrix product (MKL, one thread), which handles this
    tall, thin shape far better than numpy's BLAS, when torch is installed. The
    product is memory-bound: more threads per product would not read faster, and
    BLAS's idle threads keep spinning and slow down the work that follows.
    """
    if n_queries <= 1:
        return _numpy_product
    torch = optional("torch")  # the refiner's extra, heavy: only for batches
    if torch is None:
        return _numpy_product
    # the error bound assumes true float32 products: torch may be set to use bfloat16/TF32
    if torch.get_float32_matmul_precision() != "highest":
        return _numpy_product

    def product(rows: np.ndarray, W: np.ndarray, out: np.ndarray) -> None:
        if rows.flags.writeable:
            a = torch.from_numpy(rows)
        else:  # a read-only (memory-mapped) database is only read here
            # catch_warnings swaps process-wide state: the search's own threads take turns
            with _WARNINGS_LOCK, warnings.catch_warnings():
                warnings.filterwarnings("ignore", message=".*not writable.*", category=UserWarning)
                a = torch.from_numpy(rows)
        torch.matmul(a, torch.from_numpy(np.ascontiguousarray(W.T)), out=torch.from_numpy(out))

    return product


@functools.cache
def _blas_controller() -> Any:
    """threadpoolctl's controller of the loaded BLAS libraries (None without threadpoolctl)."""
    try:
        from threadpoolctl import ThreadpoolController  # comes with scikit-learn (a librosa dependency)
    except ImportError:  # pragma: no cover
        return None
    return ThreadpoolController()


@contextlib.contextmanager
@checks_arguments
def single_threaded_blas() -> Iterator[None]:
    """numpy's BLAS, and torch when it is loaded, limited to one thread while a search
    runs (the search runs its own threads); restored afterwards."""
    ctl = _blas_controller()
    limiter = None if ctl is None else ctl.limit(limits=1, user_api="blas")
    # not a torch that another thread (the app's refiner warm-up) is still importing
    torch = loaded("torch")
    threads = None if torch is None else torch.get_num_threads()
    if torch is not None:
        torch.set_num_threads(1)
    try:
        yield
    finally:
        if limiter is not None:
            limiter.restore_original_limits()
        if torch is not None and threads is not None:
            torch.set_num_threads(threads)
