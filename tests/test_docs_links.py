"""The README stays a short entry page and every relative link of README.md and docs/ resolves.

A relative link is a markdown link ``[text](target)`` whose target is not a URL or a pure
``#anchor``; its path (without ``#anchor``) is resolved against the linking file's folder and
must name an existing file or folder of the repository.
"""

import re
from pathlib import Path

import pytest

from pipeline.core.config import stage_names

REPO = Path(__file__).resolve().parents[1]
README_MAX_LINES = 250
#: [text](target): text without brackets, target up to the first blank or ')' (may span a line break)
LINK = re.compile(r"\[[^\]]*\]\(\s*([^)\s]+)(?:\s+\"[^\"]*\")?\s*\)")
FENCE = re.compile(r"^(```|~~~).*?^\1", re.S | re.M)


def markdown_files() -> list[Path]:
    return [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]


def relative_targets(text: str) -> list[str]:
    """Relative link targets of a markdown text, code blocks left out."""
    text = FENCE.sub("", text)
    out = []
    for target in LINK.findall(text):
        if re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target) or target.startswith("#"):
            continue  # http:, https:, mailto:, ... or an anchor in the same page
        out.append(target)
    return out


def broken_links(path: Path) -> list[str]:
    broken = []
    for target in relative_targets(path.read_text(encoding="utf-8")):
        file_part = target.split("#", 1)[0]
        if not (path.parent / file_part).exists():
            broken.append(target)
    return broken


def test_readme_is_short():
    n_lines = len((REPO / "README.md").read_text(encoding="utf-8").splitlines())
    assert n_lines <= README_MAX_LINES, f"README.md has {n_lines} lines (at most {README_MAX_LINES})"


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: str(p.relative_to(REPO)))
def test_relative_links_resolve(path):
    assert broken_links(path) == [], f"{path.relative_to(REPO)}: broken relative links"


def test_link_check_sees_broken_links(tmp_path):
    """The check itself: it finds a missing target, also across a line break, and skips URLs,
    anchors and code blocks."""
    (tmp_path / "there.md").write_text("x")
    page = tmp_path / "page.md"
    page.write_text("[ok](there.md#a) [gone](missing.md) [url](https://example.org/x)\n"
                    "[anchor](#top) [split\ntext](\nalso_missing.md)\n```\n[code](not_checked.md)\n```\n")
    assert broken_links(page) == ["missing.md", "also_missing.md"]


def test_every_stage_has_a_reference_page():
    pages = {p.stem for p in (REPO / "docs" / "stages").glob("*.md")}
    assert set(stage_names()) <= pages, f"stages without docs/stages/<stage>.md: {set(stage_names()) - pages}"
