"""The metrics service in-process: a MetricsService on a MemoryHub with a FakeClock. The test
is the detector, the controller and the cameras' processes: it puts Detections on each
camera's key, Twists reacting to some frames, services' counters and the pool's tokens, and
asks the metrics query as ``zstack query`` does (``keys.metrics()``). The clock moves only
when told: rates and ages are exact."""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import replace
from functools import partial
from typing import Any

import pytest

from common.announce import Announcer
from common.bus import QoS
from common.clock import BOOT_ID, FakeClock
from common.keys import Keys
from common.memory_bus import MemoryBus, MemoryHub
from common.messages import Header, ServiceCounters, Twist, WorkerAnnouncement
from common.node import Node
from services.camera.contract import CameraSettings
from services.detector.contract import DetectorSettings
from services.metrics.service import MetricsService
from stack.config import Config
from tests.unit.announced import Sources
from tests.unit.metrics.samples import detections

MS = 1_000_000
FRAMES = {"front": 20, "rear": 10}  # detections messages put per camera, 10 a second
BOXES = {"front": 2, "rear": 1}  # boxes in each
REACTED = {"front": 5, "rear": 4}  # frames a Twist reacts to, the first of each camera's
DETECTOR_COUNTS = {
    "frames_in": 33, "dropped": 3, "frames_in.front": 22, "dropped.front": 2,
    "frames_in.rear": 11, "dropped.rear": 1, "detections_out.rear": 10,
}  # fmt: skip
POOL_ALARM_S = 2.0


class Rig:
    """The metrics service and the test's participant (``probe``) on one hub."""

    def __init__(self) -> None:
        self.config = Config(
            cameras=(("rear", CameraSettings(mount_yaw_deg=180.0)),),
            detector=DetectorSettings(pool_alarm_s=POOL_ALARM_S),
        )
        self.clock = FakeClock()
        self.hub = MemoryHub()
        self.sources = Sources(self.hub, Keys(self.config.stack.prefix))
        for name, camera in self.config.all_cameras.items():  # as their sources would
            self.sources.announce(name, camera)
        self.node = Node("metrics", self.config, bus=self.hub.join("metrics"), clock=self.clock)
        self.service = MetricsService(self.config, self.node)
        self.keys = self.node.keys
        self.probe = self.hub.join("test")

    def put(self, key: str, payload: bytes) -> None:
        self.probe.publisher(key, QoS.TELEMETRY).put(payload)

    def header(self, source: str, seq: int, stamp_ns: int) -> Header:
        return Header(stamp_ns=stamp_ns, frame_id=source, seq=seq, source=source, boot_id=BOOT_ID)

    def counters(self, service: str, **counts: int) -> None:
        msg = ServiceCounters(
            header=self.header(service, 1, self.clock.wall_ns()),
            service=service,
            counters={k.replace("__", "."): v for k, v in counts.items()},
        )
        self.put(self.keys.counters(service), msg.encode())

    def query(self) -> dict[str, Any]:
        [reply] = self.probe.query(self.keys.metrics(), timeout_s=1.0)
        answer: dict[str, Any] = json.loads(reply.payload)
        return answer

    def close(self) -> None:
        self.service.close()
        self.sources.close()
        self.probe.close()
        self.node.close()


@pytest.fixture
def rig() -> Iterator[Rig]:
    r = Rig()
    yield r
    r.close()


def feed_two_cameras(rig: Rig) -> None:
    """Each camera's detections at 10 Hz (their frames captured as they are heard), a Twist
    150 ms after the capture of each camera's first REACTED frames, and the counters."""
    keys = rig.keys
    for seq in range(max(FRAMES.values())):
        for camera, frames in FRAMES.items():
            if seq >= frames:
                rig.clock.advance(0.007)
                continue
            stamp = rig.clock.wall_ns()
            dets = detections(rig.header(camera, seq + 1, stamp), BOXES[camera])
            rig.put(keys.detections(camera), dets.encode())
            if seq < REACTED[camera]:
                twist = Twist(
                    header=rig.header("controller", seq + 1, stamp + 150 * MS),
                    angular=(0.0, 0.0, 0.1),
                    input_stamp_ns=stamp,
                )
                rig.put(keys.cmd_vel(), twist.encode())
            rig.clock.advance(0.007)  # the cameras' stamps never coincide
        rig.clock.advance(0.1 - 0.007 * len(FRAMES))
    # Two reports of the detector's counters: one more batch of two frames between them.
    for n in (1, 2):
        counts = {**DETECTOR_COUNTS, "batches": n, "batched_frames": 2 * n}
        rig.put(keys.counters("detector"), _counters("detector", rig, counts))
        rig.clock.advance(0.5)
    rig.put(keys.counters("camera_rear"), _counters("camera_rear", rig, {"frames_out": 12}))


