"""The README's example configs, as the tests read them (tests/unit/test_readme_configs.py loads
every one; tests/integration/test_readme_pool.py runs the pool's two on two network namespaces).

A ```toml block of README.md is a whole config file, saved at the repository root: there are no
fragments. A block whose first line is a comment naming a file (``# robot.toml: ...``) is that
file; the tests find it by that name, and another block's ``extends`` may name it (else an
``extends`` names a file from the repository root).

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

#: The hosts' addresses in the README's examples: the robot beside a GPU box, and two robots
#: sharing one.
ROBOT_ADDRESS, ROBOT1_ADDRESS, ROBOT2_ADDRESS = "10.0.0.2", "10.0.0.11", "10.0.0.12"
#: The GPU backends, run on the CPU's backend where there is no GPU.
GPU_BACKENDS = ("cuda", "tensorrt")

_BLOCK = re.compile(r"^```toml\n(.*?)^```$", re.MULTILINE | re.DOTALL)
_NAME = re.compile(r"#\s*([\w.-]+\.toml)\b")
_DEVICE = re.compile(r'"device:(\d+)"')
_BACKEND = re.compile(r'^(backend\s*=\s*)"(?:{})"'.format("|".join(GPU_BACKENDS)), re.MULTILINE)


@dataclass(frozen=True)
class Block:
    """One ```toml block: where it starts (1-based line of its fence), its file name if its
    first line names one, and its text."""

    line: int
    name: str
    text: str


def toml_blocks(path: Path = README) -> list[Block]:
    text = path.read_text(encoding="utf-8")
    out = []
    for m in _BLOCK.finditer(text):
        body = m.group(1)
        first = body.split("\n", 1)[0]
        named = _NAME.match(first)
        out.append(Block(text.count("\n", 0, m.start()) + 1, named.group(1) if named else "", body))
    return out


def named_block(name: str, path: Path = README) -> Block:
    found = [b for b in toml_blocks(path) if b.name == name]
    if len(found) != 1:
        raise LookupError(f"{path.name}: {len(found)} ```toml blocks named {name}, expected 1")
    return found[0]


def as_tested(text: str, *, addresses: Mapping[str, str], samples: tuple[str, ...]) -> str:
    """``text`` as a test runs it: each README address of ``addresses`` is the test's host's,
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
    """A secured block with the test's credentials folder in place of the README's default
    (``secrets/``, the user's own): a ``credentials_dir`` line first in its ``[zenoh]`` table."""
    head, sep, tail = text.partition("[zenoh]\n")
    if not sep:
        raise ValueError("the block has no [zenoh] table")
    return f'{head}{sep}credentials_dir = "{credentials_dir.as_posix()}"\n{tail}'
