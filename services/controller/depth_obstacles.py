"""The controller's obstacles seen by depth: every depth camera's newest virtual scan
(made by the depth scan stage, services/depthscan, from its images) judged together at the
control instant. Pure: no bus, no clock.

The scans are in the ROBOT frame (REP 103: angle 0 forward, counter-clockwise positive), 360
deg round, NaN outside a camera's field of view, so that the controller's obstacle rules
(services/controller/geometry.py) read them as they read a laser's. The fresh depth cameras
together must see the whole sector ahead (:func:`depth_obstacles`): what no camera sees is not
known clear.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.messages import LaserScan
from depthscan.frame import usable
from perception import Mounting
from services.controller.geometry import wrap


def merge(scans: Sequence[LaserScan]) -> LaserScan:
    """Several cameras' virtual scans (made with one resolution) as one: each ray the nearest
    range any of them reads (0, unknown, where one knows nothing there), NaN where none
    looks. The header is the oldest scan's (its age is the merged scan's)."""
    if not scans:
        raise ValueError("nothing to merge")
    first = scans[0]
    for scan in scans[1:]:
        if len(scan.ranges) != len(first.ranges) or scan.angle_min != first.angle_min:
            raise ValueError("virtual scans of different resolutions")
    ranges: npt.NDArray[np.float32] = np.fmin.reduce([s.ranges for s in scans]).astype(np.float32)
    oldest = min(scans, key=lambda s: s.header.stamp_ns)
    return LaserScan(
        header=oldest.header,
        angle_min=first.angle_min,
        angle_increment=first.angle_increment,
        range_min=0.0,
        range_max=max(s.range_max for s in scans),
        ranges=ranges,
    )


def looks_ahead(mount: Mounting, hfov_deg: float, sector_width_deg: float) -> bool:
    """Whether a camera's horizontal field of view overlaps the sector straight ahead."""
    off = abs(math.degrees(wrap(math.radians(mount.yaw_deg))))
    return off - hfov_deg / 2 < sector_width_deg / 2


def cover_sector(views: Sequence[tuple[float, float]], sector_width_deg: float) -> bool:
    """Whether the horizontal fields of view ``views`` ((yaw_deg, hfov_deg) each) together
    cover the whole sector of ``sector_width_deg`` straight ahead."""
    half = sector_width_deg / 2
    spans = []
    for yaw, hfov in views:
        if hfov >= 360:
            return True
        centre = math.degrees(wrap(math.radians(yaw)))
        for turn in (-360.0, 0.0, 360.0):  # a view across the rear reaches both ends
            spans.append((centre + turn - hfov / 2, centre + turn + hfov / 2))
    reached = -half
    for lo, hi in sorted(spans):
        if lo > reached:
            break
        reached = max(reached, hi)
    return reached >= half


@dataclass(frozen=True, slots=True)
class DepthCamera:
    """One announced depth camera at the control instant: where it stands, its field of view,
    its newest virtual scan (None: none yet) and that scan's age in seconds."""

    mount: Mounting
    hfov_deg: float
    scan: LaserScan | None = None
    age_s: float = math.inf


@dataclass(frozen=True, slots=True)
class DepthObstacles:
    """What the depth cameras show of the obstacles now: ``scan`` merged from every fresh
    camera's, its age (the oldest merged), or ``None`` with the reason in ``missing``."""

    scan: LaserScan | None
    age_s: float = math.inf
    missing: str = ""
    #: What the map remembers round the robot (depthscan/local_map.py, the depth scan
    #: stage's): its hazard and unknown cells as a scan (None: no map), and how far ahead the
    #: corridor's floor is known.
    remembered: LaserScan | None = None
    known_m: float = math.inf
    #: Why the robot must hold still, turning included ("" when it need not): no fresh memory
    #: from the depth scan stage (services/controller/depth_input.py).
    halt: str = ""


def depth_obstacles(
    cameras: Mapping[str, DepthCamera], timeout_s: float, sector_width_deg: float
) -> DepthObstacles:
    """The depth cameras' obstacles, or why there are none to drive forward on.

    Every camera that can give a virtual scan and looks into the sector ahead must have one
    no older than ``timeout_s``: one of them gone stale leaves part of the way ahead unseen,
    and forward motion stops as it does on a stale laser scan. Together their fields of view
    must cover the whole sector: what no camera sees is not known clear. Fresh scans of the other
    cameras (beside, behind) are merged too: the corridor the body sweeps reaches beyond the
    sector.
    """
    ahead = {
        c: cam
        for c, cam in cameras.items()
        if usable(cam.mount) and looks_ahead(cam.mount, cam.hfov_deg, sector_width_deg)
    }
    if not ahead:
        unknown = sorted(c for c, cam in cameras.items() if not usable(cam.mount))
        why = "no depth camera looks ahead"
        if unknown:
            why += f" ({', '.join(unknown)}: height above the floor unknown)"
        return DepthObstacles(None, missing=why)
    for c, cam in ahead.items():
        if cam.scan is None:
            return DepthObstacles(None, missing=f"no depth from {c} yet")
        if cam.age_s > timeout_s:
            return DepthObstacles(None, missing=f"no recent depth from {c} ({cam.age_s:.2f} s)")
    if not cover_sector([(c.mount.yaw_deg, c.hfov_deg) for c in ahead.values()], sector_width_deg):
        return DepthObstacles(
            None,
            missing=f"depth does not see the whole way ahead ({sector_width_deg:g} deg): "
            + ", ".join(sorted(ahead)),
        )
    fresh = [
        cam
        for cam in cameras.values()
        if usable(cam.mount) and cam.scan is not None and cam.age_s <= timeout_s
    ]
    scans = [cam.scan for cam in fresh if cam.scan is not None]
    return DepthObstacles(merge(scans), max(cam.age_s for cam in fresh))
