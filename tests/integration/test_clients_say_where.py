"""A command that reaches nothing says where it looked (endpoint, mode, prefix, auth) and the
likely fix, in one line, and a recording of nothing is a failure, not a success."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import zenoh

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
    # Something listens on the endpoint (a bare peer, as another stack's hub would), but no
    # service of this prefix: the hint turns from "is it running" to "check the prefix".
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", json.dumps([_endpoint(config)]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(conf):
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
