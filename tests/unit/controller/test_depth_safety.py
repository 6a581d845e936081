"""The depth path's safety review (issue 32): the robot drives forward only towards what the
depth cameras have seen clear. Unknown reads blocked, "clear" only as far as the floor is seen,
a drop-off and a too-close reading are obstacles, the cameras together must see the whole
sector ahead, implausible intrinsics or mountings give no scan, and the intake's thread
survives its errors, drops what it cannot use before converting it and keeps no scan made
with an announcement gone."""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from common.messages import DepthFrame, Header, LaserScan
from depthscan.frame import MIN_NEAR_M, ScanParams, blind_zone
from depthscan.observe import Observation, virtual_scan
from perception.depth import Intrinsics, Mounting
from services.controller.contract import ControllerSettings
from services.controller.depth_obstacles import DepthCamera, depth_obstacles
from services.controller.geometry import sector_clearance
from services.depthscan import intake as depth_intake
from tests.polling import wait_for
from tests.unit.controller.rig import Rig
from tests.unit.depthscan.depth_scenes import HFOV, INTR, Face, at_bearing, depth_frame, scene

HEADER = Header(stamp_ns=1_000, frame_id="camera", seq=1, source="test")
PARAMS = ScanParams()
HEIGHT = 0.6
LEVEL = Mounting(height_m=HEIGHT)
SECTOR, HALF_WIDTH = 30.0, 0.3


def ahead(depth: np.ndarray, mount: Mounting = LEVEL, **kw: Any) -> float:
    """The room straight ahead that the controller reads from the depth image's scan."""
    s = virtual_scan(depth, INTR, mount, PARAMS, HEADER, 10.0, **kw)
    return sector_clearance(s, SECTOR, HALF_WIDTH)


def test_a_dark_wall_reads_as_near_as_the_floor_seen_before_it() -> None:
    depth = scene(HEIGHT, Face(2.5, -5.0, 5.0))
    depth[depth == np.float32(2.5)] = np.nan  # dark: no reading on the wall at all
    assert ahead(scene(HEIGHT)) > 9.0  # the floor seen far: clear far
    assert ahead(depth) == pytest.approx(2.5, abs=0.1)  # not clear beyond what was seen


def test_a_column_stopped_short_is_not_made_clear_by_its_neighbours() -> None:
    # A dark pole 14 mm wide at 2.5 m (3 px: 321..323): it hides the floor behind it from one
    # sampled column (u = 322) only, while the columns beside it, in the same 1 deg ray, see
    # the floor far. (Narrower, its hole is filled from the row's neighbours as a dropped
    # pixel's is: depthscan/frame.py _take.)
    depth = scene(HEIGHT, Face(2.5, 0.004, 0.018))
    depth[depth == np.float32(2.5)] = np.nan
    assert ahead(depth) == pytest.approx(2.5, abs=0.1)


def test_a_direction_in_view_with_no_point_at_all_is_blocked() -> None:
    # A dark pole 0.8 m ahead, nearer than the floor the camera sees (from 1.39 m): no point
    # at all in its directions, the floor seen all round it.
    depth = scene(HEIGHT, at_bearing(0.8, 0.0, 0.05))
    depth[depth == np.float32(0.8)] = np.nan
    # Blocked at the nearest range it could hide a thing.
    assert ahead(depth) == pytest.approx(MIN_NEAR_M, abs=1e-3)


def test_too_close_is_an_obstacle_at_the_minimum_range() -> None:
    # A pole 0.25 m ahead, nearer than the camera's minimum range (0.3): REP 117's -inf.
    depth = scene(HEIGHT, at_bearing(0.25, 0.0, 0.05))
    depth[depth == np.float32(0.25)] = -np.inf
    assert ahead(depth, range_min_m=0.3) == pytest.approx(0.3, abs=0.01)


def test_a_drop_off_is_an_obstacle() -> None:
    # A stairwell: the floor beyond 2.5 m is 1 m lower (its far wall not drawn).
    near, low = scene(HEIGHT), scene(HEIGHT + 1.0)
    depth = np.where(near < 2.5, near, low)
    assert ahead(depth) == pytest.approx(2.5, abs=0.15)
    # The camera's height announced wrong by more than the floor margin: the floor is
    # then an obstacle (announced lower) or a drop-off (higher): either way blocked near.
    floor = scene(HEIGHT)
    assert ahead(floor, Mounting(height_m=HEIGHT - 0.1)) < 1.5
    assert ahead(floor, Mounting(height_m=HEIGHT + 0.1)) < 1.5


def cam(yaw_deg: float, scan: LaserScan | None = None) -> DepthCamera:
    return DepthCamera(Mounting(height_m=HEIGHT, yaw_deg=yaw_deg), HFOV, scan, 0.1)


