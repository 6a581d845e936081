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
import uuid
from pathlib import Path
from typing import Any

import pytest

from deploy.credentials import generate
from stack.config_file import load_config
from tests.integration.conftest import REPO, STARTUP_S, Stack, wait_for, write_config
from tools.launch import free_port

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


def _secure_stack(tmp: Path, name: str, creds: Path, **tables: dict[str, Any]) -> Path:
    (tmp / name).mkdir()
    zenoh = {"mode": "client", "auth": "certificate", "credentials_dir": str(creds),
             "endpoint": f"tls/127.0.0.1:{free_port()}", **tables.pop("zenoh")}  # fmt: skip
    return write_config(tmp / name, zenoh=zenoh, **tables)


def test_two_robots_routers_linked_to_a_gpu_router_read_nothing_of_each_other(
    tmp_path: Path,
) -> None:
    """The secure profile with several robots: each robot its own router (a camera and the
    metrics), a GPU box's router linked to both whose one worker serves both robots' prefixes.
    Each robot's detections reach its own observer; robot 1's observer, asking robot 1's
    router, gets nothing of robot 2's: no detections, no tokens, no metrics answer."""
    run = uuid.uuid4().hex[:6]
    prefixes = (f"r1-{run}", f"r2-{run}")
    creds = tmp_path / "credentials"
    pool_prefix = f"pool-{run}"
    # One CA; each robot's principals named as its own (its router's too), the worker as the
    # pool's, the GPU box's router as its stack's.
    names = {f"{pool_prefix}/{r}" for r in ("supervisor", "detector_gpu", "observer")}
    names |= {f"{p}/{r}" for p in prefixes for r in ("supervisor", "camera", "metrics", "observer")}
    generate(creds, principals=tuple(sorted(names)))
    camera = {"source": "sample:cameraman", "frame_id": "front", "rate_hz": 3.0,
              "resize": [320, 240]}  # fmt: skip
    robots = [
        _secure_stack(
            tmp_path,
            p,
            creds,
            zenoh={"remote_principals": ["detector_gpu"], "linked_routers": [pool_prefix]},
            stack={"prefix": p, "camera": "front"},
            camera=camera,
            supervisor={"services": ["camera", "metrics"]},
        )
        for p in prefixes
    ]
    endpoints = [load_config(r, environ={}).zenoh.endpoint for r in robots]
    gpu = _secure_stack(
        tmp_path, "gpu", creds,
        zenoh={"connect": endpoints, "remote_principals": ["camera", "metrics", "observer"],
               "linked_routers": list(prefixes)},
        stack={"prefix": pool_prefix, "camera": "front"}, camera=camera,
        supervisor={"services": ["detector"]},
        detector={"worker_id": "gpu", "imgsz": 320, "prefixes": list(prefixes)},
    )  # fmt: skip
    stacks = [Stack(path, path.parent / "log") for path in (*robots, gpu)]
    r1, r2, pool = stacks
    try:
        # (The pool's worker is ready once both robots have detections: the test's session of
        # the pool stack may have joined a robot's router, which it also connects to.)
        for r in (r1, r2):
            r.wait_ready({"camera", "metrics"})
        mine = [r.subscribe(r.keys.detections("front"))[1] for r in (r1, r2)]
        _, theirs = r1.subscribe(r2.keys.all_detections())  # robot 1's observer, robot 2's keys
        wait_for(lambda: all(len(m) >= 3 for m in mine), STARTUP_S,
                 lambda: f"detections on both robots' keys:\n{pool.log()}")  # fmt: skip
        seen = len(mine[1])
        wait_for(lambda: len(mine[1]) >= seen + 5, 60, "more of robot 2's detections")
        assert theirs == [], "robot 1's observer heard robot 2's detections"
        assert list(r1.session.liveliness().get(f"{r2.keys.prefix}/**", timeout=2.0)) == []
        assert list(r1.session.get(r2.keys.metrics(), timeout=2.0)) == []
        # The control: robot 2's own observer sees its tokens (its camera's, the worker's).
        assert list(r2.session.liveliness().get(f"{r2.keys.prefix}/**", timeout=2.0))
        assert r1.metrics() is not None  # its own robot's answer does come
        assert r2.metrics() is not None
    finally:
        codes = [s.stop() for s in stacks]
    assert codes == [0, 0, 0], [s.log() for s in stacks]
