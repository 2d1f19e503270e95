"""User and file text in the app is shown as typed, never rendered as Markdown: a database label, a
take name or a typed path holding ``![x](http://...)`` is neither an image the browser fetches nor
a link. The escaping helper is checked against a Markdown renderer; the pages run with AppTest.
(tests/browser/test_browser_injection.py checks the same pages in a real browser.)"""

from __future__ import annotations

import html
import json
import re
import shutil
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from markdown_it import MarkdownIt
from streamlit.testing.v1 import AppTest

from gesturekit.app import HOME
from gesturekit.datasets.keypoint_example import write_keypoint_example
from tests.waits import APP_RUN_S

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT = APP_RUN_S  # a script run's deadline, which ends a hang (tests/waits.py)

#: CommonMark with raw HTML passed through and GitHub's tables and strikethrough: the most a
#: renderer could make of the text (Streamlit's own renderer does not pass raw HTML).
_RENDERER = MarkdownIt("commonmark", {"html": True}).enable(["table", "strikethrough"])
_MARKUP = re.compile(r"<(?!/?(?:p|br|strong|em|h[1-6])\b)[^>]*>")  # any tag but our own bold and breaks
#: What GitHub's Markdown (remark-gfm, Streamlit's renderer) turns into a link in a text node, after
#: escapes are undone: a bare URL or ``www.`` address, and an e-mail address.
_BARE_LINK = re.compile(r"(https?://|www(?=\.))[-.\w]+|[-.\w+]+@[-\w]+(\.[-\w]+)+", re.IGNORECASE)
WORD_JOINER = "\u2060"


def markdown_database(src: Path, dst: Path, *, label: str, take: str, source: str | None = None) -> Path:
    """A copy of the database at ``src`` in ``dst`` whose ``database.json`` gives it the label
    ``label`` and names its first take ``take`` (as a hand-edited or hostile file would)."""
    shutil.copytree(src, dst)
    meta = json.loads((dst / "database.json").read_text(encoding="utf-8"))
    meta["build"]["label"] = label
    meta["build"]["source"] = label if source is None else source
    meta["takes"][0]["name"] = take
    meta["takes"][0]["sources"].pop("generator", None)  # recorded takes, not the generated speaker
    (dst / "database.json").write_text(json.dumps(meta), encoding="utf-8")
    return dst


def rendered(markdown: str) -> str:
    """``markdown`` rendered to HTML."""
    return _RENDERER.render(markdown)


def visible(markup: str, *, joiners: bool = False) -> str:
    """The text a reader sees in rendered HTML (tags dropped, entities decoded, and the invisible
    word joiners that keep bare links text taken out unless ``joiners``)."""
    text = html.unescape(re.sub(r"<[^>]+>", "", markup))
    return text if joiners else text.replace(WORD_JOINER, "")


def _no_link(out: str) -> None:
    """No link, image or HTML tag in the rendered ``out``, and no bare link for GitHub's autolinker."""
    assert "<a " not in out and "<img" not in out and not _MARKUP.search(out), out
    assert not _BARE_LINK.search(visible(out, joiners=True)), out


def _escape():
    from gesturekit.app import display

    return display.escape_markdown


@pytest.fixture
def escape():
    return _escape()


# ---- the helper ---------------------------------------------------------------------------------

PAYLOADS = [
    "![l](http://127.0.0.1:8599/label.png) [c](http://127.0.0.1:8599/click)",
    "![x](pwn.png).bvh",
    '<img src="http://127.0.0.1:8599/x.png"> <a href="http://127.0.0.1:8599/">a</a>',
    "<http://127.0.0.1:8599/auto> [ref]\n\n[ref]: http://127.0.0.1:8599/ref",
    "# title\n- item\n1. one\n> quote\n```\ncode\n```\n| a | b |\n|---|---|\n| c | d |",
    "**bold** _it_ ~~gone~~ `code` $x^2$ :red[red] \\*kept\\* &amp; &#60;",
    "http://127.0.0.1:8599/bare HTTPS://x.y www.example.org me@example.org",
]


@pytest.mark.parametrize("text", PAYLOADS)
def test_escaped_payloads_render_as_their_own_text(escape, text):
    out = rendered(escape(text))
    _no_link(out)
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    assert [line.strip() for line in visible(out).splitlines() if line.strip()] == lines


