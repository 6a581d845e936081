"""What the controller does with each input as it arrives (:class:`ControllerHandlers`):
detections and scans judged and the newest fresh one held for the control loop
(:class:`Latest`), an e-stop latched or released, from the bus or from the local socket."""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from typing import Generic, Protocol, TypeVar

from common.clock import BOOT_ID, SYSTEM_CLOCK, Clock, Stamp
from common.counters import IN, LATE, input_counter, per_camera
from common.errors import DecodeError
from common.freshness import FreshnessGate, Verdict, capture_age_s, judge_age
from common.messages import CameraAnnouncement, Detections, EStop, Header, LaserScan
from common.node import Tally
from services.controller import contract
from services.controller.estop import EStopLatch
from services.controller.targets import View
from stack.config import Config

#: The source an engage handed over on the local socket is latched with (its status says it).
LOCAL_ESTOP_SOURCE = "estop-local"


class _Stamped(Protocol):
    @property
    def header(self) -> Header: ...


_S = TypeVar("_S", bound=_Stamped)


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


def age_of(msg: Header | None, arrival_age_s: float, at: Stamp) -> float:
    """How old an input is for the dead-man: the later of its capture and its arrival."""
    if msg is None:
        return float("inf")
    return max(arrival_age_s, capture_age_s(msg, at, BOOT_ID))


def take_fresh(
    tally: Tally,
    clock: Clock,
    msg: _S,
    gate: FreshnessGate,
    latest: Latest[_S],
    name: str,
    camera: str = "",
) -> None:
    """A decoded input's fate, the one path of every input the controller ages (detections,
    the laser's scan, the virtual scans and the depth memory): judge its freshness, keep it if
    fresh and newest, count the rest (``<name>_in``, ``<name>_stale|future|replay|late``; with
    ``camera``, also ``<counter>.<camera>``)."""
    verdict, age = gate.check(msg.header, clock.now())
    of = f" from {camera}" if camera else ""
    if verdict is not Verdict.FRESH:
        counter = input_counter(name, verdict)
        tally.reject(counter, f"{verdict} {name}{of} ({age:.2f} s) ignored")
    elif latest.set(msg):
        counter = input_counter(name, IN)
        tally.counters.add(counter)
    else:
        counter = input_counter(name, LATE)
        tally.reject(counter, f"{name}{of} older than the ones held ignored")
    if camera:
        tally.counters.add(per_camera(counter, camera))


def _view(latest: Latest[Detections], at: Stamp, timeout_s: float) -> View:
    """One camera's newest detections, aged at the control instant ``at``."""
    d, arrival = latest.get()
    if d is None:
        return View(None)
    capture = capture_age_s(d.header, at, BOOT_ID)
    return View(d, age_of(d.header, arrival, at), min(max(0.0, capture), timeout_s))


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
        take_fresh(self.tally, self.clock, msg, gate, latest, name, camera)

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
