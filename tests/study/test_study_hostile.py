"""Hostile participants against the study server: forged page ids, another participant's token,
replayed and changed submissions, oversized bodies, answers that do not fit the page, videos not played
to their end, path traversal in media URLs, the researcher's page without its password. Each is refused
and none changes the stored data. Also: ranged media (206, Content-Range), no system or speech name in
any page, URL or header, resuming after a reload, and an attention check failure ending the session."""

from __future__ import annotations

import json
import re

import pytest
from starlette.testclient import TestClient

import tests._study_standin as api
from gesturekit.study.server import COOKIE, MAX_BODY, create_app, parse_range
from gesturekit.study.store import open_store
from tests._study_standin import PASSWORD, SPEECHES, SYSTEMS, good_body, make_folder


@pytest.fixture
def study(tmp_path):
    folder = make_folder(tmp_path / "study", rows=2, max_failures=0)
    store = open_store(None, folder)
    app = create_app(folder, store=store, api=api)
    yield folder, store, app
    store.close()


def enter(app, pid="P1"):
    client = TestClient(app)
    r = client.get(f"/?PROLIFIC_PID={pid}&STUDY_ID=S&SESSION_ID=X")
    assert r.status_code == 200
    token = client.cookies[COOKIE]
    assert r.url.path == f"/p/{token}/"
    return client, token


def pages_of(app, token):
    server = app.state.study
    return server.to_answer(server.store.participant(token).row)


def snapshot(store):
    return store.responses_frame().to_json(), store.participants_frame().to_json()


def advance(client, app, token, n):
    for page in pages_of(app, token)[:n]:
        r = client.post(f"/p/{token}/pages/{page.id}", json=good_body(page))
        assert r.status_code == 200, r.text


def test_a_participant_goes_through_in_order_and_resumes_after_a_reload(study):
    folder, store, app = study
    client, token = enter(app)
    pages = pages_of(app, token)
    for i, page in enumerate(pages):
        html = client.get(f"/p/{token}/").text
        assert f"/p/{token}/pages/{page.id}" in html and f"Page {i + 1} of {len(pages)}" in html
        # a second browser tab of the same participant (reload) shows the same page
        assert client.get(f"/p/{token}/").text == html
        assert client.post(f"/p/{token}/pages/{page.id}", json=good_body(page)).json()["next"] == f"/p/{token}/"
    done = client.get(f"/p/{token}/").text
    assert "C0MPLETE" in done
    assert store.participants_frame()["status"].tolist() == ["finished"]
    # coming back through the entry link (the same Prolific session) gives the same participant
    again = TestClient(app).get("/?PROLIFIC_PID=P1&STUDY_ID=S&SESSION_ID=X")
    assert "C0MPLETE" in again.text and len(store.participants_frame()) == 1


