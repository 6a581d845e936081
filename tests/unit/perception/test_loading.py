"""Serving loads only what was prepared: a missing file is one NotPrepared line naming it and
what to run, never built at load; a failed INT8 build, recorded when it was prepared, loads the
FP32 model with a note (perception/variants.py locate, perception/loading.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from modelprep.files import MODELS_DIR_ENV
from modelprep.quantize import QuantizationFailed, cached_model, quantized_model
from perception import NotPrepared, choose_fast
from perception.settings import DetectorSpec, ModelSpec
from perception.variants import locate
from tests.unit.perception.tiny import tiny_model

INT8 = "m.onnxruntime-int8.onnx"
ROOT = Path(__file__).resolve().parents[3]


def test_an_int8_model_not_prepared_is_one_line_and_not_built(tmp_path: Path) -> None:
    model = tiny_model(tmp_path / "m.onnx")
    settings = ModelSpec(model=str(model), precision="int8")
    with pytest.raises(NotPrepared) as caught:
        locate(settings)
    line = str(caught.value)
    assert INT8 in line and line.endswith(": run `zstack prepare`") and "\n" not in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.onnx"]  # nothing built at load
    built = quantized_model(model, runtime="onnxruntime", progress=lambda _: None)
    prepared = locate(settings)
    assert (prepared.model, prepared.note) == (built, "")


def test_a_failed_int8_build_is_recorded_and_loads_fp32_with_a_note(tmp_path: Path) -> None:
    model = tiny_model(tmp_path / "m.onnx")
    with pytest.raises(QuantizationFailed, match="unusable: finds nothing"):
        quantized_model(model, runtime="onnxruntime", check=lambda _: "finds nothing")
    with pytest.raises(QuantizationFailed, match="unusable: finds nothing"):
        cached_model(model, runtime="onnxruntime")
    prepared = locate(ModelSpec(model=str(model), precision="int8"))
    assert prepared.model == model
    assert "finds nothing" in prepared.note and prepared.note.endswith("stays on FP32")
    # preparing again tries again (the failure may have been the machine's)
    lines: list[str] = []
    quantized_model(model, runtime="onnxruntime", progress=lines.append)
    assert lines[0].startswith("INT8 cache miss (the last build failed: INT8 m.onnx")
    assert cached_model(model, runtime="onnxruntime") == tmp_path / INT8


def test_a_default_model_not_prepared_at_its_size_names_the_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(MODELS_DIR_ENV, str(tmp_path))
    with pytest.raises(NotPrepared, match=r"at input size 320 \(.*yolov5s-coco-320\.onnx\)"):
        locate(ModelSpec(imgsz=320))
    assert list(tmp_path.iterdir()) == []  # no fetch, no rebuild


def test_an_unmeasured_fast_profile_is_not_prepared(tmp_path: Path) -> None:
    model = tiny_model(tmp_path / "m.onnx")
    with pytest.raises(NotPrepared, match=r'detector.profile = "fast" has not been measured'):
        choose_fast(DetectorSpec(model=str(model), profile="fast"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.onnx"]


def test_not_prepared_says_the_command_it_is_given() -> None:
    missing = NotPrepared("the default model (models/x.onnx) is not prepared")
    told = missing.to_run("zstack prepare --config robot.toml")
    assert str(told) == (
        "the default model (models/x.onnx) is not prepared: "
        "run `zstack prepare --config robot.toml`"
    )
    assert told.missing == missing.missing


def test_serving_loads_a_prepared_int8_model_without_importing_the_quantizer(
    tmp_path: Path,
) -> None:
    model = tiny_model(tmp_path / "m.onnx")
    built = quantized_model(model, runtime="onnxruntime", progress=lambda _: None)
    code = (
        "import sys\n"
        "import services.detector.service\n"
        "from perception import load\n"  # serving's load, and what it finds the model with:
        "from perception.settings import ModelSpec\n"
        "from perception.variants import locate\n"
        f"prepared = locate(ModelSpec(model={str(model)!r}, precision='int8'))\n"
        "print(prepared.model, repr(prepared.note))\n"
        "print(' '.join(sorted(sys.modules)))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    loaded, modules = done.stdout.splitlines()
    assert loaded == f"{built} ''"  # the INT8 model, no note
    quantizer = [m for m in modules.split() if m.split(".")[:2] == ["modelprep", "quantize"]]
    assert quantizer == []
