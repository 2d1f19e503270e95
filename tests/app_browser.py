"""Drive the app in a real browser: start ``streamlit run app/Home.py``, open it in Chromium, upload, run.

Shared by ``tests/browser/test_browser.py`` and ``bench/bench_app.py``, and the maker
of the docs' screenshots::

    python -m tests.app_browser --out docs/screenshots
    python -m tests.app_browser --front docs/images/app.jpg     # the README's picture
    python -m tests.app_browser --laptop docs/screenshots/laptop # every page at 1280x800 and 1920x1080,
                                                                  # a CLI MP4's frames at three times, and
                                                                  # the control timeline and inspector closer
    python -m tests.app_browser --timeline docs/screenshots/laptop # only the last two

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
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import urllib.request
from collections.abc import Iterator
from pathlib import Path

from tests.waits import patience, wait_until

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

#: Seconds to wait for the server, a page, or a result: a deadline that ends a hang (tests/waits.py).
TIMEOUT_S = patience(180)

try:  # Playwright's assertions (expect) wait 5 s unless told: as long as a page's waits, here
    from playwright.sync_api import expect as _expect

    _expect.set_options(timeout=TIMEOUT_S * 1000)
except ImportError:  # the browser tests skip, with the reason (unavailable)
    pass

#: The page shows no script run: the app's script state, and Streamlit's status widget gone (while a
#: run lasts, the header shows it: "Running…" and a Stop button of Streamlit's own).
_IDLE = """() => { const app = document.querySelector('[data-testid="stApp"]');
  return !!app && app.dataset.testScriptState === "notRunning"
    && !document.querySelector('[data-testid="stStatusWidget"]'); }"""

#: Resolves once the page has painted twice more: what it had to draw is on screen.
_PAINTED = "() => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)))"


#: Follows the app's script runs as its server tells the page, in ``window.__gkRuns``: ``started``
#: counts the runs begun (a ForwardMsg ``new_session``), ``running`` is false once one has ended
#: (``script_finished``, unless ended early by ``st.rerun``: the next one follows at once). Read from
#: the top-level fields of each message on the app's websocket, before the app handles it.
#: The page's own script state cannot count runs: a busy browser may take a run's first and last
#: messages in one go and never show it running; and a widget's change reaches the server before
#: the page shows any run, so "not running" may still be the state from before the change.
_RUN_LOG = """(() => {
  const runs = window.__gkRuns = {started: 0, running: false};
  const NEW_SESSION = 4, SCRIPT_FINISHED = 6, FINISHED_EARLY_FOR_RERUN = 2;  // ForwardMsg.proto
  const varint = (b, i) => {
    let v = 0, s = 1, x;
    do { x = b[i++]; v += (x & 0x7f) * s; s *= 128; } while (x & 0x80 && i < b.length);
    return [v, i];
  };
  const look = (buffer) => {
    const b = new Uint8Array(buffer);
    let i = 0, tag, n;
    while (i < b.length) {
      [tag, i] = varint(b, i);
      const field = Math.floor(tag / 8), wire = tag % 8;
      if (field === NEW_SESSION) { runs.started += 1; runs.running = true; return; }
      if (field === SCRIPT_FINISHED) {
        if (varint(b, i)[0] !== FINISHED_EARLY_FOR_RERUN) runs.running = false;
        return;
      }
      if (wire === 2) { [n, i] = varint(b, i); i += n; }
      else if (wire === 0) { i = varint(b, i)[1]; }
      else return;
    }
  };
  const Native = window.WebSocket;
  window.WebSocket = class extends Native {
    constructor(url, protocols) {
      super(url, protocols);
      if (String(url).endsWith("/_stcore/stream")) {
        this.addEventListener("message", (e) => { if (e.data instanceof ArrayBuffer) look(e.data); });
      }
    }
  };
})();"""


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
def app_server(
    home: Path,
    *,
    demo_minutes: float | None = None,
    log: Path | None = None,
    gesturekit: Path | None = None,
    env: dict[str, str] | None = None,
) -> Iterator[str]:
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
    gesturekit : Path, optional
        A ``gesturekit`` executable (an installed package's): the server is its ``gesturekit app``,
        started in ``home``, instead of ``streamlit run app/Home.py`` from the repository root.
    env : dict, optional
        The server's environment (default this process's).
    """
    port = _free_port()
    env = dict(os.environ if env is None else env, GESTUREKIT_HOME=str(home))
    if demo_minutes is not None:
        env["GESTUREKIT_DEMO_MINUTES"] = f"{demo_minutes:g}"
    log = log or Path(home) / "streamlit.log"
    cwd = REPO
    # from the repository root, as a user starts it: Streamlit reads ./.streamlit/config.toml
    # (the viewer toolbar, error details kept to the log), so the tests see what a user sees
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
    if gesturekit is not None:  # the command carries the same settings itself, from any folder
        cmd, cwd = [str(gesturekit), "app", "--port", str(port)], Path(home)
    with open(log, "wb") as out:
        proc = subprocess.Popen(
            cmd, env=env, cwd=str(cwd), stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL
        )
    url = f"http://127.0.0.1:{port}"

    def healthy() -> bool:
        try:
            with urllib.request.urlopen(f"{url}/_stcore/health", timeout=patience(10)) as r:
                return r.status == 200
        except OSError:
            return False

    def exited() -> str | None:
        return None if proc.poll() is None else f"it exited with {proc.returncode}"

    try:
        try:
            wait_until(healthy, what="streamlit answers", timeout_s=180, interval_s=0.2, give_up=exited)
        except AssertionError as e:
            raise RuntimeError(f"{e}:\n{log.read_text(errors='replace')[-3000:]}") from None
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
def browser(*, width: int = 1440, height: int = 1000, flags: tuple[str, ...] = ()):
    """A Playwright page in a fresh headless Chromium (with ``flags`` added to its own); yields the page.

    The app's script runs are followed as they come (see :func:`run_after`).
    """
    from playwright.sync_api import sync_playwright

    exe = find_chromium()
    if exe is None:
        raise RuntimeError(unavailable())
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=exe, args=list(CHROMIUM_FLAGS) + list(flags))
        try:
            page = b.new_page(viewport={"width": width, "height": height})
            page.set_default_timeout(TIMEOUT_S * 1000)
            page.add_init_script(_RUN_LOG)
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


