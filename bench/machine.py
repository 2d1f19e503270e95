"""The machine a benchmark ran on, in words, for the first line of its report."""

from __future__ import annotations

import os
import platform


def describe_machine(*, accelerator: str | None = None) -> str:
    """Processor, usable cores and memory of this machine, e.g. ``"x86_64, 2 cores, 8 GiB memory"``.

    Parameters
    ----------
    accelerator : str, optional
        Said last, e.g. ``"no GPU used (CPU only)"``.
    """
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    mem = "?"
    try:
        with open("/proc/meminfo") as f:
            kb = int(next(line for line in f if line.startswith("MemTotal")).split()[1])
        mem = f"{kb / 2**20:.0f} GiB"
    except (OSError, StopIteration, ValueError):
        pass
    words = f"{platform.processor() or platform.machine()}, {cores} cores, {mem} memory"
    return words if accelerator is None else f"{words}, {accelerator}"
