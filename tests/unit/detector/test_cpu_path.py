"""The CPU detection path imports neither the model acquisition nor the CUDA interpreter.

Each check runs in a fresh interpreter, so that what this test session already imported cannot
hide an import (or fake one).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from modelprep import files as model_files

ROOT = Path(__file__).resolve().parents[3]
#: Never imported on the CPU path: the npm fetch and TF.js translator, the torch interpreter.
OFF_THE_CPU_PATH = ("modelprep.acquire", "runtimes.onnx_torch", "torch")


def _modules_after(code: str, env: dict[str, str] | None = None) -> set[str]:
    """The names in ``sys.modules`` after a fresh interpreter runs ``code``."""
    script = f"{code}\nimport sys\nprint('\\n'.join(sorted(sys.modules)))"
    done = subprocess.run(
        [sys.executable, "-c", script],
        cwd=ROOT,
        env={**os.environ, **(env or {})},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return set(done.stdout.split())


def _off_the_path(modules: set[str]) -> list[str]:
    return sorted(
        m for m in modules if any(m == o or m.startswith(f"{o}.") for o in OFF_THE_CPU_PATH)
    )


def test_importing_the_cpu_path_imports_no_acquisition_and_no_interpreter() -> None:
    modules = _modules_after(
        "import perception, services.detector, services.detector.service, perception.pipeline, "
        "runtimes.onnx, tools.detector.cli"
    )
    assert "runtimes.onnx" in modules  # the check sees what was imported
    assert _off_the_path(modules) == []


@pytest.fixture
def current_default_model(tmp_path: Path) -> Path:
    """A models folder whose default model is current: a stand-in file, stamped as built."""
    model = model_files.default_model_path(tmp_path)
    model.write_bytes(b"stands in for the converted model")
    model_files.write_stamp(model)
    return tmp_path


def test_a_current_default_model_is_found_without_importing_the_acquisition(
    current_default_model: Path,
) -> None:
    expected = model_files.default_model_path(current_default_model)
    modules = _modules_after(
        "import perception\nfrom modelprep.files import ensure_default_model\n"
        f"assert str(ensure_default_model()) == {str(expected)!r}",
        env={model_files.MODELS_DIR_ENV: str(current_default_model)},
    )
    assert _off_the_path(modules) == []


def test_a_missing_default_model_imports_the_acquisition_to_fetch_it(tmp_path: Path) -> None:
    # No npm on PATH: the fetch fails at once, after the acquisition was imported to try it.
    modules = _modules_after(
        "from common.errors import ModelFetchError\n"
        "import perception\nfrom modelprep.files import ensure_default_model\n"
        "try:\n"
        "    ensure_default_model()\n"
        "except ModelFetchError:\n"
        "    pass\n",
        env={model_files.MODELS_DIR_ENV: str(tmp_path), "PATH": str(tmp_path)},
    )
    assert "modelprep.acquire.fetch" in modules
