"""How two runs differ: detections matched per frame by class and IoU, the distances of the
matched ones (distances.py), the commands given for the same frames, and latency per stage.
Pure: runs in, figures and markdown out.

Frames are matched by camera and sequence number, which a replay keeps (play.py puts each
camera's frames back on its own key): recording A of a live run and recording B of A played
back name each frame alike. In each frame, detections are paired greedily, highest IoU first,
only within one class and at ``iou_min`` or more. With several cameras the report gives the
figures per camera as well.

Each run's detector skips the frames that come while it is busy, and not the same ones: when
the runs share fewer than ``LOW_OVERLAP`` of the smaller run's frames the report says so, and
suggests the replay ``--rate`` at which the detector (at its measured time per frame) sees
every frame of A. A camera (or a comparison) with no frame in both is "nothing compared",
never a rate.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from common.messages import Detections
from tools.compare.distances import DistanceFigures
from tools.compare.distances import report_lines as distance_lines
from tools.compare.runs import CommandRecord, FrameId, Run

#: Below this share of the smaller run's detected frames in common, the report warns that the
#: figures rest on few frames.
LOW_OVERLAP = 0.5
#: The detector's own stages, whose sum is its time per frame.
DETECTOR_STAGES = ("preprocess", "inference", "postprocess")

#: The stages whose latency is compared: name -> what it covers.
STAGES: dict[str, str] = {
    "preprocess": "letterbox and normalise",
    "inference": "the model",
    "postprocess": "decode and NMS",
    "capture_to_detector": "capture -> the detector took the frame",
    "capture_to_detections": "capture -> detections sent",
    "capture_to_command": "capture -> first command reacting to the frame",
}


def iou_matrix(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """IoU of every box in ``a`` (n, 4) with every box in ``b`` (m, 4), xyxy: (n, m)."""
    lo = np.maximum(a[:, None, :2], b[None, :, :2])
    hi = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.prod(np.clip(hi - lo, 0, None), axis=2)
    area_a = np.prod(np.clip(a[:, 2:] - a[:, :2], 0, None), axis=1)
    area_b = np.prod(np.clip(b[:, 2:] - b[:, :2], 0, None), axis=1)
    union = area_a[:, None] + area_b[None, :] - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1), 0.0)


def match_frame(a: Detections, b: Detections, iou_min: float) -> list[tuple[int, int, float]]:
    """Pairs (i in a, j in b, IoU) of one class each, greedily by IoU, each box used once."""
    if not len(a) or not len(b):
        return []
    # float64 here only: the IoUs compared against iou_min and reported.
    iou = iou_matrix(a.boxes.xyxy.astype(np.float64), b.boxes.xyxy.astype(np.float64))
    same = np.array([[na == nb for nb in b.class_names] for na in a.class_names])
    iou = np.where(same, iou, -1.0)
    pairs: list[tuple[int, int, float]] = []
    for flat in np.argsort(-iou, axis=None):
        i, j = divmod(int(flat), iou.shape[1])
        if iou[i, j] < iou_min:
            break
        if any(i == p or j == q for p, q, _ in pairs):
            continue
        pairs.append((i, j, float(iou[i, j])))
    return pairs


def latencies_ms(run: Run) -> dict[str, list[float]]:
    """Every stage's latencies in ``run``, in ms (a stage not recorded is an empty list)."""
    out: dict[str, list[float]] = {stage: [] for stage in STAGES}
    for d in run.detections.values():
        for stage in ("preprocess", "inference", "postprocess"):
            if stage in d.timing_ms:
                out[stage].append(d.timing_ms[stage])
        if d.received_ns:
            out["capture_to_detector"].append((d.received_ns - d.header.stamp_ns) / 1e6)
        if d.published_ns:
            out["capture_to_detections"].append((d.published_ns - d.header.stamp_ns) / 1e6)
    for stamp, cmd in first_commands(run).items():
        out["capture_to_command"].append((cmd.stamp_ns - stamp) / 1e6)
    return out


def first_commands(run: Run) -> dict[int, CommandRecord]:
    """The first command reacting to each frame, by the frame's capture stamp."""
    firsts: dict[int, CommandRecord] = {}
    for cmd in sorted(run.commands, key=lambda c: c.stamp_ns):
        if cmd.input_stamp_ns > 0:
            firsts.setdefault(cmd.input_stamp_ns, cmd)
    return firsts


def commands_by_frame(run: Run) -> dict[FrameId, CommandRecord]:
    by_stamp = first_commands(run)
    return {
        frame: by_stamp[d.header.stamp_ns]
        for frame, d in run.detections.items()
        if d.header.stamp_ns in by_stamp
    }


