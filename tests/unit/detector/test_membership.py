"""The pool's membership and hand-over (services/detector/membership.py) in one process: workers
on a MemoryHub (common/memory_bus.py) with a FakeClock, each pass of their detection loop run by
the test. Deterministic and instant: a worker's death is its bus closing, a stall is the clock
moved past ``detector.pool_stall_s`` with no beat and the stall check called. Each test runs
twice: with delivery in the putting thread, and on the hub's threads in a shuffled order (as
Zenoh's callbacks come), where a pass waits for what was put before (``hub.drain()``)."""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator

import numpy as np
import pytest

from common.announce import to_chunk
from common.bus import Declared, QoS
from common.clock import FakeClock
from common.counters import per_camera
from common.errors import StackError
from common.frames import image_to_frame
from common.memory_bus import MemoryHub
from common.messages import Header, WorkerAnnouncement
from common.node import Node
from services.detector.pool import assign
from services.detector.pool_checks import AUDIT_PERIOD_S
from stack.config import Config
from tests.unit.conftest import MEMORY_BUS_SEED
from tests.unit.detector.inprocess import CameraSource, Worker, cameras_config

CAMERAS = ("front", "rear", "left", "right", "top", "back")


@pytest.fixture
def hub(delivery_threads: int) -> Iterator[MemoryHub]:
    """The bus, with CAMERAS announced on it (equal rates) by their source."""
    hub = MemoryHub(threads=delivery_threads, seed=MEMORY_BUS_SEED)
    source = CameraSource(hub)
    for cam in CAMERAS:
        source.announce(cam)
    hub.drain()
    yield hub
    hub.close()


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


@pytest.fixture
def config() -> Config:
    return cameras_config(CAMERAS)


def start(hub: MemoryHub, clock: FakeClock, config: Config, *names: str) -> list[Worker]:
    """Workers ``names``, joined one after the other, then one loop pass each (a worker that
    joined first hears the later ones on its watch and settles on its next pass)."""
    workers = []
    for name in names:
        w = Worker(hub, clock, config, name)
        w.pool.join()
        workers.append(w)
    for w in workers:
        w.loop_pass()
    return workers


def split(workers: list[Worker]) -> dict[str, frozenset[str]]:
    return {w.name: w.handlers.serving for w in workers}


def assert_each_camera_served_once(workers: list[Worker], hub: MemoryHub) -> None:
    """Every camera served by exactly one worker: in its handlers, in its gauges and in its
    serving tokens on the bus; each worker counts every member."""
    owners = [cam for w in workers for cam in w.handlers.serving]
    assert sorted(owners) == sorted(CAMERAS), split(workers)
    keys = workers[0].node.keys
    tokens = [keys.pool_serving_parts(k) for k in hub.tokens(keys.all_pool_serving())]
    assert sorted((p[0], p[2]) for p in tokens if p) == sorted(
        (w.name, cam) for w in workers for cam in w.handlers.serving
    )
    for w in workers:
        assert w.count("serving") == len(w.handlers.serving)
        assert w.count("pool_members") == len(workers)
        for cam in CAMERAS:
            assert w.count(per_camera("serving", cam)) == int(cam in w.handlers.serving)
    assert abs(sum(w.count("pool_load_permille") for w in workers) - 1000) <= len(workers)
    heard = {k.rsplit("/", 2)[-2] for k in hub.tokens(keys.all_worker_announcements())}
    assert heard >= {w.name for w in workers}  # each member announces itself


def put_frame(hub: MemoryHub, config: Config, camera: str, clock: FakeClock) -> None:
    """One frame on ``camera``'s key, from a camera's own participant."""
    cam = Node(f"camera_{camera}", config, bus=hub.join(f"camera_{camera}"), clock=clock)
    header: Header = cam.header(frame_id=camera)
    frame = image_to_frame(np.zeros((8, 8, 3), np.uint8), header)
    cam.publisher(cam.keys.frame(camera), QoS.SENSOR).put(frame.encode())
    hub.drain()


