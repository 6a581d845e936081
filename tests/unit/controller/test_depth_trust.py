"""Whose depth the controller believes (issue 38), in-process (tests/unit/controller/rig.py):
depth only from the Zenoh session that announced the camera, none stamped ahead of this host's
own clock, and a WARNING (and the gauge the metrics read) when a camera's real frames keep
arriving older than the one held, the sign of a second stream on its key."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest

from common.bus import QoS
from common.memory_bus import MemoryBus
from common.messages import CameraAnnouncement, Header
from depthscan.trust import LateWatch, foreign_source
from services.depthscan import contract
from tests.unit.controller.rig import Rig
from tests.unit.depthscan.depth_scenes import HFOV, Face, at_bearing, depth_frame, scene

HEIGHT = 0.6
FOREIGN = contract.DEPTH_FOREIGN
SECOND = contract.DEPTH_SECOND_STREAM


def announce(rig: Rig, *, with_zid: bool = True) -> MemoryBus:
    """The front depth camera announced by its source's session (naming it, ``with_zid``);
    that session."""
    rig.announce("front", hfov_deg=HFOV, depth=True, mount_height_m=HEIGHT)
    source = rig.sources.live["front"][0]
    if with_zid:
        rig.announce("front", hfov_deg=HFOV, depth=True, mount_height_m=HEIGHT, zid=source.zid)
    return source


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[Rig]:
    r = Rig(tmp_path, announced=False, obstacle_sources=("depth",))
    yield r
    r.close()


def put(rig: Rig, bus: MemoryBus, header: Header, *faces: Face, handle: bool = True) -> None:
    """A depth image of the floor (and ``faces``) put on the front camera's key by ``bus``."""
    frame = depth_frame(scene(HEIGHT, *faces), header)
    bus.publisher(rig.keys.depth("front"), QoS.SENSOR).put(frame.encode())
    if handle:
        assert rig.stage is not None
        rig.handle_depth()


def count(rig: Rig, name: str) -> int:
    return rig.stage_counters.get(name, 0)


def drives(rig: Rig) -> bool:
    rig.detections()
    twist, _ = rig.tick()
    return twist.linear[0] > 0


def test_depth_from_another_session_is_dropped_before_decoding(rig: Rig) -> None:
    source = announce(rig)
    forger = rig.hub.join("forger")
    forger.publisher(rig.keys.depth("front"), QoS.SENSOR).put(b"\x93not even a depth frame")
    assert count(rig, FOREIGN) == 1 and count(rig, f"{FOREIGN}.front") == 1
    assert count(rig, "bad_input") == 0  # never decoded
    # The real source shows a box within the safety distance; the forger, stamped ahead, a
    # clear floor: the box is what the controller sees.
    put(rig, source, rig.header(source="sim"), at_bearing(0.4, 0.0))
    put(rig, forger, rig.header(source="forged", ahead_s=0.09))
    assert not drives(rig)
    assert count(rig, "depth_in") == 1 and count(rig, FOREIGN) == 2
    rig.clock.advance(0.05)
    put(rig, source, rig.header(source="sim"))  # the real source's next frame is taken
    assert count(rig, "depth_in") == 2 and count(rig, FOREIGN) == 2


def test_a_sample_with_no_publisher_id_is_foreign_to_an_announcement_with_one() -> None:
    a = CameraAnnouncement(camera="front", rate_hz=5.0, zid="abc123")
    assert foreign_source(a, "unidentified") and foreign_source(a, "abc12/1")
    assert not foreign_source(a, "abc123/7")
    assert not foreign_source(replace(a, zid=""), "anyone/1")  # an older announcer: unchecked


