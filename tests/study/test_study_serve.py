"""The study server on a real design (gesturekit study init on the tiny stimuli folder): a participant
completes every page and gets the completion code, another fails the checks and is stopped, the videos
are the stimuli's MP4s with ranges, no page names a system or a speech; ``gesturekit study serve``
binds 127.0.0.1 and answers."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys

import httpx
import pytest
from starlette.testclient import TestClient

from gesturekit.study.design import init_study, participant_pages
from gesturekit.study.server import COOKIE, create_app
from gesturekit.study.store import open_store
from tests.study_helpers import tiny_study  # noqa: F401
from tests.study_serve import ROOT, free_port
from tests.waits import patience, wait_until

pytestmark = pytest.mark.slow  # tiny_study builds a demo database and makes a stimuli folder once per module

PASSWORD = "a long researcher secret"


@pytest.fixture(scope="module")
def design(tiny_study, tmp_path_factory):  # noqa: F811
    folder = tmp_path_factory.mktemp("serve") / "study"
    shutil.copytree(tiny_study, folder)
    return init_study(folder, pairwise=True, password=PASSWORD)


def body_for(page, design, passing=True):
    """A careful participant's body; ``passing=False`` answers every check wrongly."""
    events = [
        {"t": float(i), "kind": k, "media": m.id, "at": 0.0}
        for i, m in enumerate(page.media)
        for k in ("play", "ended")
    ]
    answers: dict = {}
    if page.kind == "rating":
        lo = 0 if design.scale == "slider100" else 1
        answers = {m.id: {pid: lo + 3 for pid, _ in design.prompts} for m in page.media}
    elif page.kind == "pairwise":
        answers = {"choice": 1}
    elif page.kind == "audio_check":
        answers = {"count": 0}
    elif page.kind == "questionnaire":
        answers = {
            q["id"]: (30 if q["type"] == "number" else q.get("options", ["ok"])[0])
            for q in design.questionnaire
            if not q.get("optional")
        }
    if page.check is not None:
        target = answers[page.check["media"]] if page.kind == "rating" else answers
        for key, span in page.check["expect"].items():
            target[key] = int(span["min"]) if passing else int(span["max"]) + 1
    return {"answers": answers, "events": events, "elapsed_s": 4.0}


def test_a_participant_completes_the_real_study_and_one_who_fails_the_checks_is_stopped(design, tmp_path):
    store = open_store(f"sqlite:///{tmp_path / 'r.sqlite3'}", design.folder)
    app = create_app(design.folder, store=store)
    client = TestClient(app)
    client.get("/?PROLIFIC_PID=good")
    token = client.cookies[COOKIE]
    person = store.participant(token)
    pages = [p for p in participant_pages(design, person.row) if p.kind != "done"]
    assert {p.kind for p in pages} >= {"instructions", "audio_check", "rating", "pairwise", "questionnaire"}
    shown = []
    for page in pages:
        html = client.get(f"/p/{token}/").text
        shown.append(html)
        assert page.id in html
        for src in re.findall(r'src="([^"]+)"', html):
            media = client.get(src, headers={"Range": "bytes=0-99"})
            assert media.status_code == 206 and len(media.content) == 100
            if src.endswith(tuple(m.id for m in page.media if m.kind != "audio_check")):
                assert media.content[4:8] == b"ftyp" and media.headers["content-type"] == "video/mp4"
        r = client.post(f"/p/{token}/pages/{page.id}", json=body_for(page, design))
        assert r.status_code == 200, (page.kind, r.text)
    done = client.get(f"/p/{token}/").text
    assert design.completion_code in done
    text = "\n".join(shown + [done])
    for secret in ("audio-only", "speech_0", "speech_1", "manifest", str(design.folder)):
        assert secret not in text
    frame = store.responses_frame()
    assert frame["page_id"].tolist() == [p.id for p in pages]
    assert frame["kind"].tolist() == [p.kind for p in pages]

    bad = TestClient(app)
    bad.get("/?PROLIFIC_PID=careless")
    token = bad.cookies[COOKIE]
    pages = [p for p in participant_pages(design, store.participant(token).row) if p.kind != "done"]
    for page in pages:
        r = bad.post(f"/p/{token}/pages/{page.id}", json=body_for(page, design, passing=False))
        if r.status_code == 409:
            break
        assert r.status_code == 200
    end = bad.get(f"/p/{token}/").text
    assert "session has ended" in end and design.completion_code not in end
    people = store.participants_frame().set_index("prolific_pid")
    assert people.loc["good", "status"] == "finished" and people.loc["careless", "status"] == "failed_checks"
    assert people.loc["careless", "failed_checks"] == design.max_failures + 1
    page = TestClient(app).get("/researcher", auth=("r", PASSWORD))
    assert page.status_code == 200 and "careless" in page.text
    assert TestClient(app).get("/researcher", auth=("r", "not the password")).status_code == 401
    store.close()


def test_the_serve_command_binds_this_machine_only_by_default(design, tmp_path):
    port = free_port()
    db = f"sqlite:///{tmp_path / 'cli.sqlite3'}"
    proc = subprocess.Popen(
        [sys.executable, "-m", "gesturekit", "study", "serve", str(design.folder), "--port", str(port), "--db", db],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:

        def answer() -> httpx.Response | None:
            try:
                return httpx.get(f"http://127.0.0.1:{port}/?PROLIFIC_PID=cli", timeout=patience(10))
            except httpx.TransportError:
                return None

        def exited() -> str | None:
            return None if proc.poll() is None else f"it exited with {proc.returncode}"

        r = wait_until(answer, what="the study server answers", timeout_s=120, interval_s=0.2, give_up=exited)
        assert r.status_code == 303 and r.headers["location"].startswith("/p/")
        assert "server" not in r.headers
        listening = subprocess.run(["ss", "-ltnH", f"sport = :{port}"], capture_output=True, text=True).stdout
        assert f"127.0.0.1:{port}" in listening and f"0.0.0.0:{port}" not in listening
    finally:
        proc.kill()
        out = proc.communicate()[0]
    assert "researcher" in out and f"127.0.0.1:{port}" in out
    assert (tmp_path / "cli.sqlite3").exists() and not (design.folder / "responses.sqlite3").exists()
