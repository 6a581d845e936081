"""Stand-ins for the detector and the laser in real-process tests of the controller: the
test's own session publishes detections and scans (stamped as they go) from a thread of its
own, while the test reads cmd_vel, the status and the log."""

from __future__ import annotations

import math
import threading
from collections.abc import Callable

import numpy as np

from common.clock import BOOT_ID, now
from common.messages import Header, LaserScan
from tests.integration.conftest import Stack
from tests.integration.test_safety import person

PERIOD_S = 0.05  # how often the test publishes, as a 20 Hz detector and laser would


def header(age_s: float = 0.0) -> Header:
    """Stamped ``age_s`` ago on both clocks, as the detector passes a frame's on."""
    at = now()
    ago = int(age_s * 1e9)
    return Header(
        stamp_ns=at.wall_ns - ago, frame_id="camera", seq=1, source="detector",
        mono_ns=at.mono_ns - ago, boot_id=BOOT_ID,
    )  # fmt: skip


def people(n: int, age_s: float = 0.0) -> bytes:
    """``n`` people (0: nobody) centred in a 640x480 image."""
    return person(header(age_s), n).encode()


def all_clear() -> bytes:
    """A 270 deg scan that sees nothing within range (the simulator's laser has no ray behind)."""
    return LaserScan(
        header=header(), angle_min=-math.radians(135), angle_increment=math.radians(270) / 540,
        range_min=0.05, range_max=12.0, ranges=np.full(541, np.inf, np.float32),
    ).encode()  # fmt: skip


class Feeder:
    """Publishes what ``make`` returns (key -> payload) every PERIOD_S on a thread of its
    own, until switched to another ``make`` or to nothing."""

    def __init__(self, stack: Stack) -> None:
        self.stack = stack
        self.pubs: dict[str, object] = {}
        self.make: Callable[[], dict[str, bytes]] | None = None
        self.last_put_ns = 0  # no capture stamp of the last round put is older (wall ns)
        self.done = threading.Event()
        self.lock = threading.Lock()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def feed(self, make: Callable[[], dict[str, bytes]] | None) -> None:
        with self.lock:
            self.make = make

    def _run(self) -> None:
        while not self.done.wait(PERIOD_S):
            with self.lock:
                if self.make is None:
                    continue
                before = now().wall_ns  # no capture stamp in this round is older
                for key, payload in self.make().items():
                    if key not in self.pubs:
                        self.pubs[key] = self.stack.session.declare_publisher(key)
                    self.pubs[key].put(payload)  # type: ignore[attr-defined]
                self.last_put_ns = before

    def close(self) -> None:
        self.done.set()
        self.thread.join(5)
