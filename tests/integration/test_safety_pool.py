"""The secure profile with a detector pool (issue 23): two real workers under the real
supervisor, each joining as its own principal (``detector``, ``detector_2``), two real cameras.
Detections flow from both workers; a worker's principal may not put frames, commands or the
e-stop, nor declare another worker's pool token: the router's access control drops them, and
the workers' membership and assignment do not change.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh

from common.clock import mono_s, now
from common.messages import Detections, Frame, Header, ServiceCounters
from common.security import stack_principals
from tests.integration.conftest import STARTUP_S, Stack, credentials_for, wait_for
from tests.integration.test_safety import person
from tests.integration.test_safety_cameras import marked_frame, put_until_allowed_arrive

pytestmark = pytest.mark.integration

CAMERAS = {"front": "camera", "rear": "camera_rear"}  # camera -> its principal
WORKERS = ("detector", "detector_2")  # detector.workers = 2: each its own principal
ROGUE = "detector_2"  # the worker whose credentials the test acts with
#: Reports of each worker's counters (one a second) after the rogue tokens, all still saying
#: two members: a token the router let through reaches the workers well within one.
QUIET_REPORTS = 3


class Heard:
    """Each worker's counters as they come (arrival, counters), and every sample on the keys
    no worker may put on."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.counters: dict[str, list[tuple[float, dict[str, int]]]] = {}
        self.forbidden: list[str] = []

    def on_counters(self, sample: zenoh.Sample) -> None:
        msg = ServiceCounters.decode(sample.payload.to_bytes())
        with self.lock:
            self.counters.setdefault(msg.service, []).append((mono_s(), dict(msg.counters)))

    def on_forbidden(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.forbidden.append(str(sample.key_expr))

    def reports(self, worker: str, after: float = 0.0) -> list[dict[str, int]]:
        with self.lock:
            return [c for t, c in self.counters.get(worker, []) if t > after]

    def split(self, after: float = 0.0) -> dict[str, frozenset[str]] | None:
        """Each worker's cameras (its latest ``serving.<cam>``) once they serve one each."""
        out = {}
        for w in WORKERS:
            reports = self.reports(w, after)
            if not reports:
                return None
            out[w] = frozenset(c for c in CAMERAS if reports[-1].get(f"serving.{c}", 0) > 0)
        if sorted(len(c) for c in out.values()) != [1, 1] or len(set(out.values())) != 2:
            return None
        return out


@pytest.fixture
def pool(make_stack: Any, tmp_path: Path) -> Iterator[tuple[Stack, Heard]]:
    creds = tmp_path / "credentials"
    prefix = credentials_for(creds, stack_principals(CAMERAS, WORKERS))
    stack: Stack = make_stack(
        zenoh={"mode": "client", "auth": "password", "credentials_dir": str(creds)},
        stack={"prefix": prefix},
        supervisor={"services": ["camera", "detector", "metrics"]},
        camera={
            "source": "sample:cameraman",
            "frame_id": "front",
            "rate_hz": 3.0,
            "resize": [320, 240],
        },
        **{"cameras.rear": {"source": "sample:astronaut", "frame_id": "rear"}},
        detector={"workers": 2, "imgsz": 320, "capacity_hz": 10.0},
    )
    heard = Heard()
    keys = stack.keys
    subs = [
        stack.session.declare_subscriber(keys.all_counters(), heard.on_counters),
        stack.session.declare_subscriber(keys.cmd_vel(), heard.on_forbidden),
        stack.session.declare_subscriber(keys.estop(), heard.on_forbidden),
    ]
    stack.wait_ready({*CAMERAS.values(), *WORKERS, "metrics"})
    yield stack, heard
    for sub in subs:
        sub.undeclare()
    assert stack.stop() == 0, stack.log()


def test_each_worker_is_a_principal_that_may_detect_and_nothing_else(
    pool: tuple[Stack, Heard],
) -> None:
    stack, heard = pool
    keys = stack.keys

    # Both workers joined as their own principals, their pool tokens let through: they split
    # the cameras, and each one's detections flow.
    split = wait_for(heard.split, STARTUP_S, lambda: f"a split:\n{stack.log()}")
    _, dets = stack.subscribe(keys.all_detections())
    started = mono_s()
    wait_for(
        lambda: all(
            (r := heard.reports(w, started))
            and r[-1].get("detections_out", 0) > r[0].get("detections_out", 0)
            for w in WORKERS
        ),
        60,
        lambda: f"detections from both workers:\n{stack.log()}",
    )
    wait_for(
        lambda: {Detections.decode(d).header.frame_id for d in list(dets)} >= set(CAMERAS),
        30,
        "detections of every camera",
    )

    # The pool as the workers see it, and as a liveliness query answers.
    def members() -> set[str]:
        replies = stack.session.liveliness().get(keys.all_pool_members(), timeout=2.0)
        return {str(r.ok.key_expr).rsplit("/", 1)[-1] for r in replies if r.ok is not None}

    assert members() == set(WORKERS)

    viewer = stack.open("viewer")  # may read every camera's frames
    frames: list[Header] = []
    viewer.declare_subscriber(keys.all_frames(), lambda s: frames.append(_header(s)))
    rogue = stack.open(ROGUE)
    try:
        # A worker's principal: refused on every frame key, cmd_vel and the e-stop; allowed on
        # every camera's detections.
        def own(key: str) -> int:
            return sum(
                1
                for d in map(Detections.decode, list(dets))
                if d.header.source == f"own-{ROGUE}" and keys.detections(d.header.frame_id) == key
            )

        forbidden = {keys.frame(c): marked_frame(f"rogue-{ROGUE}") for c in CAMERAS}
        forbidden |= {keys.cmd_vel(): b"rogue", keys.estop(): b"rogue"}
        allowed = {
            keys.detections(c): person(
                Header(stamp_ns=now().wall_ns, frame_id=c, seq=1, source=f"own-{ROGUE}")
            ).encode()
            for c in CAMERAS
        }
        put_until_allowed_arrive(rogue, forbidden, allowed, own, f"{ROGUE}'s detections")
        assert [h for h in list(frames) if h.source == f"rogue-{ROGUE}"] == [], "frames put"
        assert heard.forbidden == [], f"{ROGUE} put on {sorted(set(heard.forbidden))}"

        # Another worker's pool token, and a made-up worker's: refused by the router, so the
        # workers still count two members and keep their cameras.
        liveliness = rogue.liveliness()
        tokens = [
            liveliness.declare_token(keys.pool_member(name)) for name in ("detector", "detector_9")
        ]
        declared = mono_s()
        wait_for(
            lambda: all(len(heard.reports(w, declared)) >= QUIET_REPORTS for w in WORKERS),
            30,
            "the workers' counters after the rogue tokens",
        )
        for w in WORKERS:
            seen = {r.get("pool_members") for r in heard.reports(w, declared)}
            assert seen == {2}, f"{w} counted {seen} members after {ROGUE}'s rogue tokens"
        assert heard.split(declared) == split, "the assignment moved"
        assert members() == set(WORKERS)
        for token in tokens:
            token.undeclare()
    finally:
        rogue.close()
        viewer.close()
    print(f"split {dict(split)}; {len(dets)} detections heard")


def _header(sample: zenoh.Sample) -> Header:
    return Frame.decode(sample.payload.to_bytes()).header
