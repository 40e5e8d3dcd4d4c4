"""The documents hold together: every `DESIGN.md section N` and `MAROON_FORMAT.md N.M` cited in a docstring or
comment names a section that exists in docs/; every guide or measurement page the code cites exists, with the
heading it names; every relative link of the README and docs/ leads to a file; every page is reachable from its
folder's index; the README stays a short door (<= 200 lines)."""
from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CODE = ("bench", "methods", "metrics", "tests", "examples", "configs", "scripts", "hydra_plugins")
CITATION = re.compile(r"\b(DESIGN|MAROON_FORMAT)\.md(?: section)? (\d+(?:\.\d+)?)")
# docs/guide/metrics.md or docs/measurements/gpu.md, optionally followed by a heading in quotes
PAGE_CITATION = re.compile(r"\b(docs/(?:guide|measurements)/[\w.-]+\.md)(?:,? \"([^\"]+)\")?")
LINK = re.compile(r"\]\(([^)\s]+)\)")
README_LINES_MAX = 200


def _code_files():
    return [path for folder in CODE for path in (REPO / folder).rglob("*")
            if path.suffix in (".py", ".yaml", ".sh") and path.is_file()]


def _doc_pages():
    return [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]


def _headings(path: Path) -> list[str]:
    return re.findall(r"^#+ (.+?)\s*$", path.read_text(encoding="utf-8"), flags=re.M)


def _one_line(text: str) -> str:
    """A quoted heading that a docstring or comment wraps over lines, as one line."""
    return " ".join(re.sub(r"\n\s*#", " ", text).split())


def _sections(name: str) -> set[str]:
    text = (REPO / "docs" / f"{name}.md").read_text(encoding="utf-8")
    return set(re.findall(r"^#{2,3} (\d+(?:\.\d+)?)\.? ", text, flags=re.M))


def test_every_cited_section_exists_in_docs():
    sections = {name: _sections(name) for name in ("DESIGN", "MAROON_FORMAT")}
    cited = {(match[1], match[2], str(path.relative_to(REPO)))
             for path in _code_files() if path.suffix == ".py"
             for match in CITATION.finditer(path.read_text(encoding="utf-8"))}
    assert len(cited) > 20
    missing = sorted((doc, number, where) for doc, number, where in cited if number not in sections[doc])
    assert not missing, f"citations of sections docs/ does not have: {missing}"


def test_every_cited_guide_page_and_heading_exists():
    """Code cites a page of the guide or of the measurements (with a heading where it means one section): the page
    must exist and hold a heading that begins with the quoted words."""
    cited = [(match[1], match[2], str(path.relative_to(REPO)))
             for path in _code_files() for match in PAGE_CITATION.finditer(path.read_text(encoding="utf-8"))]
    assert len(cited) > 10
    missing = [(page, where) for page, _, where in cited if not (REPO / page).is_file()]
    assert not missing, f"cited pages that do not exist: {missing}"
    wrong = [(page, heading, where) for page, heading, where in cited
             if heading and not any(h.startswith(_one_line(heading)) for h in _headings(REPO / page))]
    assert not wrong, f"cited headings the page does not have: {wrong}"


def test_code_cites_no_section_of_the_readme():
    """The README is the short door; sections live in the guide (bench/synth/README.md is a page of its own)."""
    pattern = re.compile(r"README(?:\.md)?[,'\"]? (?:section )?[\"']|README's |see README\b")
    offending = [f"{path.relative_to(REPO)}:{number}" for path in _code_files() if path != Path(__file__).resolve()
                 for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
                 if pattern.search(line.replace("bench/synth/README.md", ""))]
    assert not offending, f"code citing a README section (cite the docs/guide page instead): {offending}"


def test_every_relative_link_leads_to_a_file():
    broken = []
    for page in _doc_pages():
        for target in LINK.findall(page.read_text(encoding="utf-8")):
            if re.match(r"[a-z]+:", target) or target.startswith("#"):
                continue                                  # a web address or an anchor on the same page
            if not (page.parent / target.split("#")[0]).exists():
                broken.append(f"{page.relative_to(REPO)} -> {target}")
    assert not broken, f"links that lead nowhere: {broken}"


def test_every_page_is_in_its_index():
    """A newcomer finds every page from the README: each page of docs/guide and docs/measurements is linked from
    that folder's README.md, and the README links both indexes."""
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    for folder in ("guide", "measurements"):
        index = REPO / "docs" / folder / "README.md"
        assert f"docs/{folder}/README.md" in readme or f"docs/{folder}/" in readme
        linked = set(LINK.findall(index.read_text(encoding="utf-8")))
        pages = {path.name for path in index.parent.glob("*.md")} - {"README.md"}
        unlisted = sorted(page for page in pages if page not in linked)
        assert pages and not unlisted, f"pages missing from docs/{folder}/README.md: {unlisted}"


def test_readme_is_short():
    lines = (REPO / "README.md").read_text(encoding="utf-8").count("\n")
    assert lines <= README_LINES_MAX, f"README.md has {lines} lines; move detail into docs/guide/"
