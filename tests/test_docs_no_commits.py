"""Pages say which machine a figure came from, never which commit (issue 43)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LATER: set[str] = set()  # pages allowed to name a commit: none
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted(
    (ROOT / "docs" / "tutorial").glob("*.md")
)]  # fmt: skip
_HEX = re.compile(r"(?<![\w.])[0-9a-f]{7,40}(?![\w.])")


def commit_like(text: str) -> list[str]:
    """Hex words of 7-40 digits with at least one letter and one digit (a short or full SHA)."""
    return [h for h in _HEX.findall(text) if re.search("[a-f]", h) and re.search("[0-9]", h)]


def test_commit_like_finds_shas_and_not_numbers():
    assert commit_like("run on `f5cac69` and 78509ef today") == ["f5cac69", "78509ef"]
    assert commit_like("GM = 3.986004418e14 m3/s2, 1234567 px, deadbeef") == []


@pytest.mark.parametrize("page", [p for p in PAGES if p.name not in LATER], ids=lambda p: p.name)
def test_page_names_no_commit(page):
    assert commit_like(page.read_text(encoding="utf-8")) == []
