"""What the cameras see, placed around the robot: the candidate targets of one control tick. Pure.

Each camera's detections are judged on their own (a stale camera's are never used, see
:class:`View`); every confident box of a target class in the fresh ones becomes a
:class:`Sighting`, with its bearing in the robot's frame (services/controller/geometry.py), so
that boxes from a front and a rear camera can be compared, chosen between and handed over.
Track ids are a camera's own (the detector tracks each camera apart): a sighting is named by
its camera and its track id together.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.messages import Detections
from services.controller.geometry import Mount, focal_px, robot_bearing


@dataclass(frozen=True, slots=True)
class View:
    """One camera's newest detections at the control instant, and their ages in seconds.

    ``age_s`` is the dead-man's age (the later of capture and arrival; inf when none has
    arrived); ``capture_age_s`` how long ago their frame was captured (the latency to
    compensate).
    """

    dets: Detections | None
    age_s: float = math.inf
    capture_age_s: float = 0.0

    def fresh(self, timeout_s: float) -> bool:
        return self.dets is not None and self.age_s <= timeout_s


@dataclass(frozen=True, slots=True)
class Sighting:
    """Box ``i`` of one camera's detections, placed in the robot's frame.

    ``bearing`` is in radians in the robot's frame when the frame was ``captured`` (a time on
    the controller's monotonic clock, in seconds).
    """

    camera: str
    dets: Detections
    i: int
    bearing: float
    captured: float
    hfov_deg: float

    @property
    def track_id(self) -> int:
        ids = self.dets.boxes.track_ids
        return -1 if ids is None else int(ids[self.i])

    @property
    def name(self) -> str:
        return self.dets.class_names[self.i]

    @property
    def focal_px(self) -> float:
        return focal_px(self.dets.image_width, self.hfov_deg)

    @property
    def angular_area(self) -> float:
        """The box's size as seen from the robot (width x height over the focal length
        squared), comparable between cameras of different resolutions and fields of view."""
        return float(np.prod(self.dets.sizes[self.i])) / self.focal_px**2


def candidates(
    dets: Detections, classes: tuple[str, ...], min_score: float
) -> npt.NDArray[np.intp]:
    """Indices of detections of one of ``classes`` with at least ``min_score``."""
    if len(dets) == 0:
        return np.empty(0, dtype=np.intp)
    mask = np.isin(np.asarray(dets.class_names, dtype=object), classes)
    return np.flatnonzero(mask & (dets.boxes.scores >= min_score))


def unknown_targets(targets: tuple[str, ...], model_classes: list[str]) -> list[str]:
    """The target classes the detector's model cannot report: the robot would search forever."""
    return [t for t in targets if t not in model_classes]


def sightings(
    fresh: Mapping[str, Detections],
    captured: Mapping[str, float],
    cameras: Mapping[str, Mount],
    classes: tuple[str, ...],
    min_score: float,
) -> list[Sighting]:
    """Every candidate in the fresh cameras' detections, camera by camera in the order of
    ``fresh``, box by box in each."""
    found = []
    for cam, dets in fresh.items():
        camera = cameras[cam]
        for i in candidates(dets, classes, min_score):
            found.append(
                Sighting(
                    cam, dets, int(i), robot_bearing(dets, int(i), camera), captured[cam],
                    camera.hfov_deg,
                )
            )  # fmt: skip
    return found


def stale_reason(views: Mapping[str, View]) -> str:
    """Why no camera's detections are fresh: none announced, none received yet, or each
    camera's age."""

    def age(v: View) -> str:
        return "none received yet" if v.dets is None else f"{v.age_s:.2f} s old"

    if not views:
        return "no camera announced"
    if len(views) == 1:
        [v] = views.values()
        return "no detections received yet" if v.dets is None else f"detections are {age(v)}"
    ages = ", ".join(f"{c} {age(v)}" for c, v in views.items())
    return f"no camera's detections are fresh ({ages})"