def test_the_cameras_must_see_the_whole_sector_ahead() -> None:
    clear = virtual_scan(scene(HEIGHT), INTR, LEVEL, PARAMS, HEADER, 10.0)
    off = virtual_scan(scene(HEIGHT), INTR, Mounting(height_m=HEIGHT, yaw_deg=40.0), PARAMS,
                       HEADER, 10.0)  # fmt: skip
    # Yaw 40, 60 deg wide: it sees 10..70 deg, not the sector's -15..10.
    partial = depth_obstacles({"side": cam(40.0, off)}, 0.5, SECTOR)
    assert partial.scan is None
    assert partial.missing == "depth does not see the whole way ahead (30 deg): side"
    # Two cameras that together cover it: yaw +-20 see -50..10 and -10..50.
    right = virtual_scan(scene(HEIGHT), INTR, Mounting(height_m=HEIGHT, yaw_deg=-20.0),
                         PARAMS, HEADER, 10.0)  # fmt: skip
    left = virtual_scan(scene(HEIGHT), INTR, Mounting(height_m=HEIGHT, yaw_deg=20.0),
                        PARAMS, HEADER, 10.0)  # fmt: skip
    both = depth_obstacles({"l": cam(20.0, left), "r": cam(-20.0, right)}, 0.5, SECTOR)
    assert both.scan is not None and both.missing == ""
    assert depth_obstacles({"front": cam(0.0, clear)}, 0.5, SECTOR).scan is not None
    # A 70 deg sector is wider than one 60 deg camera.
    wide = depth_obstacles({"front": cam(0.0, clear)}, 0.5, 70.0)
    assert wide.scan is None and wide.missing.startswith("depth does not see the whole way")


def test_the_blind_zone_below_a_level_camera() -> None:
    floor_m, below_m = blind_zone(INTR, LEVEL, 0.5)
    assert floor_m == pytest.approx(0.6 / math.tan(math.radians(23.413)), abs=0.01)  # 1.39 m
    assert below_m == pytest.approx(0.6 - 0.5 * math.tan(math.radians(23.413)), abs=0.01)


def test_bounds_keep_the_floor_margin_and_the_stride_tight() -> None:
    from common.errors import ConfigError

    with pytest.raises(ConfigError, match="depth_floor_margin_m"):
        ControllerSettings(depth_floor_margin_m=0.2)
    with pytest.raises(ConfigError, match="depth_scan_stride_px"):
        ControllerSettings(depth_scan_stride_px=9)
    ControllerSettings(depth_floor_margin_m=0.15, depth_scan_stride_px=8)


# -- the intake ---------------------------------------------------------------------------------
@pytest.fixture
def rig(tmp_path: Path) -> Iterator[Rig]:
    r = Rig(tmp_path, announced=False, obstacle_sources=("depth",), depth_max_pixels=700 * 500)
    r.announce("front", hfov_deg=HFOV, depth=True, mount_height_m=HEIGHT)
    yield r
    r.close()


def put(rig: Rig, frame: DepthFrame, camera: str = "front") -> int:
    rig.put(rig.keys.depth(camera), frame.encode())
    assert rig.stage is not None
    return rig.handle_depth()


def frame(rig: Rig, *faces: Face, **changes: Any) -> DepthFrame:
    f = depth_frame(scene(HEIGHT, *faces), rig.header(source="sim"))
    return dataclasses.replace(f, **changes)


def drives(rig: Rig) -> tuple[bool, str]:
    rig.detections()
    twist, status = rig.tick()
    return twist.linear[0] > 0, status.reason


def test_a_too_close_reading_in_a_32fc1_image_blocks(rig: Rig) -> None:
    depth = scene(HEIGHT, at_bearing(0.25, 0.0, 0.05))
    depth[depth == np.float32(0.25)] = -np.inf  # what depth_metres would make NaN
    f = frame(rig, encoding="32FC1", data=depth.astype("<f4").tobytes(), range_min_m=0.3)
    assert put(rig, f) == 1
    moving, reason = drives(rig)
    assert not moving and reason == "obstacle at 0.30 m (depth)", reason


