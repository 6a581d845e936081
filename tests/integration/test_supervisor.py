"""The supervisor as a user runs it: --duration, SIGTERM, a metrics query, bad configs."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.integration.conftest import REPO, Stack, write_config

pytestmark = pytest.mark.integration

SERVICES = {"camera", "detector", "controller", "metrics"}


def _python(*args: str, timeout: float) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *args], cwd=REPO, capture_output=True, text=True, timeout=timeout
    )


def test_duration_runs_headless_and_ends_with_a_summary(tmp_path: Path) -> None:
    config = write_config(tmp_path)
    done = _python(
        "-m", "deploy.supervisor", "--config", str(config), "--duration", "20", timeout=120
    )
    assert done.returncode == 0, done.stderr[-3000:]
    summary = json.loads(done.stdout)  # stdout holds the summary alone: it can be piped
    assert {name: s["exit_code"] for name, s in summary["services"].items()} == dict.fromkeys(
        SERVICES, 0
    )
    assert summary["metrics"]["frames"] > 0
    assert "Traceback" not in done.stderr


def test_sigterm_stops_everything_and_metrics_answer_the_cli(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack()
    stack.wait_ready(SERVICES)
    query = _python(
        "-m", "services.metrics", "query", "--config", str(stack.config_path), timeout=60
    )
    assert query.returncode == 0, query.stderr
    answer = json.loads(query.stdout)
    assert {"fps", "frames", "latency_ms", "counters", "dropped_frames"} <= answer.keys()
    assert stack.stop(sig=signal.SIGTERM) == 0, stack.log()


def test_metrics_query_without_a_stack_is_one_line(tmp_path: Path) -> None:
    done = _python(
        "-m",
        "services.metrics",
        "query",
        "--config",
        str(write_config(tmp_path)),
        "--timeout",
        "2",
        timeout=60,
    )
    assert done.returncode != 0
    assert done.stderr.strip().count("\n") == 0 and "no metrics service answered" in done.stderr


def test_bad_config_is_one_line(tmp_path: Path) -> None:
    config = tmp_path / "bad.toml"
    config.write_text("[detector]\nconf = 7\n")
    done = _python("-m", "deploy.supervisor", "--config", str(config), timeout=60)
    assert done.returncode == 2
    assert done.stderr.strip() == "supervisor: error: detector.conf must be within 0..1, got 7.0"


def test_wrong_model_fails_the_detector_without_restarts(tmp_path: Path) -> None:
    not_a_model = tmp_path / "model.onnx"
    not_a_model.write_text("this is not an ONNX file")
    config = write_config(
        tmp_path, detector={"model": str(not_a_model)}, supervisor={"services": ["detector"]}
    )
    done = _python(
        "-m", "deploy.supervisor", "--config", str(config), "--duration", "8", timeout=60
    )
    assert "exited with code 3" in done.stderr and "no restart" in done.stderr
    assert "Traceback" not in done.stderr
    # The supervisor stops at once and ends with the detector's own error and exit code.
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("supervisor: error: detector: error: ") and "not a valid ONNX" in last
    assert "(exit code 3; not restarted)" in last
    assert done.returncode == 3
    assert "detector:failed" not in done.stderr.split("exited with code 3", 1)[1]
