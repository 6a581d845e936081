"""Every Zenoh key expression of the stack is built here, and nowhere else.

All keys live under a configurable prefix (default ``stack``) so that several robots or test
runs can share one network without hearing each other:

    <prefix>/camera/<camera>/frame            Frame           camera  -> detector
    <prefix>/camera/<camera>/depth            DepthFrame      camera  -> detector, depthscan
    <prefix>/detector/<camera>/detections     Detections      detector -> controller, metrics
    <prefix>/detector/<camera>/info           queryable       detector -> JSON: model, classes
    <prefix>/scan                             LaserScan       robot/sim -> controller
    <prefix>/scan/virtual/<camera>            LaserScan       the depth camera's virtual scan
                                                              (depthscan -> controller, viewer,
                                                              recorder)
    <prefix>/scan/remembered                  LaserScan       what the depth memory holds round
                                                              the robot (depthscan -> controller)
    <prefix>/scan/known                       LaserScan       how far ahead the floor is known:
                                                              one ray (depthscan -> controller)
    <prefix>/controller/cmd_vel               Twist           controller -> robot/sim, metrics
    <prefix>/controller/status                ControllerStatus
    <prefix>/controller/estop                 EStop           anyone -> controller (latching)
    <prefix>/sim/truth                        GroundTruth     simulator -> scenario scoring
    <prefix>/counters/<service>               ServiceCounters each service -> metrics
    <prefix>/metrics                          queryable       metrics -> JSON snapshot
    <prefix>/health/<service>                 liveliness      present while a service is ready
    <prefix>/detector/pool/<worker>           liveliness      a detector worker in the pool
    <prefix>/detector/serving/<worker>/<zid>/<camera>
                                              liveliness      a worker (session <zid>) serves it
    <prefix>/camera/<camera>/announce/<chunk> liveliness      a camera's source describes it
    <prefix>/detector/workers/<worker>/<chunk>
                                              liveliness      a pool worker describes itself
                                                              (<chunk>: common/announce.py)

Who may put on which key under the secure profile: each service's contract declares it
(``services/<name>/contract.py``), stack/access.py builds the rules.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from common.errors import ConfigError

# A chunk is one path segment; Zenoh reserves *, $, ?, # and we forbid empty segments.
_CHUNK = re.compile(r"^[A-Za-z0-9_.\-]+$")


def _check_chunks(what: str, value: str) -> str:
    if not value or not all(_CHUNK.match(chunk) for chunk in value.split("/")):
        raise ConfigError(
            f"{what} {value!r} must be '/'-separated words of letters, digits, '_', '-', '.'"
        )
    return value


#: The depth memory's scans (Keys.remembered_scan, Keys.known_floor), by their key's last chunk.
MEMORY_SCANS = ("remembered", "known")


def memory_scan(key: str) -> str | None:
    """Which of the depth memory's scans (:data:`MEMORY_SCANS`) ``key`` carries, under any
    prefix; None for any other key."""
    parts = key.split("/")
    if len(parts) >= 3 and parts[-2] == "scan" and parts[-1] in MEMORY_SCANS:
        return parts[-1]
    return None


def virtual_scan_camera(key: str) -> str | None:
    """The depth camera whose virtual scan ``key`` carries, under any prefix; None for any
    other key."""
    parts = key.split("/")
    if len(parts) >= 4 and (parts[-3], parts[-2]) == ("scan", "virtual") and parts[-1]:
        return parts[-1]
    return None


def camera_in_key(key: str) -> str | None:
    """The camera whose frames, depth images or detections ``key`` carries, under any prefix
    (a recording may come from another stack's); None for any other key."""
    parts = key.split("/")
    if len(parts) >= 4 and (parts[-3], parts[-1]) in (
        ("camera", "frame"),
        ("camera", "depth"),
        ("detector", "detections"),
    ):
        return parts[-2]
    return None


@dataclass(frozen=True, slots=True)
class Keys:
    """The key space of one stack, rooted at ``prefix``."""

    prefix: str = "stack"

    def __post_init__(self) -> None:
        _check_chunks("key prefix", self.prefix)

    def frame(self, camera: str) -> str:
        return f"{self.prefix}/camera/{_check_chunks('camera name', camera)}/frame"

    def depth(self, camera: str) -> str:
        """``camera``'s depth images (DepthFrame), aligned to its colour frames."""
        return f"{self.prefix}/camera/{_check_chunks('camera name', camera)}/depth"

    def all_depths(self) -> str:
        return f"{self.prefix}/camera/*/depth"

    def detections(self, camera: str) -> str:
        return f"{self.prefix}/detector/{_check_chunks('camera name', camera)}/detections"

    def detector_info(self, camera: str) -> str:
        return f"{self.prefix}/detector/{_check_chunks('camera name', camera)}/info"

    def all_frames(self) -> str:
        return f"{self.prefix}/camera/*/frame"

    def all_detections(self) -> str:
        return f"{self.prefix}/detector/*/detections"

    def all_detector_info(self) -> str:
        return f"{self.prefix}/detector/*/info"

    def pool_member(self, worker: str) -> str:
        """A detector worker's liveliness token: present while it takes cameras
        (services/detector/pool.py)."""
        return f"{self.prefix}/detector/pool/{_check_chunks('worker id', worker)}"

    def all_pool_members(self) -> str:
        return f"{self.prefix}/detector/pool/*"

    def pool_serving(self, worker: str, zid: str, camera: str) -> str:
        """A detector worker's liveliness token while it serves ``camera``, from the session
        ``zid`` (so that two processes holding one worker name show as two)."""
        return "/".join(
            (
                f"{self.prefix}/detector/serving",
                _check_chunks("worker id", worker),
                _check_chunks("zenoh id", zid),
                _check_chunks("camera name", camera),
            )
        )

    def pool_serving_of(self, worker: str) -> str:
        """Every serving token of ``worker`` (its access rule)."""
        return f"{self.prefix}/detector/serving/{_check_chunks('worker id', worker)}/**"

    def all_pool_serving(self) -> str:
        return f"{self.prefix}/detector/serving/**"

    def pool_serving_parts(self, key: str) -> tuple[str, str, str] | None:
        """``(worker, zid, camera)`` of a serving token's key; None for another key."""
        head = f"{self.prefix}/detector/serving/"
        if not key.startswith(head):
            return None
        parts = key[len(head) :].split("/", 2)
        return (parts[0], parts[1], parts[2]) if len(parts) == 3 and all(parts) else None

    def camera_announcement(self, camera: str, chunk: str) -> str:
        """A camera's announcement token (common/announce.py): ``chunk`` encodes it."""
        return f"{self.camera_announcements_of(camera)[:-1]}{_check_chunks('announcement', chunk)}"

    def camera_announcements_of(self, camera: str) -> str:
        """Every announcement of ``camera`` (its source's access rule)."""
        return f"{self.prefix}/camera/{_check_chunks('camera name', camera)}/announce/*"

    def all_camera_announcements(self) -> str:
        return f"{self.prefix}/camera/*/announce/*"

    def camera_announcement_parts(self, key: str) -> tuple[str, str] | None:
        """``(camera, chunk)`` of a camera announcement's key; None for another key."""
        return _two_parts(key, f"{self.prefix}/camera/", "announce")

    def worker_announcement(self, worker: str, chunk: str) -> str:
        """A pool worker's announcement token (common/announce.py): ``chunk`` encodes it."""
        return f"{self.worker_announcements_of(worker)[:-1]}{_check_chunks('announcement', chunk)}"

    def worker_announcements_of(self, worker: str) -> str:
        """Every announcement of ``worker`` (its access rule)."""
        return f"{self.prefix}/detector/workers/{_check_chunks('worker id', worker)}/*"

    def all_worker_announcements(self) -> str:
        return f"{self.prefix}/detector/workers/*/*"

    def worker_announcement_parts(self, key: str) -> tuple[str, str] | None:
        """``(worker, chunk)`` of a worker announcement's key; None for another key."""
        return _two_parts(key, f"{self.prefix}/detector/workers/", "")

    def scan(self) -> str:
        return f"{self.prefix}/scan"

    def virtual_scan(self, camera: str) -> str:
        """``camera``'s virtual scan (LaserScan, robot frame), made from its depth images."""
        return f"{self.prefix}/scan/virtual/{_check_chunks('camera name', camera)}"

    def all_virtual_scans(self) -> str:
        return f"{self.prefix}/scan/virtual/*"

    def remembered_scan(self) -> str:
        """What the depth cameras' memory holds round the robot (LaserScan, robot frame)."""
        return f"{self.prefix}/scan/remembered"

    def known_floor(self) -> str:
        """How far ahead the floor is known (a LaserScan of one ray, straight ahead)."""
        return f"{self.prefix}/scan/known"

    def cmd_vel(self) -> str:
        return f"{self.prefix}/controller/cmd_vel"

    def controller_status(self) -> str:
        return f"{self.prefix}/controller/status"

    def sim_truth(self) -> str:
        return f"{self.prefix}/sim/truth"

    def estop(self) -> str:
        return f"{self.prefix}/controller/estop"

    def counters(self, service: str) -> str:
        return f"{self.prefix}/counters/{_check_chunks('service name', service)}"

    def all_counters(self) -> str:
        return f"{self.prefix}/counters/*"

    def metrics(self) -> str:
        return f"{self.prefix}/metrics"

    def health(self, service: str) -> str:
        return f"{self.prefix}/health/{_check_chunks('service name', service)}"

    def all_health(self) -> str:
        return f"{self.prefix}/health/*"


def _two_parts(key: str, head: str, middle: str) -> tuple[str, str] | None:
    """``(name, chunk)`` of ``<head><name>/<middle>/<chunk>`` (``<head><name>/<chunk>`` when
    ``middle`` is empty); None for any other key."""
    if not key.startswith(head):
        return None
    parts = key[len(head) :].split("/")
    want = 3 if middle else 2
    if len(parts) != want or not all(parts) or (middle and parts[1] != middle):
        return None
    return parts[0], parts[-1]
