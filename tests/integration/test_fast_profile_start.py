"""The fast profile under a deadline: measured ahead of time by ``zstack prepare`` (progress on
stderr, the model the detector will load on stdout, Ctrl-C or SIGTERM stops it at once leaving
nothing half-written), and a stack that starts from the cached choice, never measuring at
start-up."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from common.lifecycle import EXIT_INTERRUPTED
from tests.integration.conftest import REPO, write_config

pytestmark = pytest.mark.integration

SERVICES = ["camera", "detector", "controller", "metrics"]


def _supervise(config: Path, seconds: int) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "deploy.supervisor", "--config", str(config),
         "--duration", str(seconds)],
        cwd=REPO, capture_output=True, text=True, timeout=seconds + 120,
    )  # fmt: skip


def _prepare(config: Path) -> list[str]:
    return [sys.executable, "-m", "tools.detector", "prepare", "--config", str(config)]


def test_measured_ahead_started_from_the_cache(tmp_path: Path, default_model: Path) -> None:
    model = tmp_path / "model.onnx"  # a copy: its cache is this test's alone
    shutil.copy(default_model, model)
    config = write_config(
        tmp_path,
        detector={"model": str(model), "profile": "fast"},
        supervisor={"services": SERVICES},
    )

    # 1. Not measured yet: the stack stops at once, its last line saying what to run.
    started = time.monotonic()
    done = _supervise(config, 60)
    assert done.returncode == 2, done.stderr[-3000:]
    assert time.monotonic() - started < 45, "the detector measured at start-up"
    last = done.stderr.strip().splitlines()[-1]
    assert "detector" in last and f"zstack prepare --config {config}" in last, last
    assert 'detector.profile = "fast"' in last and len(last) < 500, last
    assert "Traceback" not in done.stderr

    # 2. SIGTERM while it quantizes: it stops at once and leaves nothing half-written.
    proc = subprocess.Popen(
        _prepare(config), cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    assert proc.stderr is not None
    seen = ""
    for line in proc.stderr:
        seen += line
        if "quantizing" in line:
            break
    proc.send_signal(signal.SIGTERM)
    try:
        rest = proc.communicate(timeout=20)[1]
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail(f"prepare went on 20 s after SIGTERM:\n{seen}")
    assert proc.returncode == EXIT_INTERRUPTED, seen + rest
    left = sorted(p.name for p in tmp_path.iterdir() if p.name.startswith((".int8-", "model.")))
    assert left == ["model.onnx"], left

    # 3. Prepared: the chosen variant's model file on stdout alone; the stack then starts from
    # the cache.
    done = subprocess.run(_prepare(config), cwd=REPO, capture_output=True, text=True,
                          timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    (chosen,) = done.stdout.splitlines()
    assert Path(chosen).is_file() and Path(chosen).parent == tmp_path, chosen
    assert "fast profile: " in done.stderr and "[measured now]" in done.stderr
    done = _supervise(config, 15)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "[cached figures]" in done.stderr and "measuring" not in done.stderr
