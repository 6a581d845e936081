"""The whole stack through the supervisor: real processes, real model, real photo, real Zenoh."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest

from common.messages import Detections, Frame, Header, LaserScan, Twist
from tests.integration.conftest import Stack, wait_for

pytestmark = pytest.mark.integration

SERVICES = {"camera", "detector", "controller", "metrics"}
# Labelled by hand on scikit-image's camera() photo (512x512): the man, hair to image bottom.
CAMERAMAN_BOX = np.array([0, 65, 330, 512], np.float32)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    w = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    h = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = w * h
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return float(inter / union)


def _garbage(good: bytes) -> list[bytes]:
    """Random bytes, a newer schema version, a truncated message and absurd dimensions."""
    env = msgpack.unpackb(good)
    wrong_version = msgpack.packb({**env, "v": env["v"] + 99})
    body = env["d"]
    if "width" in body:  # a frame claiming a billion-pixel side
        absurd_body = {**body, "width": 10**9, "height": 10**9}
    else:  # every count and stamp negative
        absurd_body = {k: -1 if isinstance(v, int) else v for k, v in body.items()}
    absurd = msgpack.packb({**env, "d": absurd_body})
    return [np.random.default_rng(0).bytes(256), wrong_version, good[: len(good) // 2], absurd]


def test_stack_detects_reacts_and_stops_cleanly(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack()
    stack.wait_ready(SERVICES)
    _, dets = stack.subscribe(stack.keys.detections("front"))
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    encodings: set[str] = set()
    _enc_sub = stack.session.declare_subscriber(
        stack.keys.detections("front"), lambda s: encodings.add(str(s.encoding))
    )

    def person_seen() -> Detections | None:
        for raw in list(dets):
            d = Detections.decode(raw)
            if "person" in d.class_names:
                return d
        return None

    d = wait_for(person_seen, 60, "a detection of the cameraman as a person")
    assert (d.image_width, d.image_height) == (512, 512)
    assert d.header.source == "camera" and d.header.stamp_ns < d.published_ns
    assert d.timing_ms["inference"] > 0
    i = d.class_names.index("person")
    box, tracks = d.boxes.xyxy[i], d.boxes.track_ids
    assert iou(box, CAMERAMAN_BOX) >= 0.5, f"person box {box} is not on the man"
    assert tracks is not None and tracks[i] > 0, "the tracker gave no track id"

    def reaction() -> Twist | None:
        stamps = {Detections.decode(r).header.stamp_ns for r in list(dets)}
        for raw in list(cmds):
            t = Twist.decode(raw)
            if t.input_stamp_ns in stamps:
                return t
        return None

    wait_for(reaction, 30, "a Twist that reacts to a detection")

    metrics = wait_for(lambda: (m := stack.metrics()) and m["frames"] > 0 and m, 30, "metrics")
    assert metrics["latency_ms"]["end_to_end"]["count"] > 0
    assert metrics["latency_ms"]["inference"]["p50"] > 0
    assert metrics["class_counts"].get("person", 0) > 0
    # Frames from this host are tracked on their monotonic stamps: however late the first
    # deliveries were while everything loaded, no stamp "jumped" and no track restarted.
    jumps = {k: v for k, v in metrics["counters"].items() if k.startswith("detector.tracker_")}
    assert jumps == {}, jumps
    assert encodings == {"application/msgpack"}
    replies = stack.session.get(stack.keys.metrics(), timeout=2.0)
    answers = [r.ok for r in replies if r.ok is not None]
    assert answers and str(answers[0].encoding) == "application/json"

    assert stack.stop() == 0, stack.log()
    log = stack.log()
    assert "all services exited cleanly" in log, log


def test_garbage_on_every_key_is_counted_and_dropped(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack()
    stack.wait_ready(SERVICES)
    _, dets = stack.subscribe(stack.keys.detections("front"))
    wait_for(lambda: len(dets) > 0, 60, "the first detections")

    hdr = Header(stamp_ns=1, frame_id="x", seq=1, source="test")
    frame = Frame(header=hdr, encoding="bgr8", width=4, height=4, data=bytes(48)).encode()
    scan = LaserScan(
        header=hdr,
        angle_min=0.0,
        angle_increment=0.1,
        range_min=0.1,
        range_max=5.0,
        ranges=np.ones(3, np.float32),
    ).encode()
    twist = Twist(header=hdr).encode()
    targets = {
        stack.keys.frame("front"): frame,  # detector
        stack.keys.detections("front"): dets[0],  # controller and metrics
        stack.keys.scan(): scan,  # controller
        stack.keys.cmd_vel(): twist,  # metrics
        stack.keys.counters("intruder"): frame,  # metrics (a Frame is not ServiceCounters)
    }
    pubs = {key: stack.session.declare_publisher(key) for key in targets}
    for key, good in targets.items():
        for bad in _garbage(good):
            pubs[key].put(bad)

    missing: dict[str, int] = {}

    def counted() -> dict[str, int] | None:
        m = stack.metrics()
        if not m:
            return None
        c = m["counters"]
        want = {"detector.bad_input": 4, "controller.bad_input": 8, "metrics.bad_input": 12}
        missing.clear()
        missing.update({k: c.get(k, 0) for k, n in want.items() if c.get(k, 0) < n})
        return None if missing else c

    counters = wait_for(counted, 30, lambda: f"the garbage to be counted; short: {missing}", 0.5)
    assert counters["detector.bad_input"] >= 4
    # Still alive and still detecting after the garbage.
    n = len(dets)
    wait_for(lambda: len(dets) > n + 2, 30, "detections to keep flowing")
    assert stack.ready_services() >= SERVICES
    assert stack.stop() == 0, stack.log()