def main_area(page):
    """The app's page itself (``stMain``): not the sidebar, nor Streamlit's header, whose toolbar
    shows buttons of Streamlit's own (a Stop while a run lasts)."""
    return page.locator('[data-testid="stMain"]')


def sidebar(page):
    """The app's sidebar (the database chooser, the page navigation)."""
    return page.locator('[data-testid="stSidebar"]')


def key_class(key: str) -> str:
    """The class Streamlit gives the element of widget key ``key``: ``st-key-`` and the key, each
    character other than a letter, digit, ``_`` or ``-`` written as ``-`` (as its frontend does)."""
    return "st-key-" + re.sub(r"[^a-zA-Z0-9_-]", "-", key.strip())


def keyed(page, key: str):
    """The element of widget key ``key`` (its container, with the widget inside)."""
    return page.locator(f".{key_class(key)}")


def remounted(page, key: str):
    """The element of a widget whose key ``app/state.remount_key`` numbers: ``key``, then ``key.1``,
    ``key.2`` ... each time the page draws the widget anew (the Synthesize page's control table)."""
    cls = key_class(key)
    return page.locator(f'.{cls}, [class*="{cls}-"]')


def button(page, key: str):
    """The button of widget key ``key``."""
    return keyed(page, key).locator("button")


def heading(page, name: str):
    """The page's heading ``name`` (in the main area)."""
    return main_area(page).get_by_role("heading", name=name, exact=True).first


def _caught_up(page) -> None:
    """The page has drawn what the server sent: it shows no run, and has painted since."""
    page.wait_for_function(_IDLE)
    page.evaluate(_PAINTED)


def wait_idle(page) -> None:
    """Wait until the app has no script run going, and the page has drawn the last one's end.

    After an action that starts a run, use :func:`run_after` instead: the server begins the
    action's run a moment later, and the app is "idle" until then.
    """
    page.wait_for_function("() => !window.__gkRuns.running")
    _caught_up(page)