def test_an_announcement_without_its_session_id_takes_any_publisher_and_says_so(
    rig: Rig, caplog: pytest.LogCaptureFixture
) -> None:
    announce(rig, with_zid=False)
    other = rig.hub.join("bridge")
    with caplog.at_level(logging.WARNING):
        put(rig, other, rig.header(source="sim"))
        rig.clock.advance(0.05)
        put(rig, other, rig.header(source="sim"))
    assert count(rig, "depth_in") == 2 and count(rig, FOREIGN) == 0
    told = [r for r in caplog.records if "without its session id" in r.getMessage()]
    assert len(told) == 1 and "front" in told[0].getMessage()  # once per announcement
    assert drives(rig)


def test_depth_stamped_ahead_of_this_hosts_clock_is_refused(rig: Rig) -> None:
    source = announce(rig)
    tolerance = rig.config.controller.depth_future_tolerance_s
    assert tolerance < 0.09 < rig.config.stack.clock_tolerance_s  # the attack's +0.09 s
    put(rig, source, rig.header(source="sim", ahead_s=0.09))
    assert count(rig, "depth_future") == 1 and count(rig, "depth_future.front") == 1
    assert count(rig, "depth_in") == 0 and not drives(rig)
    # Within the same-clock tolerance: taken.
    rig.clock.advance(0.05)
    put(rig, source, rig.header(source="sim", ahead_s=tolerance / 2))
    assert count(rig, "depth_in") == 1
    # Stamped on another host (another boot): the cross-host tolerance judges it.
    rig.clock.advance(0.05)
    other_host = replace(rig.header(source="sim", ahead_s=0.09), boot_id="another-boot")
    put(rig, source, other_host)
    assert count(rig, "depth_in") == 2 and count(rig, "depth_future") == 1
    rig.clock.advance(0.05)
    far = replace(rig.header(source="sim", ahead_s=0.5), boot_id="another-boot")
    put(rig, source, far)
    assert count(rig, "depth_future") == 2


def test_real_frames_arriving_late_behind_a_second_stream_are_warned_of(
    rig: Rig, caplog: pytest.LogCaptureFixture
) -> None:
    # An older announcer (no zid), so that a second session's frames get in: each real frame
    # comes after a forged one stamped ahead of it, and is late.
    source = announce(rig, with_zid=False)
    forger = rig.hub.join("forger")
    late = rig.config.controller.depth_late_warn_count
    with caplog.at_level(logging.WARNING):
        for n in range(late):
            rig.clock.advance(0.05)
            put(rig, forger, rig.header(source="forged", ahead_s=0.015))
            put(rig, source, rig.header(source="sim"))
            assert count(rig, f"{SECOND}.front") == (1 if n == late - 1 else 0)
    assert count(rig, "depth_late.front") == late and count(rig, SECOND) == 1
    warned = [r.getMessage() for r in caplog.records if SECOND in r.getMessage()]
    assert warned and "front" in warned[0] and "second stream" in warned[0]
    # The forger stops: once the late ones leave the window, the gauge is back to 0.
    rig.clock.advance(rig.config.controller.depth_late_warn_window_s + 0.1)
    put(rig, source, rig.header(source="sim"))
    assert count(rig, SECOND) == 0 and count(rig, f"{SECOND}.front") == 0


def test_a_withdrawn_camera_is_no_longer_suspected(rig: Rig) -> None:
    source = announce(rig, with_zid=False)
    for _ in range(rig.config.controller.depth_late_warn_count):
        rig.clock.advance(0.05)
        put(rig, source, rig.header(source="sim-a", ahead_s=0.015))
        put(rig, source, rig.header(source="sim-b"))
    assert count(rig, SECOND) == 1
    rig.withdraw("front")
    assert count(rig, SECOND) == 0 and count(rig, f"{SECOND}.front") == 0


def test_the_late_watch_counts_within_its_window() -> None:
    watch = LateWatch(count=2, window_s=1.0)
    assert watch.saw("front", True, 0.0) == (1, False)
    assert watch.saw("front", False, 0.5) == (1, False)
    assert watch.saw("front", True, 0.9) == (2, True)
    assert watch.saw("front", False, 1.5) == (1, False)  # the first left the window
    watch.saw("front", True, 1.6)
    assert watch.keep({"rear"}) == {"front"} and not watch.suspect
