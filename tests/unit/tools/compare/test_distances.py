"""``zstack compare`` with depth: the distances of the matched detections of two recordings,
whose distances differ by a known amount, read back from MCAP files our recorder writes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from common.boxes import Boxes
from common.messages import Detections, Header
from perception import depth
from services.recorder.channels import Translator
from services.recorder.contract import RecorderSettings
from services.recorder.writer import McapFile
from services.ros2.contract import Ros2Settings
from tools.compare import distances
from tools.compare.compare import compare_runs, report_markdown
from tools.compare.plots import comparison_plot
from tools.compare.runs import load_run

NAN = float("nan")
OFFSET_M = 0.25  # run B's distances are run A's plus this


def _detections(seq: int, metres: list[float] | None) -> Detections:
    """Two people side by side in frame ``seq``; ``metres``: their distances (NaN unknown), None
    for a run made without depth (no depth columns at all)."""
    columns = {}
    if metres is not None:
        columns = {name: np.full(2, NAN, np.float32) for name in depth.COLUMNS}
        columns[depth.DISTANCE] = np.array(metres, np.float32)
    header = Header(stamp_ns=10**18 + seq * 10**8, frame_id="cam", seq=seq, source="camera")
    return Detections(
        header=header, image_width=640, image_height=480, class_names=("person", "person"),
        boxes=Boxes(xyxy=np.array([[0, 0, 100, 200], [300, 0, 400, 200]], np.float32),
                    scores=np.full(2, 0.9, np.float32), class_ids=np.zeros(2, np.int32),
                    columns=columns),
    )  # fmt: skip


def _record(path: Path, frames: dict[int, list[float] | None]) -> Path:
    out = McapFile(path, RecorderSettings())
    translator = Translator(Ros2Settings(), "front")
    for seq, metres in frames.items():
        dets = _detections(seq, metres)
        for entry in translator.entries("stack/detector/front/detections", dets):
            out.add(entry, dets.header.stamp_ns)
    out.close()
    return path


def test_the_distance_column_is_perceptions() -> None:
    assert distances.DISTANCE == depth.DISTANCE


def test_two_recordings_whose_distances_differ_by_a_known_amount(tmp_path: Path) -> None:
    a = {seq: [1.0 + seq, 2.5 + seq / 10] for seq in range(1, 21)}
    b = {seq: [m + OFFSET_M for m in metres] for seq, metres in a.items()}
    b[21] = b[22] = [3.0, 3.0]  # frames only B has: not compared
    a[3] = [NAN, a[3][1]]  # the left person: no distance in A, one in B
    b[4] = [b[4][0], NAN]  # the right person: one in A, none in B
    b[5] = [NAN, NAN]
    a[5] = [NAN, NAN]  # neither
    run_a = load_run(_record(tmp_path / "a.mcap", a))
    run_b = load_run(_record(tmp_path / "b.mcap", b))
    c = compare_runs(run_a, run_b)
    f = c.distances
    assert c.matched == 40 and f.present
    assert (len(f.diffs), f.only_a, f.only_b, f.neither) == (40 - 4, 1, 1, 2)
    # float32 in the detections: a quarter metre up to their rounding.
    assert f.diffs == pytest.approx([OFFSET_M] * 36, abs=1e-5)
    md = report_markdown(c, "a.mcap", "b.mcap")
    assert "## Distances" in md
    assert "Matched detections with a distance in both runs: 36: |B - A| median **0.250 m**, " \
           "p95 0.250 m, max 0.250 m (B - A median +0.250 m)." in md  # fmt: skip
    assert "With a distance in A only: 1; in B only: 1; in neither: 2." in md
    png = comparison_plot(c, "a", "b", tmp_path / "compare.png")
    assert png.stat().st_size > 0


def test_runs_without_depth_have_no_distance_section_and_one_with_counts_as_only() -> None:
    from tools.compare.runs import Run

    plain = Run(Path("a"), detections={("front", 1): _detections(1, None)})
    with_depth = Run(Path("b"), detections={("front", 1): _detections(1, [2.0, NAN])})
    assert "Distances" not in report_markdown(compare_runs(plain, plain), "a", "a")
    c = compare_runs(plain, with_depth)
    assert (c.distances.diffs, c.distances.only_b, c.distances.neither) == ([], 1, 1)
    md = report_markdown(c, "a", "b")
    assert "no matched detection has a distance in both runs" in md
