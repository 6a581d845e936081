"""The detector pool as the metrics service sees it: each worker's cameras, load and hand-overs
from its counters, and frames detected twice. Pure: no bus, no clock.

A worker (``detector``, ``detector_<n>``) counts ``serving.<cam>`` (1 while it serves the
camera), ``pool_load_permille``, ``pool_members``, ``cameras_gained`` and ``cameras_lost``
(services/detector/service.py::PoolMember).

One worker never detects a frame twice (a frame leaves its camera's slot once), so a second
Detections for the same camera and the same frame (its header's boot id, sequence number and
capture stamp) comes from another worker: the overlap of a hand-over, while the old owner has
not yet heard that it lost the camera. :class:`Duplicates` counts them.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Mapping

from common.contracts import WorkerMetrics
from common.messages import Header
from common.settings import service_package

RECENT_FRAMES = 256  # frames remembered per camera: a hand-over's overlap is well under this


class Duplicates:
    """Frames seen twice, per camera (bounded memory: the last :data:`RECENT_FRAMES` each)."""

    def __init__(self) -> None:
        self.per_camera: dict[str, int] = {}
        self._seen: dict[str, tuple[deque[tuple[str, int, int]], set[tuple[str, int, int]]]] = {}

    @property
    def total(self) -> int:
        return sum(self.per_camera.values())

    def seen(self, camera: str, header: Header) -> bool:
        """Note ``camera``'s frame ``header``; True when it was already seen (a duplicate)."""
        order, known = self._seen.setdefault(camera, (deque(), set()))
        frame = (header.boot_id, header.seq, header.stamp_ns)
        if frame in known:
            self.per_camera[camera] = self.per_camera.get(camera, 0) + 1
            return True
        order.append(frame)
        known.add(frame)
        if len(order) > RECENT_FRAMES:
            known.discard(order.popleft())
        return False


def workers(
    counters: Mapping[str, int],
    cameras: Iterable[str],
    reported_at: Mapping[str, float],
    now: float,
) -> dict[str, WorkerMetrics]:
    """Each detector worker that counts ``serving``, from ``counters`` (``<service>.<name>``
    -> value) and when its counters last came (``reported_at``)."""
    cams = list(cameras)
    out: dict[str, WorkerMetrics] = {}
    for service in sorted(reported_at):
        if service_package(service) != "detector" or f"{service}.serving" not in counters:
            continue
        out[service] = WorkerMetrics(
            cameras=[c for c in cams if counters.get(f"{service}.serving.{c}", 0) > 0],
            load=counters.get(f"{service}.pool_load_permille", 0) / 1000.0,
            members=counters.get(f"{service}.pool_members", 0),
            cameras_gained=counters.get(f"{service}.cameras_gained", 0),
            cameras_lost=counters.get(f"{service}.cameras_lost", 0),
            reported_s_ago=max(0.0, now - reported_at[service]),
        )
    return out
