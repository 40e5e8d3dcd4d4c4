"""The design documents the code cites live in docs/: every `DESIGN.md section N` and `MAROON_FORMAT.md N.M` cited
in a docstring or comment names a section that exists there."""
from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CITATION = re.compile(r"\b(DESIGN|MAROON_FORMAT)\.md(?: section)? (\d+(?:\.\d+)?)")


def _sections(name: str) -> set[str]:
    text = (REPO / "docs" / f"{name}.md").read_text(encoding="utf-8")
    return set(re.findall(r"^#{2,3} (\d+(?:\.\d+)?)\.? ", text, flags=re.M))


def test_every_cited_section_exists_in_docs():
    sections = {name: _sections(name) for name in ("DESIGN", "MAROON_FORMAT")}
    cited = {(match[1], match[2], str(path.relative_to(REPO)))
             for folder in ("bench", "methods", "metrics", "tests", "examples")
             for path in (REPO / folder).rglob("*.py")
             for match in CITATION.finditer(path.read_text(encoding="utf-8"))}
    assert len(cited) > 20
    missing = sorted((doc, number, where) for doc, number, where in cited if number not in sections[doc])
    assert not missing, f"citations of sections docs/ does not have: {missing}"
