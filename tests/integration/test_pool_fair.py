"""Fairness between robots (issue 39, item 3), with real processes: one detector worker serves
two robots (``detector.prefixes``). Robot 1 has one camera (its camera process, 5 Hz); robot 2,
standing in from the test's session, announces ``detector.max_robot_cameras`` cameras and two
more, and sends 5 frames a second on each. Before, the worker's rounds were fair per camera:
robot 1's camera had one in 17 and its detections came 1.29 s apart (measured in the issue
with 61 cameras), over the controller's 1 s dead-man. Now the rounds go to the robots in turn:
robot 1 gets its max-min fair share of the worker's rounds (every frame it sends, up to half
the rounds), a frame of its waits for at most one round of robot 2's, and robot 2's cameras
over the cap are refused, in one line each.

What is judged is relative to what the worker does, not to the machine: on a loaded machine
(a CI run beside CPU burners) the worker's rounds slow (0.2-4.7 s each, measured), so robot 1's
rate and gaps in seconds say how fast the CPU is, while its share of the rounds and the rounds
that overtake its frames say whether the pool is fair. On a machine where the worker does over
``2 * RATE_HZ`` frames a second, the share is every frame robot 1 sends."""

from __future__ import annotations

import itertools
import threading
import time
import uuid
from pathlib import Path

import numpy as np
import pytest

from common.announce import to_chunk
from common.clock import BOOT_ID, now
from common.frames import image_to_frame
from common.keys import Keys
from common.messages import CameraAnnouncement, Detections, Header
from services.detector.contract import DetectorSettings
from tests.integration.conftest import Stack, wait_for, write_config

pytestmark = pytest.mark.integration

NOTICE_S = 30.0
RATE_HZ = 5.0
MEASURE_S = 15.0  # robot 1's detections taken: about this long at its rate


def fair_share(served: list[tuple[int, Detections]], first: int) -> float:
    """Robot 1's detections from its ``first`` on over its max-min fair share of the worker's
    detections then (published by the worker between robot 1's ``first`` and its last): what
    it sends (RATE_HZ), or half of both robots', whichever is less (robot 2 always has frames
    waiting: 16 cameras at RATE_HZ)."""
    mine = [d.published_ns for robot, d in served if robot == 1][first:]
    lo, hi = mine[0], mine[-1]
    both = sum(1 for _, d in served if lo < d.published_ns <= hi)
    return (len(mine) - 1) / min(RATE_HZ * (hi - lo) / 1e9, both / 2)


def longest_round(served: list[tuple[int, Detections]], first: int) -> float:
    """The longest the worker took over a round (seconds between two of its publications, of
    either robot) from robot 1's ``first`` detection to its last: robot 2 keeps it busy."""
    mine = [d.published_ns for robot, d in served if robot == 1][first:]
    times = sorted(d.published_ns for _, d in served if mine[0] <= d.published_ns <= mine[-1])
    return max(b - a for a, b in itertools.pairwise(times)) / 1e9


