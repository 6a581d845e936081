"""Backend choice on the command line, as a user runs it, on a machine without TensorRT.

``--backend tensorrt`` (detect, export, serve) must stop with one clear line and exit 4; ``auto``
must fall back to the CPU, say so, and work; ``benchmark`` compares backends side by side.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
from skimage import data

from runtimes.select import probe_cuda, probe_tensorrt
from tests.integration.conftest import run_detector_cli, write_config

pytestmark = pytest.mark.integration

EXIT_BACKEND = 4
NO_TRT_LINE = (
    "error: TensorRT is not installed "
    "(pip install tensorrt-cu12 on a machine with an NVIDIA driver)"
)

needs_no_tensorrt = pytest.mark.skipif(
    probe_tensorrt() is None, reason="TensorRT and a GPU are present here: nothing to refuse"
)


@pytest.fixture(scope="module")
def photos(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("photos")
    for name in ("chelsea", "coffee"):
        image = np.ascontiguousarray(getattr(data, name)()[:, :, ::-1])
        assert cv2.imwrite(str(folder / f"{name}.png"), image)
    return folder


def assert_one_line(proc: subprocess.CompletedProcess[str], code: int, line: str) -> None:
    assert proc.returncode == code, proc.stderr
    assert proc.stderr.strip().splitlines() == [line], proc.stderr
    assert proc.stdout == ""


@needs_no_tensorrt
def test_detect_on_tensorrt_without_it_is_one_line_and_exit_4(
    default_model: Path, photos: Path
) -> None:
    proc = run_detector_cli("detect", photos, "--model", default_model, "--backend", "tensorrt")
    assert_one_line(proc, EXIT_BACKEND, NO_TRT_LINE)


@needs_no_tensorrt
@pytest.mark.parametrize(
    "extra",
    [[], ["--precision", "int8", "--calib", "calib"], ["--batch", "4", "--workspace-gb", "2"]],
)
def test_export_without_tensorrt_is_one_line_and_exit_4(
    default_model: Path, extra: list[str]
) -> None:
    proc = run_detector_cli("export", "--backend", "tensorrt", "--model", default_model, *extra)
    assert_one_line(proc, EXIT_BACKEND, NO_TRT_LINE)


@needs_no_tensorrt
def test_serve_on_tensorrt_without_it_exits_4_with_one_error_line(
    default_model: Path, tmp_path: Path
) -> None:
    config = write_config(tmp_path, detector={"model": str(default_model)})
    proc = run_detector_cli("serve", "--config", config, "--backend", "tensorrt", timeout=120)
    assert proc.returncode == EXIT_BACKEND, proc.stderr
    errors = [line for line in proc.stderr.splitlines() if "error" in line.lower()]
    assert errors == [NO_TRT_LINE], proc.stderr
    assert "Traceback" not in proc.stderr


def test_serve_refuses_an_unknown_backend_with_one_line(tmp_path: Path) -> None:
    proc = run_detector_cli(
        "serve", "--config", write_config(tmp_path), "--backend", "tpu", timeout=60
    )
    assert_one_line(
        proc,
        2,
        "error: detector.backend must be one of onnx, tensorrt, cuda, openvino, auto, got 'tpu'",
    )


@pytest.mark.skipif(
    probe_tensorrt() is None or probe_cuda() is None, reason="a GPU backend is usable here"
)
def test_detect_auto_falls_back_to_a_cpu_backend_and_says_so(
    default_model: Path, photos: Path
) -> None:
    proc = run_detector_cli(
        "detect", photos, "--model", default_model, "--backend", "auto", "--json"
    )
    assert proc.returncode == 0, proc.stderr
    # Without a GPU: OpenVINO on a CPU with VNNI or AMX (the dev extra installs it), else onnx.
    from runtimes import select

    cpu_suits = select.openvino_cpu_reason(select.CPUINFO.read_text()) is None
    assert f"falling back to {'openvino' if cpu_suits else 'onnx'} (CPU)" in proc.stderr
    assert "TensorRT not installed" in proc.stderr or "TensorRT:" in proc.stderr
    cat = json.loads(proc.stdout.splitlines()[0])
    assert cat["image"].endswith("chelsea.png")
    assert "cat" in [d["class_name"] for d in cat["detections"]]


def test_benchmark_compares_backends_side_by_side(default_model: Path, photos: Path) -> None:
    proc = run_detector_cli(
        "benchmark", "--model", default_model, "--backend", "onnx", "--backend", "auto",
        "--runs", "3", "--warmup", "1", "--images", photos, "--json",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert list(report["backends"]) == ["onnx", "auto"]
    for name, entry in report["backends"].items():
        for key in ("p50_ms", "p95_ms"):
            assert set(entry[key]) == {"preprocess", "inference", "postprocess", "total"}, name
        assert entry["fps"] > 0
        assert entry["agreement"]["reference_boxes"] > 0
    # The single-backend keys stay, for the first backend.
    assert report["p50_ms"] == report["backends"]["onnx"]["p50_ms"]
    assert report["ratio_to_bare_run"] > 0.5
    assert report["backends"]["onnx"]["agreement"]["map50"] == 1.0  # the reference itself
    assert report["agreement_reference"]["backend"] == "onnx/cpu/fp32"
    assert len(report["agreement_reference"]["images"]) == 2
    if report["backends"]["auto"]["backend"]["name"] == "onnx":
        assert report["backends"]["auto"]["agreement"]["map50"] == 1.0


def test_benchmark_on_a_missing_backend_is_one_line(default_model: Path) -> None:
    if probe_tensorrt() is None:
        pytest.skip("TensorRT is present here")
    proc = run_detector_cli(
        "benchmark", "--model", default_model, "--backend", "onnx", "--backend", "tensorrt"
    )
    assert_one_line(proc, EXIT_BACKEND, NO_TRT_LINE)
