"""Every ```toml block of README.md and docs/*.md is a config the stack loads
(stack/config_file.py), so the examples cannot drift from the settings. The rule
(tests/readme.py): a block is a whole config file saved at the repository root, beside the
other named blocks of every page; no fragments. A block marked ``# not loadable: <why>`` must
fail to load, so that the mark cannot outlive its reason.

The pool's two (``# robot.toml``, ``# gpu.toml`` in docs/pool.md; their secured forms in
docs/security.md extend them) are also held to what the pages say of them;
tests/integration/test_readme_pool.py runs them."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from common.errors import ConfigError
from stack.config_file import load_config
from tests.readme import (
    README,
    REPO,
    Block,
    all_blocks,
    as_tested,
    named_block,
    pages,
    toml_blocks,
)

BLOCKS = all_blocks()
LOADABLE = [b for b in BLOCKS if not b.not_loadable]
NOT_LOADABLE = [b for b in BLOCKS if b.not_loadable]


def _save(block: Block, where: Path, blocks: list[Block] = BLOCKS) -> Path:
    """``block`` as a file at the repository root would read, beside the pages' other named
    blocks: an ``extends`` names one of those, or a file from the repository root."""
    names = {b.name for b in blocks if b.name}
    for other in blocks:
        if other.name and other is not block:
            (where / other.name).write_text(other.text, encoding="utf-8")
    data = tomllib.loads(block.text)  # a block that is not TOML fails here, naming itself
    text = block.text
    base = data.get("extends")
    if isinstance(base, str) and base not in names:
        text = text.replace(f'"{base}"', f'"{(REPO / base).as_posix()}"', 1)
    path = where / (block.name or f"block-{block.line}.toml")
    path.write_text(text, encoding="utf-8")
    return path


def test_the_pages_have_toml_blocks() -> None:
    where = [b.where for b in BLOCKS]
    assert any(b.page == "README.md" for b in BLOCKS), where  # the robot's first config
    # The pool's hosts (plain, secured), several robots, cameras, depth, ROS 2.
    assert len(BLOCKS) >= 10, where
    assert {b.page for b in BLOCKS} >= {"README.md", "docs/pool.md", "docs/security.md"}, where


def test_each_name_is_one_block_across_the_pages() -> None:
    names = [b.name for b in BLOCKS if b.name]
    assert len(names) == len(set(names)), sorted(names)


@pytest.mark.parametrize("block", LOADABLE, ids=[b.where for b in LOADABLE])
def test_every_toml_block_loads(block: Block, tmp_path: Path) -> None:
    try:
        load_config(_save(block, tmp_path), environ={})
    except ConfigError as exc:
        pytest.fail(f"{block.where}: {exc}")


def test_a_block_marked_not_loadable_does_not_load(tmp_path: Path) -> None:
    """None is marked today; a mark whose block loads after all is stale."""
    loads = []
    for block in NOT_LOADABLE:
        try:
            load_config(_save(block, tmp_path), environ={})
        except (ConfigError, tomllib.TOMLDecodeError):
            continue
        loads.append(f"{block.where} ({block.not_loadable})")
    assert loads == [], "marked not loadable, yet it loads"


def test_the_docs_pages_are_read(tmp_path: Path) -> None:
    """Every docs/*.md is one of the pages, and a mark is read from a block's first line."""
    assert set(pages()) == {README, *(REPO / "docs").glob("*.md")}
    page = tmp_path / "page.md"
    page.write_text(
        '```toml\n# not loadable: a misspelt field, on purpose\n[detector]\nworker = "x"\n```\n'
        '```toml\n# a.toml: fine\n[detector]\nworker_id = "x"\n```\n',
        encoding="utf-8",
    )
    marked, named = toml_blocks(page)
    assert (marked.not_loadable, marked.name) == ("a misspelt field, on purpose", "")
    assert (named.not_loadable, named.name, named.line) == ("", "a.toml", 6)
    with pytest.raises(ConfigError, match="worker"):
        load_config(_save(marked, tmp_path, [marked, named]), environ={})
    assert named_block("a.toml", [page]) == named


def test_the_gpu_box_needs_only_its_endpoint_backend_and_worker_id(tmp_path: Path) -> None:
    robot = load_config(_save(named_block("robot.toml"), tmp_path), environ={})
    gpu_block = named_block("gpu.toml")
    gpu = load_config(_save(gpu_block, tmp_path), environ={})
    tables = tomllib.loads(gpu_block.text)
    assert sorted(tables) == ["detector", "supervisor", "zenoh"]
    assert sorted(tables["detector"]) == ["backend", "worker_id"]
    assert gpu.supervisor.services == ("detector",)
    assert gpu.detector.backend in ("cuda", "tensorrt")
    assert list(gpu.all_cameras) == [gpu.stack.camera]  # no camera table of its own
    # One pool: the same prefix, two worker names; the GPU box links to the robot's router.
    assert gpu.stack.prefix == robot.stack.prefix
    assert gpu.detector.worker_id and robot.detector.worker_id
    assert gpu.detector.worker_id != robot.detector.worker_id
    assert robot.zenoh.mode == gpu.zenoh.mode == "client"
    assert gpu.zenoh.connect == (robot.zenoh.endpoint,)
    assert {"camera", "detector", "controller", "metrics"} <= set(robot.supervisor.services)
    assert len(robot.all_cameras) >= 2


def test_as_tested_changes_only_the_address_the_devices_and_the_gpu_backend() -> None:
    robot = named_block("robot.toml").text
    gpu = named_block("gpu.toml").text
    tested = as_tested(robot, addresses={"10.0.0.2": "10.9.9.9"}, samples=("astronaut", "chelsea"))
    assert "10.0.0.2" not in tested and "device:" not in tested
    assert '"sample:astronaut"' in tested and '"sample:chelsea"' in tested
    assert tested.count("\n") == robot.count("\n")
    gpu_tested = as_tested(gpu, addresses={"10.0.0.2": "10.9.9.9"}, samples=())
    assert tomllib.loads(gpu_tested)["detector"]["backend"] == "onnx"
    changed = [
        (a, b) for a, b in zip(gpu.splitlines(), gpu_tested.splitlines(), strict=True) if a != b
    ]
    assert [a.split("=")[0].strip() for a, _ in changed] == ["connect", "backend"], changed


def test_a_bad_block_is_caught(tmp_path: Path) -> None:
    """The check can fail: a misspelt setting in a block is a ConfigError naming it."""
    readme = tmp_path / "page.md"
    readme.write_text(
        'text\n```toml\n# gpu.toml: x\n[detector]\nworker = "gpu"\n```\n', encoding="utf-8"
    )
    [block] = toml_blocks(readme)
    assert (block.line, block.name) == (2, "gpu.toml")
    with pytest.raises(ConfigError, match="worker"):
        load_config(_save(block, tmp_path), environ={})
    assert README.is_file()
