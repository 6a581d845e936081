"""Warnings the metrics answer carries (``warnings``: name -> one line with the figures and the
fixes): settings that work, but against each other on this machine. Pure: figures in, text out.

``detections_late``: a camera's detections are so old when they are published, and come so
seldom, that they age past ``controller.detection_timeout_s`` before the next one comes. The
controller's dead-man then stops the robot between detections and the next one starts it again:
on a slow CPU it flipped between ``stale`` and ``following`` about 3 times a second. Judged per
camera as capture->detections p95 plus the time between detections (1 / its detections rate).
A camera its worker serves at the attention floor by design (services/detector/attention.py:
the worker gives other cameras priority and not this one, which sees no target) is not judged:
the controller ignores its stale detections, and it gains priority once it sees a target.

``depth_second_stream``: the depth scan stage's gauge ``depth_second_stream.<camera>`` is up:
that camera's depth frames keep arriving older than the one it holds, the sign of a second stream on
its depth key stamped ahead of the real one (issue 38: a forged clear stream won that way over
the simulator's, which showed a box). Named per camera, with the stage's counts.
"""

from __future__ import annotations

import math

from common.contracts import CameraMetrics, MetricsAnswer
from common.counters import LATE, input_counter
from services.depthscan import contract as depthscan
from services.detector.contract import ATTENTION_PRIORITY
from stack.config import Config

#: Detections of a camera in the window before it is judged at all.
MIN_SAMPLES = 5
DETECTIONS_LATE = "detections_late"
DEPTH_SECOND_STREAM = depthscan.DEPTH_SECOND_STREAM


def advise(config: Config, answer: MetricsAnswer) -> dict[str, str]:
    """The warnings that hold for ``answer`` under ``config`` (empty when none)."""
    out = {}
    cameras = answer.get("cameras", {})
    count = len(answer.get("cameras_announced", cameras))  # the cameras there are now
    floor = at_floor(answer.get("counters", {}), cameras)
    late = late_detections(config, {c: m for c, m in cameras.items() if c not in floor}, count)
    if late:
        out[DETECTIONS_LATE] = late
    second = second_depth_stream(answer.get("counters", {}))
    if second:
        out[DEPTH_SECOND_STREAM] = second
    return out


def second_depth_stream(totals: dict[str, int]) -> str:
    """The ``depth_second_stream`` line, or "" when no camera is suspected: the cameras whose
    depth scan stage's gauge ``depth_second_stream.<camera>`` is up, with their late and foreign
    depth counts."""
    prefix = f"{depthscan.SERVICE}.{depthscan.DEPTH_SECOND_STREAM}."
    cameras = sorted(k[len(prefix) :] for k, v in totals.items() if k.startswith(prefix) and v > 0)
    if not cameras:
        return ""
    late = input_counter(depthscan.DEPTH, LATE)

    def count(name: str, camera: str) -> int:
        return totals.get(f"{depthscan.SERVICE}.{name}.{camera}", 0)

    figures = "; ".join(
        f"{c}: {count(late, c)} late, {count(depthscan.DEPTH_FOREIGN, c)} foreign" for c in cameras
    )
    return (
        f"a second depth stream on the key of camera {', '.join(cameras)}: its depth frames "
        "keep arriving older than the one the depth scan stage holds, so its real frames are "
        f"ignored as late ({figures}). Something else publishes on it stamped ahead: find it "
        '(zstack query), and run the secure profile (docs/security.md, "Depth from the '
        'announced source only")'
    )


def at_floor(totals: dict[str, int], cameras: dict[str, CameraMetrics]) -> frozenset[str]:
    """The cameras served at the attention floor now: their worker's ``attention_priority``
    gauge counts some camera, and its ``attention_priority.<camera>`` not this one."""
    out = set()
    for name, m in cameras.items():
        worker = m.get("served_by", "")
        if (
            worker
            and totals.get(f"{worker}.{ATTENTION_PRIORITY}", 0) > 0
            and m.get("counters", {}).get(f"{worker}.{ATTENTION_PRIORITY}", 0) == 0
        ):
            out.add(name)
    return frozenset(out)


def _oldest_ms(m: CameraMetrics) -> float | None:
    """How old a camera's detections get before the next one comes (ms), or None when there
    are too few to judge."""
    lat = m["latency_ms"].get("capture_to_detections", {})
    if lat.get("count", 0.0) < MIN_SAMPLES or m["fps"] <= 0:
        return None
    return lat["p95"] + 1000.0 / m["fps"]


def late_detections(config: Config, cameras: dict[str, CameraMetrics], count: int = 0) -> str:
    """The ``detections_late`` line, or "" when every camera's detections come in time;
    ``count``: how many cameras there are (default: as many as ``cameras``)."""
    count = count or len(cameras)
    timeout_ms = config.controller.detection_timeout_s * 1000.0
    late = {
        name: oldest
        for name, m in cameras.items()
        if (oldest := _oldest_ms(m)) is not None and oldest > timeout_ms
    }
    if not late:
        return ""
    parts = []
    for name in late:
        lat, fps = cameras[name]["latency_ms"]["capture_to_detections"], cameras[name]["fps"]
        parts.append(
            f"{name}: capture->detections p50 {lat['p50']:.0f} ms, p95 {lat['p95']:.0f} ms, "
            f"one every {1000.0 / fps:.0f} ms"
        )
    figures = "; ".join(parts)
    fixes = []
    d = config.detector
    if d.profile != "fast":
        fixes.append('detector.profile = "fast"')
    if d.imgsz == 0 or d.imgsz > 320:
        fixes.append(f"a smaller detector.imgsz (now {d.imgsz or 'the model size'}; 480 or 320)")
    if count > 1:
        fixes.append(f"fewer cameras (now {count})")
    need_s = math.ceil(max(late.values()) * 1.2 / 100.0) / 10.0  # 20 % spare, to 0.1 s
    fixes.append(f"controller.detection_timeout_s of {need_s:.1f} s or more")
    return (
        f"detections come too late for the controller's dead-man "
        f"(controller.detection_timeout_s {timeout_ms:.0f} ms): {figures}. They age past the "
        "timeout before the next one comes, so the controller stops the robot (stale) and "
        f"starts it again on each one. Fix: {', or '.join(fixes)}"
    )
