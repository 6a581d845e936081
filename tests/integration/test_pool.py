"""A pool of two detector workers under the real supervisor (issue 23): four real camera
processes, two detector processes (``detector.workers = 2``), the controller and the metrics,
all on one private endpoint. One stack for every step, in order:

1. steady state: every camera is served by exactly one worker (their ``serving.<cam>``
   counters split the cameras), every camera's frames come back as detections, no frame is
   detected twice over a window, and each camera's info queryable names the model;
2. SIGKILL one worker: the survivor serves each of its cameras (its serving token, declared
   once it has subscribed to the camera's frames) within :data:`KILL_BOUND_S` of the kill (the
   dead one's links close at once), and detects frames captured after the kill; the metrics
   answer marks the dead worker gone and names the survivor as every camera's ``served_by``;
   no command moved the robot on detections older than the controller's dead-man
   (``controller.detection_timeout_s``) meanwhile;
3. the supervisor restarts it and the cameras are shared again (each worker serves one);
4. SIGSTOP one worker (hung, its token alive until Zenoh's lease): the other serves every
   camera within the lease plus a second of the stop, the watchdog restarts it, and the
   cameras are shared again.
"""

from __future__ import annotations

import json
import os
import signal
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import zenoh

from common.clock import mono_s
from common.keys import Keys
from common.messages import Detections, ServiceCounters, Twist
from tests.integration.conftest import STARTUP_S, Stack, wait_for
from tools.launch import service_pids

pytestmark = pytest.mark.integration

#: Zenoh's transport lease (its default: the stack's config does not change it). A frozen
#: worker's token goes when it runs out; a killed one's at once, when its links close.
ZENOH_LEASE_S = 10.0
#: Issue 23's bar: a frozen worker's cameras are served again within the lease plus a second.
HANDOVER_BOUND_S = ZENOH_LEASE_S + 1.0
#: A killed worker's: its token goes with its links, the survivor settles within a round.
KILL_BOUND_S = 2.0
CAMERAS = {"front": "cameraman", "left": "astronaut", "right": "coffee", "rear": "chelsea"}
WORKERS = ("detector", "detector_2")
WINDOW_FRAMES = 6  # detections per camera in the steady-state window (2 s at 3 Hz)
RESTART_BACKOFF_S = 8.0  # the supervisor's wait before it restarts a dead worker
RESTART_S = 90.0  # a worker's restart: backoff, interpreter, model load, warm-up, loaded box


