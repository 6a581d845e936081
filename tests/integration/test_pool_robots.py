"""One pool, several robots (issue 31, item 5): two simulated robots, each a stack of its own
under its own key prefix (its simulator, controller and metrics), share one pool of two
detector workers that serves both prefixes (``detector.prefixes``). Each robot's detections
go back on its own keys, and both robots pass ``ahead``
(``python -m tools.scenarios scenario ahead --robots 2``, tools/scenarios/robots.py)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.integration.conftest import REPO

pytestmark = pytest.mark.integration


def test_two_robots_on_one_pool_of_two_workers_both_pass_ahead(tmp_path: Path) -> None:
    base = tmp_path / "base.toml"
    # Input 320: two robots' cameras on a loaded 2-core machine.
    base.write_text(f'extends = "{REPO / "deploy" / "stack.toml"}"\n[detector]\nimgsz = 320\n')
    done = subprocess.run(
        [sys.executable, "-m", "tools.scenarios", "scenario", "ahead", "--robots", "2",
         "--workers", "2", "--json", "--config", str(base)],
        cwd=REPO, capture_output=True, text=True, timeout=500,
    )  # fmt: skip
    assert "Traceback" not in done.stderr, done.stderr
    runs = json.loads(done.stdout)
    pool_log = Path(runs["pool_log"]).read_text(errors="replace")
    assert runs["pool_exit_code"] == 0, pool_log[-3000:]
    for prefix, result in zip(runs["prefixes"], runs["robots"], strict=True):
        assert result["supervisor_exit_code"] == 0, Path(result["log"]).read_text()[-3000:]
        assert result["stale_commands"] == 0, (prefix, result)
        assert result["success"], (prefix, {k: v for k, v in result.items() if k != "log"})
        # Each robot's camera was served by the pool, named with its robot's prefix.
        assert re.search(rf"serving \[[^]]*'{re.escape(prefix)}/front'", pool_log), pool_log
    assert done.returncode == 0
    print(
        "two robots on one pool: "
        + ", ".join(
            f"{p} reached in {r['time_to_reach_s']:.1f} s"
            for p, r in zip(runs["prefixes"], runs["robots"], strict=True)
        )
    )
