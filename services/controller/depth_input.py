"""The depth scan stage's output as the controller reads it (services/depthscan puts it): each
announced depth camera's virtual scan, what the depth memory remembers round the robot and how
far ahead it knows the floor. Each is judged on arrival by the one path every aged input takes
(services/controller/handlers.py ``take_fresh``: a freshness gate, the newest kept, counted) and
aged at the control instant by the dead-man's rule (the later of its capture and its arrival),
against ``depth_timeout_s``; the cameras' scans are then judged together
(services/controller/depth_obstacles.py: every camera that looks ahead fresh, the sector
covered).

The memory is the stage's sign of life: it puts it at least every 0.1 s. Without a fresh one
(the stage killed, hung, or not run) depth is missing and the robot holds still, turning
included (``DepthObstacles.halt``): a turn the stage does not hear would misplace what it
remembers.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Mapping

from common.clock import BOOT_ID, Clock, Stamp
from common.freshness import FreshnessGate
from common.messages import CameraAnnouncement, LaserScan
from common.node import Tally
from perception import Mounting
from services.controller import contract
from services.controller.contract import ControllerSettings
from services.controller.depth_obstacles import DepthCamera, DepthObstacles, depth_obstacles
from services.controller.handlers import Latest, age_of, take_fresh


class DepthInput:
    """The newest fresh virtual scan of each announced depth camera and the newest memory
    (thread-safe: bus threads put, the control loop reads)."""

    def __init__(self, s: ControllerSettings, tally: Tally, tolerance_s: float, clock: Clock):
        self.tally, self.clock = tally, clock
        self.tolerance_s = tolerance_s
        self.timeout_s = s.depth_timeout_s
        self.sector_width_deg = s.sector_width_deg
        self._lock = threading.Lock()
        self._cameras: dict[str, CameraAnnouncement] = {}  # announced with depth
        self._scans: dict[str, Latest[LaserScan]] = {}
        # A gate outlives its camera's withdrawal: a replay is refused after a re-announcement.
        self._gates: dict[str, FreshnessGate] = {}
        self.remembered: Latest[LaserScan] = Latest(clock=clock)
        self.known: Latest[LaserScan] = Latest(clock=clock)
        self._memory_gates = {
            name: FreshnessGate(self.timeout_s, tolerance_s, BOOT_ID)
            for name in (contract.REMEMBERED, contract.KNOWN_FLOOR)
        }

    def set_cameras(self, cameras: Mapping[str, CameraAnnouncement]) -> None:
        """The cameras announced now: the scans of those announced with depth are read, the
        others' (withdrawn, or announced again without depth) dropped."""
        with self._lock:
            self._cameras = {c: a for c, a in cameras.items() if a.depth}
            for camera in list(self._scans):
                if camera not in self._cameras:
                    del self._scans[camera]
            for camera in self._cameras:
                self._scans.setdefault(camera, Latest(clock=self.clock))
                self._gates.setdefault(
                    camera, FreshnessGate(self.timeout_s, self.tolerance_s, BOOT_ID)
                )

    def on_virtual_scan(self, camera: str, payload: bytes) -> None:
        with self._lock:
            latest, gate = self._scans.get(camera), self._gates.get(camera)
        if latest is None or gate is None:
            self.tally.reject(
                contract.VIRTUAL_SCANS_UNANNOUNCED,
                f"a virtual scan of {camera!r:.80}, a camera not announced with depth, ignored",
            )
            return
        key = self.tally.keys.virtual_scan(camera)
        msg = self.tally.decode(key, LaserScan.decode, payload)
        if msg is not None:
            take_fresh(self.tally, self.clock, msg, gate, latest, contract.VIRTUAL_SCANS, camera)

    def on_remembered(self, payload: bytes) -> None:
        key = self.tally.keys.remembered_scan()
        self._memory(contract.REMEMBERED, key, self.remembered, payload)

    def on_known(self, payload: bytes) -> None:
        self._memory(contract.KNOWN_FLOOR, self.tally.keys.known_floor(), self.known, payload)

    def _memory(self, name: str, key: str, latest: Latest[LaserScan], payload: bytes) -> None:
        msg = self.tally.decode(key, LaserScan.decode, payload)
        if msg is not None:
            take_fresh(self.tally, self.clock, msg, self._memory_gates[name], latest, name)

    def obstacles(self, at: Stamp) -> DepthObstacles:
        """The depth cameras' obstacles at the control instant ``at``, with what the memory
        remembers round the robot and how far ahead the floor is known; the age is the oldest
        of them all. No fresh memory: missing, and ``halt`` says why."""
        with self._lock:
            held = {c: (a, self._scans[c].get()) for c, a in self._cameras.items()}
        cameras = {}
        for camera, (announced, (scan, arrival)) in held.items():
            age = age_of(scan.header if scan is not None else None, arrival, at)
            cameras[camera] = DepthCamera(Mounting.of(announced), announced.hfov_deg, scan, age)
        now = depth_obstacles(cameras, self.timeout_s, self.sector_width_deg)
        remembered, r_arrival = self.remembered.get()
        known, k_arrival = self.known.get()
        if remembered is None or known is None:
            halt = "no depth memory from the depth scan stage yet"
            return dataclasses.replace(now, scan=None, missing=now.missing or halt, halt=halt)
        memory_age = max(
            age_of(remembered.header, r_arrival, at), age_of(known.header, k_arrival, at)
        )
        if memory_age > self.timeout_s:
            halt = f"no recent depth memory from the depth scan stage ({memory_age:.2f} s)"
            return dataclasses.replace(now, scan=None, missing=now.missing or halt, halt=halt)
        if now.scan is None:
            return now
        return dataclasses.replace(
            now,
            age_s=max(now.age_s, memory_age),
            remembered=remembered,
            known_m=float(known.ranges[0]),
        )
