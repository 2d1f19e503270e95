"""The participant web server of a study: Starlette pages, videos with range requests, the researcher's view.

A participant arrives at the entry URL (``/?PROLIFIC_PID=..&STUDY_ID=..&SESSION_ID=..``), gets the next
free order row of the study and a token, kept in a cookie and in the page URLs
(``/p/<token>/``); the two must agree, so a token read off another screen opens
nothing. Each page is the participant's next unanswered one, so a reload or a
return resumes where they were. Answers are POSTed as JSON to
``/p/<token>/pages/<page id>`` and acknowledged once committed
(:mod:`.store`). The server refuses, and stores nothing for, a page id that is
not the participant's, a body over 64 KB, answers that do not fit the page, a
rating or pairwise page whose events lack an ``ended`` for one of its videos,
and another body for a page already answered. A participant who fails more
than ``max_failures`` attention checks is ended politely without the
completion code.

Media are served by opaque id only (``/p/<token>/m/<id>``: ids of the
study's media index; never a path), with HTTP range requests, no file name and
no modification time. No page, URL or header names a system or a speech.

``/researcher`` (HTTP Basic, the design's password; refused when the design has
none) lists who started, finished and failed checks, counts per stimulus and
per page, and offers the responses as CSV.
"""

from __future__ import annotations

import base64
import binascii
import contextlib
import html
import io
import json
import math
import os
import re
import stat
import time
from collections import Counter
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import anyio
import anyio.to_thread
from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.requests import Request
from starlette.responses import HTMLResponse, JSONResponse, RedirectResponse, Response, StreamingResponse
from starlette.routing import Route

from .._io import csv_safe
from ..errors import ConfigError, GestureKitError
from ..limits import parse_json
from .store import Store, open_store

MAX_BODY = 64 * 1024
#: request headers beyond this many bytes in all are refused (431): no participant's browser sends more
MAX_HEADER_BYTES = 16 * 1024
#: wrong researcher passwords allowed per client address within :data:`PASSWORD_WINDOW_S`; then 429
PASSWORD_TRIES = 10
PASSWORD_WINDOW_S = 60.0
DB_THREADS = 8
COOKIE = "gk_study"
EVENT_KINDS = ("play", "pause", "seeked", "ended")
_PARAM = re.compile(r"^[A-Za-z0-9_.-]{1,128}$")
_MEDIA_TYPES = {".mp4": "video/mp4", ".wav": "audio/wav", ".webm": "video/webm", ".m4a": "audio/mp4"}
_CHUNK = 1024 * 1024
TEMPLATES = Path(__file__).parent / "templates"