@pytest.mark.parametrize("names", [("detector", "detector_2"), ("a", "b", "c")])
def test_every_camera_is_served_by_exactly_one_worker_and_only_its_frames_reach_it(
    hub: MemoryHub, clock: FakeClock, config: Config, names: tuple[str, ...]
) -> None:
    workers = start(hub, clock, config, *names)
    assert_each_camera_served_once(workers, hub)
    assert all(w.handlers.serving for w in workers)  # six cameras: everyone has a share
    for cam in CAMERAS:
        put_frame(hub, config, cam, clock)
    for w in workers:  # each worker subscribed to its own cameras' frames and no others
        for cam in CAMERAS:
            assert w.count(per_camera("frames_in", cam)) == int(cam in w.handlers.serving)
    # The last to join took its share as its first assignment: no hand-over; the first, which
    # had every camera while alone, counts what it handed on.
    last, first = workers[-1], workers[0]
    assert last.count("cameras_gained") == last.count("cameras_lost") == 0
    assert first.count("cameras_lost") == len(CAMERAS) - len(first.handlers.serving)


def test_a_dead_worker_hands_its_cameras_to_the_others_at_their_next_settle(
    hub: MemoryHub, clock: FakeClock, config: Config
) -> None:
    a, b, c = start(hub, clock, config, "a", "b", "c")
    before = split([a, b, c])
    c.bus.close()  # the process is gone: its tokens with it
    hub.drain()  # and every watcher heard it
    assert hub.tokens(c.node.keys.pool_member("c")) == []
    assert split([a, b]) == {n: before[n] for n in "ab"}  # not inside the bus's callback
    a.loop_pass()
    b.loop_pass()
    assert_each_camera_served_once([a, b], hub)
    moved = [cam for w in (a, b) for cam in w.handlers.serving if cam not in before[w.name]]
    assert set(before["c"]) <= set(moved)
    gained = sum(w.count("cameras_gained") for w in (a, b))
    assert (
        gained
        == len(moved)
        == sum(w.count(per_camera("cameras_gained", m)) for w in (a, b) for m in moved)
    )
    for cam in before["c"]:
        put_frame(hub, config, cam, clock)
        assert sum(w.count(per_camera("frames_in", cam)) for w in (a, b)) == 1


def test_a_stalled_worker_resigns_the_others_take_over_and_its_next_beat_brings_it_back(
    hub: MemoryHub, clock: FakeClock, config: Config, caplog: pytest.LogCaptureFixture
) -> None:
    stall_s = config.detector.pool_stall_s
    a, b = start(hub, clock, config, "detector", "detector_2")
    share = a.handlers.serving
    keys = a.node.keys
    # Beating every half stall: nobody resigns however long it goes on.
    for _ in range(6):
        clock.advance(stall_s / 2)
        a.loop_pass()
        b.loop_pass()
        assert not a.pool.check_stall() and not b.pool.check_stall()
    # a's loop stops passing; b's goes on.
    clock.advance(stall_s / 2)
    b.loop_pass()
    assert not a.pool.check_stall()  # not yet: half the limit
    clock.advance(stall_s / 2 + 0.01)
    b.loop_pass()
    with caplog.at_level(logging.WARNING, logger="detector"):
        assert a.pool.check_stall()
    assert "leaving the pool" in caplog.text
    assert not a.pool.check_stall()  # once
    assert a.pool.resigned and a.count("pool_resigned") == 1
    assert a.handlers.serving == frozenset()
    assert hub.tokens(keys.all_pool_members()) == [keys.pool_member("detector_2")]
    assert hub.tokens(keys.pool_serving_of("detector")) == []
    # b takes a's cameras at its next pass, and a refuses their frames meanwhile.
    assert b.loop_pass() == frozenset(CAMERAS)
    assert b.count("cameras_gained") == len(share)
    assert_each_camera_served_once([b], hub)
    cam = sorted(share)[0]
    put_frame(hub, config, cam, clock)
    assert (a.count(per_camera("frames_in", cam)), b.count(per_camera("frames_in", cam))) == (0, 1)
    # a's loop passes again: its token is back, it serves its share, and b hands it back.
    assert a.loop_pass() == share
    assert not a.pool.resigned
    assert b.loop_pass() == frozenset(CAMERAS) - share
    assert b.count("cameras_lost") == len(share)
    assert_each_camera_served_once([a, b], hub)