def runs_seen(page) -> int:
    """How many script runs the app has begun for the page so far."""
    return int(page.evaluate("() => window.__gkRuns.started"))


def wait_run(page, since: int, *, timeout_s: float = TIMEOUT_S) -> None:
    """Wait until a run begun after the count ``since`` (:func:`runs_seen`) has ended, and the page has drawn it."""
    page.wait_for_function(
        "(since) => window.__gkRuns.started > since && !window.__gkRuns.running", arg=since, timeout=timeout_s * 1000
    )
    _caught_up(page)


def wait_run_begun(page, since: int, *, timeout_s: float = TIMEOUT_S) -> None:
    """Wait until a run begun after the count ``since`` (:func:`runs_seen`)."""
    page.wait_for_function("(since) => window.__gkRuns.started > since", arg=since, timeout=timeout_s * 1000)


@contextlib.contextmanager
def run_after(page):
    """Around an action that starts a script run: waits for the app to be idle before it (so the
    action's run is a new one), then for a run begun after it to end."""
    wait_idle(page)
    since = runs_seen(page)
    yield
    wait_run(page, since)


def open_app(page, url: str, path: str = "", *, heading: str) -> None:
    """Open a page of the app and wait for its title (the demo database may be built first)."""
    page.goto(f"{url}/{path}")
    main_area(page).get_by_role("heading", name=heading, exact=True).first.wait_for()
    wait_idle(page)  # the title is drawn by the page's first run: what is idle now is that run's end


def go_to(page, title: str, *, tries: int = 3, heading_text: str | None = None) -> None:
    """Switch page within the session through the sidebar navigation (keeps the user's state).

    The page switch is a run of the new page; a click that starts none (the link redrawn under
    it) is made again. ``heading_text``: the new page's title where it is not ``title`` (Home's).
    """
    nav = sidebar(page).locator('[data-testid="stSidebarNav"] a')
    if title == "Home":
        link = nav.first
    else:  # by its address: "Study" is also the start of "Study stimuli"
        link = nav.and_(page.locator(f'a[href$="/{title.replace(" ", "_")}"]')).first
    for _ in range(tries):
        wait_idle(page)
        since = runs_seen(page)
        link.click()
        try:  # the click reaches the server at once, even on a busy machine
            wait_run_begun(page, since, timeout_s=30)
        except Exception:  # noqa: BLE001  (a playwright timeout: click again)
            continue
        heading(page, heading_text or title).wait_for()
        wait_idle(page)  # the title is drawn by the new page's run
        return
    raise RuntimeError(f"no page switch to {title!r} after {tries} clicks on its link")


def upload(page, wav: Path) -> None:
    """Upload a speech file on the Synthesize page and wait until it has been read.

    The page names the speech it works on in a caption below the uploader
    (the uploader's own list shows the name as soon as the file is chosen).
    The run may still be drawing the rest of the page (the new waveform):
    :func:`wait_idle` waits for its end.
    """
    keyed(page, "synth.upload").locator('input[type="file"]').set_input_files(str(wav))
    main_area(page).locator('[data-testid="stCaptionContainer"] strong', has_text=wav.name).first.wait_for()
    button(page, "synth.go").wait_for()


def synthesize_ready(page) -> None:
    """Wait until the Synthesize page is drawn whole: its control timeline, the segment table and Run."""
    lane_track(page, "left_hand").wait_for(state="visible")
    remounted(page, "synth.segments_editor").locator("canvas").first.wait_for(state="attached")
    button(page, "synth.go").wait_for()


def timeline(page):
    """A frame locator of the Synthesize page's control timeline (app/timeline.py, a component)."""
    return keyed(page, "synth.timeline").frame_locator("iframe").first


