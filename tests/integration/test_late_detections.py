"""Detections that come too late for the dead-man, on real processes (the metrics service under
the supervisor; the test's own session stands in for a slow detector): the metrics answer says
so with the figures and the fixes (``zstack query``), and the supervisor says it once, as a
WARNING, however many status lines name it.

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
from tests.integration.conftest import REPO, Stack, wait_for
from tests.integration.feeder import Feeder, header
from tests.integration.test_safety import person

pytestmark = pytest.mark.integration

# As a slow CPU: each frame's detections are published 0.9 s after its capture, five times a
# second. They arrive fresh (under the 1 s timeout) and go stale 0.1 s later, 0.1 s before the
# next one comes.
LATE_S = 0.9


def late_person() -> bytes:
    dets = person(header(LATE_S))
    return dataclasses.replace(dets, published_ns=now().wall_ns).encode()


def test_late_detections_are_said_once_with_the_fixes(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack(supervisor={"services": ["metrics"]})
    stack.wait_ready({"metrics"})
    stack.announce()  # the test stands in for the camera and the detector
    front = stack.keys.detections("front")
    feeder = Feeder(stack)
    rounds = itertools.count()  # the feeder's rounds are 50 ms apart: one in four, 5 Hz
    feeder.feed(lambda: {front: late_person()} if next(rounds) % 4 == 0 else {})
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
