"""The study server under hostile use, each case as measured against it before: a deeply nested body, a Basic
header of non-ASCII bytes, deleted or swapped media (a file outside the folder, a symlink), a Prolific id
taken over from another session, a flood of cookie-less entries, a guessed researcher password, oversized
headers. Each is refused with a 4xx (or refused at start, naming the files) and none changes the store."""

from __future__ import annotations

import base64
import os
from types import SimpleNamespace

import pytest
from starlette.testclient import TestClient

import tests._study_standin as standin
from gesturekit.errors import ConfigError
from gesturekit.study import server as S
from gesturekit.study.store import open_store
from tests._study_standin import PASSWORD, make_folder


@pytest.fixture
def study(tmp_path):
    folder = make_folder(tmp_path / "study", rows=3, max_failures=0)
    store = open_store(None, folder)
    app = S.create_app(folder, store=store, api=standin)
    yield folder, store, app
    store.close()


def _enter(app, pid="P1", study="S", session="X"):
    client = TestClient(app)
    r = client.get(f"/?PROLIFIC_PID={pid}&STUDY_ID={study}&SESSION_ID={session}")
    return client, r


def test_a_deeply_nested_body_is_a_400_not_a_500(study):
    folder, store, app = study
    client, _ = _enter(app)
    token = client.cookies[S.COOKIE]
    page = app.state.study.to_answer(store.participant(token).row)[0]
    r = client.post(f"/p/{token}/pages/{page.id}", content=b"[" * 20_000 + b"]" * 20_000)
    assert r.status_code == 400 and "nest" in r.json()["error"]
    assert len(store.responses_frame()) == 0


@pytest.mark.parametrize("raw", [b"Basic \xe9\xe9\xe9", b"Basic " + base64.b64encode(b"r:\xff\xfe")])
def test_a_basic_header_of_non_ascii_bytes_is_a_401(study, raw):
    _, _, app = study
    r = TestClient(app).get("/researcher", headers={"Authorization": raw})
    assert r.status_code == 401


def test_a_study_with_deleted_videos_refuses_to_start_naming_them(tmp_path):
    folder = make_folder(tmp_path / "study")
    gone = sorted((folder / "videos").iterdir())[:2]
    for f in gone:
        f.unlink()
    with pytest.raises(ConfigError) as err:
        S.create_app(folder, store=open_store(None, folder), api=standin)
    assert all(f.name in str(err.value) for f in gone) and "missing" in str(err.value)


def test_media_outside_the_folder_or_symlinked_are_refused_at_start(tmp_path):
    folder = make_folder(tmp_path / "study")
    outside = tmp_path / "secret.txt"
    outside.write_text("not for participants")
    video = sorted((folder / "videos").iterdir())[0]
    video.unlink()
    os.symlink(outside, video)
    with pytest.raises(ConfigError) as err:
        S.create_app(folder, store=open_store(None, folder), api=standin)
    assert video.name in str(err.value) and "symbolic link" in str(err.value)
    video.unlink()
    video.write_bytes(b"x" * 100)

    # a manifest naming /etc/passwd (the design joins an absolute path as it is)
    def media_index(design):
        media = standin.media_index(design)
        first = sorted(media)[0]
        media[first] = standin.Media(first, outside, "stimulus")
        return media

    api = SimpleNamespace(**{k: getattr(standin, k) for k in dir(standin) if not k.startswith("__")})
    api.media_index = media_index
    with pytest.raises(ConfigError) as err:
        S.create_app(folder, store=open_store(None, folder), api=api)
    assert "outside the study folder" in str(err.value) and "secret.txt" in str(err.value)


def test_a_file_swapped_for_a_symlink_after_start_is_not_served(study):
    folder, store, app = study
    client, _ = _enter(app)
    token = client.cookies[S.COOKIE]
    media_id, media = sorted(app.state.study.media.items())[0]
    assert client.get(f"/p/{token}/m/{media_id}").status_code == 200
    secret = folder.parent / "secret.txt"
    secret.write_text("root:x:0:0")
    media.path.unlink()
    os.symlink(secret, media.path)
    r = client.get(f"/p/{token}/m/{media_id}")
    assert r.status_code == 404 and "root:x" not in r.text


def test_a_prolific_id_resumes_only_with_its_own_study_and_session_ids(study):
    folder, store, app = study
    first, r = _enter(app, "P1", "S", "X")
    token = first.cookies[S.COOKIE]
    # the same participant from a fresh browser (same Prolific session): resumes
    again, r = _enter(app, "P1", "S", "X")
    assert again.cookies[S.COOKIE] == token
    # someone who knows the Prolific id only: refused, and the session is not handed out
    thief, r = _enter(app, "P1", "S", "OTHER")
    assert r.status_code == 409 and S.COOKIE not in thief.cookies and token not in r.text
    thief, r = _enter(app, "P1", "S2", "X")
    assert r.status_code == 409 and S.COOKIE not in thief.cookies
    assert len(store.participants_frame()) == 1


def test_entries_that_never_answer_stop_holding_their_order_row(study):
    folder, store, app = study
    for i in range(5):  # a flood of cookie-less entries that answer nothing
        _enter(app, f"F{i}")
    rows = sorted(store.participants_frame()["row"])
    assert rows == [1, 1, 2, 2, 3]  # while recent, they are held: simultaneous arrivals stay balanced
    # an hour later, they hold nothing: the next participant gets row 1 again, not row 1 of a shifted order
    with store._transaction(write=True) as cur:
        cur.execute("UPDATE participants SET started_at = %s", ("2000-01-01T00:00:00.000Z",))
    client, _ = _enter(app, "REAL")
    assert store.participant(client.cookies[S.COOKIE]).row == 1


def test_repeated_wrong_passwords_are_slowed_down(study):
    _, _, app = study
    clock = [1000.0]
    app.state.study.clock = lambda: clock[0]
    client = TestClient(app)
    for _ in range(S.PASSWORD_TRIES):
        assert client.get("/researcher", auth=("r", "guess")).status_code == 401
    # past the allowance even the right password waits
    r = client.get("/researcher", auth=("r", PASSWORD))
    assert r.status_code == 429 and int(r.headers["retry-after"]) > 0
    clock[0] += S.PASSWORD_WINDOW_S + 1
    assert client.get("/researcher", auth=("r", PASSWORD)).status_code == 200


def test_oversized_headers_are_refused(study):
    _, store, app = study
    r = TestClient(app).get("/?PROLIFIC_PID=P9", headers={"X-Padding": "a" * (S.MAX_HEADER_BYTES + 1)})
    assert r.status_code == 431
    assert len(store.participants_frame()) == 0
