"""The pool in the metrics: which worker serves a camera as cameras are handed over, each
worker's figures, and frames detected twice (services/metrics/pool.py)."""

from __future__ import annotations

from dataclasses import replace

from common.clock import FakeClock
from common.messages import Header, ServiceCounters, WorkerAnnouncement
from common.node import Tally
from common.pool_audit import PoolAudit
from common.pool_rule import PoolWorker, assign
from services.detector.contract import MAX_CAPACITY_HZ
from services.metrics.aggregate import Aggregator
from services.metrics.pool import LivePool
from services.metrics.service import MetricsHandlers
from stack.config import Config
from tests.unit.announced import announcement
from tests.unit.metrics.samples import detections

HDR = Header(stamp_ns=0, frame_id="", seq=0, source="metrics")


def _counters(service: str, seq: int, **counts: int) -> ServiceCounters:
    named = {k.replace("__", "."): v for k, v in counts.items()}
    return ServiceCounters(
        header=Header(stamp_ns=seq, frame_id="", seq=seq, source=service),
        service=service,
        counters=named,
    )


def test_served_by_follows_the_hand_over() -> None:
    agg = Aggregator(10.0, cameras=["front", "rear"])
    agg.on_counters(_counters("detector", 1, serving=2, serving__front=1, serving__rear=1,
                              frames_in__front=5, frames_in__rear=5), 1.0)  # fmt: skip
    agg.on_counters(_counters("detector_2", 1, serving=0, serving__front=0, serving__rear=0), 1.1)
    assert {c: m["served_by"] for c, m in agg.cameras(1.2).items()} == {
        "front": "detector",
        "rear": "detector",
    }
    # detector_2 joins and takes rear; detector still reports its old frames_in.rear.
    agg.on_counters(_counters("detector_2", 2, serving=1, serving__rear=1, frames_in__rear=1), 2.0)
    agg.on_counters(_counters("detector", 2, serving=1, serving__front=1, serving__rear=0,
                              frames_in__front=9, frames_in__rear=6), 2.1)  # fmt: skip
    cams = agg.cameras(2.2)
    assert cams["front"]["served_by"] == "detector"
    assert cams["rear"]["served_by"] == "detector_2"
    assert cams["rear"]["frames_offered"] == 1


def test_workers_show_cameras_load_and_hand_overs() -> None:
    agg = Aggregator(10.0, cameras=["front", "rear"])
    counts = {"serving": 1, "serving__front": 1, "serving__rear": 0, "pool_load_permille": 500}
    agg.on_counters(_counters("detector", 1, **counts, pool_members=2, cameras_lost=1), 1.0)
    agg.on_counters(_counters("controller", 1, cmd_out=3), 1.0)
    workers = agg.answer(HDR, 3.0)["workers"]
    assert workers == {
        "detector": {
            "live": True, "cameras": ["front"], "load": 0.5, "members": 2, "cameras_gained": 0,
            "cameras_lost": 1, "reported_s_ago": 2.0, "load_from": "counters",
        }
    }  # fmt: skip


def test_a_frame_detected_twice_is_a_duplicate() -> None:
    agg = Aggregator(10.0, cameras=["front", "rear"])
    frame = Header(stamp_ns=1_000, frame_id="c", seq=7, source="camera")
    agg.on_detections(detections(frame, 1), 1.0, camera="front")
    agg.on_detections(detections(frame, 1), 1.0, camera="rear")  # another camera: no duplicate
    agg.on_detections(detections(frame, 1), 1.1, camera="front")
    answer = agg.answer(HDR, 1.2)
    assert answer["duplicate_detections"] == 1
    assert answer["cameras"]["front"]["duplicate_detections"] == 1
    assert answer["cameras"]["rear"]["duplicate_detections"] == 0
    assert answer["counters"]["metrics.duplicate_detections"] == 1


def test_made_up_camera_names_do_not_grow_the_frames_remembered() -> None:
    # A flood of detections on keys naming cameras nobody configured: past max_cameras they
    # are refused, and no frame of theirs is remembered for the duplicate count (whose memory
    # would otherwise grow with every new name).
    agg = Aggregator(10.0, cameras=["front"], max_cameras=2)
    frame = Header(stamp_ns=1_000, frame_id="c", seq=7, source="camera")
    for i in range(50):
        agg.on_detections(detections(frame, 1), 1.0, camera=f"fake{i}")
        agg.on_detections(detections(frame, 1), 1.0, camera=f"fake{i}")  # the same frame again
    answer = agg.answer(HDR, 1.2)
    assert answer["counters"]["metrics.cameras_refused"] == 2 * 49  # fake0 took the free place
    assert answer["duplicate_detections"] == 1  # fake0's, the one camera kept


