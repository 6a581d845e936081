"""A detector worker in the test's process: its node on a MemoryHub, with a fake clock, its
handlers and its pool membership (services/detector/membership.py), driven by the test: one
:meth:`Worker.loop_pass` is what the detection loop does between rounds."""

from __future__ import annotations

from dataclasses import replace

from common.clock import FakeClock
from common.memory_bus import MemoryBus, MemoryHub
from common.node import Node
from services.detector.handlers import DetectorHandlers
from services.detector.membership import PoolMember
from stack.config import Config


def cameras_config(names: tuple[str, ...], **detector: object) -> Config:
    """A config with cameras ``names`` (the first the [camera] table), each its own frame id,
    and ``detector`` settings changed as given."""
    base = Config()
    first, *others = names
    return replace(
        base,
        stack=replace(base.stack, camera=first),
        camera=replace(base.camera, frame_id=first),
        cameras=tuple((name, replace(base.camera, frame_id=name)) for name in others),
        detector=replace(base.detector, **detector),
    )


class Worker:
    """One pool worker: its own participant on ``hub`` (closing it is the process dying)."""

    def __init__(self, hub: MemoryHub, clock: FakeClock, config: Config, name: str) -> None:
        self.name = name
        self.bus: MemoryBus = hub.join(name)
        self.node = Node(name, config, bus=self.bus, clock=clock)
        self.handlers = DetectorHandlers(config, self.node, clock)
        self.pool = PoolMember(self.node, name, self.handlers)

    def loop_pass(self) -> frozenset[str]:
        """What the detection loop does on each pass (beat, settle, audit); what it serves."""
        self.pool.beat()
        self.pool.settle()
        self.pool.audit()
        return self.handlers.serving

    def count(self, name: str) -> int:
        return self.node.counters.get(name)
