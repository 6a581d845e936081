"""Several cameras under the supervisor: one process per camera, each named as its service
(deploy/processes.py::stack_processes), and the config warnings about cameras."""

from __future__ import annotations

import sys
from pathlib import Path

from deploy.processes import service_command, stack_processes
from deploy.supervisor import config_warnings
from stack.config import Config
from stack.config_file import load_config


def _config(tmp_path: Path, text: str) -> Config:
    path = tmp_path / "stack.toml"
    path.write_text(text)
    return load_config(path, environ={})


def test_one_camera_starts_as_it_always_did(tmp_path: Path) -> None:
    config = _config(tmp_path, '[supervisor]\nservices = ["camera", "detector"]\n')
    assert stack_processes(config) == [
        ("camera", [sys.executable, "-m", "services.camera", "serve", "--config", config.path]),
        ("detector", service_command("detector", config.path)),
    ]


THREE = """
[stack]
camera = "front"
[supervisor]
services = ["recorder", "camera", "detector", "controller"]
[cameras.rear]
mount_yaw_deg = 180.0
frame_id = "camera_rear"
[cameras.left]
mount_yaw_deg = 90.0
frame_id = "camera_left"
"""


def test_each_camera_is_a_process_of_its_own_in_the_camera_s_place(tmp_path: Path) -> None:
    config = _config(tmp_path, THREE)
    procs = stack_processes(config)
    assert [name for name, _ in procs] == [
        "recorder", "camera", "camera_rear", "camera_left", "detector", "controller",
    ]  # fmt: skip
    commands = dict(procs)
    assert commands["camera"] == service_command("camera", config.path)  # no --camera
    assert commands["camera_rear"][-2:] == ["--camera", "rear"]
    assert commands["camera_left"][:6] == service_command("camera", config.path)
    assert commands["camera_left"][-2:] == ["--camera", "left"]


def test_no_camera_service_no_camera_processes(tmp_path: Path) -> None:
    config = _config(tmp_path, THREE.replace('"camera", ', '"sim", '))
    assert [name for name, _ in stack_processes(config)] == [
        "recorder", "sim", "detector", "controller",
    ]  # fmt: skip


def _camera_warnings(config: Config) -> list[str]:
    return [w for w in config_warnings(config) if "camera" in w]


def test_an_unused_source_of_a_further_camera_is_said(tmp_path: Path) -> None:
    config = _config(
        tmp_path,
        '[supervisor]\nservices = ["sim", "detector"]\n'
        '[cameras.rear]\nsource = "sample:chelsea"\nframe_id = "camera_rear"\n',
    )
    (warning,) = _camera_warnings(config)
    assert "cameras.rear.source is 'sample:chelsea'" in warning and "unused" in warning
    assert "camera.source" not in warning.replace("cameras.rear.source", "")


def test_cameras_sharing_a_frame_id_are_said(tmp_path: Path) -> None:
    config = _config(tmp_path, "[cameras.rear]\nmount_yaw_deg = 180.0\n")
    (warning,) = _camera_warnings(config)
    assert "['front', 'rear'] share frame_id 'camera'" in warning
    assert _camera_warnings(_config(tmp_path, THREE)) == []


def test_a_ros2_robot_renders_only_the_first_camera_and_says_so(tmp_path: Path) -> None:
    config = _config(
        tmp_path,
        '[supervisor]\nservices = ["sim", "ros2", "detector"]\n[sim]\nros2_robot = true\n'
        '[cameras.rear]\nframe_id = "camera_rear"\n',
    )
    (warning,) = _camera_warnings(config)
    assert "only the first camera, 'front', is rendered; ['rear'] are not" in warning
