"""The three output families on hand-built tensors, family detection, and model metadata."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from common.coco import COCO80
from common.errors import BackendUnavailable, ConfigError, ModelError, UnknownModelFamily
from perception.decode import (
    Family,
    decode_end2end,
    decode_yolov5,
    decode_yolov8,
    detect_family,
    v5_anchor_count,
)
from perception.model_info import (
    class_names,
    parse_names,
    read_model_info,
)
from perception.pipeline import Detector
from perception.settings import DecodeOptions
from runtimes import BACKENDS, Dim, open_backend
from runtimes.base import input_size, parse_imgsz

# --- family detection ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("shape", "names", "family", "classes"),
    [
        ((1, 25200, 85), None, Family.YOLOV5, 80),
        ((1, 25200, 85), 80, Family.YOLOV5, 80),
        ((1, 84, 8400), 80, Family.YOLOV8, 80),
        ((1, 84, 8400), None, Family.YOLOV8, 80),
        ((None, 22, None), 18, Family.YOLOV8, 18),  # nudenet 320n: dynamic batch and anchors
        ((None, None, 85), None, Family.YOLOV5, 80),  # dynamic batch and input size
        ((1, 300, 6), 80, Family.END2END, None),
        ((None, 300, 6), None, Family.END2END, None),
        ((1, 25200, 6), 1, Family.YOLOV5, 1),  # one-class YOLOv5: N is the anchor count
    ],
)
def test_detect_family(
    shape: tuple[Dim, ...], names: int | None, family: Family, classes: int | None
) -> None:
    layout = detect_family(shape, num_names=names, input_hw=(640, 640))
    assert (layout.family, layout.num_classes) == (family, classes)


def test_end2end_metadata_decides_the_shared_shape() -> None:
    assert detect_family((1, 300, 6), end2end=True).family is Family.END2END
    assert detect_family((1, 25200, 6), input_hw=(640, 640), end2end=True).family is (
        Family.END2END
    )
    assert detect_family((1, 300, 6), end2end=False).family is Family.YOLOV5


@pytest.mark.parametrize(
    ("shape", "names", "text"),
    [
        ((1, 7), None, "[1, 7]"),
        ((1, 2, 3, 4), None, "[1, 2, 3, 4]"),
        ((1, 116, 8400), 80, "[1, 116, 8400] with 80 class names"),  # a segmentation head
        ((1, 4, 8400), None, "[1, 4, 8400]"),  # no class column
        ((1, 50, 50), None, "[1, 50, 50]"),
        ((None, None, None), None, "[?, ?, ?]"),
    ],
)
def test_unknown_family_says_the_shape_on_one_line(
    shape: tuple[Dim, ...], names: int | None, text: str
) -> None:
    with pytest.raises(UnknownModelFamily) as info:
        detect_family(shape, num_names=names)
    message = str(info.value)
    assert text in message and "\n" not in message


def test_v5_anchor_count() -> None:
    assert v5_anchor_count(640, 640) == 25200
    assert v5_anchor_count(320, 320) == 6300


# --- decoders -----------------------------------------------------------------------------------

# Three candidate boxes (cx, cy, w, h in input pixels) and their scores over 3 classes.
BOXES = np.array([[100, 100, 20, 40], [300, 200, 60, 60], [50, 500, 10, 10]], np.float32)
CLASS_SCORES = np.array([[0.9, 0.1, 0.2], [0.3, 0.2, 0.8], [0.1, 0.95, 0.1]], np.float32)
XYXY = np.array([[90, 80, 110, 120], [270, 170, 330, 230], [45, 495, 55, 505]], np.float32)


def v5_tensor(objectness: npt.ArrayLike, batch: int = 1) -> npt.NDArray[np.float32]:
    rows = np.concatenate(
        [BOXES, np.asarray(objectness, np.float32)[:, None], CLASS_SCORES], axis=1
    )
    return np.repeat(rows[None], batch, axis=0)


def test_decode_yolov5_scores_are_objectness_times_class() -> None:
    (c,) = decode_yolov5(v5_tensor([0.5, 1.0, 0.2]), conf=0.25)
    # Row 0: 0.5*0.9 = 0.45; row 1: 1.0*0.8; row 2: objectness 0.2 fails the cheap pre-filter.
    np.testing.assert_allclose(c.scores, [0.45, 0.8])
    np.testing.assert_array_equal(c.class_ids, [0, 2])
    np.testing.assert_allclose(c.xyxy, XYXY[:2])
    assert c.xyxy.dtype == np.float32 and c.class_ids.dtype == np.int32


def test_decode_yolov5_drops_rows_whose_product_is_below_conf() -> None:
    (c,) = decode_yolov5(v5_tensor([0.3, 1.0, 1.0]), conf=0.5)  # 0.3 * 0.9 = 0.27 < 0.5
    np.testing.assert_array_equal(c.class_ids, [2, 1])


def test_decode_yolov5_class_mask_picks_the_best_allowed_class() -> None:
    mask = np.array([False, True, True])
    (c,) = decode_yolov5(v5_tensor([1.0, 1.0, 1.0]), conf=0.15, class_mask=mask)
    # Row 0 may not be class 0: its best allowed class is 2 (0.2).
    np.testing.assert_array_equal(c.class_ids, [2, 2, 1])
    np.testing.assert_allclose(c.scores, [0.2, 0.8, 0.95])


def test_decode_yolov8_is_the_transposed_layout_without_objectness() -> None:
    channels_first = np.concatenate([BOXES, CLASS_SCORES], axis=1).T[None]  # (1, 4+3, 3)
    (c,) = decode_yolov8(np.ascontiguousarray(channels_first), conf=0.5)
    np.testing.assert_allclose(c.scores, [0.9, 0.8, 0.95])
    np.testing.assert_array_equal(c.class_ids, [0, 2, 1])
    np.testing.assert_allclose(c.xyxy, XYXY)
    (masked,) = decode_yolov8(channels_first, conf=0.5, class_mask=np.array([1, 0, 0], bool))
    np.testing.assert_array_equal(masked.class_ids, [0])


def test_decode_end2end_filters_score_class_and_padding() -> None:
    rows = np.array(
        [
            [10, 20, 30, 40, 0.9, 2],
            [15, 25, 35, 45, 0.8, 2],  # overlaps row 0: kept, NMS already ran in the graph
            [0, 0, 5, 5, 0.1, 0],  # below conf
            [0, 0, 0, 0, 0.0, -1],  # padding row
            [1, 1, 9, 9, 0.7, 99],  # class id outside the model's classes
        ],
        np.float32,
    )[None]
    (c,) = decode_end2end(rows, conf=0.25, num_classes=3)
    np.testing.assert_allclose(c.xyxy, rows[0, :2, :4])
    np.testing.assert_array_equal(c.class_ids, [2, 2])
    (none,) = decode_end2end(rows, 0.25, 3, class_mask=np.array([True, True, False]))
    assert none.scores.shape == (0,)


def test_dynamic_batch_decodes_each_image() -> None:
    out = v5_tensor([0.5, 1.0, 0.2], batch=3)
    out[1, :, 4] = 0.0  # the second image finds nothing
    results = decode_yolov5(out, conf=0.25)
    assert [len(r.scores) for r in results] == [2, 0, 2]
    v8 = np.ascontiguousarray(out[:, :, [0, 1, 2, 3, 5, 6, 7]].transpose(0, 2, 1))
    assert [len(r.scores) for r in decode_yolov8(v8, conf=0.5)] == [3, 3, 3]


# --- model metadata -----------------------------------------------------------------------------


def test_parse_names_and_imgsz() -> None:
    assert parse_names("{0: 'person', 1: 'bicycle'}") == {0: "person", 1: "bicycle"}
    assert parse_names("['a', 'b']") == {0: "a", 1: "b"}
    assert parse_names("not python") is None
    assert parse_names("{'a': 1}") is None
    assert parse_imgsz("[384, 640]") == (384, 640)
    assert parse_imgsz("320") == (320, 320)
    assert parse_imgsz("[0, 1]") is None


def test_input_size_falls_back_to_metadata_then_640() -> None:
    assert input_size((1, 3, 480, 800), {"imgsz": "[320, 320]"}) == (480, 800)
    assert input_size((None, 3, None, None), {"imgsz": "[320, 320]"}) == (320, 320)
    assert input_size((None, 3, None, None), {}) == (640, 640)
    with pytest.raises(ModelError, match="not \\[B, 3, H, W\\]"):
        input_size((1, 640, 640, 3), {})


def test_class_names_fallbacks() -> None:
    assert class_names(None, 80) == COCO80
    assert class_names(None, 2) == ("class_0", "class_1")
    assert class_names({0: "a", 2: "c"}, 3) == ("a", "class_1", "c")
    assert class_names(None, None) == COCO80  # end-to-end without names: COCO assumed


class FakeBackend:
    """Stands in for a runtime: returns a fixed output, records what it was given."""

    name = "fake"
    device = "cpu"
    precision = "fp32"

    def __init__(
        self,
        input_shape: tuple[Dim, ...],
        output: npt.NDArray[np.float32],
        metadata: Mapping[str, str] | None = None,
        declared_output: tuple[Dim, ...] | None = None,
    ) -> None:
        self.input_shape = input_shape
        self.output_shapes = (declared_output or tuple(output.shape),)
        self.metadata: Mapping[str, str] = metadata or {}
        self.output = output
        self.batches: list[tuple[int, ...]] = []
        self.closed = False

    def infer(self, batch: npt.NDArray[np.float32]) -> list[npt.NDArray[np.float32]]:
        self.batches.append(batch.shape)
        return [np.repeat(self.output[:1], batch.shape[0], axis=0)]

    def close(self) -> None:
        self.closed = True


def test_model_info_probes_a_dynamic_output() -> None:
    out = np.zeros((1, 22, 2100), np.float32)
    backend = FakeBackend(
        (None, 3, None, None), out, {"names": str(dict(enumerate("abcdefghijklmnopqr"))),
                                     "imgsz": "[320, 320]"},
        declared_output=(None, 22, None),
    )  # fmt: skip
    info = read_model_info(backend)
    assert (info.family, info.input_height, info.batch_size) == (Family.YOLOV8, 320, None)
    assert info.names[:2] == ("a", "b") and len(info.names) == 18
    assert backend.batches == [(1, 3, 320, 320)]


def test_detector_maps_end2end_boxes_back_to_image_pixels() -> None:
    # A 1280x720 image in a 640x640 input: scale 0.5, 140 px of padding above and below.
    rows = np.array([[[100, 190, 300, 290, 0.9, 15], [0, 0, 10, 10, 0.1, 0]]], np.float32)
    backend = FakeBackend((1, 3, 640, 640), rows, {"names": str(dict(enumerate(COCO80)))})
    with Detector(backend, Path("fake.onnx"), DecodeOptions(conf=0.25)) as det:
        result = det.detect(np.zeros((720, 1280, 3), np.uint8))
        assert det.names == COCO80
    assert backend.closed
    np.testing.assert_allclose(result.xyxy, [[200, 100, 600, 300]])
    assert result.class_names == ["cat"] and (result.image_width, result.image_height) == (
        1280,
        720,
    )
    assert result.timing.inference_ms >= 0


def test_the_detector_takes_the_stack_detector_settings() -> None:
    rows = np.array(
        [[[0, 0, 50, 50, 0.9, 15], [100, 100, 200, 200, 0.6, 0], [300, 300, 330, 330, 0.3, 0]]],
        np.float32,
    )
    backend = FakeBackend((1, 3, 640, 640), rows, {"names": str(dict(enumerate(COCO80)))})
    image = np.zeros((640, 640, 3), np.uint8)
    with Detector(backend, Path("fake.onnx")) as det:
        assert det.settings == DecodeOptions()  # one default per field: the settings' own
        assert det.detect(image).class_names == ["cat", "person", "person"]
    for settings, names in (
        (DecodeOptions(conf=0.5), ["cat", "person"]),
        (DecodeOptions(max_det=1), ["cat"]),
        (DecodeOptions(classes=("person",)), ["person", "person"]),
    ):
        with Detector(FakeBackend((1, 3, 640, 640), rows), Path("fake.onnx"), settings) as det:
            assert det.settings is settings
            assert det.detect(image).class_names == names


def test_detector_rejects_unknown_class_names_and_closes_the_backend() -> None:
    backend = FakeBackend((1, 3, 640, 640), np.zeros((1, 300, 6), np.float32))
    with pytest.raises(ConfigError, match=r"unknown class name.*'kitten'.*valid names: person"):
        Detector(backend, Path("fake.onnx"), DecodeOptions(classes=("kitten",)))
    assert backend.closed


def test_open_backend_errors() -> None:
    with pytest.raises(ConfigError, match="unknown backend 'nope'; valid backends: onnx"):
        open_backend("nope", "model.onnx")
    with pytest.raises(ModelError, match="no such model file"):
        open_backend("onnx", "/nonexistent/model.onnx")


def test_missing_runtime_is_backend_unavailable(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(BACKENDS, "ghost", "runtimes.no_such_runtime")
    with pytest.raises(BackendUnavailable, match="backend 'ghost' is unavailable"):
        open_backend("ghost", "model.onnx")
