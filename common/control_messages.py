"""The messages without arrays that the e-stop command sends and reads: Header, EStop and
ControllerStatus, declared here so that ``zstack estop`` never imports numpy (its first put
must leave fast: docs/benchmarks.md, "E-stop command start-up"). common/messages.py exports them
with every other message; import them from there, as the rest of the stack does.

Units as in common/messages.py: times are integer nanoseconds since the Unix epoch.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from common.codec import Message
from common.field_types import NonNegativeInt


@dataclass(frozen=True, slots=True, kw_only=True)
class Header:
    """Who produced a message, when the data it describes was captured, and its sequence.

    ``stamp_ns`` is wall-clock time. ``mono_ns`` is the same instant on the producer's
    monotonic clock and ``boot_id`` names that clock (the host's boot); 0 and "" when unknown.
    A receiver on the same boot judges age on both clocks (common/freshness.py).
    """

    stamp_ns: NonNegativeInt
    frame_id: str
    seq: NonNegativeInt
    source: str
    # Absent from headers written before these fields existed: they decode as unknown.
    mono_ns: NonNegativeInt = 0
    boot_id: str = ""


@dataclass(frozen=True, slots=True, kw_only=True)
class EStop(Message):
    """The emergency stop: ``engaged`` latches zero velocity until an EStop with False."""

    TAG: ClassVar[str] = "EStop"
    VERSION: ClassVar[int] = 1
    header: Header
    engaged: bool
    reason: str = ""


@dataclass(frozen=True, slots=True, kw_only=True)
class ControllerStatus(Message):
    """What the controller is doing and why: mode, target and state (e.g. "following").

    ``estop_saved`` is False while the controller's e-stop latch could not be written to disk
    (it holds in memory, and the controller stays stopped until it can save): the e-stop CLI
    then says the stop is not durable. ``camera`` names the camera that sees the target ("" for
    none); ``stale_cameras`` the cameras whose detections are stale or have not come (ignored
    until they are fresh again). ``no_laser`` is True when the controller is set to drive without
    a laser (``controller.no_laser``): forward motion is then not checked for obstacles.
    ``target_classes`` are the classes the controller follows or tracks
    (``controller.target_classes``): the detector gives the cameras that see one priority
    (services/detector/attention.py) without reading the controller's config."""

    TAG: ClassVar[str] = "ControllerStatus"
    VERSION: ClassVar[int] = 1
    header: Header
    mode: str
    target: str
    state: str
    reason: str = ""
    track_id: int = -1
    estop_saved: bool = True
    camera: str = ""
    stale_cameras: tuple[str, ...] = ()
    no_laser: bool = False
    target_classes: tuple[str, ...] = ()
