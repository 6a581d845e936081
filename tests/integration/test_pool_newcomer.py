"""A simulated robot whose detector is a pool's worker on another supervisor, set up as the
two-robots example of docs/pool.md does (issue 39, items 5 and 7): no worker, the simulator says
what it waits for and nothing claims motion; the worker joins, the robot moves; the robot's
metrics list the worker it does not run, and ``zstack pool`` shows the pool from the box."""

from __future__ import annotations

import json
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

from common.control_messages import ControllerStatus
from common.messages import GroundTruth, Twist
from stack.config_file import load_config
from tests.integration.conftest import REPO, STARTUP_S, Stack, wait_for, write_config
from tools.launch import free_port

pytestmark = pytest.mark.integration

MOVED_M = 0.2  # the robot has moved once its pose is this far from the start
NO_WORKER_S = 8.0  # longer than the simulator's warning period (services/sim/waiting.py)


def test_a_robot_served_by_a_pool_worker_on_another_supervisor(tmp_path: Path) -> None:
    run = uuid.uuid4().hex[:6]
    site, robot_prefix = f"site{run}", f"site{run}/robot1"
    (tmp_path / "robot").mkdir()
    (tmp_path / "box").mkdir()
    robot_cfg = write_config(
        tmp_path / "robot",
        zenoh={"mode": "client", "endpoint": f"tcp/127.0.0.1:{free_port()}"},
        stack={"prefix": robot_prefix, "camera": "front"},
        # docs/pool.md's robot: the simulator, the controller, the metrics; no worker of its own.
        supervisor={"services": ["sim", "controller", "metrics"]},
        sim={"scenario": "ahead", "width": 320, "height": 240},
        controller={"mode": "follow", "no_laser": False},
        detector={"pool_prefix": site, "prefixes": [robot_prefix]},
    )
    robot = Stack(robot_cfg, tmp_path / "robot" / "log")
    box = None
    try:
        robot.wait_ready({"sim", "controller", "metrics"})
        _, truths = robot.subscribe(robot.keys.sim_truth())
        _, statuses = robot.subscribe(robot.keys.controller_status())
        _, commands = robot.subscribe(robot.keys.cmd_vel())
        wait_for(
            lambda: "the world stands still until: detections of camera(s) front" in robot.log(),
            NO_WORKER_S + 10,
            lambda: f"the simulator's WARNING of what it waits for:\n{robot.log()}",
        )
        line = next(x for x in robot.log().splitlines() if "stands still until" in x)
        assert " WARNING " in line, line
        states = {ControllerStatus.decode(s).state for s in statuses}
        assert states and not states & {"following", "tracking"}, states
        assert all(Twist.decode(c).linear[0] <= 0.0 for c in commands)
        poses = {GroundTruth.decode(t).robot for t in truths}
        assert len(poses) == 1, poses  # the world stands still: one pose, the start's
        start = poses.pop()

        # The shared GPU box: one worker, its router linked to the robot's.
        endpoint = load_config(robot_cfg, environ={}).zenoh.endpoint
        box_cfg = write_config(
            tmp_path / "box",
            zenoh={"mode": "client", "endpoint": f"tcp/127.0.0.1:{free_port()}",
                   "connect": [endpoint]},
            stack={"prefix": f"{site}/box", "camera": "front"},
            supervisor={"services": ["detector"]},
            detector={"worker_id": "gpu", "imgsz": 320, "pool_prefix": site,
                      "prefixes": [robot_prefix]},
        )  # fmt: skip
        box = Stack(box_cfg, tmp_path / "box" / "log")

        def moved() -> bool:
            if not truths:
                return False
            x, y, _ = GroundTruth.decode(truths[-1]).robot
            return abs(x - start[0]) + abs(y - start[1]) >= MOVED_M

        wait_for(moved, STARTUP_S, lambda: f"the robot moving:\n{robot.log()}\n{box.log()}")
        assert "scenario clock started" in robot.log()

        # Item 7: the robot's metrics list the box's worker, whose counters it never hears.
        def listed() -> dict[str, object] | None:
            answer = robot.metrics()
            workers = (answer or {}).get("workers", {})
            return workers.get("detector_gpu")  # type: ignore[no-any-return]

        gpu = wait_for(listed, 30, "detector_gpu in the robot's metrics")
        assert gpu["live"] and gpu["cameras"] == ["front"], gpu
        assert gpu["capacity_hz"] > 0 and gpu["robots"] == [robot_prefix], gpu
        assert gpu["load_from"] == "cameras" and gpu["load"] > 0, gpu

        # ... and the box sees the whole pool, with no metrics service there.
        done = subprocess.run(
            [sys.executable, "-m", "deploy.zstack", "pool", "--config", str(box_cfg)],
            cwd=REPO, capture_output=True, text=True, timeout=60, check=False,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
        view = json.loads(done.stdout)
        assert view["workers"]["detector_gpu"]["cameras"] == [f"{robot_prefix}/front"], view
        assert view["robots"][robot_prefix]["front"]["served_by"] == "detector_gpu", view
        assert view["unserved"] == [], view
        print(f"pool worker on another supervisor: {json.dumps(gpu)}")
    finally:
        codes = [s.stop() for s in (robot, box) if s is not None]
    assert all(c == 0 for c in codes), codes
