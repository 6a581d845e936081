"""The controller's loop in-process (tests/unit/controller/rig.py): inputs put on the bus, one
tick, the Twist and the status read back from the bus. The clock is a FakeClock: ages are exact
and nothing waits. What needs processes (restarts, signals, the router's access control, a
real tick rate) is in tests/integration/test_safety*.py."""

from __future__ import annotations

import itertools
import json
import logging
import math
from collections.abc import Iterator
from pathlib import Path

import pytest

from common.clock import FakeClock
from services.camera.contract import CameraSettings
from services.controller.estop import EStopLatch
from services.controller.geometry import focal_px
from services.controller.service import NO_LASER_WARNING
from services.controller.statelog import STATE_CHANGES
from tests.unit.controller.rig import Rig, W, people

HOUR_S = 3600.0
REAR = CameraSettings(mount_yaw_deg=180.0)
#: Column of a person 20 deg left of the front camera's centre.
LEFT_20 = W / 2 - focal_px(W, CameraSettings().hfov_deg) * math.tan(math.radians(20))


@pytest.fixture
def rig(tmp_path: Path, delivery_threads: int) -> Iterator[Rig]:
    r = Rig(tmp_path, threads=delivery_threads)
    yield r
    r.close()


@pytest.mark.parametrize("cx,sign", [(LEFT_20, 1.0), (W - LEFT_20, -1.0)], ids=["left", "right"])
def test_a_person_off_centre_is_turned_to_in_place(rig: Rig, cx: float, sign: float) -> None:
    rig.scan()
    rig.detections(payload=people(rig.header(), cx=cx))
    twist, status = rig.tick()
    assert status.state == "turning" and twist.linear[0] == 0.0, status
    assert twist.angular[2] != 0.0 and math.copysign(1.0, twist.angular[2]) == sign, twist


def test_a_centred_person_is_driven_to_by_a_command_stamped_at_the_tick(rig: Rig) -> None:
    rig.scan()
    rig.detections()
    captured = rig.clock.now().wall_ns  # the detections were stamped now
    rig.clock.advance(0.02)
    twist, status = rig.tick()
    assert status.state == "tracking" and twist.linear[0] > 0 and twist.angular[2] == 0.0
    # Stamped at the tick's instant, naming the frame it reacts to; the status shares it.
    assert twist.header.stamp_ns == rig.clock.now().wall_ns
    assert twist.input_stamp_ns == captured and status.header == twist.header
    assert rig.counters["detections_in"] == 1 and rig.counters["scans_in"] == 1


def test_detections_older_than_the_timeout_stop_the_robot(rig: Rig) -> None:
    timeout = rig.config.controller.detection_timeout_s
    rig.scan()
    rig.detections()
    assert rig.tick()[1].state == "tracking"
    rig.clock.advance(timeout - 0.05)  # still within the dead-man's timeout ...
    rig.scan()
    twist, status = rig.tick()
    assert status.state == "tracking" and not twist.is_zero
    rig.clock.advance(0.1)  # ... and now past it: zero, at once
    rig.scan()
    twist, status = rig.tick()
    assert twist.is_zero and status.state == "stale", status
    assert status.reason == f"detections are {timeout + 0.05:.2f} s old"
    # Detections that arrive already older than the timeout are refused and counted.
    rig.detections(age_s=timeout + 0.01)
    twist, status = rig.tick()
    assert twist.is_zero and status.state == "stale"
    assert rig.counters["detections_stale"] == 1


def test_before_any_detections_the_robot_stands_still(rig: Rig) -> None:
    rig.scan()
    twist, status = rig.tick()
    assert (
        twist.is_zero
        and status.state == "stale"
        and status.reason == ("no detections received yet")
    )


@pytest.mark.parametrize("case", ["no scan", "a stale scan", "0.1 m", "0.2 m", "0.3 m"])
def test_no_forward_motion_unless_the_way_ahead_is_known_clear(rig: Rig, case: str) -> None:
    stale_s = rig.config.controller.scan_timeout_s + 0.05
    for _ in range(20):
        if case == "a stale scan":
            rig.scan(age_s=stale_s)
        elif case != "no scan":
            rig.scan(ahead_m=float(case.split()[0]))
        rig.detections()
        twist, status = rig.tick()
        assert twist.linear[0] == 0.0, f"{case}: drove forward"
        assert status.state == "blocked" and not status.no_laser, status
        rig.clock.advance(0.05)
    if case == "no scan":
        assert status.reason == "no recent laser scan", status.reason
    elif case == "a stale scan":
        assert rig.counters["scans_stale"] == 20
    else:
        assert status.reason == f"obstacle at {case[:3]}0 m", status.reason
    # The control: the same person with the way known clear is driven to.
    rig.scan()
    rig.detections()
    assert rig.tick()[0].linear[0] > 0


