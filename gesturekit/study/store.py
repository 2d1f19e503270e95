"""Where a running study keeps its participants and their responses.

SQLite in the study folder by default (``responses.sqlite3``: write-ahead log,
``synchronous=FULL``, so a committed transaction survives a killed process and a
power cut), or PostgreSQL given a ``postgresql://`` URL (psycopg 3) for hosted
studies. Every write is one transaction that commits before the caller
acknowledges anything; every call opens its own transaction, so one store may be
shared by the threads of a web server.

Two tables::

    participants  token, row, prolific_pid, study_id, session_id, started_at, finished_at, status, failed_checks
    responses     token, page_id, page_index, kind, answers, events, elapsed_s, digest, submitted_at

A response is kept once per (token, page id): :meth:`Store.submit` with the same
body again is acknowledged without a second row (idempotent), with another body it
is refused. Pages are answered in order: a response whose page index is not the
number of pages the participant already answered is refused, so two requests
racing for one participant cannot skip a page. Order rows are handed out in one
locked transaction: the row that the fewest participants hold (those ended by
failed attention checks do not count), the lowest on a tie.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import secrets
import sqlite3
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

from ..errors import ConfigError

SQLITE_NAME = "responses.sqlite3"
#: seconds a participant who has answered nothing yet holds their order row
RESERVE_S = 30 * 60
STATUSES = ("active", "finished", "failed_checks")
PARTICIPANT_COLUMNS = (
    "token",
    "row",
    "prolific_pid",
    "study_id",
    "session_id",
    "started_at",
    "finished_at",
    "status",
    "failed_checks",
)
RESPONSE_COLUMNS = ("token", "row", "page_id", "page_index", "kind", "answers", "elapsed_s", "submitted_at", "events")

_SCHEMA = (
    """CREATE TABLE IF NOT EXISTS participants (
        token TEXT PRIMARY KEY, row INTEGER NOT NULL, prolific_pid TEXT, study_id TEXT, session_id TEXT,
        started_at TEXT NOT NULL, finished_at TEXT, status TEXT NOT NULL, failed_checks INTEGER NOT NULL)""",
    """CREATE TABLE IF NOT EXISTS responses (
        token TEXT NOT NULL REFERENCES participants(token), page_id TEXT NOT NULL, page_index INTEGER NOT NULL,
        kind TEXT NOT NULL, answers TEXT NOT NULL, events TEXT NOT NULL, elapsed_s DOUBLE PRECISION,
        digest TEXT NOT NULL, submitted_at TEXT NOT NULL, PRIMARY KEY (token, page_id))""",
    "CREATE INDEX IF NOT EXISTS participants_pid ON participants (prolific_pid)",
)


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def body_digest(answers: Any, events: Any, elapsed_s: float | None) -> str:
    """SHA-256 of a response body in canonical JSON: equal bodies, equal digests."""
    text = json.dumps([answers, events, elapsed_s], sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True)
class Participant:
    """One participant as stored; ``row`` is the 1-based order row (order.csv's ``participant``)."""

    token: str
    row: int
    prolific_pid: str | None
    status: str
    failed_checks: int
    answered: int


@dataclass(frozen=True)
class Submission:
    """What :meth:`Store.submit` did.

    ``outcome`` is ``"stored"`` (committed now), ``"same"`` (this body was stored before: acknowledge it),
    ``"conflict"`` (another body was stored for this page), ``"out_of_order"`` (not the participant's next
    page), ``"closed"`` (the participant's session has ended) or ``"unknown"`` (no such participant).
    ``status`` and ``failed_checks`` are the participant's after the call.
    """

    outcome: str
    status: str | None = None
    failed_checks: int = 0


class Store:
    """A study's responses in SQLite or PostgreSQL; open with :func:`open_store`."""

    def __init__(self, url: str) -> None:
        self.url = url
        self._postgres = url.startswith(("postgresql://", "postgres://"))
        self._local = threading.local()
        self._lock = threading.Lock()
        self._write_lock = threading.Lock()
        self._connections: list[Any] = []
        with self._transaction(write=True) as cur:
            for statement in _SCHEMA:
                cur.execute(statement)

    # ------------------------------------------------------------ connections

    def _connect(self) -> Any:
        conn: Any
        if self._postgres:
            import psycopg

            conn = psycopg.connect(self.url, autocommit=True)
        else:
            conn = sqlite3.connect(self.url, isolation_level=None, check_same_thread=False, timeout=30.0)
            conn.execute("PRAGMA journal_mode=WAL")
            # FULL: a transaction is on disk when COMMIT returns, not only in the log's page cache
            conn.execute("PRAGMA synchronous=FULL")
            conn.execute("PRAGMA busy_timeout=30000")
        with self._lock:
            self._connections.append(conn)
        return conn

    def _conn(self) -> Any:
        conn = getattr(self._local, "conn", None)
        if conn is None or getattr(conn, "closed", False):
            conn = self._local.conn = self._connect()
        return conn

    @contextlib.contextmanager
    def _transaction(self, write: bool = False) -> Iterator[Any]:
        """A cursor inside one transaction, committed on leaving (rolled back on an error).

        SQLite's writers take the database's write lock at BEGIN (IMMEDIATE), so a read followed by a
        write in one transaction cannot be overtaken by another writer."""
        conn = self._conn()
        if self._postgres:
            with conn.transaction():
                with conn.cursor() as cur:
                    yield _Cursor(cur, postgres=True)
            return
        # this process's writers queue on a lock rather than in SQLite's busy handler, which polls
        # with sleeps of up to 100 ms; other processes still wait through busy_timeout
        with self._write_lock if write else contextlib.nullcontext():
            cur = conn.cursor()
            cur.execute("BEGIN IMMEDIATE" if write else "BEGIN")
            try:
                yield _Cursor(cur, postgres=False)
            except BaseException:
                conn.execute("ROLLBACK")
                raise
            conn.execute("COMMIT")

    def close(self) -> None:
        """Close every connection this store opened."""
        with self._lock:
            for conn in self._connections:
                try:
                    conn.close()
                except Exception:  # a connection of a finished thread may be gone already
                    pass
            self._connections.clear()
        self._local = threading.local()

    # ------------------------------------------------------------ participants

    def start(
        self, rows: int, *, prolific_pid: str | None = None, study_id: str | None = None, session_id: str | None = None
    ) -> tuple[Participant | None, bool]:
        """A new participant on the next free order row, or the one this Prolific id already started.

        A known ``prolific_pid`` resumes only with the ``study_id`` and ``session_id`` it started with
        (Prolific keeps both for a participant's attempt); otherwise (someone who knows only the id)
        nothing is handed out and None is returned. Rows are balanced over the participants who have
        answered a page or started within :data:`RESERVE_S`: entries that never answer stop holding a
        row, so a flood of them does not shift the balanced order.

        Parameters
        ----------
        rows : int
            Order rows of the study (1..rows).
        prolific_pid, study_id, session_id : str or None
            Prolific's URL parameters; a known ``prolific_pid`` resumes its participant.

        Returns
        -------
        (Participant or None, bool)
            The participant (None: the Prolific id belongs to another session) and whether it is new.
        """
        if rows < 1:
            raise ConfigError(f"a study needs at least one order row, got {rows}")
        with self._transaction(write=True) as cur:
            if self._postgres:
                # one lock for every row assignment: the count and the insert below are one step
                cur.execute("SELECT pg_advisory_xact_lock(27027)")
            if prolific_pid:
                cur.execute(
                    "SELECT token, study_id, session_id FROM participants WHERE prolific_pid = %s ORDER BY started_at",
                    (prolific_pid,),
                )
                found = cur.fetchone()
                if found is not None:
                    if (found[1], found[2]) != (study_id, session_id):
                        return None, False
                    return self._participant(cur, found[0]), False
            cutoff = (datetime.now(timezone.utc) - timedelta(seconds=RESERVE_S)).isoformat(timespec="milliseconds")
            cur.execute(
                "SELECT row, COUNT(*) FROM participants p WHERE status <> 'failed_checks' AND (started_at >= %s "
                "OR EXISTS (SELECT 1 FROM responses r WHERE r.token = p.token)) GROUP BY row",
                (cutoff.replace("+00:00", "Z"),),
            )
            held = {int(r): int(n) for r, n in cur.fetchall()}
            row = min(range(1, rows + 1), key=lambda r: (held.get(r, 0), r))
            token = secrets.token_urlsafe(24)
            cur.execute(
                "INSERT INTO participants VALUES (%s, %s, %s, %s, %s, %s, NULL, 'active', 0)",
                (token, row, prolific_pid, study_id, session_id, _now()),
            )
            return Participant(token, row, prolific_pid, "active", 0, 0), True

    def _participant(self, cur: _Cursor, token: str, lock: bool = False) -> Participant | None:
        cur.execute(
            "SELECT token, row, prolific_pid, status, failed_checks FROM participants WHERE token = %s"
            + (" FOR UPDATE" if lock and self._postgres else ""),
            (token,),
        )
        found = cur.fetchone()
        if found is None:
            return None
        cur.execute("SELECT COUNT(*) FROM responses WHERE token = %s", (token,))
        return Participant(found[0], int(found[1]), found[2], found[3], int(found[4]), int(cur.fetchone()[0]))

    def participant(self, token: str) -> Participant | None:
        """The stored participant of ``token`` (``answered``: how many pages it answered), or None."""
        with self._transaction() as cur:
            return self._participant(cur, token)

    def response(self, token: str, page_id: str) -> dict | None:
        """The stored response of one page: ``answers``, ``events``, ``elapsed_s``, ``digest``; or None."""
        with self._transaction() as cur:
            cur.execute(
                "SELECT answers, events, elapsed_s, digest FROM responses WHERE token = %s AND page_id = %s",
                (token, page_id),
            )
            found = cur.fetchone()
        if found is None:
            return None
        return {
            "answers": json.loads(found[0]),
            "events": json.loads(found[1]),
            "elapsed_s": found[2],
            "digest": found[3],
        }

    def finish(self, token: str) -> None:
        """Mark an active participant finished (idempotent)."""
        with self._transaction(write=True) as cur:
            cur.execute(
                "UPDATE participants SET status = 'finished', finished_at = %s WHERE token = %s AND status = 'active'",
                (_now(), token),
            )

    # ------------------------------------------------------------ responses

    def submit(
        self,
        token: str,
        page_id: str,
        page_index: int,
        kind: str,
        answers: Any,
        events: Any,
        elapsed_s: float | None,
        *,
        failed_check: bool = False,
        max_failures: int = 1,
        last: bool = False,
    ) -> Submission:
        """Keep one page's response, committed before this returns.

        Parameters
        ----------
        token, page_id : str
        page_index : int
            The page's 0-based position; it must equal the number of pages already answered.
        kind : str
            The page's kind.
        answers, events : JSON values
        elapsed_s : float or None
            Seconds the participant spent on the page.
        failed_check : bool
            The response failed an attention check: the participant's count goes up, and above
            ``max_failures`` the participant is ended (status ``failed_checks``).
        last : bool
            The last page to answer: the participant is finished (unless just ended by a check).

        Returns
        -------
        Submission
        """
        digest = body_digest(answers, events, elapsed_s)
        with self._transaction(write=True) as cur:
            person = self._participant(cur, token, lock=True)
            if person is None:
                return Submission("unknown")
            cur.execute("SELECT digest FROM responses WHERE token = %s AND page_id = %s", (token, page_id))
            before = cur.fetchone()
            if before is not None:
                outcome = "same" if before[0] == digest else "conflict"
                return Submission(outcome, person.status, person.failed_checks)
            if person.status != "active":
                return Submission("closed", person.status, person.failed_checks)
            if page_index != person.answered:
                return Submission("out_of_order", person.status, person.failed_checks)
            cur.execute(
                "INSERT INTO responses VALUES (%s, %s, %s, %s, %s, %s, %s, %s, %s)",
                (
                    token,
                    page_id,
                    page_index,
                    kind,
                    json.dumps(answers, sort_keys=True),
                    json.dumps(events),
                    elapsed_s,
                    digest,
                    _now(),
                ),
            )
            failures = person.failed_checks + int(failed_check)
            status, finished_at = "active", None
            if failures > max_failures:
                status, finished_at = "failed_checks", _now()
            elif last:
                status, finished_at = "finished", _now()
            cur.execute(
                "UPDATE participants SET failed_checks = %s, status = %s, finished_at = %s WHERE token = %s",
                (failures, status, finished_at, token),
            )
            return Submission("stored", status, failures)

    # ------------------------------------------------------------ frames

    def participants_frame(self) -> Any:
        """Every participant: ``token, row, prolific_pid, study_id, session_id, started_at, finished_at,
        status ("active"|"finished"|"failed_checks"), failed_checks`` (times ISO 8601 UTC), by start time."""
        import pandas as pd

        with self._transaction() as cur:
            cur.execute(f"SELECT {', '.join(PARTICIPANT_COLUMNS)} FROM participants ORDER BY started_at, token")
            rows = cur.fetchall()
        frame = pd.DataFrame([tuple(r) for r in rows], columns=list(PARTICIPANT_COLUMNS))
        return frame.astype({"row": "int64", "failed_checks": "int64"})

    def responses_frame(self) -> Any:
        """Every response: ``token, row, page_id, page_index, kind, answers (dict), elapsed_s, submitted_at
        (ISO 8601 UTC), events (list)``, by participant start and page index."""
        import pandas as pd

        with self._transaction() as cur:
            cur.execute(
                "SELECT r.token, p.row, r.page_id, r.page_index, r.kind, r.answers, r.elapsed_s, r.submitted_at, "
                "r.events FROM responses r JOIN participants p ON p.token = r.token "
                "ORDER BY p.started_at, r.token, r.page_index"
            )
            rows = cur.fetchall()
        records = [(*r[:5], json.loads(r[5]), r[6], r[7], json.loads(r[8])) for r in rows]
        frame = pd.DataFrame(records, columns=list(RESPONSE_COLUMNS))
        return frame.astype({"row": "int64", "page_index": "int64", "elapsed_s": "float64"})


class _Cursor:
    """A DB-API cursor taking ``%s`` placeholders on both backends (SQLite's are ``?``)."""

    def __init__(self, cur: Any, postgres: bool) -> None:
        self._cur, self._postgres = cur, postgres

    def execute(self, sql: str, params: tuple = ()) -> None:
        self._cur.execute(sql if self._postgres else sql.replace("%s", "?"), params)

    def fetchone(self) -> Any:
        return self._cur.fetchone()

    def fetchall(self) -> list:
        return list(self._cur.fetchall())


def open_store(url: str | None, folder: str | os.PathLike[str]) -> Store:
    """The response store of a study.

    Parameters
    ----------
    url : str or None
        None: SQLite in ``folder/responses.sqlite3``; ``postgresql://user@host:port/db``: PostgreSQL
        (psycopg 3, the ``study`` extra); ``sqlite:///path``: SQLite in that file.
    folder : path
        The study folder.

    Returns
    -------
    Store
    """
    if url is None:
        return Store(str(Path(folder) / SQLITE_NAME))
    if url.startswith("sqlite:///"):
        return Store(url[len("sqlite:///") :])
    if url.startswith(("postgresql://", "postgres://")):
        try:
            import psycopg  # noqa: F401
        except ImportError as exc:  # pragma: no cover - depends on the install
            raise ConfigError("a PostgreSQL store needs psycopg 3: pip install 'gesturekit[study]'") from exc
        return Store(url)
    raise ConfigError(f"unknown response store URL {url!r}: use postgresql://..., sqlite:///path or none")
