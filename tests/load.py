"""A busy machine on demand: one busy-loop process per core, for the tests marked ``load``.

The browser tests once failed only when other work kept both cores busy (Streamlit's header shows
its own Stop while a run lasts, and runs last longer then); the ``load`` tests run the same flows
with every core kept busy, so such failures show up on a quiet machine too. They run alone
(``pytest -m load``): beside other tests they would slow those down (see ``conftest.py``).
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import time
from collections.abc import Iterator

#: A busy loop that ends on its own after ``argv[1]`` seconds, should its parent never end it.
_LOOP = "import sys, time\nend = time.monotonic() + float(sys.argv[1])\nwhile time.monotonic() < end:\n    pass\n"


def cores() -> int:
    """The cores this process may run on."""
    return len(os.sched_getaffinity(0))


def _cpu_s(pid: int) -> float:
    """CPU seconds (user and system) process ``pid`` has used, from ``/proc``."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class Busy:
    """The busy loops of :func:`busy_cores`, running."""

    def __init__(self, procs: list[subprocess.Popen]) -> None:
        self.procs = procs
        self.started = time.monotonic()

    def share(self) -> float:
        """The part of a core each loop has had since it began, on average (1.0: a whole core each)."""
        wall = time.monotonic() - self.started
        used = [_cpu_s(p.pid) for p in self.procs if p.poll() is None]
        if len(used) < len(self.procs) or wall <= 0:
            return 0.0  # a loop has ended: the machine was not kept busy throughout
        return sum(used) / len(used) / wall


@contextlib.contextmanager
def busy_cores(n: int | None = None, *, most_s: float = 600.0) -> Iterator[Busy]:
    """Keep ``n`` cores busy (default: all of them) until the block ends.

    Each loop is a Python process spinning at normal priority; the block's end kills them all,
    and each ends on its own after ``most_s`` seconds should this process die first.
    """
    procs: list[subprocess.Popen] = []
    try:
        for _ in range(n or cores()):
            procs.append(
                subprocess.Popen(
                    [sys.executable, "-c", _LOOP, f"{most_s:g}"], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL
                )
            )
        yield Busy(procs)
    finally:
        for p in procs:
            p.kill()
        for p in procs:
            p.wait()