def _counters(service: str, rig: Rig, counts: dict[str, int]) -> bytes:
    header = rig.header(service, 1, rig.clock.wall_ns())
    return ServiceCounters(header=header, service=service, counters=counts).encode()


def test_the_query_shows_each_camera(rig: Rig) -> None:
    feed_two_cameras(rig)
    answer = rig.query()
    assert list(answer["cameras"]) == ["front", "rear"]
    for camera, m in answer["cameras"].items():
        assert m["fps"] == pytest.approx(10.0), camera
        assert m["frames"] == FRAMES[camera]
        assert m["detections"] == FRAMES[camera] * BOXES[camera]
        assert m["detections_per_frame"] == BOXES[camera]
        lat = m["latency_ms"]
        assert lat["end_to_end"]["count"] == REACTED[camera]
        assert lat["end_to_end"]["p50"] == pytest.approx(150.0)
        assert lat["detections_to_command"]["p50"] == pytest.approx(60.0)
        assert lat["capture_to_detections"]["p95"] == pytest.approx(90.0)
        assert lat["inference"]["count"] == FRAMES[camera]
        assert m["served_by"] == "detector"  # by its counters: no pool token heard
        assert m["frames_offered"] == DETECTOR_COUNTS[f"frames_in.{camera}"]
        assert m["dropped_frames"] == DETECTOR_COUNTS[f"dropped.{camera}"]
        assert m["batch_mean"] == 2.0
    assert answer["cameras"]["rear"]["counters"]["detector.detections_out"] == 10
    # The top level is both cameras together, with every field it always had.
    assert answer["frames"] == sum(FRAMES.values())
    # 30 detections from the first (front's) to the last (front's too) 1.9 s later.
    assert answer["fps"] == pytest.approx((sum(FRAMES.values()) - 1) / 1.9)
    assert answer["latency_ms"]["end_to_end"]["count"] == sum(REACTED.values())
    assert (answer["frames_offered"], answer["dropped_frames"]) == (33, 3)
    assert {"fps", "drop_rate", "drop_rate_total", "timeline", "class_counts"} <= answer.keys()
    assert answer["class_counts"] == {"person": 50}
    # The header and the timeline are on the injected clock (Unix seconds).
    assert answer["stamp_ns"] == rig.clock.wall_ns()
    assert all(abs(t - rig.clock.wall_ns() / 1e9) < 10 for t in answer["timeline"]["t"])
    # A further camera's own process is believed.
    assert answer["counters"]["camera_rear.frames_out"] == 12
    assert "metrics.refused.unknown_service" not in answer["counters"]
    assert answer["warnings"] == {}


def test_the_window_forgets_on_the_injected_clock(rig: Rig) -> None:
    feed_two_cameras(rig)
    rig.clock.advance(rig.config.metrics.window_s + 1.0)
    answer = rig.query()
    assert answer["fps"] == 0.0 and answer["frames"] == sum(FRAMES.values())
    assert answer["latency_ms"]["end_to_end"]["count"] == 0
    assert answer["cameras"]["front"]["fps"] == 0.0


def test_a_frame_detected_twice_is_counted_as_a_duplicate(rig: Rig) -> None:
    header = rig.header("front", 7, rig.clock.wall_ns())
    for _ in range(2):  # two workers during a hand-over
        rig.put(rig.keys.detections("front"), detections(header, 1).encode())
    answer = rig.query()
    assert answer["duplicate_detections"] == 1
    assert answer["cameras"]["front"]["duplicate_detections"] == 1
    assert answer["cameras"]["rear"]["duplicate_detections"] == 0


def test_detections_that_come_too_late_bring_a_warning_with_the_fixes(rig: Rig) -> None:
    # As a slow CPU: published 0.9 s after capture, five a second, with a 1 s timeout.
    for seq in range(10):
        stamp = rig.clock.wall_ns() - 900 * MS
        dets = detections(rig.header("front", seq + 1, stamp), 1, published_ms=900.0)
        rig.put(rig.keys.detections("front"), dets.encode())
        rig.clock.advance(0.2)
    told = rig.query()["warnings"]["detections_late"]
    assert "detections come too late" in told and "front: " in told and "p95 900 ms" in told
    assert 'detector.profile = "fast"' in told and "detector.imgsz" in told, told
    assert "fewer cameras (now 2)" in told and "controller.detection_timeout_s" in told, told


