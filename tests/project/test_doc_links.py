"""Every relative link of the documentation resolves.

The pages checked: ``README.md``, every ``docs/**/*.md`` and ``bench/README.md``. A Markdown link
or image ``[text](target)`` whose target is not ``http(s):`` or ``mailto:`` must name an existing
file or folder, relative to the page; a ``#anchor`` (alone, or after a ``.md`` target) must name a
heading of that page, slugged as GitHub slugs it (lower case, punctuation but ``-`` and ``_``
dropped, spaces to ``-``, ``-1``, ``-2`` ... for repeats). Fenced code blocks and inline code are
not Markdown, so links inside them are not checked.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

#: ``[text](target)`` and ``![alt](target)``; the target up to a space (a title) or ``)``.
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
FENCE = re.compile(r"^\s*(```|~~~)")
INLINE_CODE = re.compile(r"(`+)(?:(?!\1).)+?\1")
HEADING = re.compile(r"^ {0,3}#{1,6}\s+(.*?)\s*#*\s*$")
EXTERNAL = ("http://", "https://", "mailto:")


def doc_pages() -> list[Path]:
    """The pages whose links are checked."""
    pages = [ROOT / "README.md", ROOT / "bench" / "README.md"]
    pages += sorted((ROOT / "docs").rglob("*.md"))
    return [page for page in pages if page.is_file()]


def prose_lines(text: str, keep_code: bool = False) -> list[str]:
    """The page's lines outside fenced code blocks, inline code removed unless ``keep_code``."""
    lines, fenced = [], False
    for line in text.splitlines():
        if FENCE.match(line):
            fenced = not fenced
            continue
        if not fenced:
            lines.append(line if keep_code else INLINE_CODE.sub("", line))
    return lines


def slug(heading: str) -> str:
    """GitHub's anchor of a heading's text (links reduced to their text, markup dropped)."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)
    text = re.sub(r"[^\w\- ]", "", text.lower())
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """Every heading anchor of a Markdown page, repeats numbered as GitHub numbers them."""
    seen: dict[str, int] = {}
    result = set()
    for line in prose_lines(page.read_text(encoding="utf-8"), keep_code=True):
        match = HEADING.match(line)
        if not match:
            continue
        base = slug(match.group(1))
        count = seen.get(base, 0)
        seen[base] = count + 1
        result.add(base if count == 0 else f"{base}-{count}")
    return result


def links(page: Path) -> list[str]:
    """Every link target of the page's prose."""
    return [m.group(1) for line in prose_lines(page.read_text(encoding="utf-8"))
            for m in LINK.finditer(line)]


def broken(page: Path) -> list[str]:
    """The page's relative links that name no file, or no heading of the page they name."""
    problems = []
    for target in links(page):
        if target.startswith(EXTERNAL):
            continue
        path_part, _, anchor = target.partition("#")
        dest = (page.parent / path_part).resolve() if path_part else page
        if not dest.exists():
            problems.append(f"{target}: no such file")
            continue
        if anchor and dest.suffix == ".md" and anchor.lower() not in anchors(dest):
            shown = os.path.relpath(dest, page.parent)
            problems.append(f"{target}: no heading #{anchor} in {shown}")
    return problems


def test_pages_found() -> None:
    names = {page.relative_to(ROOT).as_posix() for page in doc_pages()}
    assert {"README.md", "bench/README.md", "docs/results.md", "docs/benchmark.md"} <= names


@pytest.mark.parametrize("page", doc_pages(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_relative_links_resolve(page: Path) -> None:
    assert broken(page) == [], f"{page.relative_to(ROOT)}: broken links"


def test_checker_finds_broken_links(tmp_path: Path) -> None:
    (tmp_path / "there.md").write_text("# A heading, with `code`\n\n## Repeat\n\n## Repeat\n")
    page = tmp_path / "page.md"
    page.write_text(
        "[ok](there.md) [ok](there.md#a-heading-with-code) [ok](there.md#repeat-1)\n"
        "![missing](figures/none.png) [bad anchor](there.md#nowhere) [web](https://x.org/a)\n"
        "`[in code](gone.md)`\n```\n[in a fence](gone.md)\n```\n[self](#top) [mail](mailto:a@b.c)\n"
        "# Top\n"
    )
    assert broken(page) == [
        "figures/none.png: no such file",
        "there.md#nowhere: no heading #nowhere in there.md",
    ]


def test_slug_matches_github() -> None:
    assert slug("Θ on the paper profile (first reported 2026-12-01, ca21acf)") == (
        "θ-on-the-paper-profile-first-reported-2026-12-01-ca21acf"
    )
    assert slug("Simulated participants, CoSpar and the user study") == (
        "simulated-participants-cospar-and-the-user-study"
    )
