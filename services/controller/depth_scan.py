"""A virtual laser scan from a depth image, for a robot whose obstacles are seen by a depth
camera rather than a laser. Pure numpy: no bus, no clock.

Each depth pixel (every ``stride_px``-th row and column) is back-projected with the image's
intrinsics and placed in the robot's base frame by the camera's mounting
(perception/depth.py ``to_robot``: forward, left, up from the floor under the base's centre).
A point lower than ``floor_margin_m`` above the floor is the floor, and one higher than
``max_height_m`` passes over the robot: both are taken out. Every other point is an obstacle,
and each angular bin of the scan keeps the nearest one's horizontal range from the base's
centre. The scan is in the ROBOT frame (REP 103: angle 0 forward, counter-clockwise positive),
360 deg round, so that the controller's obstacle rules (services/controller/geometry.py) read it
as they read a laser's.

A bin's value:
    a range   the nearest obstacle point in that direction
    inf       the camera saw that direction (some pixel had a reading there) and nothing in it
              stands between the floor and ``max_height_m``: clear within the camera's range
    NaN       unknown: outside the camera's field of view, or no pixel had a reading there
              (holes, or everything nearer than the camera's minimum range)

As with a laser's minimum range, what is nearer than the depth camera's minimum range gives no
reading at all, and a dark obstacle with no readings over the floor it stands on reads as clear:
a depth camera sees what it can measure.

A camera whose height above the floor is not known (``mount_height_m`` 0) cannot tell the
floor from an obstacle: it gives no virtual scan (the controller counts its depth frames as
``depth_no_mount`` and says so).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.messages import Header, LaserScan
from perception import Intrinsics, Mounting, to_robot
from services.controller.geometry import wrap

#: The range a scan states when its depth image states none (DepthFrame.range_max_m 0).
UNSTATED_RANGE_MAX_M = 100.0


@dataclass(frozen=True, slots=True)
class ScanParams:
    """How a virtual scan is made (the controller's ``depth_*`` settings)."""

    floor_margin_m: float = 0.05
    max_height_m: float = 1.5
    stride_px: int = 4
    resolution_deg: float = 1.0


def usable(mount: Mounting) -> bool:
    """Whether a camera mounted so can give a virtual scan: its height must be known."""
    return mount.height_m > 0


def virtual_scan(
    depth: npt.NDArray[np.float32],
    intr: Intrinsics,
    mount: Mounting,
    params: ScanParams,
    header: Header,
    range_max_m: float = 0.0,
) -> LaserScan:
    """The virtual scan of ``depth`` ((h, w) metres, NaN = no reading; perception/depth.py
    ``depth_metres``) seen through ``intr`` by a camera mounted at ``mount``, stamped with
    ``header`` (the depth frame's: its capture time). ``range_max_m``: the camera's stated
    maximum (0: not stated).

    ValueError when the mounting's height is unknown (see :func:`usable`) or the image and the
    intrinsics disagree in size.
    """
    if not usable(mount):
        raise ValueError("the camera's height above the floor is unknown (mount_height_m 0)")
    h, w = depth.shape
    if (w, h) != (intr.width, intr.height):
        raise ValueError(f"a {w}x{h} depth image with intrinsics for {intr.width}x{intr.height}")
    step = params.stride_px
    # Pixel centres of the rows and columns taken, the middle of each stride.
    v = np.arange(step // 2, h, step)
    u = np.arange(step // 2, w, step)
    z = depth[np.ix_(v, u)].astype(np.float64)
    x = (u[None, :] + 0.5 - intr.cx) / intr.fx * z
    y = (v[:, None] + 0.5 - intr.cy) / intr.fy * z
    seen = np.isfinite(z)
    fwd, left, up = to_robot(x[seen], y[seen], z[seen], mount)  # type: ignore[arg-type]
    n = max(1, round(360.0 / params.resolution_deg))
    increment = math.tau / n
    angles = np.arctan2(left, fwd)  # in [-pi, pi]
    bins = np.floor((angles + math.pi) / increment).astype(np.intp) % n
    ranges = np.full(n, np.nan, np.float64)
    ranges[np.unique(bins)] = np.inf  # seen: clear unless an obstacle point says otherwise
    solid = (up >= params.floor_margin_m) & (up <= params.max_height_m)
    np.minimum.at(ranges, bins[solid], np.hypot(fwd[solid], left[solid]))
    return LaserScan(
        header=header,
        angle_min=-math.pi + increment / 2,  # each ray at its bin's centre
        angle_increment=increment,
        range_min=0.0,
        range_max=range_max_m if range_max_m > 0 else UNSTATED_RANGE_MAX_M,
        ranges=ranges.astype(np.float32),
    )


def merge(scans: Sequence[LaserScan]) -> LaserScan:
    """Several cameras' virtual scans (made with one resolution) as one: each ray the nearest
    range any of them reads, inf where one sees clear and none sees an obstacle, NaN where none
    sees. The header is the oldest scan's (its age is the merged scan's)."""
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


def depth_obstacles(
    cameras: Mapping[str, DepthCamera], timeout_s: float, sector_width_deg: float
) -> DepthObstacles:
    """The depth cameras' obstacles, or why there are none to drive forward on.

    Every camera that can give a virtual scan and looks into the sector ahead must have one
    no older than ``timeout_s``: one of them gone stale leaves part of the way ahead unseen,
    and forward motion stops as it does on a stale laser scan. Fresh scans of the other
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
    fresh = [
        cam
        for cam in cameras.values()
        if usable(cam.mount) and cam.scan is not None and cam.age_s <= timeout_s
    ]
    scans = [cam.scan for cam in fresh if cam.scan is not None]
    return DepthObstacles(merge(scans), max(cam.age_s for cam in fresh))
