"""The controller service: every camera's latest detections and the scan in, Twist and
ControllerStatus out."""

from __future__ import annotations

import dataclasses
import json
import threading
from collections.abc import Callable
from functools import partial
from typing import Generic, Protocol, TypeVar

from common.bus import QoS
from common.clock import BOOT_ID, Stamp, mono_s, now
from common.contracts import ControllerState, DetectorInfo
from common.counters import per_camera
from common.errors import DecodeError
from common.freshness import FreshnessGate, Verdict, capture_age_s, judge_age
from common.messages import ControllerStatus, Detections, EStop, Header, LaserScan, Twist
from common.node import Node, Tally
from common.ratelimit import LogLimiter
from services.controller import contract
from services.controller.estop import EStopLatch
from services.controller.policy import Controller, Inputs, VelocityCommand
from services.controller.policy import stop as stop_command
from services.controller.statelog import log_state
from services.controller.targets import View, unknown_targets
from stack.config import Config


class _Stamped(Protocol):
    @property
    def header(self) -> Header: ...


_S = TypeVar("_S", bound=_Stamped)

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


class Latest(Generic[_S]):
    """The newest decoded message of one key and when it arrived (monotonic seconds).

    Newest by capture stamp: a message captured before the one held (a late delivery, another
    source's older view) never replaces it.
    """

    def __init__(self, arrived: threading.Event | None = None) -> None:
        self._lock = threading.Lock()
        self._msg: _S | None = None
        self._t = 0.0
        # Set on every new message (one event may be shared: every camera's wakes the loop);
        # the loop clears it.
        self.arrived = arrived or threading.Event()

    def set(self, msg: _S) -> bool:
        """Hold ``msg``; False (and nothing changes) when it is older than the one held."""
        with self._lock:
            if self._msg is not None and msg.header.stamp_ns < self._msg.header.stamp_ns:
                return False
            self._msg, self._t = msg, mono_s()
        self.arrived.set()
        return True

    def get(self) -> tuple[_S | None, float]:
        """The message and its age in seconds (inf when none has arrived)."""
        with self._lock:
            if self._msg is None:
                return None, float("inf")
            return self._msg, mono_s() - self._t


def _age(msg: Header | None, arrival_age_s: float, at: Stamp) -> float:
    """How old an input is for the dead-man: the later of its capture and its arrival."""
    if msg is None:
        return float("inf")
    return max(arrival_age_s, capture_age_s(msg, at, BOOT_ID))


def _view(latest: Latest[Detections], at: Stamp, timeout_s: float) -> View:
    """One camera's newest detections, aged at the control instant ``at``."""
    d, arrival = latest.get()
    if d is None:
        return View(None)
    capture = capture_age_s(d.header, at, BOOT_ID)
    return View(d, _age(d.header, arrival, at), min(max(0.0, capture), timeout_s))


