"""The pool over announcements (issue 31, items 1-3 and 5's worker side), in one process on a
MemoryHub with a FakeClock: the cameras come from their sources' announcements, not from a
worker's config; the members are the workers that announce themselves (a bare pool token is
ignored); shares follow the announced capacities; one worker serves several robots. Each test
runs with delivery in the putting thread and on the hub's threads (tests/unit/conftest.py)."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import replace

import numpy as np
import pytest

from common.bus import QoS
from common.clock import FakeClock
from common.counters import per_camera
from common.errors import StackError
from common.frames import image_to_frame
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.node import Node
from services.detector.handlers import DetectorHandlers
from services.detector.membership import PoolMember
from services.detector.pool_checks import AUDIT_PERIOD_S
from services.detector.service import ServedCameras
from stack.config import Config
from tests.unit.conftest import MEMORY_BUS_SEED
from tests.unit.detector.inprocess import CameraSource, Worker, cameras_config


@pytest.fixture
def hub(delivery_threads: int) -> Iterator[MemoryHub]:
    hub = MemoryHub(threads=delivery_threads, seed=MEMORY_BUS_SEED)
    yield hub
    hub.close()


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


def joined(hub: MemoryHub, clock: FakeClock, *workers: tuple[Config, str, float]) -> list[Worker]:
    """Workers (config, name, capacity), joined in order, then a loop pass each."""
    out = []
    for config, name, capacity in workers:
        w = Worker(hub, clock, config, name, capacity)
        w.pool.join()
        out.append(w)
    for w in out:
        w.loop_pass()
    return out


def owners(workers: list[Worker]) -> dict[str, list[str]]:
    """Each camera (label) and the workers that serve it."""
    out: dict[str, list[str]] = {}
    for w in workers:
        for cam in w.handlers.serving:
            out.setdefault(cam, []).append(w.name)
    return out


def frame_to(hub: MemoryHub, clock: FakeClock, prefix: str, camera: str) -> None:
    config = replace(Config(), stack=replace(Config().stack, prefix=prefix))
    node = Node("camera", config, bus=hub.join(f"cam_{prefix}_{camera}"), clock=clock)
    frame = image_to_frame(np.zeros((8, 8, 3), np.uint8), node.header(frame_id=camera))
    node.publisher(node.keys.frame(camera), QoS.SENSOR).put(frame.encode())
    hub.drain()


def test_workers_whose_configs_disagree_serve_every_announced_camera_once(
    hub: MemoryHub, clock: FakeClock
) -> None:
    """Issue 31's first case: A's config has front, left, rear at 10 Hz; B's only rear at
    2 Hz. Before, ``left`` was served by nobody. Now both take the cameras announced."""
    source = CameraSource(hub)
    for cam in ("front", "left", "rear"):
        source.announce(cam, 10.0)
    a_config = cameras_config(("front", "left", "rear"))
    b_config = cameras_config(("rear",))
    workers = joined(hub, clock, (a_config, "detector", 0), (b_config, "detector_b", 0))
    assert sorted(owners(workers)) == ["front", "left", "rear"]
    assert all(len(ws) == 1 for ws in owners(workers).values()), owners(workers)
    assert all(w.handlers.serving for w in workers)
    for cam in ("front", "left", "rear"):
        frame_to(hub, clock, "stack", cam)
    assert sum(w.count("frames_in") for w in workers) == 3


def test_a_camera_announced_at_run_time_is_served_and_one_withdrawn_is_dropped(
    hub: MemoryHub, clock: FakeClock
) -> None:
    source = CameraSource(hub)
    source.announce("front")
    # The worker's config names other cameras: they are no part of the pool.
    (w,) = joined(hub, clock, (cameras_config(("x", "y")), "detector", 0))
    assert w.handlers.serving == {"front"}
    source.announce("side")  # a camera that appears while the worker runs
    hub.drain()
    assert w.handlers.serving == {"front"}  # not inside the bus's callback
    assert w.loop_pass() == {"side", "front"}
    frame_to(hub, clock, "stack", "side")
    assert w.count(per_camera("frames_in", "side")) == 1
    assert w.count(per_camera("serving", "side")) == 1
    keys = w.node.keys
    assert [keys.pool_serving_parts(k)[2] for k in hub.tokens(keys.all_pool_serving())] == [
        "front",
        "side",
    ]
    source.withdraw("side")  # its source stopped: dropped, and its frames no longer read
    assert w.loop_pass() == {"front"}
    frame_to(hub, clock, "stack", "side")
    assert w.count(per_camera("frames_in", "side")) == 1
    assert w.count(per_camera("serving", "side")) == 0


def test_a_bare_pool_token_is_no_member_and_silences_no_camera(
    hub: MemoryHub, clock: FakeClock, caplog: pytest.LogCaptureFixture
) -> None:
    source = CameraSource(hub)
    cams = [f"cam{i}" for i in range(6)]
    for cam in cams:
        source.announce(cam)
    (w,) = joined(hub, clock, (cameras_config(("front",)), "detector", 0))
    rogue = hub.join("rogue")  # a participant that declares a pool token, announces nothing
    stray = rogue.declare_token(w.node.keys.pool_member("zz"))
    with caplog.at_level(logging.WARNING, logger="detector"):
        assert w.loop_pass() == set(cams)
    assert "no worker announcement ignored (no member): zz" in caplog.text
    assert w.count("pool_members") == 1 and w.count("pool_strays") == 1
    w.pool.audit()
    clock.advance(w.node.config.detector.pool_alarm_s + AUDIT_PERIOD_S)
    report = w.pool.audit()  # no idle member, no camera unserved: nothing to say
    assert report is not None and report.current == []
    stray.undeclare()
    w.loop_pass()
    assert w.count("pool_strays") == 0


@pytest.mark.parametrize("held_by", ["token", "announcement"])
def test_a_name_held_by_its_token_or_its_announcement_is_refused(
    hub: MemoryHub, clock: FakeClock, held_by: str
) -> None:
    config = cameras_config(("front",))
    (first,) = joined(hub, clock, (config, "detector", 0))
    second = Worker(hub, clock, config, "detector_2")
    keys = first.node.keys
    # The first worker's tokens, moved to a name a second process will ask for.
    other = hub.join("other")
    if held_by == "token":
        other.declare_token(keys.pool_member("detector_2"))
    else:
        other.declare_token(keys.worker_announcement("detector_2", "AAAA"))
    with pytest.raises(StackError, match="named 'detector_2' is already in the pool"):
        second.pool.join()


def test_shares_follow_the_announced_capacities_and_a_new_one_moves_them(
    hub: MemoryHub, clock: FakeClock
) -> None:
    source = CameraSource(hub)
    cams = [f"cam{i}" for i in range(8)]
    for cam in cams:
        source.announce(cam, 5.0)
    config = cameras_config(("front",), capacity_step=0.25, capacity_period_s=10.0)
    fast, slow = joined(hub, clock, (config, "fast", 30.0), (config, "slow", 10.0))
    assert (len(fast.handlers.serving), len(slow.handlers.serving)) == (6, 2)
    # The slow worker gets faster (its busy rounds: 4 frames in 0.1 s, 40 frames/s): its
    # moving average passes the step, but it is announced only after the period.
    for _ in range(40):
        slow.pool.observe_round(4, 0.1)
    assert slow.pool.capacity.current > 30
    slow.loop_pass()
    assert slow.count("capacity_announced") == 0
    clock.advance(10.0)
    slow.loop_pass()
    assert slow.count("capacity_announced") == 1
    assert slow.pool.announcement.seq == 1
    assert slow.count("capacity_hz") == round(slow.pool.capacity.announced)
    fast.loop_pass()
    slow.loop_pass()
    assert sorted(owners([fast, slow])) == sorted(cams)
    assert len(slow.handlers.serving) >= 4  # now at least as fast as the other


def test_one_worker_serves_two_robots_each_on_its_own_keys(
    hub: MemoryHub, clock: FakeClock
) -> None:
    """Cameras of the pool's own robot keep their bare names; another robot's read
    ``<prefix>/<camera>`` in the pool and ``<prefix>:<camera>`` in counters."""
    for prefix in ("stack", "robot2"):
        src = CameraSource(hub, prefix)
        src.announce("front")
    config = cameras_config(("front",), prefixes=("stack", "robot2"))
    both = Worker(hub, clock, config, "detector")
    both.pool.join()
    assert both.loop_pass() == {"front", "robot2:front"}
    keys = both.node.keys
    served = sorted(keys.pool_serving_parts(k)[2] for k in hub.tokens(keys.all_pool_serving()))
    assert served == ["front", "robot2/front"]
    frame_to(hub, clock, "robot2", "front")
    assert both.count(per_camera("frames_in", "robot2:front")) == 1
    assert both.count(per_camera("frames_in", "front")) == 0
    assert both.handlers.frame_keys["robot2:front"] == Keys("robot2").frame("front")
    # A worker of the first robot only takes none of robot2's cameras.
    one = Worker(hub, clock, cameras_config(("front",)), "detector_2")
    one.pool.join()
    one.loop_pass()
    both.loop_pass()
    assert "robot2:front" in both.handlers.serving
    assert one.handlers.serving <= {"front"}
    assert sorted(owners([both, one])) == ["front", "robot2:front"]


def test_each_robots_detections_and_info_go_on_its_own_keys(
    hub: MemoryHub, clock: FakeClock
) -> None:
    """The service's side of a gained camera (services/detector/service.py's
    ServedCameras): its detections publisher and info queryable on its own robot's keys."""
    source = CameraSource(hub, "robot2")
    source.announce("front")
    config = cameras_config(("front",), prefixes=("stack", "robot2"))
    node = Node("detector", config, bus=hub.join("detector"), clock=clock)
    handlers = DetectorHandlers(config, node, clock, frame_keys={})
    cameras = ServedCameras(config, node, handlers, '{"model": "m"}')
    pool = PoolMember(node, "detector", handlers, on_gained=cameras.gained, on_lost=cameras.lost)
    pool.join()
    heard: list[str] = []
    hub.join("probe").subscribe("**/detections", lambda s: heard.append(s.key))
    assert handlers.serving == {"robot2:front"}
    cameras.outputs["robot2:front"].put(b"detections")
    hub.drain()
    assert heard == [Keys("robot2").detections("front")]
    asker = hub.join("asker")
    info = Keys("robot2").detector_info("front")
    assert [r.payload for r in asker.query(info, 1.0)] == [b'{"model": "m"}']
    source.withdraw("front")  # dropped: its info is no longer answered here
    hub.drain()
    pool.settle()
    assert handlers.serving == frozenset() and asker.query(info, 1.0) == []
