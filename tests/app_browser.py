"""Drive the app in a real browser: start ``streamlit run app/Home.py``, open it in Chromium, upload, run.

Shared by ``tests/test_browser.py`` and ``bench/bench_app.py``, and the maker
of the README's screenshots::

    python -m tests.app_browser --out docs/screenshots

Chromium is Debian's (``apt-get install chromium``), driven through the
``playwright`` Python package; Playwright's own browser downloads are not
used. The server runs from the repository root (so it reads the app's
``.streamlit/config.toml``, as a user's does) on 127.0.0.1 on a free port,
with ``GESTUREKIT_HOME`` in a folder of the caller's choosing, so it never
touches the user's databases.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
HOME_SCRIPT = REPO / "app" / "Home.py"

#: Where Debian puts Chromium (the wrapper script first, then the binary itself).
CHROMIUM_PATHS = ("/usr/bin/chromium", "/usr/lib/chromium/chromium", "/usr/bin/chromium-browser")

#: Flags for a headless Chromium that reaches nothing but the app.
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
)

#: Seconds to wait for the server, a page, or a result.
TIMEOUT_S = 120


def find_chromium() -> str | None:
    """The Chromium executable: ``$GESTUREKIT_CHROMIUM`` or Debian's, None when there is none."""
    env = os.environ.get("GESTUREKIT_CHROMIUM")
    candidates = ([env] if env else []) + list(CHROMIUM_PATHS) + [shutil.which("chromium") or ""]
    for c in candidates:
        if c and os.path.isfile(c) and os.access(c, os.X_OK):
            return c
    return None


def unavailable() -> str | None:
    """Why the browser cannot be driven here (a sentence), or None when it can."""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "the playwright Python package is not installed (pip install playwright)"
    if find_chromium() is None:
        return "Chromium is not installed (apt-get install chromium), nor named by $GESTUREKIT_CHROMIUM"
    return None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def app_server(home: Path, *, demo_minutes: float | None = None, log: Path | None = None) -> Iterator[str]:
    """Run the app on 127.0.0.1 until the block ends; yields its base URL.

    Parameters
    ----------
    home : Path
        ``GESTUREKIT_HOME`` of the server (its demo database is built there
        on the first page view if it is missing).
    demo_minutes : float, optional
        ``GESTUREKIT_DEMO_MINUTES``: the size of a demo database built by the app.
    log : Path, optional
        File for the server's output; default a file in ``home``.
    """
    port = _free_port()
    env = dict(os.environ, GESTUREKIT_HOME=str(home))
    if demo_minutes is not None:
        env["GESTUREKIT_DEMO_MINUTES"] = f"{demo_minutes:g}"
    log = log or Path(home) / "streamlit.log"
    cmd = [
        sys.executable,
        "-m",
        "streamlit",
        "run",
        str(HOME_SCRIPT),
        "--server.address",
        "127.0.0.1",
        "--server.port",
        str(port),
        "--server.headless",
        "true",
        "--browser.gatherUsageStats",
        "false",
        "--server.fileWatcherType",
        "none",
        "--global.developmentMode",
        "false",
    ]
    with open(log, "wb") as out:
        # from the repository root, as a user starts it: Streamlit reads ./.streamlit/config.toml
        # (the viewer toolbar, error details kept to the log), so the tests see what a user sees
        proc = subprocess.Popen(
            cmd, env=env, cwd=str(REPO), stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL
        )
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + TIMEOUT_S
        while True:
            if proc.poll() is not None:
                raise RuntimeError(
                    f"streamlit exited with {proc.returncode}:\n{log.read_text(errors='replace')[-3000:]}"
                )
            try:
                with urllib.request.urlopen(f"{url}/_stcore/health", timeout=2) as r:
                    if r.status == 200:
                        break
            except OSError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError(
                    f"streamlit did not answer within {TIMEOUT_S} s:\n{log.read_text(errors='replace')[-3000:]}"
                )
            time.sleep(0.2)
        yield url
    finally:
        stop(proc)


def stop(proc: subprocess.Popen) -> None:
    """End a server started by a test: politely, then by force after 20 s."""
    proc.terminate()
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


@contextlib.contextmanager
def browser(*, width: int = 1440, height: int = 1000):
    """A Playwright page in a fresh headless Chromium; yields the page."""
    from playwright.sync_api import sync_playwright

    exe = find_chromium()
    if exe is None:
        raise RuntimeError(unavailable())
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=exe, args=list(CHROMIUM_FLAGS))
        try:
            page = b.new_page(viewport={"width": width, "height": height})
            page.set_default_timeout(TIMEOUT_S * 1000)
            yield page
        finally:
            b.close()


def write_speech(path: Path, *, seconds: float, seed: int = 4242) -> Path:
    """Write generated speech of the demo speaker (unseen by the demo database) as a 16-bit WAV."""
    import soundfile as sf

    from gesturekit.datasets.synthetic import generate_demo_take

    take, _ = generate_demo_take(seconds=seconds, seed=seed, name="speech")
    sf.write(str(path), take.audio, 16000, subtype="PCM_16")
    return path