class ControllerHandlers:
    """What the controller does with each input as it arrives: detections and scans are judged
    (common/freshness.py) and the newest fresh one is held for the control loop; an e-stop
    message latches or releases the stop, kept on disk (controller/estop.py).

    Every camera of the config has its own gate and its own newest detections (``dets``, by
    camera name, the first camera first): one camera's stamps never judge another's, and a
    stale camera is ignored while the others are used. With several cameras, each camera's
    counts are kept beside the totals (``detections_in.rear``, ...).
    """

    def __init__(
        self,
        config: Config,
        tally: Tally,
        halt: Callable[[], None] | None = None,
        halted: Callable[[], None] | None = None,
    ) -> None:
        s = config.controller
        self.tally = tally
        # An engage is acted on here, on the handler's thread, not at the loop's next tick:
        # ``halt`` (the zero command) once the latch holds in memory, before it is saved;
        # ``halted`` (the status, saying whether the stop could be saved) after.
        self.halt, self.halted = halt, halted
        self.tolerance_s = config.stack.clock_tolerance_s
        self.estop_release_max_age_s = s.estop_release_max_age_s
        self.latch = EStopLatch(config.estop_path, now().wall_ns + int(self.tolerance_s * 1e9))
        cameras = list(config.all_cameras)
        self.arrived = threading.Event()  # new detections from any camera
        self.dets: dict[str, Latest[Detections]] = {c: Latest(self.arrived) for c in cameras}
        self.scan: Latest[LaserScan] = Latest()
        self._det_keys = {c: tally.keys.detections(c) for c in cameras}
        self._det_gates = {
            c: FreshnessGate(s.detection_timeout_s, self.tolerance_s, BOOT_ID) for c in cameras
        }
        self._per_camera = len(cameras) > 1
        self._scan_gate = FreshnessGate(s.scan_timeout_s, self.tolerance_s, BOOT_ID)

    def on_detections(self, camera: str, payload: bytes) -> None:
        """Detections from ``camera``'s key (a camera of the config)."""
        msg = self.tally.decode(self._det_keys[camera], Detections.decode, payload)
        if msg is not None:
            where = camera if self._per_camera else ""
            self._fresh_input(
                msg, self._det_gates[camera], self.dets[camera], contract.DETECTIONS, where
            )

    def on_scan(self, payload: bytes) -> None:
        msg = self.tally.decode(self.tally.keys.scan(), LaserScan.decode, payload)
        if msg is not None:
            self._fresh_input(msg, self._scan_gate, self.scan, contract.SCANS)

    def _fresh_input(
        self, msg: _S, gate: FreshnessGate, latest: Latest[_S], name: str, camera: str = ""
    ) -> None:
        """A decoded message's fate: judge its freshness, keep it if fresh and newest, count
        the rest (``<name>_in``, ``<name>_stale|future|replay|late``; with ``camera``, also
        ``<counter>.<camera>``)."""
        verdict, age = gate.check(msg.header, now())
        of = f" from {camera}" if camera else ""
        if verdict is not Verdict.FRESH:
            counter = contract.input_counter(name, verdict)
            self.tally.reject(counter, f"{verdict} {name}{of} ({age:.2f} s) ignored")
        elif latest.set(msg):
            counter = contract.input_counter(name, contract.IN)
            self.tally.counters.add(counter)
        else:
            counter = contract.input_counter(name, contract.LATE)
            self.tally.reject(counter, f"{name}{of} older than the ones held ignored")
        if camera:
            self.tally.counters.add(per_camera(counter, camera))

    def on_estop(self, payload: bytes) -> None:
        """Latch on an engage or on garbage; release only on a fresh release newer than the
        stop that can be saved. A latch that cannot be saved holds in memory and says so
        loudly."""
        tally, latch = self.tally, self.latch
        at = now()
        latest_ns = at.wall_ns + int(self.tolerance_s * 1e9)  # no stamp the latch keeps is later
        try:
            msg = EStop.decode(payload)
        except DecodeError as exc:
            # Garbage on the e-stop key is treated as a press: fail safe, not open.
            tally.bad_input(tally.keys.estop(), exc)
            msg = None
        if msg is None or msg.engaged:
            by = msg.header.source if msg else "garbage"
            reason = msg.reason if msg else "undecodable message on the e-stop key"
            was, was_saved = latch.engaged, latch.saved
            stamp = msg.header.stamp_ns if msg else at.wall_ns
            saved = latch.engage(stamp, by, reason, latest_ns, self.halt)
            if self.halted is not None:
                self.halted()
            if not was:
                tally.log.warning("e-stop ENGAGED by %s: %s", by, reason or "-")
            if not saved and was_saved:
                tally.log.error("the e-stop is engaged but cannot be saved: %s", latch.describe())
            return
        verdict, age = judge_age(
            msg.header, at, BOOT_ID, self.estop_release_max_age_s, self.tolerance_s
        )
        if verdict is not Verdict.FRESH:
            latch.refuse(f"{verdict} ({age:.2f} s)")
            tally.reject(
                contract.ESTOP_RELEASE_REFUSED, f"{verdict} e-stop release ({age:.2f} s) refused"
            )
        elif not latch.release(msg.header.stamp_ns, msg.header.source):
            tally.reject(
                contract.ESTOP_RELEASE_REFUSED, f"e-stop release refused: {latch.last_refusal}"
            )
        else:
            tally.log.warning("e-stop released by %s: %s", msg.header.source, msg.reason or "-")


class Outputs:
    """The controller's cmd_vel and status, sent from the control loop and, on an e-stop
    engage, from the e-stop handler's thread. ``lock`` is held by the loop from reading its
    inputs to publishing its command: a command computed before an engage latched goes out
    before the engage's zero, never after it."""

    def __init__(self, node: Node, config: Config) -> None:
        self.node = node
        self.mode = config.controller.mode
        self.no_laser = config.controller.no_laser
        self.lock = threading.RLock()
        self.cmd_pub = node.publisher(node.keys.cmd_vel(), QoS.CONTROL)
        self.status_pub = node.publisher(node.keys.controller_status(), QoS.TELEMETRY)

    def send(self, cmd: VelocityCommand, at: Stamp, *, estop_saved: bool) -> None:
        """``cmd`` on cmd_vel and the status, sharing one header stamped ``at``."""
        with self.lock:
            twist = self._twist(cmd, at)
            status = ControllerStatus(
                header=twist.header,
                mode=self.mode,
                target=cmd.target,
                state=cmd.state,
                reason=cmd.reason,
                track_id=cmd.track_id,
                estop_saved=estop_saved,
                camera=cmd.camera,
                stale_cameras=cmd.stale,
                no_laser=self.no_laser,
            )
            self.status_pub.put(status.encode())

    def halt(self) -> None:
        """Zero on cmd_vel now (the status follows once the stop is saved)."""
        with self.lock:
            self._twist(VelocityCommand(0.0, 0.0, ControllerState.ESTOP, ""), now())
            self.node.counters.add(contract.ESTOP_ZERO_AT_ONCE)

    def _twist(self, cmd: VelocityCommand, at: Stamp) -> Twist:
        twist = Twist(
            header=self.node.header(at, frame_id="base_link"),
            linear=(cmd.linear_x, 0.0, 0.0),
            angular=(0.0, 0.0, cmd.angular_z),
            input_stamp_ns=cmd.input_stamp_ns,
        )
        self.cmd_pub.put(twist.encode())
        self.node.counters.add(contract.COMMANDS_OUT)
        if not cmd.is_zero:
            self.node.counters.add(contract.COMMANDS_NONZERO)
        return twist


