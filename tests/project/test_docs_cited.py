"""Every document the code and the README cite is in the repository, and so is every section
of it that they name."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

#: ``docs/NAME.md`` or ``docs/NAME.md``, "Section" as the code's docstrings and comments write them
CITE = re.compile(r'``(docs/[\w./-]+)``(?:,\s*"([^"]+)")?')


def _sources() -> list[Path]:
    folders = ("gesturekit", "app", "bench", "tools", "tests")
    # this file writes the citation's form in a comment
    return sorted(p for f in folders for p in (REPO / f).rglob("*.py") if p.name != "test_docs_cited.py")


def _citations() -> list[tuple[Path, str, str | None]]:
    found = []
    for path in _sources():
        text = path.read_text(encoding="utf-8")
        for m in CITE.finditer(text):
            found.append((path, m.group(1), m.group(2)))
    return found


def _headings(doc: Path) -> set[str]:
    return {line.lstrip("#").strip() for line in doc.read_text(encoding="utf-8").splitlines() if line.startswith("#")}


def test_the_code_cites_documents():
    cited = {doc for _, doc, _ in _citations()}
    assert "docs/METHOD.md" in cited  # the search, the refiner and its training cite it


@pytest.mark.parametrize(
    "path, doc, section", _citations(), ids=lambda v: str(v) if not isinstance(v, Path) else v.name
)
def test_every_cited_document_and_section_exists(path, doc, section):
    file = REPO / doc
    assert file.exists(), f"{path.relative_to(REPO)} cites {doc}, which the repository does not have"
    if section:
        assert section in _headings(file), (
            f"{path.relative_to(REPO)} cites section {section!r} of {doc}, which has none"
        )


def test_every_file_the_readme_links_exists():
    text = (REPO / "README.md").read_text(encoding="utf-8")
    links = re.findall(r"\]\(((?:docs|bench|tools|notebooks|app|gesturekit)/[^)#\s]+)", text)
    assert links, "the README links files of the repository"
    missing = sorted({link for link in links if not (REPO / link).exists()})
    assert not missing, f"the README links files the repository does not have: {missing}"
