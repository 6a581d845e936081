"""The controller service: every camera's latest detections and the scan (and, when its
settings need depth, the depth cameras' images) in, Twist and ControllerStatus out."""

from __future__ import annotations

import dataclasses
import json
import threading
from collections.abc import Callable, Mapping
from contextlib import ExitStack
from typing import TYPE_CHECKING, Generic, Protocol, TypeVar

from common.announce import Announced, announced_cameras
from common.bus import Declared, Publisher, QoS, Sample
from common.clock import BOOT_ID, SYSTEM_CLOCK, Clock, Stamp, mono_s
from common.contracts import ControllerState, DetectorInfo
from common.counters import per_camera
from common.errors import DecodeError
from common.estop_local import LocalEStop, socket_path
from common.freshness import FreshnessGate, Verdict, capture_age_s, judge_age
from common.keys import camera_in_key
from common.messages import CameraAnnouncement, Detections, EStop, Header, LaserScan
from common.node import Node, Tally
from common.ratelimit import LogLimiter
from services.controller import contract
from services.controller.estop import EStopLatch
from services.controller.outputs import Outputs
from services.controller.policy import Controller, Inputs, VelocityCommand
from services.controller.policy import stop as stop_command
from services.controller.statelog import log_state
from services.controller.targets import View, unknown_targets
from stack.config import Config

