"""The Synthesize page's control timeline in a real browser: ranges painted, re-levelled, moved, resized, nudged,
deleted and undone with the mouse and the keyboard; the page's control table follows, and a run uses it."""

from __future__ import annotations

import pytest

from gesturekit.skeleton import FPS
from tests import app_browser
from tests.waits import wait_until

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"),
]

SECONDS = 6.0
STEP = 8 / FPS  # the search's default step, N = 8 frames


def snapped(t: float) -> float:
    """The step boundary nearest ``t`` (what the timeline snaps to)."""
    return round(round(t / STEP) * STEP, 6)


def table(page) -> list[tuple[str, str, str]]:
    """The control table's rows (start, end, constraint), as its accessible grid shows them."""
    grid = app_browser.remounted(page, "synth.segments_editor").locator('[data-testid="stDataFrame"]')
    rows = grid.locator('tbody tr[role="row"]')
    out = []
    for i in range(rows.count()):
        cells = [c.inner_text().strip() for c in rows.nth(i).locator('td[role="gridcell"]').all()]
        if len(cells) >= 3 and any(cells):
            out.append(tuple(cells[-3:]))
    return out


def expect_table(page, ranges: list[tuple[str, str, float, float]]) -> None:
    """The table holds the timeline's ranges: one row per range (the grid shows times to 2 decimals)."""
    want = sorted((f"{lane}={level}", a, b) for lane, level, a, b in ranges)

    def same() -> bool:
        got = sorted((c, float(a), float(b)) for a, b, c in table(page))
        return len(got) == len(want) and all(
            g[0] == w[0] and abs(g[1] - w[1]) < 0.011 and abs(g[2] - w[2]) < 0.011 for g, w in zip(got, want)
        )

    wait_until(same, what=f"the control table showing {want}", timeout_s=60)


def x_of(box: dict, t: float) -> float:
    return box["x"] + box["width"] * t / SECONDS


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    home = tmp_path_factory.mktemp("timeline_home")
    wav = app_browser.write_speech(home / "speech.wav", seconds=SECONDS)
    with app_browser.app_server(home, demo_minutes=1.0) as url:
        yield url, wav


def test_paint_level_move_resize_undo_a_range_and_run_with_it(served):
    url, wav = served
    with app_browser.browser(width=1280, height=900) as page:
        app_browser.open_app(page, url, "Synthesize", heading="Synthesize")
        app_browser.upload(page, wav)
        app_browser.synthesize_ready(page)
        track = app_browser.lane_track(page, "left_hand")
        track.scroll_into_view_if_needed()
        box = track.bounding_box()
        y = box["y"] + box["height"] / 2

        # paint: a drag across the lane from 1.2 s to 3.0 s gives a range on the steps nearest to them
        app_browser.paint_range(page, "left_hand", 1.2 / SECONDS, 3.0 / SECONDS)
        start, end = snapped(1.2), snapped(3.0)
        assert app_browser.timeline_ranges(page) == [("left_hand", "high", start, end)]
        expect_table(page, [("left_hand", "high", start, end)])

        # its level, picked in the lane (the range is selected since it was painted)
        level = app_browser.timeline(page).locator('.lane[data-lane="left_hand"] button.level[data-level="low"]')
        app_browser.edit_timeline(page, level.click, what="the level low")
        assert app_browser.timeline_ranges(page) == [("left_hand", "low", start, end)]

        # move: dragged by its middle two steps to the right, its length kept
        mid = (start + end) / 2
        app_browser.edit_timeline(
            page, lambda: app_browser.drag(page, x_of(box, mid), y, x_of(box, mid + 2 * STEP)), what="moving"
        )
        moved = (round(start + 2 * STEP, 6), round(end + 2 * STEP, 6))
        assert app_browser.timeline_ranges(page) == [("left_hand", "low", *moved)]
        expect_table(page, [("left_hand", "low", *moved)])

        # resize: its right edge dragged one step further
        app_browser.edit_timeline(
            page,
            lambda: app_browser.drag(page, x_of(box, moved[1]) - 3, y, x_of(box, moved[1] + STEP) - 3),
            what="resizing",
        )
        resized = (moved[0], snapped(moved[1] + STEP))
        assert app_browser.timeline_ranges(page) == [("left_hand", "low", *resized)]

        # undo (the button): the resize is gone, the move kept; the table follows
        undo = app_browser.timeline(page).locator("#undo")
        app_browser.edit_timeline(page, undo.click, what="undo")
        assert app_browser.timeline_ranges(page) == [("left_hand", "low", *moved)]
        expect_table(page, [("left_hand", "low", *moved)])

        # the keyboard: → nudges the selected range a step, Delete removes it, Ctrl+Z brings it back
        frame = app_browser.timeline_frame(page)
        frame.evaluate("() => document.getElementById('tl').focus()")
        app_browser.edit_timeline(page, lambda: page.keyboard.press("ArrowRight"), what="→")
        nudged = (round(moved[0] + STEP, 6), round(moved[1] + STEP, 6))
        assert app_browser.timeline_ranges(page) == [("left_hand", "low", *nudged)]
        app_browser.edit_timeline(page, lambda: page.keyboard.press("Delete"), what="Delete")
        assert app_browser.timeline_ranges(page) == []
        expect_table(page, [])
        app_browser.edit_timeline(page, lambda: page.keyboard.press("Control+z"), what="Ctrl+Z")
        assert app_browser.timeline_ranges(page) == [("left_hand", "low", *nudged)]

        # a second lane overlapping the first: where both hold, the track's segment holds both
        app_browser.paint_range(page, "speed", (nudged[1] - STEP) / SECONDS, 5.5 / SECONDS)
        speed = next(r for r in app_browser.timeline_ranges(page) if r[0] == "speed")
        assert speed[2] == snapped(nudged[1] - STEP) and speed[1] == "fast"
        expect_table(page, [("left_hand", "low", *nudged), speed])

        # a run uses the page's control: the result says so
        app_browser.run_and_wait(page)
        caption = app_browser.main_area(page).get_by_text("controls:").first.inner_text()
        assert f"{round(nudged[0], 2):g}-{round(speed[2], 2):g}:left_hand=low" in caption, caption  # to 0.01 s
        assert f"{round(speed[2], 2):g}-{round(nudged[1], 2):g}:left_hand=low+speed=fast" in caption, caption

        # playback: the timeline's Play moves its cursor over the lanes
        frame = app_browser.timeline_frame(page)
        app_browser.timeline(page).locator("#play").click()
        frame.wait_for_function("() => window.gkTimeline.cursor > 0.2")
        cursor = app_browser.timeline(page).locator("#cursor")
        assert cursor.is_visible()
        assert app_browser.problems(page) == []


