"""The README is a guide that fits on a few screens, and it and the pages of docs/ link only to files and sections
that exist (a page renamed or a heading reworded breaks a link silently otherwise)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
LINK = re.compile(r"\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```.*?^```", re.MULTILINE | re.DOTALL)
README_MAX_LINES = 300


def anchors(page: Path) -> set[str]:
    """The anchors a Markdown renderer gives the page's headings: lower case, punctuation dropped, spaces to
    hyphens (GitHub's rule)."""
    headings = re.findall(r"^#{1,6}\s+(.*?)\s*$", FENCE.sub("", page.read_text()), flags=re.MULTILINE)
    return {re.sub(r"[^\w\- ]", "", h.lower()).replace(" ", "-") for h in headings}


def test_the_readme_is_a_guide_not_a_report():
    lines = (REPO / "README.md").read_text().splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines: move detail to a page of docs/"


def test_the_anchor_rule_matches_the_headings_linked_here():
    assert {"re-planning-what-val-has-accepted-before-the-answer", "the-stores-pages"} <= (
        anchors(REPO / "docs" / "service.md") | anchors(REPO / "docs" / "results.md"))


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(REPO).as_posix())
def test_every_relative_link_resolves(page: Path):
    broken = []
    for target in LINK.findall(FENCE.sub("", page.read_text())):
        if re.match(r"[a-z]+:", target):  # http:, https:, mailto: are not checked (no network in the suite)
            continue
        path, _, anchor = target.partition("#")
        linked = (page.parent / path).resolve() if path else page
        if not linked.exists():
            broken.append(f"{target}: no such file")
        elif anchor and linked.suffix == ".md" and anchor not in anchors(linked):
            broken.append(f"{target}: no heading with that anchor")
    assert not broken, f"{page.name}: " + "; ".join(broken)
