"""A worker name announced by two sessions at once (issue 39, item 2), in one process: workers on
a MemoryHub with a FakeClock. A second session with ``detector_2``'s name (its credentials,
under the password profile) re-announces it at the highest capacity there is. Before, the
others believed the newest announcement and gave ``detector_2`` every camera, while the real
``detector_2``, counting its own capacity, served only its share: the rest went unserved for
as long as the claim lived (it is never dropped: it delivers on its own cameras). Now every
view counts the name with the lowest capacity any of its live announcements claims
(common/pool_rule.py's ``one_worker``): no camera moves, each is served once, and the audit
says the name is announced twice."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from common.announce import to_chunk
from common.clock import FakeClock
from common.memory_bus import MemoryHub
from common.messages import WorkerAnnouncement
from common.pool_rule import PoolWorker, one_worker
from services.detector.contract import MAX_CAPACITY_HZ
from services.detector.pool_checks import AUDIT_PERIOD_S
from tests.unit.conftest import MEMORY_BUS_SEED
from tests.unit.detector.inprocess import CameraSource, Worker, cameras_config

CAMERAS = ("front", "rear", "left", "right")
ALARM_S = 1.0


@pytest.fixture
def hub(delivery_threads: int) -> Iterator[MemoryHub]:
    """The bus: delivering in the putting thread, or on threads of its own (conftest.py)."""
    hub = MemoryHub(threads=delivery_threads, seed=MEMORY_BUS_SEED)
    yield hub
    hub.close()


def two_workers(hub: MemoryHub) -> tuple[MemoryHub, FakeClock, Worker, Worker]:
    clock = FakeClock()
    source = CameraSource(hub)
    for cam in CAMERAS:
        source.announce(cam)
    config = cameras_config(CAMERAS, pool_alarm_s=ALARM_S)
    a = Worker(hub, clock, config, "detector", capacity_hz=20.0)
    b = Worker(hub, clock, config, "detector_2", capacity_hz=20.0)
    a.pool.join()
    b.pool.join()
    a.loop_pass()
    b.loop_pass()
    return hub, clock, a, b


def passes(clock: FakeClock, *workers: Worker) -> tuple[frozenset[str], ...]:
    """One loop pass of each worker, a little later; what each serves."""
    clock.advance(AUDIT_PERIOD_S)
    return tuple(w.loop_pass() for w in workers)


def test_a_second_session_claiming_a_live_workers_name_moves_no_camera(hub: MemoryHub) -> None:
    hub, clock, a, b = two_workers(hub)
    share_a, share_b = a.handlers.serving, b.handlers.serving
    assert share_a and share_b and share_a | share_b == frozenset(CAMERAS)
    keys = a.node.keys
    rogue = hub.join("rogue")
    claim = WorkerAnnouncement(
        worker="detector_2", capacity_hz=MAX_CAPACITY_HZ, prefixes=("stack",)
    )
    token = rogue.declare_token(keys.worker_announcement("detector_2", to_chunk(claim)))
    for _ in range(int(ALARM_S / AUDIT_PERIOD_S) + 2):
        served = passes(clock, a, b)
        # Before: a believed the claim and served nothing, b its share: two unserved.
        assert served == (share_a, share_b), "the claim moved a camera"
    assert a.pool.view.owners == b.pool.view.owners
    for worker in (a, b):
        clock.advance(AUDIT_PERIOD_S)
        report = worker.pool.audit()
        assert report is not None
        kinds = {(f.kind, f.subject) for f in report.current}
        assert kinds == {("name_twice", "detector_2")}, (worker.name, kinds)
        [twice] = report.current
        assert "announced by 2 sessions" in twice.detail
    token.undeclare()  # the claim goes: the warning clears, nothing moves
    hub.drain()
    a.pool.settle()
    clock.advance(AUDIT_PERIOD_S)
    report = a.pool.audit()
    assert report is not None and report.current == []
    assert [f.kind for f in report.cleared] == ["name_twice"]
    assert passes(clock, a, b) == (share_a, share_b)


def test_a_lower_claim_under_a_live_name_gives_the_others_more_never_nobody(
    hub: MemoryHub,
) -> None:
    # A claim can only lower the name's share: what it loses the others take, every camera
    # served once, and every worker computes the same owners.
    hub, clock, a, b = two_workers(hub)
    keys = a.node.keys
    rogue = hub.join("rogue")
    claim = WorkerAnnouncement(worker="detector_2", capacity_hz=0.5, prefixes=("stack",))
    rogue.declare_token(keys.worker_announcement("detector_2", to_chunk(claim)))
    served_a, served_b = passes(clock, a, b)
    assert served_a | served_b == frozenset(CAMERAS) and not served_a & served_b
    assert len(served_a) > len(served_b)
    assert a.pool.view.owners == b.pool.view.owners
    assert a.pool.view.members["detector_2"] == b.pool.view.members["detector_2"]
    assert b.pool.view.members["detector_2"].capacity_hz == 0.5


def test_one_worker_takes_the_lowest_capacity_and_every_robot() -> None:
    real = PoolWorker(20.0, frozenset({"robot1"}))
    claim = PoolWorker(MAX_CAPACITY_HZ, frozenset({"robot1", "robot2"}))
    assert one_worker([real]) == real
    assert one_worker([claim, real]) == one_worker([real, claim])  # order-free
    assert one_worker([claim, real]) == PoolWorker(20.0, frozenset({"robot1", "robot2"}))
    with pytest.raises(ValueError, match="at least one"):
        one_worker([])
