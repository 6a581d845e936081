"""What hostile messages can make a service keep, and what the robot takes, is bounded: huge
class names never reach the metrics' answer, and an absurd velocity never moves the base."""

from __future__ import annotations

import json
import math
import threading

import msgpack
import numpy as np
import pytest

from common.boxes import Boxes
from common.clock import now
from common.messages import Detections, GroundTruth, Twist
from tests.integration.conftest import Stack, wait_for
from tests.integration.test_safety import STACK, header

pytestmark = pytest.mark.integration

NAME_BYTES = 50_000  # each class name of the flood, as the attack sent them
MESSAGES, NAMES_EACH = 10, 100  # 1,000 names in all
ANSWER_LIMIT_BYTES = 200_000  # the metrics answer was 43.5 KB before the flood


def _with_body(message: bytes, **fields: object) -> bytes:
    """``message`` re-encoded with some of its body's fields replaced: what a hostile sender
    writes, which our own constructors refuse to build."""
    envelope = msgpack.unpackb(message)
    return bytes(msgpack.packb({**envelope, "d": {**envelope["d"], **fields}}))


def _flood_message(i: int) -> bytes:
    n = NAMES_EACH
    valid = Detections(
        header=header(now().wall_ns, source="flood"),
        image_width=640,
        image_height=480,
        boxes=Boxes(
            xyxy=np.tile(np.array([[10, 10, 20, 20]], np.float32), (n, 1)),
            scores=np.full(n, 0.9, np.float32),
            class_ids=np.arange(n, dtype=np.int32),
        ),
        class_names=("x",) * n,
    )
    names = [f"{i}-{k}-" + "x" * NAME_BYTES for k in range(n)]
    return _with_body(valid.encode(), class_names=names)


def test_huge_class_names_never_reach_the_metrics_answer(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack()
    stack.wait_ready(STACK)
    wait_for(lambda: (m := stack.metrics()) and m["frames"] > 0, 60, "metrics of real frames")
    pub = stack.session.declare_publisher(stack.keys.detections("front"))
    sent = [0]

    def after_flood() -> dict[str, object] | None:
        # Put until refused: a 5 MB put can be dropped under congestion (DROP), and the
        # flood is about what arrives.
        pub.put(_flood_message(sent[0]))
        sent[0] += 1
        m = stack.metrics()
        refused = m and m["counters"].get("metrics.bad_input", 0) >= MESSAGES
        return m if refused else None

    answer = wait_for(
        after_flood, 60, lambda: f"the metrics service to refuse the flood ({sent[0]} sent)",
        poll=0.2,
    )  # fmt: skip
    size = len(json.dumps(answer))
    assert size < ANSWER_LIMIT_BYTES, f"the metrics answer grew to {size} bytes"
    assert all(len(name) <= 128 for name in answer["class_counts"]), "a huge name was kept"
    # The service still counts the real detector's frames.
    before = answer["frames"]
    wait_for(lambda: (m := stack.metrics()) and m["frames"] > before, 30, "frames after the flood")
    assert stack.stop() == 0, stack.log()


def test_an_absurd_velocity_never_moves_the_base(make_stack) -> None:  # type: ignore[no-untyped-def]
    # The simulated base alone (no controller): whatever lands on cmd_vel is what it gets.
    stack: Stack = make_stack(supervisor={"services": ["sim", "metrics"]}, sim={"wait_for": []})
    stack.wait_ready({"sim", "metrics"})
    _, truths = stack.subscribe(stack.keys.sim_truth())
    wait_for(lambda: len(truths) > 2, 30, "the simulator's truth")
    start = GroundTruth.decode(truths[-1]).robot
    pub = stack.session.declare_publisher(stack.keys.cmd_vel())
    end = threading.Event()
    for _ in range(40):  # 2 s at 20 Hz, past the base's 0.5 s watchdog
        # 50 m/s decodes (the base refuses it); 1e308 does not decode (our constructor
        # refuses it, so it is written by hand).
        fifty = Twist(header=header(now().wall_ns, source="rogue"), linear=(50.0, 0.0, 0.0))
        pub.put(fifty.encode())
        pub.put(_with_body(fifty.encode(), linear=[1e308, 0.0, 0.0]))
        end.wait(0.05)
    last = GroundTruth.decode(list(truths)[-1]).robot
    moved = math.hypot(last[0] - start[0], last[1] - start[1])
    assert moved < 0.01, f"the base moved {moved:.2f} m on absurd commands"
    counters = wait_for(
        lambda: (
            (m := stack.metrics())
            and m["counters"].get("sim.commands_out_of_range", 0) > 0
            and m["counters"].get("sim.bad_input", 0) > 0
            and m["counters"]
        ),
        30,
        "the simulator to count both kinds of refusal",
    )
    assert counters["sim.commands_out_of_range"] >= 10, counters
    assert stack.stop() == 0, stack.log()
