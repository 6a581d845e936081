"""Real weights on real photos, and the command line as a user runs it.

The hand-labelled boxes below were drawn by looking at each photo on a 20 px grid; they are the
object as a person would box it, not the model's output.
"""

from __future__ import annotations

import importlib.resources
import json
import subprocess
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper
from skimage import data

from perception.decode import Family
from perception.pipeline import Detector
from tests.integration.conftest import run_detector_cli

pytestmark = pytest.mark.integration

# Hand-labelled boxes, x1, y1, x2, y2 in image pixels.
CHELSEA_CAT = (0.0, 0.0, 395.0, 300.0)  # 451x300: the cat's head fills most of the frame
COFFEE_CUP = (172.0, 17.0, 406.0, 296.0)  # 600x400: rim to handle, without saucer or spoon
ASTRONAUT_FACE = (180.0, 80.0, 262.0, 180.0)  # 512x512: forehead (below the hair) to chin


def box_iou(a: tuple[float, ...] | list[float], b: tuple[float, ...] | list[float]) -> float:
    iw = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    ih = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = iw * ih
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


def bgr(name: str) -> npt.NDArray[np.uint8]:
    return np.ascontiguousarray(getattr(data, name)()[:, :, ::-1])


@pytest.fixture(scope="module")
def coco_detector(default_model: Path) -> Iterator[Detector]:
    with Detector.open(default_model) as det:
        yield det


@pytest.mark.parametrize(
    ("photo", "expected", "hand_box"),
    [("chelsea", "cat", CHELSEA_CAT), ("coffee", "cup", COFFEE_CUP)],
)
def test_default_model_finds_the_object(
    coco_detector: Detector, photo: str, expected: str, hand_box: tuple[float, ...]
) -> None:
    assert coco_detector.info.family is Family.YOLOV5
    result = coco_detector.detect(bgr(photo))
    assert len(result) >= 1
    assert result.class_names[0] == expected
    assert box_iou(result.xyxy[0].tolist(), hand_box) >= 0.5


def test_class_filter_on_real_photo(coco_detector: Detector, default_model: Path) -> None:
    from services.detector.contract import DetectorSettings

    with Detector.open(default_model, settings=DetectorSettings(classes=("dog",))) as det:
        assert len(det.detect(bgr("chelsea"))) == 0


def test_yolov8_layout_on_nudenet_weights() -> None:
    model = importlib.resources.files("nudenet") / "320n.onnx"
    with Detector.open(str(model)) as det:
        assert det.info.family is Family.YOLOV8
        assert (det.info.input_height, det.info.input_width) == (320, 320)  # from imgsz metadata
        assert "FACE_FEMALE" in det.names
        result = det.detect(bgr("astronaut"))
    faces = [i for i, name in enumerate(result.class_names) if name.startswith("FACE_")]
    assert faces, f"no face among {result.class_names}"
    assert box_iou(result.xyxy[faces[0]].tolist(), ASTRONAUT_FACE) >= 0.5


# --- the command line ---------------------------------------------------------------------------


def assert_one_line_error(proc: subprocess.CompletedProcess[str], code: int, text: str) -> None:
    assert proc.returncode == code, proc.stderr
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and text in lines[0], proc.stderr


@pytest.fixture(scope="module")
def photo_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("photos")
    cv2.imwrite(str(folder / "a_chelsea.png"), bgr("chelsea"))
    cv2.imwrite(str(folder / "c_coffee.jpg"), bgr("coffee"))
    (folder / "b_corrupt.jpg").write_bytes(b"\xff\xd8 this is not really a jpeg" * 10)
    (folder / "d_missing.png").symlink_to(folder / "gone.png")  # listed, but nothing there
    (folder / "notes.txt").write_text("not an image extension: never listed")
    return folder


