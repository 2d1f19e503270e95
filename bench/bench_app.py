"""Time from uploading 30 s of speech to the first result on screen, in a real browser.

Starts ``streamlit run app/Home.py`` on 127.0.0.1 with the demo database
(20 minutes of the generated speaker, built beforehand and not timed), opens
the Synthesize page in headless Chromium (Playwright), uploads a 30 s WAV,
clicks Run and waits until the 3D view and the wrist plot are drawn. The
first attempt starts as soon as the page has opened in a fresh browser after
the server's start, while the server is still preparing the database in the
background (compiled search, refiner, figures); later attempts, each in a new
browser session, show the steady state; a last one in a new browser shows a
user's first visit once the server is prepared. Target: under 5 s.

Needs the ``playwright`` package and Chromium (``apt-get install chromium``).

Usage: python bench/bench_app.py [--minutes 20] [--seconds 30] [--repeats 3]
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _driver():
    """The browser driver shared with the browser test (``tests/app_browser.py``), loaded by its path."""
    spec = importlib.util.spec_from_file_location("gesturekit_app_browser", REPO / "tests" / "app_browser.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _machine() -> str:
    mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    return f"{os.cpu_count()} cores, {mem:.0f} GiB, {platform.machine()}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=None, help="demo database size (default: the app's default)")
    parser.add_argument("--seconds", type=float, default=30.0, help="length of the uploaded speech")
    parser.add_argument("--repeats", type=int, default=3, help="attempts after the first")
    args = parser.parse_args(argv)

    from gesturekit.demo import DEMO_MINUTES, build_demo_database

    drv = _driver()
    reason = drv.unavailable()
    if reason:
        print(f"bench_app: cannot run: {reason}")
        return 1
    minutes = DEMO_MINUTES if args.minutes is None else args.minutes
    print(f"machine: {_machine()}")
    with tempfile.TemporaryDirectory(prefix="gesturekit-bench-app-") as tmp:
        home = Path(tmp)
        t = time.perf_counter()
        db = build_demo_database(home / "db" / "demo", minutes=minutes)
        print(f"demo database: {minutes:g} min, {db.n_clips} clips (built in {time.perf_counter() - t:.1f} s, not timed below)")
        wav = drv.write_speech(home / "speech_30s.wav", seconds=args.seconds)
        print(f"speech: {wav.name}, {args.seconds:g} s, 16 kHz mono WAV, {wav.stat().st_size / 1e6:.1f} MB")
        times = []

        def attempt(page, url: str, kind: str) -> float | None:
            t_open = time.perf_counter()
            drv.open_app(page, url, "Synthesize", heading="Synthesize")  # a new session each time
            drv.synthesize_ready(page)  # the user sees the whole page (on example speech), then uploads
            t0 = time.perf_counter()
            drv.upload(page, wav)
            t1 = time.perf_counter()
            drv.run_and_wait(page)
            t2 = time.perf_counter()
            problems = drv.problems(page)
            if problems:
                print(f"the page shows an error: {problems[0][:400]}")
                return None
            print(f"{kind:>30}: page opened {t0 - t_open:5.2f} s; upload -> speech read {t1 - t0:5.2f} s, "
                  f"Run -> result on screen {t2 - t1:5.2f} s, total {t2 - t0:5.2f} s")
            return t2 - t0

        t_launch = time.perf_counter()
        with drv.app_server(home) as url:
            with drv.browser() as page:
                print(f"server answering and browser started {time.perf_counter() - t_launch:.1f} s after the "
                      "server's launch")
                for i in range(1 + args.repeats):
                    times.append(attempt(page, url, "first (server just started)" if i == 0 else f"repeat {i}"))
                    if times[-1] is None:
                        return 1
            with drv.browser() as page:  # a user's first visit once the server has prepared the database
                fresh = attempt(page, url, "new browser, prepared server")
                if fresh is None:
                    return 1
        warm = times[1:] or times
        print(f"upload of {args.seconds:g} s speech -> first result on screen: median {statistics.median(warm):.2f} s "
              f"(best {min(warm):.2f} s) warm, {fresh:.2f} s in a new browser, {times[0]:.2f} s right after the "
              "server's start; target < 5 s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
