"""Settings stay as the user left them: the database selector and page switches, in a real browser.

Choosing "another folder…" in the sidebar stops the page before its settings
are drawn; the settings, the control table and the next run must come back
unchanged. Skipped, with the reason, where the playwright package or Chromium
is missing (see ``tests/app_browser.py``).
"""

from __future__ import annotations

import json

import pytest

from gesturekit.workspace import DEMO_DATABASE_LABEL
from tests import app_browser
from tests.waits import patience

try:
    from playwright.sync_api import expect
except ImportError:  # the tests skip, with the reason (app_browser.unavailable)
    expect = None

pytestmark = pytest.mark.skipif(
    app_browser.unavailable() is not None, reason=f"no browser test: {app_browser.unavailable()}"
)

#: What the test sets on Synthesize: label of the number input -> value.
SETTINGS = {
    "k (0 = best match)": "2",
    "N (frames per step)": "6",
    "Seed": "5",
    "Candidates recorded per step": "7",
    "Keep k-NN motion below (Hz)": "1.50",
}


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    home = tmp_path_factory.mktemp("settings_home")
    with app_browser.app_server(home, demo_minutes=1.0) as url:
        yield url, home


def _number(page, label: str):
    main = app_browser.main_area(page)
    return main.locator('[data-testid="stNumberInput"]', has_text=label).locator("input").first


def _set_number(page, label: str, value: str) -> None:
    """Type ``value`` into a number input and wait for the run that takes it (it must be a change:
    Streamlit starts no run for the value a widget already has)."""
    box = _number(page, label)
    assert box.input_value() != value, f"{label} is {value} already"
    with app_browser.run_after(page):
        box.fill(value)
        box.press("Enter")


def _numbers(page) -> dict[str, str]:
    return {label: _number(page, label).input_value() for label in SETTINGS}


def _choose_database(page, option: str) -> None:
    """Choose another database in the sidebar (``option``: not the one chosen now)."""
    with app_browser.run_after(page):
        app_browser.keyed(page, "_gk.database_choice").locator('[data-testid="stSelectbox"]').click()
        # the options open in a list of their own, outside the sidebar
        dropdown = page.locator('[data-testid="stSelectboxVirtualDropdown"]')
        dropdown.get_by_role("option", name=option, exact=True).click()


def _grid(page):
    """The control table (the data editor of the Synthesize page)."""
    return app_browser.remounted(page, "synth.segments_editor").locator('[data-testid="stDataFrame"]')


def _table(page, *, expect: int = 0) -> list[str]:
    """The control table's cells, row by row, read from the data editor's accessible grid.

    A newly drawn editor fills its grid a moment later: waits for ``expect`` cells.
    """
    cells = _grid(page).locator('[role="gridcell"]')
    if expect:
        cells.nth(expect - 1).wait_for(state="attached")
    return [c.inner_text() for c in cells.all()]


def _selected_cell(grid) -> tuple[int, int] | None:
    """(row, column) of the grid's selected cell, 0-based over the data, read from its accessible table."""
    cell = grid.locator('td[role="gridcell"][aria-selected="true"]')
    if cell.count() != 1:
        return None
    cell_id = cell.first.get_attribute("id") or ""  # "glide-cell-<column + 1>-<row>"; column 0 marks rows
    parts = cell_id.split("-")
    if len(parts) != 4 or not (parts[2].isdigit() and parts[3].isdigit()):
        return None
    return int(parts[3]), int(parts[2]) - 1


