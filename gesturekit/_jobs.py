"""Running independent jobs here, in worker processes, or on a Dask cluster.

The database build (staging takes) and the study stimuli (rendering videos) both
hand out jobs this way; each job's function runs in a fresh interpreter (``spawn``)
or on a Dask worker, so it and its argument must be importable and picklable.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from .errors import ConfigError, GestureKitError, warn

if TYPE_CHECKING:
    from distributed import Client

__all__ = ["SCHEDULER_TIMEOUT", "connect_scheduler", "run_jobs"]

#: How long to try reaching a Dask scheduler before giving up.
SCHEDULER_TIMEOUT = "30s"


def connect_scheduler(address: str, *, purpose: str) -> Client:
    """A client of the Dask scheduler at ``address`` (``tcp://host:8786``).

    Raises
    ------
    MissingDependencyError
        ``distributed`` is not installed (the message says what needs it: ``purpose``).
    ConfigError
        The scheduler cannot be reached; the message names the address.
    """
    from ._optional import require

    distributed = require("distributed", purpose=purpose)
    try:
        return distributed.Client(address, timeout=SCHEDULER_TIMEOUT)
    except (OSError, ValueError, TypeError) as exc:
        raise ConfigError(f"--scheduler {address}: cannot reach a Dask scheduler there ({exc})") from None


#: Set to 1 to run more worker processes than the machine has cores (each costs ~100 MB).
OVER_CORES_ENV = "GESTUREKIT_WORKERS_OVER_CORES"


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system tells it)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def worker_count(workers: int | None) -> int:
    """How many worker processes to start: ``workers``, at most the usable cores unless
    :data:`OVER_CORES_ENV` is set to 1 (a warning names the cap); all cores when None.

    Raises
    ------
    ConfigError
        ``workers`` is not a positive integer.
    """
    cores = usable_cores()
    if workers is None:
        return cores
    try:
        n = int(workers)
    except (TypeError, ValueError):
        n = 0
    if n < 1:
        raise ConfigError(f"workers must be a positive integer, got {workers!r}")
    if n > cores and os.environ.get(OVER_CORES_ENV, "").strip() != "1":
        warn(
            f"--workers {n}: this machine lets gesturekit use {cores} cores, so {cores} worker processes "
            f"run (more would only add memory; set {OVER_CORES_ENV}=1 to start {n})"
        )
        return cores
    return n


def run_jobs(
    fn: Callable[[Any], Any],
    jobs: Sequence[Any],
    *,
    keys: Sequence[str],
    workers: int | None,
    scheduler: str | Client | None,
    on_result: Callable[[Any, Any], None],
    purpose: str,
    died: str,
    initializer: Callable[[], None] | None = None,
) -> None:
    """Run ``fn(job)`` for every job: here (one worker), in worker processes, or on a Dask cluster.

    ``on_result(job, result)`` is called in this process as each job is done (in the order
    they finish). An error of a job stops the run: jobs not started are cancelled, those
    running are let finish, and the error of the first failing job in ``jobs``' order is
    raised here. Worker processes start jobs in that order, so it is the error one process
    gives.

    Parameters
    ----------
    fn : callable
        The work of one job; importable (it runs in fresh interpreters).
    jobs : sequence
        Picklable arguments of ``fn``.
    keys : sequence of str
        A unique name per job (Dask's task keys).
    workers : int or None
        Worker processes (None: all cores); 1 runs the jobs in this process.
    scheduler : str, distributed.Client or None
        The address of a Dask scheduler or a client; then ``workers`` is not used.
    purpose : str
        What the cluster is for, in the message when ``distributed`` is missing.
    died : str
        The message when a worker process dies (killed, out of memory).
    initializer : callable, optional
        Run once in each worker process before its first job.

    Raises
    ------
    ConfigError
        ``workers`` is not a positive integer, or the scheduler cannot be reached.
    GestureKitError
        A worker process died.
    """
    if scheduler is not None:
        from ._optional import require

        distributed = require("distributed", purpose=purpose)
        client = connect_scheduler(scheduler, purpose=purpose) if isinstance(scheduler, str) else scheduler
        try:
            futures = client.map(fn, list(jobs), key=list(keys), pure=False)
            by_key = {f.key: j for f, j in zip(futures, jobs, strict=True)}
            for fut in distributed.as_completed(futures):
                on_result(by_key[fut.key], fut.result())  # raises the worker's error here
        finally:
            if client is not scheduler:
                client.close()
        return
    n = worker_count(workers)
    if n == 1 or len(jobs) <= 1:
        for job in jobs:
            on_result(job, fn(job))
        return
    import concurrent.futures as cf
    import multiprocessing

    # fresh interpreters: nothing of the caller's threads or state is inherited
    pool = cf.ProcessPoolExecutor(
        max_workers=min(n, len(jobs)), mp_context=multiprocessing.get_context("spawn"), initializer=initializer
    )
    try:
        pending = {pool.submit(fn, job): i for i, job in enumerate(jobs)}
        failed: list[tuple[int, BaseException]] = []
        for fut in cf.as_completed(pending):
            if fut.cancelled():
                continue
            exc = fut.exception()
            if exc is None:
                on_result(jobs[pending[fut]], fut.result())
                continue
            if not failed:
                for other in pending:
                    other.cancel()  # only those not started yet
            failed.append((pending[fut], exc))
        if failed:
            raise min(failed, key=lambda f: f[0])[1]
    except cf.process.BrokenProcessPool:
        raise GestureKitError(died) from None
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
