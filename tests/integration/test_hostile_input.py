"""Hostile input against one running stack (camera, detector, metrics): decompression bombs,
a flood of garbage, a payload too large for Zenoh, rogue counters and an absurd stage time.

One stack is shared by the tests of this module, in order; each checks its own counters.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh

from common.boxes import Boxes
from common.clock import BOOT_ID, now
from common.frames import image_to_frame
from common.images import load_sample
from common.messages import Detections, Frame, Header, ServiceCounters
from tests.integration.conftest import Stack, wait_for, write_config
from tests.unit.common.test_pixel_budget import bomb
from tests.unit.perception.test_nonfinite import constant_model
from tools.launch import service_pids

pytestmark = pytest.mark.integration

MAX_DETECTOR_PEAK_KB = 800_000  # the detector peaked at 265 MB; one bomb decoded adds 1.5 GB
FLOOD = 20_000
MAX_WARNING_LINES = 50


@pytest.fixture(scope="module")
def stack(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Stack]:
    tmp = tmp_path_factory.mktemp("hostile")
    config = write_config(
        tmp,
        supervisor={"services": ["camera", "detector", "metrics"], "status_period_s": 1.0},
        # Raw 1024x1024 frames are 3 MiB: every one is over the 2 MiB limit, so the detector
        # hears only the frames the tests send.
        zenoh={"max_payload_bytes": 2 * 1024 * 1024},
        camera={"source": "sample:cameraman", "rate_hz": 2.0, "resize": [1024, 1024]},
    )
    stack = Stack(config, tmp / "supervisor.log")
    try:
        stack.wait_ready({"camera", "detector", "metrics"})
        yield stack
    finally:
        if stack.proc.poll() is None:
            assert stack.stop() == 0, stack.log()


def counter(stack: Stack, name: str) -> int:
    answer = stack.metrics()
    return int(answer["counters"].get(name, 0)) if answer else 0


def header(source: str, seq: int) -> Header:
    at = now()
    return Header(
        stamp_ns=at.wall_ns, frame_id="cam", seq=seq, source=source, mono_ns=at.mono_ns,
        boot_id=BOOT_ID,
    )  # fmt: skip


def peak_rss_kb(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
    raise AssertionError(f"no VmHWM in /proc/{pid}/status")


def warnings_of(stack: Stack, service: str) -> list[str]:
    text = stack.log_path.read_text(errors="replace")
    return [line for line in text.splitlines() if f" {service} WARNING " in line]


def test_bombs_are_dropped_and_real_frames_still_detected(stack: Stack) -> None:
    key = stack.keys.frame("front")
    # Blocking, so that every bomb is delivered and can be counted (every role of the stack's
    # own publishers drops under congestion: docs/security.md, QoS by role).
    pub = stack.session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
    _, dets = stack.subscribe(stack.keys.detections("front"))
    photo = load_sample("cameraman")
    data = bomb()
    bomb_seq = 0
    for seq in (1, 2, 5):  # 3 and 4 never sent: 2 frames missed
        for _ in range(10):
            bomb_seq += 1
            pub.put(
                Frame(header=header("bomber", bomb_seq), encoding="jpeg", width=16384,
                      height=16384, data=data).encode()
            )  # fmt: skip
        frame = image_to_frame(photo, header("testcam", seq), jpeg_quality=80)
        pub.put(frame.encode())

        def detected(stamp: int = frame.header.stamp_ns) -> Detections | None:
            found = [d for d in map(Detections.decode, list(dets)) if d.header.stamp_ns == stamp]
            return found[0] if found else None

        assert len(wait_for(detected, 60, f"detections of real frame {seq}")) > 0
    [pid] = service_pids("detector", stack.config_path)
    peak = peak_rss_kb(pid)
    assert peak < MAX_DETECTOR_PEAK_KB, f"the detector peaked at {peak} kB"
    wait_for(lambda: counter(stack, "detector.frames_oversize") == 30, 30, "30 bombs counted")
    assert counter(stack, "detector.frames_missed") == 2


def test_a_flood_is_counted_in_full_and_logged_in_a_few_lines(stack: Stack) -> None:
    # Blocking, so that every message of the burst is delivered and can be counted (the
    # stack's own control publishers drop under congestion: docs/security.md, QoS by role).
    pub = stack.session.declare_publisher(
        stack.keys.frame("front"), congestion_control=zenoh.CongestionControl.BLOCK
    )
    for i in range(FLOOD):
        pub.put(b"garbage %d" % i)
    wait_for(
        lambda: counter(stack, "detector.bad_input") == FLOOD,
        60,
        lambda: f"{FLOOD} bad inputs counted (metrics: {counter(stack, 'detector.bad_input')})",
    )
    lines = warnings_of(stack, "detector")
    assert len(lines) < MAX_WARNING_LINES, "\n".join(lines[-10:])


def test_a_payload_over_the_limit_is_counted_by_its_publisher(stack: Stack) -> None:
    wait_for(lambda: counter(stack, "camera.payload_too_large") >= 2, 30, "refused camera frames")
    assert len(warnings_of(stack, "camera")) < MAX_WARNING_LINES


def matched(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """A publisher on ``key`` once a subscriber (the metrics service) is known to match it: a
    new session's first puts would otherwise go nowhere."""
    pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
    wait_for(lambda: pub.matching_status.matching, 30, f"a subscriber matching {key}")
    return pub


