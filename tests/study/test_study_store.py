"""The study's response store on SQLite and on a real PostgreSQL server: rows handed out once each and
balanced under concurrency, idempotent and in-order responses, attention checks ending a session, the
frames the analysis reads, and a server process killed with -9 mid-run losing no acknowledged response."""

from __future__ import annotations

import asyncio
import sqlite3
import threading
import time
import uuid
from collections import Counter

import httpx
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit.errors import ConfigError
from gesturekit.study.store import PARTICIPANT_COLUMNS, RESPONSE_COLUMNS, body_digest, open_store
from tests import study_pg
from tests._study_standin import make_folder
from tests.study_serve import kill9, run_participant, start_server
from tests.waits import patience


@pytest.fixture(scope="module")
def pg_cluster():
    if study_pg.binaries() is None:
        pytest.skip("PostgreSQL's initdb/pg_ctl are not installed (Debian: apt-get install postgresql)")
    with study_pg.postgres_cluster() as url:
        yield url


@pytest.fixture(params=["sqlite", "postgresql"])
def store_url(request, tmp_path):
    """None (SQLite in the study folder) or the URL of a fresh PostgreSQL database."""
    if request.param == "sqlite":
        return None
    cluster = request.getfixturevalue("pg_cluster")
    return study_pg.fresh_database(cluster, "t" + uuid.uuid4().hex[:12])


def test_sqlite_keeps_a_write_ahead_log_synced_at_every_commit(tmp_path):
    store = open_store(None, tmp_path)
    store.start(2)
    conn = store._conn()
    assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert conn.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL
    store.close()
    assert (tmp_path / "responses.sqlite3").exists()
    with sqlite3.connect(tmp_path / "responses.sqlite3") as conn:
        assert conn.execute("SELECT COUNT(*) FROM participants").fetchone()[0] == 1


def test_an_unknown_url_is_refused_naming_it(tmp_path):
    with pytest.raises(ConfigError, match="mysql://x"):
        open_store("mysql://x", tmp_path)