def test_a_curve_drawn_in_a_lane_gives_a_level_per_step(served):
    url, wav = served
    with app_browser.browser(width=1280, height=900) as page:
        app_browser.open_app(page, url, "Synthesize", heading="Synthesize")
        app_browser.upload(page, wav)
        app_browser.synthesize_ready(page)
        # at a laptop's width no lane's level buttons reach into its track, and every track starts at one x
        frame = app_browser.timeline_frame(page)
        edges = frame.evaluate(
            """() => [...document.querySelectorAll('.row.lane')].map((row) => [
                row.dataset.lane,
                row.querySelector('.levels').getBoundingClientRect().right,
                row.querySelector('.track').getBoundingClientRect().left])"""
        )
        assert len(edges) == 8
        assert [lane for lane, right, left in edges if right > left] == [], edges
        assert len({round(left, 1) for _, _, left in edges}) == 1, edges
        app_browser.timeline(page).locator('button.curve[data-lane="right_hand"]').click()
        track = app_browser.lane_track(page, "right_hand")
        track.scroll_into_view_if_needed()
        box = track.bounding_box()
        # high (the top of the lane) for the first half, low (the bottom) for the second
        top, bottom = box["y"] + 3, box["y"] + box["height"] - 3

        def curve() -> None:
            page.mouse.move(x_of(box, 0.05), top)
            page.mouse.down()
            page.mouse.move(x_of(box, 2.9), top, steps=10)
            page.mouse.move(x_of(box, 3.1), bottom, steps=4)
            page.mouse.move(x_of(box, 5.9), bottom, steps=10)
            page.mouse.up()

        app_browser.edit_timeline(page, curve, what="drawing a curve")
        wait_until(
            lambda: [r[1] for r in app_browser.timeline_ranges(page)] == ["high", "low"],
            what="a high range then a low range in the lane",
            timeout_s=60,
        )
        (_, _, a0, a1), (_, _, b0, b1) = sorted(app_browser.timeline_ranges(page), key=lambda r: r[2])
        # on step boundaries, one after the other, over the steps whose middle frame the curve spans
        for t in (a0, a1, b0):
            assert abs(t / STEP - round(t / STEP)) < 1e-4, t
        assert a0 == 0.0 and a1 <= b0 and b1 == pytest.approx(SECONDS, abs=STEP)
        assert app_browser.problems(page) == []
