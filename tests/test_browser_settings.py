"""Settings stay as the user left them: the database selector and page switches, in a real browser.

Choosing "another folder…" in the sidebar stops the page before its settings
are drawn; the settings, the control table and the next run must come back
unchanged. Skipped, with the reason, where the playwright package or Chromium
is missing (see ``tests/app_browser.py``).
"""

from __future__ import annotations

import json

import pytest

from tests import app_browser

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
    return page.locator('[data-testid="stNumberInput"]', has_text=label).locator("input").first


def _set_number(page, label: str, value: str) -> None:
    box = _number(page, label)
    box.fill(value)
    box.press("Enter")
    app_browser.wait_idle(page)


def _numbers(page) -> dict[str, str]:
    return {label: _number(page, label).input_value() for label in SETTINGS}


def _choose_database(page, option: str) -> None:
    sidebar = page.locator('[data-testid="stSidebar"]')
    sidebar.locator('[data-testid="stSelectbox"]').first.click()
    page.get_by_role("option", name=option).first.click()
    app_browser.wait_idle(page)


def _table(page, *, expect: int = 0) -> list[str]:
    """The control table's cells, row by row, read from the data editor's accessible grid.

    A newly drawn editor fills its grid a moment later: waits up to 10 s for ``expect`` cells.
    """
    cells = page.locator('[data-testid="stDataFrame"]').first.locator('[role="gridcell"]')
    for _ in range(50):
        if cells.count() >= expect:
            break
        page.wait_for_timeout(200)
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
    grid = page.locator('[data-testid="stDataFrame"]').first
    canvas = grid.locator('canvas[data-testid="data-grid-canvas"]')
    for _ in range(3):  # a busy machine may open the cell's editor late: try again
        canvas.scroll_into_view_if_needed()
        box = canvas.bounding_box()
        header = grid.locator(".dvn-underlay > canvas").nth(1).bounding_box()["height"]
        rows = canvas.locator('tbody tr[role="row"]').count()
        row_height = (box["height"] - header) / (rows + 1)  # the data rows and the editor's empty row
        page.mouse.click(box["x"] + box["width"] / 2, box["y"] + header + row_height / 2)
        at = None
        for _ in range(25):  # the selection shows in the table a moment after the click
            at = _selected_cell(grid)
            if at is not None:
                break
            page.wait_for_timeout(200)
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
            editor.wait_for(state="visible", timeout=5000)
        except Exception:  # noqa: BLE001  (not opened: select again)
            page.keyboard.press("Escape")
            continue
        page.keyboard.press("Control+a")
        # keys at a person's pace, and a pause before Enter: on a busy machine the cell's editor
        # took the keys into its box but committed the value it held before them (nothing was sent)
        page.keyboard.type(text, delay=50)
        page.wait_for_timeout(300)
        page.keyboard.press("Enter")
        app_browser.wait_idle(page)
        for _ in range(25):  # the grid shows the committed value a moment later
            cells = _table(page)
            if len(cells) > row * 3 + column and cells[row * 3 + column] == text:
                return
            page.wait_for_timeout(200)
    raise AssertionError(f"could not type {text!r} into the table's row {row}, column {column}")


def _bands(page) -> int:
    return page.locator('[data-testid="stPlotlyChart"]').first.locator("text", has_text="both_hands=high").count()


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
        app_browser.box_select(page, 0.2, 0.45)
        assert _bands(page) == 1
        # an edit in the table itself (the editor's own state, not a box selection)
        _edit_cell(page, 0, 1, "4.25")
        cells = _table(page)
        assert len(cells) == 3 and cells[1] == "4.25" and cells[2] == "both_hands=high"
        assert _numbers(page) == SETTINGS

        # "another folder…" with nothing typed stops the page before its settings are drawn
        _choose_database(page, "another folder…")
        page.get_by_text("Type the folder of a database").first.wait_for()
        typed = page.locator('[data-testid="stSidebar"] input[placeholder="/path/to/database"]')
        typed.fill(str(home / "db" / "demo"))
        typed.press("Enter")
        app_browser.wait_idle(page)
        _expect_kept(page, cells)

        _choose_database(page, "demo database (generated speaker)")
        _expect_kept(page, cells)

        # and straight back again, without typing
        _choose_database(page, "another folder…")
        _choose_database(page, "demo database (generated speaker)")
        _expect_kept(page, cells)

        app_browser.go_to(page, "Database")
        app_browser.go_to(page, "Synthesize")
        _expect_kept(page, cells)

        app_browser.run_and_wait(page)
        app_browser.wait_idle(page)
        caption = page.locator('[data-testid="stCaptionContainer"]', has_text="seed 5").first.inner_text()
        assert "k = 2" in caption and "seed 5" in caption and f"{float(cells[0]):g}-4.25:both_hands=high" in caption
        assert "differs from the paper" in caption and "N = 6 (paper 8)" in caption
        # the saved config is the one the run used
        with page.expect_download() as info:
            page.get_by_role("button", name="Config (JSON)").click()
        config = json.loads(open(info.value.path(), encoding="utf-8").read())
        settings = config["synthesis"]
        assert (settings["k"], settings["segment"], settings["seed"], settings["record"]) == (2, 6, 5, 7)
        assert settings["refiner_keep_hz"] == pytest.approx(1.5)
        assert settings["control"] == f"{float(cells[0]):g}-4.25:both_hands=high"
        assert app_browser.problems(page) == []


def _switch_database_and_back(page) -> None:
    _choose_database(page, "another folder…")
    page.get_by_text("Type the folder of a database").first.wait_for()
    _choose_database(page, "demo database (generated speaker)")


def test_the_other_pages_keep_their_settings_too(served):
    url, _ = served
    with app_browser.browser() as page:
        # Study stimuli: plain persisted number inputs
        app_browser.open_app(page, url, "Study_stimuli", heading="Study stimuli")
        _set_number(page, "Seed", "7")
        _set_number(page, "Participants", "3")
        _switch_database_and_back(page)
        page.get_by_role("heading", name="Study stimuli", exact=True).first.wait_for()
        assert (_number(page, "Seed").input_value(), _number(page, "Participants").input_value()) == ("7", "3")
        _set_number(page, "Parallel renders", "2")  # a later change sends the kept values along, unchanged
        assert (_number(page, "Seed").input_value(), _number(page, "Participants").input_value()) == ("7", "3")

        # Database: the clip viewed
        app_browser.go_to(page, "Database")
        _set_number(page, "Clip to view", "3")
        page.get_by_role("heading", name="Clip 3").first.wait_for()
        _switch_database_and_back(page)
        page.get_by_role("heading", name="Clip 3").first.wait_for()
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
        _choose_database(page, f"other  ({home / 'db'})")
        for title in ("Database", "Synthesize", "Live", "Database", "Study stimuli", "Retrieval inspector", "Live"):
            app_browser.go_to(page, title)
            page.wait_for_timeout(300)  # a run the page switch may still bring
            app_browser.wait_idle(page)
            sidebar = page.locator('[data-testid="stSidebar"]').inner_text()
            assert str(other) in sidebar, f"on {title}: {sidebar[-300:]}"
        assert app_browser.problems(page) == []
