"""The one detections struct of arrays: each error of its one check, and the message's
conversions to and from it."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from common.boxes import Boxes, check_boxes, valid_rows
from common.errors import DecodeError
from common.messages import Detections, Header

XYXY = np.array([[0, 0, 10, 20], [5, 5, 5, 5]], np.float32)  # the second box is a point
SCORES = np.array([0.9, 0.3], np.float32)
IDS = np.array([0, 7], np.int32)
TRACKS = np.array([4, -1], np.int32)


def _arrays(**change: Any) -> dict[str, Any]:
    arrays: dict[str, Any] = {
        "xyxy": XYXY.copy(),
        "scores": SCORES.copy(),
        "class_ids": IDS.copy(),
        "track_ids": TRACKS.copy(),
    }
    return {**arrays, **change}


def test_valid_arrays_pass_with_or_without_track_ids() -> None:
    check_boxes(**_arrays())
    check_boxes(**_arrays(track_ids=None))
    empty = Boxes()
    assert len(empty) == 0 and empty.xyxy.shape == (0, 4) and empty.track_ids is None
    assert len(Boxes(**_arrays())) == 2


def _xyxy_with(row: int, col: int, value: float) -> Any:
    xyxy = XYXY.copy()
    xyxy[row, col] = value
    return xyxy


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"xyxy": XYXY.tolist()}, r"xyxy must be an \(n, 4\) float32 array, got a list"),
        ({"xyxy": XYXY[:, :3]}, r"xyxy must be an \(n, 4\) float32 array, got shape \(2, 3\)"),
        ({"xyxy": XYXY[0]}, r"xyxy must be an \(n, 4\) float32 array, got shape \(4,\)"),
        ({"xyxy": XYXY.astype(np.float64)}, r"got shape \(2, 4\) dtype float64"),
        ({"scores": SCORES[:1]}, r"scores must be a \(2,\) float32 array to match xyxy, got shape"),
        ({"scores": SCORES.astype(np.float16)}, r"scores must be .* dtype float16"),
        ({"scores": [0.9, 0.3]}, r"scores must be a \(2,\) float32 array .* got a list"),
        ({"class_ids": IDS.astype(np.int64)}, r"class_ids must be a \(2,\) int32 array .* int64"),
        ({"class_ids": IDS[:, None]}, r"class_ids must be a \(2,\) int32 array .*\(2, 1\)"),
        ({"track_ids": TRACKS[:1]}, r"track_ids must be a \(2,\) int32 array to match xyxy"),
        ({"track_ids": TRACKS.astype(np.uint32)}, r"track_ids must be .* dtype uint32"),
        ({"xyxy": _xyxy_with(1, 2, np.nan)}, r"boxes and scores must be finite, got .* row 1"),
        ({"xyxy": _xyxy_with(0, 0, -np.inf)}, r"boxes and scores must be finite, got .* row 0"),
        ({"scores": np.array([0.9, np.nan], np.float32)}, r"must be finite, got .*nan in row 1"),
        ({"xyxy": _xyxy_with(0, 2, -1.0)}, r"x2 >= x1 and y2 >= y1, got \[0.0, 0.0, -1.0, 20.0\]"),
        ({"xyxy": _xyxy_with(1, 3, 4.0)}, r"x2 >= x1 and y2 >= y1, got .* in row 1"),
    ],
)
def test_each_error_says_what_was_expected(change: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        check_boxes(**_arrays(**change))
    with pytest.raises(ValueError, match=message):  # the struct checks with the same function
        Boxes(**_arrays(**change))


def test_valid_rows_is_the_rule_the_check_applies() -> None:
    xyxy = np.array([[0, 0, 1, 1], [np.nan, 0, 1, 1], [2, 0, 1, 1], [0, 2, 1, 1]], np.float32)
    scores = np.array([0.5, 0.5, 0.5, 0.5], np.float32)
    assert valid_rows(xyxy, scores).tolist() == [True, False, False, False]
    scores[0] = np.inf
    assert not valid_rows(xyxy, scores)[0]


def test_boxes_are_frozen_and_rows_are_taken_together() -> None:
    boxes = Boxes(**_arrays())
    with pytest.raises(dataclasses.FrozenInstanceError):
        boxes.scores = SCORES  # type: ignore[misc]
    picked = boxes.take(np.array([1], np.intp))
    assert picked.xyxy.tolist() == [XYXY[1].tolist()] and picked.class_ids.tolist() == [7]
    assert picked.track_ids is not None and picked.track_ids.tolist() == [-1]
    untracked = boxes.with_track_ids(None)
    assert untracked.track_ids is None and untracked.scores is boxes.scores
    with pytest.raises(ValueError, match="track_ids must be"):
        boxes.with_track_ids(np.zeros(3, np.int32))
    with pytest.raises(ValueError, match="x2 >= x1"):
        boxes.with_xyxy(XYXY[:, [2, 1, 0, 3]])


HEADER = Header(stamp_ns=1_700_000_000_000_000_000, frame_id="camera", seq=3, source="test")


@pytest.mark.parametrize("track_ids", [TRACKS, None])
def test_detections_round_trip_through_the_struct(track_ids: Any) -> None:
    boxes = Boxes(xyxy=XYXY, scores=SCORES, class_ids=IDS, track_ids=track_ids)
    msg = Detections(
        boxes=boxes,
        header=HEADER,
        image_width=640,
        image_height=480,
        class_names=("person", "cup"),
        model="m.onnx",
    )
    assert (msg.model, msg.class_names, len(msg)) == ("m.onnx", ("person", "cup"), 2)
    # The message holds the very arrays; on the wire they are flat keys (test_messages).
    assert msg.boxes.xyxy is XYXY and msg.boxes.scores is SCORES and msg.boxes.class_ids is IDS
    assert msg.boxes.track_ids is track_ids
    for back in (msg.boxes, Detections.decode(msg.encode()).boxes):
        for name in ("xyxy", "scores", "class_ids"):
            np.testing.assert_array_equal(getattr(back, name), getattr(boxes, name))
            assert getattr(back, name).dtype == getattr(boxes, name).dtype
        if track_ids is None:
            assert back.track_ids is None
        else:
            assert back.track_ids is not None
            np.testing.assert_array_equal(back.track_ids, track_ids)


def test_detections_validate_through_the_same_check() -> None:
    bad = _xyxy_with(0, 3, -5.0)
    with pytest.raises(ValueError) as from_struct:
        check_boxes(bad, SCORES, IDS)
    with pytest.raises(ValueError) as from_message:
        Detections(
            header=HEADER,
            image_width=640,
            image_height=480,
            boxes=Boxes(xyxy=bad, scores=SCORES, class_ids=IDS),
            class_names=("a", "b"),
        )
    assert str(from_message.value) == str(from_struct.value)
    with pytest.raises(ValueError, match=r"class_ids must be a \(2,\) int32 array"):
        Detections(
            header=HEADER,
            image_width=640,
            image_height=480,
            boxes=Boxes(xyxy=XYXY, scores=SCORES, class_ids=IDS.astype(np.int64)),
            class_names=("a", "b"),
        )
    with pytest.raises(ValueError, match="class_names must have 2 entries, got 1"):
        Detections(
            boxes=Boxes(xyxy=XYXY, scores=SCORES, class_ids=IDS),
            header=HEADER,
            image_width=640,
            image_height=480,
            class_names=("a",),
        )


def test_a_decoded_message_that_breaks_the_check_is_a_decode_error() -> None:
    good = Detections(
        boxes=Boxes(xyxy=XYXY, scores=SCORES, class_ids=IDS),
        header=HEADER,
        image_width=640,
        image_height=480,
        class_names=("a", "b"),
    ).encode()
    inverted = good.replace(XYXY.tobytes(), XYXY[:, [2, 3, 0, 1]].tobytes())
    assert inverted != good
    with pytest.raises(DecodeError, match="x2 >= x1"):
        Detections.decode(inverted)
