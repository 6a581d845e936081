"""A worker earns its cameras by delivering (issue 39, item 2), with real processes: a stack of
two cameras, one detector worker and the metrics service. A raw session announces a worker of
the highest capacity there is, with forged serving tokens for both cameras, and never detects:
before, it took both cameras for good (the robot's detections stopped, and with the forged
tokens no warning at all). Now the real worker, seeing no detections of them come, takes them
back within ``detector.pool_deliver_s``, the cameras' detections come again, and the worker's
log and the metrics answer say which member was dropped and why.

A second test (item 2's last case): two real workers, and a raw session that re-announces the
live ``detector_2`` at the highest capacity (as a second process with its credentials would
under the password profile). Before, ``detector`` believed the claim and served nothing while
``detector_2`` served its own share: the other camera went unserved for as long as the claim
lived (``detector_2`` delivers on its camera, so it is never dropped). Now every view counts the
name with the lowest capacity announced: no camera moves, and both say the name is announced
twice."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from common.announce import to_chunk
from common.keys import camera_in_key
from common.messages import WorkerAnnouncement
from services.detector.contract import MAX_CAPACITY_HZ
from tests.integration.conftest import Stack, wait_for, write_config

pytestmark = pytest.mark.integration

DELIVER_S = 3.0  # detector.pool_deliver_s here
ALARM_S = 1.0  # detector.pool_alarm_s
NOTICE_S = 30.0  # a line in the log, an answer, on a loaded machine
WORKER = "detector"
CAMERAS = ("front", "rear")


def test_a_liar_that_claims_every_camera_and_never_detects_loses_them(tmp_path: Path) -> None:
    config = write_config(
        tmp_path,
        supervisor={"services": ["camera", "detector", "metrics"], "status_period_s": 1.0},
        camera={"source": "sample:cameraman", "rate_hz": 4.0, "resize": [320, 240]},
        **{"cameras.rear": {"source": "sample:coffee", "frame_id": "rear"}},
        detector={
            "imgsz": 320,
            "pool_alarm_s": ALARM_S,
            "pool_deliver_s": DELIVER_S,
            "pool_readmit_s": 600.0,  # dropped for the rest of the test
        },
    )
    stack = Stack(config, tmp_path / "supervisor.log")
    try:
        stack.wait_ready({"camera", "camera_rear", WORKER, "metrics"})
        keys = stack.keys
        received: list[str] = []  # the camera of each Detections heard, in order
        sub = stack.session.declare_subscriber(
            keys.all_detections(), lambda s: received.append(camera_in_key(str(s.key_expr)) or "")
        )
        wait_for(lambda: len(received) >= 4, NOTICE_S, lambda: f"detections:\n{stack.log()}")
        rogue = stack.open("observer")
        liar = WorkerAnnouncement(worker="zz", capacity_hz=MAX_CAPACITY_HZ, prefixes=(keys.prefix,))
        liveliness = rogue.liveliness()
        tokens = [
            liveliness.declare_token(keys.worker_announcement("zz", to_chunk(liar))),
            liveliness.declare_token(keys.pool_member("zz")),
            *(
                liveliness.declare_token(keys.pool_serving("zz", str(rogue.info.zid()), cam))
                for cam in CAMERAS
            ),
        ]
        since = time.monotonic()
        try:
            # The claim wins both cameras at first: the worker serves nothing ...
            wait_for(
                lambda: "serving no camera" in stack.log(),
                NOTICE_S,
                lambda: f"the liar taking the cameras:\n{stack.log()}",
            )
            # ... until it sees that no detection of them comes: it takes them back.
            wait_for(
                lambda: "pool member zz delivered no detections" in stack.log(),
                NOTICE_S,
                lambda: f"the worker dropping the liar:\n{stack.log()}",
            )
            took_s = time.monotonic() - since
            # Detections of both cameras come again, from the real worker.
            count = len(received)
            wait_for(
                lambda: set(received[count:]) >= set(CAMERAS),
                NOTICE_S,
                lambda: f"detections again:\n{stack.log()}",
            )
            back_s = time.monotonic() - since
            # The metrics answer says which member was dropped, whatever its tokens said.
            wait_for(
                lambda: any(
                    "pool member zz, dropped from the pool" in w
                    for w in (stack.metrics() or {}).get("pool_warnings", [])
                ),
                NOTICE_S,
                lambda: f"the metrics' warnings: {(stack.metrics() or {}).get('pool_warnings')}",
            )
            print(
                f"liar dropped {took_s:.1f} s after it came (bound {DELIVER_S} s, seen on the "
                f"log); both cameras' detections back after {back_s:.1f} s"
            )
        finally:
            for token in tokens:
                token.undeclare()
            rogue.close()
            sub.undeclare()
    finally:
        if stack.proc.poll() is None:
            assert stack.stop() == 0, stack.log()


def test_a_second_session_claiming_a_live_workers_name_leaves_no_camera_unserved(
    tmp_path: Path,
) -> None:
    config = write_config(
        tmp_path,
        supervisor={"services": ["camera", "detector", "metrics"], "status_period_s": 1.0},
        camera={"source": "sample:cameraman", "rate_hz": 4.0, "resize": [320, 240]},
        **{"cameras.rear": {"source": "sample:coffee", "frame_id": "rear"}},
        detector={
            "workers": 2,
            "capacity_hz": 10.0,  # equal and fixed: one camera each, no move of its own
            "imgsz": 320,
            "pool_alarm_s": ALARM_S,
            "pool_deliver_s": DELIVER_S,
        },
    )
    stack = Stack(config, tmp_path / "supervisor.log")
    twin = "detector_2"
    try:
        stack.wait_ready({"camera", "camera_rear", WORKER, twin, "metrics"})
        keys = stack.keys

        def served_by() -> dict[str, str]:
            answer = stack.metrics() or {}
            return {c: m["served_by"] for c, m in answer.get("cameras", {}).items()}

        wait_for(
            lambda: sorted(served_by().values()) == [WORKER, twin],
            NOTICE_S,
            lambda: f"one camera each: {served_by()}\n{stack.log()}",
        )
        split = served_by()
        received: list[str] = []
        sub = stack.session.declare_subscriber(
            keys.all_detections(), lambda s: received.append(camera_in_key(str(s.key_expr)) or "")
        )
        rogue = stack.open("observer")
        claim = WorkerAnnouncement(
            worker=twin, capacity_hz=MAX_CAPACITY_HZ, prefixes=(keys.prefix,)
        )
        since = len(stack.log_path.read_text(errors="replace"))

        def unserved() -> list[str]:
            text = stack.log_path.read_text(errors="replace")[since:]
            return [line for line in text.splitlines() if "served by no detector worker" in line]

        def said_twice() -> bool:
            if unserved():  # before: the camera the claim took from detector, nobody's
                raise AssertionError(f"a camera went unserved: {unserved()}")
            warned = (stack.metrics() or {}).get("pool_warnings", [])
            return any(f"worker name {twin} is announced by 2 sessions" in w for w in warned)

        token = rogue.liveliness().declare_token(keys.worker_announcement(twin, to_chunk(claim)))
        try:
            wait_for(said_twice, NOTICE_S, lambda: f"the name announced twice:\n{stack.log()}")
            count = len(received)
            wait_for(
                lambda: set(received[count:]) >= set(CAMERAS),
                NOTICE_S,
                lambda: f"both cameras' detections:\n{stack.log()}",
            )
            assert not unserved(), unserved()
            assert served_by() == split, "the claim moved a camera"
            assert (
                f"worker name {twin} is announced by 2 sessions"
                in stack.log_path.read_text(errors="replace")[since:]
            )
        finally:
            token.undeclare()
            rogue.close()
            sub.undeclare()
    finally:
        if stack.proc.poll() is None:
            assert stack.stop() == 0, stack.log()
