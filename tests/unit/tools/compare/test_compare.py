"""Matching detections by class and IoU, command differences, latency, the report."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from common.boxes import Boxes
from common.messages import Detections, Header
from tools.compare.compare import (
    compare_runs,
    every_frame_rate,
    iou_matrix,
    match_frame,
    report_markdown,
)
from tools.compare.runs import CommandRecord, Run, detector_name


def _frame(seq: int, boxes: list[tuple[str, list[float]]], stamp: int = 0) -> Detections:
    stamp_ns = stamp or seq * 1_000_000_000
    return Detections(
        header=Header(stamp_ns=stamp_ns, frame_id="camera", seq=seq, source="camera"),
        image_width=640,
        image_height=480,
        boxes=Boxes(
            xyxy=np.array([b for _, b in boxes], dtype=np.float32).reshape(-1, 4),
            scores=np.full(len(boxes), 0.9, np.float32),
            class_ids=np.zeros(len(boxes), np.int32),  # compare goes by class name
        ),
        class_names=tuple(name for name, _ in boxes),
        timing_ms={"inference": 10.0 * seq},
        received_ns=stamp_ns + 2_000_000,
    )


def test_iou_matrix_against_hand_figures() -> None:
    a = np.array([[0, 0, 10, 10], [0, 0, 10, 10]], dtype=np.float64)
    b = np.array([[5, 0, 15, 10], [20, 20, 30, 30], [0, 0, 10, 10]], dtype=np.float64)
    assert iou_matrix(a, b)[0].tolist() == pytest.approx([50 / 150, 0.0, 1.0])


def test_match_frame_pairs_within_a_class_best_first_each_box_once() -> None:
    a = _frame(1, [("person", [0, 0, 10, 10]), ("car", [0, 0, 10, 10])])
    b = _frame(1, [("car", [1, 0, 11, 10]), ("person", [0, 0, 10, 10]), ("person", [0, 0, 9, 10])])
    pairs = match_frame(a, b, 0.5)
    assert [(i, j) for i, j, _ in pairs] == [(0, 1), (1, 0)]
    assert pairs[1][2] == pytest.approx(90 / 110)
    assert match_frame(a, _frame(1, [("dog", [0, 0, 10, 10])]), 0.5) == []


def test_compare_runs_counts_matches_commands_and_latency() -> None:
    a = Run(Path("a"), detections={
        ("front", 1): _frame(1, [("person", [0, 0, 10, 10])]),
        ("front", 2): _frame(2, [("person", [0, 0, 10, 10]), ("cup", [5, 5, 6, 6])]),
        ("front", 3): _frame(3, [("person", [0, 0, 10, 10])]),  # only A detected on frame 3
    })  # fmt: skip
    b = Run(Path("b"), detections={
        ("front", 1): _frame(1, [("person", [0, 0, 10, 10])], stamp=50_000_000_000),
        ("front", 2): _frame(2, [("person", [30, 30, 40, 40])], stamp=51_000_000_000),
    })  # fmt: skip
    a.commands = [
        CommandRecord(1_100_000_000, 1_000_000_000, 0.3, 0.1),
        CommandRecord(1_200_000_000, 1_000_000_000, 0.0, 0.0),
    ]  # a later repeat: ignored
    b.commands = [CommandRecord(50_150_000_000, 50_000_000_000, 0.2, -0.1)]  # fmt: skip
    a.detectors = ["yolov5s-coco.onnx (onnx/cpu/fp32)"]
    b.detectors = [detector_name({"model": "yolov5s-coco-480.onnx", "backend": "onnx/cpu/int8"})]
    c = compare_runs(a, b, iou_min=0.5)
    assert (c.frames, c.frames_both) == ((3, 2), 2)
    assert (c.detections, c.matched) == ((3, 2), 1)
    assert c.match_rate == pytest.approx(1 / 3)
    assert c.per_class == {"cup": (1, 0, 0), "person": (2, 2, 1)}
    assert c.command_pairs == 1
    assert c.dv == pytest.approx([0.1]) and c.dw == pytest.approx([0.2])
    lat_a, lat_b = c.latency_ms["capture_to_command"]
    assert lat_a == pytest.approx([100.0]) and lat_b == pytest.approx([150.0])
    assert c.latency_ms["capture_to_detector"][0] == pytest.approx([2.0, 2.0, 2.0])
    md = report_markdown(c, "a.mcap", "b.mcap", "compare.png")
    assert "| person | 2 | 2 | 1 |" in md and "**33.3 %**" in md
    assert (
        "Detector: A yolov5s-coco.onnx (onnx/cpu/fp32); B yolov5s-coco-480.onnx (onnx/cpu/int8)."
        in md
    )
    assert "| inference | 20.0 | 15.0 |" in md
    assert "|dv| mean / max 0.100 / 0.100 m/s" in md and "![latency and IoU](compare.png)" in md


def test_the_report_of_runs_with_nothing_in_common_says_so() -> None:
    a = Run(Path("a"), detections={("front", 1): _frame(1, [])})
    c = compare_runs(a, Run(Path("b"), detections={("front", 2): _frame(2, [])}))
    md = report_markdown(c, "a", "b")
    assert "Detector: A unknown; B unknown." in md
    assert "both 0" in md and "0 frames: |dv| mean / max - m/s" in md
    assert "Nothing compared: no frame was detected on in both runs." in md
    assert "100.0 %" not in md  # nothing compared is no agreement


def test_a_camera_with_no_frame_in_both_shows_no_rate() -> None:
    person = ("person", [0, 0, 10, 10])
    a = Run(Path("a"), detections={("front", 1): _frame(1, [person]),
                                   ("rear", 1): _frame(1, [person])})  # fmt: skip
    b = Run(Path("b"), detections={("front", 1): _frame(1, [person]),
                                   ("rear", 2): _frame(2, [person])})  # fmt: skip
    md = report_markdown(compare_runs(a, b), "a", "b")
    assert "| front | 1 | 1 | 1 | 1 | 1 | 1 | 100.0 % |" in md
    assert "| rear | 1 | 1 | 0 | 0 | 0 | 0 | - (nothing compared) |" in md


def test_runs_that_share_few_frames_say_so_and_suggest_a_rate() -> None:
    # As seen: A 25 frames detected on, B 44, one in common. A recorded 100 frames over 10 s
    # (10 per s); its detector took 400 ms a frame (2.5 per s): at rate 0.25 it sees them all.
    person = [("person", [0.0, 0.0, 10.0, 10.0])]
    a = Run(Path("a"), frames=100, frame_span_s=10.0,
            detections={("front", s): _frame(s, person) for s in range(1, 101, 4)})  # fmt: skip
    b = Run(Path("b"), detections={("front", s): _frame(s, person) for s in (1, *range(2, 88, 2))})
    for run in (a, b):
        for d in run.detections.values():
            d.timing_ms.update(preprocess=0.0, inference=400.0, postprocess=0.0)
    c = compare_runs(a, b)
    assert (c.frames, c.frames_both) == ((25, 44), 1)
    assert c.suggested_rate == pytest.approx(0.25)
    md = report_markdown(c, "a.mcap", "b.mcap")
    assert "**Few frames in common**: 1 of A's 25 and B's 44." in md, md
    assert "rest on 1 frame." in md and "`zstack compare a.mcap --rate 0.25`" in md, md
    # Most frames in common: no warning.
    assert "Few frames" not in report_markdown(compare_runs(a, a), "a", "a")


@pytest.mark.parametrize(
    "frames, span_s, ms, rate",
    [
        (100, 10.0, 400.0, 0.25),  # 2.5 detections per s for 10 frames per s
        (100, 10.0, 90.0, None),  # it keeps up at rate 1
        (100, 10.0, None, None),  # no timings recorded
        (1, 0.0, 400.0, None),  # one frame: no frame rate
        (10_000, 1.0, 1000.0, 0.01),  # the slowest replay there is
    ],
)
def test_the_rate_at_which_the_detector_sees_every_frame(
    frames: int, span_s: float, ms: float | None, rate: float | None
) -> None:
    assert every_frame_rate(frames, span_s, ms) == (None if rate is None else pytest.approx(rate))


def test_two_cameras_are_matched_each_on_its_own_and_reported_per_camera() -> None:
    # Both cameras number their frames from 1: frame 1 of the rear camera is not the front's.
    person, dog = ("person", [0, 0, 10, 10]), ("dog", [20, 20, 40, 40])
    a = Run(Path("a"), detections={
        ("front", 1): _frame(1, [person]),
        ("rear", 1): _frame(1, [dog]),
        ("rear", 2): _frame(2, [dog, person]),
    })  # fmt: skip
    b = Run(Path("b"), detections={
        ("front", 1): _frame(1, [person]),
        ("rear", 1): _frame(1, [("dog", [20, 20, 39, 40])]),
        ("rear", 2): _frame(2, [person]),  # the dog missed
        ("rear", 3): _frame(3, [dog]),  # only B detected on it
    })  # fmt: skip
    c = compare_runs(a, b, iou_min=0.5)
    assert (c.frames, c.frames_both) == ((3, 4), 3)
    assert (c.detections, c.matched) == ((4, 3), 3)
    front, rear = c.per_camera["front"], c.per_camera["rear"]
    assert (front.frames, front.frames_both, front.detections, front.matched) == (
        (1, 1), 1, (1, 1), 1,
    )  # fmt: skip
    assert (rear.frames, rear.frames_both, rear.detections, rear.matched) == (
        (2, 3), 2, (3, 2), 2,
    )  # fmt: skip
    assert rear.match_rate == pytest.approx(2 / 3)
    md = report_markdown(c, "a", "b")
    assert "(matched by camera and sequence number)" in md
    assert "| front | 1 | 1 | 1 | 1 | 1 | 1 | 100.0 % |" in md
    assert "| rear | 2 | 3 | 2 | 3 | 2 | 2 | 66.7 % |" in md
    # One camera: no per-camera table, the report as it always was.
    solo = Run(Path("s"), detections={("front", 1): _frame(1, [person])})
    plain = report_markdown(compare_runs(solo, solo), "s", "s")
    assert "## Per camera" not in plain and "(matched by sequence number)" in plain


def test_a_recording_of_two_cameras_reads_back_by_camera_and_frame(tmp_path: Path) -> None:
    from services.recorder.channels import Translator
    from services.recorder.contract import RecorderSettings
    from services.recorder.writer import McapFile
    from services.ros2.contract import Ros2Settings
    from tools.compare.runs import load_run

    out = McapFile(tmp_path / "two.mcap", RecorderSettings())
    translator = Translator(Ros2Settings(), "front")
    for camera, label in (("front", "person"), ("rear", "dog")):
        dets = _frame(1, [(label, [0, 0, 10, 10])])
        for entry in translator.entries(f"test/ab/detector/{camera}/detections", dets):
            out.add(entry, dets.header.stamp_ns)
    out.close()
    run = load_run(tmp_path / "two.mcap")
    assert {frame: d.class_names for frame, d in run.detections.items()} == {
        ("front", 1): ("person",),
        ("rear", 1): ("dog",),
    }


def test_detections_recorded_before_columns_existed_read_back_with_none() -> None:
    import json

    from common.errors import DecodeError
    from services.recorder.channels import to_json
    from tools.compare.runs import detections_from_json

    body = json.loads(to_json(_frame(3, [("person", [0, 0, 10, 10])])))
    del body["columns"]  # what a recorder wrote before columns existed
    old = detections_from_json(body)
    assert dict(old.boxes.columns) == {} and old.class_names == ("person",)
    for bad in ([1.5], {"d": "xyz"}, {"d": [1.0, 2.0]}, {"2d": [1.0]}):
        with pytest.raises(DecodeError, match="not a Detections message"):
            detections_from_json({**body, "columns": bad})