def timeline_frame(page):
    """The control timeline's frame (Playwright ``Frame``): its script's ``gkTimeline`` holds the ranges it
    shows, the selection (``sel``), the undo stack, the play cursor (``cursor``, seconds) and ``playing``."""
    lane_track(page, "left_hand").wait_for(state="attached")
    for frame in page.frames:
        try:
            if frame.evaluate("() => !!window.gkTimeline && document.body.dataset.key === 'synth.timeline'"):
                return frame
        except Exception:  # noqa: BLE001 (a frame navigating away; look at the next)
            continue
    raise RuntimeError("no control timeline frame")


def lane_track(page, lane: str):
    """The lane ``lane`` of the control timeline (where ranges are painted)."""
    return timeline(page).locator(f'.track[data-lane="{lane}"]')


def timeline_ranges(page) -> list[tuple[str, str, float, float]]:
    """The ranges the control timeline draws: (lane, level, start_s, end_s), sorted."""
    got = timeline(page).locator(".range:not(.draft)")
    out = []
    for i in range(got.count()):
        r = got.nth(i)
        out.append(
            (
                r.get_attribute("data-lane") or "",
                r.get_attribute("data-level") or "",
                float(r.get_attribute("data-start") or "nan"),
                float(r.get_attribute("data-end") or "nan"),
            )
        )
    return sorted(out)


def drag(page, x0: float, y0: float, x1: float, y1: float | None = None, *, steps: int = 8) -> None:
    """A real mouse drag from (x0, y0) to (x1, y1) in page pixels, through ``steps`` moves."""
    page.mouse.move(x0, y0)
    page.mouse.down()
    page.mouse.move(x1, y0 if y1 is None else y1, steps=steps)
    page.mouse.up()


def edit_timeline(page, action, *, what: str, tries: int = 3) -> None:
    """Do ``action()`` (a drag or key in the control timeline) once the page is idle, and wait for the runs it
    starts (the page takes the edit into its table, then draws again). An action made while a run was replacing
    the page is made again when no run follows it (``what`` names it in the error)."""
    for _ in range(tries):
        wait_idle(page)
        since = runs_seen(page)
        action()
        try:
            # the edit reaches the server at once, even on a busy machine: a run that has not begun in 30 s
            # was never asked for
            wait_run_begun(page, since, timeout_s=30)
        except Exception:  # noqa: BLE001  (a playwright timeout)
            continue
        wait_run(page, since)
        return
    raise RuntimeError(f"{what}: no run of the page after {tries} tries")


def paint_range(page, lane: str, start_frac: float, end_frac: float) -> None:
    """Paint a range in the control timeline's lane ``lane`` by dragging from ``start_frac`` to ``end_frac`` of its
    width (in the lane's level picked now), and wait until the page has taken it."""
    track = lane_track(page, lane)
    track.wait_for(state="visible")
    track.scroll_into_view_if_needed()
    before = len([r for r in timeline_ranges(page) if r[0] == lane])

    def paint() -> None:
        box = track.bounding_box()
        y = box["y"] + box["height"] / 2
        drag(page, box["x"] + box["width"] * start_frac, y, box["x"] + box["width"] * end_frac)

    edit_timeline(page, paint, what=f"painting in the lane {lane}")
    wait_until(
        lambda: len([r for r in timeline_ranges(page) if r[0] == lane]) > before,
        what=f"a new range in the lane {lane}",
        timeout_s=60,
    )


def run_and_wait(page) -> None:
    """Click Run and wait for the result: the 3D view drawn and the wrist plot, the run ended."""
    with run_after(page):
        button(page, "synth.go").click()
    wait_result(page)


def viewer(page, key: str):
    """The frame element of the skeleton viewer with key ``key``: the iframe of the Streamlit component
    (app/display.viewer_component) whose widget key is ``key``."""
    return main_area(page).locator(f".{key_class(key)} iframe").first


def viewer_locator(page, key: str):
    """A frame locator of the skeleton viewer with key ``key`` (its page's body names the key too)."""
    return main_area(page).frame_locator(f".{key_class(key)} iframe").first


