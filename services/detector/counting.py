"""The detector's per-camera counting: each counter in all and under ``<name>.<camera>``
(common/counters.py::per_camera) for the names of contract.PER_CAMERA."""

from __future__ import annotations

from common.counters import per_camera
from common.node import Tally


def count_for(tally: Tally, camera: str, name: str, n: int = 1) -> None:
    """Count ``n`` under ``name`` (the detector's total) and under ``name.<camera>``."""
    tally.counters.add(name, n)
    tally.counters.add(per_camera(name, camera), n)


def reject_for(tally: Tally, camera: str, counter: str, message: str, key: str) -> None:
    """``Tally.reject`` (counted in all, logged rate-limited per key) and counted for
    ``camera`` too."""
    tally.reject(counter, message, key=key)
    tally.counters.add(per_camera(counter, camera))
