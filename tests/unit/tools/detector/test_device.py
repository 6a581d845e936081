"""``detect --device`` as yolo's command line takes it, mapped onto our backends."""

from __future__ import annotations

import pytest

from common.errors import ConfigError
from tools.detector.device import backend_for, gpu_index


def test_device_names() -> None:
    assert gpu_index("cpu") is None and gpu_index("CPU") is None
    assert gpu_index("0") == 0 and gpu_index("cuda") == 0 and gpu_index("cuda:1") == 1
    with pytest.raises(ConfigError, match="--device must be"):
        gpu_index("mps")


def test_no_device_keeps_the_backend() -> None:
    assert backend_for(None, None) == ("onnx", {})
    assert backend_for("openvino", None) == ("openvino", {})


def test_a_gpu_device_picks_a_gpu_backend() -> None:
    assert backend_for(None, "0") == ("cuda", {"device": "cuda:0"})
    assert backend_for("cuda", "cuda:1") == ("cuda", {"device": "cuda:1"})
    assert backend_for("tensorrt", "1") == ("tensorrt", {"device": 1})
    with pytest.raises(ConfigError, match="runs on the CPU only"):
        backend_for("onnx", "0")


def test_the_cpu_device() -> None:
    assert backend_for(None, "cpu") == ("onnx", {})
    assert backend_for("openvino", "cpu") == ("openvino", {})
    assert backend_for("cuda", "cpu") == ("cuda", {"device": "cpu", "precision": "fp32"})
    with pytest.raises(ConfigError, match="GPU only"):
        backend_for("tensorrt", "cpu")