def _edit_cell(page, row: int, column: int, text: str) -> None:
    """Type into a cell of the control table (columns: start, end, constraint) as a user does.

    The editor draws its cells on a canvas, with a row-marker column, column widths of its own
    and a 36 px header: a click at an assumed pixel position can land on another cell. So one
    click selects some cell of the data rows (from the canvas's own size), the grid's accessible
    table says which one, and the arrow keys move the selection to the wanted cell before Enter
    opens its editor. Tries three times; raises AssertionError when the cell never shows ``text``.
    """
    grid = _grid(page)
    canvas = grid.locator('canvas[data-testid="data-grid-canvas"]')
    selected = grid.locator('td[role="gridcell"][aria-selected="true"]')
    cell = grid.locator(f'td[role="gridcell"]#glide-cell-{column + 1}-{row}')  # see _selected_cell
    # the accessible table is filled a moment after the grid is drawn; without its rows, the click
    # below would aim at the whole body and may land on the editor's empty row (adding a row)
    canvas.locator('tbody tr[role="row"]').nth(row).wait_for(state="attached")
    for _ in range(3):  # a busy machine may open the cell's editor late: try again
        canvas.scroll_into_view_if_needed()
        box = canvas.bounding_box()
        header = grid.locator(".dvn-underlay > canvas").nth(1).bounding_box()["height"]
        rows = canvas.locator('tbody tr[role="row"]').count()
        row_height = (box["height"] - header) / (rows + 1)  # the data rows and the editor's empty row
        page.mouse.click(box["x"] + box["width"] / 2, box["y"] + header + row_height / 2)
        try:  # the selection shows in the table a moment after the click
            selected.first.wait_for(state="attached", timeout=patience(15) * 1000)
        except Exception:  # noqa: BLE001  (a playwright timeout: the click selected nothing, click again)
            continue
        at = _selected_cell(grid)
        if at is None:
            continue
        for key, steps in (
            ("ArrowDown", row - at[0]),
            ("ArrowUp", at[0] - row),
            ("ArrowRight", column - at[1]),
            ("ArrowLeft", at[1] - column),
        ):
            for _ in range(max(steps, 0)):
                page.keyboard.press(key)
        if _selected_cell(grid) != (row, column):
            page.keyboard.press("Escape")
            continue
        page.keyboard.press("Enter")
        editor = page.locator("#portal textarea, #portal input").first
        try:
            editor.wait_for(state="visible", timeout=patience(15) * 1000)
        except Exception:  # noqa: BLE001  (not opened: select again)
            page.keyboard.press("Escape")
            continue
        page.keyboard.press("Control+a")
        # keys at a person's pace, and Enter only once the editor's box holds them all: on a busy
        # machine the cell's editor took the keys into its box but committed the value it held
        # before them (nothing was sent)
        page.keyboard.type(text, delay=50)
        try:
            expect(editor).to_have_value(text, timeout=patience(30) * 1000)
        except AssertionError:
            page.keyboard.press("Escape")
            continue
        since = app_browser.runs_seen(page)
        page.keyboard.press("Enter")
        try:  # the grid shows the committed value a moment later
            expect(cell).to_have_text(text, timeout=patience(30) * 1000)
        except AssertionError:
            continue
        app_browser.wait_run(page, since)  # the edit reached the server, which ran the page with it
        return
    raise AssertionError(f"could not type {text!r} into the table's row {row}, column {column}")


def _bands(page) -> int:
    return len([r for r in app_browser.timeline_ranges(page) if r[:2] == ("both_hands", "high")])


def _expect_kept(page, cells: list[str]) -> None:
    app_browser.synthesize_ready(page)
    assert _numbers(page) == SETTINGS
    assert _table(page, expect=len(cells)) == cells
    assert _bands(page) == 1


