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


def _busy_s() -> float:
    """CPU seconds every core of the machine has spent busy since boot (``/proc/stat``)."""
    with open("/proc/stat") as f:
        fields = [int(v) for v in f.readline().split()[1:]]
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle and waiting for I/O
    return (sum(fields[:8]) - idle) / os.sysconf("SC_CLK_TCK")


def _tree_cpu_s(root: int) -> float:
    """CPU seconds of process ``root`` and all its descendants, the ended ones it waited for included."""
    parent: dict[int, int] = {}
    total: dict[int, float] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:  # ended meanwhile
            continue
        pid = int(entry)
        parent[pid] = int(fields[1])
        total[pid] = sum(int(v) for v in fields[11:15]) / os.sysconf("SC_CLK_TCK")
    mine = 0.0
    for pid in total:
        p = pid
        while p > 1 and p != root:
            p = parent.get(p, 0)
        if p == root:
            mine += total[pid]
    return mine


class OtherWork:
    """How busy the rest of the machine was while a block ran: the CPU that processes other than
    this one and its descendants (the app's server, the browser) used, as a part of all the cores.

    A timed bound that holds on a quiet machine is checked only where the machine was quiet;
    a test on a busy machine checks what still holds there (CI shares its machine).
    """

    #: Above this part of the machine used by other work, the machine counts as busy.
    BUSY = 0.25

    def __enter__(self) -> OtherWork:
        self._start = (time.monotonic(), _busy_s(), _tree_cpu_s(os.getpid()))
        self.share = 0.0
        return self

    def __exit__(self, *exc: object) -> None:
        wall, busy, mine = (a - b for a, b in zip((time.monotonic(), _busy_s(), _tree_cpu_s(os.getpid())), self._start))
        self.share = max(0.0, busy - mine) / (wall * cores()) if wall > 0 else 0.0

    @property
    def busy(self) -> bool:
        """Whether other work took more than :attr:`BUSY` of the machine."""
        return self.share > self.BUSY
