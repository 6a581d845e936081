"""The supervisor's status line names what the operator must not miss on every line."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any, cast

from common.messages import ControllerStatus, Header
from deploy.supervisor import status_line

HEADER = Header(stamp_ns=1, frame_id="base_link", seq=1, source="controller")


def view(**status: Any) -> Any:
    s = ControllerStatus(header=HEADER, mode="track", target="", state="stale", **status)
    return SimpleNamespace(status=s, twist=None, truth=None)


def test_no_laser_is_on_every_line() -> None:
    assert "NO LASER" in status_line([], view(no_laser=True), None)
    assert "NO LASER" not in status_line([], view(), None)


def test_a_metrics_warning_is_named() -> None:
    lat = {"end_to_end": {"p50": 900.0}}
    metrics = {"fps": 5.0, "detections_per_frame": 1.0, "latency_ms": lat}
    line = status_line([], view(), cast(Any, {**metrics, "warnings": {"detections_late": "..."}}))
    assert "WARNING detections_late" in line
    assert "WARNING" not in status_line([], view(), cast(Any, metrics))
