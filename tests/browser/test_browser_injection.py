"""A hostile database in a real browser: its label and take name hold Markdown images and links that
point at a server this test listens on. The pages show that text as typed, and while they render,
no request reaches that server, nor leaves 127.0.0.1 at all (the page icon included).

Debian's Chromium driven by Playwright against ``streamlit run app/Home.py`` (see
tests/app_browser.py); skipped, with the reason, where either is missing.
"""

from __future__ import annotations

import contextlib
import http.server
import threading
from urllib.parse import urlparse

import pytest

from tests import app_browser
from tests.app.test_app_markup import markdown_database

pytestmark = pytest.mark.skipif(
    app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"
)

MAIN = '[data-testid="stMain"]'
SIDEBAR = '[data-testid="stSidebar"]'
LOCAL_HOSTS = {"127.0.0.1", "localhost"}


@contextlib.contextmanager
def recording_server():
    """An HTTP server on 127.0.0.1 that records every path asked of it; yields (base URL, hits)."""
    hits: list[str] = []

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:  # noqa: N802 (the name http.server calls)
            hits.append(self.path)
            self.send_response(404)
            self.end_headers()

        def log_message(self, *args) -> None:  # the test's output stays quiet
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}", hits
    finally:
        server.shutdown()
        server.server_close()


@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    """The app serving, as its default database, one whose label and first take's name are Markdown
    payloads aimed at the recording server; yields (app URL, payloads, hits)."""
    from gesturekit.demo import build_demo_database

    home = tmp_path_factory.mktemp("injection_home")
    scratch = tmp_path_factory.mktemp("injection_demo")
    build_demo_database(scratch / "demo", minutes=1)
    with recording_server() as (base, hits):
        payloads = {
            "label": f"![l]({base}/label.png) [c]({base}/click) <img src={base}/html.png> {base}/auto **y**",
            "take": f"![x]({base}/take.png)",
            "path": f"/srv/![p]({base}/path.png)",
        }
        # at the default path: every page opens it without a choice in the sidebar
        markdown_database(
            scratch / "demo", home / "db" / "demo", label=payloads["label"], take=payloads["take"], source="lab"
        )
        with app_browser.app_server(home) as url:
            yield url, payloads, hits


def _text(page, where: str) -> str:
    """The text shown in ``where``, without the invisible word joiners that keep bare links text."""
    return page.locator(where).first.inner_text().replace("\u2060", "")


def _no_markup_from(page, base: str) -> None:
    """No image, link or frame in the page points at ``base``."""
    for selector in (f'img[src^="{base}"]', f'a[href^="{base}"]', f'iframe[src^="{base}"]'):
        found = page.locator(selector)
        assert found.count() == 0, [
            found.nth(i).evaluate("e => e.parentElement.parentElement.outerHTML") for i in range(found.count())
        ]


def test_markdown_in_a_label_take_name_and_typed_path_is_shown_as_text_and_fetches_nothing(hostile):
    url, payloads, hits = hostile
    base = payloads["take"].split("(", 1)[1].rsplit("/", 1)[0]
    requested: list[str] = []
    with app_browser.browser() as page:
        page.on("request", lambda request: requested.append(request.url))

        app_browser.open_app(page, url, heading="gesturekit")
        page.locator(SIDEBAR).get_by_text("![l](http", exact=False).first.wait_for()
        assert payloads["label"] in _text(page, SIDEBAR)  # the database's label
        assert "Source: lab." in _text(page, MAIN)
        _no_markup_from(page, base)

        app_browser.go_to(page, "Database")
        main = page.locator(MAIN)
        main.get_by_text("take ![x](http", exact=False).first.wait_for()  # the clip's take
        assert payloads["label"] in _text(page, MAIN)  # the summary's label
        _no_markup_from(page, base)

        app_browser.go_to(page, "Synthesize")
        app_browser.synthesize_ready(page)
        app_browser.run_and_wait(page)
        app_browser.wait_idle(page)
        # a typed folder is echoed in the refusal as typed
        refiner = main.get_by_label("Refiner folder")
        if refiner.is_disabled():
            main.get_by_text("Refiner (cGAN)", exact=True).click()
            app_browser.wait_idle(page)
        refiner.fill(payloads["path"])
        refiner.press("Enter")
        error = main.locator(
            '[data-testid="stAlert"] [data-testid="stMarkdownContainer"]', has_text="outside the allowed folders"
        ).first
        error.wait_for()
        assert (
            error.inner_text()
            .replace("\u2060", "")
            .startswith(f"{payloads['path']}: the refiner folder is outside the allowed folders")
        )
        _no_markup_from(page, base)

        app_browser.go_to(page, "Retrieval inspector")
        main.get_by_text("take ![x](http", exact=False).first.wait_for()  # the step's chosen take
        assert f"take {payloads['take']} at" in _text(page, MAIN)
        app_browser.wait_idle(page)
        _no_markup_from(page, base)
        assert not app_browser.problems(page)

    assert hits == []
    away = [
        u for u in requested if urlparse(u).scheme not in ("data", "blob") and urlparse(u).hostname not in LOCAL_HOSTS
    ]
    assert away == []
    # the recording server's port was never asked for, not even a request that failed
    assert not [u for u in requested if u.startswith(base)]
