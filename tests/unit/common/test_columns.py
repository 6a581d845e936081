"""Named per-detection columns (``Boxes.columns``): their one check, the row operations that
keep them, and how they travel (a map name -> dtype and bytes, bounded on decode)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any, ClassVar

import msgpack
import numpy as np
import numpy.typing as npt
import pytest

from common.boxes import Boxes
from common.codec import Message
from common.errors import DecodeError
from common.field_types import COLUMN_DTYPES, Columns, Dim
from common.limits import MAX_COLUMN_NAME_CHARS, MAX_COLUMNS
from common.messages import Detections, Header

HEADER = Header(stamp_ns=1_700_000_000_000_000_000, frame_id="camera", seq=3, source="test")
XYXY = np.array([[0, 0, 10, 20], [5, 5, 6, 6], [1, 1, 2, 2]], np.float32)
SCORES = np.array([0.9, 0.3, 0.5], np.float32)
IDS = np.array([0, 7, 2], np.int32)
# One column of every dtype that travels, NaN included where a value is unknown.
EVERY_KIND: dict[str, Any] = {
    "distance_m": np.array([2.5, np.nan, 0.75], np.float64),
    "depth": np.array([1.5, 2.0, -np.inf], np.float32),
    "mask_id": np.array([3, -1, 2**31 - 1], np.int32),
    "big": np.array([2**40, -(2**62), 0], np.int64),
    "occluded": np.array([True, False, True]),
}


def _boxes(columns: Any) -> Boxes:
    return Boxes(xyxy=XYXY, scores=SCORES, class_ids=IDS, columns=columns)


def _detections(boxes: Boxes) -> Detections:
    return Detections(
        header=HEADER,
        image_width=64,
        image_height=48,
        boxes=boxes,
        class_names=("person", "cup", "dog"),
    )


def _body(payload: bytes) -> dict[str, Any]:
    body = msgpack.unpackb(payload)["d"]
    assert isinstance(body, dict)
    return body


def _payload(body: dict[str, Any]) -> bytes:
    out = msgpack.packb({"v": 1, "t": "Detections", "d": body}, use_bin_type=True)
    assert isinstance(out, bytes)
    return out


def test_every_dtype_that_travels_is_allowed_and_comes_back_exactly() -> None:
    assert {v.dtype.name for v in EVERY_KIND.values()} == set(COLUMN_DTYPES)
    msg = _detections(_boxes(EVERY_KIND))
    body = _body(msg.encode())
    assert body["columns"]["distance_m"]["dtype"] == "float64"
    assert body["columns"]["occluded"] == {"dtype": "bool", "data": b"\x01\x00\x01"}
    back = Detections.decode(msg.encode()).boxes.columns
    assert list(back) == list(EVERY_KIND)  # in the order they were added
    for name, values in EVERY_KIND.items():
        assert back[name].dtype == values.dtype
        np.testing.assert_array_equal(back[name], values)


def test_a_message_without_columns_decodes_with_none() -> None:
    # What every writer before columns existed put on the bus and in recordings.
    body = _body(_detections(_boxes(EVERY_KIND)).encode())
    del body["columns"]
    old = Detections.decode(_payload(body))
    assert dict(old.boxes.columns) == {} and len(old) == 3
    assert _body(_detections(_boxes({})).encode())["columns"] == {}


@pytest.mark.parametrize(
    ("columns", "message"),
    [
        ({"distance_m": np.ones(2)}, r"column 'distance_m' must be an \(3,\) array .* \(2,\)"),
        ({"distance_m": np.ones((3, 1))}, r"must be an \(3,\) array .* shape \(3, 1\)"),
        ({"d": np.ones(3, np.float16)}, r"column 'd' must be .* dtype float16"),
        ({"d": np.ones(3, np.uint8)}, r"column 'd' must be .* dtype uint8"),
        ({"d": np.array(["a", "b", "c"])}, r"column 'd' must be .* dtype <U1"),
        ({"d": np.ones(3, ">f8")}, r"column 'd' must be"),  # not in native byte order
        ({"d": [1.0, 2.0, 3.0]}, r"column 'd' must be .* got a list"),
        ({"2d": np.ones(3)}, r"a column name must match .* got '2d'"),
        ({"a b": np.ones(3)}, r"got 'a b'"),
        ({"": np.ones(3)}, r"got ''"),
        ({"x" * (MAX_COLUMN_NAME_CHARS + 1): np.ones(3)}, r"at most 64 characters"),
        ({f"c{i}": np.ones(3) for i in range(MAX_COLUMNS + 1)}, r"17 columns is over .* 16"),
        ([("d", np.ones(3))], r"columns must be a mapping"),
    ],
)
def test_each_bad_column_says_what_was_expected(columns: Any, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        _boxes(columns)


def test_every_operation_that_selects_rows_selects_the_columns_rows() -> None:
    boxes = _boxes(EVERY_KIND)
    picked = boxes.take(np.array([2, 0], np.intp))
    assert picked.columns["mask_id"].tolist() == [2**31 - 1, 3]
    assert picked.columns["occluded"].tolist() == [True, True]
    assert picked.take(np.zeros(0, np.intp)).columns["big"].shape == (0,)
    tracked = boxes.with_track_ids(np.array([1, 2, 3], np.int32))
    moved = boxes.with_xyxy(XYXY * 2)
    for kept in (tracked, moved):
        assert list(kept.columns) == list(EVERY_KIND)
        assert kept.columns["distance_m"] is boxes.columns["distance_m"]
    more = boxes.with_columns({"distance_m": np.zeros(3), "lane": np.ones(3, np.int32)})
    assert more.columns["distance_m"].tolist() == [0, 0, 0] and len(more.columns) == 6
    with pytest.raises(ValueError, match="column 'lane' must be"):
        boxes.with_columns({"lane": np.ones(2, np.int32)})


def test_the_detector_s_selection_keeps_the_columns_of_the_boxes_it_keeps() -> None:
    from perception.postprocess import select

    overlapping = np.array([[0, 0, 10, 10], [0, 0, 10, 10.5], [50, 50, 60, 60]], np.float32)
    candidates = Boxes(
        xyxy=overlapping,
        scores=np.array([0.5, 0.9, 0.7], np.float32),
        class_ids=np.zeros(3, np.int32),
        columns={"distance_m": np.array([1.0, 2.0, 3.0])},
    )
    kept = select(candidates, iou=0.5, max_det=10, apply_nms=True)
    assert kept.scores.tolist() == pytest.approx([0.9, 0.7])
    assert kept.columns["distance_m"].tolist() == [2.0, 3.0]


def test_the_columns_are_a_read_only_copy() -> None:
    given = {"distance_m": np.ones(3)}
    boxes = _boxes(given)
    given["other"] = np.zeros(3)
    assert list(boxes.columns) == ["distance_m"]
    with pytest.raises(TypeError):
        boxes.columns["x"] = np.ones(3)  # type: ignore[index]
    assert dict(Boxes().columns) == {}


def _bad_body(change: Any) -> bytes:
    body = _body(_detections(_boxes({"distance_m": EVERY_KIND["distance_m"]})).encode())
    body["columns"] = change(body["columns"])
    return _payload(body)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda c: [1, 2], r"Detections\.columns: expected map, got list"),
        (lambda c: {**c, **{f"c{i}": c["distance_m"] for i in range(16)}}, r"17 columns is over"),
        (lambda c: {"x" * 65: c["distance_m"]}, r"a column name must be 1\.\.64 characters"),
        (lambda c: {7: c["distance_m"]}, r"Detections: not msgpack"),  # strict_map_key
        (lambda c: {"d": 1.5}, r"Detections\.columns\.d: expected map, got float"),
        (lambda c: {"d": {"dtype": "float16", "data": b"\x00" * 6}}, r"d\.dtype: dtype must be"),
        (lambda c: {"d": {"dtype": 8, "data": b"\x00" * 24}}, r"d\.dtype: dtype must be one of"),
        (lambda c: {"d": {"dtype": "float64"}}, r"d\.data: expected 3 float64 values as bytes"),
        (lambda c: {"d": {"dtype": "float64", "data": b"\x00" * 16}}, r"expected 3 float64"),
        (lambda c: {"d": {"dtype": "int32", "data": "abcdefghijkl"}}, r"expected 3 int32"),
        (lambda c: {"d": {"dtype": "bool", "data": b"\x00\x02\x01"}}, r"a bool is byte 0 or 1"),
        (lambda c: {"2d": c["distance_m"]}, r"Detections: a column name must match"),
    ],
)
def test_bad_columns_on_the_wire_are_a_decode_error(change: Any, message: str) -> None:
    with pytest.raises(DecodeError, match=message):
        Detections.decode(_bad_body(change))


LONELY = Dim("k", 0, 10)


def test_columns_need_a_count_that_an_array_field_writes() -> None:
    @dataclass(frozen=True, slots=True, kw_only=True)
    class Orphan(Message):
        TAG: ClassVar[str] = "Orphan"
        columns: Annotated[dict[str, npt.NDArray[Any]], Columns(LONELY, 4, 8)]

    @dataclass(frozen=True, slots=True, kw_only=True)
    class NotAMap(Message):
        TAG: ClassVar[str] = "NotAMap"
        columns: Annotated[tuple[int, ...], Columns(LONELY, 4, 8)]

    with pytest.raises(TypeError, match="Columns' Dim 'k' sizes no array field"):
        Orphan(columns={}).encode()
    with pytest.raises(TypeError, match=r"Columns annotates a Mapping\[str, NDArray\]"):
        NotAMap(columns=()).encode()
