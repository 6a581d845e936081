"""The controller's loop in-process: a ControlLoop on a MemoryHub with a FakeClock, and a test
participant on the same hub that puts the inputs and hears cmd_vel and the status. The clock
moves only when told, and a put, a tick, an announcement return once what they put has been
delivered (in the putting thread, or with ``threads`` on the hub's own, shuffled, then waited
for with ``hub.drain()``): the command is on the list.
With depth needed (``needs_depth``), the depth scan stage runs beside it on the same hub and
clock (``stage``, services/depthscan/service.py): ``stage.intake.handle_waiting`` makes the
scans of the images put, as its thread would, and each tick publishes its memory first (the
live stage puts it every 0.1 s).
Each camera of the config is announced (as its source would: common/announce.py) on a
participant of its own, from before the controller starts; ``announce`` and ``withdraw`` change
that at run time.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from common.boxes import Boxes
from common.bus import QoS
from common.clock import BOOT_ID, FakeClock
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import ControllerStatus, Detections, EStop, Header, LaserScan, Twist
from common.node import Node
from services.camera.contract import CameraSettings
from services.controller.contract import ControllerSettings
from services.controller.service import ControlLoop
from services.depthscan.intake import DepthIntake
from services.depthscan.service import DepthScanStage
from stack.config import Config, SupervisorSettings
from tests.unit.announced import Sources
from tests.unit.conftest import MEMORY_BUS_SEED

W, H = 640, 480


class Rig:
    """One controller (``loop``) and the test's participant (``probe``) on one hub."""

    def __init__(
        self,
        tmp_path: Path,
        cameras: dict[str, CameraSettings] | None = None,
        clock: FakeClock | None = None,
        *,
        announced: bool = True,
        threads: int = 0,
        **controller: Any,
    ) -> None:
        settings = {"mode": "track", "no_laser": False, **controller}
        s = ControllerSettings(
            estop_file=str(tmp_path / "estop.json"),
            depth_memory_file=str(tmp_path / "depth-memory.npz"),
            **settings,
        )
        runs = ("depthscan", "controller") if s.needs_depth else ("controller",)
        self.config = Config(
            controller=s,
            cameras=tuple((cameras or {}).items()),
            supervisor=SupervisorSettings(services=runs),
        )
        self.clock = clock or FakeClock()
        self.hub = MemoryHub(threads=threads, seed=MEMORY_BUS_SEED)
        self.keys = Keys(self.config.stack.prefix)
        self.sources = Sources(self.hub, self.keys)
        if announced:
            for name, camera in self.config.all_cameras.items():
                self.announce(name, camera)
        self.node = Node(
            "controller",
            self.config,
            counters_period_s=self.config.controller.counters_period_s,
            bus=self.hub.join("controller"),
            clock=self.clock,
        )
        self.stage: DepthScanStage | None = None
        self.stage_node: Node | None = None
        if self.config.controller.needs_depth:
            self.stage_node = Node(
                "depthscan", self.config, bus=self.hub.join("depthscan"), clock=self.clock
            )
            self.stage = DepthScanStage(self.config, self.stage_node)
        self.loop = ControlLoop(self.config, self.node)
        self.probe = self.hub.join("test")
        self.cmds: list[Twist] = []
        self.statuses: list[ControllerStatus] = []
        self.probe.subscribe(
            self.keys.cmd_vel(), lambda s: self.cmds.append(Twist.decode(s.payload))
        )
        self.probe.subscribe(
            self.keys.controller_status(),
            lambda s: self.statuses.append(ControllerStatus.decode(s.payload)),
        )
        self._seq = 0
        self.drain()

    def drain(self) -> None:
        """Return once what was put so far has been handled (a no-op unless ``threads``)."""
        self.hub.drain()

    def announce(self, name: str, camera: CameraSettings | None = None, **fields: Any) -> None:
        """Announce camera ``name`` as a source would (``camera``'s geometry, then ``fields``),
        or announce it anew (a new token before the old one goes)."""
        self.sources.announce(name, camera, **fields)
        self.drain()

    def withdraw(self, name: str) -> None:
        """Camera ``name``'s source is gone: its session closes, its announcement with it."""
        self.sources.withdraw(name)
        self.drain()

    @property
    def counters(self) -> dict[str, int]:
        return self.node.counters.snapshot()

    @property
    def stage_counters(self) -> dict[str, int]:
        assert self.stage_node is not None
        return self.stage_node.counters.snapshot()

    @property
    def intake(self) -> DepthIntake:
        """The depth scan stage's intake (depth needed only)."""
        assert self.stage is not None
        return self.stage.intake

    def handle_depth(self) -> int:
        """The stage makes the scans of the images waiting, as its thread would; what it put
        delivered."""
        n = self.intake.handle_waiting(0.0)
        self.drain()
        return n

    def publish_memory(self) -> None:
        """The stage puts its memory, as its thread does every 0.1 s."""
        if self.stage is not None:
            self.stage.put_memory(*self.stage.intake.memory(self.clock.now()))
            self.drain()

    def put(self, key: str, payload: bytes) -> None:
        self.probe.publisher(key, QoS.SENSOR).put(payload)
        self.drain()

    def header(self, age_s: float = 0.0, source: str = "detector", ahead_s: float = 0.0) -> Header:
        """Stamped ``age_s`` ago (or ``ahead_s`` ahead) on both clocks of the fake clock."""
        self._seq += 1
        at = self.clock.now()
        shift = round((ahead_s - age_s) * 1e9)
        return Header(
            stamp_ns=at.wall_ns + shift, frame_id="camera", seq=self._seq, source=source,
            mono_ns=at.mono_ns + shift, boot_id=BOOT_ID,
        )  # fmt: skip

    def detections(self, camera: str = "front", payload: bytes | None = None, **kw: Any) -> None:
        """``payload`` (default: one centred person, stamped now) on ``camera``'s key."""
        self.put(self.keys.detections(camera), payload or people(self.header(**kw), cx=W / 2))

    def scan(self, ahead_m: float = math.inf, age_s: float = 0.0) -> None:
        self.put(self.keys.scan(), obstacle_ahead(self.header(age_s, source="laser"), ahead_m))

    def estop(self, engaged: bool, age_s: float = 0.0, ahead_s: float = 0.0) -> None:
        header = self.header(age_s, source="estop", ahead_s=ahead_s)
        msg = EStop(header=header, engaged=engaged, reason="test")
        self.put(self.keys.estop(), msg.encode())

    def tick(self, stage_alive: bool = True) -> tuple[Twist, ControllerStatus]:
        """One control tick (the stage's memory put first while ``stage_alive``); the command
        and the status it sent."""
        before = len(self.cmds)
        if stage_alive:
            self.publish_memory()
        self.loop.tick()
        self.drain()
        assert len(self.cmds) == before + 1, "a tick sends exactly one command"
        return self.cmds[-1], self.statuses[-1]

    def close(self) -> None:
        self.loop.close()
        if self.stage is not None and self.stage_node is not None:
            self.stage.close()
            self.stage_node.close()
        self.sources.close()
        self.probe.close()
        self.node.close()
        self.hub.close()