@settings(max_examples=300, deadline=None)
@given(
    text=st.text(st.characters(blacklist_categories=["Cs", "Cc"]), max_size=60)
    | st.lists(st.sampled_from(["http", "s", "://", "www", ".", "@", "a", "b.c", "![", "](", ")", "<", ">"])).map(
        "".join
    )
)
def test_any_escaped_line_renders_as_itself_without_links_images_or_html(text):
    """Whatever one line of text holds, its rendering is that text, with no link, image or tag."""
    escape = _escape()
    out = rendered(f" {escape(text)} ")  # spaces around it: a bare link may begin after one
    _no_link(out)
    # the renderer trims a paragraph's ends, and turns NUL into U+FFFD, as browsers do
    assert visible(out).strip("\n") == text.replace("\0", "\ufffd").replace(WORD_JOINER, "").strip()


# ---- the pages ------------------------------------------------------------------------------------

LABEL = "![l](http://127.0.0.1:8599/label.png) [c](http://127.0.0.1:8599/click) <b>x</b> **y**"
TAKE = "![x](http://127.0.0.1:8599/take.png)"
MARKDOWN_KINDS = ("markdown", "caption", "error", "warning", "info", "success")


def _markdown_texts(at: AppTest) -> list[str]:
    """The Markdown source of every element of the page (main area and sidebar) that renders it."""
    return [str(el.value) for kind in MARKDOWN_KINDS for el in at.get(kind)]


def _assert_literal(at: AppTest, *payloads: str) -> None:
    """No element renders a link, an image or HTML, and each payload is shown as typed somewhere."""
    assert not at.exception, at.exception
    shown = []
    for source in _markdown_texts(at):
        out = rendered(source)
        _no_link(out)
        shown.append(visible(out))
    for payload in payloads:
        assert any(payload in text for text in shown), (payload, shown)


def _open(at: AppTest, folder: Path) -> AppTest:
    at.sidebar.selectbox[0].select_index(-1).run()  # "another folder…"
    return at.sidebar.text_input(key="_gk.database_typed").input(str(folder)).run()


@pytest.fixture
def hostile_db(app_env, tmp_path) -> Path:
    return markdown_database(app_env / "db" / "demo", tmp_path / "db" / "hostile", label=LABEL, take=TAKE)


@pytest.mark.slow
def test_a_label_and_take_name_from_database_json_are_shown_literally_on_home_and_database(hostile_db):
    at = _open(AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run(), hostile_db)
    _assert_literal(at, LABEL)  # Home: the sidebar's label and the page's source line
    assert any(LABEL in visible(rendered(i.value)) for i in at.sidebar.info)
    at.switch_page("views/3_Database.py").run()
    _assert_literal(at, LABEL, TAKE)  # the summary's label and source, the clip's take


@pytest.mark.slow
def test_a_take_name_is_shown_literally_by_the_synthesis_and_the_inspector(hostile_db):
    at = _open(AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run(), hostile_db)
    at.switch_page("views/1_Synthesize.py").run()
    at.button(key="synth.go").click().run()
    _assert_literal(at, LABEL)
    at.switch_page("views/2_Retrieval_inspector.py").run()
    _assert_literal(at, TAKE)  # the step's chosen take: the demo database has one take


@pytest.mark.slow
def test_a_typed_path_is_echoed_literally_in_an_error(app_env, tmp_path):
    typed = str(tmp_path / "![p](http:" / "127.0.0.1:8599" / "path.png)")
    at = _open(AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run(), Path(typed))
    _assert_literal(at, typed)
    assert any(typed in visible(rendered(e.value)) for e in at.error)


@pytest.mark.slow
def test_a_label_and_take_names_from_the_build_form_are_shown_literally(app_env, tmp_path):
    folder = tmp_path / "kp"
    write_keypoint_example(folder, fmt="csv", takes=2, seconds=6.0, seed=1)
    take = "![x](pwn.png)"
    for suffix in (".csv", ".wav"):
        (folder / f"take_00{suffix}").rename(folder / f"{take}{suffix}")
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    at.sidebar.text_input(key="_gk.build_folder").input(str(folder))
    at.sidebar.radio(key="_gk.build_naming").set_value("JSON joint map").run()
    at.sidebar.text_input(key="_gk.build_map").input(str(folder / "joint_map.json"))
    at.sidebar.number_input(key="_gk.build_fps").set_value(15.0)
    at.sidebar.selectbox(key="_gk.build_up").set_value("-y")
    at.sidebar.checkbox(key="_gk.build_bones").check()
    at.sidebar.text_input(key="_gk.build_out").input(str(tmp_path / "db" / "built"))
    at.sidebar.text_input(key="_gk.build.label").input(LABEL)
    at = at.sidebar.button(key="_gk.build_go").click().run()
    assert not [e.value for e in at.error]
    _assert_literal(at, LABEL, take)  # the new database's label; the reading notes name the takes
    at.switch_page("views/3_Database.py").run()
    _assert_literal(at, LABEL, take)
