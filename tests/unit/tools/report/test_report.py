"""The report from a saved session: files, valid PNGs, the markdown's sections, bad input."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from common.boxes import Boxes
from common.errors import ConfigError
from common.messages import Detections, Header, ServiceCounters, Twist
from services.metrics.aggregate import Aggregator
from tools.report import report
from tools.report.report import ReportOptions, load_benchmarks, read_session, write_report
from tools.report.session import check_session, snapshot_session

MS = 1_000_000
REPO = Path(__file__).resolve().parents[4]
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _session(seconds: int = 12) -> dict[str, Any]:
    """A session as the recorder makes it, from messages of a 4 FPS detector fed at 10 Hz."""
    agg = Aggregator(window_s=100.0, history_s=100.0)
    rng = np.random.default_rng(0)
    hdr = Header(stamp_ns=0, frame_id="", seq=0, source="detector")
    for i in range(seconds * 4):
        t = 100.0 + i * 0.25
        stamp = int(t * 1e9)
        infer = float(rng.gamma(9, 25))
        det = Detections(
            header=Header(stamp_ns=stamp, frame_id="camera", seq=i, source="camera"),
            image_width=512,
            image_height=512,
            boxes=Boxes(
                xyxy=np.array([[0, 60, 330, 512]], np.float32),
                scores=np.full(1, 0.8, np.float32),
                class_ids=np.zeros(1, np.int32),
            ),
            class_names=("person",),
            timing_ms={"preprocess": 4.0, "inference": infer, "postprocess": 1.0},
            model="yolov5s-coco.onnx",
            backend="onnx/cpu/fp32",
            received_ns=stamp + 2 * MS,
            published_ns=stamp + int((40 + infer) * MS),
        )
        agg.on_detections(det, now=t + (40 + infer) / 1000, camera="front")
        cmd_stamp = det.published_ns + 3 * MS
        twist = Twist(header=Header(stamp_ns=cmd_stamp, frame_id="base_link", seq=i,
                                    source="controller"), input_stamp_ns=stamp)  # fmt: skip
        agg.on_twist(twist, now=t + 0.05 + infer / 1000)
        if i % 4 == 0:
            counters = {"frames_in": i * 10 // 4, "dropped": i * 6 // 4}
            agg.on_counters(
                ServiceCounters(header=hdr, service="detector", counters=counters), now=t
            )
    session = snapshot_session(agg, start=100.0, now=100.0 + seconds)
    session["config"] = {"camera_source": "sample:cameraman", "detector_backend": "onnx"}
    session["machine"] = {"cpu_model": "Test CPU", "cpu_count": 2, "gpus": []}
    return session


def _bench(name: str, inference: float) -> dict[str, Any]:
    p50 = {"preprocess": 4.0, "inference": inference, "postprocess": 1.0, "total": inference + 5}
    return {"p50_ms": p50, "p95_ms": {**p50, "total": inference * 1.2 + 5},
            "backend": {"name": name, "device": "cpu", "precision": "fp32"}}  # fmt: skip


def _report(options: ReportOptions) -> int:
    """The report command in-process (its own stop event: pytest keeps its Ctrl-C)."""
    return report.run(options, threading.Event())


def _check_png(path: Path) -> None:
    data = path.read_bytes()
    assert data.startswith(PNG_SIGNATURE), path
    assert len(data) < 200_000, f"{path} is {len(data)} bytes"
    image = cv2.imread(str(path))
    assert image is not None and image.shape[0] >= 400 and image.shape[1] >= 700, path


def test_report_from_a_saved_session(tmp_path: Path) -> None:
    session = _session()
    session["benchmarks"] = [_bench("onnx", 240.0), _bench("tensorrt", 12.0)]
    written = write_report(session, tmp_path / "out")
    names = sorted(p.name for p in written)
    assert names == sorted([
        "report.md", "session.json", "latency_histogram.png", "fps_over_time.png",
        "stage_breakdown.png", "backend_comparison.png",
    ])  # fmt: skip
    for path in written:
        if path.suffix == ".png":
            _check_png(path)
    md = (tmp_path / "out" / "report.md").read_text()
    for needle in (
        "## Summary",
        "## Latency per stage",
        "## Machine",
        "Test CPU",
        "![Throughput over time](fps_over_time.png)",
        "onnx/cpu/fp32",
        "tensorrt",
        "can differ by the frames of a part second",  # why frames and samples disagree
    ):
        assert needle in md, needle  # fmt: skip
    # The saved copy reads back, and the timeline has one point per recorded second.
    saved = check_session(json.loads((tmp_path / "out" / "session.json").read_text()), "saved")
    assert len(saved["summary"]["timeline"]["t"]) >= 10
    assert saved["summary"]["fps"] == pytest.approx(4.0, rel=0.05)


def test_report_command_reads_a_session_and_benchmarks(tmp_path: Path) -> None:
    (tmp_path / "s.json").write_text(json.dumps(_session(seconds=4)))
    bench = tmp_path / "b.jsonl"  # two `benchmark --json` lines in one file
    bench.write_text("\n".join(json.dumps(_bench(n, 50.0)) for n in ("onnx", "openvino")))
    out = tmp_path / "out"
    session = str(tmp_path / "s.json")
    options = ReportOptions(from_file=session, out=str(out), benchmarks=(str(bench),))
    assert _report(options) == 0
    assert (out / "backend_comparison.png").is_file()
    assert not (out / "supervisor.log").exists()  # nothing was run


def test_one_benchmark_gets_a_table_but_no_comparison_plot(tmp_path: Path) -> None:
    session = {**_session(seconds=3), "benchmarks": [_bench("onnx", 240.0)]}
    written = write_report(session, tmp_path)
    assert "backend_comparison.png" not in {p.name for p in written}
    assert "## Backends" in (tmp_path / "report.md").read_text()


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("[1, 2]", "not a session file"),
        ('{"version": 1}', "'duration_s' missing"),
        ("{nope", "not valid JSON"),
    ],
)
def test_bad_session_files_are_refused(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / "s.json"
    path.write_text(content)
    with pytest.raises(ConfigError, match=message) as err:
        read_session(path)
    assert str(err.value).startswith(str(path))


def test_a_bad_session_file_is_one_line_from_the_command(tmp_path: Path) -> None:
    path = tmp_path / "s.json"
    path.write_text("[1, 2]")
    proc = subprocess.run(
        [sys.executable, "-m", "tools.report", "report", "--from", str(path),
         "--out", str(tmp_path / "out")],
        cwd=REPO, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert proc.returncode == 2
    expected = f"report: error: {path}: not a session file (expected a JSON object)"
    assert proc.stderr.strip() == expected


def test_bad_benchmark_files_and_option_mixes_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "b.json"
    path.write_text('{"p95_ms": {}}')
    with pytest.raises(ConfigError, match=r"not `tools\.detector benchmark --json` output"):
        load_benchmarks([str(path)])
    with pytest.raises(ConfigError, match="--from reads a saved session"):
        _report(ReportOptions(from_file=str(path), duration_s=5, out=str(tmp_path)))


def test_a_side_by_side_benchmark_gives_one_entry_per_backend(tmp_path: Path) -> None:
    onnx, cuda = _bench("onnx", 240.0), _bench("cuda", 9.0)
    path = tmp_path / "b.json"
    path.write_text(json.dumps({**onnx, "backends": {"onnx": onnx, "cuda": cuda}}))
    assert [b["backend"]["name"] for b in load_benchmarks([str(path)])] == ["onnx", "cuda"]


def test_the_report_says_where_each_benchmark_ran(tmp_path: Path) -> None:
    onnx, cuda = _bench("onnx", 240.0), _bench("cuda", 9.0)
    machine = {"cpu_model": "Some GPU Box CPU", "cpu_count": 16}
    path = tmp_path / "b.json"
    path.write_text(
        json.dumps({**onnx, "machine": machine, "backends": {"onnx": onnx, "cuda": cuda}})
    )
    benchmarks = load_benchmarks([str(path)])
    assert all(b["machine"] == machine for b in benchmarks)
    session = {**_session(seconds=3), "benchmarks": benchmarks}
    write_report(session, tmp_path / "out")
    assert "Some GPU Box CPU, 16 cores" in (tmp_path / "out" / "report.md").read_text()


def test_summary_counts_detected_offered_and_dropped_over_one_span() -> None:
    from tools.report.report import _summary_rows

    session = _session()
    tl = session["summary"]["timeline"]
    # Detections heard before the detector's first counters (its warm-up) count in the total
    # since start but not on the timeline, the span over which offered frames are known.
    session["summary"]["frames"] = int(sum(tl["offered_fps"]) * tl["period_s"]) + 21
    rows = dict(_summary_rows(session))
    offered = float(rows["frames offered to the detector"])
    detected = float(rows["frames detected"].split()[0])
    dropped = float(rows["dropped by the detector"].split()[0])
    # The detector cannot detect more frames than it was offered over the same span.
    assert 0 < detected <= offered and dropped <= offered
