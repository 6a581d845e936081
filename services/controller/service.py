"""The controller service: every camera's latest detections and the scan (and, when its
settings need depth, the depth scan stage's virtual scans and memory) in, Twist and
ControllerStatus out."""

from __future__ import annotations

import dataclasses
import json
import threading
from contextlib import ExitStack
from typing import TYPE_CHECKING

from common.announce import Announced, announced_cameras
from common.bus import Declared
from common.clock import mono_s
from common.contracts import ControllerState, DetectorInfo
from common.errors import DecodeError
from common.estop_local import LocalEStop, socket_path
from common.keys import camera_in_key, virtual_scan_camera
from common.messages import CameraAnnouncement
from common.node import Node
from common.ratelimit import LogLimiter
from services.controller import contract
from services.controller.handlers import ControllerHandlers, age_of
from services.controller.outputs import Outputs
from services.controller.policy import Controller, Inputs, VelocityCommand
from services.controller.policy import stop as stop_command
from services.controller.statelog import log_state
from services.controller.targets import unknown_targets
from stack.config import Config

if TYPE_CHECKING:
    from services.controller.depth_input import DepthInput


NO_LASER_WARNING = (
    "NO LASER (controller.no_laser = true): forward motion is not checked for obstacles; "
    "the robot drives into whatever is in its way"
)

# The longest the control loop goes without looking at the stop flag, whatever its rate.
STOP_POLL_S = 0.1


def wait_either(wake: threading.Event, stop: threading.Event, timeout_s: float) -> None:
    """Return when ``wake`` is set, ``stop`` is set or ``timeout_s`` has passed, whichever
    comes first. ``stop`` is looked at every ``STOP_POLL_S``: a stop (SIGTERM) is never left
    waiting for a whole control period."""
    deadline = mono_s() + timeout_s
    while not stop.is_set():
        left = deadline - mono_s()
        if left <= 0 or wake.wait(min(left, STOP_POLL_S)):
            return