class _Refused(Exception):
    def __init__(self, status: int, message: str, headers: dict[str, str] | None = None) -> None:
        super().__init__(message)
        self.status, self.message, self.headers = status, message, headers or {}


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _integer(value: Any, lo: int, hi: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and lo <= value <= hi


def validate_submission(page: Any, body: Any, design: Any) -> tuple[dict, list, float | None]:
    """Check a POSTed body against its page; returns (answers, events, elapsed_s) or raises a refusal (422).

    Rating pages need every prompt of every media on the page (integers 1..7 or 0..100), pairwise pages a
    choice in -2..2, the audio check a count, questionnaires their questions; pages with media need an
    ``ended`` event for each of them."""
    if not isinstance(body, dict) or set(body) - {"answers", "events", "elapsed_s"}:
        raise _Refused(422, "the body is an object with answers, events and elapsed_s")
    answers, events, elapsed = body.get("answers", {}), body.get("events", []), body.get("elapsed_s")
    if not isinstance(answers, dict) or not isinstance(events, list):
        raise _Refused(422, "answers is an object and events a list")
    if elapsed is not None and not (_number(elapsed) and elapsed >= 0):
        raise _Refused(422, "elapsed_s is a number of seconds")
    media_ids = [m.id for m in page.media]
    for event in events:
        if (
            not isinstance(event, dict)
            or set(event) - {"t", "kind", "media", "at"}
            or event.get("kind") not in EVENT_KINDS
            or event.get("media") not in media_ids
            or not all(_number(event.get(k, 0)) for k in ("t", "at"))
        ):
            raise _Refused(422, "an event is {t, kind (play|pause|seeked|ended), media (a media of this page), at}")
    ended = {e["media"] for e in events if e["kind"] == "ended"}
    if page.kind in ("rating", "pairwise", "audio_check") and set(media_ids) - ended:
        raise _Refused(422, "every video of the page must be played to its end first")
    if page.kind == "rating":
        prompts = [pid for pid, _ in design.prompts]
        lo, hi = (0, 100) if design.scale == "slider100" else (1, 7)
        if set(answers) != set(media_ids):
            raise _Refused(422, "a rating page is answered for each of its videos")
        for value in answers.values():
            if not isinstance(value, dict) or set(value) != set(prompts):
                raise _Refused(422, "each video is rated on every prompt")
            if not all(_integer(v, lo, hi) for v in value.values()):
                raise _Refused(422, f"ratings are whole numbers {lo}..{hi}")
    elif page.kind == "pairwise":
        if set(answers) != {"choice"} or not _integer(answers["choice"], -2, 2):
            raise _Refused(422, "a pairwise page is answered by a choice in -2..2")
    elif page.kind == "audio_check":
        if set(answers) != {"count"} or not _integer(answers["count"], 0, 100):
            raise _Refused(422, "the audio check is answered by a count")
    elif page.kind == "questionnaire":
        questions = {q["id"]: q for q in design.questionnaire}
        if set(answers) - set(questions):
            raise _Refused(422, "an answer to no question of the questionnaire")
        for qid, q in questions.items():
            value = answers.get(qid)
            if value is None or value == "":
                if not q.get("optional", False):
                    raise _Refused(422, f"the question {qid!r} needs an answer")
            elif q["type"] == "number":
                if not _number(value) or not q.get("min", -math.inf) <= value <= q.get("max", math.inf):
                    raise _Refused(422, f"the answer to {qid!r} is a number in its range")
            elif q["type"] == "choice":
                if value not in q["options"]:
                    raise _Refused(422, f"the answer to {qid!r} is one of its options")
            elif not isinstance(value, str) or len(value) > 4000:
                raise _Refused(422, f"the answer to {qid!r} is a text of at most 4000 characters")
    elif answers:
        raise _Refused(422, f"a {page.kind} page has no answers")
    return answers, events, float(elapsed) if elapsed is not None else None


class StudyServer:
    """The state of one served study: its design, pages per order row, media and store."""

    def __init__(self, folder: str | os.PathLike[str], store: Store, api: Any = None) -> None:
        if api is None:
            from . import design as api
        self.folder = Path(folder)
        self.api = api
        self.design = api.load_design(self.folder)
        self.store = store
        self.rows = int(self.design.participants)
        self.media = api.media_index(self.design)
        check_media(self.folder, self.media)
        self.clock = time.monotonic
        self._failures: dict[str, list[float]] = {}
        self._pages: dict[int, list] = {}
        self._limiter = anyio.CapacityLimiter(DB_THREADS)
        import jinja2

        self.env = jinja2.Environment(
            loader=jinja2.FileSystemLoader(str(TEMPLATES)), autoescape=True, trim_blocks=True, lstrip_blocks=True
        )

    async def _db(self, call: Any, *args: Any) -> Any:
        """Run a store call in one of a few worker threads: each keeps its database connection, and a few
        connections serve many participants better than one per request on a small machine."""
        return await anyio.to_thread.run_sync(call, *args, limiter=self._limiter)

    def pages(self, row: int) -> list:
        if row not in self._pages:
            self._pages[row] = list(self.api.participant_pages(self.design, row))
        return self._pages[row]

    def to_answer(self, row: int) -> list:
        return [p for p in self.pages(row) if p.kind != "done"]

    def render(self, name: str, request: Request, status: int = 200, **context: Any) -> HTMLResponse:
        base = request.scope.get("root_path", "").rstrip("/")
        text = self.env.get_template(name).render(base=base, title=self.design.title, **context)
        return HTMLResponse(text, status_code=status, headers=_NO_STORE)

    # ------------------------------------------------------------ participants

    def _token(self, request: Request) -> str:
        token = request.path_params["token"]
        if not token or request.cookies.get(COOKIE) != token:
            raise _Refused(403, "this page belongs to another browser session")
        return token

    async def entry(self, request: Request) -> Response:
        base = request.scope.get("root_path", "").rstrip("/")
        cookie = request.cookies.get(COOKIE)
        if cookie and await self._db(self.store.participant, cookie) is not None:
            return RedirectResponse(f"{base}/p/{cookie}/", status_code=303)
        params = {}
        for key, name in (("PROLIFIC_PID", "prolific_pid"), ("STUDY_ID", "study_id"), ("SESSION_ID", "session_id")):
            value = request.query_params.get(key)
            if value is not None and not _PARAM.match(value):
                return self.render("message.html", request, 400, heading="Invalid link", text="Please check the link.")
            params[name] = value
        person, _ = await self._db(lambda: self.store.start(self.rows, **params))
        if person is None:  # the Prolific id is known, from another study or session: no takeover
            return self.render(
                "message.html",
                request,
                409,
                heading="Already started",
                text="This Prolific ID has started the study in another session. Please continue in the "
                "browser you started in, or contact the researcher.",
            )
        response = RedirectResponse(f"{base}/p/{person.token}/", status_code=303)
        response.set_cookie(
            COOKIE,
            person.token,
            max_age=14 * 24 * 3600,
            path=base + "/" if base else "/",
            httponly=True,
            samesite="lax",
            secure=request.url.scheme == "https",
        )
        return response

    async def page(self, request: Request) -> Response:
        token = self._token(request)
        person = await self._db(self.store.participant, token)
        if person is None:
            raise _Refused(404, "no such participant")
        if person.status == "failed_checks":
            return self.render("ended.html", request)
        pages = self.to_answer(person.row)
        if person.answered >= len(pages):
            await self._db(self.store.finish, token)
            return self.render("done.html", request, code=self.design.completion_code, redirect=self.design.redirect)
        page = pages[person.answered]
        config = {
            "submit": f"{request.scope.get('root_path', '').rstrip('/')}/p/{token}/pages/{page.id}",
            "kind": page.kind,
            "media": [m.id for m in page.media],
            "scale": self.design.scale,
            "prompts": [pid for pid, _ in self.design.prompts],
        }
        return self.render(
            "page.html",
            request,
            page=page,
            token=token,
            number=person.answered + 1,
            total=len(pages),
            design=self.design,
            config=config,
        )

    async def submit(self, request: Request) -> Response:
        token = self._token(request)
        length = request.headers.get("content-length")
        if length is not None and (not length.isdigit() or int(length) > MAX_BODY):
            raise _Refused(413, "the submission is too large")
        chunks, size = [], 0
        async for chunk in request.stream():
            size += len(chunk)
            if size > MAX_BODY:
                raise _Refused(413, "the submission is too large")
            chunks.append(chunk)
        try:
            body = parse_json(b"".join(chunks), what="the body ", error=ConfigError)
        except GestureKitError as exc:  # not JSON, not UTF-8, or nested deeper than any answer
            raise _Refused(400, exc.problem) from exc
        person = await self._db(self.store.participant, token)
        if person is None:
            raise _Refused(404, "no such participant")
        pages = self.to_answer(person.row)
        page = next((p for p in pages if p.id == request.path_params["page_id"]), None)
        if page is None:
            raise _Refused(404, "no such page")
        answers, events, elapsed = validate_submission(page, body, self.design)
        failed = self.api.check_answer(page, answers) is False
        max_failures = int(self.design.max_failures)
        result = await self._db(
            lambda: self.store.submit(
                token,
                page.id,
                page.index,
                page.kind,
                answers,
                events,
                elapsed,
                failed_check=failed,
                max_failures=max_failures,
                last=page is pages[-1],
            )
        )
        if result.outcome in ("stored", "same"):
            base = request.scope.get("root_path", "").rstrip("/")
            return JSONResponse({"ok": True, "next": f"{base}/p/{token}/"}, headers=_NO_STORE)
        if result.outcome == "unknown":
            raise _Refused(404, "no such participant")
        message = {
            "conflict": "this page was answered already",
            "out_of_order": "this is not the current page",
            "closed": "this session has ended",
        }[result.outcome]
        raise _Refused(409, message)

    async def media_file(self, request: Request) -> Response:
        token = self._token(request)
        media = self.media.get(request.path_params["media_id"])
        if media is None or await self._db(self.store.participant, token) is None:
            raise _Refused(404, "no such media")
        try:
            return ranged_file(Path(media.path), request.headers.get("range"), inside=self.folder)
        except (OSError, ValueError):  # swapped for a link, a folder or something outside since the start
            raise _Refused(404, "no such media") from None

    # ------------------------------------------------------------ researcher

    def _researcher(self, request: Request) -> None:
        stored = self.design.password_hash
        if not stored:
            raise _Refused(403, "the study has no researcher password: set one with gesturekit study init --password")
        client = request.client.host if request.client else "-"
        now = self.clock()
        recent = [t for t in self._failures.get(client, []) if now - t < PASSWORD_WINDOW_S]
        self._failures[client] = recent
        if len(recent) >= PASSWORD_TRIES:
            wait = max(1, math.ceil(PASSWORD_WINDOW_S - (now - recent[0])))
            raise _Refused(429, f"too many wrong passwords: try again in {wait} s", {"Retry-After": str(wait)})
        header = request.headers.get("authorization", "")
        password = None
        if header.lower().startswith("basic "):
            try:
                _, _, password = base64.b64decode(header[6:], validate=True).decode().partition(":")
            except (binascii.Error, ValueError):  # not base64, not ASCII, or not UTF-8 inside
                password = None
        if password is None or not self.api.verify_password(password, stored):
            if header:  # a wrong password (not a browser's first, bare request) counts against the address
                recent.append(now)
            raise _Refused(401, "the researcher's page needs the study's password")
        self._failures.pop(client, None)

    async def researcher(self, request: Request) -> Response:
        self._researcher(request)
        people = await self._db(self.store.participants_frame)
        responses = await self._db(self.store.responses_frame)
        status = Counter(people["status"]) if len(people) else Counter()
        stimulus: Counter = Counter()
        per_page: Counter = Counter()
        for _, r in responses.iterrows():
            per_page[(int(r["page_index"]), r["kind"])] += 1
            if r["kind"] == "rating":
                stimulus.update(k for k in r["answers"] if self.media.get(k) and self.media[k].kind == "stimulus")
            elif r["kind"] == "pairwise":
                page = next((p for p in self.pages(int(r["row"])) if p.id == r["page_id"]), None)
                stimulus.update(m.id for m in (page.media if page else ()) if m.kind == "stimulus")
        return self.render(
            "researcher.html",
            request,
            people=people.to_dict("records"),
            counts=status,
            stimulus=sorted(stimulus.items()),
            per_page=sorted(per_page.items()),
        )

    async def researcher_csv(self, request: Request) -> Response:
        self._researcher(request)
        frame = await self._db(self.store.responses_frame)
        frame = csv_safe(frame).assign(answers=frame["answers"].map(json.dumps), events=frame["events"].map(json.dumps))
        out = io.StringIO()
        frame.to_csv(out, index=False)
        return Response(
            out.getvalue(),
            media_type="text/csv",
            headers={**_NO_STORE, "Content-Disposition": 'attachment; filename="responses.csv"'},
        )


_NO_STORE = {"Cache-Control": "no-store", "X-Content-Type-Options": "nosniff", "Referrer-Policy": "no-referrer"}


def parse_range(header: str | None, size: int) -> tuple[int, int] | None:
    """The inclusive byte range ``(first, last)`` of a ``Range: bytes=..`` header for a file of ``size`` bytes.

    None without a header; raises ValueError for a range that is malformed, multiple or past the end."""
    if header is None:
        return None
    match = re.fullmatch(r"\s*bytes=(\d*)-(\d*)\s*", header)
    if match is None or match.group(1) == match.group(2) == "":
        raise ValueError(header)
    first, last = match.groups()
    if first == "":
        n = int(last)
        if n == 0 or size == 0:
            raise ValueError(header)
        return max(0, size - n), size - 1
    lo = int(first)
    hi = size - 1 if last == "" else min(int(last), size - 1)
    if lo >= size or hi < lo:
        raise ValueError(header)
    return lo, hi


def check_media(folder: Path, media: dict) -> None:
    """Refuse to serve a study whose media are missing, not regular files, symbolic links or outside it.

    Raises
    ------
    ConfigError
        Naming every such file (the study folder as the path).
    """
    root = folder.resolve()
    missing, linked, outside, odd = [], [], [], []
    for m in media.values():
        path = Path(m.path)
        try:
            st = os.lstat(path)
        except OSError:
            missing.append(path)
            continue
        if stat.S_ISLNK(st.st_mode):
            linked.append(path)
        elif not path.resolve().is_relative_to(root):
            outside.append(path)
        elif not stat.S_ISREG(st.st_mode):
            odd.append(path)
    problems = []
    for files, what in (
        (missing, "missing"),
        (linked, "symbolic links (only regular files of the folder are served)"),
        (outside, "outside the study folder"),
        (odd, "not regular files"),
    ):
        if files:
            named = ", ".join(str(f) for f in sorted(files)[:10]) + (
                f" and {len(files) - 10} more" if len(files) > 10 else ""
            )
            problems.append(f"{len(files)} media {what}: {named}")
    if problems:
        raise ConfigError("cannot serve the study: " + "; ".join(problems), path=folder)


def _open_regular(path: Path, inside: Path | None) -> tuple[Any, int]:
    """``path`` opened for reading if it is a regular file (no symbolic link) inside ``inside``; (file, size).

    Raises OSError (a link: ELOOP) or ValueError (not regular, or outside)."""
    if inside is not None and not path.resolve().is_relative_to(inside.resolve()):
        raise ValueError(f"{path} is outside {inside}")
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
    f = os.fdopen(fd, "rb")
    st = os.fstat(f.fileno())
    if not stat.S_ISREG(st.st_mode):
        f.close()
        raise ValueError(f"{path} is not a regular file")
    return f, st.st_size


def ranged_file(path: Path, range_header: str | None, *, inside: Path | None = None) -> Response:
    """A file as a 200 or, for a ``Range`` request, a 206 with ``Content-Range`` (416 when unsatisfiable).

    Only a regular file is served, never through a symbolic link, and, given ``inside``, only one that
    lies in that folder once resolved (OSError or ValueError otherwise). Cached privately; no file name,
    ETag or modification time is sent."""
    f, size = _open_regular(path, inside)
    headers = {
        "Accept-Ranges": "bytes",
        "Cache-Control": "private, max-age=3600",
        "X-Content-Type-Options": "nosniff",
        "Content-Type": _MEDIA_TYPES.get(path.suffix.lower(), "application/octet-stream"),
    }
    try:
        span = parse_range(range_header, size)
    except ValueError:
        f.close()
        return Response(status_code=416, headers={**headers, "Content-Range": f"bytes */{size}"})
    first, last = span if span is not None else (0, size - 1)
    headers["Content-Length"] = str(max(0, last - first + 1))
    if span is not None:
        headers["Content-Range"] = f"bytes {first}-{last}/{size}"

    def chunks() -> Iterator[bytes]:
        with f:
            f.seek(first)
            left = last - first + 1
            while left > 0:
                data = f.read(min(_CHUNK, left))
                if not data:
                    break
                left -= len(data)
                yield data

    return StreamingResponse(chunks(), status_code=206 if span is not None else 200, headers=headers)


class _HeaderLimit:
    """Refuse (431) a request whose headers exceed :data:`MAX_HEADER_BYTES` in all, before any handler runs."""

    def __init__(self, app: Any) -> None:
        self.app = app

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] == "http" and sum(len(k) + len(v) for k, v in scope["headers"]) > MAX_HEADER_BYTES:
            response = Response("request headers too large", status_code=431, headers=_NO_STORE)
            await response(scope, receive, send)
            return
        await self.app(scope, receive, send)


