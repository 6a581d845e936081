"""A worker earns its cameras by delivering (issue 39), in one process: workers on a MemoryHub
with a FakeClock. A raw participant that announces a worker of the highest capacity there is,
holds forged serving tokens for every camera and never detects takes every camera at first;
the real worker, which sees no detections of them come, takes them back within
``detector.pool_deliver_s`` and says why, and the audit warns from what arrives."""

from __future__ import annotations

import logging
from collections.abc import Iterator

import pytest

from common.announce import to_chunk
from common.boxes import Boxes
from common.bus import QoS
from common.clock import FakeClock
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import Detections, Header, WorkerAnnouncement
from services.detector import contract
from services.detector.contract import MAX_CAPACITY_HZ
from services.detector.pool_checks import AUDIT_PERIOD_S
from tests.unit.conftest import MEMORY_BUS_SEED
from tests.unit.detector.inprocess import CameraSource, Worker, cameras_config

CAMERAS = ("front", "rear", "left", "right")
DELIVER_S = 4.0
READMIT_S = 30.0
ALARM_S = 1.0


@pytest.fixture
def hub(delivery_threads: int) -> Iterator[MemoryHub]:
    """The bus: delivering in the putting thread, or on threads of its own (conftest.py)."""
    hub = MemoryHub(threads=delivery_threads, seed=MEMORY_BUS_SEED)
    yield hub
    hub.close()


def detections(hub: MemoryHub, cameras: frozenset[str], worker: str = "detector") -> None:
    """One (empty) Detections on each of ``cameras``' keys, made by ``worker``."""
    bus = hub.join("worker_output")
    keys = Keys("stack")
    for cam in sorted(cameras):
        header = Header(stamp_ns=1, frame_id=cam, seq=0, source="camera")
        msg = Detections(header=header, image_width=64, image_height=48, boxes=Boxes(),
                         class_names=(), worker=worker)  # fmt: skip
        bus.publisher(keys.detections(cam), QoS.SENSOR).put(msg.encode())
    hub.drain()  # heard before the bus goes
    bus.close()


def test_a_liar_claiming_every_camera_loses_them_to_the_worker_that_delivers(
    hub: MemoryHub, caplog: pytest.LogCaptureFixture
) -> None:
    clock = FakeClock()
    source = CameraSource(hub)
    for cam in CAMERAS:
        source.announce(cam)
    config = cameras_config(
        CAMERAS, pool_deliver_s=DELIVER_S, pool_readmit_s=READMIT_S, pool_alarm_s=ALARM_S
    )
    worker = Worker(hub, clock, config, "detector", capacity_hz=20.0)
    worker.pool.join()
    keys = worker.node.keys
    rogue = hub.join("rogue")
    liar = WorkerAnnouncement(worker="zz", capacity_hz=MAX_CAPACITY_HZ, prefixes=("stack",))
    rogue.declare_token(keys.worker_announcement("zz", to_chunk(liar)))
    rogue.declare_token(keys.pool_member("zz"))
    for cam in CAMERAS:  # forged: it serves nothing
        rogue.declare_token(keys.pool_serving("zz", rogue.zid, cam))
    assert worker.loop_pass() == frozenset(), "the claim wins every camera at first"
    caplog.set_level(logging.INFO)
    clock.advance(DELIVER_S / 2)
    assert worker.loop_pass() == frozenset()  # within the bound
    clock.advance(DELIVER_S / 2 + 0.1)
    assert worker.loop_pass() == frozenset(CAMERAS), "taken back from the liar"
    assert worker.count(contract.POOL_DROPPED) == 1
    assert worker.count(contract.POOL_DROPS) == 1
    assert any("pool member zz delivered no detections" in r.message for r in caplog.records)
    # The worker delivers; the audit warns of the liar (dropped), not of a served camera.
    for _ in range(int(ALARM_S / 0.25) + 4):
        clock.advance(0.25)
        detections(hub, frozenset(CAMERAS))
        assert worker.loop_pass() == frozenset(CAMERAS)
    clock.advance(AUDIT_PERIOD_S)
    report = worker.pool.audit()
    assert report is not None
    kinds = {(f.kind, f.subject) for f in report.current}
    assert ("undelivering", "stack/zz") in kinds, kinds
    assert not any(k == "unserved" for k, _ in kinds), kinds
    # Its time over, it is given the cameras again, delivers nothing, and waits twice as long.
    served = worker.handlers.serving
    while served:  # the worker delivers all along
        clock.advance(0.5)
        detections(hub, served)
        served = worker.loop_pass()
    assert worker.count(contract.POOL_DROPS) == 1  # only the liar was ever dropped
    clock.advance(DELIVER_S + 0.1)
    assert worker.loop_pass() == frozenset(CAMERAS)
    assert worker.count(contract.POOL_DROPS) == 2
    assert any("for 60 s" in r.message for r in caplog.records if "zz" in r.message)


