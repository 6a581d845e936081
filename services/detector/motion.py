"""How each robot the worker serves turned between two frames, for the tracker's ego-rotation
(perception/kalman_tracker.py): the robot's own commands on its ``cmd_vel``, integrated
(common/odometry.py), as the depth scan stage's memory is moved.

A command is timed by its arrival on this host's monotonic clock; a frame from this host is
tracked on its monotonic capture stamp (perception/tracker.py ``tracker_clock``), so the two
agree up to the command's delivery (a few milliseconds). A frame from another host carries only
its wall clock: no turn is taken out of its tracks (0), as before.
"""

from __future__ import annotations

import threading

from common.bus import Declared
from common.errors import DecodeError
from common.keys import Keys
from common.messages import Twist
from common.node import Node
from common.odometry import Odometry
from stack.config import Config

#: Commands kept per robot (s): a frame tracked up to this late is still placed.
HISTORY_S = 10.0


class RobotTurns:
    """Each served robot's odometry by its commands (thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._robots: dict[str, Odometry] = {}

    def command(self, prefix: str, at: float, twist: Twist) -> None:
        """Robot ``prefix`` was commanded ``twist`` at monotonic ``at`` (s)."""
        with self._lock:
            odo = self._robots.setdefault(prefix, Odometry(HISTORY_S))
        odo.command(at, float(twist.linear[0]), float(twist.angular[2]))

    def turned(self, prefix: str, t0: float, t1: float) -> float:
        """How far robot ``prefix`` turned (rad, left positive) from monotonic ``t0`` to
        ``t1`` by its commands; 0 with none heard."""
        with self._lock:
            odo = self._robots.get(prefix)
        if odo is None or t1 <= t0:
            return 0.0
        return odo.pose_at(t1)[2] - odo.pose_at(t0)[2]


def heed_commands(node: Node, config: Config, turns: RobotTurns) -> list[Declared]:
    """Feed ``turns`` with the commands of every robot the worker serves
    (``detector.prefixes``; empty: its own robot's). A command that does not decode is bad
    input (logged, counted, dropped)."""
    s = config.detector
    out = []
    for prefix in s.prefixes or (config.stack.prefix,):
        key = Keys(prefix).cmd_vel()

        def on_command(payload: bytes, prefix: str = prefix, key: str = key) -> None:
            try:
                twist = Twist.decode(payload)
            except (DecodeError, ValueError) as exc:
                node.bad_input(key, exc)
                return
            turns.command(prefix, node.clock.mono_s(), twist)

        out.append(node.subscribe(key, on_command))
    return out