def viewer_args(page, key: str) -> dict:
    """What the skeleton viewer with key ``key`` was given, decoded (:func:`gesturekit.viz.viewer.read_viewer_args`):
    the args of its last render, as its page keeps them (``window.gkArgs``), once it has drawn."""
    import base64

    from gesturekit.viz.viewer import read_viewer_args

    got = viewer_frame(page, key).evaluate(
        """() => { const a = window.gkArgs; let b64 = null;
        if (a.audio) { let s = ""; for (let i = 0; i < a.audio.length; i += 32768)
          s += String.fromCharCode.apply(null, a.audio.subarray(i, i + 32768)); b64 = btoa(s); }
        return {data: a.data, audio: b64, hash: a.hash}; }"""
    )
    audio = None if got["audio"] is None else base64.b64decode(got["audio"])
    out = read_viewer_args(got["data"], audio, key)
    out["hash"] = got["hash"]
    return out


def skeleton_canvas(page, key: str):
    """The canvas of the skeleton viewer with key ``key`` (gesturekit.viz.viewer), once it has drawn."""
    frame = viewer_locator(page, key)
    frame.locator(f'body[data-key="{key}"][data-drawn="1"]').wait_for(state="attached")
    canvas = frame.locator("canvas#c")
    canvas.wait_for(state="visible")
    return canvas


def _viewer_frames(page) -> list:
    """The frames of the page's skeleton viewers (their body names their key, and they hold a stage; the
    control timeline's frame names its key too, but draws no 3D view)."""
    out = []
    for frame in page.frames:
        try:
            viewer = "() => !!(document.body && document.body.dataset.key && document.getElementById('stage'))"
            if frame.evaluate(viewer):
                out.append(frame)
        except Exception:  # noqa: BLE001 (a frame navigating away; look at the next)
            continue
    return out


def viewer_frame(page, key: str):
    """The frame (Playwright ``Frame``) of the skeleton viewer with key ``key``, once it has drawn.

    Its script's global ``gk`` holds the shown ``frame``, ``frames`` (how many it holds), the
    clock ``time``, the speech's ``audioTime``, ``playing``, ``drawn`` and ``drawMs``.
    """
    skeleton_canvas(page, key)
    for frame in _viewer_frames(page):
        if frame.evaluate("() => document.body.dataset.key") == key:
            return frame
    raise RuntimeError(f"no skeleton viewer frame with key {key!r}")


def wait_result(page) -> None:
    """Wait until the Synthesize page shows a result: its 3D view drawn and its wrist plot."""
    skeleton_canvas(page, "synth.skeleton")
    keyed(page, "synth.wrists").locator("text", has_text="left wrist height").first.wait_for(state="visible")


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
    # every 3D view has drawn (each draws again on its own when resized), and the page has
    # painted at the new size
    for view in _viewer_frames(page):
        view.wait_for_function("() => document.body.dataset.drawn === '1'")
        view.evaluate(_PAINTED)
    page.evaluate(_PAINTED)
    part = path.with_name(f".{path.name}.part")
    page.screenshot(path=str(part), type="png")
    os.replace(part, path)  # a screenshot appears whole or not at all
    page.set_viewport_size({"width": 1440, "height": 1000})
    return path


def viewer_screenshot(page, key: str, path: Path, *, at: float = 0.4) -> Path:
    """Save a PNG of the 3D view with key ``key`` alone, showing the frame ``at`` of the way through."""
    view = viewer_frame(page, key)
    shown = view.evaluate(
        """(at) => { const s = document.getElementById("s");
        s.value = String(Math.round(at * Number(s.max))); s.dispatchEvent(new Event("input"));
        return Number(s.value); }""",
        at,
    )
    element = viewer(page, key)
    element.scroll_into_view_if_needed()
    # the slider's input draws the frame; the view's own clock must not have moved it on since
    view.wait_for_function("(k) => gk.frame === k", arg=shown)
    view.evaluate(_PAINTED)
    part = path.with_name(f".{path.name}.part")
    element.screenshot(path=str(part), type="png")
    os.replace(part, path)
    return path