class ControlLoop:
    """The controller on ``node``'s bus, at ``node``'s clock: its handlers subscribed to every
    camera's detections, the scan and the e-stop, the cameras' announcements watched (its
    cameras and their geometry), and the control loop's body, :meth:`tick`.

    ``run`` calls :meth:`tick` at least ``control_rate_hz`` times a second and at once when
    new detections arrive (``handlers.arrived``), and :meth:`stop` last; an in-process test
    calls them itself, on an in-memory bus with a fake clock. :meth:`close` undeclares the
    subscriptions.
    """

    def __init__(self, config: Config, node: Node) -> None:
        s = self.settings = config.controller
        self.node = node
        self.clock = node.clock
        self.out = Outputs(node, config)
        self.handlers = ControllerHandlers(
            config, node, self.out.halt, self._halted, clock=node.clock
        )
        latch = self.latch = self.handlers.latch
        (node.log.warning if latch.engaged else node.log.info)("%s", latch.note)
        if not latch.saved:
            node.log.error("the e-stop state cannot be saved: %s", latch.describe())
        keys = node.keys
        self.controller = Controller(s, {})
        # Every camera's detections on one subscription: those of a camera not announced are
        # heard only to be counted (ControllerHandlers.on_detections).
        self._subs: list[Declared] = [
            node.subscribe_keyed(keys.all_detections(), self._on_detections),
            node.subscribe(keys.scan(), self.handlers.on_scan),
            node.subscribe(keys.estop(), self.handlers.on_estop),
        ]
        # The depth scan stage's output, only when depth is needed (services/depthscan).
        self.depth: DepthInput | None = None
        if s.needs_depth:
            # Here, not at the top: perception loads OpenCV, which only a controller that
            # reads depth needs.
            from services.controller.depth_input import DepthInput

            depth = self.depth = DepthInput(s, node, config.stack.clock_tolerance_s, node.clock)
            self._subs += [
                node.subscribe_keyed(keys.all_virtual_scans(), self._on_virtual_scan),
                node.subscribe(keys.remembered_scan(), depth.on_remembered),
                node.subscribe(keys.known_floor(), depth.on_known),
            ]
        self._cameras_lock = threading.Lock()  # one change of the camera set at a time
        self.announced: Announced[CameraAnnouncement] | None = None
        self.announced = announced_cameras(
            node.bus, keys, self._on_cameras, self._on_bad_announcement
        )
        self._on_cameras()  # those already announced (a Zenoh watch reports them as it starts)
        node.log.info(
            "mode %s on the cameras announced under %s, targets %s",
            s.mode, keys.all_camera_announcements(), list(s.target_classes),
        )  # fmt: skip
        if s.no_laser:
            node.log.warning(NO_LASER_WARNING)
        node.log.info(
            "forward motion needs fresh %s; distance to the target from %s",
            " and ".join(
                x for x in s.obstacle_sources if not (s.no_laser and x == contract.LASER_SOURCE)
            ) or "nothing (no_laser)",
            s.distance_source,
        )  # fmt: skip
        self._last_state: ControllerState | None = None
        # Detections that go stale between one and the next flip the state several times a
        # second: the first changes are logged, then a summary each period (the metrics
        # service's detections_late warning says why and what to change).
        self._state_log = LogLimiter(clock=self.clock.mono_s)
        self._locks_counted: dict[str, int] = {}  # the policy's lock events counted so far

    def _on_detections(self, key: str, payload: bytes) -> None:
        camera = camera_in_key(key)
        if camera is None:  # unreachable: the subscription's keys all name a camera
            self.node.bad_input(key, DecodeError("not a camera's detections key"))
            return
        self.handlers.on_detections(camera, payload)

    def _on_virtual_scan(self, key: str, payload: bytes) -> None:
        camera = virtual_scan_camera(key)
        if camera is None or self.depth is None:  # unreachable: subscribed only with depth
            self.node.bad_input(key, DecodeError("not a camera's virtual scan key"))
            return
        self.depth.on_virtual_scan(camera, payload)

    def _on_cameras(self) -> None:
        """The set of announced cameras changed: the handlers take the new one at once."""
        if self.announced is None:  # called back while it is being declared: done after
            return
        with self._cameras_lock:
            before = set(self.handlers.cameras)
            now = self.announced.current()
            self.handlers.set_cameras(dict(sorted(now.items())))
            if self.depth is not None:
                self.depth.set_cameras(now)
        for camera in sorted(now.keys() - before):
            a = now[camera]
            self.node.log.info(
                "camera %s announced by %s: yaw %+.0f deg, fov %.0f deg",
                camera, a.source or "?", a.mount_yaw_deg, a.hfov_deg,
            )  # fmt: skip
        for camera in sorted(before - now.keys()):
            self.node.log.warning("camera %s withdrawn: its detections are ignored", camera)

    def _on_bad_announcement(self, key: str, error: Exception) -> None:
        self.node.bad_input(key, error, topic="camera_announcement")

    def _halted(self) -> None:
        """The e-stop's status, once the engage is saved (or could not be)."""
        estop = stop_command(ControllerState.ESTOP, self.latch.describe())
        at = self.clock.now()
        self.out.send(estop, at, estop_saved=self.latch.saved)

    def tick(self) -> float:
        """One control tick: judge every input's age at one instant, send the command and
        the status stamped with it, log a change of state, publish the counters (when due).
        Returns the tick's instant (monotonic seconds on the node's clock)."""
        handlers, latch, out = self.handlers, self.latch, self.out
        handlers.arrived.clear()  # before reading, so a message arriving now wakes the loop
        with out.lock:  # an engage's zero waits for this command, never the reverse
            # One instant per tick: the ages are judged at it and the command is stamped
            # with it, so that a reader of cmd_vel can check the judgement.
            at = self.clock.now()
            tick = at.mono_ns / 1e9
            cameras, withdrawn, views = handlers.take(at)
            self.controller.set_cameras(cameras, withdrawn)
            sc, sc_arrival = handlers.scan.get()
            sc_age = age_of(sc.header if sc is not None else None, sc_arrival, at)
            inputs = Inputs(views, sc, sc_age, latch.engaged)
            if self.depth is not None:
                seen = self.depth.obstacles(at)
                inputs = dataclasses.replace(
                    inputs,
                    depth=seen.scan,
                    depth_age_s=seen.age_s,
                    depth_missing=seen.missing,
                    depth_remembered=seen.remembered,
                    depth_known_m=seen.known_m,
                    depth_halt=seen.halt,
                )
            cmd = self.controller.step(inputs, tick)
            if cmd.state == ControllerState.ESTOP:
                cmd = dataclasses.replace(cmd, reason=latch.describe())
            out.send(cmd, at, estop_saved=latch.saved)  # the depth map moves by it too
        if cmd.state != self._last_state:
            log_state(self.node.log, self._state_log, cmd)
            self._last_state = cmd.state
        self._count_locks()
        for line in self._state_log.due():
            # The summary says what the changes were; a person reading the log after the robot
            # stood still for a while needs what it is doing now, and why.
            self.node.log.info("%s; now %s: %s", line, cmd.state, cmd.reason)
        self.node.publish_counters()
        return tick

    def _count_locks(self) -> None:
        """The policy's lock events since the last tick, as counters."""
        c = self.controller
        for name, now in (
            (contract.LOCK_REGAINED, c.locks_regained),
            (contract.LOCK_SWITCHED, c.locks_switched),
        ):
            seen = self._locks_counted.get(name, 0)
            if now > seen:
                self.node.counters.add(name, now - seen)
                self._locks_counted[name] = now

    def stop(self) -> None:
        """Leave the robot still: the last word on cmd_vel is always a stop."""
        stopped = VelocityCommand(0.0, 0.0, ControllerState.STOPPED, "shutdown")
        self.out.send(stopped, self.clock.now(), estop_saved=self.latch.saved)

    def close(self) -> None:
        if self.announced is not None:
            self.announced.close()
        for sub in self._subs:
            sub.undeclare()


