"""Every scenario runs the real stack (sim, detector, controller, metrics over Zenoh) through
``python -m tools.scenarios scenario NAME --json``, and states its own pass condition here."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import pytest

from services.controller.contract import ControllerSettings
from tests.integration.conftest import REPO
from tools.launch import free_port
from tools.scenarios.score import REACH_TOLERANCE_M, STOP_MARGIN_S

pytestmark = pytest.mark.integration

DEFAULTS = ControllerSettings()
#: Following by depth, the final distance to the target's surface is within this of the stop
#: distance: depth ranges as well as the laser (REACH_TOLERANCE_M allows for the box height);
#: 0.2 still fails a robot that stops a target radius (0.25 m) short.
DEPTH_REACH_TOLERANCE_M = 0.2


#: The detector's input in these runs (a scenario of its own may set another): at 640 a loaded
#: 2-core CI machine (a CPU burner per core, another test's stack beside) detected about once a
#: second, late for the controller's 1 s dead-man, and the robot hardly moved; the person is
#: found at 320 as well at these distances (simworld/scenarios.py).
TEST_IMGSZ = 320


def run(name: str, *extra: str, env: dict[str, str] | None = None) -> dict[str, Any]:
    args = list(extra)
    base = REPO / "deploy" / "stack.toml"
    if "--config" in args:
        at = args.index("--config") + 1
        base = Path(args[at]).resolve()
        del args[at - 1 : at + 1]
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "scenario.toml"
        config.write_text(f'extends = "{base}"\n[detector]\nimgsz = {TEST_IMGSZ}\n')
        return _run(name, "--config", str(config), *args, env=env)


def _run(name: str, *extra: str, env: dict[str, str] | None = None) -> dict[str, Any]:
    done = subprocess.run(
        [sys.executable, "-m", "tools.scenarios", "scenario", name, "--json", *extra],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=400,
        env=env,
    )
    assert "Traceback" not in done.stderr, done.stderr
    result: dict[str, Any] = json.loads(done.stdout)
    required = {
        "success",
        "time_to_reach_s",
        "final_distance_m",
        "min_clearance_m",
        "mean_bearing_error_deg",
        "stale_commands",
    }
    assert required <= result.keys()
    assert result["supervisor_exit_code"] == 0, result["log"]
    # Every scenario: never a moving command on stale inputs.
    assert result["stale_commands"] == 0, result
    assert done.returncode == (0 if result["success"] else 1)
    return result


def reached(result: dict[str, Any]) -> bool:
    """At the stop distance, within the tolerance."""
    final = result["final_distance_m"]
    return final is not None and abs(final - DEFAULTS.follow_distance_m) <= REACH_TOLERANCE_M


@pytest.mark.parametrize("name", ["ahead", "side", "crossing"])
def test_reaches_the_stop_distance(name: str) -> None:
    # An endpoint exported in the user's shell (as the README teaches) must not move the
    # scenario's private stack: the runner's own config wins in the supervisor it starts.
    exported = {**os.environ, "STACK__ZENOH__ENDPOINT": f"tcp/127.0.0.1:{free_port()}"}
    result = run(name, env=exported)
    assert reached(result), result
    assert result["time_to_reach_s"] is not None
    assert result["success"], result


def test_two_people_lock_holds_on_alice() -> None:
    # bob walks in nearer (and so bigger) than alice: a follower without a lock turns to bob
    # and ends up by him; with the lock the robot ends at alice's stop distance.
    result = run("two_people")
    assert reached(result), result
    assert result["success"], result


@pytest.mark.parametrize("mode", ["follow", "track"])
def test_obstacle_is_never_closer_than_the_safety_distance(mode: str) -> None:
    # Track mode obeys the same obstacle stop as follow (it drove into the box before).
    result = run("obstacle", "--mode", mode)
    assert result["mode"] == mode, result
    assert result["min_clearance_m"] >= DEFAULTS.safety_distance_m, result
    assert result["success"], result


def test_no_target_means_standing_still() -> None:
    result = run("no_target")
    assert result["nonzero_commands"] == 0 and result["distance_travelled_m"] < 0.05, result
    assert result["success"], result


@pytest.mark.parametrize("attempt", [1, 2])
def test_robot_stops_in_time_when_the_detector_dies(attempt: int) -> None:
    # Run twice: stale_commands must be 0 on every run, not on most (the scorer and the
    # controller judge staleness by the same rule, so a race cannot make one of them disagree).
    result = run("detector_dies")
    stop = result["stop_after_kill_s"]
    assert stop is not None and stop <= DEFAULTS.detection_timeout_s + STOP_MARGIN_S, result
    assert result["success"], result


def test_behind_the_robot_turns_round_and_stops_at_the_follow_distance() -> None:
    # The person starts behind the robot, in the rear camera's image alone (the scenario adds
    # a rear camera, mount_yaw_deg 180): the detector serves both cameras, the controller turns
    # the rear camera's bearing into the robot's frame, turns round and follows.
    result = run("behind")
    assert result["frames_per_camera"].keys() == {"front", "rear"}, result
    assert result["seen_per_camera"]["rear"] > 0, result
    assert result["checks"]["turned to face the target"], result
    assert reached(result), result
    assert result["success"], result


def test_ahead_with_the_simulator_playing_a_ros2_robot() -> None:
    # The simulator speaks only ROS 2 (Image, LaserScan, Twist on rmw_zenoh keys, through a
    # router it hosts): every frame, scan and command passes through the ros2 bridge.
    result = run("ahead", "--ros2")
    assert reached(result), result
    assert result["success"], result
    log = Path(result["log"]).read_text()
    assert "ros2 INFO in the ROS 2 graph" in log and "ros2: exited" not in log


@pytest.mark.parametrize("name", ["ahead", "obstacle"])
def test_a_robot_with_a_depth_camera_and_no_laser(name: str) -> None:
    # deploy/depth.toml: the simulator renders depth and has no laser; the controller follows
    # by the target's depth (ahead) and stops for the obstacle its virtual scan shows.
    # The hard world (the default): its stereo noise in disparity space; in range space a far
    # floor pixel read as near as 0.4 m now and then, and the follower stood blocked by it.
    config = REPO / "deploy" / "depth.toml"
    result = run(name, "--config", str(config))
    log = Path(result["log"]).read_text()
    assert "sim.laser = false: a robot with no laser, no scan" in log, log
    assert "forward motion needs fresh depth;" in log, log
    if name == "ahead":
        assert "distance to the target from depth" in log, log
        assert reached(result), result
        # Depth sees the person's front, as the laser does: the robot keeps follow_distance_m
        # from their surface (the score's distance), not from their middle, so it ends as near
        # the stop distance as with the laser (1.04 m), not a radius nearer.
        final = result["final_distance_m"]
        assert abs(final - DEFAULTS.follow_distance_m) <= DEPTH_REACH_TOLERANCE_M, result
    else:
        # Stopped by what the depth shows, or by what it showed and the map remembers.
        assert "(depth)" in log or "(remembered)" in log, "never stopped for the obstacle"
        assert result["min_clearance_m"] >= DEFAULTS.safety_distance_m, result
    assert result["success"], result