@dataclass
class Watch:
    """What the test hears: each camera's detections (arrival, message), each worker's
    counters (arrival, counters) and every command."""

    lock: threading.Lock = field(default_factory=threading.Lock)
    detections: dict[str, list[tuple[float, Detections]]] = field(default_factory=dict)
    counters: dict[str, list[tuple[float, dict[str, int]]]] = field(default_factory=dict)
    twists: list[Twist] = field(default_factory=list)
    #: Serving tokens as they came: (arrival, worker, camera).
    served: list[tuple[float, str, str]] = field(default_factory=list)
    keys: Keys = field(default_factory=Keys)

    def on_detections(self, sample: zenoh.Sample) -> None:
        camera = str(sample.key_expr).split("/")[-2]
        msg = Detections.decode(sample.payload.to_bytes())
        with self.lock:
            self.detections.setdefault(camera, []).append((mono_s(), msg))

    def on_counters(self, sample: zenoh.Sample) -> None:
        msg = ServiceCounters.decode(sample.payload.to_bytes())
        with self.lock:
            self.counters.setdefault(msg.service, []).append((mono_s(), dict(msg.counters)))

    def on_serving(self, sample: zenoh.Sample) -> None:
        parts = self.keys.pool_serving_parts(str(sample.key_expr))
        if parts is not None and sample.kind == zenoh.SampleKind.PUT:
            with self.lock:
                self.served.append((mono_s(), parts[0], parts[2]))

    def serving_since(self, worker: str, cameras: set[str], after: float) -> float | None:
        """When ``worker`` had declared serving every one of ``cameras`` after ``after``."""
        with self.lock:
            got = {c: t for t, w, c in self.served if w == worker and t > after}
        return max(got[c] for c in cameras) if cameras <= got.keys() else None

    def on_twist(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.twists.append(Twist.decode(sample.payload.to_bytes()))

    def since(self, camera: str, wall_ns: int) -> list[tuple[float, Detections]]:
        """``camera``'s detections of frames captured after ``wall_ns``."""
        with self.lock:
            got = list(self.detections.get(camera, []))
        return [(t, d) for t, d in got if d.header.stamp_ns > wall_ns]

    def served_all(self, worker: str, after: float) -> bool:
        """Whether any of ``worker``'s counters heard after ``after`` says it serves every
        camera (whatever it said since)."""
        with self.lock:
            reports = [c for t, c in self.counters.get(worker, []) if t > after]
        return any(all(c.get(f"serving.{cam}", 0) > 0 for cam in CAMERAS) for c in reports)

    def serving(self, worker: str, after: float = 0.0) -> set[str] | None:
        """The cameras ``worker``'s latest counters (heard after ``after``) say it serves."""
        with self.lock:
            reports = [c for t, c in self.counters.get(worker, []) if t > after]
        if not reports:
            return None
        return {cam for cam in CAMERAS if reports[-1].get(f"serving.{cam}", 0) > 0}


@pytest.fixture
def pool(make_stack: Any) -> Iterator[tuple[Stack, Watch]]:
    first, *others = CAMERAS
    cams = {
        name: {"source": f"sample:{sample}", "frame_id": name} for name, sample in CAMERAS.items()
    }
    stack: Stack = make_stack(
        stack={"camera": first},
        camera={**cams[first], "rate_hz": 3.0, "resize": [320, 240]},
        **{f"cameras.{n}": cams[n] for n in others},
        detector={"workers": 2, "imgsz": 320, "capacity_hz": 10.0},  # equal, fixed: no move
        # A killed worker comes back after this, not at once: with a 0.2 s backoff it rejoined
        # 0.7 s after the SIGKILL on a quiet machine, before the survivor's counters and the
        # metrics could show it serving every camera (a race of the test, not of the pool).
        supervisor={
            "services": ["camera", "detector", "controller", "metrics"],
            "restart_backoff_s": RESTART_BACKOFF_S,
        },
    )
    keys = stack.keys
    watch = Watch(keys=keys)
    subs = [
        stack.session.liveliness().declare_subscriber(keys.all_pool_serving(), watch.on_serving),
        stack.session.declare_subscriber(keys.all_detections(), watch.on_detections),
        stack.session.declare_subscriber(keys.all_counters(), watch.on_counters),
        stack.session.declare_subscriber(keys.cmd_vel(), watch.on_twist),
    ]
    stack.wait_ready({*stack.config.camera_services.values(), *WORKERS, "controller", "metrics"})
    yield stack, watch
    for sub in subs:
        sub.undeclare()
    assert stack.stop() == 0, stack.log()


def shared(watch: Watch, after: float = 0.0) -> dict[str, set[str]] | None:
    """Each worker's cameras once they split every camera between them, each serving one."""
    split = {w: watch.serving(w, after) for w in WORKERS}
    if any(not cams for cams in split.values()):
        return None
    a, b = split.values()
    assert a is not None and b is not None
    return (
        {w: c for w, c in split.items() if c is not None}
        if not a & b and a | b == set(CAMERAS)
        else None
    )


def worker_pid(stack: Stack, worker: str) -> int:
    [pid] = service_pids(worker, stack.config_path)
    return pid


def check_dead_man(stack: Stack, watch: Watch) -> int:
    """No command moved the robot on detections older than the dead-man; how many moved."""
    timeout_ns = int(stack.config.controller.detection_timeout_s * 1e9)
    with watch.lock:
        moving = [t for t in watch.twists if not t.is_zero and t.input_stamp_ns > 0]
    stale = [t for t in moving if t.header.stamp_ns - t.input_stamp_ns > timeout_ns]
    assert not stale, f"{len(stale)} moving commands on stale detections: {stale[:3]}"
    return len(moving)


def test_two_workers_share_the_cameras_and_take_over_a_dead_or_hung_one(
    pool: tuple[Stack, Watch],
) -> None:
    stack, watch = pool

    # 1. Steady state: split, everything detected, nothing twice.
    split = wait_for(lambda: shared(watch), STARTUP_S, lambda: f"a split:\n{stack.log()}")
    start = time.time_ns()
    wait_for(
        lambda: all(len(watch.since(c, start)) >= WINDOW_FRAMES for c in CAMERAS),
        60,
        lambda: f"{WINDOW_FRAMES} detections of each camera:\n{stack.log()}",
    )
    assert shared(watch) == split, "the assignment moved in steady state"
    for cam in CAMERAS:
        frames = [(d.header.boot_id, d.header.seq) for _, d in watch.since(cam, start)]
        assert len(frames) == len(set(frames)), f"{cam}: a frame detected twice"
    answer = wait_for(
        lambda: (m := stack.metrics()) and len(m.get("workers", {})) == 2 and m, 30, "metrics"
    )
    assert {w: set(m["cameras"]) for w, m in answer["workers"].items()} == split
    assert {c: m["served_by"] for c, m in answer["cameras"].items()} == {
        c: w for w, cams in split.items() for c in cams
    }
    for cam in CAMERAS:  # every worker answers for every camera, served or not
        replies = [r.ok for r in stack.session.get(stack.keys.detector_info(cam), timeout=10.0)]
        infos = [json.loads(r.payload.to_string()) for r in replies if r is not None]
        assert infos, f"no info for {cam}"
        assert {(i["model"], i["backend"]) for i in infos} == {("yolov5s-coco-320.onnx", "onnx")}

    # 2. SIGKILL a worker: its cameras come back from the other within the bound.
    victim, survivor = WORKERS[1], WORKERS[0]
    moved = split[victim]
    killed_ns, killed_at = time.time_ns(), mono_s()
    os.kill(worker_pid(stack, victim), signal.SIGKILL)
    taken = wait_for(
        lambda: watch.serving_since(survivor, moved, killed_at),
        KILL_BOUND_S + 30,
        lambda: f"the survivor to serve {sorted(moved)}:\n{stack.log()}",
    )
    assert taken - killed_at <= KILL_BOUND_S, f"served {taken - killed_at:.2f} s after the kill"
    wait_for(
        lambda: all(watch.since(c, killed_ns) for c in moved),
        30,
        lambda: f"detections of {sorted(moved)} after the kill:\n{stack.log()}",
    )
    wait_for(
        lambda: watch.served_all(survivor, killed_at),
        RESTART_BACKOFF_S,
        lambda: f"{survivor} to count every camera as served:\n{stack.log()}",
    )
    # The metrics know it from the live pool at once, not from the dead worker's last word.
    answer = wait_for(
        lambda: (
            (m := stack.metrics())
            and {c: x["served_by"] for c, x in m["cameras"].items()}
            == dict.fromkeys(CAMERAS, survivor)
            and m
        ),
        10,
        lambda: f"every camera served by {survivor} in the metrics: {stack.metrics()}",
    )
    gone = answer["workers"][victim]
    assert (gone["live"], gone["cameras"]) == (False, []), gone

    # 3. Restarted by the supervisor, it takes its share again.
    wait_for(lambda: shared(watch, killed_at), RESTART_S, lambda: f"a split again:\n{stack.log()}")
    moving = check_dead_man(stack, watch)

    # 4. SIGSTOP a worker: the other covers once its token goes; the watchdog restarts it.
    split_now = shared(watch, killed_at) or {}
    hung = next(w for w, cams in split_now.items() if cams)
    other = next(w for w in WORKERS if w != hung)
    pid = worker_pid(stack, hung)
    stopped_ns, stopped_at = time.time_ns(), mono_s()
    os.kill(pid, signal.SIGSTOP)
    try:
        covered = wait_for(
            lambda: watch.serving_since(other, split_now[hung], stopped_at),
            HANDOVER_BOUND_S + 10,
            lambda: f"every camera served while {hung} is frozen:\n{stack.log()}",
        )
        assert covered - stopped_at <= HANDOVER_BOUND_S, f"{covered - stopped_at:.1f} s"
        wait_for(
            lambda: all(watch.since(c, stopped_ns) for c in CAMERAS),
            30,
            lambda: f"detections of every camera while {hung} is frozen:\n{stack.log()}",
        )
        restarted = wait_for(
            lambda: f"{hung}: hung" in stack.log() and mono_s(),
            60,
            lambda: f"the watchdog:\n{stack.log()}",
        )
    finally:
        if Path(f"/proc/{pid}").exists():
            os.kill(pid, signal.SIGCONT)  # never leave a frozen process behind
    wait_for(lambda: shared(watch, stopped_at), RESTART_S, lambda: f"a split after:\n{stack.log()}")
    assert not Path(f"/proc/{pid}").exists(), "the frozen worker was left behind"
    moving = check_dead_man(stack, watch)
    answer = stack.metrics() or {}
    print(
        f"SIGKILL: {sorted(moved)} served {taken - killed_at:.2f} s after the kill; "
        f"SIGSTOP of {hung}: every camera served {covered - stopped_at:.1f} s after, the "
        f"watchdog restarted it {restarted - stopped_at:.1f} s after; moving commands: "
        f"{moving}; duplicate detections: {answer.get('duplicate_detections')}; "
        f"workers: {answer.get('workers')}"
    )
