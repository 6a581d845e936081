"""The controller's decisions: pure functions and one stateful Controller. No bus, no clock.

Conventions (REP 103): +x forward, +angular z turns left (counter-clockwise). Image x grows to
the right, so a target right of the image centre has a negative bearing and gives a negative
angular velocity. The camera looks along +x; its horizontal field of view turns a pixel column
into a bearing with the pinhole model.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.contracts import ControllerMode, ControllerState, DistanceSource
from common.messages import Detections, LaserScan
from common.settings import ControllerSettings
from services.controller.limits import Limits, limit
from services.controller.pid import PID, PIDGains


@dataclass(frozen=True, slots=True)
class VelocityCommand:
    """What to send: velocities plus the state and reason the status message reports."""

    linear_x: float
    angular_z: float
    state: ControllerState
    reason: str
    target: str = ""
    track_id: int = -1
    input_stamp_ns: int = 0

    @property
    def is_zero(self) -> bool:
        return self.linear_x == 0.0 and self.angular_z == 0.0


@dataclass(frozen=True, slots=True)
class Inputs:
    """The newest inputs and their ages in seconds (inf when none has arrived).

    ``dets_age_s`` is how long ago the detections arrived (the dead-man timer);
    ``capture_age_s`` how long ago their frame was captured (the latency to compensate).
    """

    dets: Detections | None
    dets_age_s: float
    scan: LaserScan | None = None
    scan_age_s: float = float("inf")
    estop: bool = False
    capture_age_s: float = 0.0


def stop(state: ControllerState, reason: str, input_stamp_ns: int = 0) -> VelocityCommand:
    return VelocityCommand(0.0, 0.0, state, reason, input_stamp_ns=input_stamp_ns)


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


def focal_px(image_width: int, hfov_deg: float) -> float:
    """The pinhole focal length in pixels for this width and horizontal field of view."""
    return (image_width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)


def bearing(dets: Detections, i: int, hfov_deg: float) -> float:
    """Bearing of box ``i``'s centre in radians, counter-clockwise positive (left of centre)."""
    dx = float(dets.centers[i, 0]) - dets.image_width / 2.0
    return -math.atan2(dx, focal_px(dets.image_width, hfov_deg))


def box_distance(dets: Detections, i: int, hfov_deg: float, target_height_m: float) -> float:
    """Distance to a target of known height from its box height (pinhole, square pixels)."""
    height_px = max(float(dets.sizes[i, 1]), 1.0)
    return target_height_m * focal_px(dets.image_width, hfov_deg) / height_px


def box_clipped(dets: Detections, i: int, margin_px: float = 2.0) -> bool:
    """Whether box ``i`` touches the top or bottom image edge (its height is then cut)."""
    y1, y2 = float(dets.boxes.xyxy[i, 1]), float(dets.boxes.xyxy[i, 3])
    return y1 <= margin_px or y2 >= dets.image_height - margin_px


def sector_range(scan: LaserScan, center_rad: float, width_deg: float) -> float:
    """The nearest valid range within +-width/2 of ``center_rad``, in metres.

    NaN rays and rays below ``range_min`` are invalid and ignored; +inf (nothing within range)
    counts as clear. A sector with no valid ray returns 0.0: what cannot be seen is treated as
    blocked.
    """
    half = math.radians(width_deg) / 2.0
    offset = np.angle(np.exp(1j * (scan.angles - center_rad)))  # wrapped to -pi..pi
    ranges = scan.ranges[np.abs(offset) <= half].astype(np.float64)
    valid = ranges[~np.isnan(ranges) & (ranges >= scan.range_min)]
    return float(valid.min()) if valid.size else 0.0


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
    hit = valid & (x > 0) & (np.abs(y) <= half_width_m)
    return float(x[hit].min()) if hit.any() else math.inf


def sector_clearance(scan: LaserScan, width_deg: float, half_width_m: float = 0.0) -> float:
    """The room straight ahead: the nearest valid range within the sector (see
    :func:`sector_range`) or, with ``half_width_m``, in the robot's corridor if that is nearer."""
    sector = sector_range(scan, 0.0, width_deg)
    return min(sector, corridor_clearance(scan, half_width_m)) if half_width_m > 0 else sector


