"""Where things are around the robot: boxes in a camera's image and rays of the laser. Pure.

Conventions (REP 103): +x forward, angles counter-clockwise positive, in radians. Image x grows
to the right, so a box right of the image centre has a negative bearing. A camera looks along
its mounting yaw (``mount_yaw_deg`` of its announcement: front 0, left 90, rear 180); its horizontal
field of view turns a pixel column into a bearing with the pinhole model, and the yaw turns
that bearing into the robot's frame. The laser's angles are in the robot's frame already.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
import numpy.typing as npt

from common.messages import Detections, LaserScan
from perception import DEPTH_CENTRE, DEPTH_DISTANCE, Mounted, Mounting, to_robot


class Mount(Mounted, Protocol):
    """Where a camera stands and looks on the robot and how wide: a camera's announcement
    (common/messages.py ``CameraAnnouncement``) or its settings."""

    @property
    def hfov_deg(self) -> float: ...


def wrap(angle: float) -> float:
    """``angle`` (radians) wrapped to (-pi, pi]; an angle already in it is returned as is."""
    if -math.pi < angle <= math.pi:
        return angle
    wrapped = math.remainder(angle, math.tau)  # in [-pi, pi]
    return math.pi if wrapped == -math.pi else wrapped


def focal_px(image_width: int, hfov_deg: float) -> float:
    """The pinhole focal length in pixels for this width and horizontal field of view."""
    return (image_width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)


def bearing(dets: Detections, i: int, hfov_deg: float) -> float:
    """Bearing of box ``i``'s centre in radians, in the camera's frame, counter-clockwise
    positive (left of the image centre)."""
    dx = float(dets.centers[i, 0]) - dets.image_width / 2.0
    return -math.atan2(dx, focal_px(dets.image_width, hfov_deg))


def robot_bearing(dets: Detections, i: int, camera: Mount) -> float:
    """Bearing of box ``i``'s centre in the robot's frame: the camera's mounting yaw plus the
    bearing in its image, wrapped to (-pi, pi]. A front camera's (yaw 0) is its image bearing."""
    return wrap(math.radians(camera.mount_yaw_deg) + bearing(dets, i, camera.hfov_deg))


def in_view(robot_bearing_rad: float, camera: Mount) -> bool:
    """Whether a bearing in the robot's frame lies within ``camera``'s horizontal field."""
    off = wrap(robot_bearing_rad - math.radians(camera.mount_yaw_deg))
    return abs(off) <= math.radians(camera.hfov_deg) / 2.0


def box_distance(dets: Detections, i: int, hfov_deg: float, target_height_m: float) -> float:
    """Distance to a target of known height from its box height (pinhole, square pixels)."""
    height_px = max(float(dets.sizes[i, 1]), 1.0)
    return target_height_m * focal_px(dets.image_width, hfov_deg) / height_px


#: The detections' column with each box's distance from its camera, in metres (NaN: unknown),
#: as the detector's depth stage writes it.
DISTANCE_COLUMN = DEPTH_DISTANCE


def depth_distance(dets: Detections, i: int, camera: Mount | None = None) -> float:
    """The horizontal distance from the robot base's centre to box ``i``'s 3D centre (its
    ``x_m`` and ``z_m`` columns, placed by ``camera``'s announced mounting: ``mount_x_m``,
    ``mount_y_m``, ``mount_yaw_deg``; none announced: at the base's centre), or NaN when it is
    unknown: no column (a frame with no depth paired), NaN, or not in front of the camera.

    Horizontal, not the 3D distance from the camera (``distance_m``): a target whose centre
    is higher or lower than the camera is farther along that line than across the floor, and
    the robot would stop nearer than ``follow_distance_m``.
    """
    columns = dets.boxes.columns
    if any(c not in columns for c in DEPTH_CENTRE):
        return math.nan
    x, _, z = (columns[c][i : i + 1] for c in DEPTH_CENTRE)
    if not (math.isfinite(x[0]) and math.isfinite(z[0])) or z[0] <= 0:
        return math.nan
    mount = Mounting() if camera is None else Mounting.of(camera)
    forward, left, _ = to_robot(x, np.zeros_like(x), z, mount)  # the height plays no part
    return float(np.hypot(forward[0], left[0]))


def box_clipped(dets: Detections, i: int, margin_px: float = 2.0) -> bool:
    """Whether box ``i`` touches the top or bottom image edge (its height is then cut)."""
    y1, y2 = float(dets.boxes.xyxy[i, 1]), float(dets.boxes.xyxy[i, 3])
    return y1 <= margin_px or y2 >= dets.image_height - margin_px


def _offsets(scan: LaserScan, center_rad: float) -> npt.NDArray[np.float64]:
    """Each ray's angle from ``center_rad``, wrapped to -pi..pi."""
    out: npt.NDArray[np.float64] = np.angle(np.exp(1j * (scan.angles - center_rad)))
    return out


def laser_covers(scan: LaserScan, bearing_rad: float) -> bool:
    """Whether a ray of ``scan`` points within one ray spacing of ``bearing_rad`` (a 270 deg
    laser has no ray behind the robot)."""
    return bool(np.min(np.abs(_offsets(scan, bearing_rad))) <= abs(scan.angle_increment))


def sector_range(
    scan: LaserScan, center_rad: float, width_deg: float, unseen: float = 0.0
) -> float:
    """The nearest valid range within +-width/2 of ``center_rad``, in metres.

    NaN rays and rays below ``range_min`` are invalid and ignored; +inf (nothing within range)
    counts as clear. A sector with no valid ray returns ``unseen``, 0.0 by default: what cannot
    be seen is treated as blocked.
    """
    half = math.radians(width_deg) / 2.0
    ranges = scan.ranges[np.abs(_offsets(scan, center_rad)) <= half].astype(np.float64)
    valid = ranges[~np.isnan(ranges) & (ranges >= scan.range_min)]
    return float(valid.min()) if valid.size else unseen


def corridor_clearance(scan: LaserScan, half_width_m: float) -> float:
    """How far the robot can drive straight on: the nearest valid hit in the corridor its body
    sweeps (``|y| <= half_width_m`` ahead of the laser), in metres along x.

    An angular sector alone misses things beside the nose that the body would still hit.
    """
    r = scan.ranges.astype(np.float64)
    valid = np.isfinite(r) & (r >= scan.range_min)
    r = np.where(valid, r, 0.0)  # inf * cos(90 deg) would be NaN (and a numpy warning)
    x = r * np.cos(scan.angles)
    y = r * np.sin(scan.angles)
    # A valid zero range (a virtual scan's "blocked here") is a hit at the base, whatever its
    # angle: skipping it as "not ahead" would drive into what the scan could not see.
    hit = valid & ((x > 0) | (r == 0)) & (np.abs(y) <= half_width_m)
    return float(x[hit].min()) if hit.any() else math.inf


def sector_clearance(scan: LaserScan, width_deg: float, half_width_m: float = 0.0) -> float:
    """The room straight ahead: the nearest valid range within the sector (see
    :func:`sector_range`) or, with ``half_width_m``, in the robot's corridor if that is nearer."""
    sector = sector_range(scan, 0.0, width_deg)
    return min(sector, corridor_clearance(scan, half_width_m)) if half_width_m > 0 else sector