def test_the_cameras_are_the_announced_ones(rig: Rig) -> None:
    answer = rig.query()
    assert list(answer["cameras"]) == ["front", "rear"]  # before any detections
    assert answer["cameras_announced"]["rear"] == {
        "width": 640, "height": 480, "rate_hz": 10.0, "mount_yaw_deg": 180.0,
        "hfov_deg": 60.0, "frame_id": "camera", "source": "test", "depth": False,
        "mount_x_m": 0.0, "mount_y_m": 0.0, "mount_height_m": 0.0,
    }  # fmt: skip
    # A camera announced at run time gets its figures at once, and its detections count.
    rig.sources.announce("left", mount_yaw_deg=90.0, rate_hz=5.0)
    assert list(rig.query()["cameras"]) == ["front", "rear", "left"]
    header = rig.header("left", 1, rig.clock.wall_ns())
    rig.put(rig.keys.detections("left"), detections(header, 1).encode())
    answer = rig.query()
    assert answer["cameras"]["left"]["frames"] == 1 and answer["frames"] == 1
    assert answer["cameras_announced"]["left"]["mount_yaw_deg"] == 90.0
    # Detections of a camera nobody announces, or no longer, are counted and dropped.
    rig.sources.withdraw("left")
    for seq, camera in enumerate(("left", "ghost", "ghost"), start=2):
        header = rig.header(camera, seq, rig.clock.wall_ns())
        rig.put(rig.keys.detections(camera), detections(header, 1).encode())
    answer = rig.query()
    assert answer["frames"] == 1 and "ghost" not in answer["cameras"]
    assert answer["cameras"]["left"]["frames"] == 1  # its figures stay
    assert sorted(answer["cameras_announced"]) == ["front", "rear"]
    assert answer["counters"]["metrics.detections_unannounced"] == 3


def _worker(
    rig: Rig,
    name: str,
    cameras: list[str],
    capacity_hz: float = 10.0,
    keys: Keys | None = None,
    prefixes: tuple[str, ...] = (),
) -> MemoryBus:
    """A detector worker's tokens and announcement (its capacity and robots), as its session
    declares them under the pool's ``keys`` (the rig's by default); gone when it is closed.
    ``cameras``: the pool names of those it serves."""
    keys = keys or rig.keys
    bus = rig.hub.join(name)
    announcement = WorkerAnnouncement(worker=name, capacity_hz=capacity_hz, prefixes=prefixes)
    Announcer(bus, partial(keys.worker_announcement, name)).update(announcement)
    bus.declare_token(keys.pool_member(name))
    for camera in cameras:
        bus.declare_token(keys.pool_serving(name, bus.zid, camera))
    return bus


def test_the_pool_tokens_say_who_serves_and_what_is_wrong(rig: Rig) -> None:
    first = _worker(rig, "detector", ["front", "rear"])
    rig.counters("detector", serving=2, serving__front=1, serving__rear=1)
    rig.clock.advance(POOL_ALARM_S + 0.5)
    answer = rig.query()
    assert {c: m["served_by"] for c, m in answer["cameras"].items()} == {
        "front": "detector",
        "rear": "detector",
    }
    assert answer["pool_warnings"] == [] and answer["workers"]["detector"]["live"]
    # A second worker serving front too: said only once it has lasted the alarm time.
    second = _worker(rig, "detector_2", ["front"])
    assert rig.query()["cameras"]["front"]["served_by"] == "detector, detector_2"
    assert rig.query()["pool_warnings"] == []
    rig.clock.advance(POOL_ALARM_S + 0.5)
    warnings = rig.query()["pool_warnings"]
    assert any("camera front is served by 2 workers" in w for w in warnings), warnings
    # The first worker gone (its session closed): rear is served by nobody, and the worker
    # that still counts as serving it by its last counters is not live.
    first.close()
    answer = rig.query()
    assert answer["cameras"]["rear"]["served_by"] == ""
    assert answer["cameras"]["front"]["served_by"] == "detector_2"
    assert answer["workers"]["detector"]["live"] is False
    rig.clock.advance(POOL_ALARM_S + 0.5)
    warnings = rig.query()["pool_warnings"]
    assert any("camera rear is served by no detector worker" in w for w in warnings), warnings
    assert not any("served by 2" in w for w in warnings), warnings
    second.close()


def test_the_pool_is_audited_by_the_announced_capacities(rig: Rig) -> None:
    """A fast and a slow worker: the rule gives the fast one both cameras (the slow one's
    share is under one camera), which is no idle member (an audit of equal capacities would
    give each one camera and warn that the slow one serves none); a token alone is no member,
    so it is not warned of either."""
    fast = _worker(rig, "detector", ["front", "rear"], capacity_hz=30.0)
    slow = _worker(rig, "detector_2", [], capacity_hz=1.0)
    stray = rig.hub.join("stray")
    stray.declare_token(rig.keys.pool_member("stray"))
    rig.query()
    rig.clock.advance(POOL_ALARM_S + 0.5)
    assert rig.query()["pool_warnings"] == []
    # The fast one gone: both cameras go to the slow one, which does not serve them.
    fast.close()
    rig.query()
    rig.clock.advance(POOL_ALARM_S + 0.5)
    warnings = rig.query()["pool_warnings"]
    assert any("detector_2 serves none of the cameras" in w for w in warnings), warnings
    slow.close()
    stray.close()