class Controller:
    """Turns the newest inputs into one command per control tick, with memory.

    Memory: the PID's history, the locked target's track id and when it was last seen, the
    previous command (for the acceleration limits), and the recent turn rates it commanded.

    Latency compensation: a detection describes the world when its frame was captured, which
    on a CPU detector is a few hundred milliseconds ago. The robot has turned since, by the
    turn rates this controller itself commanded. Subtracting that rotation from the measured
    bearing keeps the turn from overshooting; without it a slow detector makes the robot
    swing past its target and lose it.
    """

    def __init__(self, s: ControllerSettings, hfov_deg: float) -> None:
        self.s = s
        self.hfov_deg = hfov_deg
        self.pid = PID(
            PIDGains(s.bearing_kp, s.bearing_ki, s.bearing_kd, s.max_angular, s.max_angular)
        )
        self.limits = Limits(s.max_linear, s.max_angular, s.max_linear_accel, s.max_angular_accel)
        self.locked_id = -1
        self.last_seen = -math.inf
        self.last_aim: VelocityCommand | None = None
        self.previous = (0.0, 0.0)
        self.last_step: float | None = None
        self.stopping_m = 0.0
        self.turns: deque[tuple[float, float]] = deque(maxlen=1024)  # (time, w) commanded
        self.last_bearing: tuple[float, float] | None = None  # (bearing, when captured)

    def step(self, inp: Inputs, now: float) -> VelocityCommand:
        """The command for this tick; ``now`` is a monotonic time in seconds."""
        # The first tick may accelerate for one nominal period, like every later one.
        dt = 1.0 / self.s.control_rate_hz if self.last_step is None else now - self.last_step
        self.last_step = now
        if inp.estop:
            return self._halt(stop(ControllerState.ESTOP, "emergency stop latched"))
        if inp.dets is None:
            return self._halt(stop(ControllerState.STALE, "no detections received yet"))
        if inp.dets_age_s > self.s.detection_timeout_s:
            return self._halt(
                stop(ControllerState.STALE, f"detections are {inp.dets_age_s:.2f} s old")
            )
        scan = inp.scan if inp.scan_age_s <= self.s.scan_timeout_s else None
        # Room the robot needs to stop from its current speed: braking at the acceleration
        # limit, plus the distance covered while the scan ages and the next tick comes.
        v = self.previous[0]
        latency = (inp.scan_age_s if scan is not None else 0.0) + 1.0 / self.s.control_rate_hz
        self.stopping_m = v * v / (2 * self.s.max_linear_accel) + v * latency
        # The compensation trusts the capture stamp no further than the dead-man does.
        captured = now - min(inp.capture_age_s, self.s.detection_timeout_s)
        aim = self._aim(inp.dets, scan, now, dt, captured)
        if aim.state == ControllerState.SEARCHING:
            return self._halt(aim)  # the target is gone: stop now, not at the braking rate
        if not (math.isfinite(aim.linear_x) and math.isfinite(aim.angular_z)):
            # Unreachable with validated inputs; if it ever happens, stop and start afresh.
            return self._halt(
                stop(ControllerState.FAULT, "non-finite command computed", aim.input_stamp_ns)
            )
        v, w = limit(self.previous, (aim.linear_x, aim.angular_z), dt, self.limits)
        self.previous = (v, w)
        self.turns.append((now, w))
        return VelocityCommand(
            v, w, aim.state, aim.reason, aim.target, aim.track_id, aim.input_stamp_ns
        )

    def _clearance(self, scan: LaserScan) -> float:
        return sector_clearance(scan, self.s.sector_width_deg, self.s.robot_width_m / 2)

    def _halt(self, cmd: VelocityCommand) -> VelocityCommand:
        """Zero at once (safety stops bypass the acceleration limit) and forget the target."""
        self.previous = (0.0, 0.0)
        self.pid.reset()
        self.locked_id, self.last_aim, self.last_bearing = -1, None, None
        self.turns.clear()
        return cmd

    def rotation_since(self, t0: float, now: float) -> float:
        """How far the robot turned (rad) from ``t0`` to ``now``, by the rates it commanded.

        Each command holds until the next one; the newest holds until ``now``.
        """
        total = 0.0
        entries = list(self.turns)
        ends = [t for t, _ in entries[1:]] + [now]
        for (t, w), end_t in zip(entries, ends[: len(entries)], strict=True):
            start, end = max(t, t0), min(end_t, now)
            if end > start:
                total += w * (end - start)
        return total

    def _pick(self, dets: Detections, idx: npt.NDArray[np.intp]) -> int | None:
        """The target: the most central (track) or the locked / largest (follow) candidate."""
        if idx.size == 0:
            return None
        if self.s.mode is ControllerMode.TRACK:
            offsets = np.abs(dets.centers[idx, 0] - dets.image_width / 2.0)
            return int(idx[int(np.argmin(offsets))])
        if dets.boxes.track_ids is not None and self.locked_id >= 0:
            locked = idx[dets.boxes.track_ids[idx] == self.locked_id]
            if locked.size:
                return int(locked[0])
            return None  # the locked target is out of view: never jump to another one
        return int(idx[int(np.argmax(np.prod(dets.sizes[idx], axis=1)))])

    def _aim(
        self, dets: Detections, scan: LaserScan | None, now: float, dt: float, captured: float
    ) -> VelocityCommand:
        s = self.s
        classes = s.target_classes if s.mode is ControllerMode.TRACK else s.target_classes[:1]
        stamp = dets.header.stamp_ns
        best = self._pick(dets, candidates(dets, classes, s.min_score))
        if best is None:
            if self.last_aim is not None and now - self.last_seen <= s.target_lost_timeout_s:
                # A brief dropout (a missed detection): keep turning towards where the target
                # was, net of our own turning since; drive on only while the way is clear.
                held = self.last_aim
                clear = scan is not None and self._clearance(scan) > (
                    s.safety_distance_m + self.stopping_m
                )
                linear = held.linear_x if clear else 0.0
                angular = 0.0
                if self.last_bearing is not None:
                    seen, when = self.last_bearing
                    angular = self.pid.update(seen - self.rotation_since(when, now), dt)
                return VelocityCommand(
                    linear,
                    angular,
                    ControllerState.HOLDING,
                    f"target unseen for {now - self.last_seen:.1f} s",
                    held.target,
                    held.track_id,
                    stamp,
                )
            self.locked_id, self.last_aim = -1, None
            self.pid.reset()
            return stop(ControllerState.SEARCHING, f"no {'/'.join(classes)} in view", stamp)
        track_id = -1 if dets.boxes.track_ids is None else int(dets.boxes.track_ids[best])
        if s.mode is ControllerMode.FOLLOW and self.locked_id < 0 and track_id >= 0:
            self.locked_id = track_id
        self.last_seen = now
        measured = bearing(dets, best, self.hfov_deg)
        self.last_bearing = (measured, captured)
        err = measured - self.rotation_since(captured, now)
        angular = self.pid.update(err, dt)
        centred = abs(math.tan(err)) * focal_px(dets.image_width, self.hfov_deg) <= (
            s.center_tolerance * dets.image_width
        )
        name = dets.class_names[best]
        if s.mode is ControllerMode.TRACK:
            aim = VelocityCommand(
                s.forward_speed if centred else 0.0,
                angular,
                ControllerState.TRACKING if centred else ControllerState.TURNING,
                f"bearing {math.degrees(err):+.1f} deg",
                name,
                track_id,
                stamp,
            )
        else:
            aim = self._follow(dets, best, scan, err, angular, centred, name, track_id)
        self.last_aim = aim
        return aim

    def _follow(
        self,
        dets: Detections,
        i: int,
        scan: LaserScan | None,
        err: float,
        angular: float,
        centred: bool,
        name: str,
        track_id: int,
    ) -> VelocityCommand:
        s = self.s
        stamp = dets.header.stamp_ns

        def turn_only(state: ControllerState, reason: str) -> VelocityCommand:
            return VelocityCommand(0.0, angular, state, reason, name, track_id, stamp)

        distance = math.inf
        if s.distance_source is DistanceSource.LASER:
            if scan is None:
                return turn_only(ControllerState.BLOCKED, "no recent laser scan for the distance")
            # The laser rays across the middle 60% of the box's width, in the bearing ``err``
            # (already net of our turning since the frame was captured).
            f = focal_px(dets.image_width, self.hfov_deg)
            half_width = math.atan(float(dets.sizes[i, 0]) / 2 / f)
            distance = sector_range(scan, err, math.degrees(1.2 * half_width))
            if distance == 0.0:
                return turn_only(
                    ControllerState.BLOCKED, "the laser sees nothing valid towards the target"
                )
        if not math.isfinite(distance):  # by box height, or the laser saw nothing in range
            if box_clipped(dets, i):
                # A box cut by the image edge is shorter than the target: its distance would
                # be overestimated. Close enough to fill the frame is close enough.
                return turn_only(ControllerState.ARRIVED, "target fills the image height")
            distance = box_distance(dets, i, self.hfov_deg, s.target_height_m)
        if not centred:
            return turn_only(ControllerState.TURNING, f"bearing {math.degrees(err):+.1f} deg")
        if distance <= s.follow_distance_m:
            return turn_only(ControllerState.ARRIVED, f"target at {distance:.2f} m")
        if scan is None:
            return turn_only(ControllerState.BLOCKED, "no recent laser scan")
        clearance = self._clearance(scan)
        if clearance <= s.safety_distance_m + self.stopping_m:
            return turn_only(ControllerState.BLOCKED, f"obstacle at {clearance:.2f} m")
        speed = min(s.max_linear, s.distance_gain * (distance - s.follow_distance_m))
        return VelocityCommand(
            speed,
            angular,
            ControllerState.FOLLOWING,
            f"target at {distance:.2f} m",
            name,
            track_id,
            stamp,
        )
