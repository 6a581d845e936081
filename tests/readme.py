"""The example configs of README.md and docs/*.md, as the tests read them
(tests/unit/stack/test_readme_configs.py loads every one; tests/integration/test_readme_pool.py
runs the pool's, docs/pool.md and docs/security.md, on network namespaces).

A ```toml block of a page is a whole config file, saved at the repository root: there are no
fragments. A block whose first line is a comment naming a file (``# robot.toml: ...``) is that
file; the tests find it by that name, whichever page holds it (a name is used once across the
pages), and another block's ``extends`` may name it (else an ``extends`` names a file from the
repository root). A block that is deliberately not a loadable config starts with a comment
``# not loadable: <why>``; the test checks that it indeed fails to load.

:func:`as_tested` makes the only changes a test may make to a block, each one a thing that
differs between the reader's machines and the test's, and nothing else.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
README = REPO / "README.md"
DOCS = REPO / "docs"

#: The hosts' addresses in the examples (docs/pool.md, docs/security.md): the robot beside a
#: GPU box, and two robots sharing one.
ROBOT_ADDRESS, ROBOT1_ADDRESS, ROBOT2_ADDRESS = "10.0.0.2", "10.0.0.11", "10.0.0.12"
#: The GPU backends, run on the CPU's backend where there is no GPU.
GPU_BACKENDS = ("cuda", "tensorrt")

_BLOCK = re.compile(r"^```toml\n(.*?)^```$", re.MULTILINE | re.DOTALL)
_NAME = re.compile(r"#\s*([\w.-]+\.toml)\b")
_NOT_LOADABLE = re.compile(r"#\s*not loadable:\s*(\S.*)$")
_DEVICE = re.compile(r'"device:(\d+)"')
_BACKEND = re.compile(r'^(backend\s*=\s*)"(?:{})"'.format("|".join(GPU_BACKENDS)), re.MULTILINE)


@dataclass(frozen=True)
class Block:
    """One ```toml block: where it starts (1-based line of its fence), its file name if its
    first line names one, its text, the page that holds it (relative to the repository) and,
    for a block marked ``# not loadable: <why>``, why."""

    line: int
    name: str
    text: str
    page: str = "README.md"
    not_loadable: str = ""

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"


def pages() -> list[Path]:
    """The pages whose ```toml blocks are configs: the README and every docs/*.md."""
    return [README, *sorted(DOCS.glob("*.md"))]


def toml_blocks(path: Path = README) -> list[Block]:
    text = path.read_text(encoding="utf-8")
    page = path.relative_to(REPO).as_posix() if path.is_relative_to(REPO) else path.name
    out = []
    for m in _BLOCK.finditer(text):
        body = m.group(1)
        first = body.split("\n", 1)[0]
        named, unloadable = _NAME.match(first), _NOT_LOADABLE.match(first)
        out.append(
            Block(
                text.count("\n", 0, m.start()) + 1,
                named.group(1) if named else "",
                body,
                page,
                unloadable.group(1) if unloadable else "",
            )
        )
    return out


def all_blocks(paths: list[Path] | None = None) -> list[Block]:
    """Every page's ```toml blocks, the README's first."""
    return [b for path in (pages() if paths is None else paths) for b in toml_blocks(path)]


def named_block(name: str, paths: list[Path] | None = None) -> Block:
    """The one block named ``name`` (``# name.toml: ...``) across the pages."""
    found = [b for b in all_blocks(paths) if b.name == name]
    if len(found) != 1:
        where = ", ".join(b.where for b in found) or "none"
        raise LookupError(f"{len(found)} ```toml blocks named {name} ({where}), expected 1")
    return found[0]


def as_tested(text: str, *, addresses: Mapping[str, str], samples: tuple[str, ...]) -> str:
    """``text`` as a test runs it: each example's address of ``addresses`` is the test's host's,
    camera ``device:N`` is the bundled photo ``samples[N]`` (``sample:<name>``), and a GPU
    backend is ``onnx`` (ONNX Runtime on the CPU). Nothing else changes."""

    def sample(m: re.Match[str]) -> str:
        return f'"sample:{samples[int(m.group(1))]}"'

    out = text
    for readme, tested in addresses.items():
        out = out.replace(readme, tested)
    out = _DEVICE.sub(sample, out)
    return _BACKEND.sub(r'\1"onnx"', out)


def with_credentials(text: str, credentials_dir: Path) -> str:
    """A secured block with the test's credentials folder in place of the example's default
    (``secrets/``, the user's own): a ``credentials_dir`` line first in its ``[zenoh]`` table."""
    head, sep, tail = text.partition("[zenoh]\n")
    if not sep:
        raise ValueError("the block has no [zenoh] table")
    return f'{head}{sep}credentials_dir = "{credentials_dir.as_posix()}"\n{tail}'