def test_a_robots_metrics_see_its_own_cameras_in_a_pool_under_another_prefix() -> None:
    """robot2's metrics, its cameras served by a pool under robot1 (detector.pool_prefix):
    the pool's tokens are heard there, its cameras' pool names (robot2/front) read as its
    own, and robot1's front (bare in the pool) is not robot2's front."""
    base = Config(detector=DetectorSettings(pool_alarm_s=POOL_ALARM_S, pool_prefix="robot1"))
    config = replace(base, stack=replace(base.stack, prefix="robot2"))
    clock, hub = FakeClock(), MemoryHub()
    sources = Sources(hub, Keys("robot2"))
    sources.announce("front", config.camera)
    node = Node("metrics", config, bus=hub.join("metrics"), clock=clock)
    service = MetricsService(config, node)
    rig = Rig.__new__(Rig)
    rig.hub, rig.keys, rig.clock = hub, Keys("robot2"), clock
    rig.probe = hub.join("test")
    pool = Keys("robot1")
    both = ("robot1", "robot2")
    one = _worker(rig, "detector", ["front"], keys=pool, prefixes=both)  # robot1's front
    two = _worker(rig, "detector_2", ["robot2/front"], keys=pool, prefixes=both)
    rig.counters("detector_2", serving=1)
    rig.counters("detector", serving=1)
    answer = rig.query()
    assert answer["cameras"]["front"]["served_by"] == "detector_2"
    assert answer["workers"]["detector_2"]["cameras"] == ["front"]
    assert answer["workers"]["detector"]["cameras"] == []  # robot1's front is not ours
    two.close()
    clock.advance(POOL_ALARM_S + 0.5)
    rig.query()
    clock.advance(POOL_ALARM_S + 0.5)
    warnings = rig.query()["pool_warnings"]
    assert warnings == ["camera robot2/front is served by no detector worker (the pool gives "
                        "it to detector) for 5 s"], warnings  # fmt: skip
    for bus in (one, rig.probe):
        bus.close()
    service.close()
    sources.close()
    node.close()


def test_garbage_and_strangers_are_counted_never_answered(rig: Rig) -> None:
    rig.put(rig.keys.detections("front"), b"\xc1garbage")
    rig.put(rig.keys.cmd_vel(), b"\xc1garbage")
    rig.counters("stranger", frames_out=1)  # no service of this stack
    rig.put(rig.keys.detections("side"), b"\xc1not heard")  # a camera the config does not name
    answer = rig.query()
    c = answer["counters"]
    assert c["metrics.bad_input"] == 2 and c["metrics.refused.unknown_service"] == 1, c
    assert "stranger.frames_out" not in c and list(answer["cameras"]) == ["front", "rear"]


def test_the_report_line_comes_once_a_period(rig: Rig, caplog: pytest.LogCaptureFixture) -> None:
    period = rig.config.metrics.report_period_s
    with caplog.at_level("INFO", "metrics"):
        rig.service.report()  # not yet due
        assert "fps " not in caplog.text
        rig.clock.advance(period)
        rig.service.report()
        rig.service.report()  # once per period
    assert caplog.text.count("fps ") == 1


def test_no_live_worker_at_all_leaves_every_camera_unserved(rig: Rig) -> None:
    # Issue 39: a robot whose detector pool is on a shared box that is down hears no pool
    # token at all; before, its metrics said nothing of it.
    rig.query()
    rig.clock.advance(POOL_ALARM_S + 0.5)
    warnings = rig.query()["pool_warnings"]
    for camera in ("front", "rear"):
        assert any(
            f"camera {camera} is served by no detector worker (no live detector worker)" in w
            for w in warnings
        ), warnings


def test_a_member_that_claims_every_camera_and_delivers_nothing_is_warned_of(rig: Rig) -> None:
    # Issue 39: a liar at the highest capacity there is, with serving tokens for both cameras
    # (forged: it detects nothing), beside a worker that delivers. Before, with the forged
    # tokens, no warning at all. Now the metrics judge it as the workers do.
    deliver_s = rig.config.detector.pool_deliver_s
    honest = _worker(rig, "detector", [])
    liar = _worker(rig, "zz", ["front", "rear"], capacity_hz=100_000.0)
    rig.query()
    for _ in range(int((deliver_s + POOL_ALARM_S) / 0.5) + 4):
        rig.clock.advance(0.5)
        rig.query()
    warnings = rig.query()["pool_warnings"]
    assert any("pool member zz, dropped from the pool" in w for w in warnings), warnings
    assert any(
        "camera front is served by no detector worker (no detections of it arrive" in w
        for w in warnings
    ), warnings
    honest.close()
    liar.close()