def make_screenshots(out: Path, *, seconds: float = 12.0, demo_minutes: float = 3.0) -> list[Path]:
    """Screenshots of the Synthesize, Retrieval inspector and Database pages, written to ``out``.

    The app runs on a fresh demo database of ``demo_minutes`` in a temporary
    home; the Synthesize page gets ``seconds`` of generated speech with one
    painted control range.
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
    control range painted in the timeline's "both hands" lane over the fractions ``box`` of it, if given), served
    from a fresh demo database of ``demo_minutes`` in a temporary home; ``out`` is created."""
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="gesturekit-shots-") as tmp:
        home = Path(tmp)
        wav = write_speech(home / "speech.wav", seconds=seconds)
        with app_server(home, demo_minutes=demo_minutes) as url, browser() as page:
            open_app(page, url, "Synthesize", heading="Synthesize")
            upload(page, wav)
            if box is not None:
                paint_range(page, "both_hands", *box)
            run_and_wait(page)
            wait_idle(page)
            yield page


def make_front_picture(path: Path, *, seconds: float = 12.0, demo_minutes: float = 2.0) -> Path:
    """The README's and the docs' front picture: the Synthesize page's result (k-NN and refined on
    the character) with a hand-height control, 960 pixels wide, as a JPEG (tens of kilobytes)."""
    from PIL import Image

    with _result_page(path.parent, seconds=seconds, demo_minutes=demo_minutes, box=(0.3, 0.6)) as page:
        page.set_viewport_size({"width": 1280, "height": 860})
        page.get_by_role("heading", name="Result").first.evaluate("el => el.scrollIntoView({block: 'start'})")
        page.mouse.wheel(0, 130)
        for frame in _viewer_frames(page):  # each 3D view has drawn its first frame
            frame.locator('body[data-drawn="1"]').wait_for(state="attached")
        png = path.with_suffix(".part.png")
        page.screenshot(path=str(png), type="png")
    with Image.open(png) as im:
        small = im.convert("RGB").resize((960, 645), Image.LANCZOS)
    part = path.with_suffix(".part" + path.suffix)
    small.save(part, format="JPEG", quality=80, optimize=True, progressive=True)
    png.unlink()
    os.replace(part, path)
    return path


#: The pages of the app (app/nav.py): Synthesize first (its result feeds the next two), Home last.
APP_PAGES = ("Synthesize", "Retrieval inspector", "Database", "Study stimuli", "Live", "Study", "Home")

#: The 3D view a page's screenshot scrolls to (its key).
_VIEW_OF = {"Retrieval inspector": "inspect.views", "Database": "db.skeleton"}

#: Common laptop windows, (width, height) in CSS pixels.
LAPTOP_SIZES = ((1280, 800), (1920, 1080))


def _jpeg(png: Path, path: Path, *, quality: int = 82, most_bytes: int = 290_000) -> Path:
    """``png`` as a JPEG at ``path`` (atomically), smaller than ``most_bytes`` (quality lowered, then the picture
    scaled down, as needed); ``png`` is removed."""
    from PIL import Image

    part = path.with_name(f".{path.name}.part")
    with Image.open(png) as im:
        rgb = im.convert("RGB")
    scale = 1.0
    while True:
        pic = rgb if scale == 1.0 else rgb.resize((int(rgb.width * scale), int(rgb.height * scale)), Image.LANCZOS)
        pic.save(part, format="JPEG", quality=quality, optimize=True, progressive=True)
        if part.stat().st_size < most_bytes or scale < 0.5:
            break
        if quality > 70:
            quality -= 6
        else:
            scale *= 0.85
    png.unlink()
    os.replace(part, path)
    return path


def _slug(title: str) -> str:
    return re.sub(r"[^a-z0-9]+", "_", title.lower()).strip("_")