if TYPE_CHECKING:
    from services.controller.depth_intake import DepthIntake


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
#: The source an engage handed over on the local socket is latched with (its status says it).
LOCAL_ESTOP_SOURCE = "estop-local"


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

    def __init__(self, arrived: threading.Event | None = None, clock: Clock = SYSTEM_CLOCK) -> None:
        self._lock = threading.Lock()
        self._clock = clock
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
            self._msg, self._t = msg, self._clock.mono_s()
        self.arrived.set()
        return True

    def get(self) -> tuple[_S | None, float]:
        """The message and its age in seconds (inf when none has arrived)."""
        with self._lock:
            if self._msg is None:
                return None, float("inf")
            return self._msg, self._clock.mono_s() - self._t


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

    The cameras are those announced now (:meth:`set_cameras`, from the cameras' announcements
    on the bus; none until one is announced). Each has its own gate and its own newest
    detections (``dets``, by camera name): one camera's stamps never judge another's, and a
    stale camera is ignored while the others are used. Detections from a camera with no live
    announcement are ignored and counted (``detections_unannounced``); a withdrawn camera's
    held detections are dropped. Each camera's counts are kept beside the totals
    (``detections_in.rear``, ...).
    """

    def __init__(
        self,
        config: Config,
        tally: Tally,
        halt: Callable[[], None] | None = None,
        halted: Callable[[], None] | None = None,
        *,
        clock: Clock = SYSTEM_CLOCK,
    ) -> None:
        s = config.controller
        self.tally = tally
        self.clock = clock
        # An engage is acted on here, on the handler's thread, not at the loop's next tick:
        # ``halt`` (the zero command) once the latch holds in memory, before it is saved;
        # ``halted`` (the status, saying whether the stop could be saved) after.
        self.halt, self.halted = halt, halted
        self.tolerance_s = config.stack.clock_tolerance_s
        self.estop_release_max_age_s = s.estop_release_max_age_s
        self.latch = EStopLatch(config.estop_path, clock.wall_ns() + int(self.tolerance_s * 1e9))
        self.detection_timeout_s = s.detection_timeout_s
        # New detections from any camera, a camera's change, or an e-stop released: the loop ticks.
        self.arrived = threading.Event()
        # The cameras announced now and each one's newest detections, both by camera name in
        # the order they were announced; the cameras withdrawn since the loop last took them.
        self._cameras_lock = threading.Lock()
        self.cameras: dict[str, CameraAnnouncement] = {}
        self.dets: dict[str, Latest[Detections]] = {}
        self._withdrawn: set[str] = set()
        # A gate outlives its camera's withdrawal: a camera announced again still refuses a
        # replay of what it sent before.
        self._det_gates: dict[str, FreshnessGate] = {}
        self.scan: Latest[LaserScan] = Latest(clock=clock)
        self._scan_gate = FreshnessGate(s.scan_timeout_s, self.tolerance_s, BOOT_ID)

    def set_cameras(self, cameras: Mapping[str, CameraAnnouncement]) -> None:
        """The cameras announced now: a new one's detections are taken from now on, a
        withdrawn one's are dropped (and it is remembered for :meth:`take`)."""
        with self._cameras_lock:
            gone = [c for c in self.cameras if c not in cameras]
            for camera in gone:
                del self.dets[camera]
            self._withdrawn.update(gone)
            for camera in cameras:
                if camera not in self.dets:
                    self.dets[camera] = Latest(self.arrived, self.clock)
                    self._det_gates.setdefault(
                        camera,
                        FreshnessGate(self.detection_timeout_s, self.tolerance_s, BOOT_ID),
                    )
            self.cameras = dict(cameras)
        self.arrived.set()  # the loop looks at once: a withdrawn target's camera is a stop

    def take(self, at: Stamp) -> tuple[dict[str, CameraAnnouncement], set[str], dict[str, View]]:
        """At one moment: the cameras announced now, those withdrawn since the last call, and
        each announced camera's newest detections aged at the control instant ``at``."""
        with self._cameras_lock:
            withdrawn, self._withdrawn = self._withdrawn, set()
            views = {c: _view(d, at, self.detection_timeout_s) for c, d in self.dets.items()}
            return dict(self.cameras), withdrawn, views

    def on_detections(self, camera: str, payload: bytes) -> None:
        """Detections from ``camera``'s key: used only while ``camera`` is announced."""
        with self._cameras_lock:
            latest, gate = self.dets.get(camera), self._det_gates.get(camera)
        if latest is None or gate is None:
            self.tally.reject(
                contract.DETECTIONS_UNANNOUNCED,
                f"detections from {camera!r:.80}, a camera not announced, ignored",
            )
            return
        msg = self.tally.decode(self.tally.keys.detections(camera), Detections.decode, payload)
        if msg is not None:
            self._fresh_input(msg, gate, latest, contract.DETECTIONS, camera)

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
        verdict, age = gate.check(msg.header, self.clock.now())
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

    def on_local_engage(self, reason: str) -> None:
        """An engage handed over on this host (common/estop_local.py): as one on the bus,
        stamped now."""
        at = self.clock.now()
        self._engage(at.wall_ns, LOCAL_ESTOP_SOURCE, reason, at.wall_ns)

    def on_local_garbage(self, why: str) -> None:
        """Anything but an engage on the local socket: counted, and a press, as garbage on
        the e-stop key is (fail safe)."""
        self.tally.reject(contract.ESTOP_LOCAL_BAD, f"local e-stop socket: {why}")
        at = self.clock.now()
        self._engage(at.wall_ns, "garbage", "not an engage on the local e-stop socket", at.wall_ns)

    def on_local_failed(self, why: str) -> None:
        self.tally.log.warning(
            "the local e-stop socket failed (%s): zstack estop reaches this controller over "
            "Zenoh only from now", why,
        )  # fmt: skip

    def _engage(self, stamp_ns: int, by: str, reason: str, latest_ns: int) -> None:
        latch = self.latch
        was, was_saved = latch.engaged, latch.saved
        saved = latch.engage(stamp_ns, by, reason, latest_ns, self.halt)
        if self.halted is not None:
            self.halted()
        if not was:
            self.tally.log.warning("e-stop ENGAGED by %s: %s", by, reason or "-")
        if not saved and was_saved:
            self.tally.log.error("the e-stop is engaged but cannot be saved: %s", latch.describe())

    def on_estop(self, payload: bytes) -> None:
        """Latch on an engage or on garbage; release only on a fresh release newer than the
        stop that can be saved. A latch that cannot be saved holds in memory and says so
        loudly."""
        tally, latch = self.tally, self.latch
        at = self.clock.now()
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
            stamp = msg.header.stamp_ns if msg else at.wall_ns
            self._engage(stamp, by, reason, latest_ns)
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
            # The loop ticks at once: the release is acknowledged (its status) and acted on now,
            # not up to a control period later.
            self.arrived.set()
            tally.log.warning("e-stop released by %s: %s", msg.header.source, msg.reason or "-")


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
        # The depth cameras' images, only when depth is needed: the callback only leaves each
        # in its camera's slot, and the intake's own thread (``run``) turns it into a scan.
        self.depth: DepthIntake | None = None
        self.virtual_scans: VirtualScans | None = None
        if s.needs_depth:
            # Here, not at the top: perception loads OpenCV, which only a controller that
            # reads depth needs.
            from services.controller.depth_intake import DepthIntake

            self.virtual_scans = VirtualScans(node)
            self.depth = DepthIntake(
                s, node, config.stack.clock_tolerance_s, node.clock, config.depth_memory_path,
                on_scan=self.virtual_scans.put,
            )  # fmt: skip
            # The bus's own subscribe: the intake needs each sample's publisher (Sample.source).
            self._subs.append(node.bus.subscribe(keys.all_depths(), self._on_depth))
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

    def _on_detections(self, key: str, payload: bytes) -> None:
        camera = camera_in_key(key)
        if camera is None:  # unreachable: the subscription's keys all name a camera
            self.node.bad_input(key, DecodeError("not a camera's detections key"))
            return
        self.handlers.on_detections(camera, payload)

    def _on_depth(self, sample: Sample) -> None:
        camera = camera_in_key(sample.key)
        if camera is None or self.depth is None:  # unreachable: subscribed only with depth
            self.node.bad_input(sample.key, DecodeError("not a camera's depth key"))
            return
        self.depth.offer(camera, sample.payload, sample.source)

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
                self.depth.keep_watching(now)
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
        if self.depth is not None:
            self.depth.moved(at.mono_ns / 1e9, 0.0, 0.0)

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
            sc_age = _age(sc.header if sc is not None else None, sc_arrival, at)
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
                )
            cmd = self.controller.step(inputs, tick)
            if cmd.state == ControllerState.ESTOP:
                cmd = dataclasses.replace(cmd, reason=latch.describe())
            out.send(cmd, at, estop_saved=latch.saved)
            if self.depth is not None:  # the depth map moves as the robot is told to
                self.depth.moved(tick, cmd.linear_x, cmd.angular_z)
        if cmd.state != self._last_state:
            log_state(self.node.log, self._state_log, cmd)
            self._last_state = cmd.state
        for line in self._state_log.due():
            self.node.log.info("%s", line)
        self.node.publish_counters()
        return tick

    def stop(self) -> None:
        """Leave the robot still: the last word on cmd_vel is always a stop."""
        stopped = VelocityCommand(0.0, 0.0, ControllerState.STOPPED, "shutdown")
        self.out.send(stopped, self.clock.now(), estop_saved=self.latch.saved)

    def close(self) -> None:
        if self.announced is not None:
            self.announced.close()
        for sub in self._subs:
            sub.undeclare()
        if self.virtual_scans is not None:
            self.virtual_scans.close()