def test_a_robot_announcing_many_cameras_does_not_starve_another_with_one(
    tmp_path: Path,
) -> None:
    robot1, robot2 = (f"test/{uuid.uuid4().hex[:8]}" for _ in range(2))
    cap = DetectorSettings().max_robot_cameras
    config = write_config(
        tmp_path,
        stack={"prefix": robot1, "camera": "front"},
        supervisor={"services": ["camera", "detector", "metrics"], "status_period_s": 1.0},
        camera={"source": "sample:cameraman", "rate_hz": RATE_HZ, "resize": [320, 240]},
        detector={"imgsz": 320, "prefixes": [robot1, robot2]},  # the pool under robot 1's
    )
    stack = Stack(config, tmp_path / "supervisor.log")
    stop = threading.Event()
    sender: threading.Thread | None = None
    try:
        stack.wait_ready({"camera", "detector", "metrics"})
        keys2 = Keys(robot2)
        session = stack.session
        names = [f"c{i:02d}" for i in range(cap + 2)]
        tokens = [
            session.liveliness().declare_token(
                keys2.camera_announcement(
                    name,
                    to_chunk(
                        CameraAnnouncement(
                            camera=name, width=160, height=120, rate_hz=RATE_HZ, source="test"
                        )
                    ),
                )
            )
            for name in names
        ]
        image = np.full((120, 160, 3), 114, np.uint8)
        publishers = {name: session.declare_publisher(keys2.frame(name)) for name in names}

        def send() -> None:
            for seq in itertools.count(1):
                if stop.wait(1 / RATE_HZ):
                    return
                for name, pub in publishers.items():
                    at = now()
                    header = Header(
                        stamp_ns=at.wall_ns, mono_ns=at.mono_ns, boot_id=BOOT_ID,
                        frame_id=name, seq=seq, source="robot2",
                    )  # fmt: skip
                    pub.put(image_to_frame(image, header).encode())

        sender = threading.Thread(target=send, daemon=True)
        sender.start()
        arrivals: list[float] = []
        seen2: set[str] = set()
        served: list[tuple[int, Detections]] = []  # (robot, its detections), as they came

        def on_detections(sample: object) -> None:
            key = str(sample.key_expr)  # type: ignore[attr-defined]
            if key == stack.keys.detections("front"):
                arrivals.append(time.monotonic())
                served.append((1, Detections.decode(bytes(sample.payload))))  # type: ignore[attr-defined]
            elif key.startswith(robot2 + "/"):
                seen2.add(key.split("/")[-2])
                served.append((2, Detections.decode(bytes(sample.payload))))  # type: ignore[attr-defined]

        sub = session.declare_subscriber(f"{robot1}/detector/*/detections", on_detections)
        sub2 = session.declare_subscriber(keys2.all_detections(), on_detections)
        wait_for(
            lambda: len(seen2) >= cap // 2,
            NOTICE_S,
            lambda: f"robot 2's cameras served: {sorted(seen2)}\n{stack.log()}",
        )
        start, start_all = len(arrivals), len(served)
        wanted = int(RATE_HZ * MEASURE_S * 0.8)
        # Robot 1's detections wanted, or the worker's rounds that would have given them to
        # it at a fair share (a loaded machine's worker does 2-6 rounds a second): judged below.
        wait_for(
            lambda: len(arrivals) - start >= wanted or len(served) - start_all >= 4 * wanted,
            MEASURE_S * 8,
            lambda: f"{wanted} detections of robot 1's camera: {len(arrivals) - start}",
        )
        got = arrivals[start:]
        span = got[-1] - got[0]
        published = [d.published_ns for robot, d in list(served) if robot == 1][start:]
        gaps = [(b - a) / 1e9 for a, b in itertools.pairwise(published)]  # on the worker's clock
        share = fair_share(list(served), start)
        rounds_s = longest_round(list(served), start)
        # Robot 1's next frame comes within its period (a second one: the camera's own
        # jitter), then waits for the round under way and is taken in the next.
        bound_s = 2 / RATE_HZ + 2 * rounds_s
        print(
            f"robot 1's camera beside robot 2's {cap} served cameras: "
            f"{(len(got) - 1) / span:.2f} Hz, longest gap {max(gaps):.2f} s, "
            f"{share:.2f} of its fair share, rounds up to {rounds_s:.2f} s; robot 2's "
            f"cameras served {len(seen2)}"
        )
        # Every frame it sends, or near, as far as the worker's rounds go (before: about one
        # in 17 rounds, a tenth of its share).
        assert share >= 0.6, (share, (len(got) - 1) / span, max(gaps))
        # A frame of its waits for no more than the round under way (before: for the rounds
        # of robot 2's cameras that had waited longer). With the worker's rounds short (under
        # 0.3 s: a worker of 3 frames a second or more), within the controller's dead-man.
        assert max(gaps) <= bound_s, (max(gaps), bound_s, len(got))
        assert len(seen2) <= cap
        text = stack.log_path.read_text(errors="replace")
        refused = [line for line in text.splitlines() if "refused by the pool" in line]
        assert len(refused) == 2, refused
        sub.undeclare()
        sub2.undeclare()
        for token in tokens:
            token.undeclare()
    finally:
        stop.set()
        if sender is not None:
            sender.join(timeout=5)
        if stack.proc.poll() is None:
            assert stack.stop() == 0, stack.log()
