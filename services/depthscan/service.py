"""The depth scan stage: every announced depth camera's images in, its virtual scan out on
``<prefix>/scan/virtual/<camera>``, and what the depth cameras' memory holds round the robot on
``<prefix>/scan/remembered`` and ``<prefix>/scan/known`` (the controller's obstacles seen by
depth; depthimage_to_laserscan's job, the floor taken out by each camera's mounting). A thin
node over the depthscan/ library; the work is services/depthscan/intake.py's."""

from __future__ import annotations

import threading
from contextlib import ExitStack

from common.announce import Announced, announced_cameras
from common.bus import Declared, Publisher, QoS, Sample
from common.clock import BOOT_ID
from common.errors import DecodeError
from common.freshness import capture_age_s
from common.keys import camera_in_key
from common.messages import CameraAnnouncement, LaserScan, Twist
from common.node import Node
from services.depthscan import contract
from services.depthscan.intake import DepthIntake
from stack.config import Config

# The longest the stage goes without publishing its memory (the controller's sign that it is
# alive) or looking at the stop flag.
POLL_S = 0.1


class DepthScanStage:
    """The stage on ``node``'s bus, at ``node``'s clock: the announced cameras watched, their
    depth images and the controller's commands heard, each new virtual scan and the memory
    published. ``run`` calls ``intake.serve`` on a thread of its own; an in-process test calls
    ``intake.handle_waiting`` itself. :meth:`close` undeclares what it declared."""

    def __init__(self, config: Config, node: Node) -> None:
        self.node = node
        keys = node.keys
        self._pubs: dict[str, Publisher] = {}
        self._lock = threading.Lock()  # the publishers: the stage's thread against close
        self.remembered = node.publisher(keys.remembered_scan(), QoS.SENSOR)
        self.known = node.publisher(keys.known_floor(), QoS.SENSOR)
        self.intake = DepthIntake(
            config.controller, node, config.stack.clock_tolerance_s, node.clock,
            config.depth_memory_path, on_scan=self.put_scan, on_memory=self.put_memory,
        )  # fmt: skip
        self._subs: list[Declared] = [
            # The bus's own subscribe: the intake needs each sample's publisher (its source).
            node.bus.subscribe(keys.all_depths(), self._on_depth),
            node.subscribe(keys.cmd_vel(), self._on_cmd_vel),
        ]
        self._cameras_lock = threading.Lock()
        self.announced: Announced[CameraAnnouncement] | None = None
        self.announced = announced_cameras(
            node.bus, keys, self._on_cameras, self._on_bad_announcement
        )
        self._on_cameras()

    def _on_depth(self, sample: Sample) -> None:
        camera = camera_in_key(sample.key)
        if camera is None:  # unreachable: the subscription's keys all name a camera
            self.node.bad_input(sample.key, DecodeError("not a camera's depth key"))
            return
        self.intake.offer(camera, sample.payload, sample.source)

    def _on_cmd_vel(self, payload: bytes) -> None:
        """A command of the controller: the memory moves so from its stamp on (on this host's
        clock: its capture age off the arrival)."""
        msg = self.node.decode(self.node.keys.cmd_vel(), Twist.decode, payload)
        if msg is None:
            return
        now = self.node.clock.now()
        sent = now.mono_ns / 1e9 - max(0.0, capture_age_s(msg.header, now, BOOT_ID))
        self.intake.moved(sent, float(msg.linear[0]), float(msg.angular[2]))
        self.node.counters.add(contract.COMMANDS_IN)

    def _on_cameras(self) -> None:
        if self.announced is None:  # called back while it is being declared: done after
            return
        with self._cameras_lock:
            now = self.announced.current()
            self.intake.set_cameras(now)
            self.intake.keep_watching(now)

    def _on_bad_announcement(self, key: str, error: Exception) -> None:
        self.node.bad_input(key, error, topic="camera_announcement")

    def put_scan(self, camera: str, scan: LaserScan) -> None:
        """``camera``'s new virtual scan, on its own key (its publisher declared with its
        first scan)."""
        with self._lock:
            pub = self._pubs.get(camera)
            if pub is None:
                key = self.node.keys.virtual_scan(camera)
                pub = self._pubs[camera] = self.node.publisher(key, QoS.SENSOR)
            pub.put(scan.encode())
        self.node.counters.add(contract.SCANS_OUT)

    def put_memory(self, remembered: LaserScan, known: LaserScan) -> None:
        with self._lock:
            self.remembered.put(remembered.encode())
            self.known.put(known.encode())
        self.node.counters.add(contract.MEMORY_OUT)

    def close(self) -> None:
        if self.announced is not None:
            self.announced.close()
        for sub in self._subs:
            sub.undeclare()
        with self._lock:
            pubs, self._pubs = [*self._pubs.values(), self.remembered, self.known], {}
        for pub in pubs:
            pub.undeclare()


def run(config: Config, stop: threading.Event) -> int:
    """Make the virtual scans until ``stop`` is set; the memory written as it is left."""
    with ExitStack() as closing:
        node = closing.enter_context(
            Node(contract.SERVICE, config, counters_period_s=config.controller.counters_period_s)
        )
        stage = DepthScanStage(config, node)
        closing.callback(stage.close)
        worker = threading.Thread(
            target=stage.intake.serve, args=(stop, POLL_S, node.publish_counters),
            name="depth-scan", daemon=True,
        )  # fmt: skip
        worker.start()
        node.ready()
        stop.wait()
        worker.join()
        stage.intake.save_memory(force=True)
    return 0
