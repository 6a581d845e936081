"""The real metrics service with two cameras: each camera's figures apart in `zstack query`.

The test is the detector, the controller and the rear camera's process: it puts real
Detections on both cameras' keys, Twists reacting to some of their frames, and counters named
per camera, then reads the answer as a user would (``python -m services.metrics query``).
"""

from __future__ import annotations

import json
import subprocess
import sys
from typing import Any

import pytest
import zenoh

from common.clock import BOOT_ID, now
from common.messages import Detections, Header, ServiceCounters, Twist
from tests.integration.conftest import REPO, Stack, wait_for
from tests.unit.metrics.samples import detections

pytestmark = pytest.mark.integration

MS = 1_000_000
FRAMES = {"front": 20, "rear": 10}  # detections messages put per camera
BOXES = {"front": 2, "rear": 1}  # boxes in each
REACTED = {"front": 5, "rear": 4}  # frames a Twist reacts to, the first of each camera's
DETECTOR_COUNTS = {
    "frames_in": 33, "dropped": 3, "frames_in.front": 22, "dropped.front": 2,
    "frames_in.rear": 11, "dropped.rear": 1, "detections_out.rear": 10,
}  # fmt: skip


def _header(source: str, seq: int, stamp_ns: int) -> Header:
    return Header(stamp_ns=stamp_ns, frame_id=source, seq=seq, source=source, boot_id=BOOT_ID)


def _detections(camera: str, seq: int, stamp_ns: int) -> Detections:
    return detections(_header(camera, seq, stamp_ns), BOXES[camera])


def _matched(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """A publisher on ``key`` once the metrics service's subscriber matches it: a new
    session's first puts would otherwise go nowhere."""
    pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
    wait_for(lambda: pub.matching_status.matching, 30, f"a subscriber matching {key}")
    return pub


def _query(stack: Stack) -> dict[str, Any]:
    done = subprocess.run(
        [sys.executable, "-m", "services.metrics", "query", "--config", str(stack.config_path)],
        cwd=REPO, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    answer: dict[str, Any] = json.loads(done.stdout)
    return answer


def test_the_query_shows_each_camera(make_stack: Any) -> None:
    stack: Stack = make_stack(
        supervisor={"services": ["metrics"]}, **{"cameras.rear": {"mount_yaw_deg": 180.0}}
    )
    stack.wait_ready({"metrics"})
    keys = stack.keys
    session = stack.open("observer")
    try:
        dets = {camera: _matched(session, keys.detections(camera)) for camera in FRAMES}
        cmd_vel = _matched(session, keys.cmd_vel())
        start = now().wall_ns
        for camera, frames in FRAMES.items():
            offset = 0 if camera == "front" else 7 * MS  # the cameras' stamps never coincide
            for seq in range(frames):
                stamp = start + seq * 100 * MS + offset
                dets[camera].put(_detections(camera, seq + 1, stamp).encode())
                if seq < REACTED[camera]:
                    twist = Twist(
                        header=_header("controller", seq + 1, stamp + 150 * MS),
                        angular=(0.0, 0.0, 0.1),
                        input_stamp_ns=stamp,
                    )
                    cmd_vel.put(twist.encode())
        counters = {
            service: (_matched(session, keys.counters(service)), counts)
            for service, counts in (
                ("detector", DETECTOR_COUNTS),
                ("camera_rear", {"frames_out": 12}),  # a further camera's own process
            )
        }

        runs = [0]

        def counted() -> dict[str, Any] | None:
            # Put again on every poll: telemetry may be dropped under congestion. The detector
            # runs one more batch of two frames between reports (a mean over the window).
            runs[0] += 1
            batches = {"batches": runs[0], "batched_frames": 2 * runs[0]}
            for service, (pub, counts) in counters.items():
                counts = {**counts, **batches} if service == "detector" else counts
                msg = ServiceCounters(
                    header=_header(service, 1, now().wall_ns), service=service, counters=counts
                )
                pub.put(msg.encode())
            m = stack.metrics()
            if m is None or m["frames"] != sum(FRAMES.values()):
                return None
            return m if "camera_rear.frames_out" in m["counters"] else None

        wait_for(counted, 30, lambda: f"every message counted: {stack.metrics()}")
    finally:
        session.close()

    answer = _query(stack)
    assert list(answer["cameras"]) == ["front", "rear"]
    for camera, m in answer["cameras"].items():
        assert m["fps"] > 0, camera
        assert m["frames"] == FRAMES[camera]
        assert m["detections"] == FRAMES[camera] * BOXES[camera]
        assert m["detections_per_frame"] == BOXES[camera]
        lat = m["latency_ms"]
        assert lat["end_to_end"]["count"] == REACTED[camera]
        assert lat["end_to_end"]["p50"] == pytest.approx(150.0)
        assert lat["detections_to_command"]["p50"] == pytest.approx(60.0)
        assert lat["inference"]["count"] == FRAMES[camera]
        assert m["served_by"] == "detector"
        assert m["frames_offered"] == DETECTOR_COUNTS[f"frames_in.{camera}"]
        assert m["dropped_frames"] == DETECTOR_COUNTS[f"dropped.{camera}"]
        assert m["batch_mean"] == 2.0
    assert answer["cameras"]["rear"]["counters"]["detector.detections_out"] == 10
    # The top level is both cameras together, with every field it always had.
    assert answer["frames"] == sum(FRAMES.values())
    assert answer["latency_ms"]["end_to_end"]["count"] == sum(REACTED.values())
    assert (answer["frames_offered"], answer["dropped_frames"]) == (33, 3)
    assert {"fps", "drop_rate", "drop_rate_total", "timeline", "class_counts"} <= answer.keys()
    # The rear camera's own process is believed now (it used to be an unknown service).
    assert answer["counters"]["camera_rear.frames_out"] == 12
    assert "metrics.refused.unknown_service" not in answer["counters"]
    assert stack.stop() == 0, stack.log()