def test_the_live_pool_names_who_serves_and_marks_a_gone_worker() -> None:
    # The killed worker's counters still say it serves rear; its tokens have gone.
    pool = LivePool(PoolAudit({"front": 0.5, "rear": 0.5}, 1.0, 10.0))
    agg = Aggregator(10.0, cameras=["front", "rear"], pool=pool)
    agg.on_counters(_counters("detector", 1, serving=1, serving__front=1, serving__rear=0), 1.0)
    agg.on_counters(_counters("detector_2", 1, serving=1, serving__front=0, serving__rear=1), 1.0)
    pool.member("detector", live=True)
    pool.serving(("detector", "z1", "front"), live=True)
    pool.serving(("detector", "z1", "rear"), live=True)  # it took rear over at once
    pool.check(2.0)
    answer = agg.answer(HDR, 2.0)
    assert {c: m["served_by"] for c, m in answer["cameras"].items()} == {
        "front": "detector",
        "rear": "detector",
    }
    workers = answer["workers"]
    assert (workers["detector"]["live"], workers["detector"]["cameras"]) == (
        True,
        ["front", "rear"],
    )
    assert (workers["detector_2"]["live"], workers["detector_2"]["cameras"]) == (False, [])
    assert answer["pool_warnings"] == []


def test_a_shared_boxs_worker_is_listed_on_the_robot_it_serves() -> None:
    """Issue 39, item 7: the GPU box's worker counts under the box's own prefix, so the
    robot hears none of its counters; its tokens and announcement still list it, with its
    capacity, robots and the share of it this robot's cameras take."""
    pool = LivePool(PoolAudit({"front": 1.0}, 1.0, 10.0), robot="site/r1", pool_prefix="site")
    pool.cameras = {"front": 5.0, "rear": 5.0}
    agg = Aggregator(10.0, cameras=["front", "rear"], pool=pool)
    box = PoolWorker(20.0, frozenset({"site/r1", "site/r2"}))
    pool.announced = {"detector_gpu": box, "detector_other": PoolWorker(9.0, frozenset({"x"}))}
    for worker in ("detector_gpu", "detector_other"):
        pool.member(worker, live=True)
    pool.serving(("detector_gpu", "z1", "site/r1/front"), live=True)
    pool.serving(("detector_gpu", "z1", "site/r2/front"), live=True)  # robot 2's: not shown
    pool.check(2.0)
    workers = agg.answer(HDR, 2.0)["workers"]
    assert workers == {
        "detector_gpu": {
            "live": True, "cameras": ["front"], "load": 0.25, "members": 0, "cameras_gained": 0,
            "cameras_lost": 0, "reported_s_ago": -1.0, "load_from": "cameras",
            "capacity_hz": 20.0, "robots": ["site/r1", "site/r2"],
        }
    }  # fmt: skip


def test_the_metrics_count_a_name_announced_twice_as_the_workers_do() -> None:
    # Issue 39: a second session re-announcing detector_2 at the highest capacity. The metrics
    # audit weighs the name with the lowest capacity claimed, as every worker does
    # (common/pool_rule.py's one_worker), so the workers' real split is what it expects, and
    # it says the name is announced twice (before: the newest claim, and no word).
    config = Config()
    config = replace(
        config, detector=replace(config.detector, pool_alarm_s=1.0, pool_deliver_s=600.0)
    )
    clock = FakeClock()
    handlers = MetricsHandlers(config, Tally("metrics", config), clock=clock)
    cams = ("front", "rear", "left", "right")
    handlers.set_cameras({c: announcement(c, config.camera) for c in cams})
    keys = handlers.pool_keys
    prefixes = (keys.prefix,)
    real = {w: WorkerAnnouncement(worker=w, capacity_hz=20.0, prefixes=prefixes)
            for w in ("detector", "detector_2")}  # fmt: skip
    claim = WorkerAnnouncement(worker="detector_2", capacity_hz=MAX_CAPACITY_HZ, prefixes=prefixes)
    handlers.set_workers(
        {"detector": [real["detector"]], "detector_2": [real["detector_2"], claim]}
    )
    assert handlers.pool.announced["detector_2"].capacity_hz == 20.0
    rates = {c: config.camera.rate_hz for c in cams}
    for cam, worker in assign({w: 20.0 for w in real}, rates, config.detector.pool_balance).items():
        handlers.on_pool_serving(keys.pool_serving(worker, f"zid{worker[-1]}", cam), True)
    for worker in real:
        handlers.on_pool_member(keys.pool_member(worker), True)
    clock.advance(1.5)
    handlers.audit_pool()
    found = {(f.kind, f.subject) for f in handlers.pool.report.current}
    assert found == {("name_twice", "detector_2")}, handlers.pool.report.current