def people(header: Header, cx: float = W / 2, n: int = 1, h: float = 200.0) -> bytes:
    """``n`` people (0: nobody) whose boxes are centred at column ``cx``, ``h`` pixels tall."""
    box = [cx - 30, 240 - h / 2, cx + 30, 240 + h / 2]
    return Detections(
        header=header, image_width=W, image_height=H, class_names=("person",) * n,
        boxes=Boxes(
            xyxy=np.tile(np.array([box], np.float32), (n, 1)),
            scores=np.full(n, 0.9, np.float32),
            class_ids=np.zeros(n, np.int32),
        ),
    ).encode()  # fmt: skip


def obstacle_ahead(header: Header, distance_m: float = math.inf) -> bytes:
    """A 270 deg scan that sees a wall ``distance_m`` straight ahead (+-10 deg) and nothing
    else within range (inf: all clear)."""
    angles = np.linspace(-math.radians(135), math.radians(135), 541)
    ranges = np.full(541, np.inf, np.float32)
    ranges[np.abs(angles) <= math.radians(10)] = distance_m
    return LaserScan(
        header=header, angle_min=float(angles[0]), angle_increment=float(angles[1] - angles[0]),
        range_min=0.05, range_max=12.0, ranges=ranges,
    ).encode()  # fmt: skip
