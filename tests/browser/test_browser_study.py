"""The study end to end in Chromium: design, participants' pages, a failed attention check, the analysis.

A 2-speech x 3-system study (``tests/study_helpers.py``) gets a design with rating and pairwise pages,
two attention checks per participant and the audio check (``gesturekit study init``). Its participant
server (``gesturekit study serve``, on 127.0.0.1 on a free port)
is then used by headless Debian Chromium driven by Playwright (see ``tests/app_browser.py``; skipped,
with the reason, where either is missing), each participant in a fresh browser context with its own
Prolific id:

- participant 1 completes the whole study: instructions, the audio check, both rating pages (every
  video played to its end: "Next" stays disabled until the last one has ended, answers or not), the
  pairwise pages, the questionnaire, and gets the completion code;
- participant 2 rates the overlay check ("Please rate this clip 1 on every question") and the
  mismatched-audio check high, as an inattentive participant does, and is ended after the second
  failure without a code;
- participant 3 completes the study as participant 1 did (the analysis compares systems over at least
  two included participants).

``gesturekit study analyse`` then reports participant 1 included, with their ratings, and participant 2
excluded for the failed checks.

The test knows the answers an attentive participant gives from the server's side of the study (the
design's pages and the key); the browser only ever sees opaque ids.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest

from gesturekit.cli import main as cli_main
from tests import app_browser
from tests.study_helpers import study_folder, tiny_study  # noqa: F401  (fixtures)
from tests.waits import patience, wait_until

pytestmark = pytest.mark.skipif(
    app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"
)

#: What an attentive participant gives each system (every prompt, 1..7); pairwise: the higher one, clearly.
SCORES = {"knn": 6, "audio-only": 4, "random": 2}
PASSWORD = "researcher-pw"
TIMEOUT_MS = app_browser.TIMEOUT_S * 1000

#: Plays a page's media element to its end (as a participant's click on play does) and resolves then.
_PLAY_TO_END = """async (id) => {
  const el = document.querySelector(`[data-media="${id}"]`);
  if (el.ended) return el.currentTime;
  const done = new Promise((resolve) => el.addEventListener("ended", resolve, {once: true}));
  await el.play();
  await done;
  return el.currentTime;
}"""


@contextlib.contextmanager
def study_server(folder: Path, log: Path) -> Iterator[str]:
    """``gesturekit study serve`` on the study (127.0.0.1, a free port) until the block ends; yields its URL."""
    port = app_browser._free_port()
    cmd = [sys.executable, "-m", "gesturekit", "study", "serve", str(folder), "--port", str(port)]
    env = dict(os.environ, PYTHONPATH=str(app_browser.REPO))
    with open(log, "wb") as out:
        proc = subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    try:

        def accepts() -> bool:  # up once it accepts a connection (a request to / would start a participant)
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=patience(10)):
                return True
            return False

        def exited() -> str | None:
            return None if proc.poll() is None else f"it exited with {proc.returncode}"

        try:
            wait_until(accepts, what="the study server accepts", timeout_s=180, interval_s=0.1, give_up=exited)
        except AssertionError as e:
            raise RuntimeError(f"{e}:\n{log.read_text(errors='replace')[-3000:]}") from None
        yield f"http://127.0.0.1:{port}"
    finally:
        app_browser.stop(proc)


class Participant:
    """One participant's browser session: answers each page attentively or not, as told."""

    def __init__(self, browser, url: str, pid: str, folder: Path, *, attentive: bool) -> None:
        from gesturekit.study.design import load_design, participant_pages

        design = load_design(folder)
        self.attentive = attentive
        self.systems = dict(pd.read_csv(folder / "manifest.csv", dtype=str)[["id", "system"]].values)
        # every row's pages by id (HMAC of row and index: distinct over the rows)
        self.pages = {p.id: p for row in range(1, design.participants + 1) for p in participant_pages(design, row)}
        self.prompts = [p for p, _ in design.prompts]
        self.context = browser.new_context(viewport={"width": 1200, "height": 900})
        self.page = self.context.new_page()
        self.page.set_default_timeout(TIMEOUT_MS)
        self.page.goto(f"{url}/?PROLIFIC_PID={pid}&STUDY_ID=study27&SESSION_ID=session-{pid}")
        self.seen: list[str] = []  # the kinds of the pages answered, in order
        self.locked: list[str] = []  # pages whose Next was seen disabled with every answer given but a video unseen

    @property
    def next(self):
        return self.page.locator("#next")

    def run(self) -> str:
        """Answer page after page until the study ends; returns the end: "done" or "ended"."""
        from playwright.sync_api import expect

        while True:
            self.page.wait_for_load_state()
            body = self.page.locator("body")
            expect(body).to_contain_text("")  # the page is there
            if self.page.locator("#completion-code").count():
                return "done"
            if self.page.locator("#config").count() == 0:
                expect(body).to_contain_text("this session has ended")
                return "ended"
            config = json.loads(self.page.locator("#config").text_content())
            page = self.pages[config["submit"].rsplit("/", 1)[1]]
            assert config["kind"] == page.kind and config["media"] == [m.id for m in page.media]
            getattr(self, page.kind)(page)
            self.seen.append(page.kind)
            expect(self.next).to_be_enabled()
            with self.page.expect_navigation():
                self.next.click()

    def play_all(self, page, *, check_lock: bool) -> None:
        """Play every media element of the page to its end; with ``check_lock``, Next is disabled until the last."""
        from playwright.sync_api import expect

        for m in page.media:
            if check_lock:
                expect(self.next).to_be_disabled()
            at = self.page.evaluate(_PLAY_TO_END, m.id)
            assert at > 0.5  # played through: the videos are 1.2 and 1.6 s
        if check_lock:
            self.locked.append(page.id)

    def instructions(self, page) -> None:
        from playwright.sync_api import expect

        expect(self.page.locator(".instructions")).to_contain_text("animations")

    def audio_check(self, page) -> None:
        from playwright.sync_api import expect

        expect(self.next).to_be_disabled()  # the sound not yet played
        self.play_all(page, check_lock=False)
        # every participant hears the beeps right: the inattentive one fails the attention checks alone
        self.page.locator("input[name=count]").fill(str(page.check["expect"]["count"]["min"]))

    def rating(self, page) -> None:
        # answers first: Next must still wait for the videos
        for m in page.media:
            for prompt in self.prompts:
                value = self.rating_of(page, m.id, prompt)
                self.page.locator(f"input[name='r-{m.id}-{prompt}'][value='{value}']").check()
        self.play_all(page, check_lock=True)

    def rating_of(self, page, media: str, prompt: str) -> int:
        check = page.check if page.check is not None and page.check["media"] == media else None
        if check is None:
            return SCORES[self.systems[media]]
        if not self.attentive:
            return 7  # the overlay asks for 1; a mismatched clip's sync should be low
        span = check["expect"].get(prompt)
        return 4 if span is None else span["min"]

    def pairwise(self, page) -> None:
        from playwright.sync_api import expect

        expect(self.next).to_be_disabled()
        left, right = (SCORES[self.systems[m.id]] for m in page.media)
        choice = -2 if left > right else 2 if right > left else 0
        self.page.locator(f"input[name=choice][value='{choice}']").check()
        self.play_all(page, check_lock=True)

    def questionnaire(self, page) -> None:
        from playwright.sync_api import expect

        self.page.locator("[data-question=age]").fill("34")
        expect(self.next).to_be_enabled()  # the comments are optional
        self.page.locator("[data-question=comments]").fill("Clear videos.")


