"""Scores a scenario run against the simulator's truth. Pure: recorded messages in, figures out.

Figures:
    success                 the scenario's pass conditions all hold (see ``verdict``)
    time_to_reach_s         scenario time when the followed target was first within
                            follow distance + tolerance (None if never)
    final_distance_m        robot centre to the followed target's surface at the end, on the
                            line between them: a flat target's radius, a body's torso (what a
                            depth camera reads; the laser sees a body as its 0.25 m circle)
    min_clearance_m         least distance from the robot centre to an obstacle's surface or
                            a wall, as the laser measures it (None without obstacles and
                            walls)
    min_edge_clearance_m    least distance from the robot's circle to a drop-off's rectangle:
                            centre to rectangle less the robot's radius; negative: over the
                            edge (None without drop-offs)
    mean_bearing_error_deg  mean |bearing of the followed target| while it was in view
    final_bearing_deg       bearing of the followed target from the robot's forward axis at
                            the end (None without one); a ``must_face`` scenario needs it within
                            the first camera's half field of view: the robot turned to it
    frames_per_camera       frames heard on each camera's key
    detections_per_camera   detections messages heard on each camera's key
    seen_per_camera         each camera's detections messages that name a target class
    stale_commands          non-zero commands acting on detections whose frame was captured
                            longer than the detection timeout before the command was
                            stamped: the controller's own rule (must be 0)
    stop_after_kill_s       detector_dies: kill -> first zero command (None otherwise); the
                            robot must have been moving in the second before the kill
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

from common.contracts import ScenarioResult
from common.messages import ControllerStatus, Detections, GroundTruth, Twist
from services.controller.contract import ControllerSettings
from simworld.people import surface_m
from simworld.scenarios import Scenario
from simworld.world import Target, World

REACH_TOLERANCE_M = 0.4  # box-height ranging is coarse: +-0.4 m around the follow distance
STOP_MARGIN_S = 0.5  # detector_dies: allowed on top of the detection timeout
#: A hazard scenario (obstacles or drop-offs, no distance to reach): the robot may end this
#: much nearer an obstacle than the controller's safety distance (its stop from speed, the
#: sensor's noise) and still pass; nearer is a collision course.
HAZARD_MARGIN_M = 0.05


@dataclass
class ScenarioLog:
    """What the scenario runner heard, in arrival order."""

    truths: list[GroundTruth] = field(default_factory=list)
    twists: list[Twist] = field(default_factory=list)
    detections: dict[str, list[Detections]] = field(default_factory=dict)  # by camera
    frames: dict[str, int] = field(default_factory=dict)  # frames heard, by camera
    kill_ns: int | None = None
    statuses: list[ControllerStatus] = field(default_factory=list)
    # Each camera's frames as heard (their payloads, by capture stamp): only when a run
    # keeps them (a tracker's appearance is scored on them: tools/tracking).
    images: dict[str, dict[int, bytes]] = field(default_factory=dict)


def _bearing_deg(truth: GroundTruth, i: int) -> float:
    x, y, theta = truth.robot
    tx, ty = truth.targets_xy[i]
    b = math.atan2(ty - y, tx - x) - theta
    return math.degrees(math.atan2(math.sin(b), math.cos(b)))


def _distance(truth: GroundTruth, i: int, target: Target) -> float:
    """Robot centre to the target's surface on the line between them (a body's torso, a flat
    one's radius: simworld/people.py :func:`~simworld.people.surface_m`)."""
    x, y, _ = truth.robot
    tx, ty = truth.targets_xy[i]
    return math.hypot(tx - x, ty - y) - surface_m(target, truth.sim_time_s, (x, y))


def stale_commands(rec: ScenarioLog, timeout_s: float) -> int:
    """Non-zero commands on inputs older than the timeout, judged as the controller judges them.

    Each Twist carries the capture stamp of the frame it reacts to (``input_stamp_ns``) and is
    stamped with the instant at which the controller judged that frame's age; both are wall
    clock. The controller also applies the monotonic clock and the arrival time, each of which
    can only make an input older, so any command counted here broke the controller's rule.
    """
    count = 0
    for tw in rec.twists:
        age_s = (tw.header.stamp_ns - tw.input_stamp_ns) / 1e9
        if not tw.is_zero and (tw.input_stamp_ns <= 0 or age_s > timeout_s):
            count += 1
    return count


