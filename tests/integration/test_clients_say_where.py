"""A command that reaches nothing says where it looked (endpoint, mode, prefix, auth) and the
likely fix, in one line, and a recording of nothing is a failure, not a success. A replay
(``play``, ``compare``) with no stack fails at once, and one with no detector waits for it,
then fails saying so (``--no-wait`` plays at once)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import zenoh

from common.boxes import Boxes
from common.frames import image_to_frame
from common.messages import Detections, Header
from services.recorder.channels import Translator
from services.recorder.contract import RecorderSettings
from services.recorder.writer import McapFile
from services.ros2.contract import Ros2Settings
from tests.integration.conftest import REPO, write_config

pytestmark = pytest.mark.integration


def _run(module: str, *args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", module, *args], cwd=REPO, capture_output=True, text=True,
        timeout=timeout,
    )  # fmt: skip


def _endpoint(config: Path) -> str:
    for line in config.read_text().splitlines():
        if line.startswith("endpoint = "):
            return str(json.loads(line.split("=", 1)[1]))
    raise AssertionError(f"no endpoint in {config}")


def _one_error_line(stderr: str) -> str:
    assert "Traceback" not in stderr, stderr
    errors = [line for line in stderr.splitlines() if ": error: " in line]
    assert len(errors) == 1, stderr
    return errors[0]


def _recording(path: Path) -> Path:
    """A recording of one frame of camera "front" and the detections made on it."""
    out = McapFile(path, RecorderSettings())
    translator = Translator(Ros2Settings(), "front")
    header = Header(stamp_ns=1_700_000_000 * 10**9, frame_id="camera", seq=1, source="camera")
    frame = image_to_frame(np.zeros((48, 64, 3), np.uint8), header)
    dets = Detections(
        header=header, image_width=64, image_height=48, class_names=("person",),
        boxes=Boxes(xyxy=np.array([[1, 1, 9, 9]], np.float32),
                    scores=np.array([0.9], np.float32), class_ids=np.zeros(1, np.int32)),
    )  # fmt: skip
    for key, msg in (("test/x/camera/front/frame", frame),
                     ("test/x/detector/front/detections", dets)):  # fmt: skip
        for entry in translator.entries(key, msg):
            out.add(entry, header.stamp_ns)
    out.close()
    return path


def _bare_peer(config: Path) -> zenoh.Session:
    """Something listening on the endpoint (a bare peer, as another stack's hub would), but no
    service of this prefix."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", json.dumps([_endpoint(config)]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


def test_query_with_nothing_there_names_endpoint_prefix_and_auth(tmp_path: Path) -> None:
    config = write_config(tmp_path)
    done = _run("services.metrics", "query", "--config", str(config), "--timeout", "1")
    assert done.returncode == 1, done.stderr
    line = _one_error_line(done.stderr)
    assert _endpoint(config) in line and "peer mode, no auth" in line, line
    assert "prefix 'test/" in line and "is the stack running" in line, line
    assert "--config deploy/secure.toml" in line, line  # the likely cause of no link at all


def test_query_of_a_wrong_prefix_says_something_answered(tmp_path: Path) -> None:
    config = write_config(tmp_path)
    # Something listens on the endpoint, but no service of this prefix: the hint turns from
    # "is it running" to "check the prefix".
    with _bare_peer(config):
        done = _run("services.metrics", "query", "--config", str(config), "--timeout", "2")
    assert done.returncode == 1, done.stderr
    line = _one_error_line(done.stderr)
    assert "no service of this stack: check stack.prefix" in line, line


def test_record_with_no_stack_warns_and_fails(tmp_path: Path) -> None:
    config = write_config(tmp_path, recorder={"silence_warning_s": 1.0})
    out = tmp_path / "nothing.mcap"
    done = _run(
        "services.recorder", "record", "--config", str(config), "--duration", "3",
        "--out", str(out),
    )  # fmt: skip
    assert done.returncode == 1, done.stderr
    assert "warning: nothing heard from the stack yet" in done.stderr, done.stderr
    line = _one_error_line(done.stderr)
    assert "recorded nothing from the stack" in line and _endpoint(config) in line, line
    assert out.exists()  # what was recorded (its own counters) is kept, never half-written


def test_compare_with_no_stack_fails_at_once_naming_the_endpoint(tmp_path: Path) -> None:
    # It used to play into nothing for the whole recording, then blame the recording's format.
    config = write_config(tmp_path)
    recording = _recording(tmp_path / "a.mcap")
    done = _run("tools.compare", "compare", str(recording), "--config", str(config),
                "--out", str(tmp_path / "cmp"))  # fmt: skip
    assert done.returncode == 1, done.stderr
    line = _one_error_line(done.stderr)
    assert "no link to the stack" in line and _endpoint(config) in line, line
    assert "is the stack running" in line, line


def test_play_waits_for_a_detector_then_says_none_came(tmp_path: Path) -> None:
    config = write_config(tmp_path, recorder={"detector_wait_s": 1.0})
    recording = _recording(tmp_path / "a.mcap")
    done = _run("services.recorder", "play", str(recording), "--config", str(config))
    assert done.returncode == 1, done.stderr  # nothing there at all: no link
    assert "no link to the stack" in _one_error_line(done.stderr)
    with _bare_peer(config):
        done = _run("services.recorder", "play", str(recording), "--config", str(config))
        assert done.returncode == 1, done.stderr
        assert "waiting up to 1 s for a detector" in done.stderr, done.stderr
        line = _one_error_line(done.stderr)
        assert "no detector was ready within 1 s (recorder.detector_wait_s)" in line, line
        assert _endpoint(config) in line and "--no-wait" in line, line
        done = _run("services.recorder", "play", str(recording), "--config", str(config),
                    "--no-wait")  # fmt: skip
        assert done.returncode == 0, done.stderr
        assert "playing anyway (--no-wait)" in done.stderr, done.stderr
