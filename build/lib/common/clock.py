"""Stamps on two clocks: the wall clock every host shares (roughly) and this host's monotonic one.

A message carries both. A receiver on the same boot of the same host judges age on the monotonic
clock too, which no NTP step or operator's ``date`` moves; a receiver on another host can only
use the wall clock, which must then be synchronised (docs/security.md, "Clocks").
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path


def _read_boot_id() -> str:
    """This boot's id (Linux); monotonic stamps compare only within one boot of one host."""
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text(encoding="ascii").strip()
    except OSError:
        return ""  # not Linux: monotonic stamps are then never compared across processes


BOOT_ID = _read_boot_id()


@dataclass(frozen=True, slots=True)
class Stamp:
    """One instant on both clocks, in integer nanoseconds."""

    wall_ns: int
    mono_ns: int


def now() -> Stamp:
    return Stamp(time.time_ns(), time.monotonic_ns())
