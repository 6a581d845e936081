"""What ``zstack query`` says before the JSON: the announced cameras and every warning."""

from __future__ import annotations

from typing import Any

from services.metrics.summary import summary

FRONT = {
    "width": 640, "height": 480, "rate_hz": 10.0, "mount_yaw_deg": 0.0, "hfov_deg": 60.0,
    "frame_id": "front_optical", "source": "sim",
}  # fmt: skip
REAR = {**FRONT, "width": 0, "height": 0, "mount_yaw_deg": 180.0, "source": "camera"}


def test_the_cameras_then_every_warning() -> None:
    answer: Any = {
        "cameras_announced": {"front": FRONT, "rear": REAR},
        "pool_warnings": ["camera left unserved for 12 s"],
        "warnings": {"detections_late": "detections come too late"},
    }
    lines = summary(answer, "robot1")
    assert lines[0] == "cameras announced under robot1: 2"
    front, rear = lines[1:3]
    for text in ("front", "640x480", "10.0 Hz", "yaw   +0 deg", "fov  60 deg", "front_optical",
                 "source sim"):  # fmt: skip
        assert text in front, front
    assert "size unknown" in rear and "yaw +180 deg" in rear and "source camera" in rear, rear
    assert lines[3:] == [
        "WARNING pool: camera left unserved for 12 s",
        "WARNING detections_late: detections come too late",
    ]


def test_no_camera_announced_is_a_warning() -> None:
    answer: Any = {"cameras_announced": {}, "warnings": {}}
    [line] = summary(answer, "stack")
    assert line.startswith("WARNING no camera is announced under stack"), line


def test_an_older_answer_has_no_camera_lines() -> None:
    assert summary({"warnings": {}}, "stack") == []  # type: ignore[typeddict-item]