def score(
    scenario: Scenario, rec: ScenarioLog, world: World, s: ControllerSettings, hfov_deg: float
) -> ScenarioResult:
    """The figures of one run, and whether it passed."""
    truths = [t for t in rec.truths if t.sim_time_s > 0]
    if not truths:
        return {"success": False, "reason": "no simulation time elapsed"}
    clearance = min(
        (
            *(
                math.hypot(o.x - t.robot[0], o.y - t.robot[1]) - o.radius
                for t in truths
                for o in world.obstacles
            ),
            *(w.distance(t.robot[0], t.robot[1]) for t in truths for w in world.walls),
        ),
        default=None,
    )
    robot_radius = world.robot.radius
    edge_clearance = min(
        (d.distance(t.robot[0], t.robot[1]) - robot_radius for t in truths for d in world.drops),
        default=None,
    )
    out: ScenarioResult = {
        "scenario": scenario.name,
        "duration_s": truths[-1].sim_time_s,
        "time_to_reach_s": None,
        "final_distance_m": None,
        "min_clearance_m": clearance,
        "min_edge_clearance_m": edge_clearance,
        "mean_bearing_error_deg": None,
        "stale_commands": stale_commands(rec, s.detection_timeout_s),
        "commands": len(rec.twists),
        "nonzero_commands": sum(not t.is_zero for t in rec.twists),
        "stop_after_kill_s": None,
        "distance_travelled_m": sum(
            math.hypot(b.robot[0] - a.robot[0], b.robot[1] - a.robot[1])
            for a, b in itertools.pairwise(truths)
        ),
        "final_bearing_deg": None,
        "frames_per_camera": dict(rec.frames),
        "detections_per_camera": {camera: len(dets) for camera, dets in rec.detections.items()},
        "seen_per_camera": {
            camera: sum(any(n in s.target_classes for n in d.class_names) for d in dets)
            for camera, dets in rec.detections.items()
        },
    }
    if scenario.followed is not None:
        i = truths[-1].target_ids.index(scenario.followed)
        target = world.targets[i]
        reach = s.follow_distance_m + REACH_TOLERANCE_M
        out["time_to_reach_s"] = next(
            (t.sim_time_s for t in truths if _distance(t, i, target) <= reach), None
        )
        out["final_distance_m"] = _distance(truths[-1], i, target)
        out["final_bearing_deg"] = _bearing_deg(truths[-1], i)
        in_view = [
            abs(_bearing_deg(t, i)) for t in truths if abs(_bearing_deg(t, i)) <= hfov_deg / 2
        ]
        out["mean_bearing_error_deg"] = sum(in_view) / len(in_view) if in_view else None
    if rec.kill_ns is not None:
        kill_ns = rec.kill_ns
        before = [t for t in rec.twists if kill_ns - 1e9 <= t.header.stamp_ns < kill_ns]
        out["moving_at_kill"] = any(not t.is_zero for t in before)
        after = [t for t in rec.twists if t.header.stamp_ns >= kill_ns and t.is_zero]
        if after:
            out["stop_after_kill_s"] = (min(t.header.stamp_ns for t in after) - kill_ns) / 1e9
    out["success"], out["checks"] = verdict(scenario, out, s, hfov_deg)
    return out


def verdict(
    scenario: Scenario, f: ScenarioResult, s: ControllerSettings, hfov_deg: float
) -> tuple[bool, dict[str, bool]]:
    """The pass conditions, each named so a failure says which one (``hfov_deg``: the first
    camera's field of view)."""
    checks = {"no commands while stale": f["stale_commands"] == 0}
    if f["min_clearance_m"] is not None:
        checks["kept the safety distance"] = f["min_clearance_m"] >= s.safety_distance_m
        if not scenario.must_reach:
            # The hazard rule. While "kept the safety distance" above stands for every scenario
            # with obstacles it is the stricter and this one adds nothing; it is the rule a
            # hazard scenario is meant to be judged by should that one be relaxed.
            checks["never nearer an obstacle than the safety distance less the margin"] = (
                f["min_clearance_m"] >= s.safety_distance_m - HAZARD_MARGIN_M
            )
    edge = f.get("min_edge_clearance_m")
    if edge is not None:
        # Any scenario with a drop-off, whatever else it asks: over an edge is a fall.
        checks["never over an edge"] = edge > 0
    if scenario.must_reach:
        final = f["final_distance_m"]
        checks["reached the stop distance"] = (
            final is not None and abs(final - s.follow_distance_m) <= REACH_TOLERANCE_M
        )
    if scenario.must_face:
        bearing = f["final_bearing_deg"]
        checks["turned to face the target"] = bearing is not None and abs(bearing) <= hfov_deg / 2
    if scenario.followed is None:
        checks["stayed still"] = f["nonzero_commands"] == 0 and f["distance_travelled_m"] < 0.05
    if scenario.kill_detector_at_s is not None:
        stop = f["stop_after_kill_s"]
        checks["was moving when the detector died"] = bool(f.get("moving_at_kill"))
        checks["stopped in time after the detector died"] = (
            stop is not None and stop <= s.detection_timeout_s + STOP_MARGIN_S
        )
    return all(checks.values()), checks
