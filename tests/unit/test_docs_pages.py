"""The README a newcomer reads in ten minutes, and the docs/ pages it maps (issue 40, point 6).

- The README stays short (``README_MAX_LINES``) and names the two commands as the Makefile and
  CI run them.
- Its map ("## The docs") names every docs/*.md page, one line each.
- Every relative link of the README and the docs reaches a file, and a ``#anchor`` a heading
  of that page (GitHub's slugs), so moving a section cannot leave a link behind.
- Every module path they name (``common/keys.py``, ``services/detector/rounds.py::Rounds``) is a
  file of the tree, so moving or renaming a module cannot leave its old path in a page.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.readme import DOCS, README, REPO, pages

#: "At most about 250 lines" (issue 40, point 6).
README_MAX_LINES = 250
#: A markdown link's target: ``[text](target)``.
_LINK = re.compile(r"\]\(([^)\s]+)\)")
_HEADING = re.compile(r"^#{1,6}\s+(.*?)\s*#*\s*$")
#: A module path from the repository's root: folders, then a ``.py`` file. Not a template
#: (``services/<name>/contract.py``), a glob (``test_pool_*.py``), a path under ``~`` or ``$X``,
#: nor the tail of a longer path or of a URL.
_MODULE_PATH = re.compile(r"(?<![\w./<>*$~-])((?:[\w.-]+/)+[\w-]+\.py)(?![\w*<>/-])")


def slug(heading: str) -> str:
    """A heading's anchor as GitHub makes it: lower case, punctuation but ``-`` and ``_``
    dropped, each space a ``-``."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """The anchors of ``page``'s headings (outside fenced blocks)."""
    out: set[str] = set()
    fenced = False
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and (m := _HEADING.match(line)):
            out.add(slug(m.group(1)))
    return out


def broken_links(page: Path) -> list[str]:
    """Each relative link of ``page`` whose file is missing, or whose anchor is no heading."""
    out = []
    for m in _LINK.finditer(page.read_text(encoding="utf-8")):
        target = m.group(1)
        if re.match(r"[a-z][a-z0-9+.-]*:", target):  # https:, mailto: ...
            continue
        file, _, anchor = target.partition("#")
        path = (page.parent / file).resolve() if file else page
        if not path.exists():
            out.append(f"{target}: no such file")
        elif anchor and path.suffix == ".md" and anchor not in anchors(path):
            out.append(f"{target}: no heading #{anchor} in {path.name}")
    return out


def dead_module_paths(page: Path) -> list[str]:
    """Each module path ``page`` names that is no file of the tree, with its line."""
    out = []
    for n, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
        for m in _MODULE_PATH.finditer(line):
            if not (REPO / m.group(1)).is_file():
                out.append(f"line {n}: {m.group(1)}")
    return out


def test_the_readme_is_short() -> None:
    lines = README.read_text(encoding="utf-8").count("\n")
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines: move details to docs/"


def test_the_readme_names_the_two_commands_as_make_and_ci_run_them() -> None:
    readme = README.read_text(encoding="utf-8")
    section = readme.split("## The two commands", 1)[1]
    block = section.split("```", 2)[1]
    commands = [line.split("#", 1)[0].strip() for line in block.strip().splitlines()]
    assert commands == ["make run", "make test"]
    makefile = (REPO / "Makefile").read_text(encoding="utf-8")
    assert re.search(r"^run:", makefile, re.M) and re.search(r"^test:", makefile, re.M)
    ci = (REPO / ".ci" / "run").read_text(encoding="utf-8").strip().splitlines()
    assert ci[-1].strip() == "make test"  # CI runs the README's test command


def test_the_readme_maps_every_docs_page() -> None:
    readme = README.read_text(encoding="utf-8")
    mapped = readme.split("## The docs", 1)[1]
    listed = re.findall(r"^- \[[^\]]+\]\(docs/([\w.-]+\.md)\): \S", mapped, re.M)
    assert len(listed) == len(set(listed)), listed
    assert sorted(listed) == sorted(p.name for p in DOCS.glob("*.md"))


@pytest.mark.parametrize("page", pages(), ids=lambda p: p.relative_to(REPO).as_posix())
def test_every_relative_link_reaches_its_file_and_heading(page: Path) -> None:
    assert broken_links(page) == []


def test_a_broken_link_is_caught(tmp_path: Path) -> None:
    """The check can fail: a missing page and a missing heading are both named."""
    (tmp_path / "other.md").write_text("# Other page\n\n## A `code` heading: here\n")
    page = tmp_path / "page.md"
    page.write_text(
        "[ok](other.md#a-code-heading-here) [gone](missing.md) [no](other.md#nowhere) "
        "[web](https://example.com/x#y)\n"
    )
    assert [b.split(":")[0] for b in broken_links(page)] == ["missing.md", "other.md#nowhere"]


@pytest.mark.parametrize("page", pages(), ids=lambda p: p.relative_to(REPO).as_posix())
def test_every_module_path_named_is_a_file(page: Path) -> None:
    assert dead_module_paths(page) == []


def test_a_dead_module_path_is_caught(tmp_path: Path) -> None:
    """The check can fail: a made-up module is named; a real one, a template, a glob, a
    function after ``::`` and a URL's path are not."""
    page = tmp_path / "page.md"
    page.write_text(
        "`common/keys.py::Keys` and `common/no_such_module.py`\n"
        "`services/<name>/contract.py`, `tests/unit/detector/test_pool_*.py`,\n"
        "https://example.com/a/b.py and `perception/gone.py`.\n"
    )
    assert dead_module_paths(page) == [
        "line 1: common/no_such_module.py",
        "line 3: perception/gone.py",
    ]
