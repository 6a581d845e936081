"""How far the detections' depth is from the truth, live: each person detection's horizontal
range (from its ``x_m``, ``z_m`` columns, perception/depth.py) against the point a depth camera
can observe of the person it looks at, as the simulator drew it. Pure: recorded messages in,
figures out.

The truth is drawn again from the scenario's world at each detection's moment: the world (as
the simulator ran it, services/sim/worlds.py ``world_for``: bodies in the hard world, flat cards
in the simple one) set to the nearest recorded GroundTruth's scenario time and robot pose, and
simworld/depth.py ``targets_in_camera`` for the camera (services/sim/cameras.py): the surface
on the person's axis at half their height. A detection is matched to the visible target whose
truth point is nearest it in bearing, within :data:`BEARING_GATE_DEG`; a detection with no
such target (a false one, or a person hidden behind another) is left out. A matched detection
with no depth (NaN columns) counts as unknown.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field, replace

import numpy as np

from common.contracts import DepthError
from common.messages import Detections, GroundTruth
from perception import DEPTH_CENTRE
from services.sim.cameras import sim_cameras
from services.sim.worlds import world_for
from simworld.depth import targets_in_camera
from simworld.render import CameraSpec
from simworld.world import Robot, World
from stack.config import Config

#: A detection and a target's truth point further apart in bearing than this are not matched.
BEARING_GATE_DEG = 3.0
#: A target less visible than this share of it is no truth to measure against.
MIN_VISIBLE = 0.3
#: The class whose detections are measured.
PERSON = "person"
#: The depth stage's columns of a box's centre, in the camera's optical frame (x right, z ahead).
X, Z = DEPTH_CENTRE[0], DEPTH_CENTRE[2]


@dataclass(slots=True)
class _Rows:
    err: list[float] = field(default_factory=list)
    truth: list[float] = field(default_factory=list)
    unknown: int = 0


def depth_error(
    build: World, config: Config, truths: list[GroundTruth], detections: dict[str, list[Detections]]
) -> DepthError | None:
    """The figures of every camera's person detections against the truth (None: no detection
    carried depth columns, or no truth was heard)."""
    if not truths:
        return None
    world = world_for(config.sim, build)
    specs = {c.name: c.spec for c in sim_cameras(config)}
    by_stamp = sorted(truths, key=lambda t: t.header.stamp_ns)
    stamps = [t.header.stamp_ns for t in by_stamp]
    rows = _Rows()
    for camera, dets in detections.items():
        spec = specs.get(camera)
        if spec is None:
            continue
        for d in dets:
            if not all(c in d.boxes.columns for c in (X, Z)):
                continue
            truth = _nearest(by_stamp, stamps, d.header.stamp_ns)
            _measure(_at(world, truth), spec, d, rows)
    if not rows.err and not rows.unknown:
        return None
    err = np.abs(np.asarray(rows.err))
    truth_m = np.asarray(rows.truth)
    pct = 100 * err / truth_m if err.size else np.zeros(0)
    return DepthError(
        rows=len(rows.err),
        unknown=rows.unknown,
        median_pct=float(np.median(pct)) if pct.size else math.nan,
        p95_pct=float(np.percentile(pct, 95)) if pct.size else math.nan,
        median_signed_m=float(np.median(rows.err)) if rows.err else math.nan,
        range_m=(float(truth_m.min()), float(truth_m.max())) if truth_m.size else (0.0, 0.0),
    )


def _nearest(truths: list[GroundTruth], stamps: list[int], stamp_ns: int) -> GroundTruth:
    i = bisect.bisect_left(stamps, stamp_ns)
    near = [j for j in (i - 1, i) if 0 <= j < len(truths)]
    return truths[min(near, key=lambda j: abs(stamps[j] - stamp_ns))]


def _at(world: World, truth: GroundTruth) -> World:
    """``world`` at the truth's scenario time, the robot where the truth puts it."""
    x, y, theta = truth.robot
    return replace(world, robot=Robot(x=x, y=y, theta=theta), t=truth.sim_time_s)


def _measure(world: World, spec: CameraSpec, d: Detections, rows: _Rows) -> None:
    seen = [t for t in targets_in_camera(world, spec, MIN_VISIBLE) if t[1] == PERSON]
    if not seen:
        return
    names = np.asarray(d.class_names, dtype=object)  # one per box
    xs, zs = d.boxes.columns[X], d.boxes.columns[Z]
    x1, x2 = d.boxes.xyxy[:, 0], d.boxes.xyxy[:, 2]
    f, cx = spec.focal_px, spec.width / 2
    truth_bearings = np.array([math.atan2(t[2], t[4]) for t in seen])
    for i in np.flatnonzero(names == PERSON):
        bearing = math.atan2((x1[i] + x2[i]) / 2 - cx, f)  # the box's, right of the axis
        k = int(np.argmin(np.abs(truth_bearings - bearing)))
        if abs(truth_bearings[k] - bearing) > math.radians(BEARING_GATE_DEG):
            continue
        true_range = math.hypot(seen[k][2], seen[k][4])
        if not (math.isfinite(xs[i]) and math.isfinite(zs[i])):
            rows.unknown += 1
            continue
        rows.err.append(math.hypot(float(xs[i]), float(zs[i])) - true_range)
        rows.truth.append(true_range)