def make_laptop_screenshots(
    out: Path, *, seconds: float = 12.0, demo_minutes: float = 3.0, sizes: tuple[tuple[int, int], ...] = LAPTOP_SIZES
) -> list[Path]:
    """Every page of the app as a user's laptop window shows it (no scrolling), at each of ``sizes``, as JPEGs
    ``<page>_<width>x<height>.jpg`` in ``out``; the pages after Synthesize show its result (a run on ``seconds``
    of generated speech with one painted control range, on a fresh demo database)."""
    shots = []
    with _result_page(out, seconds=seconds, demo_minutes=demo_minutes, box=(0.3, 0.55)) as page:
        for i, title in enumerate(APP_PAGES):
            if i:
                go_to(page, title, heading_text="gesturekit" if title == "Home" else None)
            if problems(page):
                raise RuntimeError(f"the {title} page shows an error: {problems(page)[0][:500]}")
            for width, height in sizes:
                page.set_viewport_size({"width": width, "height": height})
                wait_idle(page)
                if title == "Synthesize":  # the result, as a user scrolls to it
                    page.get_by_role("heading", name="Result").first.evaluate(
                        "el => el.scrollIntoView({block: 'start'})"
                    )
                elif title in _VIEW_OF and keyed(page, _VIEW_OF[title]).count():  # its 3D view, scrolled to
                    keyed(page, _VIEW_OF[title]).first.evaluate("el => el.scrollIntoView({block: 'center'})")
                for view in _viewer_frames(page):
                    view.wait_for_function("() => document.body.dataset.drawn === '1'")
                    view.evaluate(_PAINTED)
                page.evaluate(_PAINTED)  # each 3D view drew at the new size (its resize draws at once)
                png = out / f".{_slug(title)}_{width}x{height}.png"
                page.screenshot(path=str(png), type="png")
                shots.append(_jpeg(png, out / f"{_slug(title)}_{width}x{height}.jpg"))
    return shots


def make_timeline_screenshots(out: Path, *, seconds: float = 12.0, demo_minutes: float = 3.0) -> list[Path]:
    """The control timeline and the inspector's candidates as a 1280x800 laptop window shows them, as JPEGs in
    ``out``: ``controls_timeline_1280x800.jpg`` (ranges painted in three lanes, a curve drawn in a fourth, the
    play cursor stopped part way) and ``inspector_candidates_1280x800.jpg`` (a step's chosen candidate large over
    the query's ghost, the others in the strip) after a run with those controls."""
    out.mkdir(parents=True, exist_ok=True)
    shots = []
    with tempfile.TemporaryDirectory(prefix="gesturekit-shots-") as tmp:
        home = Path(tmp)
        wav = write_speech(home / "speech.wav", seconds=seconds)
        with app_server(home, demo_minutes=demo_minutes) as url, browser(width=1280, height=800) as page:
            open_app(page, url, "Synthesize", heading="Synthesize")
            upload(page, wav)
            synthesize_ready(page)
            paint_range(page, "left_hand", 0.08, 0.3)
            timeline(page).locator('.lane[data-lane="speed"] button.level[data-level="slow"]').click()
            paint_range(page, "speed", 0.25, 0.55)
            paint_range(page, "symmetry", 0.6, 0.85)
            timeline(page).locator('button.curve[data-lane="right_hand"]').click()
            track = lane_track(page, "right_hand")
            track.scroll_into_view_if_needed()
            box = track.bounding_box()
            ys = (0.15, 0.2, 0.5, 0.85, 0.9, 0.6, 0.3)  # high, through the middle, low, back up

            def curve() -> None:
                xs = [box["x"] + box["width"] * (0.35 + 0.09 * i) for i in range(len(ys))]
                page.mouse.move(xs[0], box["y"] + box["height"] * ys[0])
                page.mouse.down()
                for x, y in zip(xs[1:], ys[1:]):
                    page.mouse.move(x, box["y"] + box["height"] * y, steps=6)
                page.mouse.up()

            edit_timeline(page, curve, what="drawing a curve")
            run_and_wait(page)
            wait_idle(page)
            # a click on the speech's waveform puts the play cursor there (4.4 s), as playing to it would
            wave = timeline(page).locator("#wavetrack")
            wave.scroll_into_view_if_needed()
            at = wave.bounding_box()
            page.mouse.click(at["x"] + at["width"] * 4.4 / seconds, at["y"] + at["height"] / 2)
            timeline_frame(page).wait_for_function("() => Math.abs(window.gkTimeline.cursor - 4.4) < 0.1")
            heading(page, "2 · Controls").evaluate("el => el.scrollIntoView({block: 'start'})")
            page.evaluate(_PAINTED)
            png = out / ".controls_timeline_1280x800.png"
            page.screenshot(path=str(png), type="png")
            shots.append(_jpeg(png, out / "controls_timeline_1280x800.jpg"))
            if problems(page):
                raise RuntimeError(f"the Synthesize page shows an error: {problems(page)[0][:500]}")
            go_to(page, "Retrieval inspector")
            large = keyed(page, "inspect.candidate_large")
            large.locator(".js-plotly-plot").first.wait_for()
            large.first.evaluate("el => el.scrollIntoView({block: 'start'})")
            page.mouse.move(800, 400)  # over the page, not the sidebar
            page.mouse.wheel(0, -150)  # its title too
            wait_idle(page)
            page.evaluate(_PAINTED)
            png = out / ".inspector_candidates_1280x800.png"
            page.screenshot(path=str(png), type="png")
            shots.append(_jpeg(png, out / "inspector_candidates_1280x800.jpg"))
            if problems(page):
                raise RuntimeError(f"the inspector shows an error: {problems(page)[0][:500]}")
    return shots


