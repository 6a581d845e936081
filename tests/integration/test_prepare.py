"""Model preparation ahead of serving: a detector whose model was not prepared stops at once,
its last line naming the file and ``zstack prepare --config FILE``, and builds nothing; that
command builds it (the model's path on stdout), and the stack then starts from it."""

from __future__ import annotations

import io
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from modelprep.acquire.fetch import tarball_name
from modelprep.files import (
    MODELS_DIR_ENV,
    NPM_PACKAGE,
    default_model_path,
    stamp_is_current,
    stamp_path,
)
from stack.config_file import load_config
from tests.integration.conftest import REPO, write_config
from tools.launch import prepare_models

pytestmark = pytest.mark.integration

SERVICES = ["camera", "detector", "controller", "metrics"]
SIZE = 160  # the cheapest input size to rebuild the default model at (about a second)


def _run(args: list[str], env: dict[str, str], timeout: float) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", *args], cwd=REPO, env=env, capture_output=True, text=True,
        timeout=timeout,
    )  # fmt: skip


@pytest.fixture
def models(tmp_path: Path, default_model: Path) -> Path:
    """A models folder of this test's own: the default model and the npm tarball it is rebuilt
    from, and no other size."""
    folder = tmp_path / "models"
    (folder / "cache").mkdir(parents=True)
    for path in (default_model, stamp_path(default_model)):
        shutil.copy(path, folder / path.name)
    tarball = default_model.parent / "cache" / tarball_name(NPM_PACKAGE)
    shutil.copy(tarball, folder / "cache" / tarball.name)
    return folder


def test_an_unprepared_model_stops_the_detector_until_zstack_prepare_makes_it(
    tmp_path: Path, models: Path
) -> None:
    config = write_config(tmp_path, detector={"imgsz": SIZE}, supervisor={"services": SERVICES})
    env = {**os.environ, MODELS_DIR_ENV: str(models)}
    sized = default_model_path(models, SIZE)

    # 1. Not prepared: the stack stops at once, its last line saying what and what to run.
    supervise = ["deploy.supervisor", "--config", str(config), "--duration"]
    done = _run([*supervise, "60"], env, timeout=180)
    assert done.returncode == 2, done.stderr[-3000:]
    last = done.stderr.strip().splitlines()[-1]
    assert "detector" in last and sized.name in last, last
    assert f"run `zstack prepare --config {config}`" in last and len(last) < 500, last
    assert "Traceback" not in done.stderr
    assert not sized.exists(), "the detector built its model at start-up"

    # 2. zstack prepare builds it: its path alone on stdout, progress on stderr.
    done = _run(["deploy.zstack", "prepare", "--config", str(config)], env, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.splitlines() == [str(sized)], done.stdout
    assert stamp_is_current(sized, SIZE)
    assert f"at {SIZE}x{SIZE}" in done.stderr, done.stderr

    # 3. Prepared: the stack starts and runs the model at that size.
    done = _run([*supervise, "8"], env, timeout=180)
    assert done.returncode == 0, done.stderr[-3000:]
    assert f"model {sized} on onnx" in done.stderr, done.stderr[-3000:]


def test_a_tool_starting_a_stack_prepares_its_model_first(
    tmp_path: Path, models: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # what the scenario runner, the benchmarks and make_stack run before the supervisor
    monkeypatch.setenv(MODELS_DIR_ENV, str(models))
    config = load_config(write_config(tmp_path, detector={"imgsz": SIZE}), environ={})
    log = io.BytesIO()
    prepare_models(config, log)
    assert stamp_is_current(default_model_path(models, SIZE), SIZE)
    assert f"prepare: converting yolov5@1.0.11 TF.js graph to ONNX at {SIZE}x{SIZE}" in (
        log.getvalue().decode()
    )
