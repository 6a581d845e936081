"""Which principals a stack has a use for (stack/principals.py::running_principals): the router,
the processes of ``supervisor.services``, the tools and the other hosts' principals; what
``zstack credentials`` makes secrets for. The rules stay built for every principal."""

from __future__ import annotations

from pathlib import Path

import pytest

from common.keys import Keys
from common.security import qualified, stack_principals
from deploy.processes import stack_processes
from stack.access import access_control
from stack.config_file import load_config
from stack.principals import TOOL_PRINCIPALS, running_principals, service_principals

CAMERAS = {"front": "camera", "rear": "camera_rear"}
SIM_STACK = ("sim", "detector", "controller", "metrics", "viewer")  # deploy/stack.toml's


def test_a_simulator_stack_has_no_camera_principal() -> None:
    made = running_principals(SIM_STACK, CAMERAS)
    assert made == (
        "supervisor", "recorder", "sim", "detector", "controller", "metrics", "viewer",
        "estop", "observer",
    )  # fmt: skip
    assert not {"camera", "camera_rear", "ros2"} & set(made)
    # The rules are still built for every principal: one without a secret cannot log in.
    acl = access_control(Keys("stack"), CAMERAS, "password")
    everyone = next(s for s in acl["subjects"] if s["id"] == "everyone")
    assert everyone["usernames"] == [qualified("stack", p) for p in stack_principals(CAMERAS)]


def test_a_camera_stack_has_each_cameras_and_each_workers_principal() -> None:
    workers = ("detector_b", "detector_b_2")
    made = running_principals(("camera", "detector", "controller"), CAMERAS, workers)
    assert made == (
        "supervisor", "recorder", "camera", "camera_rear", *workers, "controller", "estop",
        "observer",
    )  # fmt: skip


def test_the_tools_are_made_whatever_the_stack_runs() -> None:
    assert set(TOOL_PRINCIPALS) == {"recorder", "estop", "observer"}
    made = running_principals(("controller",), "front")
    assert made == ("supervisor", "recorder", "controller", "estop", "observer")


def test_other_hosts_principals_are_made_and_a_bad_name_is_one_line() -> None:
    # A robot that runs no worker of its own, served by the GPU box's detector_a.
    robot = running_principals(("camera", "controller"), "front", remote=("detector_a",))
    assert "detector_a" in robot and "detector" not in robot
    # The GPU box: its worker, and the robot's principals its router admits over the link
    # (a further camera of the robot's among them, though the GPU box has no camera table).
    remote = ("camera", "camera_rear", "controller", "metrics", "observer")
    gpu = running_principals(("detector",), "front", ("detector_a",), remote)
    assert gpu == (
        "supervisor", "recorder", "camera", "camera_rear", "detector_a", "controller",
        "metrics", "estop", "observer",
    )  # fmt: skip
    with pytest.raises(ValueError, match=r"names 'rogue': not a principal") as bad:
        running_principals(("detector",), "front", remote=("rogue",))
    assert "\n" not in str(bad.value)


def test_the_service_principals_are_the_processes_the_supervisor_starts(tmp_path: Path) -> None:
    config_path = tmp_path / "stack.toml"
    config_path.write_text(
        '[supervisor]\nservices = ["recorder", "camera", "detector", "controller", "viewer"]\n'
        '[stack]\ncamera = "front"\n[cameras.rear]\nmount_yaw_deg = 180.0\n'
        '[detector]\nworkers = 2\nworker_id = "b"\n'
    )
    config = load_config(config_path, environ={})
    principals = service_principals(
        config.supervisor.services, config.camera_services, config.detector_services
    )
    assert list(principals) == [name for name, _ in stack_processes(config)]