def create_app(
    folder: str | os.PathLike[str], *, db: str | None = None, store: Store | None = None, api: ModuleType | Any = None
) -> Starlette:
    """The study's web application (ASGI).

    Parameters
    ----------
    folder : path
        The study folder, with ``design.json``.
    db : str or None
        The response store's URL (:func:`.store.open_store`); None: SQLite in the folder.
    store : Store or None
        An open store instead of ``db``.
    api : module or None
        What reads the design (``load_design``, ``participant_pages``, ``media_index``, ``check_answer``,
        ``verify_password``); default :mod:`gesturekit.study.design`.

    Returns
    -------
    starlette.applications.Starlette
    """
    server = StudyServer(folder, store if store is not None else open_store(db, folder), api)

    def guarded(handler: Any) -> Any:
        async def endpoint(request: Request) -> Response:
            try:
                return await handler(request)
            except _Refused as refusal:
                headers = {**_NO_STORE, **refusal.headers}
                if refusal.status == 401:
                    headers["WWW-Authenticate"] = 'Basic realm="study", charset="UTF-8"'
                if request.method == "POST":
                    return JSONResponse({"ok": False, "error": refusal.message}, refusal.status, headers=headers)
                text = f"<!doctype html><title>{refusal.status}</title><p>{html.escape(refusal.message)}</p>"
                return HTMLResponse(text, refusal.status, headers=headers)

        return endpoint

    routes = [
        Route("/", guarded(server.entry)),
        Route("/p/{token}/", guarded(server.page)),
        Route("/p/{token}/pages/{page_id}", guarded(server.submit), methods=["POST"]),
        Route("/p/{token}/m/{media_id}", guarded(server.media_file)),
        Route("/researcher", guarded(server.researcher)),
        Route("/researcher/responses.csv", guarded(server.researcher_csv)),
    ]

    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        yield
        server.store.close()

    app = Starlette(routes=routes, lifespan=lifespan, middleware=[Middleware(_HeaderLimit)])
    app.state.study = server
    return app


def serve(
    folder: str | os.PathLike[str],
    *,
    host: str = "127.0.0.1",
    port: int = 8000,
    db: str | None = None,
    root_path: str = "",
    forwarded_allow_ips: str = "127.0.0.1",
) -> None:
    """Serve the study with uvicorn until stopped (one process: the store's locks are per process).

    Parameters
    ----------
    folder : path
    host : str
        Address to bind: 127.0.0.1 (this machine only) unless told otherwise.
    port : int
    db : str or None
        The response store's URL; None: SQLite in the folder.
    root_path : str
        The URL prefix a reverse proxy serves the study under (e.g. ``/study``).
    forwarded_allow_ips : str
        Proxies whose ``X-Forwarded-*`` headers are trusted.
    """
    import uvicorn

    app = create_app(folder, db=db)
    uvicorn.run(
        app,
        host=host,
        port=port,
        root_path=root_path,
        proxy_headers=True,
        forwarded_allow_ips=forwarded_allow_ips,
        server_header=False,
        log_level="warning",
        h11_max_incomplete_event_size=MAX_HEADER_BYTES,
    )