def test_forged_foreign_replayed_and_oversized_submissions_are_refused_and_change_nothing(study):
    folder, store, app = study
    client, token = enter(app, "P1")
    other, other_token = enter(app, "P2")
    advance(client, app, token, 3)
    page = pages_of(app, token)[3]
    before = snapshot(store)
    body = good_body(page)
    cases = [
        # a forged page id, and one of another participant's pages
        (client, f"/p/{token}/pages/000000000000", body, 404),
        (client, f"/p/{token}/pages/{pages_of(app, other_token)[0].id}x", body, 404),
        # another participant's token with our cookie, and our token with theirs
        (client, f"/p/{other_token}/pages/{pages_of(app, other_token)[0].id}", {"answers": {}, "events": []}, 403),
        (other, f"/p/{token}/pages/{page.id}", body, 403),
        # a page already answered with another body, and a page ahead of the current one
        (client, f"/p/{token}/pages/{pages_of(app, token)[0].id}", {"answers": {}, "events": [], "elapsed_s": 1}, 409),
        (client, f"/p/{token}/pages/{pages_of(app, token)[4].id}", good_body(pages_of(app, token)[4]), 409),
        # oversized
        (client, f"/p/{token}/pages/{page.id}", {**body, "answers": {"x": "y" * MAX_BODY}}, 413),
        # videos not played to the end, answers that do not fit, junk
        (client, f"/p/{token}/pages/{page.id}", {**body, "events": body["events"][:-1]}, 422),
        (client, f"/p/{token}/pages/{page.id}", {**body, "answers": {page.media[0].id: {"natural": 9}}}, 422),
        (client, f"/p/{token}/pages/{page.id}", {**body, "elapsed_s": -1}, 422),
        (client, f"/p/{token}/pages/{page.id}", {**body, "admin": True}, 422),
        (client, f"/p/{token}/pages/{page.id}", [1, 2], 422),
    ]
    for who, url, payload, status in cases:
        r = who.post(url, json=payload)
        assert r.status_code == status, (url, payload if len(str(payload)) < 200 else "...", r.text)
        assert snapshot(store) == before
    # a body that lies about its length, streamed past the limit, and bytes that are no JSON
    big = b"{" + b" " * (MAX_BODY + 10) + b"}"
    r = client.post(f"/p/{token}/pages/{page.id}", content=iter([big]), headers={"content-type": "application/json"})
    assert r.status_code == 413
    assert client.post(f"/p/{token}/pages/{page.id}", content=b"\xff{").status_code == 400
    # no cookie at all
    assert TestClient(app).post(f"/p/{token}/pages/{page.id}", json=body).status_code == 403
    assert snapshot(store) == before
    # the honest submission, then its replay: acknowledged once, stored once
    assert client.post(f"/p/{token}/pages/{page.id}", json=body).status_code == 200
    stored = snapshot(store)
    assert client.post(f"/p/{token}/pages/{page.id}", json=body).status_code == 200
    assert snapshot(store) == stored


def test_failing_more_attention_checks_than_allowed_ends_the_session_without_a_code(study):
    folder, store, app = study
    client, token = enter(app)
    advance(client, app, token, 1)
    audio = pages_of(app, token)[1]
    assert client.post(f"/p/{token}/pages/{audio.id}", json=good_body(audio, fail=True)).status_code == 200
    page = client.get(f"/p/{token}/").text
    assert "session has ended" in page and "C0MPLETE" not in page
    people = store.participants_frame()
    assert people["status"].tolist() == ["failed_checks"] and people["failed_checks"].tolist() == [1]
    before = snapshot(store)
    nxt = pages_of(app, token)[2]
    assert client.post(f"/p/{token}/pages/{nxt.id}", json=good_body(nxt)).status_code == 409
    assert snapshot(store) == before


def test_media_are_served_by_id_with_ranges_and_nothing_else(study):
    folder, store, app = study
    client, token = enter(app)
    media = api.media_index(api.load_design(folder))
    mid, item = next((k, v) for k, v in media.items() if v.kind == "stimulus")
    data = item.path.read_bytes()
    whole = client.get(f"/p/{token}/m/{mid}")
    assert whole.status_code == 200 and whole.content == data
    assert whole.headers["content-type"] == "video/mp4" and "private" in whole.headers["cache-control"]
    part = client.get(f"/p/{token}/m/{mid}", headers={"Range": "bytes=100-199"})
    assert part.status_code == 206 and part.content == data[100:200]
    assert part.headers["content-range"] == f"bytes 100-199/{len(data)}"
    tail = client.get(f"/p/{token}/m/{mid}", headers={"Range": "bytes=-10"})
    assert tail.status_code == 206 and tail.content == data[-10:]
    assert client.get(f"/p/{token}/m/{mid}", headers={"Range": f"bytes={len(data)}-"}).status_code == 416
    for header in (whole.headers, part.headers):
        assert not {"last-modified", "etag", "content-disposition", "server"} & set(header)
    for bad in (
        "..%2Fdesign.json",
        "..%2F..%2Fetc%2Fpasswd",
        "%2Fetc%2Fpasswd",
        "design.json",
        mid + ".mp4",
        "manifest.csv",
    ):
        assert client.get(f"/p/{token}/m/{bad}").status_code == 404, bad
    assert client.get("/videos/" + item.path.name).status_code == 404
    assert client.get(f"/p/{token}/../design.json").status_code in (403, 404)
    # another browser, or nobody, gets no media by a participant's URL
    assert TestClient(app).get(f"/p/{token}/m/{mid}").status_code == 403