def test_cli_detect_folder_reports_bad_images_and_goes_on(
    default_model: Path, photo_dir: Path, tmp_path: Path
) -> None:
    proc = run_detector_cli(
        "detect", photo_dir, tmp_path / "nowhere.jpg", "--model", default_model, "--json",
        "--save-dir", tmp_path / "out",
    )  # fmt: skip
    assert proc.returncode == 1
    assert "Traceback" not in proc.stderr
    assert "b_corrupt.jpg: not a readable image" in proc.stderr
    assert "d_missing.png: no such file" in proc.stderr
    assert "nowhere.jpg: no such file" in proc.stderr
    lines = [json.loads(line) for line in proc.stdout.splitlines()]
    assert [Path(r["image"]).name for r in lines] == ["a_chelsea.png", "c_coffee.jpg"]
    for record in lines:
        assert set(record) == {"image", "width", "height", "detections", "timing_ms"}
        assert isinstance(record["width"], int) and isinstance(record["height"], int)
        assert set(record["timing_ms"]) == {"preprocess", "inference", "postprocess"}
        assert all(isinstance(v, float) for v in record["timing_ms"].values())
        for det in record["detections"]:
            assert set(det) == {"class_id", "class_name", "score", "bbox_xyxy"}
            assert isinstance(det["class_id"], int) and isinstance(det["class_name"], str)
            assert 0.0 <= det["score"] <= 1.0 and len(det["bbox_xyxy"]) == 4
    assert lines[0]["detections"][0]["class_name"] == "cat"
    assert lines[1]["detections"][0]["class_name"] == "cup"
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["a_chelsea.png", "c_coffee.jpg"]


def test_cli_detect_text_output(default_model: Path, photo_dir: Path) -> None:
    proc = run_detector_cli("detect", photo_dir / "a_chelsea.png", "--model", default_model)
    assert proc.returncode == 0, proc.stderr
    assert "a_chelsea.png: 451x300, 1 detection(s): cat" in proc.stdout


def test_cli_text_file_as_model(tmp_path: Path, photo_dir: Path) -> None:
    model = tmp_path / "model.onnx"
    model.write_text("this is a text file\n")
    proc = run_detector_cli("detect", photo_dir / "a_chelsea.png", "--model", model)
    assert_one_line_error(proc, 3, "not a valid ONNX model")


def test_cli_model_with_unknown_output_shape(tmp_path: Path, photo_dir: Path) -> None:
    weights = numpy_helper.from_array(np.ones((3 * 8 * 8, 7), np.float32), "w")
    graph = helper.make_graph(
        [helper.make_node("Flatten", ["images"], ["flat"]),
         helper.make_node("MatMul", ["flat", "w"], ["output0"])],
        "not_yolo",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, 8, 8])],
        [helper.make_tensor_value_info("output0", TensorProto.FLOAT, [1, 7])],
        initializer=[weights],
    )  # fmt: skip
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    path = tmp_path / "not_yolo.onnx"
    onnx.save(model, str(path))
    proc = run_detector_cli("detect", photo_dir / "a_chelsea.png", "--model", path)
    assert_one_line_error(proc, 3, "output shape [1, 7] matches no YOLO family")


@pytest.mark.parametrize(
    ("extra", "code", "text"),
    [
        (["--conf", "1.5"], 2, "detector.conf must be within 0..1, got 1.5"),
        (["--classes", "person,kitten"], 2, "unknown class name(s) 'kitten'; valid names: person"),
        (["--backend", "tpu"], 2, "unknown backend 'tpu'"),
    ],
)
def test_cli_bad_settings(
    default_model: Path, photo_dir: Path, extra: list[str], code: int, text: str
) -> None:
    proc = run_detector_cli("detect", photo_dir / "a_chelsea.png", "--model", default_model, *extra)
    assert_one_line_error(proc, code, text)


def test_cli_benchmark_json(default_model: Path) -> None:
    proc = run_detector_cli(
        "benchmark", "--model", default_model, "--runs", "5", "--warmup", "1", "--json"
    )
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    for key in ("p50_ms", "p95_ms"):
        assert set(report[key]) >= {"preprocess", "inference", "postprocess", "total"}
        assert all(v > 0 for v in report[key].values())
    assert report["ratio_to_bare_run"] > 0.5
    assert 0 < report["pre_post_fraction_of_inference"] < 1
    assert report["backend"]["name"] == "onnx"
    assert report["model"]["family"] == "yolov5"
    assert {"cpu_count", "platform"} <= set(report["machine"])


def test_cli_fetch_model_prints_the_present_model(default_model: Path) -> None:
    proc = run_detector_cli("fetch-model", "--models-dir", default_model.parent)
    assert proc.returncode == 0, proc.stderr
    assert Path(proc.stdout.strip()) == default_model
