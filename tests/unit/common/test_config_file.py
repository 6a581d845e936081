"""Profiles (``extends``) and environment overrides of the further cameras' tables
(stack/config_file.py): a profile states only what it changes, at every depth."""

from __future__ import annotations

from pathlib import Path

import pytest

from common.errors import ConfigError
from stack.config_file import load_config

# Three files, each extending the one before; each states only what it changes.
BASE = """
[stack]
camera = "front"
[camera]
rate_hz = 10.0
frame_id = "camera_front"
resize = [640, 480]
[cameras.rear]
mount_yaw_deg = 180.0
frame_id = "camera_rear"
hfov_deg = 90.0
[cameras.left]
mount_yaw_deg = 90.0
frame_id = "camera_left"
[controller]
target_classes = ["person", "cat"]
"""
MIDDLE = """
extends = "base.toml"
[cameras.rear]
rate_hz = 5.0
[camera]
jpeg_quality = 80
[controller]
target_classes = ["cup"]
"""
TOP = """
extends = "middle.toml"
[cameras.rear]
jpeg_quality = 50
[cameras.left]
hfov_deg = 70.0
"""


def _chain(tmp_path: Path) -> Path:
    for name, text in (("base", BASE), ("middle", MIDDLE), ("top", TOP)):
        (tmp_path / f"{name}.toml").write_text(text)
    return tmp_path / "top.toml"


def test_a_three_level_chain_merges_every_table_field_by_field(tmp_path: Path) -> None:
    cameras = load_config(_chain(tmp_path), environ={}).all_cameras
    rear, left, front = cameras["rear"], cameras["left"], cameras["front"]
    # Each level's change, and everything the levels below stated, is kept.
    assert (rear.mount_yaw_deg, rear.frame_id, rear.hfov_deg) == (180.0, "camera_rear", 90.0)
    assert (rear.rate_hz, rear.jpeg_quality) == (5.0, 50)
    assert (left.mount_yaw_deg, left.frame_id, left.hfov_deg) == (90.0, "camera_left", 70.0)
    # [camera]'s own changes reach the further cameras that do not state their own.
    assert (front.jpeg_quality, left.jpeg_quality, left.resize) == (80, 80, (640, 480))
    assert (front.rate_hz, left.rate_hz, front.frame_id) == (10.0, 10.0, "camera_front")
    assert list(cameras) == ["front", "rear", "left"]  # the base's order


def test_a_list_replaces_the_base_s_list_whole(tmp_path: Path) -> None:
    # The rule: tables merge field by field; a value, a list included, replaces the base's.
    assert load_config(_chain(tmp_path), environ={}).controller.target_classes == ("cup",)


def test_a_table_replaced_by_a_value_is_a_config_error(tmp_path: Path) -> None:
    (tmp_path / "base.toml").write_text(BASE)
    (tmp_path / "top.toml").write_text('extends = "base.toml"\n[cameras]\nrear = 5\n')
    with pytest.raises(ConfigError, match=r"top\.toml: cameras\.rear must be a table"):
        load_config(tmp_path / "top.toml", environ={})


def test_a_further_camera_is_overridden_from_the_environment(tmp_path: Path) -> None:
    env = {"STACK__CAMERAS__REAR__RATE_HZ": "2.5", "STACK__CAMERAS__LEFT__FRAME_ID": "cam_l"}
    cameras = load_config(_chain(tmp_path), environ=env).all_cameras
    assert (cameras["rear"].rate_hz, cameras["rear"].mount_yaw_deg) == (2.5, 180.0)
    assert (cameras["left"].frame_id, cameras["left"].hfov_deg) == ("cam_l", 70.0)
    assert cameras["front"].rate_hz == 10.0


def test_a_camera_name_with_double_underscores_is_overridden_too(tmp_path: Path) -> None:
    (tmp_path / "stack.toml").write_text('[cameras.arm__wrist]\nframe_id = "wrist"\n')
    env = {"STACK__CAMERAS__ARM__WRIST__RATE_HZ": "4"}
    config = load_config(tmp_path / "stack.toml", environ=env)
    assert config.camera_settings("arm__wrist").rate_hz == 4.0


@pytest.mark.parametrize(
    "name, message",
    [
        # A further camera is added in the file: a misspelt name must not add one.
        ("STACK__CAMERAS__REAER__RATE_HZ", r"no further camera 'reaer'.*\['rear', 'left'\]"),
        ("STACK__CAMERAS__REAR__RATE", r"\[cameras\.rear\] has no setting 'rate'"),
        ("STACK__CAMERAS__RATE_HZ", "STACK__CAMERAS__<NAME>__<FIELD>"),
    ],
)
def test_a_bad_camera_override_is_blamed_on_the_variable(
    tmp_path: Path, name: str, message: str
) -> None:
    with pytest.raises(ConfigError, match=f"^{name}: .*{message}"):
        load_config(_chain(tmp_path), environ={name: "3"})


def test_a_bad_value_of_a_further_camera_names_its_table(tmp_path: Path) -> None:
    (tmp_path / "stack.toml").write_text(
        '[cameras.left]\nframe_id = "camera_left"\nmount_yaw_deg = 400.0\n'
    )
    with pytest.raises(ConfigError) as err:
        load_config(tmp_path / "stack.toml", environ={})
    assert str(err.value) == "cameras.left.mount_yaw_deg must be within -180..180 deg, got 400.0"
    (tmp_path / "stack.toml").write_text("[cameras.left]\nresize = [640, 0]\n")
    with pytest.raises(ConfigError, match=r"^cameras\.left\.resize must be"):
        load_config(tmp_path / "stack.toml", environ={})


def test_a_bad_override_of_a_further_camera_names_the_variable_and_the_table(
    tmp_path: Path,
) -> None:
    with pytest.raises(ConfigError) as err:
        load_config(_chain(tmp_path), environ={"STACK__CAMERAS__LEFT__RATE_HZ": "0"})
    assert str(err.value) == (
        "STACK__CAMERAS__LEFT__RATE_HZ: cameras.left.rate_hz must be within 0.1..1000 Hz, got 0.0"
    )


def test_a_camera_source_without_services_is_refused_in_one_line(tmp_path: Path) -> None:
    # The default services are the profile's simulated robot (issue 39, item 6): a real
    # robot's config that names its camera and not its services would run the simulator,
    # whose frames and clear scans stand in for the robot's own.
    path = tmp_path / "robot.toml"
    path.write_text('[camera]\nsource = "device:0"\n')
    with pytest.raises(ConfigError) as refused:
        load_config(path, environ={})
    line = str(refused.value)
    assert "\n" not in line and "camera.source" in line and "supervisor.services" in line, line
    path.write_text('[camera]\nsource = "device:0"\n[supervisor]\nservices = ["camera"]\n')
    assert load_config(path, environ={}).supervisor.services == ("camera",)