def test_cameras_of_no_detections_are_unserved_whatever_the_tokens_say(hub: MemoryHub) -> None:
    # The worker alone (never dropped: nobody could take over) serves the cameras; their
    # detections stop (a hung model that still beats): its own audit says unserved.
    clock = FakeClock()
    source = CameraSource(hub)
    for cam in CAMERAS:
        source.announce(cam)
    config = cameras_config(CAMERAS, pool_deliver_s=DELIVER_S, pool_alarm_s=ALARM_S)
    worker = Worker(hub, clock, config, "detector")
    worker.pool.join()
    assert worker.loop_pass() == frozenset(CAMERAS)
    detections(hub, frozenset(CAMERAS) - {"rear"})
    worker.pool.audit()
    clock.advance(DELIVER_S + 0.1)
    detections(hub, frozenset(CAMERAS) - {"rear"})
    worker.loop_pass()
    clock.advance(ALARM_S)
    detections(hub, frozenset(CAMERAS) - {"rear"})
    worker.loop_pass()
    clock.advance(AUDIT_PERIOD_S)
    report = worker.pool.audit()
    assert report is not None
    assert {(f.kind, f.subject) for f in report.current} == {("unserved", "rear")}
    assert "no detections of it arrive" in report.current[0].detail
    assert worker.count(contract.POOL_DROPS) == 0


def test_a_dropped_worker_that_restarts_is_judged_afresh_by_everyone(hub: MemoryHub) -> None:
    # A worker frozen (its cameras' detections stop) is dropped by the other; killed and
    # restarted (its token goes and comes back) it knows nothing of the drop, so the other
    # lifts it too: both views agree, no camera served twice or by nobody.
    clock = FakeClock()
    source = CameraSource(hub)
    for cam in CAMERAS:
        source.announce(cam)
    config = cameras_config(CAMERAS, pool_deliver_s=DELIVER_S, pool_readmit_s=READMIT_S)
    a, b = (Worker(hub, clock, config, name) for name in ("detector", "detector_2"))
    a.pool.join()
    b.pool.join()
    a.loop_pass()
    b.loop_pass()
    share = a.handlers.serving
    assert share and b.handlers.serving == frozenset(CAMERAS) - share
    for _ in range(int(DELIVER_S / 0.5) + 2):  # a frozen: only b's cameras deliver
        clock.advance(0.5)
        detections(hub, b.handlers.serving)
        b.loop_pass()
    assert b.handlers.serving == frozenset(CAMERAS) and b.count(contract.POOL_DROPPED) == 1
    a.bus.close()  # killed
    b.loop_pass()
    assert b.count(contract.POOL_DROPPED) == 0
    again = Worker(hub, clock, config, "detector")  # restarted
    again.pool.join()
    served = again.loop_pass(), b.loop_pass()
    assert served[0] == share and served[1] == frozenset(CAMERAS) - share
