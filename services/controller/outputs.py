"""The controller's outputs: cmd_vel and its status, sent from the control loop and, on an
e-stop engage, from the e-stop handler's thread."""

from __future__ import annotations

import threading

from common.bus import QoS
from common.clock import Stamp
from common.contracts import ControllerState
from common.messages import ControllerStatus, Twist
from common.node import Node
from services.controller import contract
from services.controller.policy import VelocityCommand
from stack.config import Config


class Outputs:
    """The controller's cmd_vel and status on ``node``. ``lock`` is held by the loop from
    reading its inputs to publishing its command: a command computed before an engage latched
    goes out before the engage's zero, never after it."""

    def __init__(self, node: Node, config: Config) -> None:
        self.node = node
        self.mode = config.controller.mode
        self.no_laser = config.controller.no_laser
        self.target_classes = tuple(config.controller.target_classes)
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
                target_classes=self.target_classes,
            )
            self.status_pub.put(status.encode())

    def halt(self) -> None:
        """Zero on cmd_vel now (the status follows once the stop is saved)."""
        with self.lock:
            self._twist(VelocityCommand(0.0, 0.0, ControllerState.ESTOP, ""), self.node.clock.now())
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
