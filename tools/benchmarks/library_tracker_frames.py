"""The frames the tracker comparison (library_tracker.py) feeds every tracker: the scenario's
world stepped and rendered offline with the simulator's own world and renderer, the real
default detector run once on each frame (or its boxes read from a cache), and the truth boxes
of the targets the camera shows."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from services.controller.contract import ControllerSettings
from services.sim.contract import SimSettings
from tools.benchmarks.library_shared import log

SCENARIOS_MEASURED = ("crossing", "two_people")
# Extra worlds, not stack scenarios: two people whose boxes overlap, the case where id switches
# happen at all (in crossing and two_people no two boxes ever overlap). Robot still.
STRESS_WORLDS = {
    # bob walks between the robot and alice, hiding her for a few seconds
    "pass_in_front": (((0, 4.5, 0.0),), ((0, 3.0, -2.0), (12, 3.0, 2.0)), 20.0),
    # alice and bob walk across each other's path at nearly the same depth
    "cross_paths": (((0, 4.5, -1.5), (10, 4.5, 1.5)), ((0, 4.2, 1.5), (10, 4.2, -1.5)), 20.0),
}


@dataclasses.dataclass
class ScenarioFrames:
    """What one scenario run gives the trackers: per frame, time, truth and detections."""

    name: str
    robot: str
    times: list[float]
    truth_ids: list[list[str]]  # ids of the targets whose projected box is visible
    truth_boxes: list[npt.NDArray[np.float64]]  # (k, 4) their boxes, clipped to the image
    det_xyxy: list[npt.NDArray[np.float32]]
    det_scores: list[npt.NDArray[np.float32]]
    det_classes: list[npt.NDArray[np.int32]]


def _to_camera(dx: float, dy: float, c: float, s: float) -> tuple[float, float]:
    """World offset -> (depth, lateral left), as simworld/render.py projects."""
    return dx * c + dy * s, -dx * s + dy * c


def truth_boxes(world: Any, spec: Any) -> tuple[list[str], npt.NDArray[np.float64]]:
    """The targets the camera shows, and their boxes, projected exactly as the renderer draws
    them (a billboard of the sprite's aspect standing on the floor), clipped to the image.

    A target counts as visible when its clipped box is at least 30 % of its whole box and at
    least half of that clipped box is not covered by a nearer target's or obstacle's billboard
    (the renderer pastes whole rectangles, so this is exact).
    """
    from simworld.render import OBSTACLE_HEIGHT_M, sprite

    r = world.robot
    c, s = math.cos(r.theta), math.sin(r.theta)
    f, cx, cy = spec.focal_px, spec.width / 2, spec.height / 2
    items: list[tuple[float, str | None, tuple[float, float, float, float]]] = []
    for tg, (tx, ty) in zip(world.targets, world.target_positions(), strict=True):
        cut = sprite(tg.sprite, tg.mirror)
        z, lateral = _to_camera(tx - r.x, ty - r.y, c, s)
        if z < 0.3:
            continue
        h, w = f * tg.height_m / z, f * tg.height_m * cut.shape[1] / cut.shape[0] / z
        u, bottom = cx - f * lateral / z, cy + f * spec.height_m / z
        items.append((z, tg.id, (u - w / 2, bottom - h, u + w / 2, bottom)))
    for ob in world.obstacles:
        z, lateral = _to_camera(ob.x - r.x, ob.y - r.y, c, s)
        if z < 0.3:
            continue
        u, bottom = cx - f * lateral / z, cy + f * spec.height_m / z
        w, h = f * 2 * ob.radius / z, f * OBSTACLE_HEIGHT_M / z
        items.append((z, None, (u - w / 2, bottom - h, u + w / 2, bottom)))
    label = np.full((spec.height, spec.width), -1, np.int32)
    clipped: list[tuple[int, int, int, int]] = []
    items.sort(key=lambda it: -it[0])  # far to near, as the renderer paints
    for k, (_, _, (x0, y0, x1, y1)) in enumerate(items):
        a, b = max(round(x0), 0), max(round(y0), 0)
        e, d = min(round(x1), spec.width), min(round(y1), spec.height)
        clipped.append((a, b, e, d))
        if e > a and d > b:
            label[b:d, a:e] = k
    ids, boxes = [], []
    for k, (_, tid, (x0, y0, x1, y1)) in enumerate(items):
        a, b, e, d = clipped[k]
        area_in = max(e - a, 0) * max(d - b, 0)
        if tid is None or area_in == 0 or area_in < 0.3 * (x1 - x0) * (y1 - y0):
            continue
        if np.count_nonzero(label[b:d, a:e] == k) >= 0.5 * area_in:
            ids.append(tid)
            boxes.append((a, b, e, d))
    return ids, np.array(boxes, np.float64).reshape(-1, 4)


def _steer(world: Any, target_id: str | None, follow_m: float) -> None:
    """Stand-in for the controller (not imported here): turn towards the followed target and
    drive to ``follow_m`` from its surface, from the simulator's truth. It only gives the
    camera the motion a following robot has; the trackers never see the truth."""
    if target_id is None:
        return
    r = world.robot
    i = [t.id for t in world.targets].index(target_id)
    tx, ty = world.target_positions()[i]
    z, lateral = _to_camera(tx - r.x, ty - r.y, math.cos(r.theta), math.sin(r.theta))
    bearing = math.atan2(lateral, z)
    dist = math.hypot(tx - r.x, ty - r.y) - world.targets[i].radius
    v = min(max(0.5 * (dist - follow_m), 0.0), 0.5) if abs(bearing) < 0.5 else 0.0
    world.command(v, min(max(1.5 * bearing, -1.0), 1.0))


def run_scenario(
    name: str, robot: str, rate_hz: float, max_frames: int, detector: Any, cache: Path | None
) -> ScenarioFrames:
    """Step the scenario's world, render each camera frame, detect on it (or read the cache)."""
    from simworld.render import CameraSpec, render
    from simworld.scenarios import SCENARIOS

    if name in STRESS_WORLDS:
        from simworld.scenarios import Scenario, person
        from simworld.world import Robot, World

        alice, bob, duration = STRESS_WORLDS[name]
        scenario = Scenario(
            name,
            "stress",
            lambda: World(
                Robot(), targets=[person("alice", *alice), person("bob", *bob, mirror=True)]
            ),
            duration,
        )
    else:
        scenario = SCENARIOS[name]
    sim = SimSettings()
    world = scenario.build()
    spec = CameraSpec(sim.width, sim.height, 60.0, sim.camera_height_m)
    follow_m = ControllerSettings().follow_distance_m
    n = min(max_frames, int(scenario.duration_s * rate_hz))
    cached: dict[str, Any] | None = None
    if cache is not None and cache.exists():
        with np.load(cache) as z:
            cached = {k: z[k] for k in z.files}
        if len(cached["offsets"]) != n + 1:
            cached = None
    out = ScenarioFrames(name, robot, [], [], [], [], [], [])
    dt = 1.0 / sim.physics_hz
    for k in range(n):
        while world.t < k / rate_hz - 1e-9:
            if robot == "follow":
                _steer(world, scenario.followed, follow_m)
            world.advance(dt)
        ids, boxes = truth_boxes(world, spec)
        out.times.append(world.t)
        out.truth_ids.append(ids)
        out.truth_boxes.append(boxes)
        if cached is None:
            boxes_k = detector.detect(render(world, spec)).boxes
            out.det_xyxy.append(boxes_k.xyxy)
            out.det_scores.append(boxes_k.scores)
            out.det_classes.append(boxes_k.class_ids)
            if k % 25 == 0:
                log(f"    {name}/{robot}: frame {k + 1}/{n}")
        else:
            a, b = cached["offsets"][k], cached["offsets"][k + 1]
            out.det_xyxy.append(cached["xyxy"][a:b])
            out.det_scores.append(cached["scores"][a:b])
            out.det_classes.append(cached["classes"][a:b])
    if cached is None and cache is not None:
        offsets = np.cumsum([0] + [len(x) for x in out.det_xyxy])
        tmp = cache.with_suffix(".tmp.npz")
        np.savez(
            tmp,
            offsets=offsets,
            xyxy=np.concatenate(out.det_xyxy).reshape(-1, 4),
            scores=np.concatenate(out.det_scores),
            classes=np.concatenate(out.det_classes),
        )
        tmp.replace(cache)
    return out
