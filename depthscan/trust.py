"""Whose depth the controller believes (issue 38): pure rules for the depth intake
(the depth scan stage, services/depthscan/intake.py), no bus, no clock of their own.

- **The announced source only.** A camera's announcement names the Zenoh session that
  announces it (``CameraAnnouncement.zid``), which publishes its depth from that same session;
  a depth sample whose publisher (``Sample.source``, "zid/eid") is in another session is
  foreign (:func:`foreign_source`). An announcement without ``zid`` (a source older than the
  field) cannot be checked: its depth is taken from any publisher, as before, and the intake
  says so once.
- **Not from this host's future.** Depth stamped on this boot of this host is stamped off the
  receiver's own clocks; more than a small tolerance ahead of them is forged or broken
  (:func:`ahead_on_same_clock`). Depth from another host keeps the cross-host tolerance.
- **One stream per camera.** One source's frames come in stamp order; frames that keep arriving
  older than the one held are the sign of a second stream on the key whose stamps run ahead
  (:class:`LateWatch`).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

from common.clock import Stamp
from common.freshness import ages_s
from common.messages import CameraAnnouncement, Header


def foreign_source(announced: CameraAnnouncement, source: str) -> bool:
    """Whether a sample put by ``source`` ("zid/eid", or "unidentified") is not from the
    session that announced the camera; False when the announcement names none."""
    return bool(announced.zid) and source.split("/", 1)[0] != announced.zid


def ahead_on_same_clock(header: Header, now: Stamp, boot_id: str, tolerance_s: float) -> float:
    """How far (s) ``header`` is stamped ahead of ``now`` when it was stamped on this boot
    (``boot_id``, with a monotonic stamp) and more than ``tolerance_s`` ahead on either clock;
    0.0 otherwise (fine, or from another host: the cross-host tolerance judges it)."""
    ages = ages_s(header, now, boot_id)
    if len(ages) < 2 or min(ages) >= -tolerance_s:
        return 0.0
    return -min(ages)


@dataclass
class LateWatch:
    """Per camera, the depth frames that arrived older than the one held: ``count`` of them
    within ``window_s`` makes the camera suspect (a second stream on its key) until fewer are
    left in the window. Not thread-safe: the intake's thread alone calls it."""

    count: int
    window_s: float
    _late: dict[str, deque[float]] = field(default_factory=dict)
    suspect: set[str] = field(default_factory=set)

    def saw(self, camera: str, late: bool, now_s: float) -> tuple[int, bool]:
        """A fresh frame of ``camera`` at ``now_s`` (monotonic s), ``late`` or not: (how many
        late ones are in the window now, whether the camera is suspect)."""
        times = self._late.setdefault(camera, deque())
        if late:
            times.append(now_s)
        while times and times[0] < now_s - self.window_s:
            times.popleft()
        if len(times) >= self.count:
            self.suspect.add(camera)
        else:
            self.suspect.discard(camera)
        if not times:
            del self._late[camera]
        return len(times), camera in self.suspect

    def keep(self, cameras: set[str]) -> set[str]:
        """Forget the cameras not in ``cameras`` (withdrawn); the suspect ones forgotten."""
        gone = self.suspect - cameras
        self.suspect -= gone
        for camera in set(self._late) - cameras:
            del self._late[camera]
        return gone