def make_mp4_frames(
    out: Path, *, speech: Path | None = None, seconds: float = 20.0, at=(0.15, 0.5, 0.85)
) -> list[Path]:
    """Frames of an MP4 the command line makes on the embedded demo database, at the fractions ``at`` of its
    length, as JPEGs ``mp4_<time>s.jpg`` in ``out``: ``gesturekit synthesize SPEECH --video`` (``speech``, or
    ``seconds`` of generated speech), k-NN and refined side by side."""
    import imageio_ffmpeg

    out.mkdir(parents=True, exist_ok=True)
    shots = []
    with tempfile.TemporaryDirectory(prefix="gesturekit-mp4-") as tmp:
        home = Path(tmp)
        wav = speech if speech is not None else write_speech(home / "speech.wav", seconds=seconds)
        env = dict(os.environ, GESTUREKIT_HOME=str(home))
        cmd = [sys.executable, "-m", "gesturekit", "synthesize", str(wav), "--out", str(home / "out"), "--video"]
        subprocess.run(cmd, env=env, cwd=str(REPO), check=True, stdout=subprocess.DEVNULL)
        mp4 = next((home / "out").rglob("*.mp4"))
        reader = imageio_ffmpeg.read_frames(str(mp4))
        meta = next(reader)
        (w, h), fps, duration = meta["size"], float(meta["fps"]), float(meta["duration"])
        wanted = {int(round(a * duration * fps)): a for a in at}
        try:
            for i, data in enumerate(reader):
                if i in wanted:
                    from PIL import Image

                    png = out / f".mp4_{i}.png"
                    Image.frombytes("RGB", (w, h), data).save(png)
                    shots.append(_jpeg(png, out / f"mp4_{i / fps:05.1f}s.jpg"))
                if i >= max(wanted):
                    break
        finally:
            reader.close()
    return shots


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Screenshots of the app's pages for the docs.")
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "screenshots")
    parser.add_argument("--front", type=Path, help="only the front picture, to this file (docs/images/app.jpg)")
    parser.add_argument("--laptop", type=Path, help="every page at laptop sizes and a CLI MP4's frames, to this folder")
    parser.add_argument("--speech", type=Path, help="with --laptop: the speech of the MP4 (default: generated)")
    parser.add_argument("--timeline", type=Path, help="only the control timeline and the inspector at 1280x800, here")
    args = parser.parse_args(argv)
    reason = unavailable()
    if reason:
        print(f"cannot make screenshots: {reason}", file=sys.stderr)
        return 1
    if args.front:
        print(make_front_picture(args.front))
        return 0
    if args.timeline:
        for p in make_timeline_screenshots(args.timeline):
            print(p)
        return 0
    if args.laptop:
        shots = make_mp4_frames(args.laptop, speech=args.speech) + make_laptop_screenshots(args.laptop)
        for p in shots + make_timeline_screenshots(args.laptop):
            print(p)
        return 0
    for p in make_screenshots(args.out) + make_viewer_screenshots(args.out):
        print(p)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
