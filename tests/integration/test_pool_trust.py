"""What the pool cannot refuse it must say (issues 29 and 31).

One stack (two cameras, each announced by its camera process, one real detector worker, the
metrics service) is shared by the tests of this module, which only add tokens from a raw
session or start a process beside it:

1. a bare pool token from a raw session (no worker announcement) is no member: the worker
   goes on serving both cameras, and says it ignores the token; a member that announces itself
   and serves nothing (a hung worker) leaves a camera unserved: both are a WARNING in the
   worker's log and in the metrics answer, and both clear when its tokens go;
2. a serving token for a camera the worker serves, from another session under the worker's
   own name: the camera served twice and the name held twice, in the log and the answer;
3. a second worker started with the live worker's name refuses to start, in one line;
4. a second real worker whose config names fewer cameras (another camera table) takes its
   share of the announced cameras: each camera is served by exactly one of the two.
"""

from __future__ import annotations

import signal
import subprocess
import sys
from collections.abc import Iterator
from typing import Any

import pytest

from common.announce import from_chunk, to_chunk
from common.messages import WorkerAnnouncement
from common.pool_rule import assign, camera_rates
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
        # A member that never delivers is dropped after pool_deliver_s (test_pool_earned.py);
        # here it must stay long enough for its warnings to be read.
        detector={"imgsz": 320, "pool_alarm_s": ALARM_S, "pool_deliver_s": 600.0},
    )
    stack = Stack(config, tmp / "supervisor.log")
    try:
        stack.wait_ready({"camera", "camera_rear", WORKER, "metrics"})
        yield stack
    finally:
        if stack.proc.poll() is None:
            assert stack.stop() == 0, stack.log()


def warnings(stack: Stack, *needles: str, since: int = 0) -> list[str]:
    """The worker's WARNING lines that contain every one of ``needles`` (in the log after its
    first ``since`` characters)."""
    text = stack.log_path.read_text(errors="replace")[since:]
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


def capacity_of(stack: Stack, worker: str) -> float:
    """The capacity ``worker`` announces (its WorkerAnnouncement's, from its token's key)."""
    keys = stack.keys
    [reply] = stack.session.liveliness().get(keys.worker_announcements_of(worker), timeout=5.0)
    parts = keys.worker_announcement_parts(str(reply.ok.key_expr))
    assert parts is not None
    return from_chunk(WorkerAnnouncement.decode, parts[1]).capacity_hz


def settled(stack: Stack) -> bool:
    """The worker serves both cameras, and nothing is wrong in the metrics answer."""
    return served_by(stack) == {"front": WORKER, "rear": WORKER} and answer_warnings(stack) == []


def test_a_stray_token_and_a_second_server_are_warnings(stack: Stack) -> None:
    keys = stack.keys
    wait_for(lambda: settled(stack), NOTICE_S, lambda: f"a settled pool:\n{stack.log()}")
    rogue = stack.open("observer")
    try:
        # 1. A bare token is no member: nothing moves, one line says it is ignored.
        stray = rogue.liveliness().declare_token(keys.pool_member("zy"))
        wait_for(
            lambda: warnings(stack, "no worker announcement ignored (no member): zy"),
            NOTICE_S,
            lambda: f"the worker's warnings:\n{stack.log()}",
        )
        assert settled(stack), answer_warnings(stack)
        stray.undeclare()
        # A member that serves nothing: the rule gives it a camera, which nobody serves.
        [given] = [
            c
            for c, w in assign([WORKER, "zz"], camera_rates(stack.config.all_cameras), 1.0).items()
            if w == "zz"
        ]
        # As fast as the worker says it is: the pool splits as the metrics' audit (equal
        # capacities over the config's cameras) computes it.
        hung = WorkerAnnouncement(
            worker="zz", capacity_hz=capacity_of(stack, WORKER), prefixes=(keys.prefix,)
        )
        own = rogue.liveliness().declare_token(keys.worker_announcement("zz", to_chunk(hung)))
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
        own.undeclare()
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


def test_a_worker_with_another_camera_table_takes_its_share_of_the_announced_cameras(
    stack: Stack, tmp_path_factory: pytest.TempPathFactory
) -> None:
    # A second real worker on the same bus whose config names only front: the cameras are
    # the announced ones, so the two divide front and rear, each served once (before, the two
    # computed the assignment over different tables: a camera served twice or by nobody).
    config = stack.config
    other = write_config(
        tmp_path_factory.mktemp("other_table"),
        zenoh={"endpoint": config.zenoh.endpoint, "multicast_scouting": False},
        stack={"prefix": config.stack.prefix, "camera": "front"},
        camera={"source": "sample:cameraman", "rate_hz": 7.0, "resize": [320, 240]},
        detector={"imgsz": 320, "pool_alarm_s": ALARM_S, "workers": 2},
    )
    since = len(stack.log_path.read_text(errors="replace"))
    worker = subprocess.Popen(
        [sys.executable, "-m", "services.detector", "serve",
         "--config", str(other), "--worker", "detector_2"],
        cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True,
    )  # fmt: skip
    try:
        keys = stack.keys
        wait_for(
            lambda: keys.health("detector_2") in {str(r.ok.key_expr) for r in
                stack.session.liveliness().get(keys.all_health(), timeout=2.0) if r.ok},
            STARTUP_S,
            lambda: f"the second worker ready:\n{stack.log()}",
        )  # fmt: skip
        # Each announced camera served by exactly one of the two, whichever the capacities
        # give it to, and no warning of a camera served twice or by nobody in the meantime.
        wait_for(
            lambda: (
                set(served_by(stack)) == {"front", "rear"}
                and all(w in (WORKER, "detector_2") for w in served_by(stack).values())
            ),
            NOTICE_S,
            lambda: f"each camera served by one worker: {served_by(stack)}",
        )
        assert not warnings(stack, "is served by 2 workers", since=since)
        assert not warnings(stack, "is served by no detector worker", since=since)
    finally:
        worker.send_signal(signal.SIGINT)
        assert worker.wait(timeout=30) == 0
    wait_for(lambda: settled(stack), NOTICE_S, lambda: f"cleared: {answer_warnings(stack)}")