def test_participants_complete_or_fail_the_study_and_the_analysis_shows_both(study_folder, tmp_path, capsys):  # noqa: F811
    from playwright.sync_api import sync_playwright

    from gesturekit.study.design import load_design
    from gesturekit.study.store import open_store

    init = ["study", "init", str(study_folder), "--pairwise", "--attention", "2", "--password", PASSWORD]
    assert cli_main(init) == 0
    design = load_design(study_folder)
    assert design.rating and design.pairwise and design.attention == 2 and design.audio_check is not None

    with study_server(study_folder, tmp_path / "serve.log") as url, sync_playwright() as pw:
        browser = pw.chromium.launch(
            executable_path=app_browser.find_chromium(),
            args=[*app_browser.CHROMIUM_FLAGS, "--autoplay-policy=no-user-gesture-required"],
        )
        try:
            first = Participant(browser, url, "pid-attentive", study_folder, attentive=True)
            started = time.monotonic()
            assert first.run() == "done"
            took = time.monotonic() - started
            code = first.page.locator("#completion-code").inner_text()
            second = Participant(browser, url, "pid-inattentive", study_folder, attentive=False)
            assert second.run() == "ended"
            ended_text = second.page.locator("body").inner_text()
            third = Participant(browser, url, "pid-attentive-2", study_folder, attentive=True)
            assert third.run() == "done"
        finally:
            browser.close()

    kinds = ["instructions", "audio_check", "rating", "rating"] + ["pairwise"] * 6 + ["questionnaire"]
    assert first.seen == kinds and third.seen == kinds
    assert code == design.completion_code
    with capsys.disabled():
        print(f"\nparticipant 1: {len(first.seen)} pages answered in {took:.1f} s")
    assert len(first.locked) == 8  # 2 rating + 6 pairwise pages waited for their videos
    # ended at the second failed check (max_failures 1), the second rating page: no pairwise page reached
    assert second.seen == kinds[:4]
    assert "no completion code" in ended_text and design.completion_code not in ended_text

    store = open_store(None, study_folder)
    people = store.participants_frame().set_index("prolific_pid")
    assert people.loc["pid-attentive", "status"] == "finished"
    assert people.loc["pid-inattentive", "status"] == "failed_checks"
    assert people.loc["pid-inattentive", "failed_checks"] == 2
    tokens = {pid: people.loc[pid, "token"] for pid in people.index}

    out = tmp_path / "analysis"
    assert cli_main(["study", "analyse", str(study_folder), "--out", str(out), "--rounds", "200"]) == 0
    printed = capsys.readouterr().out
    assert (
        "3 started, 0 answered nothing, 1 excluded by the checks, 0 with no rating or pairwise answer, 2 analysed"
    ) in printed
    from gesturekit.study.report import analyse_study

    report = analyse_study(study_folder, out=tmp_path / "again", rounds=200)
    table = report.participants.set_index("participant")
    assert not table.loc[tokens["pid-attentive"], "excluded"]
    assert table.loc[tokens["pid-inattentive"], "excluded"]
    assert table.loc[tokens["pid-inattentive"], "failed_checks"] == 2
    mine = report.ratings[report.ratings["participant"] == tokens["pid-attentive"]]
    assert len(mine) == 6 * 2  # every stimulus, both prompts; the check videos are no ratings
    assert (mine["value"] == mine["system"].map(SCORES)).all()
    assert tokens["pid-inattentive"] not in set(report.ratings["participant"])
    means = report.summary[report.summary["prompt"] == "all"].set_index("system")["mean"]
    assert means.to_dict() == {s: float(v) for s, v in SCORES.items()}
    markdown = (out / "report.md").read_text(encoding="utf-8")
    assert "Excluded: 1 (failed more attention checks than allowed: 1)" in markdown and "Analysed: 2" in markdown
    lines = {line.split("|")[1].strip(): line for line in markdown.splitlines() if line.startswith("| ")}
    assert "False" in lines[tokens["pid-attentive"]] and "True" in lines[tokens["pid-inattentive"]]
