"""What a joining worker hears of the pool (services/detector/pool_hearing.py): its catch-up
waits for the names a look at the bus reads through common/announce.py, so garbage alive on an
announcement key is no name to wait for, and it is reported once, by the listeners."""

from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest

from common.announce import to_chunk
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import CameraAnnouncement, WorkerAnnouncement
from services.detector.pool_hearing import PoolHearing
from tests.unit.conftest import MEMORY_BUS_SEED

POOL = Keys("site")
ROBOT = Keys("site/robot1")


class CountedEvent(threading.Event):
    """An Event that counts the waits on it."""

    waits = 0

    def wait(self, timeout: float | None = None) -> bool:
        self.waits += 1
        return super().wait(timeout)


@pytest.fixture
def hub(delivery_threads: int) -> Iterator[MemoryHub]:
    hub = MemoryHub(threads=delivery_threads, seed=MEMORY_BUS_SEED)
    yield hub
    hub.close()


def test_garbage_alive_does_not_hold_up_the_catch_up_and_is_reported_once(
    hub: MemoryHub,
) -> None:
    others = hub.join("others")
    gpu = WorkerAnnouncement(worker="gpu", capacity_hz=30.0, prefixes=(ROBOT.prefix,))
    others.declare_token(POOL.worker_announcement("gpu", to_chunk(gpu)))
    others.declare_token(POOL.worker_announcement("ghost", "AAAA"))  # base64 of no message
    front = CameraAnnouncement(camera="front", width=640, height=480, rate_hz=10.0)
    others.declare_token(ROBOT.camera_announcement("front", to_chunk(front)))
    others.declare_token(ROBOT.camera_announcement("rear", to_chunk(front)))  # not its name
    bad: list[str] = []
    me = hub.join("me")
    hearing = PoolHearing(me, POOL, [ROBOT.prefix], lambda: None, lambda k, e: bad.append(k))
    hub.drain()  # the listeners hold what is alive
    heard = CountedEvent()
    hearing._heard = heard
    hearing.catch_up()
    assert heard.waits == 0  # it waited for no garbage's name
    assert len(bad) == 2  # once each
    assert any("/workers/ghost/" in k for k in bad) and any("/camera/rear/" in k for k in bad)
    assert list(hearing.workers()) == ["gpu"]
    cameras, depth = hearing.cameras()
    assert list(cameras) == ["site/robot1/front"] and depth == {}  # common/pool_rule.py
    hearing.close()
