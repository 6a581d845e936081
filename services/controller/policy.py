"""The controller's decisions: one stateful Controller over every camera. No bus, no clock.

Conventions (REP 103): +x forward, +angular z turns left (counter-clockwise). Every bearing
here is in the robot's frame: a box's bearing in its image plus its camera's mounting yaw
(services/controller/geometry.py), so a target right of a front camera's centre has a negative
bearing and gives a negative angular velocity, and one seen by the rear camera has a bearing
near +-180 deg.

Several cameras: each camera's detections are judged on their own; a stale or silent camera is
ignored, and only when no camera is fresh does the dead-man stop the robot. The cameras and
their geometry are those announced now (``set_cameras``); when the target's camera is withdrawn
the next command is a stop and the target is let go of. The target is
chosen among the fresh cameras' boxes together (services/controller/targets.py). A target far
off the robot's heading (behind it, beside it) is turned to in place: the robot drives forward
only while the target is centred (``center_tolerance``) and, in either mode, while the way
ahead is known clear (services/controller/way_ahead.py): every obstacle source the settings
require (``obstacle_sources``: the laser's scan, the depth cameras' virtual scan) fresh, and no
fresh one showing anything within the safety distance plus the room to brake. The follow lock is
a camera's track id; when the locked target leaves that camera's view, the lock passes to a
box of the same class in another camera within ``handover_gate_deg`` of where the target
should be by now, for ``handover_window_s`` after it was last seen, and the robot holds its
turn towards it (without driving) while it is predicted between the cameras' fields of view.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from common.contracts import ControllerMode, ControllerState, DistanceSource
from common.messages import LaserScan
from services.controller.contract import ControllerSettings
from services.controller.geometry import (
    Mount,
    box_clipped,
    box_distance,
    depth_distance,
    in_view,
    laser_covers,
    sector_range,
    wrap,
)
from services.controller.limits import Limits, limit
from services.controller.pid import PID, PIDGains
from services.controller.targets import Sighting, View, sightings, stale_reason
from services.controller.way_ahead import Obstacles, blocked, creep, known_clear, tick_sources


@dataclass(frozen=True, slots=True)
class VelocityCommand:
    """What to send: velocities plus what the status message reports: the state and reason,
    the target, the camera that sees it, and the cameras whose detections are stale."""

    linear_x: float
    angular_z: float
    state: ControllerState
    reason: str
    target: str = ""
    track_id: int = -1
    input_stamp_ns: int = 0
    camera: str = ""
    stale: tuple[str, ...] = ()

    @property
    def is_zero(self) -> bool:
        return self.linear_x == 0.0 and self.angular_z == 0.0


@dataclass(frozen=True, slots=True)
class Inputs:
    """The newest inputs: each camera's :class:`View` by camera name, the scan and its age in
    seconds (inf when none has arrived), and the e-stop; the depth cameras' virtual scan
    (services/controller/depth_obstacles.py ``depth_obstacles``), its age, why there is none
    (``depth_missing``); what the depth cameras' map remembers round the robot
    (``depth_remembered``, depthscan/local_map.py: judged with the depth, when the
    depth is fresh) and how far ahead it knows the floor (``depth_known_m``); why the robot
    must hold still, turning included (``depth_halt``: no fresh memory from the depth scan
    stage, which would not hear the turn)."""

    views: Mapping[str, View]
    scan: LaserScan | None = None
    scan_age_s: float = math.inf
    estop: bool = False
    depth: LaserScan | None = None
    depth_age_s: float = math.inf
    depth_missing: str = "no depth camera"
    depth_remembered: LaserScan | None = None
    depth_known_m: float = math.inf
    depth_halt: str = ""


def stop(state: ControllerState, reason: str, input_stamp_ns: int = 0) -> VelocityCommand:
    return VelocityCommand(0.0, 0.0, state, reason, input_stamp_ns=input_stamp_ns)


#: The least time between two sightings of the target for the rate its bearing moves at (s):
#: two frames of one round are no measure of motion.
BEARING_RATE_MIN_DT_S = 0.05


class Controller:
    """Turns the newest inputs into one command per control tick, with memory.

    Memory: the PID's history, the locked target (its camera and track id) and when it was last
    seen, the previous command (for the acceleration limits), and the recent turn rates it
    commanded.

    Latency compensation: a detection describes the world when its frame was captured, which
    on a CPU detector is a few hundred milliseconds ago. The robot has turned since, by the
    turn rates this controller itself commanded. Subtracting that rotation from the measured
    bearing keeps the turn from overshooting; without it a slow detector makes the robot
    swing past its target and lose it. Each camera's frames have their own capture time. A
    distance measured on the frame (from depth, or the box's height) is likewise net of how
    far the robot drove since: else a follower on a slow detector stops short of nothing and
    ends nearer than ``follow_distance_m`` by its speed times the latency.
    """

    def __init__(self, s: ControllerSettings, cameras: Mapping[str, Mount]) -> None:
        self.s = s
        self.cameras: dict[str, Mount] = dict(cameras)
        # A camera of the target's that was withdrawn since the last step: the next is a stop.
        self.target_withdrawn = ""
        self.pid = PID(
            PIDGains(s.bearing_kp, s.bearing_ki, s.bearing_kd, s.max_angular, s.max_angular)
        )
        self.limits = Limits(s.max_linear, s.max_angular, s.max_linear_accel, s.max_angular_accel)
        self.locked: tuple[str, int] | None = None  # (camera, track id) in follow mode
        # The lock dropped when the target was lost (camera, track id, when): waited for
        # relock_window_s (see _pick). How often the lost lock was taken back, and how often
        # another track was locked after one was lost (a switch, perhaps to someone else).
        self.lost: tuple[str, int, float] | None = None
        self._regained = False
        self._ever_locked = False
        self.locks_regained = 0
        self.locks_switched = 0
        self.last_seen = -math.inf
        self.last_aim: VelocityCommand | None = None
        self.previous = (0.0, 0.0)
        self.last_step: float | None = None
        self.stopping_m = 0.0
        self.obstacles: tuple[Obstacles, ...] = ()
        self.turns: deque[tuple[float, float, float]] = deque(maxlen=1024)  # (time, v, w)
        self.last_bearing: tuple[float, float] | None = None  # (bearing, when captured)
        self.bearing_rate = 0.0  # rad/s the followed target's bearing moves across the world
        # While the target is predicted between the cameras: the newest tick's time plus
        # target_lost_timeout_s (see _handover_until).
        self.between_until = -math.inf

    def set_cameras(self, cameras: Mapping[str, Mount], withdrawn: Iterable[str] = ()) -> None:
        """The cameras announced now, with their geometry, and those withdrawn since the last
        call (a camera withdrawn and announced again in between is among both). The target's
        camera among the withdrawn makes the next step a stop that lets the target go: what
        was seen through a camera that is gone is not driven on."""
        self.cameras = dict(cameras)
        mine = self.target_camera()
        if mine and mine in set(withdrawn):
            self.target_withdrawn = mine

    def target_camera(self) -> str:
        """The camera the target is locked on or was last aimed at through ("" for none)."""
        if self.locked is not None:
            return self.locked[0]
        return self.last_aim.camera if self.last_aim is not None else ""

    def step(self, inp: Inputs, now: float) -> VelocityCommand:
        """The command for this tick; ``now`` is a monotonic time in seconds."""
        timeout = self.s.detection_timeout_s
        views = {c: inp.views.get(c, View(None)) for c in self.cameras}
        stale = tuple(c for c, v in views.items() if not v.fresh(timeout))
        cmd = self._step(inp, views, now)
        return dataclasses.replace(cmd, stale=stale) if stale else cmd

    def _step(self, inp: Inputs, views: dict[str, View], now: float) -> VelocityCommand:
        # The first tick may accelerate for one nominal period, like every later one.
        dt = 1.0 / self.s.control_rate_hz if self.last_step is None else now - self.last_step
        self.last_step = now
        if inp.estop:
            return self._halt(stop(ControllerState.ESTOP, "emergency stop latched"))
        if self.target_withdrawn:
            gone, self.target_withdrawn = self.target_withdrawn, ""
            return self._halt(
                stop(ControllerState.STALE, f"the target's camera {gone} is no longer announced")
            )
        timeout = self.s.detection_timeout_s
        fresh = {c: v for c, v in views.items() if v.fresh(timeout)}
        if not fresh:
            return self._halt(stop(ControllerState.STALE, stale_reason(views)))
        if inp.depth_halt:
            return self._halt(stop(ControllerState.BLOCKED, inp.depth_halt))
        s = self.s
        # The room to stop is from the fastest this tick may command: its speed now plus what
        # the acceleration limit allows since the last tick (after a stalled tick that is much
        # more than now).
        v = min(s.max_linear, max(0.0, self.previous[0]) + s.max_linear_accel * dt)
        self.obstacles = tick_sources(s, inp, v)
        laser = self.obstacles[0]
        self.stopping_m = laser.stopping_m
        aim = self._aim(fresh, laser.scan, now, dt)
        if aim.state == ControllerState.SEARCHING:
            return self._halt(aim)  # the target is gone: stop now, not at the braking rate
        if not (math.isfinite(aim.linear_x) and math.isfinite(aim.angular_z)):
            # Unreachable with validated inputs; if it ever happens, stop and start afresh.
            return self._halt(
                stop(ControllerState.FAULT, "non-finite command computed", aim.input_stamp_ns)
            )
        v, w = limit(self.previous, (aim.linear_x, aim.angular_z), dt, self.limits)
        self.previous = (v, w)
        self.turns.append((now, v, w))
        return dataclasses.replace(aim, linear_x=v, angular_z=w)

    def _halt(self, cmd: VelocityCommand) -> VelocityCommand:
        """Zero at once (safety stops bypass the acceleration limit) and forget the target."""
        self.previous = (0.0, 0.0)
        self.pid.reset()
        self.locked, self.last_aim, self.last_bearing = None, None, None
        self.bearing_rate = 0.0
        self.between_until = -math.inf
        self.turns.clear()
        return cmd

    def _since(self, t0: float, now: float, which: int) -> float:
        """The integral from ``t0`` to ``now`` of the commanded speed ``which`` (1: linear, 2:
        angular). Each command holds until the next one; the newest holds until ``now``."""
        total = 0.0
        entries = list(self.turns)
        ends = [e[0] for e in entries[1:]] + [now]
        for entry, end_t in zip(entries, ends[: len(entries)], strict=True):
            start, end = max(entry[0], t0), min(end_t, now)
            if end > start:
                total += entry[which] * (end - start)
        return total

    def rotation_since(self, t0: float, now: float) -> float:
        """How far the robot turned (rad) from ``t0`` to ``now``, by the rates it commanded."""
        return self._since(t0, now, 2)

    def travel_since(self, t0: float, now: float) -> float:
        """How far the robot drove forward (m) from ``t0`` to ``now``, by its commands."""
        return self._since(t0, now, 1)

    def _bearing_now(self, bearing: float, captured: float, now: float) -> float:
        """A bearing measured at ``captured``, net of the robot's turning since."""
        return wrap(bearing - self.rotation_since(captured, now))

    def _predicted(self, now: float) -> float | None:
        """Where the last seen target should be now: its last bearing, net of the robot's turn
        since, moved on (follow mode) at the rate its bearing was changing across the world
        (``bearing_rate``, at most ``hold_bearing_rate`` rad/s) for up to
        ``target_lost_timeout_s``: a person striding out of the view is turned after, not
        looked for where they were."""
        if self.last_bearing is None:
            return None
        bearing, captured = self.last_bearing
        s = self.s
        rate = max(-s.hold_bearing_rate, min(s.hold_bearing_rate, self.bearing_rate))
        ahead = min(max(now - captured, 0.0), s.target_lost_timeout_s)
        return wrap(self._bearing_now(bearing, captured, now) + rate * ahead)

    def _note_bearing(self, x: Sighting) -> None:
        """Keep ``x`` as the last sighting of the target and, in follow mode, the rate its
        bearing moves at across the world (the robot's own turn taken out), smoothed."""
        last = self.last_bearing
        if self.s.mode is ControllerMode.FOLLOW and last is not None:
            dt = x.captured - last[1]
            if dt >= BEARING_RATE_MIN_DT_S:
                moved = wrap(x.bearing + self.rotation_since(last[1], x.captured) - last[0])
                self.bearing_rate = 0.5 * self.bearing_rate + 0.5 * moved / dt
        if last is None or x.captured >= last[1]:
            self.last_bearing = (x.bearing, x.captured)

    def _between_cameras(self, now: float, fresh: Mapping[str, View]) -> bool:
        """Whether, with several cameras, the target is predicted in none of the fresh ones'
        fields of view: not seeing it then is no sign it has gone."""
        predicted = self._predicted(now)
        if len(self.cameras) < 2 or predicted is None:
            return False
        return not any(in_view(predicted, self.cameras[c]) for c in fresh)

    def _pick(self, found: list[Sighting], now: float) -> Sighting | None:
        """The target: the most central (track) or the locked / largest (follow) sighting."""
        if not found:
            return None
        if self.s.mode is ControllerMode.TRACK:
            return min(found, key=lambda x: abs(x.bearing))
        if self.locked is not None:
            cam, track_id = self.locked
            mine = [x for x in found if x.camera == cam]
            if not (mine and mine[0].dets.boxes.track_ids is None):
                for x in mine:
                    if x.track_id == track_id:
                        return x
                # Out of its camera's view: never jump to another target, but follow this
                # one into another camera's view.
                return self._handover(found, now)
        if self.lost is not None:
            cam, track_id, when = self.lost
            back = [x for x in found if x.camera == cam and x.track_id == track_id >= 0]
            if back:
                self.lost, self._regained = None, True
                return back[0]
            if now - when <= self.s.relock_window_s:
                return None  # wait for the lost one: nobody else is locked meanwhile
            self.lost = None
        return max(found, key=lambda x: x.angular_area)

    def _handover_until(self) -> float:
        """Until when a target not seen may be held and handed to another camera:
        ``handover_window_s`` after it was last seen, and, once it has been predicted between the
        cameras since, ``target_lost_timeout_s`` after the last tick it was (the camera the
        robot turned it into has that long to see it), up to the half turn at ``max_angular``
        more: a slow turn (its acceleration, a blurred image losing the target early) does not
        end the hold while the target is still out of every view."""
        s = self.s
        window = self.last_seen + s.handover_window_s
        if self.between_until <= self.last_seen:
            return window
        return max(window, min(self.between_until, window + math.pi / s.max_angular))

    def _handover(self, found: list[Sighting], now: float) -> Sighting | None:
        """The locked target as another camera sees it: the box of the same class nearest to
        where it should be now, within ``handover_gate_deg``, for ``handover_window_s`` after
        it was last seen. The lock passes to that camera's track."""
        s, predicted = self.s, self._predicted(now)
        if (
            self.locked is None
            or self.last_aim is None
            or predicted is None
            or now > self._handover_until()
        ):
            return None
        gate = math.radians(s.handover_gate_deg)
        best: Sighting | None = None
        best_off = math.inf
        for x in found:
            if x.camera == self.locked[0] or x.name != self.last_aim.target:
                continue
            off = abs(wrap(self._bearing_now(x.bearing, x.captured, now) - predicted))
            if off <= gate and off < best_off:
                best, best_off = x, off
        if best is not None:
            self.locked = (best.camera, best.track_id) if best.track_id >= 0 else None
        return best

    def _aim(
        self, fresh: dict[str, View], scan: LaserScan | None, now: float, dt: float
    ) -> VelocityCommand:
        s = self.s
        classes = s.target_classes if s.mode is ControllerMode.TRACK else s.target_classes[:1]
        newest = {c: v.dets for c, v in fresh.items() if v.dets is not None}
        stamp = max(d.header.stamp_ns for d in newest.values())
        # The compensation trusts the capture stamp no further than the dead-man does.
        captured = {c: now - min(v.capture_age_s, s.detection_timeout_s) for c, v in fresh.items()}
        best = self._pick(sightings(newest, captured, self.cameras, classes, s.min_score), now)
        if best is None:
            return self._hold(fresh, now, dt, stamp, classes)
        if s.mode is ControllerMode.FOLLOW and self.locked is None and best.track_id >= 0:
            self.locked = (best.camera, best.track_id)
            if self._regained:
                self.locks_regained += 1
            elif self._ever_locked:
                self.locks_switched += 1
            self._regained, self._ever_locked, self.lost = False, True, None
            self.bearing_rate, self.last_bearing = 0.0, None  # a new target's motion is its own
        self.last_seen = now
        self._note_bearing(best)
        err = self._bearing_now(best.bearing, best.captured, now)
        angular = self.pid.update(err, dt)
        # Centred: within center_tolerance of the image width of the camera that sees it, as
        # an angle; a target beside or behind the robot never is, and is turned to in place.
        width = best.dets.image_width
        centred = abs(err) <= math.atan(s.center_tolerance * width / best.focal_px)
        stamp = best.dets.header.stamp_ns
        if s.mode is ControllerMode.TRACK:
            stopped_by = blocked(self.obstacles, s) if centred else None
            state = ControllerState.TURNING
            if centred:
                state = ControllerState.TRACKING if stopped_by is None else ControllerState.BLOCKED
            linear, why = creep(
                self.obstacles,
                s,
                s.forward_speed if state is ControllerState.TRACKING else 0.0,
                stopped_by or f"bearing {math.degrees(err):+.1f} deg",
            )
            aim = VelocityCommand(
                linear,
                angular,
                state,
                why,
                best.name,
                best.track_id,
                stamp,
                best.camera,
            )
        else:
            aim = self._follow(best, scan, err, angular, centred, now)
        self.last_aim = aim
        return aim

    def _hold(
        self,
        fresh: dict[str, View],
        now: float,
        dt: float,
        stamp: int,
        classes: tuple[str, ...],
    ) -> VelocityCommand:
        """No target in view. A brief dropout (a missed detection): keep turning towards where
        the target was, net of our own turning since; drive on only while a scan shows the way
        clear (with ``no_laser`` too).
        A target predicted between the cameras is held up to ``handover_window_s``, turning
        in place, and on while the robot still turns towards a camera's view
        (:meth:`_handover_until`). Then stop and unlock."""
        s = self.s
        between = self._between_cameras(now, fresh)
        if between:
            self.between_until = now + s.target_lost_timeout_s
        until = self.last_seen + s.target_lost_timeout_s
        if between or self.between_until > self.last_seen:
            until = max(until, self._handover_until())
        if self.last_aim is not None and now <= until:
            held = self.last_aim
            # Driving on towards a target not seen needs a scan that shows the way clear,
            # even with no_laser (which lets the robot drive only towards a target in view).
            clear = known_clear(self.obstacles, s)
            where = ", between the cameras" if between else ""
            linear, why = creep(
                self.obstacles,
                s,
                held.linear_x if clear and not between else 0.0,
                f"target unseen for {now - self.last_seen:.1f} s{where}",
            )
            predicted = self._predicted(now)
            angular = 0.0 if predicted is None else self.pid.update(predicted, dt)
            return VelocityCommand(
                linear,
                angular,
                ControllerState.HOLDING,
                why,
                held.target,
                held.track_id,
                stamp,
                held.camera,
            )
        if self.locked is not None:
            self.lost = (*self.locked, now)
        self.locked, self.last_aim = None, None
        self.pid.reset()
        return stop(ControllerState.SEARCHING, f"no {'/'.join(classes)} in view", stamp)

    def _follow(
        self,
        x: Sighting,
        scan: LaserScan | None,
        err: float,
        angular: float,
        centred: bool,
        now: float,
    ) -> VelocityCommand:
        s = self.s
        dets, i = x.dets, x.i
        stamp = dets.header.stamp_ns

        def turn_only(state: ControllerState, reason: str) -> VelocityCommand:
            return VelocityCommand(0.0, angular, state, reason, x.name, x.track_id, stamp, x.camera)

        distance = math.inf
        on_frame = s.distance_source is not DistanceSource.LASER  # measured at its capture
        if s.distance_source is DistanceSource.DEPTH:
            distance = depth_distance(dets, i, self.cameras.get(x.camera))
            if not math.isfinite(distance):
                if not centred:
                    return turn_only(
                        ControllerState.TURNING, f"bearing {math.degrees(err):+.1f} deg"
                    )
                return turn_only(ControllerState.BLOCKED, "the target's depth is unknown")
        elif s.distance_source is DistanceSource.LASER:
            if scan is None:
                return turn_only(ControllerState.BLOCKED, "no recent laser scan for the distance")
            if not centred and not laser_covers(scan, err):
                # Behind the robot, outside the laser's field: turn to it first.
                return turn_only(
                    ControllerState.TURNING,
                    f"bearing {math.degrees(err):+.1f} deg, outside the laser's view",
                )
            # The laser rays across the middle 60% of the box's width, in the bearing ``err``
            # (in the robot's frame, net of our turning since the frame was captured).
            half_width = math.atan(float(dets.sizes[i, 0]) / 2 / x.focal_px)
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
            distance = box_distance(dets, i, x.hfov_deg, s.target_height_m)
            on_frame = True
        if on_frame:  # net of how far the robot drove since the frame was captured
            distance -= self.travel_since(x.captured, now)
        if not centred:
            return turn_only(ControllerState.TURNING, f"bearing {math.degrees(err):+.1f} deg")
        if distance <= s.follow_distance_m:
            return turn_only(ControllerState.ARRIVED, f"target at {distance:.2f} m")
        stopped_by = blocked(self.obstacles, s)
        if stopped_by is not None:
            return turn_only(ControllerState.BLOCKED, stopped_by)
        speed, why = creep(
            self.obstacles,
            s,
            min(s.max_linear, s.distance_gain * (distance - s.follow_distance_m)),
            f"target at {distance:.2f} m",
        )
        return VelocityCommand(
            speed,
            angular,
            ControllerState.FOLLOWING,
            why,
            x.name,
            x.track_id,
            stamp,
            x.camera,
        )