@dataclass(slots=True)
class CameraFigures:
    """One camera's share of a comparison."""

    frames: tuple[int, int] = (0, 0)  # detected frames in A, in B
    frames_both: int = 0
    detections: tuple[int, int] = (0, 0)  # detections in the frames both runs detected on
    matched: int = 0

    @property
    def match_rate(self) -> float:
        most = max(self.detections)
        return self.matched / most if most else 1.0


def rate_text(frames_both: int, match_rate: float) -> str:
    """A match rate as the report prints it; none where no frame was in both runs."""
    return f"{100 * match_rate:.1f} %" if frames_both else "- (nothing compared)"


def overlap(frames: tuple[int, int], frames_both: int) -> float:
    """The frames both runs detected on, as a share of the smaller run's (0 when one is
    empty)."""
    fewest = min(frames)
    return frames_both / fewest if fewest else 0.0


def detector_ms(run: Run) -> float | None:
    """The median time the run's detector spent on a frame (its stages' sum), in ms."""
    totals = [
        sum(d.timing_ms[s] for s in DETECTOR_STAGES if s in d.timing_ms)
        for d in run.detections.values()
        if any(s in d.timing_ms for s in DETECTOR_STAGES)
    ]
    return float(np.median(totals)) if totals else None


def every_frame_rate(frames: int, span_s: float, ms_per_frame: float | None) -> float | None:
    """The replay rate (0.01..1, rounded down) at which a detector taking ``ms_per_frame`` sees
    each of ``frames`` recorded over ``span_s``; None when it already does at 1, or when the
    figures are missing."""
    if ms_per_frame is None or ms_per_frame <= 0 or frames < 2 or span_s <= 0:
        return None
    rate = (1000.0 / ms_per_frame) / (frames / span_s)
    return None if rate >= 1 else max(0.01, int(rate * 100) / 100)


@dataclass(slots=True)
class Comparison:
    iou_min: float
    frames: tuple[int, int] = (0, 0)  # detected frames in A, in B
    frames_both: int = 0
    detections: tuple[int, int] = (0, 0)  # detections in the frames both runs detected on
    matched: int = 0
    ious: list[float] = field(default_factory=list)
    per_class: dict[str, tuple[int, int, int]] = field(default_factory=dict)  # a, b, matched
    command_pairs: int = 0
    dv: list[float] = field(default_factory=list)  # |linear A - linear B|, m/s
    dw: list[float] = field(default_factory=list)  # |angular A - angular B|, rad/s
    latency_ms: dict[str, tuple[list[float], list[float]]] = field(default_factory=dict)
    detectors: tuple[list[str], list[str]] = field(default_factory=lambda: ([], []))
    per_camera: dict[str, CameraFigures] = field(default_factory=dict)  # by camera name
    distances: DistanceFigures = field(default_factory=DistanceFigures)  # of the matched
    # The replay rate at which the detector sees every frame of A (None: it does at 1, or
    # unknown).
    suggested_rate: float | None = None

    @property
    def match_rate(self) -> float:
        """Matched detections over the larger side's count (1.0 when both found nothing)."""
        most = max(self.detections)
        return self.matched / most if most else 1.0

    @property
    def overlap(self) -> float:
        return overlap(self.frames, self.frames_both)


def compare_runs(a: Run, b: Run, iou_min: float = 0.5) -> Comparison:
    out = Comparison(
        iou_min=iou_min,
        frames=(len(a.detections), len(b.detections)),
        detectors=(a.detectors, b.detectors),
    )
    cameras = sorted({camera for camera, _ in (*a.detections, *b.detections)})
    out.per_camera = {
        camera: CameraFigures(frames=(
            sum(1 for c, _ in a.detections if c == camera),
            sum(1 for c, _ in b.detections if c == camera),
        ))
        for camera in cameras
    }  # fmt: skip
    both = sorted(set(a.detections) & set(b.detections))
    out.frames_both = len(both)
    count_a: Counter[str] = Counter()
    count_b: Counter[str] = Counter()
    count_m: Counter[str] = Counter()
    for frame in both:
        da, db = a.detections[frame], b.detections[frame]
        count_a.update(da.class_names)
        count_b.update(db.class_names)
        pairs = match_frame(da, db, iou_min)
        out.distances.add(da, db, pairs)
        for i, _j, iou in pairs:
            count_m[da.class_names[i]] += 1
            out.ious.append(iou)
        cam = out.per_camera[frame[0]]
        cam.frames_both += 1
        cam.detections = (cam.detections[0] + len(da), cam.detections[1] + len(db))
        cam.matched += len(pairs)
    out.detections = (sum(count_a.values()), sum(count_b.values()))
    out.matched = sum(count_m.values())
    out.per_class = {
        name: (count_a[name], count_b[name], count_m[name])
        for name in sorted(set(count_a) | set(count_b))
    }
    cmd_a, cmd_b = commands_by_frame(a), commands_by_frame(b)
    for frame in sorted(set(cmd_a) & set(cmd_b)):
        out.dv.append(abs(cmd_a[frame].linear - cmd_b[frame].linear))
        out.dw.append(abs(cmd_a[frame].angular - cmd_b[frame].angular))
    out.command_pairs = len(out.dv)
    lat_a, lat_b = latencies_ms(a), latencies_ms(b)
    out.latency_ms = {stage: (lat_a[stage], lat_b[stage]) for stage in STAGES}
    slowest = max((ms for ms in (detector_ms(a), detector_ms(b)) if ms is not None), default=None)
    out.suggested_rate = every_frame_rate(a.frames, a.frame_span_s, slowest)
    return out


