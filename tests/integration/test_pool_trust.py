"""The pool trusts whoever holds a token (issue 29): what it cannot refuse yet it must say.

One stack (two cameras, one real detector worker, the metrics service) is shared by the tests
of this module, which only add tokens from a raw session or start a process beside it:

1. a stray pool token from a raw session (a member that serves nothing) leaves a camera
   unserved: both are a WARNING in the worker's log and in the metrics answer, and both clear
   when the token goes;
2. a serving token for a camera the worker serves, from another session under the worker's
   own name: the camera served twice and the name held twice, in the log and the answer;
3. a second worker started with the live worker's name refuses to start, in one line;
4. a second real worker whose config names fewer cameras (another camera table) leaves a
   camera unserved: a WARNING in the first worker's log and in the metrics answer.
"""

from __future__ import annotations

import signal
import subprocess
import sys
from collections.abc import Iterator
from typing import Any

import pytest

from common.pool_rule import assign, camera_weights
from tests.integration.conftest import REPO, STARTUP_S, Stack, wait_for, write_config

pytestmark = pytest.mark.integration

ALARM_S = 1.0  # detector.pool_alarm_s here: the smallest allowed, so the test is short
NOTICE_S = 30.0  # a warning in the log and the answer, on a loaded machine
WORKER = "detector"


@pytest.fixture(scope="module")
def stack(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Stack]:
    tmp = tmp_path_factory.mktemp("pool_trust")
    config = write_config(
        tmp,
        supervisor={"services": ["camera", "detector", "metrics"], "status_period_s": 1.0},
        camera={"source": "sample:cameraman", "rate_hz": 2.0, "resize": [320, 240]},
        **{"cameras.rear": {"source": "sample:coffee", "frame_id": "rear"}},
        detector={"imgsz": 320, "pool_alarm_s": ALARM_S},
    )
    stack = Stack(config, tmp / "supervisor.log")
    try:
        stack.wait_ready({"camera", "camera_rear", WORKER, "metrics"})
        yield stack
    finally:
        if stack.proc.poll() is None:
            assert stack.stop() == 0, stack.log()


def warnings(stack: Stack, *needles: str) -> list[str]:
    """The worker's WARNING lines that contain every one of ``needles``."""
    text = stack.log_path.read_text(errors="replace")
    return [
        line
        for line in text.splitlines()
        if f" {WORKER} WARNING " in line and all(n in line for n in needles)
    ]


def answer_warnings(stack: Stack) -> list[str] | None:
    answer = stack.metrics()
    return None if answer is None else list(answer.get("pool_warnings", ["(none: old answer)"]))


def served_by(stack: Stack) -> dict[str, Any]:
    answer = stack.metrics() or {}
    return {c: m["served_by"] for c, m in answer.get("cameras", {}).items()}


def settled(stack: Stack) -> bool:
    """The worker serves both cameras, and nothing is wrong in the metrics answer."""
    return served_by(stack) == {"front": WORKER, "rear": WORKER} and answer_warnings(stack) == []


