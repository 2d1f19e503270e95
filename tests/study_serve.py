"""Run a study server as a separate process (uvicorn) for the durability tests and the benchmark, and
drive participants through it over HTTP."""

from __future__ import annotations

import asyncio
import json
import os
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx

from tests.waits import patience, wait_until

ROOT = Path(__file__).resolve().parents[1]

_LAUNCH = """
import importlib, sys, uvicorn
sys.path.insert(0, sys.argv[5])
from gesturekit.study.server import create_app
api = None if sys.argv[3] == "-" else importlib.import_module(sys.argv[3])
app = create_app(sys.argv[1], db=None if sys.argv[2] == "-" else sys.argv[2], api=api)
uvicorn.run(app, host="127.0.0.1", port=int(sys.argv[4]), log_level="warning", server_header=False)
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_server(folder: Path, db: str | None, api: str | None = "tests._study_standin", port: int | None = None):
    """Start the server in a subprocess; returns (process, base URL) once it answers."""
    port = port or free_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    args = [sys.executable, "-c", _LAUNCH, str(folder), db or "-", api or "-", str(port), str(ROOT)]
    proc = subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    base = f"http://127.0.0.1:{port}"

    def answers() -> bool:
        try:
            httpx.get(base + "/researcher", timeout=patience(10))
        except httpx.TransportError:
            return False
        return True

    def exited() -> str | None:
        return None if proc.poll() is None else f"it exited: {proc.stderr.read().decode()[-2000:]}"

    try:
        wait_until(answers, what="the study server answers", timeout_s=120, interval_s=0.1, give_up=exited)
    except AssertionError as e:
        proc.kill()
        raise RuntimeError(str(e)) from None
    return proc, base


def kill9(proc: subprocess.Popen) -> None:
    proc.kill()  # SIGKILL: no shutdown handler runs
    proc.wait()


_CONFIG = re.compile(r'<script type="application/json" id="config">(.*?)</script>', re.S)
_QUESTION = re.compile(r'data-question="([^"]+)"( data-number)?')


def answers_for(config: dict, page_html: str, count: int = 4) -> dict:
    """What a participant who rates everything 1 (the overlay check's answer) sends for a page."""
    kind, media = config["kind"], config["media"]
    if kind == "rating":
        return {m: {p: 1 for p in config["prompts"]} for m in media}
    if kind == "pairwise":
        return {"choice": -1}
    if kind == "audio_check":
        return {"count": count}
    if kind == "questionnaire":
        return {q: (30 if number else "none") for q, number in _QUESTION.findall(page_html)}
    return {}


async def run_participant(
    client: httpx.AsyncClient,
    base: str,
    pid: str,
    acked: list,
    timings: dict | None = None,
    fetch_media: bool = True,
    stop: asyncio.Event | None = None,
) -> str:
    """One participant from the entry URL to the done page; appends (token, page_id, body) of each
    acknowledged submission to ``acked``; ``timings`` collects page/submit seconds and media bytes.
    Returns the final page's text."""
    timings = timings if timings is not None else {"page": [], "submit": [], "bytes": 0}
    t0 = time.perf_counter()
    r = await client.get(f"{base}/?PROLIFIC_PID={pid}&STUDY_ID=s1&SESSION_ID=x{pid}", follow_redirects=True)
    timings.setdefault("entry", []).append(time.perf_counter() - t0)
    while True:
        if stop is not None and stop.is_set():
            return ""
        found = _CONFIG.search(r.text)
        if found is None:
            return r.text
        config = json.loads(found.group(1))
        token = config["submit"].split("/p/")[1].split("/")[0]
        events = []
        for i, m in enumerate(config["media"]):
            if fetch_media:
                resp = await client.get(f"{base}/p/{token}/m/{m}", headers={"Range": "bytes=0-"})
                timings["bytes"] += len(resp.content)
            events += [
                {"t": i, "kind": "play", "media": m, "at": 0.0},
                {"t": i + 1, "kind": "ended", "media": m, "at": 2.0},
            ]
        body = {"answers": answers_for(config, r.text), "events": events, "elapsed_s": 3.0}
        t0 = time.perf_counter()
        s = await client.post(base + config["submit"], json=body)
        timings["submit"].append(time.perf_counter() - t0)
        if s.status_code != 200:
            raise RuntimeError(f"submission refused: {s.status_code} {s.text}")
        acked.append((token, config["submit"].rsplit("/", 1)[1], body))
        t0 = time.perf_counter()
        r = await client.get(base + s.json()["next"])
        timings["page"].append(time.perf_counter() - t0)
