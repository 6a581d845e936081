"""The controller's decisions on hand-built detections and scans."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from common.messages import Detections, Header, LaserScan
from common.settings import ControllerSettings
from services.controller.policy import decide, follow, sector_clearance, track

HEADER = Header(stamp_ns=123, frame_id="camera", seq=1, source="test")
W, H = 640, 480


def dets(*boxes: tuple[str, float, float, float, float, float], width: int = W) -> Detections:
    """Boxes as (class, score, cx, cy, w, h) in pixels."""
    n = len(boxes)
    xyxy = np.array(
        [[cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2] for _, _, cx, cy, w, h in boxes],
        np.float32,
    ).reshape(n, 4)
    return Detections(
        header=HEADER,
        image_width=width,
        image_height=H,
        class_ids=np.zeros(n, np.int32),
        class_names=tuple(b[0] for b in boxes),
        scores=np.array([b[1] for b in boxes], np.float32),
        xyxy=xyxy,
    )


def scan(front_range: float, *, rays: int = 181, fov_deg: float = 180.0) -> LaserScan:
    angles = np.linspace(-np.radians(fov_deg / 2), np.radians(fov_deg / 2), rays)
    ranges = np.full(rays, 10.0, np.float32)
    ranges[np.abs(angles) < np.radians(5)] = front_range
    return LaserScan(
        header=HEADER,
        angle_min=float(angles[0]),
        angle_increment=float(angles[1] - angles[0]),
        range_min=0.05,
        range_max=20.0,
        ranges=ranges,
    )


TRACK = ControllerSettings(mode="track", target_classes=("person",))
FOLLOW = dataclasses.replace(TRACK, mode="follow")


def test_track_turns_towards_most_central_confident_target() -> None:
    d = dets(
        ("person", 0.9, 600, 240, 50, 100),
        ("person", 0.8, 400, 240, 50, 100),
        ("cup", 0.99, 320, 240, 50, 50),
        ("person", 0.2, 330, 240, 50, 50),
    )
    cmd = track(d, TRACK)
    # the cup is not a target, the 0.2 person is below min_score: the x=400 person is chosen
    assert cmd.target == "person"
    assert cmd.angular_z < 0  # right of centre -> clockwise
    assert cmd.linear_x == 0.0 and cmd.state == "turning"
    assert cmd.input_stamp_ns == HEADER.stamp_ns


def test_track_drives_forward_only_when_centred() -> None:
    cmd = track(dets(("person", 0.9, W / 2 + 10, 240, 50, 100)), TRACK)
    assert cmd.linear_x == TRACK.forward_speed and cmd.state == "tracking"
    left = track(dets(("person", 0.9, 100, 240, 50, 100)), TRACK)
    assert left.angular_z > 0 and left.linear_x == 0.0


def test_uses_the_image_width_from_the_message() -> None:
    # x=600 is right of centre in a 640 image but left of centre in a 1280 one
    assert track(dets(("person", 0.9, 600, 240, 50, 100), width=1280), TRACK).angular_z > 0


def test_angular_is_limited() -> None:
    s = dataclasses.replace(TRACK, angular_gain=100.0, max_angular=0.7)
    assert track(dets(("person", 0.9, 630, 240, 10, 10)), s).angular_z == pytest.approx(-0.7)


def test_no_target_means_zero() -> None:
    for policy in (lambda d: track(d, TRACK), lambda d: follow(d, scan(5.0), FOLLOW)):
        cmd = policy(dets(("cup", 0.9, 320, 240, 50, 50)))
        assert cmd.is_zero and cmd.state == "searching"


def test_follow_picks_the_largest_target() -> None:
    d = dets(("person", 0.9, 200, 240, 40, 80), ("person", 0.6, 330, 240, 100, 200))
    cmd = follow(d, scan(5.0), FOLLOW)
    assert cmd.state == "following" and cmd.linear_x > 0


def test_follow_stops_for_an_obstacle_ahead() -> None:
    d = dets(("person", 0.9, 320, 240, 100, 200))
    assert follow(d, scan(0.3), FOLLOW).linear_x == 0.0
    assert follow(d, scan(0.3), FOLLOW).state == "blocked"
    assert follow(d, None, FOLLOW).state == "blocked"  # no scan: cannot tell it is clear
    assert follow(d, scan(0.8), FOLLOW).linear_x > 0


def test_follow_stops_at_the_follow_distance() -> None:
    cmd = follow(dets(("person", 0.9, 320, 240, 200, 0.7 * H)), scan(5.0), FOLLOW)
    assert cmd.linear_x == 0.0 and cmd.state == "arrived"


def test_sector_checks_a_sector_not_one_ray() -> None:
    s = scan(10.0)
    ranges = s.ranges.copy()
    ranges[np.argmin(np.abs(s.angles - np.radians(10)))] = 0.2  # 10 deg off-axis
    off_axis = dataclasses.replace(s, ranges=ranges)
    assert sector_clearance(off_axis, 30.0) == pytest.approx(0.2)
    assert sector_clearance(off_axis, 10.0) == pytest.approx(10.0)


def test_sector_ignores_invalid_rays_and_blind_is_blocked() -> None:
    s = scan(np.nan)
    assert sector_clearance(s, 8.0) == 0.0  # every ray in the sector is NaN: blocked
    assert sector_clearance(scan(0.01), 8.0) == 0.0  # below range_min: invalid -> blind


def test_stale_or_missing_detections_command_zero() -> None:
    d = dets(("person", 0.9, 320, 240, 50, 100))
    assert decide(None, float("inf"), None, float("inf"), TRACK).is_zero
    stale = decide(d, TRACK.detection_timeout_s + 0.01, None, 0.0, TRACK)
    assert stale.is_zero and stale.state == "stale"
    assert not decide(d, 0.0, None, 0.0, TRACK).is_zero


def test_follow_treats_an_old_scan_as_missing() -> None:
    d = dets(("person", 0.9, 320, 240, 100, 200))
    assert decide(d, 0.0, scan(5.0), 0.0, FOLLOW).linear_x > 0
    assert decide(d, 0.0, scan(5.0), FOLLOW.scan_timeout_s + 1, FOLLOW).linear_x == 0.0