def test_a_stray_token_and_a_second_server_are_warnings(stack: Stack) -> None:
    keys = stack.keys
    wait_for(lambda: settled(stack), NOTICE_S, lambda: f"a settled pool:\n{stack.log()}")
    rogue = stack.open("observer")
    try:
        # 1. A member that serves nothing: the rule gives it a camera, which nobody serves.
        [given] = [
            c
            for c, w in assign(
                [WORKER, "zz"], camera_weights(stack.config.all_cameras), 1.0
            ).items()
            if w == "zz"
        ]
        stray = rogue.liveliness().declare_token(keys.pool_member("zz"))
        wait_for(
            lambda: (
                warnings(stack, "pool member zz serves none")
                and warnings(stack, f"camera {given} is served by no detector worker")
            ),
            NOTICE_S,
            lambda: f"the worker's warnings:\n{stack.log()}",
        )
        wait_for(
            lambda: (
                (w := answer_warnings(stack))
                and any("pool member zz" in x for x in w)
                and any(f"camera {given} is served by no" in x for x in w)
            ),
            NOTICE_S,
            lambda: f"the warnings in the metrics answer: {answer_warnings(stack)}",
        )
        stray.undeclare()
        wait_for(lambda: settled(stack), NOTICE_S, lambda: f"cleared: {answer_warnings(stack)}")

        # 2. Another process serving front under the worker's name: twice, both ways.
        twin = rogue.liveliness().declare_token(
            keys.pool_serving(WORKER, str(rogue.info.zid()), "front")
        )
        wait_for(
            lambda: (
                warnings(stack, "camera front is served by 2 workers")
                and warnings(stack, f"worker name {WORKER} is held by 2 processes")
            ),
            NOTICE_S,
            lambda: f"the worker's warnings:\n{stack.log()}",
        )
        wait_for(
            lambda: (
                (w := answer_warnings(stack))
                and any("camera front is served by 2" in x for x in w)
                and any(f"worker name {WORKER} is held by 2" in x for x in w)
            ),
            NOTICE_S,
            lambda: f"the warnings in the metrics answer: {answer_warnings(stack)}",
        )
        twin.undeclare()
        wait_for(lambda: settled(stack), NOTICE_S, lambda: f"cleared: {answer_warnings(stack)}")
    finally:
        rogue.close()


def test_a_second_worker_with_a_live_name_refuses_to_start(stack: Stack) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "services.detector", "serve",
         "--config", str(stack.config_path), "--worker", WORKER],
        cwd=REPO, capture_output=True, text=True, timeout=STARTUP_S,
    )  # fmt: skip
    assert done.returncode != 0, done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    # Its log until then (the model it loaded) and one line that says why it stops.
    [why] = [line for line in done.stderr.splitlines() if " INFO " not in line]
    assert why.startswith("error:") and f"{WORKER!r} is already in the pool" in why, why
    # The live worker was not disturbed: it still serves both cameras.
    assert served_by(stack) == {"front": WORKER, "rear": WORKER}


def test_a_worker_with_another_camera_table_is_a_warning(
    stack: Stack, tmp_path_factory: pytest.TempPathFactory
) -> None:
    # A second real worker on the same bus whose config names only front: the two compute
    # the assignment over different tables, so a camera is served twice or by nobody.
    config = stack.config
    other = write_config(
        tmp_path_factory.mktemp("other_table"),
        zenoh={"endpoint": config.zenoh.endpoint, "multicast_scouting": False},
        stack={"prefix": config.stack.prefix, "camera": "front"},
        camera={"source": "sample:cameraman", "rate_hz": 2.0, "resize": [320, 240]},
        detector={"imgsz": 320, "pool_alarm_s": ALARM_S, "workers": 2},
    )
    members = [WORKER, "detector_2"]
    mine = assign(members, camera_weights(config.all_cameras), 1.0)
    theirs = assign(members, {"front": 1.0}, 1.0)
    servers = {c: {w for w in members if (mine if w == WORKER else theirs).get(c) == w}
               for c in config.all_cameras}  # fmt: skip
    twice = sorted(c for c, s in servers.items() if len(s) == 2)
    nobody = sorted(c for c, s in servers.items() if not s)
    assert twice or nobody  # the two tables disagree on something for these names
    worker = subprocess.Popen(
        [sys.executable, "-m", "services.detector", "serve",
         "--config", str(other), "--worker", "detector_2"],
        cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True,
    )  # fmt: skip
    try:
        expected = [f"camera {c} is served by 2 workers" for c in twice] + [
            f"camera {c} is served by no detector worker" for c in nobody
        ]
        wait_for(
            lambda: all(warnings(stack, e) for e in expected),
            STARTUP_S,
            lambda: f"the worker's warnings {expected}:\n{stack.log()}",
        )
        wait_for(
            lambda: (w := answer_warnings(stack)) and all(any(e in x for x in w) for e in expected),
            NOTICE_S,
            lambda: f"{expected} in the metrics answer: {answer_warnings(stack)}",
        )
    finally:
        worker.send_signal(signal.SIGINT)
        assert worker.wait(timeout=30) == 0
    wait_for(lambda: settled(stack), NOTICE_S, lambda: f"cleared: {answer_warnings(stack)}")
