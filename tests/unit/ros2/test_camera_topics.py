"""Each camera's ROS 2 topics: the first camera keeps the ``[ros2]`` table's, a further one has
them under ``ros2.camera_namespace``; a config whose cameras cannot have topics of their own
is refused at load."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from common.errors import ConfigError
from services.ros2.contract import CameraTopics, Ros2Settings, camera_topics
from stack.config_file import load_config


def test_the_first_camera_keeps_the_tables_topics_a_further_one_is_namespaced() -> None:
    s = Ros2Settings()
    assert camera_topics(s, "front", "front") == CameraTopics(
        "/camera/rgb/image_raw", "/detections", "/detections/image",
        "/camera/aligned_depth_to_color/image_raw", "/camera/aligned_depth_to_color/camera_info",
        "/detections_3d",
    )  # fmt: skip
    assert camera_topics(s, "front", "rear") == CameraTopics(
        "/rear/camera/rgb/image_raw", "/rear/detections", "/rear/detections/image",
        "/rear/camera/aligned_depth_to_color/image_raw",
        "/rear/camera/aligned_depth_to_color/camera_info", "/rear/detections_3d",
    )  # fmt: skip
    custom = Ros2Settings(camera_namespace="/robot/{camera}_cam", detections_topic="dets")
    assert camera_topics(custom, "front", "rear").image == "/robot/rear_cam/camera/rgb/image_raw"
    assert camera_topics(custom, "front", "rear").detections == "robot/rear_cam/dets"  # relative


@pytest.mark.parametrize("namespace", ["/rear", "", "/{camera}/", "/{camera}-x", "//{camera}"])
def test_a_namespace_without_the_camera_or_not_a_namespace_is_refused(namespace: str) -> None:
    with pytest.raises(ConfigError, match=r"ros2\.camera_namespace"):
        Ros2Settings(camera_namespace=namespace)


def _config(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "stack.toml"
    path.write_text('[stack]\ncamera = "front"\n' + text)
    return path


def test_a_config_of_two_cameras_gives_each_its_topics(tmp_path: Path) -> None:
    config = load_config(_config(tmp_path, "[cameras.rear]\nmount_yaw_deg = 180.0\n"), environ={})
    assert list(config.all_cameras) == ["front", "rear"]
    first = config.stack.camera
    assert camera_topics(config.ros2, first, "rear").detections == "/rear/detections"


@pytest.mark.parametrize(
    "text, message",
    [
        ("[cameras.2nd]\n", "gives camera '2nd' the image topic '/2nd/camera/rgb/image_raw'"),
        ('[ros2]\ndebug_image_topic = "/rear/detections"\n[cameras.rear]\n',
         "camera 'rear''s detections topic '/rear/detections' is also camera 'front''s debug"),
        ('[ros2]\ndetections_3d_topic = "/rear/detections"\n[cameras.rear]\n',
         "camera 'rear''s detections topic '/rear/detections' is also camera 'front''s 3D"),
    ],
)  # fmt: skip
def test_cameras_that_cannot_have_topics_of_their_own_are_refused(
    tmp_path: Path, text: str, message: str
) -> None:
    with pytest.raises(ConfigError, match=re.escape(message)):
        load_config(_config(tmp_path, text), environ={})
    load_config(_config(tmp_path, text.split("[cameras.")[0]), environ={})  # one camera: fine


@pytest.mark.parametrize("frame", ["/base_link", "base link", "a*b", "x" * 129])
def test_a_3d_detections_frame_must_be_a_frame_id(frame: str) -> None:
    with pytest.raises(ConfigError, match=r"ros2\.detections_3d_frame"):
        Ros2Settings(detections_3d_frame=frame)
    Ros2Settings(detections_3d_frame="base_link")
    Ros2Settings(detections_3d_frame="")
