"""The study server under 50 participants at once, then killed with -9 mid-run: SQLite and PostgreSQL.

One local server (``uvicorn`` in its own process, as ``gesturekit study serve`` runs it) on a
study folder of 2 speeches x 3 systems with one attention check and the audio check per
participant (the page sequence of the tests' stand-in design; the videos are random bytes of
``--video-kb`` each, so no rendering is timed). ``--participants`` simulated participants
(httpx AsyncClient, one event loop) go through the study at once: entry URL, each page, every
video of a page fetched whole (a range request from byte 0), each page's answers POSTed.
Printed: entry (all participants arrive in the same instant), page and submit latency p50/p95
(target p95 < 300 ms), the video bytes per second served, and the responses lost (acknowledged
but not in the store: target 0).

Then a second run on a fresh store is killed with SIGKILL once half of its submissions were
acknowledged; the server is restarted and every acknowledged response must be in the store.
PostgreSQL runs on a throwaway cluster (Debian's ``postgresql``; skipped with the reason
when its binaries are missing).

Usage: python bench/bench_study.py [--participants 50] [--video-kb 500] [--backend sqlite,postgresql]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import platform
import sys
import tempfile
import time
import uuid
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from machine import describe_machine  # noqa: E402  (bench/ is the script's folder)

from gesturekit.study.store import open_store  # noqa: E402
from tests import study_pg  # noqa: E402
from tests._study_standin import make_folder  # noqa: E402
from tests.study_serve import kill9, run_participant, start_server  # noqa: E402


async def crowd(base: str, n: int, acked: list, timings: dict, kill_at: int | None = None, proc=None) -> float:
    """``n`` participants at once; with ``kill_at``, SIGKILL the server once that many were acknowledged.
    Returns the wall time in seconds."""
    limits = httpx.Limits(max_connections=2 * n, max_keepalive_connections=2 * n)
    t0 = time.perf_counter()
    clients = [httpx.AsyncClient(timeout=60, limits=limits) for _ in range(n)]
    try:
        tasks = [
            asyncio.create_task(run_participant(c, base, f"B{i:03d}", acked, timings)) for i, c in enumerate(clients)
        ]
        if kill_at is not None:
            while len(acked) < kill_at and not all(t.done() for t in tasks):
                await asyncio.sleep(0.005)
            kill9(proc)
        results = await asyncio.gather(*tasks, return_exceptions=True)
    finally:
        for c in clients:
            await c.aclose()
    if kill_at is None:
        failed = [r for r in results if isinstance(r, BaseException)]
        if failed:
            raise RuntimeError(f"{len(failed)} participants failed: {failed[0]!r}")
    return time.perf_counter() - t0


def lost(folder: Path, url: str | None, acked: list) -> tuple[int, int]:
    """(acknowledged responses missing from the store, responses stored)."""
    store = open_store(url, folder)
    frame = store.responses_frame()
    store.close()
    stored = {(t, p): a for t, p, a in zip(frame["token"], frame["page_id"], frame["answers"])}
    return sum(stored.get((t, p)) != body["answers"] for t, p, body in acked), len(stored)


def ms(values: list) -> str:
    return f"p50 {np.percentile(values, 50) * 1e3:6.1f} ms  p95 {np.percentile(values, 95) * 1e3:6.1f} ms"


def run_backend(name: str, url_for, args: argparse.Namespace, work: Path) -> None:
    folder = make_folder(work / f"{name}-load", rows=12, max_failures=5, video_bytes=args.video_kb * 1024)
    url = url_for()
    proc, base = start_server(folder, url)
    acked: list = []
    timings: dict = {"page": [], "submit": [], "bytes": 0}
    try:
        wall = asyncio.run(crowd(base, args.participants, acked, timings))
    finally:
        kill9(proc)
    missing, stored = lost(folder, url, acked)
    pages = len(timings["page"]) + len(timings["entry"])
    print(f"{name}: {args.participants} participants at once, {pages} pages, {len(acked)} submissions")
    print(f"  entry  {ms(timings['entry'])}  (a new participant: its row handed out, its first page)")
    print(f"  page   {ms(timings['page'])}")
    print(f"  submit {ms(timings['submit'])}")
    print(f"  video  {timings['bytes'] / wall / 2**20:.1f} MiB/s ({timings['bytes'] / 2**20:.0f} MiB in {wall:.1f} s)")
    print(f"  responses acknowledged {len(acked)}, stored {stored}, lost {missing}")

    folder = make_folder(work / f"{name}-kill", rows=12, max_failures=5, video_bytes=args.video_kb * 1024)
    url = url_for()
    proc, base = start_server(folder, url)
    acked = []
    try:
        asyncio.run(
            crowd(
                base,
                args.participants,
                acked,
                {"page": [], "submit": [], "bytes": 0},
                len(timings["submit"]) // 2,
                proc,
            )
        )
    finally:
        kill9(proc)
    proc, base = start_server(folder, url)  # the restart: it must open the store as the kill left it
    kill9(proc)
    missing, stored = lost(folder, url, acked)
    print(
        f"  kill -9 mid-run: {len(acked)} acknowledged before the kill, {stored} stored after the restart, "
        f"lost {missing}"
    )


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--participants", type=int, default=50)
    p.add_argument("--video-kb", type=int, default=500, help="size of each video (default 500 KB)")
    p.add_argument("--backend", default="sqlite,postgresql")
    args = p.parse_args()
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    python = platform.python_version()
    print(f"machine: {describe_machine()}; load average {load} (1, 5, 15 min) at the start; Python {python}")
    with tempfile.TemporaryDirectory(prefix="gk-bench-study-") as tmp:
        work = Path(tmp)
        for name in args.backend.split(","):
            if name == "sqlite":
                run_backend("SQLite", lambda: None, args, work)
            elif study_pg.binaries() is None:
                print("PostgreSQL: skipped, initdb/pg_ctl not installed (Debian: apt-get install postgresql)")
            else:
                with study_pg.postgres_cluster() as cluster:
                    run_backend(
                        "PostgreSQL",
                        lambda cluster=cluster: study_pg.fresh_database(cluster, "b" + uuid.uuid4().hex[:12]),
                        args,
                        work,
                    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