def test_without_a_laser_only_the_setting_drives_and_every_status_says_so(
    tmp_path: Path, delivery_threads: int, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING, "controller"):
        rig = Rig(tmp_path, threads=delivery_threads, no_laser=True)
    try:
        assert NO_LASER_WARNING in caplog.text
        rig.detections()
        twist, status = rig.tick()
        assert twist.linear[0] > 0 and status.state == "tracking"
        rig.clock.advance(0.05)
        rig.scan(ahead_m=0.2)  # a scan that does come is obeyed all the same
        rig.detections()
        twist, status = rig.tick()
        # Braking at the acceleration limit from the one tick's speed: to zero, but for
        # the rounding of that subtraction.
        assert twist.linear[0] == pytest.approx(0.0, abs=1e-9) and status.state == "blocked"
        assert all(s.no_laser for s in rig.statuses)
    finally:
        rig.close()


def test_an_engage_stops_at_once_latches_and_persists(rig: Rig, tmp_path: Path) -> None:
    rig.scan()
    rig.detections()
    assert not rig.tick()[0].is_zero
    rig.clock.advance(0.01)
    before = len(rig.cmds)
    rig.estop(True)
    # Before any tick, from the handler itself: the zero at once (before the stop is saved),
    # then the e-stop status with its own zero.
    assert len(rig.cmds[before:]) == 2 and all(t.is_zero for t in rig.cmds[before:])
    assert rig.statuses[-1].state == "estop" and rig.statuses[-1].estop_saved
    assert rig.counters["estop_zero_at_once"] == 1
    assert json.loads((tmp_path / "estop.json").read_text())["engaged"] is True
    for _ in range(10):
        rig.scan()
        rig.detections()
        twist, status = rig.tick()
        assert twist.is_zero and status.state == "estop", status
        assert status.reason.startswith("e-stop by estop: test"), status.reason
        rig.clock.advance(0.05)
    # A release captured longer ago than allowed is refused; the latch holds.
    rig.estop(False, age_s=rig.config.controller.estop_release_max_age_s + 1.0)
    rig.detections()
    twist, status = rig.tick()
    assert twist.is_zero and "last release refused: stale" in status.reason, status.reason
    assert rig.counters["estop_release_refused"] == 1
    # A fresh release frees the robot, and is on disk.
    rig.estop(False)
    rig.clock.advance(0.05)
    rig.scan()
    rig.detections()
    assert not rig.tick()[0].is_zero
    assert json.loads((tmp_path / "estop.json").read_text())["engaged"] is False


def test_a_new_loop_reads_the_latch_and_garbage_on_the_key_is_a_press(
    tmp_path: Path, delivery_threads: int
) -> None:
    clock = FakeClock()
    first = Rig(tmp_path, threads=delivery_threads, clock=clock)
    first.put(first.keys.estop(), b"\x00not an e-stop")  # fails safe: a press
    assert first.cmds[-1].is_zero and first.statuses[-1].state == "estop"
    assert first.counters["bad_input"] == 1
    first.close()
    second = Rig(
        tmp_path, threads=delivery_threads, clock=clock
    )  # the restarted controller, on the same file
    try:
        second.scan()
        second.detections()
        twist, status = second.tick()
        assert twist.is_zero and status.state == "estop"
        assert "undecodable message on the e-stop key" in status.reason
    finally:
        second.close()


def test_an_engage_stamped_a_century_ahead_can_still_be_released(
    tmp_path: Path, delivery_threads: int
) -> None:
    clock = FakeClock()
    rig = Rig(tmp_path, threads=delivery_threads, clock=clock)
    try:
        rig.estop(True, ahead_s=100 * 365 * 86400.0)
        # Past the clock tolerance, the most a latch's stamp may be ahead of this clock.
        clock.advance(rig.config.stack.clock_tolerance_s + 0.01)
        rig.estop(False)  # stamped now: later than the latch, which is bounded by the clock
        rig.scan()
        rig.detections()
        assert not rig.tick()[0].is_zero
    finally:
        rig.close()
    # A controller started on that file is released too.
    latch = EStopLatch(tmp_path / "estop.json", clock.wall_ns())
    assert not latch.engaged


def test_a_corrupt_state_file_starts_engaged(tmp_path: Path, delivery_threads: int) -> None:
    (tmp_path / "estop.json").write_text(
        '{"engaged": false, "since_ns": 1e400, "by": "x", "reason": "y"}'
    )
    rig = Rig(tmp_path, threads=delivery_threads)
    try:
        rig.scan()
        rig.detections()
        twist, status = rig.tick()
        assert twist.is_zero and status.state == "estop", status
        assert json.loads((tmp_path / "estop.json").read_text())["engaged"] is True
    finally:
        rig.close()