class VirtualScans:
    """Each depth camera's virtual scan as the depth intake makes it, published on the
    camera's own key (``<prefix>/scan/virtual/<camera>``: what the controller judged as
    obstacles, for the viewer and the recorder). A camera's publisher is declared with its
    first scan. Called on the intake's thread only."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self._pubs: dict[str, Publisher] = {}
        self._lock = threading.Lock()  # put (the intake's thread) against close

    def put(self, camera: str, scan: LaserScan) -> None:
        with self._lock:
            pub = self._pubs.get(camera)
            if pub is None:
                key = self.node.keys.virtual_scan(camera)
                pub = self._pubs[camera] = self.node.publisher(key, QoS.SENSOR)
            pub.put(scan.encode())

    def close(self) -> None:
        with self._lock:
            pubs, self._pubs = list(self._pubs.values()), {}
        for pub in pubs:
            pub.undeclare()


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
        if loop.depth is not None:
            threading.Thread(
                target=loop.depth.serve, args=(stop, STOP_POLL_S), name="depth-scan",
                daemon=True,
            ).start()  # fmt: skip
        node.ready()
        period = 1.0 / s.control_rate_hz
        while not stop.is_set():
            tick = loop.tick()
            wait_either(loop.handlers.arrived, stop, period - (node.clock.mono_s() - tick))
        loop.stop()  # the last word on cmd_vel: zero, before the loop and the node close
        if loop.depth is not None:
            loop.depth.save_memory(force=True)  # as the robot is left: still
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
