"""What may reach the robot's base: the last check before the wheels. Pure: messages and the
instant in, what to send out.

The robot is sent a command only when it is

- **from the controller**: its header's ``source`` is ``controller`` (anybody may put on the
  key in the default profile, and the header says who they claim to be; under the secure
  profile only the controller may put there at all);
- **fresh**: stamped within ``window_s`` (the controller's dead-man,
  ``controller.detection_timeout_s``) and not ahead of the clock by more than the tolerance,
  on every clock both ends share (common/freshness.py);
- **in order**: newer than the last one accepted from the controller (older or equal is a
  replay; common/freshness.py orders by the monotonic stamp on one boot, else the wall stamp);

and it goes out as **zero** instead when it is beyond the speed bounds, while the controller's
newest fresh status says the e-stop is engaged, or when no fresh status has come (the
controller is silent, or has not spoken yet). A refused command is not sent at all.

And the gate stops the robot on its own: whenever the command in force is not zero and it
has aged past the window (nothing fresh from the controller since), or the controller's
status says the e-stop is engaged, or its status has aged past the window, one zero is sent.
Once: a ROS 2 base stops by itself on its own cmd_vel timeout, and a stream of zeros would
hold a command multiplexer (twist_mux) on this input when the stack is gone.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from common.clock import Stamp
from common.contracts import ControllerState
from common.freshness import FreshnessGate, Verdict, capture_age_s
from common.messages import ControllerStatus, Header, Twist

#: The header source of the controller's commands and status (its service name).
CONTROLLER = "controller"
#: The frame of a velocity command: the robot's base.
BASE_FRAME = "base_link"


@dataclass(frozen=True, slots=True)
class Outcome:
    """What the gate made of a message or a tick: ``send`` (None: nothing goes out), and
    ``counter`` with ``why`` when something was refused or replaced by zero ("" when not)."""

    send: Twist | None = None
    counter: str = ""
    why: str = ""


def _zeroed(twist: Twist) -> Twist:
    return replace(twist, linear=(0.0,) * 3, angular=(0.0,) * 3)


def in_range(twist: Twist, max_linear: float, max_angular: float) -> bool:
    """Whether every component of ``twist`` is within the bounds (m/s, rad/s)."""
    return all(abs(v) <= max_linear for v in twist.linear) and all(
        abs(w) <= max_angular for w in twist.angular
    )


class CommandGate:
    """The commands for the robot, judged one by one (see the module's docstring).

    ``source`` names the gate's own stops; ``boot_id`` this host's boot (monotonic stamps
    compare only within it). Not thread-safe: the caller holds one lock around it.
    """

    def __init__(
        self,
        *,
        window_s: float,
        tolerance_s: float,
        boot_id: str,
        max_linear: float,
        max_angular: float,
        source: str,
    ) -> None:
        self.window_s = window_s
        self.boot_id = boot_id
        self.max_linear = max_linear
        self.max_angular = max_angular
        self.source = source
        self._commands = FreshnessGate(window_s, tolerance_s, boot_id)
        self._statuses = FreshnessGate(window_s, tolerance_s, boot_id)
        self._status: ControllerStatus | None = None  # the newest fresh one
        self._moving: Header | None = None  # the command in force, when it is not zero
        self._seq = 0

    def on_command(self, twist: Twist, now: Stamp) -> Outcome:
        """A Twist from the stack's cmd_vel key."""
        if twist.header.source != CONTROLLER:
            return Outcome(None, "commands_not_controller",
                           f"cmd_vel from {twist.header.source!r}, not the controller")  # fmt: skip
        verdict, age = self._commands.check(twist.header, now)
        if verdict is not Verdict.FRESH:
            return Outcome(None, f"commands_{verdict}", f"{verdict} cmd_vel ({age:.2f} s)")
        if not in_range(twist, self.max_linear, self.max_angular):
            # When in doubt, zero: the robot gets a stop, never the absurd command.
            why = f"cmd_vel {twist.linear} {twist.angular} is beyond ros2.max_command_*"
            return self._send(_zeroed(twist), "commands_out_of_range", why)
        held = self._holding(now)
        if held and not twist.is_zero:
            return self._send(_zeroed(twist), f"commands_{held[0]}", held[1])
        return self._send(twist)

    def on_status(self, status: ControllerStatus, now: Stamp) -> Outcome:
        """A ControllerStatus: a fresh, newer one from the controller is believed. When it
        says the e-stop is engaged and the robot was moving, the robot is sent zero now."""
        if status.header.source != CONTROLLER:
            return Outcome(None, "status_not_controller",
                           f"controller status from {status.header.source!r}")  # fmt: skip
        verdict, age = self._statuses.check(status.header, now)
        if verdict is not Verdict.FRESH:
            return Outcome(None, f"status_{verdict}", f"{verdict} controller status ({age:.2f} s)")
        self._status = status
        return self.on_tick(now)

    def on_tick(self, now: Stamp) -> Outcome:
        """Called often (each control period): zero, once, when the command in force must no
        longer hold."""
        if self._moving is None:
            return Outcome()
        age = capture_age_s(self._moving, now, self.boot_id)
        if age > self.window_s:
            why = f"nothing fresh from the controller for {age:.2f} s: the robot is sent zero"
            return self._send(self._stop(now), "stops_silent", why)
        held = self._holding(now)
        if held:
            return self._send(self._stop(now), f"stops_{held[0]}", held[1])
        return Outcome()

    def on_close(self, now: Stamp) -> Outcome:
        """The bridge is going: zero, if the robot was moving (the controller's own last
        zero may not come through it)."""
        if self._moving is None:
            return Outcome()
        return self._send(
            self._stop(now), "stops_shutdown", "shutting down: the robot is sent zero"
        )

    def _holding(self, now: Stamp) -> tuple[str, str] | None:
        """Why the robot must be held still whatever the command says, if it must."""
        status = self._status
        if status is None:
            return "no_status", "no status from the controller yet: the robot is sent zero"
        age = capture_age_s(status.header, now, self.boot_id)
        if age > self.window_s:
            return "no_status", f"no controller status for {age:.2f} s: the robot is sent zero"
        if status.state == ControllerState.ESTOP:
            return "estop", "the controller reports the e-stop engaged: the robot is sent zero"
        return None

    def _stop(self, now: Stamp) -> Twist:
        self._seq += 1
        header = Header(stamp_ns=now.wall_ns, frame_id=BASE_FRAME, seq=self._seq,
                        source=self.source, mono_ns=now.mono_ns, boot_id=self.boot_id)  # fmt: skip
        return Twist(header=header)

    def _send(self, twist: Twist, counter: str = "", why: str = "") -> Outcome:
        self._moving = None if twist.is_zero else twist.header
        return Outcome(twist, counter, why)