def run(config: Config, stop: threading.Event) -> int:
    """Run the control loop until ``stop`` is set.

    A command goes out at least ``control_rate_hz`` times a second, and at once when new
    detections arrive: waiting for the next tick would add up to a whole period of latency.
    Inputs are judged on arrival (common/freshness.py): stale, future-stamped or replayed
    detections and scans are counted and never acted on. Every camera of the config is
    subscribed to, and each one's detections are aged on their own at the control instant
    (policy.py: a stale camera is ignored; none fresh is the dead-man stop).
    """
    s = config.controller
    with Node("controller", config, counters_period_s=s.counters_period_s) as node:
        out = Outputs(node, config)

        def halted() -> None:
            """The e-stop's status, once the engage is saved (or could not be)."""
            estop = stop_command(ControllerState.ESTOP, latch.describe())
            out.send(estop, now(), estop_saved=latch.saved)

        handlers = ControllerHandlers(config, node, out.halt, halted)
        latch, scan = handlers.latch, handlers.scan
        (node.log.warning if latch.engaged else node.log.info)("%s", latch.note)
        if not latch.saved:
            node.log.error("the e-stop state cannot be saved: %s", latch.describe())
        cameras = config.all_cameras
        det_keys = [node.keys.detections(c) for c in cameras]
        subs = [
            *(
                node.subscribe(k, partial(handlers.on_detections, c))
                for c, k in zip(cameras, det_keys, strict=True)
            ),
            node.subscribe(node.keys.scan(), handlers.on_scan),
            node.subscribe(node.keys.estop(), handlers.on_estop),
        ]
        controller = Controller(s, cameras)
        node.log.info(
            "mode %s on %s, targets %s", s.mode, ", ".join(det_keys), list(s.target_classes)
        )
        if s.no_laser:
            node.log.warning(NO_LASER_WARNING)
        threading.Thread(
            target=_check_targets, args=(node, config, stop), name="check-targets", daemon=True
        ).start()
        node.ready()
        period = 1.0 / s.control_rate_hz
        last_state: ControllerState | None = None
        # Detections that go stale between one and the next flip the state several times a
        # second: the first changes are logged, then a summary each period (the metrics
        # service's detections_late warning says why and what to change).
        state_log = LogLimiter()
        try:
            while not stop.is_set():
                handlers.arrived.clear()  # before reading, so a message arriving now wakes us
                with out.lock:  # an engage's zero waits for this command, never the reverse
                    # One instant per tick: the ages are judged at it and the command is
                    # stamped with it, so that a reader of cmd_vel can check the judgement.
                    at = now()
                    tick = at.mono_ns / 1e9
                    sc, sc_arrival = scan.get()
                    views = {
                        c: _view(d, at, s.detection_timeout_s) for c, d in handlers.dets.items()
                    }
                    sc_age = _age(sc.header if sc is not None else None, sc_arrival, at)
                    inputs = Inputs(views, sc, sc_age, latch.engaged)
                    cmd = controller.step(inputs, tick)
                    if cmd.state == ControllerState.ESTOP:
                        cmd = dataclasses.replace(cmd, reason=latch.describe())
                    out.send(cmd, at, estop_saved=latch.saved)
                if cmd.state != last_state:
                    log_state(node.log, state_log, cmd)
                    last_state = cmd.state
                for line in state_log.due():
                    node.log.info("%s", line)
                node.publish_counters()
                wait_either(handlers.arrived, stop, period - (mono_s() - tick))
            # Leave the robot still: the last word on cmd_vel is always a stop.
            stopped = VelocityCommand(0.0, 0.0, ControllerState.STOPPED, "shutdown")
            out.send(stopped, now(), estop_saved=latch.saved)
        finally:
            for sub in subs:
                sub.undeclare()
    return 0


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