def test_database_switch_and_page_switch_keep_every_setting(served, tmp_path):
    url, home = served
    with app_browser.browser() as page:
        app_browser.open_app(page, url, "Synthesize", heading="Synthesize")
        app_browser.synthesize_ready(page)
        for label, value in SETTINGS.items():
            _set_number(page, label, value)
        app_browser.paint_range(page, "both_hands", 0.2, 0.45)
        assert _bands(page) == 1
        # an edit in the table itself (the editor's own state, not the timeline)
        _edit_cell(page, 0, 1, "4.25")
        cells = _table(page)
        assert len(cells) == 3 and cells[1] == "4.25" and cells[2] == "both_hands=high"
        assert _numbers(page) == SETTINGS

        # "another folder…" with nothing typed stops the page before its settings are drawn
        _choose_database(page, "another folder…")
        # the page says where to type (in its main area): the sidebar has a box for it
        app_browser.main_area(page).get_by_text("Type the folder of a database").first.wait_for()
        typed = app_browser.keyed(page, "_gk.database_typed").locator('input[placeholder="/path/to/database"]')
        with app_browser.run_after(page):
            typed.fill(str(home / "db" / "demo"))
            typed.press("Enter")
        _expect_kept(page, cells)

        _choose_database(page, DEMO_DATABASE_LABEL)
        _expect_kept(page, cells)

        # and straight back again, without typing
        _choose_database(page, "another folder…")
        _choose_database(page, DEMO_DATABASE_LABEL)
        _expect_kept(page, cells)

        app_browser.go_to(page, "Database")
        app_browser.go_to(page, "Synthesize")
        _expect_kept(page, cells)

        app_browser.run_and_wait(page)
        main = app_browser.main_area(page)
        caption = main.locator('[data-testid="stCaptionContainer"]', has_text="seed 5").first.inner_text()
        assert "k = 2" in caption and "seed 5" in caption and f"{float(cells[0]):g}-4.25:both_hands=high" in caption
        assert "differs from the paper" in caption and "N = 6 (paper 8)" in caption
        # the saved config is the one the run used
        with page.expect_download() as info:
            app_browser.keyed(page, "synth.download_json").get_by_role("button", name="Config (JSON)").click()
        config = json.loads(open(info.value.path(), encoding="utf-8").read())
        settings = config["synthesis"]
        assert (settings["k"], settings["segment"], settings["seed"], settings["record"]) == (2, 6, 5, 7)
        assert settings["refiner_keep_hz"] == pytest.approx(1.5)
        assert settings["control"] == f"{float(cells[0]):g}-4.25:both_hands=high"
        assert app_browser.problems(page) == []


def _switch_database_and_back(page) -> None:
    _choose_database(page, "another folder…")
    app_browser.main_area(page).get_by_text("Type the folder of a database").first.wait_for()
    _choose_database(page, DEMO_DATABASE_LABEL)


def test_the_other_pages_keep_their_settings_too(served):
    url, _ = served
    with app_browser.browser() as page:
        # Study stimuli: plain persisted number inputs
        app_browser.open_app(page, url, "Study_stimuli", heading="Study stimuli")
        _set_number(page, "Seed", "7")
        _set_number(page, "Participants", "3")
        _switch_database_and_back(page)
        app_browser.heading(page, "Study stimuli").wait_for()
        assert (_number(page, "Seed").input_value(), _number(page, "Participants").input_value()) == ("7", "3")
        # a later change sends the kept values along, unchanged (the box starts empty: every core)
        assert _number(page, "Parallel renders").input_value() == ""
        _set_number(page, "Parallel renders", "2")
        assert (_number(page, "Seed").input_value(), _number(page, "Participants").input_value()) == ("7", "3")

        # Database: the clip viewed
        app_browser.go_to(page, "Database")
        _set_number(page, "Clip to view", "3")
        app_browser.heading(page, "Clip 3").wait_for()
        _switch_database_and_back(page)
        app_browser.heading(page, "Clip 3").wait_for()
        assert _number(page, "Clip to view").input_value() == "3"

        app_browser.go_to(page, "Study stimuli")
        assert (_number(page, "Seed").input_value(), _number(page, "Participants").input_value()) == ("7", "3")
        assert app_browser.problems(page) == []


def test_the_database_chosen_stays_chosen_on_every_page(served):
    """A database other than the first option, chosen once, is the one every page opens, whichever
    way the user goes (leaving the Database page once brought the demo database back)."""
    url, home = served
    from gesturekit.demo import build_demo_database

    other = home / "db" / "other"
    if not (other / "database.json").is_file():
        build_demo_database(other, minutes=1.0)
    with app_browser.browser() as page:
        app_browser.open_app(page, url, "Synthesize", heading="Synthesize")
        _choose_database(page, "a database you built: other")
        for title in ("Database", "Synthesize", "Live", "Database", "Study stimuli", "Retrieval inspector", "Live"):
            app_browser.go_to(page, title)  # the new page drawn, and the app idle
            sidebar = app_browser.sidebar(page).inner_text()
            assert "· other:" in sidebar, f"on {title}: {sidebar[-300:]}"  # its name, no server path
        assert app_browser.problems(page) == []
