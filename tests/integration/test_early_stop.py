"""A stack stopped at any moment, even while its services are still importing, ends without a
traceback: a stop is not an error."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

from tests.integration.conftest import wait_for, write_config
from tools.launch import service_pids, start_supervisor, stop_supervisor

pytestmark = pytest.mark.integration

SERVICES = ["detector", "controller", "metrics"]


@pytest.mark.parametrize("attempt", range(3))
def test_a_stop_while_services_import_leaves_no_traceback(tmp_path: Path, attempt: int) -> None:
    config = write_config(tmp_path, supervisor={"services": SERVICES})
    log_path = tmp_path / "supervisor.log"
    with log_path.open("wb") as log:
        proc = start_supervisor(config, log)
    try:
        # Every service process exists, and none can have finished importing its runtime.
        wait_for(
            lambda: all(service_pids(s, config) for s in SERVICES) or proc.poll() is not None,
            30,
            "the services' processes",
            poll=0.01,
        )
        proc.send_signal(signal.SIGINT)
    finally:
        assert stop_supervisor(proc, 30), log_path.read_text()
    text = log_path.read_text(errors="replace")
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, text[-4000:]
    assert proc.returncode == 0, text[-4000:]


def test_a_stop_while_the_detector_measures_its_batch_and_capacity_ends_it_cleanly(
    tmp_path: Path,
) -> None:
    # At start a worker times batch sizes and its capacity: many seconds on a busy CPU. A stop
    # meanwhile waited for all of it, past the supervisor's stop_timeout_s: "detector was
    # killed by signal 9" (issue 39, a fresh clone's suite beside two CPU burners).
    config = write_config(
        tmp_path,
        supervisor={"services": ["detector"], "stop_timeout_s": 5.0},
        # 20 timed runs of batches of 1, 2, 4 and 8, then 20 capacity rounds of 8 frames:
        # far longer than stop_timeout_s at the model's 640 input, even on an idle machine.
        detector={"max_batch": 8, "batch_probe_runs": 20, "batch_choice": "measured"},
    )
    log_path = tmp_path / "supervisor.log"
    with log_path.open("wb") as log:
        proc = start_supervisor(config, log)
    try:
        wait_for(
            lambda: (
                "INFO model " in log_path.read_text(errors="replace") or proc.poll() is not None
            ),
            120,
            lambda: f"the detector's model loaded:\n{log_path.read_text(errors='replace')}",
        )
        proc.send_signal(signal.SIGINT)
    finally:
        assert stop_supervisor(proc, 60), log_path.read_text()
    text = log_path.read_text(errors="replace")
    assert "stopped while starting" in text, text[-4000:]
    assert "killed" not in text and "Traceback" not in text, text[-4000:]
    assert proc.returncode == 0, text[-4000:]
