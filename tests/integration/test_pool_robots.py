"""One pool, several robots (issue 31, item 5), on real processes: two simulated robots (two
prefixes, two simulators, two controllers, each robot's metrics) on one pool of two detector
workers (tools/scenarios/robots.py). Both pass ``ahead``; each robot's controller and metrics
see only their own camera: every detection heard on a robot's keys is of a frame of its own
camera (its frame id), and its metrics announce and count that camera alone."""

from __future__ import annotations

import pytest

from stack.config import Config
from tools.scenarios.robots import run_robots

pytestmark = pytest.mark.integration


def test_two_robots_on_one_pool_both_pass_ahead_each_on_its_own_keys() -> None:
    runs = run_robots(Config(), "ahead", robots=2, workers=2)
    served_by: set[str] = set()
    for k, run in enumerate(runs, 1):
        result, metrics = run["result"], run["metrics"]
        assert result["supervisor_exit_code"] == 0, result["log"]
        assert result["stale_commands"] == 0, result
        assert result["success"], (run["prefix"], result)
        camera = Config().stack.camera
        # Detections on this robot's keys are of its own camera's frames, and there are some.
        assert run["detection_frame_ids"] == {camera: [f"robot{k}_camera"]}, run
        assert sorted(metrics["cameras_announced"]) == [camera], metrics["cameras_announced"]
        assert metrics["cameras_announced"][camera]["frame_id"] == f"robot{k}_camera"
        assert sorted(metrics["cameras"]) == [camera]
        assert metrics["cameras"][camera]["frames"] > 0
        assert metrics["counters"].get("metrics.detections_unannounced", 0) == 0
        served_by.add(metrics["cameras"][camera]["served_by"])
    assert served_by <= {"detector", "detector_2"} and "" not in served_by, served_by
