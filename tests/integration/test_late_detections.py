"""Detections that come too late for the dead-man, on real processes (the metrics service under
the supervisor; the test's own session stands in for a slow detector): the metrics answer says
so with the figures and the fixes (``zstack query``), and the supervisor says it once, as a
WARNING, however many status lines name it. The camera has depth (issue 32): the query's lines
and JSON carry the depth figures (the detector's depth counters, the depth stage's time) too.

The controller's side (it flips between stale and moving on each detection, and summarises the
flip-flop instead of logging each change) and the warning's text for each case are in-process:
tests/unit/controller/test_loop.py and tests/unit/metrics/test_service.py, test_advice.py.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import subprocess
import sys

import pytest

from common.clock import now
from common.messages import ServiceCounters
from tests.integration.conftest import REPO, Stack, wait_for
from tests.integration.feeder import Feeder, header
from tests.integration.test_safety import person

pytestmark = pytest.mark.integration

# As a slow CPU: each frame's detections are published 0.9 s after its capture, five times a
# second. They arrive fresh (under the 1 s timeout) and go stale 0.1 s later, 0.1 s before the
# next one comes.
LATE_S = 0.9


DEPTH_COUNTERS = {"depth_in": 40, "depth_unpaired": 3, "depth_in.front": 40,
                  "depth_unpaired.front": 3, "frames_in.front": 43}  # fmt: skip


def late_person() -> bytes:
    dets = person(header(LATE_S))
    timing = {"depth": 4.0}  # the depth stage of a depth camera's frame
    return dataclasses.replace(dets, published_ns=now().wall_ns, timing_ms=timing).encode()


def depth_counters() -> bytes:
    """The detector's counters, as a worker serving a depth camera counts them."""
    return ServiceCounters(header=header(), service="detector", counters=DEPTH_COUNTERS).encode()


def test_late_detections_are_said_once_with_the_fixes(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack(supervisor={"services": ["metrics"]})
    stack.wait_ready({"metrics"})
    stack.announce(depth=True, mount_height_m=0.5)  # the test: the camera and the detector
    front = stack.keys.detections("front")
    counters = stack.keys.counters("detector")
    feeder = Feeder(stack)
    rounds = itertools.count()  # the feeder's rounds are 50 ms apart: one in four, 5 Hz
    feeder.feed(
        lambda: {front: late_person(), counters: depth_counters()} if next(rounds) % 4 == 0 else {}
    )
    try:
        wait_for(
            lambda: stack.log().count("WARNING detections_late") >= 3, 60, "three status lines"
        )
        query = subprocess.run(
            [sys.executable, "-m", "services.metrics", "query", "--config",
             str(stack.config_path)],
            cwd=REPO, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert query.returncode == 0, query.stderr
        told = json.loads(query.stdout)["warnings"]["detections_late"]
        # Before the JSON, for a person: the cameras announced, and the warning as a line.
        prefix = stack.config.stack.prefix
        assert f"cameras announced under {prefix}: 1\n  front " in query.stderr, query.stderr
        assert f"WARNING detections_late: {told}" in query.stderr, query.stderr
        answer = json.loads(query.stdout)
        assert (answer["depth_frames"], answer["depth_unpaired"]) == (40, 3)
        assert answer["cameras"]["front"]["depth_frames"] == 40
        assert answer["latency_ms"]["depth"]["p50"] == 4.0
        assert answer["cameras_announced"]["front"]["depth"] is True
        assert "  depth  at x +0.00 y +0.00 height 0.50 m\n" in query.stderr, query.stderr
        assert (
            "depth: 40 depth images, 3 colour frames without depth in time, "
            "depth stage p50 4.0 ms p95 4.0 ms\n  front: 40 depth images, 3 without depth"
        ) in query.stderr, query.stderr
    finally:
        feeder.close()
    assert stack.stop() == 0, stack.log()
    log = stack.log_path.read_text()
    for text in (told, log):
        assert "detections come too late" in text and "p95" in text, text
        assert 'detector.profile = "fast"' in text and "detector.imgsz" in text, text
        assert "controller.detection_timeout_s" in text, text
    # Said once, as a WARNING, however many status lines name it.
    assert log.count("detections come too late") == 1, log
    assert "supervisor WARNING detections come too late" in log, log