@pytest.mark.parametrize(
    "changes, announce",
    [
        ({"fy": 1e-3}, {}),  # absurd intrinsics: every point far out of the obstacle band
        ({"fx": INTR.fx * 1.5, "fy": INTR.fy * 1.5}, {}),  # a 42 deg image, announced 60
        ({"cx": -10.0}, {}),
        ({}, {"mount_height_m": 3.0}),  # announced far higher than the camera stands
    ],
    ids=["fy", "hfov", "cx", "height"],
)
def test_an_implausible_frame_gives_no_scan(
    rig: Rig, changes: dict[str, float], announce: dict[str, float]
) -> None:
    if announce:
        rig.announce("front", hfov_deg=HFOV, depth=True, **announce)
    assert put(rig, frame(rig, **changes)) == 1
    moving, reason = drives(rig)
    assert not moving and reason == "no depth from front yet", reason
    assert rig.stage_counters["depth_implausible"] == 1
    assert rig.stage_counters["depth_implausible.front"] == 1
    assert rig.stage_counters.get("depth_in", 0) == 0


def test_an_image_of_too_many_pixels_is_dropped_unconverted(rig: Rig) -> None:
    big = Intrinsics.from_hfov(1280, 960, HFOV)
    f = depth_frame(scene(HEIGHT, intr=big), rig.header(source="sim"), big)
    assert put(rig, f) == 1
    assert rig.stage_counters["depth_oversize"] == 1 and rig.stage_counters.get("depth_in", 0) == 0
    assert not drives(rig)[0]


def test_depth_of_a_camera_not_announced_with_depth_is_not_kept(rig: Rig) -> None:
    rig.put(rig.keys.depth("side"), frame(rig).encode())
    assert rig.stage is not None
    assert rig.handle_depth() == 0  # dropped as it came, not stored
    assert rig.stage_counters["depth_unannounced"] == 1


def test_a_scan_made_with_an_announcement_gone_is_not_kept(
    rig: Rig, monkeypatch: pytest.MonkeyPatch
) -> None:
    made = depth_intake.observe

    def reannounced(*args: Any, **kw: Any) -> Observation:
        # While the scan is made, the camera is announced again, mounted elsewhere.
        rig.announce("front", hfov_deg=HFOV, depth=True, mount_height_m=HEIGHT + 0.3)
        return made(*args, **kw)

    monkeypatch.setattr(depth_intake, "observe", reannounced)
    assert put(rig, frame(rig)) == 1
    assert rig.stage_counters.get("depth_in", 0) == 0
    assert not drives(rig)[0]


def test_the_intake_thread_survives_an_error(rig: Rig, monkeypatch: pytest.MonkeyPatch) -> None:
    intake = rig.intake
    assert intake is not None

    def broken(*args: Any, **kw: Any) -> LaserScan:
        raise RuntimeError("a bug")

    monkeypatch.setattr(depth_intake, "observe", broken)
    stop = threading.Event()
    thread = threading.Thread(target=intake.serve, args=(stop, 0.01), daemon=True)
    thread.start()
    try:
        rig.put(rig.keys.depth("front"), frame(rig).encode())
        wait_for(lambda: rig.stage_counters.get("depth_errors", 0) == 1, 10.0, "the error counted")
        monkeypatch.undo()
        rig.clock.advance(0.05)
        rig.put(rig.keys.depth("front"), frame(rig).encode())
        wait_for(lambda: rig.stage_counters.get("depth_in", 0) == 1, 10.0, "the next frame scanned")
        assert thread.is_alive()
    finally:
        stop.set()
        thread.join(5.0)


def test_the_blind_zone_is_logged_once_per_camera(
    rig: Rig, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.INFO, logger="depthscan"):
        put(rig, frame(rig))
        rig.clock.advance(0.05)
        put(rig, frame(rig))
    said = [r.getMessage() for r in caplog.records if "sees the floor from" in r.getMessage()]
    assert said == [
        "depth camera front (0.60 m above the floor) sees the floor from 1.39 m ahead of it; "
        "at the safety distance (0.50 m) an obstacle lower than 0.38 m is unseen"
    ]


def test_sampling_the_raw_frame_reads_what_converting_it_all_reads() -> None:
    from depthscan.frame import sample_frame, sample_metres
    from perception.depth import depth_metres

    f = depth_frame(scene(HEIGHT, at_bearing(2.0, 5.0)), HEADER)
    raw, whole = sample_frame(f, 4), sample_metres(depth_metres(f), 4)
    assert np.array_equal(raw.v, whole.v) and np.array_equal(raw.u, whole.u)
    assert np.allclose(raw.z, whole.z, equal_nan=True) and not raw.too_close.any()
    # 32FC1: -inf is "too close" (depth_metres makes it NaN), +inf and NaN no reading.
    depth = scene(HEIGHT)
    depth[:8, :8], depth[8:16, :8] = -np.inf, np.inf
    f32 = dataclasses.replace(f, encoding="32FC1", data=depth.astype("<f4").tobytes())
    s = sample_frame(f32, 4)
    assert s.too_close[:2, :2].all() and s.too_close.sum() == 4
    assert np.isnan(s.z[:4, :2]).all()
