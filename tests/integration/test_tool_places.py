"""A scenario run can be placed (issue 39, item 8): its files in ``$TMPDIR``, its stack on the
port given, and nothing of it left in the repo's ``state/`` beside the robot's own files."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from stack.config_file import load_config
from tests.integration.conftest import REPO
from tests.integration.test_scenarios import run
from tools.launch import free_port

pytestmark = pytest.mark.integration


def test_a_scenario_run_keeps_its_files_in_tmpdir_and_listens_on_the_port_given(
    tmp_path: Path,
) -> None:
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    port = free_port()
    result = run("ahead", "--port", str(port), env={**os.environ, "TMPDIR": str(tmp)})
    assert result["success"], result
    workdir = Path(result["log"]).parent
    assert workdir.parent == tmp, result["log"]
    config = load_config(workdir / "stack.toml", environ={})
    assert config.zenoh.endpoint == f"tcp/127.0.0.1:{port}"
    # The supervisor's lock (supervisor.lock_dir unset) went to TMPDIR as well.
    assert len(list(tmp.glob("zenoh-yolo-stack-*.lock"))) == 1, sorted(tmp.iterdir())
    # The private controller's latched e-stop file is the run's, not the repo's state/.
    prefix = config.stack.prefix.replace("/", "_")
    assert config.estop_path == workdir / "estop.json"
    assert config.estop_path.exists()
    assert not (REPO / "state" / f"estop-{prefix}.json").exists()
    assert not (REPO / "state" / f"depth-memory-{prefix}.npz").exists()