def run(config: Config, stop: threading.Event) -> int:
    """Run the control loop until ``stop`` is set.

    A command goes out at least ``control_rate_hz`` times a second, and at once when new
    detections arrive: waiting for the next tick would add up to a whole period of latency.
    Inputs are judged on arrival (common/freshness.py): stale, future-stamped or replayed
    detections and scans are counted and never acted on. Every announced camera's detections
    are used, each aged on its own at the control instant (policy.py: a stale camera is
    ignored; none fresh is the dead-man stop).
    """
    s = config.controller
    with ExitStack() as closing:
        node = closing.enter_context(
            Node("controller", config, counters_period_s=s.counters_period_s)
        )
        loop = ControlLoop(config, node)
        closing.callback(loop.close)
        local = _local_estop(config, node, loop.handlers)
        if local is not None:
            closing.callback(local.close)  # before the loop's close, as it engages the loop
        checker = threading.Thread(
            target=_check_targets, args=(node, config, stop), name="check-targets", daemon=True
        )
        checker.start()
        node.ready()
        period = 1.0 / s.control_rate_hz
        while not stop.is_set():
            tick = loop.tick()
            wait_either(loop.handlers.arrived, stop, period - (node.clock.mono_s() - tick))
        loop.stop()  # the last word on cmd_vel: zero, before the loop and the node close
    return 0


def _local_estop(config: Config, node: Node, handlers: ControllerHandlers) -> LocalEStop | None:
    """The local e-stop socket beside the e-stop file (common/estop_local.py), or None, said
    in the log, when it cannot be made: ``zstack estop`` then reaches this controller over
    Zenoh only."""
    path = socket_path(config.estop_path)
    try:
        local = LocalEStop(
            path, handlers.on_local_engage, handlers.on_local_garbage, handlers.on_local_failed
        )
    except OSError as exc:
        node.log.warning(
            "no local e-stop socket (%s: %s): zstack estop reaches this controller over "
            "Zenoh only", exc.strerror or exc, path,
        )  # fmt: skip
        return None
    node.log.info("local e-stop socket %s (engage only)", path)
    return local


def _check_targets(node: Node, config: Config, stop: threading.Event) -> None:
    """Ask the detector for its model's classes (until one answers) and warn, once, about
    target classes it cannot report."""
    key = node.keys.detector_info(config.stack.camera)
    while not stop.is_set():
        for reply in node.bus.query(key, timeout_s=2.0):
            try:
                info: DetectorInfo = json.loads(reply.payload)
                classes = info["classes"]
                if not (isinstance(classes, list) and all(isinstance(c, str) for c in classes)):
                    raise TypeError(f"classes must be a list of names, got {classes!r:.80}")
            except (ValueError, KeyError, TypeError) as exc:
                node.bad_input(key, exc)
                continue
            targets = config.controller.target_classes
            missing = unknown_targets(targets, classes)
            if missing:
                node.log.warning(
                    "target class(es) %s are not among the model's %d classes (%s...): the "
                    "robot will never see them; check controller.target_classes",
                    missing, len(classes), ", ".join(classes[:5]),
                )  # fmt: skip
            return
        stop.wait(2.0)
