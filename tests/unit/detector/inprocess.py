"""A detector worker in the test's process: its node on a MemoryHub, with a fake clock, its
handlers and its pool membership (services/detector/membership.py), driven by the test: one
:meth:`Worker.loop_pass` is what the detection loop does between rounds. The cameras a pool
serves are those announced on the bus: :class:`CameraSource` announces them, as a camera
process does."""

from __future__ import annotations

import threading
from dataclasses import replace
from functools import partial

from common.announce import Announcer
from common.clock import FakeClock
from common.keys import Keys
from common.memory_bus import MemoryBus, MemoryHub
from common.messages import CameraAnnouncement
from common.node import Node
from services.detector.capacity import Capacity
from services.detector.handlers import DetectorHandlers
from services.detector.membership import PoolMember
from stack.config import Config


def cameras_config(names: tuple[str, ...], **detector: object) -> Config:
    """A config with cameras ``names`` (the first the [camera] table), each its own frame id,
    and ``detector`` settings changed as given. Delivery (common/pool_delivery.py) is judged
    only where a test sets ``pool_deliver_s``: these tests put no detections on the bus."""
    detector.setdefault("pool_deliver_s", 600.0)
    base = Config()
    first, *others = names
    return replace(
        base,
        stack=replace(base.stack, camera=first),
        camera=replace(base.camera, frame_id=first),
        cameras=tuple((name, replace(base.camera, frame_id=name)) for name in others),
        detector=replace(base.detector, **detector),
    )


class CameraSource:
    """A camera source's participant on ``hub`` that announces cameras under ``prefix``, as a
    camera process, the simulator or the ROS 2 bridge does (one Announcer per camera)."""

    def __init__(self, hub: MemoryHub, prefix: str = "stack", name: str = "camera") -> None:
        self.bus = hub.join(f"{name}_{prefix.replace('/', '_')}")
        self.keys = Keys(prefix)
        self.announcers: dict[str, Announcer[CameraAnnouncement]] = {}

    def announce(self, camera: str, rate_hz: float = 5.0, *, depth: bool = False) -> None:
        """Announce ``camera`` (again); ``depth``: it has depth images too."""
        if camera not in self.announcers:
            key_of = partial(self.keys.camera_announcement, camera)
            self.announcers[camera] = Announcer(self.bus, key_of)
        about = CameraAnnouncement(camera=camera, rate_hz=rate_hz, depth=depth)
        self.announcers[camera].update(about)

    def withdraw(self, camera: str) -> None:
        self.announcers.pop(camera).close()


class Worker:
    """One pool worker: its own participant on ``hub`` (closing it is the process dying);
    ``capacity_hz``: what it announces (0: the default, 1)."""

    def __init__(
        self, hub: MemoryHub, clock: FakeClock, config: Config, name: str, capacity_hz: float = 0
    ) -> None:
        self.name = name
        self.hub = hub
        self.stop = threading.Event()  # the process's stop event (common/lifecycle.py)
        self.bus: MemoryBus = hub.join(name)
        self.node = Node(name, config, bus=self.bus, clock=clock)
        self.handlers = DetectorHandlers(config, self.node, clock, frame_keys={})
        capacity = Capacity(capacity_hz or 1.0, config.detector, clock.mono_s())
        self.pool = PoolMember(
            self.node, name, self.handlers, capacity=capacity, stopping=self.stop.is_set
        )

    def loop_pass(self) -> frozenset[str]:
        """What the detection loop does on each pass (beat, settle, audit), once what was put
        before has been delivered; what it serves once what the pass put has been too."""
        self.hub.drain()
        self.pool.beat()
        self.pool.settle()
        self.pool.audit()
        self.hub.drain()
        return self.handlers.serving

    def count(self, name: str) -> int:
        return self.node.counters.get(name)
