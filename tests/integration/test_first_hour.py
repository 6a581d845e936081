"""What a new user trips over in the first hour, each fixed and kept fixed on real processes."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import pytest
from skimage import data

from tests.integration.conftest import REPO, write_config

pytestmark = pytest.mark.integration


def test_a_warning_for_an_unused_camera_source(tmp_path: Path) -> None:
    config = write_config(
        tmp_path,
        camera={"source": "device:0"},  # set, but no camera service listed
        supervisor={"services": ["detector", "controller"]},
    )
    done = subprocess.run(
        [sys.executable, "-m", "deploy.supervisor", "--config", str(config), "--duration", "12"],
        cwd=REPO, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    assert "camera.source is 'device:0' but the camera service is not in" in done.stderr
    # Without the secure profile, one plain line says what that means.
    warned = [ln for ln in done.stderr.splitlines() if "NO ACCESS CONTROL" in ln]
    assert len(warned) == 1 and "can drive the robot and release its e-stop" in warned[0]


@pytest.mark.parametrize(
    ("tables", "expected"),
    [
        # A target the model lacks: refused with a suggestion, before anything starts.
        (
            {"controller": {"target_classes": ["persn"]}},
            "controller.target_classes ['persn'] are not among the model's 80 classes "
            "(did you mean 'persn' -> 'person'?)",
        ),
        # The detector's filter hides the controller's target: the robot would never move.
        (
            {"detector": {"classes": ["cup"]}},
            "detector.classes ['cup'] filters out controller.target_classes ['person']",
        ),
    ],
)
def test_settings_that_cannot_work_together_are_refused(
    tmp_path: Path, tables: dict[str, dict[str, object]], expected: str
) -> None:
    config = write_config(tmp_path, supervisor={"services": ["detector", "controller"]}, **tables)
    done = subprocess.run(
        [sys.executable, "-m", "deploy.supervisor", "--config", str(config), "--duration", "30"],
        cwd=REPO, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr[-3000:]
    errors = [line for line in done.stderr.splitlines() if "error:" in line]
    assert len(errors) == 1 and expected in errors[0], done.stderr[-3000:]
    assert "starting" not in done.stderr, done.stderr[-3000:]  # refused before any service


def test_detect_json_into_a_closed_pipe_is_not_a_traceback(
    default_model: Path, tmp_path: Path
) -> None:
    for i in range(6):
        cv2.imwrite(str(tmp_path / f"{i}.png"), cv2.cvtColor(data.chelsea(), cv2.COLOR_RGB2BGR))
    # `detect --json | head -1`: the reader leaves after one line.
    detect = subprocess.Popen(
        [sys.executable, "-m", "tools.detector", "detect", str(tmp_path),
         "--model", str(default_model), "--json"],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    assert detect.stdout is not None and detect.stderr is not None
    first = detect.stdout.readline()
    detect.stdout.close()
    err = detect.stderr.read().decode()
    assert detect.wait(timeout=120) == 0, err
    assert b'"image"' in first
    assert "Traceback" not in err and "BrokenPipeError" not in err, err


def test_taken_ports_on_a_ros2_robot(tmp_path: Path) -> None:
    """What a ROS 2 robot already runs: something on the viewer's port (foxglove_bridge)
    leaves the stack running without the view, names the holder and the run still exits 0
    (the viewer is optional); something on the Zenoh port (rmw_zenohd) is one clean line
    naming the port, not Zenoh's Rust source paths."""
    import socket

    from tools.launch import free_port

    # Another program holds the viewer's port: a process of its own, listening until its
    # stdin closes.
    holder = subprocess.Popen(
        [sys.executable, "-c", "import socket, sys; s = socket.socket(); "
         "s.bind(('127.0.0.1', 0)); s.listen(); print(s.getsockname()[1], flush=True); "
         "sys.stdin.read()"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout is not None
        port = int(holder.stdout.readline())
        config = write_config(
            tmp_path,
            supervisor={"services": ["detector", "controller", "metrics", "viewer"]},
            viewer={"port": port},
        )
        done = subprocess.run(
            [sys.executable, "-m", "deploy.supervisor", "--config", str(config),
             "--duration", "15"],
            cwd=REPO, capture_output=True, text=True, timeout=120,
        )  # fmt: skip
    finally:
        holder.communicate("", timeout=10)
    assert done.returncode == 0, done.stderr[-3000:]  # only the optional viewer failed
    assert "viewer failed for good" in done.stderr and "the stack runs on" in done.stderr, (
        done.stderr[-3000:]
    )
    assert f"port {port} is taken (held by pid {holder.pid} (" in done.stderr, done.stderr[-3000:]
    last = done.stderr.strip().splitlines()[-1]
    assert "viewer exited with code 2" in last and "cannot listen" in last, last
    assert "controller exited" not in last and "detector exited" not in last, last

    zenoh_port = free_port()
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", zenoh_port))
        taken.listen()
        busy = write_config(tmp_path, zenoh={"endpoint": f"tcp/127.0.0.1:{zenoh_port}"})
        done = subprocess.run(
            [sys.executable, "-m", "deploy.supervisor", "--config", str(busy), "--duration", "5"],
            cwd=REPO, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert f"port {zenoh_port} is taken" in line and ".rs:" not in line, line
