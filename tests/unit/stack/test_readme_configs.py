"""Every ```toml block of README.md is a config the stack loads (stack/config_file.py), so the
README's examples cannot drift from the settings. The rule (tests/readme.py): a block is a whole
config file saved at the repository root, beside the other named blocks; no fragments.

The pool's two (``# robot.toml``, ``# gpu.toml``; their secured forms extend them) are also held
to what the README says of them; tests/integration/test_readme_pool.py runs them."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from common.errors import ConfigError
from stack.config_file import load_config
from tests.readme import README, REPO, Block, as_tested, named_block, toml_blocks

BLOCKS = toml_blocks()


def _save(block: Block, where: Path) -> Path:
    """``block`` as a file at the repository root would read, beside the README's other named
    blocks: an ``extends`` names one of those, or a file from the repository root."""
    names = {b.name for b in BLOCKS if b.name}
    for other in BLOCKS:
        if other.name and other is not block:
            (where / other.name).write_text(other.text, encoding="utf-8")
    data = tomllib.loads(block.text)  # a block that is not TOML fails here, naming itself
    text = block.text
    base = data.get("extends")
    if isinstance(base, str) and base not in names:
        text = text.replace(f'"{base}"', f'"{(REPO / base).as_posix()}"', 1)
    path = where / (block.name or f"readme-{block.line}.toml")
    path.write_text(text, encoding="utf-8")
    return path


def test_the_readme_has_toml_blocks() -> None:
    assert len(BLOCKS) >= 6, [
        b.line for b in BLOCKS
    ]  # profile, pool hosts (plain, secured), cameras


@pytest.mark.parametrize("block", BLOCKS, ids=[f"README.md:{b.line}" for b in BLOCKS])
def test_every_readme_toml_block_loads(block: Block, tmp_path: Path) -> None:
    try:
        load_config(_save(block, tmp_path), environ={})
    except ConfigError as exc:
        pytest.fail(f"README.md line {block.line}: {exc}")


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
    readme = tmp_path / "README.md"
    readme.write_text(
        'text\n```toml\n# gpu.toml: x\n[detector]\nworker = "gpu"\n```\n', encoding="utf-8"
    )
    [block] = toml_blocks(readme)
    assert (block.line, block.name) == (2, "gpu.toml")
    with pytest.raises(ConfigError, match="worker"):
        load_config(_save(block, tmp_path), environ={})
    assert README.is_file()
