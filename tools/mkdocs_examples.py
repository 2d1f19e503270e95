"""MkDocs hook: the Examples page shows the Examples sections of the docstrings it names.

``docs/examples.md`` names each function or class by its public import path on a line of its
own, ``<!-- example: gesturekit.synthesis.synthesize -->``; the hook puts that docstring's
Examples section there (read statically by griffe, as the API reference is), so the page and the
doctests that ``tests/project/test_doctests.py`` runs are one text. ``mkdocs.yml`` names this
file under ``hooks``.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import griffe

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "examples.md"
MARKER = re.compile(r"^<!-- example: ([\w.]+) -->$", re.M)
#: the section's underlined title, then everything up to the next numpydoc section or the end
SECTION = re.compile(r"^Examples\n-+\n(.*?)(?=^\w[\w ]*\n-+\n|\Z)", re.M | re.S)


def listed(text: str | None = None) -> list[str]:
    """The import paths the Examples page names, in its order."""
    return MARKER.findall(PAGE.read_text(encoding="utf-8") if text is None else text)


def examples_section(docstring: str) -> str | None:
    """The body of a numpydoc docstring's Examples section, or None when it has none."""
    match = SECTION.search(docstring)
    return match.group(1).strip("\n") if match else None


def as_markdown(name: str, section: str) -> str:
    """The prose before the first ``>>>`` as text, the session as a Python console block."""
    prose, _, rest = section.partition(">>>")
    return f"## `{name}`\n\n{prose.strip()}\n\n```pycon\n>>>{rest.rstrip()}\n```\n".replace("\n\n\n", "\n\n")


def on_page_markdown(markdown: str, *, page: Any, config: Any, files: Any) -> str:
    if page.file.src_uri != "examples.md":
        return markdown
    package = griffe.load("gesturekit", search_paths=[str(ROOT)], resolve_aliases=True, resolve_external=False)

    def fill(match: re.Match) -> str:
        name = match.group(1)
        obj = package[name.removeprefix("gesturekit.")]
        section = examples_section(obj.docstring.value if obj.docstring else "")
        if section is None:
            raise ValueError(f"docs/examples.md names {name}, whose docstring has no Examples section")
        return as_markdown(name, section)

    return MARKER.sub(fill, markdown)