def _stat(values: list[float], q: float) -> str:
    return f"{np.percentile(values, q):.1f}" if values else "-"


def _mean_max(values: list[float]) -> str:
    return f"{np.mean(values):.3f} / {np.max(values):.3f}" if values else "-"


def _cameras_table(c: Comparison) -> list[str]:
    """The figures per camera, when there is more than one (else nothing: one camera's are the
    totals)."""
    if len(c.per_camera) < 2:
        return []
    return [
        "## Per camera",
        "",
        "| camera | frames A | frames B | both | detections A | detections B | matched | rate |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
        *(
            f"| {name} | {f.frames[0]} | {f.frames[1]} | {f.frames_both} | {f.detections[0]} | "
            f"{f.detections[1]} | {f.matched} | {rate_text(f.frames_both, f.match_rate)} |"
            for name, f in c.per_camera.items()
        ),
        "",
    ]


def _overlap_note(c: Comparison, name_a: str) -> list[str]:
    """A warning when the runs share few frames, with the rate that would fix it."""
    if min(c.frames) == 0 or c.overlap >= LOW_OVERLAP:
        return []
    fix = (
        f" Replay A at `--rate {c.suggested_rate:g}` (`zstack compare {name_a} --rate "
        f"{c.suggested_rate:g}`), at which the detector, at its measured time per frame, "
        "sees every frame."
        if c.suggested_rate is not None
        else ""
    )
    return [
        f"**Few frames in common**: {c.frames_both} of A's {c.frames[0]} and B's {c.frames[1]}. "
        "Each run's detector skipped the frames that came while it was busy, and not the same "
        f"ones: the figures below rest on {c.frames_both} frame"
        f"{'' if c.frames_both == 1 else 's'}.{fix}",
        "",
    ]


def _totals_line(c: Comparison) -> str:
    if not c.frames_both:
        return "Nothing compared: no frame was detected on in both runs."
    mean_iou = f"Mean IoU of the matched: {np.mean(c.ious):.3f}." if c.ious else ""
    return (
        f"In the frames both detected on: A {c.detections[0]}, B {c.detections[1]}, "
        f"matched {c.matched} (same class, IoU >= {c.iou_min:g}): "
        f"**{rate_text(c.frames_both, c.match_rate)}** of the larger side. {mean_iou}"
    )


def report_markdown(c: Comparison, name_a: str, name_b: str, plot: str = "") -> str:
    """The comparison as a short markdown report (``plot``: a PNG beside it to show)."""
    lines = [
        f"# {name_a} vs {name_b}",
        "",
        f"Detector: A {', '.join(c.detectors[0]) or 'unknown'}; "
        f"B {', '.join(c.detectors[1]) or 'unknown'}.",
        "",
        f"Frames detected on: A {c.frames[0]}, B {c.frames[1]}, both {c.frames_both} "
        f"(matched by {'camera and ' if len(c.per_camera) > 1 else ''}sequence number).",
        "",
        *_overlap_note(c, name_a),
        *_cameras_table(c),
        "## Detections",
        "",
        _totals_line(c),
        "",
        "| class | A | B | matched |",
        "|---|---:|---:|---:|",
        *(f"| {n} | {a} | {b} | {m} |" for n, (a, b, m) in c.per_class.items()),
        "",
        *distance_lines(c.distances),
        "## Commands",
        "",
        f"First command reacting to the same frame, {c.command_pairs} frames: "
        f"|dv| mean / max {_mean_max(c.dv)} m/s, |dw| mean / max {_mean_max(c.dw)} rad/s.",
        "",
        "## Latency per stage (ms)",
        "",
        "| stage | A p50 | B p50 | A p95 | B p95 | what |",
        "|---|---:|---:|---:|---:|---|",
        *(
            f"| {stage} | {_stat(la, 50)} | {_stat(lb, 50)} | {_stat(la, 95)} | "
            f"{_stat(lb, 95)} | {STAGES[stage]} |"
            for stage, (la, lb) in c.latency_ms.items()
        ),
    ]
    if plot:
        lines += ["", f"![latency and IoU]({plot})"]
    return "\n".join(lines) + "\n"
