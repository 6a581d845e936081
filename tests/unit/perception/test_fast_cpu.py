"""The fast CPU path's pure parts and caches: variants, the fast profile's choice, input
sizes, and the INT8 cache on a tiny model (quantized for real, in a second)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
import pytest

from common.errors import ConfigError, ModelError
from modelprep.acquire.tfjs_resize import check_size, grid_offsets
from modelprep.quantize import QuantizationFailed, head_nodes, quantized_model
from perception.fast_profile import Figures, choose
from perception.preparing import prepare, sized_model
from perception.settings import ModelSpec
from perception.variants import Variant
from tests.unit.perception.tiny import tiny_model


def test_variant_labels_parse_and_refuse_garbage() -> None:
    assert Variant.parse("onnx:int8:480") == Variant("onnx", "int8", 480)
    assert Variant.parse("onnx:int8:480").label == "onnx:int8:480"
    with pytest.raises(ConfigError, match="backend:precision:size"):
        Variant.parse("onnx-int8")


def test_choice_is_the_fastest_that_keeps_ap50() -> None:
    figures = [
        Figures("onnx:fp32:640", 100.0, 0.85),
        Figures("onnx:int8:480", 40.0, 0.83),  # fastest, but loses 0.02
        Figures("onnx:fp32:416", 45.0, 0.86),
        Figures("onnx:fp32:480", 55.0, 0.94),
    ]
    chosen, why = choose(figures, "onnx:fp32:640", 0.01)
    assert chosen == "onnx:fp32:416"
    assert "0.45x" in why and "onnx:int8:480 AP50 0.830" in why
    assert choose(figures, "onnx:fp32:640", 0.05)[0] == "onnx:int8:480"
    with pytest.raises(ConfigError, match="reference"):
        choose(figures[1:], "onnx:fp32:640", 0.01)


def test_input_size_setting_and_converter_sizes() -> None:
    assert ModelSpec(imgsz=480).imgsz == 480
    for bad in (500, 96, 1312):
        with pytest.raises(ConfigError, match=r"detector\.imgsz must be"):
            ModelSpec(imgsz=bad)
    with pytest.raises(ModelError):
        check_size(500)
    grid = grid_offsets(3)[0, 0]
    assert grid[:4].tolist() == [[-0.5, -0.5], [0.5, -0.5], [1.5, -0.5], [-0.5, 0.5]]


def test_named_model_of_another_fixed_size_is_one_config_error(tmp_path: Path) -> None:
    model = tiny_model(tmp_path / "tiny.onnx", side=32)
    assert sized_model(ModelSpec(model=str(model), imgsz=0)) == model
    with pytest.raises(ConfigError, match=r"imgsz = 480, but tiny.onnx has a 32x32 input"):
        sized_model(ModelSpec(model=str(model), imgsz=480))


def test_head_nodes_are_the_last_convs_and_after(tmp_path: Path) -> None:
    assert head_nodes(tiny_model(tmp_path / "m.onnx")) == ["head/Conv", "decode/Sigmoid"]


def test_int8_cache_is_reused_and_invalidated(tmp_path: Path) -> None:
    model = tiny_model(tmp_path / "m.onnx")
    lines: list[str] = []
    out = quantized_model(model, runtime="onnxruntime", progress=lines.append)
    assert out == tmp_path / "m.onnxruntime-int8.onnx" and out.is_file()
    assert lines[0].startswith("INT8 cache miss (no INT8 model cached yet)")
    assert any(line.startswith("calibrating: frame") for line in lines)
    ops = {n.op_type for n in onnx.load(str(out)).graph.node}
    assert "QuantizeLinear" in ops
    lines.clear()
    assert quantized_model(model, runtime="onnxruntime", progress=lines.append) == out
    assert lines == [f"INT8 cache hit: {out}"]
    tiny_model(model, seed=1)  # new weights: the model's sha256 changes
    lines.clear()
    quantized_model(model, runtime="onnxruntime", progress=lines.append)
    assert lines[0] == "INT8 cache miss (model_sha256 changed): " + lines[0].split("): ")[1]
    calib = tmp_path / "frames"
    calib.mkdir()
    import cv2

    cv2.imwrite(str(calib / "a.png"), np.full((40, 60, 3), 90, np.uint8))
    lines.clear()
    quantized_model(model, runtime="onnxruntime", calibration_dir=calib, progress=lines.append)
    assert lines[0].startswith("INT8 cache miss (calibration changed)")


def test_a_model_that_cannot_be_quantized_stays_on_fp32(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    model = tiny_model(tmp_path / "dynamic.onnx", side="size")  # no fixed size to calibrate at
    with pytest.raises(QuantizationFailed, match="fixed NCHW input size"):
        quantized_model(model, runtime="onnxruntime")
    prepared = prepare(ModelSpec(model=str(model), precision="int8"))
    assert prepared.model == model and prepared.backend == "onnx"
    assert prepared.note.endswith("the detector stays on FP32")
    warnings = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert len(warnings) == 1 and "\n" not in warnings[0]