def test_stale_future_and_replayed_detections_are_counted_and_never_acted_on(
    tmp_path: Path,
    delivery_threads: int,
) -> None:
    rig = Rig(
        tmp_path, threads=delivery_threads, target_lost_timeout_s=0.1
    )  # a target gone is let go of at once
    try:
        rig.scan()
        for name, kw in (("stale", {"age_s": HOUR_S}), ("future", {"ahead_s": HOUR_S})):
            rig.detections(**kw)
            twist, status = rig.tick()
            assert twist.is_zero and status.state == "stale", f"{name}: {status}"
            assert rig.counters[f"detections_{name}"] == 1
            rig.clock.advance(0.05)
        # A replay: an old message again, after a newer one from the same source.
        old_header = rig.header()
        old = people(old_header)
        rig.put(rig.keys.detections("front"), old)
        twist = rig.tick()[0]
        assert not twist.is_zero and twist.input_stamp_ns == old_header.stamp_ns
        rig.clock.advance(0.2)
        rig.scan()
        rig.put(rig.keys.detections("front"), people(rig.header(), n=0))  # nobody in view
        twist, status = rig.tick()
        assert twist.is_zero and status.state == "searching", status
        for _ in range(5):
            rig.clock.advance(0.05)
            rig.put(rig.keys.detections("front"), old)
            twist, status = rig.tick()
            assert twist.is_zero and status.state == "searching", "a replayed message moved it"
        assert rig.counters["detections_replay"] == 5
        assert rig.counters["detections_in"] == 2
    finally:
        rig.close()


def test_garbage_on_every_key_is_counted_and_the_loop_keeps_commanding(rig: Rig) -> None:
    keys = [rig.keys.detections("front"), rig.keys.scan(), rig.keys.estop()]
    for key in keys:
        rig.put(key, b"\xc1garbage")
    twist, status = rig.tick()
    assert twist.is_zero and status.state == "estop"  # garbage on the e-stop key: a press
    c = rig.counters
    assert c["bad_input"] == 3, c
    assert {c["bad_input.detections"], c["bad_input.scan"], c["bad_input.estop"]} == {1}, c
    for _ in range(3):
        rig.clock.advance(0.05)
        assert rig.tick()[0].is_zero


def test_the_last_word_on_shutdown_is_a_stop(rig: Rig) -> None:
    rig.scan()
    rig.detections()
    assert not rig.tick()[0].is_zero
    rig.loop.stop()
    rig.drain()
    assert rig.cmds[-1].is_zero
    assert rig.statuses[-1].state == "stopped" and rig.statuses[-1].reason == "shutdown"


def test_a_person_behind_is_turned_to_and_a_stale_camera_is_ignored(
    tmp_path: Path, delivery_threads: int
) -> None:
    rig = Rig(tmp_path, threads=delivery_threads, cameras={"rear": REAR})
    timeout = rig.config.controller.detection_timeout_s
    try:
        # Centred in the rear camera only (bearing 180 deg): a turn in place; front named stale.
        rig.scan()
        rig.detections("rear")
        twist, status = rig.tick()
        assert status.state == "turning" and status.camera == "rear", status
        assert twist.linear[0] == 0.0 and twist.angular[2] > 0
        assert status.stale_cameras == ("front",)
        # Silence past the timeout: the dead-man stop, both cameras named.
        rig.clock.advance(timeout + 0.01)
        rig.scan()
        twist, status = rig.tick()
        assert twist.is_zero and status.state == "stale"
        assert status.stale_cameras == ("front", "rear")
        # Old detections of a person behind beside fresh empty ones in front: rear ignored.
        rig.detections("rear", age_s=2 * timeout)
        rig.detections("front", people(rig.header(), n=0))
        twist, status = rig.tick()
        assert twist.is_zero and status.state == "searching", status
        assert status.stale_cameras == ("rear",)
        c = rig.counters
        assert c["detections_stale.rear"] == c["detections_stale"] == 1, c
        assert c["detections_in.rear"] == 1 and c["detections_in.front"] == 1, c
    finally:
        rig.close()


def test_detections_that_flip_the_state_are_summarised_not_logged_each(
    rig: Rig, caplog: pytest.LogCaptureFixture
) -> None:
    # As a slow CPU: detections 0.9 s old at arrival, one every 0.2 s, with a 1 s timeout:
    # fresh for 0.1 s, then stale until the next. Ticks every 0.05 s for 30 s.
    rig.scan()
    states = []
    with caplog.at_level(logging.INFO, "controller"):
        for n in range(600):
            if n % 4 == 0:
                rig.detections(age_s=0.9)
            rig.scan()
            states.append(rig.tick()[1].state)
            rig.clock.advance(0.05)
    changes = sum(a != b for a, b in itertools.pairwise(states))
    logged = caplog.text.count("state ")
    assert changes >= 100, f"only {changes} changes: the case did not flip-flop"
    assert f"{STATE_CHANGES}:" in caplog.text, "no summary of the changes not logged"
    assert logged < changes / 10, f"{logged} state lines for {changes} changes"
