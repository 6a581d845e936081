"""`report` on a short real run of the stack, with the metrics service's Prometheus endpoint on."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest
from prometheus_client.parser import text_string_to_metric_families

from tests.integration.conftest import REPO, STARTUP_S, wait_for, write_config
from tools.launch import free_port

pytestmark = pytest.mark.integration

RECORD_S = 8.0


def _scrape(port: int) -> dict[str, float]:
    """Unlabelled and summed-over-labels sample values by name; {} while nothing listens."""
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=2) as reply:
            text = reply.read().decode()
    except OSError:
        return {}
    values: dict[str, float] = {}
    for family in text_string_to_metric_families(text):
        for s in family.samples:
            if s.name.endswith("_count") or not s.labels:
                values[s.name] = values.get(s.name, 0.0) + s.value
    return values


@pytest.mark.usefixtures("default_model")  # fetched before the stack needs it
def test_report_records_a_real_run_and_prometheus_sees_it(tmp_path: Path) -> None:
    port = free_port()
    config = write_config(tmp_path, metrics={"prometheus_port": port, "report_period_s": 1.0})
    out = tmp_path / "report"
    env = {k: v for k, v in os.environ.items() if not k.startswith("STACK__")}
    proc = subprocess.Popen(
        [sys.executable, "-m", "tools.report", "report", "--config", str(config),
         "--duration", str(RECORD_S), "--out", str(out)],
        cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        start_new_session=True,
    )  # fmt: skip
    try:
        seen = wait_for(
            lambda: (v := _scrape(port)).get("stack_frames_total", 0) > 0 and v,
            STARTUP_S,
            "the Prometheus endpoint to count frames",
        )
        assert seen["stack_latency_seconds_count"] > 0 and seen["stack_fps"] >= 0
        stdout, stderr = proc.communicate(timeout=STARTUP_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)
            proc.communicate(timeout=30)
    assert proc.returncode == 0, stderr.decode()
    written = {Path(line).name for line in stdout.decode().split()}
    assert written == {"report.md", "session.json", "latency_histogram.png",
                       "fps_over_time.png", "stage_breakdown.png"}  # fmt: skip
    for name in written:
        if name.endswith(".png"):
            assert (out / name).read_bytes().startswith(b"\x89PNG\r\n\x1a\n")

    session = json.loads((out / "session.json").read_text())
    assert session["supervisor_exit_code"] == 0, (out / "supervisor.log").read_text()[-3000:]
    assert RECORD_S <= session["duration_s"] < RECORD_S + 5
    summary = session["summary"]
    assert summary["frames"] > 0 and summary["class_counts"].get("person", 0) > 0
    assert 0.0 <= summary["drop_rate"] <= 1.0
    assert len(session["latency_samples_ms"]["end_to_end"]) > 0
    assert len(summary["timeline"]["t"]) >= 3  # it ends 2 s early and starts at the counters
    assert session["metrics_service"]["frames"] > 0  # the service's own view, asked at the end
    assert session["machine"]["cpu_count"] and session["machine"]["python"]
    assert "## Latency per stage" in (out / "report.md").read_text()
