"""The controller service: latest detections and scan in, Twist and ControllerStatus out."""

from __future__ import annotations

import threading
import time
from typing import Generic, TypeVar

import zenoh

from common.bus import open_session
from common.errors import DecodeError, StackError
from common.keys import Keys
from common.messages import ControllerStatus, Detections, EStop, Header, LaserScan, Twist, now_ns
from common.node import Node
from common.settings import Config
from services.controller.policy import Command, Controller, Inputs

_M = TypeVar("_M")


class Latest(Generic[_M]):
    """The newest decoded message of one key and when it arrived (monotonic seconds)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._msg: _M | None = None
        self._t = 0.0
        self.arrived = threading.Event()  # set on every new message; the loop clears it

    def set(self, msg: _M) -> None:
        with self._lock:
            self._msg, self._t = msg, time.monotonic()
        self.arrived.set()

    def get(self) -> tuple[_M | None, float]:
        """The message and its age in seconds (inf when none has arrived)."""
        with self._lock:
            if self._msg is None:
                return None, float("inf")
            return self._msg, time.monotonic() - self._t


def run(config: Config, stop: threading.Event) -> int:
    """Run the control loop until ``stop`` is set.

    A command goes out at least ``control_rate_hz`` times a second, and at once when new
    detections arrive: waiting for the next tick would add up to a whole period of latency.
    """
    s = config.controller
    with Node("controller", config, counters_period_s=s.counters_period_s) as node:
        dets: Latest[Detections] = Latest()
        scan: Latest[LaserScan] = Latest()
        det_key = node.keys.detections(config.stack.camera)

        def on_detections(sample: zenoh.Sample) -> None:
            try:
                dets.set(Detections.decode(sample.payload.to_bytes()))
                node.counters.add("detections_in")
            except DecodeError as exc:
                node.bad_input(det_key, exc)

        estop = threading.Event()  # latched: only an explicit release clears it

        def on_estop(sample: zenoh.Sample) -> None:
            try:
                msg = EStop.decode(sample.payload.to_bytes())
            except DecodeError as exc:
                # Garbage on the e-stop key is treated as a press: fail safe, not open.
                node.bad_input(node.keys.estop(), exc)
                estop.set()
                return
            if msg.engaged:
                estop.set()
            else:
                estop.clear()
            node.log.warning(
                "e-stop %s by %s: %s",
                "ENGAGED" if msg.engaged else "released",
                msg.header.source,
                msg.reason or "-",
            )

        def on_scan(sample: zenoh.Sample) -> None:
            try:
                scan.set(LaserScan.decode(sample.payload.to_bytes()))
                node.counters.add("scans_in")
            except DecodeError as exc:
                node.bad_input(node.keys.scan(), exc)

        subs = [
            node.session.declare_subscriber(det_key, on_detections),
            node.session.declare_subscriber(node.keys.scan(), on_scan),
            node.session.declare_subscriber(node.keys.estop(), on_estop),
        ]
        controller = Controller(s, config.camera.hfov_deg)
        cmd_pub = node.session.declare_publisher(node.keys.cmd_vel())
        status_pub = node.session.declare_publisher(node.keys.controller_status())
        node.log.info("mode %s on %s, targets %s", s.mode, det_key, list(s.target_classes))
        node.ready()
        period = 1.0 / s.control_rate_hz
        last_state = ""
        try:
            while not stop.is_set():
                tick = time.monotonic()
                dets.arrived.clear()  # before reading, so a message arriving now wakes us
                d, d_age = dets.get()
                sc, sc_age = scan.get()
                captured = (time.time_ns() - d.header.stamp_ns) / 1e9 if d is not None else 0.0
                inputs = Inputs(d, d_age, sc, sc_age, estop.is_set(), max(0.0, captured))
                cmd = controller.step(inputs, tick)
                _publish(node, cmd_pub, status_pub, cmd, s.mode)
                if cmd.state != last_state:
                    node.log.info("state %s: %s", cmd.state, cmd.reason)
                    last_state = cmd.state
                node.publish_counters()
                dets.arrived.wait(max(0.0, period - (time.monotonic() - tick)))
            # Leave the robot still: the last word on cmd_vel is always a stop.
            _publish(node, cmd_pub, status_pub, Command(0.0, 0.0, "stopped", "shutdown"), s.mode)
        finally:
            for sub in subs:
                sub.undeclare()
    return 0


def _publish(
    node: Node, cmd_pub: zenoh.Publisher, status_pub: zenoh.Publisher, cmd: Command, mode: str
) -> None:
    twist = Twist(
        header=node.header(frame_id="base_link"),
        linear=(cmd.linear_x, 0.0, 0.0),
        angular=(0.0, 0.0, cmd.angular_z),
        input_stamp_ns=cmd.input_stamp_ns,
    )
    cmd_pub.put(twist.encode())
    node.counters.add("commands_out")
    if not cmd.is_zero:
        node.counters.add("commands_nonzero")
    status = ControllerStatus(
        header=twist.header,
        mode=mode,
        target=cmd.target,
        state=cmd.state,
        reason=cmd.reason,
        track_id=cmd.track_id,
    )
    status_pub.put(status.encode())


def send_estop(config: Config, engaged: bool, reason: str) -> int:
    """Publish one EStop and wait until the controller has seen it (its status says so)."""
    keys = Keys(config.stack.prefix)
    session = open_session(config.zenoh)
    seen = threading.Event()

    def on_status(sample: zenoh.Sample) -> None:
        try:
            state = ControllerStatus.decode(sample.payload.to_bytes()).state
        except DecodeError:
            return
        if (state == "estop") == engaged:
            seen.set()

    sub = session.declare_subscriber(keys.controller_status(), on_status)
    pub = session.declare_publisher(keys.estop())
    header = Header(stamp_ns=now_ns(), frame_id="", seq=1, source="estop-cli")
    try:
        # Repeat until acknowledged: the first put may race the peer mesh being formed.
        for _ in range(50):
            pub.put(EStop(header=header, engaged=engaged, reason=reason).encode())
            if seen.wait(0.2):
                print("e-stop engaged" if engaged else "e-stop released")
                return 0
        raise StackError("no controller acknowledged the e-stop within 10 s")
    finally:
        sub.undeclare()
        session.close()