@pytest.mark.parametrize(
    "header,size,expect",
    [
        (None, 10, None),
        ("bytes=0-", 10, (0, 9)),
        ("bytes=2-4", 10, (2, 4)),
        ("bytes=5-100", 10, (5, 9)),
        ("bytes=-3", 10, (7, 9)),
        ("bytes=-30", 10, (0, 9)),
        ("bytes=10-", 10, ValueError),
        ("bytes=4-2", 10, ValueError),
        ("bytes=0-1,3-4", 10, ValueError),
        ("items=0-1", 10, ValueError),
        ("bytes=-", 10, ValueError),
    ],
)
def test_range_headers(header, size, expect):
    if expect is ValueError:
        with pytest.raises(ValueError):
            parse_range(header, size)
    else:
        assert parse_range(header, size) == expect


def test_no_page_url_or_header_names_a_system_or_a_speech(study):
    folder, store, app = study
    client, token = enter(app)
    seen = []
    for page in pages_of(app, token):
        r = client.get(f"/p/{token}/")
        seen += [r.text, json.dumps(dict(r.headers)), str(r.url)]
        for m in re.findall(r'src="([^"]+)"', r.text):
            media = client.get(m, headers={"Range": "bytes=0-0"})
            seen += [m, json.dumps(dict(media.headers))]
        s = client.post(f"/p/{token}/pages/{page.id}", json=good_body(page))
        seen += [s.text, json.dumps(dict(s.headers))]
    seen.append(client.get(f"/p/{token}/").text)
    text = "\n".join(seen).lower()
    for name in (*SYSTEMS, *SPEECHES, "manifest", "videos/", "checks/", str(folder).lower()):
        assert name not in text, name


def test_the_researcher_page_needs_the_password(study):
    folder, store, app = study
    client, token = enter(app)
    advance(client, app, token, 3)
    before = snapshot(store)
    anyone = TestClient(app)
    for auth in (None, ("r", "wrong"), ("r", "")):
        for url in ("/researcher", "/researcher/responses.csv"):
            r = anyone.get(url, auth=auth)
            assert r.status_code == 401 and "www-authenticate" in r.headers
            assert token not in r.text and "P1" not in r.text
    assert anyone.get("/researcher", headers={"Authorization": "Basic !!!"}).status_code == 401
    assert snapshot(store) == before
    page = anyone.get("/researcher", auth=("r", PASSWORD))
    assert page.status_code == 200 and "P1" in page.text and "active: 1" in page.text
    csv = anyone.get("/researcher/responses.csv", auth=("r", PASSWORD))
    assert csv.status_code == 200 and csv.text.splitlines()[0].startswith("token,row,page_id,page_index,kind,answers")
    assert len(csv.text.strip().splitlines()) == 4


def test_without_a_password_in_the_design_the_researcher_page_is_closed(tmp_path):
    folder = make_folder(tmp_path / "study")
    design = json.loads((folder / "design.json").read_text())
    design["researcher"]["password_sha256"] = None
    (folder / "design.json").write_text(json.dumps(design))
    store = open_store(None, folder)
    app = create_app(folder, store=store, api=api)
    assert TestClient(app).get("/researcher", auth=("r", PASSWORD)).status_code == 403
    store.close()


def test_entry_parameters_are_checked(study):
    folder, store, app = study
    r = TestClient(app).get("/?PROLIFIC_PID=<script>")
    assert r.status_code == 400 and "<script>" not in r.text
    assert len(store.participants_frame()) == 0