@pytest.mark.slow
def test_rows_are_handed_out_balanced_under_concurrent_starts(store_url, tmp_path):
    store = open_store(store_url, tmp_path)
    got, barrier = [], threading.Barrier(8)

    def worker():
        barrier.wait()
        for _ in range(5):
            got.append(store.start(4)[0])

    threads = [threading.Thread(target=worker) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len({p.token for p in got}) == 40
    assert Counter(p.row for p in got) == {1: 10, 2: 10, 3: 10, 4: 10}
    frame = store.participants_frame()
    assert list(frame.columns) == list(PARTICIPANT_COLUMNS) and len(frame) == 40
    store.close()


def test_a_returning_prolific_participant_resumes_and_failed_rows_are_given_again(store_url, tmp_path):
    store = open_store(store_url, tmp_path)
    first, new = store.start(3, prolific_pid="P1", study_id="S", session_id="A")
    assert new and first.row == 1
    again, new = store.start(3, prolific_pid="P1", study_id="S", session_id="A")
    assert not new and again.token == first.token
    # the id alone, from another session, takes nothing over
    assert store.start(3, prolific_pid="P1", study_id="S", session_id="B") == (None, False)
    second = store.start(3, prolific_pid="P2")[0]
    assert second.row == 2
    # P2 fails two checks (max 1): its row is free again for the next participant
    store.submit(second.token, "a", 0, "rating", {}, [], 1.0, failed_check=True)
    assert store.submit(second.token, "b", 1, "rating", {}, [], 1.0, failed_check=True).status == "failed_checks"
    assert store.start(3)[0].row == 2
    store.close()


def test_responses_are_idempotent_in_order_and_end_after_too_many_failed_checks(store_url, tmp_path):
    store = open_store(store_url, tmp_path)
    person = store.start(1)[0]
    answers, events = {"m1": {"natural": 5, "sync": 4}}, [{"t": 1.0, "kind": "ended", "media": "m1", "at": 2.0}]
    assert store.submit(person.token, "p0", 0, "instructions", {}, [], 3.5).outcome == "stored"
    assert store.submit(person.token, "p2", 2, "rating", answers, events, 9.0).outcome == "out_of_order"
    assert store.submit(person.token, "p1", 1, "rating", answers, events, 9.0).outcome == "stored"
    before = store.responses_frame()
    assert store.submit(person.token, "p1", 1, "rating", answers, events, 9.0).outcome == "same"
    assert store.submit(person.token, "p1", 1, "rating", {"m1": {"natural": 1, "sync": 1}}, events, 9.0).outcome == (
        "conflict"
    )
    assert store.submit("nobody", "p2", 2, "rating", answers, events, 9.0).outcome == "unknown"
    after = store.responses_frame()
    assert after.equals(before) and list(after.columns) == list(RESPONSE_COLUMNS)
    assert after["answers"].tolist() == [{}, answers] and after["events"].tolist()[1] == events
    assert after["elapsed_s"].tolist() == [3.5, 9.0] and after["row"].tolist() == [1, 1]
    assert after["submitted_at"].str.endswith("Z").all()
    check = store.submit(person.token, "p2", 2, "rating", answers, events, 1.0, failed_check=True, max_failures=1)
    assert (check.outcome, check.status, check.failed_checks) == ("stored", "active", 1)
    check = store.submit(person.token, "p3", 3, "rating", answers, events, 1.0, failed_check=True, max_failures=1)
    assert (check.status, check.failed_checks) == ("failed_checks", 2)
    assert store.submit(person.token, "p4", 4, "rating", answers, events, 1.0).outcome == "closed"
    people = store.participants_frame()
    assert people["status"].tolist() == ["failed_checks"] and people["finished_at"].notna().all()
    store.close()


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(bodies=st.lists(st.tuples(st.integers(0, 2), st.sampled_from([{}, {"a": 1}, {"a": 2}])), min_size=1, max_size=8))
def test_the_first_body_of_a_page_is_kept_whatever_follows(tmp_path_factory, bodies):
    """Property: whatever sequence of submissions arrives, each page keeps the first body stored for it;
    a later equal body is acknowledged, a different one refused, and a skipped page never stored."""
    store = open_store(None, tmp_path_factory.mktemp("s"))
    token = store.start(1)[0].token
    kept: dict[int, dict] = {}
    for index, answers in bodies:
        outcome = store.submit(token, f"p{index}", index, "rating", answers, [], 1.0).outcome
        if index in kept:
            assert outcome == ("same" if kept[index] == answers else "conflict")
        elif index == len(kept):
            assert outcome == "stored"
            kept[index] = answers
        else:
            assert outcome == "out_of_order"
    frame = store.responses_frame()
    assert dict(zip(frame["page_index"], frame["answers"])) == kept
    assert body_digest({"a": 1, "b": 2}, [], 1.0) == body_digest({"b": 2, "a": 1}, [], 1.0)
    store.close()


@pytest.mark.slow
def test_a_server_killed_with_minus_9_loses_no_acknowledged_response(store_url, tmp_path):
    folder = make_folder(tmp_path / "study", rows=4, max_failures=5, video_bytes=20_000)
    proc, base = start_server(folder, store_url)
    acked: list = []

    async def crowd():
        # one client (one cookie jar: one browser) per participant
        clients = [httpx.AsyncClient(timeout=patience(120)) for _ in range(12)]
        try:
            tasks = [asyncio.create_task(run_participant(c, base, f"P{i}", acked)) for i, c in enumerate(clients)]
            deadline = time.monotonic() + patience(240)  # a busy machine may answer slowly; never wait for ever
            while len(acked) < 20 and not all(t.done() for t in tasks) and time.monotonic() < deadline:
                await asyncio.sleep(0.01)
            kill9(proc)
            await asyncio.gather(*tasks, return_exceptions=True)
        finally:
            for c in clients:
                await c.aclose()

    try:
        asyncio.run(crowd())
    finally:
        kill9(proc)
    assert len(acked) >= 20
    proc, base = start_server(folder, store_url)
    try:
        store = open_store(store_url, folder)
        frame = store.responses_frame()
        stored = {(t, p): a for t, p, a in zip(frame["token"], frame["page_id"], frame["answers"])}
        for token, page_id, body in acked:
            assert stored[(token, page_id)] == body["answers"]
        # and the restarted server resumes a participant where they were
        token = acked[0][0]
        page = httpx.get(f"{base}/p/{token}/", cookies={"gk_study": token})
        assert page.status_code == 200
        store.close()
    finally:
        kill9(proc)