def wait_idle(page) -> None:
    """Wait until the app has finished its current script run.

    Streamlit marks its root element with the script state; a run started
    by the last action may take a moment to begin, hence the short pause first.
    """
    page.wait_for_timeout(300)
    page.wait_for_selector('[data-testid="stApp"][data-test-script-state="notRunning"]', state="attached")


def open_app(page, url: str, path: str = "", *, heading: str) -> None:
    """Open a page of the app and wait for its title (the demo database may be built first)."""
    page.goto(f"{url}/{path}")
    page.get_by_role("heading", name=heading, exact=True).first.wait_for()
    wait_idle(page)


def go_to(page, title: str) -> None:
    """Switch page within the session through the sidebar navigation (keeps the user's state)."""
    page.locator('[data-testid="stSidebarNav"] a', has_text=title).first.click()
    page.get_by_role("heading", name=title, exact=True).first.wait_for()
    wait_idle(page)


def upload(page, wav: Path) -> None:
    """Upload a speech file on the Synthesize page and wait until it has been read.

    The page names the speech it works on in a caption below the uploader
    (the uploader's own list shows the name as soon as the file is chosen).
    The run may still be drawing the rest of the page (the new waveform):
    :func:`box_select` waits for its end.
    """
    page.locator('[data-testid="stFileUploader"] input[type="file"]').set_input_files(str(wav))
    page.locator('[data-testid="stCaptionContainer"] strong', has_text=wav.name).first.wait_for()
    page.get_by_role("button", name="Run", exact=True).wait_for()


def synthesize_ready(page) -> None:
    """Wait until the Synthesize page is drawn whole: its waveform chart, the segment table and Run."""
    page.locator('[data-testid="stPlotlyChart"] .main-svg').first.wait_for(state="visible")
    page.locator('[data-testid="stDataFrame"] canvas').first.wait_for(state="attached")
    page.get_by_role("button", name="Run", exact=True).wait_for()


def box_select(page, start_frac: float, end_frac: float, *, label: str = "both_hands=high", tries: int = 3) -> None:
    """Drag across the waveform chart (the first chart of the Synthesize page) between two fractions
    of its plot area's width, and wait until the band ``label`` of the new segment is drawn on it.

    A drag on a chart that a run is about to replace (the page still drawing, say, the waveform of
    speech just uploaded) is lost with that chart: the drag starts only once the page is idle, and
    is made again when no band appears. The band must not be on the chart before.
    """
    chart = page.locator('[data-testid="stPlotlyChart"]').first
    band = chart.locator("text", has_text=label).first
    for _ in range(tries):
        wait_idle(page)
        drag = chart.locator("rect.nsewdrag").first  # the plot area (not the legend, nor the toolbar)
        drag.wait_for(state="visible")
        drag.scroll_into_view_if_needed()
        box = drag.bounding_box()
        y = box["y"] + box["height"] / 2
        page.mouse.move(box["x"] + box["width"] * start_frac, y)
        page.mouse.down()
        page.mouse.move(box["x"] + box["width"] * (start_frac + end_frac) / 2, y, steps=5)
        page.mouse.move(box["x"] + box["width"] * end_frac, y, steps=5)
        page.mouse.up()
        try:
            band.wait_for(state="visible", timeout=30_000)
        except Exception:  # noqa: BLE001  (a playwright timeout: the selection was lost, drag again)
            continue
        wait_idle(page)
        return
    raise RuntimeError(f"no band {label!r} on the waveform after {tries} drags across it")


def run_and_wait(page) -> None:
    """Click Run and wait for the first result: the 3D view drawn and the wrist plot."""
    page.get_by_role("button", name="Run", exact=True).click()
    wait_result(page)


def skeleton_canvas(page, key: str):
    """The canvas of the skeleton viewer with key ``key`` (gesturekit.viz.viewer), once it has drawn."""
    frame = page.frame_locator(f"iframe[srcdoc*='data-key=\"{key}\"']")
    frame.locator('body[data-drawn="1"]').wait_for(state="attached")
    canvas = frame.locator("canvas#c")
    canvas.wait_for(state="visible")
    return canvas


def viewer_frame(page, key: str):
    """The frame (Playwright ``Frame``) of the skeleton viewer with key ``key``, once it has drawn.

    Its script's global ``gk`` holds the shown ``frame``, ``frames`` (how many it holds), the
    clock ``time``, the speech's ``audioTime``, ``playing``, ``drawn`` and ``drawMs``.
    """
    skeleton_canvas(page, key)
    for frame in page.frames:
        try:
            if frame.evaluate("() => document.body && document.body.dataset.key") == key:
                return frame
        except Exception:  # noqa: BLE001 (a frame navigating away; look at the next)
            continue
    raise RuntimeError(f"no skeleton viewer frame with key {key!r}")


def wait_result(page) -> None:
    skeleton_canvas(page, "synth.skeleton")
    page.locator('[data-testid="stPlotlyChart"] text', has_text="left wrist height").first.wait_for(state="visible")


