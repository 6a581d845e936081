"""What the command gate lets through to the robot, on a fake clock."""

from __future__ import annotations

from common.clock import Stamp
from common.command_gate import CONTROLLER, CommandGate, Outcome
from common.contracts import ControllerState
from common.messages import ControllerStatus, Header, Twist

BOOT = "boot-a"
S = 10**9
T0 = 1_800_000_000 * S  # wall ns
M0 = 5_000 * S  # monotonic ns


def at(t_s: float) -> Stamp:
    return Stamp(T0 + int(t_s * S), M0 + int(t_s * S))


def header(t_s: float, source: str = CONTROLLER, *, boot: str = BOOT) -> Header:
    stamp = at(t_s)
    return Header(stamp_ns=stamp.wall_ns, frame_id="base_link", seq=1, source=source,
                  mono_ns=stamp.mono_ns if boot else 0, boot_id=boot)  # fmt: skip


def twist(t_s: float, v: float = 0.3, source: str = CONTROLLER, *, boot: str = BOOT) -> Twist:
    return Twist(header=header(t_s, source, boot=boot), linear=(v, 0.0, 0.0))


def status(t_s: float, state: str = ControllerState.TRACKING) -> ControllerStatus:
    return ControllerStatus(header=header(t_s), mode="track", target="person", state=state)


def gate() -> CommandGate:
    return CommandGate(window_s=1.0, tolerance_s=0.1, boot_id=BOOT, max_linear=5.0,
                       max_angular=10.0, source="ros2")  # fmt: skip


def moving(out: Outcome) -> bool:
    return out.send is not None and not out.send.is_zero


def zero(out: Outcome) -> bool:
    return out.send is not None and out.send.is_zero


def test_fresh_ordered_controller_commands_go_out_as_they_are() -> None:
    g = gate()
    g.on_status(status(0.0), at(0.0))
    for i in range(1, 4):
        out = g.on_command(twist(i * 0.05), at(i * 0.05 + 0.01))
        assert out.send == twist(i * 0.05) and not out.counter


def test_stale_future_replayed_and_foreign_commands_are_not_sent() -> None:
    g = gate()
    g.on_status(status(9.9), at(10.0))
    assert moving(g.on_command(twist(10.0), at(10.0)))
    unstamped = Twist(header=Header(stamp_ns=0, frame_id="", seq=0, source=CONTROLLER),
                      linear=(0.3, 0.0, 0.0))  # fmt: skip
    for sent, counter in (
        (twist(10.0 - 60), "commands_stale"),
        (twist(10.0 - 3600, boot=""), "commands_stale"),
        (twist(10.0 + 3600, boot=""), "commands_future"),
        (unstamped, "commands_stale"),
        (twist(9.5), "commands_replay"),  # within the window, but older than the one sent
        (twist(10.0), "commands_replay"),  # the same again
        (twist(10.01, source="teleop"), "commands_not_controller"),
    ):
        out = g.on_command(sent, at(10.02))
        assert out.send is None and out.counter == counter, (sent.header, out)


def test_zero_while_the_estop_is_engaged_or_there_is_no_fresh_status() -> None:
    g = gate()
    first = g.on_command(twist(0.0), at(0.0))  # no status yet
    assert zero(first) and first.counter == "commands_no_status"
    g.on_status(status(0.05, ControllerState.ESTOP), at(0.05))
    held = g.on_command(twist(0.1), at(0.1))
    assert zero(held) and held.counter == "commands_estop"
    own = g.on_command(twist(0.15, 0.0), at(0.15))  # the controller's own zero: not counted
    assert zero(own) and not own.counter
    g.on_status(status(0.2), at(0.2))  # released
    assert moving(g.on_command(twist(0.25), at(0.25)))
    # The status ages past the window: commands go out as zero.
    late = g.on_command(twist(1.3), at(1.3))
    assert zero(late) and late.counter == "commands_no_status"


def test_an_engaged_estop_status_stops_a_moving_robot_at_once() -> None:
    g = gate()
    g.on_status(status(0.0), at(0.0))
    assert moving(g.on_command(twist(0.05), at(0.05)))
    out = g.on_status(status(0.1, ControllerState.ESTOP), at(0.1))
    assert zero(out) and out.counter == "stops_estop"
    assert out.send is not None and out.send.header.source == "ros2"
    assert g.on_tick(at(0.2)) == Outcome()  # once: the robot is already stopped


def test_silence_stops_the_robot_once() -> None:
    g = gate()
    g.on_status(status(0.0), at(0.0))
    assert moving(g.on_command(twist(0.05), at(0.05)))
    assert g.on_tick(at(1.0)) == Outcome()  # 0.95 s old: still in force
    out = g.on_tick(at(1.1))
    assert zero(out) and out.counter == "stops_silent"
    assert out.send is not None and out.send.header.stamp_ns == at(1.1).wall_ns
    assert g.on_tick(at(1.2)) == Outcome() and g.on_tick(at(5.0)) == Outcome()


def test_closing_stops_a_moving_robot() -> None:
    g = gate()
    assert g.on_close(at(0.0)) == Outcome()  # still: nothing to say
    g.on_status(status(0.0), at(0.0))
    assert moving(g.on_command(twist(0.05), at(0.05)))
    out = g.on_close(at(0.1))
    assert zero(out) and out.counter == "stops_shutdown"


def test_a_command_beyond_the_bounds_goes_out_as_zero() -> None:
    g = gate()
    g.on_status(status(0.0), at(0.0))
    out = g.on_command(twist(0.05, 50.0), at(0.05))
    assert zero(out) and out.counter == "commands_out_of_range"


def test_statuses_are_judged_too() -> None:
    g = gate()
    g.on_status(status(0.0, ControllerState.ESTOP), at(0.0))
    # An older "tracking" status played back does not release the hold, nor a stale one.
    assert g.on_status(status(-0.5), at(0.05)).counter == "status_replay"
    assert g.on_status(status(-5.0), at(0.05)).counter == "status_stale"
    assert zero(g.on_command(twist(0.1), at(0.1)))
