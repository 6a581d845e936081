"""A recorded scenario run as a tracker is scored on it: each camera's detections, frame by
frame, beside the truth of that frame (which person shows where, simworld/truth.py). Pure:
recorded messages and the scenario in, labelled frames out.

A frame's truth is the world at the moment the frame was captured: the simulator's truth
message nearest to the frame's stamp (it publishes one per physics step, 50 Hz: within
10 ms) gives the robot's pose and the scenario time; the scenario's world at that time, seen
by the camera as the simulator placed it (services/sim/cameras.py), gives each person's
visible box.
"""

from __future__ import annotations

import bisect
import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from common.messages import Detections, GroundTruth
from simworld.render import CameraSpec
from simworld.truth import TruthBox, visible_boxes
from simworld.world import World

#: A person is in a frame's truth when at least this share of them shows: less is a sliver
#: at the image's edge or round an occluder, which no detector is asked to find.
MIN_VISIBLE = 0.2


@dataclass(frozen=True, slots=True)
class Labelled:
    """One frame of one camera: its detections as recorded, the truth at its capture, and
    the scenario time (s)."""

    detections: Detections
    truth: tuple[TruthBox, ...]
    sim_time_s: float


def nearest_truth(stamps: Sequence[int], stamp_ns: int) -> int:
    """The index of the stamp of ``stamps`` (ascending, not empty) nearest ``stamp_ns``."""
    k = bisect.bisect_left(stamps, stamp_ns)
    if k == 0:
        return 0
    if k == len(stamps):
        return len(stamps) - 1
    return k if stamps[k] - stamp_ns < stamp_ns - stamps[k - 1] else k - 1


def world_at(world: World, truth: GroundTruth) -> World:
    """``world`` (the scenario as the simulator ran it) at ``truth``'s time and robot pose."""
    x, y, theta = truth.robot
    robot = dataclasses.replace(world.robot, x=x, y=y, theta=theta)
    return dataclasses.replace(world, robot=robot, t=truth.sim_time_s)


def label(
    world: World,
    specs: Mapping[str, CameraSpec],
    truths: Sequence[GroundTruth],
    detections: Mapping[str, Sequence[Detections]],
    min_visible: float = MIN_VISIBLE,
) -> dict[str, list[Labelled]]:
    """Each camera's frames (``detections``, by camera, each camera's in capture order)
    labelled with the truth at their capture; ``specs``: each camera as the simulator draws
    it. A camera with no spec, or a run with no truth, gives nothing."""
    ordered = sorted(truths, key=lambda t: t.header.stamp_ns)
    stamps = [t.header.stamp_ns for t in ordered]
    out: dict[str, list[Labelled]] = {}
    if not ordered:
        return out
    for camera, dets in detections.items():
        spec = specs.get(camera)
        if spec is None:
            continue
        frames = []
        for d in sorted(dets, key=lambda m: m.header.stamp_ns):
            truth = ordered[nearest_truth(stamps, d.header.stamp_ns)]
            boxes = visible_boxes(world_at(world, truth), spec, min_visible)
            frames.append(Labelled(d, tuple(boxes), truth.sim_time_s))
        out[camera] = frames
    return out