def test_rogue_counters_are_refused(stack: Stack) -> None:
    rogue = stack.open("observer")
    try:
        names = {f"rogue_{i}": i for i in range(2000)}
        pubs = [
            (matched(rogue, stack.keys.counters(key)), service)
            for key, service in (
                ("rogue", "rogue"),
                ("rogue", "detector"),
                ("detector", "detector"),
            )
        ]

        def put_all_and_check() -> bool:
            # Put again on every poll: telemetry may be dropped under congestion (a loaded CI).
            for pub, service in pubs:
                msg = ServiceCounters(header=header("rogue", 1), service=service, counters=names)
                pub.put(msg.encode())
            return (
                counter(stack, "metrics.refused.too_many_names") >= 1
                and counter(stack, "metrics.refused.unknown_service") >= 2
            )

        wait_for(put_all_and_check, 30, "the refusals")
        counters = stack.metrics()["counters"]  # type: ignore[index]
        assert not [n for n in counters if "rogue" in n]
        assert counters["metrics.refused.unknown_service"] >= 2
        # The real ones are still there: the detector serves its one camera. (Not frames_in:
        # every camera frame of this stack is over the payload limit, so a stack that got no
        # test's frames yet, as a worker of its own under xdist, has counted none.)
        assert counters["detector.serving"] == 1
    finally:
        rogue.close()


def test_an_absurd_stage_time_is_refused_and_the_answer_stays_json(stack: Stack) -> None:
    def no_constants(name: str) -> Any:
        raise ValueError(f"not JSON: {name}")

    rogue = stack.open("observer")
    try:
        pub = matched(rogue, stack.keys.detections("front"))
        sent = 0

        def put_some_and_count() -> bool:
            # Several, so that a mean of them would overflow to infinity; put again on every
            # poll: "matched" means some subscriber matches (this module's own session has one
            # too), not that the metrics service's link is up yet, so a new session's first
            # puts may reach only the others (issue 29, item 9: the count is exact, a put
            # before the link is not delivered).
            nonlocal sent
            for _ in range(3):
                sent += 1
                dets = Detections(
                    header=header("rogue", sent),
                    image_width=8,
                    image_height=8,
                    boxes=Boxes(),
                    class_names=(),
                    timing_ms={"inference": 1e308},
                )
                pub.put(dets.encode())
            return counter(stack, "metrics.refused.bad_timing") >= 3

        wait_for(
            put_some_and_count,
            30,
            lambda: f"3 refusals (counted {counter(stack, 'metrics.refused.bad_timing')})",
        )
        assert counter(stack, "metrics.refused.bad_timing") <= sent

        def raw_answer() -> str | None:
            for reply in stack.session.get(stack.keys.metrics(), timeout=2.0):
                if reply.ok is not None:
                    return str(reply.ok.payload.to_string())
            return None

        answer = json.loads(
            wait_for(raw_answer, 30, "a metrics answer"), parse_constant=no_constants
        )
        assert answer["latency_ms"]["inference"]["p99"] < 1e6
    finally:
        rogue.close()


def test_a_model_that_outputs_nan_is_counted_and_publishes_nothing(
    make_stack: Any, tmp_path: Path
) -> None:
    nan_stack: Stack = make_stack(
        supervisor={"services": ["camera", "detector", "metrics"]},
        detector={"model": str(constant_model(tmp_path, math.nan))},
    )
    nan_stack.wait_ready({"camera", "detector", "metrics"})
    _, dets = nan_stack.subscribe(nan_stack.keys.detections("front"))
    wait_for(lambda: counter(nan_stack, "detector.nonfinite_outputs") >= 3, 60, "NaN outputs")
    assert not dets, "detections published from NaN outputs"
    lines = [line for line in warnings_of(nan_stack, "detector") if "not finite" in line]
    assert 1 <= len(lines) <= 5
    assert nan_stack.stop() == 0, nan_stack.log()