def test_a_worker_asked_to_stop_hands_its_cameras_over_and_never_rejoins(
    hub: MemoryHub, clock: FakeClock, config: Config
) -> None:
    # The watchdog found a worker frozen (SIGSTOP) and sent it SIGTERM and SIGCONT: its loop
    # runs again on its way out, and must not take cameras back before it exits (issue 39).
    a, b = start(hub, clock, config, "detector", "detector_2")
    clock.advance(config.detector.pool_stall_s + 0.01)
    assert a.pool.check_stall()
    a.stop.set()
    assert a.loop_pass() == frozenset()
    assert a.pool.resigned
    assert hub.tokens(a.node.keys.all_pool_members()) == [a.node.keys.pool_member("detector_2")]
    assert b.loop_pass() == frozenset(CAMERAS)
    # Asked to stop before it resigned (its loop resumed first): the stall watch hands its
    # cameras over at its next check, however recent the loop's last pass.
    c = Worker(hub, clock, config, "detector_3")
    c.pool.join()
    c.loop_pass()
    b.loop_pass()
    assert c.handlers.serving
    c.stop.set()
    assert c.pool.check_stall()
    assert c.loop_pass() == frozenset()
    assert b.loop_pass() == frozenset(CAMERAS)


def test_a_settle_while_resigned_never_serves_again_until_the_next_beat(
    hub: MemoryHub, clock: FakeClock, config: Config
) -> None:
    a, b = start(hub, clock, config, "detector", "detector_2")
    share = a.handlers.serving
    clock.advance(config.detector.pool_stall_s + 0.01)
    assert a.pool.check_stall()
    # The membership changes while a is resigned: its stalled loop may still settle (a pass
    # stalled between beat and settle); that must not switch serving back on.
    c = Worker(hub, clock, config, "detector_3")
    c.pool.join()
    hub.drain()  # a has heard of c
    a.pool.settle()
    assert a.handlers.serving == frozenset(), "a resigned worker serves again"
    assert hub.tokens(a.node.keys.pool_serving_of("detector")) == []
    # Only its next beat brings it back, with its share of the three.
    d = config.detector
    owners = assign(
        ["detector", "detector_2", "detector_3"], dict.fromkeys(CAMERAS, 5.0), d.pool_balance
    )
    assert a.loop_pass() == {cam for cam, w in owners.items() if w == "detector"} != share
    b.loop_pass()
    c.loop_pass()
    assert_each_camera_served_once([a, b, c], hub)


def test_a_stall_inside_a_settle_does_not_switch_serving_back_on(
    hub: MemoryHub, clock: FakeClock, config: Config
) -> None:
    """The stall watch resigns while the loop is inside settle(), after the change was
    computed and before it was applied (here: as it undeclares a lost camera's
    subscription)."""
    a = Worker(hub, clock, config, "detector")
    stall = {"armed": False}
    subscribe = a.node.subscribe_bounded

    def subscribe_watched(key: str, handle: Callable[[bytes], None], depth: int = 1) -> Declared:
        sub = subscribe(key, handle, depth)

        class Watched:
            def undeclare(self) -> None:
                if stall["armed"]:  # the stall watch runs now, in the middle of the settle
                    stall["armed"] = False
                    clock.advance(config.detector.pool_stall_s + 0.01)
                    assert a.pool.check_stall()
                sub.undeclare()

        return Watched()

    a.node.subscribe_bounded = subscribe_watched  # type: ignore[method-assign]
    a.pool.join()
    assert a.loop_pass() == frozenset(CAMERAS)
    b = Worker(hub, clock, config, "detector_2")
    b.pool.join()  # a loses some cameras at its next settle
    hub.drain()
    stall["armed"] = True
    a.pool.settle()
    assert not stall["armed"], "the settle undeclared nothing: the test tests nothing"
    assert a.pool.resigned
    assert a.handlers.serving == frozenset(), "a resigned worker serves again"
    assert hub.tokens(a.node.keys.pool_serving_of("detector")) == []


