"""The controller's decisions, as pure functions of the latest inputs. No bus, no clock.

Conventions (REP 103): +x forward, +angular z turns left (counter-clockwise). A target to the
right of the image centre therefore gives a negative angular velocity. Image x grows to the
right; the horizontal offset of a box is normalised to -1 (left edge) .. +1 (right edge).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common.messages import Detections, LaserScan
from common.settings import ControllerSettings


@dataclass(frozen=True, slots=True)
class Command:
    """What to send: velocities plus the state and reason the status message reports."""

    linear_x: float
    angular_z: float
    state: str
    reason: str
    target: str = ""
    track_id: int = -1
    input_stamp_ns: int = 0

    @property
    def is_zero(self) -> bool:
        return self.linear_x == 0.0 and self.angular_z == 0.0


def stop(state: str, reason: str, input_stamp_ns: int = 0) -> Command:
    return Command(0.0, 0.0, state, reason, input_stamp_ns=input_stamp_ns)


def candidates(dets: Detections, classes: tuple[str, ...], min_score: float) -> np.ndarray:
    """Indices of detections of one of ``classes`` with at least ``min_score``."""
    if len(dets) == 0:
        return np.empty(0, dtype=np.intp)
    names = np.asarray(dets.class_names, dtype=object)
    mask = np.isin(names, classes) & (dets.scores >= min_score)
    return np.flatnonzero(mask)


def horizontal_offset(dets: Detections, i: int) -> float:
    """Box centre offset from the image centre, -1 (left edge) .. +1 (right edge)."""
    half = dets.image_width / 2.0
    return float((dets.centers[i, 0] - half) / half)


def steer(offset: float, s: ControllerSettings) -> float:
    """Proportional turn towards the target, limited to ``max_angular``."""
    return float(np.clip(-s.angular_gain * offset, -s.max_angular, s.max_angular))


def sector_clearance(scan: LaserScan, width_deg: float) -> float:
    """The nearest valid range within +-width/2 of straight ahead, in metres.

    Rays that are NaN or below ``range_min`` are invalid and ignored; +inf (nothing within
    range) counts as clear. A sector with no valid ray returns 0.0: what we cannot see is
    treated as blocked.
    """
    half = math.radians(width_deg) / 2.0
    angles = np.arctan2(np.sin(scan.angles), np.cos(scan.angles))  # wrap to -pi..pi
    ranges = scan.ranges[np.abs(angles) <= half].astype(np.float64)
    valid = ranges[~np.isnan(ranges) & (ranges >= scan.range_min)]
    if valid.size == 0:
        return 0.0
    return float(valid.min())


def track(dets: Detections, s: ControllerSettings) -> Command:
    """Turn towards the most central confident target; drive forward only when it is centred."""
    idx = candidates(dets, s.target_classes, s.min_score)
    stamp = dets.header.stamp_ns
    if idx.size == 0:
        return stop("searching", f"no {'/'.join(s.target_classes)} in view", stamp)
    offsets = np.array([horizontal_offset(dets, int(i)) for i in idx])
    best = int(idx[int(np.argmin(np.abs(offsets)))])
    offset = horizontal_offset(dets, best)
    centred = abs(offset) <= 2 * s.center_tolerance  # tolerance is of the full width
    return Command(
        linear_x=s.forward_speed if centred else 0.0,
        angular_z=steer(offset, s),
        state="tracking" if centred else "turning",
        reason=f"offset {offset:+.2f}",
        target=dets.class_names[best],
        track_id=-1 if dets.track_ids is None else int(dets.track_ids[best]),
        input_stamp_ns=stamp,
    )


def follow(dets: Detections, scan: LaserScan | None, s: ControllerSettings) -> Command:
    """Follow the largest detection of the first target class, with the obstacle stop."""
    cls = s.target_classes[0]
    idx = candidates(dets, (cls,), s.min_score)
    stamp = dets.header.stamp_ns
    if idx.size == 0:
        return stop("searching", f"no {cls} in view", stamp)
    areas = np.prod(dets.sizes[idx], axis=1)
    best = int(idx[int(np.argmax(areas))])
    offset = horizontal_offset(dets, best)
    angular = steer(offset, s)
    height = float(dets.sizes[best, 1]) / dets.image_height
    track_id = -1 if dets.track_ids is None else int(dets.track_ids[best])

    def turn_only(state: str, reason: str) -> Command:
        return Command(0.0, angular, state, reason, cls, track_id, stamp)

    if abs(offset) > 2 * s.center_tolerance:
        return turn_only("turning", f"offset {offset:+.2f}")
    if height >= s.stop_box_height:
        return turn_only("arrived", f"box height {height:.2f} of image")
    if scan is None:
        return turn_only("blocked", "no recent laser scan")
    clearance = sector_clearance(scan, s.sector_width_deg)
    if clearance <= s.safety_distance_m:
        return turn_only("blocked", f"obstacle at {clearance:.2f} m")
    return Command(
        s.forward_speed, angular, "following", f"offset {offset:+.2f}", cls, track_id, stamp
    )


def decide(
    dets: Detections | None,
    dets_age_s: float,
    scan: LaserScan | None,
    scan_age_s: float,
    s: ControllerSettings,
) -> Command:
    """The command for this control tick. Zero whenever detections are missing or stale."""
    if dets is None:
        return stop("stale", "no detections received yet")
    if dets_age_s > s.detection_timeout_s:
        return stop("stale", f"detections are {dets_age_s:.2f} s old")
    if s.mode == "track":
        return track(dets, s)
    fresh_scan = scan if scan is not None and scan_age_s <= s.scan_timeout_s else None
    return follow(dets, fresh_scan, s)
