"""A camera's header as the camera service stamps it, for the detector's tests with several
cameras (unit and integration)."""

from __future__ import annotations

from common.clock import BOOT_ID, now
from common.messages import Header


def camera_header(camera: str, seq: int) -> Header:
    """Stamped now (wall and monotonic), framed and sourced as camera ``camera`` names them."""
    at = now()
    return Header(
        stamp_ns=at.wall_ns,
        frame_id=f"{camera}_optical",
        seq=seq,
        source=f"camera_{camera}",
        mono_ns=at.mono_ns,
        boot_id=BOOT_ID,
    )