def problems(page) -> list[str]:
    """Exception boxes and tracebacks on the page (empty when there are none)."""
    out = [e.inner_text() for e in page.locator('[data-testid="stException"]').all()]
    body = page.inner_text("body")
    if "Traceback" in body:
        out.append(body[body.index("Traceback") :][:2000])
    return out


def _fit_viewport(page, *, width: int = 1440, most: int = 6000) -> None:
    """Make the window as tall as the page's content, so a screenshot holds all of it.

    Streamlit scrolls its main area inside the window, so a "full page"
    screenshot of the document would show only one window's height.
    """
    page.set_viewport_size({"width": width, "height": 1000})
    height = page.evaluate(
        "() => { const m = document.querySelector('[data-testid=\"stMain\"]');"
        " return m ? m.scrollHeight : document.documentElement.scrollHeight; }"
    )
    page.set_viewport_size({"width": width, "height": int(min(max(height, 600), most))})
    wait_idle(page)


def screenshot(page, path: Path) -> Path:
    """Save a PNG of the whole page (the window is made as tall as the content first)."""
    _fit_viewport(page)
    page.wait_for_timeout(1000)  # let the WebGL views draw at the new size
    part = path.with_name(f".{path.name}.part")
    page.screenshot(path=str(part), type="png")
    os.replace(part, path)  # a screenshot appears whole or not at all
    page.set_viewport_size({"width": 1440, "height": 1000})
    return path


def viewer_screenshot(page, key: str, path: Path, *, at: float = 0.4) -> Path:
    """Save a PNG of the 3D view with key ``key`` alone, showing the frame ``at`` of the way through."""
    view = viewer_frame(page, key)
    view.evaluate(
        """(at) => { const s = document.getElementById("s");
        s.value = String(Math.round(at * Number(s.max))); s.dispatchEvent(new Event("input")); }""",
        at,
    )
    element = page.locator(f"iframe[srcdoc*='data-key=\"{key}\"']").first
    element.scroll_into_view_if_needed()
    page.wait_for_timeout(300)
    part = path.with_name(f".{path.name}.part")
    element.screenshot(path=str(part), type="png")
    os.replace(part, path)
    return path


def make_screenshots(out: Path, *, seconds: float = 12.0, demo_minutes: float = 3.0) -> list[Path]:
    """Screenshots of the Synthesize, Retrieval inspector and Database pages, written to ``out``.

    The app runs on a fresh demo database of ``demo_minutes`` in a temporary
    home; the Synthesize page gets ``seconds`` of generated speech with one
    box-selected control segment.
    """
    shots = []
    with _result_page(out, seconds=seconds, demo_minutes=demo_minutes, box=(0.3, 0.55)) as page:
        for name, title in (
            ("synthesize", None),
            ("retrieval_inspector", "Retrieval inspector"),
            ("database", "Database"),
        ):
            if title is not None:
                go_to(page, title)
            if problems(page):
                raise RuntimeError(f"the {name} page shows an error: {problems(page)[0][:500]}")
            shots.append(screenshot(page, out / f"{name}.png"))
    return shots


def make_viewer_screenshots(out: Path, *, seconds: float = 12.0, demo_minutes: float = 3.0) -> list[Path]:
    """Screenshots of the 3D view alone, written to ``out``: ``viewer_synthesize.png`` (a result's
    k-NN and refined motions side by side) and ``viewer_database.png`` (one clip of the demo database)."""
    with _result_page(out, seconds=seconds, demo_minutes=demo_minutes) as page:
        shots = [viewer_screenshot(page, "synth.skeleton", out / "viewer_synthesize.png")]
        go_to(page, "Database")
        shots.append(viewer_screenshot(page, "db.skeleton", out / "viewer_database.png", at=0.5))
        if problems(page):
            raise RuntimeError(f"the page shows an error: {problems(page)[0][:500]}")
    return shots


@contextlib.contextmanager
def _result_page(out: Path, *, seconds: float, demo_minutes: float, box: tuple[float, float] | None = None):
    """A browser page on Synthesize with a result of ``seconds`` of generated speech (one
    box-selected control segment over the fractions ``box`` of the waveform, if given), served
    from a fresh demo database of ``demo_minutes`` in a temporary home; ``out`` is created."""
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="gesturekit-shots-") as tmp:
        home = Path(tmp)
        wav = write_speech(home / "speech.wav", seconds=seconds)
        with app_server(home, demo_minutes=demo_minutes) as url, browser() as page:
            open_app(page, url, "Synthesize", heading="Synthesize")
            upload(page, wav)
            if box is not None:
                box_select(page, *box)
            run_and_wait(page)
            wait_idle(page)
            yield page


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Screenshots of the app's pages for the README.")
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "screenshots")
    args = parser.parse_args(argv)
    reason = unavailable()
    if reason:
        print(f"cannot make screenshots: {reason}", file=sys.stderr)
        return 1
    for p in make_screenshots(args.out) + make_viewer_screenshots(args.out):
        print(p)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
