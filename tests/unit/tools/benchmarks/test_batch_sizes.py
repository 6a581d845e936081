"""The batch-size benchmark on the real default model (ONNX Runtime on the CPU)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tools.benchmarks.batch_sizes import BatchOptions, run


def test_it_times_each_size_and_names_the_detector_s_choice(
    default_model: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    said: list[str] = []
    options = BatchOptions(default_model, "onnx", 2, 1, 0.2, {}, as_json=True)
    assert run(options, said.append) == 0
    figures = json.loads(capsys.readouterr().out)
    assert set(figures["whole_ms_per_image"]) == {"1", "2"}  # JSON keys are strings
    assert all(ms > 0 for ms in figures["model_ms_per_image"].values())
    assert figures["chosen_batch"] in (1, 2)
    assert figures["backend"] == "onnx" and figures["device"] == "cpu"
    assert any("timing the whole detection" in line for line in said)