def test_the_stall_watch_thread_checks_a_few_times_per_stall_limit(
    hub: MemoryHub, clock: FakeClock, config: Config
) -> None:
    a, b = start(hub, clock, config, "detector", "detector_2")
    pauses: list[float] = []

    def pause(period: float) -> bool:
        """The watch's wait between checks: at once, twice, then "closed"."""
        pauses.append(period)
        if len(pauses) == 2:
            clock.advance(config.detector.pool_stall_s + 0.01)  # a's loop stalled meanwhile
        return len(pauses) > 2

    watch = a.pool.start_stall_watch(pause)
    watch.join(timeout=30)  # it returns at once: three pauses, two checks
    assert not watch.is_alive()
    assert pauses == [config.detector.pool_stall_s / 4] * 3
    assert a.pool.resigned and a.count("pool_resigned") == 1
    assert b.loop_pass() == frozenset(CAMERAS)


def test_alone_in_the_pool_a_stalled_worker_stays(
    hub: MemoryHub, clock: FakeClock, config: Config
) -> None:
    (a,) = start(hub, clock, config, "detector")
    clock.advance(3 * config.detector.pool_stall_s)
    assert not a.pool.check_stall()
    assert a.count("pool_resigned") == 0 and a.handlers.serving == frozenset(CAMERAS)
    assert hub.tokens(a.node.keys.all_pool_members()) == [a.node.keys.pool_member("detector")]


def test_a_name_already_live_in_the_pool_is_refused(
    hub: MemoryHub, clock: FakeClock, config: Config
) -> None:
    (first,) = start(hub, clock, config, "detector")
    second = Worker(hub, clock, config, "detector")
    with pytest.raises(StackError, match="named 'detector' is already in the pool"):
        second.pool.join()
    keys = first.node.keys
    assert hub.tokens(keys.all_pool_members()) == [keys.pool_member("detector")]
    assert first.loop_pass() == frozenset(CAMERAS)
    assert first.count("pool_members") == 1


def test_the_audit_warns_of_a_camera_nobody_serves_after_the_alarm_time_and_clears(
    hub: MemoryHub, clock: FakeClock, config: Config, caplog: pytest.LogCaptureFixture
) -> None:
    alarm_s = config.detector.pool_alarm_s
    (a,) = start(hub, clock, config, "detector")
    # A member that serves nothing (a hung worker: its token and announcement alive): the
    # cameras the rule gives it are served by nobody.
    probe = hub.join("raw")
    keys = a.node.keys
    hung = WorkerAnnouncement(worker="ghost", capacity_hz=1.0, prefixes=("stack",))
    ghost = [
        probe.declare_token(keys.worker_announcement("ghost", to_chunk(hung))),
        probe.declare_token(keys.pool_member("ghost")),
    ]
    given = frozenset(CAMERAS) - a.loop_pass()
    assert given, "the ghost was given no camera: the test tests nothing"
    clock.advance(AUDIT_PERIOD_S)
    report = a.pool.audit()
    assert report is not None and report.current == []  # a hand-over's moment: no alarm yet
    clock.advance(alarm_s)
    with caplog.at_level(logging.INFO, logger="detector"):
        report = a.pool.audit()
    assert report is not None
    assert {f.subject for f in report.raised if f.kind == "unserved"} == given
    assert report.count("idle_member") == 1
    assert a.count("pool_warnings") == len(report.current) == len(given) + 1
    assert "is served by no detector worker" in caplog.text
    assert a.pool.audit() is None  # not again within the audit period
    # The hung worker goes: the worker takes every camera again and the warnings clear.
    for token in ghost:
        token.undeclare()
    caplog.clear()
    assert a.loop_pass() == frozenset(CAMERAS)
    clock.advance(AUDIT_PERIOD_S)
    with caplog.at_level(logging.INFO, logger="detector"):
        report = a.pool.audit()
    assert report is not None and report.current == []
    assert {f.subject for f in report.cleared} == {*given, "ghost"}
    assert a.count("pool_warnings") == 0
    assert "no longer so" in caplog.text
